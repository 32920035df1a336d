// Factory registry and plugin linker: dlopen, ABI check, init through the C
// host API, all-or-nothing registration, optional crash probe in a child.
#include <dm/core/helper_program.hpp>
#include <dm/core/log.hpp>
#include <dm/core/plugin.hpp>

#include <dlfcn.h>
#include <fcntl.h>
#include <poll.h>
#include <sys/types.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <csignal>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <new>
#include <set>
#include <system_error>
#include <thread>

// The opaque host context of one plugin (declared in plugin_abi.h). Lives
// as long as the plugin is loaded; registrations are staged here during init
// and committed to the registry only if init succeeds.
struct DmHostContext {
  std::string label;                   // plugin name (or file) for logs and messages
  std::string provider;                // plugin name as recorded in Factory::provider
  std::filesystem::path providerPath;  // library path; empty for built-ins
  const dm::FactoryRegistry* registry = nullptr;
  bool initializing = true;
  std::vector<dm::Factory> staged;
  std::vector<dm::Error> registrationErrors;
  std::string error;  // set_error()
};

namespace dm {
namespace {

std::string str(const std::filesystem::path& p) { return p.string(); }

// ---- registry helpers ------------------------------------------------------

std::string joinNames(const std::vector<std::string>& names) {
  std::string s;
  for (const auto& n : names) {
    if (!s.empty()) s += ", ";
    s += n;
  }
  return s;
}

// ---- host API callbacks (C ABI: never throw) ---------------------------------

int hostRegisterFactory(DmHostContext* ctx, const char* kind, const char* name, std::uint32_t kindAbiVersion,
                        const void* vtable) noexcept {
  if (!ctx) return DM_PLUGIN_ERROR_INVALID_ARGUMENT;
  try {
    if (!ctx->initializing) {
      log::warn(
          "plugin %s: register_factory('%s', '%s') called outside init; ignored (register every "
          "factory from init)",
          ctx->label.c_str(), kind ? kind : "", name ? name : "");
      return DM_PLUGIN_ERROR_WRONG_STATE;
    }
    if (!kind || !*kind || !name || !*name || !vtable) {
      ctx->registrationErrors.push_back(
          fail(ErrorCode::InvalidArgument,
               std::string("register_factory called with ") +
                   (!kind || !*kind   ? "an empty kind"
                    : !name || !*name ? "an empty name"
                                      : "a null vtable") +
                   (kind && *kind ? std::string(" (kind '") + kind + "')" : std::string()),
               {}, "pass a non-empty kind and name and a static vtable"));
      return DM_PLUGIN_ERROR_INVALID_ARGUMENT;
    }
    const FactoryKey key{kind, name};
    for (const auto& f : ctx->staged) {
      if (f.key == key) {
        ctx->registrationErrors.push_back(fail(ErrorCode::InvalidArgument,
                                               "duplicate factory '" + key.name + "' of kind '" + key.kind +
                                                   "': registered twice by this plugin",
                                               {}, "register each (kind, name) once"));
        return DM_PLUGIN_ERROR_DUPLICATE;
      }
    }
    if (ctx->registry) {
      if (auto existing = ctx->registry->find(key.kind, key.name)) {
        ctx->registrationErrors.push_back(
            fail(ErrorCode::InvalidArgument,
                 "duplicate factory '" + key.name + "' of kind '" + key.kind + "': already provided by " +
                     (existing->providerPath.empty()
                          ? "'" + existing->provider + "'"
                          : "plugin '" + existing->provider + "' (" + str(existing->providerPath) + ")"),
                 {}, "unload the other plugin or rename the factory"));
        return DM_PLUGIN_ERROR_DUPLICATE;
      }
    }
    Factory f;
    f.key = key;
    f.kindAbiVersion = kindAbiVersion;
    f.vtable = vtable;
    f.provider = ctx->provider;
    f.providerPath = ctx->providerPath;
    ctx->staged.push_back(std::move(f));
    return DM_PLUGIN_OK;
  } catch (const std::bad_alloc&) {
    return DM_PLUGIN_ERROR_OUT_OF_MEMORY;
  } catch (...) {
    return DM_PLUGIN_ERROR_INTERNAL;
  }
}

void hostLog(DmHostContext* ctx, int level, const char* message) noexcept {
  if (!ctx || !message) return;
  log::Level l = log::Level::Info;
  if (level <= DM_PLUGIN_LOG_TRACE)
    l = log::Level::Trace;
  else if (level == DM_PLUGIN_LOG_DEBUG)
    l = log::Level::Debug;
  else if (level == DM_PLUGIN_LOG_INFO)
    l = log::Level::Info;
  else if (level == DM_PLUGIN_LOG_WARN)
    l = log::Level::Warn;
  else
    l = log::Level::Error;
  try {
    log::message(l, "plugin %s: %s", ctx->label.c_str(), message);
  } catch (...) {
    // Logging must never propagate into plugin code.
  }
}

void hostSetError(DmHostContext* ctx, const char* message) noexcept {
  if (!ctx) return;
  try {
    ctx->error = message ? message : "";
  } catch (...) {
    // Out of memory: the generic "init failed" message will have to do.
  }
}

// ---- probe-process helpers ----------------------------------------------------

const char* signalName(int sig) noexcept {
  switch (sig) {
    case SIGSEGV:
      return "SIGSEGV (segmentation fault)";
    case SIGBUS:
      return "SIGBUS (bus error)";
    case SIGILL:
      return "SIGILL (illegal instruction)";
    case SIGFPE:
      return "SIGFPE (arithmetic exception)";
    case SIGABRT:
      return "SIGABRT (abort)";
    case SIGTRAP:
      return "SIGTRAP (trap)";
    case SIGSYS:
      return "SIGSYS (bad system call)";
    case SIGKILL:
      return "SIGKILL (killed)";
    case SIGTERM:
      return "SIGTERM (terminated)";
    case SIGINT:
      return "SIGINT (interrupted)";
    case SIGPIPE:
      return "SIGPIPE (broken pipe)";
    default:
      return nullptr;
  }
}

const char* phaseName(char phase) noexcept {
  switch (phase) {
    case 'o':
      return "dlopen (static initializers)";
    case 'e':
      return "the entry point dm_plugin_entry()";
    case 'i':
      return "init()";
    case 's':
      return "shutdown()";
    default:
      return "process start";
  }
}

// A marker whose address dladdr() maps to the file DMCore was loaded from
// (dm-plugin-probe is looked for beside it).
const char kLibraryAnchor = 0;

// Loads and inits `path` in the dm-plugin-probe program (DMCore/probe/
// main.cpp), started with posix_spawn: unlike a fork of this process, whose
// other threads may hold the loader's, the allocator's or the logger's locks
// at that moment, it starts clean. Fails if the probe crashes or does not
// finish within `timeout`. Every other outcome (including ordinary load
// errors) passes, and the in-process load reports it precisely.
Status probePlugin(const std::filesystem::path& path, std::chrono::milliseconds timeout) {
  const std::string where = str(path);
  auto program = findHelperProgram(
      {.name = "dm-plugin-probe",
       .envVar = "DM_PLUGIN_PROBE",
       .purpose = "loads a plugin apart from this process before it is loaded here",
       .otherwise =
           "build or install DMPlatform's dm-plugin-probe target, set DM_PLUGIN_PROBE to its path, or "
           "turn PluginLinkerOptions::probe off",
       .anchor = &kLibraryAnchor});
  if (!program) return program.error().within(where);
  int fds[2];
  if (pipe2(fds, O_CLOEXEC) != 0)
    return fail(ErrorCode::Io, std::string("cannot create the probe pipe: ") + std::strerror(errno), where);
  pid_t pid = -1;
  const std::string args[] = {where};
  const int spawned = spawnHelperProgram(*program, args, fds[1], pid);
  close(fds[1]);
  if (spawned != 0) {
    close(fds[0]);
    return fail(ErrorCode::Io, "cannot start the probe process " + *program + ": " + std::strerror(spawned),
                where, "retry without PluginLinkerOptions::probe");
  }

  using Clock = std::chrono::steady_clock;
  const auto deadline = Clock::now() + timeout;
  auto remainingMs = [&] {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now());
    return static_cast<int>(std::max<std::int64_t>(0, left.count()));
  };
  char phase = 0;
  bool finished = false;
  for (;;) {
    pollfd p{fds[0], POLLIN, 0};
    const int r = poll(&p, 1, remainingMs());
    if (r < 0 && errno == EINTR) continue;
    if (r <= 0) break;  // timeout (or poll error: fall back to waitpid below)
    char buf[32];
    const ssize_t n = read(fds[0], buf, sizeof buf);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) break;  // EOF: the child exited (or closed the pipe)
    for (ssize_t i = 0; i < n; ++i) {
      if (buf[i] == 'D' || buf[i] == 'E')
        finished = true;
      else
        phase = buf[i];
    }
    if (finished) break;
  }
  close(fds[0]);

  int status = 0;
  bool reaped = false;
  for (;;) {
    const pid_t w = waitpid(pid, &status, WNOHANG);
    if (w == pid) {
      reaped = true;
      break;
    }
    if (w < 0 && errno != EINTR) {
      return fail(ErrorCode::Io, std::string("cannot wait for the probe process: ") + std::strerror(errno),
                  where, "do not set SIGCHLD to SIG_IGN when using probe mode");
    }
    if (remainingMs() <= 0) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  if (!reaped) {
    kill(pid, SIGKILL);
    while (waitpid(pid, &status, 0) < 0 && errno == EINTR) {
    }
    return fail(ErrorCode::Timeout,
                std::string("plugin did not finish ") + phaseName(phase) + " within " +
                    std::to_string(timeout.count()) + " ms in the probe process (it hangs); refused",
                where, "fix the plugin, or raise PluginLinkerOptions::probeTimeout if it is only slow");
  }
  if (WIFSIGNALED(status)) {
    const int sig = WTERMSIG(status);
    const char* name = signalName(sig);
    return fail(ErrorCode::Unsupported,
                std::string("plugin crashed with ") + (name ? name : "signal " + std::to_string(sig)) +
                    " during " + phaseName(phase) + " in the probe process; refused",
                where, "fix the plugin or remove it from the plugin directory");
  }
  if (!finished) {
    return fail(ErrorCode::Unsupported,
                "plugin process exited with status " +
                    std::to_string(WIFEXITED(status) ? WEXITSTATUS(status) : -1) + " during " +
                    phaseName(phase) + " without finishing (it crashed or called exit()); refused",
                where, "fix the plugin or remove it from the plugin directory");
  }
  return ok();
}

std::string dlErrorString() {
  const char* e = dlerror();
  return e ? e : "unknown dlopen error";
}

bool hasPluginSuffix(const std::filesystem::path& p) {
#if defined(__APPLE__)
  return p.extension() == ".dylib" || p.extension() == ".so";
#else
  return p.extension() == ".so";
#endif
}

std::filesystem::path canonicalOr(const std::filesystem::path& p) {
  std::error_code ec;
  auto c = std::filesystem::weakly_canonical(p, ec);
  return ec ? p : c;
}

}  // namespace

namespace detail {

// The dlopen'ed library; dlclose when the last owner (plugin record or a
// Factory copy's keepAlive) lets go. In a named namespace: PluginLinker::Loaded
// holds one, and a member type from an anonymous namespace draws
// -Wsubobject-linkage once this file is part of a unity batch.
struct PluginLibrary {
  void* handle = nullptr;
  explicit PluginLibrary(void* h) : handle(h) {}
  PluginLibrary(const PluginLibrary&) = delete;
  PluginLibrary& operator=(const PluginLibrary&) = delete;
  ~PluginLibrary() {
    if (handle) dlclose(handle);
  }
};

}  // namespace detail

// ---- FactoryRegistry ---------------------------------------------------------

Status FactoryRegistry::checkNewLocked(const Factory& f) const {
  if (f.key.kind.empty() || f.key.name.empty())
    return fail(ErrorCode::InvalidArgument,
                std::string("factory with an empty ") + (f.key.kind.empty() ? "kind" : "name") +
                    (f.key.kind.empty() ? "" : " (kind '" + f.key.kind + "')"),
                f.provider, "give every factory a non-empty kind and name");
  if (!f.vtable)
    return fail(ErrorCode::InvalidArgument,
                "factory '" + f.key.name + "' of kind '" + f.key.kind + "' has a null vtable", f.provider,
                "pass the address of a static vtable");
  if (auto it = factories_.find(f.key); it != factories_.end()) {
    const Factory& e = it->second;
    return fail(ErrorCode::InvalidArgument,
                "duplicate factory '" + f.key.name + "' of kind '" + f.key.kind + "': already provided by " +
                    (e.providerPath.empty() ? "'" + e.provider + "'"
                                            : "plugin '" + e.provider + "' (" + str(e.providerPath) + ")"),
                f.provider, "unload the other provider or rename the factory");
  }
  return ok();
}

Status FactoryRegistry::add(std::string_view kind, std::string_view name, std::uint32_t kindAbiVersion,
                            const void* vtable, std::string_view provider) {
  Factory f;
  f.key = FactoryKey{std::string(kind), std::string(name)};
  f.kindAbiVersion = kindAbiVersion;
  f.vtable = vtable;
  f.provider = std::string(provider);
  std::vector<Factory> one;
  one.push_back(std::move(f));
  return addAll(std::move(one));
}

Status FactoryRegistry::addAll(std::vector<Factory> factories) {
  std::lock_guard lock(mutex_);
  std::set<FactoryKey> seen;
  for (const auto& f : factories) {
    if (auto s = checkNewLocked(f); !s) return s;
    if (!seen.insert(f.key).second)
      return fail(ErrorCode::InvalidArgument,
                  "duplicate factory '" + f.key.name + "' of kind '" + f.key.kind + "' in one registration",
                  f.provider, "register each (kind, name) once");
  }
  for (auto& f : factories) {
    FactoryKey key = f.key;
    factories_.emplace(std::move(key), std::move(f));
  }
  return ok();
}

Status FactoryRegistry::remove(std::string_view kind, std::string_view name) {
  std::lock_guard lock(mutex_);
  if (factories_.erase(FactoryKey{std::string(kind), std::string(name)}) == 0)
    return fail(ErrorCode::NotFound,
                "no factory '" + std::string(name) + "' of kind '" + std::string(kind) + "' to remove");
  return ok();
}

Result<Factory> FactoryRegistry::find(std::string_view kind, std::string_view name) const {
  std::lock_guard lock(mutex_);
  if (auto it = factories_.find(FactoryKey{std::string(kind), std::string(name)}); it != factories_.end())
    return it->second;
  std::vector<std::string> names;
  for (const auto& [key, f] : factories_)
    if (key.kind == kind) names.push_back(key.name);
  return fail(
      ErrorCode::NotFound,
      "no factory '" + std::string(name) + "' of kind '" + std::string(kind) + "'; " +
          (names.empty() ? "no factories of that kind are registered" : "registered: " + joinNames(names)),
      {}, "check the name, or load the plugin that provides it");
}

Result<Factory> FactoryRegistry::find(std::string_view kind, std::string_view name,
                                      std::uint32_t expectedKindAbi) const {
  auto f = find(kind, name);
  if (!f) return f;
  if (f->kindAbiVersion != expectedKindAbi)
    return fail(ErrorCode::Version,
                "factory '" + std::string(name) + "' of kind '" + std::string(kind) +
                    "' has kind ABI version " + std::to_string(f->kindAbiVersion) + ", expected " +
                    std::to_string(expectedKindAbi),
                f->providerPath.empty() ? f->provider : str(f->providerPath),
                "rebuild the plugin '" + f->provider + "' against this SDK");
  return f;
}

std::vector<Factory> FactoryRegistry::list(std::string_view kind) const {
  std::lock_guard lock(mutex_);
  std::vector<Factory> out;
  for (const auto& [key, f] : factories_)
    if (kind.empty() || key.kind == kind) out.push_back(f);
  return out;
}

bool FactoryRegistry::contains(std::string_view kind, std::string_view name) const {
  std::lock_guard lock(mutex_);
  return factories_.count(FactoryKey{std::string(kind), std::string(name)}) != 0;
}

std::size_t FactoryRegistry::size() const {
  std::lock_guard lock(mutex_);
  return factories_.size();
}

// ---- PluginLinker ------------------------------------------------------------

const char* toString(PluginStatus status) noexcept {
  switch (status) {
    case PluginStatus::Loaded:
      return "loaded";
    case PluginStatus::BuiltIn:
      return "built-in";
    case PluginStatus::Refused:
      return "refused";
  }
  return "unknown";
}

struct PluginLinker::Loaded {
  PluginRecord record;
  std::shared_ptr<detail::PluginLibrary> library;  // null for built-ins
  const DmPluginInfo* info = nullptr;
  std::unique_ptr<DmHostContext> ctx;
  DmHostApi api{};
};

PluginLinker::PluginLinker(FactoryRegistry& registry, PluginLinkerOptions options)
    : registry_(registry), options_(std::move(options)) {}

PluginLinker::~PluginLinker() {
  std::lock_guard lock(mutex_);
  while (!loaded_.empty()) unloadLocked(loaded_.size() - 1);
}

std::vector<std::filesystem::path> PluginLinker::searchPaths() const {
  std::vector<std::filesystem::path> dirs;
  if (options_.useEnvironment) {
    if (const char* env = std::getenv("DM_PLUGIN_PATH")) {
      std::string s(env);
      std::size_t start = 0;
      while (start <= s.size()) {
        const std::size_t colon = s.find(':', start);
        const std::string item =
            s.substr(start, colon == std::string::npos ? std::string::npos : colon - start);
        if (!item.empty()) dirs.emplace_back(item);
        if (colon == std::string::npos) break;
        start = colon + 1;
      }
    }
  }
  std::lock_guard lock(mutex_);
  dirs.insert(dirs.end(), options_.searchPaths.begin(), options_.searchPaths.end());
  return dirs;
}

void PluginLinker::addSearchPath(std::filesystem::path dir) {
  std::lock_guard lock(mutex_);
  options_.searchPaths.push_back(std::move(dir));
}

Error PluginLinker::refuseLocked(const std::filesystem::path& path, Error error) {
  PluginRecord r;
  r.path = path;
  r.status = PluginStatus::Refused;
  r.error = error;
  failures_.push_back(std::move(r));
  log::warn("plugin refused: %s", error.message().c_str());
  return error;
}

Result<PluginRecord> PluginLinker::load(const std::filesystem::path& fileOrName) {
  const auto dirs = searchPaths();
  std::lock_guard lock(mutex_);
  if (fileOrName.empty())
    return refuseLocked({}, fail(ErrorCode::InvalidArgument, "empty plugin path", {},
                                 "pass a library path or a plugin name"));
  std::error_code ec;
  const bool explicitPath = fileOrName.is_absolute() || fileOrName.has_parent_path();
  if (explicitPath) {
    if (!std::filesystem::exists(fileOrName, ec))
      return refuseLocked(fileOrName, fail(ErrorCode::NotFound, "plugin file does not exist", str(fileOrName),
                                           "check the path"));
    return loadFileLocked(canonicalOr(fileOrName));
  }
  const std::string n = fileOrName.string();
  const std::vector<std::string> names = {n, "lib" + n + ".so", n + ".so"};
  for (const auto& dir : dirs) {
    for (const auto& candidate : names) {
      const auto p = dir / candidate;
      if (std::filesystem::is_regular_file(p, ec)) return loadFileLocked(canonicalOr(p));
    }
  }
  std::string searched;
  for (const auto& d : dirs) searched += (searched.empty() ? "" : ", ") + str(d);
  return refuseLocked(
      fileOrName,
      fail(ErrorCode::NotFound,
           "plugin '" + n + "' not found (tried " + joinNames(names) + ") in " +
               (dirs.empty() ? std::string("no directories: no search paths are configured") : searched),
           n,
           "add its directory to DM_PLUGIN_PATH or PluginLinkerOptions::searchPaths, or pass a full path"));
}

Result<PluginRecord> PluginLinker::loadFileLocked(const std::filesystem::path& file) {
  const std::string where = str(file);
  for (const auto& p : loaded_) {
    if (p->library && p->record.path == file)
      return refuseLocked(
          file, fail(ErrorCode::InvalidArgument, "already loaded as plugin '" + p->record.name + "'", where,
                     "unload it first to load it again"));
  }
  if (options_.probe) {
    if (auto s = probePlugin(file, options_.probeTimeout); !s) return refuseLocked(file, s.error());
  }

  dlerror();
  void* handle = dlopen(file.c_str(), RTLD_NOW | RTLD_LOCAL);
  if (!handle) {
    const std::string why = dlErrorString();
    if (why.find("undefined symbol") != std::string::npos)
      return refuseLocked(file, fail(ErrorCode::NotFound, "unresolved symbol: " + why, where,
                                     "link the plugin against every library it uses, or rebuild it "
                                     "against this SDK"));
    return refuseLocked(
        file, fail(ErrorCode::Parse, "cannot be loaded as a shared library (dlopen: " + why + ")", where,
                   "is it a plugin built for this platform and architecture?"));
  }
  auto plugin = std::make_shared<Loaded>();
  plugin->library = std::make_shared<detail::PluginLibrary>(handle);
  plugin->record.path = file;

  dlerror();
  void* sym = dlsym(handle, DM_PLUGIN_ENTRY_SYMBOL);
  if (!sym)
    return refuseLocked(
        file, fail(ErrorCode::NotFound,
                   std::string("no entry point '") + DM_PLUGIN_ENTRY_SYMBOL + "': not a DMPlatform plugin",
                   where, "export it with DM_PLUGIN_ENTRY from dm/core/plugin_abi.h"));
  const auto entry = reinterpret_cast<DmPluginEntryFn>(sym);
  const DmPluginInfo* info = nullptr;
  try {
    info = entry();
  } catch (...) {
    return refuseLocked(
        file, fail(ErrorCode::Unsupported, "entry point threw an exception across the C boundary", where,
                   "plugin code must not throw"));
  }
  return initLocked(std::move(plugin), info, where);
}

Result<PluginRecord> PluginLinker::addStatic(DmPluginEntryFn entry) {
  std::lock_guard lock(mutex_);
  if (!entry)
    return refuseLocked({}, fail(ErrorCode::InvalidArgument, "null entry point", "built-in plugin",
                                 "pass the plugin's entry function"));
  const DmPluginInfo* info = nullptr;
  try {
    info = entry();
  } catch (...) {
    return refuseLocked({},
                        fail(ErrorCode::Unsupported, "entry point threw an exception across the C boundary",
                             "built-in plugin", "plugin code must not throw"));
  }
  return initLocked(std::make_shared<Loaded>(), info, "built-in plugin");
}

Result<PluginRecord> PluginLinker::initLocked(std::shared_ptr<Loaded> plugin, const DmPluginInfo* info,
                                              const std::string& where) {
  const std::filesystem::path path = plugin->record.path;
  const bool builtIn = plugin->library == nullptr;
  if (!info)
    return refuseLocked(path, fail(ErrorCode::Parse, "the entry point returned no plugin table (NULL)", where,
                                   "return the address of a static DmPluginInfo"));
  // The ABI version is the first member in every ABI version: read it before
  // anything else in the table.
  if (info->abi_version != DM_PLUGIN_ABI_VERSION)
    return refuseLocked(path, fail(ErrorCode::Version,
                                   "plugin ABI version mismatch: found " + std::to_string(info->abi_version) +
                                       ", expected " + std::to_string(DM_PLUGIN_ABI_VERSION),
                                   where,
                                   "rebuild the plugin against this SDK, whose dm/core/plugin_abi.h "
                                   "defines DM_PLUGIN_ABI_VERSION " +
                                       std::to_string(DM_PLUGIN_ABI_VERSION)));
  if (!info->name || !*info->name)
    return refuseLocked(path, fail(ErrorCode::Parse, "plugin table has no name", where,
                                   "set DmPluginInfo::name to a unique non-empty string"));
  const std::string name = info->name;
  const std::string version = info->version ? info->version : "";
  auto refuse = [&](Error e) {
    Error err = refuseLocked(path, std::move(e));
    failures_.back().name = name;
    failures_.back().version = version;
    return err;
  };
  if (!info->init)
    return refuse(fail(ErrorCode::Parse, "plugin '" + name + "' has no init function", where,
                       "set DmPluginInfo::init"));
  for (const auto& p : loaded_) {
    if (p->record.name == name)
      return refuse(fail(ErrorCode::InvalidArgument,
                         "a plugin named '" + name + "' is already " +
                             (p->record.path.empty() ? std::string("registered as built-in")
                                                     : "loaded from " + str(p->record.path)),
                         where, "unload it first or remove one of the copies"));
  }

  plugin->info = info;
  plugin->ctx = std::make_unique<DmHostContext>();
  plugin->ctx->label = name;
  plugin->ctx->provider = name;
  plugin->ctx->providerPath = path;
  plugin->ctx->registry = &registry_;
  plugin->api =
      DmHostApi{DM_PLUGIN_ABI_VERSION, plugin->ctx.get(), hostRegisterFactory, hostLog, hostSetError};

  int rc = 0;
  try {
    rc = info->init(&plugin->api);
  } catch (...) {
    return refuse(fail(ErrorCode::Unsupported,
                       "plugin '" + name +
                           "': init threw an exception across the C "
                           "boundary",
                       where, "plugin code must not throw; catch inside init and return an error code"));
  }
  plugin->ctx->initializing = false;
  if (rc != 0) {
    // A failed init released what it acquired; no shutdown. Staged
    // factories are dropped with the context and the library is closed.
    // A rejected registration usually is the cause: report it first.
    const std::string& msg = plugin->ctx->error;
    const auto& regErrors = plugin->ctx->registrationErrors;
    std::string what = "plugin '" + name + "': ";
    if (!regErrors.empty()) what += regErrors.front().what + "; then ";
    what += "init failed with code " + std::to_string(rc);
    if (!msg.empty())
      what += ": " + msg;
    else if (regErrors.empty())
      what += " (no message; the plugin did not call set_error)";
    return refuse(fail(
        ErrorCode::Unsupported, std::move(what), where,
        regErrors.empty() ? "see the plugin's message; the plugin was not loaded" : regErrors.front().hint));
  }
  auto shutdownAndRefuse = [&](Error e) {
    try {
      if (info->shutdown) info->shutdown();
    } catch (...) {
      // The load is refused anyway; nothing more to report.
    }
    return refuse(std::move(e));
  };
  if (!plugin->ctx->registrationErrors.empty()) {
    Error e = plugin->ctx->registrationErrors.front();
    e.what = "plugin '" + name + "': " + e.what;
    e.where = where;
    return shutdownAndRefuse(std::move(e));
  }
  for (auto& f : plugin->ctx->staged) f.keepAlive = plugin->library;
  std::vector<FactoryKey> keys;
  for (const auto& f : plugin->ctx->staged) keys.push_back(f.key);
  if (auto s = registry_.addAll(std::move(plugin->ctx->staged)); !s) {
    Error e = s.error();
    e.what = "plugin '" + name + "': " + e.what;
    e.where = where;
    return shutdownAndRefuse(std::move(e));
  }
  plugin->ctx->staged.clear();

  plugin->record.name = name;
  plugin->record.version = version;
  plugin->record.status = builtIn ? PluginStatus::BuiltIn : PluginStatus::Loaded;
  plugin->record.factories = std::move(keys);
  PluginRecord out = plugin->record;
  log::info("plugin %s %s %s (%zu factories)%s%s", name.c_str(), version.c_str(),
            builtIn ? "registered" : "loaded", out.factories.size(), builtIn ? "" : " from ",
            builtIn ? "" : where.c_str());
  loaded_.push_back(std::move(plugin));
  return out;
}

void PluginLinker::unloadLocked(std::size_t index) {
  std::shared_ptr<Loaded> plugin = loaded_[index];
  loaded_.erase(loaded_.begin() + static_cast<std::ptrdiff_t>(index));
  // No new lookups first, then let the plugin release its resources; the
  // library closes when the last Factory copy lets go of it.
  for (const auto& key : plugin->record.factories) (void)registry_.remove(key.kind, key.name);
  try {
    if (plugin->info && plugin->info->shutdown) plugin->info->shutdown();
  } catch (...) {
    log::error("plugin %s: shutdown threw an exception across the C boundary", plugin->record.name.c_str());
  }
  log::info("plugin %s unloaded", plugin->record.name.c_str());
}

Status PluginLinker::unload(std::string_view name) {
  std::lock_guard lock(mutex_);
  for (std::size_t i = 0; i < loaded_.size(); ++i) {
    if (loaded_[i]->record.name == name) {
      unloadLocked(i);
      return ok();
    }
  }
  std::vector<std::string> names;
  for (const auto& p : loaded_) names.push_back(p->record.name);
  return fail(ErrorCode::NotFound, "no plugin named '" + std::string(name) + "' is loaded; loaded: " +
                                       (names.empty() ? std::string("none") : joinNames(names)));
}

ScanReport PluginLinker::scanLocked(const std::vector<std::filesystem::path>& dirs) {
  ScanReport report;
  for (const auto& dir : dirs) {
    std::error_code ec;
    if (!std::filesystem::is_directory(dir, ec)) {
      (void)refuseLocked(dir, fail(ErrorCode::NotFound, "plugin directory does not exist", str(dir),
                                   "create it or remove it from the plugin search path"));
      report.refused.push_back(failures_.back());
      continue;
    }
    std::vector<std::filesystem::path> files;
    for (std::filesystem::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
      std::error_code fec;
      if (hasPluginSuffix(it->path()) && it->is_regular_file(fec)) files.push_back(it->path());
    }
    if (ec) {
      (void)refuseLocked(dir, fail(ErrorCode::Io, "cannot list plugin directory: " + ec.message(), str(dir),
                                   "check its permissions"));
      report.refused.push_back(failures_.back());
      continue;
    }
    std::sort(files.begin(), files.end());
    for (const auto& f : files) {
      const auto canonical = canonicalOr(f);
      const bool already = std::any_of(loaded_.begin(), loaded_.end(), [&](const auto& p) {
        return p->library && p->record.path == canonical;
      });
      if (already) continue;
      if (auto r = loadFileLocked(canonical))
        report.loaded.push_back(std::move(*r));
      else
        report.refused.push_back(failures_.back());
    }
  }
  return report;
}

ScanReport PluginLinker::scan() {
  const auto dirs = searchPaths();
  std::lock_guard lock(mutex_);
  return scanLocked(dirs);
}

ScanReport PluginLinker::scanDirectory(const std::filesystem::path& dir) {
  std::lock_guard lock(mutex_);
  return scanLocked({dir});
}

std::vector<PluginRecord> PluginLinker::plugins() const {
  std::lock_guard lock(mutex_);
  std::vector<PluginRecord> out;
  out.reserve(loaded_.size());
  for (const auto& p : loaded_) out.push_back(p->record);
  return out;
}

std::vector<PluginRecord> PluginLinker::failures() const {
  std::lock_guard lock(mutex_);
  return failures_;
}

void PluginLinker::clearFailures() {
  std::lock_guard lock(mutex_);
  failures_.clear();
}

}  // namespace dm
