// SceneView: rendering a scene from a caller's Camera (an editor's orbit
// view) equals rendering the scene camera it was taken from, pixel for
// pixel, and a camera on the other side of the scene sees something else.
#include <dm/io/scene_file.hpp>
#include <dm/io/scene_resources.hpp>
#include <dm/renderer/scene_view.hpp>

#include <gtest/gtest.h>

#include <cstdint>
#include <cstring>

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

}  // namespace
}  // namespace dm
