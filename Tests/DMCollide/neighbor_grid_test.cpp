// The fixed-radius neighbour search against brute force: a uniform cloud, a
// thin slab (one cell deep), points on a sphere (curved, and sparse in its
// bounding box), two far clusters (the sparse table), a prefix of listed
// points with the rest found only through others' lists and
// forEachWithin(), points exactly one radius apart (not neighbours), and
// non-finite points (in no list). Lists come sorted by index.
#include <dm/collide/neighbor_grid.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <numbers>
#include <random>
#include <vector>

namespace neighbor_grid_test {

using dm::Vec3;

std::vector<std::uint32_t> bruteForce(const std::vector<Vec3>& p, std::size_t i, double r) {
  std::vector<std::uint32_t> out;
  if (!p[i].allFinite()) return out;
  for (std::size_t j = 0; j < p.size(); ++j)
    if (j != i && p[j].allFinite() && (p[j] - p[i]).squaredNorm() < r * r) out.push_back(std::uint32_t(j));
  return out;
}

void expectBruteForce(const std::vector<Vec3>& p, double r,
                      std::size_t listed = std::numeric_limits<std::size_t>::max()) {
  dm::NeighborGrid grid;
  grid.build(p, r, listed);
  const std::size_t n = std::min(p.size(), listed);
  ASSERT_EQ(grid.size(), n);
  std::size_t pairs = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const auto got = grid.neighbors(i);
    const std::vector<std::uint32_t> want = bruteForce(p, i, r);
    ASSERT_EQ(std::vector<std::uint32_t>(got.begin(), got.end()), want) << "point " << i;
    pairs += want.size();
  }
  EXPECT_EQ(grid.pairCount(), pairs);
  // forEachWithin: every point, listed or not, itself included.
  for (std::size_t i = 0; i < p.size(); i += 7) {
    std::vector<std::uint32_t> found;
    grid.forEachWithin(p[i], [&](std::uint32_t j) { found.push_back(j); });
    std::sort(found.begin(), found.end());
    std::vector<std::uint32_t> want = bruteForce(p, i, r);
    if (p[i].allFinite())
      want.insert(std::lower_bound(want.begin(), want.end(), std::uint32_t(i)), std::uint32_t(i));
    EXPECT_EQ(found, want) << "point " << i;
  }
}

TEST(NeighborGrid, AUniformCloudListsWhatBruteForceFinds) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-0.05, 0.05);
  std::vector<Vec3> p(3000);
  for (Vec3& x : p) x = Vec3(u(rng), u(rng), u(rng));
  expectBruteForce(p, 0.008);
  expectBruteForce(p, 0.03);
}

TEST(NeighborGrid, AThinSlabAndASphereListWhatBruteForceFinds) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-0.1, 0.1), e(-1e-5, 1e-5);
  std::vector<Vec3> slab(2000);
  for (Vec3& x : slab) x = Vec3(u(rng), u(rng), e(rng));
  expectBruteForce(slab, 0.01);
  std::vector<Vec3> sphere;
  std::normal_distribution<double> g;
  for (int k = 0; k < 2500; ++k) sphere.push_back(0.05 * Vec3(g(rng), g(rng), g(rng)).normalized());
  expectBruteForce(sphere, 0.006);
}

TEST(NeighborGrid, FarClustersUseTheSparseTableAndListTheSame) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(0.0, 0.02);
  std::vector<Vec3> p;
  for (int k = 0; k < 500; ++k) p.emplace_back(u(rng), u(rng), u(rng));
  for (int k = 0; k < 500; ++k) p.emplace_back(10.0 + u(rng), -7.0 + u(rng), 3.0 + u(rng));
  expectBruteForce(p, 0.004);  // (10 m / 4 mm)³ cells for 1000 points: sparse
}

TEST(NeighborGrid, OnlyTheListedPrefixGetsListsButAllAreFound) {
  std::mt19937 rng(9);
  std::uniform_real_distribution<double> u(0.0, 0.05);
  std::vector<Vec3> p(1500);
  for (Vec3& x : p) x = Vec3(u(rng), u(rng), u(rng));
  expectBruteForce(p, 0.01, 600);
}

TEST(NeighborGrid, PointsOneRadiusApartAreNotNeighboursAndNonFiniteOnesAreNowhere) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  std::vector<Vec3> p = {Vec3(0, 0, 0), Vec3(0.01, 0, 0), Vec3(0.0099, 0.001, 0), Vec3(nan, 0, 0),
                         Vec3(0.005, std::numeric_limits<double>::infinity(), 0)};
  dm::NeighborGrid grid;
  grid.build(p, 0.01);
  EXPECT_EQ(std::vector<std::uint32_t>(grid.neighbors(0).begin(), grid.neighbors(0).end()),
            std::vector<std::uint32_t>({2}));  // (0.01, 0, 0) is exactly one radius away
  EXPECT_TRUE(grid.neighbors(3).empty());
  EXPECT_TRUE(grid.neighbors(4).empty());
  expectBruteForce(p, 0.01);
}

}  // namespace neighbor_grid_test
