// keepLargestComponent and Taubin smoothing against known pieces and shapes.
#include <dm/math/mesh_filters.hpp>
#include <dm/math/mesh_topology.hpp>
#include <dm/math/primitives.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <random>

#include "../common/staircase_ball.hpp"

namespace dm {
namespace {

/// Appends `part` (shifted by `offset`, all vertices coloured `color`) to `m`.
void append(Mesh& m, const Mesh& part, const Vec3& offset, const Vec4f& color) {
  const auto base = static_cast<std::uint32_t>(m.positions.size());
  for (std::size_t v = 0; v < part.vertexCount(); ++v) {
    m.positions.push_back(part.positions[v] + offset);
    m.normals.push_back(part.positions[v].normalized());
    m.uvs.emplace_back(static_cast<float>(v), 0.5f);
    m.colors.push_back(color);
  }
  for (const Triangle& t : part.triangles) m.triangles.push_back({base + t[0], base + t[1], base + t[2]});
}

TEST(MeshFilters, LargestComponentIsTheBigSphereExactly) {
  const Mesh big = makeIcosphere(0.05, 3);    // 1280 triangles, 642 vertices
  const Mesh small = makeIcosphere(0.01, 2);  // 320 triangles
  const Mesh tri{"tri", {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}, {}, {{0, 1, 2}}, {}, {}};
  const Vec4f red(1, 0, 0, 1), green(0, 1, 0, 1), blue(0, 0, 1, 1);
  const Vec3 bigOffset(0.3, 0, 0);
  // The big sphere is neither first nor last, so indices must be remapped.
  Mesh scene;
  scene.name = "scene";
  append(scene, small, Vec3(-0.2, 0, 0), green);
  append(scene, big, bigOffset, red);
  append(scene, tri, Vec3(0, 0.5, 0), blue);
  ASSERT_EQ(analyzeTopology(scene).components, 3u);

  std::size_t removed = 99;
  const Mesh out = keepLargestComponent(scene, &removed);
  EXPECT_EQ(removed, 2u);
  EXPECT_EQ(out.name, "scene");
  ASSERT_EQ(out.vertexCount(), big.vertexCount());
  ASSERT_EQ(out.triangleCount(), big.triangleCount());
  ASSERT_TRUE(out.validate());
  ASSERT_EQ(out.normals.size(), out.vertexCount());
  ASSERT_EQ(out.uvs.size(), out.vertexCount());
  ASSERT_EQ(out.colors.size(), out.vertexCount());
  for (std::size_t v = 0; v < big.vertexCount(); ++v) {
    EXPECT_EQ(out.positions[v], big.positions[v] + bigOffset) << v;
    EXPECT_EQ(out.normals[v], big.positions[v].normalized()) << v;
    EXPECT_EQ(out.uvs[v], Vec2f(static_cast<float>(v), 0.5f)) << v;
    EXPECT_EQ(out.colors[v], red) << v;
  }
  EXPECT_EQ(out.triangles, big.triangles);
  const MeshTopology t = analyzeTopology(out);
  EXPECT_EQ(t.components, 1u);
  EXPECT_EQ(t.unreferencedVertices, 0u);
  EXPECT_TRUE(t.isClosed && t.isManifold && t.isOrientedConsistently);
}

TEST(MeshFilters, ComponentsJoinThroughSharedVerticesOnly) {
  // Two triangles touching at vertex 2 are one piece; the third is separate
  // even though it lies on top of the first (no shared index).
  Mesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {2, 1, 0}, {2, 2, 0}, {0, 0, 0}, {1, 0, 0}, {1, 1, 0}};
  m.triangles = {{5, 6, 7}, {0, 1, 2}, {2, 3, 4}};
  m.normals.assign(3, Vec3::UnitZ());  // wrong size: dropped, not carried
  std::size_t removed = 0;
  const Mesh out = keepLargestComponent(m, &removed);
  EXPECT_EQ(removed, 1u);
  EXPECT_TRUE(out.normals.empty());
  EXPECT_TRUE(out.uvs.empty() && out.colors.empty());
  ASSERT_EQ(out.vertexCount(), 5u);
  EXPECT_EQ(out.triangles, (std::vector<Triangle>{{0, 1, 2}, {2, 3, 4}}));
  for (std::size_t v = 0; v < 5; ++v) EXPECT_EQ(out.positions[v], m.positions[v]);

  // A tie goes to the piece whose first triangle comes first.
  Mesh tie;
  tie.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {5, 0, 0}, {6, 0, 0}, {5, 1, 0}};
  tie.triangles = {{3, 4, 5}, {0, 1, 2}};
  const Mesh first = keepLargestComponent(tie);
  ASSERT_EQ(first.vertexCount(), 3u);
  EXPECT_EQ(first.positions[0], Vec3(5, 0, 0));
}

TEST(MeshFilters, LargestComponentOfDegenerateInputs) {
  std::size_t removed = 7;
  const Mesh none = keepLargestComponent(Mesh{}, &removed);
  EXPECT_TRUE(none.empty());
  EXPECT_EQ(none.vertexCount(), 0u);
  EXPECT_EQ(removed, 0u);

  // Out-of-range triangles belong to no piece and must not be read.
  Mesh bad;
  bad.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {9, 9, 9}};
  bad.triangles = {{0, 1, 1000000}, {0, 1, 2}};
  const Mesh out = keepLargestComponent(bad, &removed);
  EXPECT_EQ(removed, 0u);
  ASSERT_EQ(out.triangleCount(), 1u);
  EXPECT_EQ(out.vertexCount(), 3u);
  EXPECT_TRUE(out.validate());
}

/// Icosphere of radius 1 with each vertex moved radially by uniform noise in ±2 %.
Mesh noisySphere(int levels, unsigned seed) {
  Mesh m = makeIcosphere(1.0, levels);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> noise(-0.02, 0.02);
  for (Vec3& p : m.positions) p *= 1.0 + noise(rng);
  return m;
}

struct RadialStats {
  double mean = 0, rms = 0;  // mean radius; RMS of (radius − mean radius)
};

RadialStats radialStats(const Mesh& m) {
  RadialStats s;
  for (const Vec3& p : m.positions) s.mean += p.norm();
  s.mean /= static_cast<double>(m.vertexCount());
  for (const Vec3& p : m.positions) s.rms += std::pow(p.norm() - s.mean, 2);
  s.rms = std::sqrt(s.rms / static_cast<double>(m.vertexCount()));
  return s;
}

TEST(MeshFilters, TaubinRemovesNoiseWithoutShrinking) {
  // Taubin's filter is low-pass: white noise above the pass-band (k ≈ 0.11)
  // is removed, the part below it stays, hence 50 iterations for a > 3×
  // reduction of uniform per-vertex noise.
  for (unsigned seed : {12345u, 1u, 2u}) {
    Mesh m = noisySphere(4, seed);
    const RadialStats before = radialStats(m);
    ASSERT_NEAR(before.rms, 0.02 / std::sqrt(3.0), 0.001);  // uniform ±2 % has σ = 2 %/√3
    ASSERT_NEAR(before.mean, 1.0, 0.002);
    const auto triangles = m.triangles;
    ASSERT_TRUE(smoothMesh(m, 50));
    const RadialStats after = radialStats(m);
    EXPECT_LT(after.rms, before.rms / 3) << seed;
    EXPECT_LT(std::abs(after.mean - 1.0), 0.01) << seed;
    EXPECT_LT(std::abs(after.mean - before.mean) / before.mean, 0.01) << seed;
    EXPECT_EQ(m.triangles, triangles);
    // Normals were recomputed: on the smoothed sphere they are close to radial.
    ASSERT_EQ(m.normals.size(), m.vertexCount());
    for (std::size_t v = 0; v < m.vertexCount(); ++v)
      ASSERT_GT(m.normals[v].dot(m.positions[v].normalized()), 0.99) << v;
  }
}

TEST(MeshFilters, TaubinKeepsTheRadiusOverManyIterations) {
  // The umbrella operator maps a sphere's vertex to L(p) ≈ −k·p with
  // k ≈ 1 − cos(edge angle) ≈ 0.0024 for a level-4 icosphere. Plain Laplacian
  // steps scale the radius by (1 − λk) each (−6 % after 50 with λ = 0.5);
  // a Taubin pair scales it by (1 − λk)(1 − μk) ≈ 1 + 7·10⁻⁵ (+0.4 %).
  Mesh m = makeIcosphere(1.0, 4);
  ASSERT_TRUE(smoothMesh(m, 50));
  const double change = radialStats(m).mean - 1.0;
  EXPECT_GT(change, 0.0);  // a Laplacian-only filter would give about −0.06
  EXPECT_LT(change, 0.01);
}

TEST(MeshFilters, BoundedTaubinRemovesTheStaircaseWithinItsDisplacementBound) {
  // A 12-voxel ball's staircase is a radial error of a few tenths of a voxel.
  // Smoothing (20 iterations) with a bound of a quarter voxel: no vertex
  // moves further (the
  // vertices of the raw surface lie on the isosurface, so neither does the
  // smoothed surface), yet the staircase's spread of radii shrinks, and the
  // ball keeps its size. Unbounded, the same smoothing moves some vertices
  // further: the bound is what holds them.
  const double R = 12e-3, bound = 0.25e-3;
  const Mesh raw = test::staircaseBall(12e-3, 1e-3);  // 1 mm voxels
  ASSERT_GT(raw.vertexCount(), 1000u);
  const RadialStats before = radialStats(raw);
  Mesh bounded = raw, unbounded = raw;
  ASSERT_TRUE(smoothMesh(bounded, {.iterations = 20, .maxDisplacement = bound}));
  ASSERT_TRUE(smoothMesh(unbounded, {.iterations = 20}));
  const auto largestMove = [&](const Mesh& m) {
    double d = 0;
    for (std::size_t v = 0; v < m.vertexCount(); ++v)
      d = std::max(d, (m.positions[v] - raw.positions[v]).norm());
    return d;
  };
  EXPECT_LE(largestMove(bounded), bound * (1 + 1e-12));
  EXPECT_GT(largestMove(unbounded), 1.2 * bound) << largestMove(unbounded);
  const RadialStats after = radialStats(bounded);
  std::printf(
      "staircase ball R = 12 voxels: radial rms about the mean %.3f -> %.3f voxel (bounded), mean %.3f -> "
      "%.3f\n",
      1e3 * before.rms, 1e3 * after.rms, 1e3 * before.mean, 1e3 * after.mean);
  EXPECT_LT(after.rms, 0.7 * before.rms);  // 0.207 -> 0.130 voxel when written
  EXPECT_NEAR(after.mean, before.mean, 0.05e-3);
  EXPECT_NEAR(before.mean, R, 0.25e-3);
  const MeshTopology t = analyzeTopology(bounded);
  EXPECT_TRUE(t.isClosed && t.isManifold && t.isOrientedConsistently);
}

TEST(MeshFilters, BoundaryVerticesOfAPlaneStayExactlyPut) {
  Mesh m = makePlane(0.5, 0.5, 12);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> noise(-0.01, 0.01);
  for (Vec3& p : m.positions) p += Vec3(noise(rng), noise(rng), noise(rng));
  const auto original = m.positions;
  const MeshTopology before = analyzeTopology(m);
  ASSERT_EQ(before.boundaryEdges, 48u);
  ASSERT_TRUE(smoothMesh(m, 20));
  double interiorHeightBefore = 0, interiorHeightAfter = 0;
  int boundary = 0;
  for (std::size_t v = 0; v < m.vertexCount(); ++v) {
    const std::size_t row = v / 13, col = v % 13;
    if (row == 0 || row == 12 || col == 0 || col == 12) {
      EXPECT_EQ(m.positions[v], original[v]) << v;  // bit-exact
      ++boundary;
    } else {
      EXPECT_NE(m.positions[v], original[v]) << v;
      interiorHeightBefore += original[v].z() * original[v].z();
      interiorHeightAfter += m.positions[v].z() * m.positions[v].z();
    }
  }
  EXPECT_EQ(boundary, 48);
  EXPECT_LT(interiorHeightAfter, 0.25 * interiorHeightBefore);  // the bumps are smoothed out
}

TEST(MeshFilters, SmoothingHandlesUnusedAndDegenerateParts) {
  Mesh m = makeIcosphere(1.0, 1);
  m.positions.emplace_back(5, 5, 5);  // used by no triangle: stays
  m.triangles.push_back({0, 0, 1});   // degenerate: ignored
  ASSERT_TRUE(smoothMesh(m, 3));
  EXPECT_EQ(m.positions.back(), Vec3(5, 5, 5));
  for (const Vec3& p : m.positions) EXPECT_TRUE(p.allFinite());

  // Zero iterations keep positions and only recompute normals.
  Mesh s = makeIcosphere(1.0, 2);
  const auto positions = s.positions;
  ASSERT_TRUE(smoothMesh(s, 0));
  EXPECT_EQ(s.positions, positions);
  ASSERT_EQ(s.normals.size(), s.vertexCount());
  for (std::size_t v = 0; v < s.vertexCount(); ++v) EXPECT_NEAR(s.normals[v].dot(positions[v]), 1.0, 1e-3);
}

TEST(MeshFilters, SmoothingRejectsBadParametersAndLeavesTheMesh) {
  const Mesh original = noisySphere(1, 1);
  Mesh m = original;
  auto expectRejected = [&](Status s) {
    ASSERT_FALSE(s);
    EXPECT_EQ(s.error().code, ErrorCode::InvalidArgument);
    EXPECT_FALSE(s.error().hint.empty() && s.error().where.empty());
    EXPECT_EQ(m.positions, original.positions);
    EXPECT_TRUE(m.normals.empty());
  };
  expectRejected(smoothMesh(m, -1));
  expectRejected(smoothMesh(m, 1001));
  expectRejected(smoothMesh(m, 5, 0.0));
  expectRejected(smoothMesh(m, 5, -0.5, -0.53));
  expectRejected(smoothMesh(m, 5, std::nan(""), -0.53));
  expectRejected(smoothMesh(m, 5, 0.5, 0.0));   // plain Laplacian is not Taubin
  expectRejected(smoothMesh(m, 5, 0.5, -0.5));  // mu must be strictly below -lambda
  expectRejected(smoothMesh(m, 5, 0.5, -INFINITY));
  expectRejected(smoothMesh(m, {.iterations = 5, .maxDisplacement = 0.0}));
  expectRejected(smoothMesh(m, {.iterations = 5, .maxDisplacement = -1e-3}));
  expectRejected(smoothMesh(m, {.iterations = 5, .maxDisplacement = std::nan("")}));
  Mesh broken = original;
  broken.triangles.push_back({0, 1, 9999});
  const Status s = smoothMesh(broken, 5);
  ASSERT_FALSE(s);
  EXPECT_EQ(s.error().code, ErrorCode::InvalidArgument);
  EXPECT_EQ(broken.positions, original.positions);
  EXPECT_TRUE(smoothMesh(m, 1000, 0.5, -0.5000001));  // the limits themselves are allowed
}

}  // namespace
}  // namespace dm
