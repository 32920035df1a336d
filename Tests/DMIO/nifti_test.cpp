// Tests for dm/io/nifti.hpp. Headers are crafted here byte by byte from the
// NIfTI-1/2 standard's field offsets (not from the reader's tables), and
// real data comes from the mricron-data package.
#include <dm/core/filesystem.hpp>
#include <dm/io/nifti.hpp>
#include <dm/io/volume_io.hpp>

#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "../../DMIO/src/gzip.hpp"  // the library's own zlib helper, to inspect .gz bytes
#include "../common/temp_dir.hpp"
#include "file_test_support.hpp"

namespace {

namespace fs = std::filesystem;
using Bytes = std::vector<std::byte>;

// A NIfTI-1 (348 + 4 bytes) or NIfTI-2 (540 + 4 bytes) single-file header
// with voxel data appended, written in either byte order.
class Nifti {
 public:
  Nifti(int version, bool bigEndian) : v2_(version == 2), big_(bigEndian) {
    bytes_.assign(v2_ ? 544 : 352, std::byte{0});
    put<std::int32_t>(0, v2_ ? 540 : 348);
    if (v2_)
      std::memcpy(bytes_.data() + 4, "n+2\0\r\n\032\n", 8);
    else
      std::memcpy(bytes_.data() + 344, "n+1\0", 4);
    voxOffset(v2_ ? 544 : 352);
    pixdim({1, 1, 1, 1});
    setUnits(2);
  }

  template <class T>
  void put(std::size_t off, T v) {
    std::byte b[sizeof(T)];
    std::memcpy(b, &v, sizeof(T));
    if (big_ != (std::endian::native == std::endian::big)) std::reverse(b, b + sizeof(T));
    std::memcpy(bytes_.data() + off, b, sizeof(T));
  }
  void putInt(std::size_t off1, std::size_t off2, std::int64_t v, bool wideIs64) {
    if (!v2_)
      put<std::int16_t>(off1, static_cast<std::int16_t>(v));
    else if (wideIs64)
      put<std::int64_t>(off2, v);
    else
      put<std::int32_t>(off2, static_cast<std::int32_t>(v));
  }
  void putReal(std::size_t off1, std::size_t off2, double v) {
    if (v2_)
      put<double>(off2, v);
    else
      put<float>(off1, static_cast<float>(v));
  }

  void dims(std::vector<std::int64_t> d) {
    for (std::size_t i = 0; i < 8; ++i) putInt(40 + 2 * i, 16 + 8 * i, i < d.size() ? d[i] : 1, true);
  }
  void datatype(int code, int bitpix) {  // int16 in both versions
    put<std::int16_t>(v2_ ? 12 : 70, static_cast<std::int16_t>(code));
    put<std::int16_t>(v2_ ? 14 : 72, static_cast<std::int16_t>(bitpix));
  }
  void pixdim(std::vector<double> p) {
    for (std::size_t i = 0; i < p.size(); ++i) putReal(76 + 4 * i, 104 + 8 * i, p[i]);
  }
  void voxOffset(std::int64_t off) {
    if (v2_)
      put<std::int64_t>(168, off);
    else
      put<float>(108, static_cast<float>(off));
  }
  void scale(double slope, double inter) {
    putReal(112, 176, slope);
    putReal(116, 184, inter);
  }
  void setUnits(int u) {
    if (v2_)
      put<std::int32_t>(500, u);
    else
      bytes_[123] = std::byte(u);
  }
  void qform(int code, double b, double c, double d, dm::Vec3 offset) {
    putInt(252, 344, code, false);
    putReal(256, 352, b);
    putReal(260, 360, c);
    putReal(264, 368, d);
    for (int i = 0; i < 3; ++i) putReal(268 + 4 * i, 376 + 8 * i, offset[i]);
  }
  void sform(int code, const Eigen::Matrix<double, 3, 4>& rows) {
    putInt(254, 348, code, false);
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 4; ++c) putReal(280 + 16 * r + 4 * c, 400 + 32 * r + 8 * c, rows(r, c));
  }
  template <class T>
  void data(const std::vector<T>& values) {
    for (const T& v : values) {
      const std::size_t off = bytes_.size();
      bytes_.resize(off + sizeof(T));
      put<T>(off, v);
    }
  }
  Bytes& bytes() { return bytes_; }

 private:
  bool v2_, big_;
  Bytes bytes_;
};

Bytes gzip(const Bytes& b) {
  auto z = dm::detail::deflate(b, dm::detail::CompressFormat::Gzip);
  EXPECT_TRUE(z) << z.error();
  return *z;
}

float floatAt(const Bytes& b, std::size_t off) {
  float f;
  std::memcpy(&f, b.data() + off, 4);
  return f;
}

using dm::test::mricron;
using dm::test::TempDir;
using dm::test::writeBytes;

// ---------------------------------------------------------------- real data

TEST(Nifti, Colin27AffineEqualsRawSformInMetres) {
  const fs::path path = mricron("ch2.nii.gz");
  ASSERT_FALSE(path.empty());
  auto gz = dm::readFile(path);
  ASSERT_TRUE(gz) << gz.error();
  auto raw = dm::detail::inflate(*gz, std::numeric_limits<std::size_t>::max(), path.string());
  ASSERT_TRUE(raw) << raw.error();
  ASSERT_GE(raw->size(), 352u);

  auto v = dm::readNifti(path);
  ASSERT_TRUE(v) << v.error();
  EXPECT_EQ(v->dims(), dm::Vec3i(181, 217, 181));
  EXPECT_EQ(v->type(), dm::VoxelType::U8);
  // sform_code (byte 254) is set, so the affine is srow_x/y/z (bytes 280..327) in metres.
  std::int16_t sformCode;
  std::memcpy(&sformCode, raw->data() + 254, 2);
  ASSERT_GT(sformCode, 0);
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 4; ++c)
      EXPECT_EQ(v->indexToWorld().matrix()(r, c),
                static_cast<double>(floatAt(*raw, 280 + 16 * r + 4 * c)) * 1e-3)
          << "row " << r << " col " << c;
  EXPECT_TRUE(v->spacing().isApprox(dm::Vec3::Constant(1e-3), 1e-12));
  // Voxels are the bytes after vox_offset, untouched.
  const float voxOffset = floatAt(*raw, 108);
  ASSERT_EQ(voxOffset, 352.0f);
  ASSERT_EQ(raw->size(), 352u + v->byteSize());
  EXPECT_EQ(std::memcmp(v->bytes(), raw->data() + 352, v->byteSize()), 0);
}

TEST(Nifti, Colin27HalfMillimetreLoads) {
  const fs::path path = mricron("ch2better.nii.gz");
  ASSERT_FALSE(path.empty());
  auto v = dm::readVolume(path);
  ASSERT_TRUE(v) << v.error();
  EXPECT_EQ(v->dims(), dm::Vec3i(301, 370, 316));
  EXPECT_TRUE(v->spacing().isApprox(dm::Vec3::Constant(0.5e-3), 1e-9));
}

// ---------------------------------------------------------------- writer

template <class T>
std::vector<double> sampleValues() {
  using L = std::numeric_limits<T>;
  return {static_cast<double>(L::lowest()), static_cast<double>(L::max()), 0, 1, 42,
          std::is_signed_v<T> ? -7.0 : 7.0};
}

dm::Affine3 obliqueAffine(bool mirrored) {
  dm::Affine3 a = dm::Affine3::Identity();
  const dm::Mat3 r = dm::AngleAxis(0.61, dm::Vec3(1, -2, 0.5).normalized()).toRotationMatrix();
  dm::Vec3 s(0.9e-3, 1.1e-3, 2.5e-3);
  if (mirrored) s.z() = -s.z();
  a.linear() = r * s.asDiagonal();
  a.translation() = dm::Vec3(-0.091, 0.1255, -0.0723);
  return a;
}

template <class T>
void roundTrip(const TempDir& dir, dm::VoxelType type) {
  auto v = dm::Volume::create({5, 4, 3}, type, obliqueAffine(false));
  ASSERT_TRUE(v);
  const std::vector<double> s = sampleValues<T>();
  for (std::size_t n = 0; n < v->voxelCount(); ++n) v->setValueAt(n, s[n % s.size()]);
  for (const char* name : {"rt.nii", "rt.nii.gz"}) {
    SCOPED_TRACE(std::string(dm::toString(type)) + " " + name);
    ASSERT_TRUE(dm::writeNifti(*v, dir / name));
    auto back = dm::readNifti(dir / name);
    ASSERT_TRUE(back) << back.error();
    EXPECT_EQ(back->type(), type);
    EXPECT_EQ(back->dims(), v->dims());
    ASSERT_EQ(back->byteSize(), v->byteSize());
    EXPECT_EQ(std::memcmp(back->bytes(), v->bytes(), v->byteSize()), 0);
    // Stored as float32 millimetres: relative 1e-7.
    EXPECT_LT((back->indexToWorld().matrix() - v->indexToWorld().matrix()).cwiseAbs().maxCoeff(), 1e-8);
  }
}

TEST(Nifti, WriteReadRoundTripsEveryDatatype) {
  TempDir dir("types");
  roundTrip<std::uint8_t>(dir, dm::VoxelType::U8);
  roundTrip<std::int8_t>(dir, dm::VoxelType::I8);
  roundTrip<std::uint16_t>(dir, dm::VoxelType::U16);
  roundTrip<std::int16_t>(dir, dm::VoxelType::I16);
  roundTrip<std::uint32_t>(dir, dm::VoxelType::U32);
  roundTrip<std::int32_t>(dir, dm::VoxelType::I32);
  roundTrip<float>(dir, dm::VoxelType::F32);
  roundTrip<double>(dir, dm::VoxelType::F64);
}

TEST(Nifti, ObliqueAffineSformAndQformAgree) {
  for (bool mirrored : {false, true}) {
    SCOPED_TRACE(mirrored ? "det < 0 (qfac -1)" : "det > 0");
    auto v = dm::Volume::create({6, 7, 8}, dm::VoxelType::I16, obliqueAffine(mirrored));
    ASSERT_TRUE(v);
    auto bytes = dm::encodeNifti(*v);
    ASSERT_TRUE(bytes) << bytes.error();
    auto h = dm::parseNiftiHeader(*bytes);
    ASSERT_TRUE(h) << h.error();
    EXPECT_STREQ(h->affineSource, "sform");
    EXPECT_EQ(h->pixdim[0], mirrored ? -1.0 : 1.0);
    // Force the qform: sform_code (byte 254) = 0.
    (*bytes)[254] = std::byte{0};
    (*bytes)[255] = std::byte{0};
    auto q = dm::parseNiftiHeader(*bytes);
    ASSERT_TRUE(q) << q.error();
    EXPECT_STREQ(q->affineSource, "qform");
    // Compare in millimetres: the qform equals the affine to 1e-6 mm-relative.
    const dm::Mat4 diffMm = (q->indexToWorld.matrix() - v->indexToWorld().matrix()) * 1e3;
    EXPECT_LT((diffMm.topLeftCorner<3, 3>().cwiseAbs().maxCoeff()), 1e-5);
    EXPECT_LT(diffMm.col(3).cwiseAbs().maxCoeff(), 1e-4);
    auto back = dm::parseNifti(*bytes);
    ASSERT_TRUE(back) << back.error();
    EXPECT_TRUE(back->indexToWorld().isApprox(v->indexToWorld(), 1e-6));
  }
}

TEST(Nifti, WriterRejectsDimsBeyondNifti1) {
  auto v = dm::Volume::create({32768, 1, 1}, dm::VoxelType::U8);
  ASSERT_TRUE(v);
  auto b = dm::encodeNifti(*v);
  ASSERT_FALSE(b);
  EXPECT_EQ(b.error().code, dm::ErrorCode::Unsupported);
  EXPECT_NE(b.error().what.find("32767"), std::string::npos);
  EXPECT_FALSE(dm::encodeNifti(dm::Volume()));
}

// ---------------------------------------------------------------- orientation

TEST(Nifti, QformOnlyMatchesEigenRotation) {
  const dm::Quat q(dm::AngleAxis(0.7, dm::Vec3(1, 2, 3).normalized()));
  const dm::Vec3 spacing(0.8, 1.2, 2.5);
  const dm::Vec3 offset(-40.5, 12.25, 63.0);
  for (double qfac : {1.0, -1.0}) {
    SCOPED_TRACE(qfac);
    Nifti n(1, false);
    n.dims({3, 2, 2, 2});
    n.datatype(2, 8);
    n.pixdim({qfac, spacing.x(), spacing.y(), spacing.z()});
    n.qform(1, q.x(), q.y(), q.z(), offset);
    n.data(std::vector<std::uint8_t>(8, 1));
    auto v = dm::parseNifti(n.bytes());
    ASSERT_TRUE(v) << v.error();
    const dm::Mat3 r = q.toRotationMatrix();
    const dm::Vec3 ijk(1, 0, 1);
    const dm::Vec3 expectedMm =
        r * dm::Vec3(ijk.x() * spacing.x(), ijk.y() * spacing.y(), qfac * ijk.z() * spacing.z()) + offset;
    // quatern_b/c/d are float32: rotation accurate to ~1e-7.
    EXPECT_LT((v->indexToWorld() * ijk - expectedMm * 1e-3).norm(), 1e-9);
    EXPECT_NEAR(v->indexToWorld().linear().determinant(), qfac * spacing.prod() * 1e-9, 1e-15);
  }
}

TEST(Nifti, QformHalfTurnHasZeroScalarPart) {
  // b = 0, c = 1, d = 0: a = 0, a 180° turn about y: x -> -x, z -> -z.
  Nifti n(1, false);
  n.dims({3, 2, 2, 2});
  n.datatype(2, 8);
  n.pixdim({1, 2, 3, 4});
  n.qform(2, 0, 1, 0, {0, 0, 0});
  n.data(std::vector<std::uint8_t>(8, 0));
  auto v = dm::parseNifti(n.bytes());
  ASSERT_TRUE(v) << v.error();
  const dm::Mat3 expected = dm::Vec3(-2e-3, 3e-3, -4e-3).asDiagonal();
  EXPECT_TRUE(v->indexToWorld().linear().isApprox(expected, 1e-12));
}

TEST(Nifti, PixdimOnlyAndUnits) {
  for (auto [units, factor] : {std::pair{0, 1e-3}, {1, 1.0}, {2, 1e-3}, {3, 1e-6}, {2 | 8, 1e-3}}) {
    SCOPED_TRACE(units);
    Nifti n(1, false);
    n.dims({3, 1, 1, 1});
    n.datatype(2, 8);
    n.pixdim({0, 0.5, -2, 3});  // negative pixdim used by magnitude
    n.setUnits(units);
    n.data(std::vector<std::uint8_t>{7});
    auto h = dm::parseNiftiHeader(n.bytes());
    ASSERT_TRUE(h) << h.error();
    EXPECT_STREQ(h->affineSource, "pixdim");
    EXPECT_TRUE(
        h->indexToWorld.linear().isApprox(dm::Mat3(dm::Vec3(0.5, 2, 3).asDiagonal()) * factor, 1e-15));
  }
}

TEST(Nifti, SformPreferredOverQform) {
  Nifti n(1, false);
  n.dims({3, 2, 1, 1});
  n.datatype(2, 8);
  n.qform(1, 0, 0, 1, {1, 2, 3});
  Eigen::Matrix<double, 3, 4> rows;
  rows << 0, -2, 0, 10,  //
      3, 0, 0, -20,      //
      0, 0, 4, 30;
  n.sform(2, rows);
  n.data(std::vector<std::uint8_t>{1, 2});
  auto v = dm::parseNifti(n.bytes());
  ASSERT_TRUE(v) << v.error();
  EXPECT_TRUE(v->indexToWorld().matrix().topRows<3>().isApprox(rows * 1e-3, 1e-15));
}

// ---------------------------------------------------------------- datatypes

TEST(Nifti, ScaleSlopeGivesPhysicalValues) {
  {
    Nifti n(1, false);
    n.dims({3, 3, 1, 1});
    n.datatype(4, 16);
    n.scale(0.5, -10);
    n.data(std::vector<std::int16_t>{-100, 0, 3000});
    auto v = dm::parseNifti(n.bytes());
    ASSERT_TRUE(v) << v.error();
    EXPECT_EQ(v->type(), dm::VoxelType::F32);
    EXPECT_EQ(v->valueAt(0), -60.0);
    EXPECT_EQ(v->valueAt(1), -10.0);
    EXPECT_EQ(v->valueAt(2), 1490.0);
  }
  {
    Nifti n(1, false);
    n.dims({3, 2, 1, 1});
    n.datatype(8, 32);
    n.scale(2, 1);
    n.data(std::vector<std::int32_t>{2000000000, -3});
    auto v = dm::parseNifti(n.bytes());
    ASSERT_TRUE(v) << v.error();
    EXPECT_EQ(v->type(), dm::VoxelType::F64);  // int32 * 2 needs double
    EXPECT_EQ(v->valueAt(0), 4000000001.0);
    EXPECT_EQ(v->valueAt(1), -5.0);
  }
  // (1, 0), slope 0 and NaN slope: stored values and type kept.
  for (double slope : {1.0, 0.0, std::numeric_limits<double>::quiet_NaN()}) {
    Nifti n(1, false);
    n.dims({3, 1, 1, 1});
    n.datatype(4, 16);
    n.scale(slope, 0);
    n.data(std::vector<std::int16_t>{-123});
    auto v = dm::parseNifti(n.bytes());
    ASSERT_TRUE(v) << v.error();
    EXPECT_EQ(v->type(), dm::VoxelType::I16);
    EXPECT_EQ(v->valueAt(0), -123.0);
  }
}

TEST(Nifti, SixtyFourBitIntegersBecomeFloat64) {
  Nifti a(1, false);
  a.dims({3, 2, 1, 1});
  a.datatype(1024, 64);
  a.data(std::vector<std::int64_t>{-(std::int64_t{1} << 53), 12345});
  auto v = dm::parseNifti(a.bytes());
  ASSERT_TRUE(v) << v.error();
  EXPECT_EQ(v->type(), dm::VoxelType::F64);
  EXPECT_EQ(v->valueAt(0), -9007199254740992.0);
  EXPECT_EQ(v->valueAt(1), 12345.0);
  Nifti b(1, true);
  b.dims({3, 1, 1, 1});
  b.datatype(1280, 64);
  b.data(std::vector<std::uint64_t>{std::uint64_t{1} << 60});
  auto w = dm::parseNifti(b.bytes());
  ASSERT_TRUE(w) << w.error();
  EXPECT_EQ(w->valueAt(0), std::ldexp(1.0, 60));
}

TEST(Nifti, UnsupportedDatatypesNameTheCode) {
  for (auto [code, bitpix, name] :
       {std::tuple{128, 24, "RGB24"}, {32, 64, "complex64"}, {2304, 32, "RGBA32"}}) {
    Nifti n(1, false);
    n.dims({3, 1, 1, 1});
    n.datatype(code, bitpix);
    n.data(std::vector<std::uint8_t>(static_cast<std::size_t>(bitpix / 8), 0));
    auto v = dm::parseNifti(n.bytes());
    ASSERT_FALSE(v);
    EXPECT_EQ(v.error().code, dm::ErrorCode::Unsupported);
    EXPECT_NE(v.error().what.find(std::to_string(code)), std::string::npos) << v.error();
    EXPECT_NE(v.error().what.find(name), std::string::npos) << v.error();
  }
}

TEST(Nifti, BigEndianFileIsSwapped) {
  Nifti n(1, true);
  n.dims({3, 2, 2, 1});
  n.datatype(16, 32);
  n.pixdim({1, 1.5, 1.5, 3});
  n.data(std::vector<float>{1.5f, -2.25f, 1e30f, 0.0f});
  auto h = dm::parseNiftiHeader(n.bytes());
  ASSERT_TRUE(h) << h.error();
  EXPECT_TRUE(h->bigEndian);
  auto v = dm::parseNifti(n.bytes());
  ASSERT_TRUE(v) << v.error();
  EXPECT_EQ(v->dims(), dm::Vec3i(2, 2, 1));
  EXPECT_EQ(v->value(0, 0, 0), 1.5);
  EXPECT_EQ(v->value(1, 0, 0), -2.25);
  EXPECT_EQ(v->value(0, 1, 0), static_cast<double>(1e30f));
  EXPECT_TRUE(v->spacing().isApprox(dm::Vec3(1.5e-3, 1.5e-3, 3e-3)));
}

TEST(Nifti, Nifti2HeaderWithDoublePrecisionSform) {
  for (bool big : {false, true}) {
    SCOPED_TRACE(big ? "big-endian" : "little-endian");
    Nifti n(2, big);
    n.dims({3, 2, 1, 2});
    n.datatype(64, 64);
    Eigen::Matrix<double, 3, 4> rows;
    rows << 0.1, 0, 0, -12.345678901234,  //
        0, 0.2, 0, 0.7,                   //
        0, 0, 0.3, 1e-3;
    n.sform(1, rows);
    n.data(std::vector<double>{0.1, -0.2, 1e300, 4});
    auto v = dm::parseNifti(n.bytes());
    ASSERT_TRUE(v) << v.error();
    EXPECT_EQ(v->type(), dm::VoxelType::F64);
    EXPECT_EQ(v->dims(), dm::Vec3i(2, 1, 2));
    EXPECT_EQ(v->value(0, 0, 0), 0.1);
    EXPECT_EQ(v->value(0, 0, 1), 1e300);
    // Doubles survive exactly (up to the mm -> m multiplication).
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 4; ++c) EXPECT_EQ(v->indexToWorld().matrix()(r, c), rows(r, c) * 1e-3);
  }
}

TEST(Nifti, FourDimensionalVolumeIndex) {
  Nifti n(1, false);
  n.dims({4, 2, 1, 1, 3});
  n.datatype(512, 16);
  n.data(std::vector<std::uint16_t>{1, 2, 10, 20, 100, 200});
  auto h = dm::parseNiftiHeader(n.bytes());
  ASSERT_TRUE(h);
  EXPECT_EQ(h->volumeCount, 3);
  const Bytes gz = gzip(n.bytes());
  for (const Bytes* b : {static_cast<const Bytes*>(&n.bytes()), &gz}) {
    auto v = dm::parseNifti(*b, "<memory>", {.volumeIndex = 2});
    ASSERT_TRUE(v) << v.error();
    EXPECT_EQ(v->valueAt(0), 100);
    EXPECT_EQ(v->valueAt(1), 200);
    auto bad = dm::parseNifti(*b, "<memory>", {.volumeIndex = 3});
    ASSERT_FALSE(bad);
    EXPECT_EQ(bad.error().code, dm::ErrorCode::InvalidArgument);
    EXPECT_NE(bad.error().what.find("volumeIndex"), std::string::npos);
  }
}

TEST(Nifti, TwoDimensionalImageIsOneSlice) {
  Nifti n(1, false);
  n.dims({2, 3, 2});
  n.datatype(256, 8);
  n.pixdim({1, 0.5, 0.25, 0});  // pixdim[3] unused: 0 is tolerated
  n.data(std::vector<std::int8_t>{-1, -2, -3, 4, 5, 6});
  auto v = dm::parseNifti(n.bytes());
  ASSERT_TRUE(v) << v.error();
  EXPECT_EQ(v->dims(), dm::Vec3i(3, 2, 1));
  EXPECT_EQ(v->value(2, 1, 0), 6);
  EXPECT_EQ(v->value(0, 0, 0), -1);
}

TEST(Nifti, HdrImgPairAndReadVolume) {
  TempDir dir("pair");
  Nifti n(1, false);
  n.dims({3, 2, 2, 1});
  n.datatype(4, 16);
  std::memcpy(n.bytes().data() + 344, "ni1\0", 4);
  n.voxOffset(0);
  Bytes hdr(n.bytes().begin(), n.bytes().begin() + 348);
  Bytes img(8);
  const std::int16_t vals[4] = {-5, 6, -7, 8};
  std::memcpy(img.data(), vals, 8);
  writeBytes(dir / "pair.hdr", hdr);
  writeBytes(dir / "pair.img", img);
  for (const char* name : {"pair.hdr", "pair.img"}) {
    auto v = dm::readVolume(dir / name);
    ASSERT_TRUE(v) << v.error();
    EXPECT_EQ(v->value(1, 1, 0), 8);
    EXPECT_EQ(v->value(0, 1, 0), -7);
  }
  // The same header through the single-file API is refused clearly.
  auto single = dm::parseNifti(hdr);
  ASSERT_FALSE(single);
  EXPECT_NE(single.error().what.find(".hdr/.img"), std::string::npos);
  fs::remove(dir / "pair.img");
  auto missing = dm::readNifti(dir / "pair.hdr");
  ASSERT_FALSE(missing);
  EXPECT_EQ(missing.error().code, dm::ErrorCode::NotFound);
  EXPECT_NE(missing.error().what.find("pair.img"), std::string::npos);
}

TEST(Nifti, GzipDetectedByContentNotExtension) {
  TempDir dir("gzname");
  Nifti n(1, false);
  n.dims({3, 2, 1, 1});
  n.datatype(2, 8);
  n.data(std::vector<std::uint8_t>{9, 8});
  writeBytes(dir / "compressed_but_named.nii", gzip(n.bytes()));
  writeBytes(dir / "plain_but_named.nii.gz", n.bytes());
  for (const char* name : {"compressed_but_named.nii", "plain_but_named.nii.gz"}) {
    auto v = dm::readNifti(dir / name);
    ASSERT_TRUE(v) << v.error();
    EXPECT_EQ(v->valueAt(1), 8);
  }
}

// ---------------------------------------------------------------- bad input

Nifti validHeader() {
  Nifti n(1, false);
  n.dims({3, 2, 2, 2});
  n.datatype(2, 8);
  n.data(std::vector<std::uint8_t>(8, 3));
  return n;
}

// The error must be a Parse (or given) error naming "<memory>" and `field`.
void expectError(const Bytes& b, const std::string& field, dm::ErrorCode code = dm::ErrorCode::Parse) {
  auto v = dm::parseNifti(b);
  ASSERT_FALSE(v) << "expected an error naming " << field;
  EXPECT_EQ(v.error().code, code) << v.error();
  EXPECT_EQ(v.error().where, "<memory>");
  EXPECT_NE(v.error().message().find(field), std::string::npos) << v.error();
}

TEST(NiftiBadInput, TruncatedHeader) {
  Nifti n = validHeader();
  expectError(Bytes(n.bytes().begin(), n.bytes().begin() + 200), "truncated header");
  expectError(Bytes(n.bytes().begin(), n.bytes().begin() + 2), "truncated header");
  expectError(Bytes{}, "truncated header");
}

TEST(NiftiBadInput, WrongSizeofHdr) {
  Nifti n = validHeader();
  n.put<std::int32_t>(0, 347);
  expectError(n.bytes(), "sizeof_hdr");
}

TEST(NiftiBadInput, BadMagic) {
  Nifti n = validHeader();
  std::memcpy(n.bytes().data() + 344, "n+9\0", 4);
  expectError(n.bytes(), "magic");
  Nifti n2(2, false);
  n2.dims({3, 1, 1, 1});
  n2.datatype(2, 8);
  n2.data(std::vector<std::uint8_t>{1});
  n2.bytes()[8] = std::byte{0x0a};  // the "\r" of the magic lost to a line-ending conversion
  expectError(n2.bytes(), "magic");
}

TEST(NiftiBadInput, NonPositiveOrOverflowingDims) {
  Nifti a = validHeader();
  a.dims({3, 2, 0, 2});
  expectError(a.bytes(), "dim[2]");
  Nifti b = validHeader();
  b.dims({9, 2, 2, 2});
  expectError(b.bytes(), "dim[0]");
  Nifti c = validHeader();
  c.dims({3, 2, -5, 2});
  expectError(c.bytes(), "dim[2]");
  Nifti d(2, false);  // NIfTI-2: 64-bit dims
  d.dims({3, std::int64_t{1} << 30, std::int64_t{1} << 30, std::int64_t{1} << 30});
  d.datatype(2, 8);
  expectError(d.bytes(), "dim");
  Nifti e(2, false);
  e.dims({3, std::int64_t{1} << 40, 1, 1});
  e.datatype(2, 8);
  expectError(e.bytes(), "dim[1]", dm::ErrorCode::Unsupported);
}

TEST(NiftiBadInput, DataPastEndOfFile) {
  Nifti n = validHeader();
  Bytes cut(n.bytes().begin(), n.bytes().end() - 1);
  expectError(cut, "past the end");
  expectError(cut, "vox_offset 352");
  Nifti far = validHeader();
  far.voxOffset(1 << 20);
  expectError(far.bytes(), "past the end");
  // Huge dims with a tiny file: refused before any allocation.
  Nifti huge = validHeader();
  huge.dims({3, 30000, 30000, 30000});
  expectError(huge.bytes(), "past the end");
}

TEST(NiftiBadInput, VoxOffsetInsideHeader) {
  Nifti n = validHeader();
  n.voxOffset(100);
  expectError(n.bytes(), "vox_offset");
  Nifti f = validHeader();
  f.put<float>(108, 352.5f);
  expectError(f.bytes(), "vox_offset");
}

TEST(NiftiBadInput, BadPixdim) {
  for (double p : {0.0, std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity()}) {
    Nifti n = validHeader();
    n.pixdim({1, 1, p, 1});
    expectError(n.bytes(), "pixdim[2]");
    Nifti q = validHeader();  // the qform needs pixdim too
    q.qform(1, 0, 0, 0, {0, 0, 0});
    q.pixdim({1, p, 1, 1});
    expectError(q.bytes(), "pixdim[1]");
  }
}

TEST(NiftiBadInput, NonFiniteOrSingularSform) {
  Eigen::Matrix<double, 3, 4> rows = Eigen::Matrix<double, 3, 4>::Identity();
  rows(1, 2) = std::numeric_limits<double>::quiet_NaN();
  Nifti a = validHeader();
  a.sform(1, rows);
  expectError(a.bytes(), "srow_y");
  rows.setIdentity();
  rows(2, 3) = std::numeric_limits<double>::infinity();
  Nifti b = validHeader();
  b.sform(1, rows);
  expectError(b.bytes(), "srow_z");
  rows.setIdentity();
  rows.row(2) = rows.row(0);  // collinear
  Nifti c = validHeader();
  c.sform(1, rows);
  expectError(c.bytes(), "singular");
  expectError(c.bytes(), "srow");
}

TEST(NiftiBadInput, BadQuaternion) {
  Nifti n = validHeader();
  n.qform(1, 0.9, 0.9, 0, {0, 0, 0});
  expectError(n.bytes(), "quatern");
  Nifti m = validHeader();
  m.qform(1, std::numeric_limits<double>::quiet_NaN(), 0, 0, {0, 0, 0});
  expectError(m.bytes(), "quatern");
}

TEST(NiftiBadInput, UnknownDatatypeAndBitpixMismatch) {
  Nifti a = validHeader();
  a.datatype(99, 8);
  expectError(a.bytes(), "datatype");
  expectError(a.bytes(), "99");
  Nifti b = validHeader();
  b.datatype(4, 8);  // int16 with 8 bits
  expectError(b.bytes(), "bitpix");
}

TEST(NiftiBadInput, GzipBombStopsAtTheHeadersSize) {
  // A valid 2x2x2 header followed by 32 MiB of zeros, gzip'd to ~32 KiB.
  Nifti n = validHeader();
  n.bytes().resize(n.bytes().size() + (std::size_t{32} << 20));
  const Bytes bomb = gzip(n.bytes());
  ASSERT_LT(bomb.size(), std::size_t{1} << 20);
  // The helper never returns more than the cap the reader passes ...
  auto capped = dm::detail::inflate(bomb, 352 + 8, "bomb");
  ASSERT_TRUE(capped) << capped.error();
  EXPECT_EQ(capped->size(), 360u);
  // Skipped output is discarded: the 8 voxel bytes after the 352-byte header.
  auto skipped = dm::detail::inflate(bomb, 8, "bomb", 352);
  ASSERT_TRUE(skipped) << skipped.error();
  ASSERT_EQ(skipped->size(), 8u);
  EXPECT_EQ((*skipped)[7], std::byte{3});
  // ... and the reader loads the 8 voxels it needs.
  auto v = dm::parseNifti(bomb, "bomb.nii.gz");
  ASSERT_TRUE(v) << v.error();
  EXPECT_EQ(v->voxelCount(), 8u);
  // A header claiming more than the stream holds fails after inflating only what exists.
  Nifti liar = validHeader();
  liar.dims({3, 1000, 1000, 1000});
  expectError(gzip(liar.bytes()), "past the end of the decompressed");
  // The volume limit applies before inflating.
  auto limited = dm::parseNifti(gzip(liar.bytes()), "<memory>", {.maxBytes = 1000});
  ASSERT_FALSE(limited);
  EXPECT_NE(limited.error().what.find(
                "1000x1000x1000 voxels of 1 bytes needs 1000000000 bytes, more than the budget "
                "of 1000 bytes"),
            std::string::npos)
      << limited.error();
}

TEST(NiftiBadInput, CorruptOrTruncatedGzip) {
  Bytes gz = gzip(validHeader().bytes());
  Bytes cut(gz.begin(), gz.begin() + static_cast<std::ptrdiff_t>(gz.size() / 2));
  expectError(cut, "truncated");
  Bytes corrupt = gz;
  for (std::size_t i = 12; i < corrupt.size(); i += 3) corrupt[i] = std::byte{0xff};
  auto v = dm::parseNifti(corrupt);
  ASSERT_FALSE(v);
  EXPECT_EQ(v.error().code, dm::ErrorCode::Parse);
}

TEST(NiftiBadInput, ErrorsNameTheFile) {
  TempDir dir("names");
  Nifti n = validHeader();
  n.datatype(99, 8);
  writeBytes(dir / "broken.nii", n.bytes());
  auto v = dm::readNifti(dir / "broken.nii");
  ASSERT_FALSE(v);
  EXPECT_NE(v.error().where.find("broken.nii"), std::string::npos) << v.error();
  EXPECT_NE(v.error().what.find("datatype"), std::string::npos) << v.error();
  auto missing = dm::readNifti(dir / "nope.nii");
  ASSERT_FALSE(missing);
  EXPECT_NE(missing.error().message().find("nope.nii"), std::string::npos);
}

TEST(NiftiBadInput, RandomCorruptionNeverCrashes) {
  // Flip bytes of a valid file many times; every outcome must be a value or an error.
  const Bytes base = validHeader().bytes();
  std::mt19937 rng(1234);
  int errors = 0;
  for (int trial = 0; trial < 2000; ++trial) {
    Bytes b = base;
    for (int k = 0; k < 4; ++k) b[rng() % b.size()] = std::byte(rng() & 0xff);
    auto v = dm::parseNifti(b);
    if (!v)
      ++errors;
    else
      EXPECT_LE(v->byteSize(), 64u);
  }
  EXPECT_GT(errors, 0);
}

}  // namespace
