// dm/io/haptic_device.hpp — a haptic device behind the driver ABI, made safe.
//
// HapticDevice opens a driver of kind "haptic-device" (a plugin loaded by
// dm::PluginLinker, or a built-in driver, see dm/io/drivers.hpp) and stands
// between the application's haptic loop and the device:
//
//   haptic loop ── command(force, torque, t) ──▶ [triple buffer] ──▶ servo(t) ──▶ driver
//   consumers   ◀── state() / pollEvent()    ◀── [triple buffer, ring] ◀──┘
//
// servo() runs at the device's servo rate (on its own real-time thread, or
// stepped by the engine in lockstep). It samples the device and sends the
// latest command after making it safe:
//  * NaN or Inf in a command → the command counts as zero (and is counted);
//  * force and torque are clamped to the device's limits (and an optional
//    lower application limit), keeping their direction;
//  * a command older than `deadlineSeconds` fades linearly to zero over
//    `fadeSeconds` (defaults 2 ms + 5 ms: zero within 7 ms of the last
//    command), so a stalled haptic loop never leaves a force on the user;
//  * a lost device gets no output; servo() retries the driver's reconnect
//    every `reconnectIntervalSeconds`; after reconnection the output stays
//    zero until a command newer than the reconnection arrives.
// Loss, reconnection, deadline misses and non-finite commands are events
// (pollEvent), never crashes. command() and servo() are real-time safe: no
// allocation, lock, log or throw; command() from one thread, servo() from
// one thread, state()/pollEvent() from one consumer thread.
//
// @code
//   auto dev = dm::HapticDevice::open(registry, "sim-haptic", {{"path", "circle"}, {"radius", "0.03"}});
//   if (!dev) return dev.error();
//   (*dev)->servo(t);                                   // servo thread, 1 kHz
//   (*dev)->command(force, dm::Vec3::Zero(), t);        // haptic loop
// @endcode
#pragma once

#include <dm/core/plugin.hpp>
#include <dm/core/result.hpp>
#include <dm/core/ring.hpp>
#include <dm/core/triple_buffer.hpp>
#include <dm/core/types.hpp>
#include <dm/io/device_abi.h>

#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace dm {

/// Flat key/value configuration of a device (a scene's device object with
/// every value written as a string).
using DeviceParams = std::vector<std::pair<std::string, std::string>>;

/// Outcome of one servo step.
enum class DeviceStatus : std::uint8_t { Ok, Lost, IoError };

/// Identity and limits of an opened haptic device.
struct HapticInfo {
  std::string driver, vendor, model, serial;
  std::uint32_t capabilities = 0;  ///< DM_HAPTIC_CAP_* bits
  std::uint32_t buttonCount = 0;
  Aabb workspace;             ///< m, device frame
  double maxForce = 0.0;      ///< N
  double maxTorque = 0.0;     ///< N·m
  double maxStiffness = 0.0;  ///< N/m
  double maxDamping = 0.0;    ///< N·s/m
  double servoRateHz = 0.0;
};

/// One sample, device frame (see DmHapticState).
struct HapticState {
  std::int64_t timeNs = 0;
  Vec3 position = Vec3::Zero();
  Quat orientation = Quat::Identity();
  Vec3 linearVelocity = Vec3::Zero();
  Vec3 angularVelocity = Vec3::Zero();
  std::uint32_t buttons = 0;
};

/// What servo() does to commands; see the file comment.
struct HapticSafety {
  double deadlineSeconds = 0.002;  ///< a command older than this starts to fade
  double fadeSeconds = 0.005;      ///< fade duration to zero
  double forceLimit = 0.0;         ///< N; > 0: min(this, device max force)
  double torqueLimit = 0.0;        ///< N·m; > 0: min(this, device max torque)
  double reconnectIntervalSeconds = 0.1;
};

/// Events reported by servo() through pollEvent().
enum class DeviceEventType : std::uint8_t {
  Lost,
  Reconnected,
  DeadlineMissed,
  DeadlineRecovered,
  NonFiniteCommand
};
struct DeviceEvent {
  DeviceEventType type = DeviceEventType::Lost;
  std::int64_t timeNs = 0;
};
/// "lost", "reconnected", "deadline-missed", "deadline-recovered", "non-finite-command".
std::string_view deviceEventName(DeviceEventType type) noexcept;

/// Force and torque actually sent to the device.
struct HapticOutput {
  Vec3 force = Vec3::Zero();   ///< N
  Vec3 torque = Vec3::Zero();  ///< N·m
};

/// Running totals (monotone).
struct HapticCounters {
  std::uint64_t servoSteps = 0;
  std::uint64_t clamped = 0;         ///< outputs reduced to a limit
  std::uint64_t nonFinite = 0;       ///< commands with NaN/Inf
  std::uint64_t deadlineMisses = 0;  ///< transitions into fading
  std::uint64_t losses = 0;
  std::uint64_t reconnects = 0;
  std::uint64_t ioErrors = 0;
};

namespace detail {
/// A command as it travels from the haptic loop to servo().
struct HapticCommand {
  Vec3 force = Vec3::Zero();
  Vec3 torque = Vec3::Zero();
  std::int64_t timeNs = 0;
  bool valid = false;
};
}  // namespace detail

/// A safe haptic device; see the file comment. Not copyable or movable
/// (threads hold references); owned through unique_ptr.
class HapticDevice {
 public:
  /// Opens driver `driver` of `registry` (kind "haptic-device", kind ABI
  /// DM_HAPTIC_DEVICE_KIND_ABI_VERSION) with `params`. Fails with NotFound
  /// (listing the drivers), Version, InvalidArgument (the driver's message,
  /// which names the parameter) or Device (info unavailable, nonsensical
  /// limits such as a non-positive max force or servo rate).
  static Result<std::unique_ptr<HapticDevice>> open(const FactoryRegistry& registry, std::string_view driver,
                                                    const DeviceParams& params = {},
                                                    const HapticSafety& safety = {});
  ~HapticDevice();
  HapticDevice(const HapticDevice&) = delete;
  HapticDevice& operator=(const HapticDevice&) = delete;

  const HapticInfo& info() const noexcept { return info_; }
  const HapticSafety& safety() const noexcept { return safety_; }

  /// The haptic loop's desired output at its time `nowNs`. Real-time safe.
  void command(const Vec3& force, const Vec3& torque, std::int64_t nowNs) noexcept;
  /// One servo step at `nowNs`: sample, make the command safe, send it.
  /// Real-time safe. Returns Lost while the device is away.
  DeviceStatus servo(std::int64_t nowNs) noexcept;

  /// The latest sample published by servo() (consumer thread); a default
  /// HapticState until hasState().
  const HapticState& state() noexcept { return states_.read(); }
  /// servo() has published a sample: the device has a pose (any thread).
  bool hasState() const noexcept { return hasState_.load(std::memory_order_acquire); }
  /// Next event, if any (consumer thread).
  bool pollEvent(DeviceEvent& event) noexcept { return events_.tryPop(event); }
  /// What the last servo() sent (zero while lost). Servo thread.
  const HapticOutput& lastOutput() const noexcept { return output_; }
  /// False between a loss and the reconnection.
  bool connected() const noexcept { return connected_.load(std::memory_order_acquire); }
  HapticCounters counters() const noexcept;

 private:
  HapticDevice() = default;
  using Command = detail::HapticCommand;
  void pushEvent(DeviceEventType type, std::int64_t nowNs) noexcept;
  void markLost(std::int64_t nowNs) noexcept;

  const DmHapticDeviceVTable* vt_ = nullptr;
  DmDevice* device_ = nullptr;
  std::shared_ptr<const void> keepAlive_;  // keeps the driver library loaded
  HapticInfo info_;
  HapticSafety safety_;
  double forceLimit_ = 0.0, torqueLimit_ = 0.0;

  TripleBuffer<Command> commands_;
  TripleBuffer<HapticState> states_;
  std::atomic<bool> hasState_{false};
  SpscRing<DeviceEvent, 64> events_;
  std::atomic<std::uint64_t> nonFinite_{0};
  std::atomic<bool> connected_{true};

  // servo-thread state
  HapticOutput output_;
  std::uint64_t nonFiniteSeen_ = 0;
  bool fading_ = false;
  std::int64_t lastServoNs_ = 0, lostSinceNs_ = 0, lastReconnectTryNs_ = 0, resumedAtNs_ = 0;
  std::atomic<std::uint64_t> servoSteps_{0}, clamped_{0}, deadlineMisses_{0}, losses_{0}, reconnects_{0},
      ioErrors_{0};
};

/// Scales `v` down to length `limit` if longer (direction kept); NaN/Inf
/// components give zero. Returns true if it changed `v`. O(1), noexcept.
bool clampVectorNorm(Vec3& v, double limit) noexcept;

}  // namespace dm
