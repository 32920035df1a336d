// net_tcp_bench — round-trip latency of small messages over loopback TCP:
// DM::Network (TcpClient -> TcpServer echo, each on its own network thread)
// against the reference OpenIGTLink 1.11 blocking sockets doing the same.
// Prints median / p99 / max in microseconds and the ratio ours / reference.
// Links DM::Network and OpenIGTLink (include dir /usr/include/openigtlink).
#include <dm/network/io_thread.hpp>
#include <dm/network/tcp.hpp>

#include <igtlClientSocket.h>
#include <igtlServerSocket.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <thread>
#include <vector>

namespace {

using Clock = std::chrono::steady_clock;
constexpr int kRounds = 5000;
constexpr int kWarmup = 200;
constexpr std::size_t kBytes = 64;  // a haptic state packet

struct Summary {
  double median, p99, max;
};

Summary summarize(std::vector<double> us) {
  std::sort(us.begin(), us.end());
  return {us[us.size() / 2], us[us.size() * 99 / 100], us.back()};
}

bool runOurs(Summary& out) {
  dm::IoThread serverThread("bench-server"), clientThread("bench-client");
  if (!serverThread.start() || !clientThread.start()) return false;
  dm::TcpServer* serverRaw = nullptr;
  auto server = dm::TcpServer::listen(
      serverThread, {}, {.onBytes = [&](dm::ConnectionId id, auto b) { (void)serverRaw->send(id, b); }});
  if (!server) return false;
  serverRaw = server->get();
  std::atomic<std::size_t> received{0};
  auto client = dm::TcpClient::connect(clientThread, {.peer = {"127.0.0.1", (*server)->port()}},
                                       {.onBytes = [&](auto b) { received.fetch_add(b.size()); }});
  if (!client || !(*client)->waitConnected(std::chrono::seconds(5))) return false;
  const std::vector<std::byte> packet(kBytes, std::byte{0x42});
  std::vector<double> us;
  std::size_t expected = 0;
  for (int i = 0; i < kRounds + kWarmup; ++i) {
    const auto t0 = Clock::now();
    if (!(*client)->send(packet)) return false;
    expected += kBytes;
    while (received.load() < expected) {
    }
    if (i >= kWarmup) us.push_back(std::chrono::duration<double, std::micro>(Clock::now() - t0).count());
  }
  out = summarize(std::move(us));
  (*client)->close();
  (*server)->close();
  return true;
}

bool runReference(Summary& out) {
  auto listener = igtl::ServerSocket::New();
  if (listener->CreateServer(0) != 0) return false;
  const int port = listener->GetServerPort();
  std::thread echo([&] {
    igtl::ClientSocket::Pointer s = listener->WaitForConnection(5000);
    if (!s) return;
    char buffer[kBytes];
    for (int i = 0; i < kRounds + kWarmup; ++i) {
      if (s->Receive(buffer, kBytes) != static_cast<int>(kBytes)) return;
      if (s->Send(buffer, kBytes) != 1) return;
    }
  });
  auto client = igtl::ClientSocket::New();
  if (client->ConnectToServer("127.0.0.1", port) != 0) {
    echo.join();
    return false;
  }
  char packet[kBytes] = {};
  std::vector<double> us;
  bool ok = true;
  for (int i = 0; i < kRounds + kWarmup && ok; ++i) {
    const auto t0 = Clock::now();
    ok = client->Send(packet, kBytes) == 1 && client->Receive(packet, kBytes) == static_cast<int>(kBytes);
    if (i >= kWarmup) us.push_back(std::chrono::duration<double, std::micro>(Clock::now() - t0).count());
  }
  echo.join();
  client->CloseSocket();
  listener->CloseSocket();
  out = summarize(std::move(us));
  return ok;
}

}  // namespace

int main() {
  Summary ours{}, reference{};
  if (!runOurs(ours)) {
    std::fprintf(stderr, "DM::Network run failed\n");
    return 1;
  }
  if (!runReference(reference)) {
    std::fprintf(stderr, "OpenIGTLink run failed\n");
    return 1;
  }
  std::printf("TCP loopback round trip, %zu-byte messages, %d rounds (us)\n", kBytes, kRounds);
  std::printf("%-28s %9s %9s %9s\n", "", "median", "p99", "max");
  std::printf("%-28s %9.1f %9.1f %9.1f\n", "DM::Network (async, 2 thr)", ours.median, ours.p99, ours.max);
  std::printf("%-28s %9.1f %9.1f %9.1f\n", "OpenIGTLink (blocking)", reference.median, reference.p99,
              reference.max);
  std::printf("ratio ours/reference: median %.2f, p99 %.2f\n", ours.median / reference.median,
              ours.p99 / reference.p99);
  return 0;
}
