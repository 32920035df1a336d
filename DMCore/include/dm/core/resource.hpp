// dm/core/resource.hpp — the resource manager: one instance per asset,
// shared by typed, reference-counted handles, loaded synchronously or on the
// oneTBB task pool, hot-reloadable.
//
// An asset is identified by (type, canonical file path, import options).
// Paths go through FileSystem::global().resolve() first, so mount names such
// as "mricron:ch2.nii.gz" and DM_DATA_PATH entries work.
// Loading the same asset again while any handle to it is alive returns the
// same instance (the cache is weak: releasing every handle frees the asset).
// Concurrent loads of one asset are coalesced: the loader runs once and every
// caller gets the same handle. reload() re-runs the loader and swaps the
// content atomically; every handle sees the new content and version, and a
// failed reload keeps the old content.
//
// Loaders are registered per type and per file extension (case-insensitive;
// multi-part extensions such as ".nii.gz" work, the longest match wins).
//
// @code
//   dm::ResourceManager rm;
//   rm.registerLoader<Text>({".txt"}, [](const auto& p, const dm::ImportOptions&) { return readText(p); });
//   dm::Result<dm::Handle<Text>> h = rm.load<Text>("notes.txt");
// @endcode
#pragma once

#include <dm/core/assert.hpp>
#include <dm/core/result.hpp>

#include <cstdint>
#include <filesystem>
#include <functional>
#include <initializer_list>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <string_view>
#include <typeindex>
#include <typeinfo>
#include <utility>
#include <vector>

namespace dm {

/// Import options of an asset: a small sorted string key/value map, part of
/// the asset's identity ("scale=0.001" and "scale=1" are two instances).
///
/// @code
///   dm::ImportOptions o{{"scale", "0.001"}, {"flip", "y"}};
///   o.set("smooth", "2");
///   std::string s = o.canonical();  // "flip=y;scale=0.001;smooth=2"
/// @endcode
class ImportOptions {
 public:
  using Map = std::map<std::string, std::string, std::less<>>;

  ImportOptions() = default;
  /// From {{"key", "value"}, ...}; a repeated key keeps its first value.
  ImportOptions(std::initializer_list<std::pair<const std::string, std::string>> items) : values_(items) {}

  /// Sets (or replaces) `key`; returns *this for chaining.
  ImportOptions& set(std::string key, std::string value) {
    values_.insert_or_assign(std::move(key), std::move(value));
    return *this;
  }
  /// The value of `key`, or nullptr if absent.
  const std::string* find(std::string_view key) const {
    auto it = values_.find(key);
    return it == values_.end() ? nullptr : &it->second;
  }
  /// The value of `key`, or `fallback` if absent.
  std::string getOr(std::string_view key, std::string_view fallback) const {
    const std::string* v = find(key);
    return v ? *v : std::string(fallback);
  }
  /// True if `key` is set.
  bool contains(std::string_view key) const { return find(key) != nullptr; }
  /// True if no option is set.
  bool empty() const noexcept { return values_.empty(); }
  /// Number of options.
  std::size_t size() const noexcept { return values_.size(); }
  /// All options, sorted by key.
  const Map& values() const noexcept { return values_; }

  /// Canonical serialisation "k1=v1;k2=v2" in key order; '\\', '=' and ';'
  /// inside keys and values are escaped with '\\', so two option sets are
  /// equal exactly when their canonical strings are. O(total length).
  std::string canonical() const;

  /// Same keys and values.
  friend bool operator==(const ImportOptions&, const ImportOptions&) = default;

 private:
  Map values_;
};

namespace detail {

/// Shared state of one asset (type-erased content). Internal: use Handle<T>.
class AssetCore {
 public:
  AssetCore(std::uint64_t id, std::filesystem::path path, ImportOptions options, std::type_index type,
            std::shared_ptr<const void> content)
      : id_(id),
        path_(std::move(path)),
        options_(std::move(options)),
        type_(type),
        content_(std::move(content)) {}
  AssetCore(const AssetCore&) = delete;
  AssetCore& operator=(const AssetCore&) = delete;

  std::shared_ptr<const void> content() const {
    std::lock_guard lock(mutex_);
    return content_;
  }
  std::pair<std::shared_ptr<const void>, std::uint64_t> snapshot() const {
    std::lock_guard lock(mutex_);
    return {content_, version_};
  }
  std::uint64_t version() const {
    std::lock_guard lock(mutex_);
    return version_;
  }
  /// Swaps in new content and bumps the version; the old content is
  /// released after the lock (by the caller's argument going out of scope).
  void replace(std::shared_ptr<const void>& content) {
    std::lock_guard lock(mutex_);
    content_.swap(content);
    ++version_;
  }
  std::uint64_t id() const noexcept { return id_; }
  const std::filesystem::path& path() const noexcept { return path_; }
  const ImportOptions& options() const noexcept { return options_; }
  std::type_index type() const noexcept { return type_; }

 private:
  const std::uint64_t id_;
  const std::filesystem::path path_;
  const ImportOptions options_;
  const std::type_index type_;
  mutable std::mutex mutex_;
  std::shared_ptr<const void> content_;
  std::uint64_t version_ = 1;
};

}  // namespace detail

/// A typed, reference-counted reference to one asset. Copying is cheap (one
/// atomic increment); the asset lives while any handle to it does. An empty
/// (default) handle refers to nothing. Thread-safe to copy and read.
///
/// @code
///   dm::Handle<Mesh> h = *rm.load<Mesh>("liver.obj");
///   std::shared_ptr<const Mesh> m = h.get();  // stays valid across reloads
///   std::size_t n = h->positions.size();      // pins the content for the expression
/// @endcode
template <class T>
class Handle {
 public:
  /// Keeps one content snapshot alive while dereferenced (operator->).
  class Pin {
   public:
    const T* operator->() const noexcept { return p_.get(); }
    const T& operator*() const noexcept { return *p_; }

   private:
    friend class Handle;
    explicit Pin(std::shared_ptr<const T> p) : p_(std::move(p)) {}
    std::shared_ptr<const T> p_;
  };

  /// An empty handle (refers to nothing).
  Handle() = default;

  /// True if the handle refers to an asset.
  bool valid() const noexcept { return core_ != nullptr; }
  /// Same as valid().
  explicit operator bool() const noexcept { return valid(); }

  /// The current content. The returned pointer keeps that content alive even
  /// if the asset is reloaded meanwhile (then it is the old version). O(1),
  /// takes the asset's mutex briefly. DM_DEMAND: the handle is valid.
  std::shared_ptr<const T> get() const {
    DM_DEMAND(core_ != nullptr, "Handle::get() on an empty handle");
    return std::static_pointer_cast<const T>(core_->content());
  }
  /// Member access on the current content, pinned for the full expression.
  Pin operator->() const { return Pin(get()); }

  /// Content and its version, read together.
  std::pair<std::shared_ptr<const T>, std::uint64_t> snapshot() const {
    DM_DEMAND(core_ != nullptr, "Handle::snapshot() on an empty handle");
    auto [c, v] = core_->snapshot();
    return {std::static_pointer_cast<const T>(std::move(c)), v};
  }
  /// 1 after the first load; +1 per successful reload.
  std::uint64_t version() const {
    DM_DEMAND(core_ != nullptr, "Handle::version() on an empty handle");
    return core_->version();
  }
  /// Canonical path of the asset.
  const std::filesystem::path& path() const {
    DM_DEMAND(core_ != nullptr, "Handle::path() on an empty handle");
    return core_->path();
  }
  /// Import options of the asset.
  const ImportOptions& options() const {
    DM_DEMAND(core_ != nullptr, "Handle::options() on an empty handle");
    return core_->options();
  }
  /// Identifier of the asset instance, unique within the process and never
  /// reused (a freed and reloaded asset gets a new id); 0 for empty handles.
  std::uint64_t id() const noexcept { return core_ ? core_->id() : 0; }
  /// Number of handles to this asset (including this one; approximate while
  /// other threads copy handles); 0 for empty handles.
  long useCount() const noexcept { return core_.use_count(); }
  /// Releases this reference.
  void reset() noexcept { core_.reset(); }

  /// Same asset instance.
  friend bool operator==(const Handle& a, const Handle& b) noexcept { return a.core_ == b.core_; }

 private:
  friend class ResourceManager;
  explicit Handle(std::shared_ptr<detail::AssetCore> core) : core_(std::move(core)) {}
  std::shared_ptr<detail::AssetCore> core_;
};

/// Loader of assets of type T: reads `path` (canonical, existing) with
/// `options`; returns the asset or an Error saying what, where and what to do.
/// Must be thread-safe (it may run on several worker threads at once for
/// different assets) and must not throw (exceptions become Internal errors).
template <class T>
using Loader = std::function<Result<T>(const std::filesystem::path& path, const ImportOptions& options)>;

/// Counters of a ResourceManager.
struct ResourceStats {
  std::size_t liveAssets = 0;     ///< assets with at least one live handle
  std::uint64_t loads = 0;        ///< loader invocations for first loads (successful or not)
  std::uint64_t reloads = 0;      ///< loader invocations by reload()
  std::uint64_t failedLoads = 0;  ///< loads and reloads whose loader (or file check) failed
  std::uint64_t cacheHits = 0;    ///< load requests served by a live instance or a pending load
  std::size_t pendingAsync = 0;   ///< async loads and callbacks not yet finished
};

/// Owns the asset cache, the loader table and the async task queue. All
/// member functions are thread-safe. The destructor waits for pending async
/// loads; handles may outlive the manager.
///
/// @code
///   dm::ResourceManager rm;
///   rm.registerLoader<Volume>({".nii", ".nii.gz"}, loadNifti);
///   rm.loadAsync<Volume>("head.nii.gz", {}, [](dm::Result<dm::Handle<Volume>> v) { ... });
/// @endcode
class ResourceManager {
 public:
  ResourceManager();
  ~ResourceManager();
  ResourceManager(const ResourceManager&) = delete;
  ResourceManager& operator=(const ResourceManager&) = delete;

  /// Registers `loader` for assets of type T in files ending with any of
  /// `extensions` (each starts with '.', case-insensitive, may have several
  /// parts like ".nii.gz"). Fails (InvalidArgument) on a malformed extension,
  /// an empty list or loader, or an extension already registered for T.
  template <class T>
  Status registerLoader(std::vector<std::string> extensions, Loader<T> loader) {
    if (!loader)
      return fail(ErrorCode::InvalidArgument, "empty loader function", typeName(typeid(T)),
                  "pass a callable");
    ErasedLoader erased = [fn = std::move(loader)](
                              const std::filesystem::path& p,
                              const ImportOptions& o) -> Result<std::shared_ptr<const void>> {
      Result<T> r = fn(p, o);
      if (!r) return std::move(r).error();
      return std::shared_ptr<const void>(std::make_shared<const T>(std::move(r).value()));
    };
    return registerErased(typeid(T), std::move(extensions), std::move(erased));
  }

  /// Extensions registered for T, lower case, sorted.
  template <class T>
  std::vector<std::string> extensions() const {
    return extensionsErased(typeid(T));
  }

  /// Loads (or finds) the asset of type T at `path` with `options` and
  /// blocks until it is available. Fails with NotFound (no such file; the
  /// message names the path), Unsupported (no loader for the extension; the
  /// message lists T's registered extensions) or the loader's error.
  template <class T>
  Result<Handle<T>> load(const std::filesystem::path& path, const ImportOptions& options = {}) {
    auto core = loadErased(typeid(T), path, options);
    if (!core) return std::move(core).error();
    return Handle<T>(std::move(core).value());
  }

  /// Starts loading on the oneTBB task pool and returns at once; `callback`
  /// later receives the handle or the error, on a worker thread (also when
  /// the asset is already cached). Concurrent requests for one asset share
  /// one loader run. Callbacks must not call waitIdle().
  template <class T>
  void loadAsync(const std::filesystem::path& path, const ImportOptions& options,
                 std::function<void(Result<Handle<T>>)> callback) {
    loadAsyncErased(typeid(T), path, options,
                    [cb = std::move(callback)](Result<std::shared_ptr<detail::AssetCore>> r) {
                      if (!cb) return;
                      if (!r)
                        cb(Result<Handle<T>>(std::move(r).error()));
                      else
                        cb(Result<Handle<T>>(Handle<T>(std::move(r).value())));
                    });
  }

  /// Re-runs the loader of `handle`'s asset (on the calling thread) and, on
  /// success, swaps the content for every handle and bumps the version. On
  /// failure the old content stays and the error is returned.
  template <class T>
  Status reload(const Handle<T>& handle) {
    if (!handle.valid())
      return fail(ErrorCode::InvalidArgument, "reload of an empty handle", {}, "load the asset first");
    return reloadErased(handle.core_);
  }

  /// Blocks until every pending async load and callback has finished.
  void waitIdle();

  /// Current counters.
  ResourceStats stats() const;

 private:
  using ErasedLoader =
      std::function<Result<std::shared_ptr<const void>>(const std::filesystem::path&, const ImportOptions&)>;
  using ErasedCallback = std::function<void(Result<std::shared_ptr<detail::AssetCore>>)>;

  static std::string typeName(std::type_index type);
  Status registerErased(std::type_index type, std::vector<std::string> extensions, ErasedLoader loader);
  std::vector<std::string> extensionsErased(std::type_index type) const;
  Result<std::shared_ptr<detail::AssetCore>> loadErased(std::type_index type,
                                                        const std::filesystem::path& path,
                                                        const ImportOptions& options);
  void loadAsyncErased(std::type_index type, const std::filesystem::path& path, const ImportOptions& options,
                       ErasedCallback callback);
  Status reloadErased(const std::shared_ptr<detail::AssetCore>& core);

  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace dm
