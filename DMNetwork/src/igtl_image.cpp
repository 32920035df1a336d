// OpenIGTLink IMAGE ⇄ dm::Volume / dm::Image.
//
// Wire layout (72-byte header, big-endian): version u16 (1), components u8,
// scalar type u8, endian u8 (1 big, 2 little), coordinate system u8 (1 RAS,
// 2 LPS), size u16[3], matrix float32[12] (columns i·spacing_i, j·spacing_j,
// k·spacing_k, then the position of the volume centre; mm), sub-volume offset
// u16[3], sub-volume size u16[3]; then the sub-volume's voxels, x fastest.
#include <bit>
#include <cmath>
#include <cstring>

#include "igtl_wire.hpp"

namespace dm::igtl {

using namespace wire;

namespace {

constexpr std::size_t kImageHeaderBytes = 72;

struct ScalarMap {
  std::uint8_t code;
  VoxelType voxel;
};
constexpr ScalarMap kScalars[] = {{2, VoxelType::I8},   {3, VoxelType::U8},  {4, VoxelType::I16},
                                  {5, VoxelType::U16},  {6, VoxelType::I32}, {7, VoxelType::U32},
                                  {10, VoxelType::F32}, {11, VoxelType::F64}};

bool voxelTypeOf(std::uint8_t code, VoxelType& out) {
  for (const auto& s : kScalars)
    if (s.code == code) {
      out = s.voxel;
      return true;
    }
  return false;
}
std::uint8_t scalarCodeOf(VoxelType t) {
  for (const auto& s : kScalars)
    if (s.voxel == t) return s.code;
  return 0;
}

// Copies `count` scalars of `size` bytes, reversing each when `swap`.
void copyScalars(std::byte* dst, const std::byte* src, std::size_t count, std::size_t size, bool swap) {
  if (!swap || size == 1) {
    std::memcpy(dst, src, count * size);
    return;
  }
  for (std::size_t i = 0; i < count; ++i)
    for (std::size_t b = 0; b < size; ++b) dst[i * size + b] = src[i * size + size - 1 - b];
}

// Places the sub-volume carried by `data` into `dst` (whole image, x fastest).
void placeSubVolume(std::byte* dst, const std::byte* data, const ImageInfo& info, std::size_t scalarBytes) {
  const bool swap = info.bigEndian != (std::endian::native == std::endian::big);
  const std::size_t px = scalarBytes * static_cast<std::size_t>(info.components);
  const std::size_t rowCount =
      static_cast<std::size_t>(info.subSize.x()) * static_cast<std::size_t>(info.components);
  for (int k = 0; k < info.subSize.z(); ++k)
    for (int j = 0; j < info.subSize.y(); ++j) {
      const std::size_t src = (static_cast<std::size_t>(k) * static_cast<std::size_t>(info.subSize.y()) +
                               static_cast<std::size_t>(j)) *
                              static_cast<std::size_t>(info.subSize.x()) * px;
      const std::size_t dz = static_cast<std::size_t>(k + info.subOffset.z());
      const std::size_t dy = static_cast<std::size_t>(j + info.subOffset.y());
      const std::size_t dstOff =
          ((dz * static_cast<std::size_t>(info.size.y()) + dy) * static_cast<std::size_t>(info.size.x()) +
           static_cast<std::size_t>(info.subOffset.x())) *
          px;
      copyScalars(dst + dstOff, data + src, rowCount, scalarBytes, swap);
    }
}

std::size_t scalarBytesOf(std::uint8_t code) {
  VoxelType t{};
  return voxelTypeOf(code, t) ? voxelBytes(t) : 0;
}

Result<std::vector<std::byte>> encodeImageBody(const Envelope& env, int components, std::uint8_t scalar,
                                               const Vec3i& dims, const Mat3& linearMm, const Vec3& centreMm,
                                               const std::byte* data, std::size_t rowBytes,
                                               std::size_t rowStride) {
  for (int a = 0; a < 3; ++a)
    if (dims(a) < 1 || dims(a) > 0xFFFF)
      return fail(ErrorCode::InvalidArgument,
                  formatString("image size[%d] is %d; OpenIGTLink IMAGE holds 1..65535", a, dims(a)),
                  "OpenIGTLink encoder", "split the image or send a sub-volume");
  const std::size_t rows = static_cast<std::size_t>(dims.y()) * static_cast<std::size_t>(dims.z());
  std::vector<std::byte> c;
  c.reserve(kImageHeaderBytes + rows * rowBytes);
  putBe16(c, 1);
  c.push_back(static_cast<std::byte>(components));
  c.push_back(std::byte{scalar});
  c.push_back(std::byte{std::endian::native == std::endian::big ? std::uint8_t{1} : std::uint8_t{2}});
  c.push_back(std::byte{1});  // RAS
  for (int a = 0; a < 3; ++a) putBe16(c, static_cast<std::uint16_t>(dims(a)));
  for (int col = 0; col < 3; ++col)
    for (int r = 0; r < 3; ++r) putF32(c, linearMm(r, col));
  for (int r = 0; r < 3; ++r) putF32(c, centreMm(r));
  for (int a = 0; a < 3; ++a) putBe16(c, 0);
  for (int a = 0; a < 3; ++a) putBe16(c, static_cast<std::uint16_t>(dims(a)));
  for (std::size_t r = 0; r < rows; ++r)
    c.insert(c.end(), data + r * rowStride, data + r * rowStride + rowBytes);
  return encodeRaw(env, "IMAGE", c);
}

}  // namespace

Result<ImageInfo> decodeImageInfo(const MessageView& m) {
  if (auto s = expectType(m, "IMAGE"); !s) return std::move(s).error();
  if (m.content.size() < kImageHeaderBytes)
    return bad(m, 0, ErrorCode::Parse,
               formatString("IMAGE content is %zu bytes, the image header needs 72", m.content.size()));
  const std::byte* p = m.content.data();
  const unsigned version = getBe16(p);
  if (version != 1 && version != 2)
    return bad(m, 0, ErrorCode::Version,
               formatString("IMAGE header version is %u, this codec reads 1 and 2", version));
  ImageInfo info;
  info.components = std::to_integer<int>(p[2]);
  info.scalarType = std::to_integer<std::uint8_t>(p[3]);
  const unsigned endian = std::to_integer<unsigned>(p[4]);
  const unsigned coord = std::to_integer<unsigned>(p[5]);
  if (info.components < 1) return bad(m, 2, ErrorCode::Parse, "IMAGE has 0 components per voxel");
  const std::size_t scalarBytes = scalarBytesOf(info.scalarType);
  if (scalarBytes == 0)
    return bad(m, 3, ErrorCode::Unsupported,
               formatString("IMAGE scalar type %u; supported: 2 int8, 3 uint8, 4 int16, 5 uint16, 6 int32, "
                            "7 uint32, 10 float32, 11 float64",
                            static_cast<unsigned>(info.scalarType)));
  if (endian != 1 && endian != 2)
    return bad(m, 4, ErrorCode::Parse,
               formatString("IMAGE endian field is %u, must be 1 (big) or 2 (little)", endian));
  info.bigEndian = endian == 1;
  if (coord != 1 && coord != 2)
    return bad(m, 5, ErrorCode::Parse,
               formatString("IMAGE coordinate field is %u, must be 1 (RAS) or 2 (LPS)", coord));
  info.lps = coord == 2;
  for (int a = 0; a < 3; ++a) {
    info.size(a) = getBe16(p + 6 + 2 * a);
    info.subOffset(a) = getBe16(p + 60 + 2 * a);
    info.subSize(a) = getBe16(p + 66 + 2 * a);
  }
  for (int a = 0; a < 3; ++a) {
    if (info.size(a) < 1)
      return bad(m, 6 + 2 * static_cast<std::size_t>(a), ErrorCode::Parse,
                 formatString("IMAGE size[%d] is 0", a));
    if (info.subSize(a) < 1 || info.subOffset(a) + info.subSize(a) > info.size(a))
      return bad(m, 60 + 2 * static_cast<std::size_t>(a), ErrorCode::Parse,
                 formatString("IMAGE sub-volume offset[%d] %d + size %d exceeds the image size %d", a,
                              info.subOffset(a), info.subSize(a), info.size(a)));
  }
  const std::uint64_t expected = static_cast<std::uint64_t>(info.subSize.x()) *
                                 static_cast<std::uint64_t>(info.subSize.y()) *
                                 static_cast<std::uint64_t>(info.subSize.z()) *
                                 static_cast<std::uint64_t>(info.components) * scalarBytes;
  if (expected != m.content.size() - kImageHeaderBytes)
    return bad(
        m, kImageHeaderBytes, ErrorCode::Parse,
        formatString("IMAGE sub-volume %dx%dx%d x %d components x %zu bytes needs %llu data bytes, the body "
                     "has %zu",
                     info.subSize.x(), info.subSize.y(), info.subSize.z(), info.components, scalarBytes,
                     static_cast<unsigned long long>(expected), m.content.size() - kImageHeaderBytes));
  for (int i = 0; i < 12; ++i)
    if (!std::isfinite(getF32(p + 12 + 4 * static_cast<std::size_t>(i))))
      return bad(m, 12 + 4 * static_cast<std::size_t>(i), ErrorCode::Parse,
                 formatString("IMAGE matrix element %d is not finite", i));
  return info;
}

Result<Volume> decodeVolume(const MessageView& m, std::size_t maxBytes) {
  auto info = decodeImageInfo(m);
  if (!info) return std::move(info).error();
  if (info->components != 1)
    return bad(m, 2, ErrorCode::Unsupported,
               formatString("IMAGE has %d components per voxel; a Volume holds one", info->components),
               "use decodeImage() for 2-D multi-channel images");
  VoxelType type{};
  voxelTypeOf(info->scalarType, type);
  const std::byte* p = m.content.data();
  Mat3 l;
  Vec3 centre;
  for (int col = 0; col < 3; ++col)
    for (int r = 0; r < 3; ++r) l(r, col) = getF32(p + 12 + 4 * static_cast<std::size_t>(3 * col + r));
  for (int r = 0; r < 3; ++r) centre(r) = getF32(p + 48 + 4 * static_cast<std::size_t>(r));
  if (info->lps) {
    const Mat3 flip = Vec3(-1, -1, 1).asDiagonal();
    l = flip * l;
    centre = flip * centre;
  }
  Affine3 a = Affine3::Identity();
  a.linear() = l * kMetresPerMm;
  a.translation() = (centre - l * ((info->size.cast<double>() - Vec3::Ones()) * 0.5)) * kMetresPerMm;
  auto vol = Volume::create(info->size, type, a, maxBytes);
  if (!vol) return vol.error().within(where(m, 6));
  placeSubVolume(vol->bytes(), p + kImageHeaderBytes, *info, voxelBytes(type));
  return vol;
}

Result<Image> decodeImage(const MessageView& m, std::size_t maxBytes) {
  auto info = decodeImageInfo(m);
  if (!info) return std::move(info).error();
  if (info->size.z() != 1)
    return bad(m, 10, ErrorCode::Unsupported, formatString("IMAGE is 3-D (size z = %d)", info->size.z()),
               "use decodeVolume()");
  PixelType type;
  switch (info->scalarType) {
    case 3:
      type = PixelType::U8;
      break;
    case 5:
      type = PixelType::U16;
      break;
    case 10:
      type = PixelType::F32;
      break;
    default:
      return bad(m, 3, ErrorCode::Unsupported,
                 formatString("IMAGE scalar type %u has no dm::Image pixel type (uint8, uint16, float32)",
                              static_cast<unsigned>(info->scalarType)),
                 "use decodeVolume(), which holds every scalar type");
  }
  if (info->components > 4)
    return bad(m, 2, ErrorCode::Unsupported,
               formatString("IMAGE has %d components; dm::Image holds 1-4 channels", info->components));
  auto img = Image::create(info->size.x(), info->size.y(), info->components, type, maxBytes);
  if (!img) return img.error().within(where(m, 6));
  placeSubVolume(img->data(), m.content.data() + kImageHeaderBytes, *info, pixelTypeBytes(type));
  return img;
}

Result<std::vector<std::byte>> encodeVolume(const Envelope& env, const Volume& volume) {
  if (volume.empty())
    return fail(ErrorCode::InvalidArgument, "empty volume", "OpenIGTLink encoder", "create the volume first");
  const Mat3 l = volume.indexToWorld().linear() * kMmPerMetre;
  const Vec3 centre =
      volume.indexToWorld() * ((volume.dims().cast<double>() - Vec3::Ones()) * 0.5) * kMmPerMetre;
  const std::size_t rowBytes = static_cast<std::size_t>(volume.dims().x()) * voxelBytes(volume.type());
  return encodeImageBody(env, 1, scalarCodeOf(volume.type()), volume.dims(), l, centre, volume.bytes(),
                         rowBytes, rowBytes);
}

Result<std::vector<std::byte>> encodeImage(const Envelope& env, const Image& image, double spacing) {
  if (image.empty())
    return fail(ErrorCode::InvalidArgument, "empty image", "OpenIGTLink encoder", "create the image first");
  if (!(spacing > 0) || !std::isfinite(spacing))
    return fail(ErrorCode::InvalidArgument, formatString("pixel spacing %g m", spacing),
                "OpenIGTLink encoder", "pass a positive spacing in metres");
  std::uint8_t scalar = 3;
  if (image.type() == PixelType::U16) scalar = 5;
  if (image.type() == PixelType::F32) scalar = 10;
  const Mat3 l = Mat3::Identity() * (spacing * kMmPerMetre);
  return encodeImageBody(env, image.channels(), scalar, Vec3i(image.width(), image.height(), 1), l,
                         Vec3::Zero(), image.data(), image.rowBytes(), image.strideBytes());
}

}  // namespace dm::igtl
