// Sensor and the sim-sensor driver: the plugin against the built-in, each
// reading type against its formula (force vector, rotation about an axis,
// tracker pose), noise statistics, the reading ring and its drop count,
// loss and reconnection, parameter errors, and the wrapper rejecting bad
// readings from a misbehaving driver.
#include <dm/io/sensor.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <vector>

#include "driver_test_support.hpp"

namespace {

using dm::Vec3;
using dm::test::kMs;

std::unique_ptr<dm::Sensor> openSensorOrFail(const dm::FactoryRegistry& reg, const dm::DeviceParams& params) {
  auto s = dm::Sensor::open(reg, "sim-sensor", params);
  EXPECT_TRUE(s.ok()) << (s.ok() ? "" : s.error().message());
  return s.ok() ? std::move(*s) : nullptr;
}

using dm::test::frac;

TEST(SimSensor, PluginAndBuiltInGiveIdenticalReadings) {
  dm::test::PluginDriver plugin("sim_sensor", "sim-sensor");
  ASSERT_TRUE(plugin.loaded);
  dm::test::BuiltinDrivers builtin;
  const dm::DeviceParams params = {
      {"type", "tracker"}, {"x", "sine,0.1,1"}, {"noise", "0.001"}, {"angle_noise", "0.01"}, {"seed", "77"}};
  auto p = dm::Sensor::open(plugin.registry, "sim-sensor", params);
  auto b = dm::Sensor::open(builtin.registry, "sim-sensor", params);
  ASSERT_TRUE(p.ok() && b.ok());
  EXPECT_EQ((*p)->info().identity.driver, "sim-sensor");
  EXPECT_EQ((*p)->info().identity.serial, "sim-77");
  EXPECT_EQ((*p)->info().type, dm::SensorReadingType::Pose);
  EXPECT_EQ((*p)->info().unit, "m");
  for (std::int64_t k = 0; k < 300; ++k) {
    ASSERT_EQ((*p)->poll(k * kMs), dm::DeviceStatus::Ok);
    ASSERT_EQ((*b)->poll(k * kMs), dm::DeviceStatus::Ok);
    ASSERT_EQ((*p)->latest().values, (*b)->latest().values) << k;
  }
}

TEST(SimSensor, ForceFollowsItsFormula) {
  dm::test::BuiltinDrivers b;
  auto s = openSensorOrFail(
      b.registry, {{"type", "force"}, {"x", "sine,2,1,0.5"}, {"y", "square,1,2"}, {"z", "ramp,4,0.5"}});
  ASSERT_TRUE(s);
  EXPECT_EQ(s->info().type, dm::SensorReadingType::Vector);
  EXPECT_EQ(s->info().unit, "N");
  const double pi = std::numbers::pi;
  for (std::int64_t k = 1; k < 3000; k += 11) {
    ASSERT_EQ(s->poll(k * kMs), dm::DeviceStatus::Ok);
    const dm::SensorReading& r = s->latest();
    const double t = 1e-9 * static_cast<double>(k * kMs);
    EXPECT_EQ(r.timeNs, k * kMs);
    EXPECT_EQ(r.type, dm::SensorReadingType::Vector);
    EXPECT_NEAR(r.vec3().x(), 0.5 + 2 * std::sin(2 * pi * t), 1e-12);
    EXPECT_EQ(r.vec3().y(), frac(2 * t) < 0.5 ? 1.0 : -1.0);
    EXPECT_NEAR(r.vec3().z(), 4 * (2 * frac(0.5 * t) - 1), 1e-9);
  }
}

TEST(SimSensor, OrientationRotatesAboutItsAxisAtItsRate) {
  dm::test::BuiltinDrivers b;
  auto s = openSensorOrFail(b.registry, {{"type", "orientation"}, {"axis", "1,1,0"}, {"angular_rate", "2"}});
  ASSERT_TRUE(s);
  EXPECT_EQ(s->info().type, dm::SensorReadingType::Quaternion);
  const Vec3 axis = Vec3(1, 1, 0).normalized();
  const Vec3 across = Vec3(1, -1, 0).normalized();  // perpendicular to the axis
  for (std::int64_t k = 0; k < 3000; k += 17) {
    s->poll(k * kMs);
    const dm::Quat q = s->latest().quaternion();
    const double t = 1e-3 * static_cast<double>(k);
    EXPECT_NEAR(q.norm(), 1.0, 1e-12);
    EXPECT_NEAR((q * axis - axis).norm(), 0.0, 1e-12);  // the axis is fixed
    // A perpendicular vector turns by 2t about the axis.
    const Vec3 expected = std::cos(2 * t) * across + std::sin(2 * t) * axis.cross(across);
    EXPECT_NEAR((q * across - expected).norm(), 0.0, 1e-12) << t;
  }
}

TEST(SimSensor, TrackerGivesAWholePose) {
  dm::test::BuiltinDrivers b;
  auto s = openSensorOrFail(b.registry, {{"type", "tracker"},
                                         {"x", "constant,0,1,0.1"},
                                         {"y", "sine,0.05,0.5"},
                                         {"z", "constant,0,1,-0.2"},
                                         {"axis", "0,0,1"},
                                         {"angular_rate", "1"}});
  ASSERT_TRUE(s);
  s->poll(1500 * kMs);
  const dm::SensorReading& r = s->latest();
  EXPECT_EQ(r.type, dm::SensorReadingType::Pose);
  const dm::Isometry3 pose = r.pose();
  EXPECT_NEAR((pose.translation() - Vec3(0.1, 0.05 * std::sin(std::numbers::pi * 1.5), -0.2)).norm(), 0,
              1e-12);
  EXPECT_NEAR((pose.linear() * Vec3::UnitX() - Vec3(std::cos(1.5), std::sin(1.5), 0)).norm(), 0, 1e-12);
}

TEST(SimSensor, NoiseHasTheRequestedSpread) {
  dm::test::BuiltinDrivers b;
  auto scalar = openSensorOrFail(
      b.registry,
      {{"type", "scalar"}, {"value", "constant,0,1,3"}, {"noise", "0.5"}, {"unit", "K"}, {"seed", "4"}});
  auto rot =
      openSensorOrFail(b.registry, {{"type", "orientation"}, {"angular_rate", "0"}, {"angle_noise", "0.01"}});
  ASSERT_TRUE(scalar && rot);
  EXPECT_EQ(scalar->info().unit, "K");
  double sum = 0, sum2 = 0, angle2 = 0;
  const int n = 20000;
  for (int k = 0; k < n; ++k) {
    scalar->poll(k * kMs);
    rot->poll(k * kMs);
    const double x = scalar->latest().scalar() - 3.0;
    sum += x;
    sum2 += x * x;
    const double angle = 2 * std::acos(std::min(1.0, std::abs(rot->latest().quaternion().w())));
    angle2 += angle * angle;
  }
  EXPECT_NEAR(std::sqrt(sum2 / n - (sum / n) * (sum / n)), 0.5, 0.015);
  EXPECT_NEAR(sum / n, 0.0, 0.015);
  // A rotation vector with three N(0, σ²) components: E[angle²] = 3σ².
  EXPECT_NEAR(angle2 / n, 3 * 0.01 * 0.01, 0.05 * 3e-4);
}

TEST(SimSensor, ReadingRingKeepsOrderAndCountsDrops) {
  dm::test::BuiltinDrivers b;
  auto s = openSensorOrFail(b.registry, {{"type", "scalar"}});
  ASSERT_TRUE(s);
  for (std::int64_t k = 0; k < 2000; ++k) s->poll(k * kMs);
  EXPECT_EQ(s->latest().timeNs, 1999 * kMs);
  EXPECT_EQ(s->droppedReadings(), 2000u - 1024u);
  dm::SensorReading r;
  std::int64_t expected = 0;
  while (s->popReading(r)) {
    ASSERT_EQ(r.timeNs, expected * kMs);  // the oldest kept, in order
    ++expected;
  }
  EXPECT_EQ(expected, 1024);
}

TEST(SimSensor, LossAndReconnectionAreEvents) {
  dm::test::BuiltinDrivers b;
  auto s = openSensorOrFail(b.registry, {{"drop_at", "0.05"}, {"reconnect_at", "0.1"}});
  ASSERT_TRUE(s);
  std::vector<dm::DeviceEvent> events;
  for (std::int64_t k = 0; k < 200; ++k) {
    EXPECT_EQ(s->poll(k * kMs) == dm::DeviceStatus::Lost, k >= 50 && k < 150) << k;
    dm::DeviceEvent e;
    while (s->pollEvent(e)) events.push_back(e);
  }
  ASSERT_EQ(events.size(), 2u);
  EXPECT_EQ(events[0].type, dm::DeviceEventType::Lost);
  EXPECT_EQ(events[0].timeNs, 50 * kMs);
  EXPECT_EQ(events[1].type, dm::DeviceEventType::Reconnected);
  EXPECT_EQ(events[1].timeNs, 150 * kMs);
}

TEST(SimSensor, BadParametersNameTheKey) {
  dm::test::BuiltinDrivers b;
  const std::vector<std::pair<dm::DeviceParams, std::string>> cases = {
      {{{"type", "barometer"}}, "'type'"},
      {{{"axis", "0,0,0"}}, "'axis'"},
      {{{"axis", "1,2"}}, "'axis'"},
      {{{"x", "sine,a"}}, "'x'"},
      {{{"angle_noise", "5"}}, "'angle_noise'"},
      {{{"unit", "furlongs per fortnight"}}, "'unit'"},
      {{{"rate", "0"}}, "'rate'"},
      {{{"colour", "red"}}, "'colour'"},
  };
  for (const auto& [params, needle] : cases) {
    auto s = dm::Sensor::open(b.registry, "sim-sensor", params);
    ASSERT_FALSE(s.ok()) << needle;
    EXPECT_EQ(s.error().code, dm::ErrorCode::InvalidArgument);
    EXPECT_NE(s.error().message().find(needle), std::string::npos) << s.error().message();
  }
}

// A quaternion sensor whose next reading the test sets.
DmSensorReading gNext{};
std::uint32_t gInfoType = DM_SENSOR_QUATERNION;
const DmSensorVTable kFakeVt = {
    [](const DmDeviceParam*, size_t, char*, size_t) { return reinterpret_cast<DmDevice*>(&gNext); },
    [](DmDevice*) {},
    [](DmDevice*, DmSensorInfo* info) {
      *info = DmSensorInfo{};
      info->reading_type = gInfoType;
      info->rate_hz = 100;
      return DM_DEVICE_OK;
    },
    [](DmDevice*, int64_t, DmSensorReading* r) {
      *r = gNext;
      return DM_DEVICE_OK;
    },
    nullptr,
};

TEST(Sensor, RejectsBadReadingsAndNormalisesQuaternions) {
  dm::FactoryRegistry reg;
  ASSERT_TRUE(reg.add(DM_SENSOR_KIND, "fake", DM_SENSOR_KIND_ABI_VERSION, &kFakeVt).ok());
  gInfoType = 9;
  auto bad = dm::Sensor::open(reg, "fake");
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.error().code, dm::ErrorCode::Device);
  gInfoType = DM_SENSOR_QUATERNION;
  auto s = dm::Sensor::open(reg, "fake");
  ASSERT_TRUE(s.ok()) << s.error().message();
  gNext = DmSensorReading{1, DM_SENSOR_QUATERNION, 0, {1.0000001, 0, 0, 0, 0, 0, 0}};
  EXPECT_EQ((*s)->poll(0), dm::DeviceStatus::Ok);
  EXPECT_EQ((*s)->latest().values[0], 1.0);  // renormalised
  const DmSensorReading rejected[] = {
      {2, DM_SENSOR_VEC3, 0, {1, 0, 0, 0, 0, 0, 0}},            // wrong type
      {3, DM_SENSOR_QUATERNION, 0, {NAN, 0, 0, 0, 0, 0, 0}},    // NaN
      {4, DM_SENSOR_QUATERNION, 0, {0.5, 0.5, 0, 0, 0, 0, 0}},  // far from unit length
  };
  for (const DmSensorReading& r : rejected) {
    gNext = r;
    EXPECT_EQ((*s)->poll(r.time_ns), dm::DeviceStatus::IoError);
  }
  EXPECT_EQ((*s)->latest().timeNs, 1);
  EXPECT_EQ((*s)->counters().ioErrors, 3u);
}

}  // namespace
