// dm/io/serial.hpp — serial lines (RS-232, USB-serial adapters) behind the
// driver ABI (kind "serial", see DmSerialVTable).
//
// A SerialLine is opened from parameters — path, baud, parity
// (none|even|odd), data_bits (5..8), stop_bits (1|2), flow_control
// (none|rtscts|xonxoff) — and can be reconfigured later. read() and write()
// never block longer than their timeout: read() returns what is available
// (at least one byte unless the timeout expires, then zero), write() what it
// could send in time. When the device disappears or the peer hangs up the
// call fails with ErrorCode::Device, a Lost event is queued, and later calls
// fail fast until reconnect() reopens the line (a Reconnected event).
// Unsupported settings fail with a message naming the parameter.
// Thread use: one thread calls read/write/configure/reconnect, one consumer
// may call pollEvent(). Not real-time safe (errors carry strings).
//
// Driver: "serial-posix" (termios), see dm/io/drivers.hpp.
//
// @code
//   auto line = dm::SerialLine::open(registry, "serial-posix", {{"path", "/dev/ttyUSB0"}, {"baud",
//   "115200"}}); auto sent = (*line)->write(std::as_bytes(std::span("PING\n", 5)),
//   std::chrono::milliseconds(100)); std::array<std::byte, 64> buf; auto got = (*line)->read(buf,
//   std::chrono::milliseconds(100));
// @endcode
#pragma once

#include <dm/core/plugin.hpp>
#include <dm/core/result.hpp>
#include <dm/io/device.hpp>

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <string_view>

namespace dm {

/// Parity bit of a serial frame.
enum class SerialParity : std::uint8_t {
  None = DM_SERIAL_PARITY_NONE,
  Even = DM_SERIAL_PARITY_EVEN,
  Odd = DM_SERIAL_PARITY_ODD
};
/// Flow control of a serial line.
enum class SerialFlowControl : std::uint8_t {
  None = DM_SERIAL_FLOW_NONE,
  RtsCts = DM_SERIAL_FLOW_RTSCTS,   ///< hardware (RTS/CTS lines)
  XonXoff = DM_SERIAL_FLOW_XONXOFF  ///< software (XON/XOFF characters)
};

/// Line settings (see DmSerialConfig).
struct SerialConfig {
  std::uint32_t baud = 115200;  ///< bits per second; the driver lists the rates it supports
  std::uint32_t dataBits = 8;   ///< 5..8
  SerialParity parity = SerialParity::None;
  std::uint32_t stopBits = 1;  ///< 1 or 2
  SerialFlowControl flowControl = SerialFlowControl::None;
};

/// What an opened serial line is.
struct SerialInfo {
  DeviceIdentity identity;
  std::uint32_t capabilities = 0;  ///< DM_SERIAL_CAP_* bits
  std::string path;                ///< device path
  SerialConfig config;             ///< settings in force
};

/// A serial line; see the file comment. Not copyable or movable; owned
/// through unique_ptr.
class SerialLine {
 public:
  /// Opens driver `driver` (kind "serial", ABI DM_SERIAL_KIND_ABI_VERSION) of
  /// `registry` with `params`. Fails with NotFound, Version, InvalidArgument
  /// (the driver's message naming the parameter or path) or Device.
  static Result<std::unique_ptr<SerialLine>> open(const FactoryRegistry& registry, std::string_view driver,
                                                  const DeviceParams& params);
  ~SerialLine();
  SerialLine(const SerialLine&) = delete;
  SerialLine& operator=(const SerialLine&) = delete;

  /// Identity, capabilities, path and the settings in force.
  const SerialInfo& info() const noexcept { return info_; }

  /// Applies new settings. InvalidArgument naming the setting (e.g. "baud")
  /// when one is out of range or unsupported; the old settings stay.
  Status configure(const SerialConfig& config);
  /// Reads what is available into `out`, waiting at most `timeout` (0: do
  /// not wait) for the first byte. Returns the byte count, 0 after a
  /// timeout; Device error when the line is lost, Io on a read error,
  /// InvalidArgument for a negative timeout.
  Result<std::size_t> read(std::span<std::byte> out, std::chrono::milliseconds timeout);
  /// Writes `data`, waiting at most `timeout` in all for room. Returns the
  /// bytes written (< data.size() after a timeout); errors as read().
  Result<std::size_t> write(std::span<const std::byte> data, std::chrono::milliseconds timeout);
  /// Reopens a lost line with the current settings. Device error while it
  /// is still away; ok (and nothing happens) when it is connected.
  Status reconnect();
  /// The next Lost/Reconnected event, if any (consumer thread).
  bool pollEvent(DeviceEvent& event) noexcept { return link_.pollEvent(event); }
  /// False between a loss and the reconnection.
  bool connected() const noexcept { return link_.connected(); }
  /// polls counts read and write calls.
  DeviceCounters counters() const noexcept { return link_.counters(); }

 private:
  SerialLine() = default;
  Result<int> beginTransfer(std::chrono::milliseconds timeout);
  Result<std::size_t> endTransfer(int rc, std::size_t done, std::size_t size, const char* what);
  const DmSerialVTable* vt_ = nullptr;
  DmDevice* device_ = nullptr;
  std::shared_ptr<const void> keepAlive_;
  SerialInfo info_;
  std::string where_;
  detail::DeviceLink link_{0.0};
};

}  // namespace dm
