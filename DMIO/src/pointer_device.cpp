// The "pointer" driver: a kinematic stand-in device moved by the program
// through a PointerChannel (dm/io/pointer_device.hpp). Built into DM::IO
// only; registered by registerBuiltinDrivers.
#include <dm/core/plugin_abi.h>
#include <dm/io/device_abi.h>
#include <dm/io/pointer_device.hpp>

#include <algorithm>
#include <map>
#include <memory>
#include <mutex>
#include <new>

#include "../drivers/driver_params.hpp"

namespace dm {

PointerChannel& pointerChannel(const std::string& name) {
  static std::mutex m;
  static std::map<std::string, std::unique_ptr<PointerChannel>> channels;
  std::lock_guard<std::mutex> lock(m);
  auto& c = channels[name];
  if (!c) c = std::make_unique<PointerChannel>();
  return *c;
}

namespace {

struct Pointer {
  PointerChannel* channel = nullptr;
  std::string name;
  double workspace = 0.1, maxForce = 5.0, servoRate = 1000.0;
  Vec3 last = Vec3::Zero();
  std::int64_t lastNs = 0;
  bool read = false;
};
Pointer* asPointer(DmDevice* d) { return reinterpret_cast<Pointer*>(d); }

DmDevice* pointerOpen(const DmDeviceParam* params, size_t count, char* error, size_t errorSize) {
  driver::ParamReader p(params, count, error, errorSize);
  p.onlyKnown({"channel", "workspace", "max_force", "servo_rate"});
  const char* channel = p.find("channel");
  const double workspace = p.number("workspace", 0.1, 1e-4, 10.0);
  const double maxForce = p.number("max_force", 5.0, 1e-3, 1e3);
  const double servoRate = p.number("servo_rate", 1000.0, 1.0, 1e5);
  if (channel && !*channel) p.failf("parameter 'channel': empty");
  if (!p.ok()) return nullptr;
  Pointer* d = new (std::nothrow) Pointer;
  if (!d) {
    p.failf("out of memory");
    return nullptr;
  }
  d->name = channel ? channel : "mouse";
  d->channel = &pointerChannel(d->name);
  d->workspace = workspace;
  d->maxForce = maxForce;
  d->servoRate = servoRate;
  return reinterpret_cast<DmDevice*>(d);
}

void pointerClose(DmDevice* d) { delete asPointer(d); }

int pointerInfo(DmDevice* dev, DmHapticInfo* info) {
  const Pointer* d = asPointer(dev);
  *info = DmHapticInfo{};
  driver::copyField(info->identity.driver, "pointer");
  driver::copyField(info->identity.vendor, "DMPlatform");
  driver::copyField(info->identity.model, "pointer (kinematic stand-in)");
  driver::copyField(info->identity.serial, d->name.c_str());
  info->capabilities = DM_HAPTIC_CAP_POSITION | DM_HAPTIC_CAP_VELOCITY | DM_HAPTIC_CAP_FORCE;
  info->button_count = 32;
  for (int i = 0; i < 3; ++i) {
    info->workspace_min[i] = -d->workspace;
    info->workspace_max[i] = d->workspace;
  }
  info->max_force = d->maxForce;
  info->max_stiffness = 1e9;  // kinematic: nothing it renders is unstable
  info->max_damping = 1e9;
  info->servo_rate_hz = d->servoRate;
  return DM_DEVICE_OK;
}

int pointerRead(DmDevice* dev, int64_t now, DmHapticState* s) {
  Pointer* d = asPointer(dev);
  const PointerChannel::Input& in = d->channel->input();
  Vec3 x = in.position;
  if (!x.allFinite()) x = d->last;  // a bad input keeps the device where it was
  x = x.cwiseMax(Vec3::Constant(-d->workspace)).cwiseMin(Vec3::Constant(d->workspace));
  *s = DmHapticState{};
  s->time_ns = now;
  Vec3 v = Vec3::Zero();
  if (d->read && now > d->lastNs) v = (x - d->last) / (1e-9 * double(now - d->lastNs));
  for (int i = 0; i < 3; ++i) {
    s->position[i] = x[i];
    s->linear_velocity[i] = v[i];
  }
  s->orientation[0] = 1.0;
  s->buttons = in.buttons;
  d->last = x;
  d->lastNs = now;
  d->read = true;
  return DM_DEVICE_OK;
}

int pointerWrite(DmDevice* dev, int64_t, const double force[3], const double*) {
  asPointer(dev)->channel->sent(Vec3(force[0], force[1], force[2]));
  return DM_DEVICE_OK;
}

const DmHapticDeviceVTable kPointer = {pointerOpen, pointerClose, pointerInfo,
                                       pointerRead, pointerWrite, nullptr};

int pointerInit(const DmHostApi* host) {
  return host->register_factory(host->ctx, DM_HAPTIC_DEVICE_KIND, "pointer",
                                DM_HAPTIC_DEVICE_KIND_ABI_VERSION, &kPointer);
}

const DmPluginInfo kPointerInfo = {DM_PLUGIN_ABI_VERSION, "pointer", "1.0", pointerInit, nullptr};

}  // namespace

}  // namespace dm

extern "C" const DmPluginInfo* dm_builtin_entry_pointer(void) { return &dm::kPointerInfo; }
