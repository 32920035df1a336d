#include <dm/core/filesystem.hpp>
#include <dm/io/nifti.hpp>
#include <dm/io/volume_io.hpp>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <vector>

#include "format_util.hpp"
#include "gzip.hpp"

namespace dm {

namespace {

using detail::endsWith;
using detail::isSingular;
using detail::lower;

constexpr std::size_t kSizeN1 = 348;
constexpr std::size_t kSizeN2 = 540;
constexpr std::int64_t kDefaultOffsetN1 = 352;
constexpr std::int64_t kDefaultOffsetN2 = 544;

constexpr std::uint32_t byteSwap32(std::uint32_t v) {
  return (v >> 24) | ((v >> 8) & 0xff00u) | ((v << 8) & 0xff0000u) | (v << 24);
}

// Loads a T stored at p in the file's byte order.
template <class T>
T loadAs(const std::byte* p, bool swap) {
  std::byte b[sizeof(T)];
  std::memcpy(b, p, sizeof(T));
  if (swap) std::reverse(b, b + sizeof(T));
  T v;
  std::memcpy(&v, b, sizeof(T));
  return v;
}

// Stores v little-endian at p.
template <class T>
void storeLE(std::byte* p, T v) {
  std::memcpy(p, &v, sizeof(T));
  if constexpr (std::endian::native == std::endian::big) std::reverse(p, p + sizeof(T));
}

// Byte offsets of the fields we use, per version.
struct Layout {
  std::size_t size;
  bool wide;  // NIfTI-2: 64-bit ints and doubles
  std::size_t magic, magicLen;
  std::size_t dim, datatype, bitpix, pixdim, voxOffset, sclSlope, sclInter, xyztUnits;
  std::size_t qformCode, sformCode, quatern, qoffset, srow, descrip;
};
constexpr Layout kN1{kSizeN1, false, 344, 4,   40,  70,  72,  76,  108,
                     112,     116,   123, 252, 254, 256, 268, 280, 148};
constexpr Layout kN2{kSizeN2, true, 4, 8, 16, 12, 14, 104, 168, 176, 184, 500, 344, 348, 352, 376, 400, 240};

struct Datatype {
  int code;
  int bitpix;
  const char* name;
  bool supported;
  RawElement element;
};
constexpr Datatype kDatatypes[] = {
    {1, 1, "binary", false, RawElement::U8},          {2, 8, "uint8", true, RawElement::U8},
    {4, 16, "int16", true, RawElement::I16},          {8, 32, "int32", true, RawElement::I32},
    {16, 32, "float32", true, RawElement::F32},       {32, 64, "complex64", false, RawElement::U8},
    {64, 64, "float64", true, RawElement::F64},       {128, 24, "RGB24", false, RawElement::U8},
    {256, 8, "int8", true, RawElement::I8},           {512, 16, "uint16", true, RawElement::U16},
    {768, 32, "uint32", true, RawElement::U32},       {1024, 64, "int64", true, RawElement::I64},
    {1280, 64, "uint64", true, RawElement::U64},      {1536, 128, "float128", false, RawElement::U8},
    {1792, 128, "complex128", false, RawElement::U8}, {2048, 256, "complex256", false, RawElement::U8},
    {2304, 32, "RGBA32", false, RawElement::U8},
};

const Datatype* findDatatype(int code) {
  for (const Datatype& d : kDatatypes)
    if (d.code == code) return &d;
  return nullptr;
}

int datatypeCodeOf(VoxelType t) {
  switch (t) {
    case VoxelType::U8:
      return 2;
    case VoxelType::I8:
      return 256;
    case VoxelType::U16:
      return 512;
    case VoxelType::I16:
      return 4;
    case VoxelType::U32:
      return 768;
    case VoxelType::I32:
      return 8;
    case VoxelType::F32:
      return 16;
    case VoxelType::F64:
      return 64;
  }
  return 0;
}

std::string field(const char* name, std::size_t byte) {
  return std::string(name) + " (header byte " + std::to_string(byte) + ")";
}

std::string num(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.9g", v);
  return buf;
}

std::string printable(const std::byte* p, std::size_t n) {
  return shownText(std::string_view(reinterpret_cast<const char*>(p), n), n);
}

Error parseError(std::string_view source, std::string what, std::string hint = {}) {
  return fail(ErrorCode::Parse, std::move(what), std::string(source), std::move(hint));
}

struct NiftiHeaderReader {
  std::span<const std::byte> bytes;
  const Layout& lay;
  bool swap;

  template <class T>
  T at(std::size_t off) const {
    return loadAs<T>(bytes.data() + off, swap);
  }
  // An integer field that is int16 in NIfTI-1 and int32/int64 in NIfTI-2.
  std::int64_t intField(std::size_t off, bool is64) const {
    if (!lay.wide) return at<std::int16_t>(off);
    return is64 ? at<std::int64_t>(off) : at<std::int32_t>(off);
  }
  double realField(std::size_t off) const { return lay.wide ? at<double>(off) : at<float>(off); }
  std::size_t realSize() const { return lay.wide ? 8 : 4; }
};

}  // namespace

Result<NiftiHeader> parseNiftiHeader(std::span<const std::byte> bytes, std::string_view source) {
  std::vector<std::byte> inflated;
  if (detail::isGzip(bytes)) {
    auto r = detail::inflate(bytes, kSizeN2, source);
    if (!r) return std::move(r).error();
    inflated = std::move(*r);
    bytes = inflated;
  }
  if (bytes.size() < 4)
    return parseError(source,
                      "truncated header: " + std::to_string(bytes.size()) +
                          " bytes, a NIfTI header needs 348 (NIfTI-1) or 540 (NIfTI-2)",
                      "the file is empty or cut short");

  NiftiHeader h;
  const auto sizeofHdr = loadAs<std::uint32_t>(bytes.data(), std::endian::native == std::endian::big);
  const Layout* lay = nullptr;
  bool fileBig = false;
  if (sizeofHdr == kSizeN1)
    lay = &kN1;
  else if (sizeofHdr == kSizeN2)
    lay = &kN2;
  else if (sizeofHdr == byteSwap32(kSizeN1))
    lay = &kN1, fileBig = true;
  else if (sizeofHdr == byteSwap32(kSizeN2))
    lay = &kN2, fileBig = true;
  else
    return parseError(source,
                      field("sizeof_hdr", 0) + " is " + std::to_string(static_cast<std::int32_t>(sizeofHdr)) +
                          "; expected 348 (NIfTI-1) or 540 (NIfTI-2) in either byte order",
                      "this is not a NIfTI file");
  h.version = lay->wide ? 2 : 1;
  h.bigEndian = fileBig;
  if (bytes.size() < lay->size)
    return parseError(source,
                      "truncated header: " + std::to_string(bytes.size()) + " bytes, but sizeof_hdr says " +
                          std::to_string(lay->size),
                      "the file is cut short");

  const NiftiHeaderReader r{bytes, *lay, fileBig != (std::endian::native == std::endian::big)};

  // magic
  const std::byte* mp = bytes.data() + lay->magic;
  const char* m = reinterpret_cast<const char*>(mp);
  const char suffix = lay->wide ? '2' : '1';
  const bool single = m[0] == 'n' && m[1] == '+' && m[2] == suffix && m[3] == '\0';
  const bool pair = m[0] == 'n' && m[1] == 'i' && m[2] == suffix && m[3] == '\0';
  if ((!single && !pair) || (lay->wide && std::memcmp(m + 4, "\r\n\032\n", 4) != 0))
    return parseError(source,
                      field("magic", lay->magic) + " is \"" + printable(mp, lay->magicLen) +
                          "\"; expected \"n+" + suffix + "\" or \"ni" + suffix + "\"" +
                          (lay->wide ? " followed by \\r\\n\\x1a\\n" : ""),
                      lay->wide ? "the file is corrupt (line endings converted?)"
                                : "Analyze 7.5 files without NIfTI magic are not supported");
  h.singleFile = single;

  // dim
  const std::size_t dimStride = lay->wide ? 8 : 2;
  for (int i = 0; i < 8; ++i) h.dim[i] = r.intField(lay->dim + dimStride * i, true);
  if (h.dim[0] < 1 || h.dim[0] > 7)
    return parseError(source,
                      field("dim[0]", lay->dim) + " is " + std::to_string(h.dim[0]) + "; must be 1..7");
  for (int i = 1; i < 8; ++i) {
    if (i > h.dim[0]) {
      h.dim[i] = 1;
      continue;
    }
    if (h.dim[i] < 1)
      return parseError(source, field(("dim[" + std::to_string(i) + "]").c_str(), lay->dim + dimStride * i) +
                                    " is " + std::to_string(h.dim[i]) + "; sizes must be >= 1");
    if (i <= 3 && h.dim[i] > std::numeric_limits<int>::max())
      return fail(ErrorCode::Unsupported,
                  field(("dim[" + std::to_string(i) + "]").c_str(), lay->dim + dimStride * i) + " is " +
                      std::to_string(h.dim[i]) + "; at most " +
                      std::to_string(std::numeric_limits<int>::max()) + " voxels per axis are supported",
                  std::string(source));
  }

  // datatype / bitpix
  h.datatype = static_cast<int>(r.at<std::int16_t>(lay->datatype));
  h.bitpix = static_cast<int>(r.at<std::int16_t>(lay->bitpix));
  const Datatype* dt = findDatatype(h.datatype);
  if (!dt)
    return parseError(source, field("datatype", lay->datatype) + " is " + std::to_string(h.datatype) +
                                  ", which is not a NIfTI datatype code");
  if (!dt->supported)
    return fail(ErrorCode::Unsupported,
                field("datatype", lay->datatype) + " is " + std::to_string(h.datatype) + " (" + dt->name +
                    "), which volumes do not support",
                std::string(source),
                "convert to a scalar type (uint8, int16, float32, ...), e.g. with fslmaths or nibabel");
  if (h.bitpix != dt->bitpix)
    return parseError(source, field("bitpix", lay->bitpix) + " is " + std::to_string(h.bitpix) +
                                  " but datatype " + std::to_string(h.datatype) + " (" + dt->name + ") has " +
                                  std::to_string(dt->bitpix) + " bits per voxel");

  // Sizes: one 3-D volume, and the number of volumes; guard every product.
  constexpr std::uint64_t kHuge = std::uint64_t{1} << 62;
  std::uint64_t voxels = 1;
  for (int i = 1; i <= 3; ++i) {
    voxels *= static_cast<std::uint64_t>(h.dim[i]);
    if (voxels > kHuge / 8) return parseError(source, field("dim", lay->dim) + ": voxel count overflows");
  }
  h.volumeBytes = static_cast<std::size_t>(voxels * static_cast<std::uint64_t>(dt->bitpix / 8));
  std::uint64_t volumes = 1;
  for (int i = 4; i <= 7; ++i) {
    const auto d = static_cast<std::uint64_t>(h.dim[i]);
    if (volumes > kHuge / d) return parseError(source, field("dim", lay->dim) + ": volume count overflows");
    volumes *= d;
  }
  h.volumeCount = static_cast<std::int64_t>(volumes);

  // pixdim, units
  for (int i = 0; i < 8; ++i) h.pixdim[i] = r.realField(lay->pixdim + r.realSize() * i);
  h.xyztUnits = lay->wide ? static_cast<int>(r.at<std::int32_t>(lay->xyztUnits))
                          : static_cast<int>(r.at<std::uint8_t>(lay->xyztUnits));
  switch (h.xyztUnits & 0x07) {
    case 1:
      h.unitToMetres = 1.0;
      break;  // NIFTI_UNITS_METER
    case 3:
      h.unitToMetres = 1e-6;
      break;  // NIFTI_UNITS_MICRON
    default:
      h.unitToMetres = 1e-3;
      break;  // NIFTI_UNITS_MM, or unknown: mm
  }

  // vox_offset
  if (lay->wide) {
    h.voxOffset = r.at<std::int64_t>(lay->voxOffset);
  } else {
    const float f = r.at<float>(lay->voxOffset);
    if (!std::isfinite(f) || f < 0 || f != std::floor(f) || f > 9.0e15f)
      return parseError(source, field("vox_offset", lay->voxOffset) + " is " + num(f) +
                                    "; must be a non-negative whole number of bytes");
    h.voxOffset = static_cast<std::int64_t>(f);
  }
  if (h.voxOffset < 0 || static_cast<std::uint64_t>(h.voxOffset) > kHuge)
    return parseError(source, field("vox_offset", lay->voxOffset) + " is " + std::to_string(h.voxOffset) +
                                  "; out of range");
  if (h.singleFile) {
    if (h.voxOffset == 0) h.voxOffset = lay->wide ? kDefaultOffsetN2 : kDefaultOffsetN1;
    if (h.voxOffset < static_cast<std::int64_t>(lay->size))
      return parseError(source, field("vox_offset", lay->voxOffset) + " is " + std::to_string(h.voxOffset) +
                                    ", inside the " + std::to_string(lay->size) + "-byte header");
  }

  // scaling
  h.sclSlope = r.realField(lay->sclSlope);
  h.sclInter = r.realField(lay->sclInter);

  // orientation fields
  h.qformCode = static_cast<int>(r.intField(lay->qformCode, false));
  h.sformCode = static_cast<int>(r.intField(lay->sformCode, false));
  for (int i = 0; i < 3; ++i) {
    h.quatern[i] = r.realField(lay->quatern + r.realSize() * i);
    h.qoffset[i] = r.realField(lay->qoffset + r.realSize() * i);
    for (int c = 0; c < 4; ++c) h.srow[i][c] = r.realField(lay->srow + r.realSize() * (4 * i + c));
  }
  {
    const char* d = reinterpret_cast<const char*>(bytes.data() + lay->descrip);
    h.description.assign(d, strnlen(d, 80));
  }

  // Affine in file units first; scaled to metres at the end.
  Affine3 a = Affine3::Identity();
  if (h.sformCode > 0) {
    static const char* const rowNames[3] = {"srow_x", "srow_y", "srow_z"};
    for (int i = 0; i < 3; ++i) {
      const std::size_t off = lay->srow + r.realSize() * 4 * i;
      for (int c = 0; c < 4; ++c)
        if (!std::isfinite(h.srow[i][c]))
          return parseError(source, field(rowNames[i], off) + " has a non-finite entry " + num(h.srow[i][c]),
                            "fix the sform, or set sform_code to 0 to use the qform");
      for (int c = 0; c < 3; ++c) a.linear()(i, c) = h.srow[i][c];
      a.translation()[i] = h.srow[i][3];
    }
    if (isSingular(a.linear()))
      return parseError(
          source, "the sform " + field("srow_x/y/z", lay->srow) + " is singular (zero or collinear columns)",
          "fix the sform, or set sform_code to 0 to use the qform");
    h.affineSource = "sform";
  } else {
    // pixdim[1..3] are needed by both remaining methods. Axes beyond dim[0]
    // are 1 voxel thick; a missing (0 or non-finite) spacing there counts as 1.
    Vec3 spacing;
    for (int i = 1; i <= 3; ++i) {
      const double p = h.pixdim[i];
      const bool used = i <= h.dim[0];
      if (!std::isfinite(p) || p == 0) {
        if (used)
          return parseError(
              source, field(("pixdim[" + std::to_string(i) + "]").c_str(), lay->pixdim + r.realSize() * i) +
                          " is " + num(p) + "; voxel spacing must be finite and non-zero");
        spacing[i - 1] = 1.0;
      } else {
        spacing[i - 1] = std::abs(p);
      }
    }
    if (h.qformCode > 0) {
      for (int i = 0; i < 3; ++i) {
        if (!std::isfinite(h.quatern[i]))
          return parseError(
              source, field("quatern_b/c/d", lay->quatern) + " has a non-finite entry " + num(h.quatern[i]));
        if (!std::isfinite(h.qoffset[i]))
          return parseError(
              source, field("qoffset_x/y/z", lay->qoffset) + " has a non-finite entry " + num(h.qoffset[i]));
      }
      double b = h.quatern[0], c = h.quatern[1], d = h.quatern[2];
      const double n2 = b * b + c * c + d * d;
      // Stored as floats, b²+c²+d² may exceed 1 by rounding; more is an error.
      if (n2 > 1.0 + 1e-4)
        return parseError(source, field("quatern_b/c/d", lay->quatern) + " have b²+c²+d² = " + num(n2) +
                                      " > 1; not a unit quaternion");
      double qa = 0;
      if (1.0 - n2 > 1e-7) {
        qa = std::sqrt(1.0 - n2);
      } else if (n2 > 0) {
        // A 180° rotation: a = 0; renormalise (b, c, d) as nifti1_io does.
        const double s = 1.0 / std::sqrt(n2);
        b *= s, c *= s, d *= s;
      } else {
        qa = 1;
      }
      Mat3 rot;
      rot << qa * qa + b * b - c * c - d * d, 2 * (b * c - qa * d), 2 * (b * d + qa * c),  //
          2 * (b * c + qa * d), qa * qa + c * c - b * b - d * d, 2 * (c * d - qa * b),     //
          2 * (b * d - qa * c), 2 * (c * d + qa * b), qa * qa + d * d - c * c - b * b;
      const double qfac = h.pixdim[0] < 0 ? -1.0 : 1.0;
      a.linear() = rot * Vec3(spacing.x(), spacing.y(), qfac * spacing.z()).asDiagonal();
      a.translation() = Vec3(h.qoffset[0], h.qoffset[1], h.qoffset[2]);
      h.affineSource = "qform";
    } else {
      a.linear() = spacing.asDiagonal();
      h.affineSource = "pixdim";
    }
  }
  a.linear() *= h.unitToMetres;
  a.translation() *= h.unitToMetres;
  if (!a.matrix().allFinite() || isSingular(a.linear()))
    return parseError(source, std::string("the ") + h.affineSource +
                                  " affine is not finite or singular after unit conversion");
  h.indexToWorld = a;
  return h;
}

namespace {

Result<Volume> decodeVolume(const NiftiHeader& h, std::span<const std::byte> raw, std::string_view source,
                            const NiftiReadOptions& options) {
  const Datatype* dt = findDatatype(h.datatype);
  DM_ASSERT(dt && dt->supported, "parseNiftiHeader validated the datatype");
  RawVoxelFormat fmt;
  fmt.element = dt->element;
  fmt.byteOrder = h.bigEndian ? std::endian::big : std::endian::little;
  // scl_slope = 0 or non-finite means "unscaled" (NIfTI-1 standard, nibabel).
  if (std::isfinite(h.sclSlope) && h.sclSlope != 0) {
    fmt.slope = h.sclSlope;
    fmt.intercept = std::isfinite(h.sclInter) ? h.sclInter : 0.0;
  }
  const Vec3i dims(static_cast<int>(h.dim[1]), static_cast<int>(h.dim[2]), static_cast<int>(h.dim[3]));
  return decodeRawVolume(raw, dims, fmt, h.indexToWorld, source, options.maxBytes);
}

// Checks the options against the header; returns the data's byte offset
// within the data stream (vox_offset + volumeIndex · volumeBytes).
Result<std::uint64_t> dataStart(const NiftiHeader& h, std::string_view source,
                                const NiftiReadOptions& options) {
  if (options.volumeIndex < 0 || options.volumeIndex >= h.volumeCount)
    return fail(ErrorCode::InvalidArgument,
                "volumeIndex " + std::to_string(options.volumeIndex) + " is out of range: the file holds " +
                    std::to_string(h.volumeCount) + " volume(s)",
                std::string(source));
  const auto index = static_cast<std::uint64_t>(options.volumeIndex);
  // volumeBytes <= maxBytes < 2^63 and index < 2^62; guard the product anyway.
  if (index != 0 && h.volumeBytes > (std::uint64_t{1} << 62) / index)
    return parseError(source, "data offset of volume " + std::to_string(index) + " overflows");
  return static_cast<std::uint64_t>(h.voxOffset) + index * h.volumeBytes;
}

Status checkLimit(const NiftiHeader& h, std::string_view source, const NiftiReadOptions& options) {
  if (h.volumeBytes <= options.maxBytes) return ok();
  return detail::volumeOverBudget(
      std::to_string(h.dim[1]) + "x" + std::to_string(h.dim[2]) + "x" + std::to_string(h.dim[3]) +
          " voxels of " + std::to_string(h.bitpix / 8) + " bytes",
      h.volumeBytes, options.maxBytes, std::string(source), "NiftiReadOptions::maxBytes");
}

Error pastEnd(const NiftiHeader& h, std::string_view source, std::uint64_t start, std::uint64_t have,
              bool decompressed) {
  return parseError(
      source,
      std::string("voxel data runs past the end of the ") + (decompressed ? "decompressed " : "") +
          "file: vox_offset " + std::to_string(h.voxOffset) + " + " + std::to_string(h.dim[1]) + "x" +
          std::to_string(h.dim[2]) + "x" + std::to_string(h.dim[3]) + " voxels x " +
          std::to_string(h.bitpix / 8) + " bytes needs " + std::to_string(start + h.volumeBytes) +
          " bytes, the " + (decompressed ? "decompressed data has " : "file has ") + std::to_string(have),
      "the file is truncated, or dim/datatype/vox_offset are wrong");
}

// Loads the voxels from a stream holding them at `start` (the whole .nii, or
// the .img of a pair), gzip or not.
Result<Volume> loadFromStream(const NiftiHeader& h, std::span<const std::byte> stream,
                              std::string_view source, const NiftiReadOptions& options) {
  auto start = dataStart(h, source, options);
  if (!start) return std::move(start).error();
  if (detail::isGzip(stream)) {
    // Inflate only what the header says is needed, so a gzip bomb stops there.
    if (auto s = checkLimit(h, source, options); !s) return std::move(s).error();
    // Earlier volumes of a 4-D file are decompressed and discarded, not kept.
    auto data = detail::inflate(stream, h.volumeBytes, source, static_cast<std::size_t>(*start));
    if (!data) return std::move(data).error();
    if (data->size() < h.volumeBytes) return pastEnd(h, source, *start, *start + data->size(), true);
    return decodeVolume(h, *data, source, options);
  }
  if (*start > stream.size() || stream.size() - *start < h.volumeBytes)
    return pastEnd(h, source, *start, stream.size(), false);
  if (auto s = checkLimit(h, source, options); !s) return std::move(s).error();
  return decodeVolume(h, stream.subspan(static_cast<std::size_t>(*start), h.volumeBytes), source, options);
}

}  // namespace

Result<Volume> parseNifti(std::span<const std::byte> bytes, std::string_view source,
                          const NiftiReadOptions& options) {
  auto h = parseNiftiHeader(bytes, source);
  if (!h) return std::move(h).error();
  if (!h->singleFile)
    return fail(ErrorCode::InvalidArgument,
                "this is the header of a .hdr/.img pair (magic ni" + std::to_string(h->version) +
                    "); its voxels are in the .img file",
                std::string(source), "read the .hdr file with readNifti, or use parseNiftiPair");
  return loadFromStream(*h, bytes, source, options);
}

Result<Volume> parseNiftiPair(std::span<const std::byte> header, std::span<const std::byte> image,
                              std::string_view source, const NiftiReadOptions& options) {
  auto h = parseNiftiHeader(header, source);
  if (!h) return std::move(h).error();
  if (h->singleFile)
    return fail(ErrorCode::InvalidArgument,
                "the header has single-file magic n+" + std::to_string(h->version) + ", not a .hdr/.img pair",
                std::string(source), "read it as a .nii file");
  return loadFromStream(*h, image, source, options);
}

namespace {

// For a .hdr/.img name, the partner's candidates (same case style first).
std::vector<std::filesystem::path> partnerCandidates(const std::filesystem::path& file, bool isHeader) {
  const std::string name = file.string();
  const std::string low = lower(name);
  const bool gz = endsWith(low, ".gz");
  const std::string stem = name.substr(0, name.size() - (gz ? 7 : 4));
  const bool upper = name.size() >= 3 && std::isupper(static_cast<unsigned char>(name[stem.size() + 1]));
  std::string ext = isHeader ? "img" : "hdr";
  if (upper) ext = isHeader ? "IMG" : "HDR";
  return {stem + "." + ext, stem + "." + ext + ".gz", stem + "." + ext + ".GZ"};
}

}  // namespace

namespace {

// Reads bytes [offset, offset + size) of a file, or fewer at its end.
Result<std::vector<std::byte>> readRange(const std::filesystem::path& file, std::uint64_t offset,
                                         std::size_t size) {
  std::FILE* f = std::fopen(file.c_str(), "rb");
  if (!f)
    return fail(ErrorCode::NotFound, std::string("cannot open: ") + std::strerror(errno), file.string());
  std::vector<std::byte> out;
  if (offset > static_cast<std::uint64_t>(std::numeric_limits<off_t>::max()) ||
      ::fseeko(f, static_cast<off_t>(offset), SEEK_SET) != 0) {
    std::fclose(f);
    return out;  // past the end: the caller reports the missing bytes
  }
  out.resize(size);
  const std::size_t n = std::fread(out.data(), 1, size, f);
  const bool bad = std::ferror(f) != 0;
  std::fclose(f);
  if (bad) return fail(ErrorCode::Io, "read failed at byte " + std::to_string(offset + n), file.string());
  out.resize(n);
  return out;
}

// Loads the voxels of `h` from `dataFile` (the .nii itself or the .img).
Result<Volume> loadFromFile(const NiftiHeader& h, const std::filesystem::path& dataFile,
                            const NiftiReadOptions& options) {
  const std::string source = dataFile.string();
  auto head = readRange(dataFile, 0, 2);
  if (!head) return std::move(head).error();
  if (detail::isGzip(*head)) {
    auto bytes = readFile(dataFile, std::numeric_limits<std::size_t>::max());
    if (!bytes) return std::move(bytes).error();
    return loadFromStream(h, *bytes, source, options);
  }
  // Plain data: read only the selected volume, after checking it is there.
  auto start = dataStart(h, source, options);
  if (!start) return std::move(start).error();
  std::error_code ec;
  const std::uint64_t fileSize = std::filesystem::file_size(dataFile, ec);
  if (ec) return fail(ErrorCode::Io, "cannot stat: " + ec.message(), source);
  if (*start > fileSize || fileSize - *start < h.volumeBytes)
    return pastEnd(h, source, *start, fileSize, false);
  if (auto s = checkLimit(h, source, options); !s) return std::move(s).error();
  auto raw = readRange(dataFile, *start, h.volumeBytes);
  if (!raw) return std::move(raw).error();
  if (raw->size() < h.volumeBytes) return pastEnd(h, source, *start, *start + raw->size(), false);
  return decodeVolume(h, *raw, source, options);
}

}  // namespace

Result<Volume> readNifti(const std::filesystem::path& file, const NiftiReadOptions& options) {
  const std::string low = lower(file.filename().string());
  const bool isHdr = endsWith(low, ".hdr") || endsWith(low, ".hdr.gz");
  const bool isImg = endsWith(low, ".img") || endsWith(low, ".img.gz");
  std::filesystem::path hdr = file, img = file;
  if (isHdr || isImg) {
    std::error_code ec;
    const auto cands = partnerCandidates(file, isHdr);
    bool found = false;
    for (const auto& c : cands) {
      if (std::filesystem::exists(c, ec)) {
        (isHdr ? img : hdr) = c;
        found = true;
        break;
      }
    }
    if (!found)
      return fail(ErrorCode::NotFound,
                  std::string("the ") + (isHdr ? ".img" : ".hdr") + " file of this pair is missing (tried " +
                      cands[0].string() + ", " + cands[1].string() + ")",
                  file.string(), "keep both files of an Analyze/NIfTI pair together");
  }
  // The header is at most 540 bytes, or a gzip stream starting with it.
  auto head = readRange(hdr, 0, 2);
  if (!head) return std::move(head).error();
  std::vector<std::byte> hbytes;
  if (detail::isGzip(*head)) {
    auto all = readFile(hdr, isHdr || isImg ? std::size_t{1} << 24 : std::numeric_limits<std::size_t>::max());
    if (!all) return std::move(all).error();
    if (!isHdr && !isImg) return parseNifti(*all, hdr.string(), options);
    hbytes = std::move(*all);
  } else {
    auto r = readRange(hdr, 0, kSizeN2);
    if (!r) return std::move(r).error();
    hbytes = std::move(*r);
  }
  auto h = parseNiftiHeader(hbytes, hdr.string());
  if (!h) return std::move(h).error();
  if (isHdr || isImg) {
    if (h->singleFile)
      return fail(ErrorCode::InvalidArgument,
                  "the header has single-file magic n+" + std::to_string(h->version) + ", not ni" +
                      std::to_string(h->version) + " of a .hdr/.img pair",
                  hdr.string(), "rename it to .nii");
  } else if (!h->singleFile) {
    return fail(ErrorCode::InvalidArgument,
                "this is the header of a .hdr/.img pair (magic ni" + std::to_string(h->version) + ")",
                hdr.string(), "rename it to .hdr and keep the .img next to it");
  }
  return loadFromFile(*h, img, options);
}

Result<std::vector<std::byte>> encodeNifti(const Volume& v) {
  if (v.empty())
    return fail(ErrorCode::InvalidArgument, "the volume is empty", "writeNifti",
                "create it with Volume::create");
  const Vec3i dims = v.dims();
  for (int a = 0; a < 3; ++a)
    if (dims[a] > 32767)
      return fail(ErrorCode::Unsupported,
                  "dimension " + std::to_string(a) + " is " + std::to_string(dims[a]) +
                      " voxels; NIfTI-1 stores at most 32767",
                  "writeNifti", "crop or downsample the volume, or write NRRD/MetaImage");

  // Geometry in millimetres. The sform is the affine itself; the qform is its
  // rotation part with spacing = column lengths and qfac = sign(det).
  const Mat3 lin = v.indexToWorld().linear() * 1e3;
  const Vec3 off = v.indexToWorld().translation() * 1e3;
  const Vec3 spacing = lin.colwise().norm().transpose();
  {
    // The header stores float32 millimetres; refuse what does not fit.
    const Mat3 linF = lin.cast<float>().cast<double>();
    if (!linF.allFinite() || !off.cast<float>().allFinite() || !spacing.cast<float>().allFinite() ||
        isSingular(linF))
      return fail(ErrorCode::InvalidArgument,
                  "the index-to-world affine does not fit NIfTI-1's float32 millimetre fields", "writeNifti",
                  "write NRRD or MetaImage, which store doubles");
  }
  Mat3 dir = lin * spacing.cwiseInverse().asDiagonal();
  // Nearest orthogonal matrix (polar decomposition), as the standard asks
  // for non-orthogonal sforms.
  Eigen::JacobiSVD<Mat3> svd(dir, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Mat3 rot = svd.matrixU() * svd.matrixV().transpose();
  double qfac = 1.0;
  if (rot.determinant() < 0) {
    qfac = -1.0;
    rot.col(2) *= -1.0;
  }
  Quat q(rot);
  q.normalize();
  if (q.w() < 0) q.coeffs() *= -1.0;

  const std::size_t dataBytes = v.byteSize();
  std::vector<std::byte> out(static_cast<std::size_t>(kDefaultOffsetN1) + dataBytes, std::byte{0});
  std::byte* p = out.data();
  storeLE<std::int32_t>(p + 0, static_cast<std::int32_t>(kSizeN1));
  p[38] = std::byte{'r'};  // "regular", for Analyze readers
  const std::int16_t dim[8] = {3,
                               static_cast<std::int16_t>(dims.x()),
                               static_cast<std::int16_t>(dims.y()),
                               static_cast<std::int16_t>(dims.z()),
                               1,
                               1,
                               1,
                               1};
  for (int i = 0; i < 8; ++i) storeLE<std::int16_t>(p + kN1.dim + 2 * i, dim[i]);
  storeLE<std::int16_t>(p + kN1.datatype, static_cast<std::int16_t>(datatypeCodeOf(v.type())));
  storeLE<std::int16_t>(p + kN1.bitpix, static_cast<std::int16_t>(8 * voxelBytes(v.type())));
  const float pixdim[8] = {static_cast<float>(qfac),
                           static_cast<float>(spacing.x()),
                           static_cast<float>(spacing.y()),
                           static_cast<float>(spacing.z()),
                           1,
                           1,
                           1,
                           1};
  for (int i = 0; i < 8; ++i) storeLE<float>(p + kN1.pixdim + 4 * i, pixdim[i]);
  storeLE<float>(p + kN1.voxOffset, static_cast<float>(kDefaultOffsetN1));
  storeLE<float>(p + kN1.sclSlope, 1.0f);
  storeLE<float>(p + kN1.sclInter, 0.0f);
  p[kN1.xyztUnits] = std::byte{2};  // NIFTI_UNITS_MM
  const auto [lo, hi] = v.range();
  storeLE<float>(p + 124, static_cast<float>(hi));  // cal_max
  storeLE<float>(p + 128, static_cast<float>(lo));  // cal_min
  std::memcpy(p + kN1.descrip, "DMPlatform", 10);
  storeLE<std::int16_t>(p + kN1.qformCode, 1);  // NIFTI_XFORM_SCANNER_ANAT
  storeLE<std::int16_t>(p + kN1.sformCode, 1);
  storeLE<float>(p + kN1.quatern + 0, static_cast<float>(q.x()));
  storeLE<float>(p + kN1.quatern + 4, static_cast<float>(q.y()));
  storeLE<float>(p + kN1.quatern + 8, static_cast<float>(q.z()));
  for (int i = 0; i < 3; ++i) {
    storeLE<float>(p + kN1.qoffset + 4 * i, static_cast<float>(off[i]));
    for (int c = 0; c < 3; ++c) storeLE<float>(p + kN1.srow + 16 * i + 4 * c, static_cast<float>(lin(i, c)));
    storeLE<float>(p + kN1.srow + 16 * i + 12, static_cast<float>(off[i]));
  }
  std::memcpy(p + kN1.magic, "n+1\0", 4);
  // Voxels, little-endian.
  std::memcpy(p + kDefaultOffsetN1, v.bytes(), dataBytes);
  if constexpr (std::endian::native == std::endian::big) {
    const std::size_t w = voxelBytes(v.type());
    for (std::size_t i = 0; w > 1 && i < dataBytes; i += w)
      std::reverse(p + kDefaultOffsetN1 + i, p + kDefaultOffsetN1 + i + w);
  }
  return out;
}

Status writeNifti(const Volume& v, const std::filesystem::path& file) {
  auto bytes = encodeNifti(v);
  if (!bytes) return std::move(bytes).error().within(file.string());
  if (endsWith(lower(file.filename().string()), ".gz")) {
    auto gz = detail::deflate(*bytes, detail::CompressFormat::Gzip);
    if (!gz) return std::move(gz).error().within(file.string());
    return writeFileAtomic(file, gz->data(), gz->size());
  }
  return writeFileAtomic(file, bytes->data(), bytes->size());
}

}  // namespace dm
