// The passivity test of every renderer: a scripted device path that dips
// into a box and returns to its start three times must not gain energy from
// the renderer (dm::pathWork: the work the held force does on the hand).
// A sampled stiff wall is active (Colgate & Schenkel): without damping the
// god-object returns energy, so the test can fail; damping b ≥ K·T/2 or the
// passivity controller makes it passive, and friction only dissipates. The
// VPS tool behind its implicitly integrated virtual coupling is passive as
// built; the sphere-tree method with material damping too.
#include <dm/collide/bvh.hpp>
#include <dm/collide/point_shell.hpp>
#include <dm/collide/sphere_tree.hpp>
#include <dm/collide/voxel_model.hpp>
#include <dm/haptics/god_object.hpp>
#include <dm/haptics/safety.hpp>
#include <dm/haptics/sphere_tree_6dof.hpp>
#include <dm/haptics/vps.hpp>
#include <dm/math/primitives.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <memory>
#include <vector>

#include "haptics_test_support.hpp"

namespace dm {
namespace {

constexpr double kHalf = 0.05;  // box half extent, m: top face at z = 0.05
using dm::test::kDt;

// Three turns of a 6 mm circle in the xz plane centred 1 mm above the top
// face (so 5 mm deep at the bottom), 1000 ticks a turn, ending where it began.
std::vector<Isometry3> dipPath() {
  std::vector<Isometry3> path;
  const Vec3 centre(0.0, 0.0, kHalf + 0.001);
  for (int k = 0; k <= 3000; ++k) {
    const double a = 2.0 * M_PI * k / 1000.0;
    Isometry3 p = Isometry3::Identity();
    p.translation() = centre + 0.006 * Vec3(std::cos(a), 0.0, std::sin(a));
    path.push_back(p);
  }
  path.back() = path.front();
  return path;
}

std::unique_ptr<GodObjectRenderer> godObject(const HapticMaterial& m) {
  auto bvh = MeshBvh::build(makeBox(Vec3::Constant(kHalf)));
  EXPECT_TRUE(bvh.ok());
  std::vector<GodObjectObject> objects(1);
  objects[0].bvh = std::make_shared<const MeshBvh>(std::move(*bvh));
  objects[0].material = m;
  auto r = GodObjectRenderer::create(std::move(objects), {});
  EXPECT_TRUE(r.ok());
  return std::move(*r);
}

TEST(Passivity, UndampedGodObjectIsActiveAndDampingAboveKTOver2FixesIt) {
  const std::vector<Isometry3> path = dipPath();
  const double k = 2000.0;
  auto bare = godObject({.stiffness = k});
  const double active = pathWork(*bare, path, kDt);
  auto damped = godObject({.stiffness = k, .damping = k * kDt});  // b = K·T > K·T/2
  const double passive = pathWork(*damped, path, kDt);
  std::printf("god-object closed path: work on the hand %.3e J undamped, %.3e J with b = K*T\n", active,
              passive);
  EXPECT_GT(active, 1e-6);    // the sampled wall returns energy: the test can fail
  EXPECT_LE(passive, 1e-12);  // and with enough damping it does not
}

TEST(Passivity, PassivityControllerKeepsTheUndampedGodObjectPassive) {
  auto bare = godObject({.stiffness = 2000.0});
  const double w = pathWork(*bare, dipPath(), kDt, PassivityConfig{});
  EXPECT_LE(w, 1e-9);
}

TEST(Passivity, FrictionOnlyDissipates) {
  // Sliding along the face while pressed in: friction takes energy out.
  std::vector<Isometry3> path;
  for (int k = 0; k <= 2000; ++k) {
    const double a = 2.0 * M_PI * k / 1000.0;
    Isometry3 p = Isometry3::Identity();
    p.translation() = Vec3(0.01 * std::sin(a), 0.004 * std::sin(2 * a), kHalf - 0.002 * (1 - std::cos(a)));
    path.push_back(p);
  }
  const double k = 2000.0;
  auto sticky =
      godObject({.stiffness = k, .damping = k * kDt, .staticFriction = 0.6, .dynamicFriction = 0.4});
  auto slippery = godObject({.stiffness = k, .damping = k * kDt});
  const double withFriction = pathWork(*sticky, path, kDt);
  const double without = pathWork(*slippery, path, kDt);
  std::printf("sliding path: work on the hand %.3e J with friction, %.3e J without\n", withFriction, without);
  EXPECT_LE(withFriction, 1e-12);
  EXPECT_LT(withFriction, without - 1e-6);  // friction dissipated measurably more
}

TEST(Passivity, VpsVirtualCouplingIsPassive) {
  VoxelizeOptions vox;
  vox.voxelSize = 1e-3;
  auto model = VoxelModel::fromMesh(makeBox(Vec3::Constant(kHalf)), vox);
  ASSERT_TRUE(model.ok()) << model.error().message();
  auto shell = PointShell::fromMesh(makeIcosphere(0.004, 3), {.spacing = 1e-3});
  ASSERT_TRUE(shell.ok());
  auto r = VpsRenderer::create(*shell, {{*model, Isometry3::Identity(), {.stiffness = 5000.0}}}, {});
  ASSERT_TRUE(r.ok()) << r.error().message();
  const double w = pathWork(**r, dipPath(), kDt);
  std::printf("VPS closed path: work on the hand %.3e J\n", w);
  EXPECT_LE(w, 1e-9);
}

TEST(Passivity, SphereTreeWithDampingIsPassive) {
  SphereTreeOptions env;
  env.levels = 7;
  auto box = buildSphereTreeOctree(makeBox(Vec3::Constant(kHalf)), env);
  ASSERT_TRUE(box.ok()) << box.error().message();
  SphereTreeOptions tool;
  tool.levels = 4;
  auto ball = buildSphereTreeOctree(makeIcosphere(0.004, 3), tool);
  ASSERT_TRUE(ball.ok()) << ball.error().message();
  std::vector<SphereTreeObject> objects(1);
  objects[0].tree = *box;
  objects[0].material = {.stiffness = 1000.0, .damping = 1000.0 * kDt};
  auto r = SphereTree6DofRenderer::create(*ball, std::move(objects), {.toolLevel = 3});
  ASSERT_TRUE(r.ok()) << r.error().message();
  const double w = pathWork(**r, dipPath(), kDt);
  std::printf("sphere-tree closed path: work on the hand %.3e J\n", w);
  EXPECT_LE(w, 1e-9);
}

}  // namespace
}  // namespace dm
