// readVolume()/writeVolume() dispatch: every format round-trips Colin27
// through the one entry point with the same voxels and the same placement.
#include <dm/core/filesystem.hpp>
#include <dm/io/volume_io.hpp>

#include <gtest/gtest.h>

#include <unistd.h>

#include <filesystem>
#include <string>

namespace dm {
namespace {

namespace fs = std::filesystem;

Volume loadCh2() {
  auto path = FileSystem::global().resolve("mricron:ch2.nii.gz");
  if (!path) return {};
  auto v = readVolume(*path);
  return v ? std::move(*v) : Volume{};
}

void expectSameVoxelsAndPlacement(const Volume& a, const Volume& b) {
  ASSERT_EQ(a.dims(), b.dims());
  EXPECT_TRUE(a.indexToWorld().matrix().isApprox(b.indexToWorld().matrix(), 1e-9));
  for (std::size_t i = 0; i < a.voxelCount(); i += 97) ASSERT_EQ(a.valueAt(i), b.valueAt(i)) << "voxel " << i;
}

class VolumeIo : public ::testing::TestWithParam<std::string> {};

TEST_P(VolumeIo, Ch2RoundTripsThroughTheDispatch) {
  const Volume ch2 = loadCh2();
  if (ch2.empty()) GTEST_SKIP() << "mricron-data is not installed (scripts/setup.sh installs it)";
  const fs::path dir = fs::path(::testing::TempDir()) / ("dm_volume_io_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  const fs::path out = dir / GetParam();
  ASSERT_TRUE(writeVolume(ch2, out)) << out;
  auto back = readVolume(out);
  ASSERT_TRUE(back) << back.error();
  expectSameVoxelsAndPlacement(ch2, *back);
  fs::remove_all(dir);
}

// "series/" (trailing separator) is a DICOM series directory.
INSTANTIATE_TEST_SUITE_P(Formats, VolumeIo,
                         ::testing::Values("ch2.nii.gz", "ch2.nii", "ch2.mha", "ch2.mhd", "ch2.nrrd",
                                           "ch2.vdb", "series/"),
                         [](const ::testing::TestParamInfo<std::string>& p) {
                           std::string n = p.param;
                           for (char& c : n)
                             if (!std::isalnum(static_cast<unsigned char>(c))) c = '_';
                           return n;
                         });

TEST(VolumeIoErrors, UnknownExtensionListsTheSupportedOnes) {
  auto v = readVolume("scan.xyz");
  ASSERT_FALSE(v);
  EXPECT_EQ(v.error().code, ErrorCode::Unsupported);
  EXPECT_EQ(v.error().where, "scan.xyz");
  for (const char* ext : {".nii.gz", ".nrrd", ".mha"})
    EXPECT_NE(v.error().hint.find(ext), std::string::npos) << ext;
  EXPECT_NE(v.error().hint.find("DICOM"), std::string::npos);
  EXPECT_NE(v.error().hint.find(".vdb"), std::string::npos);
  auto empty = Volume::create({2, 2, 2}, VoxelType::U8, Affine3::Identity());
  ASSERT_TRUE(empty);
  EXPECT_FALSE(writeVolume(*empty, "scan.xyz"));
}

}  // namespace
}  // namespace dm
