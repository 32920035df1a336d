// dm::squaredDistanceToForeground against brute force: every voxel's squared
// distance to the nearest foreground voxel centre, on anisotropic grids
// (a random speckle and a thin curved shell), in index units exact
// integers, and +∞ on a grid without foreground.
#include <dm/math/volume_distance.hpp>

#include <gtest/gtest.h>

#include <cstdint>
#include <limits>
#include <random>
#include <vector>

namespace {

using dm::Vec3;
using dm::Vec3i;

constexpr float kInf = std::numeric_limits<float>::infinity();

std::vector<float> bruteForce(const std::vector<std::uint8_t>& fg, const Vec3i& d, const Vec3& s) {
  std::vector<Vec3> points;
  for (int k = 0; k < d.z(); ++k)
    for (int j = 0; j < d.y(); ++j)
      for (int i = 0; i < d.x(); ++i)
        if (fg[(static_cast<std::size_t>(k) * d.y() + j) * d.x() + i] != 0)
          points.push_back(Vec3(i, j, k).cwiseProduct(s));
  std::vector<float> out(fg.size(), kInf);
  std::size_t n = 0;
  for (int k = 0; k < d.z(); ++k)
    for (int j = 0; j < d.y(); ++j)
      for (int i = 0; i < d.x(); ++i, ++n) {
        double best = kInf;
        for (const Vec3& p : points) best = std::min(best, (Vec3(i, j, k).cwiseProduct(s) - p).squaredNorm());
        out[n] = static_cast<float>(best);
      }
  return out;
}

TEST(VolumeDistance, ARandomSpeckleOnAnAnisotropicGridIsTheBruteForceDistance) {
  const Vec3i d(17, 13, 11);
  std::mt19937 rng(7);
  std::bernoulli_distribution on(0.02);
  std::vector<std::uint8_t> fg(static_cast<std::size_t>(d.prod()));
  for (auto& v : fg) v = on(rng) ? 1 : 0;
  for (const Vec3& s : {Vec3(1, 1, 1), Vec3(1.0, 2.0, 0.5), Vec3(0.3, 0.7, 1.9)}) {
    const std::vector<float> got = dm::squaredDistanceToForeground(fg, d, s);
    const std::vector<float> want = bruteForce(fg, d, s);
    ASSERT_EQ(got.size(), want.size());
    for (std::size_t n = 0; n < got.size(); ++n) ASSERT_NEAR(got[n], want[n], 1e-5 * (1 + want[n])) << n;
  }
}

TEST(VolumeDistance, AThinCurvedShellInIndexUnitsGivesExactIntegers) {
  // A one-voxel-thick spherical shell of radius 8 voxels, off the grid's centre.
  const Vec3i d(24, 22, 20);
  std::vector<std::uint8_t> fg(static_cast<std::size_t>(d.prod()));
  std::size_t n = 0;
  for (int k = 0; k < d.z(); ++k)
    for (int j = 0; j < d.y(); ++j)
      for (int i = 0; i < d.x(); ++i, ++n)
        fg[n] = std::abs((Vec3(i, j, k) - Vec3(11.3, 10.6, 9.2)).norm() - 8) < 0.5;
  const std::vector<float> got = dm::squaredDistanceToForeground(fg, d);
  const std::vector<float> want = bruteForce(fg, d, Vec3::Ones());
  for (n = 0; n < got.size(); ++n) {
    ASSERT_EQ(got[n], want[n]) << n;
    ASSERT_EQ(got[n], std::round(got[n]));
  }
}

TEST(VolumeDistance, NoForegroundIsInfinitelyFar) {
  const Vec3i d(5, 4, 3);
  const std::vector<std::uint8_t> fg(60, 0);
  for (const float v : dm::squaredDistanceToForeground(fg, d, Vec3(1, 2, 3))) EXPECT_EQ(v, kInf);
}

}  // namespace
