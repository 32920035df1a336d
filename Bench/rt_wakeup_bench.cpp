// The host's floor under a 1 kHz haptic loop: how late a SCHED_FIFO thread
// wakes for its deadline on this machine, with nothing in its tick.
//
// Ours: dm::RealTimeLoop at 1 kHz, SCHED_FIFO 80, an empty tick (its thread
// pre-faults its stack, timer slack 1 ns). Peer: the loop cyclictest
// (rt-tests) measures with — a SCHED_FIFO 80 thread in clock_nanosleep to
// absolute 1 ms deadlines — written out here, in the same process.
// Rounds alternate between the two; each prints the wake-up latency
// distribution, the deadlines missed (woken a whole period late) and the
// time the hypervisor stole meanwhile (/proc/stat). The process's memory is
// locked (dm::lockProcessMemory) when it may be. Run it on an idle machine
// and beside the main job: when the bare loop misses as the main job's
// haptic thread does, the misses are the host's.
//
//   rt_wakeup_bench [SECONDS_PER_ROUND=10] [ROUNDS=3]
#include <dm/core/host_cpu.hpp>
#include <dm/core/rt_loop.hpp>
#include <dm/core/rt_memory.hpp>

#include <pthread.h>
#include <sched.h>
#include <sys/prctl.h>
#include <time.h>

#include <atomic>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <thread>

namespace {

constexpr std::int64_t kPeriodNs = 1'000'000;
constexpr int kPriority = 80;

std::int64_t monotonicNs() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

struct Round {
  dm::LatencyHistogram::Summary wakeup;
  std::uint64_t ticks = 0, misses = 0;
  double stealS = 0.0;
  bool realTime = false;
};

// cyclictest's loop: absolute clock_nanosleep, latency = woken − deadline.
Round bareLoop(double seconds) {
  Round r;
  dm::LatencyHistogram h;
  std::atomic<bool> fifo{false};
  std::thread t([&] {
    sched_param p{};
    p.sched_priority = kPriority;
    fifo = pthread_setschedparam(pthread_self(), SCHED_FIFO, &p) == 0;
    prctl(PR_SET_TIMERSLACK, 1UL, 0UL, 0UL, 0UL);
    dm::prefaultStack();
    const std::int64_t end = monotonicNs() + static_cast<std::int64_t>(seconds * 1e9);
    std::int64_t next = monotonicNs() + kPeriodNs;
    while (next < end) {
      timespec ts{static_cast<time_t>(next / 1'000'000'000), static_cast<long>(next % 1'000'000'000)};
      while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) != 0) {
      }
      const std::int64_t late = monotonicNs() - next;
      h.record(late);
      ++r.ticks;
      if (late > kPeriodNs) {
        ++r.misses;
        next += (late / kPeriodNs) * kPeriodNs;  // skip the passed periods, as RealTimeLoop does
      }
      next += kPeriodNs;
    }
  });
  t.join();
  r.wakeup = h.summary();
  r.realTime = fifo;
  return r;
}

Round ourLoop(double seconds) {
  Round r;
  dm::RealTimeLoop loop({.rate_hz = 1000.0, .priority = kPriority, .name = "rt-bench"},
                        [](const dm::TickInfo&) {});
  if (auto s = loop.start(); !s) {
    std::fprintf(stderr, "%s\n", s.error().message().c_str());
    std::exit(1);
  }
  std::this_thread::sleep_for(std::chrono::duration<double>(seconds));
  const dm::RealTimeLoopStats st = loop.stats();
  loop.stop();
  r.wakeup = st.wakeup;
  r.ticks = st.ticks;
  r.misses = st.deadline_misses;
  r.realTime = st.rt_priority;
  return r;
}

void print(const char* name, const Round& r, double ratio) {
  std::printf("%-22s %7llu %8.1f %8.1f %8.1f %9.1f %6llu %8.3f %s", name,
              static_cast<unsigned long long>(r.ticks), r.wakeup.p50_us, r.wakeup.p99_us, r.wakeup.p999_us,
              r.wakeup.max_us, static_cast<unsigned long long>(r.misses), r.stealS,
              r.realTime ? "fifo" : "normal");
  if (ratio > 0)
    std::printf("  %6.3f\n", ratio);
  else
    std::printf("       -\n");
}

template <class F>
Round measured(F&& run) {
  const auto before = dm::readHostCpuTimes();
  Round r = run();
  const auto after = dm::readHostCpuTimes();
  if (before && after) r.stealS = after->steal_s - before->steal_s;
  return r;
}

}  // namespace

int main(int argc, char** argv) {
  const double seconds = argc > 1 ? std::atof(argv[1]) : 10.0;
  const int rounds = argc > 2 ? std::atoi(argv[2]) : 3;
  if (!(seconds > 0) || rounds < 1) {
    std::fprintf(stderr, "usage: rt_wakeup_bench [SECONDS_PER_ROUND > 0] [ROUNDS >= 1]\n");
    return 2;
  }
  const dm::Status locked = dm::lockProcessMemory();
  std::printf("1 kHz, SCHED_FIFO %d, %g s a round, memory %s\n", kPriority, seconds,
              locked ? "locked" : ("not locked: " + locked.error().message()).c_str());
  std::printf("%-22s %7s %8s %8s %8s %9s %6s %8s %s  %6s\n", "loop (wake-up, us)", "ticks", "p50", "p99",
              "p99.9", "max", "missed", "steal s", "sched", "p99.9 ratio");
  for (int i = 0; i < rounds; ++i) {
    const Round peer = measured([&] { return bareLoop(seconds); });
    const Round ours = measured([&] { return ourLoop(seconds); });
    print("clock_nanosleep (peer)", peer, 0.0);
    print("dm::RealTimeLoop", ours,
          peer.wakeup.p999_us > 0 ? ours.wakeup.p999_us / peer.wakeup.p999_us : 0.0);
  }
  return 0;
}
