// Tests of the tele-operation stream's in-process link ("inproc:NAME",
// dm/network/teleop.hpp) on a virtual clock the test advances, as a lockstep
// run does: states and forces flow with the timing the clock says (round
// trip and one-way latency measured exactly), an emulated delay falls due on
// that clock and not a nanosecond before, two runs with jitter and loss see
// the same stream tick for tick, names, hosts and clocks are checked, and
// net-haptic over such a link waits for its first state without reporting
// a lost device.
#include <dm/core/clock.hpp>
#include <dm/io/drivers.hpp>
#include <dm/network/drivers.hpp>
#include <dm/network/teleop.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "network_test_support.hpp"

namespace {

using namespace std::chrono_literals;
constexpr std::int64_t kOneMs = 1'000'000;

dm::HapticState stateAt(std::int64_t tick) {
  dm::HapticState s;
  s.timeNs = tick * kOneMs;
  s.position = dm::Vec3(1e-3 * static_cast<double>(tick), 0.0, 0.0);
  return s;
}

/// Both ends of one link, and the clock they run on.
struct InprocPair {
  dm::VirtualClock clock;
  std::unique_ptr<dm::TeleopDevice> device;
  std::unique_ptr<dm::TeleopHost> host;

  explicit InprocPair(const std::string& name,
                      std::optional<dm::LinkEmulatorOptions> emulate = std::nullopt) {
    auto d = dm::TeleopDevice::open({.local = {"inproc:" + name, 0}, .timeoutSeconds = 0.1, .clock = &clock},
                                    dm::test::sampleInfo());
    EXPECT_TRUE(d.ok()) << d.error().message();
    if (d) device = std::move(*d);
    auto h = dm::TeleopHost::open({.peer = {"inproc:" + name, 0}, .timeoutSeconds = 0.1, .emulate = emulate});
    EXPECT_TRUE(h.ok()) << h.error().message();
    if (h) host = std::move(*h);
  }

  /// One 1 kHz period: the device polls and sends its state, the host
  /// polls, reads and answers with a force; then the clock advances.
  /// Returns the position the host read (x in mm), or -1 when none yet.
  double tick(std::int64_t k) {
    device->poll();
    device->sendState(stateAt(k));
    host->poll();
    dm::HapticState s;
    const bool got = host->latestState(s);
    host->sendForce({.force = dm::Vec3(0.1, 0, 0)});
    clock.advance(kOneMs);
    return got ? 1e3 * s.position.x() : -1.0;
  }
};

TEST(TeleopInproc, StatesAndForcesFlowOnTheLinksClockWithExactTiming) {
  InprocPair link("flow");
  ASSERT_TRUE(link.device && link.host);
  EXPECT_EQ(&link.host->clock(), &link.clock);  // the host takes its device's clock
  EXPECT_EQ(link.host->port(), 0);
  auto info = link.host->waitForDevice(10ms);
  ASSERT_TRUE(info.ok()) << info.error().message();
  EXPECT_EQ(info->serial, "sim-7");
  EXPECT_EQ(info->maxForce, 8.0);
  // The device knows no host until it polled the Hello.
  EXPECT_FALSE(link.device->sendState(stateAt(0)));
  for (std::int64_t k = 0; k < 200; ++k) {
    // No delay: the host reads this tick's state in this tick.
    EXPECT_DOUBLE_EQ(link.tick(k), static_cast<double>(k)) << "tick " << k;
  }
  EXPECT_TRUE(link.host->linkUp());
  EXPECT_TRUE(link.device->linkUp());
  dm::HapticOutput f;
  std::int64_t age = -1;
  link.device->poll();
  ASSERT_TRUE(link.device->latestForce(f, &age));
  EXPECT_EQ(f.force, dm::Vec3(0.1, 0, 0));
  EXPECT_EQ(age, 0);
  // A state reaches the host in the tick it was sent (0 ms); the force the
  // host answers with reaches the device at its next poll, 1 ms later, so
  // the device measures a 1 ms round trip with no hold.
  const dm::TeleopStats host = link.host->stats(), device = link.device->stats();
  EXPECT_EQ(host.received, 200u);
  EXPECT_EQ(host.lost, 0u);
  EXPECT_LT(host.oneWay.max, 1e-6);
  EXPECT_NEAR(device.oneWay.p50, 1e-3, 1.6e-5);
  EXPECT_NEAR(device.roundTrip.p50, 1e-3, 1.6e-5);
  EXPECT_EQ(device.clockOffset, 0.0);  // one clock: no offset estimate
  EXPECT_EQ(host.jitter, 0.0);
}

TEST(TeleopInproc, AnEmulatedDelayFallsDueOnTheVirtualClock) {
  InprocPair link("delay", dm::LinkEmulatorOptions{.delay = 10ms, .seed = 1});
  ASSERT_TRUE(link.device && link.host);
  ASSERT_TRUE(link.host->waitForDevice(10ms).ok());
  // The device polls the Hello at the start of tick 0, so it streams from
  // then on; state k is sent at k ms and due at k + 10 ms: the host's tick
  // k reads state k − 10, and nothing before tick 10.
  for (std::int64_t k = 0; k < 100; ++k) {
    const double x = link.tick(k);
    if (k < 10)
      EXPECT_EQ(x, -1.0) << "tick " << k;
    else
      EXPECT_DOUBLE_EQ(x, static_cast<double>(k - 10)) << "tick " << k;
  }
  const dm::TeleopStats host = link.host->stats();
  EXPECT_NEAR(host.oneWay.p50, 10e-3, 1.6e-4);
  EXPECT_NEAR(host.oneWay.max, 10e-3, 1.6e-4);
  // The device: force of tick k (echoing state k − 10) arrives at k + 1.
  EXPECT_NEAR(link.device->stats().roundTrip.p50, 11e-3, 1.8e-4);
}

TEST(TeleopInproc, TwoRunsWithJitterAndLossSeeTheSameStream) {
  const auto run = [](const std::string& name) {
    InprocPair link(
        name, dm::LinkEmulatorOptions{
                  .delay = 10ms, .jitter = 2ms, .lossProbability = 0.05, .seed = 3, .maxPacketBytes = 512});
    EXPECT_TRUE(link.host->waitForDevice(10ms).ok());
    std::vector<double> seen;
    for (std::int64_t k = 0; k < 3000; ++k) seen.push_back(link.tick(k));
    return std::make_pair(seen, link.host->stats());
  };
  const auto [a, sa] = run("twice-a");
  const auto [b, sb] = run("twice-b");
  EXPECT_EQ(a, b);
  EXPECT_EQ(sa.lost, sb.lost);
  EXPECT_EQ(sa.late, sb.late);
  // 5 % loss of ~3000 states, within five standard deviations; jitter of
  // 2 ms on 1 ms spacing makes some states late (overtaken).
  EXPECT_NEAR(static_cast<double>(sa.lost), 0.05 * 2990, 5 * std::sqrt(2990 * 0.05 * 0.95));
  EXPECT_GT(sa.late, 0u);
  // One-way latency: due at 10 ms + U[0, 2 ms], read at the host's next
  // 1 ms poll: 11 or 12 ms, each half the time (mean 11.5 ms; the standard
  // error of ~2850 such draws is 9.4 µs).
  EXPECT_GE(sa.oneWay.min, 10e-3 * (1 - 0.016));
  EXPECT_LE(sa.oneWay.max, 12e-3 * (1 + 0.016));
  EXPECT_NEAR(sa.oneWay.mean, 11.5e-3, 5 * 9.4e-6);
}

TEST(TeleopInproc, NamesHostsAndClocksAreChecked) {
  dm::VirtualClock clock, other;
  auto first =
      dm::TeleopDevice::open({.local = {"inproc:checked", 0}, .clock = &clock}, dm::test::sampleInfo());
  ASSERT_TRUE(first.ok());
  auto again =
      dm::TeleopDevice::open({.local = {"inproc:checked", 0}, .clock = &clock}, dm::test::sampleInfo());
  ASSERT_FALSE(again.ok());
  EXPECT_NE(again.error().message().find("already open"), std::string::npos);
  auto missing = dm::TeleopHost::open({.peer = {"inproc:nobody", 0}});
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.error().code, dm::ErrorCode::NotFound);
  auto wrongClock = dm::TeleopHost::open({.peer = {"inproc:checked", 0}, .clock = &other});
  ASSERT_FALSE(wrongClock.ok());
  EXPECT_NE(wrongClock.error().message().find("clock"), std::string::npos);
  auto host = dm::TeleopHost::open({.peer = {"inproc:checked", 0}});
  ASSERT_TRUE(host.ok()) << host.error().message();  // the refused one did not keep the link
  auto second = dm::TeleopHost::open({.peer = {"inproc:checked", 0}});
  ASSERT_FALSE(second.ok());
  EXPECT_EQ(second.error().code, dm::ErrorCode::Busy);
  auto allow =
      dm::TeleopDevice::open({.local = {"inproc:allow", 0}, .allow = {"127.0.0.1"}}, dm::test::sampleInfo());
  ASSERT_FALSE(allow.ok());
  EXPECT_NE(allow.error().message().find("allow"), std::string::npos);
  auto unnamed = dm::TeleopDevice::open({.local = {"inproc:", 0}}, dm::test::sampleInfo());
  EXPECT_FALSE(unnamed.ok());
  auto socketWithClock =
      dm::TeleopDevice::open({.local = {"127.0.0.1", 0}, .clock = &clock}, dm::test::sampleInfo());
  ASSERT_FALSE(socketWithClock.ok());
  EXPECT_NE(socketWithClock.error().message().find("clock"), std::string::npos);
  // A closed device frees its name; its host's sends then fail.
  (*first)->close();
  EXPECT_FALSE((*host)->sendForce({}));
  EXPECT_FALSE((*host)->waitForDevice(10ms).ok());
  auto reopened =
      dm::TeleopDevice::open({.local = {"inproc:checked", 0}, .clock = &clock}, dm::test::sampleInfo());
  EXPECT_TRUE(reopened.ok());
}

TEST(TeleopInproc, AHostKnowsWhetherItsLinkRunsOnASuppliedClock) {
  // net-haptic waits for the first state in the run on a supplied clock
  // (it moves only as the run advances it) and before the run on the wall.
  dm::VirtualClock clock;
  auto stepped =
      dm::TeleopDevice::open({.local = {"inproc:stepped", 0}, .clock = &clock}, dm::test::sampleInfo());
  auto wall = dm::TeleopDevice::open({.local = {"inproc:wall", 0}}, dm::test::sampleInfo());
  ASSERT_TRUE(stepped.ok() && wall.ok());
  auto onStepped = dm::TeleopHost::open({.peer = {"inproc:stepped", 0}});
  auto onWall = dm::TeleopHost::open({.peer = {"inproc:wall", 0}});
  ASSERT_TRUE(onStepped.ok() && onWall.ok());
  EXPECT_TRUE((*onStepped)->onSuppliedClock());
  EXPECT_FALSE((*onWall)->onSuppliedClock());
  auto socket = dm::TeleopHost::open({.local = {"127.0.0.1", 0}, .peer = {"127.0.0.1", 9}});
  ASSERT_TRUE(socket.ok()) << socket.error().message();
  EXPECT_FALSE((*socket)->onSuppliedClock());
}

// ---- net-haptic over an in-process link -----------------------------------------

class NetHapticInproc : public ::testing::Test {
 protected:
  void SetUp() override {
    auto sim = dm::test::openHeldStylus(registry, linker);
    ASSERT_TRUE(sim) << sim.error().message();
    console = std::move(*sim);
    auto d = dm::TeleopDevice::open({.local = {"inproc:console", 0}, .timeoutSeconds = 0.1, .clock = &clock},
                                    console->info());
    ASSERT_TRUE(d) << d.error().message();
    link = std::move(*d);
    bridge = std::make_unique<dm::TeleopDeviceBridge>(*console, *link,
                                                      dm::TeleopBridgeOptions{.timeoutSeconds = 0.1});
  }

  dm::VirtualClock clock;
  dm::FactoryRegistry registry;
  dm::PluginLinker linker{registry};
  std::unique_ptr<dm::HapticDevice> console;
  std::unique_ptr<dm::TeleopDevice> link;
  std::unique_ptr<dm::TeleopDeviceBridge> bridge;
};

TEST_F(NetHapticInproc, WaitsForItsFirstStateOnTheRunsClockThenServesTheConsole) {
  auto remote = dm::HapticDevice::open(registry, "net-haptic",
                                       {{"device", "inproc:console"},
                                        {"wait_for_state", "0.05"},
                                        {"emulate_delay", "0.005"},
                                        {"emulate_seed", "2"}});
  ASSERT_TRUE(remote) << remote.error().message();
  EXPECT_EQ((*remote)->info().serial, console->info().serial);
  // States are 5 ms on the way: the first five servos have no sample yet
  // (an I/O error of the tick, not a lost device), then the console's.
  for (std::int64_t k = 0; k < 20; ++k) {
    const std::int64_t now = clock.now();
    bridge->step(now);
    (*remote)->command(dm::Vec3(0.5, 0, 0), dm::Vec3::Zero(), now);
    const dm::DeviceStatus status = (*remote)->servo(now);
    if (k < 5) {
      EXPECT_EQ(status, dm::DeviceStatus::IoError) << "tick " << k;
      EXPECT_FALSE((*remote)->hasState());
    } else {
      EXPECT_EQ(status, dm::DeviceStatus::Ok) << "tick " << k;
      EXPECT_TRUE((*remote)->state().position.isApprox(dm::Vec3(0.01, 0.02, 0.03)));
    }
    EXPECT_TRUE((*remote)->connected()) << "tick " << k;
    clock.advance(kOneMs);
  }
  // The force the simulator commanded reached the console's motor.
  EXPECT_NEAR(console->lastOutput().force.x(), 0.5, 1e-12);
}

TEST_F(NetHapticInproc, WithoutAStateWithinWaitForStateTheDeviceIsLost) {
  auto remote = dm::HapticDevice::open(registry, "net-haptic",
                                       {{"device", "inproc:console"}, {"wait_for_state", "0.003"}});
  ASSERT_TRUE(remote) << remote.error().message();
  // The console never steps: after 3 ms of waiting the device is lost.
  std::vector<dm::DeviceStatus> statuses;
  for (int k = 0; k < 5; ++k) {
    statuses.push_back((*remote)->servo(clock.now()));
    clock.advance(kOneMs);
  }
  EXPECT_EQ(statuses[0], dm::DeviceStatus::IoError);
  EXPECT_EQ(statuses[2], dm::DeviceStatus::IoError);
  EXPECT_EQ(statuses[3], dm::DeviceStatus::Lost);
  EXPECT_FALSE((*remote)->connected());
}

TEST_F(NetHapticInproc, SocketParametersAreRefusedForAnInProcessDevice) {
  for (const char* key : {"local", "synchronized_clocks"}) {
    auto remote = dm::HapticDevice::open(registry, "net-haptic", {{"device", "inproc:console"}, {key, "1"}});
    ASSERT_FALSE(remote.ok()) << key;
    EXPECT_NE(remote.error().message().find(key), std::string::npos) << remote.error().message();
  }
}

}  // namespace
