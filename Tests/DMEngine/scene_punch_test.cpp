// The punch renderer in a scene (examples/scenes/tissue_indentation.json):
// a flat punch bonded to the top of an FEM block follows the stylus 3 mm down
// and back. Its force is checked against the model the
// examples/tissue_indentation program builds by hand (dm::tetMeshBox, a
// dm::FemBody with the bottom held and the punch's nodes moved at the
// stylus's velocity, dm::FemBody::computeConstraintForces), stepped here
// along the same depths with a tighter solver: the force along the punch
// agrees to 1e-6 N at every physics step, the hand feels each step's force
// from the next haptic tick on, the unloading branch lies below the loading
// one (the damping's hysteresis), and a region that holds no node fails
// before anything runs.
#include <dm/engine/scene_runtime.hpp>
#include <dm/io/scene_file.hpp>
#include <dm/physics/fem.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <map>

#include "../common/temp_dir.hpp"
#include "scene_run_support.hpp"

namespace scene_punch_test {

using dm::Vec3;
using nlohmann::json;

// The program's model: the block of 8 × 8 × 4 cells of 5 mm, E = 12 kPa,
// ν = 0.45, β = 40 ms, the nine top nodes within 7.5 mm of the axis moved
// to `depth` each step; the force on the punch along +z.
class ProgramModel {
 public:
  ProgramModel() {
    auto mesh = dm::tetMeshBox({8, 8, 4}, Vec3(0.04, 0.04, 0.02), Vec3(-0.02, -0.02, -0.02));
    EXPECT_TRUE(mesh) << mesh.error();
    auto body = dm::FemBody::create(*mesh, {.youngsModulus = 12e3, .poissonRatio = 0.45, .density = 1000},
                                    {.beta = 0.04}, {.tolerance = 1e-9, .maxIterations = 2000});
    EXPECT_TRUE(body) << body.error();
    body_ = std::make_unique<dm::FemBody>(std::move(*body));
    body_->fixNodesWhere([](const Vec3& p) { return p.z() < -0.02 + 1e-9; });
    for (std::size_t i = 0; i < mesh->nodeCount(); ++i) {
      const Vec3& p = mesh->nodes[i];
      if (p.z() > -1e-9 && std::hypot(p.x(), p.y()) <= 7.5e-3 + 1e-9) {
        body_->setFixed(i, true);
        punch_.push_back(i);
      }
    }
    reaction_.resize(body_->nodeCount());
  }
  std::size_t punchNodes() const { return punch_.size(); }
  double step(double depth) {
    const double v = -(depth - depth_) / 0.01;
    for (std::size_t i : punch_) body_->setVelocity(i, Vec3(0, 0, v));
    EXPECT_TRUE(body_->step(0.01));
    depth_ = depth;
    body_->computeConstraintForces(reaction_);
    Vec3 f = Vec3::Zero();
    for (std::size_t i : punch_) f -= reaction_[i];
    return f.z();
  }

 private:
  std::unique_ptr<dm::FemBody> body_;
  std::vector<std::size_t> punch_;
  std::vector<Vec3> reaction_;
  double depth_ = 0;
};

TEST(ScenePunch, TheBundledIndentationFeelsTheProgramsModel) {
  const dm::test::TempDir dir("scene_punch");
  dm::SceneDesc scene = scene_run::bundledScene("tissue_indentation.json");
  const json s = scene_run::runScene(scene, 2.0, dir.path());
  ASSERT_TRUE(s.contains("physics")) << s.dump(1);
  EXPECT_EQ(scene_run::named(s["physics"]["soft"], "block")["punch"]["nodes"], 9);
  const std::vector<scene_run::TraceRow> trace = scene_run::forceTrace(dir / "forces.csv");
  ASSERT_EQ(trace.size(), 2000u);
  // The stylus's depth at each physics step (every 10th tick, which the
  // step reads) drives the program's model; the scene's hand feels that
  // step's force from the next tick on.
  ProgramModel model;
  ASSERT_EQ(model.punchNodes(), 9u);
  std::map<int, double> loading, unloading;  // depth in µm → force
  double peak = 0;
  for (std::size_t k = 0; k + 1 < trace.size(); k += 10) {
    const double depth = std::max(0.0, -trace[k].proxy.z());
    const double expected = model.step(depth);
    const double felt = trace[k + 1].force.z();
    EXPECT_NEAR(felt, expected, 1e-6) << "t = " << trace[k].t;
    peak = std::max(peak, felt);
    const int um = static_cast<int>(std::lround(depth * 1e6));
    (trace[k].t < 1.0 ? loading : unloading)[um] = felt;
  }
  EXPECT_GT(peak, 1.0);  // 3 mm into 12 kPa tissue under a 10 mm punch
  // The same depth on the way up is felt softer: the damping's loop.
  int compared = 0;
  for (const auto& [um, up] : unloading)
    if (auto down = loading.find(um); down != loading.end() && um > 500 && um < 2500) {
      EXPECT_LT(up, down->second) << um << " µm";
      ++compared;
    }
  EXPECT_GT(compared, 10);
}

TEST(ScenePunch, ARegionWithoutNodesFailsBeforeAnythingRuns) {
  const dm::test::TempDir dir("scene_punch_region");
  dm::SceneDesc scene = scene_run::bundledScene("tissue_indentation.json");
  scene.engines.haptics->punch->region = {Vec3(0.1, 0.1, 0.1), Vec3(0.2, 0.2, 0.2)};
  auto rt = dm::SceneRuntime::create(scene);
  ASSERT_TRUE(rt) << rt.error();
  auto r = (*rt)->run({.mode = dm::RunMode::Lockstep, .duration = 0.1, .outDir = dir / "out"});
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().where.find("engines/haptics/punch/region"), std::string::npos) << r.error();
  EXPECT_FALSE(std::filesystem::exists(dir / "out" / "summary.json"));
}

}  // namespace scene_punch_test
