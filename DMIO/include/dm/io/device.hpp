// dm/io/device.hpp — what the device wrappers (Controller, Daq, Sensor,
// SerialLine) share: identity, counters, and the loss/reconnection link.
//
// Every wrapper opens a driver from a FactoryRegistry by name, samples it
// from one "poll" thread and hands results to one consumer thread. When the
// driver reports DM_DEVICE_ERROR_LOST the wrapper marks the device lost,
// queues a DeviceEvent (Lost), and retries the driver's reconnect at most
// every `reconnectIntervalSeconds`; success queues a Reconnected event. The
// parameter, status and event types are those of dm/io/haptic_device.hpp.
//
// @code
//   auto pedal = dm::Controller::open(registry, "evdev-controller", {{"path", "/dev/input/event5"}});
//   dm::DeviceEvent e;
//   while ((*pedal)->pollEvent(e)) dm::log::info("%s", dm::deviceEventName(e.type).data());
// @endcode
#pragma once

#include <dm/core/ring.hpp>
#include <dm/io/device_abi.h>
#include <dm/io/haptic_device.hpp>

#include <atomic>
#include <cstdint>
#include <string>

namespace dm {

/// Who a device is (see DmDeviceIdentity).
struct DeviceIdentity {
  std::string driver;  ///< factory name, e.g. "sim-daq"
  std::string vendor;
  std::string model;
  std::string serial;
};

/// Converts the C identity (fixed, possibly unterminated fields). O(1).
DeviceIdentity toDeviceIdentity(const DmDeviceIdentity& identity);

/// Running totals of a device wrapper (monotone).
struct DeviceCounters {
  std::uint64_t polls = 0;       ///< poll/acquire calls
  std::uint64_t losses = 0;      ///< transitions into "lost"
  std::uint64_t reconnects = 0;  ///< successful reconnections
  std::uint64_t ioErrors = 0;    ///< failed or rejected reads (bad data, I/O error)
};

namespace detail {

/// Loss and reconnection bookkeeping for one device: the poll thread calls
/// due(), lost(), reconnected(), ioError(); the consumer thread pollEvent().
/// Real-time safe: no allocation, lock or throw.
class DeviceLink {
 public:
  explicit DeviceLink(double reconnectIntervalSeconds = 0.1) noexcept {
    setInterval(reconnectIntervalSeconds);
  }
  /// Sets the minimum time between reconnection attempts (s, ≥ 0).
  void setInterval(double seconds) noexcept { intervalNs_ = static_cast<std::int64_t>(seconds * 1e9); }
  /// Poll thread: counts a poll; false while lost (nothing to sample).
  bool connectedForPoll() noexcept {
    polls_.fetch_add(1, std::memory_order_relaxed);
    return connected_.load(std::memory_order_relaxed);
  }
  /// Poll thread, while lost: true when a reconnection attempt is due at nowNs
  /// (and records the attempt).
  bool reconnectDue(std::int64_t nowNs) noexcept;
  /// Poll thread: the driver reported loss at nowNs (idempotent).
  void lost(std::int64_t nowNs) noexcept;
  /// Poll thread: the driver's reconnect succeeded at nowNs.
  void reconnected(std::int64_t nowNs) noexcept;
  /// Poll thread: one failed or rejected read.
  void ioError() noexcept { ioErrors_.fetch_add(1, std::memory_order_relaxed); }
  /// Any thread: false between a loss and the reconnection.
  bool connected() const noexcept { return connected_.load(std::memory_order_acquire); }
  /// Consumer thread: the next Lost/Reconnected event, if any.
  bool pollEvent(DeviceEvent& event) noexcept { return events_.tryPop(event); }
  /// Any thread.
  DeviceCounters counters() const noexcept;

 private:
  SpscRing<DeviceEvent, 64> events_;
  std::atomic<bool> connected_{true};
  std::int64_t intervalNs_ = 100'000'000, lastTryNs_ = 0;
  std::atomic<std::uint64_t> polls_{0}, losses_{0}, reconnects_{0}, ioErrors_{0};
};

}  // namespace detail
}  // namespace dm
