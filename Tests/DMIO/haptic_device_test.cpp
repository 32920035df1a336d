// HapticDevice and the sim-haptic driver: the driver loaded as a plugin
// (built from DMIO/drivers/sim_haptic.cpp into DM_DRIVER_PLUGIN_DIR) and
// built in, its trajectories against their formulas, its sensor effects,
// the virtual hand against the analytic equilibrium of two springs, and the
// safety layer against a recording driver that keeps every output it was
// sent (clamping, NaN/Inf, deadline fade, loss and reconnection).
#include <dm/io/drivers.hpp>
#include <dm/io/haptic_device.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <complex>
#include <fstream>
#include <iomanip>
#include <numbers>
#include <string>
#include <utility>
#include <vector>

#include "../common/build_paths.hpp"
#include "../common/temp_dir.hpp"
#include "driver_test_support.hpp"

namespace {

using dm::Vec3;
using dm::test::kMs;

std::unique_ptr<dm::HapticDevice> openHapticOrFail(const dm::FactoryRegistry& reg,
                                                   const dm::DeviceParams& params,
                                                   const dm::HapticSafety& safety = {}) {
  auto d = dm::HapticDevice::open(reg, "sim-haptic", params, safety);
  EXPECT_TRUE(d.ok()) << (d.ok() ? "" : d.error().message());
  return d.ok() ? std::move(*d) : nullptr;
}

struct Builtin {
  dm::FactoryRegistry registry;
  dm::PluginLinker linker{registry};
  Builtin() { EXPECT_TRUE(dm::registerBuiltinDrivers(linker).ok()); }
};

TEST(SimHaptic, PluginAndBuiltInGiveIdenticalSamples) {
  dm::FactoryRegistry plugReg;
  dm::PluginLinker plugLinker(plugReg);
  auto loaded =
      plugLinker.load(dm::test::besideExecutable(DM_DRIVER_PLUGIN_DIR) + "/libdm_driver_sim_haptic.so");
  ASSERT_TRUE(loaded.ok()) << loaded.error().message();
  EXPECT_EQ(loaded->name, "sim-haptic");
  Builtin b;
  const dm::DeviceParams params = {{"path", "spiral"}, {"noise", "0.0001"}, {"seed", "42"}};
  auto p = openHapticOrFail(plugReg, params);
  auto s = openHapticOrFail(b.registry, params);
  ASSERT_TRUE(p && s);
  EXPECT_EQ(p->info().driver, "sim-haptic");
  EXPECT_EQ(p->info().serial, "sim-42");
  for (std::int64_t k = 0; k < 500; ++k) {
    ASSERT_EQ(p->servo(k * kMs), dm::DeviceStatus::Ok);
    ASSERT_EQ(s->servo(k * kMs), dm::DeviceStatus::Ok);
    ASSERT_EQ(p->state().position, s->state().position) << k;
  }
}

TEST(SimHaptic, CircleFollowsItsFormula) {
  Builtin b;
  auto d = openHapticOrFail(
      b.registry, {{"path", "circle"}, {"radius", "0.04"}, {"period", "0.5"}, {"center", "0.1,0,0.2"}});
  ASSERT_TRUE(d);
  const Vec3 c(0.1, 0, 0.2);
  const double w = 2 * std::numbers::pi / 0.5;
  for (std::int64_t k = 0; k < 1000; ++k) {
    d->servo(k * kMs);
    const dm::HapticState& st = d->state();
    const double t = 1e-3 * static_cast<double>(k);
    EXPECT_NEAR((st.position - (c + 0.04 * Vec3(std::cos(w * t), std::sin(w * t), 0))).norm(), 0.0, 1e-12);
    EXPECT_NEAR(st.linearVelocity.norm(), 0.04 * w, 1e-6);  // central difference, O(h²)
    EXPECT_NEAR(st.linearVelocity.dot(st.position - c), 0.0, 1e-8);
  }
  EXPECT_NEAR(d->info().workspace.min().x(), 0.1 - 0.15, 1e-15);
}

TEST(SimHaptic, LineSweepsBetweenItsEnds) {
  // A looping path starts at its first sample too, whatever the clock reads
  // then (a real-time clock does not start at zero): the sweep begins at
  // `from` and repeats every period.
  Builtin b;
  auto d =
      openHapticOrFail(b.registry, {{"path", "line"}, {"from", "0,0,0"}, {"to", "0.1,0,0"}, {"period", "1"}});
  ASSERT_TRUE(d);
  const std::int64_t t0 = 987654 * kMs;
  d->servo(t0);
  EXPECT_NEAR(d->state().position.x(), 0.0, 1e-12);
  d->servo(t0 + 250 * kMs);  // a quarter period: halfway out
  EXPECT_NEAR(d->state().position.x(), 0.05, 1e-12);
  d->servo(t0 + 500 * kMs);  // half: at the far end
  EXPECT_NEAR(d->state().position.x(), 0.1, 1e-12);
  d->servo(t0 + 750 * kMs);  // three quarters: halfway back
  EXPECT_NEAR(d->state().position.x(), 0.05, 1e-12);
  d->servo(t0 + 1250 * kMs);  // the next sweep
  EXPECT_NEAR(d->state().position.x(), 0.05, 1e-12);
}

TEST(SimHaptic, PathsWithoutLoopRunOnceFromTheFirstSampleAndHoldTheirEnd) {
  // loop 0: the path's clock starts at the first sample (a real-time clock
  // does not start at zero), goes out once and stays at the end.
  Builtin b;
  auto d = openHapticOrFail(
      b.registry, {{"path", "line"}, {"from", "0,0,0"}, {"to", "0.1,0,0"}, {"period", "1"}, {"loop", "0"}});
  ASSERT_TRUE(d);
  const std::int64_t t0 = 123456 * kMs;
  d->servo(t0);
  EXPECT_NEAR(d->state().position.x(), 0.0, 1e-12);
  d->servo(t0 + 250 * kMs);
  EXPECT_NEAR(d->state().position.x(), 0.05, 1e-12);
  for (std::int64_t ms : {500, 750, 1000, 5000}) {
    d->servo(t0 + ms * kMs);
    EXPECT_NEAR(d->state().position.x(), 0.1, 1e-12) << ms;
  }
  EXPECT_NEAR(d->state().linearVelocity.norm(), 0.0, 1e-9);

  const dm::test::TempDir dir("sim_haptic_once");
  std::ofstream(dir / "path.csv") << "t,x,y,z\n0,0,0,0\n1,0,0,0.02\n2,0.01,0,0.02\n";
  auto c =
      openHapticOrFail(b.registry, {{"path", "csv"}, {"file", (dir / "path.csv").string()}, {"loop", "0"}});
  ASSERT_TRUE(c);
  c->servo(t0);
  c->servo(t0 + 1500 * kMs);
  EXPECT_NEAR((c->state().position - Vec3(0.005, 0, 0.02)).norm(), 0.0, 1e-12);
  c->servo(t0 + 9000 * kMs);
  EXPECT_NEAR((c->state().position - Vec3(0.01, 0, 0.02)).norm(), 0.0, 1e-12);
}

TEST(SimHaptic, NoiseQuantizationAndLatency) {
  Builtin b;
  auto noisy = openHapticOrFail(b.registry, {{"path", "point"}, {"noise", "0.001"}, {"seed", "3"}});
  ASSERT_TRUE(noisy);
  double sum = 0, sum2 = 0;
  const int n = 20000;
  for (int k = 0; k < n; ++k) {
    noisy->servo(k * kMs);
    const double x = noisy->state().position.y();
    sum += x;
    sum2 += x * x;
  }
  const double mean = sum / n, sd = std::sqrt(sum2 / n - mean * mean);
  EXPECT_NEAR(sd, 0.001, 0.00005);  // 20000 samples: the estimate's sd is 0.5 %
  EXPECT_NEAR(mean, 0.0, 0.00005);

  auto q = openHapticOrFail(b.registry, {{"path", "circle"}, {"quantization", "0.0005"}});
  ASSERT_TRUE(q);
  for (int k = 0; k < 100; ++k) {
    q->servo(k * 7 * kMs);
    for (int i = 0; i < 3; ++i) {
      const double steps = q->state().position[i] / 0.0005;
      EXPECT_NEAR(steps, std::round(steps), 1e-9);
    }
  }

  auto late = openHapticOrFail(b.registry, {{"path", "circle"}, {"latency", "0.02"}});
  auto now = openHapticOrFail(b.registry, {{"path", "circle"}});
  ASSERT_TRUE(late && now);
  std::vector<Vec3> truth;
  for (std::int64_t k = 0; k < 200; ++k) {
    late->servo(k * kMs);
    now->servo(k * kMs);
    truth.push_back(now->state().position);
    if (k >= 20) {
      EXPECT_NEAR((late->state().position - truth[k - 20]).norm(), 0.0, 1e-12) << k;
    }
  }
}

TEST(SimHaptic, CsvPathInterpolatesAndLoops) {
  dm::test::TempDir dir("sim_haptic_csv");
  {
    std::ofstream f(dir / "path.csv");
    f << "t,x,y,z\n0,0,0,0\n1,0.1,0,0\n2,0.1,0.1,0\n";
  }
  Builtin b;
  auto d = openHapticOrFail(b.registry, {{"path", "csv"}, {"file", (dir / "path.csv").string()}});
  ASSERT_TRUE(d);
  d->servo(0);  // the path's time starts at the first sample
  d->servo(500 * kMs);
  EXPECT_NEAR((d->state().position - Vec3(0.05, 0, 0)).norm(), 0.0, 1e-12);
  d->servo(1500 * kMs);
  EXPECT_NEAR((d->state().position - Vec3(0.1, 0.05, 0)).norm(), 0.0, 1e-12);
  d->servo(2500 * kMs);  // loops with period 2 s
  EXPECT_NEAR((d->state().position - Vec3(0.05, 0, 0)).norm(), 0.0, 1e-12);

  {
    std::ofstream f(dir / "bad.csv");
    f << "0,0,0,0\n1,0.1,zero,0\n";
  }
  auto bad = dm::HapticDevice::open(b.registry, "sim-haptic",
                                    {{"path", "csv"}, {"file", (dir / "bad.csv").string()}});
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().message().find("bad.csv:2"), std::string::npos) << bad.error().message();
}

// The spiral's formula, its velocity included, at every tick and across
// the turn where it starts over: the velocity is the path's own, never the
// jump back to the first turn (a central difference at t = 0 reads the end
// of the last turn 12 mm away and gave 6,000 m/s).
TEST(SimHaptic, SpiralFollowsItsFormulaAndItsVelocityNeverCrossesTheRestart) {
  Builtin b;
  auto d = openHapticOrFail(b.registry, {{"path", "spiral"},
                                         {"radius", "0.0015"},
                                         {"period", "0.5"},
                                         {"pitch", "-0.0012"},
                                         {"turns", "2"},
                                         {"center", "0,0,0.006"}});
  ASSERT_TRUE(d);
  const double w = 2 * std::numbers::pi / 0.5, r = 0.0015;
  for (std::int64_t k = 0; k < 2500; ++k) {  // 2.5 turns: the restart at 1 s, then half a turn
    d->servo(k * kMs);
    const dm::HapticState& st = d->state();
    const double t = 1e-3 * static_cast<double>(k), u = t / 0.5;
    const Vec3 x(r * std::cos(w * t), r * std::sin(w * t), 0.006 - 0.0012 * (u - 2 * std::floor(u / 2)));
    const Vec3 v(-r * w * std::sin(w * t), r * w * std::cos(w * t), -0.0012 / 0.5);
    EXPECT_NEAR((st.position - x).norm(), 0.0, 1e-12) << t;
    EXPECT_NEAR((st.linearVelocity - v).norm(), 0.0, 1e-9) << t;
  }
}

// loop 0: the spiral goes down its turns once and holds its last point.
TEST(SimHaptic, SpiralWithoutLoopHoldsTheEndOfItsLastTurn) {
  Builtin b;
  auto d = openHapticOrFail(b.registry, {{"path", "spiral"},
                                         {"radius", "0.001"},
                                         {"period", "0.4"},
                                         {"pitch", "-0.0008"},
                                         {"turns", "3"},
                                         {"loop", "0"}});
  ASSERT_TRUE(d);
  const std::int64_t t0 = 5555 * kMs;
  d->servo(t0);
  EXPECT_NEAR((d->state().position - Vec3(0.001, 0, 0)).norm(), 0.0, 1e-12);
  for (std::int64_t ms : {1200, 1201, 3000, 60000}) {
    d->servo(t0 + ms * kMs);
    EXPECT_NEAR((d->state().position - Vec3(0.001, 0, -0.0024)).norm(), 0.0, 1e-12) << ms;
    EXPECT_EQ(d->state().linearVelocity.norm(), 0.0) << ms;
  }
}

// A virtual hand starts on its path at the path's speed: with no force on
// it, it follows the spiral within the lag of its spring, never flung
// away. The hand (m ẍ = k(target − x) − c ẋ) follows the circle with the
// response H = k / (k − mω² + icω), an error r·|H − 1| (0.30 mm here),
// and the descent at v with a lag c·v/k (0.036 mm); a quarter more for the
// start's transient.
TEST(SimHaptic, AVirtualHandStartsOnItsSpiralAtThePathsSpeed) {
  Builtin b;
  auto d = openHapticOrFail(b.registry, {{"path", "spiral"},
                                         {"radius", "0.0015"},
                                         {"period", "0.5"},
                                         {"pitch", "-0.0012"},
                                         {"turns", "10"},
                                         {"center", "0,0,0.006"},
                                         {"hand", "1"},
                                         {"hand_mass", "0.1"},
                                         {"hand_stiffness", "400"},
                                         {"hand_damping", "6"}});
  ASSERT_TRUE(d);
  const double w = 2 * std::numbers::pi / 0.5, r = 0.0015;
  double worst = 0.0;
  for (std::int64_t k = 0; k < 1000; ++k) {
    d->servo(k * kMs);
    const double t = 1e-3 * static_cast<double>(k);
    const Vec3 x(r * std::cos(w * t), r * std::sin(w * t), 0.006 - 0.0012 * t / 0.5);
    worst = std::max(worst, (d->state().position - x).norm());
    d->command(Vec3::Zero(), Vec3::Zero(), k * kMs);
  }
  const std::complex<double> H = 400.0 / std::complex<double>(400.0 - 0.1 * w * w, 6.0 * w);
  const double steady = r * std::abs(H - 1.0) + 6.0 * 0.0024 / 400.0;
  EXPECT_LT(worst, 1.25 * steady);
  EXPECT_GT(worst, 0.9 * steady);
}

// A looped CSV path whose last row is not its first jumps back at each
// loop; its velocity is its segment's slope, at t = 0 too, and the
// handle's angular velocity is its segment's slerp rate.
TEST(SimHaptic, CsvVelocitiesAreTheSegmentsOwnAcrossTheLoop) {
  const dm::test::TempDir dir("sim_haptic_csv_velocity");
  // Quarter turn about z over the second segment: 0.5π rad/s.
  const double c = std::cos(std::numbers::pi / 8), s = std::sin(std::numbers::pi / 8);
  std::ofstream(dir / "path.csv") << std::setprecision(17)
                                  << "t,x,y,z,qw,qx,qy,qz\n0,0,0,0,1,0,0,0\n1,0.1,0,0,1,0,0,0\n2,0.1,0.05,0," << c
                                  << ",0,0," << s << "\n";
  Builtin b;
  auto d = openHapticOrFail(b.registry, {{"path", "csv"}, {"file", (dir / "path.csv").string()}});
  ASSERT_TRUE(d);
  for (std::int64_t ms : {0, 500, 1000, 1500, 2000, 2500}) {  // loops every 2 s
    d->servo(ms * kMs);
    const bool first = (ms % 2000) < 1000;
    const Vec3 v = first ? Vec3(0.1, 0, 0) : Vec3(0, 0.05, 0);
    const Vec3 omega = first ? Vec3::Zero() : Vec3(0, 0, 0.25 * std::numbers::pi);
    EXPECT_NEAR((d->state().linearVelocity - v).norm(), 0.0, 1e-12) << ms;
    EXPECT_NEAR((d->state().angularVelocity - omega).norm(), 0.0, 1e-12) << ms;
  }
}

TEST(SimHaptic, CsvPathWithOrientationSlerpsTheHandle) {
  // A handle turning 90° about z in 1 s while moving 0.1 m along x, then
  // 90° about x (given as the negated quaternion: the same rotation; the
  // reader keeps the short way). At every time the pose is the slerp of the
  // neighbouring rows, and the angular velocity is that of the turn.
  dm::test::TempDir dir("sim_haptic_csv_q");
  const double h = std::sqrt(0.5);
  {
    std::ofstream f(dir / "turn.csv");
    f << "t,x,y,z,qw,qx,qy,qz\n# comment\n0,0,0,0,2,0,0,0\n1,0.1,0,0," << h << ",0,0," << h << "\n2,0.1,0,0,"
      << -0.5 << ",-0.5,-0.5,-0.5\n";
  }
  Builtin b;
  auto d =
      openHapticOrFail(b.registry, {{"path", "csv"}, {"file", (dir / "turn.csv").string()}, {"loop", "0"}});
  ASSERT_TRUE(d);
  EXPECT_TRUE(d->info().capabilities & DM_HAPTIC_CAP_ORIENTATION);
  const dm::Quat start = dm::Quat::Identity(), quarterZ(h, 0, 0, h), end(0.5, 0.5, 0.5, 0.5);
  for (int ms : {0, 250, 500, 999, 1000, 1300, 2000, 2500}) {
    ASSERT_EQ(d->servo(ms * kMs), dm::DeviceStatus::Ok);
    const double t = ms / 1000.0;
    const dm::Quat expected = t < 1 ? start.slerp(t, quarterZ) : quarterZ.slerp(std::min(t - 1, 1.0), end);
    EXPECT_LT(d->state().orientation.angularDistance(expected), 1e-6) << ms;
    EXPECT_NEAR(d->state().orientation.norm(), 1.0, 1e-12) << ms;
  }
  // The first segment turns at π/2 rad/s about z, the second at the angle
  // between quarterZ and end per second, about their relative axis.
  // (loop 0: the path's clock starts at the first servo.)
  d = openHapticOrFail(b.registry, {{"path", "csv"}, {"file", (dir / "turn.csv").string()}, {"loop", "0"}});
  ASSERT_EQ(d->servo(0), dm::DeviceStatus::Ok);
  ASSERT_EQ(d->servo(500 * kMs), dm::DeviceStatus::Ok);
  EXPECT_LT((d->state().angularVelocity - Vec3(0, 0, std::numbers::pi / 2)).norm(), 1e-6);
  ASSERT_EQ(d->servo(1500 * kMs), dm::DeviceStatus::Ok);
  const Eigen::AngleAxisd rel(end * quarterZ.inverse());
  EXPECT_LT((d->state().angularVelocity - rel.angle() * rel.axis()).norm(), 1e-6);
  EXPECT_LT((d->state().position - Vec3(0.1, 0, 0)).norm(), 1e-12);

  // A position-only file keeps the identity and does not claim orientation.
  {
    std::ofstream f(dir / "plain.csv");
    f << "0,0,0,0\n1,0.1,0,0\n";
  }
  auto plain = openHapticOrFail(b.registry, {{"path", "csv"}, {"file", (dir / "plain.csv").string()}});
  ASSERT_TRUE(plain);
  EXPECT_FALSE(plain->info().capabilities & DM_HAPTIC_CAP_ORIENTATION);
  ASSERT_EQ(plain->servo(500 * kMs), dm::DeviceStatus::Ok);
  EXPECT_EQ(plain->state().orientation.coeffs(), dm::Quat::Identity().coeffs());

  // Mixed widths, a zero quaternion, trailing junk, 5 numbers: refused with the line.
  const std::vector<std::pair<std::string, std::string>> bad = {
      {"0,0,0,0,1,0,0,0\n1,0,0,0\n", "bad.csv:2"},   {"0,0,0,0,1,0,0,0\n1,0,0,0,0,0,0,0\n", "bad.csv:2"},
      {"0,0,0,0\n1,0,0,0x\n", "bad.csv:2"},          {"0,0,0,0,1\n", "bad.csv:1"},
      {"t,x,y,z\n0,0,0,0,nan,0,0,0\n", "bad.csv:2"},
  };
  for (const auto& [text, where] : bad) {
    std::ofstream(dir / "bad.csv") << text;
    auto r = dm::HapticDevice::open(b.registry, "sim-haptic",
                                    {{"path", "csv"}, {"file", (dir / "bad.csv").string()}});
    ASSERT_FALSE(r.ok()) << text;
    EXPECT_NE(r.error().message().find(where), std::string::npos) << text << ": " << r.error().message();
  }
}

TEST(SimHaptic, BadParametersNameTheKey) {
  Builtin b;
  const std::vector<std::pair<dm::DeviceParams, std::string>> cases = {
      {{{"path", "zigzag"}}, "'path'"},
      {{{"radius", "big"}}, "'radius'"},
      {{{"radius", "-1"}}, "'radius'"},
      {{{"center", "1,2"}}, "'center'"},
      {{{"colour", "red"}}, "'colour'"},
      {{{"path", "csv"}}, "'file'"},
      {{{"path", "csv"}, {"file", "/nonexistent/path.csv"}}, "/nonexistent/path.csv"},
      // Keys another path (or the hand) takes would be ignored: errors.
      {{{"path", "circle"}, {"pitch", "0.001"}}, "'pitch' does nothing with path circle"},
      {{{"path", "line"}, {"center", "0,0,0"}}, "'center' does nothing with path line"},
      {{{"path", "point"}, {"loop", "0"}}, "'loop' does nothing with path point"},
      {{{"path", "spiral"}, {"from", "0,0,0"}}, "'from' does nothing with path spiral"},
      {{{"path", "spiral"}, {"hand_stiffness", "400"}}, "'hand_stiffness' needs hand 1"},
  };
  for (const auto& [params, needle] : cases) {
    auto d = dm::HapticDevice::open(b.registry, "sim-haptic", params);
    ASSERT_FALSE(d.ok()) << needle;
    EXPECT_EQ(d.error().code, dm::ErrorCode::InvalidArgument);
    EXPECT_NE(d.error().message().find(needle), std::string::npos) << d.error().message();
  }
  auto missing = dm::HapticDevice::open(b.registry, "phantom-omni");
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.error().code, dm::ErrorCode::NotFound);
}

TEST(SimHaptic, WrongAbiAndCrashingInitDriversAreRefusedCleanly) {
  dm::FactoryRegistry registry;
  dm::PluginLinker linker(registry, {.useEnvironment = false, .probe = true});
  const dm::ScanReport wrong =
      linker.scanDirectory(dm::test::besideExecutable(DM_TEST_DRIVER_DIR) + "/wrong_abi_driver");
  ASSERT_EQ(wrong.refused.size(), 1u);
  EXPECT_EQ(wrong.refused[0].error.code, dm::ErrorCode::Version);
  EXPECT_NE(wrong.refused[0].error.message().find("libdm_test_wrong_abi_driver.so"), std::string::npos)
      << wrong.refused[0].error.message();
  const dm::ScanReport crash =
      linker.scanDirectory(dm::test::besideExecutable(DM_TEST_DRIVER_DIR) + "/crash_init_driver");
  ASSERT_EQ(crash.refused.size(), 1u);
  EXPECT_NE(crash.refused[0].error.message().find("libdm_test_crash_init_driver.so"), std::string::npos)
      << crash.refused[0].error.message();
  EXPECT_EQ(registry.size(), 0u);  // nothing left behind
  // The host still works: a good driver loads after the bad ones.
  ASSERT_TRUE(dm::registerBuiltinDrivers(linker).ok());
  EXPECT_TRUE(dm::HapticDevice::open(registry, "sim-haptic").ok());
}

// Two springs on the hand: its own toward the target (k_h) and the rendered
// one toward x0 (k_v). Equilibrium x* = k_v·x0 / (k_h + k_v).
TEST(SimHaptic, VirtualHandSettlesAtTheSpringEquilibrium) {
  Builtin b;
  auto d = openHapticOrFail(b.registry, {{"path", "point"}, {"hand", "1"}, {"hand_stiffness", "300"}});
  ASSERT_TRUE(d);
  const Vec3 x0(0.02, -0.01, 0.005);
  const double kv = 200.0;
  for (std::int64_t k = 0; k < 3000; ++k) {
    d->servo(k * kMs);
    const Vec3 x = d->state().position;
    d->command(kv * (x0 - x), Vec3::Zero(), k * kMs);
  }
  EXPECT_NEAR((d->state().position - kv * x0 / (300.0 + kv)).norm(), 0.0, 1e-6);
}

TEST(SimHaptic, LossWindowGivesEventsAndNoOutput) {
  Builtin b;
  auto d = openHapticOrFail(b.registry, {{"path", "point"}, {"drop_at", "0.1"}, {"reconnect_at", "0.25"}});
  ASSERT_TRUE(d);
  std::vector<dm::DeviceEvent> events;
  for (std::int64_t k = 0; k < 400; ++k) {
    d->command(Vec3(1, 0, 0), Vec3::Zero(), k * kMs);
    const dm::DeviceStatus s = d->servo(k * kMs);
    const bool away =
        k >= 100 && k < 300;  // reconnect tried every 0.1 s after the loss: at 0.2 (too early), 0.3
    EXPECT_EQ(s == dm::DeviceStatus::Lost, away) << k;
    EXPECT_EQ(d->connected(), !away) << k;
    if (away) {
      EXPECT_EQ(d->lastOutput().force, Vec3::Zero());
    }
    dm::DeviceEvent e;
    while (d->pollEvent(e)) events.push_back(e);
  }
  ASSERT_EQ(events.size(), 2u);
  EXPECT_EQ(events[0].type, dm::DeviceEventType::Lost);
  EXPECT_EQ(events[0].timeNs, 100 * kMs);
  EXPECT_EQ(events[1].type, dm::DeviceEventType::Reconnected);
  EXPECT_EQ(events[1].timeNs, 300 * kMs);
  EXPECT_EQ(d->counters().losses, 1u);
  EXPECT_EQ(d->lastOutput().force, Vec3(1, 0, 0));  // fresh commands after the reconnection
}

// ---------------------------------------------------------------- safety ---

// A driver that records every output it receives; it can be told to lose
// the link.
struct Recorder {
  std::vector<std::array<double, 4>> outputs;  // t (s), fx, fy, fz
  bool lost = false;
  bool allowReconnect = false;
};
Recorder* gRecorder = nullptr;

const DmHapticDeviceVTable kRecorderVt = {
    [](const DmDeviceParam*, size_t, char*, size_t) -> DmDevice* {
      return reinterpret_cast<DmDevice*>(gRecorder);
    },
    [](DmDevice*) {},
    [](DmDevice*, DmHapticInfo* info) {
      *info = DmHapticInfo{};
      std::snprintf(info->identity.driver, sizeof info->identity.driver, "recorder");
      info->capabilities = DM_HAPTIC_CAP_POSITION | DM_HAPTIC_CAP_FORCE;
      info->max_force = 5.0;
      info->servo_rate_hz = 1000.0;
      return DM_DEVICE_OK;
    },
    [](DmDevice* d, int64_t now, DmHapticState* s) {
      *s = DmHapticState{};
      s->time_ns = now;
      s->orientation[0] = 1;
      return reinterpret_cast<Recorder*>(d)->lost ? DM_DEVICE_ERROR_LOST : DM_DEVICE_OK;
    },
    [](DmDevice* d, int64_t now, const double f[3], const double*) {
      auto* r = reinterpret_cast<Recorder*>(d);
      if (r->lost) return DM_DEVICE_ERROR_LOST;
      r->outputs.push_back({1e-9 * static_cast<double>(now), f[0], f[1], f[2]});
      return DM_DEVICE_OK;
    },
    [](DmDevice* d, int64_t) {
      auto* r = reinterpret_cast<Recorder*>(d);
      if (r->allowReconnect) r->lost = false;
      return r->lost ? DM_DEVICE_ERROR_LOST : DM_DEVICE_OK;
    },
};

class HapticSafety : public ::testing::Test {
 protected:
  void SetUp() override {
    gRecorder = &rec_;
    ASSERT_TRUE(
        registry_.add(DM_HAPTIC_DEVICE_KIND, "recorder", DM_HAPTIC_DEVICE_KIND_ABI_VERSION, &kRecorderVt)
            .ok());
    auto d = dm::HapticDevice::open(registry_, "recorder");
    ASSERT_TRUE(d.ok()) << d.error().message();
    dev_ = std::move(*d);
  }
  void TearDown() override {
    dev_.reset();
    gRecorder = nullptr;
  }
  // Every output that ever reached the device is finite and within the limit.
  void expectAllSafe() const {
    for (const auto& o : rec_.outputs) {
      ASSERT_TRUE(std::isfinite(o[1]) && std::isfinite(o[2]) && std::isfinite(o[3]));
      ASSERT_LE(Vec3(o[1], o[2], o[3]).norm(), 5.0 * (1 + 1e-15));
    }
  }
  Recorder rec_;
  dm::FactoryRegistry registry_;
  std::unique_ptr<dm::HapticDevice> dev_;
};

TEST_F(HapticSafety, NonFiniteCommandsNeverReachTheDevice) {
  const double nan = std::nan(""), inf = INFINITY;
  const Vec3 bad[] = {Vec3(nan, 0, 0), Vec3(0, inf, 0), Vec3(0, 0, -inf), Vec3(nan, nan, nan)};
  std::int64_t t = 0;
  for (const Vec3& f : bad) {
    dev_->command(Vec3(1, 2, 0), Vec3::Zero(), t);
    dev_->servo(t);
    t += kMs;
    dev_->command(f, Vec3::Zero(), t);
    dev_->servo(t);
    EXPECT_EQ(dev_->lastOutput().force, Vec3::Zero());
    t += kMs;
  }
  dev_->command(Vec3::Zero(), Vec3(nan, 0, 0), t);  // NaN torque spoils the whole command
  dev_->servo(t);
  EXPECT_EQ(dev_->lastOutput().force, Vec3::Zero());
  EXPECT_EQ(dev_->counters().nonFinite, 5u);
  dm::DeviceEvent e;
  int nonFiniteEvents = 0;
  while (dev_->pollEvent(e)) nonFiniteEvents += e.type == dm::DeviceEventType::NonFiniteCommand;
  EXPECT_EQ(nonFiniteEvents, 5);
  expectAllSafe();
}

TEST_F(HapticSafety, ForcesAreClampedKeepingTheirDirection) {
  const Vec3 f(30, -40, 0);  // 50 N, ten times the limit
  dev_->command(f, Vec3::Zero(), 0);
  dev_->servo(0);
  EXPECT_NEAR((dev_->lastOutput().force - f / 10.0).norm(), 0.0, 1e-12);
  dev_->command(Vec3(1e308, 1e308, 0), Vec3::Zero(), kMs);  // the norm overflows to Inf
  dev_->servo(kMs);
  EXPECT_TRUE(dev_->lastOutput().force.allFinite());
  dev_->command(Vec3(3, 0, 0), Vec3::Zero(), 2 * kMs);  // within the limit: untouched
  dev_->servo(2 * kMs);
  EXPECT_EQ(dev_->lastOutput().force, Vec3(3, 0, 0));
  EXPECT_EQ(dev_->counters().clamped, 2u);
  expectAllSafe();
}

TEST_F(HapticSafety, AStalledLoopFadesToZeroWithinTenMilliseconds) {
  // The haptic loop commands 4 N until 50 ms, then stalls; servo goes on at 1 kHz.
  for (std::int64_t k = 0; k <= 50; ++k) {
    dev_->command(Vec3(0, 0, 4), Vec3::Zero(), k * kMs);
    dev_->servo(k * kMs);
  }
  for (std::int64_t k = 51; k < 100; ++k) dev_->servo(k * kMs);
  double previous = 4.0;
  for (const auto& o : rec_.outputs) {
    const double t = o[0], fz = o[3];
    EXPECT_LE(fz, previous + 1e-15) << t;  // monotone fade
    previous = fz;
    if (t >= 0.060 - 1e-12) {
      EXPECT_EQ(fz, 0.0) << t;  // zero within 10 ms
    }
    if (t <= 0.052 + 1e-12) {
      EXPECT_EQ(fz, 4.0) << t;  // untouched within the 2 ms deadline
    }
  }
  EXPECT_EQ(dev_->counters().deadlineMisses, 1u);
  dev_->command(Vec3(0, 0, 1), Vec3::Zero(), 100 * kMs);  // the loop is back
  dev_->servo(100 * kMs);
  EXPECT_EQ(dev_->lastOutput().force, Vec3(0, 0, 1));
  std::vector<dm::DeviceEventType> types;
  dm::DeviceEvent e;
  while (dev_->pollEvent(e)) types.push_back(e.type);
  EXPECT_EQ(types, (std::vector<dm::DeviceEventType>{dm::DeviceEventType::DeadlineMissed,
                                                     dm::DeviceEventType::DeadlineRecovered}));
  expectAllSafe();
}

TEST_F(HapticSafety, LostDeviceGetsNothingAndRestartsFromZero) {
  dev_->command(Vec3(2, 0, 0), Vec3::Zero(), 0);
  dev_->servo(0);
  rec_.lost = true;
  EXPECT_EQ(dev_->servo(kMs), dm::DeviceStatus::Lost);
  EXPECT_FALSE(dev_->connected());
  EXPECT_EQ(dev_->lastOutput().force, Vec3::Zero());
  const std::size_t before = rec_.outputs.size();
  rec_.allowReconnect = true;
  EXPECT_EQ(dev_->servo(50 * kMs), dm::DeviceStatus::Lost);  // next try only after 100 ms
  EXPECT_EQ(dev_->servo(101 * kMs), dm::DeviceStatus::Ok);
  EXPECT_TRUE(dev_->connected());
  // The stale 2 N command from before the loss is not resumed.
  ASSERT_EQ(rec_.outputs.size(), before + 1);
  EXPECT_EQ(Vec3(rec_.outputs.back()[1], rec_.outputs.back()[2], rec_.outputs.back()[3]), Vec3::Zero());
  dev_->command(Vec3(1, 0, 0), Vec3::Zero(), 102 * kMs);
  dev_->servo(102 * kMs);
  EXPECT_EQ(dev_->lastOutput().force, Vec3(1, 0, 0));
  EXPECT_EQ(dev_->counters().losses, 1u);
  EXPECT_EQ(dev_->counters().reconnects, 1u);
  expectAllSafe();
}

}  // namespace
