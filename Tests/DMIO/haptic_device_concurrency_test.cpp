// HapticDevice across threads as a simulator uses it: a servo thread, a
// haptic loop commanding forces (some of them NaN or far over the limit),
// and a consumer reading states and events — run under ThreadSanitizer in
// CI. Every output that reaches the device must be finite and within the
// limit, and every state the consumer sees must be a whole sample.
#include <dm/io/drivers.hpp>
#include <dm/io/haptic_device.hpp>

#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <thread>

namespace {

using dm::Vec3;

TEST(HapticDeviceThreads, ServoCommandAndConsumerConcurrently) {
  dm::FactoryRegistry registry;
  dm::PluginLinker linker(registry);
  ASSERT_TRUE(dm::registerBuiltinDrivers(linker).ok());
  auto opened = dm::HapticDevice::open(registry, "sim-haptic",
                                       {{"path", "circle"}, {"radius", "0.05"}, {"max_force", "3"}});
  ASSERT_TRUE(opened.ok()) << opened.error().message();
  dm::HapticDevice& dev = **opened;

  constexpr std::int64_t kSteps = 20000;
  std::atomic<std::int64_t> clock{0};  // servo publishes its time; the loop commands at that time
  std::atomic<bool> done{false};
  std::atomic<int> unsafe{0};
  std::atomic<bool> consumerReady{false};

  std::thread servo([&] {
    while (!consumerReady.load(std::memory_order_acquire)) std::this_thread::yield();
    for (std::int64_t k = 0; k < kSteps; ++k) {
      if (k % 64 == 0) std::this_thread::yield();  // let the consumer interleave on a small machine
      const std::int64_t t = k * 100'000;  // 10 kHz
      dev.servo(t);
      const dm::HapticOutput& out = dev.lastOutput();
      if (!out.force.allFinite() || out.force.norm() > 3.0 * (1 + 1e-12)) unsafe.fetch_add(1);
      clock.store(t, std::memory_order_release);
    }
    done.store(true, std::memory_order_release);
  });
  std::thread loop([&] {
    std::uint64_t i = 0;
    while (!done.load(std::memory_order_acquire)) {
      const double s = (i % 7 == 0) ? std::nan("") : (i % 5 == 0 ? 100.0 : 1.0);
      dev.command(Vec3(s, 0.5, -0.5), Vec3::Zero(), clock.load(std::memory_order_acquire));
      ++i;
      std::this_thread::yield();
    }
  });
  std::int64_t lastTime = 0, states = 0, torn = 0;  // time 0 is the empty state before the first sample
  consumerReady.store(true, std::memory_order_release);
  // One more read after the servo thread has finished, so a loaded machine
  // that never ran this thread in between still checks the last state.
  for (bool finished = false; !finished;) {
    finished = done.load(std::memory_order_acquire);
    const dm::HapticState& st = dev.state();
    if (st.timeNs > lastTime) {
      lastTime = st.timeNs;
      ++states;
      // A whole sample lies on the 5 cm circle (a torn one would not).
      if (std::abs(st.position.norm() - 0.05) > 1e-9) ++torn;
    }
    dm::DeviceEvent e;
    while (dev.pollEvent(e)) {
    }
  }
  servo.join();
  loop.join();
  EXPECT_EQ(unsafe.load(), 0);
  EXPECT_EQ(torn, 0);
  EXPECT_GT(states, 0);
  EXPECT_EQ(dev.counters().servoSteps, static_cast<std::uint64_t>(kSteps));
}

}  // namespace
