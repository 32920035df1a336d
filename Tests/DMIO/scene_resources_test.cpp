// Loading a scene's resources: files, isosurfaces, shapes, images, errors.
#include <dm/core/volume.hpp>
#include <dm/io/image_io.hpp>
#include <dm/io/mesh_io.hpp>
#include <dm/io/nifti.hpp>
#include <dm/io/scene_resources.hpp>
#include <dm/math/mesh_topology.hpp>
#include <dm/math/phantom.hpp>
#include <dm/math/primitives.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <numbers>

namespace {

namespace fs = std::filesystem;

// A scene folder with a ball volume (value 100 inside radius 12 mm, 1 mm
// voxels, plus a separate 3-voxel speck), an OBJ box and a PNG.
struct SceneDir {
  // One folder per test: ctest runs the tests of this file in parallel.
  fs::path dir = fs::temp_directory_path() / "dm_scene_resources_test" /
                 ::testing::UnitTest::GetInstance()->current_test_info()->name();
  SceneDir() {
    fs::remove_all(dir);
    fs::create_directories(dir);
    dm::Affine3 a = dm::Affine3::Identity();
    a.linear() *= 0.001;
    a.translation() = dm::Vec3(-0.02, -0.02, -0.02);
    dm::Volume v = *dm::Volume::create({40, 40, 40}, dm::VoxelType::U8, a);
    auto* d = v.data<std::uint8_t>();
    for (int z = 0; z < 40; ++z)
      for (int y = 0; y < 40; ++y)
        for (int x = 0; x < 40; ++x) {
          const dm::Vec3 w = a * dm::Vec3(x, y, z);
          const bool ball = w.norm() < 0.012;
          const bool speck = x >= 35 && x <= 37 && y == 36 && z == 36;
          d[(z * 40 + y) * 40 + x] = (ball || speck) ? 100 : 0;
        }
    EXPECT_TRUE(dm::writeNifti(v, dir / "ball.nii.gz"));
    EXPECT_TRUE(dm::writeMesh(dm::makeBox({0.01, 0.02, 0.03}), dir / "box.obj"));
    dm::Image img = *dm::Image::create(4, 2, 3, dm::PixelType::U8);
    img.at<std::uint8_t>(1, 0, 0) = 200;
    EXPECT_TRUE(dm::writePng(img, dir / "tex.png"));
  }
};

dm::SceneDesc parse(const std::string& resources, const fs::path& base, int version = 1) {
  const std::string text = R"({"format": "dmplatform-scene", "version": )" + std::to_string(version) +
                           R"(, "resources": )" + resources + "}";
  auto s = dm::parseScene(text, "test.json", base);
  EXPECT_TRUE(s) << (s ? "" : s.error().message());
  return s ? *s : dm::SceneDesc{};
}

}  // namespace

TEST(SceneResources, LoadsFilesIsosurfacesShapesAndImages) {
  SceneDir d;
  const dm::SceneDesc scene = parse(R"({
    "ball": {"type": "volume", "source": "ball.nii.gz"},
    "surface": {"type": "isosurface", "volume": "ball", "level": 50},
    "surface_one": {"type": "isosurface", "volume": "ball", "level": 50, "largest_component": true, "smooth": 5},
    "surface_coarse": {"type": "isosurface", "volume": "ball", "level": 50, "largest_component": true, "downsample": 2},
    "box": {"type": "mesh", "source": "box.obj"},
    "box_mm": {"type": "mesh", "source": "box.obj", "unit": "mm"},
    "cyl": {"type": "shape", "shape": "cylinder", "radius": 0.01, "height": 0.05, "subdivisions": 4},
    "tex": {"type": "image", "source": "tex.png"}})",
                                    d.dir);
  std::vector<std::string> seen;
  auto res =
      dm::loadSceneResources(scene, {.progress = [&](std::string_view n, double) { seen.emplace_back(n); }});
  ASSERT_TRUE(res) << res.error();
  // The volume loads before what derives from it.
  ASSERT_FALSE(seen.empty());
  EXPECT_EQ(seen.front(), "ball");
  ASSERT_TRUE(res->volume("ball"));
  EXPECT_EQ(res->volume("ball")->dims(), dm::Vec3i(40, 40, 40));

  // The isosurface of the ball (plus the speck) and its largest component.
  auto all = res->mesh("surface"), one = res->mesh("surface_one");
  ASSERT_TRUE(all && one);
  EXPECT_EQ(dm::analyzeTopology(*all).components, 2u);
  const dm::MeshTopology t = dm::analyzeTopology(*one);
  EXPECT_EQ(t.components, 1u);
  EXPECT_TRUE(t.isClosed);
  ASSERT_TRUE(t.volume.has_value());
  // A 12 mm ball sampled at 1 mm: enclosed volume within 10% of 4/3 pi r^3.
  EXPECT_NEAR(*t.volume, 4.0 / 3.0 * std::numbers::pi * std::pow(0.012, 3), 0.1 * 7.2e-6);

  // Averaged over 2x2x2 voxels: about a quarter of the triangles, the same ball.
  auto coarse = res->mesh("surface_coarse");
  ASSERT_TRUE(coarse);
  const double ratio = double(coarse->triangleCount()) / double(one->triangleCount());
  EXPECT_GT(ratio, 0.15);
  EXPECT_LT(ratio, 0.4);
  const dm::MeshTopology tc = dm::analyzeTopology(*coarse);
  EXPECT_TRUE(tc.isClosed);
  ASSERT_TRUE(tc.volume.has_value());
  EXPECT_NEAR(*tc.volume, *t.volume, 0.15 * *t.volume);

  // The box file, once in metres and once read as millimetres.
  ASSERT_TRUE(res->mesh("box") && res->mesh("box_mm"));
  // (OBJ stores single-precision text.)
  EXPECT_NEAR(res->mesh("box")->bounds().sizes().z(), 0.06, 1e-7);
  EXPECT_NEAR(res->mesh("box_mm")->bounds().sizes().z(), 0.06e-3, 1e-10);

  auto cyl = res->mesh("cyl");
  ASSERT_TRUE(cyl);
  EXPECT_NEAR(cyl->bounds().sizes().z(), 0.05, 1e-12);
  EXPECT_NEAR(cyl->bounds().sizes().x(), 0.02, 1e-4);

  ASSERT_TRUE(res->image("tex"));
  EXPECT_EQ(res->image("tex")->width(), 4);
  EXPECT_EQ(res->image("tex")->at<std::uint8_t>(1, 0, 0), 200);
  EXPECT_FALSE(res->mesh("nothing"));
}

TEST(SceneResources, ErrorsNameTheResource) {
  SceneDir d;
  auto missing = dm::loadSceneResources(parse(R"({"gone": {"type": "mesh", "source": "gone.obj"}})", d.dir));
  ASSERT_FALSE(missing);
  EXPECT_NE(missing.error().where.find("resources/gone"), std::string::npos) << missing.error();

  auto level = dm::loadSceneResources(parse(R"({
    "ball": {"type": "volume", "source": "ball.nii.gz"},
    "none": {"type": "isosurface", "volume": "ball", "level": 500}})",
                                            d.dir));
  ASSERT_FALSE(level);
  EXPECT_EQ(level.error().where, "resources/none/level");

  // Not a PNG: the image reader's message, inside the resource's name.
  std::ofstream(d.dir / "bad.png") << "not a png";
  auto bad = dm::loadSceneResources(parse(R"({"img": {"type": "image", "source": "bad.png"}})", d.dir));
  ASSERT_FALSE(bad);
  EXPECT_EQ(bad.error().where.rfind("resources/img", 0), 0u) << bad.error();
}

TEST(SceneResources, EveryShapeIsClosedAndSized) {
  dm::SceneResource r;
  r.type = dm::SceneResource::Type::Shape;
  r.subdivisions = 3;
  r.shape = dm::SceneResource::Shape::Sphere;
  r.radius = 0.02;
  auto sphere = dm::makeSceneShape(r);
  ASSERT_TRUE(sphere);
  EXPECT_TRUE(dm::analyzeTopology(*sphere).isClosed);
  EXPECT_NEAR(sphere->bounds().sizes().x(), 0.04, 1e-3);
  r.shape = dm::SceneResource::Shape::Capsule;
  r.height = 0.05;
  auto capsule = dm::makeSceneShape(r);
  ASSERT_TRUE(capsule);
  EXPECT_TRUE(dm::analyzeTopology(*capsule).isClosed);
  EXPECT_NEAR(capsule->bounds().sizes().z(), 0.05 + 0.04, 1e-9);
  r.shape = dm::SceneResource::Shape::Box;
  r.halfExtents = dm::Vec3(0.1, 0.2, 0.3);
  EXPECT_NEAR(dm::makeSceneShape(r)->bounds().sizes().z(), 0.6, 1e-12);
  r.shape = dm::SceneResource::Shape::Plane;
  r.halfExtents = dm::Vec3(0.1, 0.2, 0);
  auto plane = dm::makeSceneShape(r);
  ASSERT_TRUE(plane);
  EXPECT_NEAR(plane->surfaceArea(), 0.08, 1e-12);
  r.radius = 0;
  r.shape = dm::SceneResource::Shape::Sphere;
  EXPECT_FALSE(dm::makeSceneShape(r));
  r.type = dm::SceneResource::Type::Mesh;
  EXPECT_FALSE(dm::makeSceneShape(r));
}

// The scene's memory budget: its phantoms' declared voxels are summed and
// refused before any is generated (no progress reported), naming the total
// and the budget.
TEST(SceneResources, PhantomsOverTheBudgetAreRefusedFromTheirDeclaration) {
  SceneDir d;
  const dm::SceneDesc scene = parse(R"({
    "left": {"type": "volume", "phantom": {"kind": "calvarium", "spacing": 0.0005, "half_width": 0.01}},
    "right": {"type": "volume", "phantom": {"kind": "calvarium", "spacing": 0.0004, "half_width": 0.012}}})",
                                    d.dir, 2);
  std::uint64_t declared = 0;
  for (const char* name : {"left", "right"}) {
    const dm::Vec3i n = dm::calvariumPhantomDims(*scene.resource(name)->phantom);
    declared += 2ull * std::uint64_t(n.x()) * std::uint64_t(n.y()) * std::uint64_t(n.z());
  }
  ASSERT_GT(declared, 100000u);
  int progressCalls = 0;
  dm::SceneLoadOptions tight;
  tight.maxBytes = declared - 1;
  tight.progress = [&](std::string_view, double) { ++progressCalls; };
  auto refused = dm::loadSceneResources(scene, tight);
  ASSERT_FALSE(refused);
  EXPECT_EQ(refused.error().where, "resources");
  EXPECT_NE(
      refused.error().what.find("2 phantom(s) declare " + std::to_string(declared) +
                                " bytes of voxels, more than the budget of " + std::to_string(declared - 1)),
      std::string::npos)
      << refused.error();
  EXPECT_NE(refused.error().hint.find("SceneLoadOptions::maxBytes"), std::string::npos);
  EXPECT_EQ(progressCalls, 0);

  dm::SceneLoadOptions enough;
  enough.maxBytes = declared;
  auto loaded = dm::loadSceneResources(scene, enough);
  ASSERT_TRUE(loaded) << loaded.error();
  EXPECT_EQ(loaded->volume("left")->byteSize() + loaded->volume("right")->byteSize(), declared);
}

// Files count as they load, a file two resources share once; the resource
// that takes the total over the budget fails, naming it and both figures.
TEST(SceneResources, TheLoadedTotalIsHeldToTheBudget) {
  SceneDir d;
  const dm::SceneDesc scene = parse(R"({
    "ball": {"type": "volume", "source": "ball.nii.gz"},
    "again": {"type": "volume", "source": "ball.nii.gz"},
    "box": {"type": "mesh", "source": "box.obj"}})",
                                    d.dir);
  auto all = dm::loadSceneResources(scene);
  ASSERT_TRUE(all) << all.error();
  ASSERT_EQ(all->volume("ball"), all->volume("again"));  // one file, one volume
  const dm::Mesh& box = *all->mesh("box");
  const std::uint64_t ball = 40 * 40 * 40;  // U8
  const std::uint64_t boxBytes = box.positions.size() * sizeof(dm::Vec3) +
                                 box.normals.size() * sizeof(dm::Vec3) +
                                 box.triangles.size() * sizeof(dm::Triangle) +
                                 box.uvs.size() * sizeof(dm::Vec2f) + box.colors.size() * sizeof(dm::Vec4f);
  ASSERT_EQ(all->volume("ball")->byteSize(), ball);

  dm::SceneLoadOptions exact;
  exact.maxBytes = ball + boxBytes;
  EXPECT_TRUE(dm::loadSceneResources(scene, exact));

  dm::SceneLoadOptions tight;
  tight.maxBytes = ball + boxBytes - 1;
  auto refused = dm::loadSceneResources(scene, tight);
  ASSERT_FALSE(refused);
  EXPECT_EQ(refused.error().where, "resources/box");
  EXPECT_NE(
      refused.error().what.find("brings the scene's resources to " + std::to_string(ball + boxBytes) +
                                " bytes, more than the budget of " + std::to_string(ball + boxBytes - 1)),
      std::string::npos)
      << refused.error();
}
