// rt_memory.cpp — mlockall, stack pre-faulting and getrusage's fault counts.
#include <dm/core/rt_memory.hpp>

#include <sys/mman.h>
#include <sys/resource.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <mutex>
#include <string>

#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#define DM_RT_MEMORY_SANITIZED 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer)
#define DM_RT_MEMORY_SANITIZED 1
#endif
#endif

namespace dm {

namespace {

constexpr const char* kWhere = "lockProcessMemory";

// The lock is counted: each lockProcessMemory() that succeeded holds it until
// its unlockProcessMemory() (two real-time runs in one process, the first to
// end must not unlock the other's memory). Not on a real-time path: a mutex.
std::mutex gMutex;
int gHolders = 0;  // guarded by gMutex
std::atomic<bool> gLocked{false};

// CAP_IPC_LOCK (capability 14) in the effective set: /proc/self/status's
// CapEff, a hexadecimal mask.
[[maybe_unused]] bool hasIpcLockCapability() {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("CapEff:", 0) != 0) continue;
    const unsigned long long mask = std::strtoull(line.c_str() + 7, nullptr, 16);
    return (mask >> 14) & 1ULL;
  }
  return false;
}

[[maybe_unused]] std::string limitText(rlim_t v) {
  return v == RLIM_INFINITY ? std::string("unlimited") : std::to_string(v / 1024) + " KiB";
}

PageFaults faultsOf(int who) noexcept {
  rusage u{};
  if (getrusage(who, &u) != 0) return {};
  return {static_cast<std::uint64_t>(u.ru_minflt), static_cast<std::uint64_t>(u.ru_majflt)};
}

}  // namespace

Status lockProcessMemory() {
#if defined(DM_RT_MEMORY_SANITIZED)
  return fail(ErrorCode::Unsupported, "memory is not locked under a sanitizer (its shadow maps terabytes)",
              kWhere, "run a build without sanitizers for real-time measurements");
#elif !defined(MCL_ONFAULT)
  return fail(ErrorCode::Unsupported, "mlockall(MCL_ONFAULT) is not available on this system", kWhere);
#else
  std::lock_guard lock(gMutex);
  if (gHolders > 0) {
    ++gHolders;
    return ok();
  }
  rlimit limit{};
  getrlimit(RLIMIT_MEMLOCK, &limit);
  // Without the capability the limit caps the locked bytes; with
  // MCL_FUTURE a later mapping past it would fail, so lock only when the
  // limit cannot be reached.
  if (limit.rlim_cur != RLIM_INFINITY && !hasIpcLockCapability())
    return fail(ErrorCode::Denied,
                "RLIMIT_MEMLOCK is " + limitText(limit.rlim_cur) + " and the process lacks CAP_IPC_LOCK",
                kWhere,
                "raise the limit (ulimit -l unlimited, or memlock in /etc/security/limits.conf) or grant "
                "CAP_IPC_LOCK");
  if (mlockall(MCL_CURRENT | MCL_FUTURE | MCL_ONFAULT) != 0) {
    const int err = errno;
    return fail(err == EPERM ? ErrorCode::Denied : ErrorCode::Unsupported,
                std::string("mlockall failed: ") + std::strerror(err), kWhere,
                "raise RLIMIT_MEMLOCK or grant CAP_IPC_LOCK");
  }
  gHolders = 1;
  gLocked.store(true, std::memory_order_release);
  return ok();
#endif
}

void unlockProcessMemory() noexcept {
  std::lock_guard lock(gMutex);
  if (gHolders == 0 || --gHolders > 0) return;
  munlockall();
  gLocked.store(false, std::memory_order_release);
}

bool processMemoryLocked() noexcept { return gLocked.load(std::memory_order_acquire); }

// Not inlined, so that the array is a frame of its own below the caller's;
// the empty asm reads the array, so that the compiler keeps every store.
[[gnu::noinline]] void prefaultStack(std::size_t bytes) noexcept {
  constexpr std::size_t kMax = 1024 * 1024;
  constexpr std::size_t kPage = 4096;
  unsigned char block[kMax];
  const std::size_t n = std::min(bytes, kMax);
  // The array's end is nearest the caller (stacks grow down): touch from
  // there, so that `bytes` below the caller are the ones mapped.
  for (std::size_t i = 0; i < n; i += kPage) block[kMax - 1 - i] = 0;
  asm volatile("" : : "r"(block) : "memory");
}

PageFaults readPageFaults() noexcept { return faultsOf(RUSAGE_SELF); }

PageFaults readThreadPageFaults() noexcept {
#if defined(RUSAGE_THREAD)
  return faultsOf(RUSAGE_THREAD);
#else
  return faultsOf(RUSAGE_SELF);
#endif
}

}  // namespace dm
