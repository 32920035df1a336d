// Tests of dm/vision/segmentation.hpp on a synthetic volume whose geometry
// is known: a bright noisy sphere in a dark background, with a thin bright
// bridge running from the sphere to the border (a path along which plain
// region growing leaks). Radii are checked against the distance to the
// sphere surface, the force against the symmetry of the sphere.
#include <dm/core/units.hpp>
#include <dm/vision/segmentation.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <limits>
#include <random>

#include "../common/alloc_counter.hpp"

namespace {

using dm::Vec3;
using dm::Vec3i;
using dm::Volume;

constexpr int kN = 48;
constexpr double kH = 1e-3;            // voxel size, m
constexpr double kRadius = 15.0;       // sphere radius, voxels
const Vec3 kCentre(23.6, 24.2, 23.9);  // voxels, off the lattice on purpose

Vec3 world(const Vec3& ijk) { return kH * ijk; }

// Value 100 inside the sphere (partial volume at the surface), 100 in a bridge
// of radius 1.5 voxels along +x from the centre to the border, 0 elsewhere,
// plus Gaussian noise of standard deviation 3.
Volume makePhantom() {
  dm::Affine3 a = dm::Affine3::Identity();
  a.linear() *= kH;
  auto v = Volume::create(Vec3i(kN, kN, kN), dm::VoxelType::F32, a);
  EXPECT_TRUE(v) << v.error();
  std::mt19937 rng(42);
  std::normal_distribution<double> noise(0.0, 3.0);
  for (int k = 0; k < kN; ++k)
    for (int j = 0; j < kN; ++j)
      for (int i = 0; i < kN; ++i) {
        int inside = 0;
        for (int s = 0; s < 27; ++s) {
          const Vec3 p(i + (s % 3 - 1) / 3.0, j + ((s / 3) % 3 - 1) / 3.0, k + (s / 9 - 1) / 3.0);
          const Vec3 d = p - kCentre;
          inside += d.norm() <= kRadius || (d.x() > 0 && std::hypot(d.y(), d.z()) <= 1.5);
        }
        v->setValue(i, j, k, 100.0 * inside / 27.0 + noise(rng));
      }
  return std::move(*v);
}

dm::HapticSegmentationOptions phantomOptions() {
  dm::HapticSegmentationOptions o;
  o.edgeSigma = 1.0 * dm::units::mm;
  o.rayCount = 64;
  o.minRadius = 1.0 * dm::units::mm;
  o.maxRadius = 20.0 * dm::units::mm;
  o.edgeThreshold = 0.3;
  o.gain = 1e-2;
  o.maxForce = 5.0;
  o.grow.lower = 50.0;
  o.grow.connectivity = dm::Connectivity::Six;
  return o;
}

class HapticSegmentationTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    phantom_ = new Volume(makePhantom());
    auto seg = dm::HapticSegmentation::create(*phantom_, phantomOptions());
    ASSERT_TRUE(seg) << seg.error();
    seg_ = new dm::HapticSegmentation(std::move(*seg));
  }
  static void TearDownTestSuite() {
    delete seg_;
    delete phantom_;
  }
  static Volume* phantom_;
  static dm::HapticSegmentation* seg_;
};
Volume* HapticSegmentationTest::phantom_ = nullptr;
dm::HapticSegmentation* HapticSegmentationTest::seg_ = nullptr;

TEST_F(HapticSegmentationTest, RaysComeInAntipodalPairsOfUnitLength) {
  const auto rays = seg_->rayDirections();
  ASSERT_EQ(rays.size(), 64u);
  Vec3 sum = Vec3::Zero();
  for (const Vec3& d : rays) {
    EXPECT_NEAR(d.norm(), 1.0, 1e-12);
    sum += d;
  }
  EXPECT_LT(sum.norm(), 1e-12);
}

TEST_F(HapticSegmentationTest, AdaptiveRadiusIsTheDistanceToTheSphereSurface) {
  // At the centre every ray meets the surface at the sphere radius.
  std::printf("radius at the centre %.3f mm (sphere %.1f mm)\n", seg_->adaptiveRadius(world(kCentre)) * 1e3,
              kRadius);
  EXPECT_NEAR(seg_->adaptiveRadius(world(kCentre)), kRadius * kH, 1.0 * kH);
  // Off centre the nearest surface point is R − e away (away from the bridge).
  for (double e : {5.0, 9.0}) {
    const Vec3 p = world(kCentre - Vec3(e, 0, 0));
    EXPECT_NEAR(seg_->adaptiveRadius(p), (kRadius - e) * kH, 1.0 * kH) << "offset " << e;
  }
  // Along one ray: the distance to the surface in that direction.
  EXPECT_NEAR(seg_->rayDistance(world(kCentre), Vec3(0, 0, 1)), kRadius * kH, 1.0 * kH);
  // Outside in the background, far from everything: rMax.
  EXPECT_NEAR(seg_->rayDistance(world(Vec3(3, 3, 3)), Vec3(-1, 0, 0)), 20.0 * kH, 1e-12);
  EXPECT_EQ(seg_->adaptiveRadius(Vec3::Constant(std::nan(""))), 1.0 * kH);
}

TEST_F(HapticSegmentationTest, GuidanceForcePointsInwardNearTheBoundaryAndVanishesAtTheCentre) {
  const Vec3 centreForce = seg_->guidanceForce(world(kCentre));
  double weakest = std::numeric_limits<double>::infinity();
  // 4 voxels inside the surface, on four sides away from the bridge.
  for (const Vec3& dir : {Vec3(-1, 0, 0), Vec3(0, 1, 0), Vec3(0, -1, 0), Vec3(0, 0, 1), Vec3(0, 0, -1)}) {
    const Vec3 p = world(kCentre + (kRadius - 4.0) * dir);
    const Vec3 f = seg_->guidanceForce(p);
    ASSERT_TRUE(f.allFinite());
    EXPECT_GT(f.norm(), 0.0);
    // Inward: towards the centre, i.e. against `dir`.
    EXPECT_GT(-f.normalized().dot(dir), 0.9) << "side " << dir.transpose() << " force " << f.transpose();
    weakest = std::min(weakest, f.norm());
    std::printf("force 4 mm inside, side (%g, %g, %g): (%.4f, %.4f, %.4f) N\n", dir.x(), dir.y(), dir.z(),
                f.x(), f.y(), f.z());
  }
  std::printf("force at the centre: (%.5f, %.5f, %.5f) N\n", centreForce.x(), centreForce.y(),
              centreForce.z());
  EXPECT_LT(centreForce.norm(), 0.1 * weakest) << centreForce.transpose();
  EXPECT_LE(seg_->guidanceForce(world(kCentre + Vec3(-13.5, 0, 0))).norm(), 5.0 + 1e-12);
  EXPECT_EQ(seg_->guidanceForce(Vec3(std::nan(""), 0, 0)), Vec3::Zero());
  EXPECT_EQ(seg_->guidanceForce(Vec3::Constant(std::numeric_limits<double>::infinity())), Vec3::Zero());
}

TEST_F(HapticSegmentationTest, ForceMagnitudeIsClamped) {
  auto o = phantomOptions();
  o.gain = 1e3;
  o.maxForce = 0.5;
  auto strong = dm::HapticSegmentation::create(*phantom_, o);
  ASSERT_TRUE(strong) << strong.error();
  const Vec3 f = strong->guidanceForce(world(kCentre + Vec3(-11, 0, 0)));
  EXPECT_NEAR(f.norm(), 0.5, 1e-9);
  EXPECT_GT(f.x(), 0.0);
}

TEST_F(HapticSegmentationTest, ProbePathSegmentsTheSphereWithoutLeakingIntoTheBridge) {
  dm::HapticSegmentation seg = std::move(*dm::HapticSegmentation::create(*phantom_, phantomOptions()));
  const Vec3 path[] = {{0, 0, 0}, {-6, 0, 0}, {6, 0, 0}, {0, -6, 0},
                       {0, 6, 0}, {0, 0, -6}, {0, 0, 6}, {10, 0, 0}};
  std::size_t total = 0;
  for (const Vec3& offset : path) {
    auto u = seg.update(world(kCentre + offset));
    ASSERT_TRUE(u) << u.error();
    EXPECT_GT(u->radius, 0.0);
    total += u->newVoxels;
    EXPECT_EQ(u->totalVoxels, total);
  }
  EXPECT_EQ(seg.segmentedVoxels(), total);
  EXPECT_NEAR(seg.segmentedVolume(), static_cast<double>(total) * kH * kH * kH, 1e-15);
  std::size_t interior = 0, covered = 0, outside = 0;
  for (int k = 0; k < kN; ++k)
    for (int j = 0; j < kN; ++j)
      for (int i = 0; i < kN; ++i) {
        const double r = (Vec3(i, j, k) - kCentre).norm();
        const bool in = seg.mask().value(i, j, k) != 0;
        if (r <= kRadius - 1.5) {
          ++interior;
          covered += in;
        }
        if (in && r > kRadius + 0.5) ++outside;
      }
  std::printf("segmented %zu voxels, %zu of %zu interior voxels, %zu outside\n", total, covered, interior,
              outside);
  EXPECT_EQ(outside, 0u) << "voxels segmented outside the sphere";
  EXPECT_GT(static_cast<double>(covered), 0.97 * static_cast<double>(interior));

  // Without the adaptive ball the same criteria leak along the bridge:
  // that is what the ball prevents.
  auto plain = dm::growRegion(*phantom_, std::array{Vec3i(24, 24, 24)}, phantomOptions().grow);
  ASSERT_TRUE(plain) << plain.error();
  std::size_t leaked = 0;
  for (int k = 0; k < kN; ++k)
    for (int j = 0; j < kN; ++j)
      for (int i = 0; i < kN; ++i)
        leaked += plain->mask.value(i, j, k) != 0 && (Vec3(i, j, k) - kCentre).norm() > kRadius + 2;
  std::printf("plain region growing leaked %zu voxels along the bridge\n", leaked);
  EXPECT_GT(leaked, 10u);

  // A probe outside the grid grows nothing; clear() empties the mask.
  auto away = seg.update(Vec3(1.0, 1.0, 1.0));
  ASSERT_TRUE(away) << away.error();
  EXPECT_EQ(away->grownVoxels, 0u);
  EXPECT_FALSE(seg.update(Vec3(std::nan(""), 0, 0)));
  seg.clear();
  EXPECT_EQ(seg.segmentedVoxels(), 0u);
  EXPECT_EQ(seg.mask().range().second, 0.0);
}

TEST_F(HapticSegmentationTest, RealTimeQueriesDoNotAllocate) {
  const Vec3 probes[] = {world(kCentre), world(kCentre + Vec3(-11, 0, 0)), world(Vec3(2, 2, 2)),
                         Vec3(std::nan(""), 0, 0), Vec3(5.0, 5.0, 5.0)};
  Vec3 sink = Vec3::Zero();
  dm::test::tCountAllocations = true;
  const auto before = dm::test::countedAllocations();
  for (const Vec3& p : probes) {
    sink += seg_->guidanceForce(p);
    sink.x() += seg_->adaptiveRadius(p);
    sink += seg_->edgeGradient(p);
  }
  const auto after = dm::test::countedAllocations();
  dm::test::tCountAllocations = false;
  EXPECT_EQ(after, before);
  EXPECT_TRUE(sink.allFinite());
}

TEST(HapticSegmentation, RejectsBadOptions) {
  const Volume phantom = makePhantom();
  auto bad = [&](auto edit) {
    auto o = phantomOptions();
    edit(o);
    return !dm::HapticSegmentation::create(phantom, o);
  };
  EXPECT_TRUE(bad([](auto& o) { o.rayCount = 2; }));
  EXPECT_TRUE(bad([](auto& o) { o.minRadius = 0; }));
  EXPECT_TRUE(bad([](auto& o) { o.maxRadius = 0.5e-3; }));
  EXPECT_TRUE(bad([](auto& o) { o.edgeThreshold = 1.5; }));
  EXPECT_TRUE(bad([](auto& o) { o.gain = -1; }));
  EXPECT_TRUE(bad([](auto& o) { o.rayStep = 1e-9; }));
  EXPECT_TRUE(bad([](auto& o) { o.grow.lower = 10, o.grow.upper = 5; }));
  EXPECT_FALSE(dm::HapticSegmentation::create(Volume{}));
}

}  // namespace
