// Soft tissue in a scene run on real-time threads: the haptics engine (the
// god-object on the tissue's newest surface, the needle's local model, or
// the punch bonded to it)
// and the physics engine (the FEM steps) exchange grips, surfaces, poses and
// models through their triple buffers while both run. Run under TSan in CI:
// any unsynchronised access between the two threads is a failure. The
// outcome checks are loose (a sanitizer slows the threads, the FEM steps
// most: 40× under TSan).
#include <dm/engine/scene_runtime.hpp>
#include <dm/io/scene_file.hpp>

#include <gtest/gtest.h>

#include "../common/temp_dir.hpp"
#include "scene_run_support.hpp"

namespace scene_soft_concurrency_test {

using nlohmann::json;

json runRealTime(const dm::SceneDesc& scene, double seconds, const std::filesystem::path& out) {
  auto rt = dm::SceneRuntime::create(scene);
  EXPECT_TRUE(rt) << rt.error();
  if (!rt) return {};
  auto r = (*rt)->run({.mode = dm::RunMode::RealTime, .duration = seconds, .outDir = out});
  EXPECT_TRUE(r) << r.error();
  return r ? r->summary : json();
}

TEST(SceneSoftRealTime, TheGodObjectPressesTissueWhilePhysicsStepsIt) {
  const json s = runRealTime(scene_run::bundledScene("tissue_press.json"), 1.5,
                             dm::test::TempDir("soft_rt_press").path());
  ASSERT_TRUE(s.contains("physics")) << s.dump(2);
  const json& pad = s.at("physics").at("soft").at(0);
  // Under TSan a 5,184-tetrahedron step takes about a quarter of a second
  // (6 steps in 1.5 s), so the physics lags; the haptic loop does not wait.
  EXPECT_GE(pad.at("steps").get<int>(), 2);
  EXPECT_GT(pad.at("gripped_steps").get<int>(), 0) << "the stylus reaches the pad at about 0.44 s";
  EXPECT_GT(s.at("haptics").at("contact_ticks").get<int>(), 100);
}

TEST(SceneSoftRealTime, TheNeedleGoesInWhilePhysicsStepsIt) {
  const json s = runRealTime(scene_run::bundledScene("needle_insertion.json"), 3.0,
                             dm::test::TempDir("soft_rt_needle").path());
  ASSERT_TRUE(s.contains("physics")) << s.dump(2);
  const json& n = s.at("physics").at("soft").at(0).at("needle");
  EXPECT_GT(n.at("models_published").get<int>(), 10);
  EXPECT_GE(n.at("punctures").get<int>(), 1) << "the skin pops at about 1.75 s";
}

TEST(SceneSoftRealTime, ThePunchFollowsTheStylusWhilePhysicsStepsTheTissue) {
  const json s = runRealTime(scene_run::bundledScene("tissue_indentation.json"), 1.0,
                             dm::test::TempDir("soft_rt_punch").path());
  ASSERT_TRUE(s.contains("physics")) << s.dump(2);
  const json& block = s.at("physics").at("soft").at(0);
  EXPECT_GE(block.at("steps").get<int>(), 2);
  EXPECT_GT(block.at("max_tool_force_N").get<double>(), 0.0) << "the punch is 1.5 mm deep at 0.5 s";
}

}  // namespace scene_soft_concurrency_test
