// Runs the built dmtool (DMTOOL_PATH), or any program (runProgram), for the
// Editors tests: posix_spawn in its own process group, stdout and stderr
// captured, a deadline, and the exit status or signal. Shared by dmtool_test.cpp and dmtool_*_test.cpp.
#pragma once

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <stdlib.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>
#include "../common/build_paths.hpp"

extern char** environ;

namespace dmtool_test {

struct ToolRun {
  int exitCode = -1;  ///< exit status when the process exited
  int signal = 0;     ///< terminating signal, 0 if it exited
  bool timedOut = false;
  std::string out, err;
  double seconds = 0.0;
};

// Runs dmtool with `args` in its own process group; kills the group after
// `timeoutSeconds` (dmtool forks an Assimp child of its own). With
// `stderrTerminal`, the child's stderr is a pseudo-terminal (so isatty() is
// true there) instead of a pipe.
inline ToolRun runProgram(const std::string& program, const std::vector<std::string>& args,
                          double timeoutSeconds = 60.0, bool stderrTerminal = false) {
  ToolRun r;
  int outPipe[2], errPipe[2];
  if (pipe2(outPipe, O_CLOEXEC) != 0) {
    r.err = "pipe failed";
    return r;
  }
  if (stderrTerminal) {
    errPipe[0] = posix_openpt(O_RDWR | O_NOCTTY | O_CLOEXEC);
    if (errPipe[0] < 0 || grantpt(errPipe[0]) != 0 || unlockpt(errPipe[0]) != 0) {
      r.err = "no pseudo-terminal";
      return r;
    }
    errPipe[1] = open(ptsname(errPipe[0]), O_RDWR | O_NOCTTY | O_CLOEXEC);
  } else if (pipe2(errPipe, O_CLOEXEC) != 0) {
    r.err = "pipe failed";
    return r;
  }
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_adddup2(&actions, outPipe[1], STDOUT_FILENO);
  posix_spawn_file_actions_adddup2(&actions, errPipe[1], STDERR_FILENO);
  posix_spawnattr_t attr;
  posix_spawnattr_init(&attr);
  posix_spawnattr_setflags(&attr, POSIX_SPAWN_SETPGROUP);
  posix_spawnattr_setpgroup(&attr, 0);
  std::vector<std::string> argv{program};
  argv.insert(argv.end(), args.begin(), args.end());
  std::vector<char*> cargv;
  for (std::string& a : argv) cargv.push_back(a.data());
  cargv.push_back(nullptr);
  const auto start = std::chrono::steady_clock::now();
  pid_t pid = -1;
  const int spawned = posix_spawn(&pid, program.c_str(), &actions, &attr, cargv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  posix_spawnattr_destroy(&attr);
  close(outPipe[1]);
  close(errPipe[1]);
  if (spawned != 0) {
    close(outPipe[0]);
    close(errPipe[0]);
    r.err = std::string("posix_spawn failed: ") + std::strerror(spawned);
    return r;
  }
  const auto deadline = start + std::chrono::duration<double>(timeoutSeconds);
  std::array<pollfd, 2> fds{{{outPipe[0], POLLIN, 0}, {errPipe[0], POLLIN, 0}}};
  std::array<std::string*, 2> sinks{&r.out, &r.err};
  int open = 2;
  while (open > 0) {
    const auto left =
        std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
    if (left.count() <= 0) {
      r.timedOut = true;
      kill(-pid, SIGKILL);
      break;
    }
    if (poll(fds.data(), fds.size(), static_cast<int>(std::min<long long>(left.count(), 1000))) < 0) continue;
    for (std::size_t i = 0; i < fds.size(); ++i) {
      if (fds[i].fd < 0 || fds[i].revents == 0) continue;
      char buf[65536];
      const ssize_t n = read(fds[i].fd, buf, sizeof buf);
      if (n > 0) {
        sinks[i]->append(buf, static_cast<std::size_t>(n));
      } else if (n < 0 && errno == EINTR) {
        continue;
      } else {  // EOF, or EIO from a terminal whose other side closed
        close(fds[i].fd);
        fds[i].fd = -1;
        --open;
      }
    }
  }
  for (pollfd& p : fds)
    if (p.fd >= 0) close(p.fd);
  int status = 0;
  while (waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (WIFEXITED(status)) r.exitCode = WEXITSTATUS(status);
  if (WIFSIGNALED(status)) r.signal = WTERMSIG(status);
  return r;
}

#ifdef DMTOOL_PATH
inline ToolRun runTool(const std::vector<std::string>& args, double timeoutSeconds = 60.0,
                       bool stderrTerminal = false) {
  return runProgram(dm::test::besideExecutable(DMTOOL_PATH), args, timeoutSeconds, stderrTerminal);
}
#endif

inline std::string describe(const ToolRun& r) {
  return "exit " + std::to_string(r.exitCode) + " signal " + std::to_string(r.signal) +
         (r.timedOut ? " (timed out)" : "") + "\nstdout: " + r.out + "\nstderr: " + r.err;
}

// Parses stdout as exactly one JSON object (one line).
inline nlohmann::json parseJson(const ToolRun& r) {
  nlohmann::json j = nlohmann::json::parse(r.out, nullptr, /*allow_exceptions=*/false);
  EXPECT_TRUE(j.is_object()) << describe(r);
  EXPECT_EQ(std::count(r.out.begin(), r.out.end(), '\n'), 1) << r.out;
  return j;
}

/// A fresh directory under /tmp, removed with its contents on destruction.
struct TempDir {
  std::filesystem::path path;
  TempDir() {
    char tmpl[] = "/tmp/dmtool_test_XXXXXX";
    const char* made = mkdtemp(tmpl);
    path = made ? std::filesystem::path(made) : std::filesystem::temp_directory_path();
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path, ec);
  }
};

/// Writes an axis-aligned cube of edge 1 m centred at the origin (faces CCW
/// from outside, two triangles each) as `dir/unit_box.obj`; returns the path.
inline std::string writeUnitBox(const TempDir& dir) {
  const std::string file = (dir.path / "unit_box.obj").string();
  std::ofstream f(file);
  for (int i = 0; i < 8; ++i)
    f << "v " << (i & 1 ? 0.5 : -0.5) << ' ' << (i & 2 ? 0.5 : -0.5) << ' ' << (i & 4 ? 0.5 : -0.5) << '\n';
  // Quads as two triangles each (1-based): -x, +x, -y, +y, -z, +z.
  f << "f 1 5 7\nf 1 7 3\nf 2 4 8\nf 2 8 6\nf 1 2 6\nf 1 6 5\n"
       "f 3 7 8\nf 3 8 4\nf 1 3 4\nf 1 4 2\nf 5 6 8\nf 5 8 7\n";
  return file;
}

}  // namespace dmtool_test
