// A collider added at run time by a real plugin (Tests/DMCollide/plugins/
// plane_mesh_collider.c, loaded by dm::PluginLinker): the (plane,
// triangle-mesh) pair, which no built-in collider serves. Its answers are
// checked against the built-in plane–box and plane–sphere colliders on the
// same geometry given as a mesh, on random poses.
#include <dm/collide/collider_plugin.hpp>
#include <dm/collide/query.hpp>
#include <dm/core/plugin.hpp>
#include <dm/math/primitives.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <random>
#include "../common/build_paths.hpp"

namespace {

using dm::Isometry3;
using dm::Vec3;

Isometry3 randomPose(std::mt19937& rng, double spread) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Isometry3 p = Isometry3::Identity();
  p.linear() = Eigen::Quaterniond(u(rng), u(rng), u(rng), u(rng)).normalized().toRotationMatrix();
  p.translation() = spread * Vec3(u(rng), u(rng), u(rng));
  return p;
}

// The plugin's collider for (a, b) through `table`, in the order given.
struct Query {
  const dm::Collider* collider = nullptr;
  bool swapped = false;
};

class ColliderPlugin : public ::testing::Test {
 protected:
  void SetUp() override {
    auto loaded = linker_.load(dm::test::besideExecutable(DM_COLLIDER_PLUGIN_DIR) + "/libdm_test_plane_mesh_collider.so");
    ASSERT_TRUE(loaded.ok()) << loaded.error().message();
    auto added = dm::registerPluginColliders(registry_, table_);
    ASSERT_TRUE(added.ok()) << added.error().message();
    EXPECT_EQ(*added, 1);
  }
  dm::FactoryRegistry registry_;
  dm::PluginLinker linker_{registry_};
  dm::ColliderTable table_;
};

TEST(ColliderPluginTable, PlaneMeshIsNotBuiltIn) {
  auto mesh = dm::TriangleMesh::create(std::make_shared<const dm::Mesh>(dm::makeBox(Vec3(0.1, 0.1, 0.1))));
  ASSERT_TRUE(mesh.ok());
  const dm::Plane ground(Vec3::UnitZ(), 0.0);
  dm::ColliderTable table;
  EXPECT_FALSE(table.check(ground, **mesh).ok());
}

TEST_F(ColliderPlugin, AddsThePlaneMeshPairAndMatchesThePlaneBoxCollider) {
  const Vec3 half(0.2, 0.1, 0.05);
  auto mesh = dm::TriangleMesh::create(std::make_shared<const dm::Mesh>(dm::makeBox(half)));
  ASSERT_TRUE(mesh.ok());
  const dm::Box box(half);
  const dm::Plane ground(Vec3(0.3, -0.2, 1.0), 0.02);
  ASSERT_TRUE(table_.check(ground, **mesh).ok());
  bool swapped = true;
  const dm::Collider* c = table_.find(ground, **mesh, swapped);
  ASSERT_NE(c, nullptr);
  EXPECT_FALSE(swapped);

  std::mt19937 rng(7);
  int hits = 0;
  for (int i = 0; i < 500; ++i) {
    const Isometry3 pp = randomPose(rng, 0.1), pm = randomPose(rng, 0.3);
    const dm::DistanceResult ref = dm::distance(ground, pp, box, pm);  // built-in plane–convex
    const dm::DistanceResult got = c->distance(ground, pp, **mesh, pm, nullptr);
    ASSERT_TRUE(got.supported);
    EXPECT_NEAR(got.distance, ref.distance, 1e-12) << i;
    // pointB is a box corner at the extreme, pointA its projection on the plane.
    EXPECT_NEAR((got.pointA - got.pointB).norm(), std::abs(got.distance), 1e-12);
    const bool refHit = dm::intersect(ground, pp, box, pm);
    EXPECT_EQ(c->intersect(ground, pp, **mesh, pm, nullptr), refHit) << i;
    dm::CollisionResult res;
    c->contacts(ground, pp, **mesh, pm, {true, 4}, res, nullptr);
    EXPECT_EQ(res.colliding, refHit);
    if (refHit) {
      ++hits;
      ASSERT_FALSE(res.contacts.empty());
      EXPECT_LE(res.contacts.size(), 4u);
      // The deepest contact's depth is the penetration; normals are the world plane normal.
      EXPECT_NEAR(res.contacts[0].depth, -ref.distance, 1e-12);
      const Vec3 n = pp.linear() * ground.normal();
      for (const dm::ContactPoint& cp : res.contacts) EXPECT_NEAR(cp.normal.dot(n), 1.0, 1e-12);
    }
  }
  EXPECT_GT(hits, 50);
  EXPECT_LT(hits, 450);
}

TEST_F(ColliderPlugin, ServesTheSwappedOrderWithFlippedNormals) {
  auto mesh = dm::TriangleMesh::create(std::make_shared<const dm::Mesh>(dm::makeIcosphere(0.1, 2)));
  ASSERT_TRUE(mesh.ok());
  const dm::Plane ground(Vec3::UnitZ(), 0.0);
  bool swapped = false;
  const dm::Collider* c = table_.find(**mesh, ground, swapped);
  ASSERT_NE(c, nullptr);
  EXPECT_TRUE(swapped);  // registered as (plane, mesh): the table swaps back
  // The icosphere's lowest vertex is its pole (0, 0, -r): resting 3 cm deep.
  Isometry3 pm = Isometry3::Identity();
  pm.translation() = Vec3(0, 0, 0.07);
  const dm::DistanceResult d = c->distance(ground, Isometry3::Identity(), **mesh, pm, nullptr);
  EXPECT_NEAR(d.distance, -0.03, 1e-12);
  EXPECT_NEAR(d.pointB.z(), -0.03, 1e-12);
  EXPECT_NEAR(d.pointA.z(), 0.0, 1e-15);
}

TEST(ColliderPluginErrors, RejectsWrongAbiAndNullFunctions) {
  static const DmColliderVTable kNoFns = {"plane", "triangle-mesh", nullptr, nullptr, nullptr};
  dm::FactoryRegistry registry;
  ASSERT_TRUE(registry.add(DM_COLLIDER_KIND, "broken", DM_COLLIDER_KIND_ABI_VERSION, &kNoFns).ok());
  dm::ColliderTable table;
  auto r = dm::registerPluginColliders(registry, table);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, dm::ErrorCode::InvalidArgument);
  EXPECT_NE(r.error().message().find("broken"), std::string::npos);

  dm::FactoryRegistry old;
  ASSERT_TRUE(old.add(DM_COLLIDER_KIND, "old", DM_COLLIDER_KIND_ABI_VERSION + 1, &kNoFns).ok());
  auto v = dm::registerPluginColliders(old, table);
  ASSERT_FALSE(v.ok());
  EXPECT_EQ(v.error().code, dm::ErrorCode::Version);
}

TEST(ColliderPluginView, BuiltInParametersReachTheCSide) {
  const dm::Capsule cap(0.02, 0.1);
  const DmShapeView v = dm::shapeView(cap);
  EXPECT_STREQ(v.type_name, "capsule");
  ASSERT_EQ(v.param_count, 2u);
  EXPECT_EQ(v.params[0], 0.02);
  EXPECT_EQ(v.params[1], 0.1);
  const dm::Mesh box = dm::makeBox(Vec3(1, 2, 3));
  auto mesh = dm::TriangleMesh::create(std::make_shared<const dm::Mesh>(box));
  ASSERT_TRUE(mesh.ok());
  const DmShapeView m = dm::shapeView(**mesh);
  ASSERT_EQ(m.vertex_count, box.positions.size());
  ASSERT_EQ(m.triangle_count, box.triangles.size());
  EXPECT_EQ(m.vertices[3 * 5 + 1], box.positions[5].y());
  EXPECT_EQ(m.triangles[3 * 7 + 2], box.triangles[7][2]);
}

}  // namespace
