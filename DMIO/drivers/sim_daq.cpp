// sim-daq — a simulated data-acquisition board (kind "daq"): a signal
// generator per channel, sampled at a fixed rate on the host's clock.
//
// Frame k is sampled at host time t_k = round(k · 1e9 / rate) ns; channel c
// of it is clamp(signal_c(t_k) + noise, -range, range), the noise Gaussian
// (seeded: lockstep runs repeat bit for bit). Acquisition starts at the
// first read_frames call: frames k with t_k at or after its now_ns. Like a
// real board the device buffers at most `fifo` frames between reads; older
// frames are dropped and reported as overrun. During a loss window (drop_at,
// reconnect_at) nothing is acquired; the frames missed are reported as
// overrun after the reconnection, so the index gap matches the count.
//
// Parameters (all optional):
//   channels  1..16                                                (4)
//   rate      frames per second, 1..1e6                            (1000)
//   fifo      frames the device buffers, 1..1e7                    (4096)
//   ch0 … ch15  "shape[,amplitude[,frequency[,offset]]]" V, Hz     (sine,1,c+1,0)
//   noise     V, standard deviation                                (0)
//   seed      integer, noise generator                             (1)
//   range     V: samples are clipped to [-range, range]            (10)
//   drop_at, reconnect_at  s (-1: never)
//
// Built into DM::IO and, with DM_DRIVER_PLUGIN, as libdm_driver_sim_daq.so.
#include <dm/core/plugin_abi.h>
#include <dm/io/device_abi.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <new>
#include <random>

#include "driver_params.hpp"
#include "sim_signal.hpp"

namespace {

using dm::driver::ParamReader;
using dm::driver::Signal;

// One instance; DmDevice* is this type behind the C boundary.
struct SimDaq {
  Signal channels[DM_DAQ_MAX_CHANNELS];
  unsigned channelCount = 4, fifo = 4096;
  double rate = 1000.0, noise = 0.0, range = 10.0;
  unsigned long long seed = 1;
  std::mt19937_64 rng;
  std::normal_distribution<double> gauss{0.0, 1.0};
  dm::driver::LossWindow loss;
  bool started = false;
  std::uint64_t next = 0;     // index of the next frame to hand over
  std::uint64_t overrun = 0;  // frames dropped since the previous read

  std::int64_t timeNs(std::uint64_t k) const noexcept {
    return static_cast<std::int64_t>(std::llround(static_cast<double>(k) * 1e9 / rate));
  }
  // The first index whose time is ≥ now.
  std::uint64_t firstAtOrAfter(std::int64_t now) const noexcept {
    if (now <= 0) return 0;
    auto k = static_cast<std::uint64_t>(std::ceil(static_cast<double>(now) * rate / 1e9));
    while (k > 0 && timeNs(k - 1) >= now) --k;
    while (timeNs(k) < now) ++k;
    return k;
  }
};

SimDaq* asSimDaq(DmDevice* d) { return reinterpret_cast<SimDaq*>(d); }

DmDevice* daqOpen(const DmDeviceParam* params, size_t count, char* error, size_t errorSize) {
  ParamReader r(params, count, error, errorSize);
  r.onlyKnown({"channels", "rate", "fifo", "ch0",   "ch1",  "ch2",   "ch3",     "ch4",
               "ch5",      "ch6",  "ch7",  "ch8",   "ch9",  "ch10",  "ch11",    "ch12",
               "ch13",     "ch14", "ch15", "noise", "seed", "range", "drop_at", "reconnect_at"});
  SimDaq* d = new (std::nothrow) SimDaq();
  if (!d) {
    r.failf("out of memory");
    return nullptr;
  }
  d->channelCount = dm::driver::wholeNumber(r, "channels", 4, 1, DM_DAQ_MAX_CHANNELS);
  d->rate = r.number("rate", 1000.0, 1.0, 1e6);
  d->fifo = dm::driver::wholeNumber(r, "fifo", 4096, 1, 10'000'000);
  for (unsigned c = 0; c < DM_DAQ_MAX_CHANNELS; ++c) {
    char key[8];
    std::snprintf(key, sizeof key, "ch%u", c);
    d->channels[c] = Signal{Signal::kSine, 1.0, static_cast<double>(c + 1), 0.0};
    dm::driver::readSignal(r, key, d->channels[c]);
    if (r.ok() && c >= d->channelCount && r.find(key))
      r.failf("parameter '%s': the board has only %u channels (parameter 'channels')", key, d->channelCount);
  }
  d->noise = r.number("noise", 0.0, 0.0, 1e3);
  d->seed = static_cast<unsigned long long>(r.number("seed", 1.0, 0.0, 9007199254740992.0));
  d->range = r.number("range", 10.0, 1e-9, 1e6);
  d->loss.read(r);
  if (!r.ok()) {
    delete d;
    return nullptr;
  }
  d->rng.seed(d->seed);
  return reinterpret_cast<DmDevice*>(d);
}

void daqClose(DmDevice* d) { delete asSimDaq(d); }

int daqInfo(DmDevice* dev, DmDaqInfo* info) {
  SimDaq* d = asSimDaq(dev);
  *info = DmDaqInfo{};
  dm::driver::simIdentity(info->identity, "sim-daq", "simulated signal generator", d->seed);
  info->capabilities = DM_DAQ_CAP_ANALOG_IN | DM_DAQ_CAP_RECONNECT;
  info->channel_count = d->channelCount;
  info->sample_rate_hz = d->rate;
  info->range_min = -d->range;
  info->range_max = d->range;
  info->fifo_frames = d->fifo;
  return DM_DEVICE_OK;
}

int daqRead(DmDevice* dev, int64_t now, double* samples, int64_t* times, size_t maxFrames,
            DmDaqBlock* block) {
  SimDaq* d = asSimDaq(dev);
  *block = DmDaqBlock{};
  if (d->loss.lostAt(now)) return DM_DEVICE_ERROR_LOST;
  if (!d->started) {
    d->started = true;
    d->next = d->firstAtOrAfter(now);
  }
  // Frames with time ≤ now are acquired; the FIFO keeps the newest `fifo`.
  const std::uint64_t end = d->firstAtOrAfter(now + 1);  // one past the last acquired frame
  if (end > d->next + d->fifo) {
    d->overrun += end - d->fifo - d->next;
    d->next = end - d->fifo;
  }
  const std::uint64_t n = std::min<std::uint64_t>(end > d->next ? end - d->next : 0, maxFrames);
  block->frames = static_cast<size_t>(n);
  block->first_index = d->next;
  block->overrun_frames = d->overrun;
  d->overrun = 0;
  for (std::uint64_t f = 0; f < n; ++f) {
    const std::int64_t tk = d->timeNs(d->next + f);
    times[f] = tk;
    const double t = 1e-9 * static_cast<double>(tk);
    for (unsigned c = 0; c < d->channelCount; ++c) {
      double x = d->channels[c].at(t);
      if (d->noise > 0.0) x += d->noise * d->gauss(d->rng);
      samples[f * d->channelCount + c] = std::clamp(x, -d->range, d->range);
    }
  }
  d->next += n;
  return DM_DEVICE_OK;
}

int daqReconnect(DmDevice* dev, int64_t now) {
  SimDaq* d = asSimDaq(dev);
  const bool wasLost = d->loss.lost;
  const int rc = d->loss.reconnect(now);
  if (rc == DM_DEVICE_OK && wasLost && d->started) {
    // Acquisition resumes now; what was missed is reported as overrun.
    const std::uint64_t resume = d->firstAtOrAfter(now);
    if (resume > d->next) {
      d->overrun += resume - d->next;
      d->next = resume;
    }
  }
  return rc;
}

const DmDaqVTable kSimDaq = {daqOpen, daqClose, daqInfo, daqRead, daqReconnect};

int daqInit(const DmHostApi* host) {
  return host->register_factory(host->ctx, DM_DAQ_KIND, "sim-daq", DM_DAQ_KIND_ABI_VERSION, &kSimDaq);
}

const DmPluginInfo kSimDaqInfo = {DM_PLUGIN_ABI_VERSION, "sim-daq", "1.0", daqInit, nullptr};

}  // namespace

#if defined(DM_DRIVER_PLUGIN)
DM_PLUGIN_ENTRY { return &kSimDaqInfo; }
#else
extern "C" const DmPluginInfo* dm_builtin_entry_sim_daq(void) { return &kSimDaqInfo; }
#endif
