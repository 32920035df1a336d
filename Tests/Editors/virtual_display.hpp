// virtual_display.hpp — an Xvfb X server on a free display number for the
// tests of the programs that open windows (dmedit, dmplatform --view);
// stopped on destruction. display() is empty where Xvfb is not installed.
#pragma once

#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

extern char** environ;

namespace dm::test {

// An X server on a free display number, stopped on destruction.
class VirtualDisplay {
 public:
  VirtualDisplay() {
    const char* candidates[] = {"/usr/bin/Xvfb", "/usr/local/bin/Xvfb"};
    std::string xvfb;
    for (const char* c : candidates)
      if (access(c, X_OK) == 0) xvfb = c;
    if (xvfb.empty()) return;
    for (int n = 90 + static_cast<int>(getpid() % 50); n < 200 && pid_ < 0; ++n) {
      if (std::filesystem::exists("/tmp/.X11-unix/X" + std::to_string(n)) ||
          std::filesystem::exists("/tmp/.X" + std::to_string(n) + "-lock"))
        continue;
      const std::string display = ":" + std::to_string(n);
      std::vector<std::string> argv{xvfb, display, "-screen", "0", "1024x700x24", "-nolisten", "tcp"};
      std::vector<char*> cargv;
      for (auto& a : argv) cargv.push_back(a.data());
      cargv.push_back(nullptr);
      posix_spawn_file_actions_t actions;
      posix_spawn_file_actions_init(&actions);
      posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, "/dev/null", O_WRONLY, 0);
      posix_spawn_file_actions_addopen(&actions, STDERR_FILENO, "/dev/null", O_WRONLY, 0);
      pid_t pid = -1;
      if (posix_spawn(&pid, xvfb.c_str(), &actions, nullptr, cargv.data(), environ) != 0) pid = -1;
      posix_spawn_file_actions_destroy(&actions);
      if (pid < 0) continue;
      for (int i = 0; i < 100 && !std::filesystem::exists("/tmp/.X11-unix/X" + std::to_string(n)); ++i)
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
      int status = 0;
      if (waitpid(pid, &status, WNOHANG) == pid) continue;  // it exited: display taken
      pid_ = pid;
      display_ = display;
    }
  }
  ~VirtualDisplay() {
    if (pid_ > 0) {
      kill(pid_, SIGTERM);
      waitpid(pid_, nullptr, 0);
    }
  }
  const std::string& display() const { return display_; }

 private:
  pid_t pid_ = -1;
  std::string display_;
};

}  // namespace dm::test
