// dm/core/clock.hpp — time sources in integer nanoseconds.
//
// Every loop in the SDK reads time through a dm::Clock, so the same code runs
// on the wall clock (RealClock) in real-time mode and on a VirtualClock that
// the master engine advances in lockstep (tests, CI, headless runs). Times
// are std::int64_t nanoseconds since an arbitrary fixed epoch: integer time
// keeps lockstep runs bit-for-bit reproducible (n periods always add up to
// exactly n * period).
//
// @code
//   dm::VirtualClock clock;                 // starts at 0 ns
//   clock.advance(dm::secondsToNanos(1e-3)); // one 1 kHz period
//   double t = clock.nowSeconds();          // 0.001
// @endcode
#pragma once

#include <atomic>
#include <cstdint>
#include <limits>

namespace dm {

/// Nanoseconds in one second.
inline constexpr std::int64_t kNanosPerSecond = 1'000'000'000;

/// Seconds to integer nanoseconds, rounded to nearest. Saturates at the
/// int64 range (about ±292 years); NaN gives 0. O(1).
constexpr std::int64_t secondsToNanos(double seconds) noexcept {
  const double ns = seconds * 1e9;
  if (!(ns == ns)) return 0;  // NaN (constexpr-friendly isnan)
  constexpr double kMax = 9.2e18;
  if (ns >= kMax) return std::numeric_limits<std::int64_t>::max();
  if (ns <= -kMax) return std::numeric_limits<std::int64_t>::min();
  return static_cast<std::int64_t>(ns < 0.0 ? ns - 0.5 : ns + 0.5);
}

/// Integer nanoseconds to seconds (exact below 2^53 ns, about 104 days). O(1).
constexpr double nanosToSeconds(std::int64_t ns) noexcept { return static_cast<double>(ns) * 1e-9; }

/// Abstract time source. now() is thread-safe and never allocates, locks or
/// blocks, so it may be called from real-time threads.
class Clock {
 public:
  virtual ~Clock() = default;
  /// Current time in nanoseconds since the clock's epoch. Non-decreasing
  /// (except across VirtualClock::set()).
  virtual std::int64_t now() const noexcept = 0;
  /// now() in seconds.
  double nowSeconds() const noexcept { return nanosToSeconds(now()); }

 protected:
  Clock() = default;
  Clock(const Clock&) = default;
  Clock& operator=(const Clock&) = default;
};

/// The monotonic wall clock (std::chrono::steady_clock, which is
/// CLOCK_MONOTONIC on Linux — the same timebase dm::RealTimeLoop uses for
/// its deadlines). Epoch: unspecified (usually boot).
///
/// @code
///   dm::RealClock clock;
///   std::int64_t t0 = clock.now();
/// @endcode
class RealClock final : public Clock {
 public:
  std::int64_t now() const noexcept override;
};

/// A clock that only moves when told to: for lockstep runs, where the master
/// engine advances it by one period per step. Reads are lock-free atomic
/// loads, so other threads may read it while one thread advances it.
/// Deterministic: the time is exactly the sum of what was advanced.
///
/// @code
///   dm::VirtualClock clock(0);
///   for (int i = 0; i < 1000; ++i) clock.advance(1'000'000);  // now() == 1'000'000'000
/// @endcode
class VirtualClock final : public Clock {
 public:
  /// Starts at `start_ns` nanoseconds.
  explicit VirtualClock(std::int64_t start_ns = 0) noexcept : nowNs_(start_ns) {}
  VirtualClock(const VirtualClock& other) noexcept : Clock(other), nowNs_(other.now()) {}
  VirtualClock& operator=(const VirtualClock& other) noexcept {
    set(other.now());
    return *this;
  }

  std::int64_t now() const noexcept override { return nowNs_.load(std::memory_order_acquire); }
  /// Moves time forward by `dt_ns` >= 0 nanoseconds (negative values are a
  /// programming error: DM_ASSERT in debug builds, ignored in release).
  void advance(std::int64_t dt_ns) noexcept;
  /// advance() by `dt_s` seconds, rounded to the nearest nanosecond.
  void advanceSeconds(double dt_s) noexcept { advance(secondsToNanos(dt_s)); }
  /// Jumps to `t_ns` (may go backwards: for rewinding a replay).
  void set(std::int64_t t_ns) noexcept { nowNs_.store(t_ns, std::memory_order_release); }

 private:
  std::atomic<std::int64_t> nowNs_;
};

}  // namespace dm
