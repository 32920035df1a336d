// Tests of dm/collide/query.hpp: the collider table, the analytic pair
// colliders (against FCL's closed forms and against geometry), box–box and
// plane–box manifolds, compounds, user shape types and ray casts.
#include <dm/collide/query.hpp>
#include <dm/collide/shapes.hpp>
#include <dm/math/primitives.hpp>

#include <gtest/gtest.h>

#include <fcl/fcl.h>

#include <cmath>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "collide_test_support.hpp"

namespace {

using dm::Isometry3;
using dm::Vec3;

Isometry3 pose(std::mt19937_64& rng, double maxOffset) {
  std::normal_distribution<double> g(0.0, 1.0);
  Isometry3 p = Isometry3::Identity();
  p.linear() = dm::Quat(Eigen::Vector4d(g(rng), g(rng), g(rng), g(rng)).normalized()).toRotationMatrix();
  std::uniform_real_distribution<double> u(-maxOffset, maxOffset);
  p.translation() = Vec3(u(rng), u(rng), u(rng));
  return p;
}

using dm::test::at;

struct Fcl {
  std::shared_ptr<fcl::CollisionGeometryd> g;
};

double fclDistance(const Fcl& a, const Isometry3& pa, const Fcl& b, const Isometry3& pb) {
  fcl::CollisionObjectd oa(a.g, pa), ob(b.g, pb);
  fcl::DistanceRequestd req;
  fcl::DistanceResultd res;
  fcl::distance(&oa, &ob, req, res);
  return res.min_distance;
}

// FCL's deepest contact (depth, normal A → B) or depth −1 when apart.
std::pair<double, Vec3> fclContact(const Fcl& a, const Isometry3& pa, const Fcl& b, const Isometry3& pb) {
  fcl::CollisionObjectd oa(a.g, pa), ob(b.g, pb);
  fcl::CollisionRequestd req(8, true);
  fcl::CollisionResultd res;
  fcl::collide(&oa, &ob, req, res);
  double depth = -1;
  Vec3 n = Vec3::Zero();
  for (std::size_t i = 0; i < res.numContacts(); ++i)
    if (res.getContact(i).penetration_depth > depth)
      depth = res.getContact(i).penetration_depth, n = res.getContact(i).normal;
  return {depth, n};
}

// The analytic pairs against FCL's closed forms (sphere–sphere, sphere–box,
// sphere–capsule, capsule–capsule), in both orders, 2,000 poses each:
// distance to 1e-9 m where separated, penetration depth and normal to 1e-9
// where FCL has the closed form (sphere–sphere, sphere–box), booleans
// everywhere outside a 1e-9 m band.
TEST(Query, AnalyticPairsMatchFcl) {
  const dm::Sphere sphere(0.3), small(0.1);
  const dm::Box box(Vec3(0.4, 0.25, 0.15));
  const dm::Capsule capsule(0.2, 0.3), thin(0.05, 0.4);
  const Fcl fSphere{std::make_shared<fcl::Sphered>(0.3)}, fSmall{std::make_shared<fcl::Sphered>(0.1)};
  const Fcl fBox{std::make_shared<fcl::Boxd>(0.8, 0.5, 0.3)};
  const Fcl fCapsule{std::make_shared<fcl::Capsuled>(0.2, 0.6)},
      fThin{std::make_shared<fcl::Capsuled>(0.05, 0.8)};
  struct Case {
    const dm::Shape* a;
    const Fcl* fa;
    const dm::Shape* b;
    const Fcl* fb;
    bool depthInFcl;
  };
  const Case cases[] = {{&sphere, &fSphere, &small, &fSmall, true},
                        {&sphere, &fSphere, &box, &fBox, true},
                        {&small, &fSmall, &capsule, &fCapsule, false},
                        {&capsule, &fCapsule, &thin, &fThin, false}};
  std::mt19937_64 rng(21);
  for (const Case& c : cases) {
    const std::string name =
        std::string(dm::shapeTypeName(c.a->type())) + "-" + std::string(dm::shapeTypeName(c.b->type()));
    int separated = 0, overlapping = 0;
    for (int k = 0; k < 2000; ++k) {
      const Isometry3 pa = pose(rng, 0.1), pb = pose(rng, 0.7);
      const dm::DistanceResult d = dm::distance(*c.a, pa, *c.b, pb);
      ASSERT_TRUE(d.supported);
      // Swapped order: same distance, points exchanged.
      const dm::DistanceResult e = dm::distance(*c.b, pb, *c.a, pa);
      ASSERT_NEAR(e.distance, d.distance, 1e-12);
      ASSERT_LT((e.pointA - d.pointB).norm(), 1e-12);
      if (d.distance > 0) {
        ++separated;
        ASSERT_NEAR(d.distance, fclDistance(*c.fa, pa, *c.fb, pb), 1e-9) << name << " pose " << k;
        ASSERT_NEAR((d.pointB - d.pointA).norm(), d.distance, 1e-12);
      } else {
        ++overlapping;
        dm::CollisionResult hit = dm::collide(*c.a, pa, *c.b, pb);
        ASSERT_TRUE(hit.colliding);
        ASSERT_EQ(hit.contacts.size(), 1u);
        ASSERT_NEAR(hit.contacts[0].depth, -d.distance, 1e-12);
        if (c.depthInFcl) {
          const auto [depth, normal] = fclContact(*c.fa, pa, *c.fb, pb);
          ASSERT_NEAR(hit.contacts[0].depth, depth, 1e-9) << name << " pose " << k;
          ASSERT_NEAR(hit.contacts[0].normal.dot(normal), 1.0, 1e-9) << name << " pose " << k;
        }
        // B−A order flips the normal.
        const dm::CollisionResult flipped = dm::collide(*c.b, pb, *c.a, pa);
        ASSERT_NEAR((flipped.contacts[0].normal + hit.contacts[0].normal).norm(), 0.0, 1e-12);
      }
      if (std::abs(d.distance) > 1e-9) {
        ASSERT_EQ(dm::intersect(*c.a, pa, *c.b, pb), d.distance < 0) << name << " pose " << k;
        ASSERT_EQ(dm::intersect(*c.b, pb, *c.a, pa), d.distance < 0) << name << " pose " << k;
      }
    }
    EXPECT_GT(separated, 300) << name;
    EXPECT_GT(overlapping, 150) << name;
  }
}

// A cube resting on a larger box, overlapping by 1 cm: four contacts at the
// cube's bottom corners, depth 0.01 m, normal +z (from A to B).
TEST(Query, BoxBoxFaceContact) {
  const dm::Box base(Vec3(1.0, 1.0, 0.5)), cube(Vec3(0.2, 0.2, 0.2));
  for (double angle : {0.0, 0.5, 1.2}) {
    Isometry3 pb = at(0.1, -0.2, 0.69);
    pb.linear() = dm::AngleAxis(angle, Vec3::UnitZ()).toRotationMatrix();
    dm::CollisionResult res;
    dm::collide(base, Isometry3::Identity(), cube, pb, {true, 8}, res);
    ASSERT_TRUE(res.colliding);
    ASSERT_EQ(res.contacts.size(), 4u) << angle;
    for (const auto& c : res.contacts) {
      EXPECT_NEAR(c.depth, 0.01, 1e-12);
      EXPECT_NEAR(c.normal.z(), 1.0, 1e-12);
      EXPECT_NEAR(c.position.z(), 0.495, 1e-12);
      // Each contact sits under a corner of the cube.
      const Vec3 local = pb.inverse() * c.position;
      EXPECT_NEAR(std::abs(local.x()), 0.2, 1e-12);
      EXPECT_NEAR(std::abs(local.y()), 0.2, 1e-12);
    }
    // Swapped: normal −z.
    dm::collide(cube, pb, base, Isometry3::Identity(), {true, 8}, res);
    ASSERT_EQ(res.contacts.size(), 4u);
    EXPECT_NEAR(res.contacts[0].normal.z(), -1.0, 1e-12);
  }
}

// Random overlapping boxes: the manifold depth is the separating-axis
// minimum (face axes preferred within 5 %), agrees with FCL's boolean, and
// every contact lies within depth of both boxes.
TEST(Query, BoxBoxManifoldIsConsistent) {
  const dm::Box a(Vec3(0.3, 0.2, 0.1)), b(Vec3(0.15, 0.25, 0.2));
  const Fcl fa{std::make_shared<fcl::Boxd>(0.6, 0.4, 0.2)}, fb{std::make_shared<fcl::Boxd>(0.3, 0.5, 0.4)};
  auto outside = [](const dm::Box& box, const Isometry3& p, const Vec3& x) {
    const Vec3 l = p.inverse() * x;
    return (l.cwiseAbs() - box.halfExtents()).cwiseMax(0.0).norm();
  };
  std::mt19937_64 rng(8);
  dm::CollisionResult res;
  int hits = 0, apartCount = 0, tight = 0;
  for (int k = 0; k < 2000; ++k) {
    const Isometry3 pa = pose(rng, 0.05), pb = pose(rng, 0.5);
    dm::collide(a, pa, b, pb, {true, 8}, res);
    const auto [fclDepth, fclNormal] = fclContact(fa, pa, fb, pb);
    const dm::DistanceResult exact = dm::distance(a, pa, b, pb);  // GJK/EPA: exact for boxes
    if (std::abs(exact.distance) > 1e-9) {
      ASSERT_EQ(res.colliding, exact.distance < 0) << k;
      ASSERT_EQ(res.colliding, fclDepth >= 0) << k;
      ASSERT_EQ(dm::intersect(a, pa, b, pb), res.colliding) << k;
    }
    if (!res.colliding) {
      // The separating axis' gap: a positive lower bound on the distance.
      ASSERT_GT(res.separation, 0.0) << k;
      ASSERT_LE(res.separation, exact.distance + 1e-12) << k;
      ++apartCount;
      if (res.separation > 0.5 * exact.distance) ++tight;
      continue;
    }
    ASSERT_EQ(res.separation, 0.0) << k;
    ++hits;
    ASSERT_GE(res.contacts.size(), 1u);
    ASSERT_LE(res.contacts.size(), 8u);
    const double mtd = -exact.distance;
    for (const auto& c : res.contacts) {
      ASSERT_LE(c.depth, mtd / 0.95 + 1e-9) << k;
      ASSERT_NEAR(c.normal.norm(), 1.0, 1e-12);
      ASSERT_LE(outside(a, pa, c.position), c.depth + 1e-9) << k;
      ASSERT_LE(outside(b, pb, c.position), c.depth + 1e-9) << k;
    }
    // The deepest contact is at least the minimum translation distance.
    double deepest = 0;
    for (const auto& c : res.contacts) deepest = std::max(deepest, c.depth);
    ASSERT_GE(deepest, mtd - 1e-9) << k;
    // Moving B by the deepest depth along the normal separates the boxes.
    Isometry3 moved = pb;
    moved.translation() += deepest * res.contacts[0].normal;
    ASSERT_GE(dm::distance(a, pa, b, moved).distance, -1e-9) << k;
  }
  EXPECT_GT(hits, 300);
  EXPECT_GT(apartCount, 300);
  EXPECT_GT(tight, apartCount / 2);  // a useful bound, not just a positive number
  // Face to face along x, 0.05 m apart: the bound is the gap itself.
  dm::collide(a, Isometry3::Identity(), b, Eigen::Translation3d(0.3 + 0.15 + 0.05, 0, 0) * Isometry3::Identity(),
              {true, 8}, res);
  EXPECT_FALSE(res.colliding);
  EXPECT_NEAR(res.separation, 0.05, 1e-12);  // less the 1e-14 parallel-edge guard on |R|
}

// A box on a plane, tilted about one axis: the two lower-edge vertices touch;
// flat: four vertices. Plane–sphere distance is the height minus the radius.
TEST(Query, PlaneContacts) {
  const dm::Plane ground(Vec3::UnitZ(), 0.0);  // z ≤ 0 is solid
  const dm::Box box(Vec3(0.1, 0.2, 0.3));
  dm::CollisionResult res;
  dm::collide(ground, Isometry3::Identity(), box, at(0, 0, 0.29), {}, res);
  ASSERT_EQ(res.contacts.size(), 4u);
  for (const auto& c : res.contacts) {
    EXPECT_NEAR(c.depth, 0.01, 1e-12);
    EXPECT_NEAR(c.normal.z(), 1.0, 1e-15);
  }
  Isometry3 tilted = at(0, 0, 0.0);
  tilted.linear() = dm::AngleAxis(0.3, Vec3::UnitX()).toRotationMatrix();
  const double lowest = 0.2 * std::sin(0.3) + 0.3 * std::cos(0.3);
  tilted.translation().z() = lowest - 0.005;
  dm::collide(ground, Isometry3::Identity(), box, tilted, {}, res);
  ASSERT_EQ(res.contacts.size(), 2u);
  EXPECT_NEAR(res.contacts[0].depth, 0.005, 1e-12);

  const dm::Sphere ball(0.05);
  const dm::DistanceResult d = dm::distance(ball, at(0.3, 0.1, 0.2), ground, Isometry3::Identity());
  EXPECT_NEAR(d.distance, 0.15, 1e-15);
  EXPECT_NEAR(d.pointB.z(), 0.0, 1e-15);
  EXPECT_TRUE(dm::intersect(ground, Isometry3::Identity(), ball, at(0, 0, 0.04)));
  EXPECT_FALSE(dm::intersect(ball, at(0, 0, 0.06), ground, Isometry3::Identity()));
}

// Sphere–triangle: above the face, beside an edge, beyond a vertex.
TEST(Query, SphereTriangle) {
  const dm::TriangleShape tri(Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0));
  const dm::Sphere ball(0.1);
  EXPECT_NEAR(dm::distance(tri, Isometry3::Identity(), ball, at(0.2, 0.2, 0.5)).distance, 0.4, 1e-15);
  EXPECT_NEAR(dm::distance(tri, Isometry3::Identity(), ball, at(0.5, -0.3, 0.4)).distance, 0.4, 1e-15);
  EXPECT_NEAR(dm::distance(ball, at(-0.3, -0.4, 0.0), tri, Isometry3::Identity()).distance, 0.4, 1e-15);
  const dm::CollisionResult hit = dm::collide(tri, Isometry3::Identity(), ball, at(0.2, 0.2, 0.08));
  ASSERT_TRUE(hit.colliding);
  EXPECT_NEAR(hit.contacts[0].depth, 0.02, 1e-15);
  EXPECT_NEAR(hit.contacts[0].normal.z(), 1.0, 1e-15);
}

// Compounds dispatch over their children, in either position.
TEST(Query, CompoundDispatchesOverChildren) {
  auto ball = std::make_shared<dm::Sphere>(0.1);
  const dm::Compound dumbbell({{ball, at(-0.5, 0, 0)}, {ball, at(0.5, 0, 0)}});
  const dm::Box box(Vec3(0.1, 0.1, 0.1));
  EXPECT_NEAR(dm::distance(dumbbell, Isometry3::Identity(), box, at(0.9, 0, 0)).distance, 0.2, 1e-15);
  EXPECT_NEAR(dm::distance(box, at(0, 0, 0), dumbbell, Isometry3::Identity()).distance, 0.3, 1e-15);
  EXPECT_FALSE(dm::intersect(dumbbell, Isometry3::Identity(), box, at(0, 0, 0)));
  EXPECT_TRUE(dm::intersect(box, at(0.65, 0, 0), dumbbell, Isometry3::Identity()));
  const dm::CollisionResult r = dm::collide(box, at(0.65, 0, 0), dumbbell, Isometry3::Identity());
  ASSERT_EQ(r.contacts.size(), 1u);
  // Box children apart: one child's gap bounds nothing for the compound.
  const auto cube = std::make_shared<dm::Box>(Vec3(0.1, 0.1, 0.1));
  const dm::Compound pair({{cube, at(-0.5, 0, 0)}, {cube, at(0.5, 0, 0)}});
  EXPECT_GT(dm::collide(box, at(0.3, 0, 0), *cube, Isometry3::Identity()).separation, 0.0);
  const dm::CollisionResult apart = dm::collide(pair, Isometry3::Identity(), box, at(0.75, 0, 0));
  EXPECT_FALSE(apart.colliding);
  EXPECT_EQ(apart.separation, 0.0);
  EXPECT_NEAR(r.contacts[0].depth, 0.05, 1e-15);
  EXPECT_NEAR(r.contacts[0].normal.x(), -1.0, 1e-15);  // from the box to the ball at x = 0.5
  EXPECT_NEAR(dumbbell.aabb(Isometry3::Identity()).max().x(), 0.6, 1e-15);
}

// A plugin-style shape type: GJK serves it at once; a registered collider
// replaces GJK for one pair and serves the swapped order with flipped normals.
class Tetra final : public dm::ConvexShape {
 public:
  explicit Tetra(dm::ShapeType t) : ConvexShape(t, 0.0) {}
  Vec3 supportCore(const Vec3& d, std::uint32_t&) const noexcept override {
    static const Vec3 v[4] = {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(0, 0, 1)};
    int best = 0;
    for (int i = 1; i < 4; ++i)
      if (d.dot(v[i]) > d.dot(v[best])) best = i;
    return v[best];
  }
  dm::Aabb localAabb() const noexcept override { return dm::Aabb(Vec3::Zero(), Vec3::Ones()); }
  double volume() const noexcept override { return 1.0 / 6.0; }
};

TEST(Query, UserShapeTypeAndColliderRegistration) {
  auto id = dm::registerShapeType("test-tetra");
  ASSERT_TRUE(id.ok());
  EXPECT_EQ(*dm::registerShapeType("test-tetra"), *id);  // idempotent
  EXPECT_EQ(dm::shapeTypeName(*id), "test-tetra");
  EXPECT_FALSE(dm::registerShapeType("sphere").ok());
  EXPECT_FALSE(dm::registerShapeType("").ok());

  const Tetra tetra(*id);
  const dm::Sphere ball(0.1);
  // GJK: the tetrahedron's slanted face x + y + z = 1 is 1/√3 from the origin.
  const double gap = std::sqrt(3.0) - 1.0 / std::sqrt(3.0) - 0.1;
  EXPECT_NEAR(dm::distance(tetra, Isometry3::Identity(), ball, at(1, 1, 1)).distance, gap, 1e-12);

  dm::ColliderTable& table = dm::ColliderTable::global();
  dm::Collider fixed;
  fixed.intersect = [](const dm::Shape&, const Isometry3&, const dm::Shape&, const Isometry3&,
                       dm::PairCache*) { return true; };
  fixed.contacts = [](const dm::Shape&, const Isometry3&, const dm::Shape&, const Isometry3&,
                      const dm::CollisionRequest&, dm::CollisionResult& out, dm::PairCache*) {
    out.colliding = true;
    out.contacts.push_back({Vec3::Zero(), Vec3::UnitX(), 0.5});
  };
  fixed.distance = [](const dm::Shape&, const Isometry3&, const dm::Shape&, const Isometry3&,
                      dm::PairCache*) {
    dm::DistanceResult d;
    d.distance = -0.5;
    d.pointA = Vec3::UnitX();
    return d;
  };
  ASSERT_TRUE(table.registerCollider(*id, dm::ShapeType::Sphere, fixed).ok());
  EXPECT_TRUE(dm::intersect(ball, at(9, 9, 9), tetra, Isometry3::Identity()));
  const dm::CollisionResult r = dm::collide(ball, at(9, 9, 9), tetra, Isometry3::Identity());
  ASSERT_EQ(r.contacts.size(), 1u);
  EXPECT_NEAR(r.contacts[0].normal.x(), -1.0, 0.0);  // swapped order flips
  EXPECT_NEAR(dm::distance(ball, at(9, 9, 9), tetra, Isometry3::Identity()).pointB.x(), 1.0, 0.0);
  EXPECT_FALSE(table.registerCollider(static_cast<dm::ShapeType>(dm::kMaxShapeTypes), *id, fixed).ok());
  EXPECT_FALSE(table.registerCollider(*id, *id, dm::Collider{}).ok());
}

// A closed unit cube centred at the origin, outward CCW triangles.
std::shared_ptr<const dm::Mesh> unitCube() {
  return std::make_shared<const dm::Mesh>(dm::makeBox(Vec3(0.5, 0.5, 0.5)));
}

// Mesh pairs through the table against the closed-form answers for a unit
// cube: mesh–sphere, mesh–capsule, mesh–mesh and the mesh raycaster, in both
// argument orders.
TEST(Query, MeshPairsThroughTheTable) {
  auto cube = dm::TriangleMesh::create(unitCube());
  ASSERT_TRUE(cube) << cube.error();
  const dm::TriangleMesh& mesh = **cube;
  const dm::Sphere ball(0.1);
  ASSERT_TRUE(dm::ColliderTable::global().check(mesh, ball).ok());

  dm::DistanceResult d = dm::distance(mesh, Isometry3::Identity(), ball, at(0.8, 0.1, 0.2));
  EXPECT_NEAR(d.distance, 0.2, 1e-12);
  EXPECT_NEAR(d.pointA.x(), 0.5, 1e-12);  // on the cube face
  EXPECT_NEAR(d.pointB.x(), 0.7, 1e-12);  // on the sphere
  d = dm::distance(ball, at(0.8, 0.1, 0.2), mesh, Isometry3::Identity());
  EXPECT_NEAR(d.distance, 0.2, 1e-12);
  EXPECT_NEAR(d.pointA.x(), 0.7, 1e-12);

  dm::CollisionResult r = dm::collide(mesh, Isometry3::Identity(), ball, at(0.55, 0, 0));
  ASSERT_TRUE(r.colliding);
  ASSERT_EQ(r.contacts.size(), 1u);
  EXPECT_NEAR(r.contacts[0].depth, 0.05, 1e-12);
  EXPECT_NEAR(r.contacts[0].normal.x(), 1.0, 1e-12);  // A (cube) -> B (ball)
  r = dm::collide(ball, at(0.55, 0, 0), mesh, Isometry3::Identity());
  ASSERT_EQ(r.contacts.size(), 1u);
  EXPECT_NEAR(r.contacts[0].normal.x(), -1.0, 1e-12);  // swapped order flips
  EXPECT_FALSE(dm::intersect(mesh, Isometry3::Identity(), ball, at(0.61, 0, 0)));

  const dm::Capsule pill(0.1, 0.2);  // along z
  EXPECT_NEAR(dm::distance(mesh, Isometry3::Identity(), pill, at(0.7, 0, 0)).distance, 0.1, 1e-12);
  EXPECT_NEAR(dm::distance(mesh, Isometry3::Identity(), pill, at(0, 0, 1.0)).distance, 0.2, 1e-12);
  EXPECT_TRUE(dm::intersect(pill, at(0, 0, 0.75), mesh, Isometry3::Identity()));

  const dm::TriangleMesh& other = mesh;  // the same shape at two poses
  EXPECT_NEAR(dm::distance(mesh, Isometry3::Identity(), other, at(1.5, 0, 0)).distance, 0.5, 1e-12);
  EXPECT_TRUE(dm::intersect(mesh, Isometry3::Identity(), other, at(0.9, 0.2, 0.1)));
  EXPECT_TRUE(dm::collide(mesh, Isometry3::Identity(), other, at(0.9, 0.2, 0.1)).colliding);
  EXPECT_FALSE(dm::intersect(mesh, Isometry3::Identity(), other, at(1.01, 0, 0)));

  const auto hit = dm::raycast(mesh, at(0, 0, 0), dm::Ray{Vec3(-2, 0.1, 0.1), Vec3::UnitX(), 10.0});
  ASSERT_TRUE(hit);
  EXPECT_NEAR(hit->t, 1.5, 1e-12);
  EXPECT_NEAR(hit->normal.x(), -1.0, 1e-12);
}

// Pairs without a collider say so instead of answering wrongly: a mesh
// without its BVH, and (mesh, box) which has no collider yet.
TEST(Query, MeshPairsWithoutAColliderReportUnsupported) {
  const dm::TriangleMesh bare(unitCube(), nullptr);
  const dm::Sphere ball(0.1);
  EXPECT_FALSE(dm::distance(bare, Isometry3::Identity(), ball, Isometry3::Identity()).supported);
  EXPECT_FALSE(dm::collide(bare, Isometry3::Identity(), ball, Isometry3::Identity()).supported);
  EXPECT_FALSE(dm::intersect(bare, Isometry3::Identity(), ball, Isometry3::Identity()));
  auto cube = dm::TriangleMesh::create(unitCube());
  ASSERT_TRUE(cube);
  // A half-space against a mesh has no built-in collider (a plugin adds one:
  // collider_plugin_test.cpp).
  const dm::Plane ground(Vec3::UnitZ(), 0.0);
  const dm::Status s = dm::ColliderTable::global().check(ground, **cube);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.error().message().find("no collider for (plane, triangle-mesh)"), std::string::npos)
      << s.error().message();
  EXPECT_FALSE(dm::collide(**cube, Isometry3::Identity(), ground, Isometry3::Identity()).supported);
}

// A closed mesh is a solid for every convex shape: a sphere or capsule
// inside it, touching no triangle, collides with the push-out depth (the
// nearest face plus the radius), the same rule as for a box.
TEST(Query, RoundShapesInsideAClosedMeshAreEnclosed) {
  auto cube = dm::TriangleMesh::create(unitCube());  // [-0.5, 0.5]³
  ASSERT_TRUE(cube);
  const dm::Sphere ball(0.1);
  const dm::Capsule rod(0.05, 0.1);  // along z: core from z −0.1 to 0.1
  const dm::Box block(Vec3(0.1, 0.1, 0.1));
  const Isometry3 pose = at(0.2, 0.0, 0.0);  // nearest face x = 0.5, 0.3 away
  EXPECT_TRUE(dm::intersect(**cube, Isometry3::Identity(), ball, pose));
  EXPECT_TRUE(dm::intersect(**cube, Isometry3::Identity(), rod, pose));
  const dm::DistanceResult db = dm::distance(**cube, Isometry3::Identity(), ball, pose);
  EXPECT_NEAR(db.distance, -(0.3 + 0.1), 1e-12);
  EXPECT_NEAR(db.pointA.x(), 0.5, 1e-12);  // on the face
  EXPECT_NEAR(db.pointB.x(), 0.1, 1e-12);  // the ball's deepest point
  EXPECT_NEAR(dm::distance(**cube, Isometry3::Identity(), rod, pose).distance, -(0.3 + 0.05), 1e-12);
  EXPECT_NEAR(dm::distance(**cube, Isometry3::Identity(), block, pose).distance, -(0.3 + 0.1), 1e-12);
  const dm::CollisionResult c = dm::collide(**cube, Isometry3::Identity(), ball, pose);
  ASSERT_EQ(c.contacts.size(), 1u);
  EXPECT_NEAR(c.contacts[0].depth, 0.4, 1e-12);
  EXPECT_NEAR(c.contacts[0].normal.x(), 1.0, 1e-12);  // the ball leaves through x = 0.5
  // Outside the cube the same shapes are apart, with the plain gap.
  EXPECT_NEAR(dm::distance(**cube, Isometry3::Identity(), ball, at(0.8, 0, 0)).distance, 0.2, 1e-12);
  EXPECT_FALSE(dm::intersect(**cube, Isometry3::Identity(), ball, at(0.8, 0, 0)));
}

// A reused result keeps its buffer: no allocation once it is large enough.
TEST(Query, ReusedResultKeepsItsBuffer) {
  const dm::Box a(Vec3(1, 1, 0.5)), b(Vec3(0.2, 0.2, 0.2));
  dm::CollisionResult res;
  res.contacts.reserve(8);
  const auto* buffer = res.contacts.data();
  for (int k = 0; k < 100; ++k) {
    dm::collide(a, Isometry3::Identity(), b, at(0.01 * k, 0, 0.69), {true, 8}, res);
    ASSERT_EQ(res.contacts.data(), buffer);
  }
}

// Ray casts against closed forms: sphere, box, plane, and by conservative
// advancement a cylinder (side and cap) and an ellipsoid, in posed frames.
TEST(Query, RaycastMatchesClosedForms) {
  std::mt19937_64 rng(4);
  const dm::Sphere sphere(0.5);
  const dm::Box box(Vec3(0.3, 0.4, 0.5));
  const dm::Cylinder cyl(0.25, 0.5);
  const dm::Ellipsoid ell(Vec3(0.5, 0.3, 0.2));
  std::vector<Vec3> corners;
  for (int k = 0; k < 8; ++k)
    corners.emplace_back(k & 1 ? 0.5 : -0.5, k & 2 ? 0.5 : -0.5, k & 4 ? 0.5 : -0.5);
  const auto cube = dm::ConvexHull::create(corners);
  ASSERT_TRUE(cube.ok());
  for (int k = 0; k < 200; ++k) {
    const Isometry3 p = pose(rng, 1.0);
    // Sphere: from 2 m away towards a point at lateral offset 0.3.
    const Vec3 dir = p.linear() * Vec3::UnitX();
    dm::Ray ray{p * Vec3(-2.0, 0.3, 0.0), dir};
    auto hit = dm::raycast(sphere, p, ray);
    ASSERT_TRUE(hit);
    EXPECT_NEAR(hit->t, 2.0 - 0.4, 1e-12);
    EXPECT_NEAR(hit->normal.dot(p.linear() * Vec3(-0.8, 0.6, 0)), 1.0, 1e-12);
    // Box: the face x = −0.3.
    hit = dm::raycast(box, p, {p * Vec3(-2.0, 0.1, 0.2), dir});
    ASSERT_TRUE(hit);
    EXPECT_NEAR(hit->t, 1.7, 1e-12);
    EXPECT_NEAR(hit->normal.dot(-dir), 1.0, 1e-12);
    // Cylinder side at y = 0.15: x = −√(0.25² − 0.15²) = −0.2.
    hit = dm::raycast(cyl, p, {p * Vec3(-2.0, 0.15, 0.1), dir});
    ASSERT_TRUE(hit);
    EXPECT_NEAR(hit->t, 1.8, 1e-12);
    EXPECT_NEAR(hit->normal.dot(p.linear() * Vec3(-0.8, 0.6, 0)), 1.0, 1e-12);
    // Cylinder cap from above.
    hit = dm::raycast(cyl, p, {p * Vec3(0.1, 0.1, 2.0), p.linear() * -Vec3::UnitZ()});
    ASSERT_TRUE(hit);
    EXPECT_NEAR(hit->t, 1.5, 1e-12);
    EXPECT_NEAR(hit->normal.dot(p.linear() * Vec3::UnitZ()), 1.0, 1e-12);
    // Ellipsoid along y at x = 0.3: y = −0.3·√(1 − 0.36) = −0.24, by
    // conservative advancement (GJK converges linearly on curved shapes).
    hit = dm::raycast(ell, p, {p * Vec3(0.3, -2.0, 0.0), p.linear() * Vec3::UnitY()});
    ASSERT_TRUE(hit);
    EXPECT_NEAR(hit->t, 2.0 - 0.24, 1e-8);
    const Vec3 grad(0.3 / 0.25, -0.24 / 0.09, 0.0);  // ∇(x²/a² + y²/b² + z²/c²)/2
    EXPECT_NEAR(hit->normal.dot(p.linear() * grad.normalized()), 1.0, 1e-6);
    // A hull (flat faces): the unit cube's face x = −0.5, exact.
    hit = dm::raycast(**cube, p, {p * Vec3(-2.0, 0.2, -0.1), dir});
    ASSERT_TRUE(hit);
    EXPECT_NEAR(hit->t, 1.5, 1e-12);
    EXPECT_NEAR(hit->normal.dot(-dir), 1.0, 1e-9);
    // Misses, a hit beyond maxDistance, and a start inside.
    EXPECT_FALSE(dm::raycast(sphere, p, {p * Vec3(-2.0, 0.6, 0.0), dir}));
    EXPECT_FALSE(dm::raycast(cyl, p, {p * Vec3(-2.0, 0.3, 0.0), dir}));
    EXPECT_FALSE(dm::raycast(box, p, {p * Vec3(-2.0, 0.0, 0.0), dir, 1.0}));
    hit = dm::raycast(ell, p, {p * Vec3(0.1, 0.0, 0.0), dir});
    ASSERT_TRUE(hit);
    EXPECT_EQ(hit->t, 0.0);
  }
  const dm::Plane ground(Vec3::UnitZ(), 0.0);
  auto hit = dm::raycast(ground, Isometry3::Identity(), {Vec3(0, 0, 2), Vec3(0, 0.6, -0.8)});
  ASSERT_TRUE(hit);
  EXPECT_NEAR(hit->t, 2.5, 1e-15);
}

}  // namespace
