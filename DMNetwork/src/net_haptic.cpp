// net-haptic — a haptic device on another machine, through the tele-operation
// stream (kind "haptic-device"); see dm/network/drivers.hpp for what it does
// and its parameters. The C vtable wraps a dm::TeleopHost on a network
// receive thread of its own.
#include <dm/core/endpoint.hpp>
#include <dm/core/plugin_abi.h>
#include <dm/io/device_abi.h>
#include <dm/network/drivers.hpp>
#include <dm/network/teleop.hpp>

#include <chrono>
#include <memory>
#include <new>
#include <optional>
#include <string_view>
#include <thread>

#include "driver_params.hpp"

namespace dm {

Result<SocketAddress> parseEndpoint(std::string_view text, std::string_view field, bool allowZeroPort) {
  auto hp = parseHostPort(text, field, allowZeroPort);
  if (!hp) return hp.error();
  return SocketAddress{std::move(hp->host), hp->port};
}

}  // namespace dm

namespace {

using dm::driver::ParamReader;

// One driver instance; DmDevice* is this type behind the C boundary.
struct NetHaptic {
  std::unique_ptr<dm::TeleopHost> host;
  dm::HapticInfo info;
  std::int64_t timeoutNs = 100'000'000;
  // Wave-variable mode: this driver is the slave port (see drivers.hpp).
  double waveImpedance = 0.0;
  dm::WaveLossPolicy wavePolicy = dm::WaveLossPolicy::Hold;
  std::optional<dm::WaveSlavePort> wave;
  // An in-process link on a clock that only the run advances (lockstep):
  // open cannot wait for the first state, so reads until then, within
  // wait_for_state of opening, report "no sample yet" (an I/O error of the
  // tick) instead of a lost device.
  bool waitInRun = false;
  std::int64_t firstStateDeadlineNs = 0;
  bool sawState = false;
};

// Is the device there but its first state still on the way (see waitInRun)?
bool awaitingFirstState(const NetHaptic& d) {
  return d.waitInRun && !d.sawState && d.host->clock().now() < d.firstStateDeadlineNs;
}

NetHaptic* self(DmDevice* d) { return reinterpret_cast<NetHaptic*>(d); }

DmDevice* netOpen(const DmDeviceParam* params, size_t count, char* error, size_t errorSize) {
  ParamReader r(params, count, error, errorSize);
  r.onlyKnown({"device", "local", "timeout", "connect_timeout", "wait_for_state", "synchronized_clocks",
               "wave_impedance", "wave_policy", "emulate_delay", "emulate_jitter", "emulate_loss", "emulate_seed"});
  const double waitForState = r.number("wait_for_state", 0.0, 0.0, 600.0);
  const double waveImpedance = r.number("wave_impedance", 0.0, 0.0, 1e6);
  const int wavePolicy = r.choice("wave_policy", {"hold", "zero"}, 0);
  const double emulateDelay = r.number("emulate_delay", 0.0, 0.0, 10.0);
  const double emulateJitter = r.number("emulate_jitter", 0.0, 0.0, 10.0);
  const double emulateLoss = r.number("emulate_loss", 0.0, 0.0, 1.0);
  const double emulateSeed = r.number("emulate_seed", 1.0, 0.0, 9007199254740992.0);
  const double timeout = r.number("timeout", 0.1, 1e-3, 60.0);
  const double connectTimeout = r.number("connect_timeout", 2.0, 0.0, 600.0);
  const bool synchronized = r.number("synchronized_clocks", 0.0, 0.0, 1.0) != 0.0;
  const char* deviceText = r.find("device");
  if (r.ok() && !deviceText)
    r.failf("parameter 'device' is required: \"address:port\" of the device side, or \"inproc:NAME\"");
  if (!r.ok()) return nullptr;
  const bool inproc = std::string_view(deviceText).starts_with("inproc:");
  if (inproc && (r.find("local") || r.find("synchronized_clocks"))) {
    r.failf("parameter '%s' does not apply to an in-process device (%s): it has no socket and one clock",
            r.find("local") ? "local" : "synchronized_clocks", deviceText);
    return nullptr;
  }
  auto peer = inproc ? dm::Result<dm::SocketAddress>(dm::SocketAddress{deviceText, 0})
                     : dm::parseEndpoint(deviceText, "parameter 'device'");
  if (!peer) {
    r.failf("%s", peer.error().message().c_str());
    return nullptr;
  }
  const char* localText = r.find("local");
  auto local = dm::parseEndpoint(localText ? localText : "0.0.0.0:0", "parameter 'local'", true);
  if (!local) {
    r.failf("%s", local.error().message().c_str());
    return nullptr;
  }
  auto d = std::unique_ptr<NetHaptic>(new (std::nothrow) NetHaptic());
  if (!d) {
    r.failf("out of memory");
    return nullptr;
  }
  d->timeoutNs = static_cast<std::int64_t>(timeout * 1e9);
  d->waveImpedance = waveImpedance;
  d->wavePolicy = wavePolicy == 0 ? dm::WaveLossPolicy::Hold : dm::WaveLossPolicy::Zero;
  dm::TeleopOptions options{.local = *local,
                            .peer = *peer,
                            .timeoutSeconds = timeout,
                            .clocksSynchronized = synchronized};
  if (emulateDelay > 0 || emulateJitter > 0 || emulateLoss > 0)
    options.emulate = dm::LinkEmulatorOptions{
        .delay = std::chrono::microseconds(static_cast<long long>(emulateDelay * 1e6)),
        .jitter = std::chrono::microseconds(static_cast<long long>(emulateJitter * 1e6)),
        .lossProbability = emulateLoss,
        .seed = static_cast<std::uint64_t>(emulateSeed)};
  auto host = dm::TeleopHost::open(options);
  if (!host) {
    r.failf("%s", host.error().message().c_str());
    return nullptr;
  }
  d->host = std::move(*host);
  auto info = d->host->waitForDevice(std::chrono::milliseconds(static_cast<long long>(connectTimeout * 1e3)));
  if (!info) {
    r.failf("%s", info.error().message().c_str());
    return nullptr;
  }
  d->info = std::move(*info);
  if (waitForState > 0 && d->host->onSuppliedClock()) {
    d->waitInRun = true;
    d->firstStateDeadlineNs = d->host->clock().now() + dm::secondsToNanos(waitForState);
  } else if (waitForState > 0) {
    // The first servo then already has a state instead of reporting a loss.
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(waitForState);
    dm::HapticState first;
    while (d->host->poll(), !d->host->latestState(first)) {
      if (std::chrono::steady_clock::now() >= deadline) {
        r.failf("the device side at %s answered but sent no state within wait_for_state = %g s (is its servo "
                "loop running?)",
                dm::describe(*peer).c_str(), waitForState);
        return nullptr;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
  }
  return reinterpret_cast<DmDevice*>(d.release());
}

void netClose(DmDevice* d) { delete self(d); }

int netInfo(DmDevice* dev, DmHapticInfo* out) {
  const dm::HapticInfo& info = self(dev)->info;
  *out = DmHapticInfo{};
  dm::driver::copyField(out->identity.driver, "net-haptic");
  dm::driver::copyField(out->identity.vendor, info.vendor.c_str());
  dm::driver::copyField(out->identity.model, info.model.c_str());
  dm::driver::copyField(out->identity.serial, info.serial.c_str());
  out->capabilities = info.capabilities;
  out->button_count = info.buttonCount;
  for (int i = 0; i < 3; ++i) {
    out->workspace_min[i] = info.workspace.min()[i];
    out->workspace_max[i] = info.workspace.max()[i];
  }
  out->max_force = info.maxForce;
  out->max_torque = info.maxTorque;
  out->max_stiffness = info.maxStiffness;
  out->max_damping = info.maxDamping;
  out->servo_rate_hz = info.servoRateHz;
  return DM_DEVICE_OK;
}

int netRead(DmDevice* dev, int64_t now, DmHapticState* out) {
  NetHaptic* d = self(dev);
  d->host->poll();
  dm::HapticState s;
  std::int64_t age = 0;
  if (!d->host->latestState(s, &age) || age > d->timeoutNs)
    return awaitingFirstState(*d) ? DM_DEVICE_ERROR_IO : DM_DEVICE_ERROR_LOST;
  d->sawState = true;
  if (d->waveImpedance > 0) {
    // Slave port: the tool starts where the device is, then only waves move
    // it; apply() in write moves it with the force rendered at what read
    // reported.
    if (!d->wave) {
      // The Info's servo rate is checked positive by HapticDevice::open.
      d->wave.emplace(dm::WavePortOptions{
          .impedance = d->waveImpedance, .dt = 1.0 / d->info.servoRateHz, .policy = d->wavePolicy});
      d->wave->reset(s.position);
    }
    dm::WaveSample w;
    while (d->host->popWave(w)) d->wave->receive(w);
    d->wave->begin();
    s.position = d->wave->position();
    s.linearVelocity = d->wave->velocity();
  }
  *out = DmHapticState{};
  out->time_ns = now;
  for (int i = 0; i < 3; ++i) {
    out->position[i] = s.position[i];
    out->linear_velocity[i] = s.linearVelocity[i];
    out->angular_velocity[i] = s.angularVelocity[i];
  }
  out->orientation[0] = s.orientation.w();
  out->orientation[1] = s.orientation.x();
  out->orientation[2] = s.orientation.y();
  out->orientation[3] = s.orientation.z();
  out->buttons = s.buttons;
  return DM_DEVICE_OK;
}

int netWrite(DmDevice* dev, int64_t /*now*/, const double force[3], const double torque[3]) {
  NetHaptic* d = self(dev);
  if (!d->host->linkUp()) return awaitingFirstState(*d) ? DM_DEVICE_ERROR_IO : DM_DEVICE_ERROR_LOST;
  dm::HapticOutput out;
  out.force = dm::Vec3(force[0], force[1], force[2]);
  out.torque = dm::Vec3(torque[0], torque[1], torque[2]);
  if (d->wave && !d->host->sendWave(d->wave->apply(out.force))) return DM_DEVICE_ERROR_IO;
  // In wave mode the Force still carries the timing echo; the device side does not apply it.
  return d->host->sendForce(out) ? DM_DEVICE_OK : DM_DEVICE_ERROR_IO;
}

int netReconnect(DmDevice* dev, int64_t /*now*/) {
  NetHaptic* d = self(dev);
  if (d->host->linkUp()) return DM_DEVICE_OK;
  d->host->sendHello();  // a restarted device side learns this host again
  return DM_DEVICE_ERROR_LOST;
}

const DmHapticDeviceVTable kNetHaptic = {netOpen, netClose, netInfo, netRead, netWrite, netReconnect};

int netInit(const DmHostApi* host) {
  return host->register_factory(host->ctx, DM_HAPTIC_DEVICE_KIND, "net-haptic", DM_HAPTIC_DEVICE_KIND_ABI_VERSION,
                                &kNetHaptic);
}

const DmPluginInfo kInfo = {DM_PLUGIN_ABI_VERSION, "net-haptic", "1.0", netInit, nullptr};

const DmPluginInfo* netEntry(void) { return &kInfo; }

}  // namespace

namespace dm {

std::vector<std::string> networkDriverNames() { return {"net-haptic"}; }

Status registerNetworkDrivers(PluginLinker& linker) {
  if (auto r = linker.addStatic(&netEntry); !r) return std::move(r).error();
  return ok();
}

}  // namespace dm
