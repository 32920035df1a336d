// A live view's camera turn (dm::ViewOrbit, dmplatform run --view's mouse)
// against geometry: the render engine's frame with the scene camera turned
// by yaw, pitch and zoom is the frame of a scene whose camera stands where
// spherical coordinates about the target put it; frames reach
// SceneRuntime::latestFrame only with SceneRunOptions::liveFrames; a
// render engine's "inset" draws a second camera's picture in the frame's
// upper-right corner, the picture that camera renders at that size.
#include <dm/engine/scene_runtime.hpp>
#include <dm/io/scene_file.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <numbers>
#include <string>

#include "../common/temp_dir.hpp"
#include "scene_run_support.hpp"

namespace scene_view_orbit_test {

#if defined(DM_TEST_WITH_RENDERER)
using dm::Vec3;

// A red ball on a grey table seen by the camera "eye" at `eye` looking at
// (0, 0, 0.05), up +z, rendered at `width` x `height` with `render` keys
// added; a second camera "top" looks straight down on the ball.
dm::SceneDesc ballScene(const Vec3& eye, int width = 160, int height = 120, const std::string& render = "") {
  const std::string at =
      "[" + std::to_string(eye.x()) + ", " + std::to_string(eye.y()) + ", " + std::to_string(eye.z()) + "]";
  return scene_run::parsedScene(R"({"format": "dmplatform-scene", "version": 2, "name": "orbit",
    "resources": {"ball": {"type": "shape", "shape": "sphere", "radius": 0.04, "subdivisions": 4},
                  "table": {"type": "shape", "shape": "box", "half_extents": [0.2, 0.1, 0.01]}},
    "materials": {"red": {"model": "blinn-phong", "color": [0.8, 0.05, 0.05]}},
    "objects": [{"name": "table", "mesh": "table", "pose": {"position": [0, 0, -0.01]}},
                {"name": "ball", "mesh": "ball", "material": "red", "pose": {"position": [0.05, 0, 0.04]}}],
    "lights": [{"type": "directional", "direction": [0.3, 0.5, -0.8], "intensity": 1.2}],
    "cameras": [{"name": "eye", "position": )" +
                                    at +
                                    R"(, "target": [0, 0, 0.05], "up": [0, 0, 1], "near": 0.01, "far": 5},
                {"name": "top", "position": [0.05, 0, 0.5], "target": [0.05, 0, 0], "up": [0, 1, 0],
                 "near": 0.01, "far": 5}],
    "engines": {"render": {"rate_hz": 20, "width": )" +
                                    std::to_string(width) + R"(, "height": )" + std::to_string(height) +
                                    R"(, "hud": false)" + render + R"(}}})",
                                "orbit.json");
}

// The newest frame after 0.1 s, the camera turned by `orbit` when given.
dm::Image frameOf(const dm::SceneDesc& scene, const dm::ViewOrbit* orbit, bool live = true) {
  const dm::test::TempDir dir("view_orbit");
  auto rt = dm::SceneRuntime::create(scene);
  EXPECT_TRUE(rt) << rt.error();
  if (!rt) return {};
  const dm::SceneRunOptions options{.duration = 0.1, .outDir = dir.path(), .liveFrames = live};
  EXPECT_TRUE((*rt)->prepare(options));
  if (orbit) (*rt)->setViewOrbit(*orbit);
  EXPECT_TRUE((*rt)->start(options));
  EXPECT_TRUE((*rt)->advance(0.1));
  std::uint64_t seen = 0;
  dm::Image frame;
  double t = -1.0;
  const bool got = (*rt)->latestFrame(seen, frame, t);
  EXPECT_TRUE((*rt)->finish());
  EXPECT_EQ(got, live);
  if (got) {
    EXPECT_NEAR(t, 0.05, 1e-9);  // the 20 Hz render's last tick in [0, 0.1)
  }
  return frame;
}

// Pixels whose colour differs by more than 3 levels in a channel.
double differing(const dm::Image& a, const dm::Image& b) {
  std::size_t n = 0;
  for (int y = 0; y < a.height(); ++y)
    for (int x = 0; x < a.width(); ++x)
      for (int c = 0; c < 3; ++c)
        if (std::abs(int(a.at<std::uint8_t>(x, y, c)) - int(b.at<std::uint8_t>(x, y, c))) > 3) {
          ++n;
          break;
        }
  return double(n) / double(a.width() * a.height());
}

TEST(SceneViewOrbit, ATurnedCameraSeesWhatACameraPlacedThereSees) {
  const Vec3 eye(0, -0.6, 0.15), target(0, 0, 0.05);
  const dm::ViewOrbit orbit{.yaw = std::numbers::pi / 2, .pitch = 0.3, .zoom = 0.8};
  // Spherical coordinates about the target, up +z: the azimuth turned by
  // the yaw, the angle from +z made smaller by the pitch, the distance
  // scaled by the zoom.
  const Vec3 offset = eye - target;
  const double r = offset.norm(), polar = std::acos(offset.z() / r) - orbit.pitch;
  const double azimuth = std::atan2(offset.y(), offset.x()) + orbit.yaw;
  const Vec3 there = target + orbit.zoom * r *
                                  Vec3(std::sin(polar) * std::cos(azimuth),
                                       std::sin(polar) * std::sin(azimuth), std::cos(polar));
  const dm::Image turned = frameOf(ballScene(eye), &orbit), placed = frameOf(ballScene(there), nullptr);
  const dm::Image unturned = frameOf(ballScene(eye), nullptr);
  ASSERT_FALSE(turned.empty());
  ASSERT_FALSE(placed.empty());
  ASSERT_FALSE(unturned.empty());
  EXPECT_LT(differing(turned, placed), 0.005);   // the same picture, up to rounding at edges
  EXPECT_GT(differing(turned, unturned), 0.05);  // and not the one it started from
  EXPECT_GT(scene_run::redShare(turned), 0.02);
  // Put back (the identity turn), it is the scene camera's picture again.
  const dm::ViewOrbit none;
  EXPECT_LT(differing(frameOf(ballScene(eye), &none), unturned), 0.005);
}

// The ball seen from the front at `width` x `height`, with `render` keys.
dm::SceneDesc twoCameras(int width, int height, const std::string& render) {
  return ballScene(Vec3(0, -0.6, 0.15), width, height, render);
}

TEST(SceneViewOrbit, TheInsetIsTheSecondCamerasPictureInTheUpperRightCorner) {
  const dm::Image framed =
      frameOf(twoCameras(160, 120, R"(, "inset": {"camera": "top", "size": 0.25})"), nullptr);
  const dm::Image top = frameOf(twoCameras(40, 30, R"(, "camera": "top")"), nullptr);
  const dm::Image plain = frameOf(twoCameras(160, 120, ""), nullptr);
  ASSERT_EQ(framed.width(), 160);
  ASSERT_EQ(top.width(), 40);
  ASSERT_EQ(top.height(), 30);
  std::size_t insetDiffer = 0, restDiffer = 0;
  for (int y = 0; y < 120; ++y)
    for (int x = 0; x < 160; ++x) {
      const bool inInset = x >= 120 && y < 30;
      int worst = 0;
      for (int c = 0; c < 3; ++c) {
        const int want = inInset ? top.at<std::uint8_t>(x - 120, y, c) : plain.at<std::uint8_t>(x, y, c);
        worst = std::max(worst, std::abs(int(framed.at<std::uint8_t>(x, y, c)) - want));
      }
      (inInset ? insetDiffer : restDiffer) += worst > 3;
    }
  EXPECT_LE(insetDiffer, 40u * 30u / 100u);  // the top camera's picture (1 %: rounding)
  EXPECT_EQ(restDiffer, 0u);                 // and elsewhere the front camera's
  // The ball seen from above: its 4 cm disk in the 0.35 x 0.46 m the camera
  // sees at the ball's top (45°, 0.42 m away), 3.1 % of the picture, less
  // its darkest rim.
  EXPECT_GT(scene_run::redShare(top), 0.015);
  EXPECT_LT(scene_run::redShare(top), 0.035);
}

TEST(SceneViewOrbit, FramesReachALiveViewOnlyWhenAsked) {
  (void)frameOf(ballScene(Vec3(0, -0.6, 0.15)), nullptr, false);  // latestFrame false (checked inside)
}
#endif

}  // namespace scene_view_orbit_test
