// Recording and replay of controller, DAQ and sensor streams: streams of the
// sim-controller, sim-daq and sim-sensor drivers recorded with
// DeviceRecorder, decoded (decodeControllerState/DaqBlock/SensorReading) and
// replayed through replay-controller, replay-daq and replay-sensor, compared
// value for value and timestamp for timestamp with what was recorded; a
// scaled rate and looping on the host (virtual) clock; end of stream as a
// Lost event; a file cut at every byte (a killed writer), a cut last record,
// a corrupted header and invalid payloads.
#include <dm/io/recorder.hpp>

#include <gtest/gtest.h>

#include <array>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string>
#include <vector>

#include "../common/temp_dir.hpp"
#include "driver_test_support.hpp"

namespace {

namespace fs = std::filesystem;
using dm::test::kMs;
constexpr std::uint16_t kControllerType = static_cast<std::uint16_t>(dm::RecordType::ControllerState);
constexpr std::uint16_t kDaqType = static_cast<std::uint16_t>(dm::RecordType::DaqBlock);
constexpr std::uint16_t kSensorType = static_cast<std::uint16_t>(dm::RecordType::SensorReading);

std::vector<std::uint8_t> readBytes(const fs::path& file) {
  std::ifstream in(file, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), {}};
}
void writeBytes(const fs::path& file, const std::vector<std::uint8_t>& bytes, std::size_t n) {
  std::ofstream out(file, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(n));
}
bool contains(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

bool sameController(const dm::ControllerState& a, const dm::ControllerState& b) {
  return a.timeNs == b.timeNs && a.axes == b.axes && a.buttons == b.buttons;
}
bool sameSensor(const dm::SensorReading& a, const dm::SensorReading& b) {
  return a.timeNs == b.timeNs && a.type == b.type && a.values == b.values;
}
bool sameDaq(const dm::DaqFrame& a, const dm::DaqFrame& b) {
  return a.timeNs == b.timeNs && a.index == b.index && a.values == b.values;
}

// 500 states of a noisy sim-controller polled every 4 ms from t = 0, 128
// buttons counting at 50 Hz, recorded to `file`.
std::vector<dm::ControllerState> recordController(const dm::FactoryRegistry& reg, const fs::path& file) {
  auto pad = dm::Controller::open(reg, "sim-controller",
                                  {{"axis0", "sine,0.8,3"},
                                   {"axis1", "square,0.5,2"},
                                   {"axis2", "ramp,0.9,1"},
                                   {"noise", "0.05"},
                                   {"seed", "11"},
                                   {"buttons", "128"},
                                   {"button_rate", "50"}});
  EXPECT_TRUE(pad.ok()) << pad.error().message();
  auto rec = dm::DeviceRecorder::create(file, {.metadata = R"({"device":"pad"})"});
  EXPECT_TRUE(rec.ok()) << rec.error().message();
  std::vector<dm::ControllerState> states;
  if (!pad.ok() || !rec.ok()) return states;
  for (std::int64_t k = 0; k < 500; ++k) {
    EXPECT_EQ((*pad)->poll(k * 4 * kMs), dm::DeviceStatus::Ok);
    states.push_back((*pad)->state());
    EXPECT_TRUE((*rec)->pushControllerState(states.back()));
  }
  EXPECT_TRUE((*rec)->close().ok());
  return states;
}

// 300 readings of a noisy sim-sensor force sensor polled every 1 ms.
std::vector<dm::SensorReading> recordSensor(const dm::FactoryRegistry& reg, const fs::path& file) {
  auto ft = dm::Sensor::open(reg, "sim-sensor",
                             {{"type", "force"}, {"x", "sine,2,5"}, {"noise", "0.05"}, {"seed", "3"}});
  EXPECT_TRUE(ft.ok()) << ft.error().message();
  auto rec = dm::DeviceRecorder::create(file);
  EXPECT_TRUE(rec.ok());
  std::vector<dm::SensorReading> readings;
  if (!ft.ok() || !rec.ok()) return readings;
  for (std::int64_t k = 0; k < 300; ++k) {
    EXPECT_EQ((*ft)->poll(k * kMs), dm::DeviceStatus::Ok);
    readings.push_back((*ft)->latest());
    EXPECT_TRUE((*rec)->pushSensorReading(readings.back()));
  }
  EXPECT_TRUE((*rec)->close().ok());
  return readings;
}

// A sim-daq stream of 3 channels at 1 kHz with a 64-frame FIFO, acquired
// every 10 ms for 1 s except for a 100 ms pause at 0.5 s (the FIFO
// overflows: 36 frames lost), recorded as read.
struct DaqStream {
  std::vector<dm::DaqFrame> frames;
  std::uint64_t overrun = 0;
};
DaqStream recordDaq(const dm::FactoryRegistry& reg, const fs::path& file) {
  auto daq =
      dm::Daq::open(reg, "sim-daq", {{"channels", "3"}, {"fifo", "64"}, {"noise", "0.1"}, {"seed", "7"}});
  EXPECT_TRUE(daq.ok()) << daq.error().message();
  auto rec = dm::DeviceRecorder::create(file);
  EXPECT_TRUE(rec.ok());
  DaqStream s;
  if (!daq.ok() || !rec.ok()) return s;
  std::array<dm::DaqFrame, 512> buf;
  for (std::int64_t t = 0; t <= 1000 * kMs; t += 10 * kMs) {
    if (t > 500 * kMs && t < 600 * kMs) continue;  // the pause
    EXPECT_EQ((*daq)->acquire(t), dm::DeviceStatus::Ok);
    const dm::DaqReadResult got = (*daq)->read(buf);
    EXPECT_EQ((*rec)->pushDaqFrames(std::span(buf.data(), got.frames), 3, got.overrunFrames), got.frames);
    s.frames.insert(s.frames.end(), buf.begin(), buf.begin() + static_cast<std::ptrdiff_t>(got.frames));
    s.overrun += got.overrunFrames;
  }
  EXPECT_TRUE((*rec)->close().ok());
  return s;
}

TEST(StreamRecorder, DecodersReturnExactlyWhatWasPushed) {
  dm::test::BuiltinDrivers d;
  dm::test::TempDir dir("stream_decode");
  const auto states = recordController(d.registry, dir / "pad.dmrec");
  const auto readings = recordSensor(d.registry, dir / "ft.dmrec");
  const DaqStream daq = recordDaq(d.registry, dir / "daq.dmrec");
  ASSERT_EQ(daq.overrun, 36u);  // 100 ms missed, FIFO 64 frames

  auto pad = dm::readRecording(dir / "pad.dmrec");
  ASSERT_TRUE(pad.ok()) << pad.error().message();
  EXPECT_EQ(pad->metadata, R"({"device":"pad"})");
  ASSERT_EQ(pad->records.size(), states.size());
  for (std::size_t i = 0; i < states.size(); ++i) {
    auto s = dm::decodeControllerState(pad->records[i]);
    ASSERT_TRUE(s.ok()) << s.error().message();
    ASSERT_TRUE(sameController(*s, states[i])) << i;
  }
  EXPECT_GT(states[300].buttons.count(), 0u);  // the button counter ran

  auto ft = dm::readRecording(dir / "ft.dmrec");
  ASSERT_TRUE(ft.ok());
  ASSERT_EQ(ft->records.size(), readings.size());
  for (std::size_t i = 0; i < readings.size(); ++i) {
    auto r = dm::decodeSensorReading(ft->records[i]);
    ASSERT_TRUE(r.ok()) << r.error().message();
    ASSERT_TRUE(sameSensor(*r, readings[i])) << i;
  }

  auto blocks = dm::readRecording(dir / "daq.dmrec");
  ASSERT_TRUE(blocks.ok());
  std::vector<dm::DaqFrame> frames;
  std::uint64_t overrun = 0;
  for (const auto& r : blocks->records) {
    auto b = dm::decodeDaqBlock(r);
    ASSERT_TRUE(b.ok()) << b.error().message();
    EXPECT_EQ(b->channelCount, 3u);
    EXPECT_LE(b->frames.size(), 6u);  // (256 − 16) / (16 + 3·8) frames fit a queue slot
    if (b->overrunFrames) {
      EXPECT_EQ(b->frames[0].index, frames.back().index + 1 + b->overrunFrames);  // the gap is where it was
    }
    overrun += b->overrunFrames;
    frames.insert(frames.end(), b->frames.begin(), b->frames.end());
  }
  EXPECT_EQ(overrun, daq.overrun);
  ASSERT_EQ(frames.size(), daq.frames.size());
  for (std::size_t i = 0; i < frames.size(); ++i) ASSERT_TRUE(sameDaq(frames[i], daq.frames[i])) << i;

  // A record of another type is refused, naming the record and its byte.
  auto wrong = dm::decodeSensorReading(pad->records[2]);
  ASSERT_FALSE(wrong.ok());
  const std::size_t third = 12 + pad->metadata.size() + 2 * (20 + 64);
  EXPECT_TRUE(contains(wrong.error().message(), "record 2 at byte " + std::to_string(third)))
      << wrong.error().message();
  EXPECT_FALSE(dm::decodeDaqBlock(pad->records[0]).ok());
  EXPECT_FALSE(dm::decodeControllerState(ft->records[0]).ok());
  EXPECT_FALSE(dm::decodeHapticState(pad->records[0]).ok());
}

TEST(StreamRecorder, InvalidPayloadsNameTheRecordAndTheByte) {
  dm::test::TempDir dir("stream_invalid");
  auto rec = dm::DeviceRecorder::create(dir / "bad.dmrec");
  ASSERT_TRUE(rec.ok());
  dm::ControllerState good;
  good.axes = {0.5, -0.5, 1.0, -1.0, 0.0, 0.25};
  ASSERT_TRUE((*rec)->pushControllerState(good));
  ASSERT_TRUE((*rec)->close().ok());
  auto bytes = readBytes(dir / "bad.dmrec");
  auto back = dm::parseRecording(bytes, "bad.dmrec");
  ASSERT_TRUE(back.ok());
  ASSERT_EQ(back->records.size(), 1u);

  // Axis 1 set to 5.0 (outside [-1, 1]), CRC still valid: decoding refuses.
  dm::RecordedRecord axis = back->records[0];
  const double five = 5.0;
  std::memcpy(axis.payload.data() + 8, &five, 8);
  auto a = dm::decodeControllerState(axis);
  ASSERT_FALSE(a.ok());
  EXPECT_TRUE(contains(a.error().message(), "record 0 at byte 12")) << a.error().message();
  EXPECT_TRUE(contains(a.error().message(), "axis 1")) << a.error().message();

  dm::RecordedRecord sensor;
  sensor.type = kSensorType;
  sensor.index = 4;
  sensor.offset = 999;
  sensor.payload.assign(64, std::byte{0});
  sensor.payload[0] = std::byte{7};  // reading type 7
  auto s = dm::decodeSensorReading(sensor);
  ASSERT_FALSE(s.ok());
  EXPECT_TRUE(contains(s.error().message(), "record 4 at byte 999")) << s.error().message();
  EXPECT_TRUE(contains(s.error().message(), "reading type 7")) << s.error().message();
  sensor.payload.resize(60);
  EXPECT_TRUE(contains(dm::decodeSensorReading(sensor).error().message(), "60 bytes"));

  dm::RecordedRecord block;
  block.type = kDaqType;
  block.payload.assign(16 + 40, std::byte{0});
  block.payload[0] = std::byte{3};  // 3 channels, 1 frame = 16 + 16 + 24 = 56 bytes
  block.payload[2] = std::byte{1};
  EXPECT_TRUE(dm::decodeDaqBlock(block).ok());
  block.payload[0] = std::byte{0};
  EXPECT_TRUE(contains(dm::decodeDaqBlock(block).error().message(), "channel count 0"));
  block.payload[0] = std::byte{3};
  block.payload[2] = std::byte{2};  // 2 frames claimed, 1 present
  EXPECT_TRUE(contains(dm::decodeDaqBlock(block).error().message(), "needs 96 bytes"));
  block.payload[2] = std::byte{1};
  const double nan = std::numeric_limits<double>::quiet_NaN();
  std::memcpy(block.payload.data() + 16 + 16 + 8, &nan, 8);
  EXPECT_TRUE(contains(dm::decodeDaqBlock(block).error().message(), "channel 1 (payload byte 40)"));

  // A too-wide DAQ block is not queued at all.
  auto r2 = dm::DeviceRecorder::create(dir / "empty.dmrec");
  ASSERT_TRUE(r2.ok());
  std::array<dm::DaqFrame, 2> two{};
  EXPECT_EQ((*r2)->pushDaqFrames(two, 17), 0u);
  EXPECT_EQ((*r2)->dropped(), 1u);
}

TEST(ReplayController, PlaysExactlyAtTheRecordedAScaledRateAndLooped) {
  dm::test::BuiltinDrivers d;
  dm::test::TempDir dir("replay_controller");
  const auto states = recordController(d.registry, dir / "pad.dmrec");
  ASSERT_EQ(states.size(), 500u);
  const std::string file = (dir / "pad.dmrec").string();

  // Recorded rate, started at the recording's time 0: identical states.
  auto same = dm::Controller::open(d.registry, "replay-controller", {{"file", file}});
  ASSERT_TRUE(same.ok()) << same.error().message();
  EXPECT_EQ((*same)->info().identity.driver, "replay-controller");
  EXPECT_EQ((*same)->info().identity.model, "recorded controller stream");
  EXPECT_EQ((*same)->info().identity.serial, "500-records");
  EXPECT_NEAR((*same)->info().pollRateHz, 250.0, 1e-9);
  for (std::int64_t k = 0; k < 500; ++k) {
    ASSERT_EQ((*same)->poll(k * 4 * kMs), dm::DeviceStatus::Ok);
    ASSERT_TRUE(sameController((*same)->state(), states[k])) << k;
  }
  // End of stream: a Lost status and event, the last state kept.
  EXPECT_EQ((*same)->poll(499 * 4 * kMs + 1), dm::DeviceStatus::Lost);
  EXPECT_EQ((*same)->poll(600 * 4 * kMs), dm::DeviceStatus::Lost);
  dm::DeviceEvent e;
  ASSERT_TRUE((*same)->pollEvent(e));
  EXPECT_EQ(e.type, dm::DeviceEventType::Lost);
  EXPECT_EQ(e.timeNs, 499 * 4 * kMs + 1);
  EXPECT_FALSE((*same)->pollEvent(e));
  EXPECT_FALSE((*same)->connected());
  EXPECT_TRUE(sameController((*same)->state(), states[499]));

  // Twice as fast from host time 7 s: record k plays at 7 s + 2k ms and is
  // held until the next one.
  const std::int64_t t0 = 7000 * kMs;
  auto fast = dm::Controller::open(d.registry, "replay-controller", {{"file", file}, {"rate", "2"}});
  ASSERT_TRUE(fast.ok());
  EXPECT_NEAR((*fast)->info().pollRateHz, 500.0, 1e-9);
  for (std::int64_t k = 0; k < 500; ++k) {
    for (std::int64_t sub : {std::int64_t{0}, kMs, 2 * kMs - 1}) {
      if (k == 499 && sub > 0) break;
      ASSERT_EQ((*fast)->poll(t0 + 2 * k * kMs + sub), dm::DeviceStatus::Ok) << k;
      dm::ControllerState want = states[k];
      want.timeNs = t0 + 2 * k * kMs;
      ASSERT_TRUE(sameController((*fast)->state(), want)) << k << " +" << sub;
    }
  }
  EXPECT_EQ((*fast)->poll(t0 + 2 * 499 * kMs + 1), dm::DeviceStatus::Lost);

  // Looped: period 500 · 4 ms; timestamps keep increasing.
  auto looped = dm::Controller::open(d.registry, "replay-controller", {{"file", file}, {"loop", "1"}});
  ASSERT_TRUE(looped.ok());
  for (std::int64_t k = 0; k < 1300; ++k) {
    ASSERT_EQ((*looped)->poll(t0 + k * 4 * kMs), dm::DeviceStatus::Ok) << k;
    dm::ControllerState want = states[k % 500];
    want.timeNs = t0 + k * 4 * kMs;
    ASSERT_TRUE(sameController((*looped)->state(), want)) << k;
  }
}

TEST(ReplayDaq, PlaysFramesIndicesAndOverrunsExactly) {
  dm::test::BuiltinDrivers d;
  dm::test::TempDir dir("replay_daq");
  const DaqStream rec = recordDaq(d.registry, dir / "daq.dmrec");
  ASSERT_EQ(rec.frames.size(), 1001u - 36u);
  const std::string file = (dir / "daq.dmrec").string();

  for (const double rate : {1.0, 2.0}) {
    const std::int64_t t0 = rate == 1.0 ? 0 : 3000 * kMs;
    auto daq = dm::Daq::open(d.registry, "replay-daq", {{"file", file}, {"rate", rate == 1.0 ? "1" : "2"}});
    ASSERT_TRUE(daq.ok()) << daq.error().message();
    EXPECT_EQ((*daq)->info().identity.driver, "replay-daq");
    EXPECT_EQ((*daq)->info().channelCount, 3u);
    EXPECT_NEAR((*daq)->info().sampleRateHz, 1000.0 * rate, 1e-6);
    std::vector<dm::DaqFrame> got;
    std::uint64_t overrun = 0;
    std::array<dm::DaqFrame, 512> buf;
    dm::DeviceStatus status = dm::DeviceStatus::Ok;
    std::int64_t t = t0;
    for (; t < t0 + 2000 * kMs && status == dm::DeviceStatus::Ok; t += 7 * kMs) {
      status = (*daq)->acquire(t);
      const dm::DaqReadResult r = (*daq)->read(buf);
      for (std::size_t i = 0; i < r.frames; ++i) EXPECT_LE(buf[i].timeNs, t);  // acquired up to now
      got.insert(got.end(), buf.begin(), buf.begin() + static_cast<std::ptrdiff_t>(r.frames));
      overrun += r.overrunFrames;
    }
    // The stream ends after its last frame (1 s of recording: 0.5 s at rate 2).
    EXPECT_EQ(status, dm::DeviceStatus::Lost);
    EXPECT_LE(t - t0, static_cast<std::int64_t>(1000 * kMs / rate) + 3 * 7 * kMs);
    dm::DeviceEvent e;
    ASSERT_TRUE((*daq)->pollEvent(e));
    EXPECT_EQ(e.type, dm::DeviceEventType::Lost);
    EXPECT_EQ(overrun, rec.overrun) << rate;
    ASSERT_EQ(got.size(), rec.frames.size()) << rate;
    for (std::size_t i = 0; i < got.size(); ++i) {
      dm::DaqFrame want = rec.frames[i];
      want.timeNs = t0 + static_cast<std::int64_t>(static_cast<double>(want.timeNs) / rate);  // ms: exact
      ASSERT_TRUE(sameDaq(got[i], want)) << rate << " frame " << i;
    }
  }

  // Looping continues the indices: cycle c adds c · (index span + 1).
  auto looped = dm::Daq::open(d.registry, "replay-daq", {{"file", file}, {"loop", "1"}});
  ASSERT_TRUE(looped.ok());
  std::vector<dm::DaqFrame> got;
  std::array<dm::DaqFrame, 512> buf;
  for (std::int64_t t = 0; t <= 2500 * kMs; t += 10 * kMs) {
    ASSERT_EQ((*looped)->acquire(t), dm::DeviceStatus::Ok);
    const dm::DaqReadResult r = (*looped)->read(buf);
    got.insert(got.end(), buf.begin(), buf.begin() + static_cast<std::ptrdiff_t>(r.frames));
  }
  ASSERT_GT(got.size(), 2 * rec.frames.size());
  for (std::size_t i = 0; i < got.size(); ++i) {
    const std::size_t c = i / rec.frames.size();
    dm::DaqFrame want = rec.frames[i % rec.frames.size()];
    want.timeNs += static_cast<std::int64_t>(c) * 1001 * kMs;  // period: span + one frame interval
    want.index += c * 1001;
    ASSERT_TRUE(sameDaq(got[i], want)) << i;
  }
}

TEST(ReplaySensor, PlaysExactlyAtTheRecordedAndAScaledRate) {
  dm::test::BuiltinDrivers d;
  dm::test::TempDir dir("replay_sensor");
  const auto readings = recordSensor(d.registry, dir / "ft.dmrec");
  ASSERT_EQ(readings.size(), 300u);
  const std::string file = (dir / "ft.dmrec").string();
  auto ft = dm::Sensor::open(d.registry, "replay-sensor", {{"file", file}, {"unit", "N"}});
  ASSERT_TRUE(ft.ok()) << ft.error().message();
  EXPECT_EQ((*ft)->info().type, dm::SensorReadingType::Vector);
  EXPECT_EQ((*ft)->info().unit, "N");
  EXPECT_NEAR((*ft)->info().rateHz, 1000.0, 1e-9);
  for (std::int64_t k = 0; k < 300; ++k) ASSERT_EQ((*ft)->poll(k * kMs), dm::DeviceStatus::Ok);
  dm::SensorReading r;
  for (std::size_t k = 0; k < 300; ++k) {
    ASSERT_TRUE((*ft)->popReading(r));
    ASSERT_TRUE(sameSensor(r, readings[k])) << k;
  }
  EXPECT_EQ((*ft)->poll(300 * kMs), dm::DeviceStatus::Lost);
  dm::DeviceEvent e;
  ASSERT_TRUE((*ft)->pollEvent(e));
  EXPECT_EQ(e.type, dm::DeviceEventType::Lost);

  // Half speed from host time 1 s: reading k plays at 1 s + 2k ms.
  auto slow = dm::Sensor::open(d.registry, "replay-sensor", {{"file", file}, {"rate", "0.5"}});
  ASSERT_TRUE(slow.ok());
  for (std::int64_t k = 0; k < 599; ++k) {  // the last reading plays at 1 s + 598 ms
    ASSERT_EQ((*slow)->poll(1000 * kMs + k * kMs), dm::DeviceStatus::Ok);
    dm::SensorReading want = readings[k / 2];
    want.timeNs = 1000 * kMs + (k / 2) * 2 * kMs;
    ASSERT_TRUE(sameSensor((*slow)->latest(), want)) << k;
  }
  auto tooLong =
      dm::Sensor::open(d.registry, "replay-sensor", {{"file", file}, {"unit", "0123456789abcdef"}});
  ASSERT_FALSE(tooLong.ok());
  EXPECT_TRUE(contains(tooLong.error().message(), "'unit'"));
}

TEST(StreamReplay, CutLastRecordReplaysTheCompleteOnesAndReportsTheCut) {
  dm::test::BuiltinDrivers d;
  dm::test::TempDir dir("replay_cut");
  const auto states = recordController(d.registry, dir / "pad.dmrec");
  const auto readings = recordSensor(d.registry, dir / "ft.dmrec");
  ASSERT_EQ(states.size(), 500u);

  const auto pad = readBytes(dir / "pad.dmrec");
  writeBytes(dir / "cut.dmrec", pad, pad.size() - 30);  // the last record lacks 30 bytes
  const std::size_t cutAt = pad.size() - (20 + 64);
  auto c = dm::Controller::open(d.registry, "replay-controller", {{"file", (dir / "cut.dmrec").string()}});
  ASSERT_TRUE(c.ok()) << c.error().message();
  EXPECT_EQ((*c)->info().identity.model,
            "recorded controller stream; tail cut at byte " + std::to_string(cutAt));
  EXPECT_EQ((*c)->info().identity.serial, "499-records");
  for (std::int64_t k = 0; k < 499; ++k) {
    ASSERT_EQ((*c)->poll(k * 4 * kMs), dm::DeviceStatus::Ok);
    ASSERT_TRUE(sameController((*c)->state(), states[k])) << k;
  }
  EXPECT_EQ((*c)->poll(499 * 4 * kMs), dm::DeviceStatus::Lost);  // the cut record is not played
  auto strict = dm::Controller::open(d.registry, "replay-controller",
                                     {{"file", (dir / "cut.dmrec").string()}, {"strict", "1"}});
  ASSERT_FALSE(strict.ok());
  EXPECT_TRUE(contains(strict.error().message(), "cut.dmrec")) << strict.error().message();
  EXPECT_TRUE(contains(strict.error().message(), "at byte " + std::to_string(cutAt)))
      << strict.error().message();

  const auto ft = readBytes(dir / "ft.dmrec");
  writeBytes(dir / "ftcut.dmrec", ft, ft.size() - 1);
  auto s = dm::Sensor::open(d.registry, "replay-sensor", {{"file", (dir / "ftcut.dmrec").string()}});
  ASSERT_TRUE(s.ok()) << s.error().message();
  EXPECT_TRUE(contains((*s)->info().identity.model, "tail cut at byte " + std::to_string(ft.size() - 84)));
  for (std::int64_t k = 0; k < 299; ++k) {
    ASSERT_EQ((*s)->poll(k * kMs), dm::DeviceStatus::Ok);
    ASSERT_TRUE(sameSensor((*s)->latest(), readings[k])) << k;
  }
}

TEST(StreamReplay, KilledWriterAtAnyByteLeavesEveryCompleteRecordDecodable) {
  // Each record is one write(2) on an O_APPEND file, so a killed writer
  // leaves a prefix of the file; every prefix must decode to the complete
  // records before the cut, each equal to what was pushed.
  dm::test::TempDir dir("stream_prefix");
  auto rec = dm::DeviceRecorder::create(dir / "mix.dmrec", {.metadata = "mix"});
  ASSERT_TRUE(rec.ok());
  dm::ControllerState cs;
  cs.timeNs = 5;
  cs.axes = {0.1, 0.2, -0.3, 0.4, -1.0, 1.0};
  cs.buttons.set(3);
  cs.buttons.set(127);
  dm::SensorReading sr;
  sr.timeNs = 6;
  sr.type = dm::SensorReadingType::Pose;
  sr.values = {1, 2, 3, 1, 0, 0, 0};
  std::array<dm::DaqFrame, 3> frames{};
  for (std::size_t i = 0; i < frames.size(); ++i) {
    frames[i].timeNs = 7 + static_cast<std::int64_t>(i);
    frames[i].index = 40 + i;
    frames[i].values[0] = 0.5 * static_cast<double>(i);
    frames[i].values[1] = -2.0;
  }
  ASSERT_TRUE((*rec)->pushControllerState(cs));
  ASSERT_EQ((*rec)->pushDaqFrames(frames, 2, 9), 3u);
  ASSERT_TRUE((*rec)->pushSensorReading(sr));
  ASSERT_TRUE((*rec)->close().ok());
  const auto bytes = readBytes(dir / "mix.dmrec");
  const std::size_t header = 12 + 3;
  const std::size_t ends[3] = {header + 84, header + 84 + 20 + 16 + 3 * 32, header + 84 + 132 + 84};
  ASSERT_EQ(bytes.size(), ends[2]);
  for (std::size_t cut = 0; cut <= bytes.size(); ++cut) {
    auto r = dm::parseRecording(std::span(bytes.data(), cut), "prefix");
    if (cut < header) {
      ASSERT_FALSE(r.ok()) << cut;
      continue;
    }
    ASSERT_TRUE(r.ok()) << cut;
    const std::size_t complete = (cut >= ends[0]) + (cut >= ends[1]) + (cut >= ends[2]);
    ASSERT_EQ(r->records.size(), complete) << cut;
    EXPECT_EQ(r->tail.empty(), cut == header || cut == ends[0] || cut == ends[1] || cut == ends[2]) << cut;
    if (complete >= 1) {
      auto c = dm::decodeControllerState(r->records[0]);
      ASSERT_TRUE(c.ok() && sameController(*c, cs));
    }
    if (complete >= 2) {
      auto b = dm::decodeDaqBlock(r->records[1]);
      ASSERT_TRUE(b.ok());
      EXPECT_EQ(r->records[1].timeNs, 7);
      EXPECT_EQ(b->channelCount, 2u);
      EXPECT_EQ(b->overrunFrames, 9u);
      ASSERT_EQ(b->frames.size(), 3u);
      for (std::size_t i = 0; i < 3; ++i) ASSERT_TRUE(sameDaq(b->frames[i], frames[i]));
    }
    if (complete == 3) {
      auto s = dm::decodeSensorReading(r->records[2]);
      ASSERT_TRUE(s.ok() && sameSensor(*s, sr));
    }
  }
}

TEST(StreamReplay, BadFilesAreClearErrors) {
  dm::test::BuiltinDrivers d;
  dm::test::TempDir dir("replay_bad");
  recordController(d.registry, dir / "pad.dmrec");
  auto bytes = readBytes(dir / "pad.dmrec");

  auto magic = bytes;
  magic[3] = 'X';
  writeBytes(dir / "magic.dmrec", magic, magic.size());
  const auto openError = [&](const std::string& driver, const dm::DeviceParams& params) -> std::string {
    if (driver == "replay-controller") {
      auto r = dm::Controller::open(d.registry, driver, params);
      return r.ok() ? "opened" : r.error().message();
    }
    if (driver == "replay-daq") {
      auto r = dm::Daq::open(d.registry, driver, params);
      return r.ok() ? "opened" : r.error().message();
    }
    auto r = dm::Sensor::open(d.registry, driver, params);
    return r.ok() ? "opened" : r.error().message();
  };
  for (const char* driver : {"replay-controller", "replay-daq", "replay-sensor"}) {
    const std::string msg = openError(driver, {{"file", (dir / "magic.dmrec").string()}});
    EXPECT_TRUE(contains(msg, "magic.dmrec") && contains(msg, "bad magic at byte 0"))
        << driver << ": " << msg;
  }
  auto meta = bytes;
  meta[11] = 0x7F;  // metadata length far past the end
  writeBytes(dir / "meta.dmrec", meta, meta.size());
  auto m = dm::Controller::open(d.registry, "replay-controller", {{"file", (dir / "meta.dmrec").string()}});
  ASSERT_FALSE(m.ok());
  EXPECT_TRUE(contains(m.error().message(), "meta.dmrec") && contains(m.error().message(), "at byte 8"))
      << m.error().message();

  // A controller recording holds no DAQ blocks or sensor readings.
  auto noDaq = dm::Daq::open(d.registry, "replay-daq", {{"file", (dir / "pad.dmrec").string()}});
  ASSERT_FALSE(noDaq.ok());
  EXPECT_TRUE(contains(noDaq.error().message(), "no DAQ-block records")) << noDaq.error().message();

  // A valid record (CRC and all) with an axis outside [-1, 1].
  {
    auto rec = dm::DeviceRecorder::create(dir / "axis.dmrec");
    ASSERT_TRUE(rec.ok());
    ASSERT_TRUE((*rec)->append(kControllerType, 0, std::vector<std::byte>(64)).ok());
    std::vector<std::byte> bad(64);
    const double two = 2.0;
    std::memcpy(bad.data() + 16, &two, 8);
    ASSERT_TRUE((*rec)->append(kControllerType, 4, bad).ok());
    ASSERT_TRUE((*rec)->close().ok());
  }
  auto axis =
      dm::Controller::open(d.registry, "replay-controller", {{"file", (dir / "axis.dmrec").string()}});
  ASSERT_FALSE(axis.ok());
  const std::string msg = axis.error().message();
  EXPECT_TRUE(contains(msg, "axis.dmrec") && contains(msg, "record 1 at byte 96") && contains(msg, "axis 2"))
      << msg;
  auto missing = dm::Sensor::open(d.registry, "replay-sensor", {{"file", (dir / "none.dmrec").string()}});
  ASSERT_FALSE(missing.ok());
  EXPECT_TRUE(contains(missing.error().message(), "none.dmrec"));
}

TEST(StreamReplay, PluginsReplayLikeTheBuiltInDrivers) {
  dm::test::BuiltinDrivers d;
  dm::test::TempDir dir("replay_plugins");
  const auto states = recordController(d.registry, dir / "pad.dmrec");
  const auto readings = recordSensor(d.registry, dir / "ft.dmrec");
  const DaqStream rec = recordDaq(d.registry, dir / "daq.dmrec");

  dm::test::PluginDriver pc("replay_controller", "replay-controller");
  ASSERT_TRUE(pc.loaded);
  auto c = dm::Controller::open(pc.registry, "replay-controller", {{"file", (dir / "pad.dmrec").string()}});
  ASSERT_TRUE(c.ok()) << c.error().message();
  ASSERT_EQ((*c)->poll(100 * 4 * kMs), dm::DeviceStatus::Ok);  // first poll: host 0.4 s ↔ recorded 0
  EXPECT_EQ((*c)->state().axes, states[0].axes);
  ASSERT_EQ((*c)->poll(110 * 4 * kMs), dm::DeviceStatus::Ok);
  EXPECT_EQ((*c)->state().axes, states[10].axes);

  dm::test::PluginDriver ps("replay_sensor", "replay-sensor");
  ASSERT_TRUE(ps.loaded);
  auto s = dm::Sensor::open(ps.registry, "replay-sensor", {{"file", (dir / "ft.dmrec").string()}});
  ASSERT_TRUE(s.ok()) << s.error().message();
  ASSERT_EQ((*s)->poll(0), dm::DeviceStatus::Ok);
  ASSERT_EQ((*s)->poll(42 * kMs), dm::DeviceStatus::Ok);
  EXPECT_TRUE(sameSensor((*s)->latest(), readings[42]));

  dm::test::PluginDriver pd("replay_daq", "replay-daq");
  ASSERT_TRUE(pd.loaded);
  auto q = dm::Daq::open(pd.registry, "replay-daq", {{"file", (dir / "daq.dmrec").string()}});
  ASSERT_TRUE(q.ok()) << q.error().message();
  ASSERT_EQ((*q)->acquire(100 * kMs), dm::DeviceStatus::Ok);
  std::array<dm::DaqFrame, 256> buf;
  const auto got = (*q)->read(buf);
  ASSERT_EQ(got.frames, 1u);  // only frame 0 is due at the start
  EXPECT_TRUE(sameDaq(buf[0], dm::DaqFrame{100 * kMs, rec.frames[0].index, rec.frames[0].values}));
}

}  // namespace
