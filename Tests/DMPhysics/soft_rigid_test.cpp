// Two-way soft–rigid contact (dm/physics/soft_rigid.hpp) against physics: a
// rigid box settles on clamped tissue with the tissue carrying exactly its
// weight, at the same depth at a 10 ms and a 1 ms step, and on the same
// tissue placed in a frame of its own; a gram-light body on stiff contact
// at a 10 ms step stays stable (explicit force exchange at that step
// diverges, which the test shows); a free ball hitting a free tissue block
// conserves the total linear momentum, and hitting it at an angle with
// friction across the contact it spins forward with both momenta
// conserved; bad couplings are refused by index.
#include <dm/collide/bvh.hpp>
#include <dm/math/primitives.hpp>
#include <dm/physics/soft_rigid.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <numbers>
#include <utility>

#include "../common/alloc_counter.hpp"
#include "physics_test_support.hpp"

namespace dm {
namespace {

using dm::test::kG;

using dm::test::treeOf;

// A 4 × 4 × 2 cm tissue slab, E = 10 kPa, base clamped unless `free`.
FemBody slab(bool free, double alpha = 5.0) {
  auto mesh = tetMeshBox({8, 8, 4}, Vec3(0.04, 0.04, 0.02));
  EXPECT_TRUE(mesh.ok());
  auto body = FemBody::create(*mesh, {.youngsModulus = 1e4, .poissonRatio = 0.45, .density = 1000},
                              {.alpha = alpha, .beta = 0.01}, {.tolerance = 1e-8, .maxIterations = 1000});
  EXPECT_TRUE(body.ok());
  if (!free) body->fixNodesWhere([](const Vec3& p) { return p.z() < 1e-9; });
  return std::move(*body);
}

// A rigid box of half extents `half` and density rho, its bottom `gap` above the slab's top centre.
BodyId addBox(PhysicsWorld& world, const Vec3& half, double rho, double gap) {
  auto d = rigidBodyFromMesh(makeBox(half), rho);
  EXPECT_TRUE(d.ok());
  d->kind = BodyKind::Rigid;
  d->name = "box";
  d->position = Vec3(0.02, 0.02, 0.02 + half.z() + gap);
  auto id = world.addBody(*d);
  EXPECT_TRUE(id.ok());
  return *id;
}

TEST(SoftRigid, BoxSettlesOnTissueThatCarriesItsWeight) {
  FemBody tissue = slab(false);
  tissue.setGravity({0, 0, -kG});
  PhysicsWorld world;
  ASSERT_TRUE(world.setGravity({0, 0, -kG}));
  const Vec3 half(0.01, 0.01, 0.005);
  const BodyId box = addBox(world, half, 1000, 0.0005);
  const MeshBvh tree = treeOf(makeBox(half));
  const SoftRigidContact contact{.body = box, .tree = &tree, .stiffness = 1e4};
  auto coupling = SoftRigidCoupling::create(world, tissue, {&contact, 1});
  ASSERT_TRUE(coupling.ok()) << coupling.error().message();
  WorldState state = world.makeState();
  const double weight = world.bodies()[box.index].mass * kG;
  for (int i = 0; i < 300; ++i) ASSERT_TRUE(coupling->step(state, 0.01).ok()) << "step " << i;
  const Wrench w = coupling->wrench(0);
  std::printf("box: tissue carries %.5f N of its weight %.5f N; sank %.3f mm; |v| = %.2e m/s\n", w.force.z(),
              weight, (0.02 + half.z() + 0.0005 - state.position(box).z()) * 1e3,
              state.linearVelocity(box).norm());
  EXPECT_NEAR(w.force.z(), weight, 0.01 * weight);
  EXPECT_LT(w.force.head<2>().norm(), 1e-3 * weight);
  EXPECT_LT(w.torque.norm(), 1e-3 * weight * half.x());
  EXPECT_LT(state.linearVelocity(box).norm(), 1e-4);
  EXPECT_LT(state.angularVelocity(box).norm(), 1e-3);
  // It sank into the tissue (which sagged under both weights) and stayed level.
  EXPECT_LT(state.position(box).z(), 0.02 + half.z());
  EXPECT_GT(state.orientation(box).w(), 1 - 1e-6);
  // The real-time path: coupled steps allocate nothing.
  const auto before = test::countedAllocations();
  for (int i = 0; i < 5; ++i) {
    test::tCountAllocations = true;
    const bool stepped = coupling->step(state, 0.01).ok();
    test::tCountAllocations = false;
    ASSERT_TRUE(stepped);
  }
  EXPECT_EQ(test::countedAllocations(), before);
}

// The split step solves the tissue's contact for the velocity the body will
// have after the world's gravity (gravity, contact, positions). The box's
// rest depth is then the same at a 10 ms and a 1 ms step, to a micrometre;
// solving contact before gravity let the world push it g·h² (1 mm at 10 ms)
// deeper each step.
TEST(SoftRigid, ABoxRestsAtTheSameDepthAtAnyStep) {
  const Vec3 half(0.01, 0.01, 0.005);
  const MeshBvh tree = treeOf(makeBox(half));
  auto restHeight = [&](double h) {
    FemBody tissue = slab(false);
    tissue.setGravity({0, 0, -kG});
    PhysicsWorld world;
    EXPECT_TRUE(world.setGravity({0, 0, -kG}));
    const BodyId box = addBox(world, half, 1000, 0.0005);
    const SoftRigidContact contact{.body = box, .tree = &tree, .stiffness = 1e4};
    auto coupling = SoftRigidCoupling::create(world, tissue, {&contact, 1});
    EXPECT_TRUE(coupling.ok());
    WorldState state = world.makeState();
    for (int i = 0; i < static_cast<int>(std::lround(1.5 / h)); ++i)
      EXPECT_TRUE(coupling->step(state, h).ok());
    EXPECT_LT(state.linearVelocity(box).norm(), 1e-4) << "h = " << h;
    EXPECT_NEAR(coupling->wrench(0).force.z(), world.bodies()[box.index].mass * kG,
                0.002 * world.bodies()[box.index].mass * kG);
    return state.position(box).z();
  };
  const double coarse = restHeight(0.01), fine = restHeight(0.001);
  std::printf("box rests at %.4f mm (10 ms) and %.4f mm (1 ms)\n", coarse * 1e3, fine * 1e3);
  EXPECT_NEAR(coarse, fine, 1e-6);
  EXPECT_LT(fine, 0.02 + half.z());  // it sank into the tissue
}

// The tissue in a frame of its own (rotated 90° about x and moved: its
// local y is the world's up), carrying the box: the coupling carries poses
// and velocities across, so the box rests where it rests on the same tissue
// built in the world frame, and the wrench comes back in the world.
TEST(SoftRigid, ATissueInAFrameOfItsOwnCarriesTheBoxAsInTheWorldFrame) {
  const Vec3 half(0.01, 0.01, 0.005);
  const MeshBvh tree = treeOf(makeBox(half));
  Isometry3 place = Isometry3::Identity();  // tissue frame → world
  place.translate(Vec3(0.1, 0.2, 0.3));
  place.rotate(Eigen::AngleAxisd(std::numbers::pi / 2, Vec3::UnitX()));
  auto settle = [&](bool posed) {
    auto mesh = tetMeshBox({8, 8, 4}, Vec3(0.04, 0.04, 0.02));
    EXPECT_TRUE(mesh.ok());
    const Isometry3 toTissue = posed ? Isometry3(place.inverse()) : Isometry3::Identity();
    const Vec3 offset = posed ? Vec3(0.1, 0.2, 0.3) : Vec3::Zero();  // where the slab is in the world
    for (Vec3& p : mesh->nodes) p = toTissue * (p + offset);
    auto tissue = FemBody::create(*mesh, {.youngsModulus = 1e4, .poissonRatio = 0.45, .density = 1000},
                                  {.alpha = 5.0, .beta = 0.01}, {.tolerance = 1e-8, .maxIterations = 1000});
    EXPECT_TRUE(tissue.ok());
    const Isometry3 toWorld = toTissue.inverse();
    tissue->fixNodesWhere([&](const Vec3& p) { return (toWorld * p).z() < offset.z() + 1e-9; });
    tissue->setGravity(toWorld.linear().transpose() * Vec3(0, 0, -kG));
    PhysicsWorld world;
    EXPECT_TRUE(world.setGravity({0, 0, -kG}));
    const BodyId box = addBox(world, half, 1000, 0.0005);
    WorldState state = world.makeState();
    // Off the slab's diagonal: on it the box's yaw is a mirror-symmetric
    // choice that round-off makes either way.
    EXPECT_TRUE(world.setBodyState(state, box, state.position(box) + offset + Vec3(-0.003, 0.002, 0),
                                   Quat::Identity(), Vec3::Zero(), Vec3::Zero()));
    const SoftRigidContact contact{.body = box, .tree = &tree, .stiffness = 1e4};
    auto coupling = SoftRigidCoupling::create(world, *tissue, {&contact, 1}, toWorld);
    EXPECT_TRUE(coupling.ok());
    for (int i = 0; i < 300; ++i) EXPECT_TRUE(coupling->step(state, 0.01).ok());
    return std::pair{Vec3(state.position(box) - offset), coupling->wrench(0)};
  };
  const auto [atOrigin, w0] = settle(false);
  const auto [placed, w1] = settle(true);
  EXPECT_LT((placed - atOrigin).norm(), 1e-7) << placed.transpose() << " vs " << atOrigin.transpose();
  EXPECT_LT((w1.force - w0.force).norm(), 1e-4 * w0.force.norm()) << w1.force.transpose();
  EXPECT_GT(w1.force.z(), 0.0);
}

// A 1 g cube on contact springs of 1e5 N/m per node (25 nodes: ω ≈ 5e4
// rad/s) at h = 10 ms: far past the explicit limit h·ω < 2. Solved in one
// implicit system it rests; handing the tissue's force to the body as an
// impulse after the step (the explicit exchange) blows up.
TEST(SoftRigid, LightBodyOnStiffContactStaysStableWhereExplicitExchangeDiverges) {
  const Vec3 half(0.01, 0.01, 0.0025);
  const double density = 0.001 / (8 * half.prod());  // 1 g
  const MeshBvh tree = treeOf(makeBox(half));
  {
    FemBody tissue = slab(false);
    PhysicsWorld world;
    ASSERT_TRUE(world.setGravity({0, 0, -kG}));
    const BodyId box = addBox(world, half, density, 0.0);
    const SoftRigidContact contact{.body = box, .tree = &tree, .stiffness = 1e5};
    auto coupling = SoftRigidCoupling::create(world, tissue, {&contact, 1});
    ASSERT_TRUE(coupling.ok());
    WorldState state = world.makeState();
    const double weight = world.bodies()[box.index].mass * kG;
    for (int i = 0; i < 200; ++i) ASSERT_TRUE(coupling->step(state, 0.01).ok()) << "step " << i;
    EXPECT_NEAR(coupling->wrench(0).force.z(), weight, 0.01 * weight);
    EXPECT_LT(state.linearVelocity(box).norm(), 1e-4);
  }
  {
    // The explicit exchange: the body is a kinematic obstacle for the
    // tissue and takes the tissue's force as an impulse afterwards.
    FemBody tissue = slab(false);
    PhysicsWorld world;
    ASSERT_TRUE(world.setGravity({0, 0, -kG}));
    const BodyId box = addBox(world, half, density, 0.0);
    FemObstacle o{.tree = &tree, .stiffness = 1e5};
    o.pose.translation() = world.bodies()[box.index].position;
    ASSERT_TRUE(tissue.setObstacles({&o, 1}).ok());
    WorldState state = world.makeState();
    double fastest = 0;
    for (int i = 0; i < 200 && fastest < 1.0; ++i) {
      Isometry3 pose = Isometry3::Identity();
      pose.translation() = state.position(box);
      pose.linear() = state.orientation(box).toRotationMatrix();
      tissue.setObstaclePose(0, pose);
      tissue.setObstacleVelocity(0, {state.linearVelocity(box), state.angularVelocity(box)});
      if (!tissue.step(0.01).ok()) break;
      const Wrench w = tissue.obstacleWrench(0);
      ASSERT_TRUE(world.applyImpulse(state, box, 0.01 * w.force, state.position(box)).ok());
      if (!world.step(state, 0.01).ok()) break;
      fastest = std::max(fastest, state.linearVelocity(box).norm());
    }
    EXPECT_GT(fastest, 1.0) << "the explicit exchange should have thrown the 1 g box off";
  }
}

// A steel ball (7.8 g at 6 mm) of `mesh` at `position` moving at `velocity`.
BodyId addSteelBall(PhysicsWorld& world, const Mesh& mesh, const Vec3& position, const Vec3& velocity) {
  auto d = rigidBodyFromMesh(mesh, 7800);
  EXPECT_TRUE(d.ok());
  d->kind = BodyKind::Rigid;
  d->position = position;
  d->linearVelocity = velocity;
  auto id = world.addBody(*d);
  EXPECT_TRUE(id.ok());
  return *id;
}

// A 7.8 g steel ball at 0.5 m/s hits a free tissue slab off-centre, no
// gravity: linear momentum passes between them and its total is conserved
// to the solver's tolerance.
TEST(SoftRigid, BallHittingFreeTissueConservesMomentum) {
  FemBody tissue = slab(true, 0.0);
  PhysicsWorld world;
  const Mesh ball = makeIcosphere(0.006, 3);
  const BodyId id = addSteelBall(world, ball, Vec3(0.026, 0.018, 0.02 + 0.0062), Vec3(0, 0, -0.5));
  const MeshBvh tree = treeOf(ball);
  const SoftRigidContact contact{.body = id, .tree = &tree, .stiffness = 2e4};
  auto coupling = SoftRigidCoupling::create(world, tissue, {&contact, 1});
  ASSERT_TRUE(coupling.ok());
  WorldState state = world.makeState();
  const double m = world.bodies()[id.index].mass;
  const Vec3 p0 = tissue.linearMomentum() + m * state.linearVelocity(id);
  std::size_t touched = 0;
  for (int i = 0; i < 60; ++i) {
    ASSERT_TRUE(coupling->step(state, 0.001).ok());
    touched = std::max(touched, tissue.obstacleContactCount());
    const Vec3 p = tissue.linearMomentum() + m * state.linearVelocity(id);
    ASSERT_LT((p - p0).norm(), 1e-6 * p0.norm()) << "step " << i;
  }
  EXPECT_GT(touched, 0u);
  // The ball gave the tissue most of its momentum (it is 2.5 times lighter
  // than the slab's 32 g, so it bounces back less than it came in).
  EXPECT_LT(tissue.linearMomentum().z(), -0.5 * m * 0.5);
  EXPECT_GT(state.linearVelocity(id).z(), -0.25);
  std::printf("ball: %zu nodes touched; ball v_z %.3f m/s, tissue p_z %.5f of %.5f kg m/s\n", touched,
              state.linearVelocity(id).z(), tissue.linearMomentum().z(), -m * 0.5);
}

// The same ball hitting the free slab at an angle (0.3 m/s along x), no
// gravity. Friction across the contact drags the tissue's surface along
// and sets the ball spinning forward (ω along +y, as a rolling start); both
// ways the total linear momentum is conserved to the solver's tolerance
// and the angular momentum (tissue nodes, the ball's orbit and spin, about
// the origin) to the step's first-order error (1 % of the ball's momentum
// times its radius over the impact, as without friction). Frictionless, the
// contact's normals pass near the ball's centre: it hardly spins.
TEST(SoftRigid, FrictionSpinsABallHittingTissueAtAnAngleAndConservesMomenta) {
  const Mesh ballMesh = makeIcosphere(0.006, 3);
  const MeshBvh tree = treeOf(ballMesh);
  struct Outcome {
    Vec3 spin, tissueMomentum;
    double angularError;
  };
  auto hit = [&](double friction) {
    FemBody tissue = slab(true, 0.0);
    PhysicsWorld world;
    const Vec3 v0(0.3, 0, -0.5);
    const BodyId id = addSteelBall(world, ballMesh, Vec3(0.016, 0.018, 0.02 + 0.0062), v0);
    const SoftRigidContact contact{.body = id, .tree = &tree, .stiffness = 2e4, .friction = friction};
    auto coupling = SoftRigidCoupling::create(world, tissue, {&contact, 1});
    EXPECT_TRUE(coupling.ok());
    WorldState state = world.makeState();
    const double m = world.bodies()[id.index].mass;
    const Mat3 inertia = world.bodies()[id.index].inertia;  // a ball: the same in any frame
    auto momenta = [&](Vec3& p, Vec3& l) {
      p = tissue.linearMomentum() + m * state.linearVelocity(id);
      l = state.position(id).cross(m * state.linearVelocity(id)) + inertia * state.angularVelocity(id);
      for (std::size_t k = 0; k < tissue.nodeCount(); ++k)
        l += tissue.positions()[k].cross(tissue.masses()[k] * tissue.velocities()[k]);
    };
    Vec3 p0, l0, p, l;
    double worst = 0;
    momenta(p0, l0);
    for (int i = 0; i < 60; ++i) {
      EXPECT_TRUE(coupling->step(state, 0.001).ok());
      momenta(p, l);
      EXPECT_LT((p - p0).norm(), 1e-6 * p0.norm()) << "step " << i;
      worst = std::max(worst, (l - l0).norm());
    }
    // The scale: the ball's momentum times its radius.
    EXPECT_LT(worst, 0.01 * m * v0.norm() * 0.006) << "friction " << friction;
    return Outcome{state.angularVelocity(id), tissue.linearMomentum(), worst};
  };
  const Outcome rough = hit(0.5), smooth = hit(0.0);
  std::printf(
      "angled hit: spin %.2f rad/s about y with friction, %.3f without; tissue p_x %.2e vs %.2e kg m/s\n",
      rough.spin.y(), smooth.spin.y(), rough.tissueMomentum.x(), smooth.tissueMomentum.x());
  EXPECT_GT(rough.spin.y(), 10.0);  // the contact point slowed: spin forward
  EXPECT_LT(std::abs(smooth.spin.y()), 0.1 * rough.spin.y());
  // Friction dragged the tissue along more than the normals alone.
  EXPECT_GT(rough.tissueMomentum.x(), 1.15 * smooth.tissueMomentum.x());
  // Its torques add no error of their own to the angular momentum.
  EXPECT_LT(rough.angularError, 3.0 * smooth.angularError);
}

TEST(SoftRigid, BadCouplingsAreRefusedByIndex) {
  FemBody tissue = slab(false);
  PhysicsWorld world;
  const MeshBvh tree = treeOf(makeBox(Vec3::Constant(0.01)));
  auto particle = world.addBody({.name = "dust", .kind = BodyKind::Particle, .mass = 0.001});
  ASSERT_TRUE(particle.ok());
  const BodyId box = addBox(world, Vec3::Constant(0.005), 1000, 0.01);
  auto expectFail = [&](const SoftRigidContact& c, const char* needle) {
    const SoftRigidContact list[2] = {{.body = box, .tree = &tree}, c};
    auto r = SoftRigidCoupling::create(world, tissue, list);
    ASSERT_FALSE(r.ok()) << needle;
    EXPECT_NE(r.error().message().find(needle), std::string::npos) << r.error().message();
  };
  expectFail({.body = *particle, .tree = &tree}, "contacts[1]");
  expectFail({.body = BodyId{}, .tree = &tree}, "not in the world");
  expectFail({.body = box, .tree = nullptr}, "obstacles[1]");
  expectFail({.body = box, .tree = &tree, .stiffness = -1}, "stiffness");
  expectFail({.body = box, .tree = &tree, .friction = -1}, "friction");
  expectFail({.body = box, .tree = &tree, .friction = std::nan("")}, "friction");
}

}  // namespace
}  // namespace dm
