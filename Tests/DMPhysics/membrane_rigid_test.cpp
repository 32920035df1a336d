// A mass–spring membrane and a world's rigid bodies stepped together
// (dm/physics/membrane_rigid.hpp) against mechanics: a free ball dropped
// off centre onto a sheet held at its rim by a world's static frame comes
// to rest in the sag, near the middle, the sheet carrying its weight and the
// pins both (1 %), at 500 Hz, allocation-free after the first step; a
// ball dropped beside a static block onto the same sheet leaves the block
// alone and the block holds the sheet up; bad couplings are refused by
// index.
#include <dm/collide/bvh.hpp>
#include <dm/math/primitives.hpp>
#include <dm/physics/membrane_rigid.hpp>

#include <gtest/gtest.h>

#include <cmath>

#include "../common/alloc_counter.hpp"
#include "physics_test_support.hpp"

namespace dm {
namespace {

using dm::test::kG;
using dm::test::treeOf;

// A 10 cm, 10 g sheet of 17 × 17 nodes in the plane z = 0, held at its rim.
MassSpringBody heldSheet(std::vector<std::uint32_t>& rim) {
  auto s = MassSpringBody::makeSheet({.nx = 17,
                                      .ny = 17,
                                      .width = 0.1,
                                      .height = 0.1,
                                      .origin = Vec3(-0.05, -0.05, 0.0),
                                      .mass = 0.01,
                                      .structural = {true, 400.0, 0.02, SpringModel::KelvinVoigt},
                                      .shear = {true, 200.0, 0.01, SpringModel::KelvinVoigt},
                                      .bend = {true, 0.5, 0.0, SpringModel::KelvinVoigt}});
  EXPECT_TRUE(s.ok());
  s->setGravity({0, 0, -kG});
  EXPECT_TRUE(s->setDrag(4.0).ok());
  for (std::uint32_t i = 0; i < s->particleCount(); ++i)
    if (s->position(i).head<2>().lpNorm<Eigen::Infinity>() > 0.05 - 1e-9) {
      s->setPinned(i, true);
      rim.push_back(i);
    }
  return std::move(*s);
}

// A rigid ball of radius r and mass about 20 g (an icosphere's volume) at `at`.
BodyId addBall(PhysicsWorld& world, double r, const Vec3& at) {
  auto d = rigidBodyFromMesh(makeIcosphere(r, 3), 0.02 / (4.0 / 3.0 * std::acos(-1.0) * r * r * r));
  EXPECT_TRUE(d.ok());
  d->kind = BodyKind::Rigid;
  d->name = "ball";
  d->position = at;
  auto id = world.addBody(*d);
  EXPECT_TRUE(id.ok());
  return *id;
}

Vec3 rimLoad(const MassSpringBody& s, const std::vector<std::uint32_t>& rim) {
  Vec3 f = Vec3::Zero();
  for (std::uint32_t i : rim) f += s.elementForceOn(i) + s.mass(i) * s.gravity();
  return f;
}

TEST(MembraneRigid, AFreeBallRestsInTheSagOfAHeldSheetWhichCarriesIt) {
  std::vector<std::uint32_t> rim;
  MassSpringBody sheet = heldSheet(rim);
  PhysicsWorld world;
  ASSERT_TRUE(world.setGravity({0, 0, -kG}));
  const double r = 0.015;
  const BodyId ball = addBall(world, r, Vec3(0.004, -0.003, r + 0.01));
  const double M = world.bodies()[ball.index].mass;
  const MeshBvh tree = treeOf(makeIcosphere(r, 3));
  const MembraneRigidContact contact{.body = ball, .tree = &tree, .friction = 0.5};
  auto coupling = MembraneRigidCoupling::create(world, {&contact, 1});
  ASSERT_TRUE(coupling.ok()) << coupling.error().message();
  WorldState state = world.makeState();
  const double h = 2e-3;
  // The real-time path: coupled steps allocate nothing after the first.
  const auto before = test::countedAllocations();
  for (int i = 0; i < 4000; ++i) {  // 8 s
    test::tCountAllocations = i > 0;
    const bool stepped = coupling->step(sheet, state, h).ok();
    test::tCountAllocations = false;
    ASSERT_TRUE(stepped);
    ASSERT_TRUE(world.step(state, h).ok());
  }
  EXPECT_EQ(test::countedAllocations(), before);
  const Vec3 x = state.position(ball);
  EXPECT_LT(state.linearVelocity(ball).norm(), 1e-3);
  EXPECT_LT(x.head<2>().norm(), 0.01);  // near the middle (it landed 5 mm off), not rolled off
  EXPECT_LT(x.z(), r - 1e-3);           // below the sheet's plane: it sagged
  for (std::size_t i = 0; i < sheet.particleCount(); ++i)
    ASSERT_GT((sheet.position(i) - x).norm(), 0.99 * r) << "particle " << i;  // faces within 0.4 % of r
  EXPECT_NEAR(coupling->contacts().force(0).z(), M * kG, 0.01 * M * kG);
  EXPECT_NEAR(rimLoad(sheet, rim).z(), -(M + 0.01) * kG, 0.01 * (M + 0.01) * kG);
}

TEST(MembraneRigid, AStaticBlockHoldsTheSheetUpAndABallBesideItSinks) {
  // A static 2 cm cube under the sheet's middle, its top 5 mm above the
  // rim: the sheet is a tent over it, hanging down its sides; a ball
  // dropped 3 cm to the side rolls down into the fold beside the block and
  // rests there, below the block's top and not in it (the sheet between),
  // the block and the rim carrying sheet and ball.
  std::vector<std::uint32_t> rim;
  MassSpringBody sheet = heldSheet(rim);
  PhysicsWorld world;
  ASSERT_TRUE(world.setGravity({0, 0, -kG}));
  const Vec3 half(0.01, 0.01, 0.01);
  BodyDesc block{.name = "block", .kind = BodyKind::Static, .position = Vec3(0, 0, 0.005 - 0.01)};
  auto blockId = world.addBody(block);
  ASSERT_TRUE(blockId.ok());
  const double r = 0.008;
  const BodyId ball = addBall(world, r, Vec3(0.03, 0.0, r + 0.01));
  const double M = world.bodies()[ball.index].mass;
  const MeshBvh blockTree = treeOf(makeBox(half)), ballTree = treeOf(makeIcosphere(r, 3));
  const MembraneRigidContact contacts[] = {{.body = *blockId, .tree = &blockTree, .friction = 0.3},
                                           {.body = ball, .tree = &ballTree, .friction = 0.5}};
  auto coupling = MembraneRigidCoupling::create(world, contacts);
  ASSERT_TRUE(coupling.ok()) << coupling.error().message();
  WorldState state = world.makeState();
  for (int i = 0; i < 3000; ++i) {  // 6 s
    ASSERT_TRUE(coupling->step(sheet, state, 2e-3).ok());
    ASSERT_TRUE(world.step(state, 2e-3).ok());
  }
  const Vec3 x = state.position(ball);
  EXPECT_LT(state.linearVelocity(ball).norm(), 1e-3);
  EXPECT_LT(x.z() - r, 0.005);  // its bottom below the block's top
  const Vec3 nearest = x.cwiseMax(-half + Vec3(0, 0, -0.005)).cwiseMin(half + Vec3(0, 0, -0.005));
  EXPECT_GT((x - nearest).norm(), 0.99 * r);  // beside the block, not in it
  const Vec3 onBlock = coupling->contacts().force(0), onBall = coupling->contacts().force(1);
  EXPECT_LT(onBlock.z(), -0.1 * 0.01 * kG);  // the block holds the sheet up
  EXPECT_NEAR(onBall.z(), M * kG, 0.01 * M * kG);
  // Vertically, rim and block carry the sheet and the ball.
  EXPECT_NEAR(rimLoad(sheet, rim).z() + onBlock.z(), -(M + 0.01) * kG, 0.01 * (M + 0.01) * kG);
}

TEST(MembraneRigid, BadCouplingsAreRefusedByIndex) {
  PhysicsWorld world;
  const MeshBvh tree = treeOf(makeBox(Vec3(0.01, 0.01, 0.01)));
  auto particle = world.addBody({.name = "bead", .kind = BodyKind::Particle, .mass = 0.01});
  ASSERT_TRUE(particle.ok());
  const auto where = [&](const MembraneRigidContact& c) {
    auto r = MembraneRigidCoupling::create(world, {&c, 1});
    return r ? std::string() : r.error().where;
  };
  EXPECT_EQ(where({.body = BodyId{7}, .tree = &tree}), "MembraneRigidCoupling::create: contacts[0]");
  EXPECT_EQ(where({.body = *particle, .tree = &tree}), "MembraneRigidCoupling::create: contacts[0]");
  auto block = world.addBody({.name = "block", .kind = BodyKind::Static});
  ASSERT_TRUE(block.ok());
  EXPECT_EQ(where({.body = *block, .tree = nullptr}),
            "MembraneRigidCoupling::create: ParticleObstacles::create: obstacles[0]");
  EXPECT_EQ(where({.body = *block, .tree = &tree, .friction = -1}),
            "MembraneRigidCoupling::create: ParticleObstacles::create: obstacles[0].friction");
}

}  // namespace
}  // namespace dm
