// dm/io/drivers.hpp — the device drivers that ship with DMPlatform.
//
// Each driver in DMIO/drivers/ is built twice from one source: into DM::IO
// (registered here through PluginLinker::addStatic, the same ABI check and
// init protocol a plugin goes through) and as a plugin module
// `libdm_driver_<name>.so` installed in `<prefix>/lib/dmplatform/plugins`
// (and, in a build tree, in `<build>/plugins`). Use one or the other in a
// registry: both register the same factory names.
//
// Drivers:
//  * "sim-haptic" (kind "haptic-device"): scripted paths, virtual hand,
//    noise, quantization, latency, loss window (DMIO/drivers/sim_haptic.cpp);
//  * "replay-haptic" (kind "haptic-device"): plays a recording made with
//    dm::DeviceRecorder at the recorded or a scaled rate, reporting the
//    force, torque, stiffness and damping limits it is given (a scene
//    replay gives the recorded device's) (DMIO/drivers/replay_haptic.cpp);
//  * "replay-controller" (kind "controller"), "replay-daq" (kind "daq"),
//    "replay-sensor" (kind "sensor"): play the controller states, DAQ
//    frames or sensor readings of a recording at the recorded or a scaled
//    rate, end of stream reported as a loss (DMIO/drivers/replay_*.cpp);
//  * "sim-controller" (kind "controller", dm/io/controller.hpp): scripted
//    axes (sine, square, ramp, constant) and a binary button counter;
//  * "evdev-controller" (kind "controller"): Linux input devices
//    (/dev/input/eventN, by path or by name);
//  * "sim-daq" (kind "daq", dm/io/daq.hpp): a signal generator per channel
//    with seeded noise and a device FIFO that overflows;
//  * "sim-sensor" (kind "sensor", dm/io/sensor.hpp): scalar, force,
//    orientation or tracker readings with noise;
//  * "serial-posix" (kind "serial", dm/io/serial.hpp): termios serial lines;
//  * "openhaptics-hd" (kind "haptic-device"): 3D Systems Touch, Touch X and
//    Phantom devices through the OpenHaptics HD library, loaded at run time
//    (DMIO/drivers/openhaptics_hd.cpp; docs/devices.md);
//  * "force-dimension-dhd" (kind "haptic-device"): Force Dimension omega,
//    delta and other models and the Novint Falcon through the DHD library,
//    loaded at run time (DMIO/drivers/force_dimension_dhd.cpp);
//  * "haply-2diy" (kind "haptic-device"): the Haply 2DIY pantograph on a
//    Haply board over USB serial, through the board's open hAPI 2 protocol
//    on the serial-posix driver's line code (DMIO/drivers/haply_2diy.cpp);
//  * "pointer" (kind "haptic-device", dm/io/pointer_device.hpp): a
//    kinematic stand-in the program moves (a live view's mouse); built in
//    only, no plugin module (its channels live in the program).
//    The vendor drivers are registered always; opening one where its library
//    is missing fails saying what to install, and vendorDriverStatus() tells
//    before anything is opened.
// Each driver's parameters are listed at the top of its source file.
//
// @code
//   dm::FactoryRegistry registry;
//   dm::PluginLinker linker(registry);
//   if (auto s = dm::registerBuiltinDrivers(linker); !s) return s.error();
//   auto stylus = dm::HapticDevice::open(registry, "sim-haptic", {{"path", "circle"}});
// @endcode
#pragma once

#include <dm/core/plugin.hpp>
#include <dm/core/result.hpp>

#include <string>
#include <vector>

namespace dm {

/// Names of the built-in drivers, as plugin names (sorted).
std::vector<std::string> builtinDriverNames();

/// A driver that needs a vendor's library, and whether this machine has it.
struct VendorDriverStatus {
  std::string driver;  ///< factory name, e.g. "openhaptics-hd"
  std::string api;     ///< e.g. "OpenHaptics HD"
  bool available = false;
  std::string reason;   ///< when unavailable: every name tried and what to install
  std::string library;  ///< when available: the file it loads
};

/// Looks for each vendor driver's library (dlopen, then dlclose) as the
/// driver would with its default parameters. Opens no device.
std::vector<VendorDriverStatus> vendorDriverStatus();

/// Registers every built-in driver with `linker` (addStatic). Fails like
/// PluginLinker::addStatic, e.g. when a plugin of the same name is loaded.
Status registerBuiltinDrivers(PluginLinker& linker);

}  // namespace dm
