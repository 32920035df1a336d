// serial-posix — serial lines through POSIX termios (kind "serial"): any
// tty device, e.g. /dev/ttyUSB0, /dev/ttyS0, /dev/ttyACM0, or a
// pseudo-terminal.
//
// The line is opened non-blocking in raw mode (no echo, no line editing, no
// character translation); read and write wait with poll(2) up to their
// timeout. A hang-up (POLLHUP, EIO, ENXIO, ENODEV: the adapter was unplugged
// or the pseudo-terminal's master closed) is reported as DM_DEVICE_ERROR_LOST;
// reconnect reopens the path with the same settings.
//
// Parameters:
//   path          device path (required)
//   baud          a standard rate 50 … 4000000                    (115200)
//   parity        none | even | odd                               (none)
//   data_bits     5 | 6 | 7 | 8                                   (8)
//   stop_bits     1 | 2                                           (1)
//   flow_control  none | rtscts | xonxoff                         (none)
//
// Built into DM::IO and, with DM_DRIVER_PLUGIN, as libdm_driver_serial_posix.so.
#include <dm/core/plugin_abi.h>
#include <dm/io/device_abi.h>

#include "serial_posix_core.hpp"

namespace {

using dm::driver::serial_posix::kSerialPosix;

int serInit(const DmHostApi* host) {
  return host->register_factory(host->ctx, DM_SERIAL_KIND, "serial-posix", DM_SERIAL_KIND_ABI_VERSION,
                                &kSerialPosix);
}

const DmPluginInfo kSerialPosixInfo = {DM_PLUGIN_ABI_VERSION, "serial-posix", "1.0", serInit, nullptr};

}  // namespace

#if defined(DM_DRIVER_PLUGIN)
DM_PLUGIN_ENTRY { return &kSerialPosixInfo; }
#else
extern "C" const DmPluginInfo* dm_builtin_entry_serial_posix(void) { return &kSerialPosixInfo; }
#endif
