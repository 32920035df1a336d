// A stand-in for the Force Dimension DHD library (libdhd.so) for the tests
// of the force-dimension-dhd driver: the calls that driver makes, as the
// DHD API's header and reference document them, over simulated devices (an
// omega.6 by default; the test picks the system type) whose pose, buttons,
// RESET mode and connection the test sets through the dmDhdStandIn* calls.
//
// What it keeps from the documentation: calls return 0 (DHD_NO_ERROR) or
// −1 with the error in dhdErrorGetLast(); dhdOpen opens the first device
// and dhdOpenID the given one, returning its ID; with nothing connected
// they fail with DHD_ERROR_NO_DEVICE_FOUND, and every call on a device
// unplugged mid-run with DHD_ERROR_COM; forces reach the device only after
// dhdEnableForce(DHD_ON); dhdGetStatus fills the status array
// (DHD_STATUS_RESET set while the device waits for its calibration);
// dhdGetButton says DHD_ON or DHD_OFF; dhdSetForce returns DHD_TIMEGUARD
// when called within the device's minimum period (here: never).
#include <algorithm>
#include <cstring>
#include <mutex>

namespace {

constexpr int kNoError = 0, kErrorCom = 2, kNoDeviceFound = 5, kInvalidIndex = 15;

struct StandIn {
  std::mutex m;
  int lastError = kNoError;
  int type = 34;  // omega.6
  int devices = 1;
  bool plugged = true, reset = false, open = false, forceEnabled = false;
  double position[3] = {}, frame[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  double velocity[3] = {}, angular[3] = {};
  int buttons = 0;
  double force[3] = {}, torque[3] = {};
};
StandIn& S() {
  static StandIn s;
  return s;
}
int fail(StandIn& s, int e) {
  s.lastError = e;
  return -1;
}
// The device is there and open.
bool ready(StandIn& s) {
  if (!s.plugged) return fail(s, kErrorCom), false;
  if (!s.open) return fail(s, kNoDeviceFound), false;
  s.lastError = kNoError;
  return true;
}

}  // namespace

#define API extern "C" __attribute__((visibility("default")))

API int dhdGetDeviceCount() {
  StandIn& s = S();
  std::lock_guard<std::mutex> lock(s.m);
  return s.plugged ? s.devices : 0;
}
API int dhdOpenID(char id) {
  StandIn& s = S();
  std::lock_guard<std::mutex> lock(s.m);
  if (!s.plugged || s.devices == 0) return fail(s, kNoDeviceFound);
  if (id < 0 || id >= s.devices) return fail(s, kInvalidIndex);
  s.open = true;
  s.lastError = kNoError;
  return id;
}
API int dhdOpen() { return dhdOpenID(0); }
API int dhdClose(char) {
  StandIn& s = S();
  std::lock_guard<std::mutex> lock(s.m);
  s.open = false;
  s.forceEnabled = false;
  return 0;
}
API int dhdGetSystemType(char) {
  StandIn& s = S();
  std::lock_guard<std::mutex> lock(s.m);
  return ready(s) ? s.type : -1;
}
API int dhdGetSerialNumber(unsigned short* sn, char) {
  StandIn& s = S();
  std::lock_guard<std::mutex> lock(s.m);
  if (!ready(s)) return -1;
  *sn = 4242;
  return 0;
}
API int dhdGetStatus(int* status, char) {
  StandIn& s = S();
  std::lock_guard<std::mutex> lock(s.m);
  if (!ready(s)) return -1;
  std::fill(status, status + 13, 0);  // DHD_MAX_STATUS of the 3.2 header
  status[0] = 1;                      // power
  status[1] = 1;                      // connected
  status[3] = s.reset ? 1 : 0;        // DHD_STATUS_RESET
  status[5] = s.forceEnabled ? 1 : 0;
  return 0;
}
API int dhdGetPositionAndOrientationFrame(double* px, double* py, double* pz, double m[3][3], char) {
  StandIn& s = S();
  std::lock_guard<std::mutex> lock(s.m);
  if (!ready(s)) return -1;
  *px = s.position[0];
  *py = s.position[1];
  *pz = s.position[2];
  std::memcpy(m, s.frame, sizeof s.frame);
  return 0;
}
API int dhdConfigLinearVelocity(int ms, int mode, char) {
  StandIn& s = S();
  std::lock_guard<std::mutex> lock(s.m);
  if (!ready(s)) return -1;
  return ms > 0 && (mode == 0 || mode == 1) ? 0 : fail(s, 1);
}
API int dhdGetLinearVelocity(double* vx, double* vy, double* vz, char) {
  StandIn& s = S();
  std::lock_guard<std::mutex> lock(s.m);
  if (!ready(s)) return -1;
  *vx = s.velocity[0];
  *vy = s.velocity[1];
  *vz = s.velocity[2];
  return 0;
}
API int dhdGetAngularVelocityRad(double* wx, double* wy, double* wz, char) {
  StandIn& s = S();
  std::lock_guard<std::mutex> lock(s.m);
  if (!ready(s)) return -1;
  *wx = s.angular[0];
  *wy = s.angular[1];
  *wz = s.angular[2];
  return 0;
}
API int dhdGetButton(int index, char) {
  StandIn& s = S();
  std::lock_guard<std::mutex> lock(s.m);
  if (!ready(s)) return -1;
  if (index < 0 || index >= 8) return fail(s, kInvalidIndex);
  return (s.buttons >> index) & 1;
}
API int dhdEnableForce(unsigned char on, char) {
  StandIn& s = S();
  std::lock_guard<std::mutex> lock(s.m);
  if (!ready(s)) return -1;
  s.forceEnabled = on != 0;
  if (!s.forceEnabled) std::fill(s.force, s.force + 3, 0.0);
  return 0;
}
API int dhdSetForceAndTorque(double fx, double fy, double fz, double tx, double ty, double tz, char) {
  StandIn& s = S();
  std::lock_guard<std::mutex> lock(s.m);
  if (!ready(s)) return -1;
  if (!s.forceEnabled) return 0;  // the device ignores it
  s.force[0] = fx, s.force[1] = fy, s.force[2] = fz;
  s.torque[0] = tx, s.torque[1] = ty, s.torque[2] = tz;
  return 0;
}
API int dhdSetForce(double fx, double fy, double fz, char id) {
  return dhdSetForceAndTorque(fx, fy, fz, 0, 0, 0, id);
}
API int dhdErrorGetLast() {
  StandIn& s = S();
  std::lock_guard<std::mutex> lock(s.m);
  return s.lastError;
}
API const char* dhdErrorGetStr(int e) {
  switch (e) {
    case kNoError:
      return "no error";
    case kErrorCom:
      return "communication error between the host and the haptic device";
    case kNoDeviceFound:
      return "no compatible Force Dimension device found";
    default:
      return "stand-in error";
  }
}
API const char* dhdGetSystemName(char) {
  StandIn& s = S();
  std::lock_guard<std::mutex> lock(s.m);
  return s.type == 34 ? "omega.6" : s.type == 64 ? "delta.6" : "custom";
}

// --- the test's hand on the device ----------------------------------------
API void dmDhdStandInSetType(int type, int devices) {
  StandIn& s = S();
  std::lock_guard<std::mutex> lock(s.m);
  s.type = type;
  s.devices = devices;
}
API void dmDhdStandInSetPose(const double p[3], const double r[9]) {
  StandIn& s = S();
  std::lock_guard<std::mutex> lock(s.m);
  std::copy(p, p + 3, s.position);
  for (int i = 0; i < 9; ++i) s.frame[i / 3][i % 3] = r[i];
}
API void dmDhdStandInSetVelocity(const double v[3], const double w[3]) {
  StandIn& s = S();
  std::lock_guard<std::mutex> lock(s.m);
  std::copy(v, v + 3, s.velocity);
  std::copy(w, w + 3, s.angular);
}
API void dmDhdStandInSetButtons(int b) {
  StandIn& s = S();
  std::lock_guard<std::mutex> lock(s.m);
  s.buttons = b;
}
API void dmDhdStandInSetPlugged(int p) {
  StandIn& s = S();
  std::lock_guard<std::mutex> lock(s.m);
  s.plugged = p != 0;
  if (!s.plugged) s.open = false;  // it must be opened again once back
}
API void dmDhdStandInSetReset(int r) {
  StandIn& s = S();
  std::lock_guard<std::mutex> lock(s.m);
  s.reset = r != 0;
}
API void dmDhdStandInApplied(double f[3], double t[3]) {
  StandIn& s = S();
  std::lock_guard<std::mutex> lock(s.m);
  std::copy(s.force, s.force + 3, f);
  std::copy(s.torque, s.torque + 3, t);
}
