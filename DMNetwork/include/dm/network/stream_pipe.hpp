// dm/network/stream_pipe.hpp — an in-process link emulator: delay, jitter,
// loss, duplication and reordering between a sender and a receiver.
//
// For tests and tele-operation experiments: put a LinkEmulator between the
// code that sends packets and the callback that receives them (in the same
// process, e.g. in front of UdpEndpoint::send or a codec's input) and the
// receiver sees what a real network would do to them. Each submitted packet
// independently
//   * is lost with probability `lossProbability`;
//   * otherwise arrives after delay + jitter, where jitter >= 0 is uniform on
//     [0, jitter] or half-normal with scale `jitter` (|N(0, jitter²)|, capped
//     at 6 jitter), so `delay` is the minimum one-way latency;
//   * is held back by an extra `reorderDelay` with probability
//     `reorderProbability` (later packets overtake it);
//   * arrives twice with probability `duplicateProbability` (the copy draws
//     its own jitter).
// The random decisions come from a seeded generator in submission order, so
// for a given seed and submission sequence the fate of every packet is the
// same on every run and platform; the delivery instants follow the network
// thread's steady clock. Deliveries run on the network thread, never before
// their due time. The number of packets in flight is bounded.
//
// SteppedLinkEmulator draws the same fates (same options, same generator)
// on a clock its caller supplies: no thread and no timer; the receiver asks
// for what is due at its own time. That is the link of a lockstep run on
// the master engine's virtual clock, where every delivery instant must be
// the same on every run; it never allocates after create().
//
// @code
//   auto link = dm::LinkEmulator::create(net, {.delay = 20ms, .jitter = 5ms, .lossProbability = 0.01},
//                                        [&](std::span<const std::byte> p) { receiver.feed(p); });
//   (*link)->submit(packet);
// @endcode
#pragma once

#include <dm/core/result.hpp>
#include <dm/network/io_thread.hpp>

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>

namespace dm {

/// Distribution of the extra latency above the fixed delay.
enum class JitterModel : std::uint8_t {
  Uniform,     ///< uniform on [0, jitter]
  HalfNormal,  ///< |N(0, jitter²)|, capped at 6 jitter
};

/// Settings of a LinkEmulator. Probabilities are in [0, 1].
struct LinkEmulatorOptions {
  std::chrono::microseconds delay{0};   ///< minimum one-way latency (>= 0)
  std::chrono::microseconds jitter{0};  ///< scale of the extra latency (>= 0)
  JitterModel jitterModel = JitterModel::Uniform;
  double lossProbability = 0.0;                  ///< chance a packet never arrives
  double duplicateProbability = 0.0;             ///< chance a delivered packet arrives twice
  double reorderProbability = 0.0;               ///< chance a packet is held back by reorderDelay
  std::chrono::microseconds reorderDelay{1000};  ///< extra delay of a held-back packet (>= 0)
  std::uint64_t seed = 1;                        ///< generator seed
  std::size_t maxInFlight = 4096;                ///< packets waiting for delivery; more are refused (Busy)
  std::size_t maxPacketBytes = 65536;            ///< larger packets are refused (InvalidArgument)
};

/// Counters of a LinkEmulator since creation.
struct LinkEmulatorStats {
  std::uint64_t submitted = 0;   ///< packets accepted by submit()
  std::uint64_t lost = 0;        ///< dropped by the loss draw
  std::uint64_t duplicated = 0;  ///< extra copies scheduled
  std::uint64_t reordered = 0;   ///< packets held back by reorderDelay
  std::uint64_t delivered = 0;   ///< deliveries made (copies included)
  std::uint64_t refused = 0;     ///< submit() calls refused (Busy or too large)
  std::uint64_t discarded = 0;   ///< scheduled deliveries dropped by close()
  std::uint64_t inFlight = 0;    ///< deliveries scheduled and not yet made (0: every counter is final)
};

/// Emulates a lossy, late, reordering link in front of a receiver callback.
class LinkEmulator {
 public:
  /// Receives a delivered packet on the network thread; must not block.
  using Deliver = std::function<void(std::span<const std::byte>)>;

  /// Fails with InvalidArgument for a negative time, a probability outside
  /// [0, 1] or a zero limit (the `where` names the field).
  /// @code
  ///   auto link = dm::LinkEmulator::create(net, {.lossProbability = 0.1, .seed = 7}, deliver);
  ///   if (!link) return link.error();
  /// @endcode
  static Result<std::unique_ptr<LinkEmulator>> create(IoThread& thread, LinkEmulatorOptions options,
                                                      Deliver deliver);
  /// close(), then release.
  ~LinkEmulator();
  LinkEmulator(const LinkEmulator&) = delete;
  LinkEmulator& operator=(const LinkEmulator&) = delete;

  /// Copies `packet`, draws its fate and schedules its deliveries. Busy when
  /// maxInFlight deliveries are pending, InvalidArgument above
  /// maxPacketBytes, Network after close(). Any thread; O(log inFlight +
  /// packet size); allocates.
  Status submit(std::span<const std::byte> packet);
  /// Stops: pending deliveries are discarded and counted (stats().discarded);
  /// no delivery runs after it returns. Idempotent.
  void close();
  LinkEmulatorStats stats() const;

  struct Impl;

 private:
  explicit LinkEmulator(std::shared_ptr<Impl> impl);
  std::shared_ptr<Impl> impl_;
};

/// The LinkEmulator's link on a caller's clock (see the file comment): the
/// sender submits at its time, the receiver pops what is due by its time,
/// earliest due first (ties in submission order). One thread, or a sender
/// and a receiver that the caller keeps apart; real-time safe after
/// create() (fixed slots of maxPacketBytes, maxInFlight of them).
///
/// @code
///   auto link = dm::SteppedLinkEmulator::create({.delay = 10ms, .lossProbability = 0.01, .seed = 3});
///   (*link)->submit(packet, clock.now());
///   std::span<const std::byte> p;
///   while ((*link)->popDue(clock.now(), p)) receiver.feed(p);
/// @endcode
class SteppedLinkEmulator {
 public:
  /// Fails as LinkEmulator::create, and when maxInFlight × maxPacketBytes,
  /// allocated here, is over 64 MiB (the defaults are: lower maxPacketBytes).
  static Result<std::unique_ptr<SteppedLinkEmulator>> create(LinkEmulatorOptions options);
  ~SteppedLinkEmulator();
  SteppedLinkEmulator(const SteppedLinkEmulator&) = delete;
  SteppedLinkEmulator& operator=(const SteppedLinkEmulator&) = delete;

  /// Copies `packet` sent at `nowNs` and draws its fate. False (counted as
  /// refused) when it exceeds maxPacketBytes or every slot is in flight.
  /// O(log inFlight + packet size).
  bool submit(std::span<const std::byte> packet, std::int64_t nowNs) noexcept;
  /// The next packet due at or before `nowNs`, removed from the link; the
  /// span stays valid until the next call. False when none is due.
  bool popDue(std::int64_t nowNs, std::span<const std::byte>& packet) noexcept;
  LinkEmulatorStats stats() const noexcept;

  struct Impl;

 private:
  explicit SteppedLinkEmulator(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace dm
