// The master engine in lockstep: multi-rate tick order, bit-identical reruns,
// life-cycle errors (load failure named by engine, tick failure → Error,
// illegal calls refused), shutdown of every loaded engine.
#include <dm/engine/master_engine.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <string>
#include <vector>

namespace dm {
namespace {

struct Event {
  std::string engine;
  std::int64_t ns;
  bool operator==(const Event&) const = default;
};

class Recorder final : public Engine {
 public:
  Recorder(std::string name, std::vector<Event>& log) : name_(std::move(name)), log_(log) {}
  std::string_view name() const noexcept override { return name_; }
  Status load() override {
    ++loads;
    if (failLoad) return fail(ErrorCode::NotFound, "mesh.obj missing", "objects/0");
    return ok();
  }
  bool tick(const TickInfo& t) noexcept override {
    log_.push_back({name_, t.scheduled_ns});
    return t.index + 1 != failAtTick;
  }
  Status shutdown() override {
    ++shutdowns;
    return ok();
  }
  Error error() const override { return fail(ErrorCode::Device, "device lost", "haptic-device"); }
  bool failLoad = false;
  std::uint64_t failAtTick = 0;  // 1-based; 0 = never
  int loads = 0, shutdowns = 0;

 private:
  std::string name_;
  std::vector<Event>& log_;
};

TEST(MasterEngine, LockstepInterleavesRatesByTimeThenOrder) {
  std::vector<Event> log;
  MasterEngine m;
  ASSERT_TRUE(m.addEngine(std::make_shared<Recorder>("haptics", log), {.rateHz = 1000}).ok());
  ASSERT_TRUE(m.addEngine(std::make_shared<Recorder>("physics", log), {.rateHz = 250}).ok());
  ASSERT_TRUE(m.load("test").ok());
  ASSERT_TRUE(m.start(RunMode::Lockstep).ok());
  ASSERT_TRUE(m.advance(0.01).ok());
  EXPECT_EQ(m.virtualClock().now(), 10'000'000);
  // 10 haptic ticks at 0..9 ms, 3 physics ticks at 0, 4, 8 ms, each after the haptic tick of its time.
  std::vector<Event> expected;
  for (int ms = 0; ms < 10; ++ms) {
    expected.push_back({"haptics", ms * 1'000'000});
    if (ms % 4 == 0) expected.push_back({"physics", ms * 1'000'000});
  }
  EXPECT_EQ(log, expected);
  // Advancing in pieces gives the same schedule as in one go.
  ASSERT_TRUE(m.advance(0.0025).ok());
  ASSERT_TRUE(m.advance(0.0075).ok());
  const auto stats = m.stats();
  ASSERT_EQ(stats.size(), 2u);
  EXPECT_EQ(stats[0].ticks, 20u);
  EXPECT_EQ(stats[1].ticks, 5u);
  EXPECT_NEAR(stats[0].achievedHz, 1000.0, 1e-9);
  EXPECT_NEAR(stats[1].achievedHz, 250.0, 1e-9);
  ASSERT_TRUE(m.stop("done").ok());
  EXPECT_EQ(m.state(), SimState::Stopped);
}

TEST(MasterEngine, LockstepRunsAreBitIdentical) {
  // A damped oscillator integrated at 1 kHz reading a controller that changes its
  // set point at 30 Hz: the result depends on the interleaving, which must repeat exactly.
  const auto run = [] {
    double x = 0, v = 0, target = 0;
    MasterEngine m;
    EXPECT_TRUE(m.addEngine(makeFunctionEngine("sim",
                                               [&](const TickInfo& t) {
                                                 const double a = 400.0 * (target - x) - 4.0 * v;
                                                 v += a * t.dt();
                                                 x += v * t.dt();
                                                 return true;
                                               }),
                            {.rateHz = 1000})
                    .ok());
    EXPECT_TRUE(m.addEngine(makeFunctionEngine("controller",
                                               [&](const TickInfo& t) {
                                                 target = std::sin(1e-9 *
                                                                   static_cast<double>(t.scheduled_ns) * 7.0);
                                                 return true;
                                               }),
                            {.rateHz = 30})
                    .ok());
    EXPECT_TRUE(m.load().ok());
    EXPECT_TRUE(m.start(RunMode::Lockstep).ok());
    EXPECT_TRUE(m.advance(1.5).ok());
    return x;
  };
  const double a = run(), b = run();
  EXPECT_EQ(std::memcmp(&a, &b, sizeof a), 0);
  EXPECT_NE(a, 0.0);
}

TEST(MasterEngine, LoadFailureNamesTheEngineAndShutsDownTheLoadedOnes) {
  std::vector<Event> log;
  auto first = std::make_shared<Recorder>("physics", log);
  auto second = std::make_shared<Recorder>("renderer", log);
  second->failLoad = true;
  MasterEngine m;
  ASSERT_TRUE(m.addEngine(first, {.rateHz = 100}).ok());
  ASSERT_TRUE(m.addEngine(second, {.rateHz = 30}).ok());
  const Status s = m.load();
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().code, ErrorCode::NotFound);
  EXPECT_NE(s.error().where.find("renderer"), std::string::npos) << s.error().message();
  EXPECT_EQ(m.state(), SimState::Error);
  EXPECT_FALSE(m.start(RunMode::Lockstep).ok());  // Error -> Running is illegal
  ASSERT_TRUE(m.stop().ok());
  EXPECT_EQ(first->shutdowns, 1);
  EXPECT_EQ(second->shutdowns, 0);  // never loaded
}

TEST(MasterEngine, TickFailureEntersErrorWithTheEngineError) {
  std::vector<Event> log;
  auto haptics = std::make_shared<Recorder>("haptics", log);
  haptics->failAtTick = 5;
  MasterEngine m;
  std::vector<SimState> seen;
  m.onTransition([&](const Transition& t) { seen.push_back(t.to); });
  ASSERT_TRUE(m.addEngine(haptics, {.rateHz = 1000}).ok());
  ASSERT_TRUE(m.load().ok());
  ASSERT_TRUE(m.start(RunMode::Lockstep).ok());
  const Status s = m.advance(1.0);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().code, ErrorCode::Device);
  EXPECT_EQ(log.size(), 5u);  // stopped at the failing tick
  EXPECT_EQ(m.state(), SimState::Error);
  EXPECT_EQ(m.lastError().what, "device lost");
  ASSERT_TRUE(m.stop().ok());
  EXPECT_EQ(haptics->shutdowns, 1);
  const std::vector<SimState> expected = {SimState::Loading, SimState::Ready,    SimState::Running,
                                          SimState::Error,   SimState::Stopping, SimState::Stopped};
  EXPECT_EQ(seen, expected);
}

TEST(MasterEngine, MisuseIsRefused) {
  std::vector<Event> log;
  MasterEngine m;
  EXPECT_FALSE(m.addEngine(nullptr, {}).ok());
  EXPECT_FALSE(m.addEngine(std::make_shared<Recorder>("a", log), {.rateHz = 0}).ok());
  ASSERT_TRUE(m.addEngine(std::make_shared<Recorder>("a", log), {.rateHz = 10}).ok());
  const Status dup = m.addEngine(std::make_shared<Recorder>("a", log), {.rateHz = 10});
  ASSERT_FALSE(dup.ok());
  EXPECT_NE(dup.error().what.find("already"), std::string::npos);
  EXPECT_FALSE(m.advance(1.0).ok());  // not running
  EXPECT_FALSE(m.pause().ok());
  ASSERT_TRUE(m.load().ok());
  EXPECT_FALSE(m.addEngine(std::make_shared<Recorder>("b", log), {}).ok());  // after Created
  ASSERT_TRUE(m.start(RunMode::Lockstep).ok());
  EXPECT_FALSE(m.advance(-1.0).ok());
  EXPECT_FALSE(m.advance(std::nan("")).ok());
  ASSERT_TRUE(m.pause().ok());
  EXPECT_FALSE(m.advance(0.1).ok());  // paused
  ASSERT_TRUE(m.resume().ok());
  EXPECT_TRUE(m.advance(0.1).ok());
  EXPECT_EQ(log.size(), 1u);  // 10 Hz: one tick at t = 0 in [0, 0.1)
}

}  // namespace
}  // namespace dm
