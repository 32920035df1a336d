#include <dm/core/ring.hpp>

#include <gtest/gtest.h>

#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <thread>
#include <vector>

namespace {

// Modest N: this executable also runs under ThreadSanitizer (5-10x slower).
constexpr std::uint64_t kItems = 200'000;

TEST(SpscRing, SingleThreadFifoAndBounds) {
  dm::SpscRing<int, 4> ring;
  EXPECT_EQ(ring.capacity(), 4u);
  EXPECT_TRUE(ring.emptyApprox());
  int out = -1;
  EXPECT_FALSE(ring.tryPop(out));
  EXPECT_EQ(out, -1) << "a failed pop leaves the output alone";
  for (int i = 0; i < 4; ++i) EXPECT_TRUE(ring.tryPush(i));
  EXPECT_FALSE(ring.tryPush(99)) << "all Capacity slots usable, then full";
  EXPECT_EQ(ring.sizeApprox(), 4u);
  for (int i = 0; i < 4; ++i) {
    ASSERT_TRUE(ring.tryPop(out));
    EXPECT_EQ(out, i);
  }
  EXPECT_FALSE(ring.tryPop().has_value());
  // Wrap around many times.
  for (int i = 0; i < 1000; ++i) {
    ASSERT_TRUE(ring.tryPush(i));
    auto v = ring.tryPop();
    ASSERT_TRUE(v.has_value());
    ASSERT_EQ(*v, i);
  }
}

TEST(SpscRing, MoveOnlyAndNonTrivialTypes) {
  dm::SpscRing<std::unique_ptr<int>, 8> ring;
  EXPECT_TRUE(ring.tryPush(std::make_unique<int>(5)));
  EXPECT_TRUE(ring.tryEmplace(new int(6)));
  std::unique_ptr<int> p;
  ASSERT_TRUE(ring.tryPop(p));
  EXPECT_EQ(*p, 5);
  auto q = ring.tryPop();
  ASSERT_TRUE(q && *q);
  EXPECT_EQ(**q, 6);

  // Items still queued at destruction are destroyed (ASan/LSan would flag a leak).
  auto strings = std::make_unique<dm::SpscRing<std::string, 4>>();
  EXPECT_TRUE(strings->tryPush(std::string(100, 'x')));
  EXPECT_TRUE(strings->tryPush(std::string(200, 'y')));
  strings.reset();
}

TEST(SpscRing, ProducerConsumerKeepOrderWithoutLossOrDuplication) {
  // Small enough that both the full and the empty paths are taken often.
  auto ring = std::make_unique<dm::SpscRing<std::uint64_t, 1024>>();
  std::thread producer([&] {
    for (std::uint64_t i = 1; i <= kItems; ++i)
      while (!ring->tryPush(i)) std::this_thread::yield();
  });
  std::uint64_t expected = 1;
  std::uint64_t outOfOrder = 0;
  std::uint64_t v = 0;
  while (expected <= kItems) {
    if (ring->tryPop(v)) {
      if (v != expected) ++outOfOrder;  // loss, duplication and reordering all show here
      expected = v + 1;
    } else {
      std::this_thread::yield();
    }
  }
  producer.join();
  EXPECT_EQ(outOfOrder, 0u);
  EXPECT_EQ(expected, kItems + 1);
  EXPECT_FALSE(ring->tryPop(v)) << "nothing beyond the last item";
  EXPECT_EQ(ring->sizeApprox(), 0u);
}

struct Payload {
  std::uint64_t seq = 0;
  std::uint64_t check = 0;          // derived from seq: a torn copy would not match
  std::vector<std::uint64_t> data;  // heap-owning: exercises move semantics across threads
};

TEST(SpscRing, NonTrivialPayloadsArriveIntact) {
  constexpr std::uint64_t kN = kItems / 10;
  auto ring = std::make_unique<dm::SpscRing<Payload, 16>>();
  std::thread producer([&] {
    for (std::uint64_t i = 1; i <= kN; ++i) {
      Payload p{i, i * 0x9E3779B97F4A7C15ull, std::vector<std::uint64_t>(i % 5 + 1, i)};
      while (!ring->tryPush(std::move(p))) std::this_thread::yield();
    }
  });
  std::uint64_t next = 1, bad = 0;
  Payload p;
  while (next <= kN) {
    if (!ring->tryPop(p)) {
      std::this_thread::yield();
      continue;
    }
    if (p.seq != next || p.check != next * 0x9E3779B97F4A7C15ull || p.data.size() != next % 5 + 1) ++bad;
    for (std::uint64_t x : p.data) bad += (x != next);
    next = p.seq + 1;
  }
  producer.join();
  EXPECT_EQ(bad, 0u);
}

TEST(SpscRing, SizeApproxStaysWithinBoundsUnderConcurrency) {
  auto ring = std::make_unique<dm::SpscRing<std::uint32_t, 32>>();
  std::atomic<bool> done{false};
  std::thread producer([&] {
    for (std::uint32_t i = 0; i < 50'000; ++i)
      while (!ring->tryPush(i)) std::this_thread::yield();
    done.store(true);
  });
  std::thread observer([&] {
    while (!done.load()) {
      const std::size_t s = ring->sizeApprox();
      EXPECT_LE(s, 32u);
      std::this_thread::yield();
    }
  });
  std::uint32_t got = 0, v = 0;
  while (got < 50'000) {
    if (ring->tryPop(v)) {
      ++got;
    } else {
      std::this_thread::yield();
    }
  }
  producer.join();
  observer.join();
  EXPECT_EQ(got, 50'000u);
}

}  // namespace
