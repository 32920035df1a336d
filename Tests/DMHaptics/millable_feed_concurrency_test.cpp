// MillableSurfaceFeed across threads (also under ThreadSanitizer): what the
// haptic thread mills reaches the render thread's copy exactly, and the
// surface that thread draws is the bone's own.
#include <atomic>
#include <chrono>
#include <thread>

#include "millable_feed_test_support.hpp"

namespace dm {
namespace millable_feed_test {

TEST(MillableSurfaceFeed, TheRenderCopyFollowsABurrPathAcrossThreads) {
  MillableVolume b = bone(48);
  auto feed = MillableSurfaceFeed::create(b);
  ASSERT_TRUE(feed.ok());
  Mesh surface;
  auto first = (*feed)->update(surface);
  ASSERT_TRUE(first.ok());
  EXPECT_TRUE(*first);  // the first call hands over the untouched bone
  expectSame(b, **feed, surface);
  auto again = (*feed)->update(surface);
  ASSERT_TRUE(again.ok());
  EXPECT_FALSE(*again);  // nothing changed

  // A burr groove across the curved top, published every tick on one thread
  // and meshed on another, as the haptic and render engines do.
  std::atomic<bool> done{false};
  std::atomic<int> frames{0};
  Mesh shown = surface;  // what the render thread draws
  std::thread render([&] {
    while (!done.load()) {
      if (auto u = (*feed)->update(shown); u.ok() && *u) frames.fetch_add(1);
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
  });
  const MillingTool burr = MillingTool::sphere(0.8e-3);
  for (int t = 0; t < 2000; ++t) {
    const double x = -5e-3 + 10e-3 * t / 1999.0;
    b.mill(burr, at(Vec3(x, 0.3e-3 * std::sin(x / 1e-3), 0.3e-3 * std::cos(x / 2e-3) + 0.3e-3)), 2e-3);
    (*feed)->publish(b);
  }
  done = true;
  render.join();
  EXPECT_GT(frames.load(), 0);
  // Blocks still waiting for room go with the next publishes.
  for (int round = 0; round < 10; ++round) {
    ASSERT_TRUE((*feed)->update(shown).ok());
    if ((*feed)->waiting() == 0) break;
    (*feed)->publish(b);
  }
  EXPECT_EQ((*feed)->waiting(), 0u);
  ASSERT_TRUE((*feed)->update(shown).ok());
  expectSame(b, **feed, shown);
  EXPECT_GT((*feed)->blocksSent(), 10u);
}

}  // namespace millable_feed_test
}  // namespace dm
