// replay-daq — plays the DAQ blocks of a recording (dm/io/recorder.hpp,
// DeviceRecorder::pushDaqFrames) back as a data-acquisition board (kind
// "daq").
//
// Parameters (see replay_common.hpp): file (required), rate, loop, strict.
// Every recorded block must have the same channel count. The first
// read_frames call maps host time to the first frame; frame k then plays at
// host time start + (t_k − first) / rate and is handed over by the first
// read_frames call at or after that time, stamped with it (at rate 1 with
// the recording's start time, exactly the recorded timestamps). Acquisition
// indices and overruns are the recorded ones: a call stops at an index gap,
// so the next call starts with the frame after the gap and reports the
// frames the recording lost there. Looping, cycle c adds c · (index span +
// 1) to the indices. End of stream: without loop, the call after the last
// frame was handed over reports DM_DEVICE_ERROR_LOST (the Daq queues a Lost
// event); there is no reconnect. Sample rate reported: frames per second of
// host time; range: the recorded samples' extent.
//
// Built into DM::IO and, with DM_DRIVER_PLUGIN, as libdm_driver_replay_daq.so.
#include <dm/core/plugin_abi.h>
#include <dm/io/device_abi.h>

#include <vector>

#include "replay_common.hpp"

namespace {

using dm::driver::ParamReader;

struct DaqFrame {
  std::int64_t t;
  std::uint64_t index;
  std::uint64_t overrun;  // frames the recording lost just before this one
  double values[DM_DAQ_MAX_CHANNELS];
};

// One instance; DmDevice* is this type behind the C boundary.
struct ReplayDaq {
  dm::driver::ReplayStream<DaqFrame> stream;
  std::uint32_t channels = 0;
  double rangeMin = 0.0, rangeMax = 0.0;
  std::size_t next = 0;    // next frame to hand over
  std::int64_t cycle = 0;  // loop cycle of frames[next]
  std::uint64_t indexPeriod = 1;
};

ReplayDaq* asReplayDaq(DmDevice* d) { return reinterpret_cast<ReplayDaq*>(d); }

std::string decodeBlock(const dm::record::RecordView& v, std::vector<DaqFrame>& frames,
                        std::uint32_t& channels) {
  dm::record::DaqBlockView b;
  std::string why = dm::record::parseDaqBlock(v.payload, v.size, b);
  if (!why.empty()) return why;
  if (channels && b.channels != channels)
    return "block of " + std::to_string(b.channels) + " channels after blocks of " + std::to_string(channels);
  channels = b.channels;
  for (std::uint32_t f = 0; f < b.frames; ++f) {
    DaqFrame fr{};
    fr.t = b.time(f);
    fr.index = b.index(f);
    fr.overrun = f == 0 ? b.overrun : 0;
    b.values(f, fr.values);
    frames.push_back(fr);
  }
  return why;
}

DmDevice* replayDaqOpen(const DmDeviceParam* params, size_t count, char* error, size_t errorSize) {
  return dm::driver::openReplay<ReplayDaq>(
      params, count, error, errorSize, {"file", "rate", "loop", "strict"},
      [](ReplayDaq& r, const dm::driver::ReplayOptions& o, ParamReader& p) {
        const bool loaded =
            r.stream.load(o, dm::record::kDaqBlock, 0, "DAQ-block", p,
                          [&](const dm::record::RecordView& v, std::vector<DaqFrame>& frames) {
                            return decodeBlock(v, frames, r.channels);
                          });
        if (!loaded) return;
        const auto& fr = r.stream.frames;
        r.rangeMin = r.rangeMax = fr.front().values[0];
        for (const DaqFrame& f : fr)
          for (std::uint32_t c = 0; c < r.channels; ++c) {
            r.rangeMin = std::min(r.rangeMin, f.values[c]);
            r.rangeMax = std::max(r.rangeMax, f.values[c]);
          }
        if (!(r.rangeMax > r.rangeMin)) {  // a constant signal: still a valid range
          r.rangeMin -= 1.0;
          r.rangeMax += 1.0;
        }
        const std::uint64_t lo = fr.front().index, hi = fr.back().index;
        r.indexPeriod = hi >= lo ? hi - lo + 1 : 1;
        // Frames lost while recording still took their time: the loop
        // period and the rate count acquisition indices, not frames kept.
        r.stream.clock.configure(o, fr.front().t, fr.back().t, static_cast<std::size_t>(r.indexPeriod));
      });
}

int replayDaqInfo(DmDevice* dev, DmDaqInfo* info) {
  ReplayDaq* r = asReplayDaq(dev);
  const auto& fr = r->stream.frames;
  *info = DmDaqInfo{};
  dm::driver::replayIdentity(info->identity, "replay-daq", "DAQ stream", r->stream.source);
  info->capabilities = DM_DAQ_CAP_ANALOG_IN;
  info->channel_count = r->channels;
  info->sample_rate_hz = r->stream.clock.eventRate(static_cast<double>(r->indexPeriod), 1000.0);
  info->range_min = r->rangeMin;
  info->range_max = r->rangeMax;
  info->fifo_frames = fr.size();
  return DM_DEVICE_OK;
}

int replayDaqRead(DmDevice* dev, int64_t now, double* samples, int64_t* times, size_t maxFrames,
                  DmDaqBlock* block) {
  ReplayDaq* r = asReplayDaq(dev);
  const auto& fr = r->stream.frames;
  dm::driver::ReplayClock& clock = r->stream.clock;
  clock.start(now);
  *block = DmDaqBlock{};
  std::size_t n = 0;
  while (n < maxFrames) {
    if (r->next == fr.size()) {
      if (!clock.loop()) break;
      r->next = 0;
      ++r->cycle;
    }
    const DaqFrame& f = fr[r->next];
    const std::int64_t t = clock.hostTime(f.t, r->cycle);
    if (t > now) break;
    const std::uint64_t index = f.index + static_cast<std::uint64_t>(r->cycle) * r->indexPeriod;
    if (n > 0 && index != block->first_index + n) break;  // a gap starts the next call
    if (n == 0) {
      block->first_index = index;
      block->overrun_frames = r->cycle == 0 || r->next > 0 ? f.overrun : 0;
    }
    times[n] = t;
    for (std::uint32_t c = 0; c < r->channels; ++c) samples[n * r->channels + c] = f.values[c];
    ++n;
    ++r->next;
  }
  block->frames = n;
  if (n == 0 && r->next == fr.size() && !clock.loop()) return DM_DEVICE_ERROR_LOST;  // end of stream
  return DM_DEVICE_OK;
}

const DmDaqVTable kReplayDaq = {replayDaqOpen, dm::driver::closeReplay<ReplayDaq>, replayDaqInfo,
                                replayDaqRead, nullptr};

int replayDaqInit(const DmHostApi* host) {
  return host->register_factory(host->ctx, DM_DAQ_KIND, "replay-daq", DM_DAQ_KIND_ABI_VERSION, &kReplayDaq);
}

const DmPluginInfo kReplayDaqInfo = {DM_PLUGIN_ABI_VERSION, "replay-daq", "1.0", replayDaqInit, nullptr};

}  // namespace

#if defined(DM_DRIVER_PLUGIN)
DM_PLUGIN_ENTRY { return &kReplayDaqInfo; }
#else
extern "C" const DmPluginInfo* dm_builtin_entry_replay_daq(void) { return &kReplayDaqInfo; }
#endif
