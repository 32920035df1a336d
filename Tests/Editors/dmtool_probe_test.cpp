// dmtool probe end to end: a device path pressing 10 mm into the top face of
// a unit box is replayed through each renderer; the god-object's force is
// stiffness × depth along +z, the 6-DOF methods push up, the CSV has one row
// per tick, the plot is a PNG of the stated size; bad input exits 1 or 2
// naming the file, line and column or the option.
#include <dm/core/volume.hpp>
#include <dm/io/image_io.hpp>
#include <dm/io/mesh_io.hpp>
#include <dm/io/volume_io.hpp>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <fstream>
#include <sstream>
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

// Straight down from 5 cm above the top face (z = 0.5) to 10 mm inside it
// over 0.5 s, then held for 0.5 s.
std::string writePress(const TempDir& dir) {
  const std::string path = (dir.path / "press.csv").string();
  std::ofstream f(path);
  f << "t,x,y,z\n0,0.01,0.02,0.55\n0.5,0.01,0.02,0.49\n1.0,0.01,0.02,0.49\n";
  return path;
}

std::vector<std::vector<double>> readCsv(const std::string& path, std::string& header) {
  std::ifstream f(path);
  std::getline(f, header);
  std::vector<std::vector<double>> rows;
  for (std::string line; std::getline(f, line);) {
    std::vector<double> row;
    std::stringstream ss(line);
    for (std::string cell; std::getline(ss, cell, ',');) row.push_back(std::stod(cell));
    rows.push_back(std::move(row));
  }
  return rows;
}

TEST(DmtoolProbe, GodObjectPressGivesStiffnessTimesDepth) {
  TempDir dir;
  const std::string out = (dir.path / "f.csv").string(), png = (dir.path / "f.png").string();
  const ToolRun r = runTool({"probe", writeUnitBox(dir), "--path", writePress(dir), "--renderer", "godobject",
                             "--stiffness", "800", "-o", out, "--plot", png, "--json"});
  ASSERT_EQ(r.exitCode, 0) << describe(r);
  const nlohmann::json j = parseJson(r);
  EXPECT_EQ(j["renderer"], "godobject");
  EXPECT_EQ(j["ticks"], 1001);
  std::string header;
  const auto rows = readCsv(out, header);
  EXPECT_EQ(header, "t,fx,fy,fz,tx,ty,tz,px,py,pz,qw,qx,qy,qz,contacts,penetration");
  ASSERT_EQ(rows.size(), 1001u);
  const std::vector<double>& last = rows.back();
  ASSERT_EQ(last.size(), 16u);
  EXPECT_NEAR(last[3], 800 * 0.01, 800 * 0.01 * 1e-3);  // fz = k · depth
  EXPECT_NEAR(last[1], 0.0, 1e-9);
  EXPECT_NEAR(last[9], 0.5, 1e-5);  // the proxy rests on the face
  for (const auto& row : rows) {
    if (row[0] < 0.4) {
      EXPECT_EQ(row[3], 0.0) << "force before contact at t = " << row[0];
    }
  }
  const auto image = dm::readPng(png);
  ASSERT_TRUE(image.ok()) << image.error().message();
  EXPECT_EQ(image->width(), 900);
  EXPECT_EQ(image->height(), 420);
}

TEST(DmtoolProbe, SixDofRenderersPushOutOfTheFace) {
  // A 3 cm ball tool held with its centre 10 mm under the face: 40 mm deep,
  // k · depth = 20 N up. The sphere tree's leaves (8 levels: 4 mm cells) and
  // the VPS coupling in series with a 10x stiffer contact each stay within 30%.
  TempDir dir;
  const std::string box = writeUnitBox(dir), press = writePress(dir);
  for (const char* renderer : {"vps", "spheretree"}) {
    const std::string out = (dir.path / (std::string(renderer) + ".csv")).string();
    const ToolRun r =
        runTool({"probe", box, "--path", press, "--renderer", renderer, "--tool-radius", "0.03",
                 "--stiffness", "500", "--voxel-size", "0.02", "--levels", "8", "-o", out, "--json"});
    ASSERT_EQ(r.exitCode, 0) << renderer << ": " << describe(r);
    std::string header;
    const auto rows = readCsv(out, header);
    ASSERT_EQ(rows.size(), 1001u) << renderer;
    const std::vector<double>& last = rows.back();
    EXPECT_NEAR(last[3], 20.0, 6.0) << renderer;
    EXPECT_LT(std::abs(last[1]) + std::abs(last[2]), 0.1 * last[3]) << renderer;
  }
}

// A 10 mm cube of bone below z = 0 as a signed distance volume (0.25 mm).
std::string writeBoneSlab(const TempDir& dir) {
  dm::Affine3 a = dm::Affine3::Identity();
  a.linear() = dm::Mat3::Identity() * 0.25e-3;
  a.translation() = dm::Vec3::Constant(-5e-3);
  auto v = dm::Volume::create(dm::Vec3i(40, 40, 40), dm::VoxelType::F32, a);
  EXPECT_TRUE(v.ok());
  for (int k = 0; k < 40; ++k)
    for (int j = 0; j < 40; ++j)
      for (int i = 0; i < 40; ++i) v->setValue(i, j, k, (a * dm::Vec3(i, j, k)).z());
  const std::string file = (dir.path / "bone.nii").string();
  EXPECT_TRUE(dm::writeVolume(*v, file).ok());
  return file;
}

TEST(DmtoolProbe, BurrDrillsAHoleAndWritesTheBone) {
  // A 1 mm burr pushed from 3 mm above the bone to 1.5 mm below its rest
  // height and held: it drills down, the hand feels the spring up, and the
  // written surface has the hole.
  TempDir dir;
  const std::string press = (dir.path / "drill.csv").string();
  std::ofstream(press) << "t,x,y,z\n0,0,0,0.003\n0.3,0,0,-0.0005\n1.5,0,0,-0.0005\n";
  const std::string out = (dir.path / "f.csv").string(), mesh = (dir.path / "bone.ply").string();
  const ToolRun r =
      runTool({"probe", writeBoneSlab(dir), "--path", press, "--renderer", "burr", "--tool-radius", "0.001",
               "--stiffness", "800", "--rpm", "80000", "--mesh-out", mesh, "-o", out, "--json"});
  ASSERT_EQ(r.exitCode, 0) << describe(r);
  const nlohmann::json j = parseJson(r);
  EXPECT_EQ(j["renderer"], "burr");
  EXPECT_GT(j["removedVolume"].get<double>(), 1e-10);  // well over 0.1 mm³
  std::string header;
  const auto rows = readCsv(out, header);
  ASSERT_EQ(rows.size(), 1501u);
  const std::vector<double>& last = rows.back();
  EXPECT_LT(last[9], 1e-3 - 0.25e-3);  // the burr's centre went below its resting height: a hole
  EXPECT_GT(last[3], 0.0);             // pushed up
  EXPECT_LT(std::abs(last[1]) + std::abs(last[2]), 0.2 * last[3] + 1e-3);
  auto surface = dm::readMesh(mesh);
  ASSERT_TRUE(surface.ok()) << surface.error().message();
  double lowestTop = 1.0;  // the hole's floor, near the axis
  for (const dm::Vec3& p : surface->positions)
    if (std::hypot(p.x(), p.y()) < 0.2e-3) lowestTop = std::min(lowestTop, p.z() > -4e-3 ? p.z() : 1.0);
  EXPECT_LT(lowestTop, -0.25e-3);
  // The burr's options belong to it alone.
  const ToolRun wrong = runTool(
      {"probe", writeBoneSlab(dir), "--path", press, "--renderer", "vps", "--rpm", "1000", "-o", out});
  EXPECT_EQ(wrong.exitCode, 1) << describe(wrong);
  EXPECT_NE(wrong.err.find("--rpm"), std::string::npos) << wrong.err;
}

TEST(DmtoolProbe, BadInputIsNamed) {
  TempDir dir;
  const std::string box = writeUnitBox(dir), out = (dir.path / "f.csv").string();
  const std::string bad = (dir.path / "bad.csv").string();
  std::ofstream(bad) << "t,x,y,z\n0,0,0,0\n0.1,0,zz,0\n";
  ToolRun r = runTool({"probe", box, "--path", bad, "-o", out});
  EXPECT_EQ(r.exitCode, 1) << describe(r);
  EXPECT_NE(r.err.find("bad.csv:3:"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("field 'y'"), std::string::npos) << r.err;

  r = runTool({"probe", box, "--path", writePress(dir), "--friction", "0.2,0.5", "-o", out});
  EXPECT_EQ(r.exitCode, 1) << describe(r);
  EXPECT_NE(r.err.find("dynamicFriction"), std::string::npos) << r.err;

  r = runTool({"probe", box, "-o", out});  // no --path
  EXPECT_EQ(r.exitCode, 2) << describe(r);
  r = runTool({"probe", box, "--path", writePress(dir), "--renderer", "magic", "-o", out});
  EXPECT_EQ(r.exitCode, 2) << describe(r);
  EXPECT_FALSE(std::ifstream(out).good()) << "no output may be written on failure";
}

}  // namespace
