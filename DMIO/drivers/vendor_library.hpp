// Vendor libraries of the commercial haptic device drivers, loaded at run
// time (dlopen) so that DMPlatform builds, ships and runs without them:
// which library each driver needs, where it is looked for, and what to
// install when it is missing. Header-only, so that a driver built as a
// plugin needs no DMPlatform library; dm::vendorDriverStatus()
// (dm/io/drivers.hpp) reports the same search for `dmtool devices`.
#pragma once

#include <dlfcn.h>

#include <cstddef>
#include <initializer_list>
#include <string>

namespace dm::driver {

struct VendorLibrary {
  const char* driver;        // factory name
  const char* api;           // the vendor API, for messages
  const char* const* names;  // sonames and paths tried in order (nullptr-terminated)
  const char* install;       // what to install when none loads
  const char* probeSymbol;   // a call every version defines (to find the file loaded)
};

inline constexpr const char* kOpenHapticsNames[] = {"libHD.so", "libHD.so.3.4", "libHD.so.3",
                                                    "/usr/lib/libHD.so", nullptr};
inline constexpr VendorLibrary kOpenHapticsHd = {
    "openhaptics-hd", "OpenHaptics HD", kOpenHapticsNames,
    "install OpenHaptics for Linux (3D Systems) and the Touch device driver, or give the library's path "
    "as parameter 'library'",
    "hdGetError"};

inline constexpr const char* kForceDimensionNames[] = {"libdhd.so", "libdhd.so.3", nullptr};
inline constexpr VendorLibrary kForceDimensionDhd = {
    "force-dimension-dhd", "Force Dimension DHD", kForceDimensionNames,
    "install the Force Dimension SDK for Linux (its lib/ on the library path) and the device's USB rules, "
    "or give the library's path as parameter 'library'",
    "dhdGetDeviceCount"};

inline constexpr const VendorLibrary* kVendorLibraries[] = {&kOpenHapticsHd, &kForceDimensionDhd};

/// dlopen()s `explicitPath` when given, else the library's names in order.
/// On failure returns nullptr and sets `why` to every name tried with
/// dlerror()'s reason and the install hint.
inline void* openVendorLibrary(const VendorLibrary& lib, const char* explicitPath, std::string& why) {
  why.clear();
  auto attempt = [&](const char* name) -> void* {
    void* handle = ::dlopen(name, RTLD_NOW | RTLD_LOCAL);
    if (!handle) {
      const char* e = ::dlerror();
      why += (why.empty() ? "" : "; ") + std::string(e ? e : name);
    }
    return handle;
  };
  if (explicitPath && *explicitPath) {
    if (void* h = attempt(explicitPath)) return h;
  } else {
    for (const char* const* n = lib.names; *n; ++n)
      if (void* h = attempt(*n)) return h;
  }
  why = std::string("cannot load the ") + lib.api + " library (" + why + "): " + lib.install;
  return nullptr;
}

/// A call of a vendor library and the function pointer it is resolved into.
struct VendorCall {
  template <class F>
  VendorCall(const char* n, F*& fn, bool isRequired = true) noexcept
      : name(n), slot(reinterpret_cast<void**>(&fn)), required(isRequired) {}
  const char* name;
  void** slot;
  bool required;
};

/// Resolves every call with dlsym (an optional one missing stays nullptr);
/// returns the name of the first required call missing, or nullptr.
inline const char* resolveVendorCalls(void* lib, std::initializer_list<VendorCall> calls) {
  const char* missing = nullptr;
  for (const VendorCall& c : calls) {
    *c.slot = ::dlsym(lib, c.name);
    if (!*c.slot && c.required && !missing) missing = c.name;
  }
  return missing;
}

}  // namespace dm::driver
