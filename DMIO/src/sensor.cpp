// Sensor: a "sensor" driver behind validation, a triple buffer, a reading
// ring and loss/reconnection events (see dm/io/sensor.hpp).
#include <dm/io/sensor.hpp>

#include <algorithm>
#include <cmath>

#include "device_open.hpp"

namespace dm {

std::string_view toString(SensorReadingType type) noexcept {
  switch (type) {
    case SensorReadingType::Number:
      return "scalar";
    case SensorReadingType::Vector:
      return "vec3";
    case SensorReadingType::Quaternion:
      return "quaternion";
    case SensorReadingType::Pose:
      return "pose";
  }
  return "unknown";
}

namespace {
// Number of values[] a reading of `type` uses.
std::size_t valueCount(std::uint32_t type) noexcept {
  constexpr std::size_t kCounts[] = {1, 3, 4, 7};
  return type <= DM_SENSOR_POSE ? kCounts[type] : 0;
}
}  // namespace

Result<std::unique_ptr<Sensor>> Sensor::open(const FactoryRegistry& registry, std::string_view driver,
                                             const DeviceParams& params, const SensorOptions& options) {
  auto found = detail::findDeviceVTable<DmSensorVTable>(registry, DM_SENSOR_KIND, DM_SENSOR_KIND_ABI_VERSION,
                                                        "sensor", driver);
  if (!found) return std::move(found).error();
  const DmSensorVTable* vt = found->vt;
  if (!vt || !vt->open || !vt->close || !vt->get_info || !vt->read)
    return detail::nullFunctionError(found->where, "open, close, get_info and read");
  if (!(options.reconnectIntervalSeconds >= 0.0))
    return fail(ErrorCode::InvalidArgument, "reconnectIntervalSeconds is negative or NaN", found->where,
                "use a time ≥ 0 s");
  auto dev = detail::openDeviceInstance(vt->open, params, found->where);
  if (!dev) return std::move(dev).error();

  std::unique_ptr<Sensor> s(new Sensor());
  s->vt_ = vt;
  s->device_ = *dev;
  s->keepAlive_ = found->keepAlive;
  s->link_.setInterval(options.reconnectIntervalSeconds);
  DmSensorInfo ci{};
  if (vt->get_info(*dev, &ci) != DM_DEVICE_OK)
    return fail(ErrorCode::Device, "get_info failed", found->where, "check the device connection");
  if (valueCount(ci.reading_type) == 0 || !(ci.rate_hz > 0.0) || !std::isfinite(ci.rate_hz))
    return fail(ErrorCode::Device, "driver reports nonsensical info (reading type or rate)", found->where,
                "a driver reports a DM_SENSOR_* type and a positive rate");
  s->info_ = {toDeviceIdentity(ci.identity), ci.capabilities, static_cast<SensorReadingType>(ci.reading_type),
              ci.rate_hz, detail::fixedString(ci.unit, sizeof ci.unit)};
  return s;
}

Sensor::~Sensor() {
  if (vt_ && device_) vt_->close(device_);
}

DeviceStatus Sensor::poll(std::int64_t nowNs) noexcept {
  if (!link_.connectedForPoll()) {
    if (!vt_->reconnect || !link_.reconnectDue(nowNs) || vt_->reconnect(device_, nowNs) != DM_DEVICE_OK)
      return DeviceStatus::Lost;
    link_.reconnected(nowNs);
  }
  DmSensorReading r{};
  const int rs = vt_->read(device_, nowNs, &r);
  if (rs == DM_DEVICE_ERROR_LOST) {
    link_.lost(nowNs);
    return DeviceStatus::Lost;
  }
  const std::uint32_t type = static_cast<std::uint32_t>(info_.type);
  const std::size_t n = valueCount(type);
  bool valid = rs == DM_DEVICE_OK && r.type == type &&
               std::all_of(r.values, r.values + n, [](double v) { return std::isfinite(v); });
  SensorReading out;
  out.timeNs = r.time_ns;
  out.type = info_.type;
  std::copy(r.values, r.values + n, out.values.begin());
  if (valid && (info_.type == SensorReadingType::Quaternion || info_.type == SensorReadingType::Pose)) {
    const std::size_t o = info_.type == SensorReadingType::Pose ? 3 : 0;
    const double norm =
        std::sqrt(out.values[o] * out.values[o] + out.values[o + 1] * out.values[o + 1] +
                  out.values[o + 2] * out.values[o + 2] + out.values[o + 3] * out.values[o + 3]);
    valid = std::abs(norm - 1.0) < 1e-3;  // a driver bug or garbage, not rounding
    for (std::size_t i = o; valid && i < o + 4; ++i) out.values[i] /= norm;
  }
  if (!valid) {
    link_.ioError();
    return DeviceStatus::IoError;
  }
  latest_.writeBuffer() = out;
  latest_.publish();
  if (!readings_->tryPush(out)) dropped_.fetch_add(1, std::memory_order_relaxed);
  return DeviceStatus::Ok;
}

}  // namespace dm
