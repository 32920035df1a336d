// The physics engine of a scene run: rigid bodies from scene objects,
// checked against mechanics — Coulomb sliding to rest, free fall, mass from
// density — and the haptic tool pushing a box (examples/scenes/box_push.json):
// the box moves, the momentum the hand gives away is the box's, and at rest
// the hand feels what the table holds (Newton's third law through the
// haptic–physics coupling). Lockstep reruns are bit-identical.
#include <dm/core/filesystem.hpp>
#include <dm/engine/scene_runtime.hpp>
#include <dm/io/scene_file.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <numbers>
#include <sstream>

#include "../common/build_paths.hpp"
#include "../common/temp_dir.hpp"
#include "scene_run_support.hpp"

namespace {

namespace fs = std::filesystem;
using nlohmann::json;

constexpr double kG = 9.80665;

using scene_run::fileText;
using scene_run::runScene;
using scene_run::vec;

const json& body(const json& summary, const std::string& name) {
  return scene_run::named(summary.at("physics").at("bodies"), name);
}

// The bundled box-push scene, without its render engine (the physics is
// what is checked here; example_box_push_lockstep renders it).
dm::SceneDesc boxPush() { return scene_run::bundledScene("box_push.json"); }

// A table and one dynamic body on it, no haptics.
dm::SceneDesc tableScene(const std::string& bodyResource, const std::string& bodyKeys) {
  const std::string text = R"({
    "format": "dmplatform-scene", "version": 2, "name": "table",
    "resources": {
      "table": {"type": "shape", "shape": "plane", "half_extents": [1, 1]},
      "box": {"type": "shape", "shape": "box", "half_extents": [0.02, 0.03, 0.01]},
      "ball": {"type": "shape", "shape": "sphere", "radius": 0.01}
    },
    "objects": [
      {"name": "table", "mesh": "table", "contact": {"friction": 0.3}},
      {"name": "body", "mesh": ")" +
                           bodyResource + R"(", "dynamic": true, )" + bodyKeys + R"(}
    ],
    "engines": {"physics": {"rate_hz": 1000}},
    "outputs": {"summary": true}
  })";
  return scene_run::parsedScene(text, "table.json");
}

}  // namespace

TEST(ScenePhysics, BoxSlidesToRestAfterTheCoulombDistance) {
  // A box launched at v0 along a table with μ = 0.3 decelerates at μ g and
  // stops after v0² / (2 μ g) = 42.5 mm.
  const double v0 = 0.5, mu = 0.3;
  const dm::SceneDesc scene = tableScene(
      "box",
      R"("mass": 0.1, "velocity": [0.5, 0, 0], "contact": {"friction": 0.3}, "pose": {"position": [0, 0, 0.01]})");
  const json s = runScene(scene, 0.5, dm::test::TempDir("physics_slide").path());
  const json& b = body(s, "body");
  const double expected = v0 * v0 / (2.0 * mu * kG);
  const dm::Vec3 x = vec(b.at("position_m"));
  EXPECT_NEAR(x.x(), expected, 0.02 * expected) << s.dump(2);
  // Sideways: the four corner contacts' friction is solved one after the
  // other (Gauss–Seidel), which leaves a drift of ~0.1 µm over the slide.
  EXPECT_NEAR(x.y(), 0.0, 1e-6);
  EXPECT_NEAR(x.z(), 0.01, 2e-4);  // resting on the table, within the solver's slop
  EXPECT_LT(vec(b.at("velocity_m_s")).norm(), 1e-6);
  // At rest the table carries the weight: contact force = −m g.
  const dm::Vec3 f = vec(b.at("contact_force_N"));
  EXPECT_NEAR(f.z(), 0.1 * kG, 1e-6 * kG);
  EXPECT_NEAR(std::hypot(f.x(), f.y()), 0.0, 1e-9);
}

TEST(ScenePhysics, BallFallsFreelyWithMassFromDensity) {
  // 0.2 s of free fall from 0.5 m (it does not reach the table): the
  // symplectic Euler steps of the world give z_n = z0 − g h² n(n+1)/2,
  // within h g t / 2 of the parabola; mass = ρ 4/3 π r³.
  const dm::SceneDesc scene = tableScene("ball", R"("density": 1000, "pose": {"position": [0, 0, 0.5]})");
  const json s = runScene(scene, 0.2, dm::test::TempDir("physics_fall").path());
  const json& b = body(s, "body");
  EXPECT_NEAR(b.at("mass_kg").get<double>(), 1000.0 * 4.0 / 3.0 * std::numbers::pi * 1e-6, 1e-15);
  const double n = s.at("physics").at("steps").get<double>(), h = 1e-3;
  EXPECT_NEAR(n, 200, 1);
  EXPECT_NEAR(vec(b.at("position_m")).z(), 0.5 - kG * h * h * n * (n + 1) / 2, 1e-12);
  EXPECT_NEAR(vec(b.at("velocity_m_s")).z(), -kG * h * n, 1e-12);
}

TEST(ScenePhysics, ToolPushesTheBoxAndTheHandFeelsWhatTheTableHolds) {
  const dm::SceneDesc scene = boxPush();
  const dm::test::TempDir dir("physics_push");
  const fs::path out = dir.path();
  const json s = runScene(scene, 5.0, out);
  const json& b = body(s, "box");
  const double m = b.at("mass_kg").get<double>();
  const dm::Vec3 x = vec(b.at("position_m"));
  // The box went with the push (it started at the origin) and stayed
  // upright on the table.
  EXPECT_GT(x.x(), 0.03) << s.dump(2);
  EXPECT_NEAR(x.y(), 0.0, 1e-4);
  EXPECT_NEAR(x.z(), 0.02, 2e-4);
  const json& q = b.at("orientation_wxyz");
  EXPECT_GT(std::abs(q[0].get<double>()), std::cos(0.5 * 1.0 * std::numbers::pi / 180.0));  // < 1° turned
  // At rest, still pushed.
  EXPECT_LT(vec(b.at("velocity_m_s")).norm(), 1e-4);
  const dm::Vec3 hand = vec(s.at("haptics").at("final_force_N"));
  ASSERT_GT(hand.norm(), 0.3) << "the hand no longer pushes";
  // Equilibrium of the box: tool (−hand) + table + weight = 0, so the force
  // on the hand equals the table's contact force plus the weight, to 1 %.
  const dm::Vec3 table = vec(b.at("contact_force_N"));
  const dm::Vec3 expected = table + dm::Vec3(0, 0, -m * kG);
  EXPECT_LE((hand - expected).norm(), 0.01 * hand.norm())
      << "hand " << hand.transpose() << ", table + weight " << expected.transpose();
  // Static friction holds it: the push is within the friction cone.
  EXPECT_LE(std::hypot(table.x(), table.y()), 0.3 * table.z() * (1 + 1e-6));
  // Momentum: what the hand felt over the run, Σ F dt from the trace, is
  // what the box received from the tool (opposite sign).
  dm::Vec3 handImpulse = dm::Vec3::Zero();
  for (const scene_run::TraceRow& r : scene_run::forceTrace(out / "forces.csv"))
    handImpulse += r.force * 1e-3;
  const dm::Vec3 toolImpulse = vec(b.at("tool_impulse_Ns"));
  EXPECT_GT(toolImpulse.x(), 0.5);
  EXPECT_LE((toolImpulse + handImpulse).norm(), 1e-9 * toolImpulse.norm())
      << toolImpulse.transpose() << " vs " << handImpulse.transpose();
}

TEST(ScenePhysics, LockstepRunsAreBitIdentical) {
  const dm::SceneDesc scene = boxPush();
  const dm::test::TempDir dir("physics_rerun");
  const fs::path a = dir / "a", b = dir / "b";
  const json sa = runScene(scene, 2.5, a);
  const json sb = runScene(scene, 2.5, b);
  EXPECT_EQ(fileText(a / "forces.csv"), fileText(b / "forces.csv"));
  EXPECT_EQ(sa.at("physics"), sb.at("physics"));
  EXPECT_GT(vec(body(sa, "box").at("position_m")).x(), 0.001);  // it was pushed by then
}

TEST(ScenePhysics, ASceneThatCannotBeBuiltLeavesNoOutputFolder) {
  // A physics engine that cannot be built (a gravity no file could give:
  // the parser refuses non-finite numbers, code can set one) fails before
  // anything runs, naming the entry, and no output folder is left behind.
  dm::SceneDesc scene = boxPush();
  const dm::test::TempDir dir("physics_never");
  const fs::path out = dir / "out";
  scene.engines.physics->gravity = dm::Vec3(0, 0, std::numeric_limits<double>::quiet_NaN());
  auto rt = dm::SceneRuntime::create(scene);
  ASSERT_TRUE(rt) << rt.error();
  auto r = (*rt)->run({.mode = dm::RunMode::Lockstep, .duration = 1.0, .outDir = out});
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().where.find("engines/physics/gravity"), std::string::npos) << r.error();
  EXPECT_FALSE(fs::exists(out));
}
