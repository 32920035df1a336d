// sim-haptic — a simulated 3-DOF haptic device (kind "haptic-device").
//
// Without hardware it produces what a stylus would: a scripted trajectory
// (point, line, circle, spiral, or piecewise linear from a CSV file, which
// may also give the handle's orientation, interpolated by slerp), or a
// virtual hand — a mass–spring–damper pulled toward that trajectory and
// pushed by the forces the device renders — so closed-loop force rendering
// can be tested. Sensor effects: Gaussian position noise (seeded, so lockstep
// runs repeat bit for bit), quantization to an encoder step, and latency
// (samples reported late by a fixed delay). A loss window (drop_at,
// reconnect_at) exercises connection loss and reconnection.
//
// Parameters (all optional; numbers in SI units):
//   path         point | line | circle | spiral | csv          (circle)
//   center       "x,y,z" m                                      (0,0,0)
//   radius       m, circle and spiral                           (0.03)
//   period       s per turn (circle, spiral) or per sweep (line) (2)
//   from, to     "x,y,z" m, line ends                           (-0.05,0,0) (0.05,0,0)
//   pitch        m per turn along z, spiral                     (0.005)
//   turns        turns before the spiral restarts               (4)
//   file         CSV of "t,x,y,z" or "t,x,y,z,qw,qx,qy,qz" rows (s, m, unit
//                quaternion, normalised; every row the same, values within
//                ±1e9), csv path; an optional header line first, '#' lines
//                skipped
//   loop         0 | 1: line, circle, spiral and csv paths loop (1), or
//                run once from the first sample and hold their end (0)  (1)
// A key of another path than the one chosen, or a hand_* key without hand 1,
// is an error naming it. The velocity reported is the path's own (its
// formula's, a CSV segment's slope): none across a jump such as a spiral's
// return to its first turn.
// Every path's time starts at the device's first sample (lockstep and real
// time alike).
//   hand         0 | 1: drive a virtual hand instead of the stylus (0)
//   hand_mass    kg (0.2)   hand_stiffness N/m (300)   hand_damping N·s/m (8)
//   noise        m, standard deviation per axis                 (0)
//   quantization m, encoder step                                (0)
//   latency      s, ≤ 0.5                                       (0)
//   seed         integer, noise generator                       (1)
//   max_force    N (8)   servo_rate Hz (1000)   workspace m, half extent (0.15)
//   drop_at      s, device lost from then (-1: never)
//   reconnect_at s, reconnect succeeds from then (-1: never)
//
// Built twice from this file: into DM::IO (registered by
// dm::registerBuiltinDrivers) and, with DM_DRIVER_PLUGIN, as the plugin
// libdm_driver_sim_haptic.so.
#include <dm/core/plugin_abi.h>
#include <dm/io/device_abi.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <new>
#include <random>
#include <string_view>
#include <utility>
#include <vector>

#include "driver_params.hpp"

namespace {

using dm::driver::ParamReader;
using V3 = std::array<double, 3>;

constexpr double kPi = 3.14159265358979323846;
constexpr std::size_t kHistory = 1 << 15;  // latency ring: 32768 samples

V3 add(V3 a, V3 b) { return {a[0] + b[0], a[1] + b[1], a[2] + b[2]}; }
V3 sub(V3 a, V3 b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
V3 scale(V3 a, double s) { return {a[0] * s, a[1] * s, a[2] * s}; }
V3 lerp(V3 a, V3 b, double u) { return add(a, scale(sub(b, a), u)); }

using Q4 = std::array<double, 4>;  // w, x, y, z
constexpr Q4 kIdentity = {1, 0, 0, 0};
double dot4(const Q4& a, const Q4& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3]; }
// Spherical linear interpolation from a to b (both unit, same hemisphere).
Q4 slerp(const Q4& a, const Q4& b, double u) {
  const double c = std::min(1.0, dot4(a, b));
  double wa = 1.0 - u, wb = u;
  if (c < 0.9995) {  // otherwise linear, then normalised: the same to 1e-7
    const double th = std::acos(c), sn = std::sin(th);
    wa = std::sin((1.0 - u) * th) / sn;
    wb = std::sin(u * th) / sn;
  }
  Q4 q{};
  for (int i = 0; i < 4; ++i) q[i] = wa * a[i] + wb * b[i];
  const double n = std::sqrt(dot4(q, q));
  for (double& c4 : q) c4 /= n;
  return q;
}
// Angular velocity (rad/s, world) that turns a into b in dt at a constant
// rate (a slerp's): the axis of b·a⁻¹ times its angle, over dt.
V3 angularVelocity(const Q4& a, const Q4& b, double dt) {
  const double w = dot4(a, b);  // the scalar part of b · conj(a)
  const V3 v = {-b[0] * a[1] + b[1] * a[0] - b[2] * a[3] + b[3] * a[2],
                -b[0] * a[2] + b[1] * a[3] + b[2] * a[0] - b[3] * a[1],
                -b[0] * a[3] - b[1] * a[2] + b[2] * a[1] + b[3] * a[0]};
  const double sn = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
  if (sn < 1e-12) return scale(v, (w < 0 ? -2.0 : 2.0) / dt);
  const double angle = 2.0 * std::atan2(sn, std::abs(w));  // the shorter way, as slerp turns
  return scale(v, (w < 0 ? -angle : angle) / (sn * dt));
}

enum Path { kPoint, kLine, kCircle, kSpiral, kCsv };

struct Sample {
  std::int64_t t = 0;
  V3 x{}, v{};
  Q4 q = kIdentity;
  V3 w{};
};

// One device instance; DmDevice* is this type behind the C boundary.
struct SimHaptic {
  Path path = kCircle;
  V3 center{}, from{}, to{};
  double radius = 0.03, period = 2.0, pitch = 0.005, turns = 4.0;
  std::vector<std::array<double, 8>> csv;  // t, x, y, z, qw, qx, qy, qz; t strictly increasing
  bool csvOrientation = false;             // the file has the quaternion columns
  bool repeat = true;
  std::int64_t originNs = -1;  // the path's time starts at the first sample

  bool hand = false;
  double mass = 0.2, stiffness = 300.0, damping = 8.0;
  V3 handX{}, handV{};
  std::int64_t handT = 0;
  bool handStarted = false;
  V3 force{};  // last output (N), acts on the hand

  double noise = 0.0, quantization = 0.0;
  std::int64_t latencyNs = 0;
  std::mt19937_64 rng;
  std::normal_distribution<double> gauss{0.0, 1.0};
  std::vector<Sample> history;  // ring for latency
  std::size_t historyCount = 0, historyHead = 0;

  double maxForce = 8.0, servoRate = 1000.0, workspace = 0.15;
  double dropAt = -1.0, reconnectAt = -1.0;
  bool lost = false, reconnected = false;
  unsigned long long seed = 1;

  V3 target(double t) const {
    switch (path) {
      case kPoint:
        return center;
      case kLine: {
        const double phase = repeat ? t / period - std::floor(t / period) : std::clamp(t / period, 0.0, 0.5);
        return lerp(from, to, phase < 0.5 ? 2.0 * phase : 2.0 - 2.0 * phase);
      }
      case kCircle: {
        const double w = 2.0 * kPi / period, tt = repeat ? t : std::clamp(t, 0.0, period);
        return add(center, {radius * std::cos(w * tt), radius * std::sin(w * tt), 0.0});
      }
      case kSpiral: {
        const double w = 2.0 * kPi / period;
        const double tt = repeat ? t : std::clamp(t, 0.0, turns * period), u = tt / period;
        const double along = repeat ? u - turns * std::floor(u / turns) : u;  // held at the last turn's end
        return add(center, {radius * std::cos(w * tt), radius * std::sin(w * tt), pitch * along});
      }
      case kCsv: {
        const auto [lo, u] = csvSegment(t);
        const auto& a = csv[lo];
        const auto& b = csv[std::min(lo + 1, csv.size() - 1)];
        return lerp({a[1], a[2], a[3]}, {b[1], b[2], b[3]}, u);
      }
    }
    return center;
  }

  // The CSV row `lo` and the fraction u in [0, 1) toward row lo + 1 at path
  // time t (looped over the file's span, or held at its ends).
  std::pair<std::size_t, double> csvSegment(double t) const {
    const double span = csv.back()[0] - csv.front()[0];
    double tt = span > 0 ? csv.front()[0] + std::fmod(t - csv.front()[0], span) : csv.front()[0];
    if (tt < csv.front()[0]) tt += span;
    if (!repeat) tt = std::clamp(t, csv.front()[0], csv.back()[0]);
    std::size_t lo = 0, hi = csv.size() - 1;  // binary search: csv[lo].t ≤ tt < csv[hi].t
    if (tt >= csv[hi][0]) return {hi, 0.0};
    while (hi - lo > 1) {
      const std::size_t mid = (lo + hi) / 2;
      (csv[mid][0] <= tt ? lo : hi) = mid;
    }
    return {lo, (tt - csv[lo][0]) / (csv[hi][0] - csv[lo][0])};
  }

  // The handle's orientation: slerp between the CSV rows; identity otherwise.
  Q4 targetOrientation(double t) const {
    if (path != kCsv || !csvOrientation) return kIdentity;
    const auto [lo, u] = csvSegment(t);
    const auto& a = csv[lo];
    const auto& b = csv[std::min(lo + 1, csv.size() - 1)];
    return slerp({a[4], a[5], a[6], a[7]}, {b[4], b[5], b[6], b[7]}, u);
  }

  // Seconds along the path at device time `ns`: the time since the first
  // sample, for looping paths too, so a run on the machine's monotonic
  // clock starts the path at its beginning as a lockstep run (whose clock
  // starts at 0) does, not at whatever phase the clock's uptime gives.
  double pathSeconds(std::int64_t ns) {
    if (originNs < 0) originNs = ns;
    return 1e-9 * static_cast<double>(ns - originNs);
  }

  // The path's velocity from its formula (a CSV path: its segment's slope).
  // Not a difference of positions: a path that jumps — a spiral starting
  // its next turn, a looped CSV going back to its first row — has no
  // velocity across the jump, and a difference across it (as at t = 0,
  // where t − h is the end of the last turn) would fling a virtual hand
  // that starts with it at metres per second.
  V3 targetVelocity(double t) const {
    const double w = 2.0 * kPi / period;
    switch (path) {
      case kPoint:
        return {};
      case kLine: {
        if (!repeat && (t < 0.0 || t >= 0.5 * period)) return {};
        const double phase = t / period - std::floor(t / period);
        return scale(sub(to, from), (phase < 0.5 ? 2.0 : -2.0) / period);
      }
      case kCircle:
        if (!repeat && (t < 0.0 || t >= period)) return {};
        return {-radius * w * std::sin(w * t), radius * w * std::cos(w * t), 0.0};
      case kSpiral:
        if (!repeat && (t < 0.0 || t >= turns * period)) return {};
        return {-radius * w * std::sin(w * t), radius * w * std::cos(w * t), pitch / period};
      case kCsv: {
        if (!repeat && t < csv.front()[0]) return {};  // held at the first row
        const std::size_t lo = csvSegment(t).first;
        if (lo + 1 >= csv.size()) return {};  // held at the last row
        const auto& a = csv[lo];
        const auto& b = csv[lo + 1];
        return scale(sub({b[1], b[2], b[3]}, {a[1], a[2], a[3]}), 1.0 / (b[0] - a[0]));
      }
    }
    return {};
  }

  // The handle's angular velocity: its CSV segment's slerp rate.
  V3 targetAngularVelocity(double t) const {
    if (path != kCsv || !csvOrientation || (!repeat && t < csv.front()[0])) return {};
    const std::size_t lo = csvSegment(t).first;
    if (lo + 1 >= csv.size()) return {};
    const auto& a = csv[lo];
    const auto& b = csv[lo + 1];
    return angularVelocity({a[4], a[5], a[6], a[7]}, {b[4], b[5], b[6], b[7]}, b[0] - a[0]);
  }

  // The hand integrated up to `now` with semi-implicit Euler, substeps ≤ 0.1 ms.
  void advanceHand(std::int64_t now) {
    if (!handStarted) {
      handStarted = true;
      handT = now;
      handX = target(pathSeconds(now));
      handV = targetVelocity(pathSeconds(now));
      return;
    }
    if (now <= handT) return;
    const std::int64_t total = now - handT;
    const std::int64_t steps = (total + 99999) / 100000;
    const double dt = 1e-9 * static_cast<double>(total) / static_cast<double>(steps);
    for (std::int64_t i = 1; i <= steps; ++i) {
      const double t = pathSeconds(handT) + dt * static_cast<double>(i);
      const V3 pull = scale(sub(target(t), handX), stiffness);
      const V3 acc = scale(add(sub(pull, scale(handV, damping)), force), 1.0 / mass);
      handV = add(handV, scale(acc, dt));
      handX = add(handX, scale(handV, dt));
    }
    handT = now;
  }

  // The hand holds the handle's orientation rigidly (it is a translational
  // model), so orientation and angular velocity always come from the path.
  Sample trueSample(std::int64_t now) {
    const double t = pathSeconds(now);
    Sample s{now, {}, {}, targetOrientation(t), targetAngularVelocity(t)};
    if (hand) {
      advanceHand(now);
      s.x = handX;
      s.v = handV;
    } else {
      s.x = target(t);
      s.v = targetVelocity(t);
    }
    return s;
  }

  // The true sample at now − latency, linearly interpolated in the ring.
  Sample delayed(std::int64_t now) {
    const Sample s = trueSample(now);
    if (latencyNs == 0) return s;
    history[historyHead] = s;
    historyHead = (historyHead + 1) % kHistory;
    if (historyCount < kHistory) ++historyCount;
    const std::int64_t want = now - latencyNs;
    // Newest first: find the two samples around `want`.
    Sample newer = s;
    for (std::size_t k = 1; k < historyCount; ++k) {
      const Sample& older = history[(historyHead + kHistory - 1 - k) % kHistory];
      if (older.t <= want) {
        const double u = newer.t > older.t
                             ? static_cast<double>(want - older.t) / static_cast<double>(newer.t - older.t)
                             : 0.0;
        return {want, lerp(older.x, newer.x, u), lerp(older.v, newer.v, u), slerp(older.q, newer.q, u),
                lerp(older.w, newer.w, u)};
      }
      newer = older;
    }
    newer.t = want;
    return newer;  // not enough history yet: the oldest sample
  }

  bool lostAt(std::int64_t now) {
    const double t = 1e-9 * static_cast<double>(now);
    if (!lost && !reconnected && dropAt >= 0.0 && t >= dropAt) lost = true;
    return lost;
  }
};

SimHaptic* asSimHaptic(DmDevice* d) { return reinterpret_cast<SimHaptic*>(d); }

// Reads the CSV path: rows of 4 (t,x,y,z) or 8 (plus qw,qx,qy,qz) finite
// numbers, all rows alike, times strictly increasing, quaternions of non-zero
// length (normalised, and flipped into the previous row's hemisphere so that
// slerp takes the short way). The first line may be a header.
bool loadCsv(SimHaptic& d, const char* file, ParamReader& r) {
  std::FILE* f = std::fopen(file, "r");
  if (!f) {
    r.failf("parameter 'file': cannot open '%s'", file);
    return false;
  }
  char line[1024];
  int lineNo = 0, width = 0;
  while (std::fgets(line, sizeof line, f)) {
    ++lineNo;
    if (line[0] == '#' || line[0] == '\n' || line[0] == '\r') continue;
    std::array<double, 8> row{};
    int end = 0;
    const int n = std::sscanf(line, "%lf,%lf,%lf,%lf%n,%lf,%lf,%lf,%lf%n", &row[0], &row[1], &row[2], &row[3],
                              &end, &row[4], &row[5], &row[6], &row[7], &end);
    bool finite = true;  // and within ±1e9 (s, m): differences of values stay finite
    for (int i = 0; i < n; ++i) finite = finite && std::abs(row[static_cast<std::size_t>(i)]) <= 1e9;
    const char* rest = line + end;
    while (*rest == ' ' || *rest == '\t' || *rest == '\r' || *rest == '\n') ++rest;
    if ((n != 4 && n != 8) || !finite || *rest != '\0') {
      if (lineNo == 1 && n <= 0) continue;  // a header line
      r.failf("%s:%d: expected \"t,x,y,z\" or \"t,x,y,z,qw,qx,qy,qz\" (4 or 8 numbers, each within ±1e9)",
              file, lineNo);
      break;
    }
    if (width == 0) width = n;
    if (n != width) {
      r.failf("%s:%d: %d numbers, but the rows before have %d", file, lineNo, n, width);
      break;
    }
    if (n == 8) {
      Q4 q = {row[4], row[5], row[6], row[7]};
      const double len = std::sqrt(dot4(q, q));
      if (!(len > 0.0)) {
        r.failf("%s:%d: quaternion qw,qx,qy,qz has zero length", file, lineNo);
        break;
      }
      const double sign = !d.csv.empty() && dot4(q, {d.csv.back()[4], d.csv.back()[5], d.csv.back()[6],
                                                     d.csv.back()[7]}) < 0.0
                              ? -1.0
                              : 1.0;
      for (std::size_t i = 0; i < 4; ++i) row[4 + i] = sign * q[i] / len;
    } else {
      row[4] = 1.0;
    }
    if (!d.csv.empty() && !(row[0] > d.csv.back()[0])) {
      r.failf("%s:%d: time %g does not increase", file, lineNo, row[0]);
      break;
    }
    if (d.csv.size() >= 10'000'000) {
      r.failf("%s:%d: more than 10 million rows", file, lineNo);
      break;
    }
    d.csv.push_back(row);
  }
  std::fclose(f);
  if (r.ok() && d.csv.empty()) r.failf("%s: no \"t,x,y,z\" rows", file);
  d.csvOrientation = width == 8;
  return r.ok();
}

DmDevice* simOpen(const DmDeviceParam* params, size_t count, char* error, size_t errorSize) {
  ParamReader r(params, count, error, errorSize);
  r.onlyKnown({"path",         "center",    "radius",       "period",       "from",      "to",
               "pitch",        "turns",     "file",         "hand",         "hand_mass", "hand_stiffness",
               "hand_damping", "noise",     "quantization", "latency",      "seed",      "max_force",
               "servo_rate",   "workspace", "drop_at",      "reconnect_at", "loop"});
  SimHaptic* d = new (std::nothrow) SimHaptic();
  if (!d) {
    r.failf("out of memory");
    return nullptr;
  }
  d->path = static_cast<Path>(r.choice("path", {"point", "line", "circle", "spiral", "csv"}, kCircle));
  d->center = r.triple("center", {0, 0, 0});
  d->radius = r.number("radius", 0.03, 0.0, 10.0);
  d->period = r.number("period", 2.0, 1e-3, 1e6);
  d->from = r.triple("from", {-0.05, 0, 0});
  d->to = r.triple("to", {0.05, 0, 0});
  d->pitch = r.number("pitch", 0.005, -10.0, 10.0);
  d->turns = r.number("turns", 4.0, 1e-3, 1e6);
  d->hand = r.number("hand", 0.0, 0.0, 1.0) != 0.0;
  d->repeat = r.number("loop", 1.0, 0.0, 1.0) != 0.0;
  d->mass = r.number("hand_mass", 0.2, 1e-4, 1e3);
  d->stiffness = r.number("hand_stiffness", 300.0, 0.0, 1e6);
  d->damping = r.number("hand_damping", 8.0, 0.0, 1e6);
  d->noise = r.number("noise", 0.0, 0.0, 1.0);
  d->quantization = r.number("quantization", 0.0, 0.0, 1.0);
  d->latencyNs = static_cast<std::int64_t>(std::llround(1e9 * r.number("latency", 0.0, 0.0, 0.5)));
  d->seed = static_cast<unsigned long long>(r.number("seed", 1.0, 0.0, 9007199254740992.0));
  d->maxForce = r.number("max_force", 8.0, 1e-6, 1e4);
  d->servoRate = r.number("servo_rate", 1000.0, 1.0, 1e6);
  d->workspace = r.number("workspace", 0.15, 1e-6, 100.0);
  d->dropAt = r.number("drop_at", -1.0, -1.0, 1e9);
  d->reconnectAt = r.number("reconnect_at", -1.0, -1.0, 1e9);
  // A key of another path, or of the hand without one, would be ignored:
  // name it instead.
  static constexpr const char* kPathNames[] = {"point", "line", "circle", "spiral", "csv"};
  static constexpr const char* kPathKeys[][6] = {{"center"},
                                                 {"from", "to", "period", "loop"},
                                                 {"center", "radius", "period", "loop"},
                                                 {"center", "radius", "period", "pitch", "turns", "loop"},
                                                 {"file", "loop"}};
  for (const char* key : {"center", "radius", "period", "from", "to", "pitch", "turns", "file", "loop"}) {
    const auto& keys = kPathKeys[d->path];
    const bool used = std::any_of(std::begin(keys), std::end(keys),
                                  [&](const char* k) { return k && std::string_view(k) == key; });
    if (r.ok() && !used && r.find(key))
      r.failf("parameter '%s' does nothing with path %s", key, kPathNames[d->path]);
  }
  for (const char* key : {"hand_mass", "hand_stiffness", "hand_damping"})
    if (r.ok() && !d->hand && r.find(key)) r.failf("parameter '%s' needs hand 1", key);
  if (r.ok() && d->path == kCsv) {
    const char* file = r.find("file");
    if (!file)
      r.failf("parameter 'file' is required with path csv");
    else
      loadCsv(*d, file, r);
  }
  if (r.ok() && d->latencyNs > 0) d->history.assign(kHistory, Sample{});
  if (!r.ok()) {
    delete d;
    return nullptr;
  }
  d->rng.seed(d->seed);
  return reinterpret_cast<DmDevice*>(d);
}

void simClose(DmDevice* d) { delete asSimHaptic(d); }

int simInfo(DmDevice* dev, DmHapticInfo* info) {
  SimHaptic* d = asSimHaptic(dev);
  *info = DmHapticInfo{};
  dm::driver::simIdentity(info->identity, "sim-haptic",
                          d->hand ? "simulated 3-DOF stylus in a virtual hand" : "simulated 3-DOF stylus",
                          d->seed);
  info->capabilities = DM_HAPTIC_CAP_POSITION | DM_HAPTIC_CAP_VELOCITY | DM_HAPTIC_CAP_FORCE;
  if (d->csvOrientation) info->capabilities |= DM_HAPTIC_CAP_ORIENTATION;
  info->button_count = 0;
  for (int i = 0; i < 3; ++i) {
    info->workspace_min[i] = d->center[i] - d->workspace;
    info->workspace_max[i] = d->center[i] + d->workspace;
  }
  info->max_force = d->maxForce;
  info->max_torque = 0.0;
  info->max_stiffness = 2000.0;
  info->max_damping = 20.0;
  info->servo_rate_hz = d->servoRate;
  return DM_DEVICE_OK;
}

int simRead(DmDevice* dev, int64_t now, DmHapticState* s) {
  SimHaptic* d = asSimHaptic(dev);
  if (d->lostAt(now)) return DM_DEVICE_ERROR_LOST;
  const Sample smp = d->delayed(now);
  *s = DmHapticState{};
  s->time_ns = now;
  for (int i = 0; i < 3; ++i) {
    double x = smp.x[i];
    if (d->noise > 0.0) x += d->noise * d->gauss(d->rng);
    if (d->quantization > 0.0) x = d->quantization * std::round(x / d->quantization);
    s->position[i] = x;
    s->linear_velocity[i] = smp.v[i];
  }
  for (std::size_t i = 0; i < 4; ++i) s->orientation[i] = smp.q[i];
  for (std::size_t i = 0; i < 3; ++i) s->angular_velocity[i] = smp.w[i];
  return DM_DEVICE_OK;
}

int simWrite(DmDevice* dev, int64_t now, const double force[3], const double torque[3]) {
  SimHaptic* d = asSimHaptic(dev);
  (void)torque;  // no torque output (3-DOF)
  if (d->lostAt(now)) {
    d->force = {0, 0, 0};  // motors off while the link is down
    return DM_DEVICE_ERROR_LOST;
  }
  if (d->hand) d->advanceHand(now);  // the previous force acted until now
  d->force = {force[0], force[1], force[2]};
  return DM_DEVICE_OK;
}

int simReconnect(DmDevice* dev, int64_t now) {
  SimHaptic* d = asSimHaptic(dev);
  const double t = 1e-9 * static_cast<double>(now);
  if (!d->lost) return DM_DEVICE_OK;
  if (d->reconnectAt < 0.0 || t < d->reconnectAt) return DM_DEVICE_ERROR_LOST;
  d->lost = false;
  d->reconnected = true;
  d->force = {0, 0, 0};
  return DM_DEVICE_OK;
}

const DmHapticDeviceVTable kSimHaptic = {simOpen, simClose, simInfo, simRead, simWrite, simReconnect};

int simInit(const DmHostApi* host) {
  return host->register_factory(host->ctx, DM_HAPTIC_DEVICE_KIND, "sim-haptic",
                                DM_HAPTIC_DEVICE_KIND_ABI_VERSION, &kSimHaptic);
}

const DmPluginInfo kSimHapticInfo = {DM_PLUGIN_ABI_VERSION, "sim-haptic", "1.0", simInit, nullptr};

}  // namespace

#if defined(DM_DRIVER_PLUGIN)
DM_PLUGIN_ENTRY { return &kSimHapticInfo; }
#else
extern "C" const DmPluginInfo* dm_builtin_entry_sim_haptic(void) { return &kSimHapticInfo; }
#endif
