// Isolation of third-party parsers: what the forked child and the helper's
// jobs share (the result writer and reader, the memory budget, the caller's
// collection of a result) and the forked child itself; the helper is in
// isolate_helper.cpp. See isolate.hpp.
#include "isolate.hpp"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>
#if defined(__linux__)
#include <sys/prctl.h>
#endif

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <new>

#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#define DM_ISOLATE_SANITIZED 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer)
#define DM_ISOLATE_SANITIZED 1
#endif
#endif

#if defined(DM_ISOLATE_SANITIZED)
// The sanitizers' allocator interface (clang ships the header, GCC only the
// runtime symbols): hooks called after every heap allocation and before
// every free, and the size of a live allocation.
extern "C" int __sanitizer_install_malloc_and_free_hooks(void (*mallocHook)(const volatile void*, std::size_t),
                                                         void (*freeHook)(const volatile void*));
extern "C" std::size_t __sanitizer_get_allocated_size(const volatile void* p);
#endif

#if defined(__SANITIZE_ADDRESS__)
#define DM_ISOLATE_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define DM_ISOLATE_ASAN 1
#endif
#endif

#if defined(DM_ISOLATE_ASAN)
// AddressSanitizer reports an allocation it cannot serve (one beyond its
// largest size, or one the kernel refuses to map) and dies before any
// allocator hook or new-handler sees it; these let the child tell that
// report from a real memory error of ours.
extern "C" void __sanitizer_set_death_callback(void (*callback)(void));
extern "C" const char* __asan_get_report_description();
#endif

namespace dm::detail {

void FdWriter::bytes(const void* data, std::size_t n) {
  const char* p = static_cast<const char*>(data);
  while (n > 0 && ok_) {
    const ssize_t w = ::write(fd_, p, n);
    if (w < 0 && errno == EINTR) continue;
    if (w <= 0) {
      ok_ = false;
      return;
    }
    p += w;
    n -= static_cast<std::size_t>(w);
  }
}

void FdWriter::error(const Error& e) {
  u64(static_cast<std::uint64_t>(e.code));
  str(e.what);
  str(e.where);
  str(e.hint);
}

bool ByteReader::bytes(void* out, std::size_t n) {
  if (remaining() < n) return ok_ = false;
  if (n > 0) std::memcpy(out, p_, n);
  p_ += n;
  return true;
}

std::string ByteReader::str() {
  const std::uint64_t n = u64();
  if (!ok_ || n > remaining()) {
    ok_ = false;
    return {};
  }
  std::string s(p_, static_cast<std::size_t>(n));
  p_ += n;
  return s;
}

Error ByteReader::error() {
  Error e;
  const std::uint64_t code = u64();
  e.what = str();
  e.where = str();
  e.hint = str();
  // The other process's error must name a known code and say what failed
  // (found by Tests/fuzz/isolate_result_fuzz.cpp: an empty one got through).
  if (code > static_cast<std::uint64_t>(ErrorCode::Denied) || e.what.empty()) ok_ = false;
  e.code = ok_ ? static_cast<ErrorCode>(code) : ErrorCode::Internal;
  return e;
}

namespace {

// The child's exit status when it exceeded its memory budget.
constexpr int kBudgetExitStatus = 86;

[[noreturn]] void exitOverBudget() { ::_exit(kBudgetExitStatus); }

#if defined(DM_ISOLATE_SANITIZED)
// Heap bytes allocated in the child since the hooks went in, minus those
// freed (frees of blocks from before the fork make it negative).
std::atomic<long long> gHeapGrowth{0};
long long gHeapBudget = 0;

void budgetMallocHook(const volatile void*, std::size_t size) {
  const auto n = static_cast<long long>(size);
  if (gHeapGrowth.fetch_add(n, std::memory_order_relaxed) + n > gHeapBudget) exitOverBudget();
}

void budgetFreeHook(const volatile void* p) {
  if (p != nullptr)
    gHeapGrowth.fetch_sub(static_cast<long long>(__sanitizer_get_allocated_size(p)), std::memory_order_relaxed);
}
#endif

#if defined(DM_ISOLATE_ASAN)
// An allocation AddressSanitizer could not serve is over any budget (it asked
// for more than the machine or the allocator has): the child ends as over
// budget. A death with no report at all is the runtime's own consistency
// check failing — e.g. "CHECK failed: asan_allocator.cpp ... kAllocBegMagic"
// when a block's header was overwritten — which our instrumented code cannot
// cause without a report of its own first: the uninstrumented library wrote
// past its memory (mesh_fuzz found a PLY on which Assimp 5.2.4 writes past a
// new[] block; valgrind shows the write). That is the library crashing, and
// the child ends as a crash does (an UndefinedBehaviorSanitizer death has
// no AddressSanitizer report either, and ends so too: the import fails all
// the same). Every other report (a memory error) still ends it with the
// sanitizer's exit status. Test: IsolateHelper.AHeapTheLibraryCorruptedIsACrash.
void budgetDeathCallback() {
  const char* bug = __asan_get_report_description();
  if (bug == nullptr || *bug == '\0') {  // clang 14's runtime gives "" then
    struct sigaction sa {};
    sa.sa_handler = SIG_DFL;
    sigemptyset(&sa.sa_mask);
    ::sigaction(SIGABRT, &sa, nullptr);
    sigset_t abrt;
    sigemptyset(&abrt);
    sigaddset(&abrt, SIGABRT);
    ::sigprocmask(SIG_UNBLOCK, &abrt, nullptr);
    ::raise(SIGABRT);
    ::_exit(128 + SIGABRT);  // not reached
  }
  for (const char* kind : {"out-of-memory", "allocation-size-too-big", "calloc-overflow", "pvalloc-overflow",
                           "invalid-allocation-alignment", "rss-limit-exceeded"})
    if (std::strcmp(bug, kind) == 0) exitOverBudget();
}
#endif

}  // namespace

// Caps what the child may allocate beyond what it holds now at `budget`:
// RLIMIT_AS on the address space, or, under the sanitizers (whose shadow
// memory needs the address space), allocator hooks counting heap bytes. A
// failed operator new ends the child with kBudgetExitStatus either way, so
// the parent can tell "out of budget" from a crash.
void limitMemory(std::size_t budget) {
  if (budget == 0) return;
  std::set_new_handler(exitOverBudget);
#if defined(DM_ISOLATE_ASAN)
  __sanitizer_set_death_callback(budgetDeathCallback);
#endif
#if defined(DM_ISOLATE_SANITIZED)
  gHeapBudget = static_cast<long long>(std::min<std::size_t>(budget, std::size_t{1} << 60));
  __sanitizer_install_malloc_and_free_hooks(budgetMallocHook, budgetFreeHook);
#else
  std::size_t pages = 0;
  std::ifstream statm("/proc/self/statm");
  if (!(statm >> pages)) return;
  const std::size_t mapped = pages * static_cast<std::size_t>(::sysconf(_SC_PAGESIZE));
  rlimit lim{};
  lim.rlim_cur = lim.rlim_max = static_cast<rlim_t>(mapped + budget);
  ::setrlimit(RLIMIT_AS, &lim);
#endif
}

namespace {

std::string mebibytes(std::size_t bytes) {
  char text[32];
  std::snprintf(text, sizeof text, "%.0f MiB", static_cast<double>(bytes) / (1024.0 * 1024.0));
  return text;
}

}  // namespace

Result<IsolatedRun> collectChild(const ChildControl& child, int readFd, const IsolateOptions& options,
                                 const std::string& where) {
  IsolatedRun run;
  const auto start = std::chrono::steady_clock::now();
  bool timedOut = false, readError = false;
  char chunk[1 << 16];
  for (;;) {
    int waitMs = -1;
    if (options.timeoutSeconds > 0) {
      const double left = options.timeoutSeconds -
                          std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      if (left <= 0) {
        timedOut = true;
        break;
      }
      waitMs = static_cast<int>(std::min(std::ceil(left * 1000), 1e9));
    }
    pollfd pfd{readFd, POLLIN, 0};
    const int pr = ::poll(&pfd, 1, waitMs);
    if (pr < 0 && errno == EINTR) continue;
    if (pr < 0) {
      readError = true;
      break;
    }
    if (pr == 0) continue;  // the deadline is checked at the top
    const ssize_t n = ::read(readFd, chunk, sizeof chunk);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) readError = true;
    if (n <= 0) break;  // end of data (or error)
    run.bytes.insert(run.bytes.end(), chunk, chunk + n);
  }
  ::close(readFd);
  if (timedOut) child.kill();
  const std::optional<int> ended = child.wait();
  const bool known = ended.has_value();
  const int status = ended.value_or(0);

  if (timedOut) {
    char secs[32];
    std::snprintf(secs, sizeof secs, "%g", options.timeoutSeconds);
    return fail(ErrorCode::Timeout,
                options.library + " did not finish reading the file within " + secs + " s", where,
                options.timeoutHint);
  }
  if (known && WIFSIGNALED(status))
    return fail(ErrorCode::Parse,
                options.library + " crashed while reading the file (signal " +
                    std::to_string(WTERMSIG(status)) + ", " + strsignal(WTERMSIG(status)) + ")",
                where, options.crashHint);
  if (known && WIFEXITED(status) && WEXITSTATUS(status) == kBudgetExitStatus && options.memoryBudget > 0)
    return fail(ErrorCode::Unsupported,
                options.library + " needed more than its memory budget of " + mebibytes(options.memoryBudget) +
                    " while reading the file",
                where, options.budgetHint);
  if (readError)
    return fail(ErrorCode::Io, "reading the result of the " + options.library + " process failed", where,
                options.disableHint);
  run.exitInfo = !known              ? std::string("status unknown")
                 : WIFEXITED(status) ? "exit status " + std::to_string(WEXITSTATUS(status))
                                     : std::string("stopped");
  return run;
}

Result<IsolatedRun> runIsolated(const std::function<void(FdWriter&)>& child, const IsolateOptions& options,
                                const std::string& where) {
  int fds[2];
  if (::pipe2(fds, O_CLOEXEC) != 0)
    return fail(ErrorCode::Io,
                "cannot create a pipe for the " + options.library + " process: " + std::strerror(errno),
                where, options.disableHint);
  // Unwritten stdio buffers would be inherited and could be written twice.
  std::fflush(nullptr);
  const pid_t pid = ::fork();
  if (pid < 0) {
    const int err = errno;
    ::close(fds[0]);
    ::close(fds[1]);
    return fail(ErrorCode::Io, "cannot start the " + options.library + " process: " + std::strerror(err),
                where, options.disableHint);
  }
  if (pid == 0) {
    // Child: die plainly on a fault (the parent's crash handlers are not
    // ours to run), never outlive the parent's deadline, never return.
    for (int sig : {SIGSEGV, SIGBUS, SIGFPE, SIGILL, SIGABRT, SIGPIPE}) std::signal(sig, SIG_DFL);
#if defined(__linux__)
    ::prctl(PR_SET_PDEATHSIG, SIGKILL);
#endif
    if (options.timeoutSeconds > 0) ::alarm(static_cast<unsigned>(std::ceil(options.timeoutSeconds)) + 1);
    ::close(fds[0]);
#if defined(__linux__)
    // Pipes of isolated runs on other threads must not stay open here, or
    // their readers would wait for this child to end before seeing EOF.
    if (fds[1] > 3) ::close_range(3, static_cast<unsigned>(fds[1]) - 1, 0);
    ::close_range(static_cast<unsigned>(fds[1]) + 1, ~0u, 0);
#endif
    limitMemory(options.memoryBudget);
    FdWriter w(fds[1]);
    child(w);
    ::close(fds[1]);
    ::_exit(w.ok() ? 0 : 3);
  }
  ::close(fds[1]);
  ChildControl control;
  control.kill = [pid] { ::kill(pid, SIGKILL); };
  control.wait = [pid]() -> std::optional<int> {
    int status = 0;
    pid_t waited;
    do waited = ::waitpid(pid, &status, 0);
    while (waited < 0 && errno == EINTR);
    if (waited != pid) return std::nullopt;
    return status;
  };
  return collectChild(control, fds[0], options, where);
}

}  // namespace dm::detail
