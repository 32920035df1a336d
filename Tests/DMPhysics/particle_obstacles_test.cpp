// dm::ParticleObstacles against mechanics: a membrane on a slope slides at
// g (sin θ − μ cos θ) when tan θ > μ and holds when tan θ ≤ μ (Coulomb,
// both integrators, with and without a thickness); a sheet dropped on a
// sphere drapes over it with no particle inside, its top at the sphere's
// top plus the thickness, and the sphere carries its weight (1 %); a sheet
// dropped onto a plate thinner than one step's travel stops on it; bad
// obstacles are refused by name.
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
  // Nothing to resolve: a bad step changes nothing.
  auto contacts = ParticleObstacles::create({}, 0.0);
  ASSERT_TRUE(contacts.ok());
  MassSpringBody body;
  ASSERT_TRUE(body.addParticle(Vec3::Zero(), 1.0).ok());
  EXPECT_EQ(contacts->resolve(body, NAN), 0u);
  EXPECT_EQ(contacts->obstacleCount(), 0u);
}

}  // namespace particle_obstacles_test
