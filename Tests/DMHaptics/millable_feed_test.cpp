// MillableSurfaceFeed: blocks that find the queue full reach the render
// thread's copy later, with their newest voxels, and the surface handed back
// is the whole bone's surface as MillableVolume meshes it.
#include "millable_feed_test_support.hpp"

namespace dm {
namespace millable_feed_test {

TEST(MillableSurfaceFeed, BlocksThatFindTheQueueFullGoLaterWithTheirNewestVoxels) {
  MillableVolume b = bone(128);  // 16³ blocks, the lower half bone
  auto feed = MillableSurfaceFeed::create(b);
  ASSERT_TRUE(feed.ok());
  Mesh surface;
  ASSERT_TRUE((*feed)->update(surface).ok());
  // One wide cut touches more blocks than the queue holds.
  b.mill(MillingTool::box(Vec3(20e-3, 20e-3, 20e-3)), at(Vec3(0, 0, 0)), 10.0);
  const std::size_t changed = b.changedBlocks().size();
  ASSERT_GT(changed, MillableSurfaceFeed::kQueueBlocks);
  (*feed)->publish(b);
  EXPECT_EQ((*feed)->waiting(), changed - MillableSurfaceFeed::kQueueBlocks);
  // More milling of a waiting block before it goes: it goes once, as it is then.
  b.mill(MillingTool::sphere(1e-3), at(Vec3(5e-3, 5e-3, -1e-3)), 1.0);
  int rounds = 0;
  while (true) {
    ASSERT_TRUE((*feed)->update(surface).ok());
    (*feed)->publish(b);
    ++rounds;
    if ((*feed)->waiting() == 0) break;
    ASSERT_LT(rounds, 10);
  }
  ASSERT_TRUE((*feed)->update(surface).ok());
  expectSame(b, **feed, surface);
}

}  // namespace millable_feed_test
}  // namespace dm
