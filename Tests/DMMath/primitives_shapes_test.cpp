// Cylinder, capsule and plane primitives against their analytic geometry.
#include <dm/math/mass_properties.hpp>
#include <dm/math/mesh_topology.hpp>
#include <dm/math/primitives.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

#include "math_test_support.hpp"

namespace dm {
namespace {

using dm::test::kPi;

/// The cylinder duplicates its rim vertices; welding exact duplicates must
/// give a closed, oriented genus-0 manifold.
MeshTopology weldedTopology(Mesh m) {
  auto w = weldVertices(m, 0.0);
  EXPECT_TRUE(w) << w.error();
  return analyzeTopology(m);
}

TEST(PrimitiveShapes, CylinderMatchesTheInscribedPrism) {
  const double r = 0.02, h = 0.15;
  for (int n : {3, 8, 32, 128}) {
    const Mesh c = makeCylinder(r, h, n);
    ASSERT_TRUE(c.validate());
    EXPECT_EQ(c.vertexCount(), 4u * n + 2u);
    EXPECT_EQ(c.triangleCount(), 4u * n);
    const MeshTopology t = weldedTopology(c);
    EXPECT_TRUE(t.isClosed) << n;
    EXPECT_TRUE(t.isManifold) << n;
    EXPECT_TRUE(t.isOrientedConsistently) << n;
    EXPECT_EQ(t.components, 1u);
    ASSERT_TRUE(t.genus && t.volume) << n;
    EXPECT_EQ(*t.genus, 0);
    // Inscribed regular n-gon: area n/2 r² sin(2π/n), side length 2 r sin(π/n).
    const double polygon = 0.5 * n * r * r * std::sin(2 * kPi / n);
    const double prismVolume = polygon * h;
    const double prismArea = 2 * polygon + n * 2 * r * std::sin(kPi / n) * h;
    EXPECT_GT(*t.volume, 0);
    EXPECT_NEAR(*t.volume, prismVolume, 1e-12 * prismVolume) << n;
    EXPECT_NEAR(c.surfaceArea(), prismArea, 1e-12 * prismArea) << n;
    ASSERT_TRUE(t.centroid);
    EXPECT_LT(t.centroid->norm(), 1e-12);
  }
  // Convergence to the exact cylinder: the prism's relative volume deficit is
  // 1 − sin(2π/n)/(2π/n) ≈ (2π/n)²/6.
  const double exactVolume = kPi * r * r * h, exactArea = 2 * kPi * r * r + 2 * kPi * r * h;
  double lastError = 1;
  for (int n : {8, 16, 32, 64, 128}) {
    const MeshTopology t = weldedTopology(makeCylinder(r, h, n));
    const double err = (exactVolume - *t.volume) / exactVolume;
    EXPECT_GT(err, 0);
    EXPECT_LT(err, std::pow(2 * kPi / n, 2) / 6 * 1.001);
    EXPECT_LT(err, 0.27 * lastError + 1e-15);  // second order: ×¼ per doubling
    lastError = err;
    EXPECT_NEAR(t.surfaceArea, exactArea, std::pow(2 * kPi / n, 2) / 6 * exactArea) << n;
  }
}

TEST(PrimitiveShapes, CylinderNormalsAreSharpAtTheRims) {
  const double r = 0.5, h = 2.0;
  const Mesh c = makeCylinder(r, h, 12);
  ASSERT_EQ(c.normals.size(), c.vertexCount());
  for (std::size_t v = 0; v < c.vertexCount(); ++v) {
    const Vec3& p = c.positions[v];
    const Vec3& n = c.normals[v];
    EXPECT_NEAR(n.norm(), 1.0, 1e-15);
    EXPECT_NEAR(std::abs(p.z()), 0.5 * h, 1e-15);
    const double rho = std::hypot(p.x(), p.y());
    EXPECT_TRUE(std::abs(rho) < 1e-15 || std::abs(rho - r) < 1e-14) << v;
    if (std::abs(n.z()) > 0.5) {  // cap vertex: normal ±z on the side of its cap
      EXPECT_EQ(n, Vec3(0, 0, p.z() > 0 ? 1 : -1)) << v;
    } else {  // side vertex: radial
      ASSERT_NEAR(rho, r, 1e-14);
      EXPECT_NEAR((n - Vec3(p.x(), p.y(), 0) / r).norm(), 0, 1e-14) << v;
    }
  }
  // Face normals agree with the vertex normals of their corners (flat caps,
  // outward side faces), which also checks the winding.
  for (std::size_t f = 0; f < c.triangleCount(); ++f) {
    const Vec3 fn = c.faceNormal(f);
    for (std::uint32_t v : c.triangles[f]) EXPECT_GT(fn.dot(c.normals[v]), 0.9) << f;
  }
  // Each rim point appears once on its cap and once on the side.
  int topRim = 0;
  for (std::size_t v = 0; v < c.vertexCount(); ++v)
    if ((c.positions[v] - Vec3(r, 0, 0.5 * h)).norm() < 1e-15) ++topRim;
  EXPECT_EQ(topRim, 2);
}

TEST(PrimitiveShapes, CylinderCountsAreClamped) {
  // Counts from a scene file must not overflow 32-bit indices or allocate without bound.
  const Mesh huge = makeCylinder(1.0, 1.0, std::numeric_limits<int>::max());
  EXPECT_EQ(huge.triangleCount(), 4u * 65536u);
  EXPECT_TRUE(huge.validate());
  const Mesh tiny = makeCylinder(1.0, 1.0, -3);
  EXPECT_EQ(tiny.triangleCount(), 12u);
  EXPECT_TRUE(weldedTopology(tiny).isClosed);
}

TEST(PrimitiveShapes, CapsuleConvergesToTheSphereSweptVolume) {
  const double r = 0.01, h = 0.04;
  const double exact = kPi * r * r * h + 4.0 / 3.0 * kPi * r * r * r;
  const double exactArea = 2 * kPi * r * h + 4 * kPi * r * r;
  double lastError = 1;
  for (int k : {1, 2, 4, 8}) {
    const int segments = 16 * k, rings = 4 * k;
    const Mesh c = makeCapsule(r, h, segments, rings);
    ASSERT_TRUE(c.validate());
    EXPECT_EQ(c.vertexCount(), 2u * rings * segments + 2u);
    EXPECT_EQ(c.triangleCount(), 4u * rings * segments);
    const MeshTopology t = analyzeTopology(c);
    EXPECT_TRUE(t.isClosed);
    EXPECT_TRUE(t.isManifold);
    EXPECT_TRUE(t.isOrientedConsistently);
    EXPECT_EQ(t.components, 1u);
    ASSERT_TRUE(t.genus && t.volume);
    EXPECT_EQ(*t.genus, 0);
    // All vertices on a convex surface: the inscribed polytope is smaller.
    const double err = (exact - *t.volume) / exact;
    EXPECT_GT(err, 0) << segments;
    EXPECT_LT(err, 0.27 * lastError + 1e-15) << segments;  // second order in the step
    lastError = err;
    EXPECT_LT(t.surfaceArea, exactArea);
    EXPECT_NEAR(t.surfaceArea, exactArea, 2 * err * exactArea + 1e-18);
    ASSERT_TRUE(t.centroid);
    EXPECT_LT(t.centroid->norm(), 1e-12);
    auto mp = computeMassProperties(c);
    ASSERT_TRUE(mp) << mp.error();
    EXPECT_NEAR(mp->volume, *t.volume, 1e-12 * exact);
  }
  EXPECT_LT(lastError, 0.001);  // 128 segments, 32 rings per hemisphere
}

TEST(PrimitiveShapes, CapsuleGeometryAndNormalsAreExact) {
  const double r = 0.3, h = 1.1;
  const Mesh c = makeCapsule(r, h, 10, 3);
  ASSERT_EQ(c.normals.size(), c.vertexCount());
  const Aabb box = c.bounds();
  EXPECT_NEAR(box.max().z(), 0.5 * h + r, 1e-15);
  EXPECT_NEAR(box.min().z(), -0.5 * h - r, 1e-15);
  for (std::size_t v = 0; v < c.vertexCount(); ++v) {
    const Vec3& p = c.positions[v];
    // Nearest point of the axis segment, and the exact outward normal from it.
    const Vec3 axis(0, 0, std::clamp(p.z(), -0.5 * h, 0.5 * h));
    EXPECT_NEAR((p - axis).norm(), r, 1e-14) << v;
    EXPECT_NEAR((c.normals[v] - (p - axis) / r).norm(), 0, 1e-13) << v;
  }
  for (std::size_t f = 0; f < c.triangleCount(); ++f) {
    const Vec3 fn = c.faceNormal(f);
    for (std::uint32_t v : c.triangles[f]) EXPECT_GT(fn.dot(c.normals[v]), 0.5) << f;
  }
}

TEST(PrimitiveShapes, CapsuleOfZeroHeightIsASphere) {
  const double r = 0.2;
  const Mesh s = makeCapsule(r, 0.0, 24, 6);
  EXPECT_EQ(s.vertexCount(), 24u * 11u + 2u);
  EXPECT_EQ(s.triangleCount(), 4u * 6u * 24u - 2u * 24u);
  const MeshTopology t = analyzeTopology(s);
  EXPECT_TRUE(t.isClosed && t.isManifold && t.isOrientedConsistently);
  ASSERT_TRUE(t.volume);
  const double ball = 4.0 / 3.0 * kPi * r * r * r;
  EXPECT_LT(*t.volume, ball);
  EXPECT_NEAR(*t.volume, ball, 0.03 * ball);
  for (const Vec3& p : s.positions) EXPECT_NEAR(p.norm(), r, 1e-15);
  // Negative heights are taken as zero; minimum counts are raised.
  EXPECT_EQ(makeCapsule(r, -1.0, 24, 6).positions, s.positions);
  const Mesh tiny = makeCapsule(r, 0.1, 0, 0);
  EXPECT_EQ(tiny.triangleCount(), 4u * 1u * 3u);
  EXPECT_TRUE(analyzeTopology(tiny).isClosed);
}

TEST(PrimitiveShapes, PlaneIsAFlatRectangleFacingUp) {
  const double hx = 0.4, hy = 0.25;
  for (int d : {1, 3, 10}) {
    const Mesh p = makePlane(hx, hy, d);
    ASSERT_TRUE(p.validate());
    EXPECT_EQ(p.vertexCount(), static_cast<std::size_t>((d + 1) * (d + 1)));
    EXPECT_EQ(p.triangleCount(), static_cast<std::size_t>(2 * d * d));
    EXPECT_NEAR(p.surfaceArea(), 4 * hx * hy, 1e-15);
    const Aabb box = p.bounds();
    EXPECT_EQ(box.min(), Vec3(-hx, -hy, 0));
    EXPECT_EQ(box.max(), Vec3(hx, hy, 0));
    ASSERT_EQ(p.normals.size(), p.vertexCount());
    for (const Vec3& n : p.normals) EXPECT_EQ(n, Vec3::UnitZ());
    for (std::size_t f = 0; f < p.triangleCount(); ++f) {
      EXPECT_EQ(p.faceNormal(f), Vec3::UnitZ()) << f;  // CCW seen from +z
      EXPECT_NEAR(p.faceArea(f), 4 * hx * hy / (2 * d * d), 1e-15);
    }
    const MeshTopology t = analyzeTopology(p);
    EXPECT_FALSE(t.isClosed);
    EXPECT_TRUE(t.isManifold && t.isOrientedConsistently);
    EXPECT_EQ(t.boundaryEdges, static_cast<std::size_t>(4 * d));
    EXPECT_EQ(t.eulerCharacteristic, 1);  // a disc
    // uv is an affine function of position: u = (x + hx) / 2hx, v = (hy − y) / 2hy.
    ASSERT_EQ(p.uvs.size(), p.vertexCount());
    int corners = 0;
    for (std::size_t v = 0; v < p.vertexCount(); ++v) {
      const Vec3& x = p.positions[v];
      const Vec2f uv = p.uvs[v];
      EXPECT_NEAR(uv.x(), (x.x() + hx) / (2 * hx), 1e-7);
      EXPECT_NEAR(uv.y(), (hy - x.y()) / (2 * hy), 1e-7);
      const Vec3 corner((uv.x() == 0 ? -1 : 1) * hx, (uv.y() == 0 ? 1 : -1) * hy, 0);
      if ((uv.x() == 0 || uv.x() == 1) && (uv.y() == 0 || uv.y() == 1)) {  // v = 0 is the +y (image top) edge
        EXPECT_EQ(x, corner) << uv.transpose();
        ++corners;
      }
    }
    EXPECT_EQ(corners, 4);
  }
  EXPECT_EQ(makePlane(1, 1, 0).triangleCount(), 2u);
  EXPECT_EQ(makePlane(1, 1, -5).triangleCount(), 2u);
}

}  // namespace
}  // namespace dm
