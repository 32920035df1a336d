// The calvarium phantom against its geometry: the exact cube–plane partial
// volume against a fine midpoint integration and closed forms, each column's
// bone (by CT's partial-volume law) against the analytic chord through the
// curved shell, each layer's value where a voxel lies wholly in it, the
// diploë's texture, determinism and named option errors.
#include <dm/math/phantom.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <random>
#include <vector>

namespace phantom_test {

using dm::Vec3;

// Midpoint integration of the fraction of the cube below the plane.
double gridFraction(const Vec3& centre, double h, const Vec3& n, double offset, int samples) {
  int below = 0;
  for (int k = 0; k < samples; ++k)
    for (int j = 0; j < samples; ++j)
      for (int i = 0; i < samples; ++i) {
        const Vec3 p = centre + h * (Vec3(i + 0.5, j + 0.5, k + 0.5) / samples - Vec3::Constant(0.5));
        below += n.dot(p) < offset;
      }
  return double(below) / (double(samples) * samples * samples);
}

TEST(PhantomPartialVolume, AxisAlignedPlanesCutTheCubeLinearly) {
  const Vec3 c(0.3, -0.2, 0.1);
  const double h = 0.5;
  for (double t : {-0.3, -0.25, -0.1, 0.0, 0.07, 0.25, 0.4}) {
    const double want = std::clamp(t / h + 0.5, 0.0, 1.0);
    EXPECT_NEAR(dm::cubeFractionBelowPlane(c, h, Vec3::UnitZ(), c.z() + t), want, 1e-9) << t;
    EXPECT_NEAR(dm::cubeFractionBelowPlane(c, h, -Vec3::UnitX(), -c.x() + t), want, 1e-9) << t;
  }
}

TEST(PhantomPartialVolume, ADiagonalPlaneCutsOffACornerTetrahedron) {
  // x + y + z < t in the unit cube [0,1]³ (centre ½): volume t³/6 for t ≤ 1,
  // a half through the centre.
  const Vec3 n = Vec3::Ones().normalized();
  const Vec3 c = Vec3::Constant(0.5);
  for (double t : {0.2, 0.5, 0.9, 1.0})
    EXPECT_NEAR(dm::cubeFractionBelowPlane(c, 1.0, n, t / std::sqrt(3.0)), t * t * t / 6.0, 1e-12) << t;
  EXPECT_NEAR(dm::cubeFractionBelowPlane(c, 1.0, n, 1.5 / std::sqrt(3.0)), 0.5, 1e-12);
  EXPECT_NEAR(dm::cubeFractionBelowPlane(c, 1.0, n, 2.5 / std::sqrt(3.0)), 1.0 - 0.125 / 6.0, 1e-12);
}

TEST(PhantomPartialVolume, AnyPlaneMatchesAFineIntegration) {
  std::mt19937 rng(7);
  std::normal_distribution<double> g;
  std::uniform_real_distribution<double> u(-0.9, 0.9);
  const double h = 2.0;
  const int samples = 96;  // midpoint rule: error well below 1/samples for a plane
  for (int trial = 0; trial < 24; ++trial) {
    Vec3 n(g(rng), g(rng), g(rng));
    if (trial % 4 == 0) n.z() = 0.0;  // planes parallel to an axis (the small-component floor)
    n.normalize();
    const Vec3 c(u(rng), u(rng), u(rng));
    const double offset = n.dot(c) + u(rng) * h;
    const double exact = dm::cubeFractionBelowPlane(c, h, n, offset);
    EXPECT_NEAR(exact, gridFraction(c, h, n, offset, samples), 2.0 / samples) << trial;
    // Complement: the other side of the plane holds the rest.
    EXPECT_NEAR(exact + dm::cubeFractionBelowPlane(c, h, -n, -offset), 1.0, 1e-9) << trial;
  }
}

// Every column's bone, summed by the partial-volume law, is the vertical
// chord through the curved shell of outer radius R and inner radius R − t
// at the column's centre (the shell's curvature changes the column mean by
// about h²/(12·R): nanometres).
TEST(CalvariumPhantom, EachColumnsBoneIsTheChordThroughTheCurvedShell) {
  dm::CalvariumPhantom p;
  p.spacing = 0.4e-3;
  p.halfWidth = 0.016;
  p.below = 0.012;
  p.scalp = 0.0;
  p.airHu = p.softTissueHu = p.duraHu = p.brainHu = 0.0;
  p.corticalHu = p.diploeHu = 10000.0;  // 1e-4 quantization of each voxel's fraction
  p.textureHu = 0.0;
  auto ct = dm::makeCalvariumPhantom(p);
  ASSERT_TRUE(ct) << ct.error().message();
  const dm::Vec3i n = ct->dims();
  EXPECT_EQ(n, dm::Vec3i(80, 80, 50));
  const double h = p.spacing;
  const double outer = p.radius, inner = p.radius - p.outerTable - p.diploe - p.innerTable;
  int columns = 0;
  double worst = 0.0;
  for (int j = 0; j < n.y(); ++j)
    for (int i = 0; i < n.x(); ++i) {
      const Vec3 x = ct->indexToWorld() * Vec3(i, j, 0);
      const double rho2 = x.x() * x.x() + x.y() * x.y();
      if (rho2 > 0.015 * 0.015) continue;
      double bone = 0.0;
      for (int k = 0; k < n.z(); ++k) bone += ct->value(i, j, k) / 10000.0 * h;
      const double chord = std::sqrt(outer * outer - rho2) - std::sqrt(inner * inner - rho2);
      worst = std::max(worst, std::abs(bone - chord));
      ++columns;
    }
  EXPECT_GT(columns, 4000);
  EXPECT_LT(worst, 4e-7) << "m, over " << columns << " columns";  // a thousandth of a voxel (measured 6e-8)
}

TEST(CalvariumPhantom, AVoxelWhollyInALayerHasThatLayersValue) {
  const dm::CalvariumPhantom p;  // defaults: 0.3 mm voxels
  auto ct = dm::makeCalvariumPhantom(p);
  ASSERT_TRUE(ct) << ct.error().message();
  const dm::Vec3i n = ct->dims();
  EXPECT_EQ(n, dm::Vec3i(133, 133, 60));
  // Along the axis and at the patch's corner (where the vault lies lower):
  // every voxel whose half diagonal fits in one layer holds its value.
  const double h = p.spacing, reach = std::sqrt(3.0) / 2.0 * h;
  const double r1 = p.radius, r2 = r1 - p.outerTable, r3 = r2 - p.diploe, r4 = r3 - p.innerTable,
               r5 = r4 - p.dura, r0 = r1 + p.scalp;
  const Vec3 c(0, 0, -p.radius);
  int checked[7] = {};
  for (int corner = 0; corner < 2; ++corner) {
    const int i = corner == 0 ? n.x() / 2 : 1, j = corner == 0 ? n.y() / 2 : 1;
    for (int k = 0; k < n.z(); ++k) {
      const Vec3 x = ct->indexToWorld() * Vec3(i, j, k);
      const double r = (x - c).norm();
      const double value = ct->value(i, j, k);
      auto within = [&](double lo, double hi) { return r - reach > lo && r + reach < hi; };
      if (within(r0, 1.0)) {
        EXPECT_EQ(value, p.airHu) << k;
        ++checked[0];
      } else if (within(r1, r0)) {
        EXPECT_EQ(value, p.softTissueHu) << k;
        ++checked[1];
      } else if (within(r2, r1) || within(r4, r3)) {
        EXPECT_EQ(value, p.corticalHu) << k;
        ++checked[2];
      } else if (within(r3, r2)) {
        EXPECT_LE(std::abs(value - p.diploeHu), p.textureHu + 0.5) << k;
        ++checked[3];
      } else if (within(0.0, r5)) {
        EXPECT_EQ(value, p.brainHu) << k;
        ++checked[4];
      }
    }
  }
  EXPECT_GT(checked[0], 0);
  EXPECT_GT(checked[1], 10);
  EXPECT_GE(checked[2], 4);
  EXPECT_GE(checked[3], 10);
  EXPECT_GT(checked[4], 0);
}

TEST(CalvariumPhantom, TheDiploesTextureVariesAboutItsMeanWithinItsAmplitude) {
  dm::CalvariumPhantom p;
  p.halfWidth = 0.01;
  auto ct = dm::makeCalvariumPhantom(p);
  ASSERT_TRUE(ct) << ct.error().message();
  const double h = p.spacing, reach = std::sqrt(3.0) / 2.0 * h;
  const double r2 = p.radius - p.outerTable, r3 = r2 - p.diploe;
  const Vec3 c(0, 0, -p.radius);
  double sum = 0.0, sum2 = 0.0;
  int count = 0;
  for (int k = 0; k < ct->dims().z(); ++k)
    for (int j = 0; j < ct->dims().y(); ++j)
      for (int i = 0; i < ct->dims().x(); ++i) {
        const double r = (ct->indexToWorld() * Vec3(i, j, k) - c).norm();
        if (!(r - reach > r3 && r + reach < r2)) continue;
        const double v = ct->value(i, j, k);
        EXPECT_LE(std::abs(v - p.diploeHu), p.textureHu + 0.5);
        sum += v;
        sum2 += v * v;
        ++count;
      }
  ASSERT_GT(count, 10000);
  const double mean = sum / count, sd = std::sqrt(sum2 / count - mean * mean);
  EXPECT_NEAR(mean, p.diploeHu, 0.2 * p.textureHu);
  EXPECT_GT(sd, 0.15 * p.textureHu);  // textured, not flat
  EXPECT_LT(sd, 0.6 * p.textureHu);
}

TEST(CalvariumPhantom, TheSameOptionsGiveTheSameScanAndTheSeedChangesTheTexture) {
  dm::CalvariumPhantom p;
  p.halfWidth = 0.004;
  auto a = dm::makeCalvariumPhantom(p), b = dm::makeCalvariumPhantom(p);
  ASSERT_TRUE(a && b);
  ASSERT_EQ(a->byteSize(), b->byteSize());
  EXPECT_EQ(std::memcmp(a->bytes(), b->bytes(), a->byteSize()), 0);
  p.seed = 2;
  auto c = dm::makeCalvariumPhantom(p);
  ASSERT_TRUE(c);
  EXPECT_NE(std::memcmp(a->bytes(), c->bytes(), a->byteSize()), 0);
}

TEST(CalvariumPhantom, BadOptionsAreNamed) {
  struct Case {
    const char* field;
    void (*set)(dm::CalvariumPhantom&);
  };
  const Case cases[] = {
      {"spacing", [](dm::CalvariumPhantom& p) { p.spacing = 0.0; }},
      {"spacing", [](dm::CalvariumPhantom& p) { p.spacing = 0.05; }},
      {"radius", [](dm::CalvariumPhantom& p) { p.radius = 0.01; }},
      {"radius",
       [](dm::CalvariumPhantom& p) {
         p.halfWidth = 0.001;
         p.radius = 0.006;
       }},
      {"diploe", [](dm::CalvariumPhantom& p) { p.diploe = -0.001; }},
      {"outerTable", [](dm::CalvariumPhantom& p) { p.outerTable = 0.0; }},
      {"corticalHu", [](dm::CalvariumPhantom& p) { p.corticalHu = std::nan(""); }},
      {"textureScale", [](dm::CalvariumPhantom& p) { p.textureScale = INFINITY; }},
      {"textureScale", [](dm::CalvariumPhantom& p) { p.textureScale = 1e-300; }},
  };
  for (const Case& c : cases) {
    dm::CalvariumPhantom p;
    c.set(p);
    auto v = dm::makeCalvariumPhantom(p);
    ASSERT_FALSE(v) << c.field;
    EXPECT_EQ(v.error().where, c.field) << v.error().message();
  }
  // A grid larger than the caller allows is refused, not allocated.
  auto big = dm::makeCalvariumPhantom(dm::CalvariumPhantom{}, 1024);
  ASSERT_FALSE(big);
  EXPECT_NE(big.error().where.find("phantom"), std::string::npos);
}

}  // namespace phantom_test
