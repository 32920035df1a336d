// Tests of dm::SteppedLinkEmulator (dm/network/stream_pipe.hpp): the
// LinkEmulator's fates on a clock the test steps. Every packet falls due at
// its send time plus the delay plus a jitter inside its bound, never before;
// the seeded fates are those of the threaded LinkEmulator (same counts of
// loss, duplication and reordering for the same seed); two runs give the
// same arrivals to the nanosecond; the slots are fixed and a full link
// refuses and counts; bad options are refused naming the field.
#include <dm/network/stream_pipe.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <mutex>
#include <vector>

#include "../common/eventually.hpp"

namespace {

using namespace std::chrono_literals;
using dm::test::eventually;

/// A packet carrying its index.
std::vector<std::byte> numbered(std::uint32_t index) {
  std::vector<std::byte> p(16);
  std::memcpy(p.data(), &index, 4);
  return p;
}
std::uint32_t numberOf(std::span<const std::byte> p) {
  std::uint32_t i = 0;
  std::memcpy(&i, p.data(), 4);
  return i;
}

struct Delivered {
  std::uint32_t index = 0;
  std::int64_t atNs = 0;
  bool operator==(const Delivered&) const = default;
};

/// Sends packet i at i·spacing and steps the clock by `step` until nothing
/// is in flight; returns every arrival in order and the final statistics.
std::pair<std::vector<Delivered>, dm::LinkEmulatorStats> runStepped(const dm::LinkEmulatorOptions& o,
                                                                    std::uint32_t n, std::int64_t spacingNs,
                                                                    std::int64_t stepNs) {
  auto link = dm::SteppedLinkEmulator::create(o);
  EXPECT_TRUE(link.ok());
  if (!link) return {};
  std::vector<Delivered> got;
  std::uint32_t next = 0;
  for (std::int64_t t = 0; next < n || (*link)->stats().inFlight > 0; t += stepNs) {
    for (; next < n && static_cast<std::int64_t>(next) * spacingNs <= t; ++next)
      EXPECT_TRUE((*link)->submit(numbered(next), static_cast<std::int64_t>(next) * spacingNs));
    std::span<const std::byte> p;
    while ((*link)->popDue(t, p)) got.push_back({numberOf(p), t});
  }
  return {got, (*link)->stats()};
}

TEST(SteppedLinkEmulator, EveryPacketFallsDueAfterItsDelayWithinItsJitter) {
  constexpr std::int64_t kMs = 1'000'000, kStep = 100'000;  // 1 ms spacing, 0.1 ms clock steps
  constexpr std::uint32_t kN = 2000;
  auto [got, stats] =
      runStepped({.delay = 10ms, .jitter = 2ms, .seed = 3, .maxPacketBytes = 16}, kN, kMs, kStep);
  ASSERT_EQ(got.size(), kN);
  EXPECT_EQ(stats.delivered, kN);
  EXPECT_EQ(stats.lost, 0u);
  std::vector<bool> seen(kN, false);
  for (const Delivered& a : got) {
    const std::int64_t latency = a.atNs - static_cast<std::int64_t>(a.index) * kMs;
    // Due at send + 10 ms + U[0, 2 ms]; popped at the first step at or after it.
    EXPECT_GE(latency, 10 * kMs) << "packet " << a.index;
    EXPECT_LT(latency, 12 * kMs + kStep) << "packet " << a.index;
    EXPECT_FALSE(seen[a.index]);
    seen[a.index] = true;
  }
  // 2 ms of jitter on 1 ms spacing: packets overtake each other.
  const bool inOrder = std::is_sorted(
      got.begin(), got.end(), [](const Delivered& a, const Delivered& b) { return a.index < b.index; });
  EXPECT_FALSE(inOrder);
  // The mean of the uniform jitter is 1 ms (+ half a step of popping):
  // 2000 draws of variance (2 ms)²/12 give a standard error of 13 µs.
  double mean = 0;
  for (const Delivered& a : got)
    mean += static_cast<double>(a.atNs - static_cast<std::int64_t>(a.index) * kMs);
  mean /= kN;
  EXPECT_NEAR(mean, 11.0 * kMs + 0.5 * kStep, 5 * 13'000.0 + 0.5 * kStep);
}

TEST(SteppedLinkEmulator, SameSeedSameArrivalsToTheNanosecond) {
  const dm::LinkEmulatorOptions o{.delay = 5ms,
                                  .jitter = 700us,
                                  .jitterModel = dm::JitterModel::HalfNormal,
                                  .lossProbability = 0.1,
                                  .duplicateProbability = 0.05,
                                  .reorderProbability = 0.05,
                                  .seed = 99,
                                  .maxPacketBytes = 16};
  const auto first = runStepped(o, 3000, 1'000'000, 50'000);
  const auto second = runStepped(o, 3000, 1'000'000, 50'000);
  EXPECT_EQ(first.first, second.first);
  dm::LinkEmulatorOptions other = o;
  other.seed = 100;
  EXPECT_NE(runStepped(other, 3000, 1'000'000, 50'000).first, first.first);
}

TEST(SteppedLinkEmulator, DrawsTheFatesOfTheThreadedEmulator) {
  // One FateSource serves both: for a seed, the same packets are lost,
  // duplicated and held back, whatever clock delivers them.
  const dm::LinkEmulatorOptions o{.jitter = 200us,
                                  .jitterModel = dm::JitterModel::HalfNormal,
                                  .lossProbability = 0.3,
                                  .duplicateProbability = 0.2,
                                  .reorderProbability = 0.2,
                                  .reorderDelay = 300us,
                                  .seed = 1234,
                                  .maxInFlight = 8192,
                                  .maxPacketBytes = 16};
  constexpr std::uint32_t kN = 1000;
  dm::IoThread net;
  ASSERT_TRUE(net.start().ok());
  std::mutex mutex;
  std::vector<std::uint32_t> threaded;
  auto emulator = dm::LinkEmulator::create(net, o, [&](std::span<const std::byte> p) {
    std::lock_guard lock(mutex);
    threaded.push_back(numberOf(p));
  });
  ASSERT_TRUE(emulator.ok());
  for (std::uint32_t i = 0; i < kN; ++i) ASSERT_TRUE((*emulator)->submit(numbered(i)).ok());
  ASSERT_TRUE(eventually([&] { return (*emulator)->stats().inFlight == 0; }));
  const dm::LinkEmulatorStats t = (*emulator)->stats();
  (*emulator)->close();

  auto [stepped, s] = runStepped(o, kN, 0, 100'000);  // all sent at t = 0, as fast as the threaded submits
  EXPECT_EQ(s.lost, t.lost);
  EXPECT_EQ(s.duplicated, t.duplicated);
  EXPECT_EQ(s.reordered, t.reordered);
  EXPECT_EQ(s.delivered, t.delivered);
  std::vector<std::uint32_t> a;
  for (const Delivered& x : stepped) a.push_back(x.index);
  std::sort(a.begin(), a.end());
  std::lock_guard lock(mutex);
  std::sort(threaded.begin(), threaded.end());
  EXPECT_EQ(a, threaded);   // the same packets, the same copies
  EXPECT_GT(t.lost, 200u);  // the draws did something (p = 0.3 of 1000)
  EXPECT_GT(t.duplicated, 50u);
}

TEST(SteppedLinkEmulator, AFullLinkRefusesAndCountsAndItsSlotsComeBack) {
  auto link = dm::SteppedLinkEmulator::create({.delay = 1ms, .maxInFlight = 4, .maxPacketBytes = 16});
  ASSERT_TRUE(link.ok());
  for (std::uint32_t i = 0; i < 4; ++i) EXPECT_TRUE((*link)->submit(numbered(i), 0));
  EXPECT_FALSE((*link)->submit(numbered(4), 0));
  EXPECT_FALSE((*link)->submit(std::vector<std::byte>(17), 0));  // larger than a slot
  EXPECT_EQ((*link)->stats().refused, 2u);
  EXPECT_EQ((*link)->stats().inFlight, 4u);
  std::span<const std::byte> p;
  EXPECT_FALSE((*link)->popDue(999'999, p));  // not due before 1 ms
  std::vector<std::uint32_t> order;
  while ((*link)->popDue(1'000'000, p)) order.push_back(numberOf(p));
  EXPECT_EQ(order, (std::vector<std::uint32_t>{0, 1, 2, 3}));  // equal due times keep submission order
  for (std::uint32_t i = 10; i < 14; ++i) EXPECT_TRUE((*link)->submit(numbered(i), 2'000'000));
  EXPECT_EQ((*link)->stats().inFlight, 4u);
}

TEST(SteppedLinkEmulator, ADuplicateIsTheSameBytes) {
  auto link = dm::SteppedLinkEmulator::create(
      {.jitter = 1ms, .duplicateProbability = 1.0, .seed = 4, .maxPacketBytes = 16});
  ASSERT_TRUE(link.ok());
  ASSERT_TRUE((*link)->submit(numbered(77), 0));
  EXPECT_EQ((*link)->stats().duplicated, 1u);
  std::vector<std::uint32_t> got;
  std::span<const std::byte> p;
  while ((*link)->popDue(2'000'000, p)) got.push_back(numberOf(p));
  EXPECT_EQ(got, (std::vector<std::uint32_t>{77, 77}));
}

TEST(SteppedLinkEmulator, BadOptionsAreRefusedNamingTheField) {
  auto loss = dm::SteppedLinkEmulator::create({.lossProbability = 1.5});
  ASSERT_FALSE(loss.ok());
  EXPECT_NE(loss.error().message().find("lossProbability"), std::string::npos);
  auto delay = dm::SteppedLinkEmulator::create({.delay = -1ms});
  ASSERT_FALSE(delay.ok());
  EXPECT_NE(delay.error().message().find("delay"), std::string::npos);
  // The slots are allocated up front: the defaults' 4096 × 64 KiB is refused.
  auto huge = dm::SteppedLinkEmulator::create({});
  ASSERT_FALSE(huge.ok());
  EXPECT_NE(huge.error().message().find("maxPacketBytes"), std::string::npos);
  EXPECT_TRUE(dm::SteppedLinkEmulator::create({.maxPacketBytes = 1500}).ok());
}

}  // namespace
