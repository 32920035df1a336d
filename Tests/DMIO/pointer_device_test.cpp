// The "pointer" driver, a kinematic stand-in moved by the program: a
// position set on its channel is the device's, clamped to its workspace
// cube; its velocity is the difference of two reads over the host's time;
// a non-finite input leaves it where it was; the force the host sent
// (clamped to its max_force) is read back from the channel; two channels
// are two devices; bad parameters are refused naming them.
#include <dm/io/haptic_device.hpp>
#include <dm/io/pointer_device.hpp>

#include <gtest/gtest.h>

#include <limits>

#include "driver_test_support.hpp"

namespace pointer_device_test {

using dm::Vec3;
using dm::test::kMs;

struct PointerTest : ::testing::Test {
  dm::test::BuiltinDrivers drivers;
  std::unique_ptr<dm::HapticDevice> open(const dm::DeviceParams& params) {
    auto d = dm::HapticDevice::open(drivers.registry, "pointer", params);
    EXPECT_TRUE(d.ok()) << (d.ok() ? "" : d.error().message());
    return d.ok() ? std::move(*d) : nullptr;
  }
};

TEST_F(PointerTest, FollowsItsChannelWithinItsWorkspace) {
  dm::PointerChannel& ch = dm::pointerChannel("pointer-test-a");
  ch.set(Vec3::Zero(), 0);
  auto dev = open({{"channel", "pointer-test-a"}, {"workspace", "0.05"}});
  ASSERT_TRUE(dev);
  EXPECT_EQ(dev->info().serial, "pointer-test-a");
  EXPECT_TRUE(dev->info().workspace.max().isApprox(Vec3::Constant(0.05)));
  ASSERT_EQ(dev->servo(10 * kMs), dm::DeviceStatus::Ok);
  ch.set(Vec3(0.01, -0.02, 0.03), 0b11);
  ASSERT_EQ(dev->servo(12 * kMs), dm::DeviceStatus::Ok);
  EXPECT_EQ(dev->state().position, Vec3(0.01, -0.02, 0.03));
  EXPECT_TRUE(dev->state().linearVelocity.isApprox(Vec3(5.0, -10.0, 15.0), 1e-12));  // over 2 ms
  EXPECT_EQ(dev->state().buttons, 0b11u);
  ch.set(Vec3(0.2, -0.3, 0.01), 0);  // outside: clamped to the cube
  ASSERT_EQ(dev->servo(13 * kMs), dm::DeviceStatus::Ok);
  EXPECT_EQ(dev->state().position, Vec3(0.05, -0.05, 0.01));
  ch.set(Vec3(std::numeric_limits<double>::quiet_NaN(), 0, 0), 0);
  ASSERT_EQ(dev->servo(14 * kMs), dm::DeviceStatus::Ok);
  EXPECT_EQ(dev->state().position, Vec3(0.05, -0.05, 0.01));
  EXPECT_EQ(dev->state().linearVelocity, Vec3::Zero());
}

TEST_F(PointerTest, TheForceSentIsReadBackClampedAndChannelsAreSeparate) {
  auto a = open({{"channel", "pointer-test-b"}, {"max_force", "2"}});
  auto b = open({{"channel", "pointer-test-c"}});
  ASSERT_TRUE(a && b);
  dm::pointerChannel("pointer-test-b").set(Vec3(0.01, 0, 0), 0);
  dm::pointerChannel("pointer-test-c").set(Vec3(-0.01, 0, 0), 0);
  a->command(Vec3(0.0, 3.0, 4.0), Vec3::Zero(), kMs);
  b->command(Vec3(1.0, 0.0, 0.0), Vec3::Zero(), kMs);
  ASSERT_EQ(a->servo(kMs), dm::DeviceStatus::Ok);
  ASSERT_EQ(b->servo(kMs), dm::DeviceStatus::Ok);
  EXPECT_TRUE(dm::pointerChannel("pointer-test-b").force().isApprox(Vec3(0.0, 1.2, 1.6), 1e-15));
  EXPECT_EQ(dm::pointerChannel("pointer-test-c").force(), Vec3(1.0, 0.0, 0.0));
  EXPECT_EQ(a->state().position.x(), 0.01);
  EXPECT_EQ(b->state().position.x(), -0.01);
}

TEST_F(PointerTest, BadParametersAreRefusedNamingThem) {
  for (const auto& [key, value] :
       dm::DeviceParams{{"workspace", "0"}, {"max_force", "-1"}, {"channel", ""}, {"size", "3"}}) {
    auto d = dm::HapticDevice::open(drivers.registry, "pointer", {{key, value}});
    ASSERT_FALSE(d.ok()) << key;
    EXPECT_NE(d.error().message().find("'" + key + "'"), std::string::npos) << d.error().message();
  }
}

}  // namespace pointer_device_test
