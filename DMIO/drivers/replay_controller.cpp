// replay-controller — plays the controller states of a recording
// (dm/io/recorder.hpp, DeviceRecorder::pushControllerState) back as a
// controller (kind "controller").
//
// Parameters (see replay_common.hpp): file (required), rate, loop, strict.
// The first read_state call maps host time to the first record; later calls
// return the latest record at or before first + rate · (now − start) (sample
// and hold, exact recorded axes and buttons), stamped with the host time at
// which that record plays: start + (t − first) / rate, so at rate 1 with the
// recording's start time the replayed timestamps equal the recorded ones.
// End of stream: without loop, once the replay passes the last record
// read_state reports DM_DEVICE_ERROR_LOST (the Controller keeps the last
// state and queues a Lost event); there is no reconnect.
//
// Built into DM::IO and, with DM_DRIVER_PLUGIN, as libdm_driver_replay_controller.so.
#include <dm/core/plugin_abi.h>
#include <dm/io/device_abi.h>

#include <vector>

#include "replay_common.hpp"

namespace {

using dm::driver::ParamReader;

struct ControllerFrame {
  std::int64_t t;
  double axes[DM_CONTROLLER_AXES];
  std::uint64_t buttons[2];
};

// One instance; DmDevice* is this type behind the C boundary.
struct ReplayController {
  dm::driver::ReplayStream<ControllerFrame> stream;
};

ReplayController* asReplayController(DmDevice* d) { return reinterpret_cast<ReplayController*>(d); }

std::string decodeControllerFrame(const dm::record::RecordView& v, std::vector<ControllerFrame>& frames) {
  std::string why = dm::record::checkControllerState(v.payload);
  if (!why.empty()) return why;
  ControllerFrame f{};
  f.t = v.timeNs;
  dm::record::decodeControllerState(v.payload, f.axes, f.buttons);
  frames.push_back(f);
  return why;
}

DmDevice* controllerOpen(const DmDeviceParam* params, size_t count, char* error, size_t errorSize) {
  return dm::driver::openReplay<ReplayController>(
      params, count, error, errorSize, {"file", "rate", "loop", "strict"},
      [](ReplayController& r, const dm::driver::ReplayOptions& o, ParamReader& p) {
        r.stream.load(o, dm::record::kControllerState, dm::record::kControllerStateBytes, "controller-state",
                      p, decodeControllerFrame);
      });
}

int controllerInfo(DmDevice* dev, DmControllerInfo* info) {
  ReplayController* r = asReplayController(dev);
  *info = DmControllerInfo{};
  dm::driver::replayIdentity(info->identity, "replay-controller", "controller stream", r->stream.source);
  info->capabilities = DM_CONTROLLER_CAP_AXES | DM_CONTROLLER_CAP_BUTTONS;
  info->axis_count = DM_CONTROLLER_AXES;
  info->button_count = DM_CONTROLLER_MAX_BUTTONS;
  info->poll_rate_hz = r->stream.clock.eventRate(static_cast<double>(r->stream.frames.size()), 250.0);
  return DM_DEVICE_OK;
}

int controllerRead(DmDevice* dev, int64_t now, DmControllerState* s) {
  ReplayController* r = asReplayController(dev);
  std::int64_t time = 0;
  const ControllerFrame* f = r->stream.playing(now, time);
  if (!f) return DM_DEVICE_ERROR_LOST;  // end of stream
  *s = DmControllerState{};
  s->time_ns = time;
  for (int i = 0; i < DM_CONTROLLER_AXES; ++i) s->axes[i] = f->axes[i];
  s->buttons[0] = f->buttons[0];
  s->buttons[1] = f->buttons[1];
  return DM_DEVICE_OK;
}

const DmControllerVTable kReplayController = {controllerOpen, dm::driver::closeReplay<ReplayController>,
                                              controllerInfo, controllerRead, nullptr};

int controllerInit(const DmHostApi* host) {
  return host->register_factory(host->ctx, DM_CONTROLLER_KIND, "replay-controller",
                                DM_CONTROLLER_KIND_ABI_VERSION, &kReplayController);
}

const DmPluginInfo kReplayControllerInfo = {DM_PLUGIN_ABI_VERSION, "replay-controller", "1.0", controllerInit,
                                            nullptr};

}  // namespace

#if defined(DM_DRIVER_PLUGIN)
DM_PLUGIN_ENTRY { return &kReplayControllerInfo; }
#else
extern "C" const DmPluginInfo* dm_builtin_entry_replay_controller(void) { return &kReplayControllerInfo; }
#endif
