// Quadric simplification checked against geometry: shapes whose surface is
// known exactly (sphere, torus, plane, cube), their volume, genus, boundary
// and the Hausdorff distance to the input.
#include <dm/math/mass_properties.hpp>
#include <dm/math/mesh_topology.hpp>
#include <dm/math/primitives.hpp>
#include <dm/math/simplify.hpp>

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <map>
#include <numbers>
#include <utility>
#include <vector>

namespace {

/// The unit square [0,1]² at z = z0 as an n × n grid of quads, normal +z.
dm::Mesh plane(int n, double z0 = 0.0) {
  dm::Mesh m;
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) m.positions.push_back({double(i) / n, double(j) / n, z0});
  auto id = [&](int i, int j) { return static_cast<std::uint32_t>(j * (n + 1) + i); };
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      m.triangles.push_back({id(i, j), id(i + 1, j), id(i + 1, j + 1)});
      m.triangles.push_back({id(i, j), id(i + 1, j + 1), id(i, j + 1)});
    }
  return m;
}

/// The cube [-1,1]³ with every face an n × n grid, welded, CCW from outside.
dm::Mesh subdividedCube(int n) {
  dm::Mesh m;
  for (int axis = 0; axis < 3; ++axis)
    for (int sign : {-1, 1}) {
      dm::Vec3 normal = dm::Vec3::Zero();
      normal[axis] = sign;
      dm::Vec3 e1 = dm::Vec3::Zero();
      e1[(axis + 1) % 3] = 1;
      const dm::Vec3 e2 = normal.cross(e1);  // e1 × e2 = normal
      const auto base = static_cast<std::uint32_t>(m.positions.size());
      for (int j = 0; j <= n; ++j)
        for (int i = 0; i <= n; ++i)
          m.positions.push_back(normal + (2.0 * i / n - 1) * e1 + (2.0 * j / n - 1) * e2);
      auto id = [&](int i, int j) { return base + static_cast<std::uint32_t>(j * (n + 1) + i); };
      for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) {
          m.triangles.push_back({id(i, j), id(i + 1, j), id(i + 1, j + 1)});
          m.triangles.push_back({id(i, j), id(i + 1, j + 1), id(i, j + 1)});
        }
    }
  auto weld = dm::weldVertices(m, 1e-9);
  EXPECT_TRUE(weld) << weld.error();
  return m;
}

/// Total length of the edges used by exactly one triangle.
double boundaryLength(const dm::Mesh& m) {
  std::map<std::pair<std::uint32_t, std::uint32_t>, int> count;
  for (const dm::Triangle& t : m.triangles)
    for (int c = 0; c < 3; ++c) ++count[std::minmax(t[c], t[(c + 1) % 3])];
  double len = 0;
  for (const auto& [e, k] : count)
    if (k == 1) len += (m.positions[e.first] - m.positions[e.second]).norm();
  return len;
}

void expectClosedManifold(const dm::Mesh& m, long long genus) {
  const dm::MeshTopology t = dm::analyzeTopology(m);
  EXPECT_TRUE(t.isClosed);
  EXPECT_TRUE(t.isManifold);
  EXPECT_TRUE(t.isOrientedConsistently);
  EXPECT_EQ(t.degenerateTriangles, 0u);
  EXPECT_EQ(t.unreferencedVertices, 0u);
  EXPECT_EQ(t.components, 1u);
  ASSERT_TRUE(t.genus.has_value());
  EXPECT_EQ(*t.genus, genus);
  EXPECT_EQ(t.eulerCharacteristic, 2 - 2 * genus);
  EXPECT_EQ(m.normals.size(), m.positions.size());
}

TEST(Hausdorff, ParallelSquaresAreTheirOffsetApart) {
  EXPECT_NEAR(dm::hausdorffDistance(plane(4), plane(7, 0.1)), 0.1, 1e-12);
  EXPECT_NEAR(dm::hausdorffDistance(plane(4), plane(4)), 0.0, 1e-15);
  EXPECT_EQ(dm::hausdorffDistance(dm::Mesh{}, dm::Mesh{}), 0.0);
  EXPECT_TRUE(std::isinf(dm::hausdorffDistance(plane(2), dm::Mesh{})));
}

TEST(Hausdorff, IsSymmetricAndSeesTheLargerOfBothSides) {
  // A unit square against a quarter of it: every point of the quarter lies on
  // the square (0 one way), the far corner (1, 1) is √2/2 from the quarter.
  dm::Mesh quarter = plane(4);
  for (dm::Vec3& p : quarter.positions) p *= 0.5;
  const double d = dm::hausdorffDistance(plane(4), quarter);
  EXPECT_NEAR(d, std::sqrt(0.5), 1e-12);
  EXPECT_NEAR(dm::hausdorffDistance(quarter, plane(4)), d, 1e-15);
}

TEST(Hausdorff, ConcentricSpheresAreTheRadialGapApart) {
  // Vertices of both lie on their spheres; chords add at most the sagitta.
  const dm::Mesh a = dm::makeIcosphere(1.0, 3), b = dm::makeIcosphere(1.05, 3);
  const double d = dm::hausdorffDistance(a, b, 8);
  EXPECT_GE(d, 0.05 - 1e-12);
  EXPECT_LT(d, 0.05 + 0.01);
}

TEST(Simplify, IcosphereAtTenPercentStaysAClosedSphere) {
  const dm::Mesh sphere = dm::makeIcosphere(1.0, 5);  // 20480 triangles, edge ≈ 0.03
  dm::SimplifyReport report;
  auto out = dm::simplifyMesh(sphere, {.targetRatio = 0.1}, &report);
  ASSERT_TRUE(out) << out.error();
  EXPECT_EQ(report.trianglesBefore, 20480u);
  EXPECT_EQ(report.trianglesAfter, out->triangleCount());
  EXPECT_NEAR(double(out->triangleCount()), 2048.0, 4.0);
  expectClosedManifold(*out, 0);

  auto before = dm::computeMassProperties(sphere), after = dm::computeMassProperties(*out);
  ASSERT_TRUE(before && after);
  // The fine icosphere is within 0.3% of 4π/3; the 2048-triangle one within ~1%.
  EXPECT_NEAR(after->volume / before->volume, 1.0, 0.02);
  EXPECT_LT(after->centroid.norm(), 1e-3);

  // 2048 triangles on a unit sphere have edges ≈ 0.09, sagitta ≈ 0.001.
  const double d = dm::hausdorffDistance(*out, sphere, 8);
  EXPECT_LT(d, 0.006);
  EXPECT_LE(report.maxDistance, d + 1e-12);  // the report samples less, so measures less or equal
  EXPECT_GT(report.maxDistance, 0.0);
  // Every vertex stays close to the unit sphere.
  for (const dm::Vec3& p : out->positions) EXPECT_NEAR(p.norm(), 1.0, 0.01);
}

TEST(Simplify, FlatPlaneCollapsesToFewTrianglesAndKeepsItsBoundary) {
  const dm::Mesh square = plane(24);  // 1152 triangles
  auto out = dm::simplifyMesh(square, {.targetTriangles = 2});
  ASSERT_TRUE(out) << out.error();
  EXPECT_LE(out->triangleCount(), 4u);  // a square needs 2
  EXPECT_NEAR(out->surfaceArea(), 1.0, 1e-12);
  EXPECT_NEAR(boundaryLength(*out), 4.0, 1e-12);
  EXPECT_LT(dm::hausdorffDistance(*out, square, 8), 1e-12);
  const dm::MeshTopology t = dm::analyzeTopology(*out);
  EXPECT_TRUE(t.isManifold);
  EXPECT_TRUE(t.isOrientedConsistently);
  EXPECT_EQ(t.eulerCharacteristic, 1);  // still a disc
  for (const dm::Vec3& n : out->normals) EXPECT_NEAR(n.z(), 1.0, 1e-12);
}

TEST(Simplify, WithoutBoundaryPreservationThePlaneMayShrink) {
  // The same square without penalty planes: the boundary is free to move, so
  // the error measure alone no longer guards it — but topology still holds.
  auto out = dm::simplifyMesh(plane(16), {.targetTriangles = 2, .preserveBoundary = false});
  ASSERT_TRUE(out) << out.error();
  const dm::MeshTopology t = dm::analyzeTopology(*out);
  EXPECT_TRUE(t.isManifold);
  EXPECT_EQ(t.eulerCharacteristic, 1);
  EXPECT_LE(out->triangleCount(), 8u);
}

TEST(Simplify, SubdividedCubeBecomesTheTwelveTriangleCube) {
  const dm::Mesh cube = subdividedCube(6);  // 432 triangles
  ASSERT_EQ(cube.triangleCount(), 432u);
  auto out = dm::simplifyMesh(cube, {.targetTriangles = 12});
  ASSERT_TRUE(out) << out.error();
  EXPECT_EQ(out->triangleCount(), 12u);
  expectClosedManifold(*out, 0);
  EXPECT_LT(dm::hausdorffDistance(*out, cube, 16), 1e-9);
  auto mp = dm::computeMassProperties(*out);
  ASSERT_TRUE(mp) << mp.error();
  EXPECT_NEAR(mp->volume, 8.0, 1e-9);
}

TEST(Simplify, MaxErrorStopsEarlyWithinTheBound) {
  const dm::Mesh sphere = dm::makeIcosphere(1.0, 4);  // 5120 triangles
  constexpr double kMaxError = 0.01;
  dm::SimplifyReport report;
  auto out = dm::simplifyMesh(sphere, {.targetRatio = 0.001, .maxError = kMaxError}, &report);
  ASSERT_TRUE(out) << out.error();
  // A sphere needs many triangles for 1% accuracy: it stops well before 5.
  EXPECT_GT(out->triangleCount(), 20u);
  EXPECT_LT(out->triangleCount(), 5120u / 4);
  expectClosedManifold(*out, 0);
  const double d = dm::hausdorffDistance(*out, sphere, 32);
  EXPECT_LE(d, kMaxError * 1.02);
  EXPECT_LE(report.maxDistance, kMaxError * 1.02);
  // Without the bound the same target goes much further and much further away.
  auto coarse = dm::simplifyMesh(sphere, {.targetRatio = 0.01});
  ASSERT_TRUE(coarse) << coarse.error();
  EXPECT_GT(dm::hausdorffDistance(*coarse, sphere), kMaxError);
}

TEST(Simplify, TorusKeepsGenusOneAtFivePercent) {
  const dm::Mesh ring = dm::makeTorus(1.0, 0.3, 64, 32);  // 4096 triangles
  auto out = dm::simplifyMesh(ring, {.targetRatio = 0.05});
  ASSERT_TRUE(out) << out.error();
  EXPECT_NEAR(double(out->triangleCount()), 205.0, 3.0);
  expectClosedManifold(*out, 1);
  // Still a ring: the hole is open, the tube around (R, 0, 0) is kept.
  EXPECT_LT(dm::hausdorffDistance(*out, ring, 8), 0.1);
}

TEST(Simplify, ProgressIsMonotonicBoundedAndEndsAtOne) {
  std::vector<double> calls;
  dm::SimplifyOptions opt;
  opt.targetRatio = 0.2;
  opt.progress = [&](double f) { calls.push_back(f); };
  auto out = dm::simplifyMesh(dm::makeIcosphere(1.0, 3), opt);
  ASSERT_TRUE(out) << out.error();
  ASSERT_FALSE(calls.empty());
  EXPECT_LE(calls.size(), 102u);
  EXPECT_EQ(calls.front(), 0.0);
  EXPECT_EQ(calls.back(), 1.0);
  for (std::size_t i = 1; i < calls.size(); ++i) EXPECT_GT(calls[i], calls[i - 1]);
}

TEST(Simplify, RatioOneKeepsEveryTriangleAndDropsUnusedVertices) {
  dm::Mesh m = dm::makeIcosphere(1.0, 2);
  m.positions.push_back({5, 5, 5});  // unused
  auto out = dm::simplifyMesh(m, {.targetRatio = 1.0});
  ASSERT_TRUE(out) << out.error();
  EXPECT_EQ(out->triangleCount(), m.triangleCount());
  EXPECT_EQ(out->vertexCount(), m.vertexCount() - 1);
  EXPECT_LT(dm::hausdorffDistance(*out, m),
            1e-12);  // the same surface (round-off in the closest-point arithmetic)
}

TEST(Simplify, RejectsBadInputWithAMessage) {
  const dm::Mesh good = dm::makeIcosphere(1.0, 1);
  for (double r : {0.0, -0.5, 1.5, std::nan("")}) {
    auto out = dm::simplifyMesh(good, {.targetRatio = r});
    ASSERT_FALSE(out) << r;
    EXPECT_EQ(out.error().code, dm::ErrorCode::InvalidArgument);
    EXPECT_NE(out.error().what.find("targetRatio"), std::string::npos);
  }
  auto empty = dm::simplifyMesh(dm::Mesh{}, {});
  ASSERT_FALSE(empty);
  EXPECT_NE(empty.error().what.find("no triangles"), std::string::npos);
  dm::Mesh nan = good;
  nan.positions[3].y() = std::nan("");
  EXPECT_FALSE(dm::simplifyMesh(nan, {}));
  dm::Mesh badIndex = good;
  badIndex.triangles[0][1] = 1000;
  EXPECT_FALSE(dm::simplifyMesh(badIndex, {}));
  EXPECT_FALSE(dm::simplifyMesh(good, {.maxError = -1.0}));
  EXPECT_FALSE(dm::simplifyMesh(good, {.maxError = std::nan("")}));
}

TEST(Lods, LevelsShrinkAndMeasureTheirDistanceToTheInput) {
  const dm::Mesh sphere = dm::makeIcosphere(1.0, 4);
  const std::array<double, 3> ratios = {0.5, 0.2, 0.05};
  auto lods = dm::buildLods(sphere, ratios);
  ASSERT_TRUE(lods) << lods.error();
  ASSERT_EQ(lods->size(), 4u);
  EXPECT_EQ((*lods)[0].mesh.triangleCount(), sphere.triangleCount());
  EXPECT_EQ((*lods)[0].maxDistance, 0.0);
  for (std::size_t i = 1; i < lods->size(); ++i) {
    const dm::MeshLod& l = (*lods)[i];
    EXPECT_NEAR(l.ratio, ratios[i - 1], 0.002);
    expectClosedManifold(l.mesh, 0);
    EXPECT_NEAR(l.maxDistance, dm::hausdorffDistance(l.mesh, sphere, 0), 1e-15);
    EXPECT_GE(l.maxDistance, (*lods)[i - 1].maxDistance);
  }
  EXPECT_LT((*lods)[3].maxDistance, 0.05);
  const std::array<double, 2> unordered = {0.2, 0.5};
  EXPECT_FALSE(dm::buildLods(sphere, unordered));
}

}  // namespace
