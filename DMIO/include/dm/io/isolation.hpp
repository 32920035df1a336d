// How DMIO runs a third-party parser (Assimp for meshes, OpenVDB for .vdb
// volumes) on a file: those parsers crash, loop or allocate what a length
// field asks on some malformed files (Tests/fuzz found all three), which no
// check of ours can fully prevent, so by default they run in another process
// with a deadline and a memory budget, and a crash, a hang or an allocation
// beyond the budget becomes a dm::Error.
//
//  * Helper (default): the `dm-isolate` helper program. It is started once
//    per process with posix_spawn (a fresh program: nothing of the caller's
//    threads, locks or heap comes along), ends the threads its libraries
//    start at load (DMCore's log drainer, log4cplus's pool under OpenVDB)
//    and forks each job from its one remaining thread; the job reads its
//    request from a sealed memory file and writes the result to a pipe.
//    Safe from any thread state of the caller, and per import about what a
//    fork costs. The helper ends when the caller's process does. It is
//    found, in this order, at $DM_ISOLATE_HELPER, beside the DMIO library
//    (libdmIO.so; the build tree), in <that folder>/dmplatform/ (installed:
//    <libdir>/dmplatform/dm-isolate), beside the running executable.
//  * Fork: a forked child of the caller. Fork copies only the calling
//    thread: if another thread held a lock at that instant (every DMPlatform
//    process has DMCore's log drainer and, with OpenVDB, log4cplus's pool;
//    under AddressSanitizer a child hung on the allocator's lock), the child
//    waits on it until its deadline. For fuzzers and benchmarks that know
//    their threads, not for applications.
//  * InProcess: no isolation, for trusted files; a hostile file can crash,
//    hang or exhaust the caller.
//
// What each costs per import: docs/performance.md ("Importer isolation",
// Bench/isolation_bench.cpp). What each protects against: docs/security.md.
#pragma once

#include <dm/core/result.hpp>

#include <string_view>

namespace dm {

enum class Isolation {
  Helper,    ///< the dm-isolate helper program (default; any thread state)
  Fork,      ///< a forked child (callers that know their threads)
  InProcess  ///< no isolation (trusted files only)
};

/// "helper", "fork", "in-process".
const char* toString(Isolation isolation) noexcept;

/// Parses "helper", "fork" or "in-process"; InvalidArgument naming the
/// accepted names otherwise.
Result<Isolation> parseIsolation(std::string_view text);

}  // namespace dm
