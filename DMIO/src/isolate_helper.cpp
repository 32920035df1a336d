// The dm-isolate helper (Isolation::Helper; see isolate.hpp): the caller's
// side, which starts the helper once per process and hands it jobs, and the
// helper's side, which serves them.
//
// The helper is a fresh program (posix_spawn: no fork of the caller, so no
// lock another thread of the caller held comes along) with one thread. For
// each job it forks a child of that single thread — safe, and about as
// cheap as Isolation::Fork, instead of an exec and the dynamic linking of
// Assimp and OpenVDB (~50 ms) per import. The caller sends a job on a
// SOCK_SEQPACKET control socket with three descriptors: the request (a
// sealed memory file), the result pipe's write end and a status socket on
// which the helper answers the child's pid (with a pidfd, to end it at the
// deadline) and later its wait status. The helper ends, ending its
// children, when the control socket closes: when the caller's process ends.
#include <dm/core/helper_program.hpp>
#include <dm/core/log.hpp>
#include <dm/io/isolation.hpp>

#include <dirent.h>
#include <dlfcn.h>
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/mman.h>
#include <sys/signalfd.h>
#include <sys/socket.h>
#include <sys/syscall.h>
#include <sys/wait.h>
#include <unistd.h>
#if defined(__linux__)
#include <sys/prctl.h>
#endif

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <map>
#include <mutex>
#include <utility>
#include <vector>

#include "isolate.hpp"

namespace dm {

const char* toString(Isolation isolation) noexcept {
  switch (isolation) {
    case Isolation::Helper:
      return "helper";
    case Isolation::Fork:
      return "fork";
    case Isolation::InProcess:
      return "in-process";
  }
  return "unknown";
}

Result<Isolation> parseIsolation(std::string_view text) {
  for (Isolation i : {Isolation::Helper, Isolation::Fork, Isolation::InProcess})
    if (text == toString(i)) return i;
  return fail(ErrorCode::InvalidArgument, "'" + std::string(text) + "' is no isolation", "",
              "give helper, fork or in-process");
}

}  // namespace dm

namespace dm::detail {

namespace {

// Owns a descriptor.
class Fd {
 public:
  Fd() = default;
  explicit Fd(int fd) : fd_(fd) {}
  Fd(const Fd&) = delete;
  Fd& operator=(const Fd&) = delete;
  ~Fd() { reset(); }
  int get() const { return fd_; }
  int release() { return std::exchange(fd_, -1); }
  void reset(int fd = -1) {
    if (fd_ >= 0) ::close(fd_);
    fd_ = fd;
  }

 private:
  int fd_ = -1;
};

// `fd` moved above 9 (close-on-exec), so that a spawn's file actions (dup2
// onto 0 and 3) never overwrite one of their own sources.
int highFd(int fd) {
  if (fd < 0 || fd > 9) return fd;
  const int moved = ::fcntl(fd, F_DUPFD_CLOEXEC, 10);
  ::close(fd);
  return moved;
}

// A job on the control socket, with three descriptors: the request, the
// result pipe's write end, the status socket.
struct JobMessage {
  char job[64];
  double timeoutSeconds;
  std::uint64_t memoryBudget;
};

// The helper's answers on a job's status socket.
struct StatusMessage {
  std::int32_t type;
  std::int32_t value;
};
constexpr std::int32_t kStarted = 1;     // value: the child's pid (with its pidfd)
constexpr std::int32_t kEnded = 2;       // value: its wait status
constexpr std::int32_t kUnknownJob = 3;  // the helper has no such job

bool sendWithFds(int socket, const void* data, std::size_t size, const int* fds, int count) {
  iovec iov{const_cast<void*>(data), size};
  alignas(cmsghdr) char control[CMSG_SPACE(sizeof(int) * 4)] = {};
  msghdr msg{};
  msg.msg_iov = &iov;
  msg.msg_iovlen = 1;
  if (count > 0) {
    msg.msg_control = control;
    msg.msg_controllen = CMSG_SPACE(sizeof(int) * static_cast<std::size_t>(count));
    cmsghdr* c = CMSG_FIRSTHDR(&msg);
    c->cmsg_level = SOL_SOCKET;
    c->cmsg_type = SCM_RIGHTS;
    c->cmsg_len = CMSG_LEN(sizeof(int) * static_cast<std::size_t>(count));
    std::memcpy(CMSG_DATA(c), fds, sizeof(int) * static_cast<std::size_t>(count));
  }
  ssize_t n;
  do n = ::sendmsg(socket, &msg, MSG_NOSIGNAL);
  while (n < 0 && errno == EINTR);
  return n == static_cast<ssize_t>(size);
}

// One message and up to `maxFds` descriptors (close-on-exec); the byte count
// (0: the other side closed), or -1 with errno.
ssize_t receiveWithFds(int socket, void* data, std::size_t size, int* fds, int maxFds, int& received) {
  iovec iov{data, size};
  alignas(cmsghdr) char control[CMSG_SPACE(sizeof(int) * 4)] = {};
  msghdr msg{};
  msg.msg_iov = &iov;
  msg.msg_iovlen = 1;
  msg.msg_control = control;
  msg.msg_controllen = sizeof control;
  ssize_t n;
  do n = ::recvmsg(socket, &msg, MSG_CMSG_CLOEXEC);
  while (n < 0 && errno == EINTR);
  received = 0;
  for (cmsghdr* c = CMSG_FIRSTHDR(&msg); n >= 0 && c != nullptr; c = CMSG_NXTHDR(&msg, c)) {
    if (c->cmsg_level != SOL_SOCKET || c->cmsg_type != SCM_RIGHTS) continue;
    const int count = static_cast<int>((c->cmsg_len - CMSG_LEN(0)) / sizeof(int));
    for (int i = 0; i < count; ++i) {
      int fd;
      std::memcpy(&fd, CMSG_DATA(c) + sizeof(int) * static_cast<std::size_t>(i), sizeof fd);
      if (received < maxFds)
        fds[received++] = fd;
      else
        ::close(fd);
    }
  }
  return n;
}

// Waits up to `seconds` for a message on `socket`; false on silence.
bool readable(int socket, double seconds) {
  pollfd p{socket, POLLIN, 0};
  int r;
  do r = ::poll(&p, 1, static_cast<int>(std::min(seconds * 1000.0, 1e9)));
  while (r < 0 && errno == EINTR);
  return r > 0;
}

// Debian 12's glibc 2.36 declares pidfd_open() and pidfd_send_signal()
// without C linkage (sys/pidfd.h lacks __BEGIN_DECLS), so the system calls
// are made directly.
int pidfdOpen(pid_t pid) { return static_cast<int>(::syscall(SYS_pidfd_open, pid, 0)); }
void pidfdKill(int pidfd) { ::syscall(SYS_pidfd_send_signal, pidfd, SIGKILL, nullptr, 0); }

// A marker whose address dladdr() maps to the file DMIO was loaded from.
const char kLibraryAnchor = 0;

// The caller's side: one helper per process, started at the first job and
// again if it has gone.
class HelperServer {
 public:
  static HelperServer& instance() {
    static HelperServer* server = new HelperServer;  // lives as long as the process
    return *server;
  }

  Status submit(const std::string& program, const JobMessage& job, const int fds[3],
                const IsolateOptions& options, const std::string& where) {
    std::lock_guard<std::mutex> lock(mutex_);
    for (int attempt = 0;; ++attempt) {
      // A fork of this process, or another program asked for: a helper of
      // its own.
      if (control_.get() < 0 || owner_ != ::getpid() || program != program_) {
        if (auto s = start(program, options, where); !s) return s;
      }
      if (sendWithFds(control_.get(), &job, sizeof job, fds, 3)) return ok();
      const int err = errno;
      stop();  // it has gone (killed, or crashed): once more with a new one
      if (attempt > 0)
        return fail(ErrorCode::Io,
                    "cannot hand the job to the " + options.library + " helper process (" + program +
                        "): " + std::strerror(err),
                    where, options.disableHint);
    }
  }

 private:
  Status start(const std::string& program, const IsolateOptions& options, const std::string& where) {
    stop();
    int sv[2];
    if (::socketpair(AF_UNIX, SOCK_SEQPACKET | SOCK_CLOEXEC, 0, sv) != 0)
      return fail(ErrorCode::Io,
                  std::string("cannot make a socket for the helper process: ") + std::strerror(errno), where,
                  options.disableHint);
    Fd mine(highFd(sv[0])), theirs(highFd(sv[1]));
    pid_t pid = -1;
    const std::string serve[] = {"--serve"};
    const int spawned = spawnHelperProgram(program, serve, theirs.get(), pid);
    if (spawned != 0 || mine.get() < 0)
      return fail(ErrorCode::Io,
                  "cannot start the " + options.library + " helper process (" + program +
                      "): " + std::strerror(spawned != 0 ? spawned : EMFILE),
                  where, options.disableHint);
    control_.reset(mine.release());
    pid_ = pid;
    owner_ = ::getpid();
    program_ = program;
    return ok();
  }

  void stop() {
    if (control_.get() < 0) return;
    control_.reset();  // the helper sees the end and leaves
    if (owner_ == ::getpid() && pid_ > 0) {
      // Reaped here if it has gone already; otherwise it ends on its own
      // and is reaped by whoever waits for any child, or at our exit.
      int status;
      ::waitpid(pid_, &status, WNOHANG);
    }
    pid_ = -1;
  }

  std::mutex mutex_;
  Fd control_;
  pid_t pid_ = -1;
  pid_t owner_ = 0;
  std::string program_;
};

}  // namespace

Result<std::string> helperProgram() {
  return findHelperProgram({.name = "dm-isolate",
                            .envVar = "DM_ISOLATE_HELPER",
                            .purpose = "runs Assimp and OpenVDB apart from this process",
                            .otherwise =
                                "build or install DMPlatform's dm-isolate target, set DM_ISOLATE_HELPER to "
                                "its path, or choose Isolation::Fork (single-threaded callers) or "
                                "Isolation::InProcess (trusted files)",
                            .anchor = &kLibraryAnchor});
}

Result<IsolatedRun> runHelper(const char* job, const std::function<void(FdWriter&)>& writeRequest,
                              const IsolateOptions& options, const std::string& where) {
  auto program = helperProgram();
  if (!program) return program.error().within(where);
  auto ioError = [&](const std::string& what, int err) {
    return fail(
        ErrorCode::Io,
        what + " the " + options.library + " helper process (" + *program + "): " + std::strerror(err), where,
        options.disableHint);
  };
  JobMessage message{};
  if (std::strlen(job) >= sizeof message.job)
    return fail(ErrorCode::Internal, std::string("job name '") + job + "' is too long", where);
  std::strncpy(message.job, job, sizeof message.job - 1);
  message.timeoutSeconds = options.timeoutSeconds;
  message.memoryBudget = options.memoryBudget;

  // The request: a memory file the job reads as its standard input, sealed
  // so that what it reads is exactly what was written.
  Fd request(::memfd_create("dm-isolate-request", MFD_CLOEXEC | MFD_ALLOW_SEALING));
  if (request.get() < 0) return ioError("cannot make the request of", errno);
  {
    FdWriter w(request.get());
    writeRequest(w);
    if (!w.ok()) return ioError("cannot write the request of", errno);
  }
  if (::lseek(request.get(), 0, SEEK_SET) != 0) return ioError("cannot rewind the request of", errno);
  ::fcntl(request.get(), F_ADD_SEALS, F_SEAL_SHRINK | F_SEAL_GROW | F_SEAL_WRITE | F_SEAL_SEAL);

  int fds[2];
  if (::pipe2(fds, O_CLOEXEC) != 0) return ioError("cannot make a pipe for", errno);
  Fd resultRead(fds[0]), resultWrite(fds[1]);
  int sv[2];
  if (::socketpair(AF_UNIX, SOCK_SEQPACKET | SOCK_CLOEXEC, 0, sv) != 0)
    return ioError("cannot make a socket for", errno);
  Fd status(sv[0]), statusPeer(sv[1]);
  const int handed[3] = {request.get(), resultWrite.get(), statusPeer.get()};
  if (auto s = HelperServer::instance().submit(*program, message, handed, options, where); !s)
    return s.error();
  request.reset();
  resultWrite.reset();  // the job holds the only write end now
  statusPeer.reset();

  // The helper answers at once: the job's pid (and a pidfd), or no such job.
  StatusMessage started{};
  int pidfd = -1, got = 0;
  if (!readable(status.get(), 30.0))
    return fail(
        ErrorCode::Io,
        "the " + options.library + " helper process (" + *program + ") did not start the job within 30 s",
        where, options.disableHint);
  const ssize_t n = receiveWithFds(status.get(), &started, sizeof started, &pidfd, 1, got);
  Fd pidHandle(got > 0 ? pidfd : -1);
  if (n == sizeof started && started.type == kUnknownJob)
    return fail(
        ErrorCode::Internal, "the helper program " + *program + " does not run the job '" + job + "'", where,
        "it is from another version of DMPlatform: point DM_ISOLATE_HELPER at this version's dm-isolate");
  if (n != sizeof started || started.type != kStarted || started.value <= 0)
    return fail(
        ErrorCode::Io,
        "the " + options.library + " helper process (" + *program + ") ended before it started the job",
        where, options.disableHint);
  const pid_t pid = started.value;

  ChildControl control;
  control.kill = [&] {
    if (pidHandle.get() >= 0)
      pidfdKill(pidHandle.get());
    else
      ::kill(pid, SIGKILL);
  };
  control.wait = [&]() -> std::optional<int> {
    StatusMessage ended{};
    int none = 0, noneCount = 0;
    const ssize_t m = receiveWithFds(status.get(), &ended, sizeof ended, &none, 0, noneCount);
    if (m != sizeof ended || ended.type != kEnded) return std::nullopt;
    return ended.value;
  };
  return collectChild(control, resultRead.release(), options, where);
}

namespace {

// In the forked child of the helper: the job on its request, with the
// caller's deadline and budget. `fds`: request, result, status socket.
[[noreturn]] void runJob(HelperJob run, const JobMessage& message, const int fds[3], pid_t helper) {
  ::dup2(fds[0], 0);
  ::dup2(fds[1], 3);  // over the control socket, which the child must not hold
#if defined(__linux__)
  ::close_range(4, ~0u, 0);
  ::prctl(PR_SET_PDEATHSIG, SIGKILL);
#endif
  if (::getppid() != helper) ::_exit(1);  // the helper is gone already
  sigset_t none;
  sigemptyset(&none);
  ::sigprocmask(SIG_SETMASK, &none, nullptr);
  // Die plainly on a fault, as the forked child does: a sanitizer's handler
  // would otherwise report it and exit with a status (or abort, as
  // ASAN_OPTIONS say), and the caller could not tell a crash from an exit.
  for (int sig : {SIGSEGV, SIGBUS, SIGFPE, SIGILL, SIGABRT, SIGPIPE}) std::signal(sig, SIG_DFL);
  const double timeout = message.timeoutSeconds;
  if (timeout > 0 && std::isfinite(timeout))
    ::alarm(static_cast<unsigned>(std::min(std::ceil(timeout), 1e6)) + 1);
  std::vector<char> request;
  char chunk[1 << 16];
  for (;;) {
    const ssize_t n = ::read(0, chunk, sizeof chunk);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) ::_exit(4);
    if (n == 0) break;
    request.insert(request.end(), chunk, chunk + n);
  }
  ::close(0);
  limitMemory(static_cast<std::size_t>(message.memoryBudget));
  ByteReader r(request);
  FdWriter w(3);
  run(r, w);
  ::close(3);
  ::_exit(w.ok() ? 0 : 3);
}

#if defined(__SANITIZE_THREAD__)
#define DM_HELPER_TSAN 1
#elif defined(__has_feature)
#if __has_feature(thread_sanitizer)
#define DM_HELPER_TSAN 1
#endif
#endif

// The threads of this process.
int threadCount() {
  DIR* dir = ::opendir("/proc/self/task");
  if (dir == nullptr) return -1;
  int n = 0;
  while (const dirent* e = ::readdir(dir))
    if (e->d_name[0] != '.') ++n;
  ::closedir(dir);
  return n;
}

// Ends the threads the libraries started when they were loaded, so that
// the helper forks from its only thread: DMCore's log drainer and the
// thread pool log4cplus (OpenVDB's logging) starts in its initialiser. True
// when one thread is left. ThreadSanitizer keeps a thread of its own, and
// makes fork safe beside it.
bool becomeSingleThreaded() {
  dm::log::stopDrainThread();
  using Shutdown = void (*)();
  if (void* f =
          ::dlsym(RTLD_DEFAULT, "_ZN9log4cplus18shutdownThreadPoolEv"))  // log4cplus::shutdownThreadPool()
    reinterpret_cast<Shutdown>(f)();
#if defined(DM_HELPER_TSAN)
  return true;
#else
  // A joined thread leaves /proc/self/task a moment after its join returns
  // (the kernel releases the task after it wakes the joiner).
  for (int waited = 0; waited < 2000; ++waited) {
    if (threadCount() == 1) return true;
    ::usleep(500);
  }
  return false;
#endif
}

// The helper's loop: a job from the control socket (fd 3) forks a child;
// a child's end (SIGCHLD, through a signalfd) is reported to its caller.
[[noreturn]] void serve(const HelperJobEntry* jobs, std::size_t jobCount) {
  constexpr int kControl = 3;
#if defined(__linux__)
  ::close_range(4, ~0u, 0);
#endif
  if (!becomeSingleThreaded()) {
    // A fork beside another thread is what this program exists to avoid.
    std::fprintf(stderr,
                 "dm-isolate: %d threads are left after ending the known library threads; a fork is not safe "
                 "beside them, so no job is served\n",
                 threadCount());
    ::_exit(6);
  }
  sigset_t children;
  sigemptyset(&children);
  sigaddset(&children, SIGCHLD);
  ::sigprocmask(SIG_BLOCK, &children, nullptr);
  const int ends = ::signalfd(-1, &children, SFD_CLOEXEC);
  if (ends < 0) ::_exit(5);
  const pid_t self = ::getpid();
  std::map<pid_t, int> waiting;  // child → its caller's status socket
  auto reap = [&] {
    int status = 0;
    pid_t pid;
    while ((pid = ::waitpid(-1, &status, WNOHANG)) > 0) {
      auto it = waiting.find(pid);
      if (it == waiting.end()) continue;
      const StatusMessage ended{kEnded, status};
      sendWithFds(it->second, &ended, sizeof ended, nullptr, 0);
      ::close(it->second);
      waiting.erase(it);
    }
  };
  for (;;) {
    pollfd p[2] = {{kControl, POLLIN, 0}, {ends, POLLIN, 0}};
    if (::poll(p, 2, -1) < 0) {
      if (errno == EINTR) continue;
      break;
    }
    if (p[1].revents != 0) {
      signalfd_siginfo info;
      [[maybe_unused]] const ssize_t r = ::read(ends, &info, sizeof info);
      reap();
    }
    if (p[0].revents == 0) continue;
    JobMessage message{};
    int fds[3] = {-1, -1, -1}, got = 0;
    const ssize_t n = receiveWithFds(kControl, &message, sizeof message, fds, 3, got);
    if (n <= 0) break;  // the caller's process has ended
    if (n != sizeof message || got != 3) {
      for (int i = 0; i < got; ++i) ::close(fds[i]);
      continue;
    }
    message.job[sizeof message.job - 1] = '\0';
    HelperJob run = nullptr;
    for (std::size_t i = 0; i < jobCount; ++i)
      if (std::strcmp(jobs[i].name, message.job) == 0) run = jobs[i].run;
    if (run == nullptr) {
      const StatusMessage unknown{kUnknownJob, 0};
      sendWithFds(fds[2], &unknown, sizeof unknown, nullptr, 0);
      for (int fd : fds) ::close(fd);
      continue;
    }
    const pid_t pid = ::fork();
    if (pid == 0) runJob(run, message, fds, self);
    ::close(fds[0]);
    ::close(fds[1]);
    if (pid < 0) {
      ::close(fds[2]);  // the caller sees the end before a start
      continue;
    }
    const int pidfd = pidfdOpen(pid);
    const StatusMessage started{kStarted, static_cast<std::int32_t>(pid)};
    sendWithFds(fds[2], &started, sizeof started, &pidfd, pidfd >= 0 ? 1 : 0);
    if (pidfd >= 0) ::close(pidfd);
    waiting.emplace(pid, fds[2]);
  }
  for (const auto& [pid, fd] : waiting) ::kill(pid, SIGKILL);
  ::_exit(0);
}

}  // namespace

int helperMain(int argc, char** argv, const HelperJobEntry* jobs, std::size_t jobCount) {
  if (argc == 2 && std::strcmp(argv[1], "--serve") == 0 && ::fcntl(3, F_GETFD) >= 0) {
    for (std::size_t i = 0; i < jobCount; ++i)
      if (jobs[i].prepare != nullptr) jobs[i].prepare();
    serve(jobs, jobCount);
  }
  std::fprintf(stderr,
               "usage: dm-isolate --serve\n"
               "DMPlatform's readers start this program to run Assimp and OpenVDB apart from their own\n"
               "process (see dm/io/isolation.hpp), with a control socket on fd 3. It has no use by hand.\n");
  return 2;
}

}  // namespace dm::detail
