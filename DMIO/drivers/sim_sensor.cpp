// sim-sensor — a simulated sensor (kind "sensor") with scripted values and
// seeded Gaussian noise: a scalar probe, a 3-axis force sensor, an
// orientation sensor (IMU) or a 6-DOF tracker (pose).
//
// At host time t (s):
//   scalar       value(t) + n                          values[0], unit `unit`
//   force        (x(t), y(t), z(t)) + n                N
//   orientation  q(t) = (cos(ωt/2), sin(ωt/2)·axis) ⊗ δq
//   tracker      position (x(t), y(t), z(t)) + n (m), orientation q(t) ⊗ δq
// with n ~ N(0, noise²) per component and δq a rotation by a random vector
// with components ~ N(0, angle_noise²) (rad). Signals are
// dm::driver::Signal specs.
//
// Parameters (all optional):
//   type          scalar | force | orientation | tracker        (force)
//   value         signal of a scalar                            (sine,1,1,0)
//   x, y, z       signals of the vector / tracker position      (constant,1,1,0)
//   axis          "x,y,z" rotation axis (normalised)            (0,0,1)
//   angular_rate  ω, rad/s                                      (1)
//   noise         standard deviation of n                       (0)
//   angle_noise   rad, standard deviation of δq's components    (0)
//   unit          unit of a scalar, ≤ 15 characters             ("")
//   seed          integer, noise generator                      (1)
//   rate          Hz                                            (1000)
//   drop_at, reconnect_at  s (-1: never)
//
// Built into DM::IO and, with DM_DRIVER_PLUGIN, as libdm_driver_sim_sensor.so.
#include <dm/core/plugin_abi.h>
#include <dm/io/device_abi.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <new>
#include <random>

#include "driver_params.hpp"
#include "sim_signal.hpp"

namespace {

using dm::driver::ParamReader;
using dm::driver::Signal;

enum SensorType { kScalar, kForce, kOrientation, kTracker };

// One instance; DmDevice* is this type behind the C boundary.
struct SimSensor {
  SensorType type = kForce;
  Signal value{Signal::kSine, 1.0, 1.0, 0.0};
  Signal xyz[3];
  std::array<double, 3> axis{0, 0, 1};
  double angularRate = 1.0, noise = 0.0, angleNoise = 0.0, rate = 1000.0;
  char unit[16] = "";
  unsigned long long seed = 1;
  std::mt19937_64 rng;
  std::normal_distribution<double> gauss{0.0, 1.0};
  dm::driver::LossWindow loss;

  double noisy(double x) { return noise > 0.0 ? x + noise * gauss(rng) : x; }

  // q(t) ⊗ δq into q[0..3] (w, x, y, z).
  void orientation(double t, double* q) {
    const double h = 0.5 * angularRate * t;
    double a[4] = {std::cos(h), std::sin(h) * axis[0], std::sin(h) * axis[1], std::sin(h) * axis[2]};
    double b[4] = {1.0, 0.0, 0.0, 0.0};
    if (angleNoise > 0.0) {
      const double r[3] = {angleNoise * gauss(rng), angleNoise * gauss(rng), angleNoise * gauss(rng)};
      const double angle = std::sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2]);
      if (angle > 0.0) {
        const double s = std::sin(0.5 * angle) / angle;
        b[0] = std::cos(0.5 * angle);
        b[1] = s * r[0];
        b[2] = s * r[1];
        b[3] = s * r[2];
      }
    }
    q[0] = a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3];
    q[1] = a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2];
    q[2] = a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1];
    q[3] = a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0];
  }
};

SimSensor* asSimSensor(DmDevice* d) { return reinterpret_cast<SimSensor*>(d); }

DmDevice* senOpen(const DmDeviceParam* params, size_t count, char* error, size_t errorSize) {
  ParamReader r(params, count, error, errorSize);
  r.onlyKnown({"type", "value", "x", "y", "z", "axis", "angular_rate", "noise", "angle_noise", "unit", "seed",
               "rate", "drop_at", "reconnect_at"});
  SimSensor* d = new (std::nothrow) SimSensor();
  if (!d) {
    r.failf("out of memory");
    return nullptr;
  }
  d->type = static_cast<SensorType>(r.choice("type", {"scalar", "force", "orientation", "tracker"}, kForce));
  dm::driver::readSignal(r, "value", d->value);
  static const char* const kKeys[] = {"x", "y", "z"};
  for (int i = 0; i < 3; ++i) {
    d->xyz[i] = Signal{Signal::kConstant, 1.0, 1.0, 0.0};
    dm::driver::readSignal(r, kKeys[i], d->xyz[i]);
  }
  d->axis = r.triple("axis", {0, 0, 1});
  const double norm = std::sqrt(d->axis[0] * d->axis[0] + d->axis[1] * d->axis[1] + d->axis[2] * d->axis[2]);
  if (r.ok() && !(norm > 1e-12)) r.failf("parameter 'axis': the rotation axis has zero length");
  if (r.ok())
    for (double& a : d->axis) a /= norm;
  d->angularRate = r.number("angular_rate", 1.0, -1e6, 1e6);
  d->noise = r.number("noise", 0.0, 0.0, 1e6);
  d->angleNoise = r.number("angle_noise", 0.0, 0.0, 3.0);
  if (const char* unit = r.find("unit")) {
    if (std::strlen(unit) >= sizeof d->unit)
      r.failf("parameter 'unit': '%s' is longer than 15 characters", unit);
    else
      dm::driver::copyField(d->unit, unit);
  }
  d->seed = static_cast<unsigned long long>(r.number("seed", 1.0, 0.0, 9007199254740992.0));
  d->rate = r.number("rate", 1000.0, 1e-3, 1e6);
  d->loss.read(r);
  if (!r.ok()) {
    delete d;
    return nullptr;
  }
  d->rng.seed(d->seed);
  return reinterpret_cast<DmDevice*>(d);
}

void senClose(DmDevice* d) { delete asSimSensor(d); }

int senInfo(DmDevice* dev, DmSensorInfo* info) {
  SimSensor* d = asSimSensor(dev);
  static const char* const kModels[] = {"simulated scalar sensor", "simulated 3-axis force sensor",
                                        "simulated orientation sensor", "simulated 6-DOF tracker"};
  static const std::uint32_t kTypes[] = {DM_SENSOR_SCALAR, DM_SENSOR_VEC3, DM_SENSOR_QUATERNION,
                                         DM_SENSOR_POSE};
  *info = DmSensorInfo{};
  dm::driver::simIdentity(info->identity, "sim-sensor", kModels[d->type], d->seed);
  info->capabilities = DM_SENSOR_CAP_RECONNECT;
  info->reading_type = kTypes[d->type];
  info->rate_hz = d->rate;
  dm::driver::copyField(info->unit, d->type == kScalar    ? d->unit
                                    : d->type == kForce   ? "N"
                                    : d->type == kTracker ? "m"
                                                          : "1");
  return DM_DEVICE_OK;
}

int senRead(DmDevice* dev, int64_t now, DmSensorReading* out) {
  SimSensor* d = asSimSensor(dev);
  if (d->loss.lostAt(now)) return DM_DEVICE_ERROR_LOST;
  const double t = 1e-9 * static_cast<double>(now);
  *out = DmSensorReading{};
  out->time_ns = now;
  switch (d->type) {
    case kScalar:
      out->type = DM_SENSOR_SCALAR;
      out->values[0] = d->noisy(d->value.at(t));
      break;
    case kForce:
      out->type = DM_SENSOR_VEC3;
      for (int i = 0; i < 3; ++i) out->values[i] = d->noisy(d->xyz[i].at(t));
      break;
    case kOrientation:
      out->type = DM_SENSOR_QUATERNION;
      d->orientation(t, out->values);
      break;
    case kTracker:
      out->type = DM_SENSOR_POSE;
      for (int i = 0; i < 3; ++i) out->values[i] = d->noisy(d->xyz[i].at(t));
      d->orientation(t, out->values + 3);
      break;
  }
  return DM_DEVICE_OK;
}

int senReconnect(DmDevice* dev, int64_t now) { return asSimSensor(dev)->loss.reconnect(now); }

const DmSensorVTable kSimSensor = {senOpen, senClose, senInfo, senRead, senReconnect};

int senInit(const DmHostApi* host) {
  return host->register_factory(host->ctx, DM_SENSOR_KIND, "sim-sensor", DM_SENSOR_KIND_ABI_VERSION,
                                &kSimSensor);
}

const DmPluginInfo kSimSensorInfo = {DM_PLUGIN_ABI_VERSION, "sim-sensor", "1.0", senInit, nullptr};

}  // namespace

#if defined(DM_DRIVER_PLUGIN)
DM_PLUGIN_ENTRY { return &kSimSensorInfo; }
#else
extern "C" const DmPluginInfo* dm_builtin_entry_sim_sensor(void) { return &kSimSensorInfo; }
#endif
