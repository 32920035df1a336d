// dm/io/daq.hpp — data acquisition boards behind the driver ABI (kind
// "daq", see DmDaqVTable).
//
// A DAQ samples `channelCount` channels together at `sampleRateHz`; one
// sample of every channel is a frame, with its acquisition index (0, 1, 2,
// … since the start) and its timestamp on the host's loop clock. Buffered
// acquisition runs in two stages:
//
//   device FIFO ── acquire(t) ──▶ [fixed ring of 8192 frames] ── read(out) ──▶ consumer
//   (acquisition thread)                                      (consumer thread)
//
// acquire() moves every frame the device has acquired up to t into the
// ring; read() hands the consumer the oldest frames. Frames are lost in two
// places, and both are counted and reported, never hidden: the device drops
// frames when acquire() runs too rarely (its FIFO overflows), and acquire()
// drops the newest frames when the consumer falls behind and the ring is
// full. read() returns how many frames were lost since the previous read();
// a gap in the frame indices shows where. acquire() and read() are
// real-time safe (no allocation, lock or throw).
//
// Driver: "sim-daq" (signal generator per channel with seeded noise), see
// dm/io/drivers.hpp.
//
// @code
//   auto daq = dm::Daq::open(registry, "sim-daq", {{"channels", "2"}, {"rate", "1000"}});
//   (*daq)->acquire(nowNs);                                       // acquisition thread
//   std::array<dm::DaqFrame, 64> f; auto got = (*daq)->read(f);   // consumer: got.frames, got.overrunFrames
// @endcode
#pragma once

#include <dm/core/plugin.hpp>
#include <dm/core/result.hpp>
#include <dm/core/ring.hpp>
#include <dm/io/device.hpp>

#include <array>
#include <atomic>
#include <cstdint>
#include <memory>
#include <span>
#include <string_view>
#include <vector>

namespace dm {

/// Most channels of a DAQ (DM_DAQ_MAX_CHANNELS).
inline constexpr std::size_t kDaqMaxChannels = DM_DAQ_MAX_CHANNELS;
/// Frames the ring between acquire() and read() holds.
inline constexpr std::size_t kDaqRingFrames = 8192;

/// What an opened DAQ acquires.
struct DaqInfo {
  DeviceIdentity identity;
  std::uint32_t capabilities = 0;  ///< DM_DAQ_CAP_* bits
  std::uint32_t channelCount = 0;  ///< 1..16
  double sampleRateHz = 0.0;       ///< frames per second
  double rangeMin = 0.0;           ///< V
  double rangeMax = 0.0;           ///< V
  std::uint64_t fifoFrames = 0;    ///< frames the device buffers between acquire() calls
};

/// One sample of every channel.
struct DaqFrame {
  std::int64_t timeNs = 0;                       ///< host loop time of the sample
  std::uint64_t index = 0;                       ///< acquisition index (consecutive unless frames were lost)
  std::array<double, kDaqMaxChannels> values{};  ///< V; channels ≥ channelCount are 0
};

/// What read() returned.
struct DaqReadResult {
  std::size_t frames = 0;           ///< frames written to the front of `out`
  std::uint64_t overrunFrames = 0;  ///< frames lost (device FIFO or ring) since the previous read()
};

/// Running totals of a DAQ (monotone).
struct DaqCounters {
  DeviceCounters device;                  ///< acquire() calls, losses, reconnects, I/O errors
  std::uint64_t acquiredFrames = 0;       ///< frames put into the ring
  std::uint64_t deviceOverrunFrames = 0;  ///< frames the device dropped (its FIFO overflowed)
  std::uint64_t ringOverrunFrames = 0;    ///< frames dropped by acquire(): ring full, or a NaN/Inf sample
  std::uint64_t readFrames = 0;           ///< frames handed out by read()
};

/// Options of Daq::open.
struct DaqOptions {
  double reconnectIntervalSeconds = 0.1;  ///< minimum time between reconnect attempts
};

/// A DAQ; see the file comment. Not copyable or movable; owned through
/// unique_ptr (about 1.2 MiB: the ring, on the heap).
class Daq {
 public:
  /// Opens driver `driver` (kind "daq", ABI DM_DAQ_KIND_ABI_VERSION) of
  /// `registry` with `params`. Fails with NotFound, Version, InvalidArgument
  /// (the driver's message, naming the parameter) or Device (bad vtable,
  /// channel count outside 1..16, non-positive rate, empty range).
  static Result<std::unique_ptr<Daq>> open(const FactoryRegistry& registry, std::string_view driver,
                                           const DeviceParams& params = {}, const DaqOptions& options = {});
  ~Daq();
  Daq(const Daq&) = delete;
  Daq& operator=(const Daq&) = delete;

  /// Identity, capabilities, channels, rate, range and FIFO size.
  const DaqInfo& info() const noexcept { return info_; }

  /// Moves the frames acquired up to host time nowNs from the device into
  /// the ring (dropping and counting those that do not fit). Acquisition
  /// thread; real-time safe; O(frames). Lost while the device is away.
  DeviceStatus acquire(std::int64_t nowNs) noexcept;
  /// Copies the oldest frames into `out` (as many as fit and are there) and
  /// reports the frames lost since the previous read(). Consumer thread;
  /// real-time safe; O(out.size()).
  DaqReadResult read(std::span<DaqFrame> out) noexcept;
  /// The next Lost/Reconnected event, if any (consumer thread).
  bool pollEvent(DeviceEvent& event) noexcept { return link_.pollEvent(event); }
  /// False between a loss and the reconnection.
  bool connected() const noexcept { return link_.connected(); }
  /// Frame and device totals so far (any thread).
  DaqCounters counters() const noexcept;

 private:
  Daq() = default;
  const DmDaqVTable* vt_ = nullptr;
  DmDevice* device_ = nullptr;
  std::shared_ptr<const void> keepAlive_;
  DaqInfo info_;
  std::unique_ptr<SpscRing<DaqFrame, kDaqRingFrames>> ring_ =
      std::make_unique<SpscRing<DaqFrame, kDaqRingFrames>>();
  detail::DeviceLink link_;
  // acquisition thread: scratch for one driver call
  std::vector<double> samples_;
  std::vector<std::int64_t> times_;
  std::atomic<std::uint64_t> acquired_{0}, deviceOverrun_{0}, ringOverrun_{0}, read_{0};
  // consumer thread: overruns already reported
  std::uint64_t overrunReported_ = 0;
};

}  // namespace dm
