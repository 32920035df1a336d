// BladeResistance: the force of cutting (fracture toughness × engaged
// length), the energy balance, the cut already made, and real-time safety.
#include <dm/math/primitives.hpp>
#include <dm/physics/blade.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "../common/alloc_counter.hpp"

namespace dm {
namespace {

constexpr double kJ = 600.0, kK = 1500.0;  // J/m², N/m

BladeResistance blade() {
  auto b = BladeResistance::create({.toughness = kJ, .stiffness = kK, .maxForce = 20.0});
  EXPECT_TRUE(b.ok());
  return *b;
}

TEST(BladeResistance, HeldAsASpringUntilTheCuttingForceThenCutsAtJTimesW) {
  // Edge facing +x, 8 mm of it in the tissue: the cut needs J·w = 4.8 N.
  BladeResistance b = blade();
  b.reset(Vec3::Zero());
  const Vec3 u = Vec3::UnitX();
  const double w = 0.008, limit = kJ * w, dx = 1e-5;  // 10 µm a tick: 10 mm/s at 1 kHz
  double x = 0.0;
  // Pressing: the spring, k·a, no cut.
  for (; kK * (x + dx) < limit - 1e-9;) {
    x += dx;
    const Vec3 f = b.tick(Vec3(x, 0, 0), u, w);
    ASSERT_NEAR(f.x(), -kK * x, 1e-9);
    ASSERT_NEAR(f.tail<2>().norm(), 0.0, 1e-15);
    ASSERT_FALSE(b.cutting());
  }
  EXPECT_EQ(b.cutArea(), 0.0);
  // Cutting at constant speed: the force is J·w, the area w × advance.
  const double start = x;
  for (int i = 0; i < 2000; ++i) {
    x += dx;
    const Vec3 f = b.tick(Vec3(x, 0, 0), u, w);
    if (i > 0) {
      ASSERT_TRUE(b.cutting());
      ASSERT_NEAR(f.x(), -limit, 1e-9);
    }
  }
  // The front is J·w/k behind the device; it advanced from 0.
  EXPECT_NEAR(b.front().x(), x - limit / kK, 1e-12);
  EXPECT_NEAR(b.cutArea(), w * (x - limit / kK), 1e-15);
  EXPECT_GT(x - start, 0.019);
  // Energy: the hand's work is J × area + the spring's ½(J·w)²/k, up to the
  // one tick that crossed the threshold (the trapezoid there is off by at
  // most ½·k·Δ²).
  const double spring = 0.5 * limit * limit / kK;
  EXPECT_NEAR(b.work(), kJ * b.cutArea() + spring, 0.5 * kK * dx * dx);
}

TEST(BladeResistance, FreeInTheCutAlreadyMadeAndAgainstUncutTissueAhead) {
  BladeResistance b = blade();
  b.reset(Vec3::Zero());
  const Vec3 u(0, 1, 0);
  const double w = 0.005;
  for (int i = 1; i <= 1000; ++i) b.tick(Vec3(0, 1e-5 * i, 0), u, w);  // cut 10 mm less J·w/k
  const double front = b.front().y();
  ASSERT_NEAR(front, 0.01 - kJ * w / kK, 1e-12);
  // Back along the cut and forward again up to the front: no force.
  for (int i = 1000; i >= 0; --i) {
    const Vec3 f = b.tick(Vec3(0, 1e-5 * i, 0), u, w);
    if (1e-5 * i <= front) {
      ASSERT_EQ(f.norm(), 0.0) << i;
    }
  }
  const double area = b.cutArea();
  for (int i = 0; 1e-5 * i <= front; ++i) ASSERT_EQ(b.tick(Vec3(0, 1e-5 * i, 0), u, w).norm(), 0.0);
  EXPECT_EQ(b.cutArea(), area);
  // Past it the tissue holds again, then cuts.
  const Vec3 f = b.tick(Vec3(0, front + 0.001, 0), u, w);
  EXPECT_NEAR(f.y(), -kK * 0.001, 1e-9);
  // Sideways (across the edge's facing) the blade is not held.
  const Vec3 g = b.tick(Vec3(0.002, front + 0.001, 0), u, w);
  EXPECT_NEAR(g.x(), 0.0, 1e-12);
  EXPECT_NEAR(g.y(), -kK * 0.001, 1e-9);
  // Lifted out (w = 0): no force, and the next cut starts where it enters.
  EXPECT_EQ(b.tick(Vec3(0, 0.05, 0), u, 0.0).norm(), 0.0);
  EXPECT_NEAR(b.front().y(), 0.05, 1e-15);
  EXPECT_NEAR(b.tick(Vec3(0, 0.0502, 0), u, w).y(), -kK * 0.0002, 1e-9);
}

TEST(BladeResistance, ThickerCutsNeedProportionallyMoreForceAndTheLoopIsPassive) {
  // The steady force is J·w for each engaged length (a scalpel pushed
  // deeper), and over a path that presses, cuts, backs off and cuts at
  // another depth, the hand never gets back more than the spring holds:
  // work ≥ −½(J·w_max)²/k at every tick.
  BladeResistance b = blade();
  b.reset(Vec3::Zero());
  const Vec3 u = Vec3::UnitX();
  double wMax = 0.0, worst = 0.0;
  double x = 0.0;
  for (const double w : {0.002, 0.004, 0.009}) {
    wMax = std::max(wMax, w);
    Vec3 f = Vec3::Zero();
    for (int i = 0; i < 800; ++i) f = b.tick(Vec3(x += 1e-5, 0, 0), u, w);
    EXPECT_NEAR(f.x(), -kJ * w, 1e-9) << "w = " << w;
    for (int i = 0; i < 300; ++i) worst = std::min(worst, (b.tick(Vec3(x -= 1e-5, 0, 0), u, w), b.work()));
  }
  EXPECT_GE(worst, -0.5 * std::pow(kJ * wMax, 2) / kK);
  EXPECT_GT(b.work(), kJ * b.cutArea() * 0.99);
}

TEST(BladeResistance, EngagedLengthIsTheEdgeInsideTheTissue) {
  // An icosphere of radius 10 mm: a chord at distance h from the centre is
  // 2·sqrt(r² − h²) long, with r between the faces' distance from the
  // centre (the polyhedron's inscribed radius) and the vertices' (10 mm).
  const double R = 0.010;
  const Mesh ball = makeIcosphere(R, 4);
  double rIn = R;
  for (const Triangle& t : ball.triangles) {
    const Vec3 &a = ball.positions[t[0]], &b = ball.positions[t[1]], &c = ball.positions[t[2]];
    rIn = std::min(rIn, std::abs((b - a).cross(c - a).normalized().dot(a)));
  }
  for (const double h : {0.0, 0.003, 0.0071, 0.0095}) {
    const double w = engagedLength(Vec3(-0.02, h, 0.0), Vec3(0.02, h, 0.0), ball);
    EXPECT_LE(w, 2 * std::sqrt(R * R - h * h) + 1e-15) << "h = " << h;
    EXPECT_GE(w, 2 * std::sqrt(rIn * rIn - h * h) - 1e-15) << "h = " << h;
  }
  // From the centre out: the radius; wholly inside: the whole edge; outside: 0.
  const double fromCentre = engagedLength(Vec3::Zero(), Vec3(0, 0, 0.02), ball);
  EXPECT_LE(fromCentre, R + 1e-15);
  EXPECT_GE(fromCentre, rIn - 1e-15);
  EXPECT_NEAR(engagedLength(Vec3(-0.001, 0, 0), Vec3(0.002, 0.001, 0), ball), std::sqrt(0.003 * 0.003 + 1e-6),
              1e-15);
  EXPECT_EQ(engagedLength(Vec3(0.02, 0, 0), Vec3(0.03, 0, 0), ball), 0.0);
  // Through both sides of a torus (major 20 mm, minor 5 mm): two tubes of
  // 10 mm each, the hole between them not counted.
  const Mesh torus = makeTorus(0.020, 0.005, 256, 128);
  const double through = engagedLength(Vec3(-0.03, 0, 0), Vec3(0.03, 0, 0), torus);
  EXPECT_NEAR(through, 0.020, 0.020 * 1e-3);
  EXPECT_LE(through, 0.020 + 1e-15);
  // Starting in one tube: its remaining 5 mm and the far tube's 10 mm.
  EXPECT_NEAR(engagedLength(Vec3(-0.020, 0, 0), Vec3(0.03, 0, 0), torus), 0.015, 0.015 * 1e-3);
}

TEST(BladeResistance, RealTimeSafety) {
  BladeResistance b = blade();
  b.reset(Vec3::Zero());
  b.tick(Vec3(0.001, 0, 0), Vec3::UnitX(), 0.01);
  const Vec3 proxy = b.proxy();
  // Non-finite input, a zero direction, a negative length: zero force, nothing moves.
  EXPECT_EQ(b.tick(Vec3(NAN, 0, 0), Vec3::UnitX(), 0.01).norm(), 0.0);
  EXPECT_EQ(b.tick(Vec3(0.002, 0, 0), Vec3::Zero(), 0.01).norm(), 0.0);
  EXPECT_EQ(b.tick(Vec3(0.002, 0, 0), Vec3::UnitX(), -1.0).norm(), 0.0);
  EXPECT_EQ(b.tick(Vec3(0.002, 0, 0), Vec3::UnitX(), INFINITY).norm(), 0.0);
  EXPECT_EQ(b.proxy(), proxy);
  // The force is clamped: J·w = 600 N/m² × 0.1 m = 60 N > 20 N.
  for (int i = 0; i < 100; ++i) b.tick(Vec3(0.001 * i, 0, 0), Vec3::UnitX(), 0.1);
  EXPECT_NEAR(b.tick(Vec3(0.1, 0, 0), Vec3::UnitX(), 0.1).norm(), 20.0, 1e-12);
  // No allocation in a tick.
  test::tCountAllocations = true;
  const auto before = test::countedAllocations();
  for (int i = 0; i < 1000; ++i) b.tick(Vec3(1e-5 * i, 0, 0), Vec3::UnitX(), 0.005);
  test::tCountAllocations = false;
  EXPECT_EQ(test::countedAllocations(), before);
  // Bad options are named.
  auto bad = BladeResistance::create({.toughness = 0.0});
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().message().find("toughness"), std::string::npos);
  EXPECT_FALSE(BladeResistance::create({.stiffness = NAN}).ok());
}

}  // namespace
}  // namespace dm
