// net_igtl_session_bench — OpenIGTLink TRANSFORM messages per second through
// a session over loopback TCP, ours against the reference library
// (OpenIGTLink 1.11), in one process:
//  * ours: a sender thread encodes each TRANSFORM into a reused buffer
//    (igtl::appendTransform) and hands it to an IgtlClient (its network
//    thread writes the socket); an IgtlServer on another network thread
//    frames the stream, checks each CRC-64 and decodes it to an Affine3 for
//    its onTransform handler;
//  * reference: igtl::TransformMessage::Pack + ClientSocket::Send from the
//    sender thread; a receiver thread reads the header and body from the
//    ServerSocket connection, Unpack(1) (CRC checked), GetMatrix.
// The clock runs from the first send to the last message decoded. Prints
// messages per second (best of 3 rounds) and ours/reference.
//
//   build/Bench/net_igtl_session_bench [messages per round, default 200000]
#include <dm/network/igtl_session.hpp>

#include <igtlClientSocket.h>
#include <igtlMessageHeader.h>
#include <igtlServerSocket.h>
#include <igtlTransformMessage.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <thread>
#include <vector>

namespace {

using Clock = std::chrono::steady_clock;

double ours(int n) {
  dm::IoThread serverNet("bench-igtl-srv"), clientNet("bench-igtl-cli");
  if (!serverNet.start() || !clientNet.start()) std::abort();
  std::atomic<int> decoded{0};
  std::atomic<double> sink{0.0};
  dm::IgtlHandlers handlers;
  handlers.onTransform = [&](dm::ConnectionId, const dm::igtl::MessageView&, const dm::Affine3& t) {
    sink.store(t.translation().x(), std::memory_order_relaxed);
    decoded.fetch_add(1, std::memory_order_release);
  };
  auto server = dm::IgtlServer::listen(serverNet, {.tcp = {.local = {"127.0.0.1", 0}}}, handlers);
  if (!server) std::abort();
  dm::IgtlClientOptions options;
  options.tcp.peer = {"127.0.0.1", (*server)->port()};
  options.tcp.sendQueueBytes = std::size_t{8} << 20;
  auto client = dm::IgtlClient::connect(clientNet, options, {});
  if (!client || !(*client)->waitConnected(std::chrono::seconds(2))) std::abort();
  const dm::igtl::Envelope env{.deviceName = "Tracker"};
  dm::Affine3 pose = dm::Affine3::Identity();
  std::vector<std::byte> buffer;
  const auto t0 = Clock::now();
  for (int i = 0; i < n; ++i) {
    pose.translation().x() = 1e-6 * i;
    buffer.clear();
    if (!dm::igtl::appendTransform(env, pose, buffer)) std::abort();
    while (true) {
      const dm::Status s = (*client)->send(buffer);
      if (s) break;
      if (s.error().code != dm::ErrorCode::Busy) std::abort();
      std::this_thread::yield();  // back-pressure: the queue is full, the socket drains it
    }
  }
  while (decoded.load(std::memory_order_acquire) < n) std::this_thread::yield();
  const double seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  client->reset();
  server->reset();
  return n / seconds;
}

double reference(int n) {
  auto serverSocket = igtl::ServerSocket::New();
  if (serverSocket->CreateServer(0) != 0) std::abort();
  const int port = serverSocket->GetServerPort();
  std::atomic<int> decoded{0};
  std::atomic<double> sink{0.0};
  std::thread receiver([&] {
    igtl::ClientSocket::Pointer s = serverSocket->WaitForConnection(5000);
    if (!s) std::abort();
    auto header = igtl::MessageHeader::New();
    auto body = igtl::TransformMessage::New();
    for (int i = 0; i < n; ++i) {
      header->InitPack();
      if (s->Receive(header->GetPackPointer(), header->GetPackSize()) != header->GetPackSize()) std::abort();
      header->Unpack();
      body->SetMessageHeader(header);
      body->AllocatePack();
      if (s->Receive(body->GetPackBodyPointer(), body->GetPackBodySize()) != body->GetPackBodySize()) std::abort();
      if ((body->Unpack(1) & igtl::MessageHeader::UNPACK_BODY) == 0) std::abort();
      igtl::Matrix4x4 m;
      body->GetMatrix(m);
      sink.store(m[0][3], std::memory_order_relaxed);
      decoded.fetch_add(1, std::memory_order_release);
    }
    s->CloseSocket();
  });
  auto client = igtl::ClientSocket::New();
  if (client->ConnectToServer("127.0.0.1", port) != 0) std::abort();
  auto tx = igtl::TransformMessage::New();
  tx->SetDeviceName("Tracker");
  igtl::Matrix4x4 m;
  igtl::IdentityMatrix(m);
  const auto t0 = Clock::now();
  for (int i = 0; i < n; ++i) {
    m[0][3] = 1e-3f * static_cast<float>(i);
    tx->SetMatrix(m);
    tx->Pack();
    if (client->Send(tx->GetPackPointer(), tx->GetPackSize()) == 0) std::abort();
  }
  receiver.join();
  const double seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  client->CloseSocket();
  serverSocket->CloseSocket();
  return n / seconds;
}

}  // namespace

int main(int argc, char** argv) {
  const int n = argc > 1 ? std::atoi(argv[1]) : 200000;
  if (n <= 0) {
    std::fprintf(stderr, "usage: net_igtl_session_bench [messages per round > 0]\n");
    return 2;
  }
  double bestOurs = 0, bestRef = 0;
  for (int round = 0; round < 3; ++round) {
    bestRef = std::max(bestRef, reference(n));
    bestOurs = std::max(bestOurs, ours(n));
  }
  std::printf("OpenIGTLink TRANSFORM through a loopback TCP session, %d messages, best of 3 rounds\n", n);
  std::printf("%-34s %14s\n", "", "messages/s");
  std::printf("%-34s %14.0f\n", "reference (ClientSocket -> Unpack)", bestRef);
  std::printf("%-34s %14.0f\n", "DM::Network (IgtlClient -> Server)", bestOurs);
  std::printf("ratio ours/reference: %.2f\n", bestOurs / bestRef);
  return 0;
}
