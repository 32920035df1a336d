// dm/core/image.hpp — the shared 2-D image of the data model.
//
// An Image is a typed, strided pixel buffer with shared ownership of its
// memory. Views (sub-rectangles, wraps of foreign memory such as a camera
// frame) share the buffer without copying; DMVision wraps an Image as a
// cv::Mat header (data(), strideBytes()) and DMRenderer uploads it as a
// texture with GL_UNPACK_ROW_LENGTH, so pixels are never converted on the way.
// Rows are top to bottom; channels are interleaved (RGB, RGBA, gray).
//
// @code
//   auto img = dm::Image::create(640, 480, 3, dm::PixelType::U8);
//   img->at<std::uint8_t>(10, 20, 0) = 255;          // x, y, channel
//   dm::Image roi = img->view(100, 100, 64, 64);      // no copy
// @endcode
#pragma once

#include <dm/core/result.hpp>

#include <cstddef>
#include <cstdint>
#include <memory>

namespace dm {

enum class PixelType : std::uint8_t { U8, U16, F32 };

std::size_t pixelTypeBytes(PixelType t) noexcept;
const char* toString(PixelType t) noexcept;

template <class T>
struct PixelTypeOf;
template <>
struct PixelTypeOf<std::uint8_t> {
  static constexpr PixelType value = PixelType::U8;
};
template <>
struct PixelTypeOf<std::uint16_t> {
  static constexpr PixelType value = PixelType::U16;
};
template <>
struct PixelTypeOf<float> {
  static constexpr PixelType value = PixelType::F32;
};

class Image {
 public:
  Image() = default;

  /// A zero-filled, tightly packed image. Fails on non-positive sizes,
  /// channels outside 1..4, or more than `maxBytes`.
  static Result<Image> create(int width, int height, int channels, PixelType type,
                              std::size_t maxBytes = std::size_t{1} << 32);
  /// Wraps foreign memory without copying. `owner` keeps it alive (may be
  /// null when the caller guarantees the lifetime). Fails when strideBytes is
  /// smaller than a row or the pointer is null.
  static Result<Image> wrap(void* data, int width, int height, int channels, PixelType type,
                            std::size_t strideBytes, std::shared_ptr<void> owner);

  int width() const { return width_; }
  int height() const { return height_; }
  int channels() const { return channels_; }
  PixelType type() const { return type_; }
  std::size_t strideBytes() const { return stride_; }
  std::size_t pixelBytes() const { return pixelTypeBytes(type_) * static_cast<std::size_t>(channels_); }
  std::size_t rowBytes() const { return pixelBytes() * static_cast<std::size_t>(width_); }
  bool empty() const { return data_ == nullptr; }
  /// True when rows follow each other without padding.
  bool isContiguous() const { return stride_ == rowBytes(); }

  std::byte* data() { return data_; }
  const std::byte* data() const { return data_; }
  std::byte* row(int y) { return data_ + static_cast<std::size_t>(y) * stride_; }
  const std::byte* row(int y) const { return data_ + static_cast<std::size_t>(y) * stride_; }

  /// Channel c of pixel (x, y); DM_DEMAND that T matches type().
  template <class T>
  T& at(int x, int y, int c = 0) {
    DM_DEMAND(PixelTypeOf<T>::value == type_, "Image::at<T>() with the wrong pixel type");
    DM_ASSERT(x >= 0 && y >= 0 && x < width_ && y < height_ && c >= 0 && c < channels_, "pixel out of range");
    return reinterpret_cast<T*>(row(
        y))[static_cast<std::size_t>(x) * static_cast<std::size_t>(channels_) + static_cast<std::size_t>(c)];
  }
  template <class T>
  const T& at(int x, int y, int c = 0) const {
    return const_cast<Image*>(this)->at<T>(x, y, c);
  }

  /// A sub-rectangle sharing this image's memory; clipped to the image.
  Image view(int x, int y, int width, int height) const;
  /// A deep, tightly packed copy.
  Image clone() const;
  /// True when both share one buffer (views of one image, or wraps of it).
  bool sharesMemoryWith(const Image& other) const { return owner_ && owner_ == other.owner_; }

 private:
  std::shared_ptr<void> owner_;
  std::byte* data_ = nullptr;
  int width_ = 0, height_ = 0, channels_ = 0;
  PixelType type_ = PixelType::U8;
  std::size_t stride_ = 0;
};

}  // namespace dm
