// dm/io/controller.hpp — joysticks, foot pedals and 3-D mice behind the
// driver ABI (kind "controller", see DmControllerVTable).
//
// A Controller has six analog axes, normalised to [-1, 1], and up to 128
// buttons, sampled together with the host's loop time. One poll thread calls
// poll(t) at the device's poll rate; one consumer thread reads the latest
// whole sample with state() (a triple buffer: never torn, never blocking) and
// the Lost/Reconnected events with pollEvent(). A lost device (unplugged)
// keeps its last state, and poll() retries the driver's reconnect every
// `reconnectIntervalSeconds`. poll() is real-time safe: no allocation, lock
// or throw.
//
// Drivers: "sim-controller" (scripted axes and buttons) and
// "evdev-controller" (Linux input devices), see dm/io/drivers.hpp.
//
// @code
//   auto pad = dm::Controller::open(registry, "evdev-controller", {{"name", "Foot Switch"}});
//   (*pad)->poll(nowNs);                                  // poll thread, e.g. 250 Hz
//   if ((*pad)->state().pressed(0)) clutch();             // consumer
// @endcode
#pragma once

#include <dm/core/plugin.hpp>
#include <dm/core/result.hpp>
#include <dm/core/triple_buffer.hpp>
#include <dm/io/device.hpp>

#include <array>
#include <bitset>
#include <cstdint>
#include <memory>
#include <string_view>

namespace dm {

/// Number of analog axes of a ControllerState.
inline constexpr std::size_t kControllerAxes = DM_CONTROLLER_AXES;
/// Number of buttons of a ControllerState.
inline constexpr std::size_t kControllerButtons = DM_CONTROLLER_MAX_BUTTONS;

/// What an opened controller has.
struct ControllerInfo {
  DeviceIdentity identity;
  std::uint32_t capabilities = 0;  ///< DM_CONTROLLER_CAP_* bits
  std::uint32_t axisCount = 0;     ///< axes that move (≤ 6)
  std::uint32_t buttonCount = 0;   ///< ≤ 128
  double pollRateHz = 0.0;         ///< suggested poll() rate
};

/// One sample of a controller.
struct ControllerState {
  std::int64_t timeNs = 0;                     ///< host loop time of the sample
  std::array<double, kControllerAxes> axes{};  ///< each in [-1, 1]
  std::bitset<kControllerButtons> buttons;     ///< bit i: button i pressed
  /// True if button i (< 128) is pressed. O(1).
  bool pressed(std::size_t i) const noexcept { return i < kControllerButtons && buttons.test(i); }
};

/// Options of Controller::open.
struct ControllerOptions {
  double reconnectIntervalSeconds = 0.1;  ///< minimum time between reconnect attempts
};

/// A controller; see the file comment. Not copyable or movable; owned
/// through unique_ptr.
class Controller {
 public:
  /// Opens driver `driver` (kind "controller", ABI
  /// DM_CONTROLLER_KIND_ABI_VERSION) of `registry` with `params`. Fails with
  /// NotFound (listing the drivers), Version, InvalidArgument (the driver's
  /// message, naming the parameter) or Device (bad vtable or info).
  static Result<std::unique_ptr<Controller>> open(const FactoryRegistry& registry, std::string_view driver,
                                                  const DeviceParams& params = {},
                                                  const ControllerOptions& options = {});
  ~Controller();
  Controller(const Controller&) = delete;
  Controller& operator=(const Controller&) = delete;

  /// Identity, capabilities, axis and button counts, poll rate.
  const ControllerInfo& info() const noexcept { return info_; }

  /// Samples the controller at host time nowNs and publishes the sample.
  /// Poll thread; real-time safe. Lost while the device is away; IoError
  /// when a sample failed or had an axis outside [-1, 1] or NaN (dropped).
  DeviceStatus poll(std::int64_t nowNs) noexcept;
  /// The latest published sample (consumer thread).
  const ControllerState& state() noexcept { return states_.read(); }
  /// The next Lost/Reconnected event, if any (consumer thread).
  bool pollEvent(DeviceEvent& event) noexcept { return link_.pollEvent(event); }
  /// False between a loss and the reconnection.
  bool connected() const noexcept { return link_.connected(); }
  /// Polls, losses, reconnections and I/O errors so far (any thread).
  DeviceCounters counters() const noexcept { return link_.counters(); }

 private:
  Controller() = default;
  const DmControllerVTable* vt_ = nullptr;
  DmDevice* device_ = nullptr;
  std::shared_ptr<const void> keepAlive_;
  ControllerInfo info_;
  TripleBuffer<ControllerState> states_;
  detail::DeviceLink link_;
};

}  // namespace dm
