// DeviceRecorder and the replay-haptic driver: round trip, a writer killed
// with SIGKILL mid-stream (the test binary re-runs itself as the recording
// child), truncated and corrupted files, and replay at the recorded and a
// doubled rate.
#include <dm/io/drivers.hpp>
#include <dm/io/recorder.hpp>

#include <gtest/gtest.h>

#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <thread>

#include "../common/temp_dir.hpp"
#include "driver_test_support.hpp"

extern char** environ;

namespace {

using dm::Vec3;
namespace fs = std::filesystem;
using dm::test::kMs;

struct Drivers {
  dm::FactoryRegistry registry;
  dm::PluginLinker linker{registry};
  Drivers() { EXPECT_TRUE(dm::registerBuiltinDrivers(linker).ok()); }
};

// States of a sim-haptic circle at 1 kHz (radius 5 cm).
std::vector<dm::HapticState> circleStates(const dm::FactoryRegistry& reg, int n) {
  auto dev = dm::HapticDevice::open(reg, "sim-haptic", {{"path", "circle"}, {"radius", "0.05"}});
  EXPECT_TRUE(dev.ok());
  std::vector<dm::HapticState> out;
  for (int k = 0; k < n && dev.ok(); ++k) {
    (*dev)->servo(k * kMs);
    out.push_back((*dev)->state());
  }
  return out;
}

bool sameState(const dm::HapticState& a, const dm::HapticState& b) {
  return a.timeNs == b.timeNs && a.position == b.position &&
         a.orientation.coeffs() == b.orientation.coeffs() && a.linearVelocity == b.linearVelocity &&
         a.angularVelocity == b.angularVelocity && a.buttons == b.buttons;
}

TEST(Recorder, RoundTripKeepsEveryStateBitForBit) {
  Drivers d;
  dm::test::TempDir dir("recorder_roundtrip");
  const auto states = circleStates(d.registry, 3000);
  auto rec = dm::DeviceRecorder::create(dir / "a.dmrec", {.metadata = R"({"device":"stylus"})"});
  ASSERT_TRUE(rec.ok()) << rec.error().message();
  for (const auto& s : states) {
    while (!(*rec)->pushHapticState(s)) std::this_thread::yield();  // the queue holds 8192: no wait here
  }
  const std::byte note[3] = {std::byte{1}, std::byte{2}, std::byte{3}};
  ASSERT_TRUE((*rec)->close().ok());
  EXPECT_EQ((*rec)->written(), states.size());
  EXPECT_EQ((*rec)->dropped(), 0u);
  EXPECT_FALSE((*rec)->append(1000, 0, note).ok());  // closed

  auto back = dm::readRecording(dir / "a.dmrec");
  ASSERT_TRUE(back.ok()) << back.error().message();
  // The byte budget: a recording over it is refused from its size.
  const auto size = fs::file_size(dir / "a.dmrec");
  auto over = dm::readRecording(dir / "a.dmrec", size - 1);
  ASSERT_FALSE(over.ok());
  EXPECT_NE(over.error().what.find("file is " + std::to_string(size) + " bytes, more than the limit of " +
                                   std::to_string(size - 1) + " bytes"),
            std::string::npos)
      << over.error();
  EXPECT_TRUE(dm::readRecording(dir / "a.dmrec", size).ok());
  EXPECT_EQ(back->metadata, R"({"device":"stylus"})");
  EXPECT_EQ(back->tail, "");
  ASSERT_EQ(back->records.size(), states.size());
  for (std::size_t i = 0; i < states.size(); ++i) {
    auto s = dm::decodeHapticState(back->records[i]);
    ASSERT_TRUE(s.ok());
    ASSERT_TRUE(sameState(*s, states[i])) << i;
  }
  // Refuses to overwrite unless asked.
  auto again = dm::DeviceRecorder::create(dir / "a.dmrec");
  ASSERT_FALSE(again.ok());
  EXPECT_NE(again.error().message().find("a.dmrec"), std::string::npos);
}

TEST(Recorder, SynchronousAppendAndUserRecords) {
  dm::test::TempDir dir("recorder_append");
  auto rec = dm::DeviceRecorder::create(dir / "b.dmrec");
  ASSERT_TRUE(rec.ok());
  std::vector<std::byte> big(100000, std::byte{7});
  ASSERT_TRUE((*rec)->append(1000, 5, big).ok());  // larger than a queue slot: append only
  EXPECT_FALSE((*rec)->push(1000, 6, big));
  EXPECT_EQ((*rec)->dropped(), 1u);
  ASSERT_TRUE((*rec)->close().ok());
  auto back = dm::readRecording(dir / "b.dmrec");
  ASSERT_TRUE(back.ok());
  ASSERT_EQ(back->records.size(), 1u);
  EXPECT_EQ(back->records[0].payload, big);
  EXPECT_FALSE(dm::decodeHapticState(back->records[0]).ok());
}

// The child side of KilledWriterLeavesEveryCompleteRecord: records forever.
TEST(RecorderCrash, ChildWriter) {
  const char* file = std::getenv("DM_RECORDER_CHILD_FILE");
  if (!file) GTEST_SKIP() << "runs only as the child of RecorderCrash.KilledWriterLeavesEveryCompleteRecord";
  Drivers d;
  auto dev = dm::HapticDevice::open(d.registry, "sim-haptic", {{"path", "circle"}, {"radius", "0.05"}});
  auto rec = dm::DeviceRecorder::create(file, {.overwrite = true});
  if (!dev.ok() || !rec.ok()) std::_Exit(3);
  std::vector<std::byte> blob(3000, std::byte{0x5A});
  for (std::int64_t k = 0;; ++k) {
    (*dev)->servo(k * kMs);
    (*rec)->pushHapticState((*dev)->state());
    if (k % 50 == 0) (void)(*rec)->append(1000, k * kMs, blob);  // large synchronous records too
    if (k % 20 == 0) std::this_thread::sleep_for(std::chrono::microseconds(200));
  }
}

TEST(RecorderCrash, KilledWriterLeavesEveryCompleteRecord) {
  dm::test::TempDir dir("recorder_crash");
  const std::string file = (dir / "killed.dmrec").string();
  const std::string envFile = "DM_RECORDER_CHILD_FILE=" + file;
  std::vector<char*> env;
  for (char** e = environ; *e; ++e) env.push_back(*e);
  env.push_back(const_cast<char*>(envFile.c_str()));
  env.push_back(nullptr);
  std::string self = fs::read_symlink("/proc/self/exe").string();
  std::string filter = "--gtest_filter=RecorderCrash.ChildWriter";
  char* argv[] = {self.data(), filter.data(), nullptr};
  pid_t pid = -1;
  ASSERT_EQ(posix_spawn(&pid, self.c_str(), nullptr, nullptr, argv, env.data()), 0);
  // Let it write at least 200 kB, then kill it mid-stream.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  std::error_code ec;
  while (std::chrono::steady_clock::now() < deadline && (fs::file_size(file, ec) < 200000 || ec))
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  kill(pid, SIGKILL);
  int status = 0;
  waitpid(pid, &status, 0);
  ASSERT_TRUE(WIFSIGNALED(status)) << "the child exited with " << WEXITSTATUS(status);

  auto back = dm::readRecording(file);
  ASSERT_TRUE(back.ok()) << back.error().message();
  ASSERT_GT(back->records.size(), 100u);
  // Every complete record is intact: states on the circle at consecutive milliseconds.
  std::int64_t next = 0;
  std::size_t states = 0;
  for (const auto& r : back->records) {
    if (r.type == 1000) {
      EXPECT_EQ(r.payload.size(), 3000u);
      continue;
    }
    auto s = dm::decodeHapticState(r);
    ASSERT_TRUE(s.ok());
    ASSERT_EQ(s->timeNs, next);
    ASSERT_NEAR(s->position.norm(), 0.05, 1e-12);
    next += kMs;
    ++states;
  }
  EXPECT_GT(states, 50u);

  // Replay plays back every complete state record.
  Drivers d;
  auto replay = dm::HapticDevice::open(d.registry, "replay-haptic", {{"file", file}});
  ASSERT_TRUE(replay.ok()) << replay.error().message();
  for (std::int64_t k = 0; k < static_cast<std::int64_t>(states); ++k) {
    (*replay)->servo(k * kMs);
    ASSERT_NEAR((*replay)->state().position.norm(), 0.05, 1e-12) << k;
  }
}

TEST(Recorder, TruncatedAndCorruptFilesKeepTheirCompleteRecords) {
  Drivers d;
  dm::test::TempDir dir("recorder_damaged");
  const auto states = circleStates(d.registry, 50);
  {
    auto rec = dm::DeviceRecorder::create(dir / "c.dmrec", {.metadata = "m"});
    ASSERT_TRUE(rec.ok());
    for (const auto& s : states) ASSERT_TRUE((*rec)->pushHapticState(s));
    ASSERT_TRUE((*rec)->close().ok());
  }
  std::ifstream in(dir / "c.dmrec", std::ios::binary);
  std::vector<std::uint8_t> bytes((std::istreambuf_iterator<char>(in)), {});
  const std::size_t header = 12 + 1, record = 20 + 108;
  ASSERT_EQ(bytes.size(), header + states.size() * record);
  for (std::size_t cut = header; cut <= bytes.size(); cut += 37) {
    auto r = dm::parseRecording(std::span(bytes.data(), cut), "cut");
    ASSERT_TRUE(r.ok());
    EXPECT_EQ(r->records.size(), (cut - header) / record) << cut;
    EXPECT_EQ(r->validBytes, header + r->records.size() * record);
    EXPECT_EQ(r->tail.empty(), (cut - header) % record == 0) << r->tail;
  }
  auto flipped = bytes;
  flipped[header + 7 * record + 40] ^= 0x10;  // inside record 7's payload
  auto r = dm::parseRecording(flipped, "flipped");
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->records.size(), 7u);
  EXPECT_NE(r->tail.find("CRC mismatch in the record at byte " + std::to_string(header + 7 * record)),
            std::string::npos)
      << r->tail;
  auto bad = dm::parseRecording(std::span(bytes.data() + 1, bytes.size() - 1), "shifted.dmrec");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().message().find("shifted.dmrec"), std::string::npos);
  EXPECT_NE(bad.error().message().find("byte 0"), std::string::npos);
  EXPECT_FALSE(dm::readRecording(dir / "missing.dmrec").ok());
}

TEST(ReplayHaptic, PlaysAtTheRecordedAndAScaledRate) {
  Drivers d;
  dm::test::TempDir dir("replay_rate");
  const auto states = circleStates(d.registry, 1000);
  {
    auto rec = dm::DeviceRecorder::create(dir / "r.dmrec");
    ASSERT_TRUE(rec.ok());
    for (const auto& s : states) ASSERT_TRUE((*rec)->pushHapticState(s));
    ASSERT_TRUE((*rec)->close().ok());
  }
  const std::string file = (dir / "r.dmrec").string();
  auto same = dm::HapticDevice::open(d.registry, "replay-haptic", {{"file", file}});
  auto fast = dm::HapticDevice::open(d.registry, "replay-haptic", {{"file", file}, {"rate", "2"}});
  auto looped = dm::HapticDevice::open(d.registry, "replay-haptic", {{"file", file}, {"loop", "1"}});
  ASSERT_TRUE(same.ok() && fast.ok() && looped.ok());
  const std::int64_t t0 = 5'000 * kMs;  // host time need not match recorded time
  for (std::int64_t k = 0; k < 1500; ++k) {
    (*same)->servo(t0 + k * kMs);
    (*fast)->servo(t0 + k * kMs);
    (*looped)->servo(t0 + k * kMs);
    EXPECT_EQ((*same)->state().position, states[std::min<std::int64_t>(k, 999)].position) << k;
    EXPECT_EQ((*fast)->state().position, states[std::min<std::int64_t>(2 * k, 999)].position) << k;
    EXPECT_EQ((*looped)->state().position, states[k % 1000].position) << k;
  }
  auto missing =
      dm::HapticDevice::open(d.registry, "replay-haptic", {{"file", (dir / "none.dmrec").string()}});
  ASSERT_FALSE(missing.ok());
  EXPECT_NE(missing.error().message().find("none.dmrec"), std::string::npos);
  auto noFile = dm::HapticDevice::open(d.registry, "replay-haptic", {{"rate", "2"}});
  ASSERT_FALSE(noFile.ok());
  EXPECT_NE(noFile.error().message().find("'file'"), std::string::npos);
}

}  // namespace
