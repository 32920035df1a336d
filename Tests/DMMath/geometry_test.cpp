// Closest point on a triangle against brute-force minimisation over a fine
// barycentric grid, and the known answers in each Voronoi region.
#include <dm/math/geometry.hpp>

#include <gtest/gtest.h>

#include <random>

namespace dm {
namespace {

double bruteForceDistanceSq(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  double best = 1e300;
  const int n = 400;
  for (int i = 0; i <= n; ++i)
    for (int j = 0; i + j <= n; ++j) {
      const double u = double(i) / n, v = double(j) / n;
      best = std::min(best, (p - ((1 - u - v) * a + u * b + v * c)).squaredNorm());
    }
  return best;
}

TEST(ClosestPointOnTriangle, RegionsOfTheUnitTriangle) {
  const Vec3 a(0, 0, 0), b(1, 0, 0), c(0, 1, 0);
  auto r = closestPointOnTriangle(Vec3(0.2, 0.2, 3), a, b, c);
  EXPECT_EQ(r.feature, TriangleFeature::Face);
  EXPECT_NEAR(r.distanceSq, 9.0, 1e-12);
  EXPECT_TRUE(r.point.isApprox(Vec3(0.2, 0.2, 0)));
  r = closestPointOnTriangle(Vec3(-1, -1, 0), a, b, c);
  EXPECT_EQ(r.feature, TriangleFeature::VertexA);
  r = closestPointOnTriangle(Vec3(0.5, -2, 0), a, b, c);
  EXPECT_EQ(r.feature, TriangleFeature::EdgeAB);
  EXPECT_NEAR(r.distanceSq, 4.0, 1e-12);
  r = closestPointOnTriangle(Vec3(1, 1, 0), a, b, c);
  EXPECT_EQ(r.feature, TriangleFeature::EdgeBC);
  EXPECT_NEAR(r.distanceSq, 0.5, 1e-12);
  EXPECT_NEAR(r.barycentric.sum(), 1.0, 1e-12);
}

TEST(ClosestPointOnTriangle, MatchesBruteForceOnRandomInput) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1, 1);
  for (int k = 0; k < 200; ++k) {
    const Vec3 a(u(rng), u(rng), u(rng)), b(u(rng), u(rng), u(rng)), c(u(rng), u(rng), u(rng));
    const Vec3 p = 2 * Vec3(u(rng), u(rng), u(rng));
    const auto r = closestPointOnTriangle(p, a, b, c);
    const double brute = bruteForceDistanceSq(p, a, b, c);
    EXPECT_LE(r.distanceSq, brute + 1e-12);
    EXPECT_NEAR(std::sqrt(r.distanceSq), std::sqrt(brute), 1e-2);
    const Vec3 q = r.barycentric.x() * a + r.barycentric.y() * b + r.barycentric.z() * c;
    EXPECT_LT((q - r.point).norm(), 1e-9);
  }
}

// A sliver as EPA and GJK meet it (a box edge against a cylinder rim): two
// 0.8 m edges 1e-6 m apart, turned and moved off the axes. The face point is
// the orthogonal projection: a point of the plane maps to itself, and the
// offset from any other point is orthogonal to both edge directions, each to
// rounding (measured 2.5e-16 m). Solved from vertex a (Ericson's areas, as
// before, or a Gram matrix of condition ~1e12) both missed by 1.7e-5 m.
TEST(ClosestPointOnTriangle, SliverFaceIsTheProjection) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1, 1);
  for (int k = 0; k < 50; ++k) {
    const Mat3 r = Quat(u(rng), u(rng), u(rng), u(rng)).normalized().toRotationMatrix();
    const Vec3 t = Vec3(u(rng), u(rng), u(rng));
    const Vec3 a = t, b = r * Vec3(0.8, 0, 0) + t, c = r * Vec3(0.8, 1e-6, 0) + t;
    const Vec3 inPlane = r * Vec3(0.4, 2.5e-7, 0) + t;  // barycentrics (0.5, 0.25, 0.25)
    const TriangleClosest q = closestPointOnTriangle(inPlane, a, b, c);
    EXPECT_EQ(q.feature, TriangleFeature::Face) << k;
    EXPECT_LT((q.point - inPlane).norm(), 1e-14) << k;
    const Vec3 l = planeBarycentric(inPlane, a, b, c);
    EXPECT_LT((l[0] * a + l[1] * b + l[2] * c - inPlane).norm(), 1e-14) << k;
    EXPECT_NEAR(l[0], 0.5, 1e-9) << k;  // the long direction is well conditioned

    const Vec3 p = inPlane + r * Vec3(0, 0, 0.3);
    const TriangleClosest o = closestPointOnTriangle(p, a, b, c);
    EXPECT_EQ(o.feature, TriangleFeature::Face) << k;
    EXPECT_LT(std::abs((p - o.point).dot((b - a).normalized())), 1e-14) << k;
    EXPECT_LT(std::abs((p - o.point).dot((c - b).normalized())), 1e-14) << k;
    EXPECT_NEAR(o.distanceSq, 0.09, 1e-14) << k;
  }
}

TEST(ClosestPointOnTriangle, DegenerateTrianglesFallBackToEdges) {
  // Collinear: the triangle is the segment from (0,0,0) to (2,0,0).
  auto r = closestPointOnTriangle(Vec3(1, 1, 0), Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(2, 0, 0));
  EXPECT_NEAR(r.distanceSq, 1.0, 1e-12);
  r = closestPointOnTriangle(Vec3(3, 0, 0), Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(2, 0, 0));
  EXPECT_NEAR(r.distanceSq, 1.0, 1e-12);
  // All three vertices coincide.
  r = closestPointOnTriangle(Vec3(0, 0, 2), Vec3(1, 1, 1), Vec3(1, 1, 1), Vec3(1, 1, 1));
  EXPECT_NEAR(r.distanceSq, 3.0, 1e-12);
  EXPECT_TRUE(std::isfinite(r.barycentric.sum()));
}

TEST(ClosestPointOnSegment, ClampsToTheEnds) {
  double t = -1;
  EXPECT_TRUE(
      closestPointOnSegment(Vec3(-5, 1, 0), Vec3(0, 0, 0), Vec3(1, 0, 0), &t).isApprox(Vec3(0, 0, 0)));
  EXPECT_EQ(t, 0.0);
  EXPECT_TRUE(
      closestPointOnSegment(Vec3(0.25, 1, 0), Vec3(0, 0, 0), Vec3(1, 0, 0), &t).isApprox(Vec3(0.25, 0, 0)));
  EXPECT_NEAR(t, 0.25, 1e-15);
}

}  // namespace
}  // namespace dm
