// Tests of dm/vision/region_growing.hpp: exact regions on synthetic volumes
// (boxes, balls, steps, noisy spheres) and an acceptance run on real data,
// the white matter of the Colin27 brain (mricron-data ch2bet.nii.gz).
#include <dm/core/filesystem.hpp>
#include <dm/core/units.hpp>
#include <dm/io/volume_io.hpp>
#include <dm/vision/region_growing.hpp>

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <random>

#include "vision_test_support.hpp"

namespace {

using dm::Vec3;
using dm::Vec3i;
using dm::Volume;

Volume makeIsoVolume(const Vec3i& dims, dm::VoxelType type, double h = 1e-3) {
  dm::Affine3 a = dm::Affine3::Identity();
  a.linear() *= h;
  auto v = Volume::create(dims, type, a);
  EXPECT_TRUE(v) << v.error();
  return std::move(*v);
}

using dm::test::countOn;

TEST(RegionGrowing, FillsExactlyTheConnectedBoxInsideTheInterval) {
  Volume v = makeIsoVolume({20, 16, 12}, dm::VoxelType::U8, 2e-3);
  auto fill = [&](Vec3i lo, Vec3i hi, double value) {
    for (int k = lo.z(); k <= hi.z(); ++k)
      for (int j = lo.y(); j <= hi.y(); ++j)
        for (int i = lo.x(); i <= hi.x(); ++i) v.setValue(i, j, k, value);
  };
  fill({2, 3, 1}, {7, 9, 5}, 100);    // 6×7×5 = 210 voxels
  fill({10, 3, 1}, {15, 9, 5}, 100);  // same value, not connected
  fill({2, 10, 1}, {7, 12, 5}, 200);  // connected but outside the interval
  auto r = dm::growRegion(v, std::array{Vec3i(4, 5, 3)}, {.lower = 50, .upper = 150});
  ASSERT_TRUE(r) << r.error();
  EXPECT_EQ(r->stats.voxelCount, 210u);
  EXPECT_EQ(r->stats.newVoxels, 210u);
  EXPECT_EQ(countOn(r->mask), 210u);
  EXPECT_EQ(r->stats.minIndex, Vec3i(2, 3, 1));
  EXPECT_EQ(r->stats.maxIndex, Vec3i(7, 9, 5));
  EXPECT_NEAR(r->stats.volumeM3, 210 * 8e-9, 1e-18);  // 2 mm voxels: 8 mm³ each
  EXPECT_NEAR(r->stats.volumeMl, 210 * 8e-3, 1e-12);
  EXPECT_TRUE(r->stats.worldBounds.min().isApprox(Vec3(4e-3, 6e-3, 2e-3)));
  EXPECT_TRUE(r->stats.worldBounds.max().isApprox(Vec3(14e-3, 18e-3, 10e-3)));
  EXPECT_DOUBLE_EQ(r->stats.mean, 100.0);
  EXPECT_DOUBLE_EQ(r->stats.stddev, 0.0);
  EXPECT_FALSE(r->stats.truncated);
  EXPECT_EQ(r->mask.value(12, 5, 3), 0);
  EXPECT_EQ(r->mask.value(4, 11, 3), 0);
  // A seed that fails the criteria grows nothing.
  auto none = dm::growRegion(v, std::array{Vec3i(0, 0, 0)}, {.lower = 50});
  ASSERT_TRUE(none) << none.error();
  EXPECT_EQ(none->stats.voxelCount, 0u);
  EXPECT_TRUE(none->stats.worldBounds.isEmpty());
}

TEST(RegionGrowing, ConnectivityDecidesWhetherADiagonalChainIsOneRegion) {
  Volume v = makeIsoVolume({8, 8, 8}, dm::VoxelType::U8);
  for (int t = 0; t < 6; ++t) v.setValue(t + 1, t + 1, t + 1, 1);  // corner-to-corner chain
  const std::array seed{Vec3i(1, 1, 1)};
  auto six = dm::growRegion(v, seed, {.lower = 1, .connectivity = dm::Connectivity::Six});
  auto all = dm::growRegion(v, seed, {.lower = 1, .connectivity = dm::Connectivity::TwentySix});
  ASSERT_TRUE(six && all);
  EXPECT_EQ(six->stats.voxelCount, 1u);
  EXPECT_EQ(all->stats.voxelCount, 6u);
}

TEST(RegionGrowing, BoundingBallKeepsTheVoxelsWhoseCentresLieInside) {
  Volume v = makeIsoVolume({21, 21, 21}, dm::VoxelType::U8);
  for (std::size_t n = 0; n < v.voxelCount(); ++n) v.setValueAt(n, 1);
  const Vec3 centre(10.3e-3, 9.8e-3, 10.1e-3);
  const double radius = 6.5e-3;
  auto r = dm::growRegion(v, std::array{Vec3i(10, 10, 10)}, {.bound = dm::GrowBall{centre, radius}});
  ASSERT_TRUE(r) << r.error();
  std::size_t expected = 0;
  for (int k = 0; k < 21; ++k)
    for (int j = 0; j < 21; ++j)
      for (int i = 0; i < 21; ++i) {
        const bool inside = (1e-3 * Vec3(i, j, k) - centre).norm() <= radius;
        expected += inside;
        ASSERT_EQ(r->mask.value(i, j, k) != 0, inside) << i << ' ' << j << ' ' << k;
      }
  EXPECT_EQ(r->stats.voxelCount, expected);
  // The lattice count approaches the ball volume.
  const double ball = 4.0 / 3.0 * std::numbers::pi * std::pow(radius, 3);
  EXPECT_NEAR(r->stats.volumeM3, ball, 0.05 * ball);
}

TEST(RegionGrowing, GradientBoundStopsBeforeAStep) {
  Volume v = makeIsoVolume({20, 6, 6}, dm::VoxelType::F32);
  for (int k = 0; k < 6; ++k)
    for (int j = 0; j < 6; ++j)
      for (int i = 0; i < 20; ++i) v.setValue(i, j, k, i < 12 ? 0.0 : 100.0);
  // Central differences see the step of 100 at i = 11 and 12: 50 per voxel
  // = 50 000 per metre. Plateau voxels have gradient 0.
  auto r = dm::growRegion(v, std::array{Vec3i(2, 2, 2)}, {.maxGradient = 1000.0});
  ASSERT_TRUE(r) << r.error();
  EXPECT_EQ(r->stats.voxelCount, 11u * 36u);
  EXPECT_EQ(r->stats.maxIndex.x(), 10);
  auto unbounded = dm::growRegion(v, std::array{Vec3i(2, 2, 2)}, {});
  ASSERT_TRUE(unbounded);
  EXPECT_EQ(unbounded->stats.voxelCount, v.voxelCount());
}

TEST(RegionGrowing, AdaptiveCriterionFollowsANoisySphere) {
  const int n = 40;
  const double R = 12.0;
  const Vec3 c(19.7, 20.1, 20.3);
  Volume v = makeIsoVolume({n, n, n}, dm::VoxelType::F32);
  std::mt19937 rng(5);
  std::normal_distribution<double> noise(0.0, 4.0);
  std::size_t inside = 0;
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        const bool in = (Vec3(i, j, k) - c).norm() <= R;
        inside += in;
        v.setValue(i, j, k, (in ? 120.0 : 60.0) + noise(rng));
      }
  dm::RegionGrowOptions o{.adaptive = true, .k = 3.0, .connectivity = dm::Connectivity::Six};
  auto r = dm::growRegion(v, std::array{Vec3i(20, 20, 20)}, o);
  ASSERT_TRUE(r) << r.error();
  std::size_t outside = 0;
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) outside += r->mask.value(i, j, k) != 0 && (Vec3(i, j, k) - c).norm() > R;
  EXPECT_EQ(outside, 0u);
  EXPECT_GT(static_cast<double>(r->stats.voxelCount), 0.97 * static_cast<double>(inside));
  EXPECT_NEAR(r->stats.mean, 120.0, 1.0);
  EXPECT_NEAR(r->stats.stddev, 4.0, 0.5);
}

TEST(RegionGrowing, MaxVoxelsTruncatesAndGrowerAccumulatesIntoAMask) {
  Volume v = makeIsoVolume({10, 10, 10}, dm::VoxelType::U8);
  for (std::size_t n = 0; n < v.voxelCount(); ++n) v.setValueAt(n, 1);
  auto r = dm::growRegion(v, std::array{Vec3i(5, 5, 5)}, {.maxVoxels = 100});
  ASSERT_TRUE(r) << r.error();
  EXPECT_EQ(r->stats.voxelCount, 100u);
  EXPECT_TRUE(r->stats.truncated);

  auto mask = Volume::create(v.dims(), dm::VoxelType::U8, v.indexToWorld());
  ASSERT_TRUE(mask);
  dm::RegionGrower grower;
  const dm::GrowBall a{Vec3(3e-3, 5e-3, 5e-3), 2e-3}, b{Vec3(5e-3, 5e-3, 5e-3), 2e-3};
  auto first = grower.grow(v, std::array{Vec3i(3, 5, 5)}, {.bound = a}, *mask);
  auto second = grower.grow(v, std::array{Vec3i(5, 5, 5)}, {.bound = b}, *mask);
  ASSERT_TRUE(first && second);
  EXPECT_EQ(first->voxelCount, 33u);  // lattice points within radius 2
  EXPECT_EQ(first->newVoxels, 33u);
  EXPECT_EQ(second->voxelCount, 33u);
  EXPECT_LT(second->newVoxels, 33u);  // the balls overlap
  EXPECT_EQ(countOn(*mask), first->newVoxels + second->newVoxels);
}

TEST(RegionGrowing, RejectsBadInput) {
  Volume v = makeIsoVolume({4, 4, 4}, dm::VoxelType::U8);
  auto outside = dm::growRegion(v, std::array{Vec3i(4, 0, 0)});
  ASSERT_FALSE(outside);
  EXPECT_NE(outside.error().what.find("seed 0"), std::string::npos) << outside.error();
  EXPECT_FALSE(dm::growRegion(v, std::array{Vec3i(0, 0, 0)}, {.lower = 5, .upper = 1}));
  EXPECT_FALSE(dm::growRegion(v, std::array{Vec3i(0, 0, 0)}, {.adaptive = true, .k = 0}));
  EXPECT_FALSE(dm::growRegion(v, std::array{Vec3i(0, 0, 0)}, {.bound = dm::GrowBall{Vec3::Zero(), -1}}));
  EXPECT_FALSE(dm::growRegion(Volume{}, std::array{Vec3i(0, 0, 0)}));
  dm::RegionGrower grower;
  Volume wrong = makeIsoVolume({4, 4, 5}, dm::VoxelType::U8);
  EXPECT_FALSE(grower.grow(v, std::array{Vec3i(0, 0, 0)}, {}, wrong));
  EXPECT_FALSE(dm::nearestVoxel(v, Vec3(1.0, 0, 0)));
  EXPECT_FALSE(dm::nearestVoxel(v, Vec3(std::nan(""), 0, 0)));
  EXPECT_EQ(*dm::nearestVoxel(v, Vec3(1.4e-3, 2.6e-3, 0)), Vec3i(1, 3, 0));
}

// Acceptance on real data: the white matter of the Colin27 brain
// (skull-stripped T1, 1 mm, uint8).
// The adaptive criterion (mean ± 2.5 σ of the seed's neighbourhood, updated
// as the region grows) measured 590.5 mL (mean 110.9, σ 4.9; the uint8
// histogram has its grey-matter mode near 86 and its white-matter mode near
// 113). Colin27 lives in MNI space, about 1.2× an average adult brain, whose
// white matter is 400-550 mL: the bounds keep a margin of about 25 % below
// and 18 % above the measurement.
constexpr double kMinMl = 450, kMaxMl = 700;
TEST(RegionGrowing, WhiteMatterOfColin27HasAPlausibleVolume) {
  auto path = dm::FileSystem::global().resolve("mricron:ch2bet.nii.gz");
  if (!path) GTEST_SKIP() << path.error() << " (apt install mricron-data)";
  auto brain = dm::readVolume(*path);
  ASSERT_TRUE(brain) << brain.error();
  // Right corona radiata, MNI (26, -12, 30) mm: white matter near the centre.
  const Vec3 seedWorld = Vec3(26, -12, 30) * dm::units::mm;
  const auto seed = dm::nearestVoxel(*brain, seedWorld);
  ASSERT_TRUE(seed);
  const Vec3 at = brain->indexToWorld() * seed->cast<double>();
  std::printf("seed voxel (%d, %d, %d) at world (%.1f, %.1f, %.1f) mm, value %.0f\n", seed->x(), seed->y(),
              seed->z(), at.x() * 1e3, at.y() * 1e3, at.z() * 1e3,
              brain->value(seed->x(), seed->y(), seed->z()));
  dm::RegionGrowOptions o{.adaptive = true, .k = 2.5, .connectivity = dm::Connectivity::TwentySix};
  auto wm = dm::growRegion(*brain, std::array{*seed}, o);
  ASSERT_TRUE(wm) << wm.error();
  std::printf("white matter: %zu voxels, %.1f mL, mean %.1f, sd %.1f\n", wm->stats.voxelCount,
              wm->stats.volumeMl, wm->stats.mean, wm->stats.stddev);
  EXPECT_EQ(wm->mask.value(seed->x(), seed->y(), seed->z()), 1);
  EXPECT_GT(wm->stats.volumeMl, kMinMl);
  EXPECT_LT(wm->stats.volumeMl, kMaxMl);
  // One 26-connected component, inside the brain mask.
  auto cc = dm::labelComponents(wm->mask, dm::Connectivity::TwentySix);
  ASSERT_TRUE(cc) << cc.error();
  EXPECT_EQ(cc->count(), 1u);
  std::size_t outsideBrain = 0;
  for (std::size_t n = 0; n < brain->voxelCount(); ++n)
    outsideBrain += wm->mask.valueAt(n) != 0 && brain->valueAt(n) == 0;
  EXPECT_EQ(outsideBrain, 0u);
}

}  // namespace
