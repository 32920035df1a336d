// Tests of dm/collide/toi.hpp: conservative advancement and the bisection
// resolver against closed-form impact times (spheres, boxes on planes and
// boxes, a rotating capsule) and a fine brute-force sampling of
// dm::distance; CA against bisection on convex and mesh–mesh pairs; swept
// point against ray–plane and ray–sphere geometry on an icosphere; swept
// sphere against face, edge and corner impacts on a box mesh, grazing and
// starting contacts, and against CA on the sphere–mesh distance.
#include <dm/collide/mesh_query.hpp>
#include <dm/collide/query.hpp>
#include <dm/collide/shapes.hpp>
#include <dm/collide/toi.hpp>
#include <dm/collide/triangle.hpp>
#include <dm/math/geometry.hpp>
#include <dm/math/primitives.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <memory>
#include <numbers>
#include <random>
#include <vector>

#include "collide_test_support.hpp"

namespace {

using dm::Isometry3;
using dm::Motion;
using dm::Vec3;

constexpr double kPi = std::numbers::pi;

using dm::test::at;

Isometry3 rotated(const Isometry3& p, double angle, const Vec3& axis) {
  Isometry3 r = p;
  r.linear() = dm::AngleAxis(angle, axis.normalized()).toRotationMatrix() * p.linear();
  return r;
}

Isometry3 randomToiPose(std::mt19937_64& rng, double spread) {
  std::normal_distribution<double> g(0.0, 1.0);
  std::uniform_real_distribution<double> u(-spread, spread);
  Isometry3 p = Isometry3::Identity();
  p.linear() = dm::Quat(Eigen::Vector4d(g(rng), g(rng), g(rng), g(rng)).normalized()).toRotationMatrix();
  p.translation() = Vec3(u(rng), u(rng), u(rng));
  return p;
}

std::shared_ptr<const dm::TriangleMesh> meshShape(dm::Mesh mesh) {
  auto shape = dm::TriangleMesh::create(std::make_shared<const dm::Mesh>(std::move(mesh)));
  EXPECT_TRUE(shape.ok());
  return *shape;
}

// First t in [0, 1] where dm::distance ≤ 0, by n uniform samples and then
// bisection on the sign: the brute-force reference (-1 when none).
double bruteForceImpact(const dm::Shape& a, const Motion& ma, const dm::Shape& b, const Motion& mb, int n) {
  auto touching = [&](double t) { return dm::distance(a, ma.at(t), b, mb.at(t)).distance <= 0; };
  double lo = 0;
  for (int i = 1; i <= n; ++i) {
    const double t = double(i) / n;
    if (!touching(t)) {
      lo = t;
      continue;
    }
    double hi = t;
    for (int k = 0; k < 60; ++k) (touching(0.5 * (lo + hi)) ? hi : lo) = 0.5 * (lo + hi);
    return hi;
  }
  return -1;
}

// --- Motion ----------------------------------------------------------------

TEST(ToiMotion, InterpolatesLinearlyAndByConstantRateRotation) {
  const Isometry3 start = rotated(at(1, 2, 3), 0.3, Vec3(1, 0, 0));
  const Isometry3 end = rotated(rotated(at(3, 2, -1), 0.3, Vec3(1, 0, 0)), 1.2, Vec3(0, 1, 1));
  const Motion m{start, end};
  EXPECT_TRUE(m.at(0).isApprox(start, 0.0));
  EXPECT_TRUE(m.at(1).isApprox(end, 0.0));
  EXPECT_NEAR((m.rotationVector() - 1.2 * Vec3(0, 1, 1).normalized()).norm(), 0.0, 1e-12);
  // Halfway: half the translation, half the rotation about the same world axis.
  const Isometry3 half = m.at(0.5);
  EXPECT_NEAR((half.translation() - Vec3(2, 2, 1)).norm(), 0.0, 1e-14);
  const Isometry3 expected = rotated(start, 0.6, Vec3(0, 1, 1));
  EXPECT_NEAR((half.linear() - expected.linear()).norm(), 0.0, 1e-12);
  // The bound holds for points within r of the origin, sampled along the step.
  const double r = 0.7;
  const double bound = m.maxPointDisplacement(r);
  EXPECT_NEAR(bound, Vec3(2, 0, -4).norm() + 1.2 * r, 1e-12);
  const Vec3 local = r * Vec3(0.3, -0.5, 0.8).normalized();
  double path = 0;
  for (int i = 0; i < 1000; ++i) path += (m.at((i + 1) / 1000.0) * local - m.at(i / 1000.0) * local).norm();
  EXPECT_LE(path, bound * (1 + 1e-9));
  EXPECT_GT(path, 0.5 * bound);
  EXPECT_EQ(Motion::stationary(start).maxPointDisplacement(std::numeric_limits<double>::infinity()), 0.0);
}

// --- conservative advancement on convex pairs ---------------------------

TEST(ToiConservativeAdvancement, SphereTowardSphereHasExactTime) {
  const dm::Sphere a(0.1), b(0.2);
  // A moves 2 m along x towards B at x = 1: contact at t = (1 − 0.3) / 2.
  const Motion ma{at(0, 0, 0), at(2, 0, 0)};
  const dm::ToiResult r = dm::conservativeAdvancement(a, ma, b, Motion::stationary(at(1, 0, 0)), {1e-9, 100});
  ASSERT_EQ(r.status, dm::ToiStatus::Hit);
  EXPECT_TRUE(r.hit);
  EXPECT_LE(r.t, 0.35 + 1e-15);  // never after the contact
  EXPECT_NEAR(r.t, 0.35, 1e-9);
  EXPECT_NEAR((r.point - Vec3(0.8, 0, 0)).norm(), 0.0, 1e-8);
  EXPECT_NEAR((r.normal - Vec3(1, 0, 0)).norm(), 0.0, 1e-12);
  EXPECT_GE(r.distance, 0.0);
  EXPECT_LT(r.distance, 1e-9);
  EXPECT_LE(r.iterations, 4);  // the directional bound is exact for translations

  // Both moving, off-axis: relative speed 2 along the centre line.
  const Vec3 dir = Vec3(1, 2, -2) / 3.0;
  const Motion mA{at(0, 0, 0), Isometry3(Eigen::Translation3d(dir))};
  const Motion mB{Isometry3(Eigen::Translation3d(dir)), Isometry3(Eigen::Translation3d(Vec3::Zero()))};
  const dm::ToiResult r2 = dm::conservativeAdvancement(a, mA, b, mB, {1e-10, 100});
  ASSERT_EQ(r2.status, dm::ToiStatus::Hit);
  EXPECT_NEAR(r2.t, 0.35, 1e-9);
  EXPECT_NEAR((r2.normal - dir).norm(), 0.0, 1e-9);
}

TEST(ToiConservativeAdvancement, BoxFallsOntoPlaneAndBox) {
  const dm::Box box(Vec3(0.1, 0.2, 0.05));
  const dm::Plane floor(Vec3(0, 0, 1), 0.0);
  // Falls from z = 1 to z = −1: the bottom face reaches z = 0 at z = 0.05.
  const Motion fall{at(0.3, -0.2, 1), at(0.3, -0.2, -1)};
  const dm::ToiResult r =
      dm::conservativeAdvancement(box, fall, floor, Motion::stationary(Isometry3::Identity()), {1e-10, 100});
  ASSERT_EQ(r.status, dm::ToiStatus::Hit);
  EXPECT_NEAR(r.t, 0.95 / 2, 1e-9);
  EXPECT_NEAR(r.normal.dot(Vec3(0, 0, -1)), 1.0, 1e-9);  // from the box (A) down to the floor (B)

  // Tilted by α about x: the lowest edge is hz·cos α + hy·sin α below the centre.
  const double alpha = 0.4;
  const Motion tilted{rotated(at(0, 0, 1), alpha, Vec3(1, 0, 0)),
                      rotated(at(0, 0, -1), alpha, Vec3(1, 0, 0))};
  const double low = 0.05 * std::cos(alpha) + 0.2 * std::sin(alpha);
  const dm::ToiResult rt = dm::conservativeAdvancement(
      box, tilted, floor, Motion::stationary(Isometry3::Identity()), {1e-10, 100});
  ASSERT_EQ(rt.status, dm::ToiStatus::Hit);
  EXPECT_NEAR(rt.t, (1 - low) / 2, 1e-9);
  EXPECT_NEAR(rt.point.z(), 0.0, 1e-8);

  // Onto a slab box (top at z = 0.1), turned 30° about z (no effect on t).
  const dm::Box slab(Vec3(1, 1, 0.1));
  const dm::ToiResult rb = dm::conservativeAdvancement(
      box, fall, slab, Motion::stationary(rotated(Isometry3::Identity(), kPi / 6, Vec3(0, 0, 1))),
      {1e-10, 100});
  ASSERT_EQ(rb.status, dm::ToiStatus::Hit);
  EXPECT_NEAR(rb.t, (1 - 0.15) / 2, 1e-9);
  // Bisection agrees within its time tolerance, from above.
  const dm::ToiResult bb = dm::bisectImpact(
      box, fall, slab, Motion::stationary(rotated(Isometry3::Identity(), kPi / 6, Vec3(0, 0, 1))),
      {8, 1e-9, 64});
  ASSERT_EQ(bb.status, dm::ToiStatus::Hit);
  EXPECT_GE(bb.t, 0.425 - 1e-12);
  EXPECT_NEAR(bb.t, 0.425, 2e-9);
  EXPECT_NEAR(bb.normal.dot(Vec3(0, 0, -1)), 1.0, 1e-6);
}

TEST(ToiConservativeAdvancement, RotatingCapsuleHitsSphere) {
  // Capsule (axis along world x at the start) turning 90° about z around its
  // centre; sphere of 0.1 at polar angle atan2(0.4, 0.3), 0.5 from the axis.
  const dm::Capsule rod(0.05, 0.5);
  const dm::Sphere ball(0.1);
  const Isometry3 start = rotated(Isometry3::Identity(), kPi / 2, Vec3(0, 1, 0));
  const Motion spin{start, rotated(start, kPi / 2, Vec3(0, 0, 1))};
  const Motion still = Motion::stationary(at(0.3, 0.4, 0));
  // The axis line at angle φ passes 0.5·sin(β − φ) from the centre: contact at 0.15.
  const double beta = std::atan2(0.4, 0.3);
  const double tExact = (beta - std::asin(0.3)) / (kPi / 2);
  const dm::ToiResult r = dm::conservativeAdvancement(rod, spin, ball, still, {1e-9, 200});
  ASSERT_EQ(r.status, dm::ToiStatus::Hit);
  EXPECT_LE(r.t, tExact + 1e-12);
  EXPECT_NEAR(r.t, tExact, 1e-8);
  EXPECT_NEAR(dm::distance(rod, spin.at(r.t), ball, still.at(r.t)).distance, 0.0, 1e-9);

  // With translation too, against a fine sampling of dm::distance.
  const Motion screw{at(-0.2, -0.1, 0.05) * start,
                     rotated(at(0.1, 0.05, 0.0), 1.3, Vec3(0.2, 0.1, 1)) * start};
  const double tRef = bruteForceImpact(rod, screw, ball, still, 2000);
  ASSERT_GT(tRef, 0);
  const dm::ToiResult rs = dm::conservativeAdvancement(rod, screw, ball, still, {1e-9, 200});
  ASSERT_EQ(rs.status, dm::ToiStatus::Hit);
  EXPECT_LE(rs.t, tRef + 1e-12);
  EXPECT_NEAR(rs.t, tRef, 1e-7);
  const dm::ToiResult bs = dm::bisectImpact(rod, screw, ball, still, {16, 1e-10, 64});
  ASSERT_EQ(bs.status, dm::ToiStatus::Hit);
  EXPECT_NEAR(bs.t, tRef, 1e-9);
}

TEST(ToiConservativeAdvancement, MissesZeroMotionAndOverlap) {
  const dm::Sphere a(0.1), b(0.1);
  // Passing 0.25 from B's centre: clearance 0.05.
  const Motion pass{at(-1, 0.25, 0), at(1, 0.25, 0)};
  const dm::ToiResult miss =
      dm::conservativeAdvancement(a, pass, b, Motion::stationary(Isometry3::Identity()));
  EXPECT_EQ(miss.status, dm::ToiStatus::NoHit);
  EXPECT_FALSE(miss.hit);
  EXPECT_EQ(miss.t, 1.0);
  EXPECT_EQ(dm::bisectImpact(a, pass, b, Motion::stationary(Isometry3::Identity())).status,
            dm::ToiStatus::NoHit);
  // Stops short of B.
  const Motion shortMove{at(-1, 0, 0), at(-0.5, 0, 0)};
  EXPECT_EQ(dm::conservativeAdvancement(a, shortMove, b, Motion::stationary(Isometry3::Identity())).status,
            dm::ToiStatus::NoHit);
  // Moving apart, and not moving at all.
  EXPECT_EQ(dm::conservativeAdvancement(a, Motion{at(-1, 0, 0), at(-2, 0, 0)}, b,
                                        Motion::stationary(Isometry3::Identity()))
                .status,
            dm::ToiStatus::NoHit);
  const dm::ToiResult still = dm::conservativeAdvancement(a, Motion::stationary(at(-1, 0, 0)), b,
                                                          Motion::stationary(Isometry3::Identity()));
  EXPECT_EQ(still.status, dm::ToiStatus::NoHit);
  EXPECT_EQ(still.iterations, 1);
  // Moving in parallel (same displacement): no relative motion.
  EXPECT_EQ(
      dm::conservativeAdvancement(a, Motion{at(-1, 0, 0), at(0, 0, 1)}, b, Motion{at(0, 0, 0), at(1, 0, 1)})
          .status,
      dm::ToiStatus::NoHit);
  // Overlapping at the start: t = 0, depth and normal of the contact.
  const Motion deep{at(0.15, 0, 0), at(1, 0, 0)};
  const dm::ToiResult over =
      dm::conservativeAdvancement(b, Motion::stationary(Isometry3::Identity()), a, deep);
  EXPECT_EQ(over.status, dm::ToiStatus::Overlapping);
  EXPECT_TRUE(over.hit);
  EXPECT_EQ(over.t, 0.0);
  EXPECT_NEAR(over.distance, -0.05, 1e-12);
  EXPECT_NEAR((over.normal - Vec3(1, 0, 0)).norm(), 0.0, 1e-12);
  const dm::ToiResult overB = dm::bisectImpact(b, Motion::stationary(Isometry3::Identity()), a, deep);
  EXPECT_EQ(overB.status, dm::ToiStatus::Overlapping);
  EXPECT_NEAR(overB.distance, -0.05, 1e-12);
  // Iteration cap: the last time reached is a safe lower bound.
  const dm::ToiResult capped = dm::conservativeAdvancement(
      dm::Box(Vec3(0.1, 0.1, 0.1)), Motion{at(-1, 0, 0), rotated(at(1, 0, 0), 3.0, Vec3(0, 1, 0))}, b,
      Motion::stationary(Isometry3::Identity()), {1e-12, 1});
  EXPECT_EQ(capped.status, dm::ToiStatus::MaxIterations);
  EXPECT_FALSE(capped.hit);
  EXPECT_EQ(capped.t, 0.0);
  // A rotating plane has no speed bound.
  EXPECT_EQ(dm::conservativeAdvancement(
                dm::Plane(Vec3(0, 0, 1), 0),
                Motion{Isometry3::Identity(), rotated(Isometry3::Identity(), 0.1, Vec3(1, 0, 0))}, a,
                Motion::stationary(at(0, 0, 1)))
                .status,
            dm::ToiStatus::Unsupported);
}

TEST(ToiConservativeAdvancement, AgreesWithBisectionOnRandomConvexMotions) {
  std::mt19937_64 rng(7);
  const dm::Box box(Vec3(0.15, 0.1, 0.05));
  const dm::Capsule capsule(0.05, 0.2);
  const dm::Cylinder cylinder(0.1, 0.1);
  std::vector<Vec3> pts;
  std::uniform_real_distribution<double> u(-0.15, 0.15);
  for (int i = 0; i < 30; ++i) pts.emplace_back(u(rng), u(rng), u(rng));
  const auto hull = dm::ConvexHull::create(pts);
  ASSERT_TRUE(hull.ok());
  const dm::Shape* shapes[] = {&box, &capsule, &cylinder, hull->get()};
  int hits = 0;
  for (int trial = 0; trial < 40; ++trial) {
    const dm::Shape& a = *shapes[trial % 4];
    const dm::Shape& b = *shapes[(trial / 4) % 4];
    // A crosses B's neighbourhood while both turn: usually a real impact.
    const Isometry3 b0 = randomToiPose(rng, 0.05), b1 = rotated(b0, 0.5, Vec3(u(rng), u(rng), 1));
    Isometry3 a0 = randomToiPose(rng, 0.1), a1 = randomToiPose(rng, 0.1);
    const Vec3 through = 1.2 * Vec3(u(rng), u(rng), u(rng)).normalized();
    a0.translation() += through;
    a1.translation() -= through;
    const Motion ma{a0, a1}, mb{b0, b1};
    const dm::ToiResult ca = dm::conservativeAdvancement(a, ma, b, mb, {1e-8, 400});
    const dm::ToiResult bi = dm::bisectImpact(a, ma, b, mb, {32, 1e-9, 64});
    ASSERT_NE(ca.status, dm::ToiStatus::MaxIterations) << trial;
    if (bi.status == dm::ToiStatus::Hit) {
      ASSERT_EQ(ca.status, dm::ToiStatus::Hit) << trial;
      ++hits;
      EXPECT_LE(ca.t, bi.t + 1e-12) << trial;
      EXPECT_NEAR(ca.t, bi.t, 1e-5) << trial;
      // At CA's time the gap is about its tolerance.
      const double gap = dm::distance(a, ma.at(ca.t), b, mb.at(ca.t)).distance;
      EXPECT_LT(gap, 1e-7) << trial;  // a cold GJK on a cylinder is looser than CA's warm one
    } else if (ca.status == dm::ToiStatus::Hit) {
      // Only a contact thinner than a sample interval may escape bisection.
      EXPECT_GT(bruteForceImpact(a, ma, b, mb, 4000), 0) << trial;
    }
  }
  EXPECT_GE(hits, 25);
}

TEST(ToiConservativeAdvancement, CompoundUsesTheFullSpeedBound) {
  // Two balls, the lower one 0.2 below the frame origin: falling from z = 1
  // to z = −1 onto the floor, contact when the origin is at z = 0.3.
  const dm::Compound pair({{std::make_shared<dm::Sphere>(0.1), at(0.3, 0, 0)},
                           {std::make_shared<dm::Sphere>(0.1), at(-0.3, 0, -0.2)}});
  const dm::Plane floor(Vec3(0, 0, 1), 0.0);
  const Motion fall{at(0, 0, 1), at(0, 0, -1)};
  const dm::ToiResult r =
      dm::conservativeAdvancement(pair, fall, floor, Motion::stationary(Isometry3::Identity()), {1e-10, 100});
  ASSERT_EQ(r.status, dm::ToiStatus::Hit);
  EXPECT_LE(r.t, 0.35 + 1e-15);
  EXPECT_NEAR(r.t, 0.35, 1e-10);
  EXPECT_NEAR((r.point - Vec3(-0.3, 0, 0)).norm(), 0.0, 1e-9);
  // Turning a quarter about y while falling: brute force on the distance.
  const Motion tumble{at(0, 0, 1), rotated(at(0, 0, -1), kPi / 2, Vec3(0, 1, 0))};
  const double tRef = bruteForceImpact(pair, tumble, floor, Motion::stationary(Isometry3::Identity()), 2000);
  const dm::ToiResult rt = dm::conservativeAdvancement(
      pair, tumble, floor, Motion::stationary(Isometry3::Identity()), {1e-10, 200});
  ASSERT_EQ(rt.status, dm::ToiStatus::Hit);
  EXPECT_LE(rt.t, tRef + 1e-12);
  EXPECT_NEAR(rt.t, tRef, 1e-9);
}

// --- meshes ---------------------------------------------------------------

TEST(ToiConservativeAdvancement, MeshMeshAgreesWithBisection) {
  const auto ball = meshShape(dm::makeIcosphere(0.2, 1));
  const auto block = meshShape(dm::makeBox(Vec3(0.25, 0.15, 0.1)));
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(-1, 1);
  int hits = 0;
  for (int trial = 0; trial < 30; ++trial) {
    const dm::TriangleMesh& a = trial % 2 ? *ball : *block;
    const Isometry3 b0 = randomToiPose(rng, 0.05), b1 = rotated(b0, 0.4 * u(rng), Vec3(u(rng), u(rng), 1));
    Isometry3 a0 = randomToiPose(rng, 0.05), a1 = randomToiPose(rng, 0.05);
    const Vec3 through = 1.0 * Vec3(u(rng), u(rng), u(rng)).normalized();
    a0.translation() += through;
    a1.translation() -= through;
    const Motion ma{a0, a1}, mb{b0, b1};
    const dm::ToiResult ca = dm::conservativeAdvancement(a, ma, *ball, mb, {1e-7, 400});
    const dm::ToiResult bi = dm::bisectImpact(a, ma, *ball, mb, {32, 1e-8, 64});
    ASSERT_EQ(ca.status, dm::ToiStatus::Hit) << trial;  // they pass through each other
    ASSERT_EQ(bi.status, dm::ToiStatus::Hit) << trial;
    ++hits;
    EXPECT_LE(ca.t, bi.t + 1e-12) << trial;
    EXPECT_NEAR(ca.t, bi.t, 2e-4) << trial;
    EXPECT_LT(dm::meshMeshDistance(*a.bvh(), ma.at(ca.t), *ball->bvh(), mb.at(ca.t)).distance, 1e-7) << trial;
    EXPECT_TRUE(dm::meshMeshIntersect(*a.bvh(), ma.at(bi.t), *ball->bvh(), mb.at(bi.t))) << trial;
  }
  EXPECT_EQ(hits, 30);
}

TEST(ToiSweepPoint, IcosphereAgainstRaySphereAndTrianglePlane) {
  const double radius = 0.5;
  const auto ball = meshShape(dm::makeIcosphere(radius, 3));
  const Isometry3 pose = rotated(at(0.1, -0.2, 0.3), 0.7, Vec3(1, 2, 3));
  const dm::Mesh& mesh = *ball->mesh();
  // Largest gap between the sphere and a flat triangle (level 3: edges ≈ 0.1 rad).
  double sag = 0;
  for (const auto& tri : mesh.triangles) {
    const Vec3 c = (mesh.positions[tri[0]] + mesh.positions[tri[1]] + mesh.positions[tri[2]]) / 3.0;
    sag = std::max(sag, radius - c.norm());
  }
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(-1, 1);
  for (int trial = 0; trial < 200; ++trial) {
    const Vec3 dir = Vec3(u(rng), u(rng), u(rng)).normalized();
    Vec3 perp = Vec3(u(rng), u(rng), u(rng));
    perp -= perp.dot(dir) * dir;
    if (perp.norm() == 0) continue;
    perp *= 0.45 * std::abs(u(rng)) / perp.norm();  // passes within 0.45 of the centre
    const Vec3 fromL = perp - 1.5 * dir, toL = perp + 1.5 * dir;
    const Vec3 from = pose * fromL, to = pose * toL;
    const dm::SweepHit h = dm::sweepPoint(*ball, pose, from, to);
    ASSERT_EQ(h.status, dm::SweepStatus::Hit) << trial;
    // Ray–sphere: entry at 1.5 − √(r² − |perp|²) along a 3 m path; the mesh
    // lies inside the sphere by at most `sag` (the hit is later, not earlier).
    const double tSphere = (1.5 - std::sqrt(radius * radius - perp.squaredNorm())) / 3.0;
    EXPECT_GE(h.t, tSphere - 1e-12) << trial;
    const double pointSag = radius - (pose.inverse() * h.point).norm();
    EXPECT_GE(pointSag, -1e-12);
    EXPECT_LE(pointSag, sag + 1e-12);
    // Exactly on the plane of the reported triangle, inside it, facing the ray.
    const auto& tri = mesh.triangles[h.triangle];
    const Vec3 a = pose * mesh.positions[tri[0]], b = pose * mesh.positions[tri[1]],
               c = pose * mesh.positions[tri[2]];
    const Vec3 n = (b - a).cross(c - a).normalized();
    const double tPlane = n.dot(a - from) / n.dot(to - from);
    EXPECT_NEAR(h.t, tPlane, 1e-12) << trial;
    EXPECT_LT(dm::closestPointOnTriangle(h.point, a, b, c).distanceSq, 1e-24);
    EXPECT_NEAR((h.normal - n).norm(), 0.0, 1e-12);
    EXPECT_LT(h.normal.dot(to - from), 0);
    // Culling keeps the front hit; from the centre outwards there are only back faces.
    EXPECT_EQ(dm::sweepPoint(*ball, pose, from, to, {true}).triangle, h.triangle);
    EXPECT_FALSE(dm::sweepPoint(*ball, pose, pose * perp, to, {true}).hit());
    const dm::SweepHit out = dm::sweepPoint(*ball, pose, pose * perp, to);
    ASSERT_TRUE(out.hit());
    EXPECT_GT(out.normal.dot(to - from), 0);
  }
  // Misses: beside the sphere, too short, zero motion.
  EXPECT_FALSE(dm::sweepPoint(*ball, pose, pose * Vec3(-1, 0.6, 0), pose * Vec3(1, 0.6, 0)).hit());
  EXPECT_FALSE(dm::sweepPoint(*ball, pose, pose * Vec3(-1, 0, 0), pose * Vec3(-0.6, 0, 0)).hit());
  EXPECT_FALSE(dm::sweepPoint(*ball, pose, pose * Vec3(-1, 0, 0), pose * Vec3(-1, 0, 0)).hit());
  // A mesh shape without a BVH has nothing to sweep against.
  const dm::TriangleMesh bare(ball->mesh(), nullptr);
  EXPECT_FALSE(dm::sweepPoint(bare, pose, pose * Vec3(-1, 0, 0), pose * Vec3(1, 0, 0)).hit());
  EXPECT_FALSE(dm::sweepSphere(bare, pose, 0.1, pose * Vec3(-1, 0, 0), pose * Vec3(1, 0, 0)).hit());
}

TEST(ToiSweepPoint, StartsOnAFaceAndCrossesAnEdge) {
  const auto box = meshShape(dm::makeBox(Vec3(1, 1, 1)));
  // Starting on the top face: t = 0.
  dm::SweepHit h = dm::sweepPoint(*box, Isometry3::Identity(), Vec3(0.2, 0.3, 1), Vec3(0.2, 0.3, -3));
  ASSERT_EQ(h.status, dm::SweepStatus::Hit);
  EXPECT_EQ(h.t, 0.0);
  EXPECT_NEAR((h.normal - Vec3(0, 0, 1)).norm(), 0.0, 1e-15);
  // Through the top face's diagonal edge (watertight: one of the two triangles hits).
  h = dm::sweepPoint(*box, Isometry3::Identity(), Vec3(0.25, 0.25, 3), Vec3(0.25, 0.25, -3));
  ASSERT_TRUE(h.hit());
  EXPECT_NEAR(h.t, 2.0 / 6, 1e-15);
  const dm::SweepHit h2 =
      dm::sweepPoint(*box, Isometry3::Identity(), Vec3(0.25, -0.25, 3), Vec3(0.25, -0.25, -3));
  ASSERT_TRUE(h2.hit());
  EXPECT_NEAR(h2.t, 2.0 / 6, 1e-15);
  // Through the box's corner along the diagonal.
  h = dm::sweepPoint(*box, Isometry3::Identity(), Vec3(3, 3, 3), Vec3(-3, -3, -3));
  ASSERT_TRUE(h.hit());
  EXPECT_NEAR(h.t, 1.0 / 3, 1e-15);
  EXPECT_NEAR((h.point - Vec3(1, 1, 1)).norm(), 0.0, 1e-14);
}

// --- swept sphere on a box mesh (half extents 1, radius 0.25) -------------

class ToiSweepSphere : public ::testing::Test {
 protected:
  void SetUp() override { box_ = meshShape(dm::makeBox(Vec3(1, 1, 1))); }
  dm::SweepHit sweep(const Vec3& from, const Vec3& to, const dm::SweepOptions& o = {}) const {
    return dm::sweepSphere(*box_, Isometry3::Identity(), r_, from, to, o);
  }
  std::shared_ptr<const dm::TriangleMesh> box_;
  double r_ = 0.25;
};

TEST_F(ToiSweepSphere, FaceEdgeAndCornerImpacts) {
  // Face: straight down onto the top, centre reaches z = 1.25.
  dm::SweepHit h = sweep(Vec3(0.2, -0.3, 3), Vec3(0.2, -0.3, 0));
  ASSERT_EQ(h.status, dm::SweepStatus::Hit);
  EXPECT_NEAR(h.t, (3 - 1.25) / 3, 1e-14);
  EXPECT_NEAR((h.point - Vec3(0.2, -0.3, 1)).norm(), 0.0, 1e-14);
  EXPECT_NEAR((h.normal - Vec3(0, 0, 1)).norm(), 0.0, 1e-14);
  // Oblique onto the face.
  h = sweep(Vec3(-0.5, 0, 2), Vec3(0.5, 0, 0));
  EXPECT_NEAR(h.t, 0.75 / 2, 1e-14);
  EXPECT_NEAR((h.point - Vec3(-0.5 + 0.375, 0, 1)).norm(), 0.0, 1e-14);

  // Edge (y = z = 1, along x) approached diagonally: √2·(2 − 3s) = r.
  h = sweep(Vec3(0.3, 3, 3), Vec3(0.3, 0, 0));
  ASSERT_EQ(h.status, dm::SweepStatus::Hit);
  EXPECT_NEAR(h.t, (2 - r_ / std::sqrt(2.0)) / 3, 1e-14);
  EXPECT_NEAR((h.point - Vec3(0.3, 1, 1)).norm(), 0.0, 1e-14);
  EXPECT_NEAR((h.normal - Vec3(0, 1, 1).normalized()).norm(), 0.0, 1e-12);
  // Edge hit from a path that is not perpendicular to the edge: passing over
  // the top edge x = −1 at height 0.1 below r: contact at (x + 1)² + 0.15² = r².
  h = sweep(Vec3(-3, 0.4, 1.15), Vec3(3, 0.4, 1.15));
  ASSERT_EQ(h.status, dm::SweepStatus::Hit);
  EXPECT_NEAR(h.t, (3 - 1 - std::sqrt(r_ * r_ - 0.15 * 0.15)) / 6, 1e-14);
  EXPECT_NEAR((h.point - Vec3(-1, 0.4, 1)).norm(), 0.0, 1e-14);

  // Corner (1, 1, 1) along the diagonal: √3·(2 − 3s) = r.
  h = sweep(Vec3(3, 3, 3), Vec3(0, 0, 0));
  ASSERT_EQ(h.status, dm::SweepStatus::Hit);
  EXPECT_NEAR(h.t, (2 - r_ / std::sqrt(3.0)) / 3, 1e-14);
  EXPECT_NEAR((h.point - Vec3(1, 1, 1)).norm(), 0.0, 1e-14);
  EXPECT_NEAR((h.normal - Vec3(1, 1, 1).normalized()).norm(), 0.0, 1e-12);

  // The same under a pose: everything moves with it.
  const Isometry3 pose = rotated(at(0.5, -1, 2), 1.1, Vec3(3, -1, 2));
  const dm::SweepHit hp = dm::sweepSphere(*box_, pose, r_, pose * Vec3(3, 3, 3), pose * Vec3(0, 0, 0));
  EXPECT_NEAR(hp.t, (2 - r_ / std::sqrt(3.0)) / 3, 1e-13);
  EXPECT_NEAR((hp.point - pose * Vec3(1, 1, 1)).norm(), 0.0, 1e-13);
  EXPECT_NEAR((hp.normal - pose.linear() * Vec3(1, 1, 1).normalized()).norm(), 0.0, 1e-12);
}

TEST_F(ToiSweepSphere, GrazingAndParallelMotionDoNotStop) {
  // Sliding along the top face at exactly the radius, across the diagonal
  // edge between its two triangles and over the far edge.
  EXPECT_FALSE(sweep(Vec3(-3, 0.3, 1.25), Vec3(3, -0.2, 1.25)).hit());
  // Grazing the edge x = −1, z = 1 at exactly r (parallel to it, and across it).
  const double g = r_ / std::sqrt(2.0);
  EXPECT_FALSE(sweep(Vec3(-1 - g, -3, 1 + g), Vec3(-1 - g, 3, 1 + g)).hit());
  EXPECT_FALSE(sweep(Vec3(-1.25, -3, 1.25), Vec3(-1.25, 3, 1.25)).hit());
  // Grazing the corner at exactly r on a tangent path.
  const Vec3 n = Vec3(1, 1, 1).normalized(), tangent = Vec3(1, -1, 0).normalized();
  EXPECT_FALSE(sweep(Vec3(1, 1, 1) + r_ * n - 2 * tangent, Vec3(1, 1, 1) + r_ * n + 2 * tangent).hit());
  // A hair lower they hit.
  EXPECT_TRUE(sweep(Vec3(-3, 0.3, 1.25 - 1e-6), Vec3(3, -0.2, 1.25 - 1e-6)).hit());
  EXPECT_TRUE(
      sweep(Vec3(1, 1, 1) + (r_ - 1e-6) * n - 2 * tangent, Vec3(1, 1, 1) + (r_ - 1e-6) * n + 2 * tangent)
          .hit());
  // Beside the box.
  EXPECT_FALSE(sweep(Vec3(-3, 1.3, 0), Vec3(3, 1.3, 0)).hit());
}

TEST_F(ToiSweepSphere, StartingContacts) {
  // Touching the top and pressing down: t = 0, a plain hit.
  dm::SweepHit h = sweep(Vec3(0, 0, 1.25), Vec3(0, 0, 0.5));
  EXPECT_EQ(h.status, dm::SweepStatus::Hit);
  EXPECT_EQ(h.t, 0.0);
  EXPECT_NEAR((h.normal - Vec3(0, 0, 1)).norm(), 0.0, 1e-14);
  // Touching and leaving or sliding: free.
  EXPECT_FALSE(sweep(Vec3(0, 0, 1.25), Vec3(0, 0, 2)).hit());
  EXPECT_FALSE(sweep(Vec3(0, 0, 1.25), Vec3(0.5, 0.5, 1.25)).hit());
  // Embedded 0.15 deep and pressing further: StartPenetrating.
  h = sweep(Vec3(0.1, 0, 1.1), Vec3(0.1, 0, 0.9));
  EXPECT_EQ(h.status, dm::SweepStatus::StartPenetrating);
  EXPECT_EQ(h.t, 0.0);
  EXPECT_NEAR((h.point - Vec3(0.1, 0, 1)).norm(), 0.0, 1e-14);
  EXPECT_NEAR((h.normal - Vec3(0, 0, 1)).norm(), 0.0, 1e-14);
  // Embedded but moving out, or not moving: free, so a proxy can escape.
  EXPECT_FALSE(sweep(Vec3(0.1, 0, 1.1), Vec3(0.1, 0, 1.5)).hit());
  EXPECT_FALSE(sweep(Vec3(0.1, 0, 1.1), Vec3(0.1, 0, 1.1)).hit());
  // Embedded in the top and sliding along it: no deeper, so free.
  EXPECT_FALSE(sweep(Vec3(0.5, 0, 1.1), Vec3(0.6, 0, 1.1)).hit());
  // Zero radius is the point sweep.
  h = dm::sweepSphere(*box_, Isometry3::Identity(), 0.0, Vec3(0, 0, 3), Vec3(0, 0, 0));
  EXPECT_NEAR(h.t, 2.0 / 3, 1e-15);
}

TEST_F(ToiSweepSphere, MatchesConservativeAdvancementAndBruteForce) {
  const auto ball = meshShape(dm::makeIcosphere(0.4, 2));
  const dm::Sphere probe(0.05);
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-1, 1);
  int hits = 0;
  for (int trial = 0; trial < 60; ++trial) {
    const Isometry3 pose = randomToiPose(rng, 0.1);
    const Vec3 from = 0.8 * Vec3(u(rng), u(rng), u(rng)).normalized();
    const Vec3 to = 0.5 * Vec3(u(rng), u(rng), u(rng));
    const dm::SweepHit h = dm::sweepSphere(*ball, pose, probe.radius(), from, to);
    const dm::ToiResult ca = dm::conservativeAdvancement(
        *ball, Motion::stationary(pose), probe,
        Motion{at(from.x(), from.y(), from.z()), at(to.x(), to.y(), to.z())}, {1e-10, 400});
    if (!h.hit()) {
      EXPECT_NE(ca.status, dm::ToiStatus::Hit) << trial;
      continue;
    }
    ++hits;
    ASSERT_EQ(h.status, dm::SweepStatus::Hit) << trial;
    ASSERT_EQ(ca.status, dm::ToiStatus::Hit) << trial;
    EXPECT_LE(ca.t, h.t + 1e-12) << trial;
    const double speed = (to - from).norm();
    EXPECT_NEAR(ca.t, h.t, 1e-9 / speed + 1e-12) << trial;
    // The centre is exactly r from the mesh there, at the reported point.
    const Vec3 c = from + h.t * (to - from);
    const dm::MeshPointQuery q = dm::closestPointOnMesh(*ball->bvh(), pose, c);
    EXPECT_NEAR(std::abs(q.distance), probe.radius(), 1e-12) << trial;
    EXPECT_NEAR((h.point - c).norm(), probe.radius(), 1e-12) << trial;
    EXPECT_NEAR((h.normal - (c - h.point) / probe.radius()).norm(), 0.0, 1e-9) << trial;
  }
  EXPECT_GE(hits, 30);
}

}  // namespace
