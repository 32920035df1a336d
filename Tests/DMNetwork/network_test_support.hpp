// Helpers shared by the DMNetwork tests.
#pragma once

#include <dm/core/clock.hpp>
#include <dm/io/device_abi.h>
#include <dm/io/drivers.hpp>
#include <dm/io/haptic_device.hpp>
#include <dm/network/drivers.hpp>

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <memory>
#include <vector>

namespace dm::test {

/// The bytes of a C string, without its terminating NUL.
inline std::vector<std::byte> ascii(const char* s) {
  std::vector<std::byte> b(std::strlen(s));
  std::memcpy(b.data(), s, b.size());
  return b;
}

/// The time on CLOCK_MONOTONIC, ns: the clock of the tele-operation stream.
inline std::int64_t monotonicNs() { return RealClock().now(); }

/// The identity and limits of a simulated stylus, as a device side reports them.
inline HapticInfo sampleInfo() {
  HapticInfo info;
  info.driver = "sim-haptic";
  info.vendor = "DMPlatform";
  info.model = "simulated 3-DOF stylus";
  info.serial = "sim-7";
  info.capabilities = DM_HAPTIC_CAP_POSITION | DM_HAPTIC_CAP_FORCE;
  info.buttonCount = 2;
  info.workspace = Aabb(Vec3(-0.1, -0.1, -0.05), Vec3(0.1, 0.1, 0.05));
  info.maxForce = 8;
  info.maxStiffness = 2000;
  info.maxDamping = 20;
  info.servoRateHz = 1000;
  return info;
}

/// Registers the built-in and the network drivers with `linker` and opens
/// a sim-haptic stylus held at (0.01, 0.02, 0.03) m with a 6 N limit: the
/// console of the net-haptic tests.
inline Result<std::unique_ptr<HapticDevice>> openHeldStylus(FactoryRegistry& registry, PluginLinker& linker) {
  if (auto s = registerBuiltinDrivers(linker); !s) return s.error();
  if (auto s = registerNetworkDrivers(linker); !s) return s.error();
  return HapticDevice::open(registry, "sim-haptic",
                            {{"path", "point"}, {"center", "0.01,0.02,0.03"}, {"max_force", "6"}});
}

}  // namespace dm::test
