// Thread CPU time for the benchmark programs.
#pragma once

#include <cstdint>
#include <ctime>

namespace dm::bench {

/// Thread CPU time now, ns: unlike wall time it does not count the time this
/// thread waits while other processes run on a shared machine.
inline std::int64_t threadCpuNs() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return std::int64_t{ts.tv_sec} * 1'000'000'000 + ts.tv_nsec;
}

}  // namespace dm::bench
