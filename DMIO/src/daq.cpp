// Daq: a "daq" driver drained into a fixed frame ring with overrun
// accounting and loss/reconnection events (see dm/io/daq.hpp).
#include <dm/io/daq.hpp>

#include <algorithm>
#include <cmath>

#include "device_open.hpp"

namespace dm {

namespace {
constexpr std::size_t kChunkFrames = 256;  // frames per driver call
constexpr int kMaxCallsPerAcquire = 1
                                    << 16;  // 16 M frames: a driver that never runs dry cannot hang acquire()
}  // namespace

Result<std::unique_ptr<Daq>> Daq::open(const FactoryRegistry& registry, std::string_view driver,
                                       const DeviceParams& params, const DaqOptions& options) {
  auto found =
      detail::findDeviceVTable<DmDaqVTable>(registry, DM_DAQ_KIND, DM_DAQ_KIND_ABI_VERSION, "daq", driver);
  if (!found) return std::move(found).error();
  const DmDaqVTable* vt = found->vt;
  if (!vt || !vt->open || !vt->close || !vt->get_info || !vt->read_frames)
    return detail::nullFunctionError(found->where, "open, close, get_info and read_frames");
  if (!(options.reconnectIntervalSeconds >= 0.0))
    return fail(ErrorCode::InvalidArgument, "reconnectIntervalSeconds is negative or NaN", found->where,
                "use a time ≥ 0 s");
  auto dev = detail::openDeviceInstance(vt->open, params, found->where);
  if (!dev) return std::move(dev).error();

  std::unique_ptr<Daq> d(new Daq());
  d->vt_ = vt;
  d->device_ = *dev;
  d->keepAlive_ = found->keepAlive;
  d->link_.setInterval(options.reconnectIntervalSeconds);
  DmDaqInfo ci{};
  if (vt->get_info(*dev, &ci) != DM_DEVICE_OK)
    return fail(ErrorCode::Device, "get_info failed", found->where, "check the device connection");
  if (ci.channel_count < 1 || ci.channel_count > kDaqMaxChannels || !(ci.sample_rate_hz > 0.0) ||
      !std::isfinite(ci.sample_rate_hz) || !(ci.range_max > ci.range_min) || !std::isfinite(ci.range_min) ||
      !std::isfinite(ci.range_max))
    return fail(ErrorCode::Device, "driver reports nonsensical info (channel count, sample rate or range)",
                found->where, "a driver reports 1..16 channels, a positive rate and range_min < range_max");
  d->info_ = {toDeviceIdentity(ci.identity),
              ci.capabilities,
              ci.channel_count,
              ci.sample_rate_hz,
              ci.range_min,
              ci.range_max,
              ci.fifo_frames};
  d->samples_.assign(kChunkFrames * ci.channel_count, 0.0);
  d->times_.assign(kChunkFrames, 0);
  return d;
}

Daq::~Daq() {
  if (vt_ && device_) vt_->close(device_);
}

DeviceStatus Daq::acquire(std::int64_t nowNs) noexcept {
  if (!link_.connectedForPoll()) {
    if (!vt_->reconnect || !link_.reconnectDue(nowNs) || vt_->reconnect(device_, nowNs) != DM_DEVICE_OK)
      return DeviceStatus::Lost;
    link_.reconnected(nowNs);
  }
  const std::size_t channels = info_.channelCount;
  DeviceStatus status = DeviceStatus::Ok;
  for (int call = 0; call < kMaxCallsPerAcquire; ++call) {
    DmDaqBlock block{};
    const int rs = vt_->read_frames(device_, nowNs, samples_.data(), times_.data(), kChunkFrames, &block);
    if (rs == DM_DEVICE_ERROR_LOST) {
      link_.lost(nowNs);
      return DeviceStatus::Lost;
    }
    if (rs != DM_DEVICE_OK || block.frames > kChunkFrames) {
      link_.ioError();
      return DeviceStatus::IoError;
    }
    if (block.overrun_frames) deviceOverrun_.fetch_add(block.overrun_frames, std::memory_order_relaxed);
    std::uint64_t pushed = 0;
    for (std::size_t f = 0; f < block.frames; ++f) {
      DaqFrame frame;
      frame.timeNs = times_[f];
      frame.index = block.first_index + f;
      const double* src = samples_.data() + f * channels;
      bool finite = true;
      for (std::size_t c = 0; c < channels; ++c) {
        frame.values[c] = src[c];
        finite = finite && std::isfinite(src[c]);
      }
      if (!finite) {
        // A corrupt sample is dropped like a lost one, so the gap shows.
        ringOverrun_.fetch_add(1, std::memory_order_relaxed);
        status = DeviceStatus::IoError;
        continue;
      }
      if (ring_->tryPush(frame))
        ++pushed;
      else
        ringOverrun_.fetch_add(1, std::memory_order_relaxed);
    }
    acquired_.fetch_add(pushed, std::memory_order_relaxed);
    if (block.frames < kChunkFrames) break;
  }
  if (status == DeviceStatus::IoError) link_.ioError();
  return status;
}

DaqReadResult Daq::read(std::span<DaqFrame> out) noexcept {
  DaqReadResult r;
  while (r.frames < out.size() && ring_->tryPop(out[r.frames])) ++r.frames;
  read_.fetch_add(r.frames, std::memory_order_relaxed);
  const std::uint64_t lost =
      deviceOverrun_.load(std::memory_order_relaxed) + ringOverrun_.load(std::memory_order_relaxed);
  r.overrunFrames = lost - overrunReported_;
  overrunReported_ = lost;
  return r;
}

DaqCounters Daq::counters() const noexcept {
  DaqCounters c;
  c.device = link_.counters();
  c.acquiredFrames = acquired_.load(std::memory_order_relaxed);
  c.deviceOverrunFrames = deviceOverrun_.load(std::memory_order_relaxed);
  c.ringOverrunFrames = ringOverrun_.load(std::memory_order_relaxed);
  c.readFrames = read_.load(std::memory_order_relaxed);
  return c;
}

}  // namespace dm
