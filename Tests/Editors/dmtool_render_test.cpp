// dmtool render and validate on scene files written by the test.
#include <dm/io/image_io.hpp>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <numbers>
#include <string>

#include "dmtool_run.hpp"

using namespace dmtool_test;

namespace {

// A sphere of radius 5 cm seen by an orthographic camera 40 cm tall: on a
// 200 x 200 image that is 500 px/m, so the disc covers pi (25 px)^2.
std::string writeSphereScene(const TempDir& dir, const std::string& extra = "") {
  const auto path = dir.path / "sphere.json";
  std::ofstream(path) << R"({
  "format": "dmplatform-scene", "version": 1, "name": "sphere",
  "resources": {"ball": {"type": "shape", "shape": "sphere", "radius": 0.05, "subdivisions": 5}},
  "materials": {"white": {"model": "blinn-phong", "color": [0.9, 0.9, 0.9]}},
  "objects": [{"name": "ball", "mesh": "ball", "material": "white"}],
  "lights": [{"type": "directional", "direction": [0, 0, -1], "intensity": 1.0}],
  "cameras": [{"name": "top", "projection": "orthographic", "ortho_height": 0.4,
               "position": [0, 0, 1], "target": [0, 0, 0], "up": [0, 1, 0], "near": 0.1, "far": 2)" +
                             extra + R"(}]
})";
  return path.string();
}

}  // namespace

TEST(DmtoolRender, SphereCoversTheAnalyticDisc) {
  TempDir dir;
  const std::string png = (dir.path / "sphere.png").string();
  const ToolRun r = runTool(
      {"render", writeSphereScene(dir), "-o", png, "--size", "200x200", "--samples", "4", "--json"}, 120.0);
  ASSERT_EQ(r.exitCode, 0) << describe(r);
  const nlohmann::json j = parseJson(r);
  EXPECT_EQ(j["width"], 200);
  EXPECT_GT(j["triangles"].get<int>(), 10000);
  auto img = dm::readPng(png);
  ASSERT_TRUE(img) << img.error();
  ASSERT_EQ(img->width(), 200);
  // Covered = differs from the background corner pixel.
  double covered = 0;
  const int bg = img->at<std::uint8_t>(0, 0, 0);
  for (int y = 0; y < 200; ++y)
    for (int x = 0; x < 200; ++x) {
      const int v = img->at<std::uint8_t>(x, y, 0);
      covered += std::clamp(double(v - bg) / 40.0, 0.0, 1.0) > 0.5 ? 1 : 0;
    }
  const double expected = std::numbers::pi * 25.0 * 25.0;
  EXPECT_NEAR(covered, expected, 0.03 * expected);
  // Lit straight on, the centre is the brightest pixel region.
  EXPECT_GT(img->at<std::uint8_t>(100, 100, 0), img->at<std::uint8_t>(100, 80, 0));
}

TEST(DmtoolRender, BadSceneOrSizeIsAnError) {
  TempDir dir;
  const std::string png = (dir.path / "x.png").string();
  ToolRun r = runTool({"render", writeSphereScene(dir), "-o", png, "--size", "200by200"});
  EXPECT_EQ(r.exitCode, 2) << describe(r);
  r = runTool({"render", writeSphereScene(dir), "-o", png, "--camera", "nope"});
  EXPECT_EQ(r.exitCode, 1) << describe(r);
  EXPECT_NE(r.err.find("nope"), std::string::npos) << r.err;
  r = runTool({"render", writeSphereScene(dir, R"(, "fov_y_deg": 400)"), "-o", png});
  EXPECT_EQ(r.exitCode, 1) << describe(r);
  EXPECT_NE(r.err.find("/cameras/0/fov_y_deg"), std::string::npos) << r.err;
  EXPECT_FALSE(std::filesystem::exists(png));
}

TEST(DmtoolValidate, ReportsEveryProblemWithItsPath) {
  TempDir dir;
  ToolRun r = runTool({"validate", writeSphereScene(dir), "--load", "--json"});
  ASSERT_EQ(r.exitCode, 0) << describe(r);
  EXPECT_TRUE(parseJson(r)["valid"].get<bool>());
  const auto bad = dir.path / "bad.json";
  std::ofstream(bad) << R"({"format": "dmplatform-scene", "version": 1,
    "resources": {"ball": {"type": "shape", "shape": "sphere", "radius": -1}},
    "objects": [{"name": "o", "mesh": "bal"}]})";
  r = runTool({"validate", bad.string(), "--json"});
  ASSERT_EQ(r.exitCode, 1) << describe(r);
  const nlohmann::json j = parseJson(r);
  EXPECT_FALSE(j["valid"].get<bool>());
  ASSERT_GE(j["problems"].size(), 2u);
  std::string all = j["problems"].dump();
  EXPECT_NE(all.find("/resources/ball/radius"), std::string::npos) << all;
  EXPECT_NE(all.find("/objects/0/mesh"), std::string::npos) << all;
  EXPECT_NE(all.find("did you mean"), std::string::npos) << all;
}
