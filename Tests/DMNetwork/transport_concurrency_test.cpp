// Concurrency tests of the transports (run under ThreadSanitizer in CI):
// many threads sending on one connection, start/stop races on the network
// thread, connections coming and going while the server sends.
#include <dm/network/io_thread.hpp>
#include <dm/network/tcp.hpp>

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cstring>
#include <map>
#include <mutex>
#include <thread>
#include <vector>

#include "../common/eventually.hpp"

namespace {

using namespace std::chrono_literals;

template <class F>
bool eventuallyWithin10s(F&& done) {
  return dm::test::eventually(done, 10000ms);
}

/// Frame: u32 payload length, u32 sender, u32 sequence, then `length`
/// payload bytes each equal to (sender + sequence + i) mod 251.
std::vector<std::byte> frame(std::uint32_t sender, std::uint32_t sequence, std::uint32_t length) {
  std::vector<std::byte> f(12 + length);
  std::memcpy(f.data(), &length, 4);
  std::memcpy(f.data() + 4, &sender, 4);
  std::memcpy(f.data() + 8, &sequence, 4);
  for (std::uint32_t i = 0; i < length; ++i)
    f[12 + i] = static_cast<std::byte>((sender + sequence + i) % 251);
  return f;
}

/// Reassembles frames from arbitrary chunks and checks each one.
struct FrameChecker {
  std::vector<std::byte> pending;
  std::map<std::uint32_t, std::uint32_t> nextSequence;  // per sender
  std::atomic<std::uint64_t> frames{0};
  std::atomic<std::uint64_t> corrupt{0};

  void feed(std::span<const std::byte> bytes) {  // network thread only
    pending.insert(pending.end(), bytes.begin(), bytes.end());
    std::size_t at = 0;
    while (pending.size() - at >= 12) {
      std::uint32_t length = 0, sender = 0, sequence = 0;
      std::memcpy(&length, pending.data() + at, 4);
      std::memcpy(&sender, pending.data() + at + 4, 4);
      std::memcpy(&sequence, pending.data() + at + 8, 4);
      if (pending.size() - at < 12 + std::size_t{length}) break;
      bool ok = nextSequence[sender] == sequence;  // each sender's frames in its order
      for (std::uint32_t i = 0; i < length && ok; ++i)
        ok = pending[at + 12 + i] == static_cast<std::byte>((sender + sequence + i) % 251);
      if (!ok) ++corrupt;
      nextSequence[sender] = sequence + 1;
      ++frames;
      at += 12 + length;
    }
    pending.erase(pending.begin(), pending.begin() + static_cast<std::ptrdiff_t>(at));
  }
};

TEST(TransportConcurrency, ThreadsSendingOnOneConnectionInterleaveWholeFrames) {
  dm::IoThread net;
  ASSERT_TRUE(net.start().ok());
  FrameChecker checker;
  auto server = dm::TcpServer::listen(
      net, {}, {.onBytes = [&](dm::ConnectionId, std::span<const std::byte> b) { checker.feed(b); }});
  ASSERT_TRUE(server.ok());
  // A small queue so that the senders also meet back-pressure and retry.
  auto client = dm::TcpClient::connect(
      net, {.peer = {"127.0.0.1", (*server)->port()}, .sendQueueBytes = 64 * 1024}, {});
  ASSERT_TRUE(client.ok());
  ASSERT_TRUE((*client)->waitConnected(5s).ok());

  constexpr std::uint32_t kThreads = 6, kFrames = 400;
  std::atomic<std::uint64_t> busy{0}, failed{0};
  std::vector<std::thread> senders;
  for (std::uint32_t t = 0; t < kThreads; ++t)
    senders.emplace_back([&, t] {
      for (std::uint32_t s = 0; s < kFrames; ++s) {
        const auto f = frame(t, s, (s * 37 + t * 11) % 3000);
        for (int attempt = 0;; ++attempt) {
          dm::Status st = (*client)->send(f);
          if (st.ok()) break;
          if (st.error().code != dm::ErrorCode::Busy || attempt > 100000) {
            ++failed;
            return;
          }
          ++busy;
          std::this_thread::sleep_for(50us);
        }
      }
    });
  for (auto& t : senders) t.join();
  EXPECT_EQ(failed.load(), 0u);
  ASSERT_TRUE(eventuallyWithin10s([&] { return checker.frames.load() == kThreads * kFrames; }))
      << checker.frames.load() << " frames";
  EXPECT_EQ(checker.corrupt.load(), 0u);
  const dm::ConnectionStats s = (*client)->stats();
  EXPECT_EQ(s.messagesQueued, kThreads * kFrames);
  EXPECT_EQ(s.messagesDropped, busy.load());
  (*server)->close();  // the checker is used by the server's callbacks: stop them first
}

TEST(TransportConcurrency, StartStopAndPostRacesLoseNoTaskSilently) {
  dm::IoThread net;
  std::atomic<std::uint64_t> posted{0}, ran{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t)
    threads.emplace_back([&, t] {
      for (int i = 0; i < 40; ++i) {
        if ((i + t) % 2 == 0) {
          EXPECT_TRUE(net.start().ok());
        } else {
          (void)net.stop();
        }
        for (int k = 0; k < 20; ++k) {
          net.post([&] { ran.fetch_add(1); });
          posted.fetch_add(1);
        }
      }
    });
  for (auto& t : threads) t.join();
  ASSERT_TRUE(net.start().ok());
  (void)net.stop();
  const dm::IoThreadStats s = net.stats();
  EXPECT_EQ(s.tasksRun, ran.load());
  EXPECT_EQ(s.tasksRun + s.tasksDropped, posted.load());
}

TEST(TransportConcurrency, ServerSendsWhileClientsComeAndGo) {
  dm::IoThread net;
  ASSERT_TRUE(net.start().ok());
  std::atomic<int> connects{0}, disconnects{0};
  auto server = dm::TcpServer::listen(
      net, {},
      {.onConnect = [&](dm::ConnectionId, const dm::SocketAddress&) { ++connects; },
       .onDisconnect = [&](dm::ConnectionId, const dm::Disconnect&) { ++disconnects; }});
  ASSERT_TRUE(server.ok());
  std::atomic<bool> stop{false};
  std::atomic<std::uint64_t> unexpected{0};
  std::thread broadcaster([&] {
    const std::vector<std::byte> ping(100, std::byte{7});
    while (!stop.load()) {
      for (dm::ConnectionId id : (*server)->connections()) {
        dm::Status s = (*server)->send(id, ping);
        // A connection may end between connections() and send().
        if (!s.ok() && s.error().code != dm::ErrorCode::NotFound &&
            s.error().code != dm::ErrorCode::Network && s.error().code != dm::ErrorCode::Busy)
          ++unexpected;
      }
      std::this_thread::yield();
    }
  });
  std::vector<std::thread> churn;
  std::atomic<std::uint64_t> bytes{0};
  for (int t = 0; t < 3; ++t)
    churn.emplace_back([&] {
      for (int i = 0; i < 15; ++i) {
        auto c =
            dm::TcpClient::connect(net, {.peer = {"127.0.0.1", (*server)->port()}},
                                   {.onBytes = [&](std::span<const std::byte> b) { bytes += b.size(); }});
        if (!c.ok() || !(*c)->waitConnected(5s).ok()) {
          ++unexpected;
          continue;
        }
        std::this_thread::sleep_for(1ms);
      }  // each client is closed by its destructor, racing the broadcaster
    });
  for (auto& t : churn) t.join();
  ASSERT_TRUE(eventuallyWithin10s([&] { return disconnects.load() == connects.load(); }));
  stop = true;
  broadcaster.join();
  EXPECT_EQ(unexpected.load(), 0u);
  EXPECT_EQ(connects.load(), 45);
  (*server)->close();
}

TEST(TransportConcurrency, ClosingAClientFromAnotherThreadWhileItReconnects) {
  dm::IoThread net;
  ASSERT_TRUE(net.start().ok());
  std::uint16_t port = 0;
  {
    auto probe = dm::TcpServer::listen(net, {}, {});
    ASSERT_TRUE(probe.ok());
    port = (*probe)->port();
  }
  for (int round = 0; round < 20; ++round) {
    std::atomic<int> afterClose{0};
    std::atomic<bool> closed{false};
    auto c = dm::TcpClient::connect(net,
                                    {.peer = {"127.0.0.1", port},
                                     .reconnect = true,
                                     .reconnectInitialDelay = 1ms,
                                     .reconnectMaxDelay = 2ms},
                                    {.onState = [&](dm::ConnectionState s, const std::string&) {
                                      if (closed.load() && s != dm::ConnectionState::Closed) ++afterClose;
                                    }});
    ASSERT_TRUE(c.ok());
    std::this_thread::sleep_for(std::chrono::microseconds(200 * round));
    std::thread closer([&] {
      (*c)->close();
      closed = true;
    });
    closer.join();
    std::this_thread::sleep_for(3ms);
    EXPECT_EQ(afterClose.load(), 0);
    EXPECT_EQ((*c)->state(), dm::ConnectionState::Closed);
  }
}

}  // namespace
