// Resource manager: weak asset cache keyed by (type, canonical path, import
// options), loader table per type and extension, coalesced sync/async loads
// on a oneTBB arena, atomic reload.
#include <dm/core/filesystem.hpp>
#include <dm/core/log.hpp>
#include <dm/core/resource.hpp>

#include <tbb/task_arena.h>

#include <cxxabi.h>

#if defined(__SANITIZE_THREAD__)
#define DM_RESOURCE_TSAN 1
#elif defined(__has_feature)
#if __has_feature(thread_sanitizer)
#define DM_RESOURCE_TSAN 1
#endif
#endif
#ifndef DM_RESOURCE_TSAN
#define DM_RESOURCE_TSAN 0
#endif

#include <algorithm>
#include <atomic>
#include <cctype>
#include <condition_variable>
#include <cstdlib>
#include <exception>
#include <optional>
#include <set>
#include <thread>
#include <tuple>

namespace dm {

namespace fs = std::filesystem;

namespace {

using CoreResult = Result<std::shared_ptr<detail::AssetCore>>;

std::atomic<std::uint64_t> gNextAssetId{1};

std::string lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

void escapeInto(std::string& out, const std::string& s) {
  for (char c : s) {
    if (c == '\\' || c == '=' || c == ';') out += '\\';
    out += c;
  }
}

// Why an extension string is malformed, or empty if it is fine.
std::string extensionProblem(const std::string& ext) {
  if (ext.size() < 2 || ext[0] != '.') return "must start with '.' and name at least one character";
  if (ext.back() == '.') return "must not end with '.'";
  if (ext.find("..") != std::string::npos) return "must not contain an empty part ('..')";
  for (char c : ext)
    if (c == '/' || c == '\\' || c == '\0') return "must not contain path separators";
  return {};
}

std::string join(const std::vector<std::string>& items) {
  std::string s;
  for (const auto& i : items) {
    if (!s.empty()) s += ", ";
    s += i;
  }
  return s;
}

}  // namespace

std::string ImportOptions::canonical() const {
  std::string out;
  for (const auto& [k, v] : values_) {
    if (!out.empty()) out += ';';
    escapeInto(out, k);
    out += '=';
    escapeInto(out, v);
  }
  return out;
}

struct ResourceManager::Impl {
  using Key = std::tuple<std::type_index, std::string, std::string>;  // type, canonical path, options
  using LoaderPtr = std::shared_ptr<const ErasedLoader>;

  // One in-flight load of one asset; every requester waits on it.
  struct Pending {
    enum class State { Queued, Running, Done };
    Key key;
    std::type_index type;
    fs::path path;
    ImportOptions options;
    LoaderPtr loader;
    State state = State::Queued;
    std::vector<ErasedCallback> callbacks;
    std::optional<CoreResult> result;
  };
  using PendingPtr = std::shared_ptr<Pending>;

  // What a request found: an error, a live asset, or a pending load (which
  // the requester must start if it created it).
  struct Acquired {
    std::optional<Error> error;
    std::shared_ptr<detail::AssetCore> asset;
    PendingPtr pending;
    bool created = false;
  };

  mutable std::mutex mutex;
  std::condition_variable loadDone;  // some Pending became Done
  std::condition_variable idle;      // asyncCount dropped to 0
  std::map<std::type_index, std::map<std::string, LoaderPtr>> loaders;
  std::map<Key, std::weak_ptr<detail::AssetCore>> assets;
  std::map<Key, PendingPtr> pending;
  std::size_t sweepAt = 64;
  std::size_t asyncCount = 0;
  std::uint64_t loads = 0, reloads = 0, failedLoads = 0, cacheHits = 0;
  tbb::task_arena arena;

  // Loader for `path` as `type`: longest registered extension that the file
  // name ends with (case-insensitive). Caller holds the mutex.
  Result<LoaderPtr> findLoaderLocked(std::type_index type, const fs::path& path) const {
    auto it = loaders.find(type);
    if (it == loaders.end() || it->second.empty())
      return fail(ErrorCode::Unsupported, "no loader is registered for " + typeName(type), path.string(),
                  "register one with ResourceManager::registerLoader<" + typeName(type) + ">()");
    const std::string name = lower(path.filename().string());
    const LoaderPtr* best = nullptr;
    std::size_t bestLen = 0;
    for (const auto& [ext, loader] : it->second) {
      if (name.size() > ext.size() && ext.size() > bestLen && name.ends_with(ext)) {
        best = &loader;
        bestLen = ext.size();
      }
    }
    if (!best) {
      std::vector<std::string> exts;
      for (const auto& [ext, loader] : it->second) exts.push_back(ext);
      return fail(ErrorCode::Unsupported,
                  "no " + typeName(type) + " loader for '" + path.filename().string() +
                      "'; registered extensions for " + typeName(type) + ": " + join(exts),
                  path.string(),
                  "convert the file to a supported format or register a loader for its extension");
    }
    return *best;
  }

  void sweepLocked() {
    if (assets.size() < sweepAt) return;
    std::erase_if(assets, [](const auto& kv) { return kv.second.expired(); });
    sweepAt = std::max<std::size_t>(64, 2 * assets.size());
  }

  Acquired acquire(std::type_index type, const fs::path& requested, const ImportOptions& options,
                   ErasedCallback* callback) {
    Acquired out;
    if (requested.empty()) {
      out.error = fail(ErrorCode::InvalidArgument, "empty resource path", {}, "pass a file path");
      return out;
    }
    // Mount names ("mricron:ch2.nii.gz") and DM_DATA_PATH entries resolve
    // through the file system; anything else is taken as given, so a missing
    // file still reports "file does not exist" at load time.
    fs::path located = requested;
    if (auto r = FileSystem::global().resolve(requested.string())) located = *r;
    std::error_code ec;
    fs::path path = fs::weakly_canonical(located, ec);
    if (ec) {
      out.error = fail(ErrorCode::Io, "cannot resolve the path: " + ec.message(), requested.string(),
                       "check the path and its permissions");
      return out;
    }
    Key key{type, path.string(), options.canonical()};
    std::lock_guard lock(mutex);
    auto loader = findLoaderLocked(type, path);
    if (!loader) {
      out.error = std::move(loader).error();
      return out;
    }
    if (auto it = assets.find(key); it != assets.end()) {
      if (auto live = it->second.lock()) {
        ++cacheHits;
        out.asset = std::move(live);
        return out;
      }
    }
    if (auto it = pending.find(key); it != pending.end()) {
      ++cacheHits;
      out.pending = it->second;
      if (callback) out.pending->callbacks.push_back(std::move(*callback));
      return out;
    }
    auto p =
        std::make_shared<Pending>(Pending{key, type, std::move(path), options, std::move(loader).value()});
    if (callback) p->callbacks.push_back(std::move(*callback));
    pending.emplace(std::move(key), p);
    out.pending = std::move(p);
    out.created = true;
    return out;
  }

  // Checks the file and runs the loader, converting exceptions to errors.
  static Result<std::shared_ptr<const void>> runLoader(const ErasedLoader& loader, const fs::path& path,
                                                       const ImportOptions& options) {
    std::error_code ec;
    if (!fs::exists(path, ec))
      return fail(ErrorCode::NotFound, "file does not exist", path.string(),
                  "check the path (relative paths are resolved against the working directory)");
    if (fs::is_directory(path, ec))
      return fail(ErrorCode::InvalidArgument, "is a directory, not a file", path.string(),
                  "pass a file path");
    Result<std::shared_ptr<const void>> r = fail(ErrorCode::Internal, "loader did not run");
    try {
      r = loader(path, options);
    } catch (const std::exception& e) {
      return fail(ErrorCode::Internal, std::string("loader threw an exception: ") + e.what(), path.string(),
                  "loaders must return dm::Result errors, not throw");
    } catch (...) {
      return fail(ErrorCode::Internal, "loader threw an exception", path.string(),
                  "loaders must return dm::Result errors, not throw");
    }
    if (!r) {
      Error e = std::move(r).error();
      if (e.where.empty()) e.where = path.string();
      return e;
    }
    if (!r.value())
      return fail(ErrorCode::Internal, "loader returned no content", path.string(), "please report");
    return r;
  }

  // Runs the load of `p` on this thread if nobody has started it yet.
  void run(const PendingPtr& p) {
    {
      std::lock_guard lock(mutex);
      if (p->state != Pending::State::Queued) return;
      p->state = Pending::State::Running;
    }
    auto content = runLoader(*p->loader, p->path, p->options);
    CoreResult result = fail(ErrorCode::Internal, "unset");
    if (content)
      result = std::make_shared<detail::AssetCore>(gNextAssetId.fetch_add(1), p->path, p->options, p->type,
                                                   std::move(content).value());
    else
      result = std::move(content).error();
    complete(p, std::move(result));
  }

  void complete(const PendingPtr& p, CoreResult result) {
    std::vector<ErasedCallback> callbacks;
    {
      std::lock_guard lock(mutex);
      ++loads;
      if (!result) ++failedLoads;
      if (result) {
        sweepLocked();
        assets[p->key] = result.value();
      }
      if (auto it = pending.find(p->key); it != pending.end() && it->second == p) pending.erase(it);
      p->result = result;
      p->state = Pending::State::Done;
      callbacks.swap(p->callbacks);
      loadDone.notify_all();
    }
    for (auto& cb : callbacks) schedule([cb = std::move(cb), result]() mutable { cb(std::move(result)); });
  }

  // Waits until `p` is done (running it here if it has not started).
  CoreResult wait(const PendingPtr& p) {
    run(p);
    std::unique_lock lock(mutex);
    loadDone.wait(lock, [&] { return p->state == Pending::State::Done; });
    return *p->result;
  }

  // Runs `fn` on the task pool; counted for waitIdle(). The function (and
  // what it captured, e.g. handles) is destroyed before the count drops.
  void schedule(std::function<void()> fn) {
    {
      std::lock_guard lock(mutex);
      ++asyncCount;
    }
    auto holder = std::make_shared<std::function<void()>>(std::move(fn));
#if DM_RESOURCE_TSAN
    // oneTBB as packaged is not built with ThreadSanitizer, so TSan cannot
    // see the happens-before edge of its task hand-off and reports every
    // enqueued task as a race. Under TSan the same tasks run on plain
    // threads, so that TSan checks this file's own synchronisation.
    std::thread([this, holder] { runTask(*holder); }).detach();
#else
    arena.enqueue([this, holder] { runTask(*holder); });
#endif
  }

  void runTask(std::function<void()>& fn) {
    {
      std::function<void()> local = std::move(fn);
      fn = nullptr;
      try {
        local();
      } catch (const std::exception& e) {
        log::error("resource manager: an async callback threw: %s", e.what());
      } catch (...) {
        log::error("resource manager: an async callback threw an exception");
      }
    }
    std::lock_guard lock(mutex);
    if (--asyncCount == 0) idle.notify_all();
  }
};

ResourceManager::ResourceManager() : impl_(std::make_unique<Impl>()) {}

ResourceManager::~ResourceManager() { waitIdle(); }

std::string ResourceManager::typeName(std::type_index type) {
  int status = 0;
  char* demangled = abi::__cxa_demangle(type.name(), nullptr, nullptr, &status);
  std::string name = (status == 0 && demangled) ? demangled : type.name();
  std::free(demangled);
  return name;
}

Status ResourceManager::registerErased(std::type_index type, std::vector<std::string> extensions,
                                       ErasedLoader loader) {
  if (extensions.empty())
    return fail(ErrorCode::InvalidArgument, "no file extensions given for the " + typeName(type) + " loader",
                {}, "pass at least one extension, e.g. {\".obj\"}");
  std::set<std::string> normalized;
  for (const auto& e : extensions) {
    std::string ext = lower(e);
    if (auto why = extensionProblem(ext); !why.empty())
      return fail(ErrorCode::InvalidArgument, "bad extension '" + e + "': " + why, typeName(type),
                  "write extensions like \".nii\" or \".nii.gz\"");
    normalized.insert(std::move(ext));
  }
  auto shared = std::make_shared<const ErasedLoader>(std::move(loader));
  std::lock_guard lock(impl_->mutex);
  auto& table = impl_->loaders[type];
  for (const auto& ext : normalized)
    if (table.count(ext))
      return fail(ErrorCode::InvalidArgument, typeName(type) + " already has a loader for '" + ext + "'", {},
                  "register each extension once per type");
  for (const auto& ext : normalized) table.emplace(ext, shared);
  return ok();
}

std::vector<std::string> ResourceManager::extensionsErased(std::type_index type) const {
  std::lock_guard lock(impl_->mutex);
  std::vector<std::string> out;
  if (auto it = impl_->loaders.find(type); it != impl_->loaders.end())
    for (const auto& [ext, loader] : it->second) out.push_back(ext);
  return out;
}

Result<std::shared_ptr<detail::AssetCore>> ResourceManager::loadErased(std::type_index type,
                                                                       const fs::path& path,
                                                                       const ImportOptions& options) {
  auto a = impl_->acquire(type, path, options, nullptr);
  if (a.error) return std::move(*a.error);
  if (a.asset) return std::move(a.asset);
  return impl_->wait(a.pending);
}

void ResourceManager::loadAsyncErased(std::type_index type, const fs::path& path,
                                      const ImportOptions& options, ErasedCallback callback) {
  auto a = impl_->acquire(type, path, options, &callback);
  if (a.error) {
    impl_->schedule([cb = std::move(callback), e = std::move(*a.error)]() mutable {
      if (cb) cb(CoreResult(std::move(e)));
    });
  } else if (a.asset) {
    impl_->schedule([cb = std::move(callback), asset = std::move(a.asset)]() mutable {
      if (cb) cb(CoreResult(std::move(asset)));
    });
  } else if (a.created) {
    // The callback is queued on the pending load; start the load.
    impl_->schedule([impl = impl_.get(), p = std::move(a.pending)] { impl->run(p); });
  }
}

Status ResourceManager::reloadErased(const std::shared_ptr<detail::AssetCore>& core) {
  Impl::LoaderPtr loader;
  {
    std::lock_guard lock(impl_->mutex);
    auto found = impl_->findLoaderLocked(core->type(), core->path());
    if (!found) return std::move(found).error();
    loader = std::move(found).value();
  }
  auto content = Impl::runLoader(*loader, core->path(), core->options());
  {
    std::lock_guard lock(impl_->mutex);
    ++impl_->reloads;
    if (!content) ++impl_->failedLoads;
  }
  if (!content) return std::move(content).error();
  std::shared_ptr<const void> fresh = std::move(content).value();
  core->replace(fresh);  // `fresh` now holds the old content, released below
  return ok();
}

void ResourceManager::waitIdle() {
  std::unique_lock lock(impl_->mutex);
  impl_->idle.wait(lock, [&] { return impl_->asyncCount == 0; });
}

ResourceStats ResourceManager::stats() const {
  std::lock_guard lock(impl_->mutex);
  ResourceStats s;
  for (const auto& [key, weak] : impl_->assets)
    if (!weak.expired()) ++s.liveAssets;
  s.loads = impl_->loads;
  s.reloads = impl_->reloads;
  s.failedLoads = impl_->failedLoads;
  s.cacheHits = impl_->cacheHits;
  s.pendingAsync = impl_->asyncCount;
  return s;
}

}  // namespace dm

#undef DM_RESOURCE_TSAN
