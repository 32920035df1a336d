// Tests of dm/collide/triangle.hpp: exact triangle predicates on coplanar,
// touching and degenerate input, and distances against FCL's
// TriangleDistance on random pairs.
#include <dm/collide/triangle.hpp>
#include <dm/math/geometry.hpp>

#include <gtest/gtest.h>

#include <fcl/narrowphase/detail/primitive_shape_algorithm/triangle_distance.h>

#include <array>
#include <cmath>
#include <random>

namespace {

using dm::Vec3;
using Tri = std::array<Vec3, 3>;

bool intersects(const Tri& a, const Tri& b) {
  return dm::trianglesIntersect(a[0], a[1], a[2], b[0], b[1], b[2]);
}

// The answer must not depend on argument order or corner order.
void expectSymmetric(const Tri& a, const Tri& b, bool expected) {
  const std::array<std::array<int, 3>, 6> perms{
      {{0, 1, 2}, {1, 2, 0}, {2, 0, 1}, {0, 2, 1}, {2, 1, 0}, {1, 0, 2}}};
  for (const auto& p : perms) {
    const Tri ap{a[p[0]], a[p[1]], a[p[2]]};
    EXPECT_EQ(intersects(ap, b), expected);
    EXPECT_EQ(intersects(b, ap), expected);
  }
}

const Tri kBase{Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0)};
const double kUlp = std::ldexp(1.0, -50);

TEST(Orient3d, ExactSignsNearThePlane) {
  const Vec3 a(1, 0, 0), b(0, 1, 0), c(0, 0, 1);  // plane x + y + z = 1, normal (1, 1, 1)
  EXPECT_EQ(dm::orient3d(a, b, c, Vec3(0.25, 0.25, 0.5)), 0);
  EXPECT_EQ(dm::orient3d(a, b, c, Vec3(0.25, 0.25, std::nextafter(0.5, 1.0))), 1);
  EXPECT_EQ(dm::orient3d(a, b, c, Vec3(0.25, 0.25, std::nextafter(0.5, 0.0))), -1);
  EXPECT_EQ(dm::orient3d(b, a, c, Vec3(0.25, 0.25, std::nextafter(0.5, 1.0))), -1);
  // Coordinates of very different magnitudes: the double determinant is all
  // rounding, the exact sign is not.
  const Vec3 p(1e-20, 0, 0), q(0, 1e20, 0), r(0, 0, 1);
  EXPECT_EQ(dm::orient3d(Vec3::Zero(), p, q, r), 1);
  EXPECT_EQ(
      dm::orient3d(Vec3(1, 1, 1), Vec3(1 + 2 * kUlp, 1, 1), Vec3(1, 1 + 2 * kUlp, 1), Vec3(1, 1, 1 + kUlp)),
      1);
}

TEST(TrianglesIntersect, CoplanarOverlapAndTouching) {
  expectSymmetric(kBase, {Vec3(0.2, 0.2, 0), Vec3(2, 0.2, 0), Vec3(0.2, 2, 0)}, true);      // overlapping
  expectSymmetric(kBase, {Vec3(0.1, 0.1, 0), Vec3(0.3, 0.1, 0), Vec3(0.1, 0.3, 0)}, true);  // contained
  expectSymmetric(kBase, {Vec3(1, 0, 0), Vec3(2, 0, 0), Vec3(1, 1, 0)}, true);              // vertex–vertex
  expectSymmetric(kBase, {Vec3(1 + kUlp, 0, 0), Vec3(2, 0, 0), Vec3(1 + kUlp, 1, 0)}, false);  // just apart
  expectSymmetric(kBase, {Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(1, 1, 0)}, true);                 // shared edge
  expectSymmetric(kBase, {Vec3(0.5, 0.5, 0), Vec3(1, 1, 0), Vec3(2, 0.5, 0)}, true);  // vertex on edge
  expectSymmetric(kBase, {Vec3(0.5 + kUlp, 0.5 + kUlp, 0), Vec3(1, 1, 0), Vec3(2, 0.5, 0)}, false);
  expectSymmetric(kBase, {Vec3(-1, 0.5, 0), Vec3(2, 0.5, 0), Vec3(0.5, 3, 0)}, true);  // edges cross only
  // A tilted plane with exactly representable coordinates: x + y + z = 1.
  const Tri t{Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(0, 0, 1)};
  expectSymmetric(t, {Vec3(0.5, 0.5, 0), Vec3(0.5, 0, 0.5), Vec3(0, 0.5, 0.5)}, true);
  expectSymmetric(t, {Vec3(1, 0, 0), Vec3(2, -1, 0), Vec3(2, 0, -1)}, true);
  expectSymmetric(t, {Vec3(1 + kUlp, -kUlp, 0), Vec3(2, -1, 0), Vec3(2, 0, -1)}, false);
}

TEST(TrianglesIntersect, NonCoplanarTouching) {
  expectSymmetric(kBase, {Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(0.5, 0.5, 1)}, true);         // shared edge
  expectSymmetric(kBase, {Vec3(0.25, 0.25, 0), Vec3(1, 1, 1), Vec3(-1, 1, 1)}, true);      // vertex on face
  expectSymmetric(kBase, {Vec3(0.25, 0.25, kUlp), Vec3(1, 1, 1), Vec3(-1, 1, 1)}, false);  // just above
  expectSymmetric(kBase, {Vec3(0.25, 0.25, -kUlp), Vec3(1, 1, 1), Vec3(-1, 1, 1)}, true);  // just through
  expectSymmetric(kBase, {Vec3(0.5, -1, 0), Vec3(0.5, 1, 0), Vec3(0.5, 0, 1)}, true);      // edge in plane
  expectSymmetric(kBase, {Vec3(0.5, -1, 1), Vec3(0.5, 2, 1), Vec3(0.5, 0, -1)}, true);     // piercing
  expectSymmetric(kBase, {Vec3(2, -1, 1), Vec3(2, 2, 1), Vec3(2, 0, -1)}, false);  // plane crossed outside
  expectSymmetric(kBase, {Vec3(0.5, 0.5 + kUlp, -1), Vec3(0.5, 0.5 + kUlp, 1), Vec3(3, 3, 0)}, false);
  expectSymmetric(kBase, {Vec3(0.5, 0.5, -1), Vec3(0.5, 0.5, 1), Vec3(3, 3, 0)}, true);  // edge through edge
}

TEST(TrianglesIntersect, DegenerateTriangles) {
  const Tri segment{Vec3(0.2, 0.2, -1), Vec3(0.2, 0.2, 1), Vec3(0.2, 0.2, 0.5)};
  expectSymmetric(kBase, segment, true);
  expectSymmetric(kBase, {Vec3(2, 0.2, -1), Vec3(2, 0.2, 1), Vec3(2, 0.2, 0.5)}, false);
  expectSymmetric(kBase, {Vec3(0.25, 0.25, 0), Vec3(0.25, 0.25, 0), Vec3(0.25, 0.25, 0)},
                  true);  // point on face
  expectSymmetric(kBase, {Vec3(0.25, 0.25, kUlp), Vec3(0.25, 0.25, kUlp), Vec3(0.25, 0.25, kUlp)}, false);
  expectSymmetric(kBase, {Vec3(0.5, 0.5, 0), Vec3(0.5, 0.5, 0), Vec3(0.5, 0.5, 0)}, true);  // point on edge
  // Coplanar segment crossing an edge, and one just outside.
  expectSymmetric(kBase, {Vec3(-1, 0.5, 0), Vec3(0, 0.5, 0), Vec3(1, 0.5, 0)}, true);
  expectSymmetric(kBase, {Vec3(-1, 0.5, 0), Vec3(-0.5, 0.5, 0), Vec3(-kUlp, 0.5, 0)}, false);
  // Both degenerate: crossing segments, skew segments, collinear overlap and gap, points.
  const Tri s1{Vec3(-1, 0, 0), Vec3(0, 0, 0), Vec3(1, 0, 0)};
  expectSymmetric(s1, {Vec3(0, -1, 0), Vec3(0, 1, 0), Vec3(0, 0.5, 0)}, true);
  expectSymmetric(s1, {Vec3(0, -1, kUlp), Vec3(0, 1, kUlp), Vec3(0, 0.5, kUlp)}, false);
  expectSymmetric(s1, {Vec3(1, 0, 0), Vec3(2, 0, 0), Vec3(3, 0, 0)}, true);
  expectSymmetric(s1, {Vec3(1 + kUlp, 0, 0), Vec3(2, 0, 0), Vec3(3, 0, 0)}, false);
  expectSymmetric(s1, {Vec3(0.5, 0, 0), Vec3(0.5, 0, 0), Vec3(0.5, 0, 0)}, true);
  expectSymmetric({Vec3(1, 2, 3), Vec3(1, 2, 3), Vec3(1, 2, 3)},
                  {Vec3(1, 2, 3), Vec3(1, 2, 3), Vec3(1, 2, 3)}, true);
}

TEST(TrianglesIntersect, ScaleInvariantFromTinyToHuge) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(-1, 1);
  for (int i = 0; i < 2000; ++i) {
    Tri a, b;
    for (auto& v : a) v = Vec3(u(rng), u(rng), u(rng));
    for (auto& v : b) v = Vec3(u(rng), u(rng), u(rng));
    // Make some pairs touch exactly: a shared corner.
    if (i % 3 == 0) b[0] = a[1];
    const bool ref = intersects(a, b);
    for (int e : {-60, -30, 30, 60}) {  // powers of two keep the coordinates exact
      Tri as = a, bs = b;
      for (auto& v : as) v *= std::ldexp(1.0, e);
      for (auto& v : bs) v *= std::ldexp(1.0, e);
      ASSERT_EQ(intersects(as, bs), ref) << i << " scale 2^" << e;
    }
    if (i % 3 == 0) {
      EXPECT_TRUE(ref);  // a shared point is always found
    }
  }
}

double fclTriDistance(const Tri& a, const Tri& b, Vec3& p, Vec3& q) {
  const fcl::Vector3d ta[3] = {a[0], a[1], a[2]}, tb[3] = {b[0], b[1], b[2]};
  fcl::Vector3d fp, fq;
  const double d = fcl::detail::TriangleDistance<double>::triDistance(ta, tb, fp, fq);
  p = fp;
  q = fq;
  return d;
}

TEST(TriangleDistance, MatchesFclOnRandomPairs) {
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(-1, 1);
  int separated = 0, touching = 0;
  for (int i = 0; i < 20000; ++i) {
    Tri a, b;
    for (auto& v : a) v = Vec3(u(rng), u(rng), u(rng));
    const Vec3 shift(u(rng), u(rng), u(rng));
    for (auto& v : b) v = 0.6 * Vec3(u(rng), u(rng), u(rng)) + shift;
    const dm::TriangleDistance d = dm::triangleDistance(a[0], a[1], a[2], b[0], b[1], b[2]);
    Vec3 fp, fq;
    const double ref = fclTriDistance(a, b, fp, fq);
    // Closest points lie on their triangles and realise the distance.
    EXPECT_LT(dm::closestPointOnTriangle(d.pointA, a[0], a[1], a[2]).distanceSq, 1e-24);
    EXPECT_LT(dm::closestPointOnTriangle(d.pointB, b[0], b[1], b[2]).distanceSq, 1e-24);
    EXPECT_NEAR((d.pointA - d.pointB).norm(), d.distance, 1e-14);
    if (intersects(a, b)) {
      ++touching;
      EXPECT_EQ(d.distance, 0.0);
      EXPECT_LT(ref, 1e-12);
    } else {
      ++separated;
      EXPECT_GT(d.distance, 0.0);
      ASSERT_NEAR(d.distance, ref, 1e-12 * std::max(ref, 1e-3)) << i;
    }
  }
  EXPECT_GT(separated, 1000);
  EXPECT_GT(touching, 1000);
}

TEST(TriangleIntersection, PointsLieOnBothTriangles) {
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(-1, 1);
  int found = 0;
  for (int i = 0; i < 20000; ++i) {
    Tri a, b;
    for (auto& v : a) v = Vec3(u(rng), u(rng), u(rng));
    for (auto& v : b) v = Vec3(u(rng), u(rng), u(rng));
    const dm::TriangleIntersection x = dm::triangleIntersection(a[0], a[1], a[2], b[0], b[1], b[2]);
    ASSERT_EQ(x.intersects, intersects(a, b));
    if (!x.intersects) {
      EXPECT_EQ(x.count, 0);
      continue;
    }
    ++found;
    EXPECT_FALSE(x.coplanar);
    ASSERT_EQ(x.count, 2);
    for (int k = 0; k < x.count; ++k) {
      EXPECT_LT(dm::closestPointOnTriangle(x.points[k], a[0], a[1], a[2]).distanceSq, 1e-24);
      EXPECT_LT(dm::closestPointOnTriangle(x.points[k], b[0], b[1], b[2]).distanceSq, 1e-24);
    }
  }
  EXPECT_GT(found, 1000);
}

TEST(TriangleIntersection, CoplanarOverlapPolygon) {
  // Two triangles forming a hexagram: the overlap is a regular-ish hexagon.
  const Tri a{Vec3(0, 0, 0), Vec3(3, 0, 0), Vec3(0, 3, 0)};
  const Tri b{Vec3(2, 2, 0), Vec3(-1, 2, 0), Vec3(2, -1, 0)};
  const dm::TriangleIntersection x = dm::triangleIntersection(a[0], a[1], a[2], b[0], b[1], b[2]);
  ASSERT_TRUE(x.intersects);
  EXPECT_TRUE(x.coplanar);
  EXPECT_EQ(x.count, 6);
  // Overlap {0 <= x, y <= 2, 1 <= x + y <= 3}: the 2x2 square less two corners of area 1/2.
  double area = 0;
  for (int k = 0; k < x.count; ++k) {
    const Vec3& p = x.points[k];
    const Vec3& q = x.points[(k + 1) % x.count];
    area += 0.5 * (p.x() * q.y() - q.x() * p.y());
  }
  EXPECT_NEAR(std::abs(area), 3.0, 1e-12);
}

TEST(SegmentSegment, ClosestPointsAreOptimal) {
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-1, 1);
  // Parallel and degenerate cases have known distances.
  EXPECT_NEAR(
      std::sqrt(dm::closestPointsSegmentSegment(Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0.5, 1, 0), Vec3(2, 1, 0))
                    .distanceSq),
      1.0, 1e-15);
  EXPECT_NEAR(
      std::sqrt(dm::closestPointsSegmentSegment(Vec3(0, 0, 0), Vec3(0, 0, 0), Vec3(1, 1, 0), Vec3(1, 1, 0))
                    .distanceSq),
      std::sqrt(2.0), 1e-15);
  EXPECT_NEAR(
      dm::closestPointsSegmentSegment(Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(2, 0, 0), Vec3(3, 0, 0)).distanceSq,
      1.0, 1e-15);
  for (int i = 0; i < 200; ++i) {
    const Vec3 p0(u(rng), u(rng), u(rng)), p1(u(rng), u(rng), u(rng)), q0(u(rng), u(rng), u(rng));
    // Every fourth pair nearly parallel.
    const Vec3 q1 =
        i % 4 == 0 ? Vec3(q0 + (p1 - p0) * 0.7 + Vec3::Constant(1e-9)) : Vec3(u(rng), u(rng), u(rng));
    const dm::SegmentClosest c = dm::closestPointsSegmentSegment(p0, p1, q0, q1);
    EXPECT_NEAR((c.pointA - (p0 + c.s * (p1 - p0))).norm(), 0.0, 1e-15);
    double brute = 1e300;
    for (int a = 0; a <= 100; ++a)
      for (int b = 0; b <= 100; ++b)
        brute = std::min(brute, (p0 + (p1 - p0) * (a / 100.0) - q0 - (q1 - q0) * (b / 100.0)).squaredNorm());
    EXPECT_LE(c.distanceSq, brute * (1 + 1e-12) + 1e-15);
    EXPECT_GE(c.distanceSq, brute - 0.04 * std::sqrt(brute) - 4e-4);  // grid resolution
  }
}

TEST(RayTriangle, HitsAnalyticPointAndIsWatertight) {
  dm::RayTriangleHit h;
  ASSERT_TRUE(dm::rayTriangle(Vec3(0.25, 0.25, 1), Vec3(0, 0, -2), kBase[0], kBase[1], kBase[2], 0, 10, h));
  EXPECT_DOUBLE_EQ(h.t, 0.5);
  EXPECT_NEAR((h.barycentric - Vec3(0.5, 0.25, 0.25)).norm(), 0, 1e-15);
  EXPECT_FALSE(dm::rayTriangle(Vec3(0.25, 0.25, 1), Vec3(0, 0, -2), kBase[0], kBase[1], kBase[2], 0, 0.4, h));
  EXPECT_FALSE(dm::rayTriangle(Vec3(0.25, 0.25, 1), Vec3(0, 0, 2), kBase[0], kBase[1], kBase[2], 0, 10, h));
  EXPECT_FALSE(dm::rayTriangle(Vec3(0.75, 0.75, 1), Vec3(0, 0, -1), kBase[0], kBase[1], kBase[2], 0, 10, h));
  // Rays aimed at points of the diagonal shared by the two triangles of a
  // flat quad (seen from off its plane, so the diagonal is interior) hit at
  // least one of them.
  std::mt19937_64 rng(9);
  std::uniform_real_distribution<double> u(0.01, 0.99), w(-1, 1);
  const Vec3 a(0.1, 0.2, 0.3), b(1.7, 0.4, -0.2), c(0.3, 1.9, 0.5), d = b + c - a;
  const Vec3 n = (b - a).cross(c - a).normalized();
  for (int i = 0; i < 20000; ++i) {
    const Vec3 target = a + u(rng) * (d - a);  // on the shared edge a–d
    const Vec3 offset = Vec3(w(rng), w(rng), w(rng));
    if (std::abs(offset.normalized().dot(n)) < 0.1) continue;
    const Vec3 origin = target + 3 * offset;
    const Vec3 dir = target - origin;
    dm::RayTriangleHit h1, h2;
    const bool hit1 = dm::rayTriangle(origin, dir, a, b, d, 0, 2, h1);
    const bool hit2 = dm::rayTriangle(origin, dir, a, d, c, 0, 2, h2);
    ASSERT_TRUE(hit1 || hit2) << i;
  }
}

TEST(SegmentTriangle, DistanceAndIntersection) {
  EXPECT_TRUE(
      dm::segmentTriangleIntersect(Vec3(0.2, 0.2, -1), Vec3(0.2, 0.2, 1), kBase[0], kBase[1], kBase[2]));
  EXPECT_FALSE(
      dm::segmentTriangleIntersect(Vec3(0.2, 0.2, kUlp), Vec3(0.2, 0.2, 1), kBase[0], kBase[1], kBase[2]));
  const dm::TriangleDistance d =
      dm::segmentTriangleDistance(Vec3(2, 0, 1), Vec3(2, 0, -1), kBase[0], kBase[1], kBase[2]);
  EXPECT_NEAR(d.distance, 1.0, 1e-15);
  EXPECT_NEAR((d.pointB - Vec3(1, 0, 0)).norm(), 0, 1e-15);
  const dm::TriangleDistance p =
      dm::segmentTriangleDistance(Vec3(0.2, 0.2, -1), Vec3(0.2, 0.2, 1), kBase[0], kBase[1], kBase[2]);
  EXPECT_EQ(p.distance, 0.0);
  EXPECT_NEAR((p.pointA - Vec3(0.2, 0.2, 0)).norm(), 0, 1e-15);
}

}  // namespace
