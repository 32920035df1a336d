// openhaptics-hd — 3D Systems Touch, Touch X and Phantom devices through
// the OpenHaptics HD API (kind "haptic-device"). The HD library is loaded
// at run time (dlopen): DMPlatform builds and runs without it, and opening
// the driver where it is not installed fails saying what to install
// (vendor_library.hpp; `dmtool devices` lists the driver as unavailable).
//
// Parameters:
//   library      path of the HD library (default: libHD.so, libHD.so.3.4,
//                libHD.so.3, /usr/lib/libHD.so, in that order)
//   device       the device's configuration name as set up with Touch
//                Setup (default: the default device)
//   calibration  auto | off. auto (default): whenever the HD API says the
//                calibration needs an update, the driver updates it with the
//                device's own style (encoder reset, inkwell, auto; in that
//                order of preference, as OpenHaptics' own examples pick);
//                off: it never does (a calibration tool owns it)
//
// How it runs: open() initialises the device, enables force output and
// schedules an asynchronous callback on the HD servo scheduler (started
// with the first device of a library and stopped with its last; a device
// opened or closed beside others stops and restarts it, as the HD API
// wants devices initialised before the scheduler starts). Every scheduler
// tick the callback checks the calibration, reads the device in an HD frame
// (hdBeginFrame/hdEndFrame) and sets the newest force the host wrote.
// Samples and forces cross between the scheduler's thread and the host's
// servo thread through triple buffers: read_state and write_output never
// block, allocate or call the HD library.
// Units: HD millimetres and mm/s become metres and m/s; the orientation is
// the rotation of HD_CURRENT_TRANSFORM (column-major 4×4); max stiffness and
// damping (N/mm, N·s/mm) become N/m and N·s/m; max_force is the nominal
// continuous force (the peak when the device gives no continuous one).
// Errors: a communication error or device fault (unplugged, powered off)
// ends the callback and read_state reports the device lost (DM_DEVICE_ERROR_LOST);
// reconnect() initialises it again. A force error (warm motors, exceeded
// force, impulse or velocity) is reported once, as an I/O error, by the
// next read_state. While the device is not calibrated read_state reports
// an I/O error (its position is not to be trusted) and no force is sent.
// Limits: the torque output of 6-DOF Phantoms is not driven (forces only);
// the HD API's four button bits are the buttons.
#include <dm/core/plugin_abi.h>
#include <dm/core/triple_buffer.hpp>
#include <dm/io/device_abi.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <mutex>
#include <new>
#include <string>
#include <vector>

#include "driver_params.hpp"
#include "rotation.hpp"
#include "vendor_library.hpp"

namespace {

// --- the HD API as its public headers declare it (hdDefines.h, hd.h,
// hdScheduler.h of OpenHaptics 3.x) -----------------------------------------
using HHD = unsigned int;
using HDenum = unsigned int;
using HDerror = unsigned int;
using HDint = int;
using HDdouble = double;
using HDushort = unsigned short;
using HDCallbackCode = unsigned int;
using HDSchedulerHandle = unsigned long;
using HDstring = const char*;
struct HDErrorInfo {
  HDerror errorCode;
  int internalErrorCode;
  HHD hHD;
};
using HDSchedulerCallback = HDCallbackCode (*)(void*);

constexpr HDerror HD_SUCCESS = 0x0000;
constexpr HDerror HD_DEVICE_FAULT = 0x0300, HD_COMM_ERROR = 0x0302, HD_COMM_CONFIG_ERROR = 0x0303;
constexpr HDenum HD_CURRENT_BUTTONS = 0x2000;
constexpr HDenum HD_CURRENT_VELOCITY = 0x2051, HD_CURRENT_TRANSFORM = 0x2052,
                 HD_CURRENT_ANGULAR_VELOCITY = 0x2053;
constexpr HDenum HD_DEVICE_MODEL_TYPE = 0x2501, HD_DEVICE_VENDOR = 0x2503, HD_DEVICE_SERIAL_NUMBER = 0x2504;
constexpr HDenum HD_USABLE_WORKSPACE_DIMENSIONS = 0x2551, HD_CALIBRATION_STYLE = 0x2555;
constexpr HDenum HD_UPDATE_RATE = 0x2600, HD_NOMINAL_MAX_STIFFNESS = 0x2602, HD_NOMINAL_MAX_FORCE = 0x2603;
constexpr HDenum HD_NOMINAL_MAX_CONTINUOUS_FORCE = 0x2604, HD_NOMINAL_MAX_DAMPING = 0x2609;
constexpr HDenum HD_CURRENT_FORCE = 0x2700;
constexpr HDenum HD_FORCE_OUTPUT = 0x4000;
constexpr HDenum HD_CALIBRATION_OK = 0x5000, HD_CALIBRATION_NEEDS_UPDATE = 0x5001;
constexpr HDenum HD_CALIBRATION_ENCODER_RESET = 1u << 0, HD_CALIBRATION_AUTO = 1u << 1,
                 HD_CALIBRATION_INKWELL = 1u << 2;
constexpr HDCallbackCode HD_CALLBACK_DONE = 0, HD_CALLBACK_CONTINUE = 1;
constexpr HHD HD_INVALID_HANDLE = 0xFFFFFFFFu;
constexpr HDushort HD_DEFAULT_SCHEDULER_PRIORITY = 0xFFFFu / 2;

// The calls the driver makes, resolved from the loaded library.
struct HdApi {
  HHD (*initDevice)(HDstring);
  void (*disableDevice)(HHD);
  void (*makeCurrentDevice)(HHD);
  void (*beginFrame)(HHD);
  void (*endFrame)(HHD);
  HDErrorInfo (*getError)();
  HDstring (*getErrorString)(HDerror);
  void (*enable)(HDenum);
  void (*getDoublev)(HDenum, HDdouble*);
  void (*getIntegerv)(HDenum, HDint*);
  HDstring (*getString)(HDenum);
  void (*setDoublev)(HDenum, const HDdouble*);
  HDenum (*checkCalibration)();
  void (*updateCalibration)(HDenum);
  void (*startScheduler)();
  void (*stopScheduler)();
  HDSchedulerHandle (*scheduleAsynchronous)(HDSchedulerCallback, void*, HDushort);
  void (*unschedule)(HDSchedulerHandle);

  // Resolves every call; on a missing one returns its name.
  const char* load(void* lib) {
    return dm::driver::resolveVendorCalls(lib, {{"hdInitDevice", initDevice},
                                                {"hdDisableDevice", disableDevice},
                                                {"hdMakeCurrentDevice", makeCurrentDevice},
                                                {"hdBeginFrame", beginFrame},
                                                {"hdEndFrame", endFrame},
                                                {"hdGetError", getError},
                                                {"hdGetErrorString", getErrorString},
                                                {"hdEnable", enable},
                                                {"hdGetDoublev", getDoublev},
                                                {"hdGetIntegerv", getIntegerv},
                                                {"hdGetString", getString},
                                                {"hdSetDoublev", setDoublev},
                                                {"hdCheckCalibration", checkCalibration},
                                                {"hdUpdateCalibration", updateCalibration},
                                                {"hdStartScheduler", startScheduler},
                                                {"hdStopScheduler", stopScheduler},
                                                {"hdScheduleAsynchronous", scheduleAsynchronous},
                                                {"hdUnschedule", unschedule}});
  }
};

const char* hdErrorName(HDerror e) {
  switch (e) {
    case 0x0100:
      return "HD_INVALID_ENUM";
    case 0x0101:
      return "HD_INVALID_VALUE";
    case 0x0102:
      return "HD_INVALID_OPERATION";
    case 0x0103:
      return "HD_INVALID_INPUT_TYPE";
    case 0x0104:
      return "HD_BAD_HANDLE";
    case 0x0200:
      return "HD_WARM_MOTORS";
    case 0x0201:
      return "HD_EXCEEDED_MAX_FORCE";
    case 0x0202:
      return "HD_EXCEEDED_MAX_FORCE_IMPULSE";
    case 0x0203:
      return "HD_EXCEEDED_MAX_VELOCITY";
    case 0x0204:
      return "HD_FORCE_ERROR";
    case 0x0300:
      return "HD_DEVICE_FAULT";
    case 0x0301:
      return "HD_DEVICE_ALREADY_INITIATED";
    case 0x0302:
      return "HD_COMM_ERROR";
    case 0x0303:
      return "HD_COMM_CONFIG_ERROR";
    case 0x0304:
      return "HD_TIMER_ERROR";
    case 0x0400:
      return "HD_ILLEGAL_BEGIN";
    case 0x0401:
      return "HD_ILLEGAL_END";
    case 0x0402:
      return "HD_FRAME_ERROR";
    case 0x0500:
      return "HD_INVALID_PRIORITY";
    case 0x0501:
      return "HD_SCHEDULER_FULL";
    case 0x0600:
      return "HD_INVALID_LICENSE";
    default:
      return "an HD error";
  }
}
bool isLoss(HDerror e) { return e == HD_DEVICE_FAULT || e == HD_COMM_ERROR || e == HD_COMM_CONFIG_ERROR; }

struct HdSample {
  double position[3] = {0, 0, 0};  // m
  double orientation[4] = {1, 0, 0, 0};
  double velocity[3] = {0, 0, 0};  // m/s
  double angular[3] = {0, 0, 0};   // rad/s
  std::uint32_t buttons = 0;
  bool calibrated = false;
};
struct HdForce {
  double f[3] = {0, 0, 0};
};

struct HdDevice {
  void* lib = nullptr;
  HdApi hd{};
  std::string name;  // empty: the default device
  bool autoCalibrate = true;
  HDenum calibrationStyle = 0;
  HHD handle = HD_INVALID_HANDLE;
  HDSchedulerHandle callback = 0;
  bool scheduled = false;
  DmHapticInfo info{};
  dm::TripleBuffer<HdSample> samples;  // scheduler thread → host
  dm::TripleBuffer<HdForce> forces;    // host → scheduler thread
  std::atomic<bool> lost{false};
  std::atomic<bool> callbackEnded{false};
  std::atomic<std::uint64_t> ticks{0}, faults{0};
  std::uint64_t faultsReported = 0;  // host thread
};

HdDevice* asHd(DmDevice* d) { return reinterpret_cast<HdDevice*>(d); }

// One HD scheduler tick (the scheduler's thread): calibration, one frame.
HDCallbackCode servoTick(void* data) {
  HdDevice* d = static_cast<HdDevice*>(data);
  const HdApi& hd = d->hd;
  HDenum calibration = hd.checkCalibration();
  if (calibration == HD_CALIBRATION_NEEDS_UPDATE && d->autoCalibrate && d->calibrationStyle != 0) {
    hd.updateCalibration(d->calibrationStyle);
    calibration = hd.checkCalibration();
  }
  hd.beginFrame(d->handle);
  HdSample& s = d->samples.writeBuffer();
  double m[16] = {};
  hd.getDoublev(HD_CURRENT_TRANSFORM, m);
  const double r[9] = {m[0], m[4], m[8], m[1], m[5], m[9], m[2], m[6], m[10]};  // column-major → row-major
  dm::driver::quaternionOfRotation(r, s.orientation);
  double v[3] = {}, w[3] = {};
  hd.getDoublev(HD_CURRENT_VELOCITY, v);
  hd.getDoublev(HD_CURRENT_ANGULAR_VELOCITY, w);
  HDint buttons = 0;
  hd.getIntegerv(HD_CURRENT_BUTTONS, &buttons);
  for (int i = 0; i < 3; ++i) {
    s.position[i] = 1e-3 * m[12 + i];
    s.velocity[i] = 1e-3 * v[i];
    s.angular[i] = w[i];
  }
  s.buttons = static_cast<std::uint32_t>(buttons) & 0xFu;
  s.calibrated = calibration == HD_CALIBRATION_OK;
  const HdForce& f = d->forces.read();
  const double zero[3] = {0, 0, 0};
  hd.setDoublev(HD_CURRENT_FORCE, s.calibrated ? f.f : zero);
  hd.endFrame(d->handle);
  bool lost = false;
  for (int i = 0; i < 16; ++i) {  // the error stack, bounded
    const HDErrorInfo e = hd.getError();
    if (e.errorCode == HD_SUCCESS) break;
    if (isLoss(e.errorCode))
      lost = true;
    else  // a force or frame error: reported once by read_state
      d->faults.fetch_add(1, std::memory_order_relaxed);
  }
  d->samples.publish();
  d->ticks.fetch_add(1, std::memory_order_release);
  if (lost) {
    d->lost.store(true, std::memory_order_release);
    d->callbackEnded.store(true, std::memory_order_release);
    return HD_CALLBACK_DONE;
  }
  return HD_CALLBACK_CONTINUE;
}

// The HD scheduler is one per library: how many of our devices run on it.
struct SchedulerUse {
  void* lib;
  int devices;
};
std::mutex& schedulerMutex() {
  static std::mutex m;
  return m;
}
std::vector<SchedulerUse>& schedulerUses() {
  static std::vector<SchedulerUse> uses;
  return uses;
}
int& devicesOn(void* lib) {
  for (SchedulerUse& u : schedulerUses())
    if (u.lib == lib) return u.devices;
  schedulerUses().push_back({lib, 0});
  return schedulerUses().back().devices;
}

// The HD errors pending, as one message ("" when none).
std::string drainErrors(const HdApi& hd) {
  std::string message;
  for (int i = 0; i < 16; ++i) {
    const HDErrorInfo e = hd.getError();
    if (e.errorCode == HD_SUCCESS) break;
    if (!message.empty()) continue;  // the most recent one names it
    char buf[256];
    const char* text = hd.getErrorString ? hd.getErrorString(e.errorCode) : nullptr;
    std::snprintf(buf, sizeof buf, "%s (0x%04x%s%s, device code %d)", hdErrorName(e.errorCode), e.errorCode,
                  text ? ": " : "", text ? text : "", e.internalErrorCode);
    message = buf;
  }
  return message;
}

// Initialises the device and puts its callback on the scheduler. Called
// with schedulerMutex held and this library's scheduler stopped.
std::string startDevice(HdDevice& d) {
  const HdApi& hd = d.hd;
  drainErrors(hd);
  d.handle = hd.initDevice(d.name.empty() ? nullptr : d.name.c_str());
  std::string e = drainErrors(hd);
  if (d.handle == HD_INVALID_HANDLE || !e.empty()) {
    if (d.handle != HD_INVALID_HANDLE) hd.disableDevice(d.handle);
    d.handle = HD_INVALID_HANDLE;
    return "hdInitDevice(" + (d.name.empty() ? std::string("default device") : "'" + d.name + "'") +
           ") failed: " + (e.empty() ? "an invalid handle" : e);
  }
  hd.makeCurrentDevice(d.handle);
  hd.enable(HD_FORCE_OUTPUT);
  d.lost.store(false, std::memory_order_release);
  d.callbackEnded.store(false, std::memory_order_release);
  d.ticks.store(0, std::memory_order_release);
  d.callback = hd.scheduleAsynchronous(servoTick, &d, HD_DEFAULT_SCHEDULER_PRIORITY);
  e = drainErrors(hd);
  if (!e.empty()) {
    hd.disableDevice(d.handle);
    d.handle = HD_INVALID_HANDLE;
    return "hdScheduleAsynchronous failed: " + e;
  }
  d.scheduled = true;
  return {};
}

// Takes the device's callback off the scheduler and releases the device.
// Called with schedulerMutex held and this library's scheduler stopped.
void stopDevice(HdDevice& d) {
  const HdApi& hd = d.hd;
  if (d.scheduled && !d.callbackEnded.load(std::memory_order_acquire)) hd.unschedule(d.callback);
  d.scheduled = false;
  if (d.handle != HD_INVALID_HANDLE) hd.disableDevice(d.handle);
  d.handle = HD_INVALID_HANDLE;
  drainErrors(hd);
}

void readInfo(HdDevice& d) {
  const HdApi& hd = d.hd;
  hd.makeCurrentDevice(d.handle);
  DmHapticInfo& info = d.info;
  info = DmHapticInfo{};
  dm::driver::copyField(info.identity.driver, "openhaptics-hd");
  const char* vendor = hd.getString(HD_DEVICE_VENDOR);
  const char* model = hd.getString(HD_DEVICE_MODEL_TYPE);
  const char* serial = hd.getString(HD_DEVICE_SERIAL_NUMBER);
  dm::driver::copyField(info.identity.vendor, vendor ? vendor : "3D Systems");
  dm::driver::copyField(info.identity.model, model ? model : "");
  dm::driver::copyField(info.identity.serial, serial ? serial : "");
  info.capabilities =
      DM_HAPTIC_CAP_POSITION | DM_HAPTIC_CAP_ORIENTATION | DM_HAPTIC_CAP_VELOCITY | DM_HAPTIC_CAP_FORCE;
  info.button_count = 4;
  double ws[6] = {};
  hd.getDoublev(HD_USABLE_WORKSPACE_DIMENSIONS, ws);
  for (int i = 0; i < 3; ++i) {
    info.workspace_min[i] = 1e-3 * ws[i];
    info.workspace_max[i] = 1e-3 * ws[3 + i];
  }
  double continuous = 0.0, peak = 0.0, stiffness = 0.0, damping = 0.0;
  hd.getDoublev(HD_NOMINAL_MAX_CONTINUOUS_FORCE, &continuous);
  hd.getDoublev(HD_NOMINAL_MAX_FORCE, &peak);
  hd.getDoublev(HD_NOMINAL_MAX_STIFFNESS, &stiffness);
  hd.getDoublev(HD_NOMINAL_MAX_DAMPING, &damping);
  info.max_force = continuous > 0.0 ? continuous : peak;
  info.max_stiffness = 1e3 * stiffness;
  info.max_damping = 1e3 * damping;
  HDint rate = 0, style = 0;
  hd.getIntegerv(HD_UPDATE_RATE, &rate);
  hd.getIntegerv(HD_CALIBRATION_STYLE, &style);
  info.servo_rate_hz = rate;
  const HDenum styles = static_cast<HDenum>(style);
  d.calibrationStyle = (styles & HD_CALIBRATION_ENCODER_RESET) ? HD_CALIBRATION_ENCODER_RESET
                       : (styles & HD_CALIBRATION_INKWELL)     ? HD_CALIBRATION_INKWELL
                       : (styles & HD_CALIBRATION_AUTO)        ? HD_CALIBRATION_AUTO
                                                               : 0;
}

void hdClose(DmDevice* dev) {
  HdDevice* d = asHd(dev);
  if (!d) return;
  {
    std::lock_guard<std::mutex> lock(schedulerMutex());
    int& devices = devicesOn(d->lib);
    d->hd.stopScheduler();
    stopDevice(*d);
    if (--devices > 0) d->hd.startScheduler();
  }
  ::dlclose(d->lib);
  delete d;
}

DmDevice* hdOpen(const DmDeviceParam* params, size_t count, char* error, size_t errorSize) {
  dm::driver::ParamReader p(params, count, error, errorSize);
  p.onlyKnown({"library", "device", "calibration"});
  const char* library = p.find("library");
  const char* device = p.find("device");
  const int calibration = p.choice("calibration", {"auto", "off"}, 0);
  if (!p.ok()) return nullptr;
  std::string why;
  void* lib = dm::driver::openVendorLibrary(dm::driver::kOpenHapticsHd, library, why);
  if (!lib) {
    p.failf("%s", why.c_str());
    return nullptr;
  }
  HdDevice* d = new (std::nothrow) HdDevice;
  if (!d) {
    ::dlclose(lib);
    p.failf("out of memory");
    return nullptr;
  }
  d->lib = lib;
  d->name = device ? device : "";
  d->autoCalibrate = calibration == 0;
  if (const char* missing = d->hd.load(lib)) {
    p.failf("the HD library has no %s: not an OpenHaptics HD library (%s)", missing,
            library ? library : "libHD.so");
    ::dlclose(lib);
    delete d;
    return nullptr;
  }
  std::string failed;
  {
    std::lock_guard<std::mutex> lock(schedulerMutex());
    int& devices = devicesOn(lib);
    if (devices > 0) d->hd.stopScheduler();
    failed = startDevice(*d);
    if (failed.empty()) {
      readInfo(*d);
      d->hd.startScheduler();
      failed = drainErrors(d->hd);
      if (failed.empty()) {
        ++devices;
      } else {
        failed = "hdStartScheduler failed: " + failed;
        d->hd.stopScheduler();
        stopDevice(*d);
        if (devices > 0) d->hd.startScheduler();
      }
    } else if (devices > 0) {
      d->hd.startScheduler();
    }
  }
  if (failed.empty() && !(d->info.max_force > 0.0)) {
    // Not a device the host can drive safely: say what the library reported.
    failed = "the device reports no maximum force";
    hdClose(reinterpret_cast<DmDevice*>(d));
    p.failf("%s", failed.c_str());
    return nullptr;
  }
  if (!failed.empty()) {
    p.failf("%s", failed.c_str());
    ::dlclose(lib);
    delete d;
    return nullptr;
  }
  return reinterpret_cast<DmDevice*>(d);
}

int hdInfo(DmDevice* dev, DmHapticInfo* info) {
  *info = asHd(dev)->info;
  return DM_DEVICE_OK;
}

int hdRead(DmDevice* dev, int64_t now, DmHapticState* s) {
  HdDevice* d = asHd(dev);
  if (d->lost.load(std::memory_order_acquire)) return DM_DEVICE_ERROR_LOST;
  if (d->ticks.load(std::memory_order_acquire) == 0) return DM_DEVICE_ERROR_IO;  // no frame yet
  const std::uint64_t faults = d->faults.load(std::memory_order_relaxed);
  const HdSample& sample = d->samples.read();
  if (faults != d->faultsReported) {
    d->faultsReported = faults;
    return DM_DEVICE_ERROR_IO;
  }
  if (!sample.calibrated) return DM_DEVICE_ERROR_IO;
  *s = DmHapticState{};
  s->time_ns = now;
  for (int i = 0; i < 3; ++i) {
    s->position[i] = sample.position[i];
    s->linear_velocity[i] = sample.velocity[i];
    s->angular_velocity[i] = sample.angular[i];
  }
  for (int i = 0; i < 4; ++i) s->orientation[i] = sample.orientation[i];
  s->buttons = sample.buttons;
  return DM_DEVICE_OK;
}

int hdWrite(DmDevice* dev, int64_t, const double force[3], const double*) {
  HdDevice* d = asHd(dev);
  if (d->lost.load(std::memory_order_acquire)) return DM_DEVICE_ERROR_LOST;
  HdForce& f = d->forces.writeBuffer();
  for (int i = 0; i < 3; ++i) f.f[i] = force[i];
  d->forces.publish();
  return DM_DEVICE_OK;
}

// Not real-time: the host calls it every reconnect interval while lost.
int hdReconnect(DmDevice* dev, int64_t) {
  HdDevice* d = asHd(dev);
  std::lock_guard<std::mutex> lock(schedulerMutex());
  const int devices = devicesOn(d->lib);  // this one still counts
  d->hd.stopScheduler();
  stopDevice(*d);
  const bool back = startDevice(*d).empty();
  if (back || devices > 1) d->hd.startScheduler();
  if (!back) {
    d->lost.store(true, std::memory_order_release);
    return DM_DEVICE_ERROR_LOST;
  }
  {
    HdForce& f = d->forces.writeBuffer();  // nothing old is sent to the device again
    f = HdForce{};
    d->forces.publish();
  }
  d->faultsReported = d->faults.load(std::memory_order_relaxed);
  return DM_DEVICE_OK;
}

const DmHapticDeviceVTable kOpenHaptics = {hdOpen, hdClose, hdInfo, hdRead, hdWrite, hdReconnect};

int hdPluginInit(const DmHostApi* host) {
  return host->register_factory(host->ctx, DM_HAPTIC_DEVICE_KIND, "openhaptics-hd",
                                DM_HAPTIC_DEVICE_KIND_ABI_VERSION, &kOpenHaptics);
}

const DmPluginInfo kOpenHapticsInfo = {DM_PLUGIN_ABI_VERSION, "openhaptics-hd", "1.0", hdPluginInit, nullptr};

}  // namespace

#if defined(DM_DRIVER_PLUGIN)
DM_PLUGIN_ENTRY { return &kOpenHapticsInfo; }
#else
extern "C" const DmPluginInfo* dm_builtin_entry_openhaptics_hd(void) { return &kOpenHapticsInfo; }
#endif
