// dm/core/plugin.hpp — factory registry and plugin linker.
//
// Device drivers, importers and colliders are factories identified by
// (kind, name): a kind is an extension point owned by a module (DMIO owns
// "importer", DMHaptics owns "haptic-device"), which defines the kind's C
// vtable and its kind ABI version. Factories come from two places through
// the same path:
//  * plugins: shared libraries with one C entry point (dm/core/plugin_abi.h),
//    found in plugin directories and loaded by dm::PluginLinker;
//  * built-in drivers: registered statically, either with
//    PluginLinker::addStatic(entry) (same checks, same init protocol) or
//    directly with FactoryRegistry::add().
//
// The linker checks the plugin ABI version before anything else and refuses
// a plugin with a dm::Error naming the file and the reason (not found, not a
// shared object, unresolved symbol, no entry point, wrong ABI version, init
// failure, duplicate factory). A refused plugin leaves no state behind: its
// factories are removed and the library is unloaded. In probe mode a plugin
// is first loaded and initialised in the dm-plugin-probe program (a fresh
// process started with posix_spawn, safe whatever threads the host runs;
// found as dm/core/helper_program.hpp says, DM_PLUGIN_PROBE overrides), so a
// plugin that crashes or hangs in its initialisers or init is refused
// without taking the host down.
//
// @code
//   dm::FactoryRegistry registry;
//   dm::PluginLinker linker(registry, {.searchPaths = {"/opt/dm/plugins"}});
//   auto report = linker.scan();  // loads every good plugin, reports the rest
//   auto adder = registry.vtable<AdderVTable>("test-adder", "adder", 1);
// @endcode
#pragma once

#include <dm/core/plugin_abi.h>
#include <dm/core/result.hpp>

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace dm {

/// (kind, name) of a factory, e.g. {"haptic-device", "sim-haptic"}.
struct FactoryKey {
  std::string kind;
  std::string name;
  friend bool operator==(const FactoryKey&, const FactoryKey&) = default;
  friend auto operator<=>(const FactoryKey&, const FactoryKey&) = default;
};

/// One registered factory: a kind-specific C vtable and its layout version.
/// `vtable` points into the providing library; a Factory copy keeps that
/// library mapped (keepAlive) even after the plugin is unloaded, but the
/// plugin's shutdown has then run, so only use factories of loaded plugins.
struct Factory {
  FactoryKey key;
  std::uint32_t kindAbiVersion = 0;       ///< layout version of the kind's vtable
  const void* vtable = nullptr;           ///< kind-specific C struct of function pointers
  std::string provider;                   ///< plugin name, or "static" for built-ins
  std::filesystem::path providerPath;     ///< library file; empty for built-ins
  std::shared_ptr<const void> keepAlive;  ///< keeps the providing library loaded

  /// The vtable as the kind's C struct; the caller checked kindAbiVersion.
  template <class VTable>
  const VTable* as() const noexcept {
    return static_cast<const VTable*>(vtable);
  }
};

/// Thread-safe map (kind, name) -> Factory. All operations lock one mutex;
/// lookups are O(log n) and copy one Factory.
///
/// @code
///   registry.add("importer", "obj", 1, &kObjImporterVTable);
///   auto f = registry.find("importer", "obj", 1);
///   if (f) f->as<ImporterVTable>()->open(...);
/// @endcode
class FactoryRegistry {
 public:
  FactoryRegistry() = default;
  FactoryRegistry(const FactoryRegistry&) = delete;
  FactoryRegistry& operator=(const FactoryRegistry&) = delete;

  /// Registers a built-in factory. Fails (InvalidArgument) on empty kind or
  /// name or null vtable, (InvalidArgument) if (kind, name) is taken, naming
  /// the provider that holds it. `vtable` must outlive its registration.
  Status add(std::string_view kind, std::string_view name, std::uint32_t kindAbiVersion, const void* vtable,
             std::string_view provider = "static");

  /// Registers all factories or none (same checks as add(), also among
  /// `factories` themselves). Used by the plugin linker.
  Status addAll(std::vector<Factory> factories);

  /// Removes one factory; NotFound if absent.
  Status remove(std::string_view kind, std::string_view name);

  /// The factory (kind, name); NotFound lists the names registered for kind.
  Result<Factory> find(std::string_view kind, std::string_view name) const;

  /// As find(), and Version error unless its kind ABI equals expectedKindAbi
  /// (the message says found vs expected and to rebuild the provider).
  Result<Factory> find(std::string_view kind, std::string_view name, std::uint32_t expectedKindAbi) const;

  /// The vtable of (kind, name) as `VTable`, checked against expectedKindAbi.
  /// The pointer is valid while the providing plugin stays loaded.
  template <class VTable>
  Result<const VTable*> vtable(std::string_view kind, std::string_view name,
                               std::uint32_t expectedKindAbi) const {
    auto f = find(kind, name, expectedKindAbi);
    if (!f) return std::move(f).error();
    return f->template as<VTable>();
  }

  /// Every factory of `kind` (all kinds if empty), sorted by (kind, name).
  std::vector<Factory> list(std::string_view kind = {}) const;

  /// True if (kind, name) is registered.
  bool contains(std::string_view kind, std::string_view name) const;

  /// Number of registered factories.
  std::size_t size() const;

 private:
  Status checkNewLocked(const Factory& f) const;

  mutable std::mutex mutex_;
  std::map<FactoryKey, Factory, std::less<>> factories_;
};

/// State of a plugin known to the linker.
enum class PluginStatus : std::uint8_t {
  Loaded,   ///< loaded from a shared library, factories registered
  BuiltIn,  ///< registered with addStatic(), factories registered
  Refused,  ///< refused; see PluginRecord::error
};

/// "loaded", "built-in" or "refused".
const char* toString(PluginStatus status) noexcept;

/// What the linker knows about one plugin (loaded, built-in or refused).
struct PluginRecord {
  std::string name;            ///< from the plugin table; empty if refused before reading it
  std::string version;         ///< from the plugin table; may be empty
  std::filesystem::path path;  ///< canonical library path; empty for built-ins
  PluginStatus status = PluginStatus::Refused;
  std::vector<FactoryKey> factories;  ///< registered factories (none if refused)
  Error error;                        ///< why it was refused (status Refused only)
};

/// Result of scanning directories: every good plugin loaded, every bad one
/// reported; a bad plugin never stops the scan.
struct ScanReport {
  std::vector<PluginRecord> loaded;   ///< status Loaded
  std::vector<PluginRecord> refused;  ///< status Refused, with error
};

/// Configuration of a PluginLinker.
struct PluginLinkerOptions {
  /// Directories searched by load(name) and scan(), after DM_PLUGIN_PATH.
  std::vector<std::filesystem::path> searchPaths;
  /// Also search the directories in the DM_PLUGIN_PATH environment variable
  /// (':'-separated), before searchPaths.
  bool useEnvironment = true;
  /// Load and init every plugin in the dm-plugin-probe program first;
  /// refuse it if the probe crashes (signal) or does not finish within
  /// probeTimeout. The plugin's static initializers, init and shutdown then
  /// run twice (probe, then host); costs one process start per plugin file
  /// (POSIX only). A missing probe program is a NotFound error.
  bool probe = false;
  /// Time the probe process may take to load, init and shut down a plugin.
  std::chrono::milliseconds probeTimeout{5000};
};

/// Loads plugins into a FactoryRegistry (which must outlive the linker).
/// Thread-safe: loads and unloads are serialised; plugin init runs on the
/// calling thread and must not call back into the linker. The destructor
/// unloads every plugin in reverse load order.
///
/// @code
///   dm::PluginLinker linker(registry, {.searchPaths = {dir}, .probe = true});
///   if (auto p = linker.load("sim_haptic"); !p) std::cerr << p.error() << '\n';
///   linker.unload("sim-haptic");
/// @endcode
class PluginLinker {
 public:
  explicit PluginLinker(FactoryRegistry& registry, PluginLinkerOptions options = {});
  ~PluginLinker();
  PluginLinker(const PluginLinker&) = delete;
  PluginLinker& operator=(const PluginLinker&) = delete;

  /// Directories searched, in order: DM_PLUGIN_PATH (if enabled), then the
  /// configured search paths.
  std::vector<std::filesystem::path> searchPaths() const;
  /// Appends a directory to the configured search paths.
  void addSearchPath(std::filesystem::path dir);

  /// Loads one plugin. `fileOrName` is a path (absolute, or containing a
  /// directory separator) or a bare name looked up in searchPaths() as
  /// `name`, `lib<name>.so`, `<name>.so`. On success returns the Loaded
  /// record; on failure an Error naming the file and the reason, with no
  /// state left behind (the failure is also kept in failures()).
  Result<PluginRecord> load(const std::filesystem::path& fileOrName);

  /// Registers a built-in plugin through the same protocol as a loaded one
  /// (ABI check, init, factories, shutdown on unload), without a library.
  Result<PluginRecord> addStatic(DmPluginEntryFn entry);

  /// Unloads the plugin `name`: removes its factories, calls shutdown, and
  /// closes the library. NotFound if no such plugin is loaded.
  Status unload(std::string_view name);

  /// Loads every plugin file (platform shared-library suffix) in every
  /// search path, in sorted order; already loaded files are skipped.
  ScanReport scan();
  /// As scan() for one directory; a missing directory is one refusal.
  ScanReport scanDirectory(const std::filesystem::path& dir);

  /// Loaded and built-in plugins, in load order.
  std::vector<PluginRecord> plugins() const;
  /// Refused loads since construction (or clearFailures()), oldest first.
  std::vector<PluginRecord> failures() const;
  /// Forgets the recorded failures.
  void clearFailures();

  /// The registry this linker fills.
  FactoryRegistry& registry() noexcept { return registry_; }

 private:
  struct Loaded;
  Result<PluginRecord> loadFileLocked(const std::filesystem::path& file);
  Result<PluginRecord> initLocked(std::shared_ptr<Loaded> plugin, const DmPluginInfo* info,
                                  const std::string& where);
  Error refuseLocked(const std::filesystem::path& path, Error error);
  void unloadLocked(std::size_t index);
  ScanReport scanLocked(const std::vector<std::filesystem::path>& dirs);

  FactoryRegistry& registry_;
  PluginLinkerOptions options_;
  mutable std::mutex mutex_;
  std::vector<std::shared_ptr<Loaded>> loaded_;
  std::vector<PluginRecord> failures_;
};

}  // namespace dm
