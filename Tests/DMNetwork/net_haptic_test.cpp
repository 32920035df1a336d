// Tests of the net-haptic driver and TeleopDeviceBridge: a simulated stylus
// (sim-haptic) served over 127.0.0.1 looks to dm::HapticDevice exactly like
// the local device — same identity and limits, bit-identical positions,
// forces arriving at the far motor — and link loss, device restart and a
// silent host are handled as the safety rules say. The servo paths make no
// allocation.
#include <dm/core/clock.hpp>
#include <dm/io/drivers.hpp>
#include <dm/network/drivers.hpp>
#include <dm/network/teleop.hpp>

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <string>
#include <thread>

#include "../common/alloc_counter.hpp"
#include "../common/eventually.hpp"

namespace {

using namespace std::chrono_literals;
using dm::test::eventually;

std::int64_t monotonicNs() { return dm::RealClock().now(); }  // CLOCK_MONOTONIC, as the stream

class NetHaptic : public ::testing::Test {
 protected:
  void SetUp() override {
    ASSERT_TRUE(dm::registerBuiltinDrivers(linker));
    ASSERT_TRUE(dm::registerNetworkDrivers(linker));
    auto sim = dm::HapticDevice::open(registry, "sim-haptic",
                                      {{"path", "point"}, {"center", "0.01,0.02,0.03"}, {"max_force", "6"}});
    ASSERT_TRUE(sim) << sim.error().message();
    local = std::move(*sim);
    openDeviceSide(0);
  }

  void openDeviceSide(std::uint16_t port) {
    bridge.reset();
    link.reset();
    ASSERT_TRUE(eventually([&] {
      auto d = dm::TeleopDevice::open({.local = {"127.0.0.1", port}}, local->info());
      if (d) link = std::move(*d);
      return link != nullptr;
    }));
    bridge = std::make_unique<dm::TeleopDeviceBridge>(*local, *link, dm::TeleopBridgeOptions{.timeoutSeconds = 0.1});
  }

  dm::Result<std::unique_ptr<dm::HapticDevice>> openRemote(double connectTimeout = 2.0) {
    return dm::HapticDevice::open(registry, "net-haptic",
                                  {{"device", "127.0.0.1:" + std::to_string(link->port())},
                                   {"connect_timeout", std::to_string(connectTimeout)},
                                   {"synchronized_clocks", "1"}});
  }

  /// One period of both ends, in this thread.
  void tick(dm::HapticDevice* remote, bool deviceSide = true) {
    const std::int64_t now = monotonicNs();
    if (deviceSide) bridge->step(now);
    if (remote) remote->servo(now);
    std::this_thread::sleep_for(1ms);
  }

  dm::FactoryRegistry registry;
  dm::PluginLinker linker{registry};
  std::unique_ptr<dm::HapticDevice> local;
  std::unique_ptr<dm::TeleopDevice> link;
  std::unique_ptr<dm::TeleopDeviceBridge> bridge;
};

TEST_F(NetHaptic, RemoteDeviceHasTheLocalIdentityLimitsAndPositions) {
  auto remote = openRemote();
  ASSERT_TRUE(remote) << remote.error().message();
  const dm::HapticInfo& info = (*remote)->info();
  EXPECT_EQ(info.driver, "net-haptic");
  EXPECT_EQ(info.model, local->info().model);
  EXPECT_EQ(info.serial, local->info().serial);
  EXPECT_EQ(info.maxForce, 6.0);
  EXPECT_EQ(info.capabilities, local->info().capabilities);
  EXPECT_EQ(info.workspace.min(), local->info().workspace.min());
  EXPECT_EQ(info.servoRateHz, local->info().servoRateHz);
  ASSERT_TRUE(eventually([&] {
    tick(remote->get());
    return (*remote)->state().position == dm::Vec3(0.01, 0.02, 0.03);
  }));
  EXPECT_TRUE((*remote)->connected());
}

TEST_F(NetHaptic, ForcesReachTheFarMotorClampedToTheDeviceLimit) {
  auto remote = openRemote();
  ASSERT_TRUE(remote);
  ASSERT_TRUE(eventually([&] {
    (*remote)->command(dm::Vec3(1, 2, 3), dm::Vec3::Zero(), monotonicNs());
    tick(remote->get());
    return local->lastOutput().force.isApprox(dm::Vec3(1, 2, 3), 1e-12);
  }));
  // 60 N asked, the device's 6 N given, direction kept — by the host's
  // HapticDevice before the network, so the wire never carries more.
  ASSERT_TRUE(eventually([&] {
    (*remote)->command(dm::Vec3(0, 0, 60), dm::Vec3::Zero(), monotonicNs());
    tick(remote->get());
    return local->lastOutput().force.isApprox(dm::Vec3(0, 0, 6), 1e-12);
  }));
}

TEST_F(NetHaptic, ASilentHostLeavesNoForceOnTheOperator) {
  auto remote = openRemote();
  ASSERT_TRUE(remote);
  ASSERT_TRUE(eventually([&] {
    (*remote)->command(dm::Vec3(2, 0, 0), dm::Vec3::Zero(), monotonicNs());
    tick(remote->get());
    return local->lastOutput().force.x() == 2.0;
  }));
  const std::uint64_t zeroedBefore = bridge->zeroedSteps();
  // The host stops (crashed simulation): only the device side runs.
  ASSERT_TRUE(eventually([&] {
    tick(nullptr);
    return local->lastOutput().force.isZero();
  }));
  EXPECT_GT(bridge->zeroedSteps(), zeroedBefore);
}

TEST_F(NetHaptic, LinkLossIsReportedAndTheDeviceComesBackAfterARestart) {
  auto remote = openRemote();
  ASSERT_TRUE(remote);
  ASSERT_TRUE(eventually([&] {
    tick(remote->get());
    return (*remote)->connected() && (*remote)->state().position.x() == 0.01;
  }));
  // The device side goes silent: lost after the 0.1 s timeout.
  ASSERT_TRUE(eventually([&] {
    tick(remote->get(), false);
    return !(*remote)->connected();
  }));
  EXPECT_GE((*remote)->counters().losses, 1u);
  // The device side restarts on the same port, knowing no host: the
  // driver's reconnect says Hello again and the stream resumes.
  const std::uint16_t port = link->port();
  openDeviceSide(port);
  ASSERT_TRUE(eventually([&] {
    tick(remote->get());
    return (*remote)->connected();
  }));
  EXPECT_GE((*remote)->counters().reconnects, 1u);
}

TEST_F(NetHaptic, ServoPathsDoNotAllocate) {
  auto remote = openRemote();
  ASSERT_TRUE(remote);
  ASSERT_TRUE(eventually([&] {
    tick(remote->get());
    return (*remote)->connected();
  }));
  dm::test::tCountAllocations = true;
  const auto before = dm::test::countedAllocations();
  for (int i = 0; i < 50; ++i) {
    const std::int64_t now = monotonicNs();
    (*remote)->command(dm::Vec3(0.5, 0, 0), dm::Vec3::Zero(), now);
    bridge->step(now);
    (*remote)->servo(now);
  }
  dm::test::tCountAllocations = false;
  EXPECT_EQ(dm::test::countedAllocations(), before);
}

TEST_F(NetHaptic, OpenFailsNamingTheAddressWhenNoDeviceSideAnswers) {
  const std::string where = "127.0.0.1:" + std::to_string(link->port());
  link.reset();  // nobody answers on that port any more
  bridge.reset();
  auto remote = dm::HapticDevice::open(registry, "net-haptic", {{"device", where}, {"connect_timeout", "0.2"}});
  ASSERT_FALSE(remote);
  EXPECT_NE(remote.error().message().find(where), std::string::npos) << remote.error().message();
}

TEST_F(NetHaptic, BadParametersNameTheKey) {
  auto missing = dm::HapticDevice::open(registry, "net-haptic", {});
  ASSERT_FALSE(missing);
  EXPECT_NE(missing.error().message().find("'device'"), std::string::npos) << missing.error().message();
  auto port = dm::HapticDevice::open(registry, "net-haptic", {{"device", "127.0.0.1:99999"}});
  ASSERT_FALSE(port);
  EXPECT_NE(port.error().message().find("'device'"), std::string::npos) << port.error().message();
  auto unknown = dm::HapticDevice::open(registry, "net-haptic", {{"device", "127.0.0.1:5"}, {"rate", "1"}});
  ASSERT_FALSE(unknown);
  EXPECT_NE(unknown.error().message().find("'rate'"), std::string::npos);
}

TEST(NetEndpoint, ParsesAddressPortForms) {
  auto v4 = dm::parseEndpoint("192.168.1.20:47000", "x");
  ASSERT_TRUE(v4);
  EXPECT_EQ(v4->address, "192.168.1.20");
  EXPECT_EQ(v4->port, 47000);
  auto v6 = dm::parseEndpoint("[::1]:5", "x");
  ASSERT_TRUE(v6);
  EXPECT_EQ(v6->address, "::1");
  EXPECT_FALSE(dm::parseEndpoint("127.0.0.1", "x"));
  EXPECT_FALSE(dm::parseEndpoint("127.0.0.1:0", "x"));
  EXPECT_TRUE(dm::parseEndpoint("127.0.0.1:0", "x", true));
  EXPECT_FALSE(dm::parseEndpoint("127.0.0.1:65536", "x"));
  EXPECT_FALSE(dm::parseEndpoint("127.0.0.1:12a", "x"));
}

}  // namespace
