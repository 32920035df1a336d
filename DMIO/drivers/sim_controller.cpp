// sim-controller — a simulated controller (kind "controller"): six scripted
// analog axes and up to 128 buttons, deterministic for a given seed.
//
// Axis i at host time t (s) is clamp(signal_i(t) + noise, -1, 1), signal_i
// given by parameter axisI (see dm::driver::Signal); button i is pressed
// when bit (i mod 64) of floor(t · button_rate) is set: the buttons count
// in binary, so every pattern occurs. A loss window (drop_at,
// reconnect_at) exercises connection loss and reconnection.
//
// Parameters (all optional):
//   axis0 … axis5  "shape[,amplitude[,frequency[,offset]]]"   (constant,1,1,0: at 0)
//                  shape sine | square | ramp | constant; frequency Hz
//   axes           axes reported as moving, 0..6                (6)
//   buttons        button count, 0..128                         (16)
//   button_rate    Hz of the binary button counter              (1)
//   noise          standard deviation added to every axis       (0)
//   seed           integer, noise generator                     (1)
//   poll_rate      Hz                                           (250)
//   drop_at, reconnect_at  s (-1: never)
//
// Built into DM::IO and, with DM_DRIVER_PLUGIN, as libdm_driver_sim_controller.so.
#include <dm/core/plugin_abi.h>
#include <dm/io/device_abi.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <new>
#include <random>

#include "driver_params.hpp"
#include "sim_signal.hpp"

namespace {

using dm::driver::ParamReader;
using dm::driver::Signal;

// One instance; DmDevice* is this type behind the C boundary.
struct SimController {
  Signal axes[DM_CONTROLLER_AXES];
  unsigned axisCount = DM_CONTROLLER_AXES, buttonCount = 16;
  double buttonRate = 1.0, noise = 0.0, pollRate = 250.0;
  unsigned long long seed = 1;
  std::mt19937_64 rng;
  std::normal_distribution<double> gauss{0.0, 1.0};
  dm::driver::LossWindow loss;
};

SimController* asSimController(DmDevice* d) { return reinterpret_cast<SimController*>(d); }

DmDevice* ctlOpen(const DmDeviceParam* params, size_t count, char* error, size_t errorSize) {
  ParamReader r(params, count, error, errorSize);
  r.onlyKnown({"axis0", "axis1", "axis2", "axis3", "axis4", "axis5", "axes", "buttons", "button_rate",
               "noise", "seed", "poll_rate", "drop_at", "reconnect_at"});
  SimController* d = new (std::nothrow) SimController();
  if (!d) {
    r.failf("out of memory");
    return nullptr;
  }
  static const char* const kAxisKeys[] = {"axis0", "axis1", "axis2", "axis3", "axis4", "axis5"};
  for (int i = 0; i < DM_CONTROLLER_AXES; ++i) {
    d->axes[i] = Signal{Signal::kConstant, 1.0, 1.0, 0.0};
    dm::driver::readSignal(r, kAxisKeys[i], d->axes[i]);
  }
  d->axisCount = dm::driver::wholeNumber(r, "axes", DM_CONTROLLER_AXES, 0, DM_CONTROLLER_AXES);
  d->buttonCount = dm::driver::wholeNumber(r, "buttons", 16, 0, DM_CONTROLLER_MAX_BUTTONS);
  d->buttonRate = r.number("button_rate", 1.0, 0.0, 1e6);
  d->noise = r.number("noise", 0.0, 0.0, 10.0);
  d->seed = static_cast<unsigned long long>(r.number("seed", 1.0, 0.0, 9007199254740992.0));
  d->pollRate = r.number("poll_rate", 250.0, 1.0, 1e6);
  d->loss.read(r);
  if (!r.ok()) {
    delete d;
    return nullptr;
  }
  d->rng.seed(d->seed);
  return reinterpret_cast<DmDevice*>(d);
}

void ctlClose(DmDevice* d) { delete asSimController(d); }

int ctlInfo(DmDevice* dev, DmControllerInfo* info) {
  SimController* d = asSimController(dev);
  *info = DmControllerInfo{};
  dm::driver::simIdentity(info->identity, "sim-controller", "simulated 6-axis controller", d->seed);
  info->capabilities = DM_CONTROLLER_CAP_AXES | DM_CONTROLLER_CAP_BUTTONS | DM_CONTROLLER_CAP_RECONNECT;
  info->axis_count = d->axisCount;
  info->button_count = d->buttonCount;
  info->poll_rate_hz = d->pollRate;
  return DM_DEVICE_OK;
}

int ctlRead(DmDevice* dev, int64_t now, DmControllerState* s) {
  SimController* d = asSimController(dev);
  if (d->loss.lostAt(now)) return DM_DEVICE_ERROR_LOST;
  const double t = 1e-9 * static_cast<double>(now);
  *s = DmControllerState{};
  s->time_ns = now;
  for (unsigned i = 0; i < d->axisCount; ++i) {
    double a = d->axes[i].at(t);
    if (d->noise > 0.0) a += d->noise * d->gauss(d->rng);
    s->axes[i] = std::clamp(a, -1.0, 1.0);
  }
  const double ticks = std::floor(t * d->buttonRate);
  const std::uint64_t counter = ticks > 0.0 && ticks < 1.8e19 ? static_cast<std::uint64_t>(ticks) : 0;
  for (unsigned i = 0; i < d->buttonCount; ++i)
    if ((counter >> (i % 64)) & 1u) s->buttons[i / 64] |= std::uint64_t{1} << (i % 64);
  return DM_DEVICE_OK;
}

int ctlReconnect(DmDevice* dev, int64_t now) { return asSimController(dev)->loss.reconnect(now); }

const DmControllerVTable kSimController = {ctlOpen, ctlClose, ctlInfo, ctlRead, ctlReconnect};

int ctlInit(const DmHostApi* host) {
  return host->register_factory(host->ctx, DM_CONTROLLER_KIND, "sim-controller",
                                DM_CONTROLLER_KIND_ABI_VERSION, &kSimController);
}

const DmPluginInfo kSimControllerInfo = {DM_PLUGIN_ABI_VERSION, "sim-controller", "1.0", ctlInit, nullptr};

}  // namespace

#if defined(DM_DRIVER_PLUGIN)
DM_PLUGIN_ENTRY { return &kSimControllerInfo; }
#else
extern "C" const DmPluginInfo* dm_builtin_entry_sim_controller(void) { return &kSimControllerInfo; }
#endif
