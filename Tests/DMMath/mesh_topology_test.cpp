#include <dm/math/geometry.hpp>
#include <dm/math/mesh_topology.hpp>
#include <dm/math/primitives.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>
#include <vector>

#include "math_test_support.hpp"

namespace {

using dm::Vec3;

/// Axis-aligned box [lo, lo + size], 8 vertices, 12 triangles CCW from outside.
dm::Mesh box(const Vec3& lo, double size) {
  dm::Mesh m;
  for (int c = 0; c < 8; ++c) m.positions.push_back(lo + size * Vec3(c & 1, (c >> 1) & 1, (c >> 2) & 1));
  // Faces as quads (CCW seen from outside), split into two triangles.
  const int quads[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4},
                           {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  for (const auto& q : quads) {
    const auto u = [&](int i) { return static_cast<std::uint32_t>(q[i]); };
    m.triangles.push_back({u(0), u(1), u(2)});
    m.triangles.push_back({u(0), u(2), u(3)});
  }
  return m;
}

using dm::test::merged;

TEST(MeshTopology, BoxIsAClosedOrientedSphere) {
  const auto t = dm::analyzeTopology(box(Vec3(1, 2, 3), 2.0));
  EXPECT_EQ(t.vertices, 8u);
  EXPECT_EQ(t.edges, 18u);
  EXPECT_EQ(t.triangles, 12u);
  EXPECT_EQ(t.boundaryEdges, 0u);
  EXPECT_EQ(t.components, 1u);
  EXPECT_EQ(t.eulerCharacteristic, 2);
  EXPECT_TRUE(t.isClosed);
  EXPECT_TRUE(t.isManifold);
  EXPECT_TRUE(t.isOrientedConsistently);
  ASSERT_TRUE(t.genus);
  EXPECT_EQ(*t.genus, 0);
  ASSERT_TRUE(t.volume);
  EXPECT_NEAR(*t.volume, 8.0, 1e-12);
  ASSERT_TRUE(t.centroid);
  EXPECT_LT((*t.centroid - Vec3(2, 3, 4)).norm(), 1e-12);
  EXPECT_NEAR(t.surfaceArea, 24.0, 1e-12);
}

TEST(MeshTopology, InsideOutBoxHasNegativeVolume) {
  dm::Mesh m = box(Vec3::Zero(), 1.0);
  for (auto& t : m.triangles) std::swap(t[1], t[2]);
  const auto t = dm::analyzeTopology(m);
  EXPECT_TRUE(t.isOrientedConsistently);
  ASSERT_TRUE(t.volume);
  EXPECT_NEAR(*t.volume, -1.0, 1e-12);
  EXPECT_LT((*t.centroid - Vec3::Constant(0.5)).norm(), 1e-12);
}

TEST(MeshTopology, OneFlippedTriangleBreaksOrientation) {
  dm::Mesh m = box(Vec3::Zero(), 1.0);
  std::swap(m.triangles[5][1], m.triangles[5][2]);
  const auto t = dm::analyzeTopology(m);
  EXPECT_TRUE(t.isClosed);
  EXPECT_TRUE(t.isManifold);
  EXPECT_FALSE(t.isOrientedConsistently);
  EXPECT_EQ(t.misorientedEdges, 3u);  // all three of its edges
  EXPECT_FALSE(t.volume);
  EXPECT_FALSE(t.genus);
}

TEST(MeshTopology, MissingTriangleLeavesABoundary) {
  dm::Mesh m = box(Vec3::Zero(), 1.0);
  m.triangles.pop_back();
  const auto t = dm::analyzeTopology(m);
  EXPECT_FALSE(t.isClosed);
  EXPECT_EQ(t.boundaryEdges, 3u);
  EXPECT_TRUE(t.isManifold);
  EXPECT_TRUE(t.isOrientedConsistently);
  EXPECT_EQ(t.eulerCharacteristic, 1);  // a disc
  EXPECT_FALSE(t.volume);
}

TEST(MeshTopology, TwoBoxesAreTwoComponents) {
  const auto t = dm::analyzeTopology(merged(box(Vec3::Zero(), 1.0), box(Vec3(3, 0, 0), 2.0)));
  EXPECT_EQ(t.components, 2u);
  EXPECT_EQ(t.eulerCharacteristic, 4);
  ASSERT_TRUE(t.genus);
  EXPECT_EQ(*t.genus, 0);
  EXPECT_NEAR(*t.volume, 9.0, 1e-12);
  // Centroid weighted by volume: (1·0.5 + 8·4) / 9 along x.
  EXPECT_NEAR(t.centroid->x(), (0.5 + 8 * 4.0) / 9, 1e-12);
}

TEST(MeshTopology, TorusHasGenusOne) {
  const double R = 0.05, r = 0.02;
  const auto t = dm::analyzeTopology(dm::makeTorus(R, r, 64, 32));
  EXPECT_TRUE(t.isClosed && t.isManifold && t.isOrientedConsistently);
  EXPECT_EQ(t.eulerCharacteristic, 0);
  ASSERT_TRUE(t.genus);
  EXPECT_EQ(*t.genus, 1);
  const double exact = 2 * std::numbers::pi * std::numbers::pi * R * r * r;
  EXPECT_NEAR(*t.volume, exact, 0.01 * exact);
  EXPECT_LT(t.centroid->norm(), 1e-12);
}

TEST(MeshTopology, ThreeTrianglesOnOneEdgeAreNonManifold) {
  dm::Mesh m;
  m.positions = {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(0, -1, 0), Vec3(0, 0, 1)};
  m.triangles = {{0, 1, 2}, {1, 0, 3}, {0, 1, 4}};
  const auto t = dm::analyzeTopology(m);
  EXPECT_EQ(t.nonManifoldEdges, 1u);
  EXPECT_EQ(t.boundaryEdges, 6u);
  EXPECT_FALSE(t.isManifold);
  EXPECT_FALSE(t.isOrientedConsistently);
}

TEST(MeshTopology, BoxesTouchingAtACornerMakeANonManifoldVertex) {
  // The second box's corner 0 is the first box's corner 7: one shared vertex.
  dm::Mesh a = box(Vec3::Zero(), 1.0), b = box(Vec3(1, 1, 1), 1.0);
  dm::Mesh m = merged(a, b);
  for (auto& t : m.triangles)
    for (auto& i : t)
      if (i == 8) i = 7;  // weld b's corner 0 onto a's corner 7
  const auto t = dm::analyzeTopology(m);
  EXPECT_EQ(t.nonManifoldVertices, 1u);
  EXPECT_EQ(t.nonManifoldEdges, 0u);
  EXPECT_EQ(t.unreferencedVertices, 1u);
  EXPECT_EQ(t.components, 1u);
  EXPECT_EQ(t.eulerCharacteristic, 15 - 36 + 24);
  EXPECT_TRUE(t.isClosed);
  EXPECT_FALSE(t.isManifold);
  EXPECT_FALSE(t.volume);
}

TEST(MeshTopology, DegenerateAndEmpty) {
  dm::Mesh m = box(Vec3::Zero(), 1.0);
  m.triangles.push_back({0, 0, 1});
  m.triangles.push_back({0, 1, 99});
  const auto t = dm::analyzeTopology(m);
  EXPECT_EQ(t.degenerateTriangles, 2u);
  EXPECT_EQ(t.triangles, 14u);
  EXPECT_TRUE(t.isClosed);  // the rest is still the box
  EXPECT_NEAR(*t.volume, 1.0, 1e-12);

  const auto e = dm::analyzeTopology(dm::Mesh{});
  EXPECT_FALSE(e.isClosed);
  EXPECT_EQ(e.components, 0u);
  EXPECT_EQ(e.eulerCharacteristic, 0);
}

/// Every triangle of `m` with its own three vertices (an STL-style soup).
dm::Mesh soup(const dm::Mesh& m) {
  dm::Mesh s;
  for (const auto& t : m.triangles) {
    const auto base = static_cast<std::uint32_t>(s.positions.size());
    for (auto i : t) s.positions.push_back(m.positions[i]);
    s.triangles.push_back({base, base + 1, base + 2});
  }
  return s;
}

TEST(WeldVertices, SoupBecomesAClosedBox) {
  dm::Mesh m = soup(box(Vec3(1, 2, 3), 2.0));
  ASSERT_EQ(m.vertexCount(), 36u);
  EXPECT_FALSE(dm::analyzeTopology(m).isClosed);
  auto r = dm::weldVertices(m, 1e-9);
  ASSERT_TRUE(r);
  EXPECT_EQ(r->verticesRemoved, 28u);
  EXPECT_EQ(r->trianglesRemoved, 0u);
  EXPECT_EQ(m.vertexCount(), 8u);
  const auto t = dm::analyzeTopology(m);
  EXPECT_TRUE(t.isClosed && t.isManifold && t.isOrientedConsistently);
  EXPECT_NEAR(*t.volume, 8.0, 1e-12);
}

TEST(WeldVertices, JitterWithinToleranceIsMergedDeterministically) {
  const dm::Mesh clean = soup(box(Vec3::Zero(), 0.1));
  dm::Mesh a = clean;
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-0.3e-6, 0.3e-6);  // |jitter| < 0.52e-6 < tolerance / 2
  for (auto& p : a.positions) p += Vec3(u(rng), u(rng), u(rng));
  dm::Mesh b = a;
  ASSERT_TRUE(dm::weldVertices(a, 1e-6));
  ASSERT_TRUE(dm::weldVertices(b, 1e-6));
  EXPECT_EQ(a.vertexCount(), 8u);
  EXPECT_TRUE(a.positions == b.positions);
  EXPECT_TRUE(a.triangles == b.triangles);
  EXPECT_TRUE(dm::analyzeTopology(a).isClosed);
}

TEST(WeldVertices, GreedyFirstRepresentative) {
  // 0.6 merges into 0; 1.2 is 1.2 from the kept 0 and stays, though it is 0.6
  // from the merged 0.6 (no transitive chaining). 1.5 goes to 1.2.
  dm::Mesh m;
  m.positions = {Vec3(0, 0, 0), Vec3(0.6, 0, 0), Vec3(1.2, 0, 0), Vec3(1.5, 0, 0), Vec3(0, 5, 0)};
  m.triangles = {{0, 2, 4}, {1, 3, 4}};
  auto r = dm::weldVertices(m, 1.0);
  ASSERT_TRUE(r);
  EXPECT_EQ(r->verticesRemoved, 2u);
  ASSERT_EQ(m.vertexCount(), 3u);
  EXPECT_EQ(m.positions[1], Vec3(1.2, 0, 0));
  ASSERT_EQ(m.triangles.size(), 2u);
  EXPECT_EQ(m.triangles[0], (dm::Triangle{0, 1, 2}));
  EXPECT_EQ(m.triangles[1], (dm::Triangle{0, 1, 2}));
}

TEST(WeldVertices, ZeroToleranceMergesExactDuplicatesAndSignedZeros) {
  dm::Mesh m;
  m.positions = {Vec3(0, 1, 0), Vec3(-0.0, 1, 0), Vec3(1e-300, 1, 0), Vec3(1, 0, 0)};
  m.triangles = {{0, 2, 3}, {1, 3, 2}};
  auto r = dm::weldVertices(m, 0.0);
  ASSERT_TRUE(r);
  EXPECT_EQ(r->verticesRemoved, 1u);
  EXPECT_EQ(m.vertexCount(), 3u);
}

TEST(WeldVertices, CollapsedTrianglesAreRemovedAndNormalsAveraged) {
  dm::Mesh m;
  m.positions = {Vec3(0, 0, 0), Vec3(1e-7, 0, 0), Vec3(0, 1, 0), Vec3(1, 0, 0)};
  m.normals = {Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(0, 0, 1), Vec3(0, 0, 1)};
  m.uvs = {dm::Vec2f(0, 0), dm::Vec2f(1, 1), dm::Vec2f(2, 2), dm::Vec2f(3, 3)};
  m.triangles = {{0, 1, 2}, {1, 3, 2}};
  auto r = dm::weldVertices(m, 1e-6);
  ASSERT_TRUE(r);
  EXPECT_EQ(r->trianglesRemoved, 1u);
  ASSERT_EQ(m.triangles.size(), 1u);
  EXPECT_EQ(m.triangles[0], (dm::Triangle{0, 2, 1}));
  ASSERT_EQ(m.normals.size(), 3u);
  EXPECT_LT((m.normals[0] - Vec3(1, 1, 0).normalized()).norm(), 1e-15);
  EXPECT_EQ(m.uvs.size(), 3u);
  EXPECT_EQ(m.uvs[0], dm::Vec2f(0, 0));  // the kept vertex's
  EXPECT_TRUE(m.validate());
}

TEST(WeldVertices, RejectsBadInputAndLeavesTheMeshAlone) {
  dm::Mesh m = soup(box(Vec3::Zero(), 1.0));
  const dm::Mesh before = m;
  EXPECT_FALSE(dm::weldVertices(m, -1.0));
  EXPECT_FALSE(dm::weldVertices(m, std::nan("")));
  EXPECT_FALSE(dm::weldVertices(m, INFINITY));
  m.triangles[3][1] = 1000;
  auto r = dm::weldVertices(m, 1e-6);
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().what.find("triangle 3"), std::string::npos);
  m.triangles[3][1] = before.triangles[3][1];
  m.positions[0] = Vec3(1e30, 0, 0);
  r = dm::weldVertices(m, 1e-20);
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().what.find("too small"), std::string::npos);
  m.positions[0] = before.positions[0];
  EXPECT_TRUE(m.positions == before.positions);
  EXPECT_TRUE(m.triangles == before.triangles);
}

}  // namespace

namespace winding_test {

// The winding number against solid angles: 1 anywhere inside a closed,
// outward mesh (a curved one: an icosphere, at its centre and just under
// its surface), 0 outside, −1 inside it turned inside out; a cube missing
// one face, seen from its centre, winds 5/6 (the open face's solid angle is
// 4π/6), and a point on the plane of a face far from it sees nothing of it.
TEST(WindingNumber, IsOneInsideZeroOutsideAndTheSolidAngleOfWhatIsThere) {
  const dm::Mesh ball = dm::makeIcosphere(0.05, 3);
  EXPECT_NEAR(dm::windingNumber(ball, dm::Vec3::Zero()), 1.0, 1e-12);
  EXPECT_NEAR(dm::windingNumber(ball, dm::Vec3(0.0, 0.0, 0.049)), 1.0, 1e-9);
  EXPECT_NEAR(dm::windingNumber(ball, dm::Vec3(0.03, 0.02, 0.045)), 0.0, 1e-9);
  EXPECT_NEAR(dm::windingNumber(ball, dm::Vec3(1.0, 2.0, 3.0)), 0.0, 1e-12);
  dm::Mesh inverted = ball;
  for (dm::Triangle& t : inverted.triangles) std::swap(t[1], t[2]);
  EXPECT_NEAR(dm::windingNumber(inverted, dm::Vec3::Zero()), -1.0, 1e-12);

  dm::Mesh cube = dm::makeBox(dm::Vec3(0.5, 0.5, 0.5));
  dm::Mesh open = cube;
  open.triangles.clear();
  for (const dm::Triangle& t : cube.triangles) {  // drop the two triangles of the +z face
    bool top = true;
    for (std::uint32_t v : t) top = top && cube.positions[v].z() > 0.4;
    if (!top) open.triangles.push_back(t);
  }
  ASSERT_EQ(open.triangles.size(), cube.triangles.size() - 2);
  EXPECT_NEAR(dm::windingNumber(cube, dm::Vec3(0.1, -0.2, 0.3)), 1.0, 1e-12);
  EXPECT_NEAR(dm::windingNumber(open, dm::Vec3::Zero()), 5.0 / 6.0, 1e-12);
  EXPECT_NEAR(dm::solidAngle(dm::Vec3(5, 0, 0), dm::Vec3(0, 0, 0), dm::Vec3(1, 0, 0), dm::Vec3(0, 1, 0)), 0.0,
              1e-15);
}

}  // namespace winding_test
