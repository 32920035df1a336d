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

}  // namespace dm
