// Per-call latency rows for the benchmark programs: wall time and thread
// CPU time of each call in dm::LatencyHistograms, printed as one row of
// count, mean, p50, p99, p99.9 and max (µs), CPU mean and p99.9, and a
// ratio to a peer row.
#pragma once

#include <dm/core/rt_loop.hpp>

#include <chrono>
#include <cstdint>
#include <cstdio>

#include "bench_cpu_clock.hpp"

namespace dm::bench {

struct LatencyRow {
  dm::LatencyHistogram wall, cpu;
};

/// Times one call into `row`.
template <class F>
void timeCall(LatencyRow& row, F&& call) {
  const std::int64_t c0 = threadCpuNs();
  const auto t0 = std::chrono::steady_clock::now();
  call();
  const auto t1 = std::chrono::steady_clock::now();
  row.wall.record(std::chrono::duration_cast<std::chrono::nanoseconds>(t1 - t0).count());
  row.cpu.record(threadCpuNs() - c0);
}

/// One row; `ratio` ≤ 0 prints "-".
inline void printLatencyRow(const char* name, const LatencyRow& r, double ratio) {
  const dm::LatencyHistogram::Summary s = r.wall.summary(), c = r.cpu.summary();
  std::printf("%-16s %7llu %10.2f %10.2f %10.2f %10.2f %10.2f %10.2f %10.2f", name,
              static_cast<unsigned long long>(s.count), s.mean_us, s.p50_us, s.p99_us, s.p999_us, s.max_us,
              c.mean_us, c.p999_us);
  if (ratio > 0)
    std::printf("  %8.4f\n", ratio);
  else
    std::printf("  %8s\n", "-");
}

}  // namespace dm::bench
