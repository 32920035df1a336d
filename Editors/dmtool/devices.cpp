// dmtool devices [--plugin-dir DIR]... [--no-builtin] [--open] [--json]:
// lists the device drivers found — built in, and plugins in the plugin
// directories (DM_PLUGIN_PATH, <prefix>/lib/dmplatform/plugins next to
// dmtool, a build tree's plugins/, and each --plugin-dir) — with each
// plugin's status: loaded, built-in, or refused with the reason (wrong ABI,
// crash or hang in init: plugins are probed in a child process first).
// A driver of a vendor's library (openhaptics-hd) says whether this machine
// has that library: available (and the file), or unavailable with every
// name tried and what to install. With --open, each haptic-device driver is
// also opened with its default parameters and reports its identity and
// limits, or why it needs more.
#include <dm/core/log.hpp>
#include <dm/core/plugin.hpp>
#include <dm/io/device_abi.h>
#include <dm/io/drivers.hpp>
#include <dm/io/haptic_device.hpp>
#ifdef DM_HAVE_NETWORK
#include <dm/network/drivers.hpp>
#endif

#include <unistd.h>

#include <algorithm>
#include <iostream>
#include <set>

#include "common.hpp"

namespace dmtool {
namespace {

namespace fs = std::filesystem;

struct DevicesCliOptions {
  std::vector<std::string> pluginDirs;
  bool noBuiltin = false;
  bool open = false;
  bool json = false;
  std::string only;
  bool verbose = false;
};

// Plugin directories next to the executable: installed, then build tree.
std::vector<fs::path> defaultPluginDirs() {
  std::vector<fs::path> dirs;
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (ec) return dirs;
  for (const fs::path& d : {exe.parent_path().parent_path() / "lib" / "dmplatform" / "plugins",
                            exe.parent_path().parent_path() / "plugins"})
    if (fs::is_directory(d, ec)) dirs.push_back(d);
  return dirs;
}

bool isDeviceKind(const std::string& kind) {
  static const std::set<std::string> kinds = {DM_HAPTIC_DEVICE_KIND, "controller", "daq", "sensor",
                                              "serial-line"};
  return kinds.count(kind) > 0;
}

int runDevices(const DevicesCliOptions& o) {
  if (!o.verbose) dm::log::setLevel(dm::log::Level::Warn);  // refusals are reported in the listing
  for (const std::string& d : o.pluginDirs) {
    std::error_code ec;
    if (!fs::is_directory(d, ec))
      return printError(
          dm::fail(dm::ErrorCode::NotFound, "not a directory", d, "give an existing --plugin-dir"));
  }
  dm::FactoryRegistry registry;
  dm::PluginLinkerOptions options;
  options.searchPaths = defaultPluginDirs();
  for (const std::string& d : o.pluginDirs) options.searchPaths.emplace_back(d);
  options.probe = true;  // a plugin that crashes or hangs in init is refused, not fatal
  dm::PluginLinker linker(registry, options);
  nlohmann::json plugins = nlohmann::json::array();
  if (!o.noBuiltin) {
    if (auto s = dm::registerBuiltinDrivers(linker); !s) return printError(s.error());
#ifdef DM_HAVE_NETWORK
    if (auto s = dm::registerNetworkDrivers(linker); !s) return printError(s.error());
#endif
  }
  // The plugin files of the built-in drivers (libdm_driver_<name>.so, shipped
  // next to dmtool) are the same code: list them as such instead of loading.
  std::set<std::string> builtinFiles;
  if (!o.noBuiltin)
    for (std::string n : dm::builtinDriverNames()) {
      for (char& c : n) c = c == '-' ? '_' : c;
      builtinFiles.insert("libdm_driver_" + n + ".so");
    }
  auto describe = [&](const dm::PluginRecord& p) {
    nlohmann::json j = {{"name", p.name},
                        {"version", p.version},
                        {"status", dm::toString(p.status)},
                        {"path", p.path.string()}};
    nlohmann::json factories = nlohmann::json::array();
    for (const dm::FactoryKey& k : p.factories) factories.push_back({{"kind", k.kind}, {"name", k.name}});
    j["factories"] = factories;
    if (p.status == dm::PluginStatus::Refused) j["error"] = p.error.message();
    return j;
  };
  for (const dm::PluginRecord& p : linker.plugins()) plugins.push_back(describe(p));
  for (const fs::path& dir : linker.searchPaths()) {
    std::error_code ec;
    std::vector<fs::path> files;
    for (const auto& e : fs::directory_iterator(dir, ec))
      if (e.path().extension() == ".so") files.push_back(e.path());
    std::sort(files.begin(), files.end());
    for (const fs::path& f : files) {
      if (builtinFiles.count(f.filename().string())) {
        plugins.push_back(
            {{"path", f.string()}, {"status", "same as built-in"}, {"name", f.filename().string()}});
        continue;
      }
      auto loaded = linker.load(f);
      if (loaded) {
        plugins.push_back(describe(*loaded));
      } else {
        dm::PluginRecord refused;
        refused.path = f;
        refused.error = loaded.error();
        plugins.push_back(describe(refused));
      }
    }
  }

  // Drivers of a vendor's library (loaded at run time): whether this machine has it.
  const std::vector<dm::VendorDriverStatus> vendors = dm::vendorDriverStatus();
  nlohmann::json drivers = nlohmann::json::array();
  for (const dm::Factory& f : registry.list()) {
    if (!isDeviceKind(f.key.kind) || (!o.only.empty() && f.key.name != o.only)) continue;
    nlohmann::json d = {{"kind", f.key.kind},
                        {"name", f.key.name},
                        {"provider", f.provider},
                        {"path", f.providerPath.string()}};
    for (const dm::VendorDriverStatus& v : vendors)
      if (v.driver == f.key.name) {
        d["vendor_library"] = v.api;
        d["available"] = v.available;
        d[v.available ? "library" : "unavailable_reason"] = v.available ? v.library : v.reason;
      }
    if (o.open && f.key.kind == DM_HAPTIC_DEVICE_KIND) {
      auto dev = dm::HapticDevice::open(registry, f.key.name);
      if (dev) {
        const dm::HapticInfo& i = (*dev)->info();
        d["open"] = {{"status", "ok"},     {"vendor", i.vendor},        {"model", i.model},
                     {"serial", i.serial}, {"max_force_N", i.maxForce}, {"servo_rate_hz", i.servoRateHz}};
      } else {
        d["open"] = {{"status", "error"}, {"error", dev.error().message()}};
      }
    }
    drivers.push_back(d);
  }
  // With --only, the exit code says whether that driver was found (and, with
  // --open, opened).
  int exitCode = kExitOk;
  if (!o.only.empty()) {
    if (drivers.empty()) {
      printError(dm::fail(dm::ErrorCode::NotFound, "no device driver named '" + o.only + "'",
                          "dmtool devices", "check the plugin directories listed by `dmtool devices`"));
      exitCode = kExitFailure;
    } else if (o.open && drivers[0].contains("open") && drivers[0]["open"]["status"] != "ok") {
      exitCode = kExitFailure;
    }
  }
  nlohmann::json dirs = nlohmann::json::array();
  for (const fs::path& p : linker.searchPaths()) dirs.push_back(p.string());

  if (o.json) {
    printJson({{"plugin_dirs", dirs}, {"plugins", plugins}, {"drivers", drivers}});
    return exitCode;
  }
  std::cout << "plugin directories:";
  if (dirs.empty()) std::cout << " (none)";
  for (const auto& d : dirs) std::cout << "\n  " << d.get<std::string>();
  std::cout << "\nplugins:\n";
  for (const auto& p : plugins) {
    std::cout << "  "
              << (p["name"].get<std::string>().empty() ? p["path"].get<std::string>()
                                                       : p["name"].get<std::string>())
              << "  [" << p["status"].get<std::string>() << "]";
    if (p.contains("error")) std::cout << "  " << p["error"].get<std::string>();
    std::cout << '\n';
  }
  std::cout << "drivers:\n";
  for (const auto& d : drivers) {
    std::cout << "  " << d["kind"].get<std::string>() << " / " << d["name"].get<std::string>() << "  (from "
              << d["provider"].get<std::string>() << ")";
    if (d.contains("available")) {
      if (d["available"].get<bool>())
        std::cout << "  available: " << d["library"].get<std::string>();
      else
        std::cout << "  unavailable: " << d["unavailable_reason"].get<std::string>();
    }
    if (d.contains("open")) {
      const auto& op = d["open"];
      if (op["status"] == "ok")
        std::cout << "  opened: " << op["model"].get<std::string>() << ", " << op["max_force_N"].get<double>()
                  << " N, " << op["servo_rate_hz"].get<double>() << " Hz";
      else
        std::cout << "  cannot open with defaults: " << op["error"].get<std::string>();
    }
    std::cout << '\n';
  }
  return exitCode;
}

}  // namespace

Command addDevicesCommand(CLI::App& parent) {
  auto o = std::make_shared<DevicesCliOptions>();
  CLI::App* app = parent.add_subcommand(
      "devices", "List the device drivers found (built in and plugins) and their status");
  app->add_option("--plugin-dir", o->pluginDirs, "Also load plugins from this directory (repeatable)");
  app->add_flag("--no-builtin", o->noBuiltin, "Do not list the drivers built into DM::IO");
  app->add_flag("--open", o->open, "Open each haptic-device driver with default parameters and report it");
  app->add_option(
      "--only", o->only,
      "List only the driver of this name; exit 1 if it is missing (or, with --open, fails to open)");
  app->add_flag("--verbose", o->verbose, "Also log every plugin load on stderr");
  app->add_flag("--json", o->json, "Print one JSON object on stdout");
  return {app, [o] { return runDevices(*o); }};
}

}  // namespace dmtool
