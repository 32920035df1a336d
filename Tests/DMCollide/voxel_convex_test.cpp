// Tests of the convex-shape – voxel-model colliders (pair_voxel_convex.cpp):
// box, cylinder, ellipsoid, convex hull and triangle against a voxelised
// ball, dense and OpenVDB. Ground truth: the ball is |x − c| − R, so for a
// convex shape S with c outside it the signed distance is dist(c, S) − R
// (point–convex GJK, exact), the deepest contact's normal is the direction
// from S's point nearest c towards c, and the boolean is dist(c, S) ≤ R.
// Cross-checks against the triangle-mesh colliders of the ball's mesh, the
// engulfed cases (model inside the shape, shape inside the model) and the
// swapped pair order.
#include <dm/collide/query.hpp>
#include <dm/collide/voxel_model.hpp>
#include <dm/math/geometry.hpp>
#include <dm/math/primitives.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "collide_test_support.hpp"

namespace {

using dm::Isometry3;
using dm::Vec3;

constexpr double kBallR = 0.01;     // ball radius, m
constexpr double kVoxelH = 0.5e-3;  // voxel size, m

// Dense model of the ball |x| < radius from its exact distance sampled on an
// n³ grid of spacing h centred on the origin.
std::shared_ptr<const dm::VoxelModel> ballModel(double radius, int n) {
  dm::Affine3 toWorld = dm::Affine3::Identity();
  toWorld.linear() *= kVoxelH;
  toWorld.translation().setConstant(-0.5 * kVoxelH * (n - 1));
  auto volume = dm::Volume::create({n, n, n}, dm::VoxelType::F32, toWorld);
  EXPECT_TRUE(volume);
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) volume->setValue(i, j, k, (toWorld * Vec3(i, j, k)).norm() - radius);
  auto model = dm::VoxelModel::fromSdf(*volume);
  EXPECT_TRUE(model) << model.error().message();
  return *model;
}

Isometry3 randomShapeRotation(std::mt19937_64& rng) {
  std::normal_distribution<double> g(0.0, 1.0);
  Isometry3 p = Isometry3::Identity();
  p.linear() = dm::Quat(Eigen::Vector4d(g(rng), g(rng), g(rng), g(rng)).normalized()).toRotationMatrix();
  return p;
}

using dm::test::randomUnit;

// Distance from point c to the convex shape at `pose` (GJK; exact outside)
// and the nearest point of the shape.
double pointDistance(const Vec3& c, const dm::Shape& shape, const Isometry3& pose, Vec3* nearest = nullptr) {
  const dm::Point point(c);
  const dm::DistanceResult d = dm::distance(point, Isometry3::Identity(), shape, pose);
  if (nearest) *nearest = d.pointB;
  return d.distance;
}

// Pose of `shape` with rotation from `rng` whose distance to the ball centre
// `c` is R + gap: bisection on the offset along a random direction.
Isometry3 poseAtGap(const dm::Shape& shape, const Vec3& c, double gap, std::mt19937_64& rng) {
  Isometry3 pose = randomShapeRotation(rng);
  const Vec3 u = randomUnit(rng);
  double lo = 0.0, hi = 1.0;
  for (int it = 0; it < 60; ++it) {
    const double mid = 0.5 * (lo + hi);
    pose.translation() = c + mid * u;
    (pointDistance(c, shape, pose) < kBallR + gap ? lo : hi) = mid;
  }
  pose.translation() = c + hi * u;
  return pose;
}

struct Shapes {
  std::vector<std::shared_ptr<const dm::Shape>> list;
  std::vector<std::string> names;
};

Shapes convexShapes() {
  Shapes s;
  s.list.push_back(std::make_shared<dm::Box>(Vec3(4e-3, 3e-3, 2e-3)));
  s.names.push_back("box");
  s.list.push_back(std::make_shared<dm::Cylinder>(3e-3, 4e-3));
  s.names.push_back("cylinder");
  s.list.push_back(std::make_shared<dm::Ellipsoid>(Vec3(4e-3, 3e-3, 2.5e-3)));
  s.names.push_back("ellipsoid");
  std::mt19937_64 rng(7);
  std::vector<Vec3> points;
  for (int i = 0; i < 30; ++i) points.push_back(3.5e-3 * randomUnit(rng).cwiseProduct(Vec3(1.0, 0.8, 0.6)));
  auto hull = dm::ConvexHull::create(points);
  EXPECT_TRUE(hull) << hull.error().message();
  s.list.push_back(*hull);
  s.names.push_back("hull");
  return s;
}

// Distance, boolean and contacts of every shape at random gaps in
// [gapLo, gapHi] against `model` (a ball of radius kBallR centred at poseModel's
// origin), compared with the analytic answer.
void checkAgainstBall(const dm::VoxelModel& model, const Isometry3& poseModel, double gapLo, double gapHi,
                      std::uint64_t seed) {
  const Shapes shapes = convexShapes();
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> gapDist(gapLo, gapHi);
  const Vec3 c = poseModel.translation();
  dm::CollisionResult res;
  for (std::size_t s = 0; s < shapes.list.size(); ++s) {
    const dm::Shape& shape = *shapes.list[s];
    SCOPED_TRACE(shapes.names[s]);
    ASSERT_TRUE(dm::ColliderTable::global().check(shape, model).ok());
    for (int trial = 0; trial < 12; ++trial) {
      const double gap = gapDist(rng);
      const Isometry3 pose = poseAtGap(shape, c, gap, rng);
      Vec3 nearest;
      const double truth = pointDistance(c, shape, pose, &nearest) - kBallR;
      SCOPED_TRACE("gap " + std::to_string(truth / kVoxelH) + " voxels");
      // Distance: the minimum of the field over the surface, sampled at
      // spacing h (stated bound K·h; measured well within one voxel).
      const dm::DistanceResult d = dm::distance(shape, pose, model, poseModel);
      ASSERT_TRUE(d.supported);
      EXPECT_NEAR(d.distance, truth, kVoxelH);
      EXPECT_GE(d.distance, truth - 0.05 * kVoxelH);  // samples never undercut the true minimum
      // The witness point lies on the shape's surface at the reported distance.
      EXPECT_NEAR((d.pointA - c).norm() - kBallR, d.distance, 0.05 * kVoxelH);
      EXPECT_NEAR(pointDistance(d.pointA, shape, pose), 0.0, 1e-7);
      // Boolean outside a band of one voxel.
      const bool hit = dm::intersect(shape, pose, model, poseModel);
      if (std::abs(truth) > kVoxelH) {
        EXPECT_EQ(hit, truth < 0);
      }
      dm::collide(shape, pose, model, poseModel, {.contacts = true, .maxContacts = 4}, res);
      EXPECT_EQ(res.colliding, hit);
      if (truth < -kVoxelH) {
        ASSERT_FALSE(res.contacts.empty());
        EXPECT_LE(res.contacts.size(), 4u);
        double deepest = 0.0;
        const dm::ContactPoint* top = nullptr;
        for (const dm::ContactPoint& cp : res.contacts) {
          EXPECT_LE(cp.depth, -truth + 0.05 * kVoxelH);
          EXPECT_GE(cp.depth, 0.0);
          EXPECT_NEAR(cp.normal.norm(), 1.0, 1e-9);
          if (cp.depth > deepest) deepest = cp.depth, top = &cp;
        }
        ASSERT_NE(top, nullptr);
        EXPECT_NEAR(deepest, -truth, kVoxelH);
        // The model separates along the normal: away from the shape.
        const Vec3 expected = (c - nearest).normalized();
        EXPECT_GT(top->normal.dot(expected), std::cos(0.15)) << top->normal.transpose();
        // The contact lies midway between the surfaces: depth/2 inside the ball.
        EXPECT_NEAR((top->position - c).norm() - kBallR, -0.5 * top->depth, 0.1 * kVoxelH);
      }
    }
  }
}

TEST(VoxelConvex, DenseBallMatchesAnalyticDistanceBooleanAndContacts) {
  const auto model = ballModel(kBallR, 52);
  checkAgainstBall(*model, Isometry3::Identity(), -3e-3, 2e-3, 1);
  std::mt19937_64 rng(2);
  Isometry3 pose = randomShapeRotation(rng);
  pose.translation() = Vec3(0.1, -0.2, 0.05);
  checkAgainstBall(*model, pose, -3e-3, 2e-3, 3);
}

TEST(VoxelConvex, SparseBallMatchesAnalyticAndDenseWithinItsBand) {
  const auto dense = ballModel(kBallR, 52);
  auto sparse = dense->toSparse(4 * kVoxelH);
  ASSERT_TRUE(sparse) << sparse.error().message();
  ASSERT_EQ((*sparse)->storage(), dm::VoxelStorage::Sparse);
  checkAgainstBall(**sparse, Isometry3::Identity(), -2.5 * kVoxelH, 2.5 * kVoxelH, 4);
  // Inside the band the two storages give the same answers.
  const Shapes shapes = convexShapes();
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> gapDist(-2.5 * kVoxelH, 2.5 * kVoxelH);
  for (const auto& shape : shapes.list) {
    for (int trial = 0; trial < 6; ++trial) {
      const Isometry3 pose = poseAtGap(*shape, Vec3::Zero(), gapDist(rng), rng);
      const dm::DistanceResult a = dm::distance(*shape, pose, *dense, Isometry3::Identity());
      const dm::DistanceResult b = dm::distance(*shape, pose, **sparse, Isometry3::Identity());
      EXPECT_NEAR(a.distance, b.distance, 1e-6);
      EXPECT_EQ(dm::intersect(*shape, pose, *dense, Isometry3::Identity()),
                dm::intersect(*shape, pose, **sparse, Isometry3::Identity()));
    }
  }
}

TEST(VoxelConvex, TriangleAgainstBall) {
  const auto model = ballModel(kBallR, 52);
  const dm::TriangleShape tri(Vec3(-3e-3, -2e-3, 0), Vec3(4e-3, -1e-3, 0), Vec3(0, 3e-3, 1e-3));
  ASSERT_TRUE(dm::ColliderTable::global().check(tri, *model).ok());
  std::mt19937_64 rng(6);
  std::uniform_real_distribution<double> gapDist(-3e-3, 2e-3);
  for (int trial = 0; trial < 20; ++trial) {
    const Isometry3 pose = poseAtGap(tri, Vec3::Zero(), gapDist(rng), rng);
    const dm::TriangleClosest cp = dm::closestPointOnTriangle(Vec3::Zero(), pose * tri.vertex(0),
                                                              pose * tri.vertex(1), pose * tri.vertex(2));
    const double truth = std::sqrt(cp.distanceSq) - kBallR;
    EXPECT_NEAR(dm::distance(tri, pose, *model, Isometry3::Identity()).distance, truth, kVoxelH);
    if (std::abs(truth) > kVoxelH) {
      EXPECT_EQ(dm::intersect(tri, pose, *model, Isometry3::Identity()), truth < 0);
    }
  }
}

TEST(VoxelConvex, ModelInsideShapeAndShapeInsideModelCollide) {
  // A 2 mm ball wholly inside a 16 mm box: no box surface point is in the
  // ball, the octree finds the ball's solid.
  const auto small = ballModel(2e-3, 12);
  const dm::Box big(Vec3(8e-3, 8e-3, 8e-3));
  Isometry3 poseBox = Isometry3::Identity();
  poseBox.translation() = Vec3(3e-3, -1e-3, 0.5e-3);
  EXPECT_TRUE(dm::intersect(big, poseBox, *small, Isometry3::Identity()));
  const dm::CollisionResult res = dm::collide(big, poseBox, *small, Isometry3::Identity());
  ASSERT_TRUE(res.colliding);
  ASSERT_EQ(res.contacts.size(), 1u);
  // Depth: the found point's depth below the box surface (≤ the ball centre's
  // 5 mm plus the ball radius, ≥ 5 mm − 2 mm); the normal exits the box.
  EXPECT_GT(res.contacts[0].depth, 3e-3 - kVoxelH);
  EXPECT_LT(res.contacts[0].depth, 7e-3 + kVoxelH);
  const dm::DistanceResult d = dm::distance(big, poseBox, *small, Isometry3::Identity());
  EXPECT_LT(d.distance, -3e-3 + kVoxelH);
  // Moved beyond the box the pair separates.
  poseBox.translation() = Vec3(10.6e-3 + 1.5 * kVoxelH, 0, 0);
  EXPECT_FALSE(dm::intersect(big, poseBox, *small, Isometry3::Identity()));
  EXPECT_NEAR(dm::distance(big, poseBox, *small, Isometry3::Identity()).distance, 0.6e-3 + 1.5 * kVoxelH,
              0.5 * kVoxelH);

  // A 1 mm cube deep inside the 10 mm ball: every surface point is inside;
  // the distance is the smallest field value over the surface, reached at the
  // centre of the face nearest the ball's centre: 3.5 mm − R.
  const auto ball = ballModel(kBallR, 52);
  const dm::Box cube(Vec3(0.5e-3, 0.5e-3, 0.5e-3));
  Isometry3 poseCube = Isometry3::Identity();
  poseCube.translation() = Vec3(4e-3, 0, 0);
  EXPECT_TRUE(dm::intersect(cube, poseCube, *ball, Isometry3::Identity()));
  const dm::DistanceResult inside = dm::distance(cube, poseCube, *ball, Isometry3::Identity());
  EXPECT_NEAR(inside.distance, 3.5e-3 - kBallR, 0.05 * kVoxelH);
  EXPECT_NEAR(inside.pointA.x(), 3.5e-3, 1e-12);
}

TEST(VoxelConvex, AgreesWithTriangleMeshCollidersOnTheBallMesh) {
  const dm::Mesh sphereMesh = dm::makeIcosphere(kBallR, 3);
  auto model = dm::VoxelModel::fromMesh(sphereMesh, {.voxelSize = kVoxelH});
  ASSERT_TRUE(model) << model.error().message();
  auto mesh = dm::TriangleMesh::create(std::make_shared<const dm::Mesh>(sphereMesh));
  ASSERT_TRUE(mesh) << mesh.error().message();
  const Shapes shapes = convexShapes();
  std::mt19937_64 rng(8);
  std::uniform_real_distribution<double> gapDist(-2e-3, 2e-3);
  int compared = 0;
  for (const auto& shape : shapes.list) {
    for (int trial = 0; trial < 8; ++trial) {
      Isometry3 poseModel = randomShapeRotation(rng);
      poseModel.translation() = 0.01 * randomUnit(rng);
      const Isometry3 pose = poseAtGap(*shape, poseModel.translation(), gapDist(rng), rng);
      const dm::DistanceResult ref = dm::distance(*shape, pose, **mesh, poseModel);
      const dm::DistanceResult ours = dm::distance(*shape, pose, **model, poseModel);
      ASSERT_TRUE(ref.supported);
      if (std::abs(ref.distance) > kVoxelH) {
        EXPECT_EQ(dm::intersect(*shape, pose, **model, poseModel), ref.distance < 0) << ref.distance;
      }
      // Separated: both are the distance to the same polyhedron.
      if (ref.distance > 0) {
        EXPECT_NEAR(ours.distance, ref.distance, kVoxelH);
        ++compared;
      }
    }
  }
  EXPECT_GT(compared, 5);
}

TEST(VoxelConvex, SwappedOrderFlipsNormalsAndSwapsPoints) {
  const auto model = ballModel(kBallR, 52);
  const dm::Cylinder cyl(2e-3, 3e-3);
  Isometry3 pose = Isometry3::Identity();
  pose.translation() = Vec3(kBallR + 1e-3, 0, 0);  // cylinder side 1 mm into the ball
  const dm::DistanceResult ab = dm::distance(cyl, pose, *model, Isometry3::Identity());
  const dm::DistanceResult ba = dm::distance(*model, Isometry3::Identity(), cyl, pose);
  EXPECT_NEAR(ab.distance, -1e-3, 0.05 * kVoxelH);
  EXPECT_DOUBLE_EQ(ab.distance, ba.distance);
  EXPECT_TRUE(ab.pointA.isApprox(ba.pointB));
  const dm::CollisionResult rab = dm::collide(cyl, pose, *model, Isometry3::Identity());
  const dm::CollisionResult rba = dm::collide(*model, Isometry3::Identity(), cyl, pose);
  ASSERT_FALSE(rab.contacts.empty());
  ASSERT_EQ(rab.contacts.size(), rba.contacts.size());
  EXPECT_TRUE(rab.contacts[0].normal.isApprox(-rba.contacts[0].normal));
  // The model (B) leaves along −x, away from the cylinder.
  EXPECT_LT(rab.contacts[0].normal.x(), -0.99);
  EXPECT_NEAR(rab.contacts[0].depth, 1e-3, 0.05 * kVoxelH);
}

}  // namespace
