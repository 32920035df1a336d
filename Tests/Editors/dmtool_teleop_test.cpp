// dmtool teleop-device: serves sim-haptic over the tele-operation stream, and
// this test, as the remote simulator, opens it through the net-haptic driver
// and sees the stylus where sim-haptic puts it; bad options are refused.
#include <dm/core/clock.hpp>
#include <dm/io/haptic_device.hpp>
#include <dm/network/drivers.hpp>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <string>
#include <thread>

#include "dmtool_run.hpp"

namespace {

using dmtool_test::describe;
using dmtool_test::parseJson;
using dmtool_test::runTool;

// A UDP port that was free a moment ago (bound to port 0, then released).
std::uint16_t freeUdpPort() {
  const int fd = ::socket(AF_INET, SOCK_DGRAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  ::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a);
  socklen_t n = sizeof a;
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &n);
  ::close(fd);
  return ntohs(a.sin_port);
}

std::int64_t monotonicNs() { return dm::RealClock().now(); }  // CLOCK_MONOTONIC, as the stream

TEST(DmtoolTeleop, ServesSimHapticToTheNetHapticDriver) {
  const std::string port = std::to_string(freeUdpPort());
  dmtool_test::ToolRun tool;
  std::thread server([&] {
    tool = runTool({"teleop-device", "--driver", "sim-haptic", "--param", "path=point", "--param",
                    "center=0.01,-0.02,0.03", "--listen", "127.0.0.1:" + port, "--seconds", "3", "--json"});
  });
  dm::FactoryRegistry registry;
  dm::PluginLinker linker(registry);
  ASSERT_TRUE(dm::registerNetworkDrivers(linker));
  auto remote = dm::HapticDevice::open(registry, "net-haptic",
                                       {{"device", "127.0.0.1:" + port}, {"connect_timeout", "2.5"}});
  ASSERT_TRUE(remote) << remote.error().message();
  EXPECT_EQ((*remote)->info().model, "simulated 3-DOF stylus");
  bool there = false;
  for (int i = 0; i < 2000 && !there; ++i) {
    (*remote)->servo(monotonicNs());
    there = (*remote)->state().position == dm::Vec3(0.01, -0.02, 0.03);
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  EXPECT_TRUE(there);
  server.join();
  ASSERT_EQ(tool.exitCode, 0) << describe(tool);
  EXPECT_NE(tool.err.find("serving sim-haptic"), std::string::npos) << tool.err;
  const nlohmann::json j = parseJson(tool);
  EXPECT_EQ(j["port"], std::stoi(port));
  EXPECT_GT(j["stream"]["sent"].get<std::uint64_t>(), 0u);
  EXPECT_GT(j["stream"]["received"].get<std::uint64_t>(), 0u);  // the forces the driver sent
  EXPECT_EQ(j["stream"]["malformed"], 0);
}

TEST(DmtoolTeleop, WaveImpedanceServesTheMasterPortOfAWaveLoop) {
  // A fixed stylus (sim-haptic "point") is the master; the simulator renders
  // a constant 1 N on net-haptic's tool. A master that does not move
  // reflects every wave, so the loop settles where the tool is at rest and
  // the device displays the rendered force: −Fm = √(2b)·v = F.
  const std::string port = std::to_string(freeUdpPort());
  dmtool_test::ToolRun tool;
  std::atomic<bool> done{false};
  std::thread server([&] {
    tool = runTool({"teleop-device", "--driver", "sim-haptic", "--param", "path=point", "--listen",
                    "127.0.0.1:" + port, "--wave-impedance", "40", "--timeout", "1", "--seconds", "2.5",
                    "--json"});
    done = true;
  });
  dm::FactoryRegistry registry;
  dm::PluginLinker linker(registry);
  ASSERT_TRUE(dm::registerNetworkDrivers(linker));
  auto remote = dm::HapticDevice::open(
      registry, "net-haptic",
      {{"device", "127.0.0.1:" + port}, {"connect_timeout", "2"}, {"timeout", "1"}, {"wave_impedance", "40"}});
  if (!remote) {
    server.join();
    FAIL() << remote.error().message();
  }
  double drift = 0.0;
  // At the device's 1 kHz on an absolute schedule (a late tick is caught up,
  // as the device's RealTimeLoop does): the master's receiver counts its
  // budget in samples, so a slower host would thin the force it displays.
  auto next = std::chrono::steady_clock::now();
  while (!done.load()) {  // serve until the tool has written its statistics
    const std::int64_t now = monotonicNs();
    (*remote)->servo(now);
    drift = std::max(drift, (*remote)->state().position.norm());
    (*remote)->command(dm::Vec3(0, 0, 1.0), dm::Vec3::Zero(), now);
    next += std::chrono::milliseconds(1);
    std::this_thread::sleep_until(next);
  }
  server.join();
  ASSERT_EQ(tool.exitCode, 0) << describe(tool);
  const nlohmann::json j = parseJson(tool);
  ASSERT_TRUE(j.contains("wave")) << tool.out;
  EXPECT_EQ(j["wave"]["impedance"], 40.0);
  EXPECT_GT(j["wave"]["received"].get<std::uint64_t>(), 1000u);
  EXPECT_LE(j["wave"]["energy_out_J"].get<double>(), j["wave"]["energy_in_J"].get<double>() + 1e-12);
  // What the hand feels: a tick without a new sample and without budget
  // left displays zero (the receiver never creates energy), so the last tick
  // alone may be 0 N; its 0.1 s mean is the rendered force, less the ticks
  // a late host left without a sample.
  EXPECT_NEAR(j["output_force_mean_N"][2].get<double>(), 1.0, 0.15) << tool.out;
  EXPECT_NEAR(j["output_force_mean_N"][0].get<double>(), 0.0, 1e-6);
  // The tool, pushed by 1 N against a fixed master, moves at F/(2b) =
  // 12.5 mm/s only until the master's reflection arrives: a few millimetres
  // (about 1 cm when a loaded machine stalls the device side).
  EXPECT_LT(drift, 0.03) << "m";
}

TEST(DmtoolTeleop, DevicesListsTheNetHapticDriver) {
  const auto r = runTool({"devices", "--only", "net-haptic"});
  EXPECT_EQ(r.exitCode, 0) << describe(r);
  EXPECT_NE(r.out.find("haptic-device / net-haptic"), std::string::npos) << r.out;
}

TEST(DmtoolTeleop, RefusesBadOptions) {
  const auto listen = runTool({"teleop-device", "--listen", "127.0.0.1", "--seconds", "0.1"});
  EXPECT_EQ(listen.exitCode, 2) << describe(listen);
  EXPECT_NE(listen.err.find("--listen"), std::string::npos) << listen.err;
  const auto param = runTool({"teleop-device", "--param", "radius", "--seconds", "0.1"});
  EXPECT_EQ(param.exitCode, 2) << describe(param);
  const auto driver = runTool({"teleop-device", "--driver", "phantom-omni", "--seconds", "0.1"});
  EXPECT_EQ(driver.exitCode, 1) << describe(driver);
  EXPECT_NE(driver.err.find("phantom-omni"), std::string::npos) << driver.err;
}

}  // namespace
