// dmtool spheretree end to end: runs the built dmtool on the unit box of
// assimp-testmodels and checks the written JSON against the geometry: the
// root is the cube's circumsphere (radius √3/2, tightness = its volume / 1 m³),
// every level's sphere list matches its count, and every corner and face
// point of the box lies in some deepest-level sphere; bad input exits 1
// naming the file, bad usage exits 2.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <string>
#include <vector>

#include "dmtool_run.hpp"

namespace {

namespace fs = std::filesystem;
using dmtool_test::describe;
using dmtool_test::parseJson;
using dmtool_test::runTool;
using dmtool_test::TempDir;
using dmtool_test::ToolRun;
using nlohmann::json;

const std::string kBox = "/usr/share/assimp/models/OBJ/box.obj";

json readJson(const fs::path& p) {
  std::ifstream in(p);
  return json::parse(in, nullptr, /*allow_exceptions=*/false);
}

bool inSomeSphere(const json& spheres, double x, double y, double z) {
  for (const json& s : spheres) {
    const double dx = x - s[0].get<double>(), dy = y - s[1].get<double>(), dz = z - s[2].get<double>();
    if (std::sqrt(dx * dx + dy * dy + dz * dz) <= s[3].get<double>() + 1e-12) return true;
  }
  return false;
}

// Corners and a grid of points on the six faces of the unit box.
std::vector<std::array<double, 3>> boxSurface() {
  std::vector<std::array<double, 3>> pts;
  for (int a = 0; a < 3; ++a)
    for (double side : {-0.5, 0.5})
      for (int u = 0; u <= 10; ++u)
        for (int v = 0; v <= 10; ++v) {
          std::array<double, 3> p{};
          p[a] = side;
          p[(a + 1) % 3] = -0.5 + u / 10.0;
          p[(a + 2) % 3] = -0.5 + v / 10.0;
          pts.push_back(p);
        }
  return pts;
}

TEST(DmtoolSpheretree, BoxTreeCoversTheBox) {
  TempDir dir;
  const fs::path out = dir.path / "tree.json";
  const ToolRun r = runTool({"spheretree", kBox, "--levels", "3", "-o", out.string(), "--json"});
  ASSERT_EQ(r.exitCode, 0) << describe(r);
  const json summary = parseJson(r);
  EXPECT_EQ(summary["method"], "octree");
  ASSERT_EQ(summary["levels"].size(), 3u);

  const json tree = readJson(out);
  ASSERT_TRUE(tree.is_object());
  EXPECT_EQ(tree["units"], "m");
  EXPECT_EQ(tree["method"], "octree");
  EXPECT_EQ(tree["kind"], "mesh");
  EXPECT_NE(tree["source"].get<std::string>().find("box.obj"), std::string::npos);
  const json& levels = tree["levels"];
  ASSERT_EQ(levels.size(), 3u);
  for (std::size_t l = 0; l < 3; ++l) {
    EXPECT_EQ(levels[l]["level"], l);
    EXPECT_EQ(levels[l]["spheres"].size(), levels[l]["count"].get<std::size_t>());
    EXPECT_EQ(summary["levels"][l]["count"], levels[l]["count"]);
  }
  // Root: the circumsphere of the unit cube; tightness = its volume / 1 m³.
  ASSERT_EQ(levels[0]["count"], 1);
  const json& root = levels[0]["spheres"][0];
  const double r0 = std::sqrt(3.0) / 2;
  EXPECT_NEAR(root[3].get<double>(), r0, 1e-9);
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(root[i].get<double>(), 0.0, 1e-9);
  EXPECT_NEAR(levels[0]["tightness"].get<double>(), 4.0 / 3.0 * std::numbers::pi * r0 * r0 * r0, 1e-8);
  // Level 1: one octant cell per corner, each holding three quarter faces.
  EXPECT_EQ(levels[1]["count"], 8);
  const json& deepest = levels[2]["spheres"];
  for (double x : {-0.5, 0.5})
    for (double y : {-0.5, 0.5})
      for (double z : {-0.5, 0.5}) EXPECT_TRUE(inSomeSphere(deepest, x, y, z)) << x << " " << y << " " << z;
  for (const auto& p : boxSurface()) EXPECT_TRUE(inSomeSphere(deepest, p[0], p[1], p[2]));
  // Deeper spheres are smaller.
  EXPECT_LT(levels[2]["maxRadius"].get<double>(), levels[1]["maxRadius"].get<double>());
}

TEST(DmtoolSpheretree, FittedSolidTreeAndTextSummary) {
  TempDir dir;
  const fs::path out = dir.path / "solid.json";
  const ToolRun r =
      runTool({"spheretree", kBox, "--levels", "3", "--method", "fitted", "--solid", "-o", out.string()});
  ASSERT_EQ(r.exitCode, 0) << describe(r);
  EXPECT_NE(r.out.find("level  2"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("tightness"), std::string::npos) << r.out;
  const json tree = readJson(out);
  ASSERT_TRUE(tree.is_object());
  EXPECT_EQ(tree["method"], "fitted");
  EXPECT_TRUE(tree["solid"].get<bool>());
  EXPECT_NEAR(tree["referenceVolume"].get<double>(), 1.0, 1e-12);
  const json& deepest = tree["levels"][2]["spheres"];
  // The solid cover holds the centre and the corners; its spheres hold at
  // least the box's volume.
  EXPECT_TRUE(inSomeSphere(deepest, 0, 0, 0));
  for (double x : {-0.5, 0.5})
    for (double y : {-0.5, 0.5})
      for (double z : {-0.5, 0.5}) EXPECT_TRUE(inSomeSphere(deepest, x, y, z));
  for (const json& level : tree["levels"]) EXPECT_GE(level["tightness"].get<double>(), 1.0 - 1e-9);
}

TEST(DmtoolSpheretree, ErrorsAndUsage) {
  TempDir dir;
  const std::string out = (dir.path / "t.json").string();
  const std::string missing = (dir.path / "no_such_mesh.obj").string();
  ToolRun r = runTool({"spheretree", missing, "-o", out});
  EXPECT_EQ(r.exitCode, 1) << describe(r);
  EXPECT_NE(r.err.find("no_such_mesh.obj"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(out));
  r = runTool({"spheretree", kBox});  // no -o
  EXPECT_EQ(r.exitCode, 2) << describe(r);
  r = runTool({"spheretree", kBox, "--levels", "0", "-o", out});
  EXPECT_EQ(r.exitCode, 2) << describe(r);
  r = runTool({"spheretree", kBox, "--method", "voronoi", "-o", out});
  EXPECT_EQ(r.exitCode, 2) << describe(r);
}

}  // namespace
