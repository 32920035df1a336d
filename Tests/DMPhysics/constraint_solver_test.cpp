// Tests of dm/physics/constraint_solver.hpp against analytic mechanics:
// restitution (bounce height e²·h), resting contact, Coulomb friction on an
// incline (stick / slide with g(sinθ − μcosθ)), stacking, warm starting,
// momentum in collisions, pendulum period 2π√(L/g), and joint kinematics.
#include <dm/collide/query.hpp>
#include <dm/collide/shapes.hpp>
#include <dm/physics/constraint_solver.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <vector>

#include "physics_test_support.hpp"

namespace dm {
namespace {

using dm::test::kG;
const Vec3 kGravity(0.0, 0.0, -kG);

Isometry3 poseOf(const SolverBody& b) {
  Isometry3 t = Isometry3::Identity();
  t.linear() = b.orientation.toRotationMatrix();
  t.translation() = b.position;
  return t;
}

// Appends the contacts of shape `sa` (body a, or the world at identity when
// a = kWorldBody) against shape `sb` (body b) from dm::collide().
void addContacts(const Shape& sa, int a, const Shape& sb, int b, const std::vector<SolverBody>& bodies,
                 double friction, double restitution, std::vector<ContactConstraint>& out,
                 CollisionResult& scratch) {
  const Isometry3 pa = a == kWorldBody ? Isometry3::Identity() : poseOf(bodies[static_cast<std::size_t>(a)]);
  const Isometry3 pb = b == kWorldBody ? Isometry3::Identity() : poseOf(bodies[static_cast<std::size_t>(b)]);
  collide(sa, pa, sb, pb, CollisionRequest{}, scratch);
  ASSERT_TRUE(scratch.supported);
  for (const ContactPoint& p : scratch.contacts)
    out.push_back(ContactConstraint::make(a, b, p, friction, restitution));
}

double rotationAngle(const Quat& a, const Quat& b) { return a.angularDistance(b); }

// ---------------------------------------------------------------------------

// A ball dropped from h onto a static plane with restitution e leaves the
// plane with e times its impact speed (to rounding) and rises to e²·h. The
// apex tolerance is 1 % plus the position error of a discrete contact: it is
// detected up to one step late (v·dt deep) and penetration up to the slop is
// left uncorrected.
TEST(ConstraintSolver, BallBouncesToRestitutionSquaredHeight) {
  const double radius = 0.05, h = 1.0, dt = 5e-4;
  const Sphere ball(radius);
  const Plane ground(Vec3::UnitZ(), 0.0);
  const SolverOptions options{.slop = 1e-3};
  for (double e : {0.3, 0.6, 0.9}) {
    std::vector<SolverBody> bodies{SolverBody::dynamic(1.0, sphereInertia(1.0, radius), {0, 0, radius + h})};
    std::vector<ContactConstraint> contacts;
    std::vector<Joint> joints;
    ConstraintSolver solver;
    ContactCache cache;
    CollisionResult scratch;
    bool bounced = false;
    double apex = 0.0, impactSpeed = 0.0;
    for (int step = 0; step < 6000; ++step) {
      integrateVelocities(bodies, kGravity, dt);
      contacts.clear();
      addContacts(ground, kWorldBody, ball, 0, bodies, 0.0, e, contacts, scratch);
      cache.warmStart(contacts, bodies);
      const double before = bodies[0].linearVelocity.z();
      ASSERT_TRUE(solver.solve(bodies, contacts, joints, dt, options));
      cache.store(contacts, bodies);
      if (!bounced && !contacts.empty()) {
        bounced = true;
        impactSpeed = -before;
        EXPECT_NEAR(bodies[0].linearVelocity.z(), -e * before, 1e-12 * impactSpeed) << "e = " << e;
      }
      integratePositions(bodies, dt);
      if (bounced) {
        apex = std::max(apex, bodies[0].position.z() - radius);
        if (bodies[0].linearVelocity.z() < 0.0) break;  // past the apex
      }
    }
    ASSERT_TRUE(bounced) << "e = " << e;
    EXPECT_NEAR(impactSpeed, std::sqrt(2 * kG * h), 2 * kG * dt);
    EXPECT_NEAR(apex, e * e * h, 0.01 * e * e * h + options.slop + impactSpeed * dt) << "e = " << e;
  }
}

// A box released resting on a plane (1 mm inside, within the slop) stays at
// rest for 1000 steps at 60 Hz: penetration ≤ slop + 1 mm, no drift, no
// rotation, and the four contacts carry its weight.
TEST(ConstraintSolver, BoxRestsOnPlaneWithBoundedPenetration) {
  const Vec3 half(0.2, 0.1, 0.05);
  const Box box(half);
  const Plane ground(Vec3::UnitZ(), 0.0);
  const double dt = 1.0 / 60.0;
  std::vector<SolverBody> bodies{
      SolverBody::dynamic(2.0, boxInertia(2.0, half), {0.3, -0.2, half.z() - 1e-3})};
  std::vector<ContactConstraint> contacts;
  std::vector<Joint> joints;
  ConstraintSolver solver;
  ContactCache cache;
  CollisionResult scratch;
  const SolverOptions options;
  double maxPenetration = 0.0;
  for (int step = 0; step < 1000; ++step) {
    integrateVelocities(bodies, kGravity, dt);
    contacts.clear();
    addContacts(ground, kWorldBody, box, 0, bodies, 0.6, 0.2, contacts, scratch);
    ASSERT_EQ(contacts.size(), 4u);
    cache.warmStart(contacts, bodies);
    ASSERT_TRUE(solver.solve(bodies, contacts, joints, dt, options));
    cache.store(contacts, bodies);
    integratePositions(bodies, dt);
    maxPenetration = std::max(maxPenetration, half.z() - bodies[0].position.z());
  }
  EXPECT_LE(maxPenetration, options.slop + 1e-3);
  EXPECT_NEAR(bodies[0].position.x(), 0.3, 1e-6);
  EXPECT_NEAR(bodies[0].position.y(), -0.2, 1e-6);
  EXPECT_LT(bodies[0].linearVelocity.norm(), 1e-6);
  EXPECT_LT(bodies[0].angularVelocity.norm(), 1e-6);
  EXPECT_LT(rotationAngle(bodies[0].orientation, Quat::Identity()), 1e-6);
  // Weight carried by the four contacts: Σλn = m·g·dt.
  double sum = 0.0;
  for (const auto& c : contacts) sum += c.normalImpulse;
  EXPECT_NEAR(sum, 2.0 * kG * dt, 1e-6);
}

// Block on a plane inclined by θ with friction μ: sticks when tanθ < μ,
// slides with a = g(sinθ − μcosθ) when tanθ > μ (4 contacts from
// dm::collide(plane, box)). Acceleration checked to 1 %.
TEST(ConstraintSolver, BlockOnInclineSticksOrSlidesWithCoulombAcceleration) {
  const double mu = 0.5, dt = 1.0 / 240.0, duration = 1.0;
  const Vec3 half(0.1, 0.08, 0.04);
  const Box box(half);
  for (double thetaDeg : {20.0, 35.0}) {
    const double theta = thetaDeg * std::numbers::pi / 180.0;
    // Plane through the origin rising towards +x; downhill is −(cosθ, 0, sinθ).
    const Vec3 n(-std::sin(theta), 0.0, std::cos(theta));
    const Vec3 downhill = -Vec3(std::cos(theta), 0.0, std::sin(theta));
    const Plane incline(n, 0.0);
    const Quat tilt(AngleAxis(-theta, Vec3::UnitY()));
    ASSERT_LT((tilt * Vec3::UnitZ() - n).norm(), 1e-12);
    std::vector<SolverBody> bodies{
        SolverBody::dynamic(1.5, boxInertia(1.5, half), n * (half.z() - 1e-3), tilt)};
    const Vec3 start = bodies[0].position;
    std::vector<ContactConstraint> contacts;
    std::vector<Joint> joints;
    ConstraintSolver solver;
    ContactCache cache;
    CollisionResult scratch;
    int steps = static_cast<int>(std::lround(duration / dt));
    for (int step = 0; step < steps; ++step) {
      integrateVelocities(bodies, kGravity, dt);
      contacts.clear();
      addContacts(incline, kWorldBody, box, 0, bodies, mu, 0.0, contacts, scratch);
      ASSERT_EQ(contacts.size(), 4u) << "step " << step;
      cache.warmStart(contacts, bodies);
      ASSERT_TRUE(solver.solve(bodies, contacts, joints, dt, {.velocityIterations = 20}));
      cache.store(contacts, bodies);
      integratePositions(bodies, dt);
    }
    const double travelled = (bodies[0].position - start).dot(downhill);
    const double speed = bodies[0].linearVelocity.dot(downhill);
    if (std::tan(theta) < mu) {
      EXPECT_LT(std::abs(travelled), 1e-4) << "θ = " << thetaDeg << "°";
      EXPECT_LT(std::abs(speed), 1e-4);
    } else {
      const double a = kG * (std::sin(theta) - mu * std::cos(theta));
      EXPECT_NEAR(speed / duration, a, 0.01 * a) << "θ = " << thetaDeg << "°";
      EXPECT_NEAR(travelled, 0.5 * a * duration * duration, 0.02 * 0.5 * a * duration * duration);
    }
    // Stays on the incline, does not tip.
    EXPECT_NEAR((bodies[0].position - n * half.z()).dot(n), 0.0, SolverOptions{}.slop + 1e-3);
    EXPECT_LT(rotationAngle(bodies[0].orientation, tilt), 1e-2);
  }
}

// Five stacked boxes (dm::collide box–box each step) on a plane.
struct Stack {
  static constexpr int kBoxes = 5;
  Vec3 half{0.1, 0.1, 0.1};
  Box box{half};
  Plane ground{Vec3::UnitZ(), 0.0};
  std::vector<SolverBody> bodies;
  std::vector<ContactConstraint> contacts;
  std::vector<Joint> joints;
  ConstraintSolver solver;
  ContactCache cache;
  CollisionResult scratch;

  Stack() {
    for (int i = 0; i < kBoxes; ++i) {
      // Small alternating offsets, as a hand would stack them; each box 1 mm
      // into the one below (within the slop) so that all contacts exist.
      const Vec3 p(0.002 * ((i % 2) ? 1 : -1), 0.001 * i, half.z() * (2 * i + 1) - 1e-3 * (i + 1));
      bodies.push_back(SolverBody::dynamic(1.0, boxInertia(1.0, half), p));
    }
    solver.reserve(bodies.size(), 4 * kBoxes, 0);
    cache.reserve(4 * kBoxes);
  }
  void findContacts() {
    contacts.clear();
    addContacts(ground, kWorldBody, box, 0, bodies, 0.6, 0.0, contacts, scratch);
    for (int i = 0; i + 1 < kBoxes; ++i) addContacts(box, i, box, i + 1, bodies, 0.6, 0.0, contacts, scratch);
  }
  SolverStats step(double dt, const SolverOptions& options) {
    integrateVelocities(bodies, kGravity, dt);
    findContacts();
    cache.warmStart(contacts, bodies);
    auto stats = solver.solve(bodies, contacts, joints, dt, options);
    EXPECT_TRUE(stats);
    cache.store(contacts, bodies);
    integratePositions(bodies, dt);
    return stats ? *stats : SolverStats{};
  }
};

// The stack settles within the first steps (sequential impulses are not
// symmetric, so a cold start tilts the boxes by a few mrad) and then stays at
// rest: no drift between step 1000 and 2000, no sinking beyond the slop.
TEST(ConstraintSolver, StackOfFiveBoxesStaysStable) {
  for (double dt : {1.0 / 60.0, 1e-3}) {
    Stack s;
    std::vector<Vec3> start, middle;
    for (const auto& b : s.bodies) start.push_back(b.position);
    for (int i = 0; i < 2000; ++i) {
      s.step(dt, {});
      if (i == 999)
        for (const auto& b : s.bodies) middle.push_back(b.position);
    }
    for (int i = 0; i < Stack::kBoxes; ++i) {
      const auto k = static_cast<std::size_t>(i);
      const SolverBody& b = s.bodies[k];
      const Vec3 moved = b.position - start[k];
      EXPECT_LT(moved.head<2>().norm(), 5e-3) << "box " << i << " dt " << dt;
      EXPECT_LT((b.position - middle[k]).norm(), 1e-4) << "box " << i << " dt " << dt;
      // Each interface may sink by at most the slop (+1 mm).
      EXPECT_GT(b.position.z(), s.half.z() * (2 * i + 1) - (i + 1) * (SolverOptions{}.slop + 1e-3))
          << "box " << i << " dt " << dt;
      EXPECT_LT(moved.z(), 1e-3) << "box " << i << " dt " << dt;
      EXPECT_LT(rotationAngle(b.orientation, Quat::Identity()), 1e-2) << "box " << i << " dt " << dt;
      EXPECT_LT(b.linearVelocity.norm(), 1e-3) << "box " << i << " dt " << dt;
      EXPECT_LT(b.angularVelocity.norm(), 1e-2) << "box " << i << " dt " << dt;
    }
  }
}

// With the impulses of the previous step as a start, a few sweeps leave a much
// smaller residual than a cold start, and fewer sweeps reach a tolerance.
TEST(ConstraintSolver, WarmStartingReducesIterations) {
  Stack s;
  for (int i = 0; i < 300; ++i) s.step(1.0 / 60.0, {});
  // Snapshot of a step: velocities after gravity, contacts with cached impulses.
  integrateVelocities(s.bodies, kGravity, 1.0 / 60.0);
  s.findContacts();
  ASSERT_EQ(s.cache.warmStart(s.contacts, s.bodies), static_cast<int>(s.contacts.size()));
  const auto run = [&](bool warm, const SolverOptions& base) {
    std::vector<SolverBody> bodies = s.bodies;
    std::vector<ContactConstraint> contacts = s.contacts;
    SolverOptions o = base;
    o.warmStart = warm;
    auto stats = s.solver.solve(bodies, contacts, s.joints, 1.0 / 60.0, o);
    EXPECT_TRUE(stats);
    return stats ? *stats : SolverStats{};
  };
  const SolverStats warm = run(true, {.velocityIterations = 5});
  const SolverStats cold = run(false, {.velocityIterations = 5});
  EXPECT_LT(warm.residual, 0.1 * cold.residual) << warm.residual << " vs " << cold.residual;
  // Tolerance 0.5 mm/s (0.3 % of the velocity gravity adds per step).
  const SolverStats warmTol = run(true, {.velocityIterations = 300, .tolerance = 5e-4});
  const SolverStats coldTol = run(false, {.velocityIterations = 300, .tolerance = 5e-4});
  EXPECT_LT(warmTol.residual, 5e-4);
  EXPECT_LT(5 * warmTol.iterations, coldTol.iterations) << warmTol.iterations << " vs " << coldTol.iterations;
}

// Head-on collision of two spheres without gravity: momentum is conserved,
// and the post-impact velocities follow Newton's law of restitution
// v2' − v1' = −e(v2 − v1); equal masses with e = 1 swap velocities.
// Penetration correction (split impulses) must not change the velocities.
TEST(ConstraintSolver, CollisionConservesMomentumAndFollowsRestitution) {
  const double r = 0.1;
  const Sphere sphere(r);
  struct Case {
    double m1, m2, e;
  };
  for (const Case& k : {Case{1.0, 1.0, 1.0}, Case{1.0, 3.0, 0.5}, Case{2.0, 0.5, 0.0}}) {
    std::vector<SolverBody> bodies{SolverBody::dynamic(k.m1, sphereInertia(k.m1, r), {0, 0, 0}),
                                   SolverBody::dynamic(k.m2, sphereInertia(k.m2, r), {2 * r - 0.01, 0, 0})};
    const double v1 = 2.0, v2 = -0.5;
    bodies[0].linearVelocity = {v1, 0, 0};
    bodies[1].linearVelocity = {v2, 0, 0};
    std::vector<ContactConstraint> contacts;
    std::vector<Joint> joints;
    CollisionResult scratch;
    addContacts(sphere, 0, sphere, 1, bodies, 0.3, k.e, contacts, scratch);
    ASSERT_EQ(contacts.size(), 1u);
    ConstraintSolver solver;
    ASSERT_TRUE(solver.solve(bodies, contacts, joints, 1e-3, {}));
    const double p = k.m1 * v1 + k.m2 * v2;
    const double u1 = (p + k.m2 * k.e * (v2 - v1)) / (k.m1 + k.m2);
    const double u2 = (p + k.m1 * k.e * (v1 - v2)) / (k.m1 + k.m2);
    EXPECT_NEAR(bodies[0].linearVelocity.x(), u1, 1e-9);
    EXPECT_NEAR(bodies[1].linearVelocity.x(), u2, 1e-9);
    EXPECT_NEAR(k.m1 * bodies[0].linearVelocity.x() + k.m2 * bodies[1].linearVelocity.x(), p, 1e-12);
    EXPECT_LT(bodies[0].linearVelocity.tail<2>().norm() + bodies[1].linearVelocity.tail<2>().norm(), 1e-12);
    EXPECT_LT(bodies[0].angularVelocity.norm() + bodies[1].angularVelocity.norm(), 1e-12);
    // The overlap (1 cm > slop) is removed by pseudo-velocities only.
    EXPECT_GT(bodies[1].pushVelocity.x() - bodies[0].pushVelocity.x(), 0.0);
  }
}

// A bob on a ball joint: small-angle period 2π√(L/g) (0.3 %), and the bob
// stays at distance L from the pivot (drift < 0.5 mm).
TEST(ConstraintSolver, BallJointPendulumHasSmallAnglePeriod) {
  const double L = 0.5, dt = 1e-3, theta0 = 0.05, radius = 0.005, mass = 0.2;
  const Vec3 pivot(0, 0, 1.0);
  std::vector<SolverBody> bodies{SolverBody::dynamic(
      mass, sphereInertia(mass, radius), pivot + L * Vec3(std::sin(theta0), 0, -std::cos(theta0)))};
  std::vector<Joint> joints;
  auto j = Joint::ball(bodies, kWorldBody, 0, pivot);
  ASSERT_TRUE(j);
  joints.push_back(*j);
  std::vector<ContactConstraint> contacts;
  ConstraintSolver solver;
  // Physical pendulum: I/(m g L) with I = m L² + (2/5) m r²; finite amplitude
  // lengthens the period by θ0²/16.
  const double expected = 2 * std::numbers::pi * std::sqrt((L * L + 0.4 * radius * radius) / (kG * L)) *
                          (1.0 + theta0 * theta0 / 16.0);
  std::vector<double> crossings;
  double prevX = bodies[0].position.x() - pivot.x();
  double maxDrift = 0.0;
  for (int step = 1; step <= 7000; ++step) {
    integrateVelocities(bodies, kGravity, dt);
    ASSERT_TRUE(solver.solve(bodies, contacts, joints, dt, {}));
    integratePositions(bodies, dt);
    const double x = bodies[0].position.x() - pivot.x();
    if ((prevX > 0) != (x > 0)) crossings.push_back((step - 1 + prevX / (prevX - x)) * dt);
    prevX = x;
    maxDrift = std::max(maxDrift, std::abs((bodies[0].position - pivot).norm() - L));
  }
  ASSERT_GE(crossings.size(), 6u);
  const double period =
      2.0 * (crossings.back() - crossings.front()) / static_cast<double>(crossings.size() - 1);
  EXPECT_NEAR(period, 2 * std::numbers::pi * std::sqrt(L / kG), 0.003 * expected);
  EXPECT_NEAR(period, expected, 0.003 * expected);
  EXPECT_LT(maxDrift, 5e-4);
  // Motion stays in the x–z plane of the release.
  EXPECT_LT(std::abs(bodies[0].position.y()), 1e-9);
}

// A hinge lets the body turn about its axis only; with limits the angle
// stays within [lower, upper].
TEST(ConstraintSolver, HingeKeepsRotationToItsAxisAndRespectsLimits) {
  const Vec3 half(0.15, 0.02, 0.02);
  const Vec3 anchor(0, 0, 1), axis = Vec3(0, 1, 1).normalized();
  for (bool limited : {false, true}) {
    std::vector<SolverBody> bodies{
        SolverBody::dynamic(0.5, boxInertia(0.5, half), anchor + Vec3(0.15, 0, 0))};
    bodies[0].angularVelocity = {3.0, -2.0, 5.0};  // tumbling start: everything off-axis must go
    bodies[0].linearVelocity = {0.0, 0.4, -0.3};
    auto j = Joint::hinge(bodies, kWorldBody, 0, anchor, axis);
    ASSERT_TRUE(j);
    j->limitEnabled = limited;
    j->lower = -0.4;
    j->upper = 0.6;
    std::vector<Joint> joints{*j};
    std::vector<ContactConstraint> contacts;
    ConstraintSolver solver;
    const Vec3 localAnchor = bodies[0].orientation.conjugate() * (anchor - bodies[0].position);
    const Vec3 ref0 = Vec3(1, 0, 0);  // body x axis, projected onto the plane ⟂ axis
    const Vec3 refPerp0 = (ref0 - ref0.dot(axis) * axis).normalized();
    double minAngle = 0.0, maxAngle = 0.0, maxAxisError = 0.0, maxAnchorError = 0.0;
    for (int step = 0; step < 1500; ++step) {
      integrateVelocities(bodies, kGravity, 1e-3);
      ASSERT_TRUE(solver.solve(bodies, contacts, joints, 1e-3, {.velocityIterations = 20}));
      integratePositions(bodies, 1e-3);
      const SolverBody& b = bodies[0];
      if (step > 50) {  // after the first steps have removed the off-axis spin
        maxAxisError = std::max(maxAxisError, (b.orientation * axis).cross(axis).norm());
        maxAnchorError = std::max(maxAnchorError, (b.position + b.orientation * localAnchor - anchor).norm());
        // Off-axis spin: only what 20 sweeps leave when the limit engages.
        EXPECT_LT(b.angularVelocity.cross(axis).norm(), 5e-2) << "step " << step;
      }
      const Vec3 ref = b.orientation * refPerp0;
      const double angle = std::atan2(refPerp0.cross(ref).dot(axis), refPerp0.dot(ref));
      minAngle = std::min(minAngle, angle);
      maxAngle = std::max(maxAngle, angle);
    }
    EXPECT_LT(maxAxisError, 2e-3) << "limited " << limited;
    EXPECT_LT(maxAnchorError, 2e-3) << "limited " << limited;
    if (limited) {
      EXPECT_GT(minAngle, -0.4 - 0.02);
      EXPECT_LT(maxAngle, 0.6 + 0.02);
      EXPECT_GT(maxAngle, 0.55);  // it does reach the limit (spin 5 rad/s about z)
    } else {
      EXPECT_GT(maxAngle - minAngle, 1.0);  // swings freely
    }
  }
}

// A slider keeps the body on its axis with fixed orientation, lets the axial
// velocity through unchanged, and stops at the limits.
TEST(ConstraintSolver, SliderKeepsMotionOnItsAxisAndRespectsLimits) {
  const Vec3 half(0.05, 0.02, 0.02);
  const Vec3 axis = Vec3(1, 0, 1).normalized();
  for (bool limited : {false, true}) {
    std::vector<SolverBody> bodies{SolverBody::fixed({0, 0, 0}),
                                   SolverBody::dynamic(0.3, boxInertia(0.3, half), {0.1, 0.2, 0.3})};
    bodies[1].linearVelocity = 0.5 * axis + Vec3(0.0, 1.0, 0.0);
    bodies[1].angularVelocity = {1.0, 2.0, 3.0};
    auto j = Joint::slider(bodies, 0, 1, bodies[1].position, axis);
    ASSERT_TRUE(j);
    j->limitEnabled = limited;
    j->lower = -0.05;
    j->upper = 0.1;
    std::vector<Joint> joints{*j};
    std::vector<ContactConstraint> contacts;
    ConstraintSolver solver;
    const Vec3 start = bodies[1].position;
    double minS = 0.0, maxS = 0.0, maxOffAxis = 0.0, maxRotation = 0.0;
    const double dt = 1e-3;
    for (int step = 0; step < 1000; ++step) {
      integrateVelocities(bodies, Vec3::Zero(), dt);
      ASSERT_TRUE(solver.solve(bodies, contacts, joints, dt, {}));
      integratePositions(bodies, dt);
      const Vec3 d = bodies[1].position - start;
      const double s = d.dot(axis);
      minS = std::min(minS, s);
      maxS = std::max(maxS, s);
      if (step > 20) {
        maxOffAxis = std::max(maxOffAxis, (d - s * axis).norm());
        maxRotation = std::max(maxRotation, rotationAngle(bodies[1].orientation, Quat::Identity()));
      }
    }
    EXPECT_LT(maxOffAxis, 2e-3) << "limited " << limited;
    EXPECT_LT(maxRotation, 2e-2) << "limited " << limited;
    EXPECT_LT(bodies[1].angularVelocity.norm(), 1e-6);
    if (limited) {
      EXPECT_LT(maxS, 0.1 + 2e-3);
      EXPECT_GT(maxS, 0.1 - 2e-3);
      EXPECT_NEAR(bodies[1].linearVelocity.norm(), 0.0, 1e-6);  // stopped at the upper limit
    } else {
      // No force along the axis: the axial speed (0.5 m/s) is kept, T = 1 s.
      EXPECT_NEAR(bodies[1].linearVelocity.dot(axis), 0.5, 1e-6);
      EXPECT_NEAR(maxS, 0.5, 5e-3);
    }
  }
}

// A fixed joint keeps two free bodies in their relative pose while they
// tumble, and conserves their total linear and angular momentum.
TEST(ConstraintSolver, FixedJointKeepsRelativePoseAndConservesMomentum) {
  const Vec3 half(0.05, 0.03, 0.02);
  std::vector<SolverBody> bodies{
      SolverBody::dynamic(1.0, boxInertia(1.0, half), {0, 0, 0}),
      SolverBody::dynamic(0.5, boxInertia(0.5, half), {0.1, 0.0, 0.0}, Quat(AngleAxis(0.3, Vec3::UnitZ())))};
  bodies[0].linearVelocity = {0.2, 0.0, 0.0};
  bodies[0].angularVelocity = {0.0, 0.0, 2.0};
  auto j = Joint::fixed(bodies, 0, 1, {0.05, 0, 0});
  ASSERT_TRUE(j);
  std::vector<Joint> joints{*j};
  std::vector<ContactConstraint> contacts;
  ConstraintSolver solver;
  const Isometry3 rel0 = poseOf(bodies[0]).inverse() * poseOf(bodies[1]);
  const auto momentum = [&] { return Vec3(bodies[0].linearVelocity + 0.5 * bodies[1].linearVelocity); };
  const Vec3 p0 = momentum();
  double maxPosError = 0.0, maxRotError = 0.0;
  for (int step = 0; step < 1000; ++step) {
    ASSERT_TRUE(solver.solve(bodies, contacts, joints, 1e-3, {.velocityIterations = 20}));
    EXPECT_LT((momentum() - p0).norm(), 1e-9) << "step " << step;
    integratePositions(bodies, 1e-3);
    const Isometry3 rel = poseOf(bodies[0]).inverse() * poseOf(bodies[1]);
    maxPosError = std::max(maxPosError, (rel.translation() - rel0.translation()).norm());
    maxRotError = std::max(maxRotError, Quat(rel.linear()).angularDistance(Quat(rel0.linear())));
  }
  EXPECT_LT(maxPosError, 1e-3);
  EXPECT_LT(maxRotError, 1e-2);
  // The pair turns as one body: both angular velocities agree.
  EXPECT_LT((bodies[0].angularVelocity - bodies[1].angularVelocity).norm(), 1e-3);
  EXPECT_GT(rotationAngle(bodies[0].orientation, Quat::Identity()), 0.2);
}

// The solver runs manifolds that share no dynamic body side by side in SIMD
// lanes. Lanes must not leak into each other: bodies that each touch only the
// static ground (manifolds of 4, 2 and 1 points, some sliding, one sticking,
// one flying off, with warm-start impulses) end exactly as when each body is
// solved alone, bit for bit, and so do the contacts' impulses.
TEST(ConstraintSolver, IndependentManifoldsSolveAsIfAlone) {
  const Vec3 half(0.1, 0.1, 0.1);
  const Box box(half);
  const Sphere ball(0.1);
  const Plane ground(Vec3::UnitZ(), 0.0);
  std::vector<SolverBody> bodies;
  std::vector<const Shape*> shapes;
  for (int i = 0; i < 11; ++i) {
    const double x = 0.5 * i;
    const int kind = i % 3;  // 0: box flat (4 points), 1: box on an edge (2), 2: ball (1)
    Quat q = Quat::Identity();
    double z = half.z() - 1e-3;
    if (kind == 1) {  // tilted about y: its lowest edge 1 mm deep
      q = Quat(AngleAxis(std::numbers::pi / 4 + 0.05 * i, Vec3::UnitY()));
      const Mat3 r = q.toRotationMatrix();
      z = half.x() * std::abs(r(2, 0)) + half.y() * std::abs(r(2, 1)) + half.z() * std::abs(r(2, 2)) - 1e-3;
    }
    SolverBody b = SolverBody::dynamic(1.0 + 0.1 * i, boxInertia(1.0 + 0.1 * i, half), {x, 0.0, z}, q);
    // Sliding (large tangential speed), sticking (small), lifting off (i = 7).
    b.linearVelocity = Vec3((i % 2) ? 3.0 : 0.01, 0.2 * i - 1.0, i == 7 ? 2.0 : -0.5);
    b.angularVelocity = Vec3(0.1 * i, -0.3, 0.05 * i);
    bodies.push_back(b);
    shapes.push_back(kind == 2 ? static_cast<const Shape*>(&ball) : &box);
  }
  CollisionResult scratch;
  std::vector<ContactConstraint> all;
  std::vector<std::size_t> first;  // first contact of each body
  for (std::size_t i = 0; i < bodies.size(); ++i) {
    first.push_back(all.size());
    addContacts(ground, kWorldBody, *shapes[i], static_cast<int>(i), bodies, 0.4 + 0.05 * double(i), 0.0, all,
                scratch);
  }
  first.push_back(all.size());
  for (std::size_t k = 0; k < all.size(); ++k) {  // warm-start impulses
    all[k].normalImpulse = 0.01 * double(k % 5);
    all[k].frictionImpulse = Vec3(0.002 * double(k % 3), -0.001, 0.0);
  }
  std::vector<Joint> noJoints;
  const SolverOptions options{.velocityIterations = 7, .positionIterations = 3};
  std::vector<SolverBody> together = bodies;
  ConstraintSolver solver;
  ASSERT_TRUE(solver.solve(together, all, noJoints, 1.0 / 60.0, options));
  for (std::size_t i = 0; i < bodies.size(); ++i) {
    std::vector<SolverBody> alone{bodies[i]};
    std::vector<ContactConstraint> own(all.begin() + static_cast<std::ptrdiff_t>(first[i]),
                                       all.begin() + static_cast<std::ptrdiff_t>(first[i + 1]));
    ASSERT_FALSE(own.empty()) << "body " << i;
    for (std::size_t k = 0; k < own.size(); ++k) {  // the incoming impulses
      own[k].bodyB = 0;
      own[k].normalImpulse = 0.01 * double((first[i] + k) % 5);
      own[k].frictionImpulse = Vec3(0.002 * double((first[i] + k) % 3), -0.001, 0.0);
    }
    ConstraintSolver single;
    ASSERT_TRUE(single.solve(alone, own, noJoints, 1.0 / 60.0, options));
    const SolverBody& t = together[i];
    EXPECT_EQ(t.linearVelocity, alone[0].linearVelocity) << "body " << i;
    EXPECT_EQ(t.angularVelocity, alone[0].angularVelocity) << "body " << i;
    EXPECT_EQ(t.pushVelocity, alone[0].pushVelocity) << "body " << i;
    EXPECT_EQ(t.turnVelocity, alone[0].turnVelocity) << "body " << i;
    for (std::size_t k = 0; k < own.size(); ++k) {
      EXPECT_EQ(all[first[i] + k].normalImpulse, own[k].normalImpulse) << "body " << i << " contact " << k;
      EXPECT_EQ(all[first[i] + k].frictionImpulse, own[k].frictionImpulse) << "body " << i << " contact " << k;
    }
  }
  // The scene exercises what it should: sliding and sticking contacts.
  int sliding = 0, sticking = 0;
  for (const ContactConstraint& c : all) {
    if (!(c.normalImpulse > 0.0)) continue;
    (c.frictionImpulse.norm() > (1.0 - 1e-9) * c.friction * c.normalImpulse ? sliding : sticking) += 1;
  }
  EXPECT_GT(sliding, 0);
  EXPECT_GT(sticking, 0);
}

// The cache hands impulses to the same feature key, or to the contact at the
// same point of body A (its frame moves with the body), never across pairs.
TEST(ConstraintSolver, ContactCacheMatchesByKeyOrAnchorInBodyFrame) {
  std::vector<SolverBody> bodies{SolverBody::dynamic(1.0, Mat3::Identity(), {0, 0, 0}),
                                 SolverBody::dynamic(1.0, Mat3::Identity(), {0, 0, 1})};
  const auto make = [](int a, int b, const Vec3& p, std::uint64_t key, double impulse) {
    ContactConstraint c = ContactConstraint::make(a, b, ContactPoint{p, Vec3::UnitZ(), 0.0});
    c.featureKey = key;
    c.normalImpulse = impulse;
    c.frictionImpulse = Vec3(impulse, 0, 0);
    return c;
  };
  ContactCache cache;
  cache.reserve(8);
  std::vector<ContactConstraint> old{make(0, 1, {0.1, 0, 0.5}, 0, 1.0), make(0, 1, {-0.1, 0, 0.5}, 0, 2.0),
                                     make(kWorldBody, 0, {0, 0, 0}, 7, 3.0),
                                     make(kWorldBody, 0, {0, 0, 0}, 9, 4.0)};
  cache.store(old, bodies);
  EXPECT_EQ(cache.size(), 4u);
  // Next step: body 0 has turned by 90° about z and moved; the same body
  // points are now elsewhere in the world.
  bodies[0].orientation = Quat(AngleAxis(std::numbers::pi / 2, Vec3::UnitZ()));
  bodies[0].position = {0.3, 0, 0};
  std::vector<ContactConstraint> next{
      make(0, 1, bodies[0].position + bodies[0].orientation * Vec3(-0.1, 0, 0.5), 0, 0.0),
      make(0, 1, bodies[0].position + bodies[0].orientation * Vec3(0.1, 0, 0.5), 0, 0.0),
      make(kWorldBody, 0, {5, 5, 5}, 9, 0.0),                         // same key, anywhere
      make(0, 1, {0.3, 0.0, 3.0}, 0, 0.0),                            // no old point there
      make(1, 0, bodies[0].position + Vec3(0.0, 0.1, 0.5), 0, 0.0)};  // other pair order
  EXPECT_EQ(cache.warmStart(next, bodies), 3);
  EXPECT_DOUBLE_EQ(next[0].normalImpulse, 2.0);
  EXPECT_DOUBLE_EQ(next[1].normalImpulse, 1.0);
  EXPECT_DOUBLE_EQ(next[2].normalImpulse, 4.0);
  EXPECT_DOUBLE_EQ(next[3].normalImpulse, 0.0);
  EXPECT_DOUBLE_EQ(next[4].normalImpulse, 0.0);
  // The friction impulse turned with body A: (1, 0, 0) → (0, 1, 0).
  EXPECT_LT((next[1].frictionImpulse - Vec3(0, 1, 0)).norm(), 1e-12);
}

TEST(ConstraintSolver, RejectsBadInputWithAMessage) {
  std::vector<SolverBody> bodies{SolverBody::dynamic(1.0, Mat3::Identity(), {0, 0, 0})};
  std::vector<Joint> joints;
  ConstraintSolver solver;
  ContactPoint p;
  std::vector<ContactConstraint> contacts{ContactConstraint::make(0, 3, p)};
  auto bad = solver.solve(bodies, contacts, joints, 1e-3, {});
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.error().message().find("contacts[0]"), std::string::npos) << bad.error().message();
  contacts[0].bodyB = kWorldBody;
  EXPECT_FALSE(solver.solve(bodies, contacts, joints, 0.0, {}));
  contacts[0].point.normal = {0, 0, 2};
  EXPECT_FALSE(solver.solve(bodies, contacts, joints, 1e-3, {}));
  EXPECT_FALSE(Joint::ball(bodies, 0, 0, Vec3::Zero()));
  EXPECT_FALSE(Joint::hinge(bodies, kWorldBody, 0, Vec3::Zero(), Vec3::Zero()));
  EXPECT_FALSE(Joint::slider(bodies, kWorldBody, 5, Vec3::Zero(), Vec3::UnitX()));
  EXPECT_EQ(bodies[0].linearVelocity, Vec3::Zero());
}

}  // namespace
}  // namespace dm
