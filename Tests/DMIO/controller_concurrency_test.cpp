// Controller across threads: a poll thread sampling sim-controller while a
// consumer reads the latest state and events — run under ThreadSanitizer in
// CI. Every state the consumer sees must be whole: its axes and buttons
// match the formulas at its own timestamp.
#include <dm/io/controller.hpp>
#include <dm/io/drivers.hpp>

#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <thread>

namespace {

TEST(ControllerThreads, PollAndConsumerConcurrently) {
  dm::FactoryRegistry registry;
  dm::PluginLinker linker(registry);
  ASSERT_TRUE(dm::registerBuiltinDrivers(linker).ok());
  auto opened = dm::Controller::open(registry, "sim-controller",
                                     {{"axis0", "ramp,1,3"},
                                      {"axis1", "ramp,1,3"},
                                      {"buttons", "64"},
                                      {"button_rate", "1000"},
                                      {"drop_at", "5"},
                                      {"reconnect_at", "5.5"}},
                                     {.reconnectIntervalSeconds = 0.01});
  ASSERT_TRUE(opened.ok()) << opened.error().message();
  dm::Controller& pad = **opened;

  constexpr std::int64_t kSteps = 40000;  // 10 s of virtual time at 4 kHz
  std::atomic<bool> done{false};
  std::thread poller([&] {
    for (std::int64_t k = 0; k < kSteps; ++k) pad.poll(k * 250'000);
    done.store(true, std::memory_order_release);
  });
  // timeNs 0 is the initial, empty state (and the first sample, which is skipped).
  // The loop reads once more after the poller has finished (on a loaded
  // machine the poller may finish before this thread runs at all): that
  // last read must see the last poll's state.
  std::int64_t lastTime = 0, states = 0, torn = 0, events = 0;
  for (bool finished = false; !finished;) {
    finished = done.load(std::memory_order_acquire);
    const dm::ControllerState& s = pad.state();
    if (s.timeNs > lastTime) {
      lastTime = s.timeNs;
      ++states;
      const double t = 1e-9 * static_cast<double>(s.timeNs);
      const double ramp = 2 * (3 * t - std::floor(3 * t)) - 1;
      const auto counter = static_cast<std::uint64_t>(std::floor(1000 * t));
      bool whole = s.axes[0] == s.axes[1] && std::abs(s.axes[0] - ramp) < 1e-9;
      for (std::size_t i = 0; i < 64; ++i) whole = whole && s.pressed(i) == (((counter >> i) & 1u) != 0);
      if (!whole) ++torn;
    }
    dm::DeviceEvent e;
    while (pad.pollEvent(e)) ++events;
  }
  poller.join();
  EXPECT_EQ(torn, 0);
  EXPECT_GT(states, 0);
  EXPECT_EQ(lastTime, (kSteps - 1) * 250'000);
  EXPECT_EQ(events, 2);  // lost at 5 s, back at 5.5 s
  EXPECT_EQ(pad.counters().polls, static_cast<std::uint64_t>(kSteps));
}

}  // namespace
