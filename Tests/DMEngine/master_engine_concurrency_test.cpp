// The master engine in real time: engines tick on their own threads at their
// rates, pause stops the ticks, a failing engine is noticed by poll() and the
// simulation ends in Error with that engine's error. Run under TSan in CI.
#include <dm/engine/master_engine.hpp>

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <thread>

namespace dm {
namespace {

using namespace std::chrono_literals;

TEST(MasterEngineRealTime, EnginesTickAtTheirRatesAndPauseStopsThem) {
  std::atomic<int> fast{0}, slow{0};
  MasterEngine m;
  ASSERT_TRUE(
      m.addEngine(makeFunctionEngine("fast", [&](const TickInfo&) { return ++fast, true; }), {.rateHz = 1000})
          .ok());
  ASSERT_TRUE(
      m.addEngine(makeFunctionEngine("slow", [&](const TickInfo&) { return ++slow, true; }), {.rateHz = 50})
          .ok());
  ASSERT_TRUE(m.load().ok());
  ASSERT_TRUE(m.start(RunMode::RealTime).ok());
  std::this_thread::sleep_for(300ms);
  ASSERT_TRUE(m.poll().ok());
  ASSERT_TRUE(m.pause().ok());
  const int fastAtPause = fast.load(), slowAtPause = slow.load();
  // Loose bounds: a loaded CI machine (or a sanitizer) slows the threads, never speeds them up.
  EXPECT_GT(fastAtPause, 30);
  EXPECT_LE(fastAtPause, 400);
  EXPECT_GE(slowAtPause, 2);
  EXPECT_LE(slowAtPause, 25);
  EXPECT_GT(fastAtPause, 3 * slowAtPause);
  std::this_thread::sleep_for(50ms);
  EXPECT_EQ(fast.load(), fastAtPause);  // paused: no ticks
  ASSERT_TRUE(m.resume().ok());
  std::this_thread::sleep_for(50ms);
  ASSERT_TRUE(m.stop("done").ok());
  EXPECT_GT(fast.load(), fastAtPause);
  const auto stats = m.stats();
  EXPECT_EQ(stats[0].ticks, static_cast<std::uint64_t>(fast.load()));
}

TEST(MasterEngineRealTime, FailingEngineIsNoticedByPoll) {
  std::atomic<int> n{0};
  MasterEngine m;
  ASSERT_TRUE(
      m.addEngine(makeFunctionEngine("flaky", [&](const TickInfo&) { return ++n < 20; }), {.rateHz = 1000})
          .ok());
  ASSERT_TRUE(m.load().ok());
  ASSERT_TRUE(m.start(RunMode::RealTime).ok());
  Status s = ok();
  for (int i = 0; i < 500 && s.ok(); ++i) {
    std::this_thread::sleep_for(2ms);
    s = m.poll();
  }
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(m.state(), SimState::Error);
  EXPECT_NE(s.error().where.find("flaky"), std::string::npos) << s.error().message();
  EXPECT_EQ(n.load(), 20);  // no tick after the failure
  ASSERT_TRUE(m.stop().ok());
}

}  // namespace
}  // namespace dm
