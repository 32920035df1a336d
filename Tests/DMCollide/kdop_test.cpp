// Tests of dm/collide/kdop.hpp: the axes are the documented ones, a k-DOP
// of a point set is per axis the exact extreme projection, merge equals the
// k-DOP of the union, overlap equals the brute-force interval test on every
// axis, and it never reports disjoint for intersecting convex hulls (exact
// GJK on dm::ConvexHull) nor for intersecting triangles.
#include <dm/collide/kdop.hpp>
#include <dm/collide/query.hpp>
#include <dm/collide/shapes.hpp>
#include <dm/collide/triangle.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <limits>
#include <random>
#include <utility>
#include <vector>

namespace {

using dm::Vec3;

std::vector<Vec3> randomCloud(std::mt19937_64& rng, const Vec3& center, double radius, int n) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::vector<Vec3> pts;
  while (static_cast<int>(pts.size()) < n) {
    const Vec3 p(u(rng), u(rng), u(rng));
    if (p.squaredNorm() <= 1.0) pts.push_back(center + radius * p);
  }
  return pts;
}

// Brute force: extreme projections of `pts` on `axis`.
std::pair<double, double> extent(const std::vector<Vec3>& pts, const Vec3& axis) {
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  for (const Vec3& p : pts) lo = std::min(lo, axis.dot(p)), hi = std::max(hi, axis.dot(p));
  return {lo, hi};
}

template <class T>
class KdopTyped : public ::testing::Test {};
using KdopTypes = ::testing::Types<dm::Kdop14, dm::Kdop18, dm::Kdop26>;
TYPED_TEST_SUITE(KdopTyped, KdopTypes);

TYPED_TEST(KdopTyped, AxesAreTheDocumentedDistinctDirections) {
  using D = TypeParam;
  for (int i = 0; i < 3; ++i) EXPECT_EQ(D::axis(i), Vec3::Unit(i));
  int corners = 0, edges = 0;
  for (int i = 0; i < D::kSlabs; ++i) {
    const Vec3 a = D::axis(i);
    const int nonzero = static_cast<int>((a.array() != 0).count());
    EXPECT_TRUE((a.array().abs() == 1 || a.array() == 0).all()) << a.transpose();
    corners += nonzero == 3, edges += nonzero == 2;
    for (int j = 0; j < i; ++j) EXPECT_LT(std::abs(a.normalized().dot(D::axis(j).normalized())), 1 - 1e-9);
  }
  EXPECT_EQ(corners, D::kSlabs == 9 ? 0 : 4);
  EXPECT_EQ(edges, D::kSlabs == 7 ? 0 : 6);
}

TYPED_TEST(KdopTyped, FromPointsIsTightestPerAxisAndMergeIsTheUnion) {
  using D = TypeParam;
  std::mt19937_64 rng(11);
  for (int trial = 0; trial < 50; ++trial) {
    const auto a = randomCloud(rng, Vec3::Zero(), 1.0, 1 + trial % 9);
    const auto b = randomCloud(rng, Vec3(0.5, -0.3, 0.2), 0.7, 1 + trial % 5);
    const D ka = D::fromPoints(a), kb = D::fromPoints(b);
    auto all = a;
    all.insert(all.end(), b.begin(), b.end());
    const D ku = D::fromPoints(all);
    D km = ka;
    km.merge(kb);
    for (int i = 0; i < D::kSlabs; ++i) {
      const auto [lo, hi] = extent(a, D::axis(i));
      EXPECT_EQ(ka.min(i), lo);
      EXPECT_EQ(ka.max(i), hi);
      EXPECT_EQ(km.min(i), ku.min(i));
      EXPECT_EQ(km.max(i), ku.max(i));
    }
    EXPECT_TRUE(km.contains(ka) && km.contains(kb));
    for (const Vec3& p : all) EXPECT_TRUE(ku.contains(p));
    // Every point outside a slab is outside the k-DOP.
    const Vec3 outside = Vec3(0, 0, ka.max(2) + 1e-6);
    EXPECT_FALSE(ka.contains(outside));
    // The AABB is the first three slabs, i.e. the points' bounding box.
    dm::Aabb box;
    for (const Vec3& p : a) box.extend(p);
    EXPECT_TRUE(ka.aabb().isApprox(box));
  }
}

TYPED_TEST(KdopTyped, OverlapIsTheExactIntervalTestAndConservative) {
  using D = TypeParam;
  std::mt19937_64 rng(12);
  std::uniform_real_distribution<double> off(-1.6, 1.6);
  int disjointKdops = 0, hullHits = 0;
  for (int trial = 0; trial < 200; ++trial) {
    const auto a = randomCloud(rng, Vec3::Zero(), 1.0, 8);
    const auto b = randomCloud(rng, Vec3(off(rng), off(rng), off(rng)), 1.0, 8);
    const D ka = D::fromPoints(a), kb = D::fromPoints(b);
    bool brute = true;
    for (int i = 0; i < D::kSlabs; ++i) {
      const auto [alo, ahi] = extent(a, D::axis(i));
      const auto [blo, bhi] = extent(b, D::axis(i));
      brute = brute && alo <= bhi && blo <= ahi;
    }
    EXPECT_EQ(ka.overlaps(kb), brute);
    EXPECT_EQ(kb.overlaps(ka), brute);
    // Hulls that intersect (exact GJK) always have overlapping k-DOPs.
    auto ha = dm::ConvexHull::create(a);
    auto hb = dm::ConvexHull::create(b);
    ASSERT_TRUE(ha && hb);
    const bool hulls = dm::intersect(**ha, dm::Isometry3::Identity(), **hb, dm::Isometry3::Identity());
    if (hulls) {
      ++hullHits;
      EXPECT_TRUE(ka.overlaps(kb));
    }
    disjointKdops += !ka.overlaps(kb);
  }
  EXPECT_GT(hullHits, 20);
  EXPECT_GT(disjointKdops, 20);  // the test can fail both ways
}

TYPED_TEST(KdopTyped, IntersectingTrianglesNeverGetDisjointKdops) {
  using D = TypeParam;
  std::mt19937_64 rng(13);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  int hits = 0;
  for (int trial = 0; trial < 2000; ++trial) {
    std::array<Vec3, 3> ta, tb;
    for (auto& p : ta) p = Vec3(u(rng), u(rng), u(rng));
    for (auto& p : tb) p = Vec3(u(rng), u(rng), u(rng)) + Vec3(0.8, 0.0, 0.0);
    if (!dm::trianglesIntersect(ta[0], ta[1], ta[2], tb[0], tb[1], tb[2])) continue;
    ++hits;
    EXPECT_TRUE(D::fromPoints(ta).overlaps(D::fromPoints(tb)));
  }
  EXPECT_GT(hits, 100);
}

TEST(Kdop, EmptyMergesToNothingAndOverlapsNothing) {
  const dm::Kdop26 empty;
  EXPECT_TRUE(empty.isEmpty());
  const std::array<Vec3, 2> pts = {Vec3(0, 0, 0), Vec3(1, 2, 3)};
  dm::Kdop26 k = dm::Kdop26::fromPoints(pts);
  EXPECT_FALSE(k.overlaps(empty));
  EXPECT_FALSE(empty.overlaps(k));
  EXPECT_FALSE(empty.contains(Vec3::Zero()));
  EXPECT_TRUE(k.contains(empty));
  const dm::Kdop26 before = k;
  k.merge(empty);
  for (int i = 0; i < dm::Kdop26::kSlabs; ++i) EXPECT_EQ(k.min(i), before.min(i));
  // Touching slabs count as overlapping (closed intervals).
  const std::array<Vec3, 1> corner = {Vec3(1, 2, 3)};
  EXPECT_TRUE(k.overlaps(dm::Kdop26::fromPoints(corner)));
  // A k-DOP is tighter than the AABB: the far corner of a diagonal segment's
  // box is inside the box but outside the 26-DOP.
  EXPECT_TRUE(k.aabb().contains(Vec3(1, 0, 0)));
  EXPECT_FALSE(k.contains(Vec3(1, 0, 0)));
}

}  // namespace
