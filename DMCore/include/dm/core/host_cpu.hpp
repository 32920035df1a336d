// dm/core/host_cpu.hpp — the machine's CPU time accounts, for telling a
// deadline miss the program caused from one the host caused.
//
// On a virtual machine the hypervisor can stop a virtual CPU to run another
// guest; Linux counts that time as "steal" in /proc/stat. A SCHED_FIFO loop
// that misses a deadline while steal grows was not running at all, whatever
// its priority. The main job reports the steal of its running phase next to
// the deadline misses (summary.json "host"), so a run on a busy host is told
// apart from a slow tick.
//
// It also says which SIMD instruction set the kernels that are compiled more
// than once (the mass–spring step, the contact solver) run with here:
// simdLevel(), which the environment variable DM_SIMD can cap.
//
// @code
//   auto before = dm::readHostCpuTimes();
//   run();
//   auto after = dm::readHostCpuTimes();
//   if (before && after) dm::log::info("steal %.3f s", after->steal_s - before->steal_s);
// @endcode
#pragma once

#include <dm/core/result.hpp>

#include <string_view>

namespace dm {

/// CPU time summed over all CPUs since boot, in seconds.
struct HostCpuTimes {
  double busy_s = 0.0;   ///< user + nice + system + irq + softirq
  double idle_s = 0.0;   ///< idle + iowait
  double steal_s = 0.0;  ///< the hypervisor ran something else while this machine's CPUs wanted to run
  int cpus = 0;          ///< CPUs listed (cpu0, cpu1, ...)
};

/// Parses the text of /proc/stat: the aggregate "cpu" line's fields (user
/// nice system idle iowait irq softirq steal ..., in `ticksPerSecond` units;
/// kernels before 2.6.11 have no steal field, read as 0) and the count of
/// "cpuN" lines. Fails naming the line and field on text without
/// an aggregate line, a field that is not a non-negative integer, fewer than
/// four fields (Parse), or ticksPerSecond <= 0 (InvalidArgument).
Result<HostCpuTimes> parseProcStat(std::string_view text, double ticksPerSecond);

/// Reads /proc/stat (ticks per second from sysconf(_SC_CLK_TCK)). Unsupported
/// on systems without it (not Linux); NotFound or Io if it cannot be read.
Result<HostCpuTimes> readHostCpuTimes();

/// The instruction sets of the kernels compiled once per set and picked at
/// run time (GCC on x86-64): SSE2 (the baseline), AVX2, and AVX-512 with VL
/// (x86-64-v4). The mass–spring step gives the same bits with each.
enum class SimdLevel : int { Sse2 = 0, Avx2 = 1, Avx512 = 2 };

/// "sse2", "avx2" or "avx512".
const char* toString(SimdLevel level) noexcept;

/// Parses a level by its name (toString); InvalidArgument naming the text
/// and the accepted names otherwise.
Result<SimdLevel> parseSimdLevel(std::string_view text);

/// The level the run-time picked kernels use: the widest this CPU runs (Sse2
/// where they are not built more than once), capped by the environment
/// variable DM_SIMD when it is set (e.g. DM_SIMD=sse2 to compare a result
/// with the baseline's). A DM_SIMD that does not parse is logged once as a
/// warning and ignored. Decided on the first call; thread-safe.
SimdLevel simdLevel() noexcept;

}  // namespace dm
