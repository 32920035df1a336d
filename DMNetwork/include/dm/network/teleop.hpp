// dm/network/teleop.hpp — the tele-operation device stream: a haptic device's
// state one way and force the other, over UDP at the servo rate (1 kHz).
//
// Two ends, each a UDP socket with a receive thread of its own (blocking in
// recvfrom: the stream's latency budget is below what a shared event loop
// gives, see docs/performance.md):
//
//   device side (console, device attached)          host side (simulation)
//   TeleopDevice::sendState(state)  ── State ──▶    TeleopHost::latestState()
//   TeleopDevice::latestForce()     ◀── Force ──    TeleopHost::sendForce(force)
//   answers Hello with Info         ◀── Hello ──    TeleopHost::waitForDevice()
//   sendWave / popWave              ◀── Wave ──▶    sendWave / popWave (WaveSamples, either way)
//
// Every datagram is one DMPlatform message (dm/network/message.hpp: sequence
// number, send timestamp, CRC-32C) with a fixed little-endian payload, see
// docs/network.md. Receiving (receive thread): a datagram that does not
// decode, has the wrong size, non-finite values or comes from a peer that is
// not allowed is dropped, counted and logged (rate limited). Sequence numbers
// are classified per stream by dm::SequenceTracker: duplicates and stale
// ones are dropped, a late one (reordered) is counted and used for timing
// but never replaces the newer value, gaps count as loss.
//
// Timing: each State and Force carries an echo of the newest message
// received from the peer (its send timestamp) and how long this side held
// it before sending (NTP's four timestamps). Each side therefore measures
//  * round trip = (now − echo) − hold, on its own clock alone;
//  * the peer's clock offset, from the echo of the fastest round trip of
//    the last 16 (NTP's clock filter), or 0 with clocksSynchronized (same
//    host, PTP);
//  * one-way latency = receive time − (peer send time − offset);
//  * interarrival jitter as RFC 3550 §6.4.1 defines it (J += (|D| − J)/16);
//  * loss = sequence numbers never received / expected.
// Latency percentiles come from dm::LatencyHistogram (within 1.6 %),
// allocation free.
//
// Real-time rules: sendState/sendForce build the datagram on the stack and
// hand it to the kernel with one non-blocking sendto (no allocation, lock,
// log or throw; a full socket buffer drops the datagram and counts it).
// latestState/latestForce read a dm::TripleBuffer: call each from one thread
// (the servo thread). stats(), waitForDevice(), close() are not real-time.
//
// In-process links: an address "inproc:NAME" (the device's `local`, the
// host's `peer`) joins the two ends inside one process through a pair of
// lock-free queues instead of a socket, on a dm::Clock the device side
// names (TeleopOptions::clock: the master engine's virtual clock in a
// lockstep run, the wall clock by default). No thread delivers: each end's
// poll(), called by its servo thread before it reads, takes what arrived,
// passes it through a dm::SteppedLinkEmulator when `emulate` is set (the same
// seeded fates as LinkEmulator, due on the link's clock) and handles what is
// due. With a virtual clock every delivery instant, and so every force, is
// the same on every run. The host learns its device's Info from the link
// (waitForDevice needs no round trip); the device learns its host from the
// Hello as over UDP. A name has one device and at most one host at a time.
//
// Safety: the device side reports the age of the newest force; its bridge
// (TeleopDeviceBridge) outputs zero when no force arrived within the timeout,
// so a lost link never leaves a force on the operator.
//
// @code
//   auto dev = dm::TeleopDevice::open({.local = {"0.0.0.0", 47000}}, device.info());   // console
//   auto host = dm::TeleopHost::open({.peer = {"192.168.1.20", 47000}});             // simulator
//   auto info = (*host)->waitForDevice(std::chrono::seconds(2));
//   dm::HapticState s;  std::int64_t age;
//   if ((*host)->latestState(s, &age)) (*host)->sendForce({.force = f});   // servo thread
// @endcode
#pragma once

#include <dm/core/clock.hpp>
#include <dm/core/result.hpp>
#include <dm/io/haptic_device.hpp>
#include <dm/network/io_thread.hpp>  // SocketAddress
#include <dm/network/message.hpp>
#include <dm/network/stream_pipe.hpp>
#include <dm/network/wave_variables.hpp>

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

namespace dm {

// ---- wire format ------------------------------------------------------------

/// Message types of the stream (the DMPlatform message model's `type`).
inline constexpr std::uint16_t kTeleopStateType = 0x7401;  ///< device → host: HapticState
inline constexpr std::uint16_t kTeleopForceType = 0x7402;  ///< host → device: HapticOutput
inline constexpr std::uint16_t kTeleopHelloType = 0x7403;  ///< host → device: start streaming to me
inline constexpr std::uint16_t kTeleopInfoType = 0x7404;   ///< device → host: HapticInfo
inline constexpr std::uint16_t kTeleopWaveType = 0x7405;   ///< either way: a WaveSample
inline constexpr std::uint32_t kTeleopVersion = 1;         ///< payload layout version (Hello)

/// Payload sizes (bytes after the 28-byte message header).
inline constexpr std::size_t kTeleopStateBytes = 136;
inline constexpr std::size_t kTeleopForceBytes = 64;
inline constexpr std::size_t kTeleopHelloBytes = 4;
inline constexpr std::size_t kTeleopInfoBytes = 352;
inline constexpr std::size_t kTeleopWaveBytes = 40;
/// Largest datagram of the stream (an Info).
inline constexpr std::size_t kTeleopMaxDatagram = kMessageHeaderBytes + kTeleopInfoBytes;

/// The echo every State and Force carries (NTP-style timing).
struct TeleopEcho {
  std::int64_t peerSendNs = 0;  ///< send timestamp of the newest message received from the peer
  std::int64_t holdNs = -1;     ///< ns between receiving it and sending this one; < 0: nothing to echo
};

/// One decoded datagram of the stream; which fields hold depends on `type`.
struct TeleopPacket {
  MessageHeader header;
  TeleopEcho echo;     ///< State, Force
  HapticState state;   ///< State; state.timeNs is the device's sample time (device clock)
  HapticOutput force;  ///< Force
  HapticInfo info;     ///< Info
  WaveSample wave;     ///< Wave
  std::uint32_t version = 0;  ///< Hello
};

/// Writes one State datagram into `out` (≥ 28 + kTeleopStateBytes bytes);
/// returns the bytes written, 0 when `out` is too small. No allocation.
std::size_t writeTeleopState(const MessageHeader& header, const TeleopEcho& echo, const HapticState& state,
                             std::span<std::byte> out) noexcept;
/// Writes one Force datagram, as writeTeleopState.
std::size_t writeTeleopForce(const MessageHeader& header, const TeleopEcho& echo, const HapticOutput& force,
                             std::span<std::byte> out) noexcept;
/// Writes one Hello datagram, as writeTeleopState.
std::size_t writeTeleopHello(const MessageHeader& header, std::span<std::byte> out) noexcept;
/// Writes one Wave datagram, as writeTeleopState.
std::size_t writeTeleopWave(const MessageHeader& header, const WaveSample& wave, std::span<std::byte> out) noexcept;
/// Writes one Info datagram (strings truncated to 63 bytes), as writeTeleopState.
std::size_t writeTeleopInfo(const MessageHeader& header, const HapticInfo& info,
                            std::span<std::byte> out) noexcept;
/// writeTeleopInfo into a new buffer of the exact size.
std::vector<std::byte> encodeTeleopInfo(const MessageHeader& header, const HapticInfo& info);

/// Decodes and validates one datagram of the stream. Fails with Parse
/// (message model errors, unknown type, a payload size other than the type's,
/// non-finite values, a quaternion whose norm is not 1 within 1e-3, an
/// unterminated string, an empty workspace, a negative wave energy) or
/// Version (Hello of another
/// version), naming the field and its byte offset. No allocation on
/// success except for Info's strings. O(size).
Result<TeleopPacket> decodeTeleopPacket(std::span<const std::byte> datagram);

// ---- statistics -------------------------------------------------------------

/// A latency distribution in seconds (0 when count is 0).
struct LatencyStats {
  std::uint64_t count = 0;
  double last = 0, min = 0, mean = 0, p50 = 0, p99 = 0, p999 = 0, max = 0;
};

/// Live statistics of one end of the stream.
struct TeleopStats {
  std::uint64_t sent = 0;        ///< datagrams handed to the kernel
  std::uint64_t sendFailed = 0;  ///< refused: no peer yet, socket buffer full, unreachable
  std::uint64_t received = 0;    ///< stream messages accepted (State or Force)
  std::uint64_t malformed = 0;   ///< datagrams refused by decodeTeleopPacket
  std::uint64_t foreign = 0;     ///< datagrams from a peer not allowed, or of the other side's type
  std::uint64_t duplicates = 0, late = 0, stale = 0;  ///< see dm::Arrival
  std::uint64_t lost = 0;        ///< sequence numbers skipped and not (yet) arrived late
  std::uint64_t wavesIn = 0;     ///< Wave samples queued for popWave()
  std::uint64_t wavesDropped = 0;  ///< Wave samples dropped because popWave() fell 1024 behind
  double lossRatio = 0;          ///< lost / (lost + received − duplicates − stale)
  LatencyStats roundTrip;        ///< s
  LatencyStats oneWay;           ///< s, peer → us, corrected by clockOffset
  double jitter = 0;             ///< s, RFC 3550 interarrival jitter of the received stream
  double clockOffset = 0;        ///< s, peer clock − our clock (0 with clocksSynchronized)
  bool linkUp = false;           ///< as linkUp() of the end
  double sinceLastReceive = -1;  ///< s since the newest accepted message; < 0: none yet
};

// ---- the two ends -------------------------------------------------------------

/// Settings of either end.
struct TeleopOptions {
  /// Bind address; port 0 = ephemeral. Device: "inproc:NAME" (port
  /// ignored) opens the in-process link NAME instead of a socket.
  SocketAddress local{"127.0.0.1", 0};
  /// Host: the device's address (required), or "inproc:NAME" to join the
  /// in-process link a TeleopDevice opened; device: unused.
  SocketAddress peer;
  std::vector<std::string> allow;       ///< device: host addresses accepted (empty: any)
  double timeoutSeconds = 0.1;          ///< peer silent this long: link down (> 0)
  bool clocksSynchronized = false;      ///< one-way latency without offset estimation
  /// When set, every received datagram passes through an in-process
  /// dm::LinkEmulator (delay, jitter, loss, duplication, reordering) before
  /// it is handled: tele-operation under a bad link, on one machine.
  std::optional<LinkEmulatorOptions> emulate;
  /// In-process links only: the time base of stamps, ages, timeouts and
  /// emulated delays, which must outlive both ends (null: the monotonic wall
  /// clock). The device side sets it; a host takes its device's (naming
  /// another is an error). Sockets run on the wall clock: an error there.
  const Clock* clock = nullptr;
};

/// The simulation side: receives the device state, sends forces.
class TeleopHost {
 public:
  /// Binds `options.local`, fixes the peer and starts the receive thread.
  /// InvalidArgument for bad addresses or options, Network when binding fails.
  static Result<std::unique_ptr<TeleopHost>> open(TeleopOptions options);
  ~TeleopHost();
  TeleopHost(const TeleopHost&) = delete;
  TeleopHost& operator=(const TeleopHost&) = delete;

  /// Sends Hello every 50 ms until the device answers with its Info or
  /// `timeout` passes (Timeout error naming the peer). Not real-time.
  Result<HapticInfo> waitForDevice(std::chrono::milliseconds timeout);
  /// The Info the device sent last (empty before waitForDevice succeeded).
  std::optional<HapticInfo> deviceInfo() const;
  /// Real-time safe: sends one Force now; false when the kernel refused it.
  bool sendForce(const HapticOutput& force) noexcept;
  /// Real-time safe: sends one Hello now (e.g. to ask a restarted device to
  /// resume); false when the kernel refused it.
  bool sendHello() noexcept;
  /// Real-time safe: sends one wave sample (dm/network/wave_variables.hpp);
  /// false when the kernel refused it.
  bool sendWave(const WaveSample& wave) noexcept;
  /// Real-time safe, one reader thread: the next wave sample received, in
  /// arrival order (feed them to a WaveReceiver). False when none is queued.
  bool popWave(WaveSample& wave) noexcept;
  /// Real-time safe, one reader thread: the newest state; `ageNs` = ns since
  /// it arrived. False before the first state.
  bool latestState(HapticState& state, std::int64_t* ageNs = nullptr) noexcept;
  /// Real-time safe: a state arrived within the timeout.
  bool linkUp() const noexcept;
  /// Real-time safe, the reader thread: an in-process link's end handles
  /// the datagrams that arrived and are due now (call it before reading);
  /// a socket's receive thread needs none (no-op).
  void poll() noexcept;
  /// The end's time base (TeleopOptions::clock).
  const Clock& clock() const noexcept;
  /// True when the link runs on a clock its device end was given
  /// (TeleopOptions::clock: a lockstep run's virtual clock), which moves
  /// only as its owner advances it: a wait for the first state belongs in
  /// that run, not before it. False on the wall clock (every socket).
  bool onSuppliedClock() const noexcept;
  /// 0 for an in-process link.
  std::uint16_t port() const noexcept;
  TeleopStats stats() const;
  /// Stops the receive thread (within 20 ms); idempotent. Sends after it
  /// fail. Not from the servo thread.
  void close();

  struct Impl;

 private:
  explicit TeleopHost(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

/// The device side: sends the device state, receives forces. The host is
/// learned from its Hello or Force (and must be in `allow` when given); a
/// different host is adopted only after the current one fell silent for the
/// timeout.
class TeleopDevice {
 public:
  /// Binds `options.local` and starts the receive thread; `info` is what a
  /// Hello is answered with.
  static Result<std::unique_ptr<TeleopDevice>> open(TeleopOptions options, HapticInfo info);
  ~TeleopDevice();
  TeleopDevice(const TeleopDevice&) = delete;
  TeleopDevice& operator=(const TeleopDevice&) = delete;

  /// Real-time safe: sends one State to the host now; false when no host is
  /// known yet or the kernel refused it.
  bool sendState(const HapticState& state) noexcept;
  /// Real-time safe, one reader thread: the newest force; `ageNs` = ns
  /// since it arrived. False before the first force.
  bool latestForce(HapticOutput& force, std::int64_t* ageNs = nullptr) noexcept;
  /// As TeleopHost::sendWave / popWave.
  bool sendWave(const WaveSample& wave) noexcept;
  bool popWave(WaveSample& wave) noexcept;
  /// A host is known and a Force or Hello came from it within the timeout.
  bool linkUp() const noexcept;
  /// As TeleopHost::poll / clock / port.
  void poll() noexcept;
  const Clock& clock() const noexcept;
  std::uint16_t port() const noexcept;
  TeleopStats stats() const;
  void close();

  struct Impl;

 private:
  explicit TeleopDevice(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

/// Settings of a TeleopDeviceBridge.
struct TeleopBridgeOptions {
  double timeoutSeconds = 0.1;  ///< host silent this long: zero force
  /// > 0: wave-variable mode with this wave impedance b (N·s/m); the host
  /// (net-haptic with the same `wave_impedance`) must use the same b.
  double waveImpedance = 0.0;
  WaveLossPolicy wavePolicy = WaveLossPolicy::Hold;
};

/// Runs a local HapticDevice as the device side of a stream. Each step()
/// first polls the link, then:
///  * force mode: commands the newest force, or zero when none arrived
///    within the timeout (link lost), servos the device, sends its state;
///  * wave-variable mode (dm/network/wave_variables.hpp): the device is the
///    WaveMasterPort: it displays −(b·ẋm − √(2b)·v) for the backward waves v
///    received (zero while the host is silent), servos, and sends its state
///    and the forward wave u = √(2b)·ẋm − v. The wave period is the device's
///    servo period. With the host's matched WaveSlavePort the loop stays
///    stable under delay, jitter and loss.
/// step() is real-time safe; call it from the device's servo thread.
class TeleopDeviceBridge {
 public:
  TeleopDeviceBridge(HapticDevice& device, TeleopDevice& link, TeleopBridgeOptions options = {}) noexcept;
  /// One servo period at loop time `nowNs`. Returns the device's status.
  DeviceStatus step(std::int64_t nowNs) noexcept;
  /// Steps whose force was zeroed because the link was silent.
  std::uint64_t zeroedSteps() const noexcept { return zeroed_; }
  /// The force commanded to the device (N), low-passed with a time
  /// constant of kMeanForceSeconds: what a hand feels of a force that
  /// chatters from tick to tick (a wave receiver out of budget, a lost
  /// force). Read it from the servo thread or after the loop stopped.
  const Vec3& meanForce() const noexcept { return meanForce_; }
  static constexpr double kMeanForceSeconds = 0.1;
  /// The master port in wave-variable mode, otherwise null.
  const WaveMasterPort* wavePort() const noexcept { return wave_ ? &*wave_ : nullptr; }

 private:
  HapticDevice& device_;
  TeleopDevice& link_;
  std::int64_t timeoutNs_;
  std::uint64_t zeroed_ = 0;
  std::optional<WaveMasterPort> wave_;
  std::optional<std::int64_t> lastStepNs_;  ///< the previous step's time
  Vec3 meanForce_ = Vec3::Zero();
};

}  // namespace dm
