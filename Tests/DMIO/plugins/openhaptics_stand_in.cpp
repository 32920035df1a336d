// A stand-in for the OpenHaptics HD library (libHD.so) for the tests of the
// openhaptics-hd driver: the calls that driver makes, as the HD API's
// reference documents them, over one simulated Touch device whose pose,
// buttons, calibration and connection the test sets through the
// dmHdStandIn* calls below.
//
// What it keeps from the documentation: hdInitDevice(NULL or "Default
// Device") gives a handle, another name HD_COMM_CONFIG_ERROR, a second init
// HD_DEVICE_ALREADY_INITIATED; errors stack up and hdGetError pops the most
// recent (HD_SUCCESS when none); state is read and forces set between
// hdBeginFrame and hdEndFrame (a force set outside a frame is
// HD_INVALID_OPERATION, a nested begin HD_ILLEGAL_BEGIN, an end without
// begin HD_ILLEGAL_END), and the force is applied at hdEndFrame when force
// output is enabled; the scheduler runs the asynchronous callbacks on a
// thread of its own at the update rate until they return HD_CALLBACK_DONE
// or are unscheduled; hdCheckCalibration says OK, NEEDS_UPDATE or
// NEEDS_MANUAL_INPUT, and hdUpdateCalibration with the device's style
// (inkwell, as a Touch's) brings NEEDS_UPDATE to OK. Unplugged, every frame
// raises HD_COMM_ERROR and init fails with it.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstring>
#include <mutex>
#include <thread>
#include <vector>

namespace {

using HHD = unsigned int;
using HDenum = unsigned int;
using HDerror = unsigned int;
struct HDErrorInfo {
  HDerror errorCode;
  int internalErrorCode;
  HHD hHD;
};
using Callback = unsigned int (*)(void*);

constexpr HDerror kSuccess = 0x0000, kInvalidEnum = 0x0100, kInvalidValue = 0x0101,
                  kInvalidOperation = 0x0102, kBadHandle = 0x0104, kAlreadyInitiated = 0x0301,
                  kCommError = 0x0302, kCommConfigError = 0x0303, kIllegalBegin = 0x0400,
                  kIllegalEnd = 0x0401;
constexpr HDenum kOk = 0x5000, kNeedsUpdate = 0x5001;
constexpr HDenum kInkwell = 1u << 2;

struct Task {
  unsigned long id;
  Callback cb;
  void* data;
};

struct StandIn {
  std::mutex m;  // everything below but the scheduler's thread and counters
  std::vector<HDErrorInfo> errors;
  bool initialised = false, plugged = true, forceOutput = false, inFrame = false;
  HDenum calibration = kOk;
  double transform[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};  // column-major, mm
  double velocity[3] = {}, angular[3] = {};
  int buttons = 0;
  double pendingForce[3] = {}, appliedForce[3] = {};
  std::vector<HDerror> raise;  // raised at the next frame's end
  // scheduler
  std::mutex tasksMutex;  // held while callbacks run: unschedule waits for the tick
  std::vector<Task> tasks;
  unsigned long nextTask = 1;
  std::thread thread;
  std::atomic<bool> running{false};
  std::atomic<unsigned long> frames{0};
  int rate = 1000;
};

StandIn& S() {
  static StandIn s;
  return s;
}
void push(StandIn& s, HDerror e, int internal = 0) { s.errors.push_back({e, internal, 0}); }

}  // namespace

extern "C" {

// --- the HD API ---------------------------------------------------------------
__attribute__((visibility("default"))) HHD hdInitDevice(const char* name) {
  StandIn& s = S();
  std::lock_guard<std::mutex> lock(s.m);
  if (name && std::strcmp(name, "Default Device") != 0) {
    push(s, kCommConfigError, -1);
    return 0xFFFFFFFFu;
  }
  if (!s.plugged) {
    push(s, kCommError, -2);
    return 0xFFFFFFFFu;
  }
  if (s.initialised) {
    push(s, kAlreadyInitiated);
    return 0xFFFFFFFFu;
  }
  s.initialised = true;
  return 1;
}
__attribute__((visibility("default"))) void hdDisableDevice(HHD h) {
  StandIn& s = S();
  std::lock_guard<std::mutex> lock(s.m);
  if (h != 1 || !s.initialised) return push(s, kBadHandle);
  s.initialised = false;
  s.forceOutput = false;
}
__attribute__((visibility("default"))) void hdMakeCurrentDevice(HHD h) {
  StandIn& s = S();
  std::lock_guard<std::mutex> lock(s.m);
  if (h != 1 || !s.initialised) push(s, kBadHandle);
}
__attribute__((visibility("default"))) HDErrorInfo hdGetError() {
  StandIn& s = S();
  std::lock_guard<std::mutex> lock(s.m);
  if (s.errors.empty()) return {kSuccess, 0, 0};
  const HDErrorInfo e = s.errors.back();
  s.errors.pop_back();
  return e;
}
__attribute__((visibility("default"))) const char* hdGetErrorString(HDerror e) {
  switch (e) {
    case kCommError:
      return "Communication error";
    case kCommConfigError:
      return "Communication configuration error";
    default:
      return "stand-in error";
  }
}
__attribute__((visibility("default"))) void hdEnable(HDenum cap) {
  StandIn& s = S();
  std::lock_guard<std::mutex> lock(s.m);
  if (cap == 0x4000)
    s.forceOutput = true;
  else
    push(s, kInvalidEnum);
}
__attribute__((visibility("default"))) void hdBeginFrame(HHD h) {
  StandIn& s = S();
  std::lock_guard<std::mutex> lock(s.m);
  if (h != 1 || !s.initialised) return push(s, kBadHandle);
  if (s.inFrame) return push(s, kIllegalBegin);
  s.inFrame = true;
  if (!s.plugged) push(s, kCommError, -2);
}
__attribute__((visibility("default"))) void hdEndFrame(HHD h) {
  StandIn& s = S();
  std::lock_guard<std::mutex> lock(s.m);
  if (h != 1 || !s.inFrame) return push(s, kIllegalEnd);
  s.inFrame = false;
  if (s.plugged && s.forceOutput) std::copy(s.pendingForce, s.pendingForce + 3, s.appliedForce);
  for (HDerror e : s.raise) push(s, e);
  s.raise.clear();
  s.frames.fetch_add(1);
}
__attribute__((visibility("default"))) void hdGetDoublev(HDenum p, double* v) {
  StandIn& s = S();
  std::lock_guard<std::mutex> lock(s.m);
  const double workspace[6] = {-80, -60, -35, 80, 60, 35};  // a Touch's usable box, mm
  switch (p) {
    case 0x2050:
      std::copy(s.transform + 12, s.transform + 15, v);
      break;  // HD_CURRENT_POSITION
    case 0x2051:
      std::copy(s.velocity, s.velocity + 3, v);
      break;
    case 0x2052:
      std::copy(s.transform, s.transform + 16, v);
      break;
    case 0x2053:
      std::copy(s.angular, s.angular + 3, v);
      break;
    case 0x2551:
      std::copy(workspace, workspace + 6, v);
      break;
    case 0x2602:
      v[0] = 1.26;
      break;  // N/mm
    case 0x2603:
      v[0] = 3.3;
      break;  // N
    case 0x2604:
      v[0] = 0.88;
      break;  // N
    case 0x2609:
      v[0] = 0.005;
      break;  // N·s/mm
    case 0x2700:
      std::copy(s.appliedForce, s.appliedForce + 3, v);
      break;
    default:
      push(s, kInvalidEnum);
  }
}
__attribute__((visibility("default"))) void hdGetIntegerv(HDenum p, int* v) {
  StandIn& s = S();
  std::lock_guard<std::mutex> lock(s.m);
  switch (p) {
    case 0x2000:
      v[0] = s.buttons;
      break;
    case 0x2555:
      v[0] = static_cast<int>(kInkwell);
      break;
    case 0x2600:
      v[0] = s.rate;
      break;
    default:
      push(s, kInvalidEnum);
  }
}
__attribute__((visibility("default"))) const char* hdGetString(HDenum p) {
  switch (p) {
    case 0x2501:
      return "Touch";
    case 0x2503:
      return "3D Systems (stand-in)";
    case 0x2504:
      return "stand-in-0001";
    default: {
      StandIn& s = S();
      std::lock_guard<std::mutex> lock(s.m);
      push(s, kInvalidEnum);
      return nullptr;
    }
  }
}
__attribute__((visibility("default"))) void hdSetDoublev(HDenum p, const double* v) {
  StandIn& s = S();
  std::lock_guard<std::mutex> lock(s.m);
  if (p != 0x2700) return push(s, kInvalidEnum);
  if (!s.inFrame) return push(s, kInvalidOperation);
  std::copy(v, v + 3, s.pendingForce);
}
__attribute__((visibility("default"))) HDenum hdCheckCalibration() {
  StandIn& s = S();
  std::lock_guard<std::mutex> lock(s.m);
  return s.calibration;
}
__attribute__((visibility("default"))) void hdUpdateCalibration(HDenum style) {
  StandIn& s = S();
  std::lock_guard<std::mutex> lock(s.m);
  if (style != kInkwell) return push(s, kInvalidValue);
  if (s.calibration == kNeedsUpdate) s.calibration = kOk;
}
__attribute__((visibility("default"))) unsigned long hdScheduleAsynchronous(Callback cb, void* data,
                                                                            unsigned short) {
  StandIn& s = S();
  std::lock_guard<std::mutex> lock(s.tasksMutex);
  s.tasks.push_back({s.nextTask, cb, data});
  return s.nextTask++;
}
__attribute__((visibility("default"))) void hdUnschedule(unsigned long id) {
  StandIn& s = S();
  std::lock_guard<std::mutex> lock(s.tasksMutex);
  const auto it = std::find_if(s.tasks.begin(), s.tasks.end(), [&](const Task& t) { return t.id == id; });
  if (it == s.tasks.end()) {
    std::lock_guard<std::mutex> errors(s.m);
    return push(s, kInvalidValue);
  }
  s.tasks.erase(it);
}
__attribute__((visibility("default"))) void hdStartScheduler() {
  StandIn& s = S();
  if (s.running.exchange(true)) return;
  s.thread = std::thread([&s] {
    auto next = std::chrono::steady_clock::now();
    while (s.running.load()) {
      {
        std::lock_guard<std::mutex> lock(s.tasksMutex);
        for (std::size_t i = 0; i < s.tasks.size();) {
          if (s.tasks[i].cb(s.tasks[i].data) == 0)  // HD_CALLBACK_DONE
            s.tasks.erase(s.tasks.begin() + static_cast<std::ptrdiff_t>(i));
          else
            ++i;
        }
      }
      next += std::chrono::microseconds(1000000 / s.rate);
      std::this_thread::sleep_until(next);
    }
  });
}
__attribute__((visibility("default"))) void hdStopScheduler() {
  StandIn& s = S();
  if (!s.running.exchange(false)) return;
  s.thread.join();
}

// --- the test's hand on the device ----------------------------------------
// Position in mm, rotation row-major 3×3.
__attribute__((visibility("default"))) void dmHdStandInSetPose(const double p[3], const double r[9]) {
  StandIn& s = S();
  std::lock_guard<std::mutex> lock(s.m);
  for (int row = 0; row < 3; ++row)
    for (int col = 0; col < 3; ++col) s.transform[4 * col + row] = r[3 * row + col];
  std::copy(p, p + 3, s.transform + 12);
}
__attribute__((visibility("default"))) void dmHdStandInSetVelocity(const double v[3], const double w[3]) {
  StandIn& s = S();
  std::lock_guard<std::mutex> lock(s.m);
  std::copy(v, v + 3, s.velocity);
  std::copy(w, w + 3, s.angular);
}
__attribute__((visibility("default"))) void dmHdStandInSetButtons(int buttons) {
  StandIn& s = S();
  std::lock_guard<std::mutex> lock(s.m);
  s.buttons = buttons;
}
__attribute__((visibility("default"))) void dmHdStandInSetPlugged(int plugged) {
  StandIn& s = S();
  std::lock_guard<std::mutex> lock(s.m);
  s.plugged = plugged != 0;
}
__attribute__((visibility("default"))) void dmHdStandInSetCalibration(HDenum state) {
  StandIn& s = S();
  std::lock_guard<std::mutex> lock(s.m);
  s.calibration = state;
}
__attribute__((visibility("default"))) void dmHdStandInRaise(HDerror e) {
  StandIn& s = S();
  std::lock_guard<std::mutex> lock(s.m);
  s.raise.push_back(e);
}
__attribute__((visibility("default"))) void dmHdStandInAppliedForce(double f[3]) {
  StandIn& s = S();
  std::lock_guard<std::mutex> lock(s.m);
  std::copy(s.appliedForce, s.appliedForce + 3, f);
}
__attribute__((visibility("default"))) unsigned long dmHdStandInFrames() { return S().frames.load(); }
__attribute__((visibility("default"))) int dmHdStandInInitialised() {
  StandIn& s = S();
  std::lock_guard<std::mutex> lock(s.m);
  return s.initialised ? 1 : 0;
}
}
