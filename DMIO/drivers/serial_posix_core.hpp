// The serial-posix driver's termios code, header-only so that a driver of a
// device on a serial line (e.g. haply-2diy) reaches its line through the
// same code and C calls (kSerialPosix: open with path and line settings,
// read and write with timeouts, reconnect) in its plugin module too.
// serial_posix.cpp registers kSerialPosix as the "serial" driver
// "serial-posix"; see there for the parameters and the hang-up rules.
#pragma once

#include <dm/io/device_abi.h>

#include <fcntl.h>
#include <poll.h>
#include <termios.h>
#include <unistd.h>

#include <cerrno>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <new>

#include "driver_params.hpp"

namespace dm::driver::serial_posix {

struct BaudRate {
  std::uint32_t baud;
  speed_t speed;
};
inline constexpr BaudRate kRates[] = {
    {50, B50},           {75, B75},           {110, B110},         {134, B134},         {150, B150},
    {200, B200},         {300, B300},         {600, B600},         {1200, B1200},       {1800, B1800},
    {2400, B2400},       {4800, B4800},       {9600, B9600},       {19200, B19200},     {38400, B38400},
    {57600, B57600},     {115200, B115200},   {230400, B230400},   {460800, B460800},   {500000, B500000},
    {576000, B576000},   {921600, B921600},   {1000000, B1000000}, {1152000, B1152000}, {1500000, B1500000},
    {2000000, B2000000}, {2500000, B2500000}, {3000000, B3000000}, {3500000, B3500000}, {4000000, B4000000}};

// One open line; DmDevice* is this type behind the C boundary.
struct SerialPosix {
  int fd = -1;
  char path[256] = "";
  DmSerialConfig config{115200, 8, DM_SERIAL_PARITY_NONE, 1, DM_SERIAL_FLOW_NONE};
};

inline SerialPosix* asSerialPosix(DmDevice* d) { return reinterpret_cast<SerialPosix*>(d); }

inline std::int64_t monotonicMs() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1000 + ts.tv_nsec / 1'000'000;
}

inline bool isHangup(int err) { return err == EIO || err == ENXIO || err == ENODEV || err == EPIPE; }

// Checks `c` and applies it to fd. On failure writes a message naming the
// setting and returns DM_DEVICE_ERROR_INVALID_ARGUMENT (or _IO / _LOST).
inline int applyConfig(int fd, const DmSerialConfig& c, char* error, std::size_t errorSize) {
  const BaudRate* rate = nullptr;
  for (const BaudRate& r : kRates)
    if (r.baud == c.baud) rate = &r;
  auto fail = [&](int code, auto... args) {
    if (error && errorSize) std::snprintf(error, errorSize, args...);
    return code;
  };
  if (!rate)
    return fail(
        DM_DEVICE_ERROR_INVALID_ARGUMENT,
        "parameter 'baud': %u is not a supported rate (50, 75, 110, 134, 150, 200, 300, 600, 1200, 1800, "
        "2400, 4800, 9600, 19200, 38400, 57600, 115200, 230400, 460800, 500000, 576000, 921600, "
        "1000000, 1152000, 1500000, 2000000, 2500000, 3000000, 3500000, 4000000)",
        c.baud);
  if (c.data_bits < 5 || c.data_bits > 8)
    return fail(DM_DEVICE_ERROR_INVALID_ARGUMENT, "parameter 'data_bits': %u is not 5, 6, 7 or 8",
                c.data_bits);
  if (c.parity > DM_SERIAL_PARITY_ODD)
    return fail(DM_DEVICE_ERROR_INVALID_ARGUMENT, "parameter 'parity': %u is not none, even or odd",
                c.parity);
  if (c.stop_bits != 1 && c.stop_bits != 2)
    return fail(DM_DEVICE_ERROR_INVALID_ARGUMENT, "parameter 'stop_bits': %u is not 1 or 2", c.stop_bits);
  if (c.flow_control > DM_SERIAL_FLOW_XONXOFF)
    return fail(DM_DEVICE_ERROR_INVALID_ARGUMENT,
                "parameter 'flow_control': %u is not none, rtscts or xonxoff", c.flow_control);
  termios t{};
  if (tcgetattr(fd, &t) != 0)
    return fail(isHangup(errno) ? DM_DEVICE_ERROR_LOST : DM_DEVICE_ERROR_IO, "tcgetattr: %s",
                std::strerror(errno));
  cfmakeraw(&t);
  t.c_cflag |= CLOCAL | CREAD;
  t.c_cflag &= ~static_cast<tcflag_t>(CSIZE | PARENB | PARODD | CSTOPB | CRTSCTS);
  static const tcflag_t kSizes[] = {CS5, CS6, CS7, CS8};
  t.c_cflag |= kSizes[c.data_bits - 5];
  if (c.parity != DM_SERIAL_PARITY_NONE) t.c_cflag |= PARENB;
  if (c.parity == DM_SERIAL_PARITY_ODD) t.c_cflag |= PARODD;
  if (c.stop_bits == 2) t.c_cflag |= CSTOPB;
  if (c.flow_control == DM_SERIAL_FLOW_RTSCTS) t.c_cflag |= CRTSCTS;
  t.c_iflag &= ~static_cast<tcflag_t>(IXON | IXOFF | IXANY);
  if (c.flow_control == DM_SERIAL_FLOW_XONXOFF) t.c_iflag |= IXON | IXOFF;
  t.c_cc[VMIN] = 0;
  t.c_cc[VTIME] = 0;
  if (cfsetispeed(&t, rate->speed) != 0 || cfsetospeed(&t, rate->speed) != 0)
    return fail(DM_DEVICE_ERROR_INVALID_ARGUMENT, "parameter 'baud': %u rejected by the system", c.baud);
  if (tcsetattr(fd, TCSANOW, &t) != 0)
    return fail(isHangup(errno) ? DM_DEVICE_ERROR_LOST : DM_DEVICE_ERROR_IO, "tcsetattr: %s",
                std::strerror(errno));
  return DM_DEVICE_OK;
}

// Opens and configures the line; -1 with a message on failure.
inline int openLine(const char* path, const DmSerialConfig& c, char* error, std::size_t errorSize) {
  const int fd = ::open(path, O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) {
    if (error && errorSize)
      std::snprintf(error, errorSize, "parameter 'path': cannot open '%s': %s", path, std::strerror(errno));
    return -1;
  }
  if (!isatty(fd)) {
    if (error && errorSize)
      std::snprintf(error, errorSize, "parameter 'path': '%s' is not a terminal (serial) device", path);
    ::close(fd);
    return -1;
  }
  if (applyConfig(fd, c, error, errorSize) != DM_DEVICE_OK) {
    ::close(fd);
    return -1;
  }
  return fd;
}

inline DmDevice* serOpen(const DmDeviceParam* params, size_t count, char* error, size_t errorSize) {
  dm::driver::ParamReader r(params, count, error, errorSize);
  r.onlyKnown({"path", "baud", "parity", "data_bits", "stop_bits", "flow_control"});
  const char* path = r.find("path");
  if (r.ok() && (!path || !*path)) r.failf("parameter 'path' is required (e.g. /dev/ttyUSB0)");
  if (r.ok() && std::strlen(path) >= sizeof(SerialPosix::path))
    r.failf("parameter 'path': longer than %zu characters", sizeof(SerialPosix::path) - 1);
  DmSerialConfig c{115200, 8, DM_SERIAL_PARITY_NONE, 1, DM_SERIAL_FLOW_NONE};
  const double baud = r.number("baud", 115200, 1, 4e9);
  c.baud = static_cast<std::uint32_t>(baud);
  if (r.ok() && c.baud != baud) r.failf("parameter 'baud': %g is not a whole number", baud);
  c.parity = static_cast<std::uint32_t>(r.choice("parity", {"none", "even", "odd"}, 0));
  c.data_bits = static_cast<std::uint32_t>(5 + r.choice("data_bits", {"5", "6", "7", "8"}, 3));
  c.stop_bits = static_cast<std::uint32_t>(1 + r.choice("stop_bits", {"1", "2"}, 0));
  c.flow_control = static_cast<std::uint32_t>(r.choice("flow_control", {"none", "rtscts", "xonxoff"}, 0));
  if (!r.ok()) return nullptr;
  SerialPosix* d = new (std::nothrow) SerialPosix();
  if (!d) {
    r.failf("out of memory");
    return nullptr;
  }
  dm::driver::copyField(d->path, path);
  d->config = c;
  d->fd = openLine(path, c, error, errorSize);
  if (d->fd < 0) {
    delete d;
    return nullptr;
  }
  return reinterpret_cast<DmDevice*>(d);
}

inline void serClose(DmDevice* dev) {
  SerialPosix* d = asSerialPosix(dev);
  if (d->fd >= 0) ::close(d->fd);
  delete d;
}

inline int serInfo(DmDevice* dev, DmSerialInfo* info) {
  SerialPosix* d = asSerialPosix(dev);
  *info = DmSerialInfo{};
  dm::driver::copyField(info->identity.driver, "serial-posix");
  dm::driver::copyField(info->identity.vendor, "POSIX");
  dm::driver::copyField(info->identity.model, "termios serial line");
  dm::driver::copyField(info->identity.serial, d->path);
  info->capabilities = DM_SERIAL_CAP_RECONNECT | DM_SERIAL_CAP_CONFIGURE;
  dm::driver::copyField(info->path, d->path);
  info->config = d->config;
  return DM_DEVICE_OK;
}

inline int serConfigure(DmDevice* dev, const DmSerialConfig* config, char* error, size_t errorSize) {
  SerialPosix* d = asSerialPosix(dev);
  if (d->fd < 0) return DM_DEVICE_ERROR_LOST;
  const int rc = applyConfig(d->fd, *config, error, errorSize);
  if (rc == DM_DEVICE_OK) d->config = *config;
  return rc;
}

// Waits for `events` until deadlineMs; 1 ready, 0 timeout, -1 hang-up, -2 error.
inline int waitFor(int fd, short events, std::int64_t deadlineMs) {
  for (;;) {
    const std::int64_t left = deadlineMs - monotonicMs();
    pollfd p{fd, events, 0};
    const int rc = ::poll(&p, 1, left > 0 ? static_cast<int>(left) : 0);
    if (rc < 0 && errno == EINTR) continue;
    if (rc < 0) return -2;
    if (rc == 0) return 0;
    // Hang-up first: a hung-up tty also reports readable (read gives 0).
    // The caller has already drained what was left by reading before waiting.
    if (p.revents & (POLLHUP | POLLERR | POLLNVAL)) return -1;
    if (p.revents & events) return 1;
  }
}

inline int serRead(DmDevice* dev, void* data, size_t size, int timeoutMs, size_t* transferred) {
  SerialPosix* d = asSerialPosix(dev);
  *transferred = 0;
  if (d->fd < 0) return DM_DEVICE_ERROR_LOST;
  const std::int64_t deadline = monotonicMs() + timeoutMs;
  for (;;) {
    const ssize_t n = size ? ::read(d->fd, data, size) : 0;
    if (n > 0) {
      *transferred = static_cast<size_t>(n);
      return DM_DEVICE_OK;
    }
    if (n < 0 && errno != EAGAIN && errno != EINTR)
      return isHangup(errno) ? DM_DEVICE_ERROR_LOST : DM_DEVICE_ERROR_IO;
    if (size == 0) return DM_DEVICE_OK;
    const int w = waitFor(d->fd, POLLIN, deadline);
    if (w == 0) return DM_DEVICE_OK;  // timeout, nothing read
    if (w == -1) return DM_DEVICE_ERROR_LOST;
    if (w == -2) return DM_DEVICE_ERROR_IO;
  }
}

inline int serWrite(DmDevice* dev, const void* data, size_t size, int timeoutMs, size_t* transferred) {
  SerialPosix* d = asSerialPosix(dev);
  *transferred = 0;
  if (d->fd < 0) return DM_DEVICE_ERROR_LOST;
  const std::int64_t deadline = monotonicMs() + timeoutMs;
  const char* p = static_cast<const char*>(data);
  while (*transferred < size) {
    const ssize_t n = ::write(d->fd, p + *transferred, size - *transferred);
    if (n > 0) {
      *transferred += static_cast<size_t>(n);
      continue;
    }
    if (n < 0 && errno != EAGAIN && errno != EINTR)
      return isHangup(errno) ? DM_DEVICE_ERROR_LOST : DM_DEVICE_ERROR_IO;
    const int w = waitFor(d->fd, POLLOUT, deadline);
    if (w == 0) return DM_DEVICE_OK;  // timeout: partial write
    if (w == -1) return DM_DEVICE_ERROR_LOST;
    if (w == -2) return DM_DEVICE_ERROR_IO;
  }
  return DM_DEVICE_OK;
}

inline int serReconnect(DmDevice* dev) {
  SerialPosix* d = asSerialPosix(dev);
  if (d->fd >= 0) ::close(d->fd);
  d->fd = openLine(d->path, d->config, nullptr, 0);
  return d->fd >= 0 ? DM_DEVICE_OK : DM_DEVICE_ERROR_LOST;
}

inline constexpr DmSerialVTable kSerialPosix = {serOpen, serClose, serInfo,     serConfigure,
                                                serRead, serWrite, serReconnect};

}  // namespace dm::driver::serial_posix
