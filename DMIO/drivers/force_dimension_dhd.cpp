// force-dimension-dhd — Force Dimension omega, delta and sigma devices, and
// the Novint Falcon, through the Force Dimension DHD API (kind
// "haptic-device"). The DHD library is loaded at run time (dlopen):
// DMPlatform builds and runs without it, and opening the driver where it is
// not installed fails saying what to install (vendor_library.hpp; `dmtool
// devices` lists the driver as unavailable).
//
// Parameters:
//   library    path of the DHD library (default: libdhd.so, libdhd.so.3)
//   index      which device when several are connected: 0 .. count − 1
//              (default: the first, dhdOpen())
//   max_force  N, the continuous force the host may send (default: the
//              model's datasheet value below; required for a model not
//              listed there)
//   max_torque N·m, torque output for a model with an active wrist (default:
//              the library's dhdGetMaxTorque when it has one, else none)
//   workspace  m, half extents "x,y,z" of the device's box (default: the
//              model's datasheet value below)
//   servo_rate Hz at which the host should servo it (default 1000; the
//              devices run up to 8 kHz)
// Models known (dhdGetSystemType → datasheet): omega.3/6/7 12 N, workspace
// Ø 160 × 110 mm; delta.3/6 20 N, Ø 400 × 260 mm; Novint Falcon 9 N,
// 100 mm cube. A cylinder Ø × L is given as the box x ± L/2, y and z ± Ø/2.
//
// How it runs: DHD calls are synchronous (the device's USB transfers), made
// on the host's servo thread as Force Dimension's examples make them in
// their haptic loop: read_state reads position and orientation frame,
// linear velocity (the library's estimator, configured at open), angular
// velocity when the library has dhdGetAngularVelocityRad, and the buttons;
// write_output sets force (and torque with an active wrist). Nothing is
// allocated or locked on that path.
// Errors: a call failing with DHD_ERROR_COM, DHD_ERROR_NO_DEVICE_FOUND or
// DHD_ERROR_DEVICE_NOT_READY reports the device lost; reconnect opens it
// again. A device in RESET mode (waiting for its calibration) has its
// samples refused (an I/O error) and gets no force. Other failures are
// I/O errors. dhdSetForce's TimeGuard return (called sooner than the
// device's minimum period) is not an error.
// Limits: the gripper of an omega.7 or sigma.7 is not read or driven.
#include <dm/core/plugin_abi.h>
#include <dm/io/device_abi.h>

#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <new>
#include <string>

#include "driver_params.hpp"
#include "rotation.hpp"
#include "vendor_library.hpp"

namespace {

// --- the DHD API as its public header declares it (dhdc.h) -----------------
constexpr int DHD_NO_ERROR = 0, DHD_ERROR_COM = 2, DHD_ERROR_NO_DEVICE_FOUND = 5,
              DHD_ERROR_DEVICE_NOT_READY = 12;
constexpr int DHD_ON = 1, DHD_OFF = 0;
constexpr int DHD_TIMEGUARD = 1;
constexpr int DHD_STATUS_RESET = 3;
constexpr int DHD_MAX_BUTTONS = 8;
constexpr int DHD_VELOCITY_WINDOWING = 0, DHD_VELOCITY_WINDOW = 20;  // ms
constexpr int kStatusSlots = 32;  // DHD_MAX_STATUS grew across versions (13 in 3.2): room for any

struct DhdApi {
  int (*getDeviceCount)();
  int (*open)();
  int (*openID)(char);
  int (*close)(char);
  int (*getSystemType)(char);
  const char* (*getSystemName)(char);  // optional (3.2.x on)
  int (*getSerialNumber)(unsigned short*, char);
  int (*getStatus)(int*, char);
  int (*getPositionAndOrientationFrame)(double*, double*, double*, double (*)[3], char);
  int (*configLinearVelocity)(int, int, char);
  int (*getLinearVelocity)(double*, double*, double*, char);
  int (*getAngularVelocityRad)(double*, double*, double*, char);  // optional
  int (*getButton)(int, char);
  int (*setForce)(double, double, double, char);
  int (*setForceAndTorque)(double, double, double, double, double, double, char);
  int (*enableForce)(unsigned char, char);
  int (*errorGetLast)();    // optional (newer SDKs)
  int* (*errnoLocation)();  // optional (3.2); one of the two is needed
  const char* (*errorGetStr)(int);
  double (*getMaxTorque)(char);  // optional

  // Resolves every call (some only newer SDKs have); on a missing one returns its name.
  const char* load(void* lib) {
    if (const char* missing = dm::driver::resolveVendorCalls(
            lib, {{"dhdGetDeviceCount", getDeviceCount},
                  {"dhdOpen", open},
                  {"dhdOpenID", openID},
                  {"dhdClose", close},
                  {"dhdGetSystemType", getSystemType},
                  {"dhdGetSystemName", getSystemName, false},
                  {"dhdGetSerialNumber", getSerialNumber},
                  {"dhdGetStatus", getStatus},
                  {"dhdGetPositionAndOrientationFrame", getPositionAndOrientationFrame},
                  {"dhdConfigLinearVelocity", configLinearVelocity},
                  {"dhdGetLinearVelocity", getLinearVelocity},
                  {"dhdGetAngularVelocityRad", getAngularVelocityRad, false},
                  {"dhdGetButton", getButton},
                  {"dhdSetForce", setForce},
                  {"dhdSetForceAndTorque", setForceAndTorque},
                  {"dhdEnableForce", enableForce},
                  {"dhdErrorGetLast", errorGetLast, false},
                  {"dhdErrnoLocation", errnoLocation, false},
                  {"dhdErrorGetStr", errorGetStr},
                  {"dhdGetMaxTorque", getMaxTorque, false}}))
      return missing;
    if (!errorGetLast && !errnoLocation) return "dhdErrorGetLast (or dhdErrnoLocation)";
    return nullptr;
  }
  int lastError() const { return errorGetLast ? errorGetLast() : *errnoLocation(); }
};

// Datasheet values of the models the driver knows.
struct Model {
  int type;
  const char* name;
  double force;    // N, continuous
  double half[3];  // m
};
constexpr Model kModels[] = {
    {33, "omega.3", 12.0, {0.055, 0.08, 0.08}},      {34, "omega.6", 12.0, {0.055, 0.08, 0.08}},
    {36, "omega.6 left", 12.0, {0.055, 0.08, 0.08}}, {35, "omega.7", 12.0, {0.055, 0.08, 0.08}},
    {37, "omega.7 left", 12.0, {0.055, 0.08, 0.08}}, {63, "delta.3", 20.0, {0.13, 0.2, 0.2}},
    {64, "delta.6", 20.0, {0.13, 0.2, 0.2}},         {60, "Novint Falcon", 9.0, {0.05, 0.05, 0.05}},
};
const Model* modelOf(int type) {
  for (const Model& m : kModels)
    if (m.type == type) return &m;
  return nullptr;
}

struct DhdDevice {
  void* lib = nullptr;
  DhdApi dhd{};
  int index = -1;  // -1: the first (dhdOpen)
  char id = -1;
  bool torque = false;
  bool inReset = false;  // the last read found it waiting for its calibration
  DmHapticInfo info{};
};

DhdDevice* asDhd(DmDevice* d) { return reinterpret_cast<DhdDevice*>(d); }

bool isLoss(int error) {
  return error == DHD_ERROR_COM || error == DHD_ERROR_NO_DEVICE_FOUND || error == DHD_ERROR_DEVICE_NOT_READY;
}
// The DHD status of a failed call.
int statusOf(const DhdDevice& d) {
  return isLoss(d.dhd.lastError()) ? DM_DEVICE_ERROR_LOST : DM_DEVICE_ERROR_IO;
}

std::string describeError(const DhdApi& dhd) {
  const int e = dhd.lastError();
  const char* text = dhd.errorGetStr(e);
  char buf[200];
  std::snprintf(buf, sizeof buf, "DHD error %d (%s)", e, text ? text : "no description");
  return buf;
}

// Opens the device and readies it for the servo loop; "" or why not.
std::string startDevice(DhdDevice& d) {
  const DhdApi& dhd = d.dhd;
  const int count = dhd.getDeviceCount();
  if (count <= 0)
    return count < 0 ? "dhdGetDeviceCount failed: " + describeError(dhd) : "no device connected";
  if (d.index >= count) {
    char buf[120];
    std::snprintf(buf, sizeof buf, "parameter 'index': %d, but %d device%s connected", d.index, count,
                  count == 1 ? " is" : "s are");
    return buf;
  }
  const int id = d.index < 0 ? dhd.open() : dhd.openID(static_cast<char>(d.index));
  if (id < 0) return "dhdOpen failed: " + describeError(dhd);
  d.id = static_cast<char>(id);
  if (dhd.configLinearVelocity(DHD_VELOCITY_WINDOW, DHD_VELOCITY_WINDOWING, d.id) < 0 ||
      dhd.enableForce(DHD_ON, d.id) < 0) {
    const std::string why = describeError(dhd);
    dhd.close(d.id);
    return "configuring the device failed: " + why;
  }
  return {};
}

void dhdCloseDevice(DmDevice* dev) {
  DhdDevice* d = asDhd(dev);
  if (!d) return;
  d->dhd.enableForce(DHD_OFF, d->id);
  d->dhd.close(d->id);
  ::dlclose(d->lib);
  delete d;
}

DmDevice* dhdOpenDevice(const DmDeviceParam* params, size_t count, char* error, size_t errorSize) {
  dm::driver::ParamReader p(params, count, error, errorSize);
  p.onlyKnown({"library", "index", "max_force", "max_torque", "workspace", "servo_rate"});
  const char* library = p.find("library");
  const double index = p.number("index", -1.0, 0.0, 15.0);
  const double maxForce = p.number("max_force", 0.0, 1e-3, 1e3);
  const double maxTorque = p.number("max_torque", 0.0, 0.0, 1e2);
  const bool forceGiven = p.find("max_force") != nullptr, torqueGiven = p.find("max_torque") != nullptr;
  const bool workspaceGiven = p.find("workspace") != nullptr;
  const std::array<double, 3> half = p.triple("workspace", {0, 0, 0});
  const double servoRate = p.number("servo_rate", 1000.0, 1.0, 1e5);
  if (index >= 0.0 && index != std::floor(index))
    p.failf("parameter 'index': %g is not a whole number", index);
  if (workspaceGiven && p.ok() && !(half[0] > 0 && half[1] > 0 && half[2] > 0))
    p.failf("parameter 'workspace': half extents must be > 0");
  if (!p.ok()) return nullptr;
  std::string why;
  void* lib = dm::driver::openVendorLibrary(dm::driver::kForceDimensionDhd, library, why);
  if (!lib) {
    p.failf("%s", why.c_str());
    return nullptr;
  }
  DhdDevice* d = new (std::nothrow) DhdDevice;
  if (!d) {
    ::dlclose(lib);
    p.failf("out of memory");
    return nullptr;
  }
  d->lib = lib;
  d->index = static_cast<int>(index);
  if (const char* missing = d->dhd.load(lib)) {
    p.failf("the DHD library has no %s: not a Force Dimension DHD library (%s)", missing,
            library ? library : "libdhd.so");
    ::dlclose(lib);
    delete d;
    return nullptr;
  }
  if (const std::string failed = startDevice(*d); !failed.empty()) {
    p.failf("%s", failed.c_str());
    ::dlclose(lib);
    delete d;
    return nullptr;
  }
  const DhdApi& dhd = d->dhd;
  const int type = dhd.getSystemType(d->id);
  const Model* model = modelOf(type);
  DmHapticInfo& info = d->info;
  dm::driver::copyField(info.identity.driver, "force-dimension-dhd");
  dm::driver::copyField(info.identity.vendor, type == 60 ? "Novint" : "Force Dimension");
  const char* name = dhd.getSystemName ? dhd.getSystemName(d->id) : nullptr;
  dm::driver::copyField(info.identity.model, name ? name : model ? model->name : "DHD device");
  unsigned short serial = 0;
  if (dhd.getSerialNumber(&serial, d->id) >= 0)
    std::snprintf(info.identity.serial, sizeof info.identity.serial, "%u", serial);
  info.max_force = forceGiven ? maxForce : model ? model->force : 0.0;
  double torque = torqueGiven ? maxTorque : dhd.getMaxTorque ? dhd.getMaxTorque(d->id) : 0.0;
  d->torque = torque > 0.0;
  info.max_torque = d->torque ? torque : 0.0;
  info.capabilities =
      DM_HAPTIC_CAP_POSITION | DM_HAPTIC_CAP_ORIENTATION | DM_HAPTIC_CAP_VELOCITY | DM_HAPTIC_CAP_FORCE;
  if (d->torque) info.capabilities |= DM_HAPTIC_CAP_TORQUE;
  info.button_count = DHD_MAX_BUTTONS;
  for (int i = 0; i < 3; ++i) {
    const double h = workspaceGiven ? half[i] : model ? model->half[i] : 0.0;
    info.workspace_min[i] = -h;
    info.workspace_max[i] = h;
  }
  info.max_stiffness = 0.0;  // DHD gives none: the host's own limits apply
  info.max_damping = 0.0;
  info.servo_rate_hz = servoRate;
  if (!(info.max_force > 0.0) || !(info.workspace_max[0] > 0.0)) {
    p.failf(
        "device type %d (%s) is not one the driver knows: give parameters 'max_force' and 'workspace' "
        "from its datasheet",
        type, info.identity.model);
    dhdCloseDevice(reinterpret_cast<DmDevice*>(d));
    return nullptr;
  }
  return reinterpret_cast<DmDevice*>(d);
}

int dhdInfo(DmDevice* dev, DmHapticInfo* info) {
  *info = asDhd(dev)->info;
  return DM_DEVICE_OK;
}

int dhdRead(DmDevice* dev, int64_t now, DmHapticState* s) {
  DhdDevice* d = asDhd(dev);
  const DhdApi& dhd = d->dhd;
  int status[kStatusSlots] = {};
  if (dhd.getStatus(status, d->id) < 0) return statusOf(*d);
  d->inReset = status[DHD_STATUS_RESET] != 0;
  if (d->inReset) return DM_DEVICE_ERROR_IO;  // waiting for its calibration
  double px = 0, py = 0, pz = 0, r[3][3] = {};
  if (dhd.getPositionAndOrientationFrame(&px, &py, &pz, r, d->id) < 0) return statusOf(*d);
  double v[3] = {}, w[3] = {};
  if (dhd.getLinearVelocity(&v[0], &v[1], &v[2], d->id) < 0) return statusOf(*d);
  if (dhd.getAngularVelocityRad && dhd.getAngularVelocityRad(&w[0], &w[1], &w[2], d->id) < 0)
    return statusOf(*d);
  std::uint32_t buttons = 0;
  for (int b = 0; b < DHD_MAX_BUTTONS; ++b) {
    const int pressed = dhd.getButton(b, d->id);
    if (pressed < 0) return statusOf(*d);
    if (pressed == DHD_ON) buttons |= 1u << b;
  }
  *s = DmHapticState{};
  s->time_ns = now;
  s->position[0] = px;
  s->position[1] = py;
  s->position[2] = pz;
  const double rows[9] = {r[0][0], r[0][1], r[0][2], r[1][0], r[1][1], r[1][2], r[2][0], r[2][1], r[2][2]};
  dm::driver::quaternionOfRotation(rows, s->orientation);
  for (int i = 0; i < 3; ++i) {
    s->linear_velocity[i] = v[i];
    s->angular_velocity[i] = w[i];
  }
  s->buttons = buttons;
  return DM_DEVICE_OK;
}

int dhdWrite(DmDevice* dev, int64_t, const double force[3], const double torque[3]) {
  DhdDevice* d = asDhd(dev);
  const DhdApi& dhd = d->dhd;
  static constexpr double kZero[3] = {0, 0, 0};
  if (d->inReset) force = torque = kZero;
  const int r =
      d->torque ? dhd.setForceAndTorque(force[0], force[1], force[2], torque[0], torque[1], torque[2], d->id)
                : dhd.setForce(force[0], force[1], force[2], d->id);
  if (r == DHD_NO_ERROR || r == DHD_TIMEGUARD) return DM_DEVICE_OK;
  return statusOf(*d);
}

// Not real-time: the host calls it every reconnect interval while lost.
int dhdReconnect(DmDevice* dev, int64_t) {
  DhdDevice* d = asDhd(dev);
  d->dhd.close(d->id);
  return startDevice(*d).empty() ? DM_DEVICE_OK : DM_DEVICE_ERROR_LOST;
}

const DmHapticDeviceVTable kDhd = {dhdOpenDevice, dhdCloseDevice, dhdInfo, dhdRead, dhdWrite, dhdReconnect};

int dhdPluginInit(const DmHostApi* host) {
  return host->register_factory(host->ctx, DM_HAPTIC_DEVICE_KIND, "force-dimension-dhd",
                                DM_HAPTIC_DEVICE_KIND_ABI_VERSION, &kDhd);
}

const DmPluginInfo kDhdInfo = {DM_PLUGIN_ABI_VERSION, "force-dimension-dhd", "1.0", dhdPluginInit, nullptr};

}  // namespace

#if defined(DM_DRIVER_PLUGIN)
DM_PLUGIN_ENTRY { return &kDhdInfo; }
#else
extern "C" const DmPluginInfo* dm_builtin_entry_force_dimension_dhd(void) { return &kDhdInfo; }
#endif
