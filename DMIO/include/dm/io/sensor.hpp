// dm/io/sensor.hpp — force sensors, trackers, IMUs and other measuring
// devices behind the driver ABI (kind "sensor", see DmSensorVTable).
//
// A Sensor produces typed, timestamped readings: a scalar, a vector, a unit
// quaternion or a pose (position + orientation), the same type for every
// reading of one sensor (info().type). One poll thread calls poll(t) at the
// sensor's rate; readings reach one consumer thread two ways: latest() (the
// newest whole reading, triple-buffered) and popReading() (every reading in
// order through a 1024-slot ring; when the consumer falls behind the newest
// readings are dropped and counted). Loss and reconnection are events as for
// every device (dm/io/device.hpp). poll() is real-time safe.
//
// Driver: "sim-sensor" (scripted force, tracker, orientation or scalar
// sensor with noise), see dm/io/drivers.hpp.
//
// @code
//   auto ft = dm::Sensor::open(registry, "sim-sensor", {{"type", "force"}, {"noise", "0.01"}});
//   (*ft)->poll(nowNs);                                   // poll thread
//   dm::Vec3 f = (*ft)->latest().vec3();                  // consumer, N
// @endcode
#pragma once

#include <dm/core/plugin.hpp>
#include <dm/core/result.hpp>
#include <dm/core/ring.hpp>
#include <dm/core/triple_buffer.hpp>
#include <dm/core/types.hpp>
#include <dm/io/device.hpp>

#include <array>
#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>

namespace dm {

/// What a SensorReading holds (DM_SENSOR_* of the ABI).
enum class SensorReadingType : std::uint8_t {
  Number = DM_SENSOR_SCALAR,  ///< one value ("scalar")
  Vector = DM_SENSOR_VEC3,    ///< three values ("vec3")
  Quaternion = DM_SENSOR_QUATERNION,
  Pose = DM_SENSOR_POSE
};
/// "scalar", "vec3", "quaternion" or "pose".
std::string_view toString(SensorReadingType type) noexcept;

/// One typed, timestamped reading; values laid out as DmSensorReading.
struct SensorReading {
  std::int64_t timeNs = 0;  ///< host loop time of the measurement
  SensorReadingType type = SensorReadingType::Number;
  std::array<double, 7> values{};
  /// values[0] (Number).
  double scalar() const noexcept { return values[0]; }
  /// values[0..2] (Vector, or the position of a Pose).
  dm::Vec3 vec3() const noexcept { return {values[0], values[1], values[2]}; }
  /// The unit quaternion of a Quaternion (values[0..3]) or Pose (values[3..6]) reading.
  Quat quaternion() const noexcept {
    const std::size_t o = type == SensorReadingType::Pose ? 3 : 0;
    return Quat(values[o], values[o + 1], values[o + 2], values[o + 3]);
  }
  /// Position and orientation of a Pose reading.
  Isometry3 pose() const noexcept {
    Isometry3 p = Isometry3::Identity();
    p.linear() = quaternion().toRotationMatrix();
    p.translation() = vec3();
    return p;
  }
};

/// What an opened sensor measures.
struct SensorInfo {
  DeviceIdentity identity;
  std::uint32_t capabilities = 0;  ///< DM_SENSOR_CAP_* bits
  SensorReadingType type = SensorReadingType::Number;
  double rateHz = 0.0;  ///< suggested poll() rate
  std::string unit;     ///< SI unit of the values, e.g. "N"
};

/// Options of Sensor::open.
struct SensorOptions {
  double reconnectIntervalSeconds = 0.1;  ///< minimum time between reconnect attempts
};

/// A sensor; see the file comment. Not copyable or movable; owned through
/// unique_ptr (about 70 KiB: the reading ring).
class Sensor {
 public:
  /// Opens driver `driver` (kind "sensor", ABI DM_SENSOR_KIND_ABI_VERSION)
  /// of `registry` with `params`. Fails with NotFound, Version,
  /// InvalidArgument (the driver's message, naming the parameter) or Device.
  static Result<std::unique_ptr<Sensor>> open(const FactoryRegistry& registry, std::string_view driver,
                                              const DeviceParams& params = {},
                                              const SensorOptions& options = {});
  ~Sensor();
  Sensor(const Sensor&) = delete;
  Sensor& operator=(const Sensor&) = delete;

  /// Identity, capabilities, reading type, rate and unit.
  const SensorInfo& info() const noexcept { return info_; }

  /// Takes one reading at host time nowNs. Poll thread; real-time safe.
  /// Lost while the sensor is away; IoError when the reading failed or was
  /// rejected (wrong type, NaN/Inf, a quaternion far from unit length).
  /// Quaternions are renormalised.
  DeviceStatus poll(std::int64_t nowNs) noexcept;
  /// The newest reading (consumer thread).
  const SensorReading& latest() noexcept { return latest_.read(); }
  /// The oldest reading not yet popped, if any (consumer thread).
  bool popReading(SensorReading& reading) noexcept { return readings_->tryPop(reading); }
  /// The next Lost/Reconnected event, if any (consumer thread).
  bool pollEvent(DeviceEvent& event) noexcept { return link_.pollEvent(event); }
  /// False between a loss and the reconnection.
  bool connected() const noexcept { return link_.connected(); }
  /// Polls, losses, reconnections and I/O errors so far (any thread).
  DeviceCounters counters() const noexcept { return link_.counters(); }
  /// Readings dropped because the ring was full (monotone).
  std::uint64_t droppedReadings() const noexcept { return dropped_.load(std::memory_order_relaxed); }

 private:
  Sensor() = default;
  const DmSensorVTable* vt_ = nullptr;
  DmDevice* device_ = nullptr;
  std::shared_ptr<const void> keepAlive_;
  SensorInfo info_;
  TripleBuffer<SensorReading> latest_;
  std::unique_ptr<SpscRing<SensorReading, 1024>> readings_ =
      std::make_unique<SpscRing<SensorReading, 1024>>();
  std::atomic<std::uint64_t> dropped_{0};
  detail::DeviceLink link_;
};

}  // namespace dm
