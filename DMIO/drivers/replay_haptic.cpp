// replay-haptic — plays a haptic-state recording (dm/io/recorder.hpp) back
// as a haptic device (kind "haptic-device").
//
// Parameters:
//   file   the recording (required); every complete record is used, a
//          damaged tail (a killed recorder) is ignored
//   rate   playback speed, > 0 (1 = as recorded, 2 = twice as fast)
//   loop   0 | 1: start over after the last record (0: hold the last one)
//   max_force N (8), servo_rate Hz (1000), workspace m, half extent (0.15)
// The first read_state call maps host time to the first record; later
// calls return the latest record at or before
// first + rate · (now − start) (sample and hold, exact recorded values).
// Forces written to it are accepted and dropped.
#include <dm/core/plugin_abi.h>
#include <dm/io/device_abi.h>

#include <algorithm>
#include <cstdio>
#include <new>
#include <vector>

#include "driver_params.hpp"
#include "record_format.hpp"

namespace {

using dm::driver::ParamReader;

struct Frame {
  std::int64_t t;
  double v[13];
  std::uint32_t buttons;
};

struct ReplayHaptic {
  std::vector<Frame> frames;  // time-ordered
  double rate = 1.0;
  bool loop = false;
  double maxForce = 8.0, servoRate = 1000.0, workspace = 0.15;
  bool started = false;
  std::int64_t startNs = 0;
};

ReplayHaptic* self(DmDevice* d) { return reinterpret_cast<ReplayHaptic*>(d); }

bool loadFrames(ReplayHaptic& r, const char* file, ParamReader& p) {
  std::FILE* f = std::fopen(file, "rb");
  if (!f) {
    p.failf("parameter 'file': cannot open '%s'", file);
    return false;
  }
  std::vector<unsigned char> bytes;
  unsigned char chunk[65536];
  std::size_t n;
  while ((n = std::fread(chunk, 1, sizeof chunk, f)) > 0) {
    if (bytes.size() + n > (std::size_t(1) << 30)) {
      std::fclose(f);
      p.failf("%s: larger than 1 GiB", file);
      return false;
    }
    bytes.insert(bytes.end(), chunk, chunk + n);
  }
  std::fclose(f);
  std::int64_t last = INT64_MIN;
  bool ordered = true;
  const auto scan = dm::record::scan(bytes.data(), bytes.size(), [&](const dm::record::RecordView& v) {
    if (v.type != dm::record::kHapticState || v.size != dm::record::kHapticStateBytes) return;
    Frame fr{};
    fr.t = v.timeNs;
    dm::record::decodeDoubles(v.payload, fr.v, 13);
    fr.buttons = dm::record::getU32(v.payload + 8 * 13);
    ordered = ordered && fr.t >= last;
    last = fr.t;
    r.frames.push_back(fr);
  });
  if (!scan.headerOk) {
    p.failf("%s: %s", file, scan.error.c_str());
    return false;
  }
  if (r.frames.empty()) {
    p.failf("%s: no haptic-state records", file);
    return false;
  }
  if (!ordered)
    std::stable_sort(r.frames.begin(), r.frames.end(),
                     [](const Frame& a, const Frame& b) { return a.t < b.t; });
  return true;
}

DmDevice* replayOpen(const DmDeviceParam* params, size_t count, char* error, size_t errorSize) {
  ParamReader p(params, count, error, errorSize);
  p.onlyKnown({"file", "rate", "loop", "max_force", "servo_rate", "workspace"});
  auto* r = new (std::nothrow) ReplayHaptic();
  if (!r) {
    p.failf("out of memory");
    return nullptr;
  }
  r->rate = p.number("rate", 1.0, 1e-6, 1e6);
  r->loop = p.number("loop", 0.0, 0.0, 1.0) != 0.0;
  r->maxForce = p.number("max_force", 8.0, 1e-6, 1e4);
  r->servoRate = p.number("servo_rate", 1000.0, 1.0, 1e6);
  r->workspace = p.number("workspace", 0.15, 1e-6, 100.0);
  const char* file = p.find("file");
  if (p.ok() && !file) p.failf("parameter 'file' is required");
  if (p.ok()) loadFrames(*r, file, p);
  if (!p.ok()) {
    delete r;
    return nullptr;
  }
  return reinterpret_cast<DmDevice*>(r);
}

void replayClose(DmDevice* d) { delete self(d); }

int replayInfo(DmDevice* dev, DmHapticInfo* info) {
  ReplayHaptic* r = self(dev);
  *info = DmHapticInfo{};
  dm::driver::copyField(info->identity.driver, "replay-haptic");
  dm::driver::copyField(info->identity.vendor, "DMPlatform");
  dm::driver::copyField(info->identity.model, "recorded haptic stream");
  std::snprintf(info->identity.serial, sizeof info->identity.serial, "%zu-frames", r->frames.size());
  info->capabilities =
      DM_HAPTIC_CAP_POSITION | DM_HAPTIC_CAP_ORIENTATION | DM_HAPTIC_CAP_VELOCITY | DM_HAPTIC_CAP_FORCE;
  info->button_count = 32;
  for (int i = 0; i < 3; ++i) {
    info->workspace_min[i] = -r->workspace;
    info->workspace_max[i] = r->workspace;
  }
  info->max_force = r->maxForce;
  info->max_stiffness = 2000.0;
  info->max_damping = 20.0;
  info->servo_rate_hz = r->servoRate;
  return DM_DEVICE_OK;
}

int replayRead(DmDevice* dev, int64_t now, DmHapticState* s) {
  ReplayHaptic* r = self(dev);
  if (!r->started) {
    r->started = true;
    r->startNs = now;
  }
  const std::int64_t first = r->frames.front().t, span = r->frames.back().t - first;
  auto offset = static_cast<std::int64_t>(r->rate * static_cast<double>(now - r->startNs));
  if (r->loop && span > 0) offset %= span + 1;
  const std::int64_t want = first + offset;
  // Latest frame with t ≤ want (the first frame before the start).
  auto it = std::upper_bound(r->frames.begin(), r->frames.end(), want,
                             [](std::int64_t t, const Frame& f) { return t < f.t; });
  const Frame& f = it == r->frames.begin() ? r->frames.front() : *(it - 1);
  *s = DmHapticState{};
  s->time_ns = now;
  for (int i = 0; i < 3; ++i) {
    s->position[i] = f.v[i];
    s->linear_velocity[i] = f.v[7 + i];
    s->angular_velocity[i] = f.v[10 + i];
  }
  for (int i = 0; i < 4; ++i) s->orientation[i] = f.v[3 + i];
  s->buttons = f.buttons;
  return DM_DEVICE_OK;
}

int replayWrite(DmDevice*, int64_t, const double*, const double*) { return DM_DEVICE_OK; }

const DmHapticDeviceVTable kReplayHaptic = {replayOpen, replayClose, replayInfo,
                                            replayRead, replayWrite, nullptr};

int replayInit(const DmHostApi* host) {
  return host->register_factory(host->ctx, DM_HAPTIC_DEVICE_KIND, "replay-haptic",
                                DM_HAPTIC_DEVICE_KIND_ABI_VERSION, &kReplayHaptic);
}

const DmPluginInfo kInfo = {DM_PLUGIN_ABI_VERSION, "replay-haptic", "1.0", replayInit, nullptr};

}  // namespace

#if defined(DM_DRIVER_PLUGIN)
DM_PLUGIN_ENTRY { return &kInfo; }
#else
extern "C" const DmPluginInfo* dm_builtin_entry_replay_haptic(void) { return &kInfo; }
#endif
