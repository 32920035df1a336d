// Daq across threads: an acquisition thread moving frames into the ring
// while a consumer reads them — run under ThreadSanitizer in CI. Every
// frame the consumer gets must be whole (its values match its index), in
// order, and every frame produced is either read or counted as overrun.
#include <dm/io/daq.hpp>
#include <dm/io/drivers.hpp>

#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <thread>
#include <vector>

namespace {

TEST(DaqThreads, AcquireAndReadConcurrently) {
  dm::FactoryRegistry registry;
  dm::PluginLinker linker(registry);
  ASSERT_TRUE(dm::registerBuiltinDrivers(linker).ok());
  // Channel c is the ramp 2·frac(t) − 1 plus c: all channels of a frame agree.
  auto opened = dm::Daq::open(registry, "sim-daq",
                              {{"channels", "4"},
                               {"rate", "20000"},
                               {"fifo", "1000000"},
                               {"ch0", "ramp,1,1,0"},
                               {"ch1", "ramp,1,1,1"},
                               {"ch2", "ramp,1,1,2"},
                               {"ch3", "ramp,1,1,3"}});
  ASSERT_TRUE(opened.ok()) << opened.error().message();
  dm::Daq& daq = **opened;

  constexpr std::int64_t kSteps = 2000;  // 2 s of virtual time in 1 ms steps: 40 001 frames
  std::atomic<bool> done{false};
  std::thread acquisition([&] {
    for (std::int64_t k = 0; k <= kSteps; ++k) {
      daq.acquire(k * 1'000'000);
      if (k % 16 == 0) std::this_thread::yield();
    }
    done.store(true, std::memory_order_release);
  });

  std::vector<dm::DaqFrame> chunk(256);
  std::uint64_t read = 0, overrun = 0, gaps = 0, bad = 0;
  std::int64_t nextIndex = 0;
  for (;;) {
    const bool finished = done.load(std::memory_order_acquire);
    const dm::DaqReadResult r = daq.read(chunk);
    overrun += r.overrunFrames;
    for (std::size_t i = 0; i < r.frames; ++i) {
      const dm::DaqFrame& f = chunk[i];
      const auto index = static_cast<std::int64_t>(f.index);
      if (index < nextIndex) ++bad;  // out of order or repeated
      gaps += static_cast<std::uint64_t>(index - nextIndex);
      nextIndex = index + 1;
      const double t = 1e-9 * static_cast<double>(f.timeNs);
      const double ramp = 2 * (t - std::floor(t)) - 1;
      for (int c = 0; c < 4; ++c)
        if (std::abs(f.values[c] - (ramp + c)) > 1e-9) ++bad;
    }
    read += r.frames;
    if (finished && r.frames == 0) break;
  }
  acquisition.join();
  EXPECT_EQ(bad, 0u);
  gaps += static_cast<std::uint64_t>(40'001 - nextIndex);  // frames dropped at the end leave no later frame
  EXPECT_EQ(gaps, overrun);                                // every gap is reported, with its size
  EXPECT_EQ(read + overrun, 40'001u);
  EXPECT_EQ(daq.counters().readFrames, read);
}

}  // namespace
