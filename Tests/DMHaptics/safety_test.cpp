// Safety stage: the Colgate–Schenkel passivity bound and the limits it
// implies, material and wrench clamping, the loop-side fade, and the work a
// sampled (zero-order-hold) half-space wall does on the user along a path
// that enters and leaves it — against the closed-form sum — with and without
// the Hannaford–Ryu passivity controller.
#include <dm/haptics/safety.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <numbers>
#include <vector>

#include "../common/alloc_counter.hpp"

namespace dm {
namespace {

// Analytic penalty wall: solid where n·(x − c) < 0; penetration d = −n·(x − c),
// force on the hand F = (K·d − B·(v·n))·n inside, 0 outside. The wall is
// object 0: its pose moves c and n.
class HalfSpaceWall final : public HapticRenderer {
 public:
  HalfSpaceWall(double k, double b) : k_(k), b_(b) {}
  std::string_view name() const noexcept override { return "halfspace"; }
  void reset(const Isometry3&) noexcept override {}
  HapticResponse tick(const HapticInput& in) noexcept override {
    const Vec3 n = pose_.linear() * Vec3::UnitZ();
    const double d = -n.dot(in.devicePose.translation() - pose_.translation());
    HapticResponse r;
    r.proxyPose = in.devicePose;
    if (d > 0.0) {
      r.force = (k_ * d - b_ * in.linearVelocity.dot(n)) * n;
      r.contacts = 1;
      r.penetration = d;
      r.proxyPose.translation() += d * n;
    }
    return r;
  }
  std::size_t objectCount() const noexcept override { return 1; }
  void setObjectPose(std::size_t index, const Isometry3& pose) noexcept override {
    if (index == 0 && pose.matrix().allFinite()) pose_ = pose;
  }

 private:
  double k_, b_;
  Isometry3 pose_ = Isometry3::Identity();
};

Isometry3 at(double x, double y, double z) { return Isometry3(Eigen::Translation3d(x, y, z)); }

// Straight down into the wall z < 0 by N steps of dx, then back out.
std::vector<Isometry3> inAndOut(int n, double dx) {
  std::vector<Isometry3> path;
  for (int k = 0; k <= n; ++k) path.push_back(at(0, 0, -dx * k));
  for (int k = n - 1; k >= 0; --k) path.push_back(at(0, 0, -dx * k));
  return path;
}

TEST(PassivityBound, ColgateSchenkelFormula) {
  EXPECT_DOUBLE_EQ(passiveStiffnessBound(1.0, 0.0, 1000.0), 2000.0);  // K < 2b/T
  EXPECT_DOUBLE_EQ(passiveStiffnessBound(1.0, 0.4, 1000.0), 1200.0);  // K < 2(b − |B|)/T
  EXPECT_DOUBLE_EQ(passiveStiffnessBound(1.0, -0.4, 1000.0), 1200.0);
  EXPECT_DOUBLE_EQ(passiveStiffnessBound(1.0, 0.0, 4000.0), 8000.0);  // faster loop, stiffer wall
  EXPECT_EQ(passiveStiffnessBound(1.0, 1.0, 1000.0), 0.0);
  EXPECT_EQ(passiveStiffnessBound(1.0, 0.0, 0.0), 0.0);
  EXPECT_EQ(passiveStiffnessBound(std::numeric_limits<double>::quiet_NaN(), 0.0, 1000.0), 0.0);
}

TEST(PassivityBound, LimitsScaleWithTheEffectiveRate) {
  HapticInfo info;
  info.maxStiffness = 2000.0;
  info.maxDamping = 20.0;
  info.maxForce = 8.0;
  info.servoRateHz = 1000.0;
  const HapticLimits at1k = limitsFor(info, 1000.0);
  EXPECT_DOUBLE_EQ(at1k.maxStiffness, 2000.0);
  EXPECT_DOUBLE_EQ(at1k.deviceDamping, 1.0);  // b = K·T/2
  EXPECT_DOUBLE_EQ(at1k.maxDamping, 20.0);
  EXPECT_DOUBLE_EQ(at1k.maxForce, 8.0);
  EXPECT_DOUBLE_EQ(limitsFor(info, 250.0).maxStiffness, 500.0);
  EXPECT_DOUBLE_EQ(limitsFor(info, 4000.0).maxStiffness, 2000.0);  // the motors update at 1 kHz
  EXPECT_DOUBLE_EQ(limitsFor(info, 4000.0).rateHz, 1000.0);
  EXPECT_EQ(limitsFor(info, 0.0).maxStiffness, 0.0);
  // Consistent with the bound: the stiffness limit is passive with b, not beyond.
  const HapticLimits l = limitsFor(info, 500.0);
  EXPECT_DOUBLE_EQ(passiveStiffnessBound(l.deviceDamping, 0.0, l.rateHz), l.maxStiffness);
}

TEST(PassivityBound, ClampMaterialKeepsAValidMaterialInRange) {
  const HapticLimits lim{.maxStiffness = 2000.0, .maxDamping = 20.0, .maxForce = 8.0};
  const HapticMaterial m = clampMaterial(
      {.stiffness = 5000.0, .damping = 50.0, .staticFriction = 0.3, .dynamicFriction = 0.5}, lim);
  EXPECT_EQ(m.stiffness, 2000.0);
  EXPECT_EQ(m.damping, 20.0);
  EXPECT_EQ(m.staticFriction, 0.3);
  EXPECT_EQ(m.dynamicFriction, 0.3);
  EXPECT_TRUE(m.validate("m").ok());
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const HapticMaterial bad =
      clampMaterial({.stiffness = nan, .damping = -1.0, .staticFriction = nan, .dynamicFriction = nan}, lim);
  EXPECT_TRUE(bad.validate("m").ok());
  EXPECT_EQ(bad.damping, 0.0);
  const HapticMaterial soft = clampMaterial({.stiffness = 300.0, .damping = 2.0}, lim);
  EXPECT_EQ(soft.stiffness, 300.0);
  EXPECT_EQ(soft.damping, 2.0);
}

TEST(SanitizeWrench, NonFiniteIsZeroAndNormsAreClamped) {
  Vec3 f(3, 4, 0), t(0, 0, 1);
  EXPECT_FALSE(sanitizeWrench(f, t, 2.5, 10.0));
  EXPECT_NEAR((f - Vec3(1.5, 2.0, 0)).norm(), 0.0, 1e-15);  // direction kept, |f| = 2.5
  EXPECT_EQ(t, Vec3(0, 0, 1));
  Vec3 g(std::numeric_limits<double>::infinity(), 0, 0), u(0, 0, 1);
  EXPECT_TRUE(sanitizeWrench(g, u, 8.0, 0.0));
  EXPECT_EQ(g, Vec3::Zero());
  EXPECT_EQ(u, Vec3::Zero());  // torque limit 0: a 3-DOF device renders no torque
}

TEST(OutputFade, RampsLinearlyHoldsTheLastForceAndRecovers) {
  OutputFade fade(0.004);
  Vec3 f(0, 0, 2), t = Vec3::Zero();
  fade.apply(f, t, true, false, 1e-3);
  EXPECT_EQ(f, Vec3(0, 0, 2));
  for (int k = 1; k <= 5; ++k) {
    Vec3 nanF(std::numeric_limits<double>::quiet_NaN(), 0, 0), nanT = Vec3::Zero();
    fade.apply(nanF, nanT, false, true, 1e-3);
    const double g = std::max(0.0, 1.0 - 0.25 * k);
    EXPECT_NEAR(fade.gain(), g, 1e-15);
    EXPECT_NEAR((nanF - Vec3(0, 0, 2 * g)).norm(), 0.0, 1e-15);
  }
  for (int k = 1; k <= 4; ++k) {
    Vec3 ff(0, 0, 1), tt = Vec3::Zero();
    fade.apply(ff, tt, true, false, 1e-3);
    EXPECT_NEAR(ff.z(), 0.25 * k, 1e-15);
  }
  fade.cut();
  EXPECT_EQ(fade.gain(), 0.0);
  OutputFade instant(0.0);
  Vec3 a(1, 0, 0), b = Vec3::Zero();
  instant.apply(a, b, true, true, 1e-3);
  EXPECT_EQ(a.norm(), 0.0);
}

TEST(PathWork, ZeroOrderHoldWallDeliversKNdx2) {
  // W = Σ F_k·(x_{k+1} − x_k) telescopes to K·N·Δx² for the held spring
  // force (the classical energy leak of a sampled wall): positive, so the
  // sampled wall is active however small Δx is.
  const double k = 2000.0, dx = 1e-3;
  const int n = 10;
  HalfSpaceWall wall(k, 0.0);
  const auto path = inAndOut(n, dx);
  const double w = pathWork(wall, path, 1e-2);
  EXPECT_NEAR(w, k * n * dx * dx, 1e-12);
  // A continuous (sub-sampled) wall along the same path is lossless: the
  // leak shrinks with the step, K·N·Δx² = K·D·Δx → 0.
  const auto fine = inAndOut(10 * n, dx / 10);
  EXPECT_NEAR(pathWork(wall, fine, 1e-3), k * n * dx * dx / 10, 1e-12);
}

TEST(PathWork, VirtualDampingAboveKTOverTwoMakesTheWallPassive) {
  // With backward-difference velocities the sum is exact:
  // W = Δx²·(K·N − (2N − 3)·B/T), ≤ 0 iff B ≥ K·T·N/(2N − 3) → K·T/2 (Colgate).
  const double k = 2000.0, dx = 5e-4, T = 1e-3;
  const int n = 50;
  const auto path = inAndOut(n, dx);
  for (double ratio : {0.45, 0.55, 0.7}) {
    const double b = ratio * k * T;
    HalfSpaceWall wall(k, b);
    const double w = pathWork(wall, path, T);
    EXPECT_NEAR(w, dx * dx * (k * n - (2.0 * n - 3.0) * b / T), 1e-12) << ratio;
    EXPECT_EQ(w > 0.0, ratio < n / (2.0 * n - 3.0)) << ratio;
  }
}

TEST(PassivityController, KeepsASlowlySampledStiffWallPassive) {
  // 100 Hz, 2000 N/m: 20 mJ generated without the controller.
  const double k = 2000.0, dx = 1e-3;
  const int n = 10;
  HalfSpaceWall wall(k, 0.0);
  const auto path = inAndOut(n, dx);
  const double active = pathWork(wall, path, 1e-2);
  EXPECT_GT(active, 0.01);
  const double controlled = pathWork(wall, path, 1e-2, PassivityConfig{});
  EXPECT_LE(controlled, 1e-12);
  // Observe-only gives the uncontrolled value back.
  EXPECT_NEAR(pathWork(wall, path, 1e-2, PassivityConfig{.enabled = false}), active, 1e-15);
  // A threshold lets that much energy through, not more.
  EXPECT_LE(pathWork(wall, path, 1e-2, PassivityConfig{.threshold = 5e-3}), 5e-3 + 1e-12);
  EXPECT_GT(pathWork(wall, path, 1e-2, PassivityConfig{.threshold = 5e-3}), 4e-3);
}

TEST(PassivityController, ClosedCircleThroughATiltedWallAt1kHz) {
  // A 3 cm circle in the x–z plane whose lower part dips 1 cm into a wall
  // tilted by 0.2 rad, rendered at 1 kHz with a stiff 20 kN/m spring; two turns.
  const double k = 20000.0, T = 1e-3, r = 0.03;
  HalfSpaceWall wall(k, 0.0);
  wall.setObjectPose(0, Isometry3(Eigen::Translation3d(0, 0, -0.02)) * Eigen::AngleAxisd(0.2, Vec3::UnitY()));
  std::vector<Isometry3> path;
  const int steps = 2000;  // 1 s per turn
  for (int i = 0; i <= 2 * steps; ++i) {
    const double a = 2 * std::numbers::pi * i / steps;
    path.push_back(at(r * std::sin(a), 0, r * std::cos(a)));
  }
  const double active = pathWork(wall, path, T);
  EXPECT_GT(active, 1e-4);
  const double controlled = pathWork(wall, path, T, PassivityConfig{});
  // It dissipates exactly the leak: the wall ends lossless, not braking the user.
  EXPECT_NEAR(controlled, 0.0, 1e-9);
}

TEST(PassivityController, ObserverAndControllerDoNotAllocate) {
  HalfSpaceWall wall(1000.0, 0.0);
  const auto path = inAndOut(20, 1e-3);
  const auto before = test::countedAllocations();
  test::tCountAllocations = true;
  const double w = pathWork(wall, path, 1e-3, PassivityConfig{});
  test::tCountAllocations = false;
  EXPECT_EQ(test::countedAllocations(), before);
  EXPECT_LE(w, 1e-12);
}

TEST(PassivityController, RotationDeltaIsTheRotationVector) {
  const Isometry3 a(Eigen::AngleAxisd(0.3, Vec3::UnitX()));
  const Isometry3 b = Isometry3(Eigen::AngleAxisd(0.5, Vec3::UnitZ())) * a;
  EXPECT_NEAR((rotationDelta(a, b) - Vec3(0, 0, 0.5)).norm(), 0.0, 1e-12);
  EXPECT_NEAR(rotationDelta(a, a).norm(), 0.0, 1e-12);
}

}  // namespace
}  // namespace dm
