// Soft–rigid contact of FemBody against rigid obstacles (closed meshes),
// against physics: a rigid plate compressing a ν = 0 block carries exactly
// E·A·δ/L; a block resting on a table presses on it with its weight; a
// spherical tool meets Hertz's force; bad obstacles are refused.
#include <dm/collide/bvh.hpp>
#include <dm/math/primitives.hpp>
#include <dm/physics/fem.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include "../common/alloc_counter.hpp"
#include "physics_test_support.hpp"

namespace dm {
namespace {

using dm::test::treeOf;

Isometry3 at(const Vec3& p) {
  Isometry3 t = Isometry3::Identity();
  t.translation() = p;
  return t;
}

constexpr double kL = 0.02;  // a 20 mm cube of tissue

FemBody cube(double poisson, double alpha) {
  auto mesh = tetMeshBox({4, 4, 4}, Vec3::Constant(kL));
  EXPECT_TRUE(mesh.ok());
  auto body = FemBody::create(*mesh, {.youngsModulus = 1e4, .poissonRatio = poisson, .density = 1000},
                              {.alpha = alpha, .beta = 0.01});
  EXPECT_TRUE(body.ok());
  return std::move(*body);
}

TEST(FemContact, RigidPlateCompressingABlockCarriesEATimesStrain) {
  // ν = 0: uniaxial strain is uniaxial stress, and the linear solution is a
  // uniform strain δ/L whatever the clamp at the base. Frictionless plate.
  FemBody body = cube(0.0, 20.0);
  body.fixNodesWhere([](const Vec3& p) { return p.z() < 1e-9; });
  const MeshBvh plate = treeOf(makeBox(Vec3(0.03, 0.03, 0.01)));
  const double delta = 0.001;
  const FemObstacle o{.tree = &plate, .pose = at(Vec3(0.01, 0.01, kL - delta + 0.01)), .stiffness = 1e6};
  ASSERT_TRUE(body.setObstacles({&o, 1}).ok());
  for (int i = 0; i < 300; ++i) {
    ASSERT_TRUE(body.step(0.01).ok());
  }
  const double expected = 1e4 * kL * kL * delta / kL;  // E A δ / L = 0.2 N
  EXPECT_EQ(body.obstacleContactCount(), 25u);           // the 5 x 5 top nodes
  EXPECT_NEAR(body.obstacleForce(0).z(), expected, 0.01 * expected);
  std::printf("plate: %.5f N against E A delta / L = %.5f N\n", body.obstacleForce(0).z(), expected);
  EXPECT_LT(std::hypot(body.obstacleForce(0).x(), body.obstacleForce(0).y()), 1e-6 * expected);
  for (std::size_t i = 0; i < body.nodeCount(); ++i) {
    if (body.restPositions()[i].z() > kL - 1e-9) {
      EXPECT_NEAR(body.positions()[i].z(), kL - delta, 1e-6);
    }
  }
}

TEST(FemContact, BlockRestingOnATablePressesWithItsWeight) {
  FemBody body = cube(0.45, 10.0);
  body.setGravity({0, 0, -9.81});
  const MeshBvh table = treeOf(makeBox(Vec3(0.05, 0.05, 0.01)));
  const FemObstacle o{.tree = &table, .pose = at(Vec3(0.01, 0.01, -0.0105)), .stiffness = 1e4};  // top at z = -0.5 mm
  ASSERT_TRUE(body.setObstacles({&o, 1}).ok());
  const auto before = test::countedAllocations();
  for (int i = 0; i < 400; ++i) {
    test::tCountAllocations = true;  // contact search and solve reuse their storage
    const bool stepped = body.step(0.01).ok();
    test::tCountAllocations = false;
    ASSERT_TRUE(stepped);
  }
  EXPECT_EQ(test::countedAllocations(), before);
  const double weight = body.totalMass() * 9.81;  // 8 g: 0.078 N
  EXPECT_NEAR(body.obstacleForce(0).z(), -weight, 0.01 * weight);
  std::printf("table: %.5f N against the weight %.5f N\n", -body.obstacleForce(0).z(), weight);
  EXPECT_LT(body.linearMomentum().norm(), 1e-3 * body.totalMass());  // at rest
  double lowest = 1.0;
  for (const Vec3& p : body.positions()) lowest = std::min(lowest, p.z());
  // It sank into the penalty by about its load per node over k, not through.
  EXPECT_LT(lowest, -0.0005);
  EXPECT_GT(lowest, -0.0005 - weight / 1e4);
}

TEST(FemContact, SphericalToolFollowsHertzWithinTheMeshResolution) {
  // A rigid ball (R = 4 mm) pressed into a 20 mm block of E = 10 kPa,
  // ν = 0.45 on a 2.5 mm mesh: Hertz's half-space, F = 4/3 E* √R δ^1.5 with
  // E* = E / (1 − ν²). The contact radius √(Rδ) (2–2.8 mm) is about one
  // element, so 20 % is what this resolution resolves.
  auto mesh = tetMeshBox({8, 8, 8}, Vec3::Constant(kL));
  ASSERT_TRUE(mesh.ok());
  auto made = FemBody::create(*mesh, {.youngsModulus = 1e4, .poissonRatio = 0.45, .density = 1000},
                              {.alpha = 20.0, .beta = 0.01});
  ASSERT_TRUE(made.ok());
  FemBody& body = *made;
  body.fixNodesWhere([](const Vec3& p) { return p.z() < 1e-9; });
  const double R = 0.004;
  const MeshBvh ball = treeOf(makeIcosphere(R, 3));
  FemObstacle tool{.tree = &ball, .pose = at(Vec3(0.01, 0.01, kL + R)), .stiffness = 1e5};
  ASSERT_TRUE(body.setObstacles({&tool, 1}).ok());
  double reached = 0.0;
  for (double depth : {0.001, 0.002}) {
    // The tool moves in over 0.4 s, as a hand would, then holds 0.8 s.
    std::vector<double> held;
    for (int i = 0; i < 120; ++i) {
      const double d = reached + (depth - reached) * std::min(1.0, (i + 1) / 40.0);
      ASSERT_TRUE(body.setObstaclePose(0, at(Vec3(0.01, 0.01, kL + R - d))));
      ASSERT_TRUE(body.step(0.01).ok());
      if (i >= 110) held.push_back(body.obstacleForce(0).z());
    }
    reached = depth;
    const auto [lo, hi] = std::minmax_element(held.begin(), held.end());
    EXPECT_LT(*hi - *lo, 1e-3 * *hi) << "the contact chatters at depth " << depth;
    const double hertz = 4.0 / 3.0 * 1e4 / (1 - 0.45 * 0.45) * std::sqrt(R) * std::pow(depth, 1.5);
    EXPECT_NEAR(*hi, hertz, 0.2 * hertz) << "depth " << depth;
    EXPECT_GT(body.obstacleContactCount(), 0u);
    std::printf("depth %.1f mm: %.4f N against Hertz %.4f N (%zu nodes in contact)\n", depth * 1e3, *hi, hertz,
                body.obstacleContactCount());
  }
  // Taken away, nothing touches it and it pushes on nothing.
  ASSERT_TRUE(body.setObstaclePose(0, at(Vec3(0.01, 0.01, 0.1))));
  ASSERT_TRUE(body.step(0.01).ok());
  EXPECT_EQ(body.obstacleContactCount(), 0u);
  EXPECT_EQ(body.obstacleForce(0), Vec3::Zero());
}

TEST(FemContact, BadObstaclesAreRefusedByIndex) {
  FemBody body = cube(0.45, 1.0);
  const MeshBvh ball = treeOf(makeIcosphere(0.004, 2));
  Mesh open;
  open.positions = {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0)};
  open.triangles = {{0, 1, 2}};
  const MeshBvh plate = treeOf(open);
  Isometry3 sheared = Isometry3::Identity();
  sheared.linear()(0, 1) = 0.3;
  const FemObstacle good{.tree = &ball};
  for (const FemObstacle& bad : {FemObstacle{.tree = nullptr}, FemObstacle{.tree = &plate},
                                 FemObstacle{.tree = &ball, .pose = sheared},
                                 FemObstacle{.tree = &ball, .stiffness = 0.0}}) {
    const FemObstacle set[2] = {good, bad};
    const Status s = body.setObstacles(set);
    ASSERT_FALSE(s.ok());
    EXPECT_NE(s.error().where.find("obstacles[1]"), std::string::npos) << s.error().message();
  }
  EXPECT_EQ(body.obstacleCount(), 0u);
  EXPECT_FALSE(body.setObstaclePose(0, Isometry3::Identity()));
  EXPECT_EQ(body.obstacleForce(3), Vec3::Zero());
}

}  // namespace
}  // namespace dm
