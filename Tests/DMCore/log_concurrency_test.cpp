// The real-time log path under concurrent producers: nothing lost unless the
// queue was full (then counted), nothing duplicated, nothing torn.
#include <dm/core/log.hpp>

#include <gtest/gtest.h>

#include <atomic>
#include <cstdio>
#include <mutex>
#include <set>
#include <string>
#include <thread>
#include <vector>

namespace {

TEST(LogRt, ConcurrentProducersDeliverEveryAcceptedRecord) {
  std::mutex m;
  std::set<std::string> seen;
  std::atomic<int> duplicates{0};
  dm::log::setLevel(dm::log::Level::Trace);
  dm::log::setSink([&](dm::log::Level l, std::string_view text) {
    if (l != dm::log::Level::Debug || text.rfind("rt-test ", 0) != 0) return;
    std::lock_guard lock(m);
    if (!seen.insert(std::string(text)).second) duplicates++;
  });
  // Keep the console quiet: the sink still receives everything that passes the level.
  constexpr int kThreads = 3, kPerThread = 2000;
  const std::uint64_t droppedBefore = dm::log::rtDropped();
  std::atomic<int> accepted{0};
  std::vector<std::thread> producers;
  for (int t = 0; t < kThreads; ++t)
    producers.emplace_back([t, &accepted] {
      for (int i = 0; i < kPerThread; ++i)
        if (dm::log::rt(dm::log::Level::Debug, "rt-test %d %d %s", t, i, "payload-xxxxxxxxxxxxxxxx"))
          accepted++;
    });
  for (auto& p : producers) p.join();
  dm::log::flush();
  dm::log::setSink({});
  dm::log::setLevel(dm::log::Level::Info);
  const auto dropped = dm::log::rtDropped() - droppedBefore;
  EXPECT_EQ(duplicates.load(), 0);
  EXPECT_EQ(static_cast<int>(seen.size()), accepted.load());
  EXPECT_EQ(static_cast<std::uint64_t>(accepted.load()) + dropped,
            static_cast<std::uint64_t>(kThreads * kPerThread));
  for (const auto& s : seen) {
    int t = -1, i = -1;
    char payload[64];
    ASSERT_EQ(std::sscanf(s.c_str(), "rt-test %d %d %63s", &t, &i, payload), 3) << s;
    EXPECT_STREQ(payload, "payload-xxxxxxxxxxxxxxxx");
  }
}

TEST(LogRt, FullQueueDropsAndCountsInsteadOfBlocking) {
  dm::log::setLevel(dm::log::Level::Trace);
  dm::log::setSink([](dm::log::Level, std::string_view) {});
  const std::uint64_t before = dm::log::rtDropped();
  // Far more records than slots, faster than the 2 ms drain cadence.
  for (std::size_t i = 0; i < 4 * dm::log::kRtQueueSlots; ++i)
    (void)dm::log::rt(dm::log::Level::Trace, "flood %zu", i);
  EXPECT_GT(dm::log::rtDropped(), before);
  dm::log::flush();
  dm::log::setSink({});
  dm::log::setLevel(dm::log::Level::Info);
}

TEST(Log, LevelFilterAndLongMessages) {
  std::vector<std::string> got;
  dm::log::setSink([&](dm::log::Level, std::string_view t) { got.emplace_back(t); });
  dm::log::setLevel(dm::log::Level::Warn);
  dm::log::info("hidden");
  dm::log::warn("shown %d", 1);
  const std::string longText(2000, 'a');
  dm::log::error("%s", longText.c_str());
  EXPECT_FALSE(dm::log::rt(dm::log::Level::Info, "below level"));
  dm::log::setSink({});
  dm::log::setLevel(dm::log::Level::Info);
  ASSERT_EQ(got.size(), 2u);
  EXPECT_EQ(got[0], "shown 1");
  EXPECT_EQ(got[1], longText);
}

}  // namespace
