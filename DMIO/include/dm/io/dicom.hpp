// dm/io/dicom.hpp — DICOM image series (one single-frame file per slice).
//
// Reading. readDicomSeries() takes a directory (every file in it that parses
// as DICOM; others are skipped with a debug log) or one file (then the files
// of its directory with the same SeriesInstanceUID). When the files hold
// several series, DicomReadOptions::seriesUid picks one; left empty, the read
// fails unless there is exactly one, and the error's hint lists every UID with
// its slice count. A symlink in the folder must lead into an allowed root
// (FileSystem::confine), else the read fails with ErrorCode::Denied. Slices are sorted by the projection of ImagePositionPatient
// (0020,0032) onto the slice normal n = row × column cosine of
// ImageOrientationPatient (0020,0037), so k grows along +n whatever the file
// names or InstanceNumbers say. The slice step is the mean difference of the
// sorted positions (a gantry tilt gives a sheared affine); gaps must agree
// within max(0.01 mm, 1 % of the mean gap) and each position must lie within
// that tolerance of first + k · step.
//
// Geometry. DICOM's patient frame is LPS in millimetres; the SDK world is
// RAS+ in metres (see volume_io.hpp), so x and y are negated and lengths
// scaled by 1e-3. Voxel (i, j, k) is column i, row j of slice k: the i step is
// the row cosine × column spacing = PixelSpacing[1], the j step the column
// cosine × row spacing = PixelSpacing[0] (PixelSpacing (0028,0030) is
// "row spacing \ column spacing").
//
// Voxels. SamplesPerPixel 1 (MONOCHROME1/2; MONOCHROME1 values are kept as
// stored, not inverted), BitsAllocated 8, 16 or 32, PixelRepresentation
// unsigned/signed, BitsStored < BitsAllocated masked (sign-extended when
// signed) at HighBit. Transfer syntaxes: implicit VR little endian, explicit
// VR little endian, explicit VR big endian (retired); compressed or deflated
// syntaxes fail with ErrorCode::Unsupported naming the syntax (decompress
// first, e.g. `dcmdjpeg`/`dcmdrle`). RescaleSlope/RescaleIntercept
// (0028,1053)/(0028,1052) are applied with decodeRawVolume()'s rules: the
// stored type is kept when every slice has (1, 0), otherwise the Volume is
// float32 (8/16-bit) or float64 (32-bit). Multi-frame files
// (NumberOfFrames > 1) fail with Unsupported.
//
// Robustness. Every file is first walked element by element (meta header,
// data set, nested sequences up to depth 16) with each declared length
// checked against the bytes that remain in its container; only then is the
// header part (the bytes before PixelData) handed to DCMTK, so a hostile
// length can never make DCMTK allocate more than the file's size. Errors name
// the file and the tag, e.g. "missing (0028,0030) PixelSpacing", or the byte
// offset of a malformed element. Nothing beyond DicomReadOptions::maxBytes is
// allocated for voxels. DCMTK's own dcmdata log is silenced on first use (the
// SDK reports through dm::Error).
//
// Writing. writeDicomSeries() writes one explicit VR little endian file per
// z-slice (see DicomWriteOptions) with geometry from the Volume's affine, so
// readDicomSeries() gives back the same voxels and affine (to the ~1e-10
// relative precision of DICOM's 16-character decimal strings).
//
// @code
//   auto v = dm::readDicomSeries("/data/ct/series1");
//   if (!v) { std::cerr << v.error() << '\n'; return 1; }
//   dm::Vec3 p = v->indexToWorld() * dm::Vec3(0, 0, 0);  // RAS+, metres
// @endcode
#pragma once

#include <dm/core/result.hpp>
#include <dm/core/volume.hpp>

#include <cstddef>
#include <filesystem>
#include <span>
#include <string>
#include <string_view>

namespace dm {

/// Options for reading DICOM.
struct DicomReadOptions {
  /// SeriesInstanceUID to load when a directory holds several series; empty:
  /// the directory must hold exactly one (a file argument picks its own).
  std::string seriesUid;
  /// Largest voxel payload accepted, in bytes (checked before allocating).
  std::size_t maxBytes = Volume::kDefaultMaxBytes;
  /// Largest single file read, in bytes.
  std::size_t maxFileBytes = std::size_t{1} << 30;
};

/// Loads a DICOM series from a directory, or the series of one file (see the
/// header comment for sorting, geometry, voxel types and failures). Errors
/// name the offending file and tag; a directory without DICOM files fails
/// with NotFound. O(total file size).
/// @code
///   dm::DicomReadOptions o; o.seriesUid = "1.2.826.0.1.3680043.2.1125.1";
///   auto v = dm::readDicomSeries("/data/study", o);
///   if (v) std::printf("%d slices\n", v->dims().z());
/// @endcode
Result<Volume> readDicomSeries(const std::filesystem::path& dirOrFile, const DicomReadOptions& options = {});

/// Loads one single-frame DICOM file (Part 10 with preamble and meta header,
/// or a bare implicit/explicit VR little endian data set) from memory as an
/// nx×ny×1 Volume. ImagePositionPatient, ImageOrientationPatient and
/// PixelSpacing are required; the k step is the normal times
/// SpacingBetweenSlices (0018,0088), else SliceThickness (0018,0050), else
/// 1 mm. `sourceName` appears in errors. Never crashes or allocates beyond
/// the input size and `options.maxBytes` on bad input. O(bytes).
/// @code
///   auto bytes = dm::readFile("slice.dcm");
///   auto v = dm::parseDicomSlice(*bytes, "slice.dcm");
/// @endcode
Result<Volume> parseDicomSlice(std::span<const std::byte> bytes, std::string_view sourceName = "<memory>",
                               const DicomReadOptions& options = {});

/// Options for writing a DICOM series.
struct DicomWriteOptions {
  /// Replace the files of a non-empty directory (files named slice_*.dcm are
  /// removed first); false: a non-empty directory fails with InvalidArgument.
  bool overwrite = false;
  /// Modality (0008,0060): "CT" writes CT Image Storage, "MR" MR Image
  /// Storage, anything else Secondary Capture Image Storage.
  std::string modality = "OT";
  /// SeriesInstanceUID and StudyInstanceUID; empty: new UIDs are generated.
  std::string seriesUid;
  std::string studyUid;
  /// SeriesDescription (0008,103E), PatientName (0010,0010), PatientID (0010,0020).
  std::string seriesDescription = "DMPlatform volume";
  std::string patientName = "Anonymous";
  std::string patientId = "DM0000";
};

/// Writes `volume` as nz files `slice_00000.dcm` ... into `dir` (created if
/// missing), explicit VR little endian, each written atomically. Geometry:
/// IOP from the i and j axes of indexToWorld() (they must be perpendicular),
/// IPP = origin + k · (k axis), PixelSpacing, SliceThickness and
/// SpacingBetweenSlices = |k axis|, all in LPS mm. Voxels: uint8, uint16 and
/// int16 are written unchanged (RescaleSlope 1, Intercept 0). Other types
/// whose values are all integers in [-32768, 32767] are written as int16
/// exactly; otherwise as int16 with slope s = (max - min) / 65535 and
/// intercept b = min + 32768 s, i.e. quantised to steps of s (error at most
/// s/2). A volume whose k axis points against row × column cosine reads back
/// with k reversed (same world positions). Fails on an empty volume, sheared
/// in-plane axes, dimensions above 65535, a non-empty `dir` without
/// `overwrite`, or an I/O error (naming the file). O(voxels).
/// @code
///   if (auto s = dm::writeDicomSeries(*v, "out/series1"); !s) std::cerr << s.error() << '\n';
/// @endcode
Status writeDicomSeries(const Volume& volume, const std::filesystem::path& dir,
                        const DicomWriteOptions& options = {});

}  // namespace dm
