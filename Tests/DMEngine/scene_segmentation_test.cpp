// A scene's segmentation engine (DMVision's haptic-guided segmentation at the
// haptic tool, its guidance in the haptic loop) on a volume whose answer is
// known: a homogeneous ball of 10 mm radius at 1 mm voxels, the probe (a
// stylus in free space, renderer "none") circling 4 mm off its centre. It
// paints only the ball (precision 1 against the reference grown from the
// seed, which is the ball's voxels: 4/3·π·(10 mm)³ within the voxelisation),
// its guidance pushes the probe away from the nearer edge — toward the
// centre — on every tick it acts, nothing without guidance, the mask is
// written with the volume's geometry, and a seed outside the volume fails
// before anything runs, naming the key.
#include <dm/engine/scene_runtime.hpp>
#include <dm/io/scene_file.hpp>
#include <dm/io/volume_io.hpp>  // readVolume

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <numbers>
#include <string>

#include "../common/temp_dir.hpp"
#include "scene_run_support.hpp"

namespace scene_segmentation_test {

using nlohmann::json;
namespace fs = std::filesystem;

#if defined(DM_TEST_WITH_VISION)

constexpr double kBallRadius = 0.010;  // m
constexpr int kN = 40;                 // voxels a side, 1 mm, centred on the origin

std::string ballScene(bool guidance, const std::string& seed = "[0, 0, 0]") {
  return R"({"format": "dmplatform-scene", "version": 2, "name": "ball",
    "resources": {"ball": {"type": "volume", "source": "ball.nii.gz"}},
    "devices": [{"name": "stylus", "driver": "sim-haptic",
                 "config": {"path": "circle", "radius": 0.004, "period": 1}}],
    "engines": {
      "haptics": {"device": "stylus", "renderer": "none"},
      "segmentation": {"volume": "ball", "seed": )" +
         seed + R"(, "guidance": )" + (guidance ? "true" : "false") +
         R"(, "max_radius": 0.008, "gain": 0.01, "reference": {"k": 2.5}}
    },
    "outputs": {"forces": true, "plot": false, "summary": true}})";
}

TEST(SceneSegmentation, ItPaintsTheBallAndItsGuidancePushesTowardTheCentre) {
  const dm::test::TempDir dir("scene_segmentation");
  scene_run::writeBallVolume(dir / "ball.nii.gz", kBallRadius, kN);
  const dm::SceneDesc scene = scene_run::parsedScene(ballScene(true), "ball.json", dir.path());
  const json s = scene_run::runScene(scene, 1.0, dir / "guided");
  ASSERT_TRUE(s.contains("segmentation")) << s.dump(1);
  const json& g = s["segmentation"];
  EXPECT_EQ(g["updates"].get<int>(), 20);               // 20 Hz for 1 s
  EXPECT_EQ(g["window"], json::array({100.0, 100.0}));  // the seed's neighbourhood: all 100
  const double ballMl = 4.0 / 3.0 * std::numbers::pi * std::pow(kBallRadius, 3) * 1e6;
  EXPECT_NEAR(g["reference_ml"].get<double>(), ballMl, 0.05 * ballMl);
  EXPECT_EQ(g["precision"].get<double>(), 1.0);
  EXPECT_EQ(g["outside_volume_voxels"].get<int>(), 0);
  EXPECT_GT(g["painted_ml"].get<double>(), 0.0);
  EXPECT_LE(g["painted_ml"].get<double>(), g["reference_ml"].get<double>());
  auto mask = dm::readVolume(dir / "guided" / "segmentation.nii.gz");
  ASSERT_TRUE(mask) << mask.error();
  EXPECT_EQ(mask->dims(), dm::Vec3i(kN, kN, kN));
  // The probe is 4 mm off centre, the edge 6 mm away outward and 14 mm
  // inward: the guidance points inward, toward the centre.
  int acting = 0;
  for (const scene_run::TraceRow& row : scene_run::forceTrace(dir / "guided" / "forces.csv")) {
    if (row.force.norm() < 1e-9) continue;
    ++acting;
    EXPECT_LT(row.force.dot(row.proxy), -0.9 * row.force.norm() * row.proxy.norm())
        << row.t;  // proxy = device point
  }
  EXPECT_GT(acting, 900);

  const dm::SceneDesc control = scene_run::parsedScene(ballScene(false), "ball.json", dir.path());
  const json c = scene_run::runScene(control, 1.0, dir / "control");
  EXPECT_EQ(c["haptics"]["max_force_N"].get<double>(), 0.0);
  EXPECT_FALSE(c["segmentation"]["guidance"].get<bool>());
}

TEST(SceneSegmentation, ASeedOutsideTheVolumeFailsBeforeTheRun) {
  const dm::test::TempDir dir("scene_segmentation_seed");
  scene_run::writeBallVolume(dir / "ball.nii.gz", kBallRadius, kN);
  const dm::SceneDesc scene = scene_run::parsedScene(ballScene(true, "[0.5, 0, 0]"), "ball.json", dir.path());
  auto rt = dm::SceneRuntime::create(scene);
  ASSERT_TRUE(rt) << rt.error();
  auto r = (*rt)->run({.mode = dm::RunMode::Lockstep, .duration = 0.1, .outDir = dir / "out"});
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().where.find("engines/segmentation/seed"), std::string::npos) << r.error();
  EXPECT_FALSE(fs::exists(dir / "out" / "summary.json"));
}

#endif

}  // namespace scene_segmentation_test
