// The ODE backend against the built-in contact solver and closed forms:
// free fall, sliding on a slope with Coulomb friction, a resting box, a
// bouncing ball, a hinge pendulum, a cylinder standing and lying, a ball
// rolling in a tessellated bowl (a static triangle mesh), a convex hull at rest, with
// ODE's contact forces against the weight; unsupported scenes give errors
// naming the body.
#include <dm/collide/shapes.hpp>
#include <dm/math/primitives.hpp>
#include <dm/physics/ode_backend.hpp>
#include <dm/physics/world.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <memory>
#include <numbers>

#include "physics_test_support.hpp"

namespace {

using dm::BodyId;
using dm::PhysicsWorld;
using dm::Vec3;
using dm::WorldState;

using dm::test::kG;
constexpr double kDt = 1e-3;

/// A rigid body of `shape` with the solid's inertia, or a static one.
BodyId add(PhysicsWorld& w, std::shared_ptr<const dm::Shape> shape, double mass, const Vec3& x,
           const dm::Quat& q = dm::Quat::Identity(), dm::ContactMaterial m = {}) {
  dm::BodyDesc d;
  d.kind = mass > 0 ? dm::BodyKind::Rigid : dm::BodyKind::Static;
  d.mass = mass > 0 ? mass : 1.0;
  if (shape->type() == dm::ShapeType::Box)
    d.inertia = dm::boxInertia(d.mass, static_cast<const dm::Box&>(*shape).halfExtents());
  else if (shape->type() == dm::ShapeType::Sphere)
    d.inertia = dm::sphereInertia(d.mass, static_cast<const dm::Sphere&>(*shape).radius());
  d.position = x;
  d.orientation = q;
  d.shape = std::move(shape);
  const BodyId id = *w.addBody(d);
  EXPECT_TRUE(w.setMaterial(id, m).ok());
  return id;
}

/// Runs the world for `steps` on both backends; `probe` sees each state after
/// every step (backend 0: built-in, 1: ODE).
void runBoth(const PhysicsWorld& w, int steps, const std::function<void(int, const WorldState&)>& probe) {
  WorldState built = w.makeState(), ode = w.makeState();
  auto backend = dm::OdeWorld::create(w, {.iterations = 20});
  ASSERT_TRUE(backend.ok()) << backend.error().message();
  for (int i = 0; i < steps; ++i) {
    ASSERT_TRUE(w.step(built, kDt).ok());
    ASSERT_TRUE(backend->step(ode, kDt).ok());
    probe(0, built);
    probe(1, ode);
  }
}

TEST(OdeBackend, FreeFallAgreesWithBuiltInAndClosedForm) {
  PhysicsWorld w;
  const BodyId ball = add(w, std::make_shared<dm::Sphere>(0.1), 2.0, {0, 0, 10});
  ASSERT_TRUE(w.setGravity({0, 0, -kG}).ok());
  double z[2] = {0, 0}, t = 0;
  runBoth(w, 1000, [&](int k, const WorldState& s) {
    z[k] = s.position(ball).z();
    t = s.time();
  });
  const double exact = 10.0 - 0.5 * kG * t * t;
  // First-order steppers: error ≤ g·dt·t/2 ≈ 5 mm after 1 s.
  EXPECT_NEAR(z[0], exact, 6e-3);
  EXPECT_NEAR(z[1], exact, 6e-3);
  EXPECT_NEAR(z[0], z[1], 1e-2);
}

TEST(OdeBackend, SlopeSlidingAccelerationAgrees) {
  const double theta = 20.0 * std::numbers::pi / 180.0, mu = 0.2;
  PhysicsWorld w;
  const Vec3 n(0, -std::sin(theta), std::cos(theta));
  add(w, std::make_shared<dm::Plane>(n, 0.0), 0.0, Vec3::Zero(), dm::Quat::Identity(), {.friction = mu});
  const double h = 0.05;
  const BodyId box = add(w, std::make_shared<dm::Box>(Vec3(0.1, 0.1, h)), 1.0, n * h,
                         dm::Quat(Eigen::AngleAxisd(theta, Vec3::UnitX())), {.friction = mu});
  ASSERT_TRUE(w.setGravity({0, 0, -kG}).ok());
  const Vec3 down(0, -std::cos(theta), -std::sin(theta));
  double travel[2] = {0, 0}, t = 0;
  runBoth(w, 1000, [&](int k, const WorldState& s) {
    travel[k] = (s.position(box) - n * h).dot(down);
    t = s.time();
  });
  const double expected = 0.5 * kG * (std::sin(theta) - mu * std::cos(theta)) * t * t;
  EXPECT_NEAR(travel[0], expected, 0.05 * expected);
  EXPECT_NEAR(travel[1], expected, 0.05 * expected);
}

TEST(OdeBackend, RestingBoxStaysOnBothBackends) {
  PhysicsWorld w;
  add(w, std::make_shared<dm::Plane>(Vec3::UnitZ(), 0.0), 0.0, Vec3::Zero());
  const BodyId box = add(w, std::make_shared<dm::Box>(Vec3(0.1, 0.2, 0.05)), 3.0, {0, 0, 0.05});
  ASSERT_TRUE(w.setGravity({0, 0, -kG}).ok());
  double drift[2] = {0, 0};
  runBoth(w, 2000, [&](int k, const WorldState& s) {
    drift[k] = std::max(drift[k], (s.position(box) - Vec3(0, 0, 0.05)).norm());
  });
  EXPECT_LT(drift[0], 1e-3);
  EXPECT_LT(drift[1], 1e-3);
}

TEST(OdeBackend, BounceHeightAgrees) {
  const double e = 0.5, r = 0.05, h0 = 1.0;
  PhysicsWorld w;
  add(w, std::make_shared<dm::Plane>(Vec3::UnitZ(), 0.0), 0.0, Vec3::Zero(), dm::Quat::Identity(),
      {.friction = 0.0, .restitution = e});
  const BodyId ball = add(w, std::make_shared<dm::Sphere>(r), 1.0, {0, 0, r + h0}, dm::Quat::Identity(),
                          {.friction = 0.0, .restitution = e});
  ASSERT_TRUE(w.setGravity({0, 0, -kG}).ok());
  bool bounced[2] = {false, false};
  double apex[2] = {0, 0};
  runBoth(w, 900, [&](int k, const WorldState& s) {
    if (s.linearVelocity(ball).z() > 0) bounced[k] = true;
    if (bounced[k]) apex[k] = std::max(apex[k], s.position(ball).z() - r);
  });
  ASSERT_TRUE(bounced[0] && bounced[1]);
  EXPECT_NEAR(apex[0], e * e * h0, 0.03 * e * e * h0);
  EXPECT_NEAR(apex[1], e * e * h0, 0.05 * e * e * h0);
}

TEST(OdeBackend, HingePendulumPeriodAgrees) {
  const double length = 0.5, theta0 = 0.05;
  PhysicsWorld w;
  dm::BodyDesc bob;
  bob.kind = dm::BodyKind::Rigid;
  const double r = 0.02;  // a small solid sphere: physical-pendulum inertia m r²·2/5 + m L²
  bob.inertia = dm::sphereInertia(1.0, r);
  bob.position = Vec3(length * std::sin(theta0), 0, -length * std::cos(theta0));
  const BodyId b = *w.addBody(bob);
  ASSERT_TRUE(w.addJoint({.type = dm::JointType::Hinge, .b = b, .axis = Vec3::UnitY()}).ok());
  ASSERT_TRUE(w.setGravity({0, 0, -kG}).ok());
  std::vector<double> crossings[2];
  double prev[2] = {bob.position.x(), bob.position.x()}, reach[2] = {0, 0};
  runBoth(w, 4000, [&](int k, const WorldState& s) {
    const double x = s.position(b).x();
    reach[k] = s.position(b).norm();
    if (prev[k] > 0 && x <= 0) crossings[k].push_back(s.time() - kDt * x / (x - prev[k]));
    prev[k] = x;
  });
  const double expected = 2 * std::numbers::pi * std::sqrt((0.4 * r * r + length * length) / (kG * length)) *
                          (1 + theta0 * theta0 / 16);
  for (int k = 0; k < 2; ++k) {
    ASSERT_GE(crossings[k].size(), 3u);
    const double period =
        (crossings[k].back() - crossings[k].front()) / static_cast<double>(crossings[k].size() - 1);
    EXPECT_NEAR(period, expected, 5e-3 * expected) << "backend " << k;
    EXPECT_NEAR(reach[k], length, 1e-3) << "backend " << k;  // the joint holds
  }
}

TEST(OdeBackend, UnsupportedShapesAndOptionsAreNamed) {
  PhysicsWorld w;
  dm::BodyDesc tube;
  tube.name = "egg";
  tube.kind = dm::BodyKind::Rigid;
  tube.shape = std::make_shared<dm::Ellipsoid>(Vec3(0.01, 0.01, 0.02));
  ASSERT_TRUE(w.addBody(tube).ok());
  auto ode = dm::OdeWorld::create(w);
  ASSERT_FALSE(ode.ok());
  EXPECT_EQ(ode.error().code, dm::ErrorCode::Unsupported);
  EXPECT_NE(ode.error().message().find("'egg'"), std::string::npos) << ode.error().message();
  EXPECT_NE(ode.error().message().find("ellipsoid"), std::string::npos) << ode.error().message();

  PhysicsWorld w2;
  dm::BodyDesc floor;
  floor.name = "floating-floor";
  floor.kind = dm::BodyKind::Rigid;
  floor.shape = std::make_shared<dm::Plane>(Vec3::UnitZ(), 0.0);
  ASSERT_TRUE(w2.addBody(floor).ok());
  auto ode2 = dm::OdeWorld::create(w2);
  ASSERT_FALSE(ode2.ok());
  EXPECT_NE(ode2.error().message().find("'floating-floor'"), std::string::npos) << ode2.error().message();

  PhysicsWorld w3;
  add(w3, std::make_shared<dm::Sphere>(0.1), 1.0, Vec3::Zero());
  EXPECT_FALSE(dm::OdeWorld::create(w3, {.iterations = 0}).ok());
  auto ok = dm::OdeWorld::create(w3);
  ASSERT_TRUE(ok.ok());
  WorldState s = w3.makeState();
  EXPECT_FALSE(ok->step(s, -1.0).ok());
  PhysicsWorld other;
  WorldState empty = other.makeState();
  EXPECT_FALSE(ok->step(empty, kDt).ok());
}

/// The body's weight on its supports once it rests: ODE's contact force on
/// it, summed over the last step's contacts.
Vec3 odeContactForce(const dm::OdeWorld& ode, BodyId b) { return ode.lastContactForces()[b.index]; }

TEST(OdeBackend, ACylinderRestsOnItsEndAndOnItsSideAndTheFloorCarriesItsWeight) {
  const double r = 0.03, half = 0.06, m = 0.4;
  for (const bool onSide : {false, true}) {
    PhysicsWorld w;
    add(w, std::make_shared<dm::Plane>(Vec3::UnitZ(), 0.0), 0.0, Vec3::Zero(), dm::Quat::Identity(),
        {.friction = 0.5});
    dm::BodyDesc d;
    d.kind = dm::BodyKind::Rigid;
    d.mass = m;
    const double side = m * (3 * r * r + 4 * half * half) / 12;
    d.inertia = Vec3(side, side, 0.5 * m * r * r).asDiagonal();
    d.shape = std::make_shared<dm::Cylinder>(r, half);
    const double rest = onSide ? r : half;  // its centre's height at rest
    d.position = Vec3(0, 0, rest + 0.01);
    if (onSide) d.orientation = dm::Quat(Eigen::AngleAxisd(std::numbers::pi / 2, Vec3::UnitX()));
    const BodyId c = *w.addBody(d);
    ASSERT_TRUE(w.setMaterial(c, {.friction = 0.5}).ok());
    ASSERT_TRUE(w.setGravity({0, 0, -kG}).ok());
    auto ode = dm::OdeWorld::create(w);
    ASSERT_TRUE(ode.ok()) << ode.error().message();
    WorldState s = w.makeState();
    for (int i = 0; i < 1500; ++i) ASSERT_TRUE(ode->step(s, kDt).ok());
    EXPECT_NEAR(s.position(c).z(), rest, 1e-3) << (onSide ? "on its side" : "on its end");
    EXPECT_LT(s.linearVelocity(c).norm(), 1e-3);
    // At rest the floor carries the weight: within 1 %.
    EXPECT_NEAR(odeContactForce(*ode, c).z(), m * kG, 0.01 * m * kG);
    EXPECT_NEAR(Vec3(odeContactForce(*ode, c).x(), odeContactForce(*ode, c).y(), 0).norm(), 0.0,
                1e-3 * m * kG);
  }
}

TEST(OdeBackend, ABallRollsInATessellatedBowlAtTheRollingPendulumsRateOnBothBackends) {
  // A bowl: the lower part of an icosphere (radius R, level 6, 2 mm
  // edges), its triangles turned to face in. A solid ball rolling without
  // slipping in it is a pendulum of length R − r slowed by its spin:
  // ω² = 5 g / (7 (R − r)); sliding without friction it would swing 18 %
  // faster. The facets shorten the period as they coarsen (measured here:
  // level 4, 3 % built-in and 1.4 % ODE; level 5, 1.3 % both; level 6,
  // 0.2 % and 0.1 %).
  const double R = 0.1, r = 0.02, m = 0.05, theta0 = 0.15;
  dm::Mesh sphere = dm::makeIcosphere(R, 6);
  auto bowl = std::make_shared<dm::Mesh>();
  bowl->positions = sphere.positions;
  for (const dm::Triangle& t : sphere.triangles)
    if (sphere.positions[t[0]].z() < 0.2 * R && sphere.positions[t[1]].z() < 0.2 * R &&
        sphere.positions[t[2]].z() < 0.2 * R)
      bowl->triangles.push_back({t[0], t[2], t[1]});
  auto shape = dm::TriangleMesh::create(bowl);
  ASSERT_TRUE(shape.ok()) << shape.error().message();
  PhysicsWorld w;
  add(w, *shape, 0.0, Vec3::Zero(), dm::Quat::Identity(), {.friction = 0.4});
  const Vec3 start = (R - r) * Vec3(std::sin(theta0), 0, -std::cos(theta0));
  const BodyId ball =
      add(w, std::make_shared<dm::Sphere>(r), m, start, dm::Quat::Identity(), {.friction = 0.4});
  ASSERT_TRUE(w.setGravity({0, 0, -kG}).ok());
  std::vector<double> crossings[2];
  double prev[2] = {start.x(), start.x()}, closest[2] = {R, R};
  runBoth(w, 2500, [&](int k, const WorldState& s) {
    const Vec3 x = s.position(ball);
    closest[k] = std::min(closest[k], R - x.norm());  // the ball's centre from the wall
    if (prev[k] > 0 && x.x() <= 0) crossings[k].push_back(s.time() - kDt * x.x() / (x.x() - prev[k]));
    prev[k] = x.x();
  });
  const double expected =
      2 * std::numbers::pi / std::sqrt(5 * kG / (7 * (R - r))) * (1 + theta0 * theta0 / 16);
  for (int k = 0; k < 2; ++k) {
    ASSERT_GE(crossings[k].size(), 3u) << "backend " << k;
    const double period =
        (crossings[k].back() - crossings[k].front()) / static_cast<double>(crossings[k].size() - 1);
    EXPECT_NEAR(period, expected, 0.005 * expected) << "backend " << k;
    EXPECT_GT(closest[k], r - 1.5e-3) << "backend " << k;  // never into the bowl past the allowed penetration
  }
}

TEST(OdeBackend, AConvexHullRestsOnItsFaceAndAHullWithATriangleMeshIsRefused) {
  // The hull of a box's corners, tilted and dropped: it lands on a face and
  // rests at its half height with the floor carrying its weight.
  const Vec3 h(0.05, 0.03, 0.02);
  const double m = 0.3;
  dm::Mesh corners = dm::makeBox(h);
  auto hull = dm::ConvexHull::create(corners.positions);
  ASSERT_TRUE(hull.ok()) << hull.error().message();
  PhysicsWorld w;
  add(w, std::make_shared<dm::Plane>(Vec3::UnitZ(), 0.0), 0.0, Vec3::Zero(), dm::Quat::Identity(),
      {.friction = 0.6});
  dm::BodyDesc d;
  d.name = "block";
  d.kind = dm::BodyKind::Rigid;
  d.mass = m;
  d.inertia = dm::boxInertia(m, h);
  d.shape = *hull;
  d.position = Vec3(0, 0, 0.1);
  d.orientation = dm::Quat(Eigen::AngleAxisd(0.3, Vec3(1, 1, 0).normalized()));
  const BodyId block = *w.addBody(d);
  ASSERT_TRUE(w.setMaterial(block, {.friction = 0.6}).ok());
  ASSERT_TRUE(w.setGravity({0, 0, -kG}).ok());
  auto ode = dm::OdeWorld::create(w);
  ASSERT_TRUE(ode.ok()) << ode.error().message();
  WorldState s = w.makeState();
  for (int i = 0; i < 2000; ++i) ASSERT_TRUE(ode->step(s, kDt).ok());
  EXPECT_NEAR(s.position(block).z(), h.z(), 1e-3);
  EXPECT_NEAR(std::abs((s.orientation(block) * Vec3::UnitZ()).z()), 1.0, 1e-3);  // flat on its big face
  EXPECT_NEAR(odeContactForce(*ode, block).z(), m * kG, 0.01 * m * kG);

  auto floor = dm::TriangleMesh::create(std::make_shared<dm::Mesh>(dm::makePlane(1, 1, 4)));
  ASSERT_TRUE(floor.ok());
  dm::BodyDesc mesh;
  mesh.name = "table";
  mesh.kind = dm::BodyKind::Static;
  mesh.shape = *floor;
  ASSERT_TRUE(w.addBody(mesh).ok());
  auto refused = dm::OdeWorld::create(w);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.error().code, dm::ErrorCode::Unsupported);
  EXPECT_NE(refused.error().message().find("'block'"), std::string::npos) << refused.error().message();
  EXPECT_NE(refused.error().message().find("'table'"), std::string::npos) << refused.error().message();
}

}  // namespace
