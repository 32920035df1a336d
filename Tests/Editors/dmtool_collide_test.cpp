// dmtool collide end to end: two unit boxes (an OBJ written here) and
// primitive specs at poses whose distance, overlap, contact depth and normal
// have closed forms; malformed poses and specs exit 2 naming the option, a
// missing mesh file exits 1 naming the file.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <string>
#include <vector>

#include "dmtool_run.hpp"

namespace {

using dmtool_test::describe;
using dmtool_test::parseJson;
using dmtool_test::runTool;
using dmtool_test::TempDir;
using dmtool_test::ToolRun;
using dmtool_test::writeUnitBox;
using nlohmann::json;

// Round-trip decimal text of x.
std::string num(double x) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.17g", x);
  return buf;
}

std::string translated(double x, double y = 0.0, double z = 0.0) {
  return num(x) + " " + num(y) + " " + num(z) + " 1 0 0 0";
}

json query(const std::string& a, const std::string& b, const std::string& poseB, const std::string& kind,
           const std::string& poseA = "0 0 0 1 0 0 0") {
  const ToolRun r =
      runTool({"collide", a, b, "--pose-a", poseA, "--pose-b", poseB, "--query", kind, "--json"});
  EXPECT_EQ(r.exitCode, 0) << describe(r);
  json j = parseJson(r);
  EXPECT_EQ(j["supported"], true) << r.out;
  return j;
}

TEST(DmtoolCollide, DistanceBetweenTwoBoxMeshesIsTheGap) {
  TempDir dir;
  const std::string box = writeUnitBox(dir);
  json j = query(box, box, translated(1.25, 0.1, -0.2), "distance");
  EXPECT_NEAR(j["distance"].get<double>(), 0.25, 1e-12);
  EXPECT_NEAR(j["pointA"][0].get<double>(), 0.5, 1e-12);
  EXPECT_NEAR(j["pointB"][0].get<double>(), 0.75, 1e-12);
  // The boolean on both sides of touching.
  EXPECT_EQ(query(box, box, translated(1.25), "boolean")["colliding"], false);
  EXPECT_EQ(query(box, box, translated(0.9), "boolean")["colliding"], true);
}

TEST(DmtoolCollide, RotatedBoxByQuaternion) {
  TempDir dir;
  const std::string box = writeUnitBox(dir);
  // 45° about z: B's vertical edge reaches √2/2 m towards A's face at x = 0.5.
  const double h = std::acos(-1.0) / 8;
  const double reach = std::sqrt(0.5);
  const std::string rotated =
      num(0.5 + reach + 0.1) + " 0 0 " + num(std::cos(h)) + " 0 0 " + num(std::sin(h));
  json j = query(box, box, rotated, "distance");
  EXPECT_NEAR(j["distance"].get<double>(), 0.1, 1e-12);
  // The same with A rotated instead and a sphere for B.
  const std::string rotA = "0 0 0 " + num(std::cos(h)) + " 0 0 " + num(std::sin(h));
  j = query(box, "sphere:0.2", translated(reach + 0.3), "distance", rotA);
  EXPECT_NEAR(j["distance"].get<double>(), 0.1, 1e-12);
}

TEST(DmtoolCollide, ContactsHaveTheOverlapDepthAndFaceNormal) {
  TempDir dir;
  const std::string box = writeUnitBox(dir);
  // Mesh box against a sphere, a box primitive (mesh–convex) and box–box.
  const std::vector<std::pair<std::string, double>> cases = {
      {"sphere:0.25", 0.7}, {"box:0.25,0.25,0.25", 0.7}, {"box:0.5,0.5,0.5", 0.95}};
  for (const auto& [b, x] : cases) {
    const bool primitiveA = b == "box:0.5,0.5,0.5";
    json j = query(primitiveA ? "box:0.5,0.5,0.5" : box, b, translated(x, 0.05, -0.03), "contacts");
    EXPECT_EQ(j["colliding"], true) << b;
    ASSERT_TRUE(j["contacts"].is_array() && !j["contacts"].empty()) << j;
    for (const json& c : j["contacts"]) {
      EXPECT_NEAR(c["depth"].get<double>(), 0.05, 1e-9) << b << ' ' << j;
      EXPECT_NEAR(c["normal"][0].get<double>(), 1.0, 1e-9) << b << ' ' << j;
      EXPECT_NEAR(c["position"][0].get<double>(), 0.5, 0.05 + 1e-9) << b << ' ' << j;
    }
    EXPECT_NEAR(
        query(primitiveA ? "box:0.5,0.5,0.5" : box, b, translated(x, 0.05, -0.03), "distance")["distance"]
            .get<double>(),
        -0.05, 1e-9)
        << b;
  }
  // Apart: no contacts.
  json j = query(box, "sphere:0.25", translated(2.0), "contacts");
  EXPECT_EQ(j["colliding"], false);
  EXPECT_TRUE(j["contacts"].empty());
}

TEST(DmtoolCollide, HumanReadableOutput) {
  const ToolRun r =
      runTool({"collide", "sphere:0.1", "sphere:0.2", "--pose-b", translated(0.5), "--query", "distance"});
  ASSERT_EQ(r.exitCode, 0) << describe(r);
  EXPECT_NE(r.out.find("distance"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("0.2"), std::string::npos) << r.out;  // 0.5 − 0.1 − 0.2
}

TEST(DmtoolCollide, BadPosesAndSpecsExitTwoNamingTheOption) {
  const std::vector<std::vector<std::string>> bad = {
      {"--pose-a", "0 0 0 1 0 0"},       // six numbers
      {"--pose-b", "0 0 x 1 0 0 0"},     // not a number
      {"--pose-b", "0 0 0 1 0.01 0 0"},  // |q| = 1.00005
  };
  for (const auto& opt : bad) {
    const ToolRun r = runTool({"collide", "sphere:0.1", "sphere:0.1", opt[0], opt[1]});
    EXPECT_EQ(r.exitCode, 2) << opt[1] << '\n' << describe(r);
    EXPECT_NE(r.err.find(opt[0]), std::string::npos) << describe(r);
  }
  for (const std::string spec : {"sphere:-1", "box:0.1,0.2"}) {
    const ToolRun r = runTool({"collide", spec, "sphere:0.1"});
    EXPECT_EQ(r.exitCode, 2) << spec << '\n' << describe(r);
    EXPECT_NE(r.err.find(spec), std::string::npos) << describe(r);
  }
  const ToolRun q = runTool({"collide", "sphere:0.1", "sphere:0.1", "--query", "volume"});
  EXPECT_EQ(q.exitCode, 2) << describe(q);
}

TEST(DmtoolCollide, MissingMeshFileExitsOneNamingIt) {
  TempDir dir;
  const std::string missing = (dir.path / "no_such_tool.obj").string();
  const ToolRun r = runTool({"collide", "sphere:0.1", missing, "--query", "distance"});
  EXPECT_EQ(r.exitCode, 1) << describe(r);
  EXPECT_NE(r.err.find("no_such_tool.obj"), std::string::npos) << describe(r);
  EXPECT_TRUE(r.out.empty()) << r.out;
}

}  // namespace
