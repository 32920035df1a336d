// The conformance suite every haptic-device driver passes, built in and as
// its plugin module: what it reports about itself is usable (its factory
// name, a positive force limit and servo rate, a workspace box, position
// and force capabilities); it streams finite samples with a unit
// quaternion stamped with the host's time at its servo rate; a force within
// its limit reaches it unchanged and a NaN never does; it opens and closes
// again and again; an unknown parameter is refused naming it. Drivers of
// vendor libraries run against the stand-in libraries built with the tests
// (Tests/DMIO/plugins), the serial Haply driver against a stand-in board on
// a pseudo-terminal (haply_board_stand_in.hpp). A planar device's workspace
// is flat along z, and its samples lie in that plane.
#include <dm/io/haptic_device.hpp>

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <limits>
#include <string>
#include <thread>

#include "driver_test_support.hpp"
#include "haply_board_stand_in.hpp"

namespace haptic_conformance_test {

struct DriverCase {
  const char* label;
  const char* driver;
  const char* pluginFile;  // nullptr: built in
  dm::DeviceParams params;
  bool planar = false;  // moves in the plane z = workspace z
};

std::ostream& operator<<(std::ostream& os, const DriverCase& c) { return os << c.label; }

// The stand-in vendor library a driver of a vendor's library loads here.
std::string standInFor(const std::string& driver) {
  if (driver == "openhaptics-hd") return dm::test::besideExecutable(DM_TEST_HD_STAND_IN);
  if (driver == "force-dimension-dhd") return dm::test::besideExecutable(DM_TEST_DHD_STAND_IN);
  return {};
}

class HapticDriverConformance : public ::testing::TestWithParam<DriverCase> {
 protected:
  void SetUp() override {
    const DriverCase& c = GetParam();
    if (c.pluginFile) {
      auto r = linker_.load(dm::test::besideExecutable(DM_DRIVER_PLUGIN_DIR) + "/" + c.pluginFile);
      ASSERT_TRUE(r.ok()) << r.error().message();
    } else {
      ASSERT_TRUE(dm::registerBuiltinDrivers(linker_).ok());
    }
  }
  dm::Result<std::unique_ptr<dm::HapticDevice>> open(dm::DeviceParams params) {
    if (const std::string lib = standInFor(GetParam().driver); !lib.empty())
      params.emplace_back("library", lib);
    if (std::string(GetParam().driver) == "haply-2diy") {
      // A board on a pseudo-terminal, its arms at a pose mid-workspace.
      if (!board_)
        board_ = std::make_unique<dm::test::HaplyBoardStandIn>(
            std::filesystem::temp_directory_path() / ("dm_conformance_board_" + std::to_string(::getpid())));
      board_->setCounts(1, -1536);  // arm 1 at 180° − 40°
      board_->setCounts(2, 1536);   // arm 2 at 40°
      params.emplace_back("path", board_->path());
    }
    return dm::HapticDevice::open(registry_, GetParam().driver, params);
  }
  static std::int64_t now() {
    return std::chrono::duration_cast<std::chrono::nanoseconds>(
               std::chrono::steady_clock::now().time_since_epoch())
        .count();
  }
  // Servo steps at the device's rate in real time until the first good
  // sample (a driver with a servo thread of its own needs its first tick).
  static bool firstSample(dm::HapticDevice& d) {
    for (int i = 0; i < 2000; ++i) {
      if (d.servo(now()) == dm::DeviceStatus::Ok) return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    return false;
  }
  dm::FactoryRegistry registry_;
  dm::PluginLinker linker_{registry_};
  std::unique_ptr<dm::test::HaplyBoardStandIn> board_;
};

TEST_P(HapticDriverConformance, ReportsUsableIdentityAndLimits) {
  auto d = open(GetParam().params);
  ASSERT_TRUE(d.ok()) << d.error().message();
  const dm::HapticInfo& i = (*d)->info();
  EXPECT_EQ(i.driver, GetParam().driver);
  EXPECT_GT(i.maxForce, 0.0);
  EXPECT_GT(i.servoRateHz, 0.0);
  for (int a = 0; a < (GetParam().planar ? 2 : 3); ++a)
    EXPECT_LT(i.workspace.min()[a], i.workspace.max()[a]) << a;
  if (GetParam().planar) {
    EXPECT_EQ(i.workspace.min().z(), i.workspace.max().z());
  }
  EXPECT_TRUE(i.capabilities & DM_HAPTIC_CAP_POSITION);
  EXPECT_TRUE(i.capabilities & DM_HAPTIC_CAP_FORCE);
  EXPECT_LE(i.buttonCount, 32u);
}

TEST_P(HapticDriverConformance, StreamsFiniteStampedSamples) {
  auto d = open(GetParam().params);
  ASSERT_TRUE(d.ok()) << d.error().message();
  dm::HapticDevice& dev = **d;
  ASSERT_TRUE(firstSample(dev));
  int good = 0;
  for (int k = 0; k < 200; ++k) {
    const std::int64_t t = now();
    const dm::DeviceStatus s = dev.servo(t);
    ASSERT_EQ(s, dm::DeviceStatus::Ok) << k;
    const dm::HapticState& st = dev.state();
    EXPECT_EQ(st.timeNs, t);
    EXPECT_TRUE(st.position.allFinite());
    EXPECT_TRUE(st.linearVelocity.allFinite());
    EXPECT_NEAR(st.orientation.norm(), 1.0, 1e-12);
    if (GetParam().planar) {
      EXPECT_EQ(st.position.z(), dev.info().workspace.min().z());
    }
    ++good;
    std::this_thread::sleep_for(std::chrono::microseconds(500));
  }
  EXPECT_EQ(good, 200);
  EXPECT_EQ(dev.counters().nonFinite, 0u);
}

TEST_P(HapticDriverConformance, AForceWithinItsLimitArrivesAndANanNever) {
  auto d = open(GetParam().params);
  ASSERT_TRUE(d.ok()) << d.error().message();
  dm::HapticDevice& dev = **d;
  ASSERT_TRUE(firstSample(dev));
  const double f = 0.5 * dev.info().maxForce;
  dev.command(dm::Vec3(f, -0.5 * f, 0.25 * f), dm::Vec3::Zero(), now());
  ASSERT_EQ(dev.servo(now()), dm::DeviceStatus::Ok);
  EXPECT_EQ(dev.lastOutput().force, dm::Vec3(f, -0.5 * f, 0.25 * f));
  const double nan = std::numeric_limits<double>::quiet_NaN();
  dev.command(dm::Vec3(nan, 0, 0), dm::Vec3::Zero(), now());
  ASSERT_EQ(dev.servo(now()), dm::DeviceStatus::Ok);
  EXPECT_EQ(dev.lastOutput().force, dm::Vec3::Zero());
}

TEST_P(HapticDriverConformance, OpensAndClosesAgainAndAgain) {
  for (int k = 0; k < 3; ++k) {
    auto d = open(GetParam().params);
    ASSERT_TRUE(d.ok()) << k << ": " << d.error().message();
    EXPECT_TRUE(firstSample(**d)) << k;
  }
}

TEST_P(HapticDriverConformance, AnUnknownParameterIsRefusedNamingIt) {
  dm::DeviceParams params = GetParam().params;
  params.emplace_back("colour", "red");
  auto d = open(params);
  ASSERT_FALSE(d.ok());
  EXPECT_NE(d.error().message().find("colour"), std::string::npos) << d.error().message();
}

INSTANTIATE_TEST_SUITE_P(
    Drivers, HapticDriverConformance,
    ::testing::Values(
        DriverCase{"sim_haptic", "sim-haptic", nullptr, {{"path", "circle"}}},
        DriverCase{"sim_haptic_plugin", "sim-haptic", "libdm_driver_sim_haptic.so", {}},
        DriverCase{"openhaptics_hd", "openhaptics-hd", nullptr, {}},
        DriverCase{"openhaptics_hd_plugin", "openhaptics-hd", "libdm_driver_openhaptics_hd.so", {}},
        DriverCase{"force_dimension_dhd", "force-dimension-dhd", nullptr, {}},
        DriverCase{
            "force_dimension_dhd_plugin", "force-dimension-dhd", "libdm_driver_force_dimension_dhd.so", {}},
        DriverCase{"haply_2diy", "haply-2diy", nullptr, {{"max_force", "2"}}, true},
        DriverCase{
            "haply_2diy_plugin", "haply-2diy", "libdm_driver_haply_2diy.so", {{"max_force", "2"}}, true},
        DriverCase{"pointer", "pointer", nullptr, {{"channel", "conformance"}}}),
    [](const ::testing::TestParamInfo<DriverCase>& i) { return std::string(i.param.label); });

}  // namespace haptic_conformance_test
