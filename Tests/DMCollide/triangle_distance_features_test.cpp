// Tests of the separated-triangle distance (dm::separatedTriangleDistance,
// and triangleDistance's separated path): its early exit at a separating
// edge pair and its interior-only vertex–face cases must give the minimum
// over all 15 feature pairs (6 vertex–triangle, 9 edge–edge), computed here
// by brute force, on random, parallel-face, edge-on and touching pairs.
#include <dm/collide/triangle.hpp>
#include <dm/math/geometry.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <random>

namespace {

using dm::Vec3;
using Tri = std::array<Vec3, 3>;

double bruteDistance(const Tri& a, const Tri& b) {
  double best = std::numeric_limits<double>::infinity();
  for (int i = 0; i < 3; ++i) {
    best = std::min(best, dm::closestPointOnTriangle(a[i], b[0], b[1], b[2]).distanceSq);
    best = std::min(best, dm::closestPointOnTriangle(b[i], a[0], a[1], a[2]).distanceSq);
    for (int j = 0; j < 3; ++j)
      best = std::min(best, dm::closestPointsSegmentSegment(a[i], a[(i + 1) % 3], b[j], b[(j + 1) % 3])
                                .distanceSq);
  }
  return std::sqrt(best);
}

void expectMatches(const Tri& a, const Tri& b, int i) {
  const double ref = bruteDistance(a, b);
  for (bool swap : {false, true}) {
    const Tri& x = swap ? b : a;
    const Tri& y = swap ? a : b;
    const dm::TriangleDistance d = dm::separatedTriangleDistance(x[0], x[1], x[2], y[0], y[1], y[2]);
    // Relative 1e-12, plus the absolute rounding of the feature points
    // (coordinates of size 1: a few 1e-16) for the touching and 1e-12 gaps.
    ASSERT_NEAR(d.distance, ref, 1e-12 * ref + 1e-14) << i << (swap ? " swapped" : "");
    EXPECT_NEAR((d.pointA - d.pointB).norm(), d.distance, 1e-14);
    EXPECT_LT(dm::closestPointOnTriangle(d.pointA, x[0], x[1], x[2]).distanceSq, 1e-24) << i;
    EXPECT_LT(dm::closestPointOnTriangle(d.pointB, y[0], y[1], y[2]).distanceSq, 1e-24) << i;
  }
}

TEST(SeparatedTriangleDistance, MatchesAllFeaturePairsOnRandomPairs) {
  std::mt19937_64 rng(41);
  std::uniform_real_distribution<double> u(-1, 1);
  for (int i = 0; i < 20000; ++i) {
    Tri a, b;
    for (auto& v : a) v = Vec3(u(rng), u(rng), u(rng));
    const Vec3 shift(u(rng), u(rng), u(rng));
    for (auto& v : b) v = 0.6 * Vec3(u(rng), u(rng), u(rng)) + shift;
    expectMatches(a, b, i);  // intersecting pairs too: then the smallest feature pair
  }
}

TEST(SeparatedTriangleDistance, ParallelFacesAndEdgeOnPairs) {
  std::mt19937_64 rng(43);
  std::uniform_real_distribution<double> u(-1, 1);
  for (int i = 0; i < 5000; ++i) {
    Tri a;
    for (auto& v : a) v = Vec3(u(rng), u(rng), u(rng));
    const Vec3 n = (a[1] - a[0]).cross(a[2] - a[0]).normalized();
    const double gap = (i % 3 == 0) ? 0.0 : std::pow(10.0, -1 - (i % 12));
    Tri b;
    if (i % 2 == 0) {
      // Parallel face over A's interior (vertex–face and face–face ties).
      const Vec3 c = (a[0] + a[1] + a[2]) / 3;
      for (int k = 0; k < 3; ++k) b[k] = c + 0.3 * (a[k] - c) + 0.2 * (a[(k + 1) % 3] - c) * u(rng) + gap * n;
    } else {
      // Edge over an edge, crossing or parallel, at a small gap.
      const Vec3 m = 0.5 * (a[0] + a[1]);
      const Vec3 e = (a[1] - a[0]).normalized();
      const Vec3 side = n.cross(e);
      const Vec3 dir = (i % 4 == 1) ? e : Vec3(e + u(rng) * side).normalized();
      b = {m - 0.3 * dir + gap * n, m + 0.3 * dir + gap * n, m + 0.5 * n + 0.2 * side * u(rng) + gap * n};
    }
    expectMatches(a, b, i);
  }
}

TEST(SeparatedTriangleDistance, DegenerateTriangles) {
  const Tri a{Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0)};
  const Tri seg{Vec3(0.2, 0.2, 0.5), Vec3(0.3, 0.1, 0.5), Vec3(0.4, 0.0, 0.5)};  // collinear
  const Tri pt{Vec3(0.2, 0.2, 0.5), Vec3(0.2, 0.2, 0.5), Vec3(0.2, 0.2, 0.5)};
  expectMatches(a, seg, 0);
  expectMatches(a, pt, 1);
  expectMatches(seg, pt, 2);
  const dm::TriangleDistance d = dm::separatedTriangleDistance(a[0], a[1], a[2], pt[0], pt[1], pt[2]);
  EXPECT_NEAR(d.distance, 0.5, 1e-15);
}

}  // namespace
