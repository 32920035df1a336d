#include <dm/core/pose.hpp>

#include <gtest/gtest.h>

#include <random>

namespace {

dm::Pose randomPose(std::mt19937& rng) {
  std::uniform_real_distribution<double> u(-1, 1);
  return {dm::Vec3(u(rng), u(rng), u(rng)), dm::Quat(u(rng), u(rng), u(rng), u(rng)).normalized()};
}

TEST(Pose, MatchesIsometryAlgebra) {
  std::mt19937 rng(7);
  for (int n = 0; n < 100; ++n) {
    const dm::Pose a = randomPose(rng), b = randomPose(rng);
    const dm::Vec3 x(0.3, -0.2, 0.9);
    EXPECT_TRUE(((a * b) * x).isApprox(a.isometry() * (b.isometry() * x), 1e-12));
    EXPECT_TRUE((a.inverse() * (a * x)).isApprox(x, 1e-12));
    EXPECT_TRUE(dm::Pose(a.isometry()).isometry().isApprox(a.isometry(), 1e-12));
  }
}

TEST(Pose, InterpolationEndsAndMidpoint) {
  const dm::Pose a({0, 0, 0}, dm::Quat::Identity());
  const dm::Pose b({2, 0, 0}, dm::Quat(dm::AngleAxis(M_PI / 2, dm::Vec3::UnitZ())));
  const dm::Pose m = dm::Pose::interpolate(a, b, 0.5);
  EXPECT_TRUE(m.p.isApprox(dm::Vec3(1, 0, 0)));
  EXPECT_NEAR(dm::AngleAxis(m.q).angle(), M_PI / 4, 1e-12);
  EXPECT_TRUE(dm::Pose::interpolate(a, b, 1.0).q.isApprox(b.q));
}

}  // namespace
