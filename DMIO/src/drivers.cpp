// The built-in drivers: entry points compiled from DMIO/drivers/*.cpp into
// DM::IO (see dm/io/drivers.hpp).
#include <dm/io/drivers.hpp>

#include <dlfcn.h>

#include "../drivers/vendor_library.hpp"

extern "C" const DmPluginInfo* dm_builtin_entry_evdev_controller(void);
extern "C" const DmPluginInfo* dm_builtin_entry_haply_2diy(void);
extern "C" const DmPluginInfo* dm_builtin_entry_openhaptics_hd(void);
extern "C" const DmPluginInfo* dm_builtin_entry_pointer(void);  // src/pointer_device.cpp
extern "C" const DmPluginInfo* dm_builtin_entry_force_dimension_dhd(void);
extern "C" const DmPluginInfo* dm_builtin_entry_serial_posix(void);
extern "C" const DmPluginInfo* dm_builtin_entry_sim_controller(void);
extern "C" const DmPluginInfo* dm_builtin_entry_sim_daq(void);
extern "C" const DmPluginInfo* dm_builtin_entry_sim_haptic(void);
extern "C" const DmPluginInfo* dm_builtin_entry_sim_sensor(void);
extern "C" const DmPluginInfo* dm_builtin_entry_replay_haptic(void);
extern "C" const DmPluginInfo* dm_builtin_entry_replay_controller(void);
extern "C" const DmPluginInfo* dm_builtin_entry_replay_daq(void);
extern "C" const DmPluginInfo* dm_builtin_entry_replay_sensor(void);

namespace dm {

namespace {
struct BuiltinDriver {
  const char* name;
  DmPluginEntryFn entry;
};
constexpr BuiltinDriver kDrivers[] = {
    {"evdev-controller", &dm_builtin_entry_evdev_controller},
    {"force-dimension-dhd", &dm_builtin_entry_force_dimension_dhd},
    {"haply-2diy", &dm_builtin_entry_haply_2diy},
    {"openhaptics-hd", &dm_builtin_entry_openhaptics_hd},
    {"pointer", &dm_builtin_entry_pointer},
    {"replay-controller", &dm_builtin_entry_replay_controller},
    {"replay-daq", &dm_builtin_entry_replay_daq},
    {"replay-haptic", &dm_builtin_entry_replay_haptic},
    {"replay-sensor", &dm_builtin_entry_replay_sensor},
    {"serial-posix", &dm_builtin_entry_serial_posix},
    {"sim-controller", &dm_builtin_entry_sim_controller},
    {"sim-daq", &dm_builtin_entry_sim_daq},
    {"sim-haptic", &dm_builtin_entry_sim_haptic},
    {"sim-sensor", &dm_builtin_entry_sim_sensor},
};
}  // namespace

std::vector<std::string> builtinDriverNames() {
  std::vector<std::string> names;
  for (const BuiltinDriver& d : kDrivers) names.emplace_back(d.name);
  return names;
}

Status registerBuiltinDrivers(PluginLinker& linker) {
  for (const BuiltinDriver& d : kDrivers)
    if (auto r = linker.addStatic(d.entry); !r) return std::move(r).error();
  return ok();
}

std::vector<VendorDriverStatus> vendorDriverStatus() {
  std::vector<VendorDriverStatus> out;
  for (const driver::VendorLibrary* lib : driver::kVendorLibraries) {
    VendorDriverStatus st{lib->driver, lib->api, false, {}, {}};
    if (void* h = driver::openVendorLibrary(*lib, nullptr, st.reason)) {
      st.available = true;
      Dl_info where{};
      // The file it came from: where a call it must define lives.
      if (void* sym = ::dlsym(h, lib->probeSymbol); sym && ::dladdr(sym, &where) && where.dli_fname)
        st.library = where.dli_fname;
      ::dlclose(h);
    }
    out.push_back(std::move(st));
  }
  return out;
}

}  // namespace dm
