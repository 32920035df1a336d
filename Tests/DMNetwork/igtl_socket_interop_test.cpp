// Byte-level interoperability of the TCP transports with the reference
// OpenIGTLink 1.11 sockets: messages packed by the reference library travel
// through our TcpClient / TcpServer and unpack (CRC checked) on the other
// side, in both directions. Decoding with our own codec is tested elsewhere.
#include <dm/network/io_thread.hpp>
#include <dm/network/tcp.hpp>

#include <gtest/gtest.h>

#include <igtlClientSocket.h>
#include <igtlMessageHeader.h>
#include <igtlServerSocket.h>
#include <igtlStringMessage.h>
#include <igtlTransformMessage.h>
#include <igtl_header.h>

#include <atomic>
#include <chrono>
#include <cstring>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "../common/eventually.hpp"

namespace {

using namespace std::chrono_literals;

using dm::test::eventually;

igtl::StringMessage::Pointer packedString(const char* device, const std::string& text) {
  auto m = igtl::StringMessage::New();
  m->SetDeviceName(device);
  m->SetString(text.c_str());
  m->Pack();
  return m;
}

std::span<const std::byte> bytesOf(igtl::MessageBase* m) {
  return {static_cast<const std::byte*>(m->GetPackPointer()), static_cast<std::size_t>(m->GetPackSize())};
}

/// Reads one STRING message from a reference socket (bounded by its receive
/// timeout); empty on failure. The CRC is checked by Unpack(1).
std::string receiveString(igtl::Socket* socket, std::string* device) {
  auto header = igtl::MessageHeader::New();
  header->InitPack();
  if (socket->Receive(header->GetPackPointer(), header->GetPackSize()) != header->GetPackSize()) return {};
  header->Unpack();
  if (std::string(header->GetDeviceType()) != "STRING") return {};
  auto body = igtl::StringMessage::New();
  body->SetMessageHeader(header);
  body->AllocatePack();
  if (socket->Receive(body->GetPackBodyPointer(), body->GetPackBodySize()) != body->GetPackBodySize())
    return {};
  if ((body->Unpack(1) & igtl::MessageHeader::UNPACK_BODY) == 0) return {};
  if (device) *device = header->GetDeviceName();
  return body->GetString();
}

/// Splits a byte stream of OpenIGTLink messages with the reference header
/// parser; returns the STRING bodies in order (CRC checked), "" for others.
std::vector<std::string> unpackStream(const std::vector<std::byte>& stream, std::size_t* consumed) {
  std::vector<std::string> out;
  std::size_t at = 0;
  while (stream.size() - at >= IGTL_HEADER_SIZE) {
    auto header = igtl::MessageHeader::New();
    header->InitPack();
    std::memcpy(header->GetPackPointer(), stream.data() + at, IGTL_HEADER_SIZE);
    header->Unpack();
    const std::size_t bodySize = static_cast<std::size_t>(header->GetBodySizeToRead());
    if (stream.size() - at - IGTL_HEADER_SIZE < bodySize) break;
    if (std::string(header->GetDeviceType()) == "STRING") {
      auto body = igtl::StringMessage::New();
      body->SetMessageHeader(header);
      body->AllocatePack();
      std::memcpy(body->GetPackBodyPointer(), stream.data() + at + IGTL_HEADER_SIZE, bodySize);
      out.push_back((body->Unpack(1) & igtl::MessageHeader::UNPACK_BODY) ? body->GetString() : "<bad crc>");
    } else {
      auto body = igtl::TransformMessage::New();
      body->SetMessageHeader(header);
      body->AllocatePack();
      std::memcpy(body->GetPackBodyPointer(), stream.data() + at + IGTL_HEADER_SIZE, bodySize);
      out.push_back((body->Unpack(1) & igtl::MessageHeader::UNPACK_BODY) ? "" : "<bad crc>");
    }
    at += IGTL_HEADER_SIZE + bodySize;
  }
  if (consumed) *consumed = at;
  return out;
}

TEST(IgtlSocketInterop, OurClientDeliversAReferencePackedMessageToTheReferenceServer) {
  auto referenceServer = igtl::ServerSocket::New();
  ASSERT_EQ(referenceServer->CreateServer(0), 0);
  const int port = referenceServer->GetServerPort();
  ASSERT_GT(port, 0);

  std::string received, device, replyStatus;
  std::thread reference([&] {
    igtl::ClientSocket::Pointer socket = referenceServer->WaitForConnection(5000);
    if (!socket) return;
    socket->SetReceiveTimeout(5000);
    received = receiveString(socket, &device);
    // And back: a reference-packed reply to our client.
    auto reply = packedString("reference", "reply from OpenIGTLink");
    replyStatus = socket->Send(reply->GetPackPointer(), reply->GetPackSize()) == 1 ? "sent" : "failed";
    std::this_thread::sleep_for(50ms);  // let the bytes leave before closing
    socket->CloseSocket();
  });

  dm::IoThread net;
  ASSERT_TRUE(net.start().ok());
  std::mutex mutex;
  std::vector<std::byte> fromReference;
  auto client = dm::TcpClient::connect(net, {.peer = {"127.0.0.1", static_cast<std::uint16_t>(port)}},
                                       {.onBytes = [&](std::span<const std::byte> b) {
                                         std::lock_guard lock(mutex);
                                         fromReference.insert(fromReference.end(), b.begin(), b.end());
                                       }});
  ASSERT_TRUE(client.ok());
  ASSERT_TRUE((*client)->waitConnected(5s).ok());
  const std::string text = "DMPlatform -> OpenIGTLink: " + std::string(3000, 'x') + " end";
  auto message = packedString("dm-test", text);
  ASSERT_TRUE((*client)->send(bytesOf(message)).ok());
  reference.join();
  referenceServer->CloseSocket();

  EXPECT_EQ(received, text);
  EXPECT_EQ(device, "dm-test");
  EXPECT_EQ(replyStatus, "sent");
  auto reply = packedString("reference", "reply from OpenIGTLink");
  ASSERT_TRUE(eventually([&] {
    std::lock_guard lock(mutex);
    return fromReference.size() >= static_cast<std::size_t>(reply->GetPackSize());
  }));
  std::lock_guard lock(mutex);
  std::size_t consumed = 0;
  const auto strings = unpackStream(fromReference, &consumed);
  ASSERT_EQ(strings.size(), 1u);
  EXPECT_EQ(strings[0], "reply from OpenIGTLink");
  EXPECT_EQ(consumed, fromReference.size());
}

TEST(IgtlSocketInterop, ReferenceClientBytesArriveIntactAtOurServer) {
  dm::IoThread net;
  ASSERT_TRUE(net.start().ok());
  std::mutex mutex;
  std::vector<std::byte> stream;
  auto server =
      dm::TcpServer::listen(net, {}, {.onBytes = [&](dm::ConnectionId, std::span<const std::byte> b) {
                              std::lock_guard lock(mutex);
                              stream.insert(stream.end(), b.begin(), b.end());
                            }});
  ASSERT_TRUE(server.ok());

  auto referenceClient = igtl::ClientSocket::New();
  ASSERT_EQ(referenceClient->ConnectToServer("127.0.0.1", (*server)->port()), 0);
  referenceClient->SetReceiveTimeout(5000);

  // A mix of messages, packed and sent by the reference library.
  std::vector<std::byte> expected;
  std::vector<std::string> texts;
  for (int i = 0; i < 20; ++i) {
    if (i % 5 == 4) {
      auto t = igtl::TransformMessage::New();
      t->SetDeviceName("tool");
      igtl::Matrix4x4 m;
      igtl::IdentityMatrix(m);
      m[0][3] = static_cast<float>(i);
      t->SetMatrix(m);
      t->Pack();
      ASSERT_EQ(referenceClient->Send(t->GetPackPointer(), t->GetPackSize()), 1);
      const auto b = bytesOf(t);
      expected.insert(expected.end(), b.begin(), b.end());
      texts.push_back("");
    } else {
      texts.push_back("message " + std::to_string(i) + std::string(static_cast<std::size_t>(i * 97), '#'));
      auto s = packedString("console", texts.back());
      ASSERT_EQ(referenceClient->Send(s->GetPackPointer(), s->GetPackSize()), 1);
      const auto b = bytesOf(s);
      expected.insert(expected.end(), b.begin(), b.end());
    }
  }
  ASSERT_TRUE(eventually([&] {
    std::lock_guard lock(mutex);
    return stream.size() >= expected.size();
  }));
  {
    std::lock_guard lock(mutex);
    EXPECT_TRUE(stream == expected);  // byte-identical
    std::size_t consumed = 0;
    EXPECT_EQ(unpackStream(stream, &consumed), texts);
    EXPECT_EQ(consumed, stream.size());
  }

  // Our server answers; the reference client unpacks it.
  const auto ids = (*server)->connections();
  ASSERT_EQ(ids.size(), 1u);
  auto answer = packedString("dm-server", "answer from DMPlatform");
  ASSERT_TRUE((*server)->send(ids[0], bytesOf(answer)).ok());
  std::string device;
  EXPECT_EQ(receiveString(referenceClient, &device), "answer from DMPlatform");
  EXPECT_EQ(device, "dm-server");
  referenceClient->CloseSocket();
}

}  // namespace
