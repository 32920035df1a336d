// dm/core/rt_loop.hpp — periodic real-time loop with allocation-free timing.
//
// dm::RealTimeLoop calls a tick function at a fixed rate (default 1 kHz, the
// haptic rate) on its own thread. Deadlines are absolute: tick k is due at
// t0 + k * period on CLOCK_MONOTONIC (clock_nanosleep with TIMER_ABSTIME),
// optionally followed by a short busy-wait for the last few microseconds,
// so lateness never accumulates. Optionally the thread runs under SCHED_FIFO
// and is pinned to one CPU; where the OS refuses (EPERM without
// CAP_SYS_NICE), start() logs one warning and the loop runs anyway, and
// stats() says what took effect.
//
// Overruns: a tick that ends after the next deadline is a deadline miss.
// By default the loop then skips every period whose deadline has already
// passed (it never runs a burst of ticks to catch up: right for a haptic
// loop, where a late force is worse than none) and counts the skipped
// periods; the next tick sees how many were skipped in TickInfo::skipped.
// A loop given catch_up = N > 0 instead runs the late ticks at once, back to
// back, while it is at most N periods behind, and skips only beyond that: a
// render loop then makes up one slow frame with the next ones and keeps its
// average rate.
//
// The loop thread never allocates, locks or logs synchronously: timings go
// into preallocated histograms (LatencyHistogram), the tick function is
// stored once, and the only logging is dm::log::rt. The tick function must
// follow the same rules.
//
// Lockstep: runLockstep(clock, n) runs the same tick function n times on
// the calling thread, advancing a dm::VirtualClock by one period per tick,
// so tests and headless runs execute the real-time code deterministically.
//
// @code
//   dm::RealTimeLoop loop({.rate_hz = 1000, .name = "haptics"},
//                         [&](const dm::TickInfo& t) { device.update(t.dt()); });
//   if (auto s = loop.start(); !s) { dm::log::error("%s", s.error().message().c_str()); }
//   ...; loop.stop();  dm::RealTimeLoopStats st = loop.stats();
// @endcode
#pragma once

#include <dm/core/clock.hpp>
#include <dm/core/result.hpp>

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>

namespace dm {

/// Log-linear histogram of non-negative durations in nanoseconds, with a
/// fixed array of counters (no allocation, ever). Values below 32 ns have
/// their own bucket; above, each power of two [2^e, 2^(e+1)) is split into
/// 32 equal buckets, so a bucket is at most 1/32 of its lower bound wide.
/// Percentiles report the bucket's midpoint (clamped to [min, max]): within
/// 1/64 (1.6 %) of a true sample value, exact below 32 ns. Covers the whole
/// int64 range in 1888 buckets (15 KiB).
///
/// record() is for ONE writer thread (relaxed atomic load + store, no
/// read-modify-write); any thread may read at the same time and gets an
/// approximate but race-free snapshot.
///
/// @code
///   dm::LatencyHistogram h;
///   h.record(1200);                       // ns
///   std::int64_t p99 = h.percentile(99);  // ns
/// @endcode
class LatencyHistogram {
 public:
  static constexpr int kSubBucketBits = 5;
  static constexpr std::int64_t kSubBuckets = std::int64_t{1} << kSubBucketBits;                  // 32
  static constexpr std::size_t kBucketCount = kSubBuckets + (63 - kSubBucketBits) * kSubBuckets;  // 1888

  /// Summary of a histogram, all durations in MICROSECONDS (double).
  struct Summary {
    std::uint64_t count = 0;  ///< number of samples
    double min_us = 0;        ///< smallest sample (exact)
    double mean_us = 0;       ///< arithmetic mean (exact up to double rounding)
    double p50_us = 0;        ///< median, to the histogram's resolution
    double p99_us = 0;        ///< 99th percentile
    double p999_us = 0;       ///< 99.9th percentile
    double max_us = 0;        ///< largest sample (exact)
  };

  LatencyHistogram() noexcept;
  LatencyHistogram(const LatencyHistogram&) = delete;
  LatencyHistogram& operator=(const LatencyHistogram&) = delete;

  /// Adds one sample of `ns` nanoseconds (negative values count as 0).
  /// Single writer only. Real-time safe. O(1).
  void record(std::int64_t ns) noexcept;
  /// Forgets every sample. Must not run concurrently with record(). O(buckets).
  void reset() noexcept;

  /// Number of samples.
  std::uint64_t count() const noexcept { return count_.load(std::memory_order_relaxed); }
  /// Smallest and largest samples in ns (exact); 0 when empty.
  std::int64_t min() const noexcept;
  std::int64_t max() const noexcept;
  /// Mean in ns; 0 when empty.
  double mean() const noexcept;
  /// The `p`-th percentile (p in [0, 100], clamped) in ns: the midpoint of
  /// the bucket holding the ceil(p/100 * count)-th smallest sample (the
  /// smallest for p = 0), clamped to [min, max]. 0 when empty. O(buckets).
  std::int64_t percentile(double p) const noexcept;
  /// count, min, mean, p50, p99, p99.9, max from one snapshot, in us.
  /// Uses 15 KiB of stack. O(buckets).
  Summary summary() const noexcept;

  /// Bucket holding `ns` (clamped to >= 0), and that bucket's inclusive
  /// bounds in ns. O(1).
  static std::size_t bucketIndex(std::int64_t ns) noexcept;
  static std::int64_t bucketLowest(std::size_t index) noexcept;
  static std::int64_t bucketHighest(std::size_t index) noexcept;

 private:
  using Counts = std::array<std::uint64_t, kBucketCount>;
  std::uint64_t snapshot(Counts& out) const noexcept;
  std::int64_t percentileOf(const Counts& counts, std::uint64_t total, double p) const noexcept;

  std::array<std::atomic<std::uint64_t>, kBucketCount> counts_;
  std::atomic<std::uint64_t> count_{0};
  std::atomic<std::uint64_t> sum_{0};
  std::atomic<std::int64_t> min_;
  std::atomic<std::int64_t> max_{0};
};

/// Whether the loop busy-waits the last spin_ns before each deadline
/// (tighter wake-ups for one core's worth of CPU time).
enum class SpinMode : std::uint8_t {
  Auto,  ///< spin only on machines with more than 2 hardware threads
  Off,   ///< sleep until the deadline
  On,    ///< sleep until deadline - spin_ns, then spin
};

/// Configuration of a RealTimeLoop.
struct RealTimeLoopConfig {
  double rate_hz = 1000.0;     ///< ticks per second, in [0.001, 1e6]
  int priority = 0;            ///< SCHED_FIFO priority 1..99; 0 keeps normal scheduling
  int cpu = -1;                ///< CPU index to pin the thread to; -1: no pinning
  std::string name = "dm-rt";  ///< thread name (first 15 characters) and log prefix
  SpinMode spin = SpinMode::Auto;
  std::int64_t spin_ns = 50'000;  ///< busy-wait window before each deadline, in [0, period]
  /// Periods a late loop may fall behind and still run every one of them,
  /// back to back; further behind, the passed periods are skipped. 0 skips
  /// at once (haptics). In [0, 1000].
  int catch_up = 0;
};

/// What a tick function is told. Times are in nanoseconds on the loop's
/// clock: CLOCK_MONOTONIC (== dm::RealClock) in real time, the VirtualClock
/// in lockstep.
struct TickInfo {
  std::uint64_t index = 0;        ///< ticks run before this one (0-based)
  std::int64_t scheduled_ns = 0;  ///< deadline this tick was due at
  std::int64_t start_ns = 0;      ///< when it actually started (>= scheduled_ns)
  std::int64_t period_ns = 0;     ///< the loop period
  std::uint64_t skipped = 0;      ///< periods skipped just before this tick (overrun)
  /// The period in seconds, the time step for integrators.
  double dt() const noexcept { return nanosToSeconds(period_ns); }
};

/// Seconds since a loop started, from its ticks: lockstep's virtual clock
/// starts at 0, a real-time loop's monotonic clock does not, and a HUD, a
/// trace or a camera path wants scene time either way. The origin is the
/// first tick seen, less the periods before it. One per loop thread.
class TickTime {
 public:
  double seconds(const TickInfo& tick) noexcept {
    if (!started_) {
      originNs_ = tick.scheduled_ns - static_cast<std::int64_t>(tick.index) * tick.period_ns;
      started_ = true;
    }
    return nanosToSeconds(tick.scheduled_ns - originNs_);
  }

 private:
  std::int64_t originNs_ = 0;
  bool started_ = false;
};

/// Statistics of a RealTimeLoop since its last start() (or construction).
/// Durations in MICROSECONDS.
struct RealTimeLoopStats {
  std::uint64_t ticks = 0;  ///< ticks run
  /// Ticks whose end passed the next deadline (scheduled + period). This
  /// includes every tick that started more than one period late.
  std::uint64_t deadline_misses = 0;
  std::uint64_t skipped_periods = 0;    ///< periods skipped instead of bursting
  LatencyHistogram::Summary execution;  ///< tick duration: end - start
  LatencyHistogram::Summary wakeup;     ///< wake-up latency: start - scheduled
  std::int64_t period_ns = 0;           ///< the loop period
  bool running = false;                 ///< the loop thread is ticking
  bool rt_priority = false;             ///< SCHED_FIFO priority took effect
  bool pinned = false;                  ///< CPU pinning took effect
  bool spinning = false;                ///< busy-waits before deadlines
  bool tick_threw = false;              ///< the tick function threw; the loop stopped
};

/// A periodic loop on its own thread (see the file comment). start(), stop()
/// and runLockstep() may be called from any thread, stats() from any thread
/// at any time. Moving a running loop is allowed; destroying it stops it.
class RealTimeLoop {
 public:
  using TickFn = std::function<void(const TickInfo&)>;

  /// Stores the configuration and the tick function; starts nothing. An
  /// invalid configuration is reported by start() and runLockstep().
  RealTimeLoop(RealTimeLoopConfig config, TickFn tick);
  ~RealTimeLoop();
  RealTimeLoop(RealTimeLoop&&) noexcept;
  RealTimeLoop& operator=(RealTimeLoop&&) noexcept;
  RealTimeLoop(const RealTimeLoop&) = delete;
  RealTimeLoop& operator=(const RealTimeLoop&) = delete;

  /// Checks a configuration: rate_hz in [0.001, 1e6], priority 0 or within
  /// SCHED_FIFO's range, cpu -1 or in [0, CPU_SETSIZE), spin_ns in [0, period],
  /// catch_up in [0, 1000].
  /// InvalidArgument naming the field otherwise.
  static Status validate(const RealTimeLoopConfig& config);

  /// Resets the statistics and starts the loop thread; the first tick runs
  /// at once. Applies priority and pinning from the calling thread; if the
  /// OS refuses either, logs one warning (dm::log::warn) and continues.
  /// Fails with InvalidArgument for a bad configuration, Busy if already
  /// running or inside runLockstep(), Internal if no thread can be created.
  Status start();

  /// Asks the loop to stop after the current tick and joins its thread.
  /// Idempotent; a no-op when not running. Called from inside the tick
  /// function, it only requests the stop (a thread cannot join itself).
  void stop();
  /// Asks the loop to stop without waiting. Real-time safe.
  void requestStop() noexcept;
  /// Whether the loop thread is ticking.
  bool running() const noexcept;

  /// Lockstep: runs the tick function `n` times on the calling thread. Tick
  /// k is scheduled at, and starts at, clock.now(); then the clock advances
  /// by exactly one period. Records the same statistics as the real loop
  /// (with virtual times). Busy if the loop thread is running,
  /// InvalidArgument for a bad configuration, Internal if the tick function
  /// threw (the remaining ticks are not run).
  /// @code
  ///   dm::VirtualClock clock;
  ///   if (auto s = loop.runLockstep(clock, 1000); !s) return s;  // clock.now() == 1e9 ns at 1 kHz
  /// @endcode
  Status runLockstep(VirtualClock& clock, std::uint64_t n);
  /// runLockstep(clock, 1).
  Status stepOnce(VirtualClock& clock) { return runLockstep(clock, 1); }

  /// A snapshot of the statistics. Safe while running; allocation-free.
  RealTimeLoopStats stats() const noexcept;
  /// The execution-time and wake-up histograms (ns), for custom percentiles.
  const LatencyHistogram& executionHistogram() const noexcept;
  const LatencyHistogram& wakeupHistogram() const noexcept;

  const RealTimeLoopConfig& config() const noexcept;
  /// round(1e9 / rate_hz) ns, or 0 if the rate is invalid.
  std::int64_t periodNs() const noexcept;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace dm
