// Tests of dm::UdpEndpoint over 127.0.0.1 and of dm::LinkEmulator's delay,
// loss, duplication and determinism against their stated distributions.
#include <dm/network/io_thread.hpp>
#include <dm/network/stream_pipe.hpp>
#include <dm/network/udp.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <mutex>
#include <random>
#include <thread>
#include <vector>

#include "../common/eventually.hpp"

namespace {

using namespace std::chrono_literals;

using dm::test::eventually;

/// Datagrams received, with their senders.
struct DatagramInbox {
  std::mutex mutex;
  std::vector<std::vector<std::byte>> datagrams;
  std::vector<dm::SocketAddress> senders;
  dm::DatagramCallback callback() {
    return [this](std::span<const std::byte> b, const dm::SocketAddress& from) {
      std::lock_guard lock(mutex);
      datagrams.emplace_back(b.begin(), b.end());
      senders.push_back(from);
    };
  }
  std::size_t count() {
    std::lock_guard lock(mutex);
    return datagrams.size();
  }
};

TEST(UdpEndpoint, RoundTripOfRandomDatagramsUpToTheMaximum) {
  dm::IoThread net;
  ASSERT_TRUE(net.start().ok());
  DatagramInbox atA;
  auto a = dm::UdpEndpoint::open(net, {.maxDatagramBytes = 9000}, atA.callback());
  ASSERT_TRUE(a.ok()) << a.error();
  // B echoes every datagram to its sender.
  dm::UdpEndpoint* bRaw = nullptr;
  auto b = dm::UdpEndpoint::open(net, {.maxDatagramBytes = 9000},
                                 [&](std::span<const std::byte> d, const dm::SocketAddress& from) {
                                   EXPECT_TRUE(bRaw->sendTo(from, d).ok());
                                 });
  ASSERT_TRUE(b.ok());
  bRaw = b->get();
  EXPECT_NE((*a)->port(), 0);
  EXPECT_NE((*a)->port(), (*b)->port());

  std::mt19937 rng(3);
  std::vector<std::vector<std::byte>> sent;
  for (std::size_t size : {1u, 2u, 100u, 1472u, 1473u, 4000u, 8999u, 9000u}) {
    std::vector<std::byte> d(size);
    for (auto& x : d) x = static_cast<std::byte>(rng() & 0xFF);
    ASSERT_TRUE((*a)->sendTo({"127.0.0.1", (*b)->port()}, d).ok());
    sent.push_back(d);
    // One at a time: loopback does not lose datagrams at this rate, and the
    // wait keeps the order independent of the kernel's queueing.
    ASSERT_TRUE(eventually([&] { return atA.count() == sent.size(); })) << size;
  }
  std::lock_guard lock(atA.mutex);
  EXPECT_TRUE(atA.datagrams == sent);
  EXPECT_EQ(atA.senders[0].port, (*b)->port());
  EXPECT_EQ(atA.senders[0].address, "127.0.0.1");
  const dm::UdpStats s = (*a)->stats();
  EXPECT_EQ(s.datagramsOut, sent.size());
  EXPECT_EQ(s.datagramsIn, sent.size());
  EXPECT_EQ(s.bytesIn, s.bytesOut);
}

TEST(UdpEndpoint, OversizeIsRefusedWhenSendingAndDroppedWhenReceiving) {
  dm::IoThread net;
  ASSERT_TRUE(net.start().ok());
  DatagramInbox small;
  auto receiver = dm::UdpEndpoint::open(net, {.maxDatagramBytes = 100}, small.callback());
  ASSERT_TRUE(receiver.ok());
  auto sender = dm::UdpEndpoint::open(net, {.maxDatagramBytes = 1472}, {});
  ASSERT_TRUE(sender.ok());
  const dm::SocketAddress to{"127.0.0.1", (*receiver)->port()};

  auto refused = (*sender)->sendTo(to, std::vector<std::byte>(1473));
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.error().code, dm::ErrorCode::InvalidArgument);

  ASSERT_TRUE((*sender)->sendTo(to, std::vector<std::byte>(101)).ok());  // one byte too many for the receiver
  ASSERT_TRUE((*sender)->sendTo(to, std::vector<std::byte>(100, std::byte{9})).ok());
  ASSERT_TRUE(eventually([&] { return small.count() == 1; }));
  EXPECT_TRUE(eventually([&] { return (*receiver)->stats().oversizeDropped == 1; }));
  std::lock_guard lock(small.mutex);
  EXPECT_EQ(small.datagrams[0], std::vector<std::byte>(100, std::byte{9}));
}

TEST(UdpEndpoint, ConnectFixesThePeerAndFiltersOthers) {
  dm::IoThread net;
  ASSERT_TRUE(net.start().ok());
  DatagramInbox atA, atB;
  auto a = dm::UdpEndpoint::open(net, {}, atA.callback());
  auto b = dm::UdpEndpoint::open(net, {}, atB.callback());
  auto stranger = dm::UdpEndpoint::open(net, {}, {});
  ASSERT_TRUE(a.ok() && b.ok() && stranger.ok());
  EXPECT_EQ((*b)->send(std::vector<std::byte>(4)).error().code, dm::ErrorCode::InvalidArgument);
  ASSERT_TRUE((*b)->connect({"127.0.0.1", (*a)->port()}).ok());

  ASSERT_TRUE((*stranger)->sendTo({"127.0.0.1", (*b)->port()}, std::vector<std::byte>(5, std::byte{1})).ok());
  ASSERT_TRUE((*a)->sendTo({"127.0.0.1", (*b)->port()}, std::vector<std::byte>(6, std::byte{2})).ok());
  ASSERT_TRUE(eventually([&] { return atB.count() >= 1; }));
  ASSERT_TRUE((*b)->send(std::vector<std::byte>(7, std::byte{3})).ok());
  ASSERT_TRUE(eventually([&] { return atA.count() == 1; }));
  std::this_thread::sleep_for(20ms);  // give a wrongly admitted stranger datagram time to show up
  std::lock_guard lockB(atB.mutex);
  ASSERT_EQ(atB.datagrams.size(), 1u);
  EXPECT_EQ(atB.datagrams[0], std::vector<std::byte>(6, std::byte{2}));
  std::lock_guard lockA(atA.mutex);
  EXPECT_EQ(atA.datagrams[0], std::vector<std::byte>(7, std::byte{3}));
}

TEST(UdpEndpoint, RejectsBadOptionsAndAddresses) {
  dm::IoThread net;
  EXPECT_EQ(dm::UdpEndpoint::open(net, {.maxDatagramBytes = 0}, {}).error().code,
            dm::ErrorCode::InvalidArgument);
  EXPECT_EQ(dm::UdpEndpoint::open(net, {.maxDatagramBytes = dm::kMaxUdpPayload + 1}, {}).error().code,
            dm::ErrorCode::InvalidArgument);
  EXPECT_EQ(dm::UdpEndpoint::open(net, {.local = {"not an address", 0}}, {}).error().code,
            dm::ErrorCode::InvalidArgument);
  auto a = dm::UdpEndpoint::open(net, {}, {});
  ASSERT_TRUE(a.ok());
  EXPECT_EQ(dm::UdpEndpoint::open(net, {.local = {"127.0.0.1", (*a)->port()}}, {}).error().code,
            dm::ErrorCode::Network);
  EXPECT_EQ((*a)->sendTo({"127.0.0.1", 0}, std::vector<std::byte>(1)).error().code,
            dm::ErrorCode::InvalidArgument);
  (*a)->close();
  EXPECT_EQ((*a)->sendTo({"127.0.0.1", 9}, std::vector<std::byte>(1)).error().code, dm::ErrorCode::Network);
}

TEST(UdpEndpoint, FullSendQueueAnswersBusy) {
  dm::IoThread net;  // not started: nothing drains the queue
  auto a = dm::UdpEndpoint::open(net, {.sendQueueDatagrams = 3}, {});
  ASSERT_TRUE(a.ok());
  for (int i = 0; i < 3; ++i) ASSERT_TRUE((*a)->sendTo({"127.0.0.1", 9}, std::vector<std::byte>(8)).ok());
  EXPECT_EQ((*a)->sendTo({"127.0.0.1", 9}, std::vector<std::byte>(8)).error().code, dm::ErrorCode::Busy);
  EXPECT_EQ((*a)->stats().queueFullDropped, 1u);
}

// ----------------------------------------------------------- LinkEmulator ---

/// A packet carrying its index and the steady-clock instant it was submitted.
std::vector<std::byte> stamped(std::uint32_t index) {
  std::vector<std::byte> p(12);
  const std::int64_t t = std::chrono::steady_clock::now().time_since_epoch().count();
  std::memcpy(p.data(), &index, 4);
  std::memcpy(p.data() + 4, &t, 8);
  return p;
}
std::uint32_t indexOf(std::span<const std::byte> p) {
  std::uint32_t i = 0;
  std::memcpy(&i, p.data(), 4);
  return i;
}

/// Runs `n` packets through an emulator; returns the delivered indices
/// (sorted) and the final statistics.
std::pair<std::vector<std::uint32_t>, dm::LinkEmulatorStats> runEmulator(dm::IoThread& net,
                                                                         const dm::LinkEmulatorOptions& o,
                                                                         std::uint32_t n) {
  std::mutex mutex;
  std::vector<std::uint32_t> got;
  auto link = dm::LinkEmulator::create(net, o, [&](std::span<const std::byte> p) {
    std::lock_guard lock(mutex);
    got.push_back(indexOf(p));
  });
  EXPECT_TRUE(link.ok());
  if (!link) return {};
  for (std::uint32_t i = 0; i < n; ++i) EXPECT_TRUE((*link)->submit(stamped(i)).ok());
  EXPECT_TRUE(eventually([&] { return (*link)->stats().inFlight == 0; }));
  const auto stats = (*link)->stats();
  (*link)->close();
  std::lock_guard lock(mutex);
  std::sort(got.begin(), got.end());
  return {got, stats};
}

TEST(LinkEmulator, LossAndDuplicationRatesLieWithinBinomialBounds) {
  dm::IoThread net;
  ASSERT_TRUE(net.start().ok());
  constexpr std::uint32_t kN = 5000;
  const double pLoss = 0.2, pDup = 0.1;
  auto [got, stats] = runEmulator(
      net, {.lossProbability = pLoss, .duplicateProbability = pDup, .seed = 11, .maxInFlight = 4 * kN}, kN);
  // Five standard deviations: a correct generator fails this about once in
  // two million seeds.
  const double lossSigma = std::sqrt(kN * pLoss * (1 - pLoss));
  EXPECT_NEAR(static_cast<double>(stats.lost), kN * pLoss, 5 * lossSigma);
  const double kept = static_cast<double>(kN - stats.lost);
  EXPECT_NEAR(static_cast<double>(stats.duplicated), kept * pDup, 5 * std::sqrt(kept * pDup * (1 - pDup)));
  EXPECT_EQ(stats.submitted, kN);
  EXPECT_EQ(stats.delivered, kN - stats.lost + stats.duplicated);
  EXPECT_EQ(got.size(), stats.delivered);
  // A packet arrives at most twice.
  std::size_t twice = 0;
  for (std::size_t i = 1; i < got.size(); ++i) {
    if (got[i] == got[i - 1]) ++twice;
    if (i >= 2) {
      EXPECT_FALSE(got[i] == got[i - 2]);
    }
  }
  EXPECT_EQ(twice, stats.duplicated);
}

TEST(LinkEmulator, NoPacketArrivesBeforeItsDelayAndJitterReorders) {
  dm::IoThread net;
  ASSERT_TRUE(net.start().ok());
  constexpr auto kDelay = 15ms;
  std::mutex mutex;
  std::vector<std::uint32_t> order;
  std::int64_t earliestNs = std::numeric_limits<std::int64_t>::max();
  auto link = dm::LinkEmulator::create(
      net, {.delay = kDelay, .jitter = 5ms, .seed = 5}, [&](std::span<const std::byte> p) {
        const std::int64_t now = std::chrono::steady_clock::now().time_since_epoch().count();
        std::int64_t sentAt = 0;
        std::memcpy(&sentAt, p.data() + 4, 8);
        std::lock_guard lock(mutex);
        order.push_back(indexOf(p));
        earliestNs = std::min(earliestNs, now - sentAt);
      });
  ASSERT_TRUE(link.ok());
  constexpr std::uint32_t kN = 200;
  for (std::uint32_t i = 0; i < kN; ++i) ASSERT_TRUE((*link)->submit(stamped(i)).ok());
  ASSERT_TRUE(eventually([&] {
    std::lock_guard lock(mutex);
    return order.size() == kN;
  }));
  std::lock_guard lock(mutex);
  EXPECT_GE(earliestNs, std::chrono::duration_cast<std::chrono::nanoseconds>(kDelay).count());
  // Back-to-back packets with 5 ms of uniform jitter overtake each other.
  EXPECT_FALSE(std::is_sorted(order.begin(), order.end()));
}

TEST(LinkEmulator, SameSeedSameFatesOtherSeedOtherFates) {
  dm::IoThread net;
  ASSERT_TRUE(net.start().ok());
  dm::LinkEmulatorOptions o{.jitter = 200us,
                            .jitterModel = dm::JitterModel::HalfNormal,
                            .lossProbability = 0.3,
                            .duplicateProbability = 0.2,
                            .reorderProbability = 0.2,
                            .reorderDelay = 300us,
                            .seed = 1234};
  const auto first = runEmulator(net, o, 1000);
  const auto second = runEmulator(net, o, 1000);
  o.seed = 4321;
  const auto other = runEmulator(net, o, 1000);
  EXPECT_EQ(first.first, second.first);
  EXPECT_EQ(first.second.lost, second.second.lost);
  EXPECT_EQ(first.second.reordered, second.second.reordered);
  EXPECT_NE(first.first, other.first);
}

TEST(LinkEmulator, CloseDiscardsAndCountsPendingDeliveries) {
  dm::IoThread net;
  ASSERT_TRUE(net.start().ok());
  std::atomic<int> delivered{0};
  auto link = dm::LinkEmulator::create(net, {.delay = 10s, .maxInFlight = 5},
                                       [&](std::span<const std::byte>) { ++delivered; });
  ASSERT_TRUE(link.ok());
  for (std::uint32_t i = 0; i < 5; ++i) ASSERT_TRUE((*link)->submit(stamped(i)).ok());
  EXPECT_EQ((*link)->submit(stamped(5)).error().code, dm::ErrorCode::Busy);
  (*link)->close();
  const auto s = (*link)->stats();
  EXPECT_EQ(s.discarded, 5u);
  EXPECT_EQ(s.refused, 1u);
  EXPECT_EQ(delivered.load(), 0);
  EXPECT_EQ((*link)->submit(stamped(6)).error().code, dm::ErrorCode::Network);
}

TEST(LinkEmulator, RejectsBadOptions) {
  dm::IoThread net;
  EXPECT_FALSE(dm::LinkEmulator::create(net, {.lossProbability = 1.5}, {}).ok());
  EXPECT_FALSE(dm::LinkEmulator::create(net, {.duplicateProbability = -0.1}, {}).ok());
  EXPECT_FALSE(dm::LinkEmulator::create(net, {.delay = -1ms}, {}).ok());
  EXPECT_FALSE(dm::LinkEmulator::create(net, {.maxInFlight = 0}, {}).ok());
  auto nanLoss = dm::LinkEmulator::create(net, {.lossProbability = std::nan("")}, {});
  ASSERT_FALSE(nanLoss.ok());
  EXPECT_NE(nanLoss.error().where.find("lossProbability"), std::string::npos);
}

}  // namespace
