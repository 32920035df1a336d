// dm/io/nrrd.hpp — NRRD volumes (.nrrd with attached data, .nhdr detached).
//
// Fields read (case-insensitive): the NRRD0001..NRRD0005 magic, type (every
// scalar spelling of the spec: uchar, unsigned char, uint8, uint8_t, short,
// int16, ... float, double; 64-bit integers are converted to float64), dimension,
// sizes, endian, encoding (raw, gzip/gz, ascii/text/txt, hex; bzip2 fails
// with Unsupported), space or space dimension, space directions, space
// origin, space units, spacings (used when there are no space directions),
// kinds, byte skip (-1 with raw: the data is the file's tail), line skip and
// data file / datafile (one file, relative to the header's folder; LIST and
// numbered-file formats fail with Unsupported). Key/value pairs ("key:=value")
// and comments are skipped.
//
// Geometry. Spatial axes are the axes with a space direction (or, without
// space directions, the first three axes whose kind is domain/space/???
// or unset). Up to three are supported; non-spatial axes must come after them
// (or have size 1) and index the volumes that MetaImage/NIfTI would call
// 4-D: NrrdReadOptions::volumeIndex picks one. World coordinates are
// converted to the SDK's RAS metres: "right-anterior-superior" (RAS, RAST) is
// kept, "left-posterior-superior" (LPS, LPST) negates x and y,
// "left-anterior-superior" (LAS, LAST) negates x; "scanner-xyz" and
// "3D-right-handed" (and a bare "space dimension") are taken as RAS-aligned;
// "3D-left-handed" fails with Unsupported. Lengths are in "space units"
// (mm when absent; m, cm, mm, um/micron accepted), converted to metres.
// With fewer than three spatial axes the missing index axes get unit-length
// (1 mm) directions orthogonal to the others.
//
// Bad input fails with a dm::Error naming the file (or sourceName), the
// field and its header line; gzip data is inflated only up to the size the
// header needs.
//
// @code
//   auto v = dm::readNrrd("brain.nrrd");
//   if (!v) { std::cerr << v.error() << '\n'; return 1; }
//   auto s = dm::writeNrrd(*v, "brain_copy.nhdr", {.gzip = true});
// @endcode
#pragma once

#include <dm/core/result.hpp>
#include <dm/core/volume.hpp>

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <span>
#include <string_view>
#include <vector>

namespace dm {

/// Options for reading NRRD files.
struct NrrdReadOptions {
  /// Which 3-D volume to load when the file has non-spatial axes (0-based,
  /// flattened over those axes in file order).
  std::int64_t volumeIndex = 0;
  /// Largest voxel payload (and decompressed size) accepted, in bytes.
  std::size_t maxBytes = Volume::kDefaultMaxBytes;
};

/// Options for writing NRRD files.
struct NrrdWriteOptions {
  /// Encoding "gzip" instead of "raw".
  bool gzip = false;
};

/// Loads an NRRD with attached data (.nrrd bytes). `sourceName` appears in
/// error messages. A header with a "data file" field fails with
/// InvalidArgument (use readNrrd). O(voxels).
/// @code
///   auto bytes = dm::readFile("brain.nrrd");
///   auto v = dm::parseNrrd(*bytes, "brain.nrrd");
/// @endcode
Result<Volume> parseNrrd(std::span<const std::byte> bytes, std::string_view sourceName = "<memory>",
                         const NrrdReadOptions& options = {});

/// Reads a .nrrd or .nhdr file; a detached data file is looked up relative
/// to the header's folder and must lie in an allowed root
/// (FileSystem::confine), else ErrorCode::Denied before it is opened.
/// Errors name the file. O(file size).
/// @code
///   auto v = dm::readNrrd("brain.nhdr");
///   if (v) std::printf("%d slices\n", v->dims().z());
/// @endcode
Result<Volume> readNrrd(const std::filesystem::path& file, const NrrdReadOptions& options = {});

/// Encodes `volume` as one .nrrd buffer (NRRD0004, attached data, little
/// endian, space right-anterior-superior, space directions and origin in mm
/// with 17 significant digits). Fails on an empty volume.
Result<std::vector<std::byte>> encodeNrrd(const Volume& volume, const NrrdWriteOptions& options = {});

/// Writes `volume` to `file`: ".nrrd" attaches the data, ".nhdr" writes the
/// header plus "<stem>.raw" (or "<stem>.raw.gz") next to it. Each file is
/// written atomically (data first, then header).
/// @code
///   if (auto s = dm::writeNrrd(*v, "out.nrrd"); !s) std::cerr << s.error() << '\n';
/// @endcode
Status writeNrrd(const Volume& volume, const std::filesystem::path& file,
                 const NrrdWriteOptions& options = {});

}  // namespace dm
