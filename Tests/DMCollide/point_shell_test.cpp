// Tests of dm/collide/point_shell.hpp: surface sampling of meshes (count,
// points on the surface, face normals, even spread), the bounding-sphere
// hierarchy and input validation.
#include <dm/collide/point_shell.hpp>
#include <dm/math/primitives.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <string>
#include <vector>

namespace {

using dm::Vec3;

// Point indices [first, first + count) under node `n`.
void subtreeRange(const dm::PointShell& s, std::uint32_t n, std::uint32_t& lo, std::uint32_t& hi) {
  const dm::PointShellNode& node = s.nodes()[n];
  if (node.isLeaf()) {
    lo = std::min(lo, node.first);
    hi = std::max(hi, node.first + node.count);
    return;
  }
  subtreeRange(s, node.first, lo, hi);
  subtreeRange(s, node.first + 1, lo, hi);
}

TEST(PointShell, BoxSamplingHasAreaOverSpacingSquaredPointsOnTheFacesWithFaceNormals) {
  const Vec3 h(0.02, 0.015, 0.01);
  const double spacing = 1e-3;
  auto shell = dm::PointShell::fromMesh(dm::makeBox(h), {.spacing = spacing});
  ASSERT_TRUE(shell) << shell.error().message();
  const double area = 8.0 * (h.x() * h.y() + h.y() * h.z() + h.z() * h.x());
  const double expected = area / (spacing * spacing);
  EXPECT_NEAR(static_cast<double>((*shell)->size()), expected, 1.0);
  EXPECT_NEAR((*shell)->areaPerPoint() * static_cast<double>((*shell)->size()), area, 1e-12);

  const auto pts = (*shell)->points();
  const auto nrm = (*shell)->normals();
  for (std::size_t k = 0; k < pts.size(); ++k) {
    const Vec3 excess = pts[k].cwiseAbs() - h;
    ASSERT_LE(excess.maxCoeff(), 1e-12) << "point " << k << " outside the box";
    // On a face: the normal's axis is one where |p| reaches the half extent.
    int axis = 0;
    nrm[k].cwiseAbs().maxCoeff(&axis);
    ASSERT_NEAR(nrm[k].norm(), 1.0, 1e-12);
    ASSERT_NEAR(std::abs(nrm[k][axis]), 1.0, 1e-12) << "normal not a face normal at " << k;
    ASSERT_NEAR(std::abs(pts[k][axis]), h[axis], 1e-12) << "point " << k << " not on the face of its normal";
    ASSERT_GT(nrm[k][axis] * pts[k][axis], 0.0) << "normal points inward at " << k;
  }
}

TEST(PointShell, SampleEliminationSpreadsPointsEvenly) {
  // Poisson-disk-like: no two points much closer than the spacing, and the
  // nearest-neighbour distance close to the hexagonal packing value
  // spacing·√(2/√3) ≈ 1.07·spacing (uniform random points would have
  // min ≈ 0 and mean ≈ 0.5·spacing).
  const double spacing = 1e-3;
  auto shell = dm::PointShell::fromMesh(dm::makeBox(Vec3(0.015, 0.015, 0.005)), {.spacing = spacing});
  ASSERT_TRUE(shell) << shell.error().message();
  const auto pts = (*shell)->points();
  double minNn = std::numeric_limits<double>::infinity(), meanNn = 0.0;
  for (std::size_t i = 0; i < pts.size(); ++i) {
    double nn = std::numeric_limits<double>::infinity();
    for (std::size_t j = 0; j < pts.size(); ++j)
      if (j != i) nn = std::min(nn, (pts[i] - pts[j]).norm());
    minNn = std::min(minNn, nn);
    meanNn += nn;
  }
  meanNn /= static_cast<double>(pts.size());
  EXPECT_GT(minNn, 0.35 * spacing);
  EXPECT_GT(meanNn, 0.8 * spacing);
  EXPECT_LT(meanNn, 1.15 * spacing);
}

TEST(PointShell, SphereSamplingLiesOnTheSphereWithRadialNormals) {
  const double r = 0.005;
  const dm::Mesh ball = dm::makeIcosphere(r, 4);
  auto shell = dm::PointShell::fromMesh(ball, {.spacing = 0.4e-3, .seed = 7});
  ASSERT_TRUE(shell) << shell.error().message();
  // Flat facets: points between the inscribed facet distance and r, normals
  // within the facet angle (~0.04 rad at level 4) of the radial direction.
  for (std::size_t k = 0; k < (*shell)->size(); ++k) {
    const Vec3 p = (*shell)->points()[k];
    EXPECT_LE(p.norm(), r * (1 + 1e-12));
    EXPECT_GE(p.norm(), r * 0.995);
    EXPECT_GT(p.normalized().dot((*shell)->normals()[k]), 0.995);
  }
}

TEST(PointShell, HierarchySpheresContainTheirPoints) {
  auto shell = dm::PointShell::fromMesh(dm::makeTorus(0.02, 0.005, 48, 16), {.spacing = 1e-3});
  ASSERT_TRUE(shell) << shell.error().message();
  const auto nodes = (*shell)->nodes();
  const auto pts = (*shell)->points();
  std::size_t leafPoints = 0;
  for (std::uint32_t n = 0; n < nodes.size(); ++n) {
    std::uint32_t lo = std::numeric_limits<std::uint32_t>::max(), hi = 0;
    subtreeRange(**shell, n, lo, hi);
    for (std::uint32_t k = lo; k < hi; ++k)
      ASSERT_LE((pts[k] - nodes[n].center).norm(), nodes[n].radius) << "node " << n << " point " << k;
    if (nodes[n].isLeaf()) {
      EXPECT_LE(nodes[n].count, dm::PointShell::kLeafSize);
      leafPoints += nodes[n].count;
    }
  }
  EXPECT_EQ(leafPoints, pts.size());  // leaves partition the points
  std::uint32_t lo = 0, hi = 0;
  subtreeRange(**shell, 0, lo, hi);
  EXPECT_EQ(hi, pts.size());
  const dm::Aabb box = (*shell)->localAabb();
  for (const Vec3& p : pts) EXPECT_TRUE(box.contains(p));
}

TEST(PointShell, CreateNormalisesAndKeepsTheInputIndex) {
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::vector<Vec3> p(100), n(100);
  for (int i = 0; i < 100; ++i) {
    p[i] = Vec3(u(rng), u(rng), u(rng));
    n[i] = 3.0 * p[i];
  }
  auto shell = dm::PointShell::create(p, n);
  ASSERT_TRUE(shell) << shell.error().message();
  ASSERT_EQ((*shell)->size(), 100u);
  for (std::size_t k = 0; k < 100; ++k) {
    const std::uint32_t i = (*shell)->originalIndex(k);
    EXPECT_EQ((*shell)->points()[k], p[i]);
    EXPECT_NEAR(((*shell)->normals()[k] - p[i].normalized()).norm(), 0.0, 1e-15);
  }
  EXPECT_EQ((*shell)->volume(), 0.0);
}

TEST(PointShell, BadInputIsAnErrorNamingTheIndex) {
  std::vector<Vec3> p(5, Vec3(0.1, 0.2, 0.3)), n(5, Vec3::UnitZ());
  {
    std::vector<Vec3> four(4, Vec3::UnitX());
    auto s = dm::PointShell::create(p, four);
    ASSERT_FALSE(s);
    EXPECT_NE(s.error().message().find("5 points but 4 normals"), std::string::npos) << s.error().message();
  }
  {
    auto q = p;
    q[3].y() = std::numeric_limits<double>::quiet_NaN();
    auto s = dm::PointShell::create(q, n);
    ASSERT_FALSE(s);
    EXPECT_NE(s.error().message().find("points[3]"), std::string::npos) << s.error().message();
  }
  {
    auto m = n;
    m[2] = Vec3::Zero();
    auto s = dm::PointShell::create(p, m);
    ASSERT_FALSE(s);
    EXPECT_NE(s.error().message().find("normals[2]"), std::string::npos) << s.error().message();
    EXPECT_NE(s.error().message().find("zero"), std::string::npos) << s.error().message();
  }
  {
    auto s = dm::PointShell::create({}, {});
    ASSERT_FALSE(s);
    EXPECT_NE(s.error().message().find("no points"), std::string::npos);
  }
  const dm::Mesh box = dm::makeBox(Vec3(0.01, 0.01, 0.01));
  {
    auto s = dm::PointShell::fromMesh(box, {.spacing = 0.0});
    ASSERT_FALSE(s);
    EXPECT_NE(s.error().message().find("spacing"), std::string::npos) << s.error().message();
  }
  {
    auto s = dm::PointShell::fromMesh(box, {.spacing = 1e-6, .maxPoints = 1000});
    ASSERT_FALSE(s);
    EXPECT_NE(s.error().message().find("maxPoints"), std::string::npos) << s.error().message();
  }
  {
    auto s = dm::PointShell::fromMesh(dm::Mesh{}, {.spacing = 1e-3});
    ASSERT_FALSE(s);
  }
}

}  // namespace
