#include <dm/core/triple_buffer.hpp>

#include <gtest/gtest.h>

#include <array>
#include <atomic>
#include <cstdint>
#include <thread>

namespace {

TEST(TripleBuffer, SingleThreadSemantics) {
  dm::TripleBuffer<int> tb(-1);
  EXPECT_EQ(tb.readBuffer(), -1);
  EXPECT_FALSE(tb.update()) << "nothing published yet";
  EXPECT_FALSE(tb.freshApprox());
  tb.write(1);
  EXPECT_TRUE(tb.freshApprox());
  tb.write(2);  // overwrites 1 before the reader looked: only the latest matters
  EXPECT_TRUE(tb.update());
  EXPECT_EQ(tb.readBuffer(), 2);
  EXPECT_FALSE(tb.update());
  EXPECT_EQ(tb.read(), 2) << "the value stays until something newer arrives";
  tb.writeBuffer() = 3;
  EXPECT_EQ(tb.read(), 2) << "unpublished writes are invisible";
  tb.publish();
  EXPECT_EQ(tb.read(), 3);
  dm::TripleBuffer<double> zeros;
  EXPECT_EQ(zeros.read(), 0.0);
}

// Every field equals the counter: a torn read shows as unequal fields.
struct State {
  std::array<std::uint64_t, 16> fields{};
};

TEST(TripleBuffer, ReaderNeverSeesTornOrOlderValues) {
  // Modest N: also runs under ThreadSanitizer.
  constexpr std::uint64_t kWrites = 200'000;
  auto tb = std::make_unique<dm::TripleBuffer<State>>();
  std::thread writer([&] {
    for (std::uint64_t c = 1; c <= kWrites; ++c) {
      State& s = tb->writeBuffer();
      for (auto& f : s.fields) f = c;
      tb->publish();
    }
  });
  std::uint64_t last = 0, torn = 0, backwards = 0, reads = 0, distinct = 0;
  while (last != kWrites) {
    const State& s = tb->read();
    const std::uint64_t c = s.fields[0];
    for (std::uint64_t f : s.fields) torn += (f != c);
    backwards += (c < last);
    distinct += (c != last);
    last = c;
    ++reads;
  }
  writer.join();
  EXPECT_EQ(torn, 0u);
  EXPECT_EQ(backwards, 0u);
  EXPECT_EQ(last, kWrites) << "the final value is seen";
  EXPECT_GE(distinct, 1u);
  // After the writer is done, the last value stays readable.
  EXPECT_EQ(tb->read().fields[15], kWrites);
  EXPECT_FALSE(tb->update());
}

TEST(TripleBuffer, WriterNeverWaitsForASlowReader) {
  // The reader holds on to its buffer while the writer publishes many
  // values; the writer must finish regardless, and the reader then gets the
  // newest value in one update.
  auto tb = std::make_unique<dm::TripleBuffer<State>>();
  const State& held = tb->read();
  std::atomic<bool> finished{false};
  std::thread writer([&] {
    for (std::uint64_t c = 1; c <= 10'000; ++c) {
      tb->writeBuffer().fields.fill(c);
      tb->publish();
    }
    finished.store(true);
  });
  writer.join();
  EXPECT_TRUE(finished.load());
  EXPECT_EQ(held.fields[0], 0u) << "the reader's buffer was not touched meanwhile";
  EXPECT_TRUE(tb->update());
  EXPECT_EQ(tb->readBuffer().fields[7], 10'000u);
}

}  // namespace
