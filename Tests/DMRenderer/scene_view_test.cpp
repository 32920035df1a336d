// SceneView: rendering a scene from a caller's Camera (an editor's orbit
// view) equals rendering the scene camera it was taken from, pixel for
// pixel, and a camera on the other side of the scene sees something else.
#include <dm/io/image_io.hpp>
#include <dm/io/scene_file.hpp>
#include <dm/io/scene_resources.hpp>
#include <dm/renderer/scene_view.hpp>

#include <gtest/gtest.h>

#include <cstdint>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "render_fixture.hpp"

namespace dm {
namespace {

constexpr const char* kScene = R"({
  "format": "dmplatform-scene",
  "version": 1,
  "resources": { "ball": { "type": "shape", "shape": "sphere", "radius": 0.05, "subdivisions": 3 } },
  "materials": { "red": { "color": [0.8, 0.1, 0.1, 1.0] } },
  "objects": [ { "name": "ball", "mesh": "ball", "material": "red", "pose": { "position": [0.03, 0, 0] } } ],
  "lights": [ { "type": "directional", "direction": [-0.3, -0.5, -1.0] } ],
  "cameras": [ { "name": "front", "position": [0, -0.4, 0.1], "target": [0, 0, 0], "up": [0, 0, 1] } ]
})";

TEST(SceneView, ACallersCameraRendersLikeTheSceneCameraItCameFrom) {
  if (!test::renderContext()) GTEST_SKIP() << "no EGL OpenGL 4.5 context";
  std::vector<Error> problems;
  auto scene = parseScene(kScene, "scene_view_test", ".", &problems);
  ASSERT_TRUE(scene) << scene.error() << formatSceneErrors(problems);
  auto resources = loadSceneResources(*scene);
  ASSERT_TRUE(resources) << resources.error();
  auto view = SceneView::create(*scene, *resources);
  ASSERT_TRUE(view) << view.error();
  auto a = RenderTarget::create({.width = 96, .height = 72});
  auto b = RenderTarget::create({.width = 96, .height = 72});
  ASSERT_TRUE(a && b);
  ASSERT_TRUE(view->render(*a, "front", 0.0));
  auto cam = view->camera("front", 0.0);
  ASSERT_TRUE(cam) << cam.error();
  ASSERT_TRUE(view->render(*b, *cam));
  auto ia = a->readColor(), ib = b->readColor();
  ASSERT_TRUE(ia && ib);
  std::size_t differ = 0, lit = 0;
  for (int y = 0; y < 72; ++y)
    for (int x = 0; x < 96; ++x)
      for (int c = 0; c < 3; ++c) {
        differ += ia->at<std::uint8_t>(x, y, c) != ib->at<std::uint8_t>(x, y, c);
        lit += c == 0 && ia->at<std::uint8_t>(x, y, 0) > 60;
      }
  EXPECT_EQ(differ, 0u);
  EXPECT_GT(lit, 100u) << "the red ball should fill part of the frame";
  // From behind and to the side the ball (off-centre in x) lands elsewhere.
  ASSERT_TRUE(view->render(*b, Camera::lookAt({0.3, 0.3, 0.1}, {0, 0, 0}, {0, 0, 1})));
  auto ic = b->readColor();
  ASSERT_TRUE(ic);
  std::size_t changed = 0;
  for (int y = 0; y < 72; ++y)
    for (int x = 0; x < 96; ++x) changed += ia->at<std::uint8_t>(x, y, 0) != ic->at<std::uint8_t>(x, y, 0);
  EXPECT_GT(changed, 100u);
}

// A scene material's height_map and height_scale reach the renderer: seen
// at 45° by an orthographic camera, a 1 m plane whose texture edges lie in a
// 0.1 m pit (u > 0.375) shows them moved, while the plateau (u < 0.375)
// renders as without the relief. The geometry of the shift is checked in
// scene_renderer_height_test.cpp.
TEST(SceneView, HeightMapAndScaleFromTheSceneFileReachTheRenderer) {
  if (!test::renderContext()) GTEST_SKIP() << "no EGL OpenGL 4.5 context";
  const auto dir = std::filesystem::temp_directory_path() / "dm_scene_view_height_test";
  std::filesystem::create_directories(dir);
  auto stripes = Image::create(64, 64, 3, PixelType::U8);
  auto step = Image::create(64, 64, 1, PixelType::U8);
  ASSERT_TRUE(stripes && step);
  for (int y = 0; y < 64; ++y)
    for (int x = 0; x < 64; ++x) {
      const bool red = (x / 16) % 2 == 0;
      stripes->at<std::uint8_t>(x, y, 0) = red ? 230 : 20;
      stripes->at<std::uint8_t>(x, y, 1) = 20;
      stripes->at<std::uint8_t>(x, y, 2) = red ? 20 : 230;
      step->at<std::uint8_t>(x, y) = x < 24 ? 255 : 0;
    }
  ASSERT_TRUE(writePng(*stripes, dir / "stripes.png"));
  ASSERT_TRUE(writePng(*step, dir / "step.png"));
  auto render = [&](const std::string& relief) -> Image {
    const std::string text = R"({
      "format": "dmplatform-scene", "version": 1,
      "resources": {
        "floor": {"type": "shape", "shape": "plane", "half_extents": [0.5, 0.5]},
        "stripes": {"type": "image", "source": "stripes.png"},
        "step": {"type": "image", "source": "step.png"}
      },
      "materials": {"m": {"texture": "stripes", "specular": [0, 0, 0])" +
                             relief + R"(}},
      "objects": [{"name": "floor", "mesh": "floor", "material": "m"}],
      "lights": [{"type": "directional", "direction": [0, 0, -1]}],
      "cameras": [{"name": "side", "projection": "orthographic", "ortho_height": 1,
                   "position": [1.4142, 0, 1.4142], "target": [0, 0, 0], "up": [0, 1, 0]}]
    })";
    std::vector<Error> problems;
    auto scene = parseScene(text, "height_scene.json", dir, &problems);
    EXPECT_TRUE(scene) << (scene ? "" : scene.error().message()) << formatSceneErrors(problems);
    if (!scene) return Image{};
    auto resources = loadSceneResources(*scene);
    EXPECT_TRUE(resources) << resources.error();
    auto view = SceneView::create(*scene, *resources);
    EXPECT_TRUE(view) << view.error();
    auto target = RenderTarget::create({.width = 128, .height = 128, .samples = 1});
    EXPECT_TRUE(target);
    if (!resources || !view || !target) return Image{};
    EXPECT_TRUE(view->render(*target, "side", 0.0));
    auto img = target->readColor();
    EXPECT_TRUE(img);
    return img ? *img : Image{};
  };
  const Image flat = render("");
  const Image relief = render(R"(, "height_map": "step", "height_scale": 0.1)");
  ASSERT_FALSE(flat.empty() || relief.empty());
  // Column of u on the plane: 64 + (u - 0.5) cos 45° x 128.
  // (The plateau's first texel is skipped: the repeat-wrapped height map dips there.)
  auto column = [](double u) { return int(64 + (u - 0.5) * 0.7071 * 128); };
  const int plateauBegin = column(0.05), plateauEnd = column(0.3), pitStart = column(0.45);
  std::size_t plateauChanged = 0, pitChanged = 0;
  for (int y = 0; y < 128; ++y)
    for (int x = 0; x < 128; ++x) {
      const bool changed = std::abs(flat.at<std::uint8_t>(x, y, 0) - relief.at<std::uint8_t>(x, y, 0)) > 40;
      if (x >= plateauBegin && x < plateauEnd) plateauChanged += changed;
      if (x >= pitStart) pitChanged += changed;
    }
  EXPECT_EQ(plateauChanged, 0u);
  // Two edges in the pit move by 0.1 m x tan 45° x cos 45° x 128 px/m = 9 px on each of ~90 rows.
  EXPECT_GT(pitChanged, 2u * 7 * 80) << "the relief should move the pit's texture edges";
}

}  // namespace
}  // namespace dm
