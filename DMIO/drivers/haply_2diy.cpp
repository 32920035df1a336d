// haply-2diy — the Haply 2DIY (the two-degree-of-freedom pantograph
// "Haplet") on a Haply board over USB serial (kind "haptic-device"),
// speaking the board's open protocol as Haply's hAPI 2 defines it (the Java
// hAPI: Board.java, Device.java, Pantograph.java; boards with the Haply M3
// firmware 1.5+, M0 0.3+ or the modular kit firmware 0.4+). The line is the
// serial-posix driver's (serial_posix_core.hpp), so the device needs no
// vendor library.
//
// The protocol (host → board: a type byte, a device id byte, bytes, then
// IEEE-754 float32 values, little-endian):
//   reset   0, 0
//   setup   1, id, [actuator port mask, a direction (0 CW, 1 CCW) per
//           actuator in port order], [encoder port mask, a direction per
//           encoder], [analog sensor count, their pins (54 + n for An),
//           ascending], [PWM pin count, pins], then per encoder in port order
//           its offset (degrees at power-up) and resolution (counts per turn).
//           A port mask has bit p − 1 set for port p.
//   update  2, id, a byte per PWM pin, a torque per actuator in port order.
//           The board answers: id, a float per analog sensor (pin order),
//           then the angle in degrees of each encoder (port order).
// One update is in flight at a time: write_output sends the newest torques
// when the board has answered the last update, read_state takes the answer.
//
// Kinematics (hAPI's Pantograph): motor 1 at the origin, motor 2 at (d, 0),
// arms of length l, forearms of length L meeting at the handle; the handle
// is the forearms' intersection above the elbows. Position = (x, y, 0) in
// metres, the pantograph's plane being the device frame's z = 0 plane.
// Torque = s · Jᵀ f with J = ∂(x, y)/∂(θ1, θ2) and s = 0.1 / l: the numbers
// Haply's hAPI sends for the same force (its Jacobian is J / l, its gain
// 0.1), so the device feels as it does under Haply's own API. The force's z
// component cannot be rendered by a planar device and is dropped. Velocity
// is the position's difference over the last 16 answers.
//
// Calibration: the 2DIY's encoders have no index, so they count from the
// pose the arms were in at power-up, which the offsets describe (hAPI's:
// arm 1 at 180°, arm 2 at 0°, both level and pointing out). Angles that are
// no pose of the linkage — the handle behind the motors' axis (y ≤ 0) or
// the elbows crossed — mean the offsets, directions or ports do not match
// the device or it was powered with its arms elsewhere: those samples are
// refused (an I/O error) and no torque is sent until a sample is a pose.
//
// Parameters:
//   path              the board's serial device, e.g. /dev/ttyACM0 (required)
//   baud              line rate (115200; a USB board ignores it)
//   device_id         0 .. 255, echoed by the board (3)
//   max_force         N, the force the host may send (required: Haply
//                     publishes no continuous force for the 2DIY)
//   ports             the ports of motor+encoder 1 and 2 ("1,2")
//   directions        cw or ccw for arm 1 and 2, encoder and motor ("cw,cw")
//   offsets           degrees of arm 1 and 2 at power-up ("180,0")
//   resolution        encoder counts per turn (13824)
//   links             l, L, d in metres ("0.05,0.07,0.02")
//   button_pin        analog pin read as the button, A0 .. A11 (none)
//   button_threshold  the pin's value from which it is pressed (512)
//   servo_rate        Hz at which the host should servo it (1000)
//   timeout           s to wait for the board's first answer at open (1)
// Errors: the line lost (unplugged) → DM_DEVICE_ERROR_LOST, and reconnect
// reopens it and sends reset and setup again; no answer for 20 ms → the
// update is sent again, for 1 s → lost; an answer of the wrong length or
// id → an I/O error (the line is drained and the next update resyncs).
// Limits: two degrees of freedom (no z, no orientation); the board's PWM
// pins are not driven.
#include <dm/core/plugin_abi.h>
#include <dm/io/device_abi.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <new>
#include <string>

#include "driver_params.hpp"
#include "haply_protocol.hpp"
#include "serial_posix_core.hpp"

namespace {

namespace serial = dm::driver::serial_posix;
using dm::driver::haply::HaplyLinkage;
using dm::driver::haply::HaplyPose;
using dm::driver::haply::haplyPoseOf;
using dm::driver::haply::putFloatLE;

constexpr std::uint8_t kHaplyReset = 0, kHaplySetup = 1, kHaplyUpdate = 2;
constexpr int kHaplyFirstAnalogPin = 54;  // A0 as the board numbers it
constexpr std::int64_t kHaplyResendNs = 20'000'000, kHaplyLostNs = 1'000'000'000;
constexpr std::int64_t kHaplyStaleNs = 50'000'000;  // an answer older than this is no sample
constexpr int kHaplyVelocityWindow = 16;
constexpr double kHaplyTorqueGain = 0.1;  // hAPI Pantograph's gain

struct Haply2Diy {
  DmDevice* line = nullptr;  // the serial-posix line
  DmHapticInfo info{};
  std::uint8_t id = 3;
  int port[2] = {1, 2};  // arm k's port
  int dir[2] = {0, 0};   // 0 CW, 1 CCW
  std::array<double, 2> offset{180, 0};
  double resolution = 13824;
  HaplyLinkage link;
  int buttonPin = -1;  // the board's pin number, -1: none
  double buttonThreshold = 512;

  // Servo-thread state.
  std::uint8_t rx[64] = {};
  std::size_t rxCount = 0;
  bool inFlight = false;
  std::int64_t sentNs = 0;       // when the update in flight was sent
  std::int64_t lastHeardNs = 0;  // the last answer (or open, reconnect)
  HaplyPose pose;
  bool button = false;
  std::array<double, kHaplyVelocityWindow> histX{}, histY{};
  std::array<std::int64_t, kHaplyVelocityWindow> histT{};
  int histCount = 0, histNext = 0;
  double vx = 0, vy = 0;

  std::size_t answerSize() const { return 1 + 4 * ((buttonPin >= 0 ? 1 : 0) + 2); }
  // Port order: which arm is at the lower port.
  int firstArm() const { return port[0] < port[1] ? 0 : 1; }
};

Haply2Diy* asHaply(DmDevice* d) { return reinterpret_cast<Haply2Diy*>(d); }

// Writes all of `n` bytes, waiting up to timeoutMs; a device status.
int haplyWriteAll(Haply2Diy& d, const std::uint8_t* data, std::size_t n, int timeoutMs) {
  std::size_t sent = 0;
  const int rc = serial::kSerialPosix.write(d.line, data, n, timeoutMs, &sent);
  if (rc != DM_DEVICE_OK) return rc;
  return sent == n ? DM_DEVICE_OK : DM_DEVICE_ERROR_IO;
}

// Drops what the line holds until it has been quiet for 20 ms (at most
// 0.5 s): answers to a previous session's updates, still in the tty's
// buffer or on their way, would be taken for ours. Not real-time.
void haplyDrain(Haply2Diy& d) {
  const std::int64_t deadline = serial::monotonicMs() + 500;
  std::uint8_t sink[64];
  std::size_t got = 1;
  while (got > 0 && serial::monotonicMs() < deadline)
    if (serial::kSerialPosix.read(d.line, sink, sizeof sink, 20, &got) != DM_DEVICE_OK) break;
  d.rxCount = 0;
}

// Reset and setup, as hAPI's Board and Device::device_set_parameters send
// them, after draining the line; not real-time (open and reconnect).
int haplySendSetup(Haply2Diy& d) {
  haplyDrain(d);
  const std::uint8_t reset[2] = {kHaplyReset, 0};
  if (int rc = haplyWriteAll(d, reset, sizeof reset, 100); rc != DM_DEVICE_OK) return rc;
  std::uint8_t m[64];
  std::size_t n = 0;
  m[n++] = kHaplySetup;
  m[n++] = d.id;
  const std::uint8_t mask = static_cast<std::uint8_t>((1u << (d.port[0] - 1)) | (1u << (d.port[1] - 1)));
  const int a = d.firstArm(), b = 1 - a;
  m[n++] = mask;  // actuators
  m[n++] = static_cast<std::uint8_t>(d.dir[a]);
  m[n++] = static_cast<std::uint8_t>(d.dir[b]);
  m[n++] = mask;  // encoders, on the same ports
  m[n++] = static_cast<std::uint8_t>(d.dir[a]);
  m[n++] = static_cast<std::uint8_t>(d.dir[b]);
  if (d.buttonPin >= 0) {
    m[n++] = 1;
    m[n++] = static_cast<std::uint8_t>(d.buttonPin);
  } else {
    m[n++] = 0;
  }
  m[n++] = 0;  // no PWM pins
  for (int arm : {a, b}) {
    putFloatLE(m + n, static_cast<float>(d.offset[arm]));
    putFloatLE(m + n + 4, static_cast<float>(d.resolution));
    n += 8;
  }
  return haplyWriteAll(d, m, n, 100);
}

// Sends an update with the torques for `force` at the newest pose (none
// when it is no pose). Real-time safe.
int haplySendUpdate(Haply2Diy& d, std::int64_t now, const double force[3]) {
  double tau[2] = {0, 0};
  if (d.pose.valid) {
    const double s = kHaplyTorqueGain / d.link.l;
    for (int i = 0; i < 2; ++i) tau[i] = s * (d.pose.jt[i][0] * force[0] + d.pose.jt[i][1] * force[1]);
  }
  std::uint8_t m[2 + 8];
  m[0] = kHaplyUpdate;
  m[1] = d.id;
  const int a = d.firstArm();
  putFloatLE(m + 2, static_cast<float>(tau[a]));
  putFloatLE(m + 6, static_cast<float>(tau[1 - a]));
  const int rc = haplyWriteAll(d, m, sizeof m, 0);
  if (rc == DM_DEVICE_OK) {
    d.inFlight = true;
    d.sentNs = now;
  }
  return rc;
}

// Takes an answer out of d.rx; false (drained) when it is not one.
bool haplyTakeAnswer(Haply2Diy& d, std::int64_t now) {
  dm::driver::haply::Answer answer;
  const bool whole =
      dm::driver::haply::decodeAnswer(d.rx, d.rxCount, d.id, d.buttonPin >= 0, d.firstArm() == 1, answer);
  d.rxCount = 0;
  d.inFlight = false;
  if (!whole) return false;
  if (d.buttonPin >= 0) d.button = answer.analog >= d.buttonThreshold;
  d.pose = haplyPoseOf(d.link, answer.degrees[0], answer.degrees[1]);
  d.lastHeardNs = now;
  if (d.pose.valid) {
    const int oldest = d.histCount == kHaplyVelocityWindow ? d.histNext : 0;
    if (d.histCount > 0 && now > d.histT[oldest]) {
      const double dt = 1e-9 * static_cast<double>(now - d.histT[oldest]);
      d.vx = (d.pose.x - d.histX[oldest]) / dt;
      d.vy = (d.pose.y - d.histY[oldest]) / dt;
    }
    d.histX[d.histNext] = d.pose.x;
    d.histY[d.histNext] = d.pose.y;
    d.histT[d.histNext] = now;
    d.histNext = (d.histNext + 1) % kHaplyVelocityWindow;
    d.histCount = std::min(d.histCount + 1, kHaplyVelocityWindow);
  } else {
    d.histCount = d.histNext = 0;
    d.vx = d.vy = 0;
  }
  return true;
}

// Reads what the board has sent; a device status (I/O for a garbled answer).
int haplyReceive(Haply2Diy& d, std::int64_t now) {
  for (;;) {
    std::size_t got = 0;
    const std::size_t room = sizeof d.rx - d.rxCount;
    const int rc = serial::kSerialPosix.read(d.line, d.rx + d.rxCount, room, 0, &got);
    if (rc != DM_DEVICE_OK) return rc;
    d.rxCount += got;
    if (got == 0 || d.rxCount == sizeof d.rx) break;
  }
  if (d.rxCount == 0) return DM_DEVICE_OK;
  if (d.rxCount < d.answerSize() && d.inFlight) return DM_DEVICE_OK;  // the rest is on its way
  return haplyTakeAnswer(d, now) ? DM_DEVICE_OK : DM_DEVICE_ERROR_IO;
}

// Waits (not real-time: open) for the answer to an update.
bool haplyAwaitAnswer(Haply2Diy& d, double seconds, std::string& why) {
  const std::int64_t deadline = serial::monotonicMs() + static_cast<std::int64_t>(seconds * 1000);
  while (serial::monotonicMs() < deadline) {
    std::size_t got = 0;
    const int rc = serial::kSerialPosix.read(d.line, d.rx + d.rxCount, sizeof d.rx - d.rxCount, 10, &got);
    if (rc != DM_DEVICE_OK) {
      why = "the line failed while waiting for the board's answer";
      return false;
    }
    d.rxCount += got;
    if (d.rxCount >= d.answerSize()) {
      const std::size_t count = d.rxCount;
      const std::uint8_t firstByte = d.rx[0];
      if (haplyTakeAnswer(d, 0)) return true;
      char buf[160];
      std::snprintf(buf, sizeof buf,
                    "the board answered %zu bytes starting with %u, not %zu starting with the id %u", count,
                    unsigned{firstByte}, d.answerSize(), unsigned{d.id});
      why = buf;
      return false;
    }
  }
  char buf[120];
  std::snprintf(buf, sizeof buf, "no answer from the board within %g s (%zu of %zu bytes)", seconds,
                d.rxCount, d.answerSize());
  why = buf;
  return false;
}

void haplyClose(DmDevice* dev) {
  Haply2Diy* d = asHaply(dev);
  if (d->line) {
    const double zero[3] = {0, 0, 0};
    d->pose.valid = false;  // zero torque on the way out
    (void)haplySendUpdate(*d, 0, zero);
    serial::kSerialPosix.close(d->line);
  }
  delete d;
}

DmDevice* haplyOpen(const DmDeviceParam* params, size_t count, char* error, size_t errorSize) {
  dm::driver::ParamReader p(params, count, error, errorSize);
  p.onlyKnown({"path", "baud", "device_id", "max_force", "ports", "directions", "offsets", "resolution",
               "links", "button_pin", "button_threshold", "servo_rate", "timeout"});
  Haply2Diy* d = new (std::nothrow) Haply2Diy;
  if (!d) {
    p.failf("out of memory");
    return nullptr;
  }
  const char* path = p.find("path");
  if (p.ok() && (!path || !*path))
    p.failf("parameter 'path' is required (the board's serial device, e.g. /dev/ttyACM0)");
  const char* baud = p.find("baud");
  d->id = static_cast<std::uint8_t>(p.number("device_id", 3, 0, 255));
  const double maxForce = p.number("max_force", 0.0, 1e-3, 100.0);
  if (p.ok() && !p.find("max_force"))
    p.failf("parameter 'max_force' is required (N; Haply publishes no continuous force for the 2DIY)");
  std::array<double, 2> ports{1, 2};
  if (p.numbers("ports", ports) &&
      (ports[0] != std::floor(ports[0]) || ports[1] != std::floor(ports[1]) || ports[0] < 1 || ports[0] > 4 ||
       ports[1] < 1 || ports[1] > 4 || ports[0] == ports[1]))
    p.failf("parameter 'ports': two different ports 1 .. 4, e.g. \"1,2\"");
  if (const char* dirs = p.find("directions")) {
    const std::string v = dirs;
    const auto comma = v.find(',');
    const std::string first = v.substr(0, comma),
                      second = comma == std::string::npos ? "" : v.substr(comma + 1);
    for (int i = 0; i < 2; ++i) {
      const std::string& s = i == 0 ? first : second;
      if (s == "cw" || s == "ccw")
        d->dir[i] = s == "ccw" ? 1 : 0;
      else
        p.failf("parameter 'directions': '%s' is not two of cw and ccw, e.g. \"cw,ccw\"", dirs);
    }
  }
  p.numbers("offsets", d->offset);
  d->resolution = p.number("resolution", 13824, 1, 1e7);
  const std::array<double, 3> links = p.triple("links", {0.05, 0.07, 0.02});
  d->link = {links[0], links[1], links[2]};
  if (p.ok() && !(links[0] > 0 && links[1] > links[0] && links[2] >= 0 && links[2] < 2 * links[0]))
    p.failf("parameter 'links': l, L, d must have 0 < l < L and 0 <= d < 2 l");
  if (const char* pin = p.find("button_pin")) {
    char* end = nullptr;
    const long n = (pin[0] == 'A') ? std::strtol(pin + 1, &end, 10) : -1;
    if (pin[0] != 'A' || end == pin + 1 || *end || n < 0 || n > 11)
      p.failf("parameter 'button_pin': '%s' is not an analog pin A0 .. A11", pin);
    else
      d->buttonPin = kHaplyFirstAnalogPin + static_cast<int>(n);
  }
  d->buttonThreshold = p.number("button_threshold", 512, -1e9, 1e9);
  const double servoRate = p.number("servo_rate", 1000.0, 1.0, 1e5);
  const double timeout = p.number("timeout", 1.0, 0.01, 60.0);
  if (!p.ok()) {
    delete d;
    return nullptr;
  }
  d->port[0] = static_cast<int>(ports[0]);
  d->port[1] = static_cast<int>(ports[1]);

  const DmDeviceParam lineParams[2] = {{"path", path}, {"baud", baud ? baud : "115200"}};
  char lineError[256] = "";
  d->line = serial::kSerialPosix.open(lineParams, 2, lineError, sizeof lineError);
  if (!d->line) {
    p.failf("%s", lineError);
    delete d;
    return nullptr;
  }
  std::string why;
  const double zero[3] = {0, 0, 0};
  if (haplySendSetup(*d) != DM_DEVICE_OK || haplySendUpdate(*d, 0, zero) != DM_DEVICE_OK) {
    why = "cannot write to the board";
  } else if (haplyAwaitAnswer(*d, timeout, why)) {
    why.clear();
  }
  if (!why.empty()) {
    p.failf(
        "%s on '%s': is it a Haply board with hAPI 2 firmware (M3 1.5+, M0 0.3+), and are device_id and "
        "button_pin those of the device?",
        why.c_str(), path);
    serial::kSerialPosix.close(d->line);
    delete d;
    return nullptr;
  }

  // Its servo loop starts from here: the answer to open is a sample of now
  // on the host's real-time clock, the velocity starts from the next.
  d->lastHeardNs = serial::monotonicMs() * 1'000'000;
  d->histCount = d->histNext = 0;

  DmHapticInfo& info = d->info;
  dm::driver::copyField(info.identity.driver, "haply-2diy");
  dm::driver::copyField(info.identity.vendor, "Haply Robotics");
  dm::driver::copyField(info.identity.model, "2DIY pantograph (hAPI 2 board)");
  dm::driver::copyField(info.identity.serial, path);
  info.capabilities = DM_HAPTIC_CAP_POSITION | DM_HAPTIC_CAP_VELOCITY | DM_HAPTIC_CAP_FORCE;
  info.button_count = d->buttonPin >= 0 ? 1 : 0;
  // The box around the linkage's reach in front of the motors; the plane z = 0.
  const double reach = d->link.l + d->link.L;
  info.workspace_min[0] = d->link.d - reach;
  info.workspace_max[0] = reach;
  info.workspace_min[1] = 0.0;
  info.workspace_max[1] = reach;
  info.workspace_min[2] = info.workspace_max[2] = 0.0;
  info.max_force = maxForce;
  info.max_torque = 0.0;
  info.max_stiffness = 0.0;  // none published: the host's own limits apply
  info.max_damping = 0.0;
  info.servo_rate_hz = servoRate;
  return reinterpret_cast<DmDevice*>(d);
}

int haplyInfo(DmDevice* dev, DmHapticInfo* info) {
  *info = asHaply(dev)->info;
  return DM_DEVICE_OK;
}

int haplyRead(DmDevice* dev, int64_t now, DmHapticState* s) {
  Haply2Diy& d = *asHaply(dev);
  const int rc = haplyReceive(d, now);
  if (rc != DM_DEVICE_OK) return rc;
  if (d.inFlight && now - d.lastHeardNs > kHaplyLostNs) return DM_DEVICE_ERROR_LOST;  // the board went silent
  if (now - d.lastHeardNs > kHaplyStaleNs || !d.pose.valid) return DM_DEVICE_ERROR_IO;
  *s = DmHapticState{};
  s->time_ns = now;
  s->position[0] = d.pose.x;
  s->position[1] = d.pose.y;
  s->orientation[0] = 1.0;
  s->linear_velocity[0] = d.vx;
  s->linear_velocity[1] = d.vy;
  s->buttons = d.button ? 1u : 0u;
  return DM_DEVICE_OK;
}

int haplyWrite(DmDevice* dev, int64_t now, const double force[3], const double[3]) {
  Haply2Diy& d = *asHaply(dev);
  if (d.inFlight && now - d.sentNs < kHaplyResendNs)
    return DM_DEVICE_OK;          // the newest goes with the next update
  if (d.inFlight) d.rxCount = 0;  // unanswered: ask again, dropping any part of an answer
  return haplySendUpdate(d, now, force);
}

// Not real-time: the host calls it every reconnect interval while lost.
int haplyReconnect(DmDevice* dev, int64_t now) {
  Haply2Diy& d = *asHaply(dev);
  if (serial::kSerialPosix.reconnect(d.line) != DM_DEVICE_OK) return DM_DEVICE_ERROR_LOST;
  d.rxCount = 0;
  d.inFlight = false;
  d.pose = HaplyPose{};
  d.histCount = d.histNext = 0;
  d.lastHeardNs = now;
  const double zero[3] = {0, 0, 0};
  if (haplySendSetup(d) != DM_DEVICE_OK || haplySendUpdate(d, now, zero) != DM_DEVICE_OK)
    return DM_DEVICE_ERROR_LOST;
  return DM_DEVICE_OK;
}

const DmHapticDeviceVTable kHaply = {haplyOpen, haplyClose, haplyInfo, haplyRead, haplyWrite, haplyReconnect};

int haplyPluginInit(const DmHostApi* host) {
  return host->register_factory(host->ctx, DM_HAPTIC_DEVICE_KIND, "haply-2diy",
                                DM_HAPTIC_DEVICE_KIND_ABI_VERSION, &kHaply);
}

const DmPluginInfo kHaplyInfo = {DM_PLUGIN_ABI_VERSION, "haply-2diy", "1.0", haplyPluginInit, nullptr};

}  // namespace

#if defined(DM_DRIVER_PLUGIN)
DM_PLUGIN_ENTRY { return &kHaplyInfo; }
#else
extern "C" const DmPluginInfo* dm_builtin_entry_haply_2diy(void) { return &kHaplyInfo; }
#endif
