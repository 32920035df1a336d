#include <dm/core/assert.hpp>
#include <dm/core/log.hpp>
#include <dm/core/rt_loop.hpp>
#include <dm/core/rt_memory.hpp>

#include <pthread.h>
#include <sched.h>
#include <sys/prctl.h>
#include <time.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <exception>
#include <limits>
#include <mutex>
#include <string>
#include <system_error>
#include <thread>
#include <utility>

namespace dm {

// ---------------------------------------------------------------------------
// LatencyHistogram

namespace {
constexpr std::int64_t kNoMin = std::numeric_limits<std::int64_t>::max();
constexpr int kMaxCatchUp = 1000;  // RealTimeLoopConfig::catch_up

// Single-writer increment: a relaxed load and store, no locked instruction.
template <class A, class V>
inline void addRelaxed(A& a, V v) noexcept {
  a.store(a.load(std::memory_order_relaxed) + v, std::memory_order_relaxed);
}
}  // namespace

LatencyHistogram::LatencyHistogram() noexcept : min_(kNoMin) {
  for (auto& c : counts_) c.store(0, std::memory_order_relaxed);
}

std::size_t LatencyHistogram::bucketIndex(std::int64_t ns) noexcept {
  if (ns < kSubBuckets) return ns < 0 ? 0 : static_cast<std::size_t>(ns);
  const auto u = static_cast<std::uint64_t>(ns);
  const int e = static_cast<int>(std::bit_width(u)) - 1;  // 2^e <= u < 2^(e+1), e >= 5
  const int shift = e - kSubBucketBits;
  const auto sub = static_cast<std::size_t>((u >> shift) - static_cast<std::uint64_t>(kSubBuckets));
  return static_cast<std::size_t>(kSubBuckets) + static_cast<std::size_t>(shift) * kSubBuckets + sub;
}

std::int64_t LatencyHistogram::bucketLowest(std::size_t index) noexcept {
  index = std::min(index, kBucketCount - 1);
  if (index < static_cast<std::size_t>(kSubBuckets)) return static_cast<std::int64_t>(index);
  const std::size_t k = index - kSubBuckets;
  const std::size_t shift = k / kSubBuckets;
  const std::uint64_t sub = k % kSubBuckets;
  return static_cast<std::int64_t>((static_cast<std::uint64_t>(kSubBuckets) + sub) << shift);
}

std::int64_t LatencyHistogram::bucketHighest(std::size_t index) noexcept {
  index = std::min(index, kBucketCount - 1);
  if (index < static_cast<std::size_t>(kSubBuckets)) return static_cast<std::int64_t>(index);
  const std::size_t shift = (index - kSubBuckets) / kSubBuckets;
  const auto width = std::uint64_t{1} << shift;
  return static_cast<std::int64_t>(static_cast<std::uint64_t>(bucketLowest(index)) + (width - 1));
}

void LatencyHistogram::record(std::int64_t ns) noexcept {
  if (ns < 0) ns = 0;
  addRelaxed(counts_[bucketIndex(ns)], std::uint64_t{1});
  addRelaxed(sum_, static_cast<std::uint64_t>(ns));
  if (ns < min_.load(std::memory_order_relaxed)) min_.store(ns, std::memory_order_relaxed);
  if (ns > max_.load(std::memory_order_relaxed)) max_.store(ns, std::memory_order_relaxed);
  // Count last, so a reader that sees n samples mostly sees their buckets too.
  addRelaxed(count_, std::uint64_t{1});
}

void LatencyHistogram::reset() noexcept {
  for (auto& c : counts_) c.store(0, std::memory_order_relaxed);
  count_.store(0, std::memory_order_relaxed);
  sum_.store(0, std::memory_order_relaxed);
  min_.store(kNoMin, std::memory_order_relaxed);
  max_.store(0, std::memory_order_relaxed);
}

std::int64_t LatencyHistogram::min() const noexcept {
  const std::int64_t m = min_.load(std::memory_order_relaxed);
  return m == kNoMin ? 0 : m;
}

std::int64_t LatencyHistogram::max() const noexcept { return max_.load(std::memory_order_relaxed); }

double LatencyHistogram::mean() const noexcept {
  const std::uint64_t n = count();
  return n == 0 ? 0.0 : static_cast<double>(sum_.load(std::memory_order_relaxed)) / static_cast<double>(n);
}

std::uint64_t LatencyHistogram::snapshot(Counts& out) const noexcept {
  std::uint64_t total = 0;
  for (std::size_t i = 0; i < kBucketCount; ++i) {
    out[i] = counts_[i].load(std::memory_order_relaxed);
    total += out[i];
  }
  return total;
}

std::int64_t LatencyHistogram::percentileOf(const Counts& counts, std::uint64_t total,
                                            double p) const noexcept {
  if (total == 0) return 0;
  if (!(p > 0.0)) p = 0.0;  // also NaN
  p = std::min(p, 100.0);
  // rank of the sample (1-based); the tiny relative slack keeps p/100*n that
  // is an integer up to rounding (99.9% of 1000) from rounding up to n+1.
  const double x = p / 100.0 * static_cast<double>(total);
  auto rank = static_cast<std::uint64_t>(std::ceil(x - x * 1e-12));
  rank = std::clamp<std::uint64_t>(rank, 1, total);
  std::uint64_t cumulative = 0;
  std::size_t bucket = kBucketCount - 1;
  for (std::size_t i = 0; i < kBucketCount; ++i) {
    cumulative += counts[i];
    if (cumulative >= rank) {
      bucket = i;
      break;
    }
  }
  const std::int64_t lo = bucketLowest(bucket);
  const std::int64_t mid = lo + (bucketHighest(bucket) - lo) / 2;
  return std::clamp(mid, std::min(min(), max()), max());
}

std::int64_t LatencyHistogram::percentile(double p) const noexcept {
  Counts counts;
  const std::uint64_t total = snapshot(counts);
  return percentileOf(counts, total, p);
}

LatencyHistogram::Summary LatencyHistogram::summary() const noexcept {
  Counts counts;
  const std::uint64_t total = snapshot(counts);
  Summary s;
  s.count = total;
  if (total == 0) return s;
  constexpr double kUs = 1e-3;
  s.min_us = static_cast<double>(min()) * kUs;
  s.max_us = static_cast<double>(max()) * kUs;
  s.mean_us = static_cast<double>(sum_.load(std::memory_order_relaxed)) / static_cast<double>(total) * kUs;
  s.p50_us = static_cast<double>(percentileOf(counts, total, 50.0)) * kUs;
  s.p99_us = static_cast<double>(percentileOf(counts, total, 99.0)) * kUs;
  s.p999_us = static_cast<double>(percentileOf(counts, total, 99.9)) * kUs;
  return s;
}

// ---------------------------------------------------------------------------
// RealTimeLoop

namespace {

std::int64_t monotonicNow() noexcept {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * kNanosPerSecond + ts.tv_nsec;
}

inline void cpuRelax() noexcept {
#if defined(__x86_64__) || defined(__i386__)
  __builtin_ia32_pause();
#elif defined(__aarch64__) || defined(__arm__)
  __asm__ __volatile__("yield" ::: "memory");
#endif
}

// Sleeps until `deadline` (absolute, CLOCK_MONOTONIC) or until a stop is
// requested. Sleeps at most kMaxChunk at a time so stop() of a slow loop
// (a 1 Hz logger) is not delayed by a whole period.
void sleepUntil(std::int64_t deadline, const std::atomic<bool>& stop) noexcept {
  constexpr std::int64_t kMaxChunk = 20'000'000;
  for (;;) {
    const std::int64_t now = monotonicNow();
    if (now >= deadline || stop.load(std::memory_order_relaxed)) return;
    const std::int64_t target = std::min(deadline, now + kMaxChunk);
    timespec ts{};
    ts.tv_sec = static_cast<time_t>(target / kNanosPerSecond);
    ts.tv_nsec = static_cast<long>(target % kNanosPerSecond);
    // EINTR just loops; any other error cannot happen with valid arguments.
    clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr);
  }
}

std::int64_t periodFor(double rate_hz) noexcept {
  if (!(rate_hz >= 1e-3 && rate_hz <= 1e6)) return 0;
  return static_cast<std::int64_t>(std::llround(1e9 / rate_hz));
}

std::string loopWhere(const RealTimeLoopConfig& c, const char* field) {
  return "RealTimeLoop '" + c.name + "': config." + field;
}

}  // namespace

struct RealTimeLoop::Impl {
  Impl(RealTimeLoopConfig c, TickFn t)
      : config(std::move(c)), tick(std::move(t)), period(periodFor(config.rate_hz)) {}
  ~Impl() { stop(); }

  Status start();
  void stop();
  Status runLockstep(VirtualClock& clock, std::uint64_t n);
  void threadMain() noexcept;
  void resetStats() noexcept;

  // Records one tick; single writer (the loop thread, or the lockstep caller).
  void recordTick(std::int64_t wakeup_ns, std::int64_t exec_ns, bool missed) noexcept {
    wakeup.record(wakeup_ns);
    execution.record(exec_ns);
    if (missed) addRelaxed(misses, std::uint64_t{1});
    addRelaxed(ticks, std::uint64_t{1});
  }

  const RealTimeLoopConfig config;
  const TickFn tick;
  const std::int64_t period;

  LatencyHistogram execution;
  LatencyHistogram wakeup;
  std::atomic<std::uint64_t> ticks{0};
  std::atomic<std::uint64_t> misses{0};
  std::atomic<std::uint64_t> skipped{0};

  std::atomic<bool> stopRequested{false};
  std::atomic<bool> running{false};
  std::atomic<bool> gate{false};
  std::atomic<bool> rtPriority{false};
  std::atomic<bool> pinned{false};
  std::atomic<bool> spinning{false};
  std::atomic<bool> tickThrew{false};
  std::atomic<std::thread::id> loopThread{};

  std::mutex control;           // serializes start/stop/runLockstep; never taken by the loop thread
  std::thread thread;           // guarded by control
  bool lockstepActive = false;  // guarded by control
};

Status RealTimeLoop::validate(const RealTimeLoopConfig& c) {
  if (periodFor(c.rate_hz) == 0)
    return fail(ErrorCode::InvalidArgument,
                "rate_hz is " + std::to_string(c.rate_hz) + ", must be in [0.001, 1e6]",
                loopWhere(c, "rate_hz"), "use e.g. 1000 for a haptic loop or 500 for physics");
  const int lo = sched_get_priority_min(SCHED_FIFO);
  const int hi = sched_get_priority_max(SCHED_FIFO);
  if (c.priority != 0 && (c.priority < lo || c.priority > hi))
    return fail(ErrorCode::InvalidArgument,
                "priority is " + std::to_string(c.priority) + ", must be 0 (normal scheduling) or in [" +
                    std::to_string(lo) + ", " + std::to_string(hi) + "] (SCHED_FIFO)",
                loopWhere(c, "priority"), "use 0, or e.g. 80 for a haptic loop");
  if (c.cpu < -1 || c.cpu >= CPU_SETSIZE)
    return fail(ErrorCode::InvalidArgument,
                "cpu is " + std::to_string(c.cpu) + ", must be -1 (no pinning) or in [0, " +
                    std::to_string(CPU_SETSIZE) + ")",
                loopWhere(c, "cpu"), "use -1, or the index of an isolated CPU");
  if (c.spin_ns < 0 || c.spin_ns > periodFor(c.rate_hz))
    return fail(ErrorCode::InvalidArgument,
                "spin_ns is " + std::to_string(c.spin_ns) +
                    ", must be in [0, period = " + std::to_string(periodFor(c.rate_hz)) + " ns]",
                loopWhere(c, "spin_ns"), "use about 50000 (50 us), or SpinMode::Off");
  if (c.catch_up < 0 || c.catch_up > kMaxCatchUp)
    return fail(ErrorCode::InvalidArgument,
                "catch_up is " + std::to_string(c.catch_up) + ", must be in [0, " + std::to_string(kMaxCatchUp) + "]",
                loopWhere(c, "catch_up"), "use 0 for a haptic loop, 1 or 2 for a render loop");
  return ok();
}

void RealTimeLoop::Impl::resetStats() noexcept {
  execution.reset();
  wakeup.reset();
  ticks.store(0, std::memory_order_relaxed);
  misses.store(0, std::memory_order_relaxed);
  skipped.store(0, std::memory_order_relaxed);
  tickThrew.store(false, std::memory_order_relaxed);
}

Status RealTimeLoop::Impl::start() {
  if (Status s = validate(config); !s) return s;
  std::unique_lock lock(control);
  if (running.load(std::memory_order_acquire))
    return fail(ErrorCode::Busy, "already running", "RealTimeLoop '" + config.name + "'",
                "call stop() first");
  if (lockstepActive)
    return fail(ErrorCode::Busy, "runLockstep() is in progress", "RealTimeLoop '" + config.name + "'",
                "start the real-time thread after the lockstep run returns");
  if (thread.joinable()) thread.join();  // a previous run that ended by itself (the tick threw)

  resetStats();
  stopRequested.store(false, std::memory_order_relaxed);
  gate.store(false, std::memory_order_relaxed);
  const bool spin =
      config.spin_ns > 0 && (config.spin == SpinMode::On ||
                             (config.spin == SpinMode::Auto && std::thread::hardware_concurrency() > 2));
  spinning.store(spin, std::memory_order_relaxed);
  rtPriority.store(false, std::memory_order_relaxed);
  pinned.store(false, std::memory_order_relaxed);
  running.store(true, std::memory_order_release);
  try {
    thread = std::thread([this] { threadMain(); });
  } catch (const std::system_error& e) {
    running.store(false, std::memory_order_release);
    return fail(ErrorCode::Internal, std::string("cannot create the loop thread: ") + e.what(),
                "RealTimeLoop '" + config.name + "'", "check the process's thread limit (ulimit -u)");
  }

  // Name, priority and pinning are applied from here, before the thread is
  // let through its start gate, so the loop runs under its final settings
  // and the (allocating, locking) warning is logged from this thread.
  const pthread_t handle = thread.native_handle();
  const std::string shortName = config.name.substr(0, 15);  // the kernel's limit
  if (!shortName.empty()) pthread_setname_np(handle, shortName.c_str());
  int priorityError = 0;
  if (config.priority > 0) {
    sched_param param{};
    param.sched_priority = config.priority;
    priorityError = pthread_setschedparam(handle, SCHED_FIFO, &param);
    rtPriority.store(priorityError == 0, std::memory_order_relaxed);
  }
  int pinError = 0;
  if (config.cpu >= 0) {
    cpu_set_t set;
    CPU_ZERO(&set);
    CPU_SET(static_cast<std::size_t>(config.cpu), &set);
    pinError = pthread_setaffinity_np(handle, sizeof(set), &set);
    pinned.store(pinError == 0, std::memory_order_relaxed);
  }
  loopThread.store(thread.get_id(), std::memory_order_relaxed);
  gate.store(true, std::memory_order_release);
  gate.notify_one();
  lock.unlock();

  if (priorityError != 0 || pinError != 0) {
    std::string what, hint;
    if (priorityError != 0) {
      what = "SCHED_FIFO priority " + std::to_string(config.priority) + " refused (" +
             std::generic_category().message(priorityError) + ")";
      hint = "grant CAP_SYS_NICE or an rtprio limit (/etc/security/limits.conf) for real-time priority";
    }
    if (pinError != 0) {
      what += (what.empty() ? "" : "; ") + ("pinning to CPU " + std::to_string(config.cpu) + " refused (" +
                                            std::generic_category().message(pinError) + ")");
      hint += (hint.empty() ? "" : "; ") +
              std::string("pin to a CPU in the process's cpuset, see taskset -p PID");
    }
    log::warn("RealTimeLoop '%s': %s; running without it (%s)", config.name.c_str(), what.c_str(),
              hint.c_str());
  }
  return ok();
}

void RealTimeLoop::Impl::stop() {
  if (std::this_thread::get_id() == loopThread.load(std::memory_order_relaxed)) {
    stopRequested.store(true, std::memory_order_release);  // joining ourselves would deadlock
    return;
  }
  std::lock_guard lock(control);
  if (!thread.joinable()) return;
  stopRequested.store(true, std::memory_order_release);
  thread.join();
  loopThread.store(std::thread::id{}, std::memory_order_relaxed);
  running.store(false, std::memory_order_release);
}

void RealTimeLoop::Impl::threadMain() noexcept {
  gate.wait(false, std::memory_order_acquire);
  // Normal-priority threads get 50 us of timer slack by default, which would
  // show up directly as wake-up latency; 1 ns asks for exact wake-ups.
  prctl(PR_SET_TIMERSLACK, 1UL, 0UL, 0UL, 0UL);
  // The ticks' stack frames mapped now, not at the first deep tick (a
  // minor fault each page, in the middle of a deadline).
  prefaultStack();
  const std::int64_t spinNs = spinning.load(std::memory_order_relaxed) ? config.spin_ns : 0;
  std::uint64_t index = 0;
  std::uint64_t skippedTotal = 0;
  std::uint64_t skippedBefore = 0;
  std::int64_t next = monotonicNow();  // the first tick runs at once
  while (!stopRequested.load(std::memory_order_acquire)) {
    if (spinNs > 0) {
      sleepUntil(next - spinNs, stopRequested);
      while (monotonicNow() < next) cpuRelax();
    } else {
      sleepUntil(next, stopRequested);
    }
    if (stopRequested.load(std::memory_order_acquire)) break;

    const std::int64_t start = monotonicNow();
    const TickInfo info{index, next, start, period, skippedBefore};
    try {
      tick(info);
    } catch (...) {
      tickThrew.store(true, std::memory_order_release);
      log::rt(log::Level::Error, "RealTimeLoop '%s': the tick function threw at tick %llu; loop stopped",
              config.name.c_str(), static_cast<unsigned long long>(index));
      break;
    }
    const std::int64_t end = monotonicNow();

    // Deadline miss: the tick ended after the next deadline. Then skip every
    // period whose deadline has passed instead of bursting to catch up,
    // unless they are few enough (catch_up) to run back to back.
    const std::int64_t following = next + period;
    const bool missed = end > following;
    skippedBefore = 0;
    if (missed) {
      const auto passed = static_cast<std::uint64_t>((end - following) / period) + 1;
      if (passed > static_cast<std::uint64_t>(config.catch_up)) skippedBefore = passed;
    }
    next = following + static_cast<std::int64_t>(skippedBefore) * period;
    skippedTotal += skippedBefore;
    skipped.store(skippedTotal, std::memory_order_relaxed);
    recordTick(start - info.scheduled_ns, end - start, missed);
    ++index;
  }
  running.store(false, std::memory_order_release);
}

Status RealTimeLoop::Impl::runLockstep(VirtualClock& clock, std::uint64_t n) {
  if (Status s = validate(config); !s) return s;
  {
    std::lock_guard lock(control);
    if (running.load(std::memory_order_acquire))
      return fail(ErrorCode::Busy, "the real-time thread is running", "RealTimeLoop '" + config.name + "'",
                  "stop() the loop before running it in lockstep");
    if (lockstepActive)
      return fail(ErrorCode::Busy, "runLockstep() is already in progress",
                  "RealTimeLoop '" + config.name + "'",
                  "do not call runLockstep() from the tick function or from two threads");
    lockstepActive = true;
  }
  struct Release {
    Impl& impl;
    ~Release() {
      std::lock_guard lock(impl.control);
      impl.lockstepActive = false;
    }
  } release{*this};

  for (std::uint64_t k = 0; k < n; ++k) {
    const std::int64_t scheduled = clock.now();
    const std::uint64_t index = ticks.load(std::memory_order_relaxed);
    const TickInfo info{index, scheduled, scheduled, period, 0};
    std::string thrown;
    try {
      tick(info);
    } catch (const std::exception& e) {
      thrown = e.what();
    } catch (...) {
      thrown = "unknown exception";
    }
    if (!thrown.empty()) {
      tickThrew.store(true, std::memory_order_release);
      return fail(ErrorCode::Internal, "the tick function threw: " + thrown,
                  "RealTimeLoop '" + config.name + "': lockstep tick " + std::to_string(index),
                  "tick functions must not throw; handle the error inside the tick");
    }
    const std::int64_t end = clock.now();
    recordTick(0, end - scheduled, end > scheduled + period);
    clock.advance(period);
  }
  return ok();
}

RealTimeLoop::RealTimeLoop(RealTimeLoopConfig config, TickFn tick)
    : impl_(std::make_unique<Impl>(std::move(config), std::move(tick))) {}

RealTimeLoop::~RealTimeLoop() = default;
RealTimeLoop::RealTimeLoop(RealTimeLoop&&) noexcept = default;
RealTimeLoop& RealTimeLoop::operator=(RealTimeLoop&&) noexcept = default;

Status RealTimeLoop::start() {
  DM_DEMAND(impl_ != nullptr, "RealTimeLoop used after move");
  return impl_->start();
}

void RealTimeLoop::stop() {
  if (impl_) impl_->stop();
}

void RealTimeLoop::requestStop() noexcept {
  if (impl_) impl_->stopRequested.store(true, std::memory_order_release);
}

bool RealTimeLoop::running() const noexcept {
  return impl_ && impl_->running.load(std::memory_order_acquire);
}

Status RealTimeLoop::runLockstep(VirtualClock& clock, std::uint64_t n) {
  DM_DEMAND(impl_ != nullptr, "RealTimeLoop used after move");
  return impl_->runLockstep(clock, n);
}

RealTimeLoopStats RealTimeLoop::stats() const noexcept {
  RealTimeLoopStats s;
  if (!impl_) return s;
  const Impl& m = *impl_;
  s.ticks = m.ticks.load(std::memory_order_relaxed);
  s.deadline_misses = m.misses.load(std::memory_order_relaxed);
  s.skipped_periods = m.skipped.load(std::memory_order_relaxed);
  s.execution = m.execution.summary();
  s.wakeup = m.wakeup.summary();
  s.period_ns = m.period;
  s.running = m.running.load(std::memory_order_acquire);
  s.rt_priority = m.rtPriority.load(std::memory_order_relaxed);
  s.pinned = m.pinned.load(std::memory_order_relaxed);
  s.spinning = m.spinning.load(std::memory_order_relaxed);
  s.tick_threw = m.tickThrew.load(std::memory_order_acquire);
  return s;
}

const LatencyHistogram& RealTimeLoop::executionHistogram() const noexcept {
  DM_DEMAND(impl_ != nullptr, "RealTimeLoop used after move");
  return impl_->execution;
}

const LatencyHistogram& RealTimeLoop::wakeupHistogram() const noexcept {
  DM_DEMAND(impl_ != nullptr, "RealTimeLoop used after move");
  return impl_->wakeup;
}

const RealTimeLoopConfig& RealTimeLoop::config() const noexcept {
  DM_DEMAND(impl_ != nullptr, "RealTimeLoop used after move");
  return impl_->config;
}

std::int64_t RealTimeLoop::periodNs() const noexcept { return impl_ ? impl_->period : 0; }

}  // namespace dm
