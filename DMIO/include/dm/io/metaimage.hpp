// dm/io/metaimage.hpp — ITK MetaImage volumes (.mha, .mhd + .raw/.zraw).
//
// Header keys read (case-insensitive): ObjectType (Image), NDims (1..4),
// DimSize, ElementType (MET_UCHAR, MET_CHAR, MET_USHORT, MET_SHORT, MET_UINT,
// MET_INT, MET_ULONG, MET_LONG (4 bytes, as in MetaIO), MET_ULONG_LONG,
// MET_LONG_LONG (converted to float64), MET_FLOAT, MET_DOUBLE),
// ElementSpacing (else ElementSize, else 1), Offset / Position / Origin,
// TransformMatrix / Rotation / Orientation, ElementNumberOfChannels (must be
// 1), BinaryData (must be True), BinaryDataByteOrderMSB / ElementByteOrderMSB,
// CompressedData (zlib or gzip stream), CompressedDataSize, HeaderSize (bytes
// to skip in a separate data file; -1: the data is the file's tail), and
// ElementDataFile, which ends the header: LOCAL (data follows the header
// line, as in .mha) or one file name relative to the header's folder. LIST
// and numbered-slice patterns fail with Unsupported. Other keys (including
// AnatomicalOrientation, which ITK also ignores for geometry) are skipped.
//
// Geometry. TransformMatrix lists the direction of index axis 0, then of axis
// 1, ... (ITK's convention: entries [i·N .. i·N+N) are axis i's direction
// cosines). MetaImage world coordinates are LPS millimetres (ITK); the SDK
// world is RAS metres, so indexToWorld = diag(-1, -1, 1) · [D·diag(spacing) |
// Offset] · 1e-3: x and y of every world point are negated. NDims = 4 holds
// DimSize[3] volumes one after another; MetaImageReadOptions::volumeIndex
// picks one. NDims 1 or 2 gives ny (and nz) = 1.
//
// Bad input fails with a dm::Error naming the file (or the sourceName) and
// the key and header line; data shorter than DimSize needs fails naming the
// byte counts; compressed data is inflated only up to the size the header
// needs.
//
// @code
//   auto v = dm::readMetaImage("liver.mhd");
//   if (!v) { std::cerr << v.error() << '\n'; return 1; }
//   auto s = dm::writeMetaImage(*v, "copy.mha", {.compress = true});
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

/// Options for reading MetaImage files.
struct MetaImageReadOptions {
  /// Which 3-D volume of an NDims = 4 image to load (0-based).
  std::int64_t volumeIndex = 0;
  /// Largest voxel payload (and decompressed size) accepted, in bytes.
  std::size_t maxBytes = Volume::kDefaultMaxBytes;
};

/// Options for writing MetaImage files.
struct MetaImageWriteOptions {
  /// Compress the voxels with zlib (CompressedData = True); .mhd data then
  /// goes to a .zraw file instead of .raw.
  bool compress = false;
};

/// Loads a MetaImage whose voxels are in the same buffer (ElementDataFile =
/// LOCAL, i.e. .mha bytes). `sourceName` appears in error messages. A header
/// naming a separate data file fails with InvalidArgument (use
/// readMetaImage). O(voxels).
/// @code
///   auto bytes = dm::readFile("ct.mha");
///   auto v = dm::parseMetaImage(*bytes, "ct.mha");
/// @endcode
Result<Volume> parseMetaImage(std::span<const std::byte> bytes, std::string_view sourceName = "<memory>",
                              const MetaImageReadOptions& options = {});

/// Reads a .mha or .mhd file; a separate data file is looked up relative to
/// the header's folder and must lie in an allowed root (FileSystem::confine:
/// the header's folder, the mounts, DM_DATA_PATH, DM_ALLOW_PATH), else
/// ErrorCode::Denied before it is opened. Errors name the header or data
/// file. O(file size).
/// @code
///   auto v = dm::readMetaImage("ct.mhd");
///   if (v) std::printf("spacing %g m\n", v->spacing().x());
/// @endcode
Result<Volume> readMetaImage(const std::filesystem::path& file, const MetaImageReadOptions& options = {});

/// Encodes `volume` as a single .mha buffer (ElementDataFile = LOCAL),
/// little-endian, geometry converted to LPS millimetres with 17 significant
/// digits. Fails on an empty volume.
Result<std::vector<std::byte>> encodeMetaImage(const Volume& volume,
                                               const MetaImageWriteOptions& options = {});

/// Writes `volume` to `file`: ".mha" gives one file with LOCAL data, ".mhd"
/// a header plus "<stem>.raw" (or ".zraw" when compressing) next to it. Each
/// file is written atomically (data first, then header).
/// @code
///   if (auto s = dm::writeMetaImage(*v, "ct.mhd"); !s) std::cerr << s.error() << '\n';
/// @endcode
Status writeMetaImage(const Volume& volume, const std::filesystem::path& file,
                      const MetaImageWriteOptions& options = {});

}  // namespace dm
