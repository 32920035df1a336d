#include <dm/math/pca.hpp>

#include <gtest/gtest.h>

#include <random>
#include <vector>

namespace {

TEST(Pca, RecoversAxesOfAnisotropicGaussian) {
  // Samples with standard deviations 3, 2, 0.5 along a rotated frame.
  const dm::Mat3 R = dm::AngleAxis(0.7, dm::Vec3(1, 2, 3).normalized()).toRotationMatrix();
  std::mt19937 rng(42);
  std::normal_distribution<double> n(0.0, 1.0);
  std::vector<dm::Vec3> pts;
  for (int i = 0; i < 20000; ++i)
    pts.push_back(dm::Vec3(1, -2, 0.5) + R * dm::Vec3(3 * n(rng), 2 * n(rng), 0.5 * n(rng)));
  auto p = dm::pca(pts);
  ASSERT_TRUE(p);
  EXPECT_NEAR(p->variances[0], 9.0, 0.3);
  EXPECT_NEAR(p->variances[1], 4.0, 0.15);
  EXPECT_NEAR(p->variances[2], 0.25, 0.01);
  for (int k = 0; k < 3; ++k) EXPECT_GT(std::abs(p->axes.col(k).dot(R.col(k))), 0.995);
  EXPECT_NEAR(p->axes.determinant(), 1.0, 1e-9);
  EXPECT_LT((p->mean - dm::Vec3(1, -2, 0.5)).norm(), 0.06);
}

TEST(Pca, RejectsEmptyAndNonFinite) {
  EXPECT_FALSE(dm::pca(std::vector<dm::Vec3>{}));
  std::vector<dm::Vec3> bad{dm::Vec3(0, 0, 0), dm::Vec3(std::nan(""), 0, 0)};
  auto r = dm::pca(bad);
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().what.find("NaN"), std::string::npos);
}

}  // namespace
