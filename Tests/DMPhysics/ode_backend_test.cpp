// The ODE backend against the built-in contact solver and closed forms:
// free fall, sliding on a slope with Coulomb friction, a resting box, a
// bouncing ball, a hinge pendulum; unsupported scenes give errors naming the
// body.
#include <dm/collide/shapes.hpp>
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
  tube.name = "tube";
  tube.kind = dm::BodyKind::Rigid;
  tube.shape = std::make_shared<dm::Cylinder>(0.01, 0.1);
  ASSERT_TRUE(w.addBody(tube).ok());
  auto ode = dm::OdeWorld::create(w);
  ASSERT_FALSE(ode.ok());
  EXPECT_EQ(ode.error().code, dm::ErrorCode::Unsupported);
  EXPECT_NE(ode.error().message().find("'tube'"), std::string::npos) << ode.error().message();
  EXPECT_NE(ode.error().message().find("cylinder"), std::string::npos) << ode.error().message();

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

}  // namespace
