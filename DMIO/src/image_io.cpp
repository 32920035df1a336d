// image_io.cpp — PNG through libpng.
//
// libpng reports errors by longjmp. Every setjmp lives in a small function
// below that touches only plain C state (ReadState / WriteState, raw
// pointers): no object with a destructor is alive in a frame that longjmp
// skips. The C++ callers own the libpng structs through guards and turn the
// recorded message into a dm::Error.
#include <dm/core/filesystem.hpp>
#include <dm/io/image_io.hpp>

#include <png.h>

#include <algorithm>
#include <bit>
#include <csetjmp>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <string>

namespace dm {
namespace {

constexpr bool kLittleEndian = std::endian::native == std::endian::little;

/// DEFLATE cannot expand data by more than about 1032:1 (a 258-byte match
/// in two bits); the margin covers zlib headers and chunk framing.
constexpr std::size_t kMaxDeflateRatio = 1040;

struct ReadState {
  png_structp png = nullptr;
  png_infop info = nullptr;
  const png_byte* data = nullptr;
  std::size_t size = 0;
  std::size_t offset = 0;
  char message[256] = {};
};

struct Header {
  png_uint_32 width = 0, height = 0;
  int bitDepth = 0, colorType = 0, interlace = 0;
  std::size_t fileRowBytes = 0;  ///< bytes of a row as stored (before expansion)
  int channels = 0;              ///< after expansion
  int outDepth = 0;              ///< 8 or 16 after expansion
  std::size_t outRowBytes = 0;
};

void onError(png_structp png, png_const_charp msg) {
  auto* message = static_cast<char*>(png_get_error_ptr(png));
  std::snprintf(message, 256, "%s", msg ? msg : "unknown libpng error");
  png_longjmp(png, 1);
}

void onWarning(png_structp, png_const_charp) {}  // e.g. bad ancillary CRCs: libpng skips those chunks

void onRead(png_structp png, png_bytep out, png_size_t n) {
  auto* s = static_cast<ReadState*>(png_get_io_ptr(png));
  if (n > s->size - s->offset) {
    char msg[128];
    std::snprintf(msg, sizeof msg, "data ends at byte %zu, %zu more bytes were expected (truncated file)",
                  s->size, n - (s->size - s->offset));
    png_error(png, msg);
  }
  std::memcpy(out, s->data + s->offset, n);
  s->offset += n;
}

/// Reads the chunks up to the first IDAT and sets up the expansions.
int readHeader(ReadState* s, Header* h) {
  if (setjmp(png_jmpbuf(s->png))) return 0;
  png_read_info(s->png, s->info);
  png_get_IHDR(s->png, s->info, &h->width, &h->height, &h->bitDepth, &h->colorType, &h->interlace, nullptr,
               nullptr);
  h->fileRowBytes = png_get_rowbytes(s->png, s->info);
  // Palette -> RGB(A), gray < 8 bits -> 8 bits, tRNS -> alpha channel.
  png_set_expand(s->png);
  if (h->bitDepth == 16 && kLittleEndian) png_set_swap(s->png);
  png_set_interlace_handling(s->png);
  png_read_update_info(s->png, s->info);
  h->channels = png_get_channels(s->png, s->info);
  h->outDepth = png_get_bit_depth(s->png, s->info);
  h->outRowBytes = png_get_rowbytes(s->png, s->info);
  return 1;
}

int readRows(ReadState* s, png_bytep* rows) {
  if (setjmp(png_jmpbuf(s->png))) return 0;
  png_read_image(s->png, rows);
  png_read_end(s->png, nullptr);
  return 1;
}

struct WriteState {
  png_structp png = nullptr;
  png_infop info = nullptr;
  unsigned char* buffer = nullptr;
  std::size_t size = 0, capacity = 0;
  char message[256] = {};
};

struct WriteParams {
  png_uint_32 width = 0, height = 0;
  int bitDepth = 8, colorType = PNG_COLOR_TYPE_GRAY;
  int compressionLevel = -1;  // zlib level 0..9, -1: zlib's default
};

void onWrite(png_structp png, png_bytep data, png_size_t n) {
  auto* s = static_cast<WriteState*>(png_get_io_ptr(png));
  if (n > s->capacity - s->size) {
    std::size_t cap = std::max<std::size_t>(s->capacity * 2, 4096);
    while (cap - s->size < n) cap *= 2;
    void* grown = std::realloc(s->buffer, cap);
    if (!grown) png_error(png, "out of memory while encoding");
    s->buffer = static_cast<unsigned char*>(grown);
    s->capacity = cap;
  }
  std::memcpy(s->buffer + s->size, data, n);
  s->size += n;
}

void onFlush(png_structp) {}

int writeRows(WriteState* s, const WriteParams* p, png_bytep* rows) {
  if (setjmp(png_jmpbuf(s->png))) return 0;
  png_set_write_fn(s->png, s, onWrite, onFlush);
  if (p->compressionLevel >= 0) {
    png_set_compression_level(s->png, p->compressionLevel);
    // Fast levels: one cheap filter instead of libpng's per-row search.
    if (p->compressionLevel <= 3) png_set_filter(s->png, PNG_FILTER_TYPE_BASE, PNG_FILTER_SUB);
  }
  png_set_IHDR(s->png, s->info, p->width, p->height, p->bitDepth, p->colorType, PNG_INTERLACE_NONE,
               PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_write_info(s->png, s->info);
  if (p->bitDepth == 16 && kLittleEndian) png_set_swap(s->png);
  png_write_image(s->png, rows);
  png_write_end(s->png, nullptr);
  return 1;
}

const char* colorTypeName(int t) {
  switch (t) {
    case PNG_COLOR_TYPE_GRAY:
      return "gray";
    case PNG_COLOR_TYPE_GRAY_ALPHA:
      return "gray+alpha";
    case PNG_COLOR_TYPE_RGB:
      return "RGB";
    case PNG_COLOR_TYPE_RGBA:
      return "RGBA";
    case PNG_COLOR_TYPE_PALETTE:
      return "palette";
    default:
      return "unknown";
  }
}

}  // namespace

Result<Image> parsePng(std::span<const std::byte> bytes, std::string_view sourceName,
                       const ImageReadOptions& options) {
  const std::string source(sourceName);
  const auto* data = reinterpret_cast<const png_byte*>(bytes.data());
  if (bytes.size() < 8 || png_sig_cmp(data, 0, 8) != 0)
    return fail(ErrorCode::Parse, "not a PNG file: the first 8 bytes are not the PNG signature",
                source + ": byte 0", "check the file type; only PNG is read here");

  ReadState s;
  s.data = data;
  s.size = bytes.size();
  s.png = png_create_read_struct(PNG_LIBPNG_VER_STRING, s.message, onError, onWarning);
  if (!s.png) return fail(ErrorCode::Internal, "png_create_read_struct failed", source);
  struct Guard {
    ReadState& s;
    ~Guard() { png_destroy_read_struct(&s.png, s.info ? &s.info : nullptr, nullptr); }
  } guard{s};
  s.info = png_create_info_struct(s.png);
  if (!s.info) return fail(ErrorCode::Internal, "png_create_info_struct failed", source);
  png_set_read_fn(s.png, &s, onRead);

  auto libpngError = [&](const char* stage) {
    return fail(ErrorCode::Parse, std::string("libpng: ") + s.message,
                source + ": " + stage + " (near byte " + std::to_string(s.offset) + ")",
                "the file is corrupt or truncated; re-export or re-download it");
  };
  Header h;
  if (!readHeader(&s, &h)) return libpngError("header");

  const std::string dims = std::to_string(h.width) + "x" + std::to_string(h.height);
  const std::size_t pixels = std::size_t{h.width} * std::size_t{h.height};
  if (pixels > options.maxPixels)
    return fail(ErrorCode::InvalidArgument,
                "image of " + dims + " = " + std::to_string(pixels) + " pixels exceeds the limit of " +
                    std::to_string(options.maxPixels),
                source + ": IHDR", "raise ImageReadOptions::maxPixels if the image is genuine");
  if (h.outRowBytes > options.maxBytes / h.height)
    return fail(ErrorCode::InvalidArgument,
                "decoded image of " + dims + " x " + std::to_string(h.outRowBytes / h.width) +
                    " bytes per pixel exceeds the limit of " + std::to_string(options.maxBytes) + " bytes",
                source + ": IHDR", "raise ImageReadOptions::maxBytes if the image is genuine");
  if (h.fileRowBytes > kMaxDeflateRatio * bytes.size() / h.height)
    return fail(ErrorCode::Parse,
                "a file of " + std::to_string(bytes.size()) + " bytes cannot hold the " + dims + " " +
                    colorTypeName(h.colorType) + " image its IHDR declares",
                source + ": IHDR", "the file is truncated or its header is corrupt");
  if ((h.outDepth != 8 && h.outDepth != 16) || h.channels < 1 || h.channels > 4)
    return fail(ErrorCode::Unsupported,
                "unexpected decoded layout: " + std::to_string(h.channels) + " channels of " +
                    std::to_string(h.outDepth) + " bits",
                source + ": IHDR");

  auto img = Image::create(static_cast<int>(h.width), static_cast<int>(h.height), h.channels,
                           h.outDepth == 16 ? PixelType::U16 : PixelType::U8, options.maxBytes);
  if (!img) return std::move(img).error().within(source);
  if (img->rowBytes() != h.outRowBytes)
    return fail(ErrorCode::Internal, "libpng row size disagrees with the image", source);
  std::vector<png_bytep> rows(h.height);
  for (png_uint_32 y = 0; y < h.height; ++y)
    rows[y] = reinterpret_cast<png_bytep>(img->row(static_cast<int>(y)));
  if (!readRows(&s, rows.data())) return libpngError("image data");
  return std::move(*img);
}

Result<Image> readPng(const std::filesystem::path& file, const ImageReadOptions& options) {
  auto bytes = readFile(file, std::numeric_limits<std::size_t>::max());
  if (!bytes) return std::move(bytes).error();
  return parsePng(*bytes, file.string(), options);
}

Result<std::vector<std::byte>> encodePng(const Image& image, int compressionLevel) {
  if (compressionLevel < -1 || compressionLevel > 9)
    return fail(ErrorCode::InvalidArgument,
                "PNG compression level " + std::to_string(compressionLevel) + " is outside -1..9", "encodePng",
                "use -1 (zlib's default), 1 (fast) .. 9 (small)");
  if (image.empty()) return fail(ErrorCode::InvalidArgument, "cannot encode an empty image", "encodePng");
  if (image.type() == PixelType::F32)
    return fail(ErrorCode::Unsupported, "PNG cannot store 32-bit float pixels", "encodePng",
                "convert the image to U8 or U16 first");
  if (image.channels() < 1 || image.channels() > 4)
    return fail(ErrorCode::InvalidArgument,
                "PNG needs 1..4 channels, got " + std::to_string(image.channels()), "encodePng");
  WriteParams p;
  p.width = static_cast<png_uint_32>(image.width());
  p.height = static_cast<png_uint_32>(image.height());
  p.bitDepth = image.type() == PixelType::U16 ? 16 : 8;
  static constexpr int kColorTypes[] = {PNG_COLOR_TYPE_GRAY, PNG_COLOR_TYPE_GRAY_ALPHA, PNG_COLOR_TYPE_RGB,
                                        PNG_COLOR_TYPE_RGBA};
  p.colorType = kColorTypes[image.channels() - 1];
  p.compressionLevel = compressionLevel;

  WriteState s;
  s.png = png_create_write_struct(PNG_LIBPNG_VER_STRING, s.message, onError, onWarning);
  if (!s.png) return fail(ErrorCode::Internal, "png_create_write_struct failed", "encodePng");
  struct Guard {
    WriteState& s;
    ~Guard() {
      png_destroy_write_struct(&s.png, s.info ? &s.info : nullptr);
      std::free(s.buffer);
    }
  } guard{s};
  s.info = png_create_info_struct(s.png);
  if (!s.info) return fail(ErrorCode::Internal, "png_create_info_struct failed", "encodePng");

  // libpng copies each row before transforming it (byte swap), so the
  // const_cast never leads to a write into the caller's image.
  std::vector<png_bytep> rows(p.height);
  for (png_uint_32 y = 0; y < p.height; ++y)
    rows[y] = reinterpret_cast<png_bytep>(const_cast<std::byte*>(image.row(static_cast<int>(y))));
  if (!writeRows(&s, &p, rows.data()))
    return fail(ErrorCode::Internal, std::string("libpng: ") + s.message, "encodePng");
  const auto* begin = reinterpret_cast<const std::byte*>(s.buffer);
  return std::vector<std::byte>(begin, begin + s.size);
}

Status writePng(const Image& image, const std::filesystem::path& file, int compressionLevel) {
  auto bytes = encodePng(image, compressionLevel);
  if (!bytes) return std::move(bytes).error().within(file.string());
  return writeFileAtomic(file, bytes->data(), bytes->size());
}

}  // namespace dm
