// dm/core/rt_memory.hpp — keeping a real-time thread's memory in RAM: the
// process's pages locked, the thread's stack touched before its first tick,
// and the page faults a run took, counted.
//
// A page fault in a haptic tick costs from microseconds (a minor fault: the
// page is in RAM but not yet mapped, e.g. a stack page touched for the first
// time) to milliseconds (a major fault: the page was evicted and is read
// back from disk, e.g. code of the shared libraries under memory pressure).
// lockProcessMemory() keeps every page the process has, and every page it
// maps later, in RAM once touched (mlockall with MCL_ONFAULT, so that large
// reservations — a sanitizer's shadow, a renderer's pools — are not filled
// in); prefaultStack() touches the first part of the calling thread's stack
// so that the ticks' frames are mapped before the first deadline
// (RealTimeLoop does it at its thread's start); readPageFaults() says how
// many faults a run took (the main job reports them in summary.json "host").
//
// Locking needs CAP_IPC_LOCK (root has it) or an RLIMIT_MEMLOCK large
// enough; without either it fails saying which limit to raise, and the
// caller runs on unlocked (the main job logs a warning). Under a sanitizer
// (whose shadow maps terabytes) it is Unsupported.
//
// @code
//   if (auto s = dm::lockProcessMemory(); !s) dm::log::warn("%s", s.error().message().c_str());
//   ... run ...
//   dm::unlockProcessMemory();
// @endcode
#pragma once

#include <dm/core/result.hpp>

#include <cstddef>
#include <cstdint>

namespace dm {

/// Locks the process's pages in RAM: those it has, and those it maps or
/// touches later (mlockall(MCL_CURRENT | MCL_FUTURE | MCL_ONFAULT)). Denied
/// naming RLIMIT_MEMLOCK and CAP_IPC_LOCK when neither allows it;
/// Unsupported under a sanitizer or where mlockall is not available.
/// The lock is counted: each call that succeeded holds it (thread-safe).
Status lockProcessMemory();

/// Gives back one successful lockProcessMemory(); the last one unlocks
/// (munlockall). A no-op when none is held.
void unlockProcessMemory() noexcept;

/// True while lockProcessMemory()'s lock is in force.
bool processMemoryLocked() noexcept;

/// Stack bytes prefaultStack() touches by default: more than the deepest
/// tick of the engines (collision queries, the renderers' solvers) uses.
inline constexpr std::size_t kRealTimeStackBytes = 256 * 1024;

/// Touches `bytes` (at most 1 MiB) of the calling thread's stack below the
/// caller's frame, one write per page, so that they are mapped. Real-time
/// safe once done; call it at a thread's start, not in a tick.
void prefaultStack(std::size_t bytes = kRealTimeStackBytes) noexcept;

/// Page faults taken so far (getrusage): minor (mapped without I/O) and
/// major (read back from disk).
struct PageFaults {
  std::uint64_t minor = 0;
  std::uint64_t major = 0;
};

/// The whole process's faults.
PageFaults readPageFaults() noexcept;

/// The calling thread's faults (RUSAGE_THREAD; the process's where that is
/// not available).
PageFaults readThreadPageFaults() noexcept;

}  // namespace dm
