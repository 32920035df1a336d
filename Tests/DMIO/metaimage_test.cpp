// Tests for dm/io/metaimage.hpp: crafted headers with hand-computed
// geometry (ITK's LPS millimetres -> the SDK's RAS metres) and round trips.
#include <dm/core/filesystem.hpp>
#include <dm/io/metaimage.hpp>
#include <dm/io/volume_io.hpp>

#include <gtest/gtest.h>

#include <unistd.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "../../DMIO/src/gzip.hpp"
#include "../common/temp_dir.hpp"
#include "file_test_support.hpp"

namespace {

namespace fs = std::filesystem;
using Bytes = std::vector<std::byte>;

using dm::test::operator+;
using dm::test::raw;
using dm::test::TempDir;
using dm::test::text;
using dm::test::writeBytes;

TEST(MetaImage, LpsGeometryBecomesRasMetres) {
  // Axis 0 points along LPS +y (posterior), axis 1 along LPS -x (right), axis 2 along +z.
  const std::string h =
      "ObjectType = Image\nNDims = 3\nBinaryData = True\nBinaryDataByteOrderMSB = False\n"
      "TransformMatrix = 0 1 0 -1 0 0 0 0 1\nOffset = 10 -20 30\nElementSpacing = 0.5 2 3\n"
      "DimSize = 2 3 4\nElementType = MET_SHORT\nElementDataFile = LOCAL\n";
  std::vector<std::int16_t> vals(24);
  for (int n = 0; n < 24; ++n) vals[static_cast<std::size_t>(n)] = static_cast<std::int16_t>(n * 100 - 1000);
  auto v = dm::parseMetaImage(text(h) + raw(vals));
  ASSERT_TRUE(v) << v.error();
  EXPECT_EQ(v->type(), dm::VoxelType::I16);
  EXPECT_EQ(v->dims(), dm::Vec3i(2, 3, 4));
  EXPECT_EQ(v->value(1, 2, 3), 23 * 100 - 1000);
  // LPS world of index (i, j, k): Offset + i*0.5*(0,1,0) + j*2*(-1,0,0) + k*3*(0,0,1) mm.
  for (const dm::Vec3& ijk : {dm::Vec3(0, 0, 0), dm::Vec3(1, 0, 0), dm::Vec3(0, 2, 0), dm::Vec3(1, 2, 3)}) {
    const dm::Vec3 lps = dm::Vec3(10, -20, 30) + ijk.x() * dm::Vec3(0, 0.5, 0) +
                         ijk.y() * dm::Vec3(-2, 0, 0) + ijk.z() * dm::Vec3(0, 0, 3);
    const dm::Vec3 ras(-lps.x(), -lps.y(), lps.z());
    EXPECT_TRUE((v->indexToWorld() * ijk).isApprox(ras * 1e-3, 1e-14)) << ijk.transpose();
  }
  EXPECT_TRUE(v->spacing().isApprox(dm::Vec3(0.5e-3, 2e-3, 3e-3)));
}

TEST(MetaImage, SynonymsDefaultsAndTwoDimensions) {
  const std::string h =
      "NDims = 2\nDimSize = 3 2\nElementSize = 0.25 0.5\nPosition = 1 2\nOrientation = 1 0 0 1\n"
      "ElementType = MET_UCHAR\nElementDataFile = LOCAL\n";
  auto v = dm::parseMetaImage(text(h) + raw(std::vector<std::uint8_t>{1, 2, 3, 4, 5, 6}));
  ASSERT_TRUE(v) << v.error();
  EXPECT_EQ(v->dims(), dm::Vec3i(3, 2, 1));
  EXPECT_EQ(v->value(2, 1, 0), 6);
  EXPECT_TRUE(v->indexToWorld().translation().isApprox(dm::Vec3(-1e-3, -2e-3, 0)));
  EXPECT_TRUE(v->spacing().isApprox(dm::Vec3(0.25e-3, 0.5e-3, 1e-3)));
}

TEST(MetaImage, BigEndianAndSixtyFourBitTypes) {
  const std::string h =
      "NDims = 3\nDimSize = 2 1 1\nElementByteOrderMSB = True\nElementType = MET_FLOAT\nElementDataFile = "
      "LOCAL\n";
  auto v = dm::parseMetaImage(text(h) + raw(std::vector<float>{3.5f, -1e-20f}, true));
  ASSERT_TRUE(v) << v.error();
  EXPECT_EQ(v->valueAt(0), 3.5);
  EXPECT_EQ(v->valueAt(1), static_cast<double>(-1e-20f));
  const std::string h64 = "NDims = 1\nDimSize = 2\nElementType = MET_LONG_LONG\nElementDataFile = LOCAL\n";
  auto w = dm::parseMetaImage(text(h64) + raw(std::vector<std::int64_t>{-5, std::int64_t{1} << 40}));
  ASSERT_TRUE(w) << w.error();
  EXPECT_EQ(w->type(), dm::VoxelType::F64);
  EXPECT_EQ(w->valueAt(0), -5.0);
  EXPECT_EQ(w->valueAt(1), std::ldexp(1.0, 40));
}

TEST(MetaImage, CompressedLocalDataAndVolumeIndex) {
  std::vector<std::uint16_t> vals{1, 2, 3, 4, 5, 6, 7, 8};
  auto z = dm::detail::deflate(raw(vals), dm::detail::CompressFormat::Zlib);
  ASSERT_TRUE(z);
  const std::string h =
      "NDims = 4\nDimSize = 2 1 1 4\nElementType = MET_USHORT\nCompressedData = True\n"
      "CompressedDataSize = " +
      std::to_string(z->size()) + "\nElementDataFile = LOCAL\n";
  auto v = dm::parseMetaImage(text(h) + *z, "<memory>", {.volumeIndex = 3});
  ASSERT_TRUE(v) << v.error();
  EXPECT_EQ(v->dims(), dm::Vec3i(2, 1, 1));
  EXPECT_EQ(v->valueAt(0), 7);
  EXPECT_EQ(v->valueAt(1), 8);
  auto bad = dm::parseMetaImage(text(h) + *z, "<memory>", {.volumeIndex = 4});
  ASSERT_FALSE(bad);
  EXPECT_EQ(bad.error().code, dm::ErrorCode::InvalidArgument);
}

TEST(MetaImage, DetachedDataWithHeaderSize) {
  TempDir dir("detached");
  const Bytes data = raw(std::vector<std::int32_t>{-1, 2, -3, 4});
  writeBytes(dir / "skip.raw", text("JUNKJUNK") + data);
  writeBytes(dir / "skip.mhd", text("NDims = 3\nDimSize = 2 2 1\nElementType = MET_INT\nHeaderSize = 8\n"
                                    "ElementDataFile = skip.raw\n"));
  auto v = dm::readVolume(dir / "skip.mhd");
  ASSERT_TRUE(v) << v.error();
  EXPECT_EQ(v->value(1, 1, 0), 4);
  // HeaderSize = -1: the voxels are the file's last bytes.
  writeBytes(dir / "tail.mhd", text("NDims = 3\nDimSize = 2 2 1\nElementType = MET_INT\nHeaderSize = -1\n"
                                    "ElementDataFile = skip.raw\n"));
  auto t = dm::readMetaImage(dir / "tail.mhd");
  ASSERT_TRUE(t) << t.error();
  EXPECT_EQ(t->value(0, 1, 0), -3);
  // Missing data file: the error names it and the header.
  writeBytes(dir / "lost.mhd",
             text("NDims = 3\nDimSize = 2 2 1\nElementType = MET_INT\nElementDataFile = gone.raw\n"));
  auto lost = dm::readMetaImage(dir / "lost.mhd");
  ASSERT_FALSE(lost);
  EXPECT_NE(lost.error().message().find("gone.raw"), std::string::npos) << lost.error();
  EXPECT_NE(lost.error().message().find("lost.mhd"), std::string::npos) << lost.error();
}

dm::Affine3 obliqueAffine() {
  dm::Affine3 a = dm::Affine3::Identity();
  a.linear() = dm::AngleAxis(-1.1, dm::Vec3(0.3, 1, -0.2).normalized()).toRotationMatrix() *
               dm::Vec3(0.7e-3, 1.3e-3, -2.1e-3).asDiagonal();
  a.translation() = dm::Vec3(0.0123, -0.0456, 0.0789);
  return a;
}

template <class T>
void fill(dm::Volume& v) {
  using L = std::numeric_limits<T>;
  const double s[] = {static_cast<double>(L::lowest()), static_cast<double>(L::max()), 0, 17, -3};
  for (std::size_t n = 0; n < v.voxelCount(); ++n) v.setValueAt(n, s[n % 5]);
}

void fillAny(dm::Volume& v) {
  switch (v.type()) {
    case dm::VoxelType::U8:
      fill<std::uint8_t>(v);
      break;
    case dm::VoxelType::I8:
      fill<std::int8_t>(v);
      break;
    case dm::VoxelType::U16:
      fill<std::uint16_t>(v);
      break;
    case dm::VoxelType::I16:
      fill<std::int16_t>(v);
      break;
    case dm::VoxelType::U32:
      fill<std::uint32_t>(v);
      break;
    case dm::VoxelType::I32:
      fill<std::int32_t>(v);
      break;
    case dm::VoxelType::F32:
      fill<float>(v);
      break;
    case dm::VoxelType::F64:
      fill<double>(v);
      break;
  }
}

TEST(MetaImage, RoundTripEveryTypeMhaAndMhd) {
  TempDir dir("roundtrip");
  for (auto type : {dm::VoxelType::U8, dm::VoxelType::I8, dm::VoxelType::U16, dm::VoxelType::I16,
                    dm::VoxelType::U32, dm::VoxelType::I32, dm::VoxelType::F32, dm::VoxelType::F64}) {
    auto v = dm::Volume::create({4, 3, 5}, type, obliqueAffine());
    ASSERT_TRUE(v);
    fillAny(*v);
    for (const char* name : {"a.mha", "b.mhd"}) {
      for (bool compress : {false, true}) {
        SCOPED_TRACE(std::string(dm::toString(type)) + " " + name + (compress ? " compressed" : ""));
        ASSERT_TRUE(dm::writeMetaImage(*v, dir / name, {.compress = compress}));
        auto back = dm::readVolume(dir / name);
        ASSERT_TRUE(back) << back.error();
        EXPECT_EQ(back->type(), type);
        EXPECT_EQ(back->dims(), v->dims());
        ASSERT_EQ(back->byteSize(), v->byteSize());
        EXPECT_EQ(std::memcmp(back->bytes(), v->bytes(), v->byteSize()), 0);
        EXPECT_TRUE(back->indexToWorld().isApprox(v->indexToWorld(), 1e-14));
      }
    }
  }
  EXPECT_TRUE(fs::exists(dir / "b.raw"));
  EXPECT_TRUE(fs::exists(dir / "b.zraw"));
  EXPECT_FALSE(dm::writeMetaImage(dm::Volume(), dir / "empty.mha"));
  auto v = dm::Volume::create({1, 1, 1}, dm::VoxelType::U8);
  EXPECT_FALSE(dm::writeMetaImage(*v, dir / "wrong.txt"));
}

// ---------------------------------------------------------------- bad input

void expectError(const std::string& header, const Bytes& data, const std::string& needle,
                 dm::ErrorCode code = dm::ErrorCode::Parse) {
  auto v = dm::parseMetaImage(text(header) + data);
  ASSERT_FALSE(v) << "expected an error naming " << needle;
  EXPECT_EQ(v.error().code, code) << v.error();
  EXPECT_EQ(v.error().where, "<memory>");
  EXPECT_NE(v.error().message().find(needle), std::string::npos) << v.error();
}

const std::string kTail = "ElementType = MET_UCHAR\nElementDataFile = LOCAL\n";
using dm::test::kEight;

TEST(MetaImageBadInput, MissingOrMalformedKeys) {
  expectError("DimSize = 2 2 2\n" + kTail, kEight, "NDims");
  expectError("NDims = 3\n" + kTail, kEight, "DimSize");
  expectError("NDims = 3\nDimSize = 2 2 2\nElementDataFile = LOCAL\n", kEight, "ElementType");
  expectError("NDims = 3\nDimSize = 2 2\n" + kTail, kEight, "DimSize (line 2)");
  expectError("NDims = 3\nDimSize = 2 2 2 2\n" + kTail, kEight, "DimSize");
  expectError("NDims = 3\nDimSize = 2 0 2\n" + kTail, kEight, "DimSize");
  expectError("NDims = 3\nDimSize = 2 x 2\n" + kTail, kEight, "not a number");
  expectError("NDims = 9\nDimSize = 2 2 2\n" + kTail, kEight, "NDims", dm::ErrorCode::Unsupported);
  expectError("NDims = 3\nDimSize = 2 2 2\nElementType = MET_QUUX\nElementDataFile = LOCAL\n", kEight,
              "MET_QUUX");
  expectError("NDims = 3\nNDims = 3\nDimSize = 2 2 2\n" + kTail, kEight, "twice");
  expectError("NDims = 3\nthis line has no equals sign\n" + kTail, kEight, "line 2");
  expectError("NDims = 3\nDimSize = 2 2 2\nBinaryDataByteOrderMSB = maybe\n" + kTail, kEight,
              "True or False");
}

TEST(MetaImageBadInput, NotAHeaderAtAll) {
  Bytes junk(5000);
  std::mt19937 rng(7);
  for (auto& b : junk) b = std::byte(rng() & 0xff);
  auto v = dm::parseMetaImage(junk);
  ASSERT_FALSE(v);
  EXPECT_EQ(v.error().code, dm::ErrorCode::Parse);
  auto empty = dm::parseMetaImage(Bytes{});
  ASSERT_FALSE(empty);
  EXPECT_NE(empty.error().what.find("ElementDataFile"), std::string::npos);
}

TEST(MetaImageBadInput, GeometryErrors) {
  expectError("NDims = 3\nDimSize = 2 2 2\nElementSpacing = 1 0 1\n" + kTail, kEight, "ElementSpacing");
  expectError("NDims = 3\nDimSize = 2 2 2\nElementSpacing = 1 nan 1\n" + kTail, kEight, "ElementSpacing");
  expectError("NDims = 3\nDimSize = 2 2 2\nOffset = 1 inf 1\n" + kTail, kEight, "Offset");
  expectError("NDims = 3\nDimSize = 2 2 2\nTransformMatrix = 1 0 0 1 0 0 0 0 1\n" + kTail, kEight,
              "singular");
  expectError("NDims = 3\nDimSize = 2 2 2\nTransformMatrix = 1 0 0 0 1 0\n" + kTail, kEight,
              "TransformMatrix");
}

TEST(MetaImageBadInput, DataErrors) {
  expectError("NDims = 3\nDimSize = 2 2 2\n" + kTail, Bytes(7), "needs 8");
  expectError("NDims = 3\nDimSize = 30000 30000 30000\n" + kTail, kEight, "holds 8 bytes");
  expectError(
      "NDims = 3\nDimSize = 2 2 2\nElementType = MET_UCHAR\nCompressedData = True\nElementDataFile = LOCAL\n",
      kEight, "compressed");
  expectError("NDims = 3\nDimSize = 2 2 2\nElementType = MET_UCHAR\nElementDataFile = LIST\n", kEight, "LIST",
              dm::ErrorCode::Unsupported);
  expectError("NDims = 3\nDimSize = 2 2 2\nElementType = MET_UCHAR\nElementDataFile = slice%03d.raw 1 8 1\n",
              kEight, "slice", dm::ErrorCode::Unsupported);
  expectError("NDims = 3\nDimSize = 2 2 2\nElementNumberOfChannels = 3\n" + kTail, Bytes(24),
              "single-channel", dm::ErrorCode::Unsupported);
  expectError("NDims = 3\nDimSize = 2 2 2\nElementType = MET_UCHAR\nElementDataFile = other.raw\n", kEight,
              "readMetaImage", dm::ErrorCode::InvalidArgument);
  // A compression bomb: 8 voxels declared, 16 MiB of zeros compressed; inflation stops at 8 bytes.
  auto bomb = dm::detail::deflate(Bytes(std::size_t{16} << 20), dm::detail::CompressFormat::Zlib);
  ASSERT_TRUE(bomb);
  auto v = dm::parseMetaImage(text("NDims = 3\nDimSize = 2 2 2\nElementType = MET_UCHAR\nCompressedData = "
                                   "True\nElementDataFile = LOCAL\n") +
                              *bomb);
  ASSERT_TRUE(v) << v.error();
  EXPECT_EQ(v->byteSize(), 8u);
}

TEST(MetaImageBadInput, RandomCorruptionNeverCrashes) {
  auto vol = dm::Volume::create({3, 2, 2}, dm::VoxelType::I16, obliqueAffine());
  ASSERT_TRUE(vol);
  for (bool compress : {false, true}) {
    auto enc = dm::encodeMetaImage(*vol, {.compress = compress});
    ASSERT_TRUE(enc);
    std::mt19937 rng(99);
    for (int trial = 0; trial < 1500; ++trial) {
      Bytes b = *enc;
      for (int k = 0; k < 3; ++k) b[rng() % b.size()] = std::byte(rng() & 0xff);
      auto v = dm::parseMetaImage(b);
      if (v) {
        EXPECT_LE(v->byteSize(), 1024u);
      }
    }
  }
}

}  // namespace
