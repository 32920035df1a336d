// Force effects against their formulas: viscous drag and its region, the
// snap-to-surface triangle profile (a callable plane and a MeshBvh box),
// the vibration frequency by counting zero crossings, the virtual fixtures
// (sphere, rotated box, corridor: zero inside, spring + damper outside,
// never pulling outward), and the fixed-capacity effect stack.
#include <dm/haptics/effects.hpp>
#include <dm/math/primitives.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "../common/alloc_counter.hpp"

namespace dm {
namespace {

HapticInput probe(const Vec3& p, const Vec3& v = Vec3::Zero(), std::int64_t timeNs = 0) {
  HapticInput in;
  in.devicePose = Isometry3(Eigen::Translation3d(p));
  in.linearVelocity = v;
  in.timeNs = timeNs;
  return in;
}

Vec3 forceOf(const ForceEffect& e, const HapticInput& in) {
  HapticResponse r;
  e.apply(in, r);
  EXPECT_EQ(r.torque, Vec3::Zero());
  return r.force;
}

TEST(Viscosity, OpposesVelocityInsideItsRegionOnly) {
  const ViscosityEffect everywhere(4.0);
  EXPECT_NEAR(
      (forceOf(everywhere, probe(Vec3(1, 2, 3), Vec3(0.1, -0.2, 0.05))) - Vec3(-0.4, 0.8, -0.2)).norm(), 0.0,
      1e-15);
  const ViscosityEffect boxed(4.0, Aabb(Vec3(-0.01, -0.01, -0.01), Vec3(0.01, 0.01, 0.01)));
  EXPECT_NEAR((forceOf(boxed, probe(Vec3(0, 0, 0.005), Vec3(0, 0, 0.1))) - Vec3(0, 0, -0.4)).norm(), 0.0,
              1e-15);
  EXPECT_EQ(forceOf(boxed, probe(Vec3(0, 0, 0.02), Vec3(0, 0, 0.1))), Vec3::Zero());
  // Power −b·|v|² ≤ 0: it only dissipates.
  const Vec3 v(0.3, 0.1, -0.2);
  EXPECT_LT(forceOf(everywhere, probe(Vec3::Zero(), v)).dot(v), 0.0);
  EXPECT_EQ(ViscosityEffect(-1.0).damping(), 0.0);
}

TEST(SnapToSurface, TriangleProfileTowardAPlane) {
  // Surface z = 0 given as a callable; k = 500 N/m, capture 2 cm.
  const SnapToSurfaceEffect snap(
      [](const Vec3& p, Vec3& q) {
        q = Vec3(p.x(), p.y(), 0.0);
        return true;
      },
      500.0, 0.02);
  for (double z : {0.002, 0.008, 0.01, 0.012, 0.019, -0.005}) {
    const Vec3 f = forceOf(snap, probe(Vec3(0.3, -0.1, z)));
    const double r = std::abs(z);
    const double expected = 500.0 * std::min(r, 0.02 - r);
    EXPECT_NEAR(f.norm(), expected, 1e-12) << z;
    EXPECT_NEAR(f.z(), -std::copysign(expected, z), 1e-12) << z;  // toward the surface
    EXPECT_NEAR(std::hypot(f.x(), f.y()), 0.0, 1e-15);
  }
  EXPECT_EQ(forceOf(snap, probe(Vec3(0, 0, 0.025))), Vec3::Zero());  // beyond capture
  EXPECT_EQ(forceOf(snap, probe(Vec3(0, 0, 0.0))), Vec3::Zero());    // on the surface
  // Continuous: at r = c/2 both branches give k·c/2; at r → c the force → 0.
  EXPECT_NEAR(snap.magnitudeAt(0.01 - 1e-9), snap.magnitudeAt(0.01 + 1e-9), 1e-6);
  EXPECT_NEAR(snap.magnitudeAt(0.02 - 1e-9), 0.0, 1e-6);
}

TEST(SnapToSurface, PullsTowardTheClosestPointOfAMesh) {
  auto bvh = MeshBvh::build(makeBox(Vec3(0.05, 0.05, 0.05)));
  ASSERT_TRUE(bvh.ok()) << bvh.error().message();
  const Isometry3 pose(Eigen::Translation3d(0.1, 0, 0));
  const SnapToSurfaceEffect snap(*bvh, pose, 400.0, 0.03);
  // 1 cm above the top face: pulled straight down by k·1 cm.
  const Vec3 f = forceOf(snap, probe(Vec3(0.1, 0.01, 0.06)));
  EXPECT_NEAR((f - Vec3(0, 0, -4.0)).norm(), 0.0, 1e-9);
  // 2 cm beside the +x face: k·(3 cm − 2 cm) toward −x.
  const Vec3 g = forceOf(snap, probe(Vec3(0.17, 0, 0)));
  EXPECT_NEAR((g - Vec3(-4.0, 0, 0)).norm(), 0.0, 1e-9);
  EXPECT_EQ(forceOf(snap, probe(Vec3(0.1, 0, 0.2))), Vec3::Zero());  // 15 cm away
}

TEST(Vibration, FrequencyAmplitudeAndAxis) {
  const double f = 150.0, a = 0.7;
  const VibrationEffect vib(a, f, Vec3(0, 3, 4));  // normalized to (0, 0.6, 0.8)
  int crossings = 0;
  double previous = 0.0, peak = 0.0;
  const std::int64_t stepNs = 50'000;  // sampled at 20 kHz for one second
  for (std::int64_t i = 0; i <= 20'000; ++i) {
    const Vec3 force = forceOf(vib, probe(Vec3::Zero(), Vec3::Zero(), i * stepNs + 17'000));
    ASSERT_NEAR(force.cross(Vec3(0, 0.6, 0.8)).norm(), 0.0, 1e-12);
    const double s = force.dot(Vec3(0, 0.6, 0.8));
    if (i > 0 && (s > 0.0) != (previous > 0.0)) ++crossings;
    previous = s;
    peak = std::max(peak, std::abs(s));
  }
  EXPECT_EQ(crossings, 2 * static_cast<int>(f));  // two zero crossings per cycle
  EXPECT_NEAR(peak, a, 1e-3);
  // The phase: at t = 0 the force is A·sin(φ) along the axis.
  const VibrationEffect shifted(a, f, Vec3::UnitX(), std::numbers::pi / 2);
  EXPECT_NEAR(forceOf(shifted, probe(Vec3::Zero())).x(), a, 1e-12);
  EXPECT_EQ(forceOf(VibrationEffect(a, f, Vec3::Zero()), probe(Vec3::Zero(), Vec3::Zero(), 1'000'000)),
            Vec3::Zero());
}

TEST(ForceField, AddsTheFieldAtTheDevicePointAndIgnoresNonFiniteAnswers) {
  // A linear spring field toward the origin, F = −k p, and one that fails.
  const ForceFieldEffect spring([](const Vec3& p) { return Vec3(-50.0 * p); }, "spring");
  EXPECT_EQ(spring.name(), "spring");
  EXPECT_NEAR((forceOf(spring, probe(Vec3(0.01, -0.02, 0.004))) - Vec3(-0.5, 1.0, -0.2)).norm(), 0.0, 1e-15);
  const ForceFieldEffect broken([](const Vec3&) { return Vec3(std::nan(""), 0, 0); });
  EXPECT_EQ(broken.name(), "field");
  HapticResponse r;
  r.force = Vec3(1, 2, 3);
  broken.apply(probe(Vec3::Zero()), r);
  EXPECT_EQ(r.force, Vec3(1, 2, 3));
  const ForceFieldEffect empty(nullptr);
  EXPECT_EQ(forceOf(empty, probe(Vec3::Ones())), Vec3::Zero());
}

TEST(VirtualFixture, SphereSpringAndDamperOutsideOnly) {
  const VirtualFixture fix(SafeSphere{Vec3(0.1, 0, 0), 0.02}, 800.0, 5.0);
  EXPECT_EQ(forceOf(fix, probe(Vec3(0.11, 0.01, 0), Vec3(1, 1, 1))), Vec3::Zero());  // inside
  // 5 mm outside along +y, at rest: −k·d toward the centre.
  EXPECT_NEAR((forceOf(fix, probe(Vec3(0.1, 0.025, 0))) - Vec3(0, -4.0, 0)).norm(), 0.0, 1e-12);
  // Moving outward at 0.1 m/s adds b·v.
  EXPECT_NEAR((forceOf(fix, probe(Vec3(0.1, 0.025, 0), Vec3(0, 0.1, 0))) - Vec3(0, -4.5, 0)).norm(), 0.0,
              1e-12);
  // Rushing back in faster than the spring: the damper never pulls outward.
  EXPECT_EQ(forceOf(fix, probe(Vec3(0.1, 0.025, 0), Vec3(0, -2.0, 0))), Vec3::Zero());
  // Tangential velocity is not damped.
  EXPECT_NEAR((forceOf(fix, probe(Vec3(0.1, 0.025, 0), Vec3(0.3, 0, 0))) - Vec3(0, -4.0, 0)).norm(), 0.0,
              1e-12);
}

TEST(VirtualFixture, RotatedBoxPushesBackThroughTheNearestFaceOrCorner) {
  const Isometry3 pose =
      Eigen::Translation3d(0, 0, 0.1) * Eigen::AngleAxisd(std::numbers::pi / 4, Vec3::UnitZ());
  const VirtualFixture fix(SafeBox{pose, Vec3(0.02, 0.01, 0.03)}, 1000.0);
  const Vec3 ex = pose.linear() * Vec3::UnitX();
  EXPECT_EQ(forceOf(fix, probe(pose * Vec3(0.019, -0.009, 0.029))), Vec3::Zero());
  // 4 mm beyond the local +x face.
  EXPECT_NEAR((forceOf(fix, probe(pose * Vec3(0.024, 0.005, 0))) + 4.0 * ex).norm(), 0.0, 1e-12);
  // Beyond a corner: toward the corner, by k·distance.
  const Vec3 corner = pose * Vec3(0.02, 0.01, 0.03);
  const Vec3 p = pose * Vec3(0.023, 0.014, 0.03);
  const Vec3 f = forceOf(fix, probe(p));
  EXPECT_NEAR((f - 1000.0 * (corner - p)).norm(), 0.0, 1e-12);
  EXPECT_NEAR(f.norm(), 1000.0 * 0.005, 1e-12);
}

TEST(VirtualFixture, CorridorAroundASegment) {
  const SafeCorridor corridor{Vec3(0, 0, 0), Vec3(0, 0, 0.1), 0.005};
  const VirtualFixture fix(corridor, 600.0);
  EXPECT_EQ(forceOf(fix, probe(Vec3(0.003, 0.003, 0.05))), Vec3::Zero());  // r = 4.2 mm
  // 8 mm off the axis at mid-length: radial, k·3 mm.
  const Vec3 side = forceOf(fix, probe(Vec3(0, 0.008, 0.05)));
  EXPECT_NEAR((side - Vec3(0, -1.8, 0)).norm(), 0.0, 1e-12);
  // Past the far end on the axis: back along the axis (round end cap).
  const Vec3 end = forceOf(fix, probe(Vec3(0, 0, 0.108)));
  EXPECT_NEAR((end - Vec3(0, 0, -1.8)).norm(), 0.0, 1e-12);
  bool inside = false;
  const Vec3 q = closestPointInRegion(corridor, Vec3(0.01, 0, 0.02), &inside);
  EXPECT_FALSE(inside);
  EXPECT_NEAR((q - Vec3(0.005, 0, 0.02)).norm(), 0.0, 1e-15);
}

TEST(EffectStack, ComposesBySumHasAFixedCapacityAndNeverAllocates) {
  EffectStack stack(2);
  auto visc = stack.add(std::make_unique<ViscosityEffect>(2.0));
  ASSERT_TRUE(visc.ok());
  auto fix = stack.add(std::make_unique<VirtualFixture>(SafeSphere{Vec3::Zero(), 0.01}, 100.0));
  ASSERT_TRUE(fix.ok());
  auto full = stack.add(std::make_unique<VibrationEffect>(1.0, 10.0, Vec3::UnitX()));
  ASSERT_FALSE(full.ok());
  EXPECT_EQ(full.error().code, ErrorCode::Busy);
  EXPECT_FALSE(stack.add(nullptr).ok());

  const HapticInput in = probe(Vec3(0.02, 0, 0), Vec3(0, 0.1, 0));
  HapticResponse r;
  r.force = Vec3(0, 0, 1);  // a renderer's contact force stays
  const auto before = test::countedAllocations();
  test::tCountAllocations = true;
  stack.apply(in, r);
  test::tCountAllocations = false;
  EXPECT_EQ(test::countedAllocations(), before);
  EXPECT_NEAR((r.force - Vec3(-1.0, -0.2, 1.0)).norm(), 0.0, 1e-12);  // fixture −k·1 cm, drag −b·v

  EXPECT_TRUE(stack.remove(*visc));
  EXPECT_FALSE(stack.remove(*visc));
  EXPECT_EQ(stack.size(), 1u);
  HapticResponse r2;
  stack.apply(in, r2);
  EXPECT_NEAR((r2.force - Vec3(-1.0, 0, 0)).norm(), 0.0, 1e-12);
  EXPECT_TRUE(stack.add(std::make_unique<VibrationEffect>(1.0, 10.0, Vec3::UnitX())).ok());
  stack.clear();
  EXPECT_TRUE(stack.empty());
}

}  // namespace
}  // namespace dm
