// PNG reading and writing: round trips of every layout through strided views,
// real files from the OpenCV sample data checked against an independent
// decoder, hand-assembled files for palette, low bit depth and Adam7
// interlacing (built here from the PNG specification with stored DEFLATE
// blocks), and corrupt input.
#include <dm/core/filesystem.hpp>
#include <dm/io/image_io.hpp>

#include <gtest/gtest.h>

#include <unistd.h>

#include <array>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

namespace {

using Bytes = std::vector<std::byte>;

// --- a minimal PNG writer following the specification, independent of libpng --

std::uint32_t crc32(const std::uint8_t* p, std::size_t n, std::uint32_t crc = 0) {
  crc = ~crc;
  for (std::size_t i = 0; i < n; ++i) {
    crc ^= p[i];
    for (int k = 0; k < 8; ++k) crc = (crc >> 1) ^ (0xEDB88320u & (0u - (crc & 1u)));
  }
  return ~crc;
}

void put32(std::vector<std::uint8_t>& out, std::uint32_t v) {
  for (int s = 24; s >= 0; s -= 8) out.push_back(static_cast<std::uint8_t>(v >> s));
}

void chunk(std::vector<std::uint8_t>& out, const char* type, const std::vector<std::uint8_t>& data) {
  put32(out, static_cast<std::uint32_t>(data.size()));
  const std::size_t start = out.size();
  out.insert(out.end(), type, type + 4);
  out.insert(out.end(), data.begin(), data.end());
  put32(out, crc32(out.data() + start, out.size() - start));
}

/// zlib stream of stored (uncompressed) DEFLATE blocks.
std::vector<std::uint8_t> zlibStored(const std::vector<std::uint8_t>& raw) {
  std::vector<std::uint8_t> z = {0x78, 0x01};
  std::size_t pos = 0;
  do {
    const std::size_t n = std::min<std::size_t>(raw.size() - pos, 65535);
    z.push_back(pos + n == raw.size() ? 1 : 0);
    z.push_back(static_cast<std::uint8_t>(n));
    z.push_back(static_cast<std::uint8_t>(n >> 8));
    z.push_back(static_cast<std::uint8_t>(~n));
    z.push_back(static_cast<std::uint8_t>(~n >> 8));
    z.insert(z.end(), raw.begin() + static_cast<std::ptrdiff_t>(pos),
             raw.begin() + static_cast<std::ptrdiff_t>(pos + n));
    pos += n;
  } while (pos < raw.size());
  std::uint32_t a = 1, b = 0;
  for (std::uint8_t c : raw) {
    a = (a + c) % 65521;
    b = (b + a) % 65521;
  }
  put32(z, (b << 16) | a);
  return z;
}

/// A PNG with the given IHDR fields, filtered scanlines and extra chunks before IDAT.
Bytes makePng(std::uint32_t w, std::uint32_t h, int depth, int colorType, int interlace,
              const std::vector<std::uint8_t>& scanlines,
              const std::vector<std::pair<const char*, std::vector<std::uint8_t>>>& extra = {}) {
  std::vector<std::uint8_t> out = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1A, '\n'};
  std::vector<std::uint8_t> ihdr;
  put32(ihdr, w);
  put32(ihdr, h);
  ihdr.insert(ihdr.end(), {static_cast<std::uint8_t>(depth), static_cast<std::uint8_t>(colorType), 0, 0,
                           static_cast<std::uint8_t>(interlace)});
  chunk(out, "IHDR", ihdr);
  for (const auto& [type, data] : extra) chunk(out, type, data);
  chunk(out, "IDAT", zlibStored(scanlines));
  chunk(out, "IEND", {});
  Bytes bytes(out.size());
  std::memcpy(bytes.data(), out.data(), out.size());
  return bytes;
}

std::uint32_t be32(const Bytes& b, std::size_t at) {
  return (std::to_integer<std::uint32_t>(b[at]) << 24) | (std::to_integer<std::uint32_t>(b[at + 1]) << 16) |
         (std::to_integer<std::uint32_t>(b[at + 2]) << 8) | std::to_integer<std::uint32_t>(b[at + 3]);
}

/// Σ (i + 1) · sample_i over samples in row-major, channel-interleaved order, mod 2⁶⁴.
std::uint64_t weightedSum(const dm::Image& img) {
  std::uint64_t sum = 0, i = 0;
  for (int y = 0; y < img.height(); ++y)
    for (int x = 0; x < img.width(); ++x)
      for (int c = 0; c < img.channels(); ++c) {
        const std::uint64_t v =
            img.type() == dm::PixelType::U8 ? img.at<std::uint8_t>(x, y, c) : img.at<std::uint16_t>(x, y, c);
        sum += ++i * v;
      }
  return sum;
}

template <class T>
void fillPattern(dm::Image& img) {
  std::uint32_t state = 12345;
  for (int y = 0; y < img.height(); ++y)
    for (int x = 0; x < img.width(); ++x)
      for (int c = 0; c < img.channels(); ++c) {
        state = state * 1664525u + 1013904223u;
        img.at<T>(x, y, c) = static_cast<T>(state >> 16);
      }
}

template <class T>
void expectSamePixels(const dm::Image& a, const dm::Image& b) {
  ASSERT_EQ(a.width(), b.width());
  ASSERT_EQ(a.height(), b.height());
  ASSERT_EQ(a.channels(), b.channels());
  ASSERT_EQ(a.type(), b.type());
  for (int y = 0; y < a.height(); ++y)
    for (int x = 0; x < a.width(); ++x)
      for (int c = 0; c < a.channels(); ++c) ASSERT_EQ(a.at<T>(x, y, c), b.at<T>(x, y, c)) << x << "," << y;
}

TEST(Png, EveryChannelCountAndDepthRoundTripsThroughAStridedView) {
  for (dm::PixelType type : {dm::PixelType::U8, dm::PixelType::U16})
    for (int channels = 1; channels <= 4; ++channels) {
      SCOPED_TRACE(std::string(dm::toString(type)) + " x" + std::to_string(channels));
      auto full = dm::Image::create(41, 29, channels, type);
      ASSERT_TRUE(full) << full.error();
      if (type == dm::PixelType::U8)
        fillPattern<std::uint8_t>(*full);
      else
        fillPattern<std::uint16_t>(*full);
      const dm::Image view = full->view(5, 3, 30, 19);
      ASSERT_FALSE(view.isContiguous());
      auto png = dm::encodePng(view);
      ASSERT_TRUE(png) << png.error();
      // IHDR as the specification lays it out.
      EXPECT_EQ(be32(*png, 16), 30u);
      EXPECT_EQ(be32(*png, 20), 19u);
      EXPECT_EQ(std::to_integer<int>((*png)[24]), type == dm::PixelType::U8 ? 8 : 16);
      constexpr std::array<int, 4> kColorType = {0, 4, 2, 6};  // gray, gray+alpha, RGB, RGBA
      EXPECT_EQ(std::to_integer<int>((*png)[25]), kColorType[channels - 1]);
      auto back = dm::parsePng(*png, "roundtrip");
      ASSERT_TRUE(back) << back.error();
      if (type == dm::PixelType::U8)
        expectSamePixels<std::uint8_t>(view, *back);
      else
        expectSamePixels<std::uint16_t>(view, *back);
    }
}

TEST(Png, SixteenBitSamplesAreBigEndianInTheFile) {
  auto img = dm::Image::create(1, 1, 1, dm::PixelType::U16);
  ASSERT_TRUE(img);
  img->at<std::uint16_t>(0, 0) = 0x1234;
  auto png = dm::encodePng(*img);
  ASSERT_TRUE(png) << png.error();
  // A file built by hand from the specification reads back the same value.
  const Bytes handmade = makePng(1, 1, 16, 0, 0, {0, 0x12, 0x34});
  auto back = dm::parsePng(handmade, "handmade");
  ASSERT_TRUE(back) << back.error();
  EXPECT_EQ(back->at<std::uint16_t>(0, 0), 0x1234);
  auto mine = dm::parsePng(*png, "encoded");
  ASSERT_TRUE(mine) << mine.error();
  EXPECT_EQ(mine->at<std::uint16_t>(0, 0), 0x1234);
}

TEST(Png, WriteAndReadAFile) {
  auto img = dm::Image::create(16, 8, 3, dm::PixelType::U8);
  ASSERT_TRUE(img);
  fillPattern<std::uint8_t>(*img);
  const auto path =
      std::filesystem::temp_directory_path() / ("dm_png_test_" + std::to_string(::getpid()) + ".png");
  ASSERT_TRUE(dm::writePng(*img, path));
  auto back = dm::readPng(path);
  ASSERT_TRUE(back) << back.error();
  expectSamePixels<std::uint8_t>(*img, *back);
  std::filesystem::remove(path);
  auto missing = dm::readPng(path);
  ASSERT_FALSE(missing);
  EXPECT_NE(missing.error().message().find(path.filename().string()), std::string::npos);
}

// Every compression level is lossless; a level outside -1..9 is refused.
TEST(Png, CompressionLevelsAreLosslessAndChecked) {
  auto img = dm::Image::create(64, 48, 4, dm::PixelType::U8);
  ASSERT_TRUE(img);
  fillPattern<std::uint8_t>(*img);
  for (int level : {-1, 0, 1, 3, 6, 9}) {
    auto png = dm::encodePng(*img, level);
    ASSERT_TRUE(png) << "level " << level << ": " << png.error();
    auto back = dm::parsePng(*png, "level");
    ASSERT_TRUE(back) << back.error();
    expectSamePixels<std::uint8_t>(*img, *back);
  }
  for (int level : {-2, 10}) {
    auto png = dm::encodePng(*img, level);
    ASSERT_FALSE(png);
    EXPECT_EQ(png.error().code, dm::ErrorCode::InvalidArgument);
    EXPECT_NE(png.error().what.find(std::to_string(level)), std::string::npos);
  }
}

TEST(Png, FloatImagesAreRefusedOnWrite) {
  auto img = dm::Image::create(4, 4, 1, dm::PixelType::F32);
  ASSERT_TRUE(img);
  auto png = dm::encodePng(*img);
  ASSERT_FALSE(png);
  EXPECT_EQ(png.error().code, dm::ErrorCode::Unsupported);
  EXPECT_NE(png.error().what.find("float"), std::string::npos);
  auto s = dm::writePng(*img, std::filesystem::temp_directory_path() / "dm_never_written.png");
  ASSERT_FALSE(s);
  EXPECT_NE(s.error().message().find("dm_never_written.png"), std::string::npos);
  EXPECT_FALSE(dm::encodePng(dm::Image{}));
}

struct RealPng {
  const char* name;
  int width, height, channels;
  std::uint64_t sum, weightedSum;
  std::array<int, 4> third;  ///< pixel (w/3, h/4)
};

TEST(Png, RealFilesMatchAnIndependentDecoder) {
  // Expected values from a separate decoder (Python zlib + the specification's
  // unfilter and palette expansion), not from this code.
  const RealPng files[] = {
      {"box.png", 324, 223, 1, 9548299, 343301636059ull, {193}},                               // gray
      {"imageTextN.png", 556, 257, 3, 99731864, 21328144263885ull, {3, 1, 4}},                 // palette
      {"mask.png", 128, 128, 2, 5100782, 83692726986ull, {0, 255}},                            // gray + alpha
      {"opencv-logo-white.png", 180, 238, 4, 12689206, 1225832599947ull, {255, 42, 68, 255}},  // RGBA
      {"pic1.png", 400, 300, 3, 55492143, 10359821030107ull, {1, 1, 1}},                       // RGB
  };
  for (const RealPng& f : files) {
    SCOPED_TRACE(f.name);
    auto path = dm::FileSystem::global().resolve(std::string("opencv:") + f.name);
    ASSERT_TRUE(path) << path.error() << " (scripts/setup.sh installs opencv-doc)";
    auto img = dm::readPng(*path);
    ASSERT_TRUE(img) << img.error();
    EXPECT_EQ(img->width(), f.width);
    EXPECT_EQ(img->height(), f.height);
    ASSERT_EQ(img->channels(), f.channels);
    EXPECT_EQ(img->type(), dm::PixelType::U8);
    std::uint64_t sum = 0;
    for (int y = 0; y < img->height(); ++y)
      for (int x = 0; x < img->width(); ++x)
        for (int c = 0; c < img->channels(); ++c) sum += img->at<std::uint8_t>(x, y, c);
    EXPECT_EQ(sum, f.sum);
    EXPECT_EQ(weightedSum(*img), f.weightedSum);
    for (int c = 0; c < f.channels; ++c)
      EXPECT_EQ(img->at<std::uint8_t>(f.width / 3, f.height / 4, c), f.third[c]);
    // Our encoder and decoder preserve it exactly.
    auto again = dm::encodePng(*img);
    ASSERT_TRUE(again) << again.error();
    auto back = dm::parsePng(*again, "re-encoded");
    ASSERT_TRUE(back) << back.error();
    EXPECT_EQ(weightedSum(*back), f.weightedSum);
  }
}

TEST(Png, PaletteWithTransparencyAndTwoBitIndicesExpandsToRgba) {
  // 4x2 image, 2-bit indices: row 0 = 0 1 2 3, row 1 = 3 2 1 0.
  const std::vector<std::uint8_t> scan = {0, 0b00011011, 0, 0b11100100};
  const std::vector<std::uint8_t> plte = {10, 20, 30, 40, 50, 60, 70, 80, 90, 200, 210, 220};
  const std::vector<std::uint8_t> trns = {0, 128};  // entries 2, 3 stay opaque
  auto img = dm::parsePng(makePng(4, 2, 2, 3, 0, scan, {{"PLTE", plte}, {"tRNS", trns}}), "palette");
  ASSERT_TRUE(img) << img.error();
  ASSERT_EQ(img->channels(), 4);
  const int idx[2][4] = {{0, 1, 2, 3}, {3, 2, 1, 0}};
  const int alpha[4] = {0, 128, 255, 255};
  for (int y = 0; y < 2; ++y)
    for (int x = 0; x < 4; ++x) {
      for (int c = 0; c < 3; ++c) EXPECT_EQ(img->at<std::uint8_t>(x, y, c), plte[3 * idx[y][x] + c]);
      EXPECT_EQ(img->at<std::uint8_t>(x, y, 3), alpha[idx[y][x]]);
    }
}

TEST(Png, OneBitGrayScalesToFullRange) {
  // 10x1, bits 1010011100 -> 255 0 255 0 0 255 255 255 0 0.
  auto img = dm::parsePng(makePng(10, 1, 1, 0, 0, {0, 0b10100111, 0b00000000}), "1bit");
  ASSERT_TRUE(img) << img.error();
  ASSERT_EQ(img->channels(), 1);
  const int expected[10] = {255, 0, 255, 0, 0, 255, 255, 255, 0, 0};
  for (int x = 0; x < 10; ++x) EXPECT_EQ(img->at<std::uint8_t>(x, 0), expected[x]) << x;
}

TEST(Png, Adam7InterlacedFileIsDeinterlaced) {
  constexpr int kW = 13, kH = 9;
  auto value = [](int x, int y) { return static_cast<std::uint8_t>(7 * x + 31 * y + 3); };
  // Adam7 passes: start x, start y, step x, step y (PNG specification, 8.2).
  const int passes[7][4] = {{0, 0, 8, 8}, {4, 0, 8, 8}, {0, 4, 4, 8}, {2, 0, 4, 4},
                            {0, 2, 2, 4}, {1, 0, 2, 2}, {0, 1, 1, 2}};
  std::vector<std::uint8_t> scan;
  for (const auto& p : passes)
    for (int y = p[1]; y < kH; y += p[3]) {
      if (p[0] >= kW) break;
      scan.push_back(0);  // filter: none
      for (int x = p[0]; x < kW; x += p[2]) scan.push_back(value(x, y));
    }
  auto img = dm::parsePng(makePng(kW, kH, 8, 0, 1, scan), "adam7");
  ASSERT_TRUE(img) << img.error();
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) ASSERT_EQ(img->at<std::uint8_t>(x, y), value(x, y)) << x << "," << y;
}

TEST(Png, GrayWithColourKeyGainsAlpha) {
  const std::vector<std::uint8_t> scan = {0, 5, 9, 5};
  auto img = dm::parsePng(makePng(3, 1, 8, 0, 0, scan, {{"tRNS", {0, 9}}}), "key");
  ASSERT_TRUE(img) << img.error();
  ASSERT_EQ(img->channels(), 2);
  EXPECT_EQ(img->at<std::uint8_t>(0, 0, 1), 255);
  EXPECT_EQ(img->at<std::uint8_t>(1, 0, 1), 0);
  EXPECT_EQ(img->at<std::uint8_t>(1, 0, 0), 9);
}

Bytes sampleFile() {
  auto img = dm::Image::create(64, 48, 3, dm::PixelType::U8);
  fillPattern<std::uint8_t>(*img);
  return *dm::encodePng(*img);
}

TEST(Png, TruncatedDataFailsNamingTheSource) {
  const Bytes full = sampleFile();
  ASSERT_TRUE(dm::parsePng(full, "full"));
  for (std::size_t keep : {std::size_t{0}, std::size_t{7}, std::size_t{20}, std::size_t{40}, full.size() / 2,
                           full.size() - 13, full.size() - 1}) {
    SCOPED_TRACE(keep);
    auto r = dm::parsePng(std::span(full).first(keep), "cut.png");
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().code, dm::ErrorCode::Parse);
    EXPECT_NE(r.error().where.find("cut.png"), std::string::npos);
    EXPECT_FALSE(r.error().what.empty());
  }
}

TEST(Png, BadCrcIsReportedByLibpng) {
  Bytes bytes = sampleFile();
  // The first IDAT follows signature (8) + IHDR (25); flip a bit of its CRC.
  ASSERT_EQ(std::memcmp(bytes.data() + 37, "IDAT", 4), 0);
  const std::size_t crcAt = 41 + be32(bytes, 33);
  ASSERT_LT(crcAt + 4, bytes.size());
  bytes[crcAt + 2] ^= std::byte{0x40};
  auto r = dm::parsePng(bytes, "crc.png");
  ASSERT_FALSE(r);
  EXPECT_EQ(r.error().code, dm::ErrorCode::Parse);
  EXPECT_NE(r.error().what.find("CRC"), std::string::npos) << r.error();
  EXPECT_NE(r.error().where.find("crc.png"), std::string::npos);
  // Corrupt compressed data is zlib's complaint, passed on.
  Bytes data = sampleFile();
  data[45] ^= std::byte{0x40};
  auto z = dm::parsePng(data, "zlib.png");
  ASSERT_FALSE(z);
  EXPECT_NE(z.error().what.find("IDAT"), std::string::npos) << z.error();
  // A corrupt IHDR CRC fails in the header.
  Bytes header = sampleFile();
  header[29] ^= std::byte{1};
  auto h = dm::parsePng(header, "ihdr.png");
  ASSERT_FALSE(h);
  EXPECT_NE(h.error().what.find("CRC"), std::string::npos) << h.error();
}

TEST(Png, HugeDimensionsFailFromTheHeaderBeforeAllocating) {
  // 60000 x 60000 RGBA: 3.6 G pixels, over the default pixel limit.
  auto huge = dm::parsePng(makePng(60000, 60000, 8, 6, 0, {0, 0, 0, 0, 0}), "huge.png");
  ASSERT_FALSE(huge);
  EXPECT_EQ(huge.error().code, dm::ErrorCode::InvalidArgument);
  EXPECT_NE(huge.error().what.find("60000x60000"), std::string::npos) << huge.error();
  // 16000 x 16000 RGBA (1 GB) fits the limits but a 60-byte file cannot hold it.
  auto big = dm::parsePng(makePng(16000, 16000, 8, 6, 0, {0, 0, 0, 0, 0}), "big.png");
  ASSERT_FALSE(big);
  EXPECT_EQ(big.error().code, dm::ErrorCode::Parse);
  EXPECT_NE(big.error().what.find("cannot hold"), std::string::npos) << big.error();
  // Tight caller limits apply too.
  auto small = dm::parsePng(sampleFile(), "limited.png", {.maxPixels = 100});
  ASSERT_FALSE(small);
  EXPECT_NE(small.error().hint.find("maxPixels"), std::string::npos);
  auto bytes = dm::parsePng(sampleFile(), "limited.png", {.maxBytes = 1000});
  ASSERT_FALSE(bytes);
  EXPECT_NE(bytes.error().hint.find("maxBytes"), std::string::npos);
}

TEST(Png, NonPngBytesAreRejected) {
  const char gif[] = "GIF89a\x01\x00\x01\x00\x00\x00\x00;";
  auto r = dm::parsePng(std::as_bytes(std::span(gif)), "image.gif");
  ASSERT_FALSE(r);
  EXPECT_EQ(r.error().code, dm::ErrorCode::Parse);
  EXPECT_NE(r.error().what.find("not a PNG"), std::string::npos);
  EXPECT_FALSE(dm::parsePng({}, "empty"));
  // A zero-width IHDR is libpng's to refuse.
  auto zero = dm::parsePng(makePng(0, 4, 8, 0, 0, {0}), "zero.png");
  ASSERT_FALSE(zero);
  EXPECT_NE(zero.error().what.find("libpng"), std::string::npos);
}

}  // namespace
