// Tests for dm/io/nrrd.hpp: crafted headers in every space and encoding with
// hand-computed geometry, and round trips through the writer.
#include <dm/core/filesystem.hpp>
#include <dm/io/nrrd.hpp>
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

std::string header(const std::string& space, const std::string& rest) {
  return "NRRD0004\n# comment\ntype: short\ndimension: 3\nspace: " + space +
         "\nsizes: 2 3 4\nspace directions: (0,1.5,0) (-2,0,0) (0,0,0.5)\nendian: little\n"
         "space origin: (10,-20,30)\nkey:=value: ignored\n" +
         rest + "\n\n";  // the blank line ends the header
}

std::vector<std::int16_t> ramp(int n) {
  std::vector<std::int16_t> v(static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i) v[static_cast<std::size_t>(i)] = static_cast<std::int16_t>(37 * i - 400);
  return v;
}

TEST(Nrrd, SpacesMapToRasMetres) {
  const Bytes data = raw(ramp(24));
  // x, y sign flips from each space to RAS.
  for (auto [space, flip] : {std::pair{"right-anterior-superior", dm::Vec3(1, 1, 1)},
                             {"RAS", dm::Vec3(1, 1, 1)},
                             {"left-posterior-superior", dm::Vec3(-1, -1, 1)},
                             {"LPS", dm::Vec3(-1, -1, 1)},
                             {"left-anterior-superior", dm::Vec3(-1, 1, 1)},
                             {"scanner-xyz", dm::Vec3(1, 1, 1)}}) {
    SCOPED_TRACE(space);
    auto v = dm::parseNrrd(text(header(space, "encoding: raw")) + data);
    ASSERT_TRUE(v) << v.error();
    EXPECT_EQ(v->dims(), dm::Vec3i(2, 3, 4));
    EXPECT_EQ(v->value(1, 2, 3), 37 * 23 - 400);
    for (const dm::Vec3& ijk : {dm::Vec3(0, 0, 0), dm::Vec3(1, 0, 0), dm::Vec3(1, 2, 3)}) {
      const dm::Vec3 file = dm::Vec3(10, -20, 30) + ijk.x() * dm::Vec3(0, 1.5, 0) +
                            ijk.y() * dm::Vec3(-2, 0, 0) + ijk.z() * dm::Vec3(0, 0, 0.5);
      EXPECT_TRUE((v->indexToWorld() * ijk).isApprox(flip.cwiseProduct(file) * 1e-3, 1e-14))
          << ijk.transpose();
    }
  }
}

TEST(Nrrd, EncodingsAgree) {
  const std::vector<std::int16_t> vals = ramp(24);
  auto gz = dm::detail::deflate(raw(vals), dm::detail::CompressFormat::Gzip);
  ASSERT_TRUE(gz);
  std::string ascii, hex;
  for (std::int16_t x : vals) ascii += std::to_string(x) + (x % 3 ? " " : "\n");
  for (std::byte b : raw(vals, true)) {
    char buf[4];
    std::snprintf(buf, sizeof buf, "%02X", static_cast<unsigned>(b));
    hex += buf;
    hex += ' ';
  }
  const std::vector<std::pair<std::string, Bytes>> cases = {
      {header("RAS", "encoding: raw"), raw(vals)},
      {header("RAS", "encoding: gzip"), *gz},
      {header("RAS", "encoding: text"), text(ascii)},
      {"NRRD0004\ntype: int16\ndimension: 3\nsizes: 2 3 4\nendian: big\nencoding: hex\n\n", text(hex)},
      {"NRRD0001\ntype: signed short int\ndimension: 3\nsizes: 2 3 4\nendian: big\nencoding: raw\n\n",
       raw(vals, true)},
  };
  for (const auto& [h, data] : cases) {
    SCOPED_TRACE(h);
    auto v = dm::parseNrrd(text(h) + data);
    ASSERT_TRUE(v) << v.error();
    ASSERT_EQ(v->type(), dm::VoxelType::I16);
    for (std::size_t n = 0; n < vals.size(); ++n) EXPECT_EQ(v->valueAt(n), vals[n]) << n;
  }
}

TEST(Nrrd, SpacingsFallbackUnitsAndTypeSpellings) {
  auto v = dm::parseNrrd(text("NRRD0005\ntype: unsigned char\ndimension: 2\nsizes: 3 2\nspacings: 0.5 2\n"
                              "encoding: raw\n\n") +
                         raw(std::vector<std::uint8_t>{1, 2, 3, 4, 5, 6}));
  ASSERT_TRUE(v) << v.error();
  EXPECT_EQ(v->dims(), dm::Vec3i(3, 2, 1));
  EXPECT_EQ(v->type(), dm::VoxelType::U8);
  // Missing third axis: a 1 mm direction orthogonal to the others.
  EXPECT_TRUE(v->spacing().isApprox(dm::Vec3(0.5e-3, 2e-3, 1e-3)));
  EXPECT_NEAR(std::abs(v->indexToWorld().linear().determinant()), 0.5e-3 * 2e-3 * 1e-3, 1e-18);

  auto m = dm::parseNrrd(
      text("NRRD0004\ntype: long long\ndimension: 3\nspace dimension: 3\nsizes: 1 1 2\n"
           "space directions: (0.001,0,0) (0,0.002,0) (0,0,0.003)\nspace units: \"m\" \"m\" \"m\"\n"
           "space origin: (1,2,3)\nendian: little\nencoding: raw\n\n") +
      raw(std::vector<std::int64_t>{-9, 9}));
  ASSERT_TRUE(m) << m.error();
  EXPECT_EQ(m->type(), dm::VoxelType::F64);
  EXPECT_EQ(m->valueAt(0), -9.0);
  EXPECT_TRUE(m->spacing().isApprox(dm::Vec3(1e-3, 2e-3, 3e-3)));
  EXPECT_TRUE(m->indexToWorld().translation().isApprox(dm::Vec3(1, 2, 3)));
}

TEST(Nrrd, TimeAxisSelectsVolumeAndSkips) {
  std::vector<float> vals{1, 2, 3, 4, 5, 6};  // 2x1x1 voxels, 3 time points
  const std::string h =
      "NRRD0004\ntype: float\ndimension: 4\nspace: right-anterior-superior-time\nsizes: 2 1 1 3\n"
      "space directions: (1,0,0,0) (0,1,0,0) (0,0,1,0) none\nkinds: domain domain domain time\n"
      "endian: little\nencoding: raw\n";
  auto v = dm::parseNrrd(text(h + "\n") + raw(vals), "<memory>", {.volumeIndex = 2});
  ASSERT_TRUE(v) << v.error();
  EXPECT_EQ(v->valueAt(0), 5);
  EXPECT_EQ(v->valueAt(1), 6);
  auto skip = dm::parseNrrd(text(h + "line skip: 2\nbyte skip: 3\n\nl1\nl2\nabc") + raw(vals), "<memory>",
                            {.volumeIndex = 1});
  ASSERT_TRUE(skip) << skip.error();
  EXPECT_EQ(skip->valueAt(0), 3);
  auto tail = dm::parseNrrd(text(h + "byte skip: -1\n\nJUNK") + raw(vals));
  ASSERT_TRUE(tail) << tail.error();
  EXPECT_EQ(tail->valueAt(1), 2);
  auto out = dm::parseNrrd(text(h + "\n") + raw(vals), "<memory>", {.volumeIndex = 3});
  ASSERT_FALSE(out);
  EXPECT_EQ(out.error().code, dm::ErrorCode::InvalidArgument);
}

dm::Affine3 obliqueNrrdAffine() {
  dm::Affine3 a = dm::Affine3::Identity();
  a.linear() = dm::AngleAxis(2.2, dm::Vec3(-0.3, 0.4, 1).normalized()).toRotationMatrix() *
               dm::Vec3(0.4e-3, -1.7e-3, 2.9e-3).asDiagonal();
  a.translation() = dm::Vec3(-0.1, 0.02, 0.3);
  return a;
}

TEST(Nrrd, RoundTripEveryTypeAttachedAndDetached) {
  TempDir dir("roundtrip");
  for (auto type : {dm::VoxelType::U8, dm::VoxelType::I8, dm::VoxelType::U16, dm::VoxelType::I16,
                    dm::VoxelType::U32, dm::VoxelType::I32, dm::VoxelType::F32, dm::VoxelType::F64}) {
    auto v = dm::Volume::create({3, 5, 4}, type, obliqueNrrdAffine());
    ASSERT_TRUE(v);
    for (std::size_t n = 0; n < v->voxelCount(); ++n)
      v->setValueAt(n, 1e12 * std::sin(0.7 * static_cast<double>(n)));
    for (const char* name : {"a.nrrd", "b.nhdr"}) {
      for (bool gzip : {false, true}) {
        SCOPED_TRACE(std::string(dm::toString(type)) + " " + name + (gzip ? " gzip" : ""));
        ASSERT_TRUE(dm::writeNrrd(*v, dir / name, {.gzip = gzip}));
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
  EXPECT_TRUE(fs::exists(dir / "b.raw.gz"));
}

// ---------------------------------------------------------------- bad input

void expectNrrdError(const std::string& h, const Bytes& data, const std::string& needle,
                     dm::ErrorCode code = dm::ErrorCode::Parse) {
  auto v = dm::parseNrrd(text(h) + data);
  ASSERT_FALSE(v) << "expected an error naming " << needle;
  EXPECT_EQ(v.error().code, code) << v.error();
  EXPECT_EQ(v.error().where, "<memory>");
  EXPECT_NE(v.error().message().find(needle), std::string::npos) << v.error();
}

using dm::test::kEight;
std::string minimal(const std::string& extra) {
  return "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n" + extra + "\n";
}

TEST(NrrdBadInput, HeaderErrors) {
  expectNrrdError("NRRD0009\n\n", kEight, "magic");
  expectNrrdError("P6\n2 2\n255\n", kEight, "magic");
  expectNrrdError("", {}, "magic");
  expectNrrdError("NRRD0004\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n\n", kEight, "\"type\"");
  expectNrrdError("NRRD0004\ntype: quaternion\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n\n", kEight,
                  "quaternion");
  expectNrrdError("NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2\nencoding: raw\n\n", kEight, "sizes");
  expectNrrdError("NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 0 2\nencoding: raw\n\n", kEight, "sizes");
  expectNrrdError("NRRD0004\ntype: uint8\ndimension: 99\nsizes: 2 2 2\nencoding: raw\n\n", kEight,
                  "dimension");
  expectNrrdError("NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2\nencoding: lz4\n\n", kEight, "lz4");
  expectNrrdError(minimal("type: uint8\n"), kEight, "twice");
  expectNrrdError(minimal("garbage line\n"), kEight, "line 6");
  expectNrrdError("NRRD0004\ntype: uint16\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n\n", Bytes(16),
                  "endian");
  expectNrrdError("NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n", {}, "blank line");
}

TEST(NrrdBadInput, UnsupportedFeatures) {
  expectNrrdError("NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2\nencoding: bzip2\n\n", kEight, "bzip2",
                  dm::ErrorCode::Unsupported);
  expectNrrdError("NRRD0004\ntype: block\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n\n", kEight, "block",
                  dm::ErrorCode::Unsupported);
  expectNrrdError(minimal("space: 3D-left-handed\nspace directions: (1,0,0) (0,1,0) (0,0,1)\n"), kEight,
                  "left-handed", dm::ErrorCode::Unsupported);
  // RGB: a 3-component axis first.
  expectNrrdError(
      "NRRD0004\ntype: uint8\ndimension: 4\nsizes: 3 2 2 2\nspace: RAS\n"
      "space directions: none (1,0,0) (0,1,0) (0,0,1)\nencoding: raw\n\n",
      Bytes(24), "multi-component", dm::ErrorCode::Unsupported);
  expectNrrdError(minimal("data file: LIST\n"), kEight, "several", dm::ErrorCode::Unsupported);
  expectNrrdError(minimal("data file: slice%03d.raw 0 9 1\n"), kEight, "several", dm::ErrorCode::Unsupported);
  expectNrrdError(minimal("data file: other.raw\n"), {}, "readNrrd", dm::ErrorCode::InvalidArgument);
}

TEST(NrrdBadInput, GeometryErrors) {
  expectNrrdError(minimal("space: RAS\nspace directions: (1,0,0) (2,0,0) (0,0,1)\n"), kEight, "singular");
  expectNrrdError(minimal("space: RAS\nspace directions: (1,0,0) (0,nan,0) (0,0,1)\n"), kEight,
                  "space directions");
  expectNrrdError(minimal("space: RAS\nspace directions: (1,0,0) (0,1) (0,0,1)\n"), kEight, "components");
  expectNrrdError(minimal("space: RAS\nspace directions: (1,0,0) (0,1,0)\n"), kEight, "entries");
  expectNrrdError(minimal("space directions: (1,0,0) (0,1,0) (0,0,1)\n"), kEight, "space dimension");
  expectNrrdError(minimal("space: RAS\nspace origin: (0,inf,0)\n"), kEight, "space origin");
  expectNrrdError(minimal("space: RAS\nspace units: \"mm\" \"furlong\" \"mm\"\n"), kEight, "furlong");
  expectNrrdError(minimal("space: moon\n"), kEight, "moon");
}

TEST(NrrdBadInput, DataErrors) {
  expectNrrdError(minimal(""), Bytes(7), "need 8");
  expectNrrdError("NRRD0004\ntype: uint8\ndimension: 3\nsizes: 30000 30000 30000\nencoding: raw\n\n", kEight,
                  "holds 8 bytes");
  expectNrrdError(minimal("").replace(minimal("").find("raw"), 3, "gzip"), kEight, "compressed");
  expectNrrdError(minimal("").replace(minimal("").find("raw"), 3, "ascii"), text("1 2 3 x 5 6 7 8"), "\"x\"");
  expectNrrdError(minimal("").replace(minimal("").find("raw"), 3, "ascii"), text("1 2 3 4 5 6 7"),
                  "cannot hold");
  expectNrrdError(minimal("").replace(minimal("").find("raw"), 3, "hex"), text("01020304050607  "), "need 8");
  expectNrrdError(minimal("").replace(minimal("").find("raw"), 3, "hex"), text("01020304g5060708"),
                  "non-hex");
  expectNrrdError(minimal("line skip: 5\n"), text("a\nb\n"), "line skip");
  // A gzip bomb: 8 voxels declared, 16 MiB of zeros; inflation stops at 8 bytes.
  auto bomb = dm::detail::deflate(Bytes(std::size_t{16} << 20), dm::detail::CompressFormat::Gzip);
  ASSERT_TRUE(bomb);
  auto v = dm::parseNrrd(text(minimal("").replace(minimal("").find("raw"), 3, "gzip")) + *bomb);
  ASSERT_TRUE(v) << v.error();
  EXPECT_EQ(v->byteSize(), 8u);
}

TEST(NrrdBadInput, DetachedFileErrorsNameTheFiles) {
  TempDir dir("detached");
  writeBytes(dir / "h.nhdr", text("NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n"
                                  "data file: missing.raw\n"));
  auto v = dm::readNrrd(dir / "h.nhdr");
  ASSERT_FALSE(v);
  EXPECT_NE(v.error().message().find("missing.raw"), std::string::npos) << v.error();
  EXPECT_NE(v.error().message().find("h.nhdr"), std::string::npos) << v.error();
  writeBytes(dir / "missing.raw", Bytes(5));
  auto s = dm::readNrrd(dir / "h.nhdr");
  ASSERT_FALSE(s);
  EXPECT_NE(s.error().where.find("missing.raw"), std::string::npos) << s.error();
  writeBytes(dir / "missing.raw", kEight);
  auto ok = dm::readNrrd(dir / "h.nhdr");
  ASSERT_TRUE(ok) << ok.error();
}

TEST(NrrdBadInput, RandomCorruptionNeverCrashes) {
  auto vol = dm::Volume::create({3, 2, 2}, dm::VoxelType::F32, obliqueNrrdAffine());
  ASSERT_TRUE(vol);
  for (bool gzip : {false, true}) {
    auto enc = dm::encodeNrrd(*vol, {.gzip = gzip});
    ASSERT_TRUE(enc);
    std::mt19937 rng(5);
    for (int trial = 0; trial < 1500; ++trial) {
      Bytes b = *enc;
      for (int k = 0; k < 3; ++k) b[rng() % b.size()] = std::byte(rng() & 0xff);
      auto v = dm::parseNrrd(b);
      if (v) {
        EXPECT_LE(v->byteSize(), 1024u);
      }
    }
  }
}

}  // namespace
