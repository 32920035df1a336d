// The openhaptics-hd driver against the stand-in HD library
// (Tests/DMIO/plugins/openhaptics_stand_in.cpp, a simulated Touch that the
// test moves, unplugs and decalibrates): it reports the device in SI units;
// a pose, velocity and buttons set on the device arrive in metres with the
// rotation as a quaternion; forces reach the device, clamped by the host to
// the continuous force; a device that needs manual calibration gets no force
// until it is calibrated, and the driver updates a calibration that only
// needs an update (unless told not to); a device unplugged mid-run is lost,
// gets nothing, and comes back when plugged in; a force error is one I/O
// error; bad parameters, a missing library and a library that is not the
// HD API are refused naming them, and vendorDriverStatus() says whether
// this machine has the real library.
#include <dm/io/drivers.hpp>
#include <dm/io/haptic_device.hpp>

#include <gtest/gtest.h>

#include <dlfcn.h>

#include <chrono>
#include <cmath>
#include <functional>
#include <numbers>
#include <string>
#include <thread>

#include "driver_test_support.hpp"

namespace openhaptics_hd_test {

using dm::Vec3;

constexpr unsigned kCalibrationOk = 0x5000, kNeedsUpdate = 0x5001, kNeedsManualInput = 0x5002;

std::string standInPath() { return dm::test::besideExecutable(DM_TEST_HD_STAND_IN); }

// The test's hand on the stand-in device (the same library instance the
// driver loads: dlopen of one path gives one copy).
struct StandIn : dm::test::StandInLibrary {
  StandIn() : StandInLibrary(standInPath()) {}
  void pose(const Vec3& mm, const dm::Mat3& r) const {
    double rr[9];
    for (int i = 0; i < 9; ++i) rr[i] = r(i / 3, i % 3);
    fn<void (*)(const double*, const double*)>("dmHdStandInSetPose")(mm.data(), rr);
  }
  void velocity(const Vec3& mmPerS, const Vec3& w) const {
    fn<void (*)(const double*, const double*)>("dmHdStandInSetVelocity")(mmPerS.data(), w.data());
  }
  void buttons(int b) const { fn<void (*)(int)>("dmHdStandInSetButtons")(b); }
  void plugged(bool p) const { fn<void (*)(int)>("dmHdStandInSetPlugged")(p ? 1 : 0); }
  void calibration(unsigned s) const { fn<void (*)(unsigned)>("dmHdStandInSetCalibration")(s); }
  unsigned calibration() const { return fn<unsigned (*)()>("hdCheckCalibration")(); }
  void raise(unsigned e) const { fn<void (*)(unsigned)>("dmHdStandInRaise")(e); }
  Vec3 applied() const {
    Vec3 f;
    fn<void (*)(double*)>("dmHdStandInAppliedForce")(f.data());
    return f;
  }
};

std::int64_t now() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

class OpenHapticsHd : public ::testing::Test {
 protected:
  void SetUp() override {
    ASSERT_NE(hand_.lib, nullptr) << ::dlerror();
    hand_.plugged(true);
    hand_.calibration(kCalibrationOk);
    hand_.buttons(0);
    hand_.pose(Vec3::Zero(), dm::Mat3::Identity());
    hand_.velocity(Vec3::Zero(), Vec3::Zero());
  }
  dm::Result<std::unique_ptr<dm::HapticDevice>> open(dm::DeviceParams params = {}) {
    params.emplace_back("library", standInPath());
    return dm::HapticDevice::open(drivers_.registry, "openhaptics-hd", params);
  }
  // Servo steps every millisecond of real time until `done` (at most 2 s).
  static bool servoUntil(dm::HapticDevice& d, const std::function<bool(dm::DeviceStatus)>& done) {
    for (int i = 0; i < 2000; ++i) {
      if (done(d.servo(now()))) return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    return false;
  }
  static bool ok(dm::DeviceStatus s) { return s == dm::DeviceStatus::Ok; }
  StandIn hand_;
  dm::test::BuiltinDrivers drivers_;
};

TEST_F(OpenHapticsHd, ReportsTheDeviceInSiUnits) {
  auto d = open();
  ASSERT_TRUE(d.ok()) << d.error().message();
  const dm::HapticInfo& i = (*d)->info();
  EXPECT_EQ(i.driver, "openhaptics-hd");
  EXPECT_EQ(i.model, "Touch");
  EXPECT_EQ(i.vendor, "3D Systems (stand-in)");
  EXPECT_EQ(i.serial, "stand-in-0001");
  EXPECT_DOUBLE_EQ(i.maxForce, 0.88);        // the continuous force, not the 3.3 N peak
  EXPECT_DOUBLE_EQ(i.maxStiffness, 1260.0);  // 1.26 N/mm
  EXPECT_DOUBLE_EQ(i.maxDamping, 5.0);       // 0.005 N·s/mm
  EXPECT_DOUBLE_EQ(i.servoRateHz, 1000.0);
  EXPECT_TRUE(i.workspace.min().isApprox(Vec3(-0.08, -0.06, -0.035)));
  EXPECT_TRUE(i.workspace.max().isApprox(Vec3(0.08, 0.06, 0.035)));
  EXPECT_FALSE(i.capabilities & DM_HAPTIC_CAP_TORQUE);  // forces only
  EXPECT_EQ(i.maxTorque, 0.0);
}

TEST_F(OpenHapticsHd, PoseVelocityAndButtonsArriveInMetres) {
  auto d = open();
  ASSERT_TRUE(d.ok()) << d.error().message();
  // A stylus tilted 35° about an oblique axis, off the centre.
  const Vec3 axis = Vec3(1.0, 2.0, -0.5).normalized();
  const dm::Quat q(dm::AngleAxis(35.0 * std::numbers::pi / 180.0, axis));
  hand_.pose(Vec3(12.5, -30.0, 7.0), q.toRotationMatrix());
  hand_.velocity(Vec3(100.0, 0.0, -50.0), Vec3(0.0, 1.5, 0.0));
  hand_.buttons(0b101);
  dm::HapticDevice& dev = **d;
  ASSERT_TRUE(servoUntil(dev, [&](dm::DeviceStatus s) { return ok(s) && dev.state().buttons == 0b101; }));
  const dm::HapticState& st = dev.state();
  EXPECT_TRUE(st.position.isApprox(Vec3(0.0125, -0.030, 0.007), 1e-12)) << st.position.transpose();
  EXPECT_NEAR(std::abs(st.orientation.dot(q)), 1.0, 1e-12);
  EXPECT_TRUE(st.linearVelocity.isApprox(Vec3(0.1, 0.0, -0.05), 1e-12));
  EXPECT_TRUE(st.angularVelocity.isApprox(Vec3(0.0, 1.5, 0.0), 1e-12));
}

TEST_F(OpenHapticsHd, ForcesReachTheDeviceClampedToItsContinuousForce) {
  auto d = open();
  ASSERT_TRUE(d.ok()) << d.error().message();
  dm::HapticDevice& dev = **d;
  const Vec3 f(0.3, -0.2, 0.1);
  ASSERT_TRUE(servoUntil(dev, [&](dm::DeviceStatus s) {
    dev.command(f, Vec3::Zero(), now());
    return ok(s) && hand_.applied() == f;
  }));
  ASSERT_TRUE(servoUntil(dev, [&](dm::DeviceStatus s) {
    dev.command(Vec3(0.0, 0.0, -5.0), Vec3::Zero(), now());
    return ok(s) && hand_.applied().isApprox(Vec3(0.0, 0.0, -0.88), 1e-15);
  })) << hand_.applied().transpose();
}

TEST_F(OpenHapticsHd, NoForceUntilCalibratedAndAnUpdateIsMadeForTheUser) {
  auto d = open();
  ASSERT_TRUE(d.ok()) << d.error().message();
  dm::HapticDevice& dev = **d;
  const Vec3 f(0.2, 0.0, 0.0);
  ASSERT_TRUE(servoUntil(dev, [&](dm::DeviceStatus s) {
    dev.command(f, Vec3::Zero(), now());
    return ok(s) && hand_.applied() == f;
  }));
  // The stylus must go into its inkwell: samples are refused, no force.
  hand_.calibration(kNeedsManualInput);
  ASSERT_TRUE(servoUntil(dev, [&](dm::DeviceStatus s) {
    dev.command(f, Vec3::Zero(), now());
    return s == dm::DeviceStatus::IoError && hand_.applied() == Vec3::Zero();
  }));
  for (int k = 0; k < 20; ++k) {
    dev.command(f, Vec3::Zero(), now());
    EXPECT_EQ(dev.servo(now()), dm::DeviceStatus::IoError);
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  EXPECT_EQ(hand_.applied(), Vec3::Zero());
  // In the inkwell it only needs an update, which the driver makes.
  hand_.calibration(kNeedsUpdate);
  ASSERT_TRUE(servoUntil(dev, [&](dm::DeviceStatus s) {
    dev.command(f, Vec3::Zero(), now());
    return ok(s) && hand_.applied() == f;
  }));
  EXPECT_EQ(hand_.calibration(), kCalibrationOk);
}

TEST_F(OpenHapticsHd, WithCalibrationOffTheDriverLeavesItToTheUser) {
  auto d = open({{"calibration", "off"}});
  ASSERT_TRUE(d.ok()) << d.error().message();
  dm::HapticDevice& dev = **d;
  ASSERT_TRUE(servoUntil(dev, ok));
  hand_.calibration(kNeedsUpdate);
  ASSERT_TRUE(servoUntil(dev, [](dm::DeviceStatus s) { return s == dm::DeviceStatus::IoError; }));
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  EXPECT_EQ(hand_.calibration(), kNeedsUpdate);
  EXPECT_EQ(dev.servo(now()), dm::DeviceStatus::IoError);
}

TEST_F(OpenHapticsHd, UnpluggedMidRunItIsLostGetsNothingAndComesBack) {
  auto d = open();
  ASSERT_TRUE(d.ok()) << d.error().message();
  dm::HapticDevice& dev = **d;
  const Vec3 f(0.0, 0.4, 0.0);
  ASSERT_TRUE(servoUntil(dev, [&](dm::DeviceStatus s) {
    dev.command(f, Vec3::Zero(), now());
    return ok(s) && hand_.applied() == f;
  }));
  hand_.plugged(false);
  ASSERT_TRUE(servoUntil(dev, [](dm::DeviceStatus s) { return s == dm::DeviceStatus::Lost; }));
  EXPECT_FALSE(dev.connected());
  EXPECT_EQ(dev.lastOutput().force, Vec3::Zero());
  dm::DeviceEvent e;
  bool lostEvent = false;
  while (dev.pollEvent(e)) lostEvent = lostEvent || e.type == dm::DeviceEventType::Lost;
  EXPECT_TRUE(lostEvent);
  // Still unplugged: the reconnection attempts (every 0.1 s) fail.
  for (int k = 0; k < 250; ++k) {
    dev.command(f, Vec3::Zero(), now());
    EXPECT_EQ(dev.servo(now()), dm::DeviceStatus::Lost) << k;
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  hand_.plugged(true);
  ASSERT_TRUE(servoUntil(dev, ok));
  EXPECT_TRUE(dev.connected());
  bool reconnected = false;
  while (dev.pollEvent(e)) reconnected = reconnected || e.type == dm::DeviceEventType::Reconnected;
  EXPECT_TRUE(reconnected);
  EXPECT_EQ(dev.counters().losses, 1u);
  // The force resumes with a command newer than the reconnection.
  ASSERT_TRUE(servoUntil(dev, [&](dm::DeviceStatus s) {
    dev.command(f, Vec3::Zero(), now());
    return ok(s) && hand_.applied() == f;
  }));
}

TEST_F(OpenHapticsHd, AForceErrorIsOneIoErrorAndTheDeviceStays) {
  auto d = open();
  ASSERT_TRUE(d.ok()) << d.error().message();
  dm::HapticDevice& dev = **d;
  ASSERT_TRUE(servoUntil(dev, ok));
  const std::uint64_t before = dev.counters().ioErrors;
  hand_.raise(0x0203);  // HD_EXCEEDED_MAX_VELOCITY
  ASSERT_TRUE(servoUntil(dev, [](dm::DeviceStatus s) { return s == dm::DeviceStatus::IoError; }));
  for (int k = 0; k < 50; ++k) {
    EXPECT_EQ(dev.servo(now()), dm::DeviceStatus::Ok) << k;
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  EXPECT_EQ(dev.counters().ioErrors, before + 1);
  EXPECT_TRUE(dev.connected());
}

TEST_F(OpenHapticsHd, BadParametersAndLibrariesAreRefusedNamingThem) {
  auto bad = open({{"calibration", "sometimes"}});
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().message().find("'calibration'"), std::string::npos) << bad.error().message();
  auto named = open({{"device", "Left Touch"}});
  ASSERT_FALSE(named.ok());
  EXPECT_NE(named.error().message().find("'Left Touch'"), std::string::npos) << named.error().message();
  EXPECT_NE(named.error().message().find("HD_COMM_CONFIG_ERROR"), std::string::npos)
      << named.error().message();

  auto missing =
      dm::HapticDevice::open(drivers_.registry, "openhaptics-hd", {{"library", "/nonexistent/libHD.so"}});
  ASSERT_FALSE(missing.ok());
  const std::string m = missing.error().message();
  EXPECT_NE(m.find("OpenHaptics HD"), std::string::npos) << m;
  EXPECT_NE(m.find("/nonexistent/libHD.so"), std::string::npos) << m;
  EXPECT_NE(m.find("install OpenHaptics"), std::string::npos) << m;

  const std::string notHd = dm::test::besideExecutable(DM_DRIVER_PLUGIN_DIR) + "/libdm_driver_sim_haptic.so";
  auto wrong = dm::HapticDevice::open(drivers_.registry, "openhaptics-hd", {{"library", notHd}});
  ASSERT_FALSE(wrong.ok());
  EXPECT_NE(wrong.error().message().find("hdInitDevice"), std::string::npos) << wrong.error().message();
}

TEST_F(OpenHapticsHd, VendorStatusSaysWhetherThisMachineHasTheLibrary) {
  const auto all = dm::vendorDriverStatus();
  const auto it =
      std::find_if(all.begin(), all.end(), [](const auto& s) { return s.driver == "openhaptics-hd"; });
  ASSERT_NE(it, all.end());
  EXPECT_EQ(it->api, "OpenHaptics HD");
  void* real = ::dlopen("libHD.so", RTLD_NOW | RTLD_LOCAL);
  EXPECT_EQ(it->available, real != nullptr);
  if (real) {
    EXPECT_FALSE(it->library.empty());
    ::dlclose(real);
  } else {
    EXPECT_NE(it->reason.find("libHD.so"), std::string::npos) << it->reason;
    EXPECT_NE(it->reason.find("install OpenHaptics"), std::string::npos) << it->reason;
  }
}

}  // namespace openhaptics_hd_test
