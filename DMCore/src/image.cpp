#include <dm/core/image.hpp>

#include <algorithm>
#include <cstring>
#include <string>

namespace dm {

std::size_t pixelTypeBytes(PixelType t) noexcept {
  switch (t) {
    case PixelType::U8:
      return 1;
    case PixelType::U16:
      return 2;
    case PixelType::F32:
      return 4;
  }
  return 1;
}

const char* toString(PixelType t) noexcept {
  switch (t) {
    case PixelType::U8:
      return "uint8";
    case PixelType::U16:
      return "uint16";
    case PixelType::F32:
      return "float32";
  }
  return "unknown";
}

Result<Image> Image::create(int width, int height, int channels, PixelType type, std::size_t maxBytes) {
  if (width <= 0 || height <= 0)
    return fail(ErrorCode::InvalidArgument,
                "image size " + std::to_string(width) + "x" + std::to_string(height) + " must be positive",
                "image");
  if (channels < 1 || channels > 4)
    return fail(ErrorCode::InvalidArgument, "channels must be 1..4, got " + std::to_string(channels),
                "image");
  const std::size_t row =
      pixelTypeBytes(type) * static_cast<std::size_t>(channels) * static_cast<std::size_t>(width);
  if (row > maxBytes / static_cast<std::size_t>(height))
    return fail(ErrorCode::InvalidArgument,
                "image of " + std::to_string(width) + "x" + std::to_string(height) +
                    " exceeds the limit of " + std::to_string(maxBytes) + " bytes",
                "image");
  const std::size_t bytes = row * static_cast<std::size_t>(height);
  std::shared_ptr<std::byte[]> buf(new std::byte[bytes]());
  Image img;
  img.data_ = buf.get();
  img.owner_ = std::shared_ptr<void>(buf, buf.get());
  img.width_ = width;
  img.height_ = height;
  img.channels_ = channels;
  img.type_ = type;
  img.stride_ = row;
  return img;
}

Result<Image> Image::wrap(void* data, int width, int height, int channels, PixelType type,
                          std::size_t strideBytes, std::shared_ptr<void> owner) {
  if (!data) return fail(ErrorCode::InvalidArgument, "null pixel pointer", "image");
  if (width <= 0 || height <= 0 || channels < 1 || channels > 4)
    return fail(ErrorCode::InvalidArgument,
                "bad image geometry " + std::to_string(width) + "x" + std::to_string(height) + "x" +
                    std::to_string(channels),
                "image");
  const std::size_t row =
      pixelTypeBytes(type) * static_cast<std::size_t>(channels) * static_cast<std::size_t>(width);
  if (strideBytes < row)
    return fail(ErrorCode::InvalidArgument,
                "stride " + std::to_string(strideBytes) + " is smaller than a row of " + std::to_string(row) +
                    " bytes",
                "image");
  Image img;
  img.data_ = static_cast<std::byte*>(data);
  img.owner_ = std::move(owner);
  img.width_ = width;
  img.height_ = height;
  img.channels_ = channels;
  img.type_ = type;
  img.stride_ = strideBytes;
  return img;
}

Image Image::view(int x, int y, int width, int height) const {
  Image v;
  const int x0 = std::clamp(x, 0, width_), y0 = std::clamp(y, 0, height_);
  const int x1 = std::clamp(x + width, x0, width_), y1 = std::clamp(y + height, y0, height_);
  if (x1 == x0 || y1 == y0 || empty()) return v;
  v = *this;
  v.data_ = data_ + static_cast<std::size_t>(y0) * stride_ + static_cast<std::size_t>(x0) * pixelBytes();
  v.width_ = x1 - x0;
  v.height_ = y1 - y0;
  return v;
}

Image Image::clone() const {
  if (empty()) return {};
  Image out = *create(width_, height_, channels_, type_);
  for (int y = 0; y < height_; ++y) std::memcpy(out.row(y), row(y), rowBytes());
  return out;
}

}  // namespace dm
