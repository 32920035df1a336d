// dm/io/volume_io.hpp — one entry point for every volume format, and the
// raw-voxel decoder the format readers share.
//
// readVolume() picks the reader from the file name: .nii, .nii.gz, .hdr,
// .hdr.gz, .img, .img.gz (NIfTI, see nifti.hpp), .mhd, .mha (MetaImage, see
// metaimage.hpp), .nrrd, .nhdr (NRRD, see nrrd.hpp), a directory or a .dcm
// file (DICOM series, see dicom.hpp), .vdb (OpenVDB, see vdb.hpp);
// case-insensitive. Every reader returns a dm::Volume whose indexToWorld()
// maps voxel indices to the SDK world frame: RAS+ axes (x Right, y Anterior,
// z Superior of the patient), in metres. LPS formats (DICOM, MetaImage, LPS
// NRRD) are converted by negating x and y.
//
// @code
//   auto v = dm::readVolume(dm::FileSystem::global().resolve("mricron:ch2.nii.gz").value());
//   if (!v) { std::cerr << v.error() << '\n'; return 1; }
//   dm::Vec3 p = v->indexToWorld() * dm::Vec3(90, 108, 90);  // RAS+, m
// @endcode
#pragma once

#include <dm/core/result.hpp>
#include <dm/core/volume.hpp>

#include <bit>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <span>
#include <string_view>

namespace dm {

/// Options shared by all volume readers.
struct VolumeReadOptions {
  /// Which 3-D volume of a 4-D file to load (0-based; flattened over the
  /// dimensions beyond the third).
  std::int64_t volumeIndex = 0;
  /// Largest voxel payload accepted, in bytes (also caps decompression).
  std::size_t maxBytes = Volume::kDefaultMaxBytes;
};

/// The extensions readVolume() understands, as one comma-separated string
/// (".nii, .nii.gz, .hdr, ..."), for messages and file dialogs.
const char* supportedVolumeExtensions() noexcept;

/// Reads a volume, choosing the format by extension (see the header
/// comment). Fails with Unsupported listing the supported extensions for an
/// unknown one, otherwise like the format's reader.
Result<Volume> readVolume(const std::filesystem::path& file, const VolumeReadOptions& options = {});

/// Writes a volume, choosing the format by extension: .nii/.nii.gz (NIfTI-1),
/// .mhd/.mha (MetaImage), .nrrd/.nhdr (NRRD), .vdb (OpenVDB, sparse), or a
/// DICOM series when `file` ends in a separator or names an existing
/// directory. Atomic per file written.
/// @code
///   if (auto s = dm::writeVolume(*v, "copy.nrrd"); !s) std::cerr << s.error() << '\n';
/// @endcode
Status writeVolume(const Volume& volume, const std::filesystem::path& file);

/// Scalar element of a raw voxel stream.
enum class RawElement : std::uint8_t { U8, I8, U16, I16, U32, I32, U64, I64, F32, F64 };

/// Bytes of one element of `e`.
std::size_t rawElementBytes(RawElement e) noexcept;

/// How raw voxel bytes are encoded.
struct RawVoxelFormat {
  RawElement element = RawElement::U8;
  std::endian byteOrder = std::endian::little;
  /// Physical value = slope · stored + intercept; (1, 0) keeps the stored type.
  double slope = 1.0;
  double intercept = 0.0;
};

/// Decodes `dims` voxels (x fastest) from `raw` into a Volume with
/// `indexToWorld` (metres). Types map one to one, except U64/I64 which become
/// F64 (exact up to 2^53). With scaling other than (1, 0) the Volume is F32
/// for elements of at most 16 bits and F32, F64 otherwise. Extra trailing
/// bytes are ignored. Fails, naming `sourceName`, when `raw` is shorter than
/// the voxels need, when the output exceeds `maxBytes`, or on a bad affine.
/// O(voxels).
/// @code
///   auto v = dm::decodeRawVolume(bytes, {256, 256, 120}, {dm::RawElement::I16}, affine, "ct.raw");
/// @endcode
Result<Volume> decodeRawVolume(std::span<const std::byte> raw, const Vec3i& dims,
                               const RawVoxelFormat& format, const Affine3& indexToWorld,
                               std::string_view sourceName, std::size_t maxBytes = Volume::kDefaultMaxBytes);

/// The RawElement that stores `t` unchanged (for writers).
RawElement rawElementOf(VoxelType t) noexcept;

}  // namespace dm
