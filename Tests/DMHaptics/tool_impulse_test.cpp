// ToolImpulseChannel: the haptic thread's impulses reach the physics thread
// as running totals, so however many ticks fall between two physics steps
// the body gets exactly the momentum the hand gave away.
#include <dm/haptics/tool_impulse.hpp>

#include <gtest/gtest.h>

#include <array>
#include <limits>

namespace {

using dm::ToolImpulse;
using dm::Vec3;

}  // namespace

TEST(ToolImpulseChannel, ImpulseSinceTheLastTakeWithItsMomentAboutTheOrigin) {
  dm::ToolImpulseChannel c(2);
  std::array<ToolImpulse, 2> out;
  EXPECT_FALSE(c.take(out));  // nothing published yet
  EXPECT_EQ(out[0].linear, Vec3::Zero());

  // Three haptic ticks of 1 ms on object 1 before one physics step.
  for (int i = 0; i < 3; ++i) {
    c.add(1, Vec3(2, 0, 0), Vec3(0, 0.5, 0), 1e-3);
    c.publish();
  }
  ASSERT_TRUE(c.take(out));
  EXPECT_EQ(out[0].linear, Vec3::Zero());
  EXPECT_NEAR(out[1].linear.x(), 6e-3, 1e-18);
  // p × F dt summed: (0, 0.5, 0) × (2, 0, 0) = (0, 0, −1), times 3 ms.
  EXPECT_NEAR(out[1].angular.z(), -3e-3, 1e-18);
  EXPECT_FALSE(c.take(out));  // nothing new: zeros
  EXPECT_EQ(out[1].linear, Vec3::Zero());

  c.add(0, Vec3(0, 0, -1), Vec3(1, 0, 0), 2e-3);
  c.publish();
  ASSERT_TRUE(c.take(out));
  EXPECT_NEAR(out[0].linear.z(), -2e-3, 1e-18);
  EXPECT_NEAR(out[0].angular.y(), 2e-3, 1e-18);  // (1,0,0) × (0,0,−1) = (0, 1, 0)
  EXPECT_EQ(out[1].linear, Vec3::Zero());
  EXPECT_NEAR(c.taken(1).linear.x(), 6e-3, 1e-18);
  EXPECT_EQ(c.taken(7).linear, Vec3::Zero());
}

TEST(ToolImpulseChannel, BadSamplesNeverReachABody) {
  dm::ToolImpulseChannel c(1);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  c.add(0, Vec3(nan, 0, 0), Vec3::Zero(), 1e-3);
  c.add(0, Vec3(1, 0, 0), Vec3(0, std::numeric_limits<double>::infinity(), 0), 1e-3);
  c.add(0, Vec3(1, 0, 0), Vec3::Zero(), -1e-3);
  c.add(0, Vec3(1, 0, 0), Vec3::Zero(), nan);
  c.add(3, Vec3(1, 0, 0), Vec3::Zero(), 1e-3);  // no such object
  c.publish();
  std::array<ToolImpulse, 1> out;
  ASSERT_TRUE(c.take(out));
  EXPECT_EQ(out[0].linear, Vec3::Zero());
  EXPECT_EQ(out[0].angular, Vec3::Zero());
}
