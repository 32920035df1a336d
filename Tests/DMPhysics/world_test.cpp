// PhysicsWorld mechanics (dm/physics/world.hpp, body.hpp, accumulators.hpp):
// validation, impulses, torques at anchors, user forces, bounds, mass
// properties from meshes, determinism, snapshots and allocation-free steps.
#include <dm/math/primitives.hpp>
#include <dm/physics/world.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <memory>
#include <new>
#include <string>

// Allocation counter for the real-time check (Eigen's dynamic buffers use
// malloc and are sized by makeState()).
#include "../common/alloc_counter.hpp"

namespace {

using dm::BodyDesc;
using dm::BodyId;
using dm::BodyKind;
using dm::ErrorCode;
using dm::IntegratorKind;
using dm::Mat3;
using dm::PhysicsWorld;
using dm::Quat;
using dm::Vec3;
using dm::WorldState;

BodyDesc rigidBox(const Vec3& half, double mass, IntegratorKind integ = IntegratorKind::SymplecticEuler) {
  BodyDesc d;
  d.kind = BodyKind::Rigid;
  d.integrator = integ;
  d.mass = mass;
  d.inertia = (mass / 3.0) * Vec3(half.y() * half.y() + half.z() * half.z(),
                                  half.x() * half.x() + half.z() * half.z(),
                                  half.x() * half.x() + half.y() * half.y())
                                 .asDiagonal();
  d.shape = std::make_shared<dm::Box>(half);
  return d;
}

// --- Mass properties ---------------------------------------------------------

TEST(PhysicsBody, MassPropertiesFromBoxMeshMatchAnalyticBox) {
  const Vec3 half(0.3, 0.2, 0.05), offset(1.0, -2.0, 0.5);
  const double density = 7900.0;
  dm::Mesh mesh = dm::makeBox(half);
  for (Vec3& p : mesh.positions) p += offset;  // centroid away from the mesh origin
  auto d = dm::rigidBodyFromMesh(mesh, density);
  ASSERT_TRUE(d.ok()) << d.error();
  const double m = density * 8 * half.prod();
  EXPECT_NEAR(d->mass, m, 1e-12 * m);
  const Vec3 diag =
      (m / 3.0) * Vec3(half.y() * half.y() + half.z() * half.z(), half.x() * half.x() + half.z() * half.z(),
                       half.x() * half.x() + half.y() * half.y());
  EXPECT_LT((d->inertia - Mat3(diag.asDiagonal())).norm(), 1e-10 * diag.norm());
  EXPECT_LT((d->position - offset).norm(), 1e-12);
  EXPECT_LT((d->shapeOffset.translation() + offset).norm(), 1e-12);
  EXPECT_EQ(d->kind, BodyKind::Rigid);

  PhysicsWorld w;
  ASSERT_TRUE(w.addBody(*d).ok());
  // An open mesh fails with the mass-properties message.
  mesh.triangles.pop_back();
  EXPECT_FALSE(dm::rigidBodyFromMesh(mesh, density).ok());
}

// --- Validation ---------------------------------------------------------------

TEST(PhysicsWorld, RejectsBadBodiesNamingBodyAndField) {
  PhysicsWorld w;
  BodyDesc d;
  d.name = "bob";
  d.mass = -1.0;
  auto r = w.addBody(d);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, ErrorCode::InvalidArgument);
  EXPECT_NE(r.error().message().find("bob"), std::string::npos) << r.error();
  EXPECT_NE(r.error().message().find("mass"), std::string::npos) << r.error();

  d.mass = 1.0;
  d.position.x() = std::nan("");
  r = w.addBody(d);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message().find("position"), std::string::npos) << r.error();

  BodyDesc rb = rigidBox({0.1, 0.1, 0.1}, 1.0);
  rb.name = "lid";
  rb.inertia(2, 2) = -0.5;  // not positive definite
  r = w.addBody(rb);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message().find("inertia"), std::string::npos) << r.error();
  EXPECT_NE(r.error().message().find("lid"), std::string::npos) << r.error();
  rb.inertia = Vec3(1.0, 1.0, 5.0).asDiagonal();  // violates I1 + I2 >= I3
  EXPECT_FALSE(w.addBody(rb).ok());
  rb.inertia = Mat3::Identity();
  rb.inertia(0, 1) = 0.2;  // not symmetric
  EXPECT_FALSE(w.addBody(rb).ok());
  rb.inertia = Mat3::Identity();
  rb.orientation = Quat(0, 0, 0, 0);
  EXPECT_FALSE(w.addBody(rb).ok());
  EXPECT_EQ(w.bodyCount(), 0u);  // nothing was added by the failures
}

TEST(PhysicsWorld, RejectsBadAccumulatorsAndSteps) {
  PhysicsWorld w;
  const BodyId a = *w.addBody({.name = "a"});
  BodyDesc ground;
  ground.kind = BodyKind::Static;
  const BodyId g = *w.addBody(ground);

  auto st = w.addSpring({.a = a, .b = BodyId{7}, .stiffness = 1.0});
  ASSERT_FALSE(st.ok());
  EXPECT_EQ(st.error().code, ErrorCode::NotFound);
  EXPECT_NE(st.error().message().find("springs[0]"), std::string::npos) << st.error();
  st = w.addSpring({.a = a, .b = g, .stiffness = -1.0});
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.error().message().find("stiffness"), std::string::npos) << st.error();
  EXPECT_FALSE(w.addSpring({.a = a, .b = a, .stiffness = 1.0}).ok());
  EXPECT_FALSE(w.addDrag({.body = BodyId{}, .linear = 1.0}).ok());
  EXPECT_FALSE(w.addDrag({.body = a, .linear = std::nan("")}).ok());
  EXPECT_FALSE(w.addImpulse({.body = g, .impulse = {1, 0, 0}}).ok());  // static body
  EXPECT_FALSE(w.addNewtonianGravity({.gravitationalConstant = 0.0}).ok());
  EXPECT_FALSE(w.addNewtonianGravity({.bodies = {a, a}}).ok());
  EXPECT_FALSE(w.setGravity({0, 0, std::nan("")}).ok());
  EXPECT_FALSE(w.addUserForce("none", dm::UserForceFn{}).ok());
  EXPECT_FALSE(w.addUserForce("none", static_cast<DmForceCallback>(nullptr), nullptr).ok());
  EXPECT_TRUE(w.forces().springs.empty());

  WorldState s = w.makeState();
  for (double dt : {0.0, -1e-3, std::nan(""), HUGE_VAL}) {
    st = w.step(s, dt);
    ASSERT_FALSE(st.ok()) << dt;
    EXPECT_NE(st.error().message().find("dt"), std::string::npos) << st.error();
  }
  EXPECT_EQ(s.stepCount(), 0u);
  EXPECT_FALSE(w.applyImpulse(s, BodyId{9}, {1, 0, 0}, Vec3::Zero()).ok());
  EXPECT_FALSE(w.findBody("missing").ok());
  EXPECT_EQ(*w.findBody("a"), a);

  // A state made before more bodies were added no longer fits.
  ASSERT_TRUE(w.addBody({.name = "late"}).ok());
  st = w.step(s, 1e-3);
  ASSERT_FALSE(st.ok());
  EXPECT_EQ(st.error().code, ErrorCode::InvalidArgument);
}

TEST(PhysicsWorld, BlowUpIsReportedWithBodyAndField) {
  PhysicsWorld w;
  BodyDesc ground;
  ground.kind = BodyKind::Static;
  const BodyId g = *w.addBody(ground);
  const BodyId p = *w.addBody({.name = "bouncer", .position = {1, 0, 0}});
  // ω dt = 1e4: explicit integration diverges.
  ASSERT_TRUE(w.addSpring({.a = g, .b = p, .stiffness = 1e8}).ok());
  WorldState s = w.makeState();
  dm::Status st;
  for (int i = 0; i < 2000 && st.ok(); ++i) st = w.step(s, 1.0);
  ASSERT_FALSE(st.ok());
  EXPECT_EQ(st.error().code, ErrorCode::Unsupported);
  EXPECT_NE(st.error().message().find("bouncer"), std::string::npos) << st.error();
}

// --- Impulses, torques, user forces ------------------------------------------

TEST(PhysicsWorld, ImpulseChangesMomentumByExactlyJ) {
  PhysicsWorld w;
  BodyDesc d = rigidBox({0.2, 0.1, 0.05}, 3.0, IntegratorKind::VelocityVerlet);
  d.linearVelocity = Vec3(0.5, -1.0, 0.25);
  d.angularVelocity = Vec3(0.1, 0.2, -0.3);
  d.orientation = Quat(dm::AngleAxis(0.3, Vec3(1, 1, 0).normalized()));
  const BodyId b = *w.addBody(d);
  const Vec3 J(2.0, -1.5, 0.75), point(0.1, 0.05, -0.02);
  ASSERT_TRUE(w.addImpulse({.body = b, .impulse = J, .point = point, .time = 0.0105}).ok());
  WorldState s = w.makeState();
  const Vec3 p0 = w.linearMomentum(s);
  ASSERT_TRUE(w.step(s, 0.01).ok());  // [0, 0.01): not yet
  EXPECT_LT((w.linearMomentum(s) - p0).norm(), 1e-14);
  const Vec3 r = s.orientation(b) * point;  // lever arm at the moment of the impulse
  const Vec3 x1 = s.position(b);
  const Vec3 l1 = w.angularMomentum(s, x1);
  ASSERT_TRUE(w.step(s, 0.01).ok());  // [0.01, 0.02): applied once
  EXPECT_LT((w.linearMomentum(s) - (p0 + J)).norm(), 1e-14 * J.norm());
  // Torque-free rotation conserves L about the centre of mass, so ΔL = r × J
  // up to the rotation integrator's error over one step (ω dt ≈ 0.2 here).
  EXPECT_LT((w.angularMomentum(s, s.position(b)) - (l1 + r.cross(J))).norm(), 1e-6 * r.cross(J).norm());
  EXPECT_GT(r.cross(J).norm(), 0.05);  // the impulse does turn the body
  for (int i = 0; i < 5; ++i) ASSERT_TRUE(w.step(s, 0.01).ok());
  EXPECT_LT((w.linearMomentum(s) - (p0 + J)).norm(), 1e-14 * J.norm());  // not applied again

  // The immediate form at a world point: ΔP = J and ΔL = (point − x) × J, no integration in between.
  const Vec3 before = w.linearMomentum(s);
  const Vec3 lBefore = w.angularMomentum(s, s.position(b));
  const Vec3 at = s.position(b) + Vec3(0.05, -0.1, 0.02);
  ASSERT_TRUE(w.applyImpulse(s, b, -J, at).ok());
  EXPECT_LT((w.linearMomentum(s) - (before - J)).norm(), 1e-14 * J.norm());
  const Vec3 dL = (at - s.position(b)).cross(-J);
  EXPECT_LT((w.angularMomentum(s, s.position(b)) - (lBefore + dL)).norm(),
            1e-12 * (lBefore.norm() + dL.norm()));
  EXPECT_GT(dL.norm(), 0.1);
}

TEST(PhysicsWorld, SpringAtAnchorTurnsRigidBody) {
  PhysicsWorld w;
  BodyDesc ground;
  ground.kind = BodyKind::Static;
  ground.position = Vec3(0, 0, 1);
  const BodyId g = *w.addBody(ground);
  BodyDesc d = rigidBox({0.2, 0.1, 0.05}, 2.0);
  d.orientation = Quat(dm::AngleAxis(0.5, Vec3::UnitZ()));
  const BodyId b = *w.addBody(d);
  const Vec3 anchor(0.2, 0.1, 0.05);
  const double k = 50.0, L0 = 0.5;
  ASSERT_TRUE(w.addSpring({.a = g, .b = b, .anchorB = anchor, .stiffness = k, .restLength = L0}).ok());
  WorldState s = w.makeState();
  const Vec3 r = s.orientation(b) * anchor;
  const Vec3 dvec = (s.position(b) + r) - ground.position;  // from A's anchor to B's
  const Vec3 fB = -k * (dvec.norm() - L0) * dvec.normalized();
  ASSERT_TRUE(w.step(s, 1e-3).ok());
  // The reported accumulators are the start-of-step evaluation.
  EXPECT_LT((s.force(b) - fB).norm(), 1e-12 * fB.norm());
  EXPECT_LT((s.torque(b) - r.cross(fB)).norm(), 1e-12 * fB.norm());
  EXPECT_GT(s.angularVelocity(b).norm(), 0.0);
}

extern "C" void cGravity(void* user, const DmForceInput* in, double* forces, double*) {
  const double g = *static_cast<const double*>(user);
  for (uint32_t i = 0; i < in->bodyCount; ++i) forces[3 * i + 2] += in->masses[i] * g;
}

TEST(PhysicsWorld, UserForcesMatchBuiltInGravityBitForBit) {
  auto build = [] {
    auto w = std::make_unique<PhysicsWorld>();
    (void)w->addBody({.name = "p", .mass = 0.7, .linearVelocity = {1, 0, 3}});
    (void)w->addBody(rigidBox({0.1, 0.2, 0.3}, 1.5, IntegratorKind::Rk4));
    return w;
  };
  static double g = -9.81;
  auto w0 = build(), w1 = build(), w2 = build();
  ASSERT_TRUE(w0->setGravity({0, 0, g}).ok());
  ASSERT_TRUE(w1->addUserForce("c-gravity", &cGravity, &g).ok());
  ASSERT_TRUE(w2->addUserForce("gravity", [](const dm::BodyStateView& v, dm::ForceOutput& out) {
                  for (std::size_t i = 0; i < out.force.size(); ++i)
                    out.force[i] += v.mass[i] * Vec3(0, 0, g);
                }).ok());
  WorldState s0 = w0->makeState(), s1 = w1->makeState(), s2 = w2->makeState();
  for (int i = 0; i < 200; ++i) {
    ASSERT_TRUE(w0->step(s0, 1e-3).ok());
    ASSERT_TRUE(w1->step(s1, 1e-3).ok());
    ASSERT_TRUE(w2->step(s2, 1e-3).ok());
  }
  EXPECT_EQ(dm::stateHash(s0.data()), dm::stateHash(s1.data()));
  EXPECT_EQ(dm::stateHash(s0.data()), dm::stateHash(s2.data()));
  EXPECT_NEAR(s0.linearVelocity(BodyId{0}).z(), 3 + g * 0.2, 1e-12);
}

// --- Bounds -------------------------------------------------------------------

TEST(PhysicsWorld, BoundsFollowTheShape) {
  PhysicsWorld w;
  const Vec3 half(0.3, 0.1, 0.05);
  BodyDesc d = rigidBox(half, 1.0, IntegratorKind::Rk4);
  d.angularVelocity = Vec3(0, 0, 2.0);
  d.linearVelocity = Vec3(1, 0, 0);
  const BodyId b = *w.addBody(d);
  const BodyId p = *w.addBody({.name = "point", .position = {4, 5, 6}});
  WorldState s = w.makeState();
  for (int i = 0; i < 400; ++i) ASSERT_TRUE(w.step(s, 1e-3).ok());
  // Rotation about z by θ: half extents |cos θ| hx + |sin θ| hy etc.
  const double th = 2.0 * s.time();
  const Vec3 ext(std::abs(std::cos(th)) * half.x() + std::abs(std::sin(th)) * half.y(),
                 std::abs(std::sin(th)) * half.x() + std::abs(std::cos(th)) * half.y(), half.z());
  EXPECT_LT((s.bounds(b).max() - (s.position(b) + ext)).norm(), 1e-9);
  EXPECT_LT((s.bounds(b).min() - (s.position(b) - ext)).norm(), 1e-9);
  EXPECT_NEAR(s.position(b).x(), s.time(), 1e-12);
  EXPECT_EQ(s.bounds(p).min(), Vec3(4, 5, 6));
  EXPECT_EQ(s.bounds(p).max(), Vec3(4, 5, 6));
}

// --- Determinism and snapshots ---------------------------------------------

std::unique_ptr<PhysicsWorld> busyWorld() {
  auto w = std::make_unique<PhysicsWorld>();
  BodyDesc ground;
  ground.kind = BodyKind::Static;
  ground.name = "ground";
  const BodyId g = *w->addBody(ground);
  const BodyId p1 = *w->addBody({.name = "p1", .mass = 0.5, .position = {0.3, 0, 0}});
  const BodyId p2 = *w->addBody({.name = "p2",
                                 .integrator = IntegratorKind::VelocityVerlet,
                                 .mass = 0.8,
                                 .position = {0, 0.4, 0.1},
                                 .linearVelocity = {0, 0, 0.3}});
  BodyDesc rb = rigidBox({0.1, 0.2, 0.05}, 1.2, IntegratorKind::Rk4);
  rb.name = "box";
  rb.position = Vec3(0.2, 0.2, -0.3);
  rb.angularVelocity = Vec3(0.3, -0.2, 1.0);
  const BodyId b = *w->addBody(rb);
  BodyDesc rb2 = rigidBox({0.05, 0.05, 0.2}, 0.6, IntegratorKind::SymplecticEuler);
  rb2.position = Vec3(-0.3, 0.1, 0.2);
  const BodyId b2 = *w->addBody(rb2);
  EXPECT_TRUE(w->setGravity({0, 0, -9.81}).ok());
  EXPECT_TRUE(w->addSpring({.a = g, .b = p1, .stiffness = 40, .restLength = 0.2, .damping = 0.1}).ok());
  EXPECT_TRUE(
      w->addSpring({.a = p1, .b = b, .anchorB = {0.1, 0.2, 0.05}, .stiffness = 30, .restLength = 0.3}).ok());
  EXPECT_TRUE(w->addSpring({.a = b, .b = p2, .anchorA = {-0.1, 0, 0}, .stiffness = 25, .damping = 0.2}).ok());
  EXPECT_TRUE(
      w->addSpring({.a = g, .b = b2, .anchorB = {0, 0, 0.2}, .stiffness = 60, .restLength = 0.3}).ok());
  EXPECT_TRUE(w->addDrag({.body = p2, .linear = 0.05, .quadratic = 0.02}).ok());
  EXPECT_TRUE(w->addDrag({.body = b, .linear = 0.01, .angular = 0.003}).ok());
  EXPECT_TRUE(w->addNewtonianGravity({.gravitationalConstant = 0.01, .softening = 0.05}).ok());
  EXPECT_TRUE(w->addTorque({.body = b2, .torque = {0, 0.01, 0}}).ok());
  EXPECT_TRUE(w->addForce({.body = b2, .force = {0.1, 0, 0}, .point = {0, 0, 0.1}}).ok());
  EXPECT_TRUE(w->addImpulse({.body = p2, .impulse = {0.1, 0, 0}, .time = 0.05}).ok());
  EXPECT_TRUE(w->addUserForce("swirl", [](const dm::BodyStateView& v, dm::ForceOutput& out) {
                 for (std::size_t i = 0; i < out.force.size(); ++i)
                   out.force[i] +=
                       0.05 * Vec3(-v.position[i].y(), v.position[i].x(), 0) * std::sin(3 * v.time);
               }).ok());
  return w;
}

TEST(PhysicsWorld, LockstepRunsAreBitIdentical) {
  const auto wa = busyWorld(), wb = busyWorld();
  WorldState a = wa->makeState(), b = wb->makeState(), c = wa->makeState();
  EXPECT_EQ(dm::stateHash(a.data()), dm::stateHash(b.data()));
  for (int i = 0; i < 500; ++i) {
    ASSERT_TRUE(wa->step(a, 1e-3).ok());
    ASSERT_TRUE(wb->step(b, 1e-3).ok());
    ASSERT_TRUE(wa->step(c, 1e-3).ok());
    ASSERT_EQ(dm::stateHash(a.data()), dm::stateHash(b.data())) << "step " << i;
    ASSERT_EQ(dm::stateHash(a.data()), dm::stateHash(c.data())) << "step " << i;
  }
  // Something moved, and the hash sees a one-ulp change.
  EXPECT_GT((a.position(BodyId{3}) - Vec3(0.2, 0.2, -0.3)).norm(), 1e-3);
  dm::WorldSnapshot snap = a.snapshot();
  const std::uint64_t h = dm::stateHash(snap);
  snap.linearVelocity[2].x() = std::nextafter(snap.linearVelocity[2].x(), 1e300);
  EXPECT_NE(dm::stateHash(snap), h);
  // A different dt sequence gives a different state.
  ASSERT_TRUE(wb->step(b, 5e-4).ok());
  ASSERT_TRUE(wb->step(b, 5e-4).ok());
  ASSERT_TRUE(wa->step(a, 1e-3).ok());
  EXPECT_NE(dm::stateHash(a.data()), dm::stateHash(b.data()));
}

TEST(PhysicsWorld, SnapshotRestoreReproducesTrajectory) {
  const auto w = busyWorld();
  WorldState s = w->makeState();
  for (int i = 0; i < 30; ++i) ASSERT_TRUE(w->step(s, 1e-3).ok());
  const dm::WorldSnapshot snap = s.snapshot();  // before the impulse at t = 0.05
  std::vector<std::uint64_t> hashes;
  for (int i = 0; i < 300; ++i) {
    ASSERT_TRUE(w->step(s, 1e-3).ok());
    hashes.push_back(dm::stateHash(s.data()));
  }
  const dm::Aabb endBounds = s.bounds(BodyId{3});
  ASSERT_TRUE(w->restore(s, snap).ok());
  EXPECT_EQ(dm::stateHash(s.data()), dm::stateHash(snap));
  EXPECT_EQ(s.stepCount(), 30u);
  for (int i = 0; i < 300; ++i) {
    ASSERT_TRUE(w->step(s, 1e-3).ok());
    ASSERT_EQ(dm::stateHash(s.data()), hashes[i]) << "step " << i;
  }
  EXPECT_EQ(s.bounds(BodyId{3}).min(), endBounds.min());

  // A copy of the state is an independent run.
  WorldState copy = s;
  ASSERT_TRUE(w->step(copy, 1e-3).ok());
  EXPECT_EQ(dm::stateHash(s.data()), hashes.back());

  // Bad snapshots are refused.
  dm::WorldSnapshot bad = snap;
  bad.position[1].y() = std::nan("");
  auto st = w->restore(s, bad);
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.error().message().find("p1"), std::string::npos) << st.error();
  bad = snap;
  bad.orientation.pop_back();
  EXPECT_FALSE(w->restore(s, bad).ok());
}

TEST(PhysicsWorld, StepAllocatesNothingAfterSetup) {
  const auto w = busyWorld();
  WorldState s = w->makeState();
  dm::WorldSnapshot snap = s.snapshot();
  ASSERT_TRUE(w->step(s, 1e-3).ok());
  const auto before = dm::test::countedAllocations();
  dm::test::tCountAllocations = true;
  bool allOk = true;
  for (int i = 0; i < 200; ++i) allOk = allOk && w->step(s, 1e-3).ok();
  s.copyTo(snap);
  allOk = allOk && w->restore(s, snap).ok();
  dm::test::tCountAllocations = false;
  EXPECT_TRUE(allOk);
  EXPECT_EQ(dm::test::countedAllocations(), before);
  // The counter works.
  dm::test::tCountAllocations = true;
  auto probe = std::make_unique<int>(1);
  dm::test::tCountAllocations = false;
  EXPECT_GE(dm::test::countedAllocations(), before + 1);
}

}  // namespace
