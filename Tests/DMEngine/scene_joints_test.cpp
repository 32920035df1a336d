// A scene's joints in a run (engines/physics/joints, built by the physics
// engine into its PhysicsWorld), against mechanics: a ball on a hinge and
// on a ball joint swings as the physical pendulum it is (period and
// amplitude: its angle three-eighths of a period after release within 1 %
// of θ0·cos(3π/4), its speed within 2 %), in its plane; a box on a vertical
// slider falls to its lower limit and rests there, turned by nothing; a bar
// hinged at one end falls to its angle limit; a box welded to the world
// holds its pose against gravity. summary.json reports each joint's anchor
// gap (and a slider's travel). The pendulums swing on the ODE backend too.
#include <dm/engine/scene_runtime.hpp>
#include <dm/io/scene_file.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <string>
#include <vector>

#include "../common/temp_dir.hpp"
#include "scene_run_support.hpp"

namespace scene_joints_test {

namespace fs = std::filesystem;
using dm::Vec3;
using nlohmann::json;

constexpr double kG = 9.80665;

dm::SceneDesc sceneWith(const std::string& objects, const std::string& joints,
                        const std::string& backend = "builtin") {
  const std::string text = R"({
    "format": "dmplatform-scene", "version": 2, "name": "joints",
    "resources": {
      "ball": {"type": "shape", "shape": "sphere", "radius": 0.01},
      "box": {"type": "shape", "shape": "box", "half_extents": [0.02, 0.02, 0.02]},
      "bar": {"type": "shape", "shape": "box", "half_extents": [0.1, 0.01, 0.01]}
    },
    "objects": [)" + objects +
                           R"(],
    "engines": {"physics": {"rate_hz": 1000, "backend": ")" +
                           backend + (backend == "ode" ? R"(", "ode": {"iterations": 50}, )" : R"(", )") +
                           R"("joints": [)" + joints + R"(]}},
    "outputs": {"summary": true}
  })";
  return scene_run::parsedScene(text, "joints.json");
}

const json& bodyOf(const json& summary, const std::string& name) {
  return scene_run::named(summary.at("physics").at("bodies"), name);
}
const json& jointOf(const json& summary, const std::string& name) {
  return scene_run::named(summary.at("physics").at("joints"), name);
}

// A 10 g ball of radius r on a massless link of L = 0.5 m from the pivot
// (0, 0, 1), released at rest θ0 = 0.1 rad from the vertical in the x–z
// plane. As a physical pendulum its period is 2π sqrt(I/(m g L)) with
// I = m (L² + 2r²/5) (θ0²/16 = 0.06 % longer at this amplitude).
struct Pendulum {
  double L = 0.5, r = 0.01, theta0 = 0.1;
  double omega() const { return std::sqrt(kG * L / (L * L + 0.4 * r * r)); }
  Vec3 start() const { return {L * std::sin(theta0), 0.0, 1.0 - L * std::cos(theta0)}; }
};

void expectSwing(const std::string& joint, const std::string& backend = "builtin") {
  const Pendulum p;
  const Vec3 c = p.start();
  const std::string ball =
      R"({"name": "bob", "mesh": "ball", "dynamic": true, "mass": 0.01, "pose": {"position": [)" +
      std::to_string(c.x()) + ", 0, " + std::to_string(c.z()) + "]}}";
  const double t = 0.75 * std::numbers::pi / p.omega();  // 3/8 of a period
  // The run's length is whole physics steps: the angle is compared at the
  // time the run reached.
  const double steps = std::round(t * 1000.0), tRun = steps / 1000.0;
  dm::test::TempDir dir("scene_joints_" + joint + "_" + backend);
  const json s = scene_run::runScene(
      sceneWith(ball,
                R"({"name": "pivot", "type": ")" + joint + R"(", "a": "bob", "anchor": [0, 0, 1])" +
                    (joint == "hinge" ? R"(, "axis": [0, 1, 0]})" : "}"),
                backend),
      tRun, dir.path());
  const json& b = bodyOf(s, "bob");
  const Vec3 x = scene_run::vec(b.at("position_m")), v = scene_run::vec(b.at("velocity_m_s"));
  const double theta = std::atan2(x.x(), 1.0 - x.z());
  const double expected = p.theta0 * std::cos(p.omega() * tRun);
  EXPECT_NEAR(theta, expected, 0.01 * std::abs(expected)) << joint << " on " << backend << " " << s.dump(2);
  const double speed = p.L * p.theta0 * p.omega() * std::sin(p.omega() * tRun);
  EXPECT_NEAR(v.norm(), speed, 0.02 * speed) << joint;
  EXPECT_NEAR((x - Vec3(0, 0, 1)).norm(), p.L, 1e-4) << joint;  // on its link
  EXPECT_LT(std::abs(x.y()), 1e-6) << joint;                    // in its plane
  EXPECT_LT(jointOf(s, "pivot").at("anchor_gap_m").get<double>(), 1e-4) << joint;
}

TEST(SceneJoints, ABallOnAHingeOrABallJointSwingsAsThePhysicalPendulum) {
  expectSwing("hinge");
  expectSwing("ball");
}

// ODE's dWorldQuickStep is an SOR sweep: a small ball (its own inertia
// 4e-7 kg·m²) on a 0.5 m arm makes the joint's matrix ill-conditioned, and
// the anchors part by what the sweeps leave — measured 0.16 mm (ball) and
// 0.07 mm (hinge) at ODE's 20 iterations, 0.02 mm at 50, 0.1 µm at 200.
// The scene asks for 50 (engines/physics/ode/iterations).
TEST(SceneJoints, OnTheOdeBackendTooTheBallSwingsAsThePhysicalPendulum) {
  expectSwing("hinge", "ode");
  expectSwing("ball", "ode");
}

TEST(SceneJoints, ABoxOnAVerticalSliderFallsToItsLowerLimitAndRests) {
  dm::test::TempDir dir("scene_joints_slider");
  const json s = scene_run::runScene(
      sceneWith(R"({"name": "carriage", "mesh": "box", "dynamic": true, "mass": 0.2,
                    "pose": {"position": [0.1, 0.2, 0.5]}})",
                R"({"name": "rail", "type": "slider", "a": "carriage", "anchor": [0.1, 0.2, 0.5],
                    "axis": [0, 0, 1], "limits": [-0.05, 0.05]})"),
      0.6, dir.path());  // it reaches the limit after sqrt(2·0.05/g) = 0.1 s
  const json& b = bodyOf(s, "carriage");
  const Vec3 x = scene_run::vec(b.at("position_m"));
  EXPECT_NEAR(x.z(), 0.45, 1e-3) << s.dump(2);
  EXPECT_NEAR(x.x(), 0.1, 1e-6);
  EXPECT_NEAR(x.y(), 0.2, 1e-6);
  EXPECT_LT(scene_run::vec(b.at("velocity_m_s")).norm(), 1e-2);
  const json& w = b.at("orientation_wxyz");
  EXPECT_NEAR(std::abs(w[0].get<double>()), 1.0, 1e-6);  // the slider turns nothing
  const json& rail = jointOf(s, "rail");
  // The travel is the second body's (the world's) along the axis from the
  // carriage: the carriage went down 5 cm, so the world is 5 cm up from it.
  EXPECT_NEAR(rail.at("travel_m").get<double>(), 0.05, 1e-3);
  EXPECT_LT(rail.at("anchor_gap_m").get<double>(), 1e-4);
}

TEST(SceneJoints, ABarHingedAtOneEndFallsToItsAngleLimit) {
  // A 20 cm bar, horizontal, hinged about y at its end x = 0; gravity turns
  // it down (about +y) until the limit holds it at 0.5 rad.
  dm::test::TempDir dir("scene_joints_hinge_limit");
  const json s = scene_run::runScene(
      sceneWith(R"({"name": "bar", "mesh": "bar", "dynamic": true, "mass": 0.1,
                    "pose": {"position": [0.1, 0, 0.5]}})",
                R"({"name": "hinge", "type": "hinge", "a": "bar", "anchor": [0, 0, 0.5], "axis": [0, 1, 0],
                    "limits": [-0.5, 0.5]})"),
      1.0, dir.path());
  const json& b = bodyOf(s, "bar");
  const Vec3 x = scene_run::vec(b.at("position_m"));
  const double angle = std::atan2(0.5 - x.z(), x.x());  // below the horizontal
  EXPECT_NEAR(angle, 0.5, 0.01) << s.dump(2);
  EXPECT_NEAR((x - Vec3(0, 0, 0.5)).norm(), 0.1, 1e-4);  // the centre stays 10 cm from the hinge
  EXPECT_LT(scene_run::vec(b.at("angular_velocity_rad_s")).norm(), 0.05);
}

TEST(SceneJoints, ABoxWeldedToTheWorldHoldsItsPose) {
  dm::test::TempDir dir("scene_joints_fixed");
  const json s = scene_run::runScene(
      sceneWith(R"({"name": "held", "mesh": "box", "dynamic": true, "mass": 0.5,
                    "pose": {"position": [0, 0, 0.3]}},
                   {"name": "free", "mesh": "box", "dynamic": true, "mass": 0.5,
                    "pose": {"position": [1, 0, 0.3]}})",
                R"({"name": "weld", "type": "fixed", "a": "held", "anchor": [0, 0, 0.32]})"),
      0.2, dir.path());
  EXPECT_LT(bodyOf(s, "held").at("displacement_m").get<double>(), 1e-5) << s.dump(2);
  // The free one fell g t²/2 = 19.6 cm meanwhile.
  EXPECT_NEAR(bodyOf(s, "free").at("displacement_m").get<double>(), 0.5 * kG * 0.04, 2e-3);
  EXPECT_LT(jointOf(s, "weld").at("anchor_gap_m").get<double>(), 1e-5);
}

}  // namespace scene_joints_test
