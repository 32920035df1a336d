// Lockstep replay of a device path: tick times, interpolated poses, finite
// difference velocities and the CSV written from them, checked with an
// analytic wall renderer (F = k · depth along +z below z = 0).
#include <dm/haptics/probe.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <sstream>
#include <string>

namespace dm {
namespace {

class WallRenderer final : public HapticRenderer {
 public:
  std::string_view name() const noexcept override { return "wall"; }
  void reset(const Isometry3&) noexcept override { resets++; }
  HapticResponse tick(const HapticInput& in) noexcept override {
    HapticResponse r;
    const Vec3 x = in.devicePose.translation();
    lastVelocity = in.linearVelocity;
    r.proxyPose = in.devicePose;
    if (x.z() < 0) {
      r.force = Vec3(0, 0, -k * x.z());
      r.proxyPose.translation().z() = 0;
      r.contacts = 1;
      r.penetration = -x.z();
    }
    return r;
  }
  std::size_t objectCount() const noexcept override { return 0; }
  void setObjectPose(std::size_t, const Isometry3&) noexcept override {}
  double k = 500.0;
  int resets = 0;
  Vec3 lastVelocity = Vec3::Zero();
};

TEST(Probe, ReplaysAPressAtTheTickRate) {
  // 10 mm above the wall down to 10 mm into it over 1 s, linearly.
  const auto path = parseDevicePathCsv("t,x,y,z\n0,0,0,0.01\n1,0,0,-0.01\n");
  ASSERT_TRUE(path.ok());
  WallRenderer wall;
  const auto samples = replayDevicePath(wall, *path, 1000.0);
  ASSERT_TRUE(samples.ok()) << samples.error().message();
  ASSERT_EQ(samples->size(), 1001u);
  EXPECT_EQ(wall.resets, 1);
  for (const ProbeSample& s : *samples) {
    const double z = 0.01 - 0.02 * s.t;
    EXPECT_NEAR(s.devicePose.translation().z(), z, 1e-12);
    EXPECT_NEAR(s.response.force.z(), z < 0 ? -500.0 * z : 0.0, 1e-9);
  }
  EXPECT_NEAR(samples->back().t, 1.0, 1e-12);
  EXPECT_NEAR(wall.lastVelocity.z(), -0.02, 1e-9);  // m/s, finite difference of the path

  const std::string csv = formatProbeCsv(*samples);
  std::istringstream lines(csv);
  std::string header, first;
  std::getline(lines, header);
  EXPECT_EQ(header, "t,fx,fy,fz,tx,ty,tz,px,py,pz,qw,qx,qy,qz,contacts,penetration");
  int rows = 0;
  for (std::string line; std::getline(lines, line);) ++rows;
  EXPECT_EQ(rows, 1001);
}

TEST(Probe, RefusesBadRatesAndHugeReplays) {
  const auto path = parseDevicePathCsv("0,0,0,0\n10,0,0,0\n");
  ASSERT_TRUE(path.ok());
  WallRenderer wall;
  EXPECT_FALSE(replayDevicePath(wall, *path, 0.0).ok());
  EXPECT_FALSE(replayDevicePath(wall, *path, std::nan("")).ok());
  const auto big = replayDevicePath(wall, *path, 1000.0, 5000);
  ASSERT_FALSE(big.ok());
  EXPECT_NE(big.error().what.find("exceed"), std::string::npos);
  EXPECT_FALSE(replayDevicePath(wall, DevicePath{}, 1000.0).ok());
}

}  // namespace
}  // namespace dm
