// dmtool phantom end to end: the written file is the generator's scan voxel
// for voxel on the documented grid (read back through DMIO, and by
// `dmtool info`), its values span air to cortical bone, and bad options
// exit 1 naming the field or 2 for bad usage.
#include <dm/io/volume_io.hpp>
#include <dm/math/phantom.hpp>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cstring>
#include <string>

#include "dmtool_run.hpp"

namespace dmtool_phantom_test {

using dmtool_test::describe;
using dmtool_test::parseJson;
using dmtool_test::runTool;
using dmtool_test::TempDir;
using dmtool_test::ToolRun;
using nlohmann::json;

TEST(DmtoolPhantom, WritesTheCalvariumScanTheGeneratorMakes) {
  TempDir tmp;
  const std::string out = (tmp.path / "calvarium.nrrd").string();
  const ToolRun r = runTool({"phantom", "calvarium", "-o", out, "--spacing", "0.0005", "--half-width",
                             "0.005", "--below", "0.009", "--seed", "3", "--json"});
  ASSERT_EQ(r.exitCode, 0) << describe(r);
  const json j = parseJson(r);
  // 10 mm across and 17 mm deep at 0.5 mm.
  EXPECT_EQ(j["dims"], json::array({20, 20, 34}));
  EXPECT_EQ(j["datatype"], "int16");
  EXPECT_EQ(j["range"], json::array({-1000, 1800}));  // air above the scalp; the outer table's inside
  // The file holds the generator's scan, voxel for voxel, where it says.
  dm::CalvariumPhantom p;
  p.spacing = 0.0005;
  p.halfWidth = 0.005;
  p.below = 0.009;
  p.seed = 3;
  auto want = dm::makeCalvariumPhantom(p);
  ASSERT_TRUE(want) << want.error();
  auto got = dm::readVolume(out);
  ASSERT_TRUE(got) << got.error();
  ASSERT_EQ(got->dims(), want->dims());
  ASSERT_EQ(got->type(), dm::VoxelType::I16);
  EXPECT_EQ(std::memcmp(got->bytes(), want->bytes(), want->byteSize()), 0);
  EXPECT_TRUE(got->indexToWorld().isApprox(want->indexToWorld(), 1e-12));
  const ToolRun info = runTool({"info", "--json", out});
  ASSERT_EQ(info.exitCode, 0) << describe(info);
  EXPECT_EQ(parseJson(info)["dims"], j["dims"]);
}

TEST(DmtoolPhantom, BadOptionsAreNamed) {
  TempDir tmp;
  const std::string out = (tmp.path / "x.nrrd").string();
  // A vault flatter than the patch is wide: the operation fails, naming the field.
  const ToolRun flat = runTool({"phantom", "calvarium", "-o", out, "--radius", "0.01"});
  EXPECT_EQ(flat.exitCode, 1) << describe(flat);
  EXPECT_NE(flat.err.find("radius"), std::string::npos) << flat.err;
  EXPECT_FALSE(std::filesystem::exists(out));
  // An unknown kind, a zero spacing: usage errors.
  EXPECT_EQ(runTool({"phantom", "femur", "-o", out}).exitCode, 2);
  EXPECT_EQ(runTool({"phantom", "calvarium", "-o", out, "--spacing", "0"}).exitCode, 2);
}

}  // namespace dmtool_phantom_test
