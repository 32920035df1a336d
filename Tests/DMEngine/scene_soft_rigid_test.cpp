// Soft tissue and rigid bodies in one scene run, two-way (a dynamic body is
// an obstacle of the tissue whose velocity the tissue's implicit step solves,
// dm::SoftRigidCoupling). Checked against mechanics: a 27 g ball dropped on
// a 60 × 60 × 30 mm pad held at its bottom comes to rest carried by the
// tissue (the tissue's force on it is its weight; the held bottom carries
// the pad's weight and the ball's) at Hertz's indentation of an elastic
// half-space by a rigid sphere; on the ODE backend it rests at the same
// depth; lockstep reruns are bit-identical; the bundled fragment-on-tissue
// example ends with the fragment carried where it landed and the pad in
// equilibrium.
#include <dm/engine/scene_runtime.hpp>
#include <dm/io/scene_file.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <string>
#include <vector>

#include "../common/temp_dir.hpp"
#include "scene_run_support.hpp"

namespace scene_soft_rigid_test {

namespace fs = std::filesystem;
using nlohmann::json;
using scene_run::runScene;
using scene_run::vec;

constexpr double kG = 9.80665;
// The pad: E, ν, its top at z = kTop; the ball: radius, mass.
constexpr double kE = 2e4, kNu = 0.3, kTop = 0.03, kRadius = 0.01, kMass = 0.027;

// The ball 0.5 mm above the pad's top centre, the physics engine at
// `rateHz` on `backend`.
dm::SceneDesc ballOnPad(int rateHz, const std::string& backend) {
  const std::string text = R"({
    "format": "dmplatform-scene", "version": 2, "name": "ball_on_pad",
    "resources": {
      "pad": {"type": "shape", "shape": "box", "half_extents": [0.03, 0.03, 0.015]},
      "ball": {"type": "shape", "shape": "sphere", "radius": 0.01, "subdivisions": 4}
    },
    "objects": [
      {"name": "pad", "mesh": "pad", "pose": {"position": [0, 0, 0.015]},
       "soft": {"youngs_modulus": 2e4, "poisson_ratio": 0.3, "density": 1000,
                "damping": {"alpha": 20, "beta": 0.01}, "voxel_size": 0.004, "fixed": ["-z"]}},
      {"name": "ball", "mesh": "ball", "dynamic": true, "mass": 0.027, "pose": {"position": [0, 0, 0.0405]}}
    ],
    "engines": {"physics": {"rate_hz": )" +
                           std::to_string(rateHz) + R"(, "backend": ")" + backend + R"("}},
    "outputs": {"summary": true}
  })";
  return scene_run::parsedScene(text, "ball_on_pad.json");
}

// Hertz: a rigid sphere of radius R pressed by F into an elastic
// half-space sinks δ = (3F / (4 E* √R))^(2/3), E* = E / (1 − ν²).
double hertzDepth(double force) {
  const double eStar = kE / (1 - kNu * kNu);
  return std::pow(3 * force / (4 * eStar * std::sqrt(kRadius)), 2.0 / 3.0);
}

TEST(SceneSoftRigid, ABallDroppedOnTissueRestsAtHertzsDepthCarriedByIt) {
  const json s = runScene(ballOnPad(200, "builtin"), 1.0, dm::test::TempDir("ball_on_pad").path());
  ASSERT_TRUE(s.contains("physics")) << s.dump(2);
  const json& ball = scene_run::named(s.at("physics").at("bodies"), "ball");
  const json& pad = scene_run::named(s.at("physics").at("soft"), "pad");
  const double weight = kMass * kG;
  // At rest vertically, carried by the tissue alone. The contact is
  // frictionless, and the cubes' tetrahedra (split along one diagonal) make
  // the pad slightly anisotropic: the ball slides a little off the centre,
  // slowly (about 2 mm in a second).
  const dm::Vec3 at = vec(ball.at("position_m"));
  EXPECT_LT(std::abs(vec(ball.at("velocity_m_s")).z()), 1e-4);
  EXPECT_LT(at.head<2>().norm(), 0.003) << at.transpose();
  const json& obstacle = scene_run::named(pad.at("obstacles"), "ball");
  EXPECT_TRUE(obstacle.at("dynamic").get<bool>());
  const dm::Vec3 onBall = vec(obstacle.at("force_N"));
  EXPECT_NEAR(onBall.z(), weight, 0.002 * weight);
  EXPECT_LT(onBall.head<2>().norm(), 0.01 * weight);
  // The body's own summary says the same: the tissue's force, no rigid contact.
  EXPECT_EQ(vec(ball.at("soft_force_N")), onBall);
  EXPECT_EQ(vec(ball.at("contact_force_N")).norm(), 0.0);
  // The held bottom carries the pad's weight and the ball's.
  const dm::Vec3 held = vec(pad.at("held_force_N")), padWeight = vec(pad.at("weight_N"));
  EXPECT_NEAR(held.z(), weight - padWeight.z(), 0.01 * (weight - padWeight.z()));
  // Hertz's depth (2.01 mm; contact radius √(Rδ) = 4.5 mm, a seventh of
  // the pad's thickness): the 4 mm tetrahedra, the contact's penalty
  // springs and the pad's finite thickness leave it within 6 %.
  const double depth = kTop + kRadius - at.z();
  const double hertz = hertzDepth(weight);
  EXPECT_NEAR(depth, hertz, 0.06 * hertz) << "sank " << depth * 1e3 << " mm, Hertz " << hertz * 1e3 << " mm";
  EXPECT_GT(pad.at("obstacle_contacts").get<int>(), 0);
}

TEST(SceneSoftRigid, OnTheOdeBackendTheBallRestsAtTheSameDepth) {
  const json a = runScene(ballOnPad(200, "builtin"), 1.0, dm::test::TempDir("ball_builtin").path());
  const json b = runScene(ballOnPad(200, "ode"), 1.0, dm::test::TempDir("ball_ode").path());
  ASSERT_TRUE(a.contains("physics") && b.contains("physics"));
  EXPECT_EQ(b.at("physics").at("backend"), "ode");
  const dm::Vec3 pa = vec(scene_run::named(a.at("physics").at("bodies"), "ball").at("position_m"));
  const dm::Vec3 pb = vec(scene_run::named(b.at("physics").at("bodies"), "ball").at("position_m"));
  // Both advance the ball by gravity from the velocity the tissue left it
  // (no rigid contact here): the same rest, to a micrometre.
  EXPECT_LT((pa - pb).norm(), 1e-6) << pa.transpose() << " vs " << pb.transpose();
  const json& pad = scene_run::named(b.at("physics").at("soft"), "pad");
  EXPECT_NEAR(vec(scene_run::named(pad.at("obstacles"), "ball").at("force_N")).z(), kMass * kG,
              0.002 * kMass * kG);
}

TEST(SceneSoftRigid, LockstepRunsAreBitIdentical) {
  const json a = runScene(ballOnPad(200, "builtin"), 0.2, dm::test::TempDir("ball_rerun_a").path());
  const json b = runScene(ballOnPad(200, "builtin"), 0.2, dm::test::TempDir("ball_rerun_b").path());
  ASSERT_TRUE(a.contains("physics") && b.contains("physics"));
  EXPECT_EQ(a.at("physics").at("bodies"), b.at("physics").at("bodies"));
  EXPECT_EQ(a.at("physics").at("soft"), b.at("physics").at("soft"));
}

// The bundled example: a 6.1 g bone fragment dropped on a pad, the pad
// pressed beside it through the god-object, friction across the contact.
// At rest (3 s) the fragment stays where it landed, level, carried by the
// tissue (its weight, 1 %), and the pad is in equilibrium: its held bottom
// carries its weight, the fragment's and the hand's push (1 %).
TEST(SceneSoftRigid, TheFragmentOnTissueExampleEndsInEquilibrium) {
  const json s = runScene(scene_run::bundledScene("fragment_on_tissue.json"), 3.0,
                          dm::test::TempDir("fragment_on_tissue").path());
  ASSERT_TRUE(s.contains("physics")) << s.dump(2);
  const json& fragment = scene_run::named(s.at("physics").at("bodies"), "fragment");
  const json& pad = scene_run::named(s.at("physics").at("soft"), "pad");
  const double weight = fragment.at("mass_kg").get<double>() * kG;
  EXPECT_NEAR(weight, 0.02 * 0.016 * 0.01 * 1900 * kG, 1e-12);
  EXPECT_LT(vec(fragment.at("velocity_m_s")).norm(), 1e-3);
  EXPECT_LT(vec(fragment.at("angular_velocity_rad_s")).norm(), 0.01);
  const dm::Vec3 at = vec(fragment.at("position_m"));
  EXPECT_LT((at.head<2>() - dm::Vec2(-0.012, 0)).norm(), 0.002) << at.transpose();
  EXPECT_GT(std::abs(fragment.at("orientation_wxyz")[0].get<double>()), 0.999);  // level, not spun
  const dm::Vec3 onFragment = vec(scene_run::named(pad.at("obstacles"), "fragment").at("force_N"));
  EXPECT_NEAR(onFragment.z(), weight, 0.01 * weight);
  // The pad: held + weight + the tool's push + the fragment's = 0.
  const dm::Vec3 held = vec(pad.at("held_force_N"));
  const dm::Vec3 tool = vec(pad.at("tool_force_N"));
  EXPECT_GT(-tool.z(), 0.8) << "the hand presses the pad";
  const dm::Vec3 residual = held + vec(pad.at("weight_N")) + tool - onFragment;
  EXPECT_LT(residual.norm(), 0.01 * held.norm()) << residual.transpose();
}

}  // namespace scene_soft_rigid_test
