// The haply-2diy driver against a stand-in Haply board on a pseudo-terminal
// (haply_board_stand_in.hpp): it sets the board up as Haply's hAPI does;
// the position is the pantograph's handle and the torques are those hAPI
// sends for the same force (both checked against hAPI's own formulas,
// written out here); ports in the other order swap both; an analog pin is
// the button; angles that are no pose of the linkage (a board powered with
// its arms elsewhere, offsets that do not match) are refused with no
// torque; a wrong answer is an I/O error it recovers from; a board that
// goes silent or is unplugged is lost and comes back; a board that never
// answers and bad parameters are refused naming them.
#include <dm/io/drivers.hpp>
#include <dm/io/haptic_device.hpp>

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <numbers>
#include <string>
#include <thread>

#include "driver_test_support.hpp"
#include "haply_board_stand_in.hpp"

namespace haply_2diy_test {

using dm::Vec3;
namespace fs = std::filesystem;

// hAPI's Pantograph (Haply-API-Java, Pantograph.java) as it is written:
// forward kinematics by its quadratic, its Jacobian J / l and gain 0.1.
struct HapiPantograph {
  double l = 0.05, L = 0.07, d = 0.02;
  double x = 0, y = 0, J11 = 0, J12 = 0, J21 = 0, J22 = 0;
  void forwardKinematics(double deg1, double deg2) {
    const double th1 = std::numbers::pi / 180 * deg1, th2 = std::numbers::pi / 180 * deg2;
    const double c1 = std::cos(th1), c2 = std::cos(th2), s1 = std::sin(th1), s2 = std::sin(th2);
    const double xA = l * c1, yA = l * s1, xB = d + l * c2, yB = l * s2;
    const double R = xA * xA + yA * yA, S = xB * xB + yB * yB;
    const double M = (yA - yB) / (xB - xA), N = 0.5 * (S - R) / (xB - xA);
    const double a = M * M + 1, b = 2 * (M * N - M * xA - yA), c = N * N - 2 * N * xA + R - L * L;
    y = (-b + std::sqrt(b * b - 4 * a * c)) / (2 * a);
    x = M * y + N;
    const double phi1 = std::acos((x - l * c1) / L), phi2 = std::acos((x - d - l * c2) / L);
    const double s21 = std::sin(phi2 - phi1), s12 = std::sin(th1 - phi2), s22 = std::sin(th2 - phi2);
    J11 = -(s1 * s21 + std::sin(phi1) * s12) / s21;
    J12 = (c1 * s21 + std::cos(phi1) * s12) / s21;
    J21 = std::sin(phi1) * s22 / s21;
    J22 = -std::cos(phi1) * s22 / s21;
  }
  double tau1(double fx, double fy) const { return 0.1 * (J11 * fx + J12 * fy); }
  double tau2(double fx, double fy) const { return 0.1 * (J21 * fx + J22 * fy); }
};

std::int64_t nowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

class Haply2Diy : public ::testing::Test {
 protected:
  Haply2Diy() : board_(fs::temp_directory_path() / ("dm_haply_board_" + std::to_string(::getpid()))) {}
  dm::Result<std::unique_ptr<dm::HapticDevice>> open(dm::DeviceParams params = {}) {
    params.emplace_back("path", board_.path());
    bool force = false;
    for (const auto& [k, v] : params) force = force || k == "max_force";
    if (!force) params.emplace_back("max_force", "3");
    return dm::HapticDevice::open(drivers_.registry, "haply-2diy", params);
  }
  // Servo steps a millisecond apart in real time until `want` (or 3 s).
  static bool servoUntil(dm::HapticDevice& d, dm::DeviceStatus want) {
    for (int i = 0; i < 3000; ++i) {
      if (d.servo(nowNs()) == want) return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    return false;
  }
  // The arms at (deg1, deg2): the counts that make the board read them.
  void arms(double deg1, double deg2, int port1 = 1, int port2 = 2) {
    board_.setCounts(port1, board_.countsFor(port1, deg1));
    board_.setCounts(port2, board_.countsFor(port2, deg2));
  }
  dm::test::HaplyBoardStandIn board_;
  dm::test::BuiltinDrivers drivers_;
};

TEST_F(Haply2Diy, TheBoardIsSetUpAsHapiSetsItUp) {
  auto d = open();
  ASSERT_TRUE(d.ok()) << d.error().message();
  const dm::test::HaplyBoardStandIn::Setup s = board_.setup();
  EXPECT_EQ(s.resets, 1);
  EXPECT_EQ(s.setups, 1);
  EXPECT_EQ(s.id, 3);
  EXPECT_EQ(s.actuatorMask, 0b11);
  EXPECT_EQ(s.encoderMask, 0b11);
  EXPECT_EQ(s.actuatorDirections, (std::vector<std::uint8_t>{0, 0}));
  EXPECT_EQ(s.encoderDirections, (std::vector<std::uint8_t>{0, 0}));
  EXPECT_EQ(s.offsets, (std::vector<float>{180.0f, 0.0f}));
  EXPECT_EQ(s.resolutions, (std::vector<float>{13824.0f, 13824.0f}));
  EXPECT_TRUE(s.sensorPins.empty());
  EXPECT_TRUE(s.pwmPins.empty());
  const dm::HapticInfo& i = (*d)->info();
  EXPECT_EQ(i.driver, "haply-2diy");
  EXPECT_EQ(i.vendor, "Haply Robotics");
  EXPECT_EQ(i.serial, board_.path());
  EXPECT_EQ(i.maxForce, 3.0);
  EXPECT_EQ(i.buttonCount, 0u);
  EXPECT_FALSE(i.capabilities & DM_HAPTIC_CAP_ORIENTATION);
  // The linkage's reach in front of the motors, in the plane z = 0.
  EXPECT_DOUBLE_EQ(i.workspace.min().x(), 0.02 - 0.12);
  EXPECT_DOUBLE_EQ(i.workspace.max().x(), 0.12);
  EXPECT_DOUBLE_EQ(i.workspace.max().y(), 0.12);
  EXPECT_EQ(i.workspace.min().z(), 0.0);
  EXPECT_EQ(i.workspace.max().z(), 0.0);
}

// The handle where hAPI's kinematics put it, over poses across the
// workspace (arms level, one arm raised, both raised, near the motors).
TEST_F(Haply2Diy, ThePositionIsThePantographsHandle) {
  auto d = open();
  ASSERT_TRUE(d.ok()) << d.error().message();
  HapiPantograph hapi;
  for (const auto& [a1, a2] :
       {std::pair{180.0, 0.0}, std::pair{120.0, 50.0}, std::pair{150.0, 80.0}, std::pair{100.0, 30.0}}) {
    arms(a1, a2);
    hapi.forwardKinematics(a1, a2);
    // Until the board's answer for the new counts has come.
    bool there = false;
    for (int i = 0; i < 500 && !there; ++i) {
      if ((*d)->servo(nowNs()) == dm::DeviceStatus::Ok)
        there = ((*d)->state().position - Vec3(hapi.x, hapi.y, 0)).norm() < 2e-6;
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    EXPECT_TRUE(there) << a1 << ", " << a2 << ": " << (*d)->state().position.transpose() << " vs " << hapi.x
                       << ", " << hapi.y;
    EXPECT_EQ((*d)->state().position.z(), 0.0);
  }
}

// The torques reaching the board are hAPI's for the same force, and the z
// force (which the plane cannot render) changes nothing.
TEST_F(Haply2Diy, TheTorquesAreWhatHapiSendsForTheForce) {
  auto d = open();
  ASSERT_TRUE(d.ok()) << d.error().message();
  arms(130.0, 60.0);
  HapiPantograph hapi;
  hapi.forwardKinematics(130.0, 60.0);
  const Vec3 f(1.5, -0.8, 0.7);
  bool there = false;
  for (int i = 0; i < 500 && !there; ++i) {
    (*d)->command(f, Vec3::Zero(), nowNs());
    (*d)->servo(nowNs());
    const auto t = board_.torques();
    there =
        std::abs(t[0] - hapi.tau1(f.x(), f.y())) < 1e-5 && std::abs(t[1] - hapi.tau2(f.x(), f.y())) < 1e-5;
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  const auto t = board_.torques();
  EXPECT_TRUE(there) << t[0] << ", " << t[1] << " vs " << hapi.tau1(f.x(), f.y()) << ", "
                     << hapi.tau2(f.x(), f.y());
  EXPECT_GT(std::abs(t[0]), 0.01);
}

// Arm 1 on port 2 and arm 2 on port 1 (parameter ports "2,1"): the setup
// lists port 1's settings first, the angles and torques are swapped back.
TEST_F(Haply2Diy, PortsInTheOtherOrderSwapAnglesAndTorques) {
  auto d = open({{"ports", "2,1"}, {"directions", "ccw,cw"}, {"offsets", "170,10"}});
  ASSERT_TRUE(d.ok()) << d.error().message();
  const auto s = board_.setup();
  EXPECT_EQ(s.encoderDirections, (std::vector<std::uint8_t>{0, 1}));  // port 1 (arm 2) cw, port 2 ccw
  EXPECT_EQ(s.offsets, (std::vector<float>{10.0f, 170.0f}));
  arms(140.0, 40.0, 2, 1);
  HapiPantograph hapi;
  hapi.forwardKinematics(140.0, 40.0);
  const Vec3 f(-1.0, 0.5, 0.0);
  bool there = false;
  for (int i = 0; i < 500 && !there; ++i) {
    (*d)->command(f, Vec3::Zero(), nowNs());
    if ((*d)->servo(nowNs()) == dm::DeviceStatus::Ok) {
      const auto t = board_.torques();
      there = ((*d)->state().position - Vec3(hapi.x, hapi.y, 0)).norm() < 2e-6 &&
              std::abs(t[1] - hapi.tau1(f.x(), f.y())) < 1e-5 &&
              std::abs(t[0] - hapi.tau2(f.x(), f.y())) < 1e-5;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  EXPECT_TRUE(there) << (*d)->state().position.transpose();
}

TEST_F(Haply2Diy, AnAnalogPinIsTheButton) {
  auto d = open({{"button_pin", "A2"}, {"button_threshold", "600"}});
  ASSERT_TRUE(d.ok()) << d.error().message();
  EXPECT_EQ(board_.setup().sensorPins, (std::vector<std::uint8_t>{56}));
  EXPECT_EQ((*d)->info().buttonCount, 1u);
  arms(150.0, 30.0);
  for (const auto& [value, pressed] : {std::pair{900.0f, 1u}, std::pair{100.0f, 0u}, std::pair{600.0f, 1u}}) {
    board_.setSensor(56, value);
    bool seen = false;
    for (int i = 0; i < 500 && !seen; ++i) {
      seen = (*d)->servo(nowNs()) == dm::DeviceStatus::Ok && (*d)->state().buttons == pressed;
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    EXPECT_TRUE(seen) << value;
  }
}

// Offsets that do not match the board (given swapped): at power-up the
// board reads arm 1 at 0° and arm 2 at 180°, elbows crossed — no pose of
// the 2DIY. Samples are refused and no torque is sent, until the angles
// are a pose.
TEST_F(Haply2Diy, AnglesThatAreNoPoseAreRefusedWithNoTorque) {
  auto d = open({{"offsets", "0,180"}});
  ASSERT_TRUE(d.ok()) << d.error().message();
  for (int i = 0; i < 100; ++i) {
    (*d)->command(Vec3(2, 1, 0), Vec3::Zero(), nowNs());
    EXPECT_EQ((*d)->servo(nowNs()), dm::DeviceStatus::IoError) << i;
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  EXPECT_EQ(board_.torques()[0], 0.0f);
  EXPECT_EQ(board_.torques()[1], 0.0f);
  EXPECT_GT(board_.setup().updates, 10);
  arms(150.0, 30.0);
  EXPECT_TRUE(servoUntil(**d, dm::DeviceStatus::Ok));
  for (int i = 0; i < 20; ++i) {
    (*d)->command(Vec3(2, 1, 0), Vec3::Zero(), nowNs());
    (*d)->servo(nowNs());
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  EXPECT_NE(board_.torques()[0], 0.0f);
}

TEST_F(Haply2Diy, AnAnswerWithAnotherIdIsAnIoErrorItRecoversFrom) {
  auto d = open();
  ASSERT_TRUE(d.ok()) << d.error().message();
  arms(150.0, 30.0);
  ASSERT_TRUE(servoUntil(**d, dm::DeviceStatus::Ok));
  board_.setAnswerId(9);
  EXPECT_TRUE(servoUntil(**d, dm::DeviceStatus::IoError));
  board_.setAnswerId(-1);
  EXPECT_TRUE(servoUntil(**d, dm::DeviceStatus::Ok));
  EXPECT_GT((*d)->counters().ioErrors, 0u);
}

// The cable pulled mid-run: lost; plugged in again (a new pseudo-terminal
// behind the same name, a board that knows no setup): the driver reopens
// it, sets it up again and the samples resume.
TEST_F(Haply2Diy, UnpluggedMidRunItIsLostAndComesBack) {
  auto d = open();
  ASSERT_TRUE(d.ok()) << d.error().message();
  arms(150.0, 30.0);
  ASSERT_TRUE(servoUntil(**d, dm::DeviceStatus::Ok));
  board_.unplug();
  EXPECT_TRUE(servoUntil(**d, dm::DeviceStatus::Lost));
  EXPECT_FALSE((*d)->connected());
  board_.replug();
  EXPECT_TRUE(servoUntil(**d, dm::DeviceStatus::Ok));
  EXPECT_EQ((*d)->counters().reconnects, 1u);
  EXPECT_EQ(board_.setup().setups, 2);
  EXPECT_EQ(board_.setup().resets, 2);
}

// A board that stops answering (its firmware hung) is lost after a second
// of silence, and comes back when it answers again.
TEST_F(Haply2Diy, ABoardThatGoesSilentIsLost) {
  auto d = open();
  ASSERT_TRUE(d.ok()) << d.error().message();
  arms(150.0, 30.0);
  ASSERT_TRUE(servoUntil(**d, dm::DeviceStatus::Ok));
  // The last answer came at most a servo step before the silence began:
  // lost a second after it, not at the first unanswered updates.
  board_.setSilent(true);
  const auto t0 = std::chrono::steady_clock::now();
  EXPECT_TRUE(servoUntil(**d, dm::DeviceStatus::Lost));
  const auto silent = std::chrono::steady_clock::now() - t0;
  EXPECT_GE(silent, std::chrono::milliseconds(900));
  EXPECT_LE(silent, std::chrono::milliseconds(2500));
  board_.setSilent(false);
  EXPECT_TRUE(servoUntil(**d, dm::DeviceStatus::Ok));
}

TEST_F(Haply2Diy, ABoardThatNeverAnswersIsRefusedAtOpen) {
  board_.setSilent(true);
  auto d = open({{"timeout", "0.2"}});
  ASSERT_FALSE(d.ok());
  EXPECT_NE(d.error().message().find("no answer from the board within 0.2 s"), std::string::npos)
      << d.error().message();
  EXPECT_NE(d.error().message().find(board_.path()), std::string::npos) << d.error().message();
}

TEST_F(Haply2Diy, BadParametersAreRefusedNamingThem) {
  const std::pair<dm::DeviceParams, const char*> cases[] = {
      {{{"ports", "1,1"}}, "ports"},
      {{{"ports", "0,5"}}, "ports"},
      {{{"directions", "cw,up"}}, "directions"},
      {{{"offsets", "180"}}, "offsets"},
      {{{"offsets", "180,nan"}}, "offsets"},
      {{{"ports", "1,2,3"}}, "ports"},
      {{{"links", "0.05,0.07"}}, "links"},
      {{{"button_pin", "B3"}}, "button_pin"},
      {{{"button_pin", "A12"}}, "button_pin"},
      {{{"links", "0.07,0.05,0.02"}}, "links"},
      {{{"device_id", "300"}}, "device_id"},
      {{{"max_force", "-1"}}, "max_force"},
      {{{"path", "/dev/null"}}, "path"},
  };
  for (const auto& testCase : cases) {
    const auto& params = testCase.first;  // not a structured binding: clang 14 cannot capture one
    const auto& key = testCase.second;
    auto d = dm::HapticDevice::open(drivers_.registry, "haply-2diy", [&] {
      dm::DeviceParams p = params;
      bool hasPath = false, hasForce = false;
      for (const auto& [k, v] : p) hasPath = hasPath || k == "path", hasForce = hasForce || k == "max_force";
      if (!hasPath) p.emplace_back("path", board_.path());
      if (!hasForce) p.emplace_back("max_force", "3");
      return p;
    }());
    ASSERT_FALSE(d.ok()) << key;
    EXPECT_NE(d.error().message().find(key), std::string::npos) << d.error().message();
  }
  auto noForce = dm::HapticDevice::open(drivers_.registry, "haply-2diy", {{"path", board_.path()}});
  ASSERT_FALSE(noForce.ok());
  EXPECT_NE(noForce.error().message().find("max_force"), std::string::npos);
  auto noPath = dm::HapticDevice::open(drivers_.registry, "haply-2diy", {{"max_force", "3"}});
  ASSERT_FALSE(noPath.ok());
  EXPECT_NE(noPath.error().message().find("path"), std::string::npos);
}

}  // namespace haply_2diy_test
