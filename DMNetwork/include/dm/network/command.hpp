// dm/network/command.hpp — command channels over TCP that can require a
// shared-secret authentication and a peer allow-list.
//
// A CommandServer receives commands (a type and a payload in the message
// model of dm/network/message.hpp) and may answer them; a CommandClient
// sends them and receives the answers. With a key, every message is signed
// with HMAC-SHA-256 (dm/network/auth.hpp) under a per-connection session key
// and replay-protected by its sequence number; messages without a valid tag,
// replays and messages from peers outside the allow-list are refused, logged
// with the reason and counted, and never reach the handler.
//
// Handshake (with a key). Sequence numbers alone cannot stop an attacker
// from replaying a recorded conversation on a new connection, so each
// connection gets its own key:
//   1. server → client  type 0xFFF0, payload Ns (16 random bytes), unsigned
//   2. client → server  type 0xFFF1, sequence 0, payload Nc (16 random
//      bytes), signed with the session key
//        Ks = HMAC-SHA-256(K, "DMNM session v1" ‖ Ns ‖ Nc)
//   3. every further message in both directions is signed with Ks; each
//      side refuses sequence numbers it has seen (SequenceTracker).
// A wrong key fails step 2: the server refuses it and closes the connection.
// Application command types are 0 .. 0xFFEF. Without a key (requireAuth
// false) messages pass unsigned and there is no handshake.
//
// Threads: handlers run on the IoThread and must not block; send() and
// reply() may be called from any thread (they sign under a short lock and
// queue through TcpClient/TcpServer, so they allocate: real-time threads
// hand commands over through a ring).
//
// @code
//   dm::IoThread net; (void)net.start();
//   auto server = dm::CommandServer::listen(net, {.keyHex = key, .tcp = {.allow = {"10.0.0.0/24"}}},
//       [&](const dm::Command& c) { if (c.header.type == kStop) stopRobot(); });
//   auto client = dm::CommandClient::connect(net, {.keyHex = key, .tcp = {.peer = {"10.0.0.5", port}}}, {});
//   if ((*client)->waitReady(std::chrono::seconds(2))) (void)(*client)->send(kStop, {});
// @endcode
#pragma once

#include <dm/core/result.hpp>
#include <dm/network/auth.hpp>
#include <dm/network/message.hpp>
#include <dm/network/tcp.hpp>

#include <array>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>

namespace dm {

inline constexpr std::uint16_t kCommandHelloType = 0xFFF0;       ///< server's nonce (handshake step 1)
inline constexpr std::uint16_t kCommandHelloReplyType = 0xFFF1;  ///< client's nonce (handshake step 2)
inline constexpr std::uint16_t kCommandMaxType = 0xFFEF;         ///< highest application command type
inline constexpr std::size_t kCommandNonceBytes = 16;
using CommandNonce = std::array<std::byte, kCommandNonceBytes>;

/// The session key of one connection: HMAC-SHA-256(key, "DMNM session v1"
/// ‖ serverNonce ‖ clientNonce). Public so that other implementations (and
/// tests) can speak the protocol. Fails like hmacSha256.
Result<AuthTag> deriveCommandSessionKey(std::span<const std::byte> key, const CommandNonce& serverNonce,
                                        const CommandNonce& clientNonce);

/// One received command (or, at the client, one reply). The payload views a
/// receive buffer and is valid only during the handler call.
struct Command {
  ConnectionId connection = 0;  ///< the server's id of the sending connection (0 at the client)
  SocketAddress peer;           ///< the sender's address
  MessageHeader header;  ///< type, sequence, sender's timestamp (authenticated flag bit set when signed)
  std::span<const std::byte> payload;
};
using CommandHandler = std::function<void(const Command&)>;

/// Why a message was refused.
enum class CommandRefusal : std::uint8_t {
  NoTag,      ///< unsigned where a signature is required, or a command before the handshake
  BadTag,     ///< signature does not verify (wrong key, tampering, failed handshake)
  Replayed,   ///< sequence number seen before on this connection
  Stale,      ///< sequence number too far behind to tell
  Malformed,  ///< not a message (bad magic, CRC, size) or a reserved type misused; the connection is closed
};
const char* toString(CommandRefusal r) noexcept;

/// Counters of a command channel end.
struct CommandStats {
  std::uint64_t accepted = 0;      ///< messages handed to the handler
  std::uint64_t noTag = 0;         ///< refused: CommandRefusal::NoTag
  std::uint64_t badTag = 0;        ///< refused: CommandRefusal::BadTag
  std::uint64_t replayed = 0;      ///< refused: CommandRefusal::Replayed
  std::uint64_t stale = 0;         ///< refused: CommandRefusal::Stale
  std::uint64_t malformed = 0;     ///< refused: CommandRefusal::Malformed
  std::uint64_t handshakes = 0;    ///< sessions established
  std::uint64_t peersRefused = 0;  ///< connections refused by the allow-list or limit (server)
  std::uint64_t refused() const { return noTag + badTag + replayed + stale + malformed; }
};

/// Settings of a CommandServer.
struct CommandServerOptions {
  /// Shared secret as hex (≥ 32 digits = 16 bytes; `openssl rand -hex 32`).
  /// Empty: no authentication, allowed only with requireAuth = false.
  std::string keyHex;
  bool requireAuth = true;                                        ///< refuse to start without a key
  TcpServerOptions tcp;                                           ///< address, allow-list (tcp.allow), limits
  MessageLimits limits{.maxPayloadBytes = std::size_t{1} << 20};  ///< per message, before allocating
};

/// Accepts command connections; see the file comment.
class CommandServer {
 public:
  /// Listens on options.tcp.local. Fails with InvalidArgument for a missing
  /// or malformed key (naming "keyHex" and the digit) or bad TCP options,
  /// Network when the port is taken.
  /// @code
  ///   auto s = dm::CommandServer::listen(net, {.keyHex = key}, onCommand);
  /// @endcode
  static Result<std::unique_ptr<CommandServer>> listen(IoThread& thread, CommandServerOptions options,
                                                       CommandHandler onCommand);
  ~CommandServer();
  CommandServer(const CommandServer&) = delete;
  CommandServer& operator=(const CommandServer&) = delete;

  std::uint16_t port() const noexcept;
  /// Sends a reply (signed with that connection's session key when
  /// authenticated). Fails with NotFound for an unknown connection,
  /// Network before its handshake, InvalidArgument for a reserved type or
  /// an oversize payload, Busy under back-pressure. Any thread.
  Status reply(ConnectionId connection, std::uint16_t type, std::span<const std::byte> payload);
  CommandStats stats() const;
  /// Stops listening and closes every connection. Idempotent.
  void close();

  struct Impl;

 private:
  explicit CommandServer(std::shared_ptr<Impl> impl);
  std::shared_ptr<Impl> impl_;
};

/// Settings of a CommandClient.
struct CommandClientOptions {
  std::string keyHex;       ///< as CommandServerOptions::keyHex
  bool requireAuth = true;  ///< refuse to start without a key
  TcpClientOptions tcp;     ///< peer, reconnection, limits
  MessageLimits limits{.maxPayloadBytes = std::size_t{1} << 20};
};

/// Sends commands to a CommandServer and receives its replies; see the file comment.
class CommandClient {
 public:
  /// Starts connecting. Fails with InvalidArgument for a missing or
  /// malformed key or bad TCP options.
  /// @code
  ///   auto c = dm::CommandClient::connect(net, {.keyHex = key, .tcp = {.peer = {"127.0.0.1", port}}},
  ///   onReply);
  /// @endcode
  static Result<std::unique_ptr<CommandClient>> connect(IoThread& thread, CommandClientOptions options,
                                                        CommandHandler onReply);
  ~CommandClient();
  CommandClient(const CommandClient&) = delete;
  CommandClient& operator=(const CommandClient&) = delete;

  /// Blocks (never on the network thread) until connected and, with a key,
  /// the handshake is done; Timeout otherwise.
  Status waitReady(std::chrono::milliseconds timeout) const;
  /// Sends one command with the next sequence number and the current time.
  /// Fails with Network when not ready, InvalidArgument for a type above
  /// kCommandMaxType or an oversize payload, Busy under back-pressure.
  Status send(std::uint16_t type, std::span<const std::byte> payload);
  CommandStats stats() const;
  void close();

  struct Impl;

 private:
  explicit CommandClient(std::shared_ptr<Impl> impl);
  std::shared_ptr<Impl> impl_;
};

}  // namespace dm
