#include <dm/core/arena.hpp>

#include <gtest/gtest.h>

#include <cstdint>
#include <limits>
#include <utility>

namespace {

bool isAligned(const void* p, std::size_t alignment) {
  return reinterpret_cast<std::uintptr_t>(p) % alignment == 0;
}

struct alignas(32) Wide {
  double v[4];
};

TEST(Arena, AllocationsAreAlignedAndDisjoint) {
  dm::Arena arena(4096);
  auto bytes = arena.allocate<char>(3);
  auto doubles = arena.allocate<double>(5);
  auto wide = arena.allocate<Wide>(2);
  auto ints = arena.allocate<std::int32_t>(7, 9);
  ASSERT_EQ(bytes.size(), 3u);
  ASSERT_EQ(doubles.size(), 5u);
  ASSERT_EQ(wide.size(), 2u);
  ASSERT_EQ(ints.size(), 7u);
  EXPECT_TRUE(isAligned(doubles.data(), alignof(double)));
  EXPECT_TRUE(isAligned(wide.data(), 32));
  EXPECT_TRUE(isAligned(ints.data(), alignof(std::int32_t)));
  for (int x : ints) EXPECT_EQ(x, 9);
  // Disjoint and in order: each starts after the previous one ends.
  const auto addr = [](const void* p) { return reinterpret_cast<std::uintptr_t>(p); };
  EXPECT_GE(addr(doubles.data()), addr(bytes.data() + bytes.size()));
  EXPECT_GE(addr(wide.data()), addr(doubles.data() + doubles.size()));
  EXPECT_GE(addr(ints.data()), addr(wide.data() + wide.size()));
  // Writes to one do not disturb another.
  for (auto& d : doubles) d = 1.5;
  for (auto& w : wide) w = Wide{{2, 2, 2, 2}};
  for (double d : doubles) EXPECT_EQ(d, 1.5);
  for (int x : ints) EXPECT_EQ(x, 9);
}

TEST(Arena, LargeAlignmentsBeyondTheBase) {
  dm::Arena arena(8192);
  (void)arena.allocateBytes(1, 1);
  void* p = arena.allocateBytes(16, 1024);
  ASSERT_NE(p, nullptr);
  EXPECT_TRUE(isAligned(p, 1024));
  EXPECT_EQ(arena.allocateBytes(16, 3), nullptr) << "non power-of-two alignment is refused";
}

TEST(Arena, ExhaustionReturnsEmptyAndIsCounted) {
  dm::Arena arena(256);
  auto a = arena.allocate<std::uint8_t>(200);
  ASSERT_EQ(a.size(), 200u);
  auto b = arena.allocate<std::uint8_t>(100);  // 56 bytes left
  EXPECT_TRUE(b.empty());
  EXPECT_EQ(arena.exhaustions(), 1u);
  EXPECT_EQ(arena.used(), 200u) << "a failed allocation consumes nothing";
  auto c = arena.allocate<std::uint8_t>(56);  // exactly what is left
  EXPECT_EQ(c.size(), 56u);
  EXPECT_EQ(arena.remaining(), 0u);
  EXPECT_TRUE(arena.allocate<std::uint8_t>(1).empty());
  EXPECT_EQ(arena.exhaustions(), 2u);
  // Sizes whose byte count overflows size_t are exhaustions, not wrap-arounds.
  EXPECT_TRUE(arena.allocate<double>(std::numeric_limits<std::size_t>::max() / 4).empty());
  EXPECT_EQ(arena.exhaustions(), 3u);
  // Zero-sized requests are neither allocations nor failures.
  EXPECT_TRUE(arena.allocate<double>(0).empty());
  EXPECT_EQ(arena.allocateBytes(0), nullptr);
  EXPECT_EQ(arena.exhaustions(), 3u);
}

TEST(Arena, ResetReusesMemoryAndKeepsHighWater) {
  dm::Arena arena(1024);
  auto first = arena.allocate<double>(10);
  EXPECT_EQ(arena.used(), 80u);
  arena.reset();
  EXPECT_EQ(arena.used(), 0u);
  auto again = arena.allocate<double>(10);
  EXPECT_EQ(again.data(), first.data()) << "after reset the same memory is handed out";
  (void)arena.allocate<double>(30);
  EXPECT_EQ(arena.highWater(), 320u);
  arena.reset();
  (void)arena.allocate<double>(5);
  EXPECT_EQ(arena.highWater(), 320u) << "high-water mark survives reset()";
  arena.resetStatistics();
  EXPECT_EQ(arena.highWater(), 40u);
  EXPECT_EQ(arena.exhaustions(), 0u);
}

TEST(Arena, MarkerAndScopeRewind) {
  dm::Arena arena(1024);
  auto keep = arena.allocate<int>(4);
  const std::size_t usedBefore = arena.used();
  {
    dm::Arena::Scope scratch(arena);
    auto tmp = arena.allocate<double>(50);
    EXPECT_EQ(tmp.size(), 50u);
    EXPECT_GT(arena.used(), usedBefore);
  }
  EXPECT_EQ(arena.used(), usedBefore);
  const auto m = arena.mark();
  auto tmp = arena.allocate<char>(100);
  arena.rewind(m);
  auto reused = arena.allocate<char>(100);
  EXPECT_EQ(reused.data(), tmp.data());
  EXPECT_EQ(keep.size(), 4u);
}

TEST(Arena, MoveTransfersTheBuffer) {
  dm::Arena a(512);
  auto s = a.allocate<int>(3, 5);
  dm::Arena b(std::move(a));
  EXPECT_EQ(b.capacity(), 512u);
  EXPECT_EQ(b.used(), 12u);
  EXPECT_EQ(s[2], 5) << "memory stays valid across the move";
  EXPECT_EQ(a.capacity(), 0u);  // NOLINT(bugprone-use-after-move): moved-from state is specified
  EXPECT_TRUE(a.allocate<int>(1).empty());
  dm::Arena c(16);
  c = std::move(b);
  EXPECT_EQ(c.capacity(), 512u);
}

TEST(Arena, ZeroCapacityAlwaysExhausted) {
  dm::Arena arena(0);
  EXPECT_TRUE(arena.allocate<int>(1).empty());
  EXPECT_EQ(arena.exhaustions(), 1u);
}

}  // namespace
