// Rigid bodies in the DFSPH fluid (two-way coupling) against Archimedes,
// and the boundary sampler against the geometry it samples: a sphere's
// samples lie on the inset sphere, no two closer than half a spacing, with
// no hole wider than a spacing; a sphere held under water feels ρ0 g V up
// (within 8 % at three spacings to its radius) and nothing sideways; spheres
// of 500 and 700 kg/m³ released too deep rise and float at the drafts that
// displace their own mass (their centres 0.27 R apart); a sphere towed through the fluid is held back and the
// fluid moves with it; bad bodies, states and meshes are refused naming
// what is wrong.
#include <dm/math/primitives.hpp>
#include <dm/physics/sph_boundary.hpp>
#include <dm/physics/sph_fluid.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <vector>

namespace sph_rigid_test {

using dm::Vec3;

constexpr double kD = 0.01;  // m, spacing
constexpr double kR = 0.03;  // m, the spheres' radius
constexpr double kRho0 = 1000.0, kG = 9.81;
const double kVolume = 4.0 / 3.0 * std::numbers::pi * kR * kR * kR;

std::vector<Vec3> ballSamples() {
  auto p = dm::sampleBoundary(dm::makeIcosphere(kR, 4), kD, kD / 3.0);
  EXPECT_TRUE(p) << p.error();
  return p ? *p : std::vector<Vec3>{};
}

dm::Isometry3 at(const Vec3& c) {
  dm::Isometry3 pose = dm::Isometry3::Identity();
  pose.translation() = c;
  return pose;
}

// A 12 cm square tank of syrup-like fluid (ν 1e-3 m²/s: the sphere settles
// in a second) `depth` deep with a sphere at c, the fluid inside it removed.
dm::SphFluid tankWithBall(double depth, const Vec3& c) {
  auto f = dm::SphFluid::create({.particleSpacing = kD, .viscosity = 1e-3});
  EXPECT_TRUE(f) << f.error();
  dm::SphFluid s = *f;
  s.addBoxBoundary({0, 0, 0}, {0.12, 0.12, 0.3});
  s.addBlock({0, 0, 0}, {0.12, 0.12, depth});
  s.removeIf([&](const Vec3& x) { return (x - c).norm() < kR; });
  auto body = s.addRigidBoundary(ballSamples(), at(c));
  EXPECT_TRUE(body) << body.error();
  return s;
}

// The free surface away from the body: the mean height of the top layer of
// particles more than 1.5 R from the sphere's axis, plus half a spacing.
double surfaceHeight(const dm::SphFluid& s, const Vec3& axis) {
  double top = -std::numeric_limits<double>::infinity();
  for (const Vec3& x : s.positions())
    if ((x.head<2>() - axis.head<2>()).norm() > 1.5 * kR) top = std::max(top, x.z());
  double sum = 0.0;
  int n = 0;
  for (const Vec3& x : s.positions())
    if ((x.head<2>() - axis.head<2>()).norm() > 1.5 * kR && x.z() > top - 0.5 * kD) {
      sum += x.z();
      ++n;
    }
  return sum / n + 0.5 * kD;
}

TEST(SphBoundary, SphereSamplesLieOnTheInsetSphereAndCoverIt) {
  const double inset = kD / 3.0;
  const std::vector<Vec3> p = ballSamples();
  ASSERT_GT(p.size(), 100u);
  // The area over the samples is about a spacing squared each (no more
  // than 1.5 d², no less than d²/4: the half-spacing exclusion).
  const double area = 4.0 * std::numbers::pi * kR * kR / double(p.size());
  EXPECT_GT(area, 0.25 * kD * kD);
  EXPECT_LT(area, 1.5 * kD * kD);
  for (const Vec3& x : p) {
    // The icosphere's flat faces lie within 0.3 % of R of the sphere.
    EXPECT_GT(x.norm(), kR - inset - 0.003 * kR);
    EXPECT_LT(x.norm(), kR - 0.9 * inset);
  }
  double closest = INFINITY;
  for (std::size_t i = 0; i < p.size(); ++i)
    for (std::size_t j = i + 1; j < p.size(); ++j) closest = std::min(closest, (p[i] - p[j]).norm());
  EXPECT_GE(closest, 0.5 * kD * (kR - inset) / kR - 1e-12);
  // Every point of the inset sphere (a Fibonacci lattice of 2000) has a
  // sample within a spacing.
  const int n = 2000;
  double worst = 0.0;
  for (int k = 0; k < n; ++k) {
    const double z = 1.0 - (2.0 * k + 1.0) / n, r = std::sqrt(1.0 - z * z);
    const double phi = k * std::numbers::pi * (3.0 - std::sqrt(5.0));
    const Vec3 q = (kR - inset) * Vec3(r * std::cos(phi), r * std::sin(phi), z);
    double best = INFINITY;
    for (const Vec3& x : p) best = std::min(best, (x - q).norm());
    worst = std::max(worst, best);
  }
  EXPECT_LT(worst, kD);
}

TEST(SphBoundary, BadMeshesAndSpacingsAreRefusedNamingThem) {
  const dm::Mesh ball = dm::makeIcosphere(kR, 2);
  auto r = dm::sampleBoundary(ball, 0.0, 0.0);
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().message().find("spacing 0"), std::string::npos) << r.error();
  r = dm::sampleBoundary(ball, kD, kD);
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().message().find("inset"), std::string::npos) << r.error();
  r = dm::sampleBoundary(dm::Mesh{}, kD, 0.0);
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().message().find("no triangles"), std::string::npos) << r.error();
  dm::Mesh bad = ball;
  bad.triangles[5][1] = 100000;
  r = dm::sampleBoundary(bad, kD, 0.0);
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().message().find("triangle 5"), std::string::npos) << r.error();
  bad = ball;
  bad.positions[7].x() = NAN;
  r = dm::sampleBoundary(bad, kD, 0.0);
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().message().find("vertex 7"), std::string::npos) << r.error();
  r = dm::sampleBoundary(dm::makeIcosphere(10.0, 2), 1e-4, 0.0);  // 1.3e10 samples
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().message().find("too large"), std::string::npos) << r.error();
}

TEST(SphRigid, ASphereHeldUnderWaterFeelsArchimedesBuoyancy) {
  const Vec3 c(0.06, 0.06, 0.07);
  dm::SphFluid s = tankWithBall(0.15, c);
  Vec3 mean = Vec3::Zero();
  int n = 0;
  for (int k = 0; k < 500; ++k) {
    ASSERT_TRUE(s.step(0.002));
    if (s.time() > 0.6) {  // settled: the fluid's waves from the start die out by about 0.6 s
      mean += s.rigidLoad(0).force;
      ++n;
    }
  }
  mean /= n;
  // At three spacings to the radius the sampling of the surface shows: this
  // icosphere feels 0.94 of ρ0 g V, the same sphere sampled from another
  // icosphere 0.99 (Tests/python/test_fluid.py), a cube 0.99.
  const double buoyancy = kRho0 * kG * kVolume;  // 1.11 N
  EXPECT_NEAR(mean.z(), buoyancy, 0.08 * buoyancy) << mean.transpose();
  EXPECT_LT(mean.head<2>().norm(), 0.02 * buoyancy) << mean.transpose();
  EXPECT_LT(s.rigidLoad(0).torque.norm(), 0.02 * buoyancy * kR);  // pressure acts through the centre
  EXPECT_TRUE(s.rigidPose(0).isApprox(at(c)));                    // at rest: it does not move
}

struct Floating {
  double start, centre, highest, speed, sideways;
  double below;  // the centre under the free surface, in radii
};

// A sphere of `density` released 0.6 R below where Archimedes floats it
// (its centre `draft` R under the 12 cm surface), integrated by the caller
// as a body of a PhysicsWorld would be, for a second.
Floating floatSphere(double density, double draft) {
  const double depth = 0.12;
  const Vec3 c(0.06, 0.06, depth - (draft + 0.6) * kR);
  dm::SphFluid s = tankWithBall(depth, c);
  const double m = density * kVolume;
  dm::Isometry3 pose = at(c);
  Vec3 v = Vec3::Zero();
  const double dt = 0.002;
  Floating out{.start = c.z(), .centre = 0, .highest = c.z(), .speed = 0, .sideways = 0, .below = 0};
  for (int k = 0; k < 500; ++k) {
    EXPECT_TRUE(s.setRigidState(0, pose, v, Vec3::Zero()));
    EXPECT_TRUE(s.step(dt));
    v += dt * (s.rigidLoad(0).force / m + Vec3(0, 0, -kG));
    pose.translation() += dt * v;
    out.highest = std::max(out.highest, pose.translation().z());
  }
  out.centre = pose.translation().z();
  out.below = (surfaceHeight(s, c) - out.centre) / kR;
  out.speed = v.norm();
  out.sideways = (pose.translation() - c).head<2>().norm();
  return out;
}

TEST(SphRigid, LightSpheresRiseAndFloatAtTheirArchimedesDrafts) {
  // Submerged share f of a sphere whose centre is x R under the surface:
  // 1/2 + 3x/4 − x³/4. 500 kg/m³ floats half under (x = 0), 700 kg/m³ with
  // x = 0.2735. Each centre is measured from its own tank's free surface
  // (the heavier sphere displaces more and raises it); the difference of
  // the two drafts is Archimedes' alone, as where a particle fluid's surface
  // lies within its top spacing cancels.
  const Floating half = floatSphere(500.0, 0.0), deeper = floatSphere(700.0, 0.2735);
  for (const Floating& f : {half, deeper}) {
    EXPECT_GT(f.highest - f.start, 0.4 * kR);  // it rose
    EXPECT_LT(f.speed, 0.01);                  // m/s: and came to rest
    EXPECT_LT(f.sideways, 0.1 * kR);
  }
  EXPECT_NEAR(deeper.below - half.below, 0.2735, 0.05)
      << "500 kg/m³: " << half.below << " R under the surface, 700 kg/m³: " << deeper.below << " R";
}

TEST(SphRigid, ASphereTowedThroughTheFluidIsHeldBackAndDragsTheFluidAlong) {
  const Vec3 c(0.03 + kR, 0.06, 0.06);
  dm::SphFluid s = tankWithBall(0.13, c);
  for (int k = 0; k < 100; ++k) ASSERT_TRUE(s.step(0.002));  // settle
  const Vec3 towing(0.1, 0, 0);                              // m/s along +x
  dm::Isometry3 pose = at(c);
  double drag = 0.0;
  for (int k = 0; k < 150; ++k) {
    ASSERT_TRUE(s.setRigidState(0, pose, towing, Vec3::Zero()));
    ASSERT_TRUE(s.step(0.002));
    pose.translation() += 0.002 * towing;
    if (k >= 50) drag += s.rigidLoad(0).force.x() / 100.0;
  }
  EXPECT_LT(drag, -1e-3);  // N, against the motion
  EXPECT_NEAR(s.rigidPose(0).translation().x(), pose.translation().x(),
              1e-12);  // it moved on at its velocity
  // The fluid just behind the sphere follows it.
  double vx = 0.0;
  int n = 0;
  for (std::size_t i = 0; i < s.size(); ++i) {
    const Vec3 r = s.positions()[i] - pose.translation();
    if (r.x() < -kR && r.x() > -kR - 2 * kD && r.head<2>().norm() < kR + 2 * kD &&
        std::abs(r.z()) < 0.5 * kR) {
      vx += s.velocities()[i].x();
      ++n;
    }
  }
  ASSERT_GT(n, 0);
  EXPECT_GT(vx / n, 0.2 * towing.x());
}

TEST(SphRigid, BadBodiesAndStatesAreRefusedNamingThem) {
  auto f = dm::SphFluid::create({.particleSpacing = kD});
  ASSERT_TRUE(f);
  dm::SphFluid s = *f;
  auto r = s.addRigidBoundary({});
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().message().find("no boundary particles"), std::string::npos) << r.error();
  const std::vector<Vec3> nan = {Vec3(0, 0, 0), Vec3(NAN, 0, 0)};
  r = s.addRigidBoundary(nan);
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().message().find("point 1"), std::string::npos) << r.error();
  auto st = s.setRigidState(0, at(Vec3::Zero()), Vec3::Zero(), Vec3::Zero());
  ASSERT_FALSE(st);
  EXPECT_NE(st.error().message().find("body 0 of 0"), std::string::npos) << st.error();
  ASSERT_TRUE(s.addRigidBoundary(ballSamples()));
  st = s.setRigidState(0, at(Vec3::Zero()), Vec3(0, INFINITY, 0), Vec3::Zero());
  ASSERT_FALSE(st);
  EXPECT_NE(st.error().message().find("non-finite"), std::string::npos) << st.error();
  EXPECT_EQ(s.rigidBodyCount(), 1u);
}

}  // namespace sph_rigid_test
