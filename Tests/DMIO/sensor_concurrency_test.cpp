// Sensor across threads: a poll thread reading sim-sensor (a tracker) while
// a consumer pops every reading and looks at the latest — run under
// ThreadSanitizer in CI. Readings arrive whole and in order, and each one
// is either popped or counted as dropped.
#include <dm/io/drivers.hpp>
#include <dm/io/sensor.hpp>

#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <thread>

namespace {

TEST(SensorThreads, PollAndConsumerConcurrently) {
  dm::FactoryRegistry registry;
  dm::PluginLinker linker(registry);
  ASSERT_TRUE(dm::registerBuiltinDrivers(linker).ok());
  auto opened = dm::Sensor::open(
      registry, "sim-sensor", {{"type", "tracker"}, {"x", "ramp,1,1"}, {"y", "ramp,1,1"}, {"axis", "0,0,1"}});
  ASSERT_TRUE(opened.ok()) << opened.error().message();
  dm::Sensor& tracker = **opened;

  constexpr std::int64_t kSteps = 50000;
  std::atomic<bool> done{false};
  std::thread poller([&] {
    for (std::int64_t k = 0; k < kSteps; ++k) tracker.poll(k * 1'000'000);
    done.store(true, std::memory_order_release);
  });
  auto whole = [](const dm::SensorReading& r) {
    const double t = 1e-9 * static_cast<double>(r.timeNs);
    const double ramp = 2 * (t - std::floor(t)) - 1;
    const dm::Quat q = r.quaternion();
    return r.values[0] == r.values[1] && std::abs(r.values[0] - ramp) < 1e-9 &&
           std::abs(q.w() - std::cos(0.5 * t)) < 1e-12 && std::abs(q.z() - std::sin(0.5 * t)) < 1e-12;
  };
  std::int64_t popped = 0, torn = 0, lastTime = -1, disorder = 0;
  for (;;) {
    const bool finished = done.load(std::memory_order_acquire);
    const dm::SensorReading& latest = tracker.latest();  // timeNs 0: the initial, empty reading
    if (latest.timeNs != 0 && !whole(latest)) ++torn;
    dm::SensorReading r;
    bool any = false;
    while (tracker.popReading(r)) {
      any = true;
      ++popped;
      if (!whole(r)) ++torn;
      if (r.timeNs <= lastTime) ++disorder;
      lastTime = r.timeNs;
    }
    if (finished && !any) break;
  }
  poller.join();
  EXPECT_EQ(torn, 0);
  EXPECT_EQ(disorder, 0);
  EXPECT_EQ(static_cast<std::uint64_t>(popped) + tracker.droppedReadings(),
            static_cast<std::uint64_t>(kSteps));
}

}  // namespace
