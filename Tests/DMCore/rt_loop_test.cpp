#include <dm/core/rt_loop.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <random>
#include <stdexcept>
#include <vector>

namespace {

// ---------------------------------------------------------------------------
// LatencyHistogram

// Scene time from ticks: a virtual clock from 0 and a monotonic clock from
// anywhere give the same seconds; a first tick seen late (index 2) still
// counts from the loop's start.
TEST(TickTime, SecondsSinceTheLoopStartedOnEitherClock) {
  for (std::int64_t start : {std::int64_t{0}, std::int64_t{17'245'959'421'937}}) {
    dm::TickTime time;
    const std::int64_t period = 1'000'000;
    EXPECT_DOUBLE_EQ(time.seconds({.index = 0, .scheduled_ns = start, .period_ns = period}), 0.0);
    EXPECT_NEAR(time.seconds({.index = 3, .scheduled_ns = start + 3 * period, .period_ns = period}), 0.003, 1e-12);
    // An overrun skipped periods: scheduled time, not the index, is the time.
    EXPECT_NEAR(time.seconds({.index = 4, .scheduled_ns = start + 9 * period, .period_ns = period}), 0.009, 1e-12);
    dm::TickTime late;
    EXPECT_NEAR(late.seconds({.index = 2, .scheduled_ns = start + 2 * period, .period_ns = period}), 0.002, 1e-12);
  }
}

TEST(LatencyHistogram, BucketsTileTheRangeWithBoundedWidth) {
  using H = dm::LatencyHistogram;
  EXPECT_EQ(H::bucketLowest(0), 0);
  for (std::size_t i = 0; i + 1 < H::kBucketCount; ++i) {
    ASSERT_EQ(H::bucketHighest(i) + 1, H::bucketLowest(i + 1)) << "gap or overlap after bucket " << i;
    const std::int64_t width = H::bucketHighest(i) - H::bucketLowest(i) + 1;
    if (i < 32) {
      ASSERT_EQ(width, 1);
    } else {
      ASSERT_LE(width * 32, H::bucketLowest(i)) << "bucket " << i << " wider than 1/32 of its value";
    }
  }
  EXPECT_EQ(H::bucketHighest(H::kBucketCount - 1), INT64_MAX);
  std::mt19937_64 rng(7);
  for (int k = 0; k < 10000; ++k) {
    const auto v = static_cast<std::int64_t>(rng() >> (rng() % 63 + 1));
    const std::size_t b = H::bucketIndex(v);
    ASSERT_LE(H::bucketLowest(b), v);
    ASSERT_GE(H::bucketHighest(b), v);
  }
  EXPECT_EQ(H::bucketIndex(-5), 0u);
}

TEST(LatencyHistogram, SmallValuesAreExact) {
  dm::LatencyHistogram h;
  for (int v = 1; v <= 9; ++v) h.record(v);
  EXPECT_EQ(h.count(), 9u);
  EXPECT_EQ(h.percentile(50), 5);
  EXPECT_EQ(h.percentile(0), 1);
  EXPECT_EQ(h.percentile(100), 9);
  EXPECT_EQ(h.min(), 1);
  EXPECT_EQ(h.max(), 9);
  EXPECT_DOUBLE_EQ(h.mean(), 5.0);
}

TEST(LatencyHistogram, UniformSamplesGivePercentilesWithinResolution) {
  // Samples 1..100000 ns. The q-quantile is q * 100000; the histogram
  // reports a bucket midpoint, within 1/64 of the true value.
  dm::LatencyHistogram h;
  for (std::int64_t v = 1; v <= 100'000; ++v) h.record(v);
  const double tol = 1.0 / 64.0;
  for (double p : {1.0, 10.0, 50.0, 90.0, 99.0, 99.9}) {
    const double expected = p / 100.0 * 100'000.0;
    EXPECT_NEAR(static_cast<double>(h.percentile(p)), expected, expected * tol) << "p" << p;
  }
  const auto s = h.summary();
  EXPECT_EQ(s.count, 100'000u);
  EXPECT_DOUBLE_EQ(s.mean_us, 50.0005);  // (1 + 100000) / 2 ns, exact
  EXPECT_DOUBLE_EQ(s.min_us, 0.001);
  EXPECT_DOUBLE_EQ(s.max_us, 100.0);
  EXPECT_NEAR(s.p50_us, 50.0, 50.0 * tol);
  EXPECT_NEAR(s.p99_us, 99.0, 99.0 * tol);
  EXPECT_NEAR(s.p999_us, 99.9, 99.9 * tol);
  EXPECT_LE(s.p50_us, s.p99_us);
  EXPECT_LE(s.p99_us, s.p999_us);
  EXPECT_LE(s.p999_us, s.max_us);
}

TEST(LatencyHistogram, TailPercentilesSeeOutliers) {
  // 990 samples at 1 us and 10 at 1 ms: p99 is still 1 us (the 990th
  // sample), p99.9 falls among the outliers.
  dm::LatencyHistogram h;
  for (int i = 0; i < 990; ++i) h.record(1000);
  for (int i = 0; i < 10; ++i) h.record(1'000'000);
  EXPECT_NEAR(static_cast<double>(h.percentile(99)), 1000.0, 1000.0 / 64);
  EXPECT_NEAR(static_cast<double>(h.percentile(99.9)), 1e6, 1e6 / 64);
  EXPECT_EQ(h.percentile(100), 1'000'000);
}

TEST(LatencyHistogram, EmptyAndReset) {
  dm::LatencyHistogram h;
  EXPECT_EQ(h.percentile(50), 0);
  EXPECT_EQ(h.summary().count, 0u);
  EXPECT_EQ(h.summary().max_us, 0.0);
  h.record(12345);
  h.record(-3);  // counted as 0
  EXPECT_EQ(h.min(), 0);
  h.reset();
  EXPECT_EQ(h.count(), 0u);
  EXPECT_EQ(h.max(), 0);
  EXPECT_EQ(h.min(), 0);
  h.record(777);
  EXPECT_EQ(h.min(), 777);
  EXPECT_EQ(h.max(), 777);
  EXPECT_EQ(h.percentile(50), 777) << "clamped to [min, max]";
}

// ---------------------------------------------------------------------------
// RealTimeLoop configuration

TEST(RealTimeLoop, PeriodFromRate) {
  EXPECT_EQ(dm::RealTimeLoop({.rate_hz = 1000}, [](const dm::TickInfo&) {}).periodNs(), 1'000'000);
  EXPECT_EQ(dm::RealTimeLoop({.rate_hz = 60}, [](const dm::TickInfo&) {}).periodNs(), 16'666'667);
  EXPECT_EQ(dm::RealTimeLoop({.rate_hz = 4000}, [](const dm::TickInfo&) {}).periodNs(), 250'000);
  EXPECT_EQ(dm::RealTimeLoop({}, [](const dm::TickInfo&) {}).config().rate_hz, 1000.0);
}

TEST(RealTimeLoop, InvalidConfigurationsAreReportedNotFatal) {
  const auto check = [](dm::RealTimeLoopConfig c, const char* field) {
    dm::RealTimeLoop loop(c, [](const dm::TickInfo&) {});
    const dm::Status s = loop.start();
    ASSERT_FALSE(s) << field;
    EXPECT_EQ(s.error().code, dm::ErrorCode::InvalidArgument);
    EXPECT_NE(s.error().where.find(field), std::string::npos) << s.error().message();
    EXPECT_FALSE(s.error().hint.empty());
    EXPECT_FALSE(loop.running());
    dm::VirtualClock clock;
    EXPECT_FALSE(loop.runLockstep(clock, 1));
    EXPECT_EQ(clock.now(), 0);
  };
  check({.rate_hz = 0}, "rate_hz");
  check({.rate_hz = -5}, "rate_hz");
  check({.rate_hz = std::nan("")}, "rate_hz");
  check({.rate_hz = 1e9}, "rate_hz");
  check({.priority = 1000}, "priority");
  check({.priority = -1}, "priority");
  check({.cpu = -2}, "cpu");
  check({.cpu = 1 << 20}, "cpu");
  check({.rate_hz = 1000, .spin_ns = 2'000'000}, "spin_ns");
  check({.spin_ns = -1}, "spin_ns");
  EXPECT_TRUE(dm::RealTimeLoop::validate({}));
}

TEST(RealTimeLoop, StopWithoutStartIsANoOp) {
  dm::RealTimeLoop loop({}, [](const dm::TickInfo&) {});
  loop.stop();
  loop.stop();
  EXPECT_FALSE(loop.running());
  EXPECT_EQ(loop.stats().ticks, 0u);
}

// ---------------------------------------------------------------------------
// Lockstep

TEST(RealTimeLoop, LockstepAdvancesClockExactlyAndTicksNTimes) {
  std::vector<dm::TickInfo> seen;
  dm::RealTimeLoop loop({.rate_hz = 1000}, [&](const dm::TickInfo& t) { seen.push_back(t); });
  const std::int64_t t0 = 5'000;
  dm::VirtualClock clock(t0);
  ASSERT_TRUE(loop.runLockstep(clock, 250));
  ASSERT_TRUE(loop.stepOnce(clock));
  const std::uint64_t n = 251;
  EXPECT_EQ(clock.now(), t0 + static_cast<std::int64_t>(n) * 1'000'000);
  ASSERT_EQ(seen.size(), n);
  for (std::uint64_t k = 0; k < n; ++k) {
    EXPECT_EQ(seen[k].index, k);
    EXPECT_EQ(seen[k].scheduled_ns, t0 + static_cast<std::int64_t>(k) * 1'000'000);
    EXPECT_EQ(seen[k].start_ns, seen[k].scheduled_ns);
    EXPECT_EQ(seen[k].period_ns, 1'000'000);
    EXPECT_EQ(seen[k].skipped, 0u);
    EXPECT_DOUBLE_EQ(seen[k].dt(), 1e-3);
  }
  const dm::RealTimeLoopStats s = loop.stats();
  EXPECT_EQ(s.ticks, n);
  EXPECT_EQ(s.deadline_misses, 0u);
  EXPECT_EQ(s.skipped_periods, 0u);
  EXPECT_EQ(s.execution.count, n);
  EXPECT_EQ(s.wakeup.max_us, 0.0) << "virtual ticks start exactly on time";
  EXPECT_FALSE(s.running);
}

// A damped, driven pendulum integrated by the tick function: nonlinear, so
// any difference in tick order, time or step size shows in the bits.
struct Pendulum {
  double theta = 1.0, omega = 0.0;
  std::vector<double> trace;
  void tick(const dm::TickInfo& t) {
    const double time = dm::nanosToSeconds(t.scheduled_ns);
    const double alpha = -9.81 * std::sin(theta) - 0.3 * omega + 0.5 * std::cos(2.0 * time);
    omega += alpha * t.dt();  // semi-implicit Euler
    theta += omega * t.dt();
    trace.push_back(theta);
  }
};

std::vector<double> runPendulumLockstep(std::uint64_t n) {
  Pendulum p;
  dm::RealTimeLoop loop({.rate_hz = 1000, .name = "pendulum"}, [&p](const dm::TickInfo& t) { p.tick(t); });
  dm::VirtualClock clock;
  EXPECT_TRUE(loop.runLockstep(clock, n));
  return p.trace;
}

TEST(RealTimeLoop, LockstepRunsAreBitIdentical) {
  const std::uint64_t n = 3000;
  const std::vector<double> a = runPendulumLockstep(n);
  const std::vector<double> b = runPendulumLockstep(n);
  ASSERT_EQ(a.size(), n);
  ASSERT_EQ(b.size(), n);
  EXPECT_EQ(std::memcmp(a.data(), b.data(), n * sizeof(double)), 0);
  // The same code called directly gives the same bits: lockstep adds nothing.
  Pendulum direct;
  for (std::uint64_t k = 0; k < n; ++k) {
    dm::TickInfo t;
    t.index = k;
    t.scheduled_ns = t.start_ns = static_cast<std::int64_t>(k) * 1'000'000;
    t.period_ns = 1'000'000;
    direct.tick(t);
  }
  EXPECT_EQ(std::memcmp(a.data(), direct.trace.data(), n * sizeof(double)), 0);
  // And the pendulum really moved (the test can fail): the small-angle
  // period is 2*pi/sqrt(9.81) ~ 2 s, so in 3 s theta crossed zero.
  EXPECT_LT(*std::min_element(a.begin(), a.end()), 0.0);
}

TEST(RealTimeLoop, LockstepTickThatAdvancesTheClockPastTheDeadlineIsAMiss) {
  dm::VirtualClock clock;
  dm::RealTimeLoop loop({.rate_hz = 100}, [&clock](const dm::TickInfo& t) {
    if (t.index % 4 == 3) clock.advance(20'000'000);  // 2 periods of "work"
  });
  ASSERT_TRUE(loop.runLockstep(clock, 8));
  const auto s = loop.stats();
  EXPECT_EQ(s.ticks, 8u);
  EXPECT_EQ(s.deadline_misses, 2u);
  EXPECT_DOUBLE_EQ(s.execution.max_us, 20'000.0);
  EXPECT_EQ(clock.now(), 8 * 10'000'000 + 2 * 20'000'000);
}

TEST(RealTimeLoop, LockstepReportsAThrowingTick) {
  int calls = 0;
  dm::RealTimeLoop loop({.name = "thrower"}, [&calls](const dm::TickInfo& t) {
    ++calls;
    if (t.index == 2) throw std::runtime_error("sensor exploded");
  });
  dm::VirtualClock clock;
  const dm::Status s = loop.runLockstep(clock, 10);
  ASSERT_FALSE(s);
  EXPECT_EQ(calls, 3);
  EXPECT_NE(s.error().what.find("sensor exploded"), std::string::npos);
  EXPECT_NE(s.error().where.find("tick 2"), std::string::npos);
  EXPECT_TRUE(loop.stats().tick_threw);
  EXPECT_EQ(clock.now(), 2 * 1'000'000) << "the throwing tick does not advance the clock";
}

TEST(RealTimeLoop, LockstepFromInsideATickIsRefused) {
  dm::VirtualClock inner;
  dm::Status nested = dm::ok();
  dm::RealTimeLoop* self = nullptr;
  dm::RealTimeLoop loop({}, [&](const dm::TickInfo&) { nested = self->runLockstep(inner, 1); });
  self = &loop;
  dm::VirtualClock clock;
  ASSERT_TRUE(loop.runLockstep(clock, 1));
  ASSERT_FALSE(nested);
  EXPECT_EQ(nested.error().code, dm::ErrorCode::Busy);
}

}  // namespace
