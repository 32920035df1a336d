// Declared-size budgets of the volume readers (issue 37): a header whose
// dimensions and voxel type need more bytes than the reader's maxBytes is
// refused from the header, before any voxel memory is allocated or any
// compressed byte inflated, with the figure and the limit in the message
// (detail::volumeOverBudget words it the same for every format). Two cases
// per format: a compressed header declaring 10^15 bytes or so (an attempt
// to allocate that would fail quite differently), and a real volume read
// with a budget one byte short of it and then exactly at it.
#include <dm/core/volume.hpp>
#include <dm/io/metaimage.hpp>
#include <dm/io/nifti.hpp>
#include <dm/io/nrrd.hpp>
#include <dm/io/volume_io.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "../../DMIO/src/gzip.hpp"
#include "../common/temp_dir.hpp"
#include "file_test_support.hpp"

namespace {

namespace fs = std::filesystem;
using Bytes = std::vector<std::byte>;
using dm::test::operator+;
using dm::test::TempDir;
using dm::test::text;

Bytes gzipped(const Bytes& b) {
  auto z = dm::detail::deflate(b, dm::detail::CompressFormat::Gzip);
  EXPECT_TRUE(z);
  return z ? *z : Bytes{};
}

Bytes zlibbed(const Bytes& b) {
  auto z = dm::detail::deflate(b, dm::detail::CompressFormat::Zlib);
  EXPECT_TRUE(z);
  return z ? *z : Bytes{};
}

Bytes fileBytes(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  std::vector<char> c((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  Bytes b(c.size());
  if (!c.empty()) std::memcpy(b.data(), c.data(), c.size());
  return b;
}

// 24 x 20 x 16 int16 voxels of a ball's signed distance (mm): 15,360 bytes.
dm::Volume ball() {
  dm::Affine3 a = dm::Affine3::Identity();
  a.linear() *= 0.001;
  dm::Volume v = *dm::Volume::create({24, 20, 16}, dm::VoxelType::I16, a);
  auto* d = v.data<std::int16_t>();
  std::size_t n = 0;
  for (int k = 0; k < 16; ++k)
    for (int j = 0; j < 20; ++j)
      for (int i = 0; i < 24; ++i)
        d[n++] = static_cast<std::int16_t>(std::lround(std::hypot(i - 11.5, j - 9.5, k - 7.5) - 6.0));
  return v;
}
constexpr std::size_t kBallBytes = 24 * 20 * 16 * 2;

void expectOverBudget(const dm::Result<dm::Volume>& r, const std::string& declared, std::uint64_t bytes,
                      std::uint64_t limit, const std::string& option) {
  ASSERT_FALSE(r);
  EXPECT_EQ(r.error().code, dm::ErrorCode::InvalidArgument);
  const std::string want = declared + " needs " + std::to_string(bytes) + " bytes, more than the budget of " +
                           std::to_string(limit) + " bytes (" + option + ")";
  EXPECT_NE(r.error().what.find(want), std::string::npos) << r.error() << "\nwanted: " << want;
  EXPECT_NE(r.error().hint.find("raise " + option), std::string::npos) << r.error();
}

TEST(VolumeBudget, MetaImageDeclaringAPetabyteIsRefusedBeforeInflating) {
  const Bytes z = zlibbed(Bytes(4096));
  auto r = dm::parseMetaImage(text("NDims = 3\nDimSize = 100000 100000 50000\nElementType = MET_SHORT\n"
                                   "CompressedData = True\nElementDataFile = LOCAL\n") +
                              z);
  expectOverBudget(r, "DimSize 100000x100000x50000 of MET_SHORT", 1'000'000'000'000'000ull,
                   dm::Volume::kDefaultMaxBytes, "MetaImageReadOptions::maxBytes");
}

TEST(VolumeBudget, NrrdDeclaringAPetabyteIsRefusedBeforeInflating) {
  const Bytes z = gzipped(Bytes(4096));
  auto r = dm::parseNrrd(text("NRRD0004\ntype: short\ndimension: 3\nsizes: 100000 100000 50000\n"
                              "endian: little\nencoding: gzip\n\n") +
                         z);
  expectOverBudget(r, "sizes 100000x100000x50000 of short", 1'000'000'000'000'000ull,
                   dm::Volume::kDefaultMaxBytes, "NrrdReadOptions::maxBytes");
}

TEST(VolumeBudget, NiftiDeclaringTerabytesIsRefusedBeforeInflating) {
  TempDir dir("volume_budget_nifti");
  ASSERT_TRUE(dm::writeNifti(ball(), dir / "ball.nii"));
  Bytes header = fileBytes(dir / "ball.nii");
  ASSERT_GE(header.size(), 352u);
  header.resize(352 + 64);  // the header and a little data: the rest is never looked at
  const std::int16_t dims[3] = {30000, 30000, 30000};
  std::memcpy(header.data() + 42, dims, sizeof dims);  // dim[1..3]
  auto r = dm::parseNifti(gzipped(header), "huge.nii.gz");
  expectOverBudget(r, "30000x30000x30000 voxels of 2 bytes", 54'000'000'000'000ull,
                   dm::Volume::kDefaultMaxBytes, "NiftiReadOptions::maxBytes");
}

// A real volume in each format: one byte short of its size is refused
// naming both, its size reads it back voxel for voxel.
TEST(VolumeBudget, EveryFormatHoldsARealVolumeToTheByte) {
  TempDir dir("volume_budget");
  const dm::Volume v = ball();
  ASSERT_EQ(v.byteSize(), kBallBytes);
  ASSERT_TRUE(dm::writeMetaImage(v, dir / "ball.mha", {.compress = true}));
  ASSERT_TRUE(dm::writeNrrd(v, dir / "ball.nrrd"));
  ASSERT_TRUE(dm::writeNifti(v, dir / "ball.nii.gz"));

  expectOverBudget(dm::readMetaImage(dir / "ball.mha", {.maxBytes = kBallBytes - 1}),
                   "DimSize 24x20x16 of MET_SHORT", kBallBytes, kBallBytes - 1,
                   "MetaImageReadOptions::maxBytes");
  expectOverBudget(dm::readNrrd(dir / "ball.nrrd", {.maxBytes = kBallBytes - 1}), "sizes 24x20x16 of int16",
                   kBallBytes, kBallBytes - 1, "NrrdReadOptions::maxBytes");
  expectOverBudget(dm::readNifti(dir / "ball.nii.gz", {.maxBytes = kBallBytes - 1}),
                   "24x20x16 voxels of 2 bytes", kBallBytes, kBallBytes - 1, "NiftiReadOptions::maxBytes");
  // readVolume passes its budget on.
  auto viaVolume = dm::readVolume(dir / "ball.nrrd", {.maxBytes = kBallBytes - 1});
  ASSERT_FALSE(viaVolume);
  EXPECT_NE(viaVolume.error().what.find("more than the budget of " + std::to_string(kBallBytes - 1)),
            std::string::npos)
      << viaVolume.error();

  for (const char* name : {"ball.mha", "ball.nrrd", "ball.nii.gz"}) {
    SCOPED_TRACE(name);
    auto back = dm::readVolume(dir / name, {.maxBytes = kBallBytes});
    ASSERT_TRUE(back) << back.error();
    ASSERT_EQ(back->dims(), v.dims());
    for (std::size_t n = 0; n < v.voxelCount(); ++n) ASSERT_EQ(back->valueAt(n), v.valueAt(n)) << n;
  }
}

}  // namespace
