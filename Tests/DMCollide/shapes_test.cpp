// Tests of dm/collide/shapes.hpp: support mappings, bounds, volumes (against
// closed forms and FCL's computeVolume), hull adjacency and type registry.
#include <dm/collide/shapes.hpp>

#include <gtest/gtest.h>

#include <fcl/fcl.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <numbers>
#include <random>
#include <set>
#include <utility>
#include <vector>

#include "collide_test_support.hpp"

namespace {

using dm::Isometry3;
using dm::Vec3;

using dm::test::randomUnit;

Isometry3 randomPose(std::mt19937_64& rng) {
  std::normal_distribution<double> g(0.0, 1.0);
  Isometry3 p = Isometry3::Identity();
  p.linear() = dm::Quat(Eigen::Vector4d(g(rng), g(rng), g(rng), g(rng)).normalized()).toRotationMatrix();
  p.translation() = Vec3(g(rng), g(rng), g(rng));
  return p;
}

std::vector<Vec3> randomSpherePoints(std::mt19937_64& rng, int n, double r) {
  std::vector<Vec3> p(n);
  for (auto& v : p) v = r * randomUnit(rng);
  return p;
}

// Hill-climbing support equals the brute-force maximum over the vertices,
// from any warm-start hint.
TEST(Shapes, HullSupportMatchesBruteForce) {
  std::mt19937_64 rng(1);
  for (int n : {4, 12, 40, 1000}) {
    auto hull = dm::ConvexHull::create(randomSpherePoints(rng, n, 0.5));
    ASSERT_TRUE(hull.ok());
    const auto& verts = (*hull)->vertices();
    std::uint32_t hint = 0;
    for (int k = 0; k < 2000; ++k) {
      const Vec3 d = randomUnit(rng);
      if (k % 7 == 0) hint = static_cast<std::uint32_t>(k % verts.size());
      double best = -1e300;
      for (const Vec3& v : verts) best = std::max(best, d.dot(v));
      ASSERT_NEAR(d.dot((*hull)->supportCore(d, hint)), best, 1e-15) << n;
    }
  }
}

// Hull adjacency is the edge graph of a closed polytope: symmetric,
// degree ≥ 3, and V − E + F = 2.
TEST(Shapes, HullAdjacencyIsTheEdgeGraph) {
  std::mt19937_64 rng(2);
  auto hull = dm::ConvexHull::create(randomSpherePoints(rng, 300, 1.0));
  ASSERT_TRUE(hull.ok());
  const auto& h = **hull;
  std::set<std::pair<std::uint32_t, std::uint32_t>> edges;
  for (std::uint32_t i = 0; i < h.vertices().size(); ++i) {
    ASSERT_GE(h.neighbors(i).size(), 3u);
    for (std::uint32_t j : h.neighbors(i)) {
      edges.insert({std::min(i, j), std::max(i, j)});
      const auto back = h.neighbors(j);
      ASSERT_NE(std::find(back.begin(), back.end(), i), back.end());
    }
  }
  EXPECT_EQ(long(h.vertices().size()) - long(edges.size()) + long(h.mesh().triangles.size()), 2);
}

// Closed-form support points lie on the surface and maximise the direction
// over dense surface samples.
TEST(Shapes, PrimitiveSupportIsExtreme) {
  std::mt19937_64 rng(3);
  const dm::Box box(Vec3(0.3, 0.2, 0.1));
  const dm::Cylinder cyl(0.2, 0.4);
  const dm::Ellipsoid ell(Vec3(0.5, 0.3, 0.2));
  const dm::Capsule cap(0.1, 0.3);
  std::uint32_t hint = 0;
  for (int k = 0; k < 500; ++k) {
    const Vec3 d = randomUnit(rng);
    // Surface samples of each shape.
    double boxBest = -1e9, cylBest = -1e9, ellBest = -1e9, capBest = -1e9;
    for (int s = 0; s < 400; ++s) {
      const Vec3 u = randomUnit(rng);
      boxBest = std::max(boxBest, d.dot(u.cwiseSign().cwiseProduct(box.halfExtents())));
      const double phi = 2 * std::numbers::pi * s / 400.0;
      cylBest =
          std::max(cylBest, d.dot(Vec3(0.2 * std::cos(phi), 0.2 * std::sin(phi), u.z() > 0 ? 0.4 : -0.4)));
      ellBest = std::max(ellBest, d.dot(ell.radii().cwiseProduct(u)));
      capBest = std::max(capBest, d.dot(Vec3(0, 0, u.z() > 0 ? 0.3 : -0.3) + 0.1 * u));
    }
    EXPECT_GE(d.dot(box.supportCore(d, hint)), boxBest - 1e-15);
    EXPECT_GE(d.dot(cyl.supportCore(d, hint)), cylBest - 1e-15);
    const Vec3 e = ell.supportCore(d, hint);
    EXPECT_NEAR(e.cwiseQuotient(ell.radii()).squaredNorm(), 1.0, 1e-12);
    EXPECT_GE(d.dot(e), ellBest - 1e-15);
    EXPECT_GE(d.dot(cap.support(d)), capBest - 1e-15);
    EXPECT_NEAR(d.dot(cap.support(d)), std::abs(d.z()) * 0.3 + 0.1, 1e-15);
  }
}

// The closed-form world AABBs equal the support-based (tight) ones.
TEST(Shapes, WorldAabbIsTight) {
  std::mt19937_64 rng(4);
  auto hull = dm::ConvexHull::create(randomSpherePoints(rng, 50, 0.4));
  ASSERT_TRUE(hull.ok());
  const std::vector<std::shared_ptr<const dm::ConvexShape>> shapes = {
      std::make_shared<dm::Sphere>(0.3),
      std::make_shared<dm::Box>(Vec3(0.3, 0.2, 0.1)),
      std::make_shared<dm::Capsule>(0.1, 0.3),
      std::make_shared<dm::Cylinder>(0.2, 0.4),
      std::make_shared<dm::Ellipsoid>(Vec3(0.5, 0.3, 0.2)),
      *hull};
  for (int k = 0; k < 200; ++k) {
    const Isometry3 p = randomPose(rng);
    for (const auto& s : shapes) {
      const dm::Aabb fast = s->aabb(p);
      const dm::Aabb tight = s->ConvexShape::aabb(p);
      ASSERT_LT((fast.min() - tight.min()).cwiseAbs().maxCoeff(), 1e-12) << dm::shapeTypeName(s->type());
      ASSERT_LT((fast.max() - tight.max()).cwiseAbs().maxCoeff(), 1e-12) << dm::shapeTypeName(s->type());
      // The bounding sphere holds the box's extreme points.
      const dm::BoundingSphere bs = s->boundingSphere();
      for (int j = 0; j < 20; ++j) {
        const Vec3 d = randomUnit(rng);
        ASSERT_LE((s->support(d) - bs.center).norm(), bs.radius + 1e-12);
      }
    }
  }
}

// Volumes against closed forms and FCL's computeVolume().
TEST(Shapes, VolumesMatchFcl) {
  EXPECT_NEAR(dm::Sphere(0.3).volume(), fcl::Sphered(0.3).computeVolume(), 1e-15);
  EXPECT_NEAR(dm::Box(Vec3(0.3, 0.2, 0.1)).volume(), fcl::Boxd(0.6, 0.4, 0.2).computeVolume(), 1e-15);
  EXPECT_NEAR(dm::Capsule(0.1, 0.3).volume(), fcl::Capsuled(0.1, 0.6).computeVolume(), 1e-15);
  EXPECT_NEAR(dm::Cylinder(0.2, 0.4).volume(), fcl::Cylinderd(0.2, 0.8).computeVolume(), 1e-15);
  EXPECT_NEAR(dm::Ellipsoid(Vec3(0.5, 0.3, 0.2)).volume(), fcl::Ellipsoidd(0.5, 0.3, 0.2).computeVolume(),
              1e-15);
  std::vector<Vec3> cube;
  for (int k = 0; k < 27; ++k)
    cube.emplace_back(k % 3 * 0.5, k / 3 % 3 * 0.5, k / 9 * 0.5);  // grid, 1 m cube
  auto hull = dm::ConvexHull::create(cube);
  ASSERT_TRUE(hull.ok());
  EXPECT_EQ((*hull)->vertices().size(), 8u);
  EXPECT_NEAR((*hull)->volume(), 1.0, 1e-14);
  EXPECT_TRUE(std::isinf(dm::Plane(Vec3::UnitZ(), 0).volume()));
}

TEST(Shapes, HullOfFlatPointsFails) {
  const std::vector<Vec3> flat = {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(1, 1, 0)};
  auto hull = dm::ConvexHull::create(flat);
  ASSERT_FALSE(hull.ok());
  EXPECT_NE(hull.error().message().find("coplanar"), std::string::npos) << hull.error().message();
}

TEST(Shapes, PlaneAndMeshBounds) {
  const dm::Plane p(Vec3(0, 0, 2), 1.0);  // normalised: z ≤ 0.5
  EXPECT_NEAR(p.normal().z(), 1.0, 0);
  EXPECT_NEAR(p.offset(), 0.5, 0);
  EXPECT_NEAR(p.localAabb().max().z(), 0.5, 0);
  Isometry3 up = Isometry3::Identity();
  up.translation() = Vec3(0, 0, 1);
  EXPECT_NEAR(p.aabb(up).max().z(), 1.5, 1e-15);
  EXPECT_TRUE(std::isinf(p.aabb(up).max().x()));

  auto mesh = std::make_shared<dm::Mesh>();
  mesh->positions = {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(0, 0, 1)};
  mesh->triangles = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  const dm::TriangleMesh tet(mesh, nullptr);
  EXPECT_NEAR(tet.volume(), 1.0 / 6.0, 1e-15);
  EXPECT_EQ(tet.localAabb().max(), Vec3(1, 1, 1));
  EXPECT_EQ(tet.type(), dm::ShapeType::TriangleMesh);
  EXPECT_FALSE(tet.isConvex());
  EXPECT_EQ(dm::shapeTypeName(dm::ShapeType::TriangleMesh), "triangle-mesh");
}

}  // namespace
