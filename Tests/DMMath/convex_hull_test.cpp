#include <dm/math/convex_hull.hpp>
#include <dm/math/mass_properties.hpp>
#include <dm/math/mesh_topology.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <random>
#include <set>
#include <vector>

#include "math_test_support.hpp"

namespace {

using dm::Vec3;

using dm::test::kPi;

std::array<double, 3> key(const Vec3& p) { return {p.x(), p.y(), p.z()}; }

/// Largest signed distance (m) of `points` above the planes of the hull's triangles.
double maxDistanceOutside(const dm::Mesh& hull, const std::vector<Vec3>& points) {
  double worst = -std::numeric_limits<double>::infinity();
  for (std::size_t t = 0; t < hull.triangleCount(); ++t) {
    const Vec3 n = hull.faceNormal(t);
    const Vec3& a = hull.positions[hull.triangles[t][0]];
    for (const Vec3& p : points) worst = std::max(worst, n.dot(p - a));
  }
  return worst;
}

/// Checks what convexHull() promises: a closed, oriented, sphere-like
/// manifold without degenerate or duplicate triangles whose vertices are
/// input points, convex, containing every input point within `eps` (m).
void expectValidHull(const dm::Mesh& hull, const std::vector<Vec3>& points, double eps) {
  const dm::MeshTopology t = dm::analyzeTopology(hull);
  EXPECT_TRUE(t.isClosed);
  EXPECT_TRUE(t.isManifold);
  EXPECT_TRUE(t.isOrientedConsistently);
  EXPECT_EQ(t.components, 1u);
  EXPECT_EQ(t.eulerCharacteristic, 2);  // V − E + F
  EXPECT_EQ(t.degenerateTriangles, 0u);
  EXPECT_EQ(t.unreferencedVertices, 0u);
  EXPECT_EQ(2 * hull.vertexCount() - 4, hull.triangleCount());

  std::set<std::array<std::uint32_t, 3>> seen;
  const double extent = hull.bounds().diagonal().norm();
  for (std::size_t i = 0; i < hull.triangleCount(); ++i) {
    auto tri = hull.triangles[i];
    std::rotate(tri.begin(), std::min_element(tri.begin(), tri.end()), tri.end());
    EXPECT_TRUE(seen.insert(tri).second) << "duplicate triangle " << i;
    EXPECT_GT(hull.faceArea(i), 1e-14 * extent * extent) << "degenerate triangle " << i;
  }

  std::set<std::array<double, 3>> input;
  for (const Vec3& p : points) input.insert(key(p));
  std::set<std::array<double, 3>> vertices;
  for (const Vec3& p : hull.positions) {
    EXPECT_TRUE(input.count(key(p))) << "hull vertex " << p.transpose() << " is not an input point";
    EXPECT_TRUE(vertices.insert(key(p)).second) << "vertex " << p.transpose() << " repeated";
  }
  EXPECT_LE(maxDistanceOutside(hull, hull.positions), eps) << "not convex";
  EXPECT_LE(maxDistanceOutside(hull, points), eps) << "an input point is outside";
  auto mp = dm::computeMassProperties(hull);
  EXPECT_TRUE(mp) << mp.error();
}

std::vector<Vec3> uniformInCube(std::size_t n, unsigned seed, double lo = 0.0, double hi = 1.0) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(lo, hi);
  std::vector<Vec3> pts(n);
  for (Vec3& p : pts) p = Vec3(u(rng), u(rng), u(rng));
  return pts;
}

std::vector<Vec3> cubeCorners(double side = 1.0) {
  std::vector<Vec3> c;
  for (int i = 0; i < 8; ++i) c.emplace_back(side * (i & 1), side * ((i >> 1) & 1), side * ((i >> 2) & 1));
  return c;
}

/// n points spread evenly over the sphere (Fibonacci lattice).
std::vector<Vec3> fibonacciSphere(std::size_t n, double r, const Vec3& centre) {
  std::vector<Vec3> pts;
  const double golden = kPi * (3 - std::sqrt(5.0));
  for (std::size_t i = 0; i < n; ++i) {
    const double z = 1 - (2 * static_cast<double>(i) + 1) / static_cast<double>(n);
    const double rho = std::sqrt(1 - z * z), phi = golden * static_cast<double>(i);
    pts.push_back(centre + r * Vec3(rho * std::cos(phi), rho * std::sin(phi), z));
  }
  return pts;
}

/// A (k+1)² grid on each face of the unit cube plus an interior grid.
std::vector<Vec3> cubeGrid(int k) {
  std::vector<Vec3> pts;
  for (int i = 0; i <= k; ++i)
    for (int j = 0; j <= k; ++j) {
      const double a = static_cast<double>(i) / k, b = static_cast<double>(j) / k;
      for (const double c : {0.0, 1.0}) {
        pts.emplace_back(c, a, b);
        pts.emplace_back(a, c, b);
        pts.emplace_back(a, b, c);
      }
    }
  for (int i = 1; i < k; i += 2)
    for (int j = 1; j < k; j += 2)
      for (int l = 1; l < k; l += 2) pts.emplace_back(double(i) / k, double(j) / k, double(l) / k);
  return pts;
}

double hullVolume(const dm::Mesh& hull) {
  auto mp = dm::computeMassProperties(hull);
  return mp ? mp->volume : -1.0;
}

TEST(ConvexHull, RandomPointsWithCubeCornersGiveTheCube) {
  std::vector<Vec3> pts = uniformInCube(3000, 1);
  for (const Vec3& c : cubeCorners()) pts.push_back(c);
  std::shuffle(pts.begin(), pts.end(), std::mt19937(7));
  auto hull = dm::convexHull(pts);
  ASSERT_TRUE(hull) << hull.error();
  expectValidHull(*hull, pts, 1e-12);
  EXPECT_EQ(hull->vertexCount(), 8u);
  EXPECT_EQ(hull->triangleCount(), 12u);
  EXPECT_NEAR(hullVolume(*hull), 1.0, 1e-14);
}

TEST(ConvexHull, RandomPointsInACube) {
  for (const unsigned seed : {2u, 3u, 4u}) {
    const std::vector<Vec3> pts = uniformInCube(4000, seed, -0.5, 0.5);
    auto hull = dm::convexHull(pts);
    ASSERT_TRUE(hull) << hull.error();
    expectValidHull(*hull, pts, 1e-12);
    // E[1 − V] for n uniform points is O(log² n / n): a few percent here.
    const double v = hullVolume(*hull);
    EXPECT_LT(v, 1.0);
    EXPECT_GT(v, 0.95);
  }
}

TEST(ConvexHull, FarFromOriginGivesTheSameHull) {
  std::vector<Vec3> pts = uniformInCube(2000, 5);
  for (const Vec3& c : cubeCorners()) pts.push_back(c);
  const Vec3 shift(1000.0, -2000.0, 1500.0);
  for (Vec3& p : pts) p = 0.05 * p + shift;  // a 5 cm cube, 2.7 km away
  auto hull = dm::convexHull(pts);
  ASSERT_TRUE(hull) << hull.error();
  expectValidHull(*hull, pts, 1e-12);
  EXPECT_EQ(hull->vertexCount(), 8u);
  EXPECT_NEAR(hullVolume(*hull), 1.25e-4, 1e-9 * 1.25e-4);
}

TEST(ConvexHull, PointsOnASphereAreAllVertices) {
  const double r = 0.1;
  const std::vector<Vec3> pts = fibonacciSphere(2000, r, Vec3(0.3, -0.2, 1.0));
  auto hull = dm::convexHull(pts);
  ASSERT_TRUE(hull) << hull.error();
  expectValidHull(*hull, pts, 1e-12);
  EXPECT_EQ(hull->vertexCount(), pts.size());
  EXPECT_EQ(hull->triangleCount(), 2 * pts.size() - 4);
  const double ball = 4.0 / 3 * kPi * r * r * r;
  EXPECT_LT(hullVolume(*hull), ball);
  EXPECT_GT(hullVolume(*hull), 0.995 * ball);
}

TEST(ConvexHull, CubeFaceGridMergesCoplanarFacets) {
  const std::vector<Vec3> pts = cubeGrid(10);
  auto hull = dm::convexHull(pts);
  ASSERT_TRUE(hull) << hull.error();
  expectValidHull(*hull, pts, 1e-12);
  EXPECT_EQ(hull->vertexCount(), 8u);
  EXPECT_EQ(hull->triangleCount(), 12u);
  EXPECT_NEAR(hullVolume(*hull), 1.0, 1e-14);
}

TEST(ConvexHull, RotatedCubeFaceGridFarAway) {
  std::vector<Vec3> pts = cubeGrid(8);
  const dm::Mat3 rot = dm::Quat(dm::AngleAxis(1.1, Vec3(0.3, -1, 0.6).normalized())).toRotationMatrix();
  const Vec3 shift(1000.0, 2000.0, -500.0);
  for (Vec3& p : pts) p = rot * p + shift;  // coplanar only up to rounding (~1e-13 m)
  auto hull = dm::convexHull(pts);
  ASSERT_TRUE(hull) << hull.error();
  expectValidHull(*hull, pts, 1e-11);
  EXPECT_EQ(hull->vertexCount(), 8u);
  EXPECT_EQ(hull->triangleCount(), 12u);
  EXPECT_NEAR(hullVolume(*hull), 1.0, 1e-11);
}

TEST(ConvexHull, DuplicatePointsAppearOnce) {
  std::vector<Vec3> pts;
  for (int rep = 0; rep < 5; ++rep)
    for (const Vec3& c : cubeCorners(2.0)) pts.push_back(c);
  for (const Vec3& p : uniformInCube(200, 9, 0.0, 2.0)) {
    pts.push_back(p);
    pts.push_back(p);
  }
  std::shuffle(pts.begin(), pts.end(), std::mt19937(3));
  auto hull = dm::convexHull(pts);
  ASSERT_TRUE(hull) << hull.error();
  expectValidHull(*hull, pts, 1e-12);
  EXPECT_EQ(hull->vertexCount(), 8u);
  EXPECT_NEAR(hullVolume(*hull), 8.0, 1e-13);
}

TEST(ConvexHull, TetrahedronKeepsInputOrder) {
  const std::vector<Vec3> pts = {Vec3(0, 0, 0), Vec3(0, 0, 1), Vec3(1, 0, 0), Vec3(0, 1, 0),
                                 Vec3(0.1, 0.1, 0.1)};
  auto hull = dm::convexHull(pts);
  ASSERT_TRUE(hull) << hull.error();
  expectValidHull(*hull, pts, 1e-15);
  ASSERT_EQ(hull->vertexCount(), 4u);
  for (std::size_t i = 0; i < 4; ++i) EXPECT_EQ(hull->positions[i], pts[i]);
  EXPECT_NEAR(hullVolume(*hull), 1.0 / 6, 1e-16);
}

// Regular n-gon prism: caps of n coplanar vertices (plus points inside the
// caps and on the side edges) triangulated without new vertices.
TEST(ConvexHull, PrismCapsAreLargeCoplanarPolygons) {
  const int n = 180;
  const double r = 0.02, h = 0.15;
  std::vector<Vec3> pts;
  for (int i = 0; i < n; ++i) {
    const double a = 2 * kPi * i / n;
    for (const double z : {0.0, h / 2, h}) pts.emplace_back(r * std::cos(a), r * std::sin(a), z);
  }
  for (const double z : {0.0, h}) pts.emplace_back(0, 0, z);
  auto hull = dm::convexHull(pts);
  ASSERT_TRUE(hull) << hull.error();
  expectValidHull(*hull, pts, 1e-15);
  EXPECT_EQ(hull->vertexCount(), static_cast<std::size_t>(2 * n));
  const double v = n / 2.0 * r * r * std::sin(2 * kPi / n) * h;
  EXPECT_NEAR(hullVolume(*hull), v, 1e-12 * v);
}

// Small subsets of an integer lattice: coplanar faces, collinear edges and
// coincident points everywhere. A lattice polytope's volume is a multiple of
// 1/6, and the same set rotated (coplanar only up to rounding) must give the
// same vertices and volume.
TEST(ConvexHull, LatticeSubsetsStress) {
  std::mt19937 rng(11);
  std::uniform_int_distribution<int> coord(0, 3);
  int built = 0;
  for (int trial = 0; trial < 300; ++trial) {
    SCOPED_TRACE("trial " + std::to_string(trial));
    std::vector<Vec3> pts(static_cast<std::size_t>(6 + trial % 40));
    for (Vec3& p : pts) p = Vec3(coord(rng), coord(rng), coord(rng));
    const dm::Mat3 rot = dm::Quat::UnitRandom().toRotationMatrix();
    std::vector<Vec3> turned = pts;
    for (Vec3& p : turned) p = rot * p + Vec3(5, -3, 2);
    auto hull = dm::convexHull(pts);
    auto hullTurned = dm::convexHull(turned);
    if (!hull) {
      // Only a genuinely flat subset may fail, in both positions.
      EXPECT_NE(hull.error().what.find("degenerate"), std::string::npos) << hull.error();
      EXPECT_FALSE(hullTurned);
      continue;
    }
    ASSERT_TRUE(hullTurned) << hullTurned.error();
    ++built;
    expectValidHull(*hull, pts, 1e-15);
    expectValidHull(*hullTurned, turned, 1e-12);
    const double v = hullVolume(*hull);
    EXPECT_NEAR(6 * v, std::round(6 * v), 1e-12);
    EXPECT_NEAR(hullVolume(*hullTurned), v, 1e-12);
    EXPECT_EQ(hullTurned->vertexCount(), hull->vertexCount());
  }
  EXPECT_GT(built, 250);
}

TEST(ConvexHull, DegenerateInputIsAnError) {
  const auto message = [](const std::vector<Vec3>& pts) {
    auto h = dm::convexHull(pts);
    EXPECT_FALSE(h);
    return h ? std::string() : h.error().message();
  };
  EXPECT_NE(message({}).find("no points"), std::string::npos);
  EXPECT_NE(message({Vec3(1, 2, 3)}).find("0-dimensional"), std::string::npos);
  EXPECT_NE(message({Vec3(1, 2, 3), Vec3(1, 2, 3), Vec3(1, 2, 3)}).find("0-dimensional"), std::string::npos);
  EXPECT_NE(message({Vec3(0, 0, 0), Vec3(1, 1, 1)}).find("1-dimensional"), std::string::npos);
  std::vector<Vec3> line;
  for (int i = 0; i < 10; ++i) line.push_back(Vec3(1, 2, 3) + 0.1 * i * Vec3(1, -2, 0.5));
  EXPECT_NE(message(line).find("collinear within"), std::string::npos) << message(line);
  EXPECT_NE(message({Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0)}).find("2-dimensional"), std::string::npos);
  std::vector<Vec3> plane;
  for (int i = 0; i < 7; ++i)
    for (int j = 0; j < 7; ++j) plane.push_back(Vec3(0.1 * i, 0.2 * j, 0.3 * i - 0.05 * j + 4));
  EXPECT_NE(message(plane).find("coplanar within"), std::string::npos) << message(plane);
  std::vector<Vec3> nan = cubeCorners();
  nan[3].y() = std::nan("");
  EXPECT_NE(message(nan).find("point 3"), std::string::npos) << message(nan);
  nan[3].y() = std::numeric_limits<double>::infinity();
  EXPECT_NE(message(nan).find("point 3"), std::string::npos);
}

TEST(ConvexHull, ToleranceOption) {
  const std::vector<Vec3> pts = fibonacciSphere(1000, 1.0, Vec3::Zero());
  for (const double bad : {-1e-9, 0.5, std::nan("")}) {
    dm::ConvexHullOptions o;
    o.relativeTolerance = bad;
    EXPECT_FALSE(dm::convexHull(pts, o));
  }
  // A coarse tolerance drops points within it of the hull: fewer vertices,
  // an exactly convex result, and every point within a few tolerances
  // (s = 3 m here, tolerance 3 mm).
  dm::ConvexHullOptions coarse;
  coarse.relativeTolerance = 1e-3;
  auto hull = dm::convexHull(pts, coarse);
  ASSERT_TRUE(hull) << hull.error();
  expectValidHull(*hull, pts, 5 * 3e-3);
  EXPECT_LE(maxDistanceOutside(*hull, hull->positions), 1e-15);
  EXPECT_LT(hull->vertexCount(), pts.size());
  EXPECT_GT(hull->vertexCount(), 50u);
}

TEST(ConvexHull, HundredThousandPointsInACube) {
  const std::vector<Vec3> cube = uniformInCube(100000, 21);
  auto t0 = std::chrono::steady_clock::now();
  auto hull = dm::convexHull(cube);
  const double msCube =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  ASSERT_TRUE(hull) << hull.error();
  expectValidHull(*hull, cube, 1e-12);

  const std::vector<Vec3> sphere =
      fibonacciSphere(20000, 1.0, Vec3::Zero());  // all on the hull: the costliest case
  t0 = std::chrono::steady_clock::now();
  auto all = dm::convexHull(sphere);
  const double msSphere =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  ASSERT_TRUE(all) << all.error();
  const dm::MeshTopology t = dm::analyzeTopology(*all);
  EXPECT_TRUE(t.isClosed && t.isManifold && t.isOrientedConsistently);
  EXPECT_EQ(t.eulerCharacteristic, 2);
  EXPECT_EQ(all->vertexCount(), sphere.size());
  std::printf("100k points in a cube: %zu hull vertices in %.1f ms; 20k on a sphere: %zu in %.1f ms\n",
              hull->vertexCount(), msCube, all->vertexCount(), msSphere);
}

}  // namespace
