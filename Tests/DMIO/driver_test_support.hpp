// Helpers for the device driver tests: a registry with the built-in drivers,
// and a registry with one driver plugin loaded from DM_DRIVER_PLUGIN_DIR
// (where the build puts libdm_driver_<name>.so).
#pragma once

#include <dm/core/plugin.hpp>
#include <dm/io/drivers.hpp>

#include <gtest/gtest.h>

#include <dlfcn.h>

#include <cmath>
#include <cstdint>
#include <string>

#include "../common/build_paths.hpp"

namespace dm::test {

/// One millisecond in the nanoseconds of device timestamps.
inline constexpr std::int64_t kMs = 1'000'000;

/// The fractional part of x, in [0, 1): the phase of a periodic signal.
inline double frac(double x) { return x - std::floor(x); }

/// A registry filled by registerBuiltinDrivers().
struct BuiltinDrivers {
  FactoryRegistry registry;
  PluginLinker linker{registry};
  BuiltinDrivers() { EXPECT_TRUE(registerBuiltinDrivers(linker).ok()); }
};

/// A registry with the plugin libdm_driver_<file>.so loaded through the
/// linker; `loaded` is false (with a test failure) if it was refused.
struct PluginDriver {
  FactoryRegistry registry;
  PluginLinker linker{registry};
  bool loaded = false;
  PluginDriver(const std::string& file, const std::string& expectedName) {
    auto r = linker.load(dm::test::besideExecutable(DM_DRIVER_PLUGIN_DIR) + "/libdm_driver_" + file + ".so");
    EXPECT_TRUE(r.ok()) << (r.ok() ? "" : r.error().message());
    if (!r.ok()) return;
    EXPECT_EQ(r->name, expectedName);
    EXPECT_EQ(r->status, PluginStatus::Loaded);
    loaded = true;
  }
};

/// A stand-in vendor library (Tests/DMIO/plugins/*_stand_in.cpp) opened by
/// the test beside the driver that loads it: dlopen of one path gives one
/// copy, so the test's calls move, unplug or decalibrate the driver's
/// simulated device.
struct StandInLibrary {
  explicit StandInLibrary(const std::string& path) : lib(::dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL)) {}
  ~StandInLibrary() {
    if (lib) ::dlclose(lib);
  }
  StandInLibrary(const StandInLibrary&) = delete;
  StandInLibrary& operator=(const StandInLibrary&) = delete;
  /// Its call `name` as a function pointer of type F.
  template <class F>
  F fn(const char* name) const {
    return reinterpret_cast<F>(::dlsym(lib, name));
  }
  void* lib;
};

}  // namespace dm::test
