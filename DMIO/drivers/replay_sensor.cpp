// replay-sensor — plays the sensor readings of a recording
// (dm/io/recorder.hpp, DeviceRecorder::pushSensorReading) back as a sensor
// (kind "sensor").
//
// Parameters (see replay_common.hpp): file (required), rate, loop, strict;
// and unit, the SI unit to report (≤ 15 characters, default ""). Every
// recorded reading must have the same type (scalar, vec3, quaternion or
// pose); it is the sensor's reading type.
// The first read call maps host time to the first record; later calls return
// the latest reading at or before first + rate · (now − start) (sample and
// hold, exact recorded values), stamped with the host time at which it
// plays: start + (t − first) / rate. End of stream: without loop, once the
// replay passes the last reading read reports DM_DEVICE_ERROR_LOST (the
// Sensor queues a Lost event); there is no reconnect.
//
// Built into DM::IO and, with DM_DRIVER_PLUGIN, as libdm_driver_replay_sensor.so.
#include <dm/core/plugin_abi.h>
#include <dm/io/device_abi.h>

#include <cstring>
#include <vector>

#include "replay_common.hpp"

namespace {

using dm::driver::ParamReader;

struct SensorFrame {
  std::int64_t t;
  std::uint32_t type;
  double values[7];
};

// One instance; DmDevice* is this type behind the C boundary.
struct ReplaySensor {
  dm::driver::ReplayStream<SensorFrame> stream;
  char unit[16] = {};
};

ReplaySensor* asReplaySensor(DmDevice* d) { return reinterpret_cast<ReplaySensor*>(d); }

std::string decodeSensorFrame(const dm::record::RecordView& v, std::vector<SensorFrame>& frames) {
  std::string why = dm::record::checkSensorReading(v.payload);
  if (!why.empty()) return why;
  SensorFrame f{};
  f.t = v.timeNs;
  dm::record::decodeSensorReading(v.payload, f.type, f.values);
  if (!frames.empty() && f.type != frames.front().type)
    return "reading type " + std::to_string(f.type) + " differs from the first reading's (" +
           std::to_string(frames.front().type) + "); a sensor has one reading type";
  frames.push_back(f);
  return why;
}

DmDevice* sensorOpen(const DmDeviceParam* params, size_t count, char* error, size_t errorSize) {
  return dm::driver::openReplay<ReplaySensor>(
      params, count, error, errorSize, {"file", "rate", "loop", "strict", "unit"},
      [](ReplaySensor& r, const dm::driver::ReplayOptions& o, ParamReader& p) {
        if (const char* unit = p.find("unit")) {
          if (std::strlen(unit) >= sizeof r.unit)
            p.failf("parameter 'unit': '%s' is longer than 15 characters", unit);
          dm::driver::copyField(r.unit, unit);
        }
        if (p.ok())
          r.stream.load(o, dm::record::kSensorReading, dm::record::kSensorReadingBytes, "sensor-reading", p,
                        decodeSensorFrame);
      });
}

int sensorInfo(DmDevice* dev, DmSensorInfo* info) {
  ReplaySensor* r = asReplaySensor(dev);
  *info = DmSensorInfo{};
  dm::driver::replayIdentity(info->identity, "replay-sensor", "sensor stream", r->stream.source);
  info->reading_type = r->stream.frames.front().type;
  info->rate_hz = r->stream.clock.eventRate(static_cast<double>(r->stream.frames.size()), 1000.0);
  dm::driver::copyField(info->unit, r->unit);
  return DM_DEVICE_OK;
}

int sensorRead(DmDevice* dev, int64_t now, DmSensorReading* reading) {
  ReplaySensor* r = asReplaySensor(dev);
  std::int64_t time = 0;
  const SensorFrame* f = r->stream.playing(now, time);
  if (!f) return DM_DEVICE_ERROR_LOST;  // end of stream
  *reading = DmSensorReading{};
  reading->time_ns = time;
  reading->type = f->type;
  for (int i = 0; i < 7; ++i) reading->values[i] = f->values[i];
  return DM_DEVICE_OK;
}

const DmSensorVTable kReplaySensor = {sensorOpen, dm::driver::closeReplay<ReplaySensor>, sensorInfo,
                                      sensorRead, nullptr};

int sensorInit(const DmHostApi* host) {
  return host->register_factory(host->ctx, DM_SENSOR_KIND, "replay-sensor", DM_SENSOR_KIND_ABI_VERSION,
                                &kReplaySensor);
}

const DmPluginInfo kReplaySensorInfo = {DM_PLUGIN_ABI_VERSION, "replay-sensor", "1.0", sensorInit, nullptr};

}  // namespace

#if defined(DM_DRIVER_PLUGIN)
DM_PLUGIN_ENTRY { return &kReplaySensorInfo; }
#else
extern "C" const DmPluginInfo* dm_builtin_entry_replay_sensor(void) { return &kReplaySensorInfo; }
#endif
