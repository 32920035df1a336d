// registerIoLoaders(): meshes and volumes load through the resource manager
// with the same content as the direct readers, are cached per (path,
// options), and bad extensions or options fail with a message.
#include <dm/core/filesystem.hpp>
#include <dm/io/mesh_io.hpp>
#include <dm/io/resources.hpp>
#include <dm/io/volume_io.hpp>

#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <string>

namespace {

namespace fs = std::filesystem;

bool contains(const std::vector<std::string>& v, const std::string& s) {
  return std::find(v.begin(), v.end(), s) != v.end();
}

fs::path ch2() {
  auto p = dm::FileSystem::global().resolve("mricron:ch2.nii.gz");
  return p ? *p : fs::path();
}

const fs::path kBox = "/usr/share/assimp/models/OBJ/box.obj";

TEST(IoResources, ExtensionListsComeFromTheReaders) {
  const auto vol = dm::volumeExtensions();
  for (const char* e :
       {".nii", ".nii.gz", ".hdr", ".img.gz", ".mhd", ".mha", ".nrrd", ".nhdr", ".dcm", ".vdb"})
    EXPECT_TRUE(contains(vol, e)) << e;
  for (const std::string& e : vol) {
    EXPECT_EQ(e.front(), '.');
    EXPECT_EQ(e.find(' '), std::string::npos) << e;
    EXPECT_EQ(std::count(vol.begin(), vol.end(), e), 1) << e;
  }
  const auto mesh = dm::meshExtensions();
  for (const char* e : {".obj", ".stl", ".ply", ".off", ".glb", ".dae"}) EXPECT_TRUE(contains(mesh, e)) << e;
  for (const std::string& e : mesh) EXPECT_TRUE(dm::canReadMesh("x" + e)) << e;
}

TEST(IoResources, IsVolumePathByExtensionOrDirectory) {
  EXPECT_TRUE(dm::isVolumePath("head.nii.gz"));
  EXPECT_TRUE(dm::isVolumePath("HEAD.NII"));
  EXPECT_TRUE(dm::isVolumePath("/data/ct.mha"));
  EXPECT_TRUE(dm::isVolumePath(fs::temp_directory_path()));  // a DICOM series is a directory
  EXPECT_FALSE(dm::isVolumePath("liver.stl"));
  EXPECT_FALSE(dm::isVolumePath("notes.gz"));
  EXPECT_FALSE(dm::isVolumePath(".nii"));  // a bare extension is no file name
}

TEST(IoResources, LoadsAMeshOnceAndMatchesTheReader) {
  dm::ResourceManager rm;
  ASSERT_TRUE(dm::registerIoLoaders(rm));
  auto a = rm.load<dm::Mesh>(kBox);
  ASSERT_TRUE(a) << a.error();
  auto b = rm.load<dm::Mesh>(kBox);
  ASSERT_TRUE(b) << b.error();
  EXPECT_TRUE(*a == *b);
  EXPECT_EQ(a->id(), b->id());
  EXPECT_EQ(rm.stats().loads, 1u);
  auto direct = dm::readMesh(kBox);
  ASSERT_TRUE(direct) << direct.error();
  EXPECT_EQ((*a)->triangles, direct->triangles);
  EXPECT_EQ((*a)->positions, direct->positions);
  // The unit box: 12 triangles spanning [-0.5, 0.5]^3.
  EXPECT_EQ((*a)->triangleCount(), 12u);
  EXPECT_NEAR((*a)->bounds().sizes().prod(), 1.0, 1e-12);
}

TEST(IoResources, MeshImportOptionsAreAppliedAndPartOfTheIdentity) {
  dm::ResourceManager rm;
  ASSERT_TRUE(dm::registerIoLoaders(rm));
  auto m = rm.load<dm::Mesh>(kBox);
  auto mm = rm.load<dm::Mesh>(kBox, {{"unit", "mm"}});
  auto scaled = rm.load<dm::Mesh>(kBox, {{"unit", "cm"}, {"scale", "2"}});
  ASSERT_TRUE(m && mm && scaled);
  EXPECT_NE(m->id(), mm->id());
  EXPECT_NEAR((*mm)->bounds().sizes().x(), 1e-3, 1e-15);
  EXPECT_NEAR((*scaled)->bounds().sizes().x(), 2e-2, 1e-15);

  auto typo = rm.load<dm::Mesh>(kBox, {{"scal", "2"}});
  ASSERT_FALSE(typo);
  EXPECT_EQ(typo.error().code, dm::ErrorCode::InvalidArgument);
  EXPECT_NE(typo.error().message().find("scal"), std::string::npos) << typo.error();
  EXPECT_NE(typo.error().message().find("unit, scale"), std::string::npos) << typo.error();
  auto notNumber = rm.load<dm::Mesh>(kBox, {{"scale", "two"}});
  ASSERT_FALSE(notNumber);
  EXPECT_NE(notNumber.error().message().find("two"), std::string::npos) << notNumber.error();
  auto badUnit = rm.load<dm::Mesh>(kBox, {{"unit", "furlong"}});
  ASSERT_FALSE(badUnit);
}

TEST(IoResources, LoadsAVolumeOnceAndMatchesTheReader) {
  const fs::path file = ch2();
  ASSERT_FALSE(file.empty()) << "mricron-data is not installed";
  dm::ResourceManager rm;
  ASSERT_TRUE(dm::registerIoLoaders(rm));
  auto a = rm.load<dm::Volume>(file);
  ASSERT_TRUE(a) << a.error();
  auto b = rm.load<dm::Volume>(file);
  ASSERT_TRUE(b) << b.error();
  EXPECT_TRUE(*a == *b);
  EXPECT_EQ(rm.stats().loads, 1u);
  EXPECT_EQ((*a)->dims(), dm::Vec3i(181, 217, 181));  // Colin27 at 1 mm
  auto direct = dm::readVolume(file);
  ASSERT_TRUE(direct) << direct.error();
  EXPECT_TRUE((*a)->indexToWorld().isApprox(direct->indexToWorld(), 0.0));
  EXPECT_EQ((*a)->range(), direct->range());

  auto second = rm.load<dm::Volume>(file, {{"volume", "1"}});  // a 3-D file has only volume 0
  EXPECT_FALSE(second);
  auto negative = rm.load<dm::Volume>(file, {{"volume", "-1"}});
  ASSERT_FALSE(negative);
  EXPECT_EQ(negative.error().code, dm::ErrorCode::InvalidArgument);
}

// A DICOM series loads through the manager by naming any of its files.
TEST(IoResources, LoadsADicomSeriesThroughOneOfItsFiles) {
  const fs::path file = ch2();
  ASSERT_FALSE(file.empty()) << "mricron-data is not installed";
  auto direct = dm::readVolume(file);
  ASSERT_TRUE(direct) << direct.error();
  const fs::path dir = fs::temp_directory_path() / ("dm_resources_dicom_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  ASSERT_TRUE(dm::writeVolume(*direct, dir / ""));
  fs::path slice;
  for (const auto& e : fs::directory_iterator(dir))
    if (e.path().extension() == ".dcm") slice = e.path();
  ASSERT_FALSE(slice.empty());
  dm::ResourceManager rm;
  ASSERT_TRUE(dm::registerIoLoaders(rm));
  auto series = rm.load<dm::Volume>(slice);
  ASSERT_TRUE(series) << series.error();
  EXPECT_EQ((*series)->dims(), direct->dims());
  EXPECT_TRUE((*series)->indexToWorld().isApprox(direct->indexToWorld(), 1e-9));
  fs::remove_all(dir);
}

TEST(IoResources, UnknownExtensionAndMissingFileFail) {
  dm::ResourceManager rm;
  ASSERT_TRUE(dm::registerIoLoaders(rm));
  const fs::path txt = fs::temp_directory_path() / "dm_resources_test.unknownext";
  std::ofstream(txt) << "not a mesh\n";
  auto u = rm.load<dm::Mesh>(txt);
  ASSERT_FALSE(u);
  EXPECT_EQ(u.error().code, dm::ErrorCode::Unsupported);
  auto uv = rm.load<dm::Volume>(kBox);  // a mesh file is no volume
  ASSERT_FALSE(uv);
  EXPECT_EQ(uv.error().code, dm::ErrorCode::Unsupported);
  fs::remove(txt);
  auto missing = rm.load<dm::Mesh>("/nonexistent/dir/liver.stl");
  ASSERT_FALSE(missing);
  EXPECT_EQ(missing.error().code, dm::ErrorCode::NotFound);
  EXPECT_NE(missing.error().message().find("liver.stl"), std::string::npos);
}

TEST(IoResources, RegisteringTwiceFails) {
  dm::ResourceManager rm;
  ASSERT_TRUE(dm::registerIoLoaders(rm));
  EXPECT_FALSE(dm::registerIoLoaders(rm));
}

}  // namespace
