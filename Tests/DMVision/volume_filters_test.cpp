// Tests of dm/vision/volume_filters.hpp against analytic results (Gaussian
// moments, linear fields, sphere geometry, ball volumes) and brute-force
// reference implementations written here (BFS labelling, offset-loop
// morphology).
#include <dm/core/units.hpp>
#include <dm/vision/volume_filters.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <numbers>
#include <random>
#include <vector>

#include "vision_test_support.hpp"

namespace {

using dm::Vec3;
using dm::Vec3i;
using dm::Volume;
using dm::VoxelType;

Volume makeVolume(const Vec3i& dims, VoxelType type, const dm::Affine3& a = dm::Affine3::Identity()) {
  auto v = Volume::create(dims, type, a);
  EXPECT_TRUE(v) << v.error();
  return std::move(*v);
}

dm::Affine3 scaled(const Vec3& spacing) {
  dm::Affine3 a = dm::Affine3::Identity();
  a.linear() = spacing.asDiagonal();
  return a;
}

// A ball of radius `radius` voxels around `centre` with partial-volume
// values in [0, value] (4³ subsamples per voxel), so the step lies at the
// true radius.
Volume makeSphere(int n, const Vec3& centre, double radius, double value, const Vec3& spacing) {
  Volume v = makeVolume(Vec3i(n, n, n), VoxelType::F32, scaled(spacing));
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        int inside = 0;
        for (int s = 0; s < 64; ++s) {
          const Vec3 p(i + ((s & 3) + 0.5) / 4 - 0.5, j + (((s >> 2) & 3) + 0.5) / 4 - 0.5,
                       k + ((s >> 4) + 0.5) / 4 - 0.5);
          inside += (p - centre).norm() <= radius;
        }
        v.setValue(i, j, k, value * inside / 64.0);
      }
  return v;
}

Volume randomMask(const Vec3i& dims, double density, unsigned seed) {
  Volume v = makeVolume(dims, VoxelType::U8);
  std::mt19937 rng(seed);
  std::bernoulli_distribution on(density);
  for (std::size_t n = 0; n < v.voxelCount(); ++n) v.setValueAt(n, on(rng) ? 1 : 0);
  return v;
}

bool sameMask(const Volume& a, const Volume& b) {
  for (std::size_t n = 0; n < a.voxelCount(); ++n)
    if ((a.valueAt(n) != 0) != (b.valueAt(n) != 0)) return false;
  return true;
}

using dm::test::countOn;

TEST(VolumeFilters, GaussianOfAConstantIsTheConstant) {
  Volume v = makeVolume({20, 18, 16}, VoxelType::I16, scaled(Vec3(1, 2, 0.5) * dm::units::mm));
  for (std::size_t n = 0; n < v.voxelCount(); ++n) v.setValueAt(n, 75);
  auto s = dm::gaussianSmooth(v, 1.5 * dm::units::mm);
  ASSERT_TRUE(s) << s.error();
  EXPECT_EQ(s->type(), VoxelType::F32);
  EXPECT_EQ(s->dims(), v.dims());
  EXPECT_TRUE(s->indexToWorld().isApprox(v.indexToWorld()));
  for (std::size_t n = 0; n < s->voxelCount(); ++n) ASSERT_NEAR(s->valueAt(n), 75.0, 1e-4) << n;
}

TEST(VolumeFilters, GaussianOfAnImpulseHasTheRequestedSecondMomentInWorldUnits) {
  // Anisotropic spacing: sigma 2 mm is 4, 2 and 2.5 voxels along i, j, k.
  const Vec3 spacing = Vec3(0.5, 1.0, 0.8) * dm::units::mm;
  const double sigma = 2.0 * dm::units::mm;
  Volume v = makeVolume({51, 31, 31}, VoxelType::F64, scaled(spacing));
  const Vec3i c(25, 15, 15);
  v.setValue(c.x(), c.y(), c.z(), 1.0);
  auto s = dm::gaussianSmooth(v, sigma, 5.0);
  ASSERT_TRUE(s) << s.error();
  double sum = 0;
  Vec3 second = Vec3::Zero();
  double cross = 0;
  for (int k = 0; k < 31; ++k)
    for (int j = 0; j < 31; ++j)
      for (int i = 0; i < 51; ++i) {
        const double w = s->value(i, j, k);
        const Vec3 d = (Vec3(i, j, k) - c.cast<double>()).cwiseProduct(spacing);
        sum += w;
        second += w * d.cwiseProduct(d);
        cross += w * d.x() * d.y();
      }
  EXPECT_NEAR(sum, 1.0, 1e-5);
  for (int a = 0; a < 3; ++a) EXPECT_NEAR(std::sqrt(second[a] / sum), sigma, 0.005 * sigma) << "axis " << a;
  EXPECT_NEAR(cross / sum, 0.0, 1e-12);
  // Peak of the separable kernel: the product of three unit-sum 1-D Gaussians.
  const Vec3 sv = Vec3::Constant(sigma).cwiseQuotient(spacing);
  const double peak = 1.0 / (std::pow(2 * std::numbers::pi, 1.5) * sv.prod());
  EXPECT_NEAR(s->value(c.x(), c.y(), c.z()), peak, 0.02 * peak);
}

TEST(VolumeFilters, GaussianOfALinearRampIsTheRampInTheInterior) {
  Volume v = makeVolume({30, 24, 20}, VoxelType::F32, scaled(Vec3(1, 1.5, 2) * dm::units::mm));
  auto ramp = [](int i, int j, int k) { return 3.0 + 2.0 * i - 1.0 * j + 0.5 * k; };
  for (int k = 0; k < 20; ++k)
    for (int j = 0; j < 24; ++j)
      for (int i = 0; i < 30; ++i) v.setValue(i, j, k, ramp(i, j, k));
  auto s = dm::gaussianSmooth(v, 1.5 * dm::units::mm);  // radii 5, 3, 3 voxels at 3 sigma
  ASSERT_TRUE(s) << s.error();
  for (int k = 3; k < 17; ++k)
    for (int j = 3; j < 21; ++j)
      for (int i = 5; i < 25; ++i)
        ASSERT_NEAR(s->value(i, j, k), ramp(i, j, k), 2e-4) << i << ' ' << j << ' ' << k;
}

TEST(VolumeFilters, GaussianRejectsBadParameters) {
  Volume empty;
  EXPECT_FALSE(dm::gaussianSmooth(empty, 1e-3));
  Volume v = makeVolume({8, 8, 8}, VoxelType::U8, scaled(Vec3::Constant(1e-3)));
  EXPECT_FALSE(dm::gaussianSmooth(v, -1e-3));
  EXPECT_FALSE(dm::gaussianSmooth(v, std::nan("")));
  EXPECT_FALSE(dm::gaussianSmooth(v, 1e-3, 0.5));
  auto huge = dm::gaussianSmooth(v, 1.0);  // 1 m = 1000 voxels: kernel radius 3000
  ASSERT_FALSE(huge);
  EXPECT_NE(huge.error().what.find("kernel radius"), std::string::npos) << huge.error();
  auto none = dm::gaussianSmooth(v, 0.0);  // sigma 0 is a float copy
  ASSERT_TRUE(none) << none.error();
}

TEST(VolumeFilters, GradientOfALinearFieldIsItsSlopeInWorldUnitsOnAnAnisotropicAffine) {
  dm::Affine3 a = dm::Affine3::Identity();
  a.linear() = dm::AngleAxis(0.4, Vec3(1, 2, 3).normalized()).toRotationMatrix() *
               Vec3(0.5, 1.0, 2.0).asDiagonal() * 1e-3;
  a.translation() = Vec3(0.01, -0.02, 0.03);
  Volume v = makeVolume({12, 10, 8}, VoxelType::F64, a);
  const Vec3 slope(1500.0, -800.0, 250.0);  // value per metre
  for (int k = 0; k < 8; ++k)
    for (int j = 0; j < 10; ++j)
      for (int i = 0; i < 12; ++i) v.setValue(i, j, k, 7.0 + slope.dot(a * Vec3(i, j, k)));
  auto g = dm::gradient(v);
  ASSERT_TRUE(g) << g.error();
  auto m = dm::gradientMagnitude(v);
  ASSERT_TRUE(m) << m.error();
  for (int k = 0; k < 8; ++k)
    for (int j = 0; j < 10; ++j)
      for (int i = 0; i < 12; ++i) {
        ASSERT_LT((g->at(i, j, k) - slope).norm(), 1e-3 * slope.norm()) << i << ' ' << j << ' ' << k;
        ASSERT_NEAR(m->value(i, j, k), slope.norm(), 1e-3 * slope.norm());
      }
  Volume empty;
  EXPECT_FALSE(dm::gradient(empty));
  EXPECT_FALSE(dm::gradientMagnitude(empty));
}

TEST(VolumeFilters, EdgesOfASphereLieOnItsSurface) {
  const double radius = 10.0;  // voxels, 1 mm each
  const Vec3 centre(19.5, 20.0, 20.25);
  Volume v = makeSphere(40, centre, radius, 100.0, Vec3::Constant(1e-3));
  auto e = dm::detectEdges(v, {.sigma = 1e-3, .low = 0.3, .high = 0.6});
  ASSERT_TRUE(e) << e.error();
  EXPECT_NEAR(e->strength.range().second, 1.0, 1e-6);
  EXPECT_GE(e->strength.range().first, 0.0);
  // The steepest slope of a blurred unit step of height 100 is 100/(sqrt(2π)σ),
  // a little less for a curved surface sampled on a grid.
  EXPECT_NEAR(e->maxGradient, 100.0 / (std::sqrt(2 * std::numbers::pi) * 1e-3), 0.25 * 100.0 / 2.5e-3);
  double sum = 0, lo = 1e9, hi = 0;
  std::size_t count = 0;
  for (int k = 0; k < 40; ++k)
    for (int j = 0; j < 40; ++j)
      for (int i = 0; i < 40; ++i)
        if (e->edges.value(i, j, k) != 0) {
          const double r = (Vec3(i, j, k) - centre).norm();
          sum += r;
          lo = std::min(lo, r);
          hi = std::max(hi, r);
          ++count;
        }
  ASSERT_GT(count, 0u);
  std::printf("%zu edge voxels, radius mean %.3f, range [%.3f, %.3f] voxels (sphere %.1f)\n", count,
              sum / count, lo, hi, radius);
  EXPECT_NEAR(sum / count, radius, 0.5);
  EXPECT_GT(lo, radius - 1.5);
  EXPECT_LT(hi, radius + 1.5);
  // A one-voxel-thick shell has about as many voxels as its area in voxels.
  const double area = 4 * std::numbers::pi * radius * radius;
  EXPECT_GT(count, 0.6 * area);
  EXPECT_LT(count, 2.0 * area);
  EXPECT_FALSE(dm::detectEdges(v, {.low = 0.5, .high = 0.2}));
}

TEST(VolumeFilters, ThresholdIsBinaryOrBand) {
  Volume v = makeVolume({5, 1, 1}, VoxelType::F32);
  for (int i = 0; i < 5; ++i) v.setValue(i, 0, 0, i * 10.0);
  auto bin = dm::threshold(v, 20.0);
  ASSERT_TRUE(bin) << bin.error();
  auto band = dm::threshold(v, 10.0, 30.0);
  ASSERT_TRUE(band) << band.error();
  const int wantBin[5] = {0, 0, 1, 1, 1}, wantBand[5] = {0, 1, 1, 1, 0};
  for (int i = 0; i < 5; ++i) {
    EXPECT_EQ(bin->value(i, 0, 0), wantBin[i]) << i;
    EXPECT_EQ(band->value(i, 0, 0), wantBand[i]) << i;
  }
  EXPECT_FALSE(dm::threshold(v, 5.0, 1.0));
  EXPECT_FALSE(dm::threshold(v, std::nan("")));
}

TEST(VolumeFilters, ComponentsOfKnownBlobsHaveExactCountsAndSizes) {
  Volume m = makeVolume({20, 20, 20}, VoxelType::U8);
  auto box = [&](Vec3i lo, Vec3i size) {
    for (int k = 0; k < size.z(); ++k)
      for (int j = 0; j < size.y(); ++j)
        for (int i = 0; i < size.x(); ++i) m.setValue(lo.x() + i, lo.y() + j, lo.z() + k, 1);
  };
  box({1, 1, 1}, {3, 3, 3});     // 27
  box({10, 2, 3}, {2, 4, 5});    // 40
  box({15, 15, 15}, {1, 1, 1});  // 1
  auto cc = dm::labelComponents(m, dm::Connectivity::Six);
  ASSERT_TRUE(cc) << cc.error();
  ASSERT_EQ(cc->count(), 3u);
  EXPECT_EQ(cc->sizes, (std::vector<std::size_t>{40, 27, 1}));
  EXPECT_EQ(cc->labels.value(11, 5, 7), 1);
  EXPECT_EQ(cc->labels.value(2, 2, 2), 2);
  EXPECT_EQ(cc->labels.value(15, 15, 15), 3);
  EXPECT_EQ(cc->labels.value(0, 0, 0), 0);
  auto largest = dm::largestComponent(m);
  ASSERT_TRUE(largest) << largest.error();
  EXPECT_EQ(countOn(*largest), 40u);
  EXPECT_EQ(largest->value(11, 5, 7), 1);
}

TEST(VolumeFilters, ConnectivityDecidesWhetherDiagonalNeighboursJoin) {
  Volume corner = makeVolume({4, 4, 4}, VoxelType::U8);
  corner.setValue(1, 1, 1, 1);
  corner.setValue(2, 2, 2, 1);  // shares only a corner
  Volume edge = makeVolume({4, 4, 4}, VoxelType::U8);
  edge.setValue(1, 1, 1, 1);
  edge.setValue(2, 2, 1, 1);  // shares an edge
  auto count = [](const Volume& v, dm::Connectivity c) { return dm::labelComponents(v, c).value().count(); };
  EXPECT_EQ(count(corner, dm::Connectivity::Six), 2u);
  EXPECT_EQ(count(corner, dm::Connectivity::Eighteen), 2u);
  EXPECT_EQ(count(corner, dm::Connectivity::TwentySix), 1u);
  EXPECT_EQ(count(edge, dm::Connectivity::Six), 2u);
  EXPECT_EQ(count(edge, dm::Connectivity::Eighteen), 1u);
  EXPECT_EQ(count(edge, dm::Connectivity::TwentySix), 1u);
}

// Reference labelling: breadth-first search from every unlabelled voxel.
std::vector<std::size_t> bfsComponentSizes(const Volume& m, dm::Connectivity c) {
  std::vector<char> seen(m.voxelCount(), 0);
  std::vector<std::size_t> sizes;
  const Vec3i d = m.dims();
  for (int k = 0; k < d.z(); ++k)
    for (int j = 0; j < d.y(); ++j)
      for (int i = 0; i < d.x(); ++i) {
        if (m.value(i, j, k) == 0 || seen[m.linearIndex(i, j, k)]) continue;
        std::vector<Vec3i> stack{Vec3i(i, j, k)};
        seen[m.linearIndex(i, j, k)] = 1;
        std::size_t size = 0;
        while (!stack.empty()) {
          const Vec3i p = stack.back();
          stack.pop_back();
          ++size;
          for (int dz = -1; dz <= 1; ++dz)
            for (int dy = -1; dy <= 1; ++dy)
              for (int dx = -1; dx <= 1; ++dx) {
                const int order = std::abs(dx) + std::abs(dy) + std::abs(dz);
                if (order == 0 || (c == dm::Connectivity::Six && order > 1) ||
                    (c == dm::Connectivity::Eighteen && order > 2))
                  continue;
                const Vec3i q = p + Vec3i(dx, dy, dz);
                if (!m.contains(q.x(), q.y(), q.z()) || m.value(q.x(), q.y(), q.z()) == 0) continue;
                char& s = seen[m.linearIndex(q.x(), q.y(), q.z())];
                if (!s) {
                  s = 1;
                  stack.push_back(q);
                }
              }
        }
        sizes.push_back(size);
      }
  std::sort(sizes.rbegin(), sizes.rend());
  return sizes;
}

TEST(VolumeFilters, ComponentsMatchABreadthFirstSearchOnRandomMasks) {
  for (auto c : {dm::Connectivity::Six, dm::Connectivity::Eighteen, dm::Connectivity::TwentySix}) {
    for (unsigned seed : {1u, 2u}) {
      const Volume m = randomMask({17, 13, 11}, c == dm::Connectivity::Six ? 0.3 : 0.15, seed);
      auto cc = dm::labelComponents(m, c);
      ASSERT_TRUE(cc) << cc.error();
      EXPECT_EQ(cc->sizes, bfsComponentSizes(m, c)) << "connectivity " << int(c) << " seed " << seed;
      // Every voxel of a label is foreground, and each label's voxel count is its size.
      std::vector<std::size_t> counted(cc->count() + 1, 0);
      for (std::size_t n = 0; n < m.voxelCount(); ++n) {
        const auto l = static_cast<std::size_t>(cc->labels.valueAt(n));
        ASSERT_EQ(l != 0, m.valueAt(n) != 0);
        ++counted[l];
      }
      for (std::size_t l = 1; l <= cc->count(); ++l) EXPECT_EQ(counted[l], cc->sizes[l - 1]);
    }
  }
}

// Reference morphology: loops over the element's offsets; voxels outside the
// grid are skipped (they neither erode nor dilate).
Volume bruteMorphology(const Volume& m, int r, dm::StructuringElement se, bool erosion) {
  Volume out = makeVolume(m.dims(), VoxelType::U8);
  const Vec3i d = m.dims();
  for (int k = 0; k < d.z(); ++k)
    for (int j = 0; j < d.y(); ++j)
      for (int i = 0; i < d.x(); ++i) {
        bool result = erosion;
        for (int dz = -r; dz <= r; ++dz)
          for (int dy = -r; dy <= r; ++dy)
            for (int dx = -r; dx <= r; ++dx) {
              if (se == dm::StructuringElement::Ball && dx * dx + dy * dy + dz * dz > r * r) continue;
              if (!m.contains(i + dx, j + dy, k + dz)) continue;
              const bool on = m.value(i + dx, j + dy, k + dz) != 0;
              if (erosion && !on) result = false;
              if (!erosion && on) result = true;
            }
        out.setValue(i, j, k, result);
      }
  return out;
}

TEST(VolumeFilters, MorphologyMatchesBruteForceOverTheStructuringElement) {
  const Volume m = randomMask({14, 12, 10}, 0.55, 7);
  const Volume sparse = randomMask({14, 12, 10}, 0.04, 8);
  for (auto se : {dm::StructuringElement::Ball, dm::StructuringElement::Cube})
    for (int r : {1, 2, 3}) {
      auto e = dm::erode(m, r, se);
      ASSERT_TRUE(e) << e.error();
      EXPECT_TRUE(sameMask(*e, bruteMorphology(m, r, se, true))) << "erode r " << r << " se " << int(se);
      auto d = dm::dilate(sparse, r, se);
      ASSERT_TRUE(d) << d.error();
      EXPECT_TRUE(sameMask(*d, bruteMorphology(sparse, r, se, false)))
          << "dilate r " << r << " se " << int(se);
    }
  auto same = dm::erode(m, 0);
  ASSERT_TRUE(same);
  EXPECT_TRUE(sameMask(*same, m));
}

TEST(VolumeFilters, ErodingABallByABallLeavesTheAnalyticBall) {
  const int n = 41;
  const double R = 15.0;
  const int r = 5;
  Volume ball = makeVolume({n, n, n}, VoxelType::U8);
  const Vec3 c(20, 20, 20);
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) ball.setValue(i, j, k, (Vec3(i, j, k) - c).squaredNorm() <= R * R);
  auto e = dm::erode(ball, r);
  ASSERT_TRUE(e) << e.error();
  const double analytic = 4.0 / 3.0 * std::numbers::pi * std::pow(R - r, 3);
  EXPECT_NEAR(static_cast<double>(countOn(*e)), analytic, 0.05 * analytic);
  auto d = dm::dilate(*e, r);
  ASSERT_TRUE(d) << d.error();
  const double grown = 4.0 / 3.0 * std::numbers::pi * std::pow(R, 3);
  EXPECT_NEAR(static_cast<double>(countOn(*d)), grown, 0.05 * grown);
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        const double dist = (Vec3(i, j, k) - c).norm();
        // Every voxel at most R − r from the centre survives; none beyond R − r + 1.
        if (dist <= R - r) {
          ASSERT_EQ(e->value(i, j, k), 1) << i << ' ' << j << ' ' << k;
        }
        if (dist > R - r + 1) {
          ASSERT_EQ(e->value(i, j, k), 0) << i << ' ' << j << ' ' << k;
        }
      }
}

TEST(VolumeFilters, OpeningAndClosingAreIdempotentAndOrdered) {
  const Volume m = randomMask({24, 22, 20}, 0.5, 11);
  for (auto se : {dm::StructuringElement::Ball, dm::StructuringElement::Cube}) {
    auto o1 = dm::opening(m, 2, se);
    ASSERT_TRUE(o1) << o1.error();
    auto o2 = dm::opening(*o1, 2, se);
    ASSERT_TRUE(o2) << o2.error();
    EXPECT_TRUE(sameMask(*o1, *o2));
    auto c1 = dm::closing(m, 2, se);
    ASSERT_TRUE(c1) << c1.error();
    auto c2 = dm::closing(*c1, 2, se);
    ASSERT_TRUE(c2) << c2.error();
    EXPECT_TRUE(sameMask(*c1, *c2));
    // opening ⊆ mask ⊆ closing, and neither is trivial here.
    std::size_t lost = 0, gained = 0;
    for (std::size_t n = 0; n < m.voxelCount(); ++n) {
      ASSERT_LE(o1->valueAt(n), m.valueAt(n));
      ASSERT_GE(c1->valueAt(n), m.valueAt(n));
      lost += m.valueAt(n) != o1->valueAt(n);
      gained += m.valueAt(n) != c1->valueAt(n);
    }
    EXPECT_GT(lost, 0u);
    EXPECT_GT(gained, 0u);
  }
}

TEST(VolumeFilters, MorphologyRejectsBadRadiiAndEmptyVolumes) {
  const Volume m = randomMask({4, 4, 4}, 0.5, 3);
  EXPECT_FALSE(dm::erode(m, -1));
  EXPECT_FALSE(dm::dilate(m, 5000));
  Volume empty;
  EXPECT_FALSE(dm::opening(empty, 1));
  EXPECT_FALSE(dm::closing(empty, 1));
  EXPECT_FALSE(dm::labelComponents(empty));
  EXPECT_FALSE(dm::threshold(empty, 0.0));
}

}  // namespace
