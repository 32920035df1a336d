#include <dm/core/log.hpp>
#include <dm/core/rt_loop.hpp>

#include <gtest/gtest.h>

#include <sched.h>

#include <atomic>
#include <chrono>
#include <cstdint>
#include <cstdlib>
#include <mutex>
#include <new>
#include <string>
#include <thread>
#include <vector>

#include "../common/eventually.hpp"

// Allocation counting for one thread: the loop thread marks itself, and
// every operator new on a marked thread is counted.
#include "../common/alloc_counter.hpp"

namespace {

using namespace std::chrono_literals;

std::int64_t steadyNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

// Polls `cond` for up to `timeout` (generous: the machine may be loaded and
// this may run under ThreadSanitizer). No timing is asserted.
template <class F>
bool waitFor(F cond) {
  return dm::test::eventually(cond, std::chrono::seconds(10));
}

void expectMonotone(const dm::LatencyHistogram::Summary& s, std::uint64_t count) {
  EXPECT_EQ(s.count, count);
  EXPECT_LE(s.min_us, s.p50_us);
  EXPECT_LE(s.p50_us, s.p99_us);
  EXPECT_LE(s.p99_us, s.p999_us);
  EXPECT_LE(s.p999_us, s.max_us);
  EXPECT_LE(s.mean_us, s.max_us);
  EXPECT_GE(s.mean_us, s.min_us);
}

TEST(RealTimeLoopConcurrency, TicksAtRateAndStopsFromAnotherThread) {
  struct Seen {
    std::atomic<std::uint64_t> ticks{0};
    std::atomic<std::uint64_t> badSchedule{0};
    std::atomic<std::uint64_t> skippedSum{0};
    std::int64_t firstScheduled = 0;  // loop thread only
  } seen;
  dm::RealTimeLoop loop({.rate_hz = 1000, .name = "test-1khz"}, [&seen](const dm::TickInfo& t) {
    // Accounting identity: tick k is due at t0 + (k + skipped so far) * period.
    if (t.index == 0) seen.firstScheduled = t.scheduled_ns;
    const std::uint64_t skippedSoFar = seen.skippedSum.load(std::memory_order_relaxed) + t.skipped;
    seen.skippedSum.store(skippedSoFar, std::memory_order_relaxed);
    const std::int64_t due =
        seen.firstScheduled + static_cast<std::int64_t>(t.index + skippedSoFar) * t.period_ns;
    if (t.scheduled_ns != due || t.start_ns < t.scheduled_ns || t.index != seen.ticks.load())
      seen.badSchedule++;
    seen.ticks.fetch_add(1);
  });
  const std::int64_t t0 = steadyNs();
  ASSERT_TRUE(loop.start());
  EXPECT_TRUE(loop.running());
  EXPECT_FALSE(loop.start()) << "a second start() is refused (Busy)";
  std::this_thread::sleep_for(300ms);
  std::thread stopper([&loop] { loop.stop(); });
  stopper.join();
  const std::int64_t elapsed = steadyNs() - t0;
  EXPECT_FALSE(loop.running());
  loop.stop();  // idempotent

  const std::uint64_t ticks = seen.ticks.load();
  const double expected = static_cast<double>(elapsed) / 1e6;  // periods in the run
  EXPECT_GE(static_cast<double>(ticks), 0.5 * expected)
      << "ticks " << ticks << " in " << elapsed * 1e-6 << " ms; skipped " << loop.stats().skipped_periods
      << ", worst wake-up " << loop.stats().wakeup.max_us << " us";
  EXPECT_LE(static_cast<double>(ticks), expected + 2.0) << "never more ticks than periods: no bursts";
  EXPECT_EQ(seen.badSchedule.load(), 0u);

  const dm::RealTimeLoopStats s = loop.stats();
  EXPECT_EQ(s.ticks, ticks);
  // Skips are counted when the overrun is detected, so a miss by the very
  // last tick adds skips no later tick reported.
  EXPECT_GE(s.skipped_periods, seen.skippedSum.load());
  if (s.skipped_periods != seen.skippedSum.load()) {
    EXPECT_GT(s.deadline_misses, 0u);
  }
  EXPECT_LE(s.deadline_misses, s.ticks);
  EXPECT_EQ(s.period_ns, 1'000'000);
  EXPECT_FALSE(s.running);
  EXPECT_FALSE(s.tick_threw);
  expectMonotone(s.execution, ticks);
  expectMonotone(s.wakeup, ticks);
  EXPECT_GE(s.wakeup.min_us, 0.0);
}

TEST(RealTimeLoopConcurrency, SlowTicksAreDeadlineMissesAndPeriodsAreSkipped) {
  constexpr std::uint64_t kFirstSlow = 3, kSlowTicks = 5;
  std::atomic<std::uint64_t> ticks{0};
  std::atomic<std::uint64_t> minSkippedAfterSlow{~std::uint64_t{0}};
  dm::RealTimeLoop loop({.rate_hz = 1000, .name = "test-slow"}, [&](const dm::TickInfo& t) {
    // A tick right after a slow one reports the periods skipped for it.
    if (t.index > kFirstSlow && t.index <= kFirstSlow + kSlowTicks && t.skipped < minSkippedAfterSlow.load())
      minSkippedAfterSlow.store(t.skipped);
    if (t.index >= kFirstSlow && t.index < kFirstSlow + kSlowTicks) std::this_thread::sleep_for(3ms);
    ticks.fetch_add(1);
  });
  ASSERT_TRUE(loop.start());
  EXPECT_TRUE(waitFor([&] { return ticks.load() >= kFirstSlow + kSlowTicks + 5; }));
  loop.stop();
  const auto s = loop.stats();
  // Each slow tick lasts >= 3 periods, so it ends >= 2 periods after the
  // next deadline: a miss, and >= 3 skipped periods (no catch-up burst).
  EXPECT_GE(s.deadline_misses, kSlowTicks);
  EXPECT_LE(s.deadline_misses, s.ticks);
  EXPECT_GE(s.skipped_periods, 3 * kSlowTicks);
  EXPECT_GE(minSkippedAfterSlow.load(), 3u);
  EXPECT_NE(minSkippedAfterSlow.load(), ~std::uint64_t{0});
  EXPECT_GE(s.execution.max_us, 3000.0);
  expectMonotone(s.execution, s.ticks);
}

// With catch_up, the periods a slow tick passed are run back to back, not
// skipped: every tick k is due at t0 + k * period, and ticks still run late.
TEST(RealTimeLoopConcurrency, CatchUpRunsLatePeriodsInsteadOfSkippingThem) {
  constexpr std::uint64_t kSlow = 3, kTicks = 40;
  std::atomic<std::uint64_t> ticks{0}, lateAfterSlow{0}, skippedSeen{0};
  std::atomic<std::int64_t> first{0};
  std::atomic<bool> scheduleKept{true};
  // 200 periods of slack: only a stall of 0.2 s on a loaded machine skips.
  dm::RealTimeLoop loop({.rate_hz = 1000, .name = "test-catchup", .catch_up = 200}, [&](const dm::TickInfo& t) {
    if (t.index == 0) first.store(t.scheduled_ns);
    if (t.scheduled_ns != first.load() + static_cast<std::int64_t>(t.index) * t.period_ns)
      scheduleKept.store(false);
    skippedSeen.fetch_add(t.skipped);
    if (t.index > kSlow && t.start_ns - t.scheduled_ns > t.period_ns) lateAfterSlow.fetch_add(1);
    if (t.index == kSlow) std::this_thread::sleep_for(5ms);
    ticks.fetch_add(1);
  });
  ASSERT_TRUE(loop.start());
  EXPECT_TRUE(waitFor([&] { return ticks.load() >= kTicks; }));
  loop.stop();
  const auto s = loop.stats();
  EXPECT_TRUE(scheduleKept.load());
  EXPECT_EQ(skippedSeen.load(), 0u);
  EXPECT_EQ(s.skipped_periods, 0u);
  EXPECT_GE(s.deadline_misses, 1u);     // the slow tick itself
  EXPECT_GE(lateAfterSlow.load(), 2u);  // the ticks it delayed ran late, back to back
}

TEST(RealTimeLoopConcurrency, CatchUpOutOfRangeIsRefused) {
  for (int c : {-1, 1001}) {
    dm::RealTimeLoop loop({.name = "test-catchup-bad", .catch_up = c}, [](const dm::TickInfo&) {});
    const dm::Status s = loop.start();
    ASSERT_FALSE(s);
    EXPECT_NE(s.error().where.find("catch_up"), std::string::npos) << s.error().message();
  }
}

TEST(RealTimeLoopConcurrency, StatsReadableWhileRunning) {
  std::atomic<std::uint64_t> ticks{0};
  dm::RealTimeLoop loop({.rate_hz = 2000, .name = "test-stats"},
                        [&](const dm::TickInfo&) { ticks.fetch_add(1); });
  ASSERT_TRUE(loop.start());
  std::uint64_t lastCount = 0, decreases = 0, snapshots = 0;
  while (ticks.load() < 100 && snapshots < 100'000) {
    const auto s = loop.stats();
    decreases += (s.ticks < lastCount);
    lastCount = s.ticks;
    EXPECT_TRUE(s.running);
    EXPECT_LE(s.execution.p50_us, s.execution.max_us);
    ++snapshots;
    std::this_thread::sleep_for(200us);
  }
  loop.stop();
  EXPECT_EQ(decreases, 0u);
  EXPECT_GE(loop.stats().ticks, lastCount);
}

TEST(RealTimeLoopConcurrency, StopFromInsideTheTickAndRestart) {
  std::atomic<std::uint64_t> ticks{0};
  dm::RealTimeLoop* self = nullptr;
  dm::RealTimeLoop loop({.rate_hz = 1000, .name = "test-self"}, [&](const dm::TickInfo& t) {
    ticks.fetch_add(1);
    if (t.index == 9) self->stop();  // only requests the stop
  });
  self = &loop;
  ASSERT_TRUE(loop.start());
  EXPECT_TRUE(waitFor([&] { return !loop.running(); }));
  loop.stop();
  EXPECT_EQ(ticks.load(), 10u);
  EXPECT_EQ(loop.stats().ticks, 10u);
  // Restart: statistics start over.
  ASSERT_TRUE(loop.start());
  EXPECT_TRUE(waitFor([&] { return !loop.running(); }));
  loop.stop();
  EXPECT_EQ(loop.stats().ticks, 10u);
  EXPECT_EQ(ticks.load(), 20u);
}

TEST(RealTimeLoopConcurrency, LockstepIsRefusedWhileRunning) {
  dm::RealTimeLoop loop({.rate_hz = 1000, .name = "test-busy"}, [](const dm::TickInfo&) {});
  ASSERT_TRUE(loop.start());
  dm::VirtualClock clock;
  const dm::Status s = loop.runLockstep(clock, 3);
  ASSERT_FALSE(s);
  EXPECT_EQ(s.error().code, dm::ErrorCode::Busy);
  EXPECT_EQ(clock.now(), 0);
  loop.stop();
  EXPECT_TRUE(loop.runLockstep(clock, 3));
  EXPECT_EQ(clock.now(), 3'000'000);
}

TEST(RealTimeLoopConcurrency, ThrowingTickStopsTheLoop) {
  dm::RealTimeLoop loop({.rate_hz = 1000, .name = "test-throw"}, [](const dm::TickInfo& t) {
    if (t.index == 4) throw std::runtime_error("boom");
  });
  ASSERT_TRUE(loop.start());
  EXPECT_TRUE(waitFor([&] { return !loop.running(); }));
  const auto s = loop.stats();
  EXPECT_TRUE(s.tick_threw);
  EXPECT_EQ(s.ticks, 4u) << "ticks 0..3 completed";
  loop.stop();
}

TEST(RealTimeLoopConcurrency, LoopThreadDoesNotAllocate) {
  std::atomic<std::uint64_t> ticks{0};
  // The loop thread marks itself on its first tick; every allocation it
  // makes from then on (tick, timing, sleeping, bookkeeping) is counted.
  dm::RealTimeLoop loop({.rate_hz = 2000, .name = "test-noalloc"}, [&](const dm::TickInfo&) {
    dm::test::tCountAllocations = true;
    ticks.fetch_add(1, std::memory_order_relaxed);
  });
  const std::uint64_t before = dm::test::countedAllocations();
  ASSERT_TRUE(loop.start());
  EXPECT_TRUE(waitFor([&] { return ticks.load() >= 200; }));
  (void)loop.stats();  // reading stats concurrently must not make the loop allocate either
  loop.stop();
  EXPECT_EQ(dm::test::countedAllocations(), before);
  // The counter works: allocating on a marked thread is seen.
  std::thread([] {
    dm::test::tCountAllocations = true;
    dm::test::allocateOnce();
  }).join();
  EXPECT_EQ(dm::test::countedAllocations(), before + 1);
}

TEST(RealTimeLoopConcurrency, PriorityAndPinningTakeEffectOrFallBackWithOneWarning) {
  std::mutex mu;
  std::vector<std::string> warnings;
  dm::log::setSink([&](dm::log::Level level, std::string_view msg) {
    if (level != dm::log::Level::Warn) return;
    std::lock_guard lock(mu);
    warnings.emplace_back(msg);
  });
  std::atomic<int> policy{-1}, cpu{-1};
  std::atomic<std::uint64_t> ticks{0};
  dm::RealTimeLoop loop({.rate_hz = 1000, .priority = 10, .cpu = 0, .name = "test-prio"},
                        [&](const dm::TickInfo&) {
                          if (ticks.load() == 5) {
                            policy.store(sched_getscheduler(0));
                            cpu.store(sched_getcpu());
                          }
                          ticks.fetch_add(1);
                        });
  ASSERT_TRUE(loop.start()) << "refused priority or pinning is not an error";
  EXPECT_TRUE(waitFor([&] { return ticks.load() >= 20; }));
  loop.stop();
  dm::log::flush();
  dm::log::setSink({});
  const auto s = loop.stats();
  EXPECT_EQ(s.rt_priority, policy.load() == SCHED_FIFO);
  if (s.pinned) {
    EXPECT_EQ(cpu.load(), 0);
  }
  std::lock_guard lock(mu);
  std::size_t ours = 0;
  for (const auto& w : warnings) ours += (w.find("test-prio") != std::string::npos);
  if (s.rt_priority && s.pinned) {
    EXPECT_EQ(ours, 0u);
  } else {
    EXPECT_EQ(ours, 1u) << "exactly one warning names what was refused";
  }
}

TEST(RealTimeLoopConcurrency, RefusedPinningIsLoggedOnceAndTheLoopRuns) {
  // CPU_SETSIZE - 1 passes validation but exists on no test machine, so the
  // kernel refuses the affinity (EINVAL): the logged fallback path.
  std::mutex mu;
  std::vector<std::string> warnings;
  dm::log::setSink([&](dm::log::Level level, std::string_view msg) {
    if (level != dm::log::Level::Warn) return;
    std::lock_guard lock(mu);
    warnings.emplace_back(msg);
  });
  std::atomic<std::uint64_t> ticks{0};
  dm::RealTimeLoop loop({.rate_hz = 1000, .cpu = CPU_SETSIZE - 1, .name = "test-nocpu"},
                        [&](const dm::TickInfo&) { ticks.fetch_add(1); });
  ASSERT_TRUE(loop.start());
  EXPECT_TRUE(waitFor([&] { return ticks.load() >= 10; }));
  loop.stop();
  dm::log::flush();
  dm::log::setSink({});
  EXPECT_FALSE(loop.stats().pinned);
  EXPECT_FALSE(loop.stats().rt_priority) << "priority was not requested";
  std::lock_guard lock(mu);
  std::size_t ours = 0;
  for (const auto& w : warnings)
    ours += (w.find("test-nocpu") != std::string::npos &&
             w.find("CPU " + std::to_string(CPU_SETSIZE - 1)) != std::string::npos);
  EXPECT_EQ(ours, 1u);
}

TEST(RealTimeLoopConcurrency, SpinModeRunsAndIsReported) {
  std::atomic<std::uint64_t> ticks{0};
  std::atomic<std::uint64_t> early{0};
  dm::RealTimeLoop loop({.rate_hz = 1000, .name = "test-spin", .spin = dm::SpinMode::On, .spin_ns = 50'000},
                        [&](const dm::TickInfo& t) {
                          early += (t.start_ns < t.scheduled_ns);
                          ticks.fetch_add(1);
                        });
  ASSERT_TRUE(loop.start());
  EXPECT_TRUE(waitFor([&] { return ticks.load() >= 30; }));
  loop.stop();
  const auto s = loop.stats();
  EXPECT_TRUE(s.spinning);
  EXPECT_EQ(early.load(), 0u) << "spinning never starts a tick before its deadline";
  expectMonotone(s.wakeup, s.ticks);
  dm::RealTimeLoop off({.spin = dm::SpinMode::Off}, [](const dm::TickInfo&) {});
  ASSERT_TRUE(off.start());
  off.stop();
  EXPECT_FALSE(off.stats().spinning);
}

}  // namespace
