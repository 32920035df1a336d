// dm::ParticleObstacles against mechanics: a membrane on a slope slides at
// g (sin θ − μ cos θ) when tan θ > μ and holds when tan θ ≤ μ (Coulomb,
// both integrators, with and without a thickness); a sheet dropped on a
// sphere drapes over it with no particle inside, its top at the sphere's
// top plus the thickness, and the sphere carries its weight (1 %); a sheet
// dropped onto a plate thinner than one step's travel stops on it; a free
// plate thinner than one step's travel that hits a free sheet passes its
// momentum exactly (every step) and both end at M V / (M + m) (1 %); a free
// ball dropped on a sheet held at its rim comes to rest carried by it, the
// rim carrying both weights (1 %); a kinematic plate carries a sheet
// resting on it along by friction; bad obstacles are refused by name.
#include <dm/collide/bvh.hpp>
#include <dm/collide/mesh_query.hpp>
#include <dm/math/primitives.hpp>
#include <dm/physics/mass_spring.hpp>
#include <dm/physics/particle_obstacles.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

namespace particle_obstacles_test {

using dm::Isometry3;
using dm::MassSpringBody;
using dm::MeshBvh;
using dm::ParticleObstacle;
using dm::ParticleObstacles;
using dm::Vec3;

constexpr double kG = 9.81;

MeshBvh tree(const dm::Mesh& mesh) {
  auto t = MeshBvh::build(mesh);
  EXPECT_TRUE(t.ok());
  return std::move(*t);
}

// A 2 cm triangle of three particles on the top face of a box tilted by
// `angle` about y (its top face through the origin), stepped for `seconds`;
// returns the particles' mean velocity along the slope's downhill direction
// and their largest distance from the face's plane.
struct SlopeRun {
  double downhillSpeed = 0.0;
  double offPlane = 0.0;
  double moved = 0.0;
};
SlopeRun slide(double angle, double mu, double thickness, bool implicit, double seconds) {
  const MeshBvh box = tree(dm::makeBox(Vec3(2.0, 2.0, 0.05)));  // 4 m long: it slides 0.6 m in 0.5 s
  Isometry3 pose = Isometry3::Identity();
  pose.rotate(Eigen::AngleAxisd(angle, Vec3::UnitY()));
  pose.translate(Vec3(0, 0, -0.05));  // the top face at the origin
  const Vec3 normal = pose.linear() * Vec3::UnitZ();
  const Vec3 downhill = (Vec3(0, 0, -kG) - Vec3(0, 0, -kG).dot(normal) * normal).normalized();
  MassSpringBody body;
  const Isometry3 face = pose * Eigen::Translation3d(0, 0, 0.05);
  for (const Vec3& p : {Vec3(0, 0, 0), Vec3(0.02, 0, 0), Vec3(0.01, 0.017, 0)})
    EXPECT_TRUE(body.addParticle(face * p + thickness * normal, 1e-3).ok());
  const dm::SpringMaterial stiff{true, 200.0, 0.0, dm::SpringModel::KelvinVoigt};
  for (auto [a, b] : {std::pair{0u, 1u}, {1u, 2u}, {2u, 0u}}) EXPECT_TRUE(body.addElement(a, b, stiff).ok());
  body.setGravity(Vec3(0, 0, -kG));
  const ParticleObstacle o{.tree = &box, .pose = pose, .friction = mu};
  auto contacts = ParticleObstacles::create({&o, 1}, thickness);
  EXPECT_TRUE(contacts.ok());
  const Vec3 start = body.position(0);
  const double h = 2e-3;
  const int steps = static_cast<int>(std::lround(seconds / h));
  for (int s = 0; s < steps; ++s) {
    if (implicit)
      EXPECT_TRUE(body.stepImplicit(h).ok());
    else
      EXPECT_TRUE(body.stepSymplectic(h));
    EXPECT_EQ(
        contacts->resolve(body, h, implicit ? dm::ParticleStep::Implicit : dm::ParticleStep::Symplectic), 3u);
  }
  SlopeRun run;
  for (std::size_t i = 0; i < 3; ++i) {
    run.downhillSpeed += body.velocity(i).dot(downhill) / 3.0;
    run.offPlane =
        std::max(run.offPlane, std::abs((body.position(i) - face.translation()).dot(normal) - thickness));
  }
  run.moved = (body.position(0) - start).norm();
  return run;
}

TEST(ParticleObstacles, AMembraneOnASlopeSlidesAtGSinMinusMuCosOrHoldsByCoulombsLaw) {
  const double angle = 30.0 * std::numbers::pi / 180.0;  // tan θ = 0.577
  for (const bool implicit : {true, false})
    for (const double thickness : {0.0, 1e-3}) {
      SCOPED_TRACE(testing::Message() << "implicit " << implicit << ", thickness " << thickness);
      const double t = 0.5, mu = 0.3;
      const SlopeRun sliding = slide(angle, mu, thickness, implicit, t);
      const double expected = kG * (std::sin(angle) - mu * std::cos(angle)) * t;
      EXPECT_NEAR(sliding.downhillSpeed, expected, 0.01 * expected);
      EXPECT_LT(sliding.offPlane, 1e-9);
      const SlopeRun frictionless = slide(angle, 0.0, thickness, implicit, t);
      EXPECT_NEAR(frictionless.downhillSpeed, kG * std::sin(angle) * t, 0.01 * kG * std::sin(angle) * t);
      const SlopeRun held = slide(angle, 0.6, thickness, implicit, 1.0);  // just above tan θ
      EXPECT_LT(held.moved, 1e-9);
      EXPECT_LT(std::abs(held.downhillSpeed), 1e-9);
    }
}

// A sheet of `side` metres (n × n nodes, 10 g) centred over a static mesh,
// its centre `gap` above it, dropped and run for `seconds`.
struct Drop {
  MassSpringBody sheet;
  ParticleObstacles contacts;
};
Drop drop(const MeshBvh& obstacle, double top, double side, int n, double gap, double mu, double thickness,
          double h, double seconds) {
  auto sheet = MassSpringBody::makeSheet({.nx = n,
                                          .ny = n,
                                          .width = side,
                                          .height = side,
                                          .origin = Vec3(-0.5 * side, -0.5 * side, top + gap),
                                          .mass = 0.01,
                                          .structural = {true, 40.0, 0.02, dm::SpringModel::KelvinVoigt},
                                          .shear = {true, 20.0, 0.01, dm::SpringModel::KelvinVoigt},
                                          .bend = {true, 0.5, 0.0, dm::SpringModel::KelvinVoigt}});
  EXPECT_TRUE(sheet.ok());
  sheet->setGravity(Vec3(0, 0, -kG));
  EXPECT_TRUE(sheet->setDrag(4.0));
  const ParticleObstacle o{.tree = &obstacle, .pose = Isometry3::Identity(), .friction = mu};
  auto contacts = ParticleObstacles::create({&o, 1}, thickness);
  EXPECT_TRUE(contacts.ok());
  const int steps = static_cast<int>(std::lround(seconds / h));
  for (int s = 0; s < steps; ++s) {
    EXPECT_TRUE(sheet->stepImplicit(h).ok());
    contacts->resolve(*sheet, h);
  }
  return {std::move(*sheet), std::move(*contacts)};
}

TEST(ParticleObstacles, ASheetDrapesOverASphereWhichCarriesItsWeight) {
  const double r = 0.03, thickness = 5e-4;
  const dm::Mesh ball = dm::makeIcosphere(r, 4);  // a vertex at (0, 0, r)
  const MeshBvh sphere = tree(ball);
  Drop d = drop(sphere, r, 0.08, 25, 0.01, 1.0, thickness, 5e-3, 3.0);
  const MassSpringBody& s = d.sheet;
  double highest = -HUGE_VAL, closest = HUGE_VAL;
  for (std::size_t i = 0; i < s.particleCount(); ++i) {
    highest = std::max(highest, s.position(i).z());
    closest =
        std::min(closest, dm::closestPointOnMesh(sphere, Isometry3::Identity(), s.position(i)).distance);
  }
  EXPECT_GE(closest, thickness - 1e-9);       // nothing inside, nor nearer than the thickness
  EXPECT_NEAR(highest, r + thickness, 1e-6);  // the centre node rests on the sphere's top vertex
  EXPECT_LT(s.position(0).z(), r - 0.01);     // the corners hang down its sides
  EXPECT_GT(d.contacts.contacts(), 100u);
  const Vec3 f = d.contacts.force(0);
  EXPECT_NEAR(f.z(), -0.01 * kG, 0.01 * 0.01 * kG);  // the sphere carries the weight
  EXPECT_LT(std::hypot(f.x(), f.y()), 1e-3 * 0.01 * kG);
  EXPECT_LT(s.kineticEnergy(), 1e-9);
}

TEST(ParticleObstacles, ASheetFallingOntoAPlateThinnerThanOneStepsTravelStopsOnIt) {
  // 1 mm thick; the sheet hits it at about 1 m/s, 5 mm a step at 200 Hz.
  const MeshBvh plate = tree(dm::makeBox(Vec3(0.1, 0.1, 0.5e-3)));
  Drop d = drop(plate, 0.5e-3, 0.06, 13, 0.05, 0.5, 0.0, 5e-3, 2.0);
  for (std::size_t i = 0; i < d.sheet.particleCount(); ++i)
    EXPECT_NEAR(d.sheet.position(i).z(), 0.5e-3, 1e-9) << "particle " << i;
  EXPECT_NEAR(d.contacts.force(0).z(), -0.01 * kG, 0.01 * 0.01 * kG);
}

Vec3 momentum(const MassSpringBody& s) {
  Vec3 p = Vec3::Zero();
  for (std::size_t i = 0; i < s.particleCount(); ++i) p += s.mass(i) * s.velocity(i);
  return p;
}

// A free rigid body and a membrane stepped together in the order the
// header gives: gravity into the body's velocity; the membrane's step with
// the body's mass lent to the particles touching it; the contacts at the
// body's pose at the step's end, as its velocity then predicts; then the
// body's position and orientation from its final velocity (what a world's
// step does after contact: symplectic Euler).
struct FreeBody {
  Isometry3 pose = Isometry3::Identity();  // the tree's frame, centre of mass at its origin
  Vec3 velocity = Vec3::Zero(), spin = Vec3::Zero();

  Isometry3 advanced(double h) const {
    Isometry3 next = pose;
    next.pretranslate(h * velocity);
    const double angle = h * spin.norm();
    if (angle > 0.0) {
      const Vec3 c = next.translation();
      next.pretranslate(-c).prerotate(Eigen::AngleAxisd(angle, spin.normalized())).pretranslate(c);
    }
    return next;
  }
  std::size_t step(MassSpringBody& membrane, ParticleObstacles& contacts, const Vec3& gravity, double h,
                   bool implicit) {
    velocity += h * gravity;
    EXPECT_TRUE(contacts.setMotion(0, pose, velocity, spin).ok());
    contacts.beforeStep(membrane);
    if (implicit)
      EXPECT_TRUE(membrane.stepImplicit(h).ok());
    else
      EXPECT_TRUE(membrane.stepSymplectic(h).ok());
    contacts.afterStep(membrane, h);
    velocity = contacts.velocity(0), spin = contacts.spin(0);
    EXPECT_TRUE(contacts.setMotion(0, advanced(h), velocity, spin).ok());
    const std::size_t n =
        contacts.resolve(membrane, h, implicit ? dm::ParticleStep::Implicit : dm::ParticleStep::Symplectic);
    velocity = contacts.velocity(0), spin = contacts.spin(0);
    pose = advanced(h);
    return n;
  }
};

dm::Result<MassSpringBody> sheet(int n, double side, double mass, double z, double stiffness = 40.0) {
  return MassSpringBody::makeSheet({.nx = n,
                                    .ny = n,
                                    .width = side,
                                    .height = side,
                                    .origin = Vec3(-0.5 * side, -0.5 * side, z),
                                    .mass = mass,
                                    .structural = {true, stiffness, 0.02, dm::SpringModel::KelvinVoigt},
                                    .shear = {true, 0.5 * stiffness, 0.01, dm::SpringModel::KelvinVoigt},
                                    .bend = {true, 0.5, 0.0, dm::SpringModel::KelvinVoigt}});
}

TEST(ParticleObstacles, AThinFreePlateHittingAFreeSheetTakesItAlongAsMomentumSays) {
  // A 6 × 6 cm plate 0.2 mm thick (50 g) at 5 m/s: 0.5 mm a step, more
  // than its thickness; a free 10 g sheet (4 × 4 cm) at rest below it. No
  // gravity: momentum is conserved, to rounding, at every step, and the
  // sheet, hit all over at once, moves on with the plate at M V / (M + m)
  // (a perfectly inelastic collision; the contacts solved together).
  const double M = 0.05, m = 0.01, V = 5.0, h = 1e-4;
  const Vec3 half(0.03, 0.03, 1e-4);
  const MeshBvh plate = tree(dm::makeBox(half));
  const Vec3 Ib(M / 3.0 * (half.y() * half.y() + half.z() * half.z()),
                M / 3.0 * (half.x() * half.x() + half.z() * half.z()),
                M / 3.0 * (half.x() * half.x() + half.y() * half.y()));
  FreeBody box;
  box.pose.translation() = Vec3(0, 0, 2e-3);
  box.velocity = Vec3(0, 0, -V);
  auto s = sheet(13, 0.04, m, 0.0);
  ASSERT_TRUE(s.ok());
  const ParticleObstacle o{.tree = &plate,
                           .pose = box.pose,
                           .friction = 0.5,
                           .inverseMass = 1.0 / M,
                           .inverseInertia = Ib.cwiseInverse().asDiagonal()};
  auto contacts = ParticleObstacles::create({&o, 1}, 0.0);
  ASSERT_TRUE(contacts.ok());
  const Vec3 p0 = M * box.velocity;
  std::size_t touched = 0;
  for (int k = 0; k < 1000; ++k) {  // 0.1 s
    touched += box.step(*s, *contacts, Vec3::Zero(), h, false);
    ASSERT_LT((momentum(*s) + M * box.velocity - p0).norm(), 1e-12 * p0.norm()) << "step " << k;
  }
  EXPECT_GE(touched, s->particleCount());
  const double common = M * V / (M + m);
  EXPECT_NEAR(-box.velocity.z(), common, 1e-6 * common);
  for (std::size_t i = 0; i < s->particleCount(); ++i) {
    EXPECT_NEAR(-s->velocity(i).z(), common, 1e-6 * common) << "particle " << i;
    const Vec3 local = box.pose.inverse() * s->position(i);  // none went through
    ASSERT_LT(local.z(), -half.z() + 1e-9) << "particle " << i;
  }
}

TEST(ParticleObstacles, AFreeBallDroppedOnAHeldSheetRestsOnItAndTheRimCarriesBoth) {
  // A 20 g ball (r 1.5 cm) dropped 1 cm, off centre, onto a 10 g sheet
  // 10 cm wide held at its rim, at 500 Hz: it comes to rest in the sag,
  // the sheet carrying its weight and the rim both (1 %), no
  // particle inside it. (By impulses alone it fell through: the springs
  // behind the few particles it touched never reached it within a step.)
  const double M = 0.02, m = 0.01, r = 0.015, h = 2e-3;
  const MeshBvh ball = tree(dm::makeIcosphere(r, 3));
  auto s = sheet(17, 0.1, m, 0.0, 400.0);
  ASSERT_TRUE(s.ok());
  s->setGravity(Vec3(0, 0, -kG));
  ASSERT_TRUE(s->setDrag(4.0).ok());
  std::vector<std::uint32_t> rim;
  for (std::uint32_t i = 0; i < s->particleCount(); ++i) {
    const Vec3 p = s->position(i);
    if (std::max(std::abs(p.x()), std::abs(p.y())) > 0.05 - 1e-9) {
      s->setPinned(i, true);
      rim.push_back(i);
    }
  }
  FreeBody b;
  b.pose.translation() = Vec3(0.004, -0.003, r + 0.01);
  const double inverseI = 1.0 / (0.4 * M * r * r);
  const ParticleObstacle o{.tree = &ball,
                           .pose = b.pose,
                           .friction = 0.5,
                           .inverseMass = 1.0 / M,
                           .inverseInertia = inverseI * dm::Mat3::Identity()};
  auto contacts = ParticleObstacles::create({&o, 1}, 0.0);
  ASSERT_TRUE(contacts.ok());
  const Vec3 g(0, 0, -kG);
  for (int k = 0; k < 4000; ++k) b.step(*s, *contacts, g, h, true);  // 8 s
  // At rest (its rocking in the sag died out, to a noise of 0.3 mm/s) in
  // the sag, below the sheet's plane: near the middle, where it landed 5 mm
  // off (the dent it makes moves with it; the sheet's own sag is too
  // shallow there to roll it against the contacts' friction), not rolled
  // off towards the rim.
  EXPECT_LT(b.velocity.norm(), 1e-3);
  EXPECT_LT(std::hypot(b.pose.translation().x(), b.pose.translation().y()), 0.01);
  EXPECT_LT(b.pose.translation().z(), r - 1e-3);
  EXPECT_GE(contacts->contacts(), 3u);
  for (std::size_t i = 0; i < s->particleCount(); ++i)
    ASSERT_GT((s->position(i) - b.pose.translation()).norm(), 0.99 * r);  // the faces are within 0.4 % of r
  // What the sheet puts on the ball: its weight, upward.
  EXPECT_NEAR(contacts->force(0).z(), M * kG, 0.01 * M * kG);
  Vec3 rimLoad = Vec3::Zero();
  for (std::uint32_t i : rim) rimLoad += s->elementForceOn(i) + s->mass(i) * g;
  EXPECT_NEAR(rimLoad.z(), -(M + m) * kG, 0.01 * (M + m) * kG);
}

TEST(ParticleObstacles, AMovingPlateCarriesASheetRestingOnItByFriction) {
  // A kinematic plate (no mass given: nothing moves it but its motion)
  // slides at 0.1 m/s under a sheet resting on it; with μ = 1 the sheet
  // rides along, without it the sheet stays where it was.
  const MeshBvh plate = tree(dm::makeBox(Vec3(0.5, 0.5, 1e-3)));
  for (const double mu : {1.0, 0.0}) {
    SCOPED_TRACE(testing::Message() << "mu " << mu);
    auto s = sheet(9, 0.04, 0.01, 1e-3);
    ASSERT_TRUE(s.ok());
    s->setGravity(Vec3(0, 0, -kG));
    Isometry3 pose = Isometry3::Identity();
    const ParticleObstacle o{.tree = &plate, .pose = pose, .friction = mu};
    auto contacts = ParticleObstacles::create({&o, 1}, 0.0);
    ASSERT_TRUE(contacts.ok());
    const double h = 2e-3, speed = 0.1;
    for (int k = 0; k < 500; ++k) {  // 1 s: 10 cm
      pose.pretranslate(Vec3(h * speed, 0, 0));
      ASSERT_TRUE(s->stepImplicit(h).ok());
      ASSERT_TRUE(contacts->setMotion(0, pose, Vec3(speed, 0, 0), Vec3::Zero()).ok());
      EXPECT_EQ(contacts->resolve(*s, h), s->particleCount());
    }
    const double moved = momentum(*s).x() / 0.01;
    if (mu > 0.0) {
      // Friction μ m g brings it to the plate's speed after v/(μ g), the
      // sheet lagging v²/(2 μ g) behind (to one step's travel).
      EXPECT_NEAR(moved, speed, 1e-9);
      EXPECT_NEAR(s->position(0).x(), -0.02 + 0.1 - speed * speed / (2.0 * mu * kG), h * speed);
    } else {
      EXPECT_NEAR(moved, 0.0, 1e-9);
      EXPECT_NEAR(s->position(0).x(), -0.02, 1e-9);
    }
    EXPECT_NEAR(s->position(40).z(), 1e-3, 1e-9);  // on the plate's top
  }
}

TEST(ParticleObstacles, BadObstaclesAreRefusedByName) {
  const MeshBvh closed = tree(dm::makeBox(Vec3(0.1, 0.1, 0.1)));
  const MeshBvh open = tree(dm::makePlane(0.1, 0.1, 1));
  const auto error = [](std::span<const ParticleObstacle> o, double thickness) {
    auto r = ParticleObstacles::create(o, thickness);
    return r ? std::string() : r.error().where;
  };
  ParticleObstacle o{.tree = &closed};
  EXPECT_EQ(error({&o, 1}, 0.0), "");
  EXPECT_EQ(error({&o, 1}, -1.0), "ParticleObstacles::create: thickness");
  EXPECT_EQ(error({&o, 1}, NAN), "ParticleObstacles::create: thickness");
  o.friction = -0.1;
  EXPECT_EQ(error({&o, 1}, 0.0), "ParticleObstacles::create: obstacles[0].friction");
  o = {.tree = &open};
  EXPECT_EQ(error({&o, 1}, 0.0), "ParticleObstacles::create: obstacles[0]");
  o = {.tree = nullptr};
  EXPECT_EQ(error({&o, 1}, 0.0), "ParticleObstacles::create: obstacles[0]");
  o = {.tree = &closed};
  o.pose.linear() *= 2.0;
  EXPECT_EQ(error({&o, 1}, 0.0), "ParticleObstacles::create: obstacles[0].pose");
  o = {.tree = &closed, .inverseMass = -1.0};
  EXPECT_EQ(error({&o, 1}, 0.0), "ParticleObstacles::create: obstacles[0].inverseMass");
  o = {.tree = &closed, .inverseMass = 1.0, .inverseInertia = -dm::Mat3::Identity()};
  EXPECT_EQ(error({&o, 1}, 0.0), "ParticleObstacles::create: obstacles[0].inverseInertia");
  o.inverseInertia = dm::Mat3::Identity();
  o.inverseInertia(0, 1) = 0.5;  // not symmetric
  EXPECT_EQ(error({&o, 1}, 0.0), "ParticleObstacles::create: obstacles[0].inverseInertia");
  o = {.tree = &closed, .centerOfMass = Vec3(NAN, 0, 0)};
  EXPECT_EQ(error({&o, 1}, 0.0), "ParticleObstacles::create: obstacles[0].centerOfMass");
  // A bad motion is refused and changes nothing.
  o = {.tree = &closed};
  auto moving = ParticleObstacles::create({&o, 1}, 0.0);
  ASSERT_TRUE(moving.ok());
  EXPECT_EQ(moving->setMotion(1, Isometry3::Identity(), Vec3::Zero(), Vec3::Zero()).error().where,
            "ParticleObstacles::setMotion: i");
  Isometry3 scaled = Isometry3::Identity();
  scaled.linear() *= 2.0;
  EXPECT_EQ(moving->setMotion(0, scaled, Vec3::Zero(), Vec3::Zero()).error().where,
            "ParticleObstacles::setMotion: pose");
  EXPECT_EQ(moving->setMotion(0, Isometry3::Identity(), Vec3(0, NAN, 0), Vec3::Zero()).error().where,
            "ParticleObstacles::setMotion: velocity");
  EXPECT_EQ(moving->velocity(0), Vec3::Zero());
  // Nothing to resolve: a bad step changes nothing.
  auto contacts = ParticleObstacles::create({}, 0.0);
  ASSERT_TRUE(contacts.ok());
  MassSpringBody body;
  ASSERT_TRUE(body.addParticle(Vec3::Zero(), 1.0).ok());
  EXPECT_EQ(contacts->resolve(body, NAN), 0u);
  EXPECT_EQ(contacts->obstacleCount(), 0u);
}

}  // namespace particle_obstacles_test
