// ToolImpulseChannel across threads: a 1 kHz-style writer and a slower
// reader running at once; the impulses the reader takes add up exactly to
// what the writer put in (values chosen exactly representable, so the sums
// are exact), whatever the interleaving — nothing lost, nothing twice.
#include <dm/haptics/tool_impulse.hpp>

#include <gtest/gtest.h>

#include <array>
#include <atomic>
#include <thread>

TEST(ToolImpulseChannelConcurrency, TakenImpulsesAddUpToWhatWasGiven) {
  constexpr int kTicks = 200000;
  dm::ToolImpulseChannel c(2);
  std::atomic<bool> done{false};
  std::thread writer([&] {
    for (int i = 0; i < kTicks; ++i) {
      c.add(static_cast<std::size_t>(i % 2), dm::Vec3(1.0, -2.0, 0.5), dm::Vec3(0.25, 0, 0), 0.125);
      c.publish();
    }
    done.store(true, std::memory_order_release);
  });
  dm::Vec3 sum[2] = {dm::Vec3::Zero(), dm::Vec3::Zero()};
  std::array<dm::ToolImpulse, 2> out;
  int takes = 0;
  const auto takeInto = [&] {
    if (!c.take(out)) return;
    ++takes;
    for (std::size_t k = 0; k < 2; ++k) sum[k] += out[k].linear;
  };
  while (!done.load(std::memory_order_acquire)) takeInto();
  takeInto();  // every publish happened before `done`: this take sees the last totals
  writer.join();
  for (int k = 0; k < 2; ++k) {
    EXPECT_EQ(sum[k], dm::Vec3(1.0, -2.0, 0.5) * (0.125 * kTicks / 2)) << k;
    EXPECT_EQ(c.taken(static_cast<std::size_t>(k)).linear, sum[k]);
  }
  EXPECT_GE(takes, 1);
}
