// dmtool teleop-device --driver NAME [--param key=value]... [--plugin-dir DIR]...
//                      [--listen ADDR:PORT] [--allow ADDR]... [--timeout S]
//                      [--seconds S] [--json]
// serves a local haptic device to a simulator elsewhere over the
// tele-operation stream (dm/network/teleop.hpp): the device side that the
// simulator's "net-haptic" driver talks to. A real-time loop at the device's
// servo rate runs a TeleopDeviceBridge: it servos the device, sends its
// state, and commands the newest force, or zero when the host fell silent
// for --timeout; with --wave-impedance B it exchanges wave variables instead
// (stable under delay; the simulator's net-haptic uses the same B). Prints the bound address first ("serving ... on ADDR:PORT",
// useful with port 0), then the link statistics once a second; with
// --seconds it stops after that long (otherwise on SIGINT/SIGTERM) and, with
// --json, prints the final statistics as one JSON object.
#include <dm/core/log.hpp>
#include <dm/core/plugin.hpp>
#include <dm/core/rt_loop.hpp>
#include <dm/io/drivers.hpp>
#include <dm/io/haptic_device.hpp>
#include <dm/network/drivers.hpp>
#include <dm/network/teleop.hpp>

#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <iostream>
#include <thread>

#include "common.hpp"

namespace dmtool {
namespace {

struct TeleopCliOptions {
  std::string driver = "sim-haptic";
  std::vector<std::string> params;
  std::vector<std::string> pluginDirs;
  std::string listen = "0.0.0.0:47000";
  std::vector<std::string> allow;
  double timeout = 0.1;
  double waveImpedance = 0.0;
  std::string wavePolicy = "hold";
  double seconds = 0.0;
  bool json = false;
};

std::atomic<bool> gStop{false};
extern "C" void onSignal(int) { gStop.store(true); }

nlohmann::json statsJson(const dm::LatencyStats& s) {
  return {{"count", s.count}, {"p50_us", 1e6 * s.p50}, {"p99_us", 1e6 * s.p99},
          {"p999_us", 1e6 * s.p999}, {"max_us", 1e6 * s.max}};
}

nlohmann::json statsJson(const dm::TeleopStats& s) {
  return {{"sent", s.sent},
          {"send_failed", s.sendFailed},
          {"received", s.received},
          {"malformed", s.malformed},
          {"foreign", s.foreign},
          {"duplicates", s.duplicates},
          {"late", s.late},
          {"lost", s.lost},
          {"loss_ratio", s.lossRatio},
          {"round_trip", statsJson(s.roundTrip)},
          {"one_way", statsJson(s.oneWay)},
          {"jitter_us", 1e6 * s.jitter},
          {"clock_offset_us", 1e6 * s.clockOffset},
          {"link_up", s.linkUp}};
}

int runTeleopDevice(const TeleopCliOptions& o) {
  auto listen = dm::parseEndpoint(o.listen, "--listen", true);
  if (!listen) {
    std::cerr << "dmtool: " << listen.error().message() << '\n';
    return kExitUsage;
  }
  dm::DeviceParams params;
  for (const std::string& p : o.params) {
    const std::size_t eq = p.find('=');
    if (eq == std::string::npos || eq == 0) {
      std::cerr << "dmtool: --param '" << p << "' is not key=value\n";
      return kExitUsage;
    }
    params.emplace_back(p.substr(0, eq), p.substr(eq + 1));
  }
  dm::FactoryRegistry registry;
  dm::PluginLinkerOptions linkerOptions;
  linkerOptions.probe = true;  // a plugin that crashes in init is refused, not fatal
  dm::PluginLinker linker(registry, linkerOptions);
  if (auto s = dm::registerBuiltinDrivers(linker); !s) return printError(s.error());
  for (const std::string& dir : o.pluginDirs) (void)linker.scanDirectory(dir);  // refusals are logged
  auto device = dm::HapticDevice::open(registry, o.driver, params);
  if (!device) return printError(device.error());
  auto link = dm::TeleopDevice::open({.local = *listen, .allow = o.allow, .timeoutSeconds = o.timeout},
                                     (*device)->info());
  if (!link) return printError(link.error());
  const dm::HapticInfo& info = (*device)->info();
  // With --json stdout holds only the JSON object.
  std::FILE* banner = o.json ? stderr : stdout;
  std::fprintf(banner, "serving %s (%s) on %s at %g Hz\n", o.driver.c_str(), info.model.c_str(),
               dm::describe({listen->address, (*link)->port()}).c_str(), info.servoRateHz);
  std::fflush(banner);

  const double rate = info.servoRateHz > 0 ? info.servoRateHz : 1000.0;
  dm::TeleopDeviceBridge bridge(
      **device, **link,
      {.timeoutSeconds = o.timeout,
       .waveImpedance = o.waveImpedance,
       .wavePolicy = o.wavePolicy == "zero" ? dm::WaveLossPolicy::Zero : dm::WaveLossPolicy::Hold});
  dm::RealTimeLoop loop({.rate_hz = rate, .name = "dm-teleop-dev"},
                        [&](const dm::TickInfo& t) { bridge.step(t.start_ns); });
  if (auto s = loop.start(); !s) return printError(s.error());
  gStop = false;
  std::signal(SIGINT, onSignal);
  std::signal(SIGTERM, onSignal);
  const auto start = std::chrono::steady_clock::now();
  auto nextReport = start + std::chrono::seconds(1);
  while (!gStop.load()) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
    const auto now = std::chrono::steady_clock::now();
    if (o.seconds > 0 && now - start >= std::chrono::duration<double>(o.seconds)) break;
    if (now >= nextReport && !o.json) {
      nextReport += std::chrono::seconds(1);
      const dm::TeleopStats s = (*link)->stats();
      std::printf("link %s  sent %llu  received %llu  lost %llu  rtt p50 %.0f us p99 %.0f us  jitter %.0f us\n",
                  s.linkUp ? "up" : "down", static_cast<unsigned long long>(s.sent),
                  static_cast<unsigned long long>(s.received), static_cast<unsigned long long>(s.lost),
                  1e6 * s.roundTrip.p50, 1e6 * s.roundTrip.p99, 1e6 * s.jitter);
      std::fflush(stdout);
    }
  }
  loop.stop();
  std::signal(SIGINT, SIG_DFL);
  std::signal(SIGTERM, SIG_DFL);
  const dm::TeleopStats s = (*link)->stats();
  if (o.json) {
    nlohmann::json j = {{"driver", o.driver},
                        {"port", (*link)->port()},
                        {"zeroed_steps", bridge.zeroedSteps()},
                        {"loop_ticks", loop.stats().ticks},
                        {"output_force_N", dmtool::toJson((*device)->lastOutput().force)},
                        {"output_force_mean_N", dmtool::toJson(bridge.meanForce())},
                        {"stream", statsJson(s)}};
    if (const dm::WaveMasterPort* w = bridge.wavePort()) {
      const dm::WaveReceiverStats ws = w->receiver().stats();
      j["wave"] = {{"impedance", o.waveImpedance},
                   {"energy_in_J", w->receiver().energyIn()},
                   {"energy_out_J", w->receiver().energyOut()},
                   {"received", ws.received},
                   {"stale", ws.stale},
                   {"held", ws.held},
                   {"limited", ws.limited}};
    }
    printJson(j);
  }
  return kExitOk;
}

}  // namespace

Command addTeleopDeviceCommand(CLI::App& parent) {
  auto o = std::make_shared<TeleopCliOptions>();
  CLI::App* app = parent.add_subcommand(
      "teleop-device", "Serve a local haptic device to a remote simulator (its net-haptic driver) over UDP");
  app->add_option("--driver", o->driver, "Haptic-device driver to open (default sim-haptic)");
  app->add_option("--param", o->params, "Driver parameter key=value (repeatable)");
  app->add_option("--plugin-dir", o->pluginDirs, "Also load driver plugins from this directory (repeatable)");
  app->add_option("--listen", o->listen, "Address:port to serve on (default 0.0.0.0:47000; port 0: any)");
  app->add_option("--allow", o->allow, "Accept only this host address (repeatable; default any)");
  app->add_option("--timeout", o->timeout, "Seconds without a force before the output is zeroed (default 0.1)")
      ->check(CLI::Range(1e-3, 60.0));
  app->add_option("--wave-impedance", o->waveImpedance,
                  "Wave-variable mode with this impedance b in N*s/m (the simulator's net-haptic needs the same "
                  "wave_impedance); 0: force mode (default)")
      ->check(CLI::Range(0.0, 1e6));
  app->add_option("--wave-policy", o->wavePolicy, "Wave receiver loss policy: hold (default) or zero")
      ->check(CLI::IsMember({"hold", "zero"}));
  app->add_option("--seconds", o->seconds, "Stop after this long (default: run until SIGINT/SIGTERM)")
      ->check(CLI::Range(0.0, 1e7));
  app->add_flag("--json", o->json, "Print the final statistics as one JSON object (no periodic lines)");
  return {app, [o] { return runTeleopDevice(*o); }};
}

}  // namespace dmtool
