// dm-plugin-probe: the program PluginLinker starts in probe mode
// (dm/core/plugin.hpp) to load and initialise a plugin apart from the host
// before the host loads it. A fresh process with one thread, started with
// posix_spawn (the host's threads and the locks they hold stay behind, which
// a bare fork of the host could not promise): it dlopens the plugin named
// by argv[1], calls its entry point, init() with a host API that accepts and
// discards every registration, and shutdown(), and writes one byte to fd 3
// as it enters each phase ('o' dlopen, 'e' entry point, 'i' init, 's'
// shutdown) and 'D' (done) or 'E' (an ordinary load error, which the host's
// own load reports precisely). A crash or a hang shows as the last phase
// written; the host kills it at its deadline.
#include <dm/core/plugin_abi.h>

#include <dlfcn.h>
#include <unistd.h>

#include <cerrno>
#include <csignal>
#include <cstdint>
#include <initializer_list>

namespace {

constexpr int kProgressFd = 3;

void mark(char c) {
  while (::write(kProgressFd, &c, 1) < 0 && errno == EINTR) {
  }
}

int acceptRegistration(DmHostContext*, const char*, const char*, std::uint32_t, const void*) noexcept {
  return DM_PLUGIN_OK;
}
void discardLog(DmHostContext*, int, const char*) noexcept {}
void discardError(DmHostContext*, const char*) noexcept {}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) return 2;
  // Crash as the kernel would, even where a sanitizer runtime installed
  // handlers that turn faults into reports and exit codes.
  for (int sig : {SIGSEGV, SIGBUS, SIGILL, SIGFPE, SIGABRT, SIGTRAP, SIGSYS}) {
    struct sigaction sa {};
    sa.sa_handler = SIG_DFL;
    sigemptyset(&sa.sa_mask);
    sigaction(sig, &sa, nullptr);
  }
  try {
    mark('o');
    void* handle = ::dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    if (handle == nullptr) {
      mark('E');
      ::_exit(0);
    }
    mark('e');
    void* sym = ::dlsym(handle, DM_PLUGIN_ENTRY_SYMBOL);
    if (sym == nullptr) {
      mark('E');
      ::_exit(0);
    }
    const DmPluginInfo* info = reinterpret_cast<DmPluginEntryFn>(sym)();
    if (info == nullptr || info->abi_version != DM_PLUGIN_ABI_VERSION || info->init == nullptr) {
      mark('E');
      ::_exit(0);
    }
    mark('i');
    const DmHostApi api{DM_PLUGIN_ABI_VERSION, nullptr, acceptRegistration, discardLog, discardError};
    const int rc = info->init(&api);
    if (rc == 0 && info->shutdown != nullptr) {
      mark('s');
      info->shutdown();
    }
    mark('D');
  } catch (...) {  // thrown through the C ABI: the host's own load reports it
    mark('E');
  }
  // No static destructors or leak checks of a plugin we only looked at.
  ::_exit(0);
}
