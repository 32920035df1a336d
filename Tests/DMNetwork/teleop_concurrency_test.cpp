// The tele-operation stream with its real threads: a device-side servo thread
// (sim-haptic behind a TeleopDeviceBridge) and a host servo thread (the
// net-haptic driver in a dm::HapticDevice) at 1 kHz each, the two ends' receive
// threads in between, and a third thread reading the statistics — the way a
// simulator runs it. Run under ThreadSanitizer in CI.
#include <dm/core/clock.hpp>
#include <dm/io/drivers.hpp>
#include <dm/network/drivers.hpp>
#include <dm/network/teleop.hpp>

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <string>
#include <thread>

#include "../common/eventually.hpp"
#include "network_test_support.hpp"

namespace {

using namespace std::chrono_literals;
using dm::test::eventually;
using dm::test::monotonicNs;

/// Calls `step(now)` every millisecond until `stop`.
template <class F>
std::thread servoThread(std::atomic<bool>& stop, F step) {
  return std::thread([&stop, step]() mutable {
    auto next = std::chrono::steady_clock::now();
    while (!stop.load()) {
      step(monotonicNs());
      next += 1ms;
      std::this_thread::sleep_until(next);
    }
  });
}

TEST(TeleopStreamConcurrency, TwoServoThreadsAndAStatsReaderExchangeStatesAndForces) {
  dm::FactoryRegistry registry;
  dm::PluginLinker linker(registry);
  ASSERT_TRUE(dm::registerBuiltinDrivers(linker));
  ASSERT_TRUE(dm::registerNetworkDrivers(linker));
  auto local = dm::HapticDevice::open(registry, "sim-haptic", {{"path", "circle"}, {"radius", "0.02"}});
  ASSERT_TRUE(local);
  auto link = dm::TeleopDevice::open({}, (*local)->info());
  ASSERT_TRUE(link);
  dm::TeleopDeviceBridge bridge(**local, **link);
  std::atomic<bool> stopDevice{false}, stopHost{false}, forceArrived{false};
  std::thread device = servoThread(stopDevice, [&](std::int64_t now) {
    bridge.step(now);
    if ((*local)->lastOutput().force.isApprox(dm::Vec3(0, 0, 0.5), 1e-12)) forceArrived = true;
  });

  auto remote = dm::HapticDevice::open(registry, "net-haptic",
                                       {{"device", "127.0.0.1:" + std::to_string((*link)->port())},
                                        {"synchronized_clocks", "1"}});
  ASSERT_TRUE(remote) << remote.error().message();
  std::atomic<double> maxRadiusError{0.0};
  std::atomic<int> samples{0};
  std::thread host = servoThread(stopHost, [&](std::int64_t now) {
    (*remote)->servo(now);
    const dm::HapticState& s = (*remote)->state();
    if ((*remote)->connected()) {
      // The stylus runs on a circle of radius 2 cm about the origin in z = 0.
      const double err = std::abs(std::hypot(s.position.x(), s.position.y()) - 0.02) + std::abs(s.position.z());
      if (err > maxRadiusError.load()) maxRadiusError.store(err);
      samples.fetch_add(1);
    }
    (*remote)->command(dm::Vec3(0, 0, 0.5), dm::Vec3::Zero(), now);
  });

  dm::TeleopStats seen;
  ASSERT_TRUE(eventually([&] {
    seen = (*link)->stats();  // read while both servo threads run
    return samples.load() >= 300 && seen.received >= 300 && forceArrived.load();
  }));
  stopHost = true;
  host.join();
  stopDevice = true;
  device.join();

  EXPECT_LT(maxRadiusError.load(), 1e-9);  // positions cross the network bit-exactly
  EXPECT_EQ(seen.malformed, 0u);
  EXPECT_GT(seen.roundTrip.count, 0u);
  EXPECT_GT(seen.roundTrip.p50, 0.0);
  remote->reset();
  (*link)->close();
}

}  // namespace
