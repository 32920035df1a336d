// The segmentation engine in a scene run on real-time threads: the haptic
// loop evaluates the guidance (the edge map fixed at build) every tick and
// hands the device point to the segmentation engine through its own triple
// buffer, while that engine paints on its thread. Run under TSan in CI: any
// unsynchronised access between the two is a failure. A homogeneous ball
// (10 mm, 1 mm voxels) keeps the build quick under the sanitizer; the
// outcome checks are loose (the threads run slower there).
#include <dm/engine/scene_runtime.hpp>
#include <dm/io/scene_file.hpp>

#include <gtest/gtest.h>

#include <string>

#include "../common/temp_dir.hpp"
#include "scene_run_support.hpp"

namespace scene_segmentation_concurrency_test {

using nlohmann::json;

#if defined(DM_TEST_WITH_VISION)

TEST(SceneSegmentationRealTime, ThePaintingReadsTheToolWhileTheLoopFeelsTheGuidance) {
  const dm::test::TempDir dir("segmentation_rt");
  scene_run::writeBallVolume(dir / "ball.nii.gz", 0.010);
  const dm::SceneDesc scene =
      scene_run::parsedScene(R"({"format": "dmplatform-scene", "version": 2, "name": "ball",
    "resources": {"ball": {"type": "volume", "source": "ball.nii.gz"}},
    "devices": [{"name": "stylus", "driver": "sim-haptic",
                 "config": {"path": "circle", "radius": 0.004, "period": 1}}],
    "engines": {
      "haptics": {"device": "stylus", "renderer": "none"},
      "segmentation": {"volume": "ball", "seed": [0, 0, 0], "rate_hz": 50, "max_radius": 0.008, "gain": 0.01}
    },
    "outputs": {"forces": false, "plot": false, "summary": true}})",
                             "ball.json", dir.path());
  auto rt = dm::SceneRuntime::create(scene);
  ASSERT_TRUE(rt) << rt.error();
  auto r = (*rt)->run({.mode = dm::RunMode::RealTime, .duration = 1.0, .outDir = dir / "out"});
  ASSERT_TRUE(r) << r.error();
  const json& g = r->summary.at("segmentation");
  EXPECT_GE(g.at("updates").get<int>(), 5);
  EXPECT_GT(g.at("painted_voxels").get<int>(), 0);
  EXPECT_GT(r->summary.at("haptics").at("max_force_N").get<double>(), 0.0);
}

#endif

}  // namespace scene_segmentation_concurrency_test
