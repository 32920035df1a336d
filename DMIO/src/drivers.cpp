// The built-in drivers: entry points compiled from DMIO/drivers/*.cpp into
// DM::IO (see dm/io/drivers.hpp).
#include <dm/io/drivers.hpp>

extern "C" const DmPluginInfo* dm_builtin_entry_evdev_controller(void);
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

}  // namespace dm
