// replay-haptic — plays a haptic-state recording (dm/io/recorder.hpp) back
// as a haptic device (kind "haptic-device").
//
// Parameters (file, rate, loop, strict: see replay_common.hpp):
//   file   the recording (required); every complete record is used
//   rate   playback speed, > 0 (1 = as recorded, 2 = twice as fast)
//   loop   0 | 1: start over after the last record (0: hold the last one)
//   strict 0 | 1: refuse a recording with a damaged tail
//   max_force N (8), servo_rate Hz (1000), workspace m, half extent (0.15),
//   max_torque N·m (0: no torque output), max_stiffness N/m (2000),
//   max_damping N·s/m (20) — what the device reports (HapticDeviceInfo),
//   so a recorded run replays under the recorded device's limits
// The first read_state call maps host time to the first record; later
// calls return the latest record at or before
// first + rate · (now − start) (sample and hold, exact recorded values).
// Forces written to it are accepted and dropped.
#include <dm/core/plugin_abi.h>
#include <dm/io/device_abi.h>

#include <vector>

#include "replay_common.hpp"

namespace {

using dm::driver::ParamReader;

struct HapticFrame {
  std::int64_t t;
  double v[13];
  std::uint32_t buttons;
};

struct ReplayHaptic {
  dm::driver::ReplayStream<HapticFrame> stream;
  double maxForce = 8.0, servoRate = 1000.0, workspace = 0.15;
  double maxTorque = 0.0, maxStiffness = 2000.0, maxDamping = 20.0;
};

ReplayHaptic* asReplayHaptic(DmDevice* d) { return reinterpret_cast<ReplayHaptic*>(d); }

std::string decodeHapticFrame(const dm::record::RecordView& v, std::vector<HapticFrame>& frames) {
  HapticFrame fr{};
  fr.t = v.timeNs;
  dm::record::decodeDoubles(v.payload, fr.v, 13);
  fr.buttons = dm::record::getU32(v.payload + 8 * 13);
  frames.push_back(fr);
  return {};
}

DmDevice* replayOpen(const DmDeviceParam* params, size_t count, char* error, size_t errorSize) {
  return dm::driver::openReplay<ReplayHaptic>(
      params, count, error, errorSize,
      {"file", "rate", "loop", "strict", "max_force", "servo_rate", "workspace", "max_torque",
       "max_stiffness", "max_damping"},
      [](ReplayHaptic& r, const dm::driver::ReplayOptions& o, ParamReader& p) {
        r.maxForce = p.number("max_force", 8.0, 1e-6, 1e4);
        r.servoRate = p.number("servo_rate", 1000.0, 1.0, 1e6);
        r.workspace = p.number("workspace", 0.15, 1e-6, 100.0);
        r.maxTorque = p.number("max_torque", 0.0, 0.0, 1e4);
        r.maxStiffness = p.number("max_stiffness", 2000.0, 1e-6, 1e9);
        r.maxDamping = p.number("max_damping", 20.0, 0.0, 1e9);
        if (p.ok())
          r.stream.load(o, dm::record::kHapticState, dm::record::kHapticStateBytes, "haptic-state", p,
                        decodeHapticFrame);
      });
}

int replayInfo(DmDevice* dev, DmHapticInfo* info) {
  ReplayHaptic* r = asReplayHaptic(dev);
  *info = DmHapticInfo{};
  dm::driver::replayIdentity(info->identity, "replay-haptic", "haptic stream", r->stream.source);
  info->capabilities =
      DM_HAPTIC_CAP_POSITION | DM_HAPTIC_CAP_ORIENTATION | DM_HAPTIC_CAP_VELOCITY | DM_HAPTIC_CAP_FORCE;
  if (r->maxTorque > 0.0) info->capabilities |= DM_HAPTIC_CAP_TORQUE;
  info->max_torque = r->maxTorque;
  info->button_count = 32;
  for (int i = 0; i < 3; ++i) {
    info->workspace_min[i] = -r->workspace;
    info->workspace_max[i] = r->workspace;
  }
  info->max_force = r->maxForce;
  info->max_stiffness = r->maxStiffness;
  info->max_damping = r->maxDamping;
  info->servo_rate_hz = r->servoRate;
  return DM_DEVICE_OK;
}

int replayRead(DmDevice* dev, int64_t now, DmHapticState* s) {
  ReplayHaptic* r = asReplayHaptic(dev);
  // Past the end the last record holds (hold, unlike the other replays:
  // a haptic loop keeps rendering the final pose).
  const HapticFrame& f = dm::driver::latestAtOrBefore(r->stream.frames, r->stream.clock.at(now).recordedNs);
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

const DmHapticDeviceVTable kReplayHaptic = {
    replayOpen, dm::driver::closeReplay<ReplayHaptic>, replayInfo, replayRead, replayWrite, nullptr};

int replayInit(const DmHostApi* host) {
  return host->register_factory(host->ctx, DM_HAPTIC_DEVICE_KIND, "replay-haptic",
                                DM_HAPTIC_DEVICE_KIND_ABI_VERSION, &kReplayHaptic);
}

const DmPluginInfo kReplayHapticInfo = {DM_PLUGIN_ABI_VERSION, "replay-haptic", "1.0", replayInit, nullptr};

}  // namespace

#if defined(DM_DRIVER_PLUGIN)
DM_PLUGIN_ENTRY { return &kReplayHapticInfo; }
#else
extern "C" const DmPluginInfo* dm_builtin_entry_replay_haptic(void) { return &kReplayHapticInfo; }
#endif
