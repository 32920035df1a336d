// Tests of dm::FactoryRegistry and dm::PluginLinker against real plugin
// libraries built from Tests/DMCore/plugins/ (see its CMakeLists.txt).
#include <dm/core/log.hpp>
#include <dm/core/plugin.hpp>

#include <gtest/gtest.h>

#include <dlfcn.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cstdlib>
#include <fstream>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "../common/build_paths.hpp"
#include "core_test_support.hpp"
#include "plugins/test_adder.h"

namespace {

namespace fs = std::filesystem;

fs::path pluginDir(const char* sub) { return fs::path(dm::test::besideExecutable(DM_TEST_PLUGIN_DIR)) / sub; }
fs::path pluginFile(const char* sub, const char* target) {
  return pluginDir(sub) / (std::string("lib") + target + ".so");
}

// True if the library is currently mapped in this process.
bool isMapped(const fs::path& lib) {
  void* h = dlopen(lib.c_str(), RTLD_NOW | RTLD_NOLOAD);
  if (!h) return false;
  dlclose(h);
  return true;
}

using dm::test::contains;

// Captures log messages (plugins log through the host API).
class LogCapture {
 public:
  LogCapture() {
    previous_ = dm::log::level();
    dm::log::setLevel(dm::log::Level::Info);
    dm::log::setSink([this](dm::log::Level, std::string_view msg) {
      std::lock_guard lock(mutex_);
      lines_.emplace_back(msg);
    });
  }
  ~LogCapture() {
    dm::log::setSink({});
    dm::log::setLevel(previous_);
  }
  bool saw(const std::string& part) const {
    std::lock_guard lock(mutex_);
    return std::any_of(lines_.begin(), lines_.end(), [&](const std::string& l) { return contains(l, part); });
  }

 private:
  mutable std::mutex mutex_;
  std::vector<std::string> lines_;
  dm::log::Level previous_;
};

class TempDir {
 public:
  TempDir() {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    path_ = fs::temp_directory_path() /
            ("dm_plugin_test_" + std::string(info->name()) + "_" + std::to_string(::getpid()));
    fs::remove_all(path_);
    fs::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(path_, ec);
  }
  const fs::path& path() const { return path_; }

 private:
  fs::path path_;
};

std::vector<std::string> names(const std::vector<dm::PluginRecord>& records) {
  std::vector<std::string> out;
  for (const auto& r : records) out.push_back(r.name);
  std::sort(out.begin(), out.end());
  return out;
}

TEST(PluginLinker, LoadsGoodPluginAndCallsThroughItsVtables) {
  dm::FactoryRegistry registry;
  dm::PluginLinker linker(registry, {.useEnvironment = false});
  const fs::path file = pluginFile("good", "dm_test_good");
  auto rec = linker.load(file);
  ASSERT_TRUE(rec) << rec.error();
  EXPECT_EQ(rec->name, "test-good");
  EXPECT_EQ(rec->version, "1.2.3");
  EXPECT_EQ(rec->status, dm::PluginStatus::Loaded);
  EXPECT_EQ(rec->path, fs::weakly_canonical(file));
  ASSERT_EQ(rec->factories.size(), 2u);
  EXPECT_EQ(registry.size(), 2u);

  auto adder =
      registry.vtable<DmTestAdderVTable>(DM_TEST_ADDER_KIND, "adder", DM_TEST_ADDER_KIND_ABI_VERSION);
  auto offset =
      registry.vtable<DmTestAdderVTable>(DM_TEST_ADDER_KIND, "offset-adder", DM_TEST_ADDER_KIND_ABI_VERSION);
  ASSERT_TRUE(adder) << adder.error();
  ASSERT_TRUE(offset) << offset.error();
  EXPECT_EQ((*adder)->add(2, 3), 5);
  EXPECT_EQ((*adder)->add(-7, 7), 0);
  EXPECT_EQ((*offset)->add(2, 3), 1005);

  // Opaque handles: state lives in the plugin; the plugin counts live ones.
  void* lib = dlopen(file.c_str(), RTLD_NOW | RTLD_NOLOAD);
  ASSERT_NE(lib, nullptr);
  auto live = reinterpret_cast<int (*)()>(dlsym(lib, "dm_test_good_live_accumulators"));
  ASSERT_NE(live, nullptr);
  DmTestAccumulator* acc = (*adder)->create(10);
  ASSERT_NE(acc, nullptr);
  EXPECT_EQ(live(), 1);
  EXPECT_EQ((*adder)->accumulate(acc, 5), 15);
  EXPECT_EQ((*adder)->accumulate(acc, -20), -5);
  DmTestAccumulator* acc2 = (*offset)->create(0);
  EXPECT_EQ((*offset)->accumulate(acc2, 1), 1001);
  EXPECT_EQ(live(), 2);
  (*adder)->destroy(acc);
  (*offset)->destroy(acc2);
  EXPECT_EQ(live(), 0);
  dlclose(lib);

  const auto loaded = linker.plugins();
  ASSERT_EQ(loaded.size(), 1u);
  EXPECT_EQ(loaded[0].name, "test-good");
  EXPECT_EQ(loaded[0].path, fs::weakly_canonical(file));
  EXPECT_TRUE(linker.failures().empty());
}

TEST(PluginLinker, CppPluginCrossesOnlyTheCBoundary) {
  dm::FactoryRegistry registry;
  dm::PluginLinker linker(registry, {.useEnvironment = false});
  auto rec = linker.load(pluginFile("good", "dm_test_cpp"));
  ASSERT_TRUE(rec) << rec.error();
  EXPECT_EQ(rec->name, "test-cpp");
  auto sat = registry.vtable<DmTestAdderVTable>(DM_TEST_ADDER_KIND, "saturating-adder",
                                                DM_TEST_ADDER_KIND_ABI_VERSION);
  ASSERT_TRUE(sat) << sat.error();
  EXPECT_EQ((*sat)->add(60, 70), 100);
  EXPECT_EQ((*sat)->add(-60, -70), -100);
  EXPECT_EQ((*sat)->add(20, 22), 42);
  DmTestAccumulator* acc = (*sat)->create(90);
  EXPECT_EQ((*sat)->accumulate(acc, 5), 95);
  EXPECT_EQ((*sat)->accumulate(acc, 50), 100);
  (*sat)->destroy(acc);
}

TEST(PluginLinker, FindsPluginsByNameInSearchPathsAndEnvironment) {
  dm::FactoryRegistry registry;
  {
    dm::PluginLinker linker(registry,
                            {.searchPaths = {pluginDir("bad"), pluginDir("good")}, .useEnvironment = false});
    auto rec = linker.load("dm_test_good");
    ASSERT_TRUE(rec) << rec.error();
    EXPECT_EQ(rec->path, fs::weakly_canonical(pluginFile("good", "dm_test_good")));

    auto missing = linker.load("no_such_plugin");
    ASSERT_FALSE(missing);
    EXPECT_EQ(missing.error().code, dm::ErrorCode::NotFound);
    const std::string msg = missing.error().message();
    EXPECT_HAS(msg, "plugin 'no_such_plugin' not found");
    EXPECT_HAS(msg, "libno_such_plugin.so");
    EXPECT_HAS(msg, pluginDir("bad").string());
    EXPECT_HAS(msg, pluginDir("good").string());
    EXPECT_HAS(msg, "DM_PLUGIN_PATH");
  }
  EXPECT_EQ(registry.size(), 0u);  // the destructor unloaded everything

  const std::string env = "/nonexistent/dm/plugins:" + pluginDir("good").string();
  ASSERT_EQ(setenv("DM_PLUGIN_PATH", env.c_str(), 1), 0);
  {
    dm::PluginLinker linker(registry, {.searchPaths = {pluginDir("dup")}});
    const auto dirs = linker.searchPaths();
    ASSERT_EQ(dirs.size(), 3u);
    EXPECT_EQ(dirs[0], fs::path("/nonexistent/dm/plugins"));
    EXPECT_EQ(dirs[1], pluginDir("good"));
    EXPECT_EQ(dirs[2], pluginDir("dup"));
    auto rec = linker.load("dm_test_cpp");
    EXPECT_TRUE(rec) << rec.error();
  }
  unsetenv("DM_PLUGIN_PATH");
  {
    dm::PluginLinker linker(registry);
    EXPECT_TRUE(linker.searchPaths().empty());
    auto rec = linker.load("dm_test_cpp");
    ASSERT_FALSE(rec);
    EXPECT_HAS(rec.error().message(), "no search paths are configured");
  }
}

TEST(PluginLinker, RefusesMissingFileNamingThePath) {
  dm::FactoryRegistry registry;
  dm::PluginLinker linker(registry, {.useEnvironment = false});
  const fs::path file = "/nonexistent/dm/libghost.so";
  auto rec = linker.load(file);
  ASSERT_FALSE(rec);
  EXPECT_EQ(rec.error().code, dm::ErrorCode::NotFound);
  EXPECT_EQ(rec.error().where, file.string());
  EXPECT_HAS(rec.error().what, "does not exist");
  ASSERT_EQ(linker.failures().size(), 1u);
  EXPECT_EQ(linker.failures()[0].path, file);
  EXPECT_EQ(linker.failures()[0].status, dm::PluginStatus::Refused);
}

TEST(PluginLinker, RefusesAFileThatIsNotASharedObject) {
  TempDir tmp;
  const fs::path file = tmp.path() / "libfake.so";
  std::ofstream(file) << "this is a text file, not an ELF shared object\n";
  dm::FactoryRegistry registry;
  dm::PluginLinker linker(registry, {.useEnvironment = false});
  auto rec = linker.load(file);
  ASSERT_FALSE(rec);
  EXPECT_EQ(rec.error().code, dm::ErrorCode::Parse);
  EXPECT_EQ(rec.error().where, fs::weakly_canonical(file).string());
  EXPECT_HAS(rec.error().what, "cannot be loaded as a shared library");
  EXPECT_HAS(rec.error().what, "dlopen");
}

TEST(PluginLinker, RefusesUnresolvedSymbolBeforeRunningPluginCode) {
  dm::FactoryRegistry registry;
  dm::PluginLinker linker(registry, {.useEnvironment = false});
  const fs::path file = pluginFile("bad", "dm_test_unresolved");
  auto rec = linker.load(file);
  ASSERT_FALSE(rec);
  EXPECT_EQ(rec.error().where, fs::weakly_canonical(file).string());
  EXPECT_HAS(rec.error().what, "unresolved symbol");
  EXPECT_HAS(rec.error().what, "dm_test_function_that_does_not_exist");
  EXPECT_FALSE(isMapped(file));
}

TEST(PluginLinker, RefusesLibraryWithoutEntryPoint) {
  dm::FactoryRegistry registry;
  dm::PluginLinker linker(registry, {.useEnvironment = false});
  const fs::path file = pluginFile("bad", "dm_test_no_entry");
  auto rec = linker.load(file);
  ASSERT_FALSE(rec);
  EXPECT_EQ(rec.error().code, dm::ErrorCode::NotFound);
  EXPECT_EQ(rec.error().where, fs::weakly_canonical(file).string());
  EXPECT_HAS(rec.error().what, "no entry point 'dm_plugin_entry'");
  EXPECT_HAS(rec.error().hint, "DM_PLUGIN_ENTRY");
  EXPECT_FALSE(isMapped(file));
}

TEST(PluginLinker, RefusesWrongAbiVersionBeforeCallingInit) {
  dm::FactoryRegistry registry;
  dm::PluginLinker linker(registry, {.useEnvironment = false});
  const fs::path file = pluginFile("bad", "dm_test_wrong_abi");
  auto rec = linker.load(file);
  ASSERT_FALSE(rec);
  const dm::Error& e = rec.error();
  EXPECT_EQ(e.code, dm::ErrorCode::Version);
  EXPECT_EQ(e.where, fs::weakly_canonical(file).string());
  EXPECT_HAS(e.what, "found " + std::to_string(DM_PLUGIN_ABI_VERSION + 41u) + ", expected " +
                         std::to_string(DM_PLUGIN_ABI_VERSION));
  EXPECT_HAS(e.hint, "rebuild the plugin against this SDK");
  EXPECT_FALSE(registry.contains(DM_TEST_ADDER_KIND, "from-wrong-abi"));  // init never ran
  EXPECT_EQ(registry.size(), 0u);
  EXPECT_FALSE(isMapped(file));
  EXPECT_TRUE(linker.plugins().empty());
}

TEST(PluginLinker, InitFailurePassesThePluginMessageAndLeavesNoState) {
  LogCapture logs;
  dm::FactoryRegistry registry;
  dm::PluginLinker linker(registry, {.useEnvironment = false});
  const fs::path file = pluginFile("bad", "dm_test_init_fails");
  auto rec = linker.load(file);
  ASSERT_FALSE(rec);
  const dm::Error& e = rec.error();
  EXPECT_EQ(e.where, fs::weakly_canonical(file).string());
  EXPECT_HAS(e.what, "plugin 'test-init-fails'");
  EXPECT_HAS(e.what, "init failed with code 7");
  EXPECT_HAS(e.what, "calibration file /etc/dm/test.cal not found; run dm-calibrate first");
  // The factory it registered before failing is gone, the library is closed,
  // and shutdown was not called after a failed init.
  EXPECT_FALSE(registry.contains(DM_TEST_ADDER_KIND, "half-registered"));
  EXPECT_EQ(registry.size(), 0u);
  EXPECT_FALSE(isMapped(file));
  EXPECT_FALSE(logs.saw("test-init-fails: shutdown"));
  EXPECT_TRUE(linker.plugins().empty());
  const auto failures = linker.failures();
  ASSERT_EQ(failures.size(), 1u);
  EXPECT_EQ(failures[0].name, "test-init-fails");
  EXPECT_EQ(failures[0].version, "0.1");
  EXPECT_EQ(failures[0].status, dm::PluginStatus::Refused);
  EXPECT_HAS(failures[0].error.what, "init failed with code 7");
  linker.clearFailures();
  EXPECT_TRUE(linker.failures().empty());
}

TEST(PluginLinker, RefusesDuplicateFactoryAsAWhole) {
  LogCapture logs;
  dm::FactoryRegistry registry;
  dm::PluginLinker linker(registry, {.useEnvironment = false});
  ASSERT_TRUE(linker.load(pluginFile("good", "dm_test_good")));
  const fs::path dup = pluginFile("dup", "dm_test_duplicate");
  auto rec = linker.load(dup);
  ASSERT_FALSE(rec);
  const dm::Error& e = rec.error();
  EXPECT_EQ(e.where, fs::weakly_canonical(dup).string());
  EXPECT_HAS(e.what, "plugin 'test-duplicate'");
  EXPECT_HAS(e.what, "duplicate factory 'adder' of kind 'test-adder'");
  EXPECT_HAS(e.what, "plugin 'test-good'");
  // All or nothing: the non-conflicting factory is not registered either,
  // the plugin was shut down (its init had succeeded) and unloaded.
  EXPECT_FALSE(registry.contains(DM_TEST_ADDER_KIND, "subtractor"));
  EXPECT_TRUE(logs.saw("test-duplicate: shutdown"));
  EXPECT_FALSE(isMapped(dup));
  auto adder =
      registry.vtable<DmTestAdderVTable>(DM_TEST_ADDER_KIND, "adder", DM_TEST_ADDER_KIND_ABI_VERSION);
  ASSERT_TRUE(adder);
  EXPECT_EQ((*adder)->add(5, 3), 8);  // still test-good's, not the subtractor

  // Loading the same file twice is refused too; the first copy stays.
  auto again = linker.load(pluginFile("good", "dm_test_good"));
  ASSERT_FALSE(again);
  EXPECT_HAS(again.error().what, "already loaded as plugin 'test-good'");
  EXPECT_EQ(linker.plugins().size(), 1u);

  // Without the conflict the same plugin loads.
  dm::FactoryRegistry other;
  dm::PluginLinker otherLinker(other, {.useEnvironment = false});
  auto alone = otherLinker.load(dup);
  ASSERT_TRUE(alone) << alone.error();
  auto sub =
      other.vtable<DmTestAdderVTable>(DM_TEST_ADDER_KIND, "subtractor", DM_TEST_ADDER_KIND_ABI_VERSION);
  ASSERT_TRUE(sub);
  EXPECT_EQ((*sub)->add(5, 3), 2);
}

// A built-in "plugin" compiled into the host, registered through the same
// protocol as a shared library.
int builtinTwice(int a, int b) { return 2 * (a + b); }
const DmTestAdderVTable kBuiltinVTable = {builtinTwice, nullptr, nullptr, nullptr};
int builtinInit(const DmHostApi* host) {
  return host->register_factory(host->ctx, DM_TEST_ADDER_KIND, "builtin-doubler",
                                DM_TEST_ADDER_KIND_ABI_VERSION, &kBuiltinVTable);
}
const DmPluginInfo kBuiltinInfo = {DM_PLUGIN_ABI_VERSION, "builtin-adders", "1.0", builtinInit, nullptr};
const DmPluginInfo* builtinEntry() { return &kBuiltinInfo; }
const DmPluginInfo kStaleBuiltinInfo = {DM_PLUGIN_ABI_VERSION + 1, "stale", "0", builtinInit, nullptr};
const DmPluginInfo* staleEntry() { return &kStaleBuiltinInfo; }

TEST(FactoryRegistry, StaticRegistrationSharesThePluginPath) {
  dm::FactoryRegistry registry;
  // Direct registration of a C++-side vtable.
  ASSERT_TRUE(registry.add(DM_TEST_ADDER_KIND, "direct", DM_TEST_ADDER_KIND_ABI_VERSION, &kBuiltinVTable));
  auto twice = registry.add(DM_TEST_ADDER_KIND, "direct", DM_TEST_ADDER_KIND_ABI_VERSION, &kBuiltinVTable);
  ASSERT_FALSE(twice);
  EXPECT_HAS(twice.error().what, "duplicate factory 'direct' of kind 'test-adder'");
  auto null = registry.add(DM_TEST_ADDER_KIND, "null", 1, nullptr);
  ASSERT_FALSE(null);
  EXPECT_HAS(null.error().what, "null vtable");
  EXPECT_FALSE(registry.add("", "x", 1, &kBuiltinVTable));

  // Built-in plugin through the C protocol.
  dm::PluginLinker linker(registry, {.useEnvironment = false});
  auto rec = linker.addStatic(builtinEntry);
  ASSERT_TRUE(rec) << rec.error();
  EXPECT_EQ(rec->status, dm::PluginStatus::BuiltIn);
  EXPECT_TRUE(rec->path.empty());
  auto f = registry.find(DM_TEST_ADDER_KIND, "builtin-doubler", DM_TEST_ADDER_KIND_ABI_VERSION);
  ASSERT_TRUE(f) << f.error();
  EXPECT_EQ(f->provider, "builtin-adders");
  EXPECT_EQ(f->as<DmTestAdderVTable>()->add(3, 4), 14);

  // The same checks apply: a stale built-in table is refused by version.
  auto stale = linker.addStatic(staleEntry);
  ASSERT_FALSE(stale);
  EXPECT_EQ(stale.error().code, dm::ErrorCode::Version);

  // Kind ABI mismatch is reported by find with found vs expected.
  auto wrongKind = registry.find(DM_TEST_ADDER_KIND, "builtin-doubler", DM_TEST_ADDER_KIND_ABI_VERSION + 1);
  ASSERT_FALSE(wrongKind);
  EXPECT_EQ(wrongKind.error().code, dm::ErrorCode::Version);
  EXPECT_HAS(wrongKind.error().what, "kind ABI version " + std::to_string(DM_TEST_ADDER_KIND_ABI_VERSION) +
                                         ", expected " + std::to_string(DM_TEST_ADDER_KIND_ABI_VERSION + 1));

  auto unknown = registry.find(DM_TEST_ADDER_KIND, "nope");
  ASSERT_FALSE(unknown);
  EXPECT_EQ(unknown.error().code, dm::ErrorCode::NotFound);
  EXPECT_HAS(unknown.error().what, "registered: builtin-doubler, direct");

  // A shared-library plugin colliding with a built-in is refused.
  ASSERT_TRUE(registry.add(DM_TEST_ADDER_KIND, "adder", 1, &kBuiltinVTable));
  auto clash = linker.load(pluginFile("good", "dm_test_good"));
  ASSERT_FALSE(clash);
  EXPECT_HAS(clash.error().what,
             "duplicate factory 'adder' of kind 'test-adder': already provided by 'static'");
  EXPECT_FALSE(registry.contains(DM_TEST_ADDER_KIND, "offset-adder"));

  EXPECT_EQ(registry.list(DM_TEST_ADDER_KIND).size(), 3u);
  EXPECT_TRUE(registry.list("importer").empty());
  ASSERT_TRUE(linker.unload("builtin-adders"));
  EXPECT_FALSE(registry.contains(DM_TEST_ADDER_KIND, "builtin-doubler"));
  ASSERT_TRUE(registry.remove(DM_TEST_ADDER_KIND, "direct"));
  EXPECT_FALSE(registry.remove(DM_TEST_ADDER_KIND, "direct"));
}

TEST(PluginLinker, UnloadCallsShutdownRemovesFactoriesAndClosesTheLibrary) {
  LogCapture logs;
  dm::FactoryRegistry registry;
  dm::PluginLinker linker(registry, {.useEnvironment = false});
  const fs::path file = pluginFile("good", "dm_test_good");
  ASSERT_TRUE(linker.load(file));
  ASSERT_TRUE(linker.load(pluginFile("good", "dm_test_cpp")));
  EXPECT_TRUE(logs.saw("test-good: init done"));
  EXPECT_TRUE(isMapped(file));

  ASSERT_TRUE(linker.unload("test-good"));
  EXPECT_TRUE(logs.saw("test-good: shutdown"));
  EXPECT_FALSE(registry.contains(DM_TEST_ADDER_KIND, "adder"));
  EXPECT_FALSE(registry.contains(DM_TEST_ADDER_KIND, "offset-adder"));
  EXPECT_TRUE(registry.contains(DM_TEST_ADDER_KIND, "saturating-adder"));
  EXPECT_FALSE(isMapped(file));
  EXPECT_EQ(names(linker.plugins()), std::vector<std::string>{"test-cpp"});

  auto again = linker.unload("test-good");
  ASSERT_FALSE(again);
  EXPECT_EQ(again.error().code, dm::ErrorCode::NotFound);
  EXPECT_HAS(again.error().what, "loaded: test-cpp");

  // Reload after unload works; a Factory copy keeps the code mapped after
  // unload until it is dropped.
  ASSERT_TRUE(linker.load(file));
  auto f = registry.find(DM_TEST_ADDER_KIND, "adder");
  ASSERT_TRUE(f);
  ASSERT_TRUE(linker.unload("test-good"));
  EXPECT_TRUE(isMapped(file));
  EXPECT_EQ(f->as<DmTestAdderVTable>()->add(1, 1), 2);
  f = dm::fail(dm::ErrorCode::NotFound, "dropped");
  EXPECT_FALSE(isMapped(file));
}

TEST(PluginLinker, ScanLoadsEveryGoodPluginAndReportsEveryBadOne) {
  dm::FactoryRegistry registry;
  const fs::path missingDir = "/nonexistent/dm/plugin-dir";
  dm::PluginLinker linker(registry,
                          {.searchPaths = {pluginDir("good"), pluginDir("bad"), pluginDir("dup"), missingDir},
                           .useEnvironment = false});
  const dm::ScanReport report = linker.scan();
  EXPECT_EQ(names(report.loaded), (std::vector<std::string>{"test-cpp", "test-good"}));
  // Four bad plugins, the duplicate (after test-good) and the missing dir.
  ASSERT_EQ(report.refused.size(), 6u);
  std::vector<std::string> refusedFiles;
  for (const auto& r : report.refused) {
    EXPECT_EQ(r.status, dm::PluginStatus::Refused);
    EXPECT_FALSE(r.error.what.empty());
    EXPECT_EQ(r.error.where, r.path.string());
    refusedFiles.push_back(r.path.filename().string());
  }
  std::sort(refusedFiles.begin(), refusedFiles.end());
  EXPECT_EQ(refusedFiles, (std::vector<std::string>{"libdm_test_duplicate.so", "libdm_test_init_fails.so",
                                                    "libdm_test_no_entry.so", "libdm_test_unresolved.so",
                                                    "libdm_test_wrong_abi.so", "plugin-dir"}));
  EXPECT_EQ(linker.failures().size(), 6u);
  EXPECT_EQ(registry.size(), 3u);  // adder, offset-adder, saturating-adder

  // A second scan skips what is loaded and reports the bad ones again.
  const dm::ScanReport second = linker.scanDirectory(pluginDir("good"));
  EXPECT_TRUE(second.loaded.empty());
  EXPECT_TRUE(second.refused.empty());
  EXPECT_EQ(linker.plugins().size(), 2u);
}

TEST(PluginLinker, ProbeModeRefusesCrashingAndHangingPlugins) {
  dm::FactoryRegistry registry;
  dm::PluginLinker linker(
      registry, {.useEnvironment = false, .probe = true, .probeTimeout = std::chrono::milliseconds(500)});

  const fs::path crash = pluginFile("crash", "dm_test_init_crash");
  auto crashed = linker.load(crash);
  ASSERT_FALSE(crashed);
  EXPECT_EQ(crashed.error().where, fs::weakly_canonical(crash).string());
  EXPECT_HAS(crashed.error().what, "crashed with SIGSEGV");
  EXPECT_HAS(crashed.error().what, "init()");
  EXPECT_FALSE(isMapped(crash));  // never loaded into this process

  const fs::path hang = pluginFile("crash", "dm_test_init_hang");
  auto hung = linker.load(hang);
  ASSERT_FALSE(hung);
  EXPECT_EQ(hung.error().code, dm::ErrorCode::Timeout);
  EXPECT_HAS(hung.error().what, "did not finish init() within 500 ms");
  EXPECT_HAS(hung.error().hint, "probeTimeout");
  EXPECT_FALSE(isMapped(hang));

  // Good plugins pass the probe and load; ordinary refusals keep their
  // precise in-process message.
  auto good = linker.load(pluginFile("good", "dm_test_good"));
  ASSERT_TRUE(good) << good.error();
  auto adder =
      registry.vtable<DmTestAdderVTable>(DM_TEST_ADDER_KIND, "adder", DM_TEST_ADDER_KIND_ABI_VERSION);
  ASSERT_TRUE(adder);
  EXPECT_EQ((*adder)->add(20, 22), 42);
  auto wrong = linker.load(pluginFile("bad", "dm_test_wrong_abi"));
  ASSERT_FALSE(wrong);
  EXPECT_EQ(wrong.error().code, dm::ErrorCode::Version);
  auto failing = linker.load(pluginFile("bad", "dm_test_init_fails"));
  ASSERT_FALSE(failing);
  EXPECT_HAS(failing.error().what, "init failed with code 7");

  // A probing scan of the dangerous directory reports both and goes on.
  const dm::ScanReport report = linker.scanDirectory(pluginDir("crash"));
  EXPECT_TRUE(report.loaded.empty());
  EXPECT_EQ(report.refused.size(), 2u);
}

// The probe is a spawned program, not a fork of this process: it starts
// clean whatever the host's threads hold. 100 probes of a good plugin while
// four threads churn the allocator and the dynamic loader (dlopen/dlclose
// of another plugin: a fork taken while one holds the loader's lock would
// leave the child's dlopen waiting forever) all pass and load.
TEST(PluginLinker, ProbesBesideBusyThreadsNeverHangOrFail) {
  std::atomic<bool> stop{false};
  std::vector<std::thread> busy;
  const fs::path other = pluginFile("good", "dm_test_cpp");
  for (int i = 0; i < 4; ++i)
    busy.emplace_back([&stop, &other, i] {
      std::vector<std::unique_ptr<char[]>> blocks;
      while (!stop.load(std::memory_order_relaxed)) {
        blocks.push_back(std::make_unique<char[]>(std::size_t(64) << (i % 8)));
        if (blocks.size() > 64) blocks.clear();
        if (i % 2 == 0) {
          if (void* h = dlopen(other.c_str(), RTLD_NOW | RTLD_LOCAL)) dlclose(h);
        }
      }
    });
  const fs::path good = pluginFile("good", "dm_test_good");
  int loaded = 0;
  for (int round = 0; round < 100; ++round) {
    dm::FactoryRegistry registry;
    dm::PluginLinker linker(registry, {.useEnvironment = false, .probe = true});
    auto plugin = linker.load(good);
    EXPECT_TRUE(plugin) << "round " << round << ": " << plugin.error();
    loaded += plugin ? 1 : 0;
  }
  stop = true;
  for (auto& t : busy) t.join();
  EXPECT_EQ(loaded, 100);
}

// Where the probe program is not, probe mode fails naming what it looked
// for, and loads nothing.
TEST(PluginLinker, AMissingProbeProgramIsNamed) {
  ASSERT_EQ(setenv("DM_PLUGIN_PROBE", "/nonexistent/dm-plugin-probe", 1), 0);
  dm::FactoryRegistry registry;
  dm::PluginLinker linker(registry, {.useEnvironment = false, .probe = true});
  const fs::path good = pluginFile("good", "dm_test_good");
  auto refused = linker.load(good);
  unsetenv("DM_PLUGIN_PROBE");
  ASSERT_FALSE(refused);
  EXPECT_EQ(refused.error().code, dm::ErrorCode::NotFound);
  EXPECT_HAS(refused.error().what, "DM_PLUGIN_PROBE names '/nonexistent/dm-plugin-probe'");
  EXPECT_HAS(refused.error().hint, "dm-plugin-probe");
  EXPECT_FALSE(isMapped(good));
  // Found again beside libdmCore.so once the variable is gone.
  EXPECT_TRUE(linker.load(good));
}

}  // namespace
