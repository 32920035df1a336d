// Logging on spdlog. The real-time path is a bounded lock-free MPMC queue
// (Vyukov) of fixed-size slots in static storage, drained by one background
// thread into the same spdlog logger, so rt() never allocates or blocks.
#include <dm/core/log.hpp>

#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <array>
#include <atomic>
#include <chrono>
#include <cstdarg>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <mutex>
#include <string>
#include <thread>

namespace dm::log {
namespace {

spdlog::level::level_enum toSpd(Level l) {
  switch (l) {
    case Level::Trace:
      return spdlog::level::trace;
    case Level::Debug:
      return spdlog::level::debug;
    case Level::Info:
      return spdlog::level::info;
    case Level::Warn:
      return spdlog::level::warn;
    case Level::Error:
      return spdlog::level::err;
    case Level::Critical:
      return spdlog::level::critical;
    case Level::Off:
      return spdlog::level::off;
  }
  return spdlog::level::info;
}

Level levelFromEnv() {
  const char* e = std::getenv("DM_LOG_LEVEL");
  if (!e) return Level::Info;
  const std::string s(e);
  for (int i = 0; i <= static_cast<int>(Level::Off); ++i)
    if (s == toString(static_cast<Level>(i))) return static_cast<Level>(i);
  return Level::Info;
}

struct Slot {
  std::atomic<std::size_t> seq{0};
  Level level = Level::Info;
  std::array<char, kRtMessageBytes> text{};
};

// The real-time queue. Slots live in static storage: nothing is allocated
// after the first touch of the logging state.
class RtQueue {
 public:
  RtQueue() {
    for (std::size_t i = 0; i < kRtQueueSlots; ++i) slots_[i].seq.store(i, std::memory_order_relaxed);
  }
  // Claims a slot, formats into it, publishes it. Lock-free for producers.
  bool push(Level level, const char* fmt, va_list args) noexcept {
    std::size_t pos = tail_.load(std::memory_order_relaxed);
    Slot* slot = nullptr;
    for (;;) {
      slot = &slots_[pos & kMask];
      const std::size_t seq = slot->seq.load(std::memory_order_acquire);
      const auto dif = static_cast<std::ptrdiff_t>(seq) - static_cast<std::ptrdiff_t>(pos);
      if (dif == 0) {
        if (tail_.compare_exchange_weak(pos, pos + 1, std::memory_order_relaxed)) break;
      } else if (dif < 0) {
        dropped_.fetch_add(1, std::memory_order_relaxed);
        return false;
      } else {
        pos = tail_.load(std::memory_order_relaxed);
      }
    }
    slot->level = level;
    std::vsnprintf(slot->text.data(), slot->text.size(), fmt, args);
    slot->seq.store(pos + 1, std::memory_order_release);
    return true;
  }
  // Single consumer (the drain thread, or flush() under drainMutex).
  template <class F>
  std::size_t drain(F&& consume) {
    std::size_t n = 0;
    for (;;) {
      Slot& slot = slots_[head_ & kMask];
      if (slot.seq.load(std::memory_order_acquire) != head_ + 1) return n;
      consume(slot.level, std::string_view(slot.text.data()));
      slot.seq.store(head_ + kRtQueueSlots, std::memory_order_release);
      ++head_;
      ++n;
    }
  }
  std::uint64_t dropped() const noexcept { return dropped_.load(std::memory_order_relaxed); }

 private:
  static_assert((kRtQueueSlots & (kRtQueueSlots - 1)) == 0, "slots must be a power of two");
  static constexpr std::size_t kMask = kRtQueueSlots - 1;
  std::array<Slot, kRtQueueSlots> slots_;
  alignas(64) std::atomic<std::size_t> tail_{0};
  alignas(64) std::size_t head_ = 0;
  alignas(64) std::atomic<std::uint64_t> dropped_{0};
};

struct State {
  std::shared_ptr<spdlog::logger> logger;
  std::atomic<Level> level{Level::Info};
  std::mutex sinkMutex;  // guards sink; never taken on the real-time path
  Sink sink;
  RtQueue queue;
  std::mutex drainMutex;  // one consumer of the queue at a time
  std::atomic<bool> running{true};
  std::mutex stopMutex;  // one joiner of the drainer
  std::thread drainer;

  State() {
    logger = std::make_shared<spdlog::logger>("dm", std::make_shared<spdlog::sinks::stderr_color_sink_mt>());
    logger->set_pattern("%H:%M:%S.%e %^%-5l%$ %v");
    logger->set_level(spdlog::level::trace);  // filtering happens here, in `level`
    level.store(levelFromEnv());
    drainer = std::thread([this] {
      while (running.load(std::memory_order_acquire)) {
        if (drainOnce() == 0) std::this_thread::sleep_for(std::chrono::milliseconds(2));
      }
    });
  }
  ~State() {
    stopDrainer();
    logger->flush();
  }
  void stopDrainer() {
    std::lock_guard lock(stopMutex);
    running.store(false, std::memory_order_release);
    if (drainer.joinable()) drainer.join();
    drainOnce();
  }
  std::size_t drainOnce() {
    std::lock_guard lock(drainMutex);
    return queue.drain([this](Level l, std::string_view text) { emit(l, text); });
  }
  void emit(Level l, std::string_view text) {
    logger->log(toSpd(l), "{}", text);
    std::lock_guard lock(sinkMutex);
    if (sink) sink(l, text);
  }
};

State& state() {
  static State s;
  return s;
}

// Touch the state at load time so the drain thread exists before any
// real-time thread calls rt(), and rt() never constructs anything.
[[maybe_unused]] const bool kStarted = (state(), true);

void vmessage(Level l, const char* fmt, va_list args) {
  if (!enabled(l)) return;
  char small[512];
  va_list copy;
  va_copy(copy, args);
  const int n = std::vsnprintf(small, sizeof small, fmt, copy);
  va_end(copy);
  if (n < 0) return;
  if (static_cast<std::size_t>(n) < sizeof small) {
    state().emit(l, std::string_view(small, static_cast<std::size_t>(n)));
    return;
  }
  std::string big(static_cast<std::size_t>(n) + 1, '\0');
  std::vsnprintf(big.data(), big.size(), fmt, args);
  big.resize(static_cast<std::size_t>(n));
  state().emit(l, big);
}

}  // namespace

const char* toString(Level level) noexcept {
  switch (level) {
    case Level::Trace:
      return "trace";
    case Level::Debug:
      return "debug";
    case Level::Info:
      return "info";
    case Level::Warn:
      return "warn";
    case Level::Error:
      return "error";
    case Level::Critical:
      return "critical";
    case Level::Off:
      return "off";
  }
  return "info";
}

void setLevel(Level level) noexcept { state().level.store(level, std::memory_order_relaxed); }
Level level() noexcept { return state().level.load(std::memory_order_relaxed); }
bool enabled(Level l) noexcept { return l != Level::Off && l >= level(); }

#define DM_LOG_FORWARD(lvl)   \
  va_list args;               \
  va_start(args, fmt);        \
  vmessage((lvl), fmt, args); \
  va_end(args)

void message(Level l, const char* fmt, ...) { DM_LOG_FORWARD(l); }
void trace(const char* fmt, ...) { DM_LOG_FORWARD(Level::Trace); }
void debug(const char* fmt, ...) { DM_LOG_FORWARD(Level::Debug); }
void info(const char* fmt, ...) { DM_LOG_FORWARD(Level::Info); }
void warn(const char* fmt, ...) { DM_LOG_FORWARD(Level::Warn); }
void error(const char* fmt, ...) { DM_LOG_FORWARD(Level::Error); }
#undef DM_LOG_FORWARD

bool rt(Level l, const char* fmt, ...) noexcept {
  if (!enabled(l)) return false;
  va_list args;
  va_start(args, fmt);
  const bool pushed = state().queue.push(l, fmt, args);
  va_end(args);
  return pushed;
}

std::uint64_t rtDropped() noexcept { return state().queue.dropped(); }

void flush() {
  state().drainOnce();
  state().logger->flush();
}

void stopDrainThread() { state().stopDrainer(); }

void setSink(Sink sink) {
  std::lock_guard lock(state().sinkMutex);
  state().sink = std::move(sink);
}

}  // namespace dm::log
