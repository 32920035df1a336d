// helper_program.cpp — where DMPlatform's helper programs are found
// (dm/core/helper_program.hpp).
#include <dm/core/helper_program.hpp>

#include <dlfcn.h>
#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <filesystem>
#include <system_error>
#include <vector>

namespace dm {

Result<std::string> findHelperProgram(const HelperProgram& program) {
  namespace fs = std::filesystem;
  auto runnable = [](const fs::path& p) {
    std::error_code ec;
    return fs::is_regular_file(p, ec) && ::access(p.c_str(), X_OK) == 0;
  };
  if (const char* env = std::getenv(program.envVar); env != nullptr && *env != '\0') {
    if (runnable(env)) return std::string(env);
    return fail(ErrorCode::NotFound,
                std::string(program.envVar) + " names '" + env + "', which is not an executable file",
                program.envVar,
                std::string("point it at the ") + program.name + " program of this DMPlatform, or unset it");
  }
  std::vector<fs::path> places;
  std::error_code ec;
  Dl_info info{};
  if (program.anchor != nullptr && ::dladdr(program.anchor, &info) != 0 && info.dli_fname != nullptr &&
      *info.dli_fname != '\0') {
    const fs::path lib = fs::weakly_canonical(fs::absolute(info.dli_fname, ec), ec);
    places.push_back(lib.parent_path() / program.name);
    places.push_back(lib.parent_path() / "dmplatform" / program.name);
  }
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (!ec) places.push_back(exe.parent_path() / program.name);
  std::string looked;
  for (const fs::path& p : places) {
    if (runnable(p)) return p.string();
    looked += (looked.empty() ? "" : ", ") + p.string();
  }
  return fail(ErrorCode::NotFound,
              std::string("the helper program ") + program.name + ", which " + program.purpose +
                  ", is not in " + (looked.empty() ? std::string("any known folder") : looked),
              "", program.otherwise);
}

int spawnHelperProgram(const std::string& program, std::span<const std::string> args, int channel,
                       pid_t& pid) {
  // dup2 onto the same number would keep its close-on-exec flag: hand the
  // program a descriptor above the ones it gets.
  int high = channel;
  if (channel <= 3) {
    high = ::fcntl(channel, F_DUPFD_CLOEXEC, 10);
    if (high < 0) return errno;
  }
  std::vector<std::string> strings;
  strings.reserve(args.size() + 1);
  strings.push_back(program);
  strings.insert(strings.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (std::string& a : strings) argv.push_back(a.data());
  argv.push_back(nullptr);
  posix_spawn_file_actions_t actions;
  posix_spawnattr_t attr;
  posix_spawn_file_actions_init(&actions);
  posix_spawnattr_init(&attr);
  posix_spawn_file_actions_adddup2(&actions, high, 3);
  posix_spawn_file_actions_addopen(&actions, 0, "/dev/null", O_RDONLY, 0);
  posix_spawn_file_actions_addopen(&actions, 1, "/dev/null", O_WRONLY, 0);
  sigset_t none, all;
  sigemptyset(&none);
  sigfillset(&all);
  posix_spawnattr_setsigmask(&attr, &none);
  posix_spawnattr_setsigdefault(&attr, &all);
  posix_spawnattr_setflags(&attr, POSIX_SPAWN_SETSIGMASK | POSIX_SPAWN_SETSIGDEF);
  const int spawned = ::posix_spawn(&pid, program.c_str(), &actions, &attr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  posix_spawnattr_destroy(&attr);
  if (high != channel) ::close(high);
  return spawned;
}

}  // namespace dm
