// The force-dimension-dhd driver against the stand-in DHD library
// (Tests/DMIO/plugins/force_dimension_stand_in.cpp, simulated devices that
// the test moves, unplugs and puts in RESET mode): it reports a known model
// with its datasheet's force and workspace, and refuses an unknown one until
// given them; pose, orientation frame, velocities and buttons arrive as the
// device gives them; forces (and torques, with an active wrist) reach the
// device; a device waiting for its calibration has its samples refused and
// gets no force; a device unplugged mid-run is lost and comes back; bad
// parameters and a missing library are refused naming them.
#include <dm/io/drivers.hpp>
#include <dm/io/haptic_device.hpp>

#include <gtest/gtest.h>

#include <dlfcn.h>

#include <algorithm>
#include <numbers>
#include <string>

#include "driver_test_support.hpp"

namespace force_dimension_dhd_test {

using dm::Vec3;
using dm::test::kMs;

std::string standInPath() { return dm::test::besideExecutable(DM_TEST_DHD_STAND_IN); }

struct StandIn : dm::test::StandInLibrary {
  StandIn() : StandInLibrary(standInPath()) {}
  void type(int t, int devices = 1) const { fn<void (*)(int, int)>("dmDhdStandInSetType")(t, devices); }
  void pose(const Vec3& p, const dm::Mat3& r) const {
    double rr[9];
    for (int i = 0; i < 9; ++i) rr[i] = r(i / 3, i % 3);
    fn<void (*)(const double*, const double*)>("dmDhdStandInSetPose")(p.data(), rr);
  }
  void velocity(const Vec3& v, const Vec3& w) const {
    fn<void (*)(const double*, const double*)>("dmDhdStandInSetVelocity")(v.data(), w.data());
  }
  void buttons(int b) const { fn<void (*)(int)>("dmDhdStandInSetButtons")(b); }
  void plugged(bool p) const { fn<void (*)(int)>("dmDhdStandInSetPlugged")(p ? 1 : 0); }
  void reset(bool r) const { fn<void (*)(int)>("dmDhdStandInSetReset")(r ? 1 : 0); }
  std::pair<Vec3, Vec3> applied() const {
    Vec3 f, t;
    fn<void (*)(double*, double*)>("dmDhdStandInApplied")(f.data(), t.data());
    return {f, t};
  }
};

class ForceDimensionDhd : public ::testing::Test {
 protected:
  void SetUp() override {
    ASSERT_NE(hand_.lib, nullptr) << ::dlerror();
    hand_.type(34);  // omega.6
    hand_.plugged(true);
    hand_.reset(false);
    hand_.buttons(0);
    hand_.pose(Vec3::Zero(), dm::Mat3::Identity());
    hand_.velocity(Vec3::Zero(), Vec3::Zero());
  }
  dm::Result<std::unique_ptr<dm::HapticDevice>> open(dm::DeviceParams params = {}) {
    params.emplace_back("library", standInPath());
    return dm::HapticDevice::open(drivers_.registry, "force-dimension-dhd", params);
  }
  // One servo step a millisecond after the last (the host's loop time).
  dm::DeviceStatus step(dm::HapticDevice& d) { return d.servo(t_ += kMs); }
  StandIn hand_;
  dm::test::BuiltinDrivers drivers_;
  std::int64_t t_ = 0;
};

TEST_F(ForceDimensionDhd, AKnownModelReportsItsDatasheet) {
  auto d = open();
  ASSERT_TRUE(d.ok()) << d.error().message();
  const dm::HapticInfo& i = (*d)->info();
  EXPECT_EQ(i.driver, "force-dimension-dhd");
  EXPECT_EQ(i.vendor, "Force Dimension");
  EXPECT_EQ(i.model, "omega.6");
  EXPECT_EQ(i.serial, "4242");
  EXPECT_EQ(i.maxForce, 12.0);
  EXPECT_TRUE(i.workspace.max().isApprox(Vec3(0.055, 0.08, 0.08)));
  EXPECT_TRUE(i.workspace.min().isApprox(-Vec3(0.055, 0.08, 0.08)));
  EXPECT_FALSE(i.capabilities & DM_HAPTIC_CAP_TORQUE);  // the omega.6's wrist is passive
  EXPECT_EQ(i.servoRateHz, 1000.0);
  EXPECT_EQ(i.buttonCount, 8u);
}

TEST_F(ForceDimensionDhd, AnUnknownModelNeedsItsDatasheetValues) {
  hand_.type(91);  // DHD_DEVICE_CUSTOM
  auto bare = open();
  ASSERT_FALSE(bare.ok());
  EXPECT_NE(bare.error().message().find("'max_force'"), std::string::npos) << bare.error().message();
  auto given = open({{"max_force", "6"}, {"workspace", "0.1,0.12,0.08"}});
  ASSERT_TRUE(given.ok()) << given.error().message();
  EXPECT_EQ((*given)->info().maxForce, 6.0);
  EXPECT_TRUE((*given)->info().workspace.max().isApprox(Vec3(0.1, 0.12, 0.08)));
}

TEST_F(ForceDimensionDhd, PoseFrameVelocitiesAndButtonsArriveAsTheDeviceGivesThem) {
  auto d = open();
  ASSERT_TRUE(d.ok()) << d.error().message();
  const dm::Quat q(dm::AngleAxis(-50.0 * std::numbers::pi / 180.0, Vec3(0.3, -1.0, 0.4).normalized()));
  hand_.pose(Vec3(0.021, -0.013, 0.034), q.toRotationMatrix());
  hand_.velocity(Vec3(0.2, -0.1, 0.05), Vec3(0.5, 0.0, -1.0));
  hand_.buttons(0b10000011);
  dm::HapticDevice& dev = **d;
  ASSERT_EQ(step(dev), dm::DeviceStatus::Ok);
  const dm::HapticState& s = dev.state();
  EXPECT_EQ(s.timeNs, t_);
  EXPECT_EQ(s.position, Vec3(0.021, -0.013, 0.034));
  EXPECT_NEAR(std::abs(s.orientation.dot(q)), 1.0, 1e-12);
  EXPECT_EQ(s.linearVelocity, Vec3(0.2, -0.1, 0.05));
  EXPECT_EQ(s.angularVelocity, Vec3(0.5, 0.0, -1.0));
  EXPECT_EQ(s.buttons, 0b10000011u);
}

TEST_F(ForceDimensionDhd, ForcesAndAnActiveWristsTorquesReachTheDevice) {
  auto omega = open();
  ASSERT_TRUE(omega.ok()) << omega.error().message();
  (*omega)->command(Vec3(1.5, -2.0, 3.0), Vec3(0.1, 0.0, 0.0), t_ + kMs);
  ASSERT_EQ(step(**omega), dm::DeviceStatus::Ok);
  EXPECT_EQ(hand_.applied().first, Vec3(1.5, -2.0, 3.0));
  EXPECT_EQ(hand_.applied().second, Vec3::Zero());  // no torque output: none sent
  (*omega)->command(Vec3(0.0, 30.0, 0.0), Vec3::Zero(), t_ + kMs);
  ASSERT_EQ(step(**omega), dm::DeviceStatus::Ok);
  EXPECT_EQ(hand_.applied().first, Vec3(0.0, 12.0, 0.0));  // clamped by the host to the datasheet's
  omega->reset();

  hand_.type(64);  // delta.6: an active wrist
  auto delta = open({{"max_torque", "0.2"}});
  ASSERT_TRUE(delta.ok()) << delta.error().message();
  EXPECT_TRUE((*delta)->info().capabilities & DM_HAPTIC_CAP_TORQUE);
  EXPECT_EQ((*delta)->info().maxForce, 20.0);
  (*delta)->command(Vec3(4.0, 0.0, -1.0), Vec3(0.0, 0.05, -0.1), t_ + kMs);
  ASSERT_EQ(step(**delta), dm::DeviceStatus::Ok);
  EXPECT_EQ(hand_.applied().first, Vec3(4.0, 0.0, -1.0));
  EXPECT_EQ(hand_.applied().second, Vec3(0.0, 0.05, -0.1));
}

TEST_F(ForceDimensionDhd, ADeviceWaitingForItsCalibrationGetsNoForce) {
  auto d = open();
  ASSERT_TRUE(d.ok()) << d.error().message();
  dm::HapticDevice& dev = **d;
  const Vec3 f(0.0, 0.0, 2.0);
  dev.command(f, Vec3::Zero(), t_ + kMs);
  ASSERT_EQ(step(dev), dm::DeviceStatus::Ok);
  EXPECT_EQ(hand_.applied().first, f);
  hand_.reset(true);
  for (int k = 0; k < 5; ++k) {
    dev.command(f, Vec3::Zero(), t_ + kMs);
    EXPECT_EQ(step(dev), dm::DeviceStatus::IoError) << k;
    EXPECT_EQ(hand_.applied().first, Vec3::Zero()) << k;
  }
  hand_.reset(false);
  dev.command(f, Vec3::Zero(), t_ + kMs);
  EXPECT_EQ(step(dev), dm::DeviceStatus::Ok);
  EXPECT_EQ(hand_.applied().first, f);
}

TEST_F(ForceDimensionDhd, UnpluggedMidRunItIsLostAndComesBack) {
  auto d = open();
  ASSERT_TRUE(d.ok()) << d.error().message();
  dm::HapticDevice& dev = **d;
  const Vec3 f(1.0, 1.0, 0.0);
  dev.command(f, Vec3::Zero(), t_ + kMs);
  ASSERT_EQ(step(dev), dm::DeviceStatus::Ok);
  hand_.plugged(false);
  EXPECT_EQ(step(dev), dm::DeviceStatus::Lost);
  EXPECT_FALSE(dev.connected());
  for (int k = 0; k < 300; ++k) {  // 0.3 s: three reconnection attempts fail
    dev.command(f, Vec3::Zero(), t_ + kMs);
    EXPECT_EQ(step(dev), dm::DeviceStatus::Lost) << k;
  }
  EXPECT_EQ(dev.lastOutput().force, Vec3::Zero());
  hand_.plugged(true);
  dm::DeviceStatus s = dm::DeviceStatus::Lost;
  for (int k = 0; k < 200 && s != dm::DeviceStatus::Ok; ++k) s = step(dev);
  ASSERT_EQ(s, dm::DeviceStatus::Ok);
  EXPECT_TRUE(dev.connected());
  EXPECT_EQ(dev.counters().losses, 1u);
  EXPECT_EQ(dev.counters().reconnects, 1u);
  dev.command(f, Vec3::Zero(), t_ + kMs);
  ASSERT_EQ(step(dev), dm::DeviceStatus::Ok);
  EXPECT_EQ(hand_.applied().first, f);
}

TEST_F(ForceDimensionDhd, BadParametersAndAMissingLibraryAreRefusedNamingThem) {
  auto index = open({{"index", "2"}});
  ASSERT_FALSE(index.ok());
  EXPECT_NE(index.error().message().find("'index': 2, but 1 device is connected"), std::string::npos)
      << index.error().message();
  auto half = open({{"index", "0.5"}});
  ASSERT_FALSE(half.ok());
  EXPECT_NE(half.error().message().find("'index'"), std::string::npos) << half.error().message();
  auto workspace = open({{"workspace", "0.1,0,0.1"}});
  ASSERT_FALSE(workspace.ok());
  EXPECT_NE(workspace.error().message().find("'workspace'"), std::string::npos);
  hand_.plugged(false);
  auto none = open();
  ASSERT_FALSE(none.ok());
  EXPECT_NE(none.error().message().find("no device connected"), std::string::npos) << none.error().message();
  hand_.plugged(true);

  auto missing = dm::HapticDevice::open(drivers_.registry, "force-dimension-dhd",
                                        {{"library", "/nonexistent/libdhd.so"}});
  ASSERT_FALSE(missing.ok());
  EXPECT_NE(missing.error().message().find("Force Dimension DHD"), std::string::npos);
  EXPECT_NE(missing.error().message().find("install the Force Dimension SDK"), std::string::npos);

  const auto all = dm::vendorDriverStatus();
  const auto it =
      std::find_if(all.begin(), all.end(), [](const auto& s) { return s.driver == "force-dimension-dhd"; });
  ASSERT_NE(it, all.end());
  void* real = ::dlopen("libdhd.so", RTLD_NOW | RTLD_LOCAL);
  EXPECT_EQ(it->available, real != nullptr);
  if (real) ::dlclose(real);
}

}  // namespace force_dimension_dhd_test
