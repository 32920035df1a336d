#include <dm/io/dicom.hpp>
#include <dm/io/metaimage.hpp>
#include <dm/io/nifti.hpp>
#include <dm/io/nrrd.hpp>
#include <dm/io/vdb.hpp>
#include <dm/io/volume_io.hpp>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstring>
#include <limits>
#include <string>
#include <type_traits>

#include "format_util.hpp"

namespace dm {

namespace {

using detail::endsWith;

std::string lowerName(const std::filesystem::path& p) {
  std::string s = p.filename().string();
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

enum class Format { Nifti, MetaImage, Nrrd, Dicom, Vdb, Unknown };

// A DICOM series is a directory; one written series is asked for with a
// trailing separator ("out/series/") or by naming an existing directory.
bool namesDirectory(const std::filesystem::path& file) {
  std::error_code ec;
  return !file.empty() && (!file.has_filename() || std::filesystem::is_directory(file, ec));
}

Format formatOf(const std::filesystem::path& file) {
  if (namesDirectory(file)) return Format::Dicom;
  const std::string n = lowerName(file);
  for (const char* e : {".nii", ".nii.gz", ".hdr", ".hdr.gz", ".img", ".img.gz"})
    if (endsWith(n, e)) return Format::Nifti;
  if (endsWith(n, ".mhd") || endsWith(n, ".mha")) return Format::MetaImage;
  if (endsWith(n, ".nrrd") || endsWith(n, ".nhdr")) return Format::Nrrd;
  if (endsWith(n, ".dcm")) return Format::Dicom;
  if (endsWith(n, ".vdb")) return Format::Vdb;
  return Format::Unknown;
}

template <class T>
T loadSwapped(const std::byte* p, bool swap) {
  std::byte b[sizeof(T)];
  std::memcpy(b, p, sizeof(T));
  if (swap) std::reverse(b, b + sizeof(T));
  T v;
  std::memcpy(&v, b, sizeof(T));
  return v;
}

template <class In, class Out>
void convert(const std::byte* src, std::byte* dst, std::size_t n, bool swap, bool scaled, double slope,
             double intercept) {
  for (std::size_t i = 0; i < n; ++i) {
    const In in = loadSwapped<In>(src + i * sizeof(In), swap);
    Out out;
    if (scaled)
      out = static_cast<Out>(slope * static_cast<double>(in) + intercept);
    else
      out = static_cast<Out>(in);
    std::memcpy(dst + i * sizeof(Out), &out, sizeof(Out));
  }
}

template <class In>
void convertTo(VoxelType outType, const std::byte* src, std::byte* dst, std::size_t n, bool swap, bool scaled,
               double slope, double intercept) {
  switch (outType) {
    case VoxelType::U8:
      convert<In, std::uint8_t>(src, dst, n, swap, scaled, slope, intercept);
      break;
    case VoxelType::I8:
      convert<In, std::int8_t>(src, dst, n, swap, scaled, slope, intercept);
      break;
    case VoxelType::U16:
      convert<In, std::uint16_t>(src, dst, n, swap, scaled, slope, intercept);
      break;
    case VoxelType::I16:
      convert<In, std::int16_t>(src, dst, n, swap, scaled, slope, intercept);
      break;
    case VoxelType::U32:
      convert<In, std::uint32_t>(src, dst, n, swap, scaled, slope, intercept);
      break;
    case VoxelType::I32:
      convert<In, std::int32_t>(src, dst, n, swap, scaled, slope, intercept);
      break;
    case VoxelType::F32:
      convert<In, float>(src, dst, n, swap, scaled, slope, intercept);
      break;
    case VoxelType::F64:
      convert<In, double>(src, dst, n, swap, scaled, slope, intercept);
      break;
  }
}

}  // namespace

const char* supportedVolumeExtensions() noexcept {
  return ".nii, .nii.gz, .hdr, .hdr.gz, .img, .img.gz (NIfTI), .mhd, .mha (MetaImage), .nrrd, .nhdr (NRRD), "
         ".dcm or a directory (DICOM series), .vdb (OpenVDB)";
}

Result<Volume> readVolume(const std::filesystem::path& file, const VolumeReadOptions& options) {
  switch (formatOf(file)) {
    case Format::Nifti:
      return readNifti(file, {options.volumeIndex, options.maxBytes});
    case Format::MetaImage:
      return readMetaImage(file, {options.volumeIndex, options.maxBytes});
    case Format::Nrrd:
      return readNrrd(file, {options.volumeIndex, options.maxBytes});
    case Format::Dicom: {
      DicomReadOptions dicom;
      dicom.maxBytes = options.maxBytes;
      return readDicomSeries(file, dicom);
    }
    case Format::Vdb: {
      VdbReadOptions vdb;
      vdb.maxBytes = options.maxBytes;
      return readVdb(file, vdb);
    }
    case Format::Unknown:
      break;
  }
  return fail(ErrorCode::Unsupported, "unknown volume file extension", file.string(),
              std::string("supported: ") + supportedVolumeExtensions());
}

Status writeVolume(const Volume& volume, const std::filesystem::path& file) {
  if (namesDirectory(file)) return writeDicomSeries(volume, file);
  const std::string n = lowerName(file);
  if (endsWith(n, ".nii") || endsWith(n, ".nii.gz")) return writeNifti(volume, file);
  if (endsWith(n, ".mhd") || endsWith(n, ".mha")) return writeMetaImage(volume, file);
  if (endsWith(n, ".nrrd") || endsWith(n, ".nhdr")) return writeNrrd(volume, file);
  if (endsWith(n, ".vdb")) return writeVdb(volume, file);
  return fail(ErrorCode::Unsupported, "unknown volume file extension for writing", file.string(),
              "supported: .nii, .nii.gz, .mhd, .mha, .nrrd, .nhdr, .vdb, or a directory ending in '/' "
              "(DICOM series)");
}

std::size_t rawElementBytes(RawElement e) noexcept {
  switch (e) {
    case RawElement::U8:
    case RawElement::I8:
      return 1;
    case RawElement::U16:
    case RawElement::I16:
      return 2;
    case RawElement::U32:
    case RawElement::I32:
    case RawElement::F32:
      return 4;
    case RawElement::U64:
    case RawElement::I64:
    case RawElement::F64:
      return 8;
  }
  return 1;
}

RawElement rawElementOf(VoxelType t) noexcept {
  switch (t) {
    case VoxelType::U8:
      return RawElement::U8;
    case VoxelType::I8:
      return RawElement::I8;
    case VoxelType::U16:
      return RawElement::U16;
    case VoxelType::I16:
      return RawElement::I16;
    case VoxelType::U32:
      return RawElement::U32;
    case VoxelType::I32:
      return RawElement::I32;
    case VoxelType::F32:
      return RawElement::F32;
    case VoxelType::F64:
      return RawElement::F64;
  }
  return RawElement::U8;
}

Result<Volume> decodeRawVolume(std::span<const std::byte> raw, const Vec3i& dims,
                               const RawVoxelFormat& format, const Affine3& indexToWorld,
                               std::string_view sourceName, std::size_t maxBytes) {
  const std::string source(sourceName);
  if ((dims.array() <= 0).any())
    return fail(ErrorCode::InvalidArgument,
                "dims " + std::to_string(dims.x()) + "x" + std::to_string(dims.y()) + "x" +
                    std::to_string(dims.z()) + " must all be positive",
                source);
  if (!std::isfinite(format.slope) || !std::isfinite(format.intercept) || format.slope == 0)
    return fail(ErrorCode::InvalidArgument,
                "intensity scaling slope must be finite and non-zero, intercept finite", source);
  const std::size_t eb = rawElementBytes(format.element);
  std::size_t count = 1;
  for (int a = 0; a < 3; ++a) {
    const auto d = static_cast<std::size_t>(dims[a]);
    if (count > std::numeric_limits<std::size_t>::max() / d / 8)
      return fail(ErrorCode::InvalidArgument, "voxel count overflows", source);
    count *= d;
  }
  if (raw.size() / eb < count)
    return fail(ErrorCode::Parse,
                "voxel data has " + std::to_string(raw.size()) + " bytes but " + std::to_string(dims.x()) +
                    "x" + std::to_string(dims.y()) + "x" + std::to_string(dims.z()) + " voxels of " +
                    std::to_string(eb) + " bytes need " + std::to_string(count * eb),
                source, "the data is truncated, or the header's sizes/type are wrong");

  const bool scaled = !(format.slope == 1.0 && format.intercept == 0.0);
  VoxelType out;
  switch (format.element) {
    case RawElement::U8:
      out = VoxelType::U8;
      break;
    case RawElement::I8:
      out = VoxelType::I8;
      break;
    case RawElement::U16:
      out = VoxelType::U16;
      break;
    case RawElement::I16:
      out = VoxelType::I16;
      break;
    case RawElement::U32:
      out = VoxelType::U32;
      break;
    case RawElement::I32:
      out = VoxelType::I32;
      break;
    case RawElement::F32:
      out = VoxelType::F32;
      break;
    default:
      out = VoxelType::F64;
      break;  // F64, and 64-bit integers
  }
  if (scaled) out = (eb <= 2 || format.element == RawElement::F32) ? VoxelType::F32 : VoxelType::F64;

  auto v = Volume::create(dims, out, indexToWorld, maxBytes);
  if (!v) {
    Error e = std::move(v).error();
    e.where = source;
    return e;
  }
  const bool swap = format.byteOrder != std::endian::native && eb > 1;
  std::byte* dst = v->bytes();
  const std::byte* src = raw.data();
  if (!scaled && !swap && voxelBytes(out) == eb && rawElementOf(out) == format.element) {
    std::memcpy(dst, src, count * eb);
    return v;
  }
  switch (format.element) {
    case RawElement::U8:
      convertTo<std::uint8_t>(out, src, dst, count, swap, scaled, format.slope, format.intercept);
      break;
    case RawElement::I8:
      convertTo<std::int8_t>(out, src, dst, count, swap, scaled, format.slope, format.intercept);
      break;
    case RawElement::U16:
      convertTo<std::uint16_t>(out, src, dst, count, swap, scaled, format.slope, format.intercept);
      break;
    case RawElement::I16:
      convertTo<std::int16_t>(out, src, dst, count, swap, scaled, format.slope, format.intercept);
      break;
    case RawElement::U32:
      convertTo<std::uint32_t>(out, src, dst, count, swap, scaled, format.slope, format.intercept);
      break;
    case RawElement::I32:
      convertTo<std::int32_t>(out, src, dst, count, swap, scaled, format.slope, format.intercept);
      break;
    case RawElement::U64:
      convertTo<std::uint64_t>(out, src, dst, count, swap, scaled, format.slope, format.intercept);
      break;
    case RawElement::I64:
      convertTo<std::int64_t>(out, src, dst, count, swap, scaled, format.slope, format.intercept);
      break;
    case RawElement::F32:
      convertTo<float>(out, src, dst, count, swap, scaled, format.slope, format.intercept);
      break;
    case RawElement::F64:
      convertTo<double>(out, src, dst, count, swap, scaled, format.slope, format.intercept);
      break;
  }
  return v;
}

}  // namespace dm
