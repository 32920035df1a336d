// Tests of dm/collide/voxel_model.hpp and the voxel pairs (pair_voxel.cpp):
// distance and gradient of sphere models against |p| − r, dense vs OpenVDB
// storage, the occupancy distance transform against brute force, the
// Voxmap–PointShell contact at analytic penetrations, round shapes, ray
// casts against the analytic ray–sphere hit, and input errors.
#include <dm/collide/point_shell.hpp>
#include <dm/collide/query.hpp>
#include <dm/collide/voxel_model.hpp>
#include <dm/math/primitives.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "collide_test_support.hpp"

namespace {

using dm::Isometry3;
using dm::Vec3;

// F32 volume holding |x| − radius, n³ voxels of size h centred on the origin.
dm::Volume sphereSdf(double radius, double h, int n) {
  dm::Affine3 a = dm::Affine3::Identity();
  a.linear() = h * dm::Mat3::Identity();
  a.translation() = Vec3::Constant(-0.5 * (n - 1) * h);
  auto v = dm::Volume::create({n, n, n}, dm::VoxelType::F32, a);
  EXPECT_TRUE(v);
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) v->setValue(i, j, k, (a * Vec3(i, j, k)).norm() - radius);
  return std::move(*v);
}

Vec3 randomInBall(std::mt19937_64& rng, double radius) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  while (true) {
    const Vec3 p(u(rng), u(rng), u(rng));
    if (p.squaredNorm() <= 1.0) return radius * p;
  }
}

using dm::test::randomUnit;

using dm::test::at;

Isometry3 randomModelPose(std::mt19937_64& rng, double offset) {
  std::normal_distribution<double> g(0.0, 1.0);
  Isometry3 p = Isometry3::Identity();
  p.linear() = dm::Quat(Eigen::Vector4d(g(rng), g(rng), g(rng), g(rng)).normalized()).toRotationMatrix();
  p.translation() = offset * randomUnit(rng);
  return p;
}

constexpr double kR = 0.01;    // model sphere radius, m
constexpr double kH = 0.5e-3;  // voxel size, m

std::shared_ptr<const dm::VoxelModel> analyticSphere(double radius = kR, double h = kH, int n = 52) {
  auto m = dm::VoxelModel::fromSdf(sphereSdf(radius, h, n));
  EXPECT_TRUE(m) << m.error().message();
  return *m;
}

TEST(VoxelModel, AnalyticSphereDistanceAndGradientMatchWithinHalfAVoxel) {
  auto model = analyticSphere();
  EXPECT_EQ(model->storage(), dm::VoxelStorage::Dense);
  std::mt19937_64 rng(1);
  double worst = 0.0, worstNear = 0.0, worstAngle = 0.0;
  for (int s = 0; s < 2000; ++s) {
    const Vec3 p = randomInBall(rng, kR + 4 * kH);
    Vec3 g;
    const double d = model->distance(p, g);
    const double err = std::abs(d - (p.norm() - kR));
    worst = std::max(worst, err);
    // Near the surface the field is smooth (curvature 1/r): trilinear error
    // ≤ 3h²/(8r) ≈ 0.02 h. Near the centre |p| has a kink.
    if (std::abs(p.norm() - kR) < 4 * kH) worstNear = std::max(worstNear, err);
    // The trilinear gradient is first-order: its direction errs by about
    // (voxel size) × (curvature 1/|p|).
    if (p.norm() > 2 * kH)
      worstAngle =
          std::max(worstAngle, std::acos(std::min(1.0, g.normalized().dot(p.normalized()))) * p.norm() / kH);
    EXPECT_EQ(model->occupied(p),
              model->voxelOccupied(static_cast<int>(std::lround((p.x() + 25.5 * kH) / kH)),
                                   static_cast<int>(std::lround((p.y() + 25.5 * kH) / kH)),
                                   static_cast<int>(std::lround((p.z() + 25.5 * kH) / kH))));
  }
  EXPECT_LT(worst, 0.5 * kH);
  EXPECT_LT(worstNear, 0.03 * kH);
  EXPECT_LT(worstAngle, 1.0);
  // Outside the grid: value at the nearest grid point plus the distance to
  // the grid, never below the true distance there.
  const Vec3 far(0.05, 0.0, 0.0);
  EXPECT_GE(model->distance(far), far.norm() - kR - 1e-9);
  EXPECT_NEAR(model->gradient(far).normalized().dot(Vec3::UnitX()), 1.0, 1e-9);
  // Volume: the occupied voxels' volume approximates the ball's.
  EXPECT_NEAR(model->volume(), 4.0 / 3.0 * M_PI * kR * kR * kR, 0.02 * 4.0 / 3.0 * M_PI * kR * kR * kR);
  EXPECT_EQ(model->bytes(), 52u * 52u * 52u * 4u + (52u * 52u * 52u + 63u) / 64u * 8u);
  EXPECT_TRUE(std::isnan(model->distance(Vec3(std::nan(""), 0, 0))));
}

TEST(VoxelModel, IcosphereMeshModelMatchesTheSphere) {
  const double r = 0.008;
  auto model = dm::VoxelModel::fromMesh(dm::makeIcosphere(r, 3), {.voxelSize = kH});
  ASSERT_TRUE(model) << model.error().message();
  std::mt19937_64 rng(2);
  for (int s = 0; s < 1000; ++s) {
    const Vec3 p = randomInBall(rng, r + 3 * kH);
    ASSERT_NEAR(model->get()->distance(p), p.norm() - r, 0.5 * kH) << "at " << p.transpose();
  }
  const double ball = 4.0 / 3.0 * M_PI * r * r * r;
  EXPECT_NEAR((*model)->volume(), ball, 0.03 * ball);
  EXPECT_EQ((*model)->bandWidth(), std::numeric_limits<double>::infinity());
  // With a band the field is clamped there, and the model says so.
  auto banded = dm::VoxelModel::fromMesh(dm::makeIcosphere(r, 3), {.voxelSize = kH, .bandWidth = 2 * kH});
  ASSERT_TRUE(banded) << banded.error().message();
  EXPECT_EQ((*banded)->bandWidth(), 2 * kH);
  EXPECT_NEAR((*banded)->distance(Vec3::Zero()), -2 * kH, 1e-7);
  auto sparse = (*banded)->toSparse(4 * kH);
  ASSERT_TRUE(sparse) << sparse.error().message();
  EXPECT_EQ((*sparse)->bandWidth(), 2 * kH);
}

TEST(VoxelModel, SparseStorageAgreesWithDenseInsideTheBand) {
  auto dense = analyticSphere(kR, kH, 56);
  const double band = 3 * kH;
  auto sparse = dense->toSparse(band);
  ASSERT_TRUE(sparse) << sparse.error().message();
  EXPECT_EQ((*sparse)->storage(), dm::VoxelStorage::Sparse);
  EXPECT_EQ((*sparse)->bandWidth(), band);
  EXPECT_GT((*sparse)->bytes(), 0u);
  EXPECT_EQ((*sparse)->occupiedCount(), dense->occupiedCount());
  std::mt19937_64 rng(3);
  int inBand = 0;
  for (int s = 0; s < 3000; ++s) {
    const Vec3 p = randomInBall(rng, kR + 5 * kH);
    Vec3 gd, gs;
    const double dd = dense->distance(p, gd);
    const double ds = (*sparse)->distance(p, gs);
    if (std::abs(dd) < band - 1.5 * kH) {
      ++inBand;
      ASSERT_NEAR(ds, dd, 1e-12) << "at " << p.transpose();
      ASSERT_NEAR((gs - gd).norm(), 0.0, 1e-9);
    } else if (dd > band + 1.5 * kH) {
      ASSERT_NEAR(ds, band, 1e-7);  // clamped outside
    } else if (dd < -band - 1.5 * kH) {
      ASSERT_NEAR(ds, -band, 1e-7);  // clamped inside (signed flood fill)
    }
    ASSERT_EQ((*sparse)->occupied(p), dense->occupied(p)) << "at " << p.transpose();
  }
  EXPECT_GT(inBand, 100);
  // Ray casts see the same surface.
  for (int s = 0; s < 50; ++s) {
    const Vec3 o = 2 * kR * randomUnit(rng);
    const dm::Ray ray{o, (-o + 0.3 * kR * randomUnit(rng)).normalized()};
    auto hd = dense->raycast(ray), hs = (*sparse)->raycast(ray);
    ASSERT_EQ(hd.has_value(), hs.has_value());
    if (hd) {
      EXPECT_NEAR(hd->t, hs->t, 1e-9);
    }
  }
  // The Voxmap–PointShell contact sees the same depths through both.
  auto shell = dm::PointShell::fromMesh(dm::makeIcosphere(0.003, 2), {.spacing = 0.5e-3});
  ASSERT_TRUE(shell) << shell.error().message();
  for (int s = 0; s < 5; ++s) {
    const Vec3 u = randomUnit(rng);
    const Isometry3 pose = at((kR + 0.003 - 0.8e-3) * u);
    const dm::DistanceResult dd = dm::distance(**shell, pose, *dense, Isometry3::Identity());
    const dm::DistanceResult ds = dm::distance(**shell, pose, **sparse, Isometry3::Identity());
    EXPECT_NEAR(ds.distance, dd.distance, 1e-12);
    // A coarse shell (facet sag ≈ 40 µm, half-spacing gaps) sits up to
    // ~0.1 h short of the analytic depth.
    EXPECT_NEAR(dd.distance, -0.8e-3, 0.2 * kH);
    EXPECT_EQ(dm::voxmapPenalty(**shell, pose, **sparse, Isometry3::Identity()).count,
              dm::voxmapPenalty(**shell, pose, *dense, Isometry3::Identity()).count);
  }
  // Back to dense: the clamped field.
  auto back = (*sparse)->toDense();
  ASSERT_TRUE(back) << back.error().message();
  for (int k = 0; k < 56; k += 5)
    for (int j = 0; j < 56; j += 3)
      for (int i = 0; i < 56; ++i)
        ASSERT_NEAR((*back)->voxelDistance(i, j, k), std::clamp(dense->voxelDistance(i, j, k), -band, band),
                    1e-7);
  // Too narrow a band cannot be sign-filled.
  auto thin = dense->toSparse(0.5 * kH);
  ASSERT_FALSE(thin);
  EXPECT_NE(thin.error().message().find("bandWidth"), std::string::npos) << thin.error().message();
}

TEST(VoxelModel, OccupancyDistanceTransformMatchesBruteForce) {
  // Anisotropic, rotated grid with random blobs.
  const dm::Vec3i dims(14, 11, 9);
  dm::Affine3 a = dm::Affine3::Identity();
  a.linear() = dm::AngleAxis(0.4, Vec3(1, 2, 3).normalized()).toRotationMatrix() *
               Vec3(1e-3, 1.5e-3, 0.8e-3).asDiagonal();
  a.translation() = Vec3(0.01, -0.02, 0.003);
  auto vol = dm::Volume::create(dims, dm::VoxelType::U8, a);
  ASSERT_TRUE(vol);
  std::mt19937_64 rng(4);
  std::uniform_int_distribution<int> ui(0, 13), uj(0, 10), uk(0, 8);
  for (int blob = 0; blob < 4; ++blob) {
    const Vec3 c = a * Vec3(ui(rng), uj(rng), uk(rng));
    for (int k = 0; k < dims.z(); ++k)
      for (int j = 0; j < dims.y(); ++j)
        for (int i = 0; i < dims.x(); ++i)
          if ((a * Vec3(i, j, k) - c).norm() < 2.5e-3) vol->setValue(i, j, k, 200);
  }
  auto model = dm::VoxelModel::fromOccupancy(*vol, 100.0);
  ASSERT_TRUE(model) << model.error().message();
  const double half = 0.5 * 0.8e-3;
  double worst = 0.0;
  for (int k = 0; k < dims.z(); ++k)
    for (int j = 0; j < dims.y(); ++j)
      for (int i = 0; i < dims.x(); ++i) {
        const bool in = vol->value(i, j, k) >= 100;
        double best = std::numeric_limits<double>::infinity();
        for (int kk = 0; kk < dims.z(); ++kk)
          for (int jj = 0; jj < dims.y(); ++jj)
            for (int ii = 0; ii < dims.x(); ++ii)
              if ((vol->value(ii, jj, kk) >= 100) != in)
                best = std::min(best, (a.linear() * Vec3(i - ii, j - jj, k - kk)).norm());
        const double expected = in ? half - best : best - half;
        worst = std::max(worst, std::abs((*model)->voxelDistance(i, j, k) - expected));
        ASSERT_EQ((*model)->voxelOccupied(i, j, k), in);
      }
  EXPECT_LT(worst, 1e-8);  // float storage of millimetre values
}

TEST(VoxelModel, PointShellAgainstSphereMatchesAnalyticPenetration) {
  const double bigR = 0.02, h = 1e-3, smallR = 0.004;
  auto model = analyticSphere(bigR, h, 64);
  auto shell = dm::PointShell::fromMesh(dm::makeIcosphere(smallR, 3), {.spacing = 0.4e-3});
  ASSERT_TRUE(shell) << shell.error().message();
  std::mt19937_64 rng(5);
  dm::CollisionResult res;
  for (int trial = 0; trial < 20; ++trial) {
    const Vec3 u = randomUnit(rng);
    const double delta = trial % 2 ? 1.5e-3 : 0.5e-3;  // analytic penetration
    Isometry3 poseShell = randomModelPose(rng, 0.0);
    poseShell.translation() = (bigR + smallR - delta) * u;
    const Isometry3 poseModel = Isometry3::Identity();
    EXPECT_TRUE(dm::intersect(**shell, poseShell, *model, poseModel));
    dm::collide(**shell, poseShell, *model, poseModel, {.contacts = true, .maxContacts = 6}, res);
    ASSERT_TRUE(res.supported);
    ASSERT_TRUE(res.colliding);
    ASSERT_FALSE(res.contacts.empty());
    EXPECT_LE(res.contacts.size(), 6u);
    const dm::ContactPoint& deepest = res.contacts[0];  // reduceContacts keeps the deepest first
    // Sampling leaves the deepest point up to a spacing from the pole:
    // depth short by ≤ r(1 − cos(spacing/r)) ≈ 10 µm, plus interpolation.
    EXPECT_NEAR(deepest.depth, delta, 0.05 * h);
    EXPECT_GT(deepest.normal.dot(-u), 0.995);  // from the shell to the model
    const dm::DistanceResult d = dm::distance(**shell, poseShell, *model, poseModel);
    EXPECT_NEAR(d.distance, -deepest.depth, 1e-12);
    // Penalty sum: by symmetry along −u; count equals brute force.
    const dm::VoxmapPenalty pen = dm::voxmapPenalty(**shell, poseShell, *model, poseModel);
    int brute = 0;
    for (const Vec3& p : (*shell)->points()) brute += model->distance(poseShell * p) <= 0;
    EXPECT_EQ(pen.count, brute);
    EXPECT_GT(pen.force.normalized().dot(-u), 0.99);
    EXPECT_NEAR(pen.maxDepth, deepest.depth, 1e-12);
    // Swapped order flips the normal.
    dm::collide(*model, poseModel, **shell, poseShell, {.contacts = true, .maxContacts = 6}, res);
    ASSERT_FALSE(res.contacts.empty());
    EXPECT_GT(res.contacts[0].normal.dot(u), 0.995);
  }
  // Separated: distance is the brute-force minimum over the points (the
  // hierarchy culling loses nothing), about the analytic gap.
  for (int trial = 0; trial < 10; ++trial) {
    const Vec3 u = randomUnit(rng);
    const double gap = 1e-3 + 0.5e-3 * trial;
    const Isometry3 poseShell = at((bigR + smallR + gap) * u);
    EXPECT_FALSE(dm::intersect(**shell, poseShell, *model, Isometry3::Identity()));
    dm::collide(**shell, poseShell, *model, Isometry3::Identity(), {}, res);
    EXPECT_FALSE(res.colliding);
    EXPECT_TRUE(res.contacts.empty());
    const dm::DistanceResult d = dm::distance(**shell, poseShell, *model, Isometry3::Identity());
    double brute = std::numeric_limits<double>::infinity();
    for (const Vec3& p : (*shell)->points()) brute = std::min(brute, model->distance(poseShell * p));
    EXPECT_EQ(d.distance, brute);
    EXPECT_NEAR(d.distance, gap, 0.05 * h);
    EXPECT_NEAR((d.pointB - d.pointA).norm(), d.distance, 1e-9);
    EXPECT_NEAR(d.pointB.norm(), bigR, 0.05 * h);
  }
}

TEST(VoxelModel, RoundShapesAgainstSphereModel) {
  auto model = analyticSphere();
  std::mt19937_64 rng(6);
  for (int trial = 0; trial < 40; ++trial) {
    const Vec3 u = randomUnit(rng);
    const double off = kR + (trial % 5 - 2) * 1e-3;  // centres inside and outside the model
    // Sphere.
    const dm::Sphere ball(2e-3);
    const Isometry3 pb = at(off * u);
    const dm::DistanceResult ds = dm::distance(ball, pb, *model, Isometry3::Identity());
    EXPECT_NEAR(ds.distance, off - kR - 2e-3, 0.05 * kH);
    EXPECT_EQ(dm::intersect(ball, pb, *model, Isometry3::Identity()), ds.distance <= 0);
    const dm::CollisionResult cs = dm::collide(ball, pb, *model, Isometry3::Identity());
    ASSERT_EQ(cs.colliding, ds.distance <= 0);
    if (cs.colliding) {
      EXPECT_GT(cs.contacts[0].normal.dot(-u), 0.99);
    }
    // Point.
    const dm::Point point(off * u);
    EXPECT_NEAR(dm::distance(point, Isometry3::Identity(), *model, Isometry3::Identity()).distance, off - kR,
                0.05 * kH);
    // Capsule along u: its inner end is deepest, at off − halfLength.
    const dm::Capsule cap(1e-3, 3e-3);
    Isometry3 pc = Isometry3::Identity();
    pc.linear() = Eigen::Quaterniond::FromTwoVectors(Vec3::UnitZ(), u).toRotationMatrix();
    pc.translation() = (off + 3e-3) * u;
    EXPECT_NEAR(dm::distance(cap, pc, *model, Isometry3::Identity()).distance, off - kR - 1e-3, 0.05 * kH);
    // Capsule across u, tangent plane: its middle is deepest.
    pc.linear() = Eigen::Quaterniond::FromTwoVectors(Vec3::UnitZ(), u.unitOrthogonal()).toRotationMatrix();
    pc.translation() = off * u;
    EXPECT_NEAR(dm::distance(cap, pc, *model, Isometry3::Identity()).distance, off - kR - 1e-3, 0.05 * kH);
  }
  // Unsupported pairs say so.
  const dm::Plane plane(Vec3::UnitZ(), 0.0);
  EXPECT_FALSE(dm::collide(plane, Isometry3::Identity(), *model, Isometry3::Identity()).supported);
  EXPECT_FALSE(dm::ColliderTable::global().check(plane, *model).ok());
}

TEST(VoxelModel, RaycastMatchesAnalyticRaySphereHit) {
  auto model = analyticSphere();
  std::mt19937_64 rng(7);
  const Isometry3 pose = randomModelPose(rng, 0.05);
  int hits = 0;
  for (int s = 0; s < 200; ++s) {
    const Vec3 o = (0.012 + 0.01 * (s % 3)) * randomUnit(rng);
    const Vec3 dir = (-o + 0.9 * kR * randomUnit(rng)).normalized();
    // Analytic hit in the model frame.
    const double b = o.dot(dir), c = o.squaredNorm() - kR * kR, disc = b * b - c;
    const dm::Ray world{pose * o, pose.linear() * dir};
    const auto hit = dm::raycast(*model, pose, world);
    if (disc < -0.04 * kR * kR) {
      EXPECT_FALSE(hit.has_value()) << "ray " << s;
    }
    if (disc < 0.04 * kR * kR) continue;  // skip grazing rays (t is ill-conditioned there)
    const double t = -b - std::sqrt(disc);
    ASSERT_TRUE(hit.has_value()) << "ray " << s;
    ++hits;
    EXPECT_NEAR(hit->t, t, 0.05 * kH);
    const Vec3 local = pose.inverse() * hit->point;
    EXPECT_GT((pose.linear().transpose() * hit->normal).dot(local.normalized()), 0.99);
  }
  EXPECT_GT(hits, 100);
  // A miss, a zero direction, a hit beyond maxDistance and a start inside.
  EXPECT_FALSE(model->raycast({Vec3(0.011, 0, 0), Vec3::Zero()}));
  EXPECT_FALSE(model->raycast({Vec3(0.02, 0.02, 0), Vec3::UnitX()}));
  EXPECT_FALSE(model->raycast({Vec3(-0.02, 0, 0), Vec3::UnitX(), 0.005}));
  const auto inside = model->raycast({Vec3(0.001, 0, 0), Vec3::UnitY()});
  ASSERT_TRUE(inside);
  EXPECT_EQ(inside->t, 0.0);
  EXPECT_EQ(inside->normal, -Vec3::UnitY());
}

TEST(VoxelModel, BadInputIsAnErrorNamingTheField) {
  {
    auto m = dm::VoxelModel::fromSdf(dm::Volume{});
    ASSERT_FALSE(m);
    EXPECT_NE(m.error().message().find("empty"), std::string::npos) << m.error().message();
  }
  {
    auto m = dm::VoxelModel::fromOccupancy(dm::Volume{}, 0.5);
    ASSERT_FALSE(m);
    EXPECT_NE(m.error().message().find("empty"), std::string::npos) << m.error().message();
  }
  auto v = dm::Volume::create({4, 5, 6}, dm::VoxelType::F32);
  ASSERT_TRUE(v);
  v->setValue(1, 2, 3, std::numeric_limits<double>::quiet_NaN());
  {
    auto m = dm::VoxelModel::fromSdf(*v);
    ASSERT_FALSE(m);
    EXPECT_NE(m.error().message().find("(1, 2, 3)"), std::string::npos) << m.error().message();
  }
  {
    auto m = dm::VoxelModel::fromOccupancy(*v, 0.5);
    ASSERT_FALSE(m);
    EXPECT_NE(m.error().message().find("(1, 2, 3)"), std::string::npos) << m.error().message();
  }
  v->setValue(1, 2, 3, 0.0);
  {
    auto m = dm::VoxelModel::fromOccupancy(*v, 0.5);  // nothing inside
    ASSERT_FALSE(m);
    EXPECT_NE(m.error().message().find("threshold"), std::string::npos) << m.error().message();
  }
  {
    auto m = dm::VoxelModel::fromOccupancy(*v, -1.0);  // everything inside
    ASSERT_FALSE(m);
    EXPECT_NE(m.error().message().find("every voxel"), std::string::npos) << m.error().message();
  }
  {
    dm::Mesh open = dm::makeBox(Vec3(0.01, 0.01, 0.01));
    open.triangles.pop_back();
    auto m = dm::VoxelModel::fromMesh(open, {.voxelSize = 1e-3});
    ASSERT_FALSE(m);
    EXPECT_NE(m.error().message().find("fromMesh"), std::string::npos) << m.error().message();
  }
}

}  // namespace
