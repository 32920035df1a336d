// Command channels (dm/network/command.hpp): authenticated commands and
// replies arrive; unsigned commands, wrong keys, replays on the same and on a
// new connection, and peers outside the allow-list are refused and counted.
// The replay tests speak the protocol by hand (deriveCommandSessionKey), so
// they also pin down the documented handshake.
#include <dm/network/auth.hpp>
#include <dm/network/command.hpp>
#include <dm/network/io_thread.hpp>
#include <dm/network/message.hpp>
#include <dm/network/tcp.hpp>

#include <gtest/gtest.h>

#include <chrono>
#include <cstring>
#include <mutex>
#include <string>
#include <vector>

#include "../common/eventually.hpp"

namespace {

using namespace std::chrono_literals;
using dm::test::eventually;

const std::string kKey = "000102030405060708090a0b0c0d0e0f101112131415161718191a1b1c1d1e1f";
const std::string kOtherKey = "ff0102030405060708090a0b0c0d0e0f101112131415161718191a1b1c1d1e1f";

std::vector<std::byte> bytes(const std::string& s) {
  std::vector<std::byte> b(s.size());
  std::memcpy(b.data(), s.data(), s.size());
  return b;
}
std::string text(std::span<const std::byte> b) { return {reinterpret_cast<const char*>(b.data()), b.size()}; }

/// What a command handler saw, thread-safe.
struct CommandInbox {
  std::mutex mutex;
  std::vector<std::pair<std::uint16_t, std::string>> items;
  std::vector<dm::ConnectionId> from;
  dm::CommandHandler handler() {
    return [this](const dm::Command& c) {
      std::lock_guard lock(mutex);
      items.emplace_back(c.header.type, text(c.payload));
      from.push_back(c.connection);
    };
  }
  std::size_t size() {
    std::lock_guard lock(mutex);
    return items.size();
  }
};

/// A raw TCP peer that collects the messages it receives.
struct RawPeer {
  std::mutex mutex;
  dm::MessageStreamDecoder decoder;
  std::vector<std::vector<std::byte>> payloads;
  std::vector<dm::MessageHeader> headers;
  std::unique_ptr<dm::TcpClient> client;

  RawPeer(dm::IoThread& net, std::uint16_t port) {
    auto c = dm::TcpClient::connect(net, {.peer = {"127.0.0.1", port}},
                                    {.onBytes = [this](std::span<const std::byte> b) {
                                      std::lock_guard lock(mutex);
                                      ASSERT_TRUE(decoder.feed(b));
                                      while (true) {
                                        auto m = decoder.next();
                                        ASSERT_TRUE(m);
                                        if (!*m) break;
                                        headers.push_back((**m).header);
                                        payloads.emplace_back((**m).payload.begin(), (**m).payload.end());
                                      }
                                    }});
    EXPECT_TRUE(c) << c.error();
    client = std::move(*c);
  }
  std::size_t received() {
    std::lock_guard lock(mutex);
    return payloads.size();
  }
};

/// Runs the client side of the handshake by hand on `peer`; returns the
/// session authenticator (sequence numbers are the caller's business).
dm::MessageAuthenticator handshake(RawPeer& peer, const std::string& keyHex) {
  EXPECT_TRUE(eventually([&] { return peer.received() >= 1; }));
  dm::CommandNonce serverNonce{}, clientNonce{};
  {
    std::lock_guard lock(peer.mutex);
    EXPECT_EQ(peer.headers[0].type, dm::kCommandHelloType);
    EXPECT_EQ(peer.payloads[0].size(), dm::kCommandNonceBytes);
    std::memcpy(serverNonce.data(), peer.payloads[0].data(), dm::kCommandNonceBytes);
  }
  for (std::size_t i = 0; i < clientNonce.size(); ++i) clientNonce[i] = std::byte(i * 7 + 1);
  auto key = dm::parseHexKey(keyHex);
  EXPECT_TRUE(key);
  auto sessionKey = dm::deriveCommandSessionKey(*key, serverNonce, clientNonce);
  EXPECT_TRUE(sessionKey);
  auto auth = dm::MessageAuthenticator::fromKey(*sessionKey);
  EXPECT_TRUE(auth);
  std::vector<std::byte> wire;
  EXPECT_TRUE(auth->sign({.type = dm::kCommandHelloReplyType, .sequence = 0}, clientNonce, wire));
  EXPECT_TRUE(peer.client->send(wire));
  return std::move(*auth);
}

struct Net {
  dm::IoThread net{"command-test"};
  Net() { EXPECT_TRUE(net.start()); }
};

}  // namespace

TEST(CommandChannel, AuthenticatedCommandsArriveInOrderAndRepliesComeBack) {
  Net n;
  CommandInbox commands, replies;
  std::unique_ptr<dm::CommandServer>* serverRef = nullptr;
  auto server = dm::CommandServer::listen(n.net, {.keyHex = kKey}, [&](const dm::Command& c) {
    commands.handler()(c);
    (void)(*serverRef)->reply(c.connection, 100, bytes("ack " + text(c.payload)));
  });
  ASSERT_TRUE(server) << server.error();
  serverRef = &*server;
  auto client = dm::CommandClient::connect(
      n.net, {.keyHex = kKey, .tcp = {.peer = {"127.0.0.1", (*server)->port()}}}, replies.handler());
  ASSERT_TRUE(client) << client.error();
  ASSERT_TRUE((*client)->waitReady(5s));
  for (int i = 0; i < 3; ++i)
    ASSERT_TRUE((*client)->send(std::uint16_t(7 + i), bytes("cmd" + std::to_string(i))));
  ASSERT_TRUE(eventually([&] { return replies.size() == 3; }));
  std::lock_guard lock(commands.mutex);
  ASSERT_EQ(commands.items.size(), 3u);
  for (int i = 0; i < 3; ++i) {
    EXPECT_EQ(commands.items[i].first, 7 + i);
    EXPECT_EQ(commands.items[i].second, "cmd" + std::to_string(i));
    EXPECT_EQ(replies.items[i].first, 100);
    EXPECT_EQ(replies.items[i].second, "ack cmd" + std::to_string(i));
  }
  EXPECT_EQ((*server)->stats().accepted, 3u);
  EXPECT_EQ((*server)->stats().handshakes, 1u);
  EXPECT_EQ((*server)->stats().refused(), 0u);
  EXPECT_EQ((*client)->stats().accepted, 3u);
  EXPECT_FALSE((*client)->send(dm::kCommandHelloType, {})) << "reserved types are refused";
}

TEST(CommandChannel, UnsignedCommandsAreRefused) {
  Net n;
  CommandInbox commands;
  auto server = dm::CommandServer::listen(n.net, {.keyHex = kKey}, commands.handler());
  ASSERT_TRUE(server) << server.error();
  RawPeer peer(n.net, (*server)->port());
  ASSERT_TRUE(peer.client->waitConnected(5s));
  // Before the handshake: refused, and the connection is closed.
  auto plain = dm::encodeMessage({.type = 1, .sequence = 1}, bytes("open valve"));
  ASSERT_TRUE(plain);
  ASSERT_TRUE(peer.client->send(*plain));
  ASSERT_TRUE(eventually([&] { return (*server)->stats().noTag == 1; }));
  // After a valid handshake: an unsigned command is refused, a signed one accepted.
  RawPeer second(n.net, (*server)->port());
  ASSERT_TRUE(second.client->waitConnected(5s));
  auto auth = handshake(second, kKey);
  ASSERT_TRUE(eventually([&] { return (*server)->stats().handshakes == 1; }));
  ASSERT_TRUE(second.client->send(*plain));
  std::vector<std::byte> wire;
  ASSERT_TRUE(auth.sign({.type = 2, .sequence = 1}, bytes("close valve"), wire));
  ASSERT_TRUE(second.client->send(wire));
  ASSERT_TRUE(eventually([&] { return commands.size() == 1; }));
  EXPECT_EQ((*server)->stats().noTag, 2u);
  std::lock_guard lock(commands.mutex);
  EXPECT_EQ(commands.items[0].second, "close valve");
}

TEST(CommandChannel, WrongKeyFailsTheHandshake) {
  Net n;
  CommandInbox commands;
  auto server = dm::CommandServer::listen(n.net, {.keyHex = kKey}, commands.handler());
  ASSERT_TRUE(server) << server.error();
  auto client = dm::CommandClient::connect(
      n.net, {.keyHex = kOtherKey, .tcp = {.peer = {"127.0.0.1", (*server)->port()}}}, {});
  ASSERT_TRUE(client) << client.error();
  ASSERT_TRUE(eventually([&] { return (*server)->stats().badTag >= 1; }));
  EXPECT_EQ((*server)->stats().handshakes, 0u);
  // The server closed the connection: nothing the client sends arrives.
  (void)(*client)->send(1, bytes("forged"));
  EXPECT_TRUE(eventually([&] { return (*client)->stats().accepted == 0 && !(*client)->waitReady(1ms); }));
  EXPECT_EQ(commands.size(), 0u);
  EXPECT_EQ((*server)->stats().accepted, 0u);
}

TEST(CommandChannel, ReplaysAreRefusedOnTheSameAndOnANewConnection) {
  Net n;
  CommandInbox commands;
  auto server = dm::CommandServer::listen(n.net, {.keyHex = kKey}, commands.handler());
  ASSERT_TRUE(server) << server.error();
  std::vector<std::byte> recorded;
  {
    RawPeer peer(n.net, (*server)->port());
    ASSERT_TRUE(peer.client->waitConnected(5s));
    auto auth = handshake(peer, kKey);
    ASSERT_TRUE(auth.sign({.type = 3, .sequence = 1}, bytes("cut"), recorded));
    ASSERT_TRUE(peer.client->send(recorded));
    ASSERT_TRUE(peer.client->send(recorded));  // the same bytes again
    std::vector<std::byte> late, next;
    ASSERT_TRUE(auth.sign({.type = 3, .sequence = 3}, bytes("three"), next));
    ASSERT_TRUE(auth.sign({.type = 3, .sequence = 2}, bytes("two"), late));
    ASSERT_TRUE(peer.client->send(next));
    ASSERT_TRUE(peer.client->send(late));  // reordered but new: accepted
    ASSERT_TRUE(eventually([&] { return commands.size() == 3; }));
    ASSERT_TRUE(eventually([&] { return (*server)->stats().replayed == 1; }));
  }
  // A recording replayed on a new connection fails: another session key.
  RawPeer attacker(n.net, (*server)->port());
  ASSERT_TRUE(attacker.client->waitConnected(5s));
  (void)handshake(attacker, kKey);
  ASSERT_TRUE(eventually([&] { return (*server)->stats().handshakes == 2; }));
  ASSERT_TRUE(attacker.client->send(recorded));
  ASSERT_TRUE(eventually([&] { return (*server)->stats().badTag == 1; }));
  EXPECT_EQ(commands.size(), 3u);
  std::lock_guard lock(commands.mutex);
  EXPECT_EQ(commands.items[1].second, "three");
  EXPECT_EQ(commands.items[2].second, "two");
}

TEST(CommandChannel, PeersOutsideTheAllowListAreRefused) {
  Net n;
  CommandInbox commands;
  auto server = dm::CommandServer::listen(n.net, {.keyHex = kKey, .tcp = {.allow = {"10.0.0.0/8"}}},
                                          commands.handler());
  ASSERT_TRUE(server) << server.error();
  auto client = dm::CommandClient::connect(
      n.net, {.keyHex = kKey, .tcp = {.peer = {"127.0.0.1", (*server)->port()}}}, {});
  ASSERT_TRUE(client) << client.error();
  ASSERT_TRUE(eventually([&] { return (*server)->stats().peersRefused >= 1; }));
  EXPECT_FALSE((*client)->waitReady(200ms));
  EXPECT_EQ(commands.size(), 0u);
}

TEST(CommandChannel, KeysAreRequiredUnlessTurnedOffAndThenPlainCommandsPass) {
  Net n;
  auto refused = dm::CommandServer::listen(n.net, {}, {});
  ASSERT_FALSE(refused);
  EXPECT_EQ(refused.error().code, dm::ErrorCode::InvalidArgument);
  EXPECT_NE(refused.error().message().find("keyHex"), std::string::npos) << refused.error().message();
  auto shortKey = dm::CommandServer::listen(n.net, {.keyHex = "abcd"}, {});
  ASSERT_FALSE(shortKey);
  EXPECT_NE(shortKey.error().message().find("keyHex"), std::string::npos) << shortKey.error().message();
  auto badDigit =
      dm::CommandClient::connect(n.net, {.keyHex = kKey.substr(0, 40) + "zz" + kKey.substr(42)}, {});
  ASSERT_FALSE(badDigit);
  EXPECT_NE(badDigit.error().message().find("offset 40"), std::string::npos) << badDigit.error().message();

  CommandInbox commands;
  auto open = dm::CommandServer::listen(n.net, {.requireAuth = false}, commands.handler());
  ASSERT_TRUE(open) << open.error();
  auto client = dm::CommandClient::connect(
      n.net, {.requireAuth = false, .tcp = {.peer = {"127.0.0.1", (*open)->port()}}}, {});
  ASSERT_TRUE(client) << client.error();
  ASSERT_TRUE((*client)->waitReady(5s));
  ASSERT_TRUE((*client)->send(5, bytes("home")));
  ASSERT_TRUE(eventually([&] { return commands.size() == 1; }));
  EXPECT_EQ((*open)->stats().handshakes, 0u);
}
