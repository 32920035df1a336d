// Tests of dm::IoThread and the TCP transports over real sockets on
// 127.0.0.1 with ephemeral ports. Every wait is bounded, so a failure shows
// as a failed expectation, never as a hung ctest.
#include <dm/network/io_thread.hpp>
#include <dm/network/tcp.hpp>

#include <gtest/gtest.h>

#include <netinet/in.h>
#include <pthread.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstring>
#include <map>
#include <mutex>
#include <random>
#include <thread>
#include <vector>

#include "../common/eventually.hpp"

namespace {

using namespace std::chrono_literals;

using dm::test::eventually;

std::vector<std::byte> randomPayload(std::mt19937& rng, std::size_t n) {
  std::vector<std::byte> v(n);
  for (auto& b : v) b = static_cast<std::byte>(rng() & 0xFF);
  return v;
}

/// Bytes received by one side, thread-safe.
struct Sink {
  std::mutex mutex;
  std::vector<std::byte> bytes;
  std::size_t chunks = 0;
  void add(std::span<const std::byte> b) {
    std::lock_guard lock(mutex);
    bytes.insert(bytes.end(), b.begin(), b.end());
    ++chunks;
  }
  std::size_t size() {
    std::lock_guard lock(mutex);
    return bytes.size();
  }
};

/// A server that sends back whatever it receives.
std::unique_ptr<dm::TcpServer> echoServer(dm::IoThread& net, std::uint16_t port = 0) {
  auto holder = std::make_shared<dm::TcpServer*>(nullptr);
  dm::TcpServerCallbacks cb;
  cb.onBytes = [holder](dm::ConnectionId id, std::span<const std::byte> b) {
    // On the network thread; the server outlives its callbacks.
    EXPECT_TRUE((*holder)->send(id, b).ok());
  };
  auto server = dm::TcpServer::listen(net, {.local = {"127.0.0.1", port}, .sendQueueBytes = 64 << 20}, cb);
  if (!server) {
    ADD_FAILURE() << server.error();
    return nullptr;
  }
  *holder = server->get();
  return std::move(*server);
}

TEST(IoThread, RunsPostedTasksInOrderOnANamedThread) {
  dm::IoThread net("dm-net-test");
  ASSERT_TRUE(net.start().ok());
  std::mutex mutex;
  std::vector<int> order;
  std::string name;
  bool onThread = false;
  for (int i = 0; i < 100; ++i)
    net.post([&, i] {
      std::lock_guard lock(mutex);
      order.push_back(i);
    });
  net.runAndWait([&] {
    char buffer[32] = {};
    pthread_getname_np(pthread_self(), buffer, sizeof buffer);
    name = buffer;
    onThread = net.onThread();
  });
  EXPECT_TRUE(eventually([&] {
    std::lock_guard lock(mutex);
    return order.size() == 100;
  }));
  std::vector<int> expected(100);
  for (int i = 0; i < 100; ++i) expected[i] = i;
  EXPECT_EQ(order, expected);
  EXPECT_EQ(name, "dm-net-test");
  EXPECT_TRUE(onThread);
  EXPECT_FALSE(net.onThread());
}

TEST(IoThread, StopReportsAndDiscardsQueuedTasks) {
  dm::IoThread net;
  ASSERT_TRUE(net.start().ok());
  std::atomic<bool> blockerRunning{false};
  std::atomic<int> ran{0};
  // The blocker holds the thread until stop() has been requested, so the ten
  // tasks behind it are certainly still queued when stop() looks.
  net.post([&] {
    blockerRunning = true;
    while (!net.stopRequested()) std::this_thread::sleep_for(1ms);
  });
  for (int i = 0; i < 10; ++i) net.post([&] { ++ran; });
  ASSERT_TRUE(eventually([&] { return blockerRunning.load(); }));
  const dm::IoStopReport report = net.stop();
  EXPECT_EQ(report.tasksDropped, 10u);
  EXPECT_EQ(ran.load(), 0);
  EXPECT_EQ(net.stats().tasksDropped, 10u);
  EXPECT_FALSE(net.running());

  // Restartable; tasks posted while stopped wait for the start.
  net.post([&] { ++ran; });
  ASSERT_TRUE(net.start().ok());
  EXPECT_TRUE(eventually([&] { return ran.load() == 1; }));
  EXPECT_EQ(net.stop().tasksDropped, 0u);
}

TEST(IoThread, ThrowingTaskIsCountedAndTheThreadGoesOn) {
  dm::IoThread net;
  ASSERT_TRUE(net.start().ok());
  std::atomic<bool> after{false};
  net.post([] { throw std::runtime_error("test exception"); });
  net.post([&] { after = true; });
  EXPECT_TRUE(eventually([&] { return after.load(); }));
  EXPECT_EQ(net.stats().tasksThrew, 1u);
}

TEST(IoThread, RunAndWaitRunsInlineWhileStopped) {
  dm::IoThread net;
  std::thread::id where;
  net.runAndWait([&] { where = std::this_thread::get_id(); });
  EXPECT_EQ(where, std::this_thread::get_id());
}

TEST(TcpEcho, RandomPayloadsOfManySizesArriveByteExactAndInOrder) {
  dm::IoThread net;
  ASSERT_TRUE(net.start().ok());
  auto server = echoServer(net);
  ASSERT_TRUE(server);
  Sink received;
  // A small receive buffer forces the echo to come back in many chunks with
  // boundaries unrelated to the sends.
  auto client = dm::TcpClient::connect(
      net, {.peer = {"127.0.0.1", server->port()}, .sendQueueBytes = 64 << 20, .readChunkBytes = 777},
      {.onBytes = [&](std::span<const std::byte> b) { received.add(b); }});
  ASSERT_TRUE(client.ok()) << client.error();
  ASSERT_TRUE((*client)->waitConnected(5s).ok());

  std::mt19937 rng(42);
  std::vector<std::byte> sent;
  std::size_t messages = 0;
  for (std::size_t size :
       {1u, 2u, 3u, 7u, 58u, 100u, 777u, 778u, 1000u, 1460u, 4096u, 65535u, 65536u, 300001u}) {
    for (int rep = 0; rep < 3; ++rep) {
      const auto payload = randomPayload(rng, size);
      ASSERT_TRUE((*client)->send(payload).ok());
      sent.insert(sent.end(), payload.begin(), payload.end());
      ++messages;
    }
  }
  ASSERT_TRUE(eventually([&] { return received.size() >= sent.size(); }, 10s))
      << received.size() << " of " << sent.size();
  {
    std::lock_guard lock(received.mutex);
    ASSERT_EQ(received.bytes.size(), sent.size());
    EXPECT_TRUE(received.bytes == sent);
    EXPECT_GT(received.chunks, sent.size() / 777);  // chunked by the 777-byte buffer
  }
  const dm::ConnectionStats s = (*client)->stats();
  EXPECT_EQ(s.bytesOut, sent.size());
  EXPECT_EQ(s.bytesIn, sent.size());
  EXPECT_EQ(s.messagesQueued, messages);
  EXPECT_EQ(s.queuedBytes, 0u);
  EXPECT_EQ(s.messagesDropped, 0u);
  const auto ids = server->connections();
  ASSERT_EQ(ids.size(), 1u);
  auto serverSide = server->stats(ids[0]);
  ASSERT_TRUE(serverSide.ok());
  EXPECT_EQ(serverSide->bytesIn, sent.size());
  EXPECT_EQ(serverSide->bytesOut, sent.size());
}

TEST(TcpServer, ServesManyClientsEachGetsItsOwnBytesBack) {
  dm::IoThread net;
  ASSERT_TRUE(net.start().ok());
  auto server = echoServer(net);
  ASSERT_TRUE(server);
  constexpr int kClients = 12;
  std::vector<Sink> sinks(kClients);
  std::vector<std::unique_ptr<dm::TcpClient>> clients;
  std::vector<std::vector<std::byte>> payloads;
  std::mt19937 rng(7);
  for (int i = 0; i < kClients; ++i) {
    auto c = dm::TcpClient::connect(net, {.peer = {"127.0.0.1", server->port()}},
                                    {.onBytes = [&, i](std::span<const std::byte> b) { sinks[i].add(b); }});
    ASSERT_TRUE(c.ok()) << c.error();
    clients.push_back(std::move(*c));
    payloads.push_back(randomPayload(rng, 1000 + 137 * i));
  }
  for (int i = 0; i < kClients; ++i) {
    ASSERT_TRUE(clients[i]->waitConnected(5s).ok());
    ASSERT_TRUE(clients[i]->send(payloads[i]).ok());
  }
  for (int i = 0; i < kClients; ++i) {
    ASSERT_TRUE(eventually([&] { return sinks[i].size() >= payloads[i].size(); })) << "client " << i;
    std::lock_guard lock(sinks[i].mutex);
    EXPECT_TRUE(sinks[i].bytes == payloads[i]) << "client " << i;
  }
  EXPECT_EQ(server->serverStats().accepted, static_cast<std::uint64_t>(kClients));
  EXPECT_EQ(server->serverStats().active, static_cast<std::uint64_t>(kClients));
}

TEST(TcpServer, ReportsEphemeralPortAndRefusesATakenOne) {
  dm::IoThread net;
  auto a = dm::TcpServer::listen(net, {}, {});
  ASSERT_TRUE(a.ok()) << a.error();
  EXPECT_NE((*a)->port(), 0);
  auto b = dm::TcpServer::listen(net, {.local = {"127.0.0.1", (*a)->port()}}, {});
  ASSERT_FALSE(b.ok());
  EXPECT_EQ(b.error().code, dm::ErrorCode::Network);
  auto c = dm::TcpServer::listen(net, {.local = {"localhost", 0}}, {});
  ASSERT_FALSE(c.ok());
  EXPECT_EQ(c.error().code, dm::ErrorCode::InvalidArgument);
}

TEST(TcpServer, DisconnectEventsReachBothSidesWithReasons) {
  dm::IoThread net;
  ASSERT_TRUE(net.start().ok());
  std::mutex mutex;
  std::vector<dm::ConnectionId> connected;
  std::vector<dm::DisconnectReason> ended;
  dm::SocketAddress peerSeen;
  auto server = dm::TcpServer::listen(net, {},
                                      {.onConnect =
                                           [&](dm::ConnectionId id, const dm::SocketAddress& peer) {
                                             std::lock_guard lock(mutex);
                                             connected.push_back(id);
                                             peerSeen = peer;
                                           },
                                       .onDisconnect =
                                           [&](dm::ConnectionId, const dm::Disconnect& d) {
                                             std::lock_guard lock(mutex);
                                             ended.push_back(d.reason);
                                           }});
  ASSERT_TRUE(server.ok());
  auto client = dm::TcpClient::connect(net, {.peer = {"127.0.0.1", (*server)->port()}}, {});
  ASSERT_TRUE(client.ok());
  ASSERT_TRUE((*client)->waitConnected(5s).ok());
  ASSERT_TRUE(eventually([&] {
    std::lock_guard lock(mutex);
    return connected.size() == 1;
  }));
  EXPECT_EQ(peerSeen.address, "127.0.0.1");
  EXPECT_NE(peerSeen.port, 0);
  (*client)->close();
  EXPECT_EQ((*client)->state(), dm::ConnectionState::Closed);
  ASSERT_TRUE(eventually([&] {
    std::lock_guard lock(mutex);
    return ended.size() == 1;
  }));
  EXPECT_EQ(ended[0], dm::DisconnectReason::PeerClosed);
  EXPECT_TRUE((*server)->connections().empty());
  EXPECT_EQ((*server)->send(connected[0], std::vector<std::byte>(4)).error().code, dm::ErrorCode::NotFound);
}

TEST(TcpClient, ReconnectsWhenTheServerComesBackOnTheSamePort) {
  dm::IoThread net;
  ASSERT_TRUE(net.start().ok());
  auto server = echoServer(net);
  ASSERT_TRUE(server);
  const std::uint16_t port = server->port();
  std::mutex mutex;
  std::vector<dm::ConnectionState> states;
  Sink received;
  auto client = dm::TcpClient::connect(net,
                                       {.peer = {"127.0.0.1", port},
                                        .reconnect = true,
                                        .reconnectInitialDelay = 10ms,
                                        .reconnectMaxDelay = 80ms},
                                       {.onState =
                                            [&](dm::ConnectionState s, const std::string&) {
                                              std::lock_guard lock(mutex);
                                              states.push_back(s);
                                            },
                                        .onBytes = [&](std::span<const std::byte> b) { received.add(b); }});
  ASSERT_TRUE(client.ok());
  ASSERT_TRUE((*client)->waitConnected(5s).ok());

  server->close();  // the client sees its connection end, then retries with back-off
  ASSERT_TRUE(eventually([&] { return (*client)->state() != dm::ConnectionState::Connected; }));
  EXPECT_FALSE((*client)->send(std::vector<std::byte>(3)).ok());
  std::this_thread::sleep_for(100ms);  // a few refused attempts while nobody listens
  EXPECT_NE((*client)->state(), dm::ConnectionState::Connected);
  server.reset();

  server = echoServer(net, port);
  ASSERT_TRUE(server);
  // Back-off is capped at 80 ms, so the next attempt comes well within this.
  ASSERT_TRUE((*client)->waitConnected(5s).ok());
  EXPECT_EQ((*client)->stats().reconnects, 1u);
  const std::vector<std::byte> hello{std::byte{1}, std::byte{2}, std::byte{3}};
  ASSERT_TRUE((*client)->send(hello).ok());
  ASSERT_TRUE(eventually([&] { return received.size() == 3; }));
  std::lock_guard lock(mutex);
  ASSERT_GE(states.size(), 4u);
  EXPECT_EQ(states.front(), dm::ConnectionState::Connecting);
  EXPECT_EQ(states[1], dm::ConnectionState::Connected);
  EXPECT_EQ(states[2], dm::ConnectionState::Backoff);
  EXPECT_EQ(states.back(), dm::ConnectionState::Connected);
}

TEST(TcpClient, RefusedConnectionWithoutReconnectEndsDisconnected) {
  dm::IoThread net;
  ASSERT_TRUE(net.start().ok());
  std::uint16_t port = 0;
  {
    auto probe = dm::TcpServer::listen(net, {}, {});  // a port that was just free
    ASSERT_TRUE(probe.ok());
    port = (*probe)->port();
  }
  std::mutex mutex;
  std::string lastDetail;
  auto client = dm::TcpClient::connect(net, {.peer = {"127.0.0.1", port}, .connectTimeout = 500ms},
                                       {.onState = [&](dm::ConnectionState, const std::string& d) {
                                         std::lock_guard lock(mutex);
                                         lastDetail = d;
                                       }});
  ASSERT_TRUE(client.ok());
  ASSERT_TRUE(eventually([&] { return (*client)->state() == dm::ConnectionState::Disconnected; }));
  auto waited = (*client)->waitConnected(10ms);
  ASSERT_FALSE(waited.ok());
  EXPECT_EQ(waited.error().code, dm::ErrorCode::Timeout);
  std::lock_guard lock(mutex);
  EXPECT_NE(lastDetail.find("refused"), std::string::npos) << lastDetail;
}

TEST(TcpClient, RejectsBadOptions) {
  dm::IoThread net;
  EXPECT_EQ(dm::TcpClient::connect(net, {.peer = {"127.0.0.1", 0}}, {}).error().code,
            dm::ErrorCode::InvalidArgument);
  EXPECT_EQ(
      dm::TcpClient::connect(
          net, {.peer = {"127.0.0.1", 9}, .reconnectInitialDelay = 100ms, .reconnectMaxDelay = 10ms}, {})
          .error()
          .code,
      dm::ErrorCode::InvalidArgument);
  EXPECT_EQ(dm::TcpClient::connect(net, {.peer = {"127.0.0.1", 9}, .sendQueueBytes = 0}, {}).error().code,
            dm::ErrorCode::InvalidArgument);
  EXPECT_EQ(dm::TcpClient::connect(net, {.peer = {"no-such-host.invalid", 9}}, {}).error().code,
            dm::ErrorCode::NotFound);
}

/// A listening socket whose connections are never accepted or read: the
/// kernel completes the handshake and then the window closes.
struct SilentListener {
  int fd = -1;
  std::uint16_t port = 0;
  SilentListener() {
    fd = ::socket(AF_INET, SOCK_STREAM, 0);
    int small = 4096;
    ::setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &small, sizeof small);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0 || ::listen(fd, 4) != 0) return;
    socklen_t len = sizeof a;
    ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len);
    port = ntohs(a.sin_port);
  }
  ~SilentListener() { ::close(fd); }
};

TEST(TcpClient, PeerThatDoesNotReadTurnsSendsBusyWithinTheQueueLimit) {
  dm::IoThread net;
  ASSERT_TRUE(net.start().ok());
  SilentListener peer;
  ASSERT_NE(peer.port, 0);
  constexpr std::size_t kLimit = 256 * 1024;
  std::mutex mutex;
  std::string closedDetail;
  auto client = dm::TcpClient::connect(net, {.peer = {"127.0.0.1", peer.port}, .sendQueueBytes = kLimit},
                                       {.onState = [&](dm::ConnectionState s, const std::string& d) {
                                         std::lock_guard lock(mutex);
                                         if (s == dm::ConnectionState::Closed) closedDetail = d;
                                       }});
  ASSERT_TRUE(client.ok());
  ASSERT_TRUE((*client)->waitConnected(5s).ok());
  const std::vector<std::byte> chunk(16 * 1024, std::byte{0x5A});
  std::uint64_t accepted = 0;
  bool busy = false;
  // The kernel's buffers take a few MB at most; after that the queue fills.
  // A refusal alone may only mean that the network thread has not run yet
  // (both cores busy): back-pressure is when the queue stays full once that
  // thread has had time to hand the kernel all it takes.
  for (int i = 0; i < 20000 && !busy; ++i) {
    dm::Status s = (*client)->send(chunk);
    if (s.ok()) {
      accepted += chunk.size();
      ASSERT_LE((*client)->stats().queuedBytes, kLimit);
    } else {
      ASSERT_EQ(s.error().code, dm::ErrorCode::Busy) << s.error();
      std::this_thread::sleep_for(20ms);
      busy = (*client)->stats().queuedBytes > kLimit - chunk.size();
    }
    if (i % 64 == 0) std::this_thread::sleep_for(1ms);  // let the network thread fill the kernel buffers
  }
  ASSERT_TRUE(busy) << accepted << " bytes accepted without back-pressure";
  const dm::ConnectionStats s = (*client)->stats();
  EXPECT_GE(s.messagesDropped, 1u);
  EXPECT_LE(s.queuedBytes, kLimit);
  EXPECT_GT(s.queuedBytes, kLimit - chunk.size() - 1);  // the refusal came because the queue was full
  EXPECT_EQ(s.bytesOut + s.queuedBytes, accepted);
  (*client)->close();
  std::lock_guard lock(mutex);
  EXPECT_NE(closedDetail.find("unsent bytes discarded"), std::string::npos) << closedDetail;
}

TEST(TcpServer, AllowListRefusesOtherPeersAndAdmitsListedOnes) {
  dm::IoThread net;
  ASSERT_TRUE(net.start().ok());
  std::atomic<int> connects{0};
  auto closedServer =
      dm::TcpServer::listen(net, {.allow = {"10.0.0.0/8", "192.168.1.7"}},
                            {.onConnect = [&](dm::ConnectionId, const dm::SocketAddress&) { ++connects; }});
  ASSERT_TRUE(closedServer.ok());
  std::atomic<bool> lost{false};
  auto refusedClient = dm::TcpClient::connect(net, {.peer = {"127.0.0.1", (*closedServer)->port()}},
                                              {.onState = [&](dm::ConnectionState s, const std::string&) {
                                                if (s == dm::ConnectionState::Disconnected) lost = true;
                                              }});
  ASSERT_TRUE(refusedClient.ok());
  // The kernel completes the handshake; the server then closes the socket.
  EXPECT_TRUE(eventually([&] { return lost.load(); }));
  EXPECT_TRUE(eventually([&] { return (*closedServer)->serverStats().refused == 1; }));
  EXPECT_EQ(connects.load(), 0);
  EXPECT_EQ((*closedServer)->serverStats().accepted, 0u);

  auto openServer =
      dm::TcpServer::listen(net, {.allow = {"10.0.0.0/8", "127.0.0.0/8"}},
                            {.onConnect = [&](dm::ConnectionId, const dm::SocketAddress&) { ++connects; }});
  ASSERT_TRUE(openServer.ok());
  auto admitted = dm::TcpClient::connect(net, {.peer = {"127.0.0.1", (*openServer)->port()}}, {});
  ASSERT_TRUE(admitted.ok());
  EXPECT_TRUE(eventually([&] { return connects.load() == 1; }));
  EXPECT_EQ((*openServer)->serverStats().refused, 0u);
}

TEST(TcpServer, BadAllowListEntryNamesItsIndex) {
  dm::IoThread net;
  for (const char* bad : {"10.0.0.0/33", "300.1.1.1", "10.0.0.0/x", "::1/129"}) {
    auto s = dm::TcpServer::listen(net, {.allow = {"127.0.0.1", bad}}, {});
    ASSERT_FALSE(s.ok()) << bad;
    EXPECT_EQ(s.error().code, dm::ErrorCode::InvalidArgument);
    EXPECT_NE(s.error().where.find("allow[1]"), std::string::npos) << s.error();
  }
}

TEST(TcpServer, CloseWithClientsConnectedReportsToBoth) {
  dm::IoThread net;
  ASSERT_TRUE(net.start().ok());
  std::atomic<int> serverSide{0};
  auto server =
      dm::TcpServer::listen(net, {}, {.onDisconnect = [&](dm::ConnectionId, const dm::Disconnect& d) {
                              EXPECT_EQ(d.reason, dm::DisconnectReason::LocalClose);
                              ++serverSide;
                            }});
  ASSERT_TRUE(server.ok());
  std::vector<std::unique_ptr<dm::TcpClient>> clients;
  for (int i = 0; i < 3; ++i) {
    auto c = dm::TcpClient::connect(net, {.peer = {"127.0.0.1", (*server)->port()}}, {});
    ASSERT_TRUE(c.ok());
    ASSERT_TRUE((*c)->waitConnected(5s).ok());
    clients.push_back(std::move(*c));
  }
  ASSERT_TRUE(eventually([&] { return (*server)->serverStats().active == 3; }));
  (*server)->close();
  EXPECT_EQ(serverSide.load(), 3);  // reported before close() returned
  for (auto& c : clients)
    EXPECT_TRUE(eventually([&] { return c->state() == dm::ConnectionState::Disconnected; }));
}

}  // namespace
