// dm/network/drivers.hpp — device drivers that reach a device over the network.
//
// "net-haptic" (kind "haptic-device"): the host side of the tele-operation
// stream (dm/network/teleop.hpp). It makes a haptic device attached to another
// machine — served there by a TeleopDevice with a TeleopDeviceBridge, e.g. the
// `dm-teleop-device` tool — look like a local one: dm::HapticDevice opens it
// like any driver, with the same clamping, NaN guard, deadline fade and
// loss/reconnect handling. open() asks the device side for its identity and
// limits (Hello → Info) and fails with a message naming the address when
// nothing answers. read_state reports the device lost when no state arrived
// within `timeout`; reconnect sends Hello again and succeeds once states flow.
// Each instance owns its stream's receive thread.
//
// Parameters:
//   device               "address:port" of the device side (required; numeric),
//                        or "inproc:NAME": the in-process link NAME that a
//                        TeleopDevice of this process opened (teleop.hpp),
//                        e.g. a scene's served device in a lockstep run;
//                        `local` and `synchronized_clocks` do not apply to it
//   local                "address:port" to bind                (0.0.0.0:0)
//   timeout              s without a state before "lost"       (0.1)
//   connect_timeout      s open() waits for the device's Info  (2)
//   wait_for_state       s open() then waits for the first state, so the
//                        first servo has one; none by then: open fails (0).
//                        On an in-process link whose clock only the run
//                        advances (lockstep) open cannot wait: the reads
//                        and writes before the first state, within this
//                        long of opening on that clock, report an I/O error
//                        of the tick (no sample yet) instead of a lost device
//   synchronized_clocks  0 | 1: clocks are synchronized (same host, PTP) (0)
//   wave_impedance       N·s/m; > 0: wave-variable mode, the device side's
//                        TeleopDeviceBridge must use the same b     (0: off)
//   wave_policy          hold | zero: the WaveReceiver's loss policy (hold)
//   emulate_delay, emulate_jitter (s), emulate_loss (0..1), emulate_seed:
//                        pass received states through an in-process
//                        LinkEmulator (uniform jitter) — latency training
//                        and tests on one machine                (off)
//
// Wave-variable mode: the driver is the matched WaveSlavePort
// (dm/network/wave_variables.hpp). The position it reports is a virtual
// tool that starts at the device's position and is moved only by the
// forward waves; the force the application renders on it (after
// HapticDevice's clamping) moves it for one servo period at the next write
// and returns as the backward wave. The loop stays stable under delay,
// jitter and loss (verified with 100 ms one way in simulated time and
// through the link emulator end to end); the price is that the tool drifts
// from the device's position under loss and delay. Choose b well above
// k·T for the stiffest contact k rendered at servo period T (the tests hold
// a 2 kN/m contact with 40 N·s/m at 1 kHz).
//
// The driver is compiled into DM::Network and registered through
// PluginLinker::addStatic (same ABI check and init protocol as a plugin).
//
// @code
//   dm::FactoryRegistry registry;  dm::PluginLinker linker(registry);
//   dm::registerNetworkDrivers(linker);
//   auto stylus = dm::HapticDevice::open(registry, "net-haptic", {{"device", "192.168.1.20:47000"}});
// @endcode
#pragma once

#include <dm/core/plugin.hpp>
#include <dm/core/result.hpp>
#include <dm/network/io_thread.hpp>

#include <string>
#include <string_view>
#include <vector>

namespace dm {

/// Names of the network drivers, as plugin names (sorted).
std::vector<std::string> networkDriverNames();

/// Registers every network driver with `linker` (addStatic). Fails like
/// PluginLinker::addStatic, e.g. when a plugin of the same name is loaded.
Status registerNetworkDrivers(PluginLinker& linker);

/// dm::parseHostPort (dm/core/endpoint.hpp) as a SocketAddress: splits
/// "address:port" (IPv6 as "[::1]:port"); InvalidArgument naming `field`
/// when the port is missing or not 1..65535 (0 allowed with `allowZeroPort`).
Result<SocketAddress> parseEndpoint(std::string_view text, std::string_view field, bool allowZeroPort = false);

}  // namespace dm
