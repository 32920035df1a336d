// The built-in drivers: entry points compiled from DMIO/drivers/*.cpp into
// DM::IO (see dm/io/drivers.hpp).
#include <dm/io/drivers.hpp>

extern "C" const DmPluginInfo* dm_builtin_entry_sim_haptic(void);
extern "C" const DmPluginInfo* dm_builtin_entry_replay_haptic(void);

namespace dm {

namespace {
struct BuiltinDriver {
  const char* name;
  DmPluginEntryFn entry;
};
constexpr BuiltinDriver kDrivers[] = {
    {"replay-haptic", &dm_builtin_entry_replay_haptic},
    {"sim-haptic", &dm_builtin_entry_sim_haptic},
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
