// HapticSegmentation's threading promise (dm/vision/segmentation.hpp): the
// haptic thread may call guidanceForce() and adaptiveRadius() while another
// thread runs update(). Checked here (and under ThreadSanitizer in CI): the
// forces and radii computed during concurrent updates are exactly those of
// a quiet object, and the updates still paint the structure.
#include <dm/vision/segmentation.hpp>

#include <gtest/gtest.h>

#include <atomic>
#include <thread>
#include <vector>

namespace {

using dm::Vec3;

constexpr int kN = 32;
constexpr double kH = 1e-3;  // voxel size, m

// A bright ball of radius 10 voxels (value 100) in a dark grid.
dm::Volume ballPhantom() {
  dm::Affine3 a = dm::Affine3::Identity();
  a.linear() *= kH;
  auto v = dm::Volume::create(dm::Vec3i(kN, kN, kN), dm::VoxelType::F32, a);
  EXPECT_TRUE(v) << v.error();
  const Vec3 centre(15.5, 15.5, 15.5);
  for (int k = 0; k < kN; ++k)
    for (int j = 0; j < kN; ++j)
      for (int i = 0; i < kN; ++i) v->setValue(i, j, k, (Vec3(i, j, k) - centre).norm() <= 10 ? 100.0 : 0.0);
  return std::move(*v);
}

}  // namespace

TEST(HapticSegmentationConcurrency, GuidanceDuringUpdatesMatchesTheQuietValues) {
  const dm::Volume phantom = ballPhantom();
  dm::HapticSegmentationOptions o;
  o.edgeSigma = 1e-3;
  o.rayCount = 32;
  o.maxRadius = 12e-3;
  o.gain = 1e-2;
  o.grow.lower = 50;
  auto seg = dm::HapticSegmentation::create(phantom, o);
  ASSERT_TRUE(seg) << seg.error();

  std::vector<Vec3> probes;
  for (int s = 0; s < 16; ++s) probes.push_back(kH * Vec3(9.0 + s * 0.9, 15.5 + (s % 3), 14.0 + (s % 5) * 0.5));
  std::vector<Vec3> forces;
  std::vector<double> radii;
  for (const Vec3& p : probes) {
    forces.push_back(seg->guidanceForce(p));
    radii.push_back(seg->adaptiveRadius(p));
  }

  std::atomic<bool> done{false};
  std::atomic<int> mismatches{0};
  std::atomic<long> queries{0};
  std::thread haptic([&] {
    while (!done.load(std::memory_order_acquire)) {
      for (std::size_t i = 0; i < probes.size(); ++i) {
        if (seg->guidanceForce(probes[i]) != forces[i] || seg->adaptiveRadius(probes[i]) != radii[i])
          mismatches.fetch_add(1, std::memory_order_relaxed);
        queries.fetch_add(1, std::memory_order_relaxed);
      }
    }
  });
  while (queries.load() == 0) std::this_thread::yield();  // the haptic thread is running
  std::size_t total = 0;
  long queriesDuringUpdates = 0;
  // Rounds of updates until enough queries overlapped them (a loaded machine
  // may not schedule the haptic thread during the first ones).
  for (int round = 0; round < 1000 && queriesDuringUpdates < 200; ++round) {
    if (round > 0) seg->clear();
    const long before = queries.load();
    for (const Vec3& p : probes) {
      auto u = seg->update(p);
      ASSERT_TRUE(u) << u.error();
      total = u->totalVoxels;
    }
    queriesDuringUpdates += queries.load() - before;
  }
  done.store(true, std::memory_order_release);
  haptic.join();
  EXPECT_EQ(mismatches.load(), 0);
  EXPECT_GE(queriesDuringUpdates, 200) << "the queries must overlap the updates";
  // About 4/3·π·10³ ≈ 4189 voxels in the ball; the updates paint most of it and nothing outside.
  EXPECT_GT(total, 2000u);
  EXPECT_LT(total, 4400u);
}
