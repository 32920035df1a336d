// dm/io/nifti.hpp — NIfTI-1 / NIfTI-2 volumes (.nii, .nii.gz, .hdr/.img).
//
// World frame. NIfTI's world is RAS+ (x toward the subject's Right, y
// Anterior, z Superior) in millimetres. The SDK keeps those axes unchanged
// and only converts lengths to metres: Volume::indexToWorld() maps a voxel
// index (i, j, k) to RAS+ metres. (xyzt_units may declare metres or microns;
// unknown units are read as millimetres, as the standard recommends.)
//
// Orientation. When sform_code > 0 the sform rows srow_x/y/z are the affine;
// otherwise when qform_code > 0 the quaternion (b, c, d, a = sqrt(1-b²-c²-d²)),
// qfac = sign of pixdim[0] (0 counts as +1), pixdim[1..3] and qoffset_x/y/z
// are; otherwise "method 1": diag(pixdim[1..3]) with no translation.
// Negative pixdim[1..3] are used by magnitude (the sign lives in qfac).
//
// Voxels. uint8, int8, uint16, int16, uint32, int32, float32 and float64
// keep their type. int64 and uint64 are converted to float64 (exact up to
// |v| <= 2^53, rounded beyond). When scl_slope is finite, non-zero and
// (scl_slope, scl_inter) != (1, 0), values are scaled to physical units
// v = scl_slope * stored + scl_inter and the Volume becomes float32 (stored
// types of at most 16 bits and float32) or float64 (32/64-bit integers and
// float64). A zero or non-finite slope means "no scaling" (the standard and
// nibabel's reading); a non-finite intercept with a usable slope counts as 0.
// Binary (1), complex (32, 1792, 2048), RGB24 (128), RGBA32 (2304) and
// float128 (1536) fail with ErrorCode::Unsupported naming the datatype code.
//
// Dimensions. dim[0] is 1..7. dim[0] = 1 or 2 gives nz (and ny) = 1. With
// dim[0] >= 4 the file holds dim[4]·…·dim[dim[0]] 3-D volumes one after the
// other; NiftiReadOptions::volumeIndex picks one (default the first), and
// NiftiHeader::dims reports them all.
//
// Bad input (truncated or inconsistent header, bad magic, data past the end
// of the file, non-finite or singular geometry, unknown datatype, gzip data
// that ends early) fails with a dm::Error whose `where` is the file name (or
// the sourceName given to parse*, e.g. "<memory>") and whose `what` names the
// header field and its byte offset. Gzip inflation is capped at the size the
// header needs, so nothing allocates more than the header's stated size and
// no more than NiftiReadOptions::maxBytes.
//
// @code
//   auto v = dm::readNifti("head.nii.gz");
//   if (!v) { std::cerr << v.error() << '\n'; return 1; }
//   dm::Vec3 p = v->indexToWorld() * dm::Vec3(10, 20, 30);  // RAS+, metres
// @endcode
#pragma once

#include <dm/core/result.hpp>
#include <dm/core/volume.hpp>

#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <span>
#include <string>
#include <string_view>

namespace dm {

/// Options for reading NIfTI files.
struct NiftiReadOptions {
  /// Which 3-D volume of a 4-D (or higher) file to load, 0-based: the
  /// flattened index over dim[4..7]. Out of range fails with InvalidArgument.
  std::int64_t volumeIndex = 0;
  /// Largest voxel payload (and decompressed size) accepted, in bytes.
  std::size_t maxBytes = Volume::kDefaultMaxBytes;
};

/// The decoded fields of a NIfTI header that the loader uses. Geometry is
/// already converted to metres (RAS+ axes kept).
struct NiftiHeader {
  int version = 1;                    ///< 1 or 2
  bool bigEndian = false;             ///< byte order of the file
  bool singleFile = true;             ///< magic n+1/n+2 (true) or ni1/ni2 (.hdr/.img pair)
  std::array<std::int64_t, 8> dim{};  ///< dim[0] = number of dimensions, dim[1..7] sizes (unused = 1)
  std::array<double, 8> pixdim{};     ///< as stored (file units)
  int datatype = 0;                   ///< NIfTI datatype code (2 = uint8, 4 = int16, ...)
  int bitpix = 0;                     ///< bits per voxel
  std::int64_t voxOffset = 0;         ///< byte offset of the voxel data (default applied)
  double sclSlope = 0;                ///< as stored
  double sclInter = 0;                ///< as stored
  int xyztUnits = 0;                  ///< as stored
  double unitToMetres = 1e-3;         ///< spatial unit factor from xyzt_units
  int qformCode = 0;                  ///< as stored
  int sformCode = 0;                  ///< as stored
  std::array<double, 3> quatern{};    ///< quatern_b, c, d as stored
  std::array<double, 3> qoffset{};    ///< qoffset_x, y, z as stored (file units)
  std::array<std::array<double, 4>, 3> srow{};  ///< srow_x, srow_y, srow_z as stored (file units)
  std::string description;                      ///< descrip, NUL-trimmed
  /// The index-to-world affine chosen by the rules above, RAS+ metres.
  Affine3 indexToWorld = Affine3::Identity();
  /// Which rule produced indexToWorld: "sform", "qform" or "pixdim".
  const char* affineSource = "pixdim";
  /// Number of 3-D volumes (product of dim[4..dim[0]], 1 for 3-D files).
  std::int64_t volumeCount = 1;
  /// Bytes of one 3-D volume as stored.
  std::size_t volumeBytes = 0;
};

/// Decodes and validates a NIfTI-1/2 header from the first bytes of a file
/// (at least 348 or 540 bytes; gzip data is inflated, capped at 540 bytes).
/// Checks sizeof_hdr, magic, dims, datatype/bitpix, pixdim, vox_offset and
/// the chosen affine; does not check that the voxel data is present. O(1).
Result<NiftiHeader> parseNiftiHeader(std::span<const std::byte> bytes,
                                     std::string_view sourceName = "<memory>");

/// Loads a single-file NIfTI (.nii bytes, gzip detected by magic bytes 1f 8b)
/// from memory. `sourceName` appears in error messages. Fails (never crashes,
/// never allocates beyond the header's stated size) on bad input, on a
/// header of a .hdr/.img pair (use parseNiftiPair), or on an unsupported
/// datatype. O(voxels).
/// @code
///   auto bytes = dm::readFile("head.nii.gz");
///   auto v = dm::parseNifti(*bytes, "head.nii.gz");
/// @endcode
Result<Volume> parseNifti(std::span<const std::byte> bytes, std::string_view sourceName = "<memory>",
                          const NiftiReadOptions& options = {});

/// Loads a .hdr/.img pair from memory: `header` holds the .hdr bytes, `image`
/// the .img bytes (either may be gzip). vox_offset is the offset into `image`.
Result<Volume> parseNiftiPair(std::span<const std::byte> header, std::span<const std::byte> image,
                              std::string_view sourceName = "<memory>", const NiftiReadOptions& options = {});

/// Reads a NIfTI file: .nii or .nii.gz (gzip detected by content, not by
/// extension), or a .hdr/.img pair given by either name (.hdr.gz/.img.gz
/// accepted). Errors name the file. O(file size).
/// @code
///   auto v = dm::readNifti("/usr/share/mricron/templates/ch2.nii.gz");
///   if (v) std::printf("%d x %d x %d\n", v->dims().x(), v->dims().y(), v->dims().z());
/// @endcode
Result<Volume> readNifti(const std::filesystem::path& file, const NiftiReadOptions& options = {});

/// Encodes `volume` as a single-file NIfTI-1 image (352-byte header + data,
/// little-endian) with both sform and qform (codes 1, scanner anatomical) set
/// from indexToWorld() in millimetres, xyzt_units = mm, the Volume's
/// datatype and no scaling. A sheared affine is written exactly in the sform;
/// the qform then holds its nearest rotation (the standard's rule).
/// Fails on an empty volume or a dimension above 32767 (NIfTI-1's limit).
Result<std::vector<std::byte>> encodeNifti(const Volume& volume);

/// Writes `volume` as NIfTI-1 (see encodeNifti) to `file`, gzip-compressed
/// when the name ends in ".gz", atomically (temporary file, then rename).
/// @code
///   if (auto s = dm::writeNifti(*v, "out.nii.gz"); !s) std::cerr << s.error() << '\n';
/// @endcode
Status writeNifti(const Volume& volume, const std::filesystem::path& file);

}  // namespace dm
