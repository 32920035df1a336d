#include <dm/core/clock.hpp>

#include <gtest/gtest.h>

#include <chrono>
#include <cstdint>
#include <limits>
#include <thread>

namespace {

TEST(Clock, SecondsNanosConversions) {
  EXPECT_EQ(dm::secondsToNanos(1.0), dm::kNanosPerSecond);
  EXPECT_EQ(dm::secondsToNanos(1e-3), 1'000'000);
  EXPECT_EQ(dm::secondsToNanos(1.0 / 60.0), 16'666'667);  // rounded to nearest
  EXPECT_EQ(dm::secondsToNanos(-2.5e-9), -3);             // rounds half away from zero
  EXPECT_EQ(dm::secondsToNanos(0.0), 0);
  EXPECT_EQ(dm::secondsToNanos(std::numeric_limits<double>::quiet_NaN()), 0);
  EXPECT_EQ(dm::secondsToNanos(1e300), std::numeric_limits<std::int64_t>::max());
  EXPECT_EQ(dm::secondsToNanos(-1e300), std::numeric_limits<std::int64_t>::min());
  EXPECT_DOUBLE_EQ(dm::nanosToSeconds(1'500'000'000), 1.5);
  static_assert(dm::secondsToNanos(2.0) == 2 * dm::kNanosPerSecond, "usable in constant expressions");
}

TEST(Clock, RealClockIsMonotonicAndAdvancesAcrossSleep) {
  dm::RealClock clock;
  std::int64_t prev = clock.now();
  for (int i = 0; i < 10000; ++i) {
    const std::int64_t t = clock.now();
    ASSERT_GE(t, prev);
    prev = t;
  }
  const std::int64_t before = clock.now();
  std::this_thread::sleep_for(std::chrono::milliseconds(2));
  // sleep_for sleeps at least the requested time on the steady clock.
  EXPECT_GE(clock.now() - before, 2'000'000);
}

TEST(Clock, RealClockMatchesSteadyClock) {
  dm::RealClock clock;
  const auto a = std::chrono::duration_cast<std::chrono::nanoseconds>(
                     std::chrono::steady_clock::now().time_since_epoch())
                     .count();
  const std::int64_t t = clock.now();
  const auto b = std::chrono::duration_cast<std::chrono::nanoseconds>(
                     std::chrono::steady_clock::now().time_since_epoch())
                     .count();
  EXPECT_LE(a, t);
  EXPECT_LE(t, b);
}

TEST(Clock, VirtualClockMovesOnlyWhenTold) {
  dm::VirtualClock clock(123);
  EXPECT_EQ(clock.now(), 123);
  EXPECT_EQ(clock.now(), 123);
  clock.advance(1'000'000);
  EXPECT_EQ(clock.now(), 1'000'123);
  clock.advanceSeconds(0.5);
  EXPECT_EQ(clock.now(), 500'000'000 + 1'000'123);
  clock.set(7);
  EXPECT_EQ(clock.now(), 7);
  EXPECT_DOUBLE_EQ(clock.nowSeconds(), 7e-9);
}

TEST(Clock, VirtualClockIsExactOverManySteps) {
  // 1e6 steps of 1 kHz add up to exactly 1000 s: integer time does not drift.
  dm::VirtualClock clock;
  const std::int64_t period = dm::secondsToNanos(1.0 / 1000.0);
  for (int i = 0; i < 1'000'000; ++i) clock.advance(period);
  EXPECT_EQ(clock.now(), 1000 * dm::kNanosPerSecond);
  // ... whereas summing the period in double seconds does drift.
  double t = 0.0;
  for (int i = 0; i < 1'000'000; ++i) t += 1e-3;
  EXPECT_NE(t, 1000.0);
}

TEST(Clock, UsableThroughTheBaseClass) {
  dm::VirtualClock vc(42);
  const dm::Clock& c = vc;
  EXPECT_EQ(c.now(), 42);
  dm::VirtualClock copy = vc;
  vc.advance(8);
  EXPECT_EQ(copy.now(), 42);
  copy = vc;
  EXPECT_EQ(copy.now(), 50);
}

}  // namespace
