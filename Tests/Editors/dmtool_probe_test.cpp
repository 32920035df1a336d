// dmtool probe end to end: a device path pressing 10 mm into the top face of
// a unit box is replayed through each renderer; the god-object's force is
// stiffness × depth along +z, the 6-DOF methods push up, the CSV has one row
// per tick, the plot is a PNG of the stated size; bad input exits 1 or 2
// naming the file, line and column or the option.
#include <dm/io/image_io.hpp>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

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
