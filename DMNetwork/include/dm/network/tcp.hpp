// dm/network/tcp.hpp — TCP byte streams on the network thread: a server that
// accepts many connections and a client that reconnects.
//
// These move bytes, nothing else: framing (SLIP, OpenIGTLink headers) lives
// in the codecs above them. Everything runs on an IoThread:
//  * Callbacks (connect, bytes, disconnect, state) run on the network thread
//    and must not block. Byte chunks arrive in order but with arbitrary
//    boundaries; the span is valid only during the call. Hand data on
//    through a lock-free ring (dm/core/ring.hpp) to the haptic loop.
//  * send() may be called from any thread. It copies the bytes into a
//    bounded per-connection queue and returns; the network thread writes
//    them asynchronously, in call order, each call's bytes contiguous on the
//    wire. When the queue would exceed its byte limit the call fails with
//    ErrorCode::Busy and nothing is queued (back-pressure: the caller drops
//    or retries; counted in ConnectionStats::messagesDropped). send()
//    allocates and takes a short lock, so real-time threads go through a
//    ring instead.
//  * Closing (close(), the destructor, a lost connection) reports the bytes
//    that were still queued (Disconnect::unsentBytes, ConnectionStats).
// TCP_NODELAY is on by default: haptic packets are small and late is wrong.
//
// @code
//   dm::IoThread net; (void)net.start();
//   auto server = dm::TcpServer::listen(net, {.local = {"127.0.0.1", 0}}, {.onBytes = onBytes});
//   auto client = dm::TcpClient::connect(net, {.peer = {"127.0.0.1", (*server)->port()}}, {});
// @endcode
#pragma once

#include <dm/core/result.hpp>
#include <dm/network/io_thread.hpp>

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

namespace dm {

/// Identifies one accepted connection of a TcpServer; never reused by it.
using ConnectionId = std::uint64_t;

/// Counters of one connection (for a TcpClient: summed over its reconnections).
/// A snapshot is consistent for the bytes leaving the send queue: every
/// accepted byte is in exactly one of bytesOut, queuedBytes and (at a
/// disconnect) bytesDropped.
struct ConnectionStats {
  std::uint64_t bytesIn = 0;          ///< bytes received
  std::uint64_t bytesOut = 0;         ///< bytes written to the socket
  std::uint64_t messagesQueued = 0;   ///< send() calls accepted
  std::uint64_t messagesDropped = 0;  ///< send() calls refused with Busy (queue full)
  std::uint64_t bytesDropped = 0;     ///< bytes of refused calls, plus unsent bytes at disconnect
  std::uint64_t queuedBytes = 0;      ///< bytes accepted but not yet written (now)
  std::uint64_t reconnects = 0;       ///< successful connections after the first (client)
};

/// Why a connection ended.
enum class DisconnectReason : std::uint8_t {
  PeerClosed,  ///< the peer closed its side (end of stream)
  Error,       ///< a socket error (reset, timeout, unreachable)
  LocalClose,  ///< we closed it: disconnect(), close(), destructor
};
const char* toString(DisconnectReason reason) noexcept;

/// Report of a finished connection.
struct Disconnect {
  DisconnectReason reason = DisconnectReason::LocalClose;
  std::string detail;                ///< the system's message, e.g. "Connection reset by peer"
  std::uint64_t unsentBytes = 0;     ///< queued bytes that were never written
  std::uint64_t unsentMessages = 0;  ///< send() calls whose bytes were not (completely) written
};

/// Statistics of a TcpServer.
struct TcpServerStats {
  std::uint64_t accepted = 0;  ///< connections accepted
  std::uint64_t refused = 0;   ///< connections refused by the allow-list or the connection limit
  std::uint64_t active = 0;    ///< connections open now
};

/// Settings of a TcpServer.
struct TcpServerOptions {
  /// Local address and port to listen on; port 0 picks an ephemeral port
  /// (see TcpServer::port()). "0.0.0.0" or "::" listen on every interface.
  SocketAddress local{"127.0.0.1", 0};
  /// Peers allowed to connect: IPv4/IPv6 addresses ("10.0.0.7") or CIDR
  /// blocks ("192.168.1.0/24", "fe80::/10"). Empty allows everyone. Refused
  /// peers are closed at once, counted and logged with their address.
  std::vector<std::string> allow;
  std::size_t sendQueueBytes = std::size_t{1} << 20;  ///< per-connection send queue limit, bytes (>= 1)
  std::size_t readChunkBytes = 64 * 1024;             ///< receive buffer per connection, bytes (1 .. 16 MiB)
  std::size_t maxConnections = 256;                   ///< further connections are refused and counted
  bool noDelay = true;                                ///< TCP_NODELAY on accepted sockets
};

/// Callbacks of a TcpServer; each runs on the network thread, must not
/// block, and may be empty.
struct TcpServerCallbacks {
  std::function<void(ConnectionId, const SocketAddress& peer)> onConnect;
  std::function<void(ConnectionId, std::span<const std::byte>)> onBytes;
  std::function<void(ConnectionId, const Disconnect&)> onDisconnect;
};

/// Callbacks that forward to `onConnect(id, peer)`, `onBytes(id, bytes)` and
/// `onDisconnect(id, disconnect)` of the object behind `weak` while it
/// lives (a session layer over TcpServer that may be destroyed first).
template <class T>
TcpServerCallbacks forwardTcpServerCallbacks(std::weak_ptr<T> weak) {
  return {.onConnect = [weak](ConnectionId id, const SocketAddress& peer) {
            if (auto self = weak.lock()) self->onConnect(id, peer);
          },
          .onBytes = [weak](ConnectionId id, std::span<const std::byte> bytes) {
            if (auto self = weak.lock()) self->onBytes(id, bytes);
          },
          .onDisconnect = [weak](ConnectionId id, const Disconnect& d) {
            if (auto self = weak.lock()) self->onDisconnect(id, d);
          }};
}

/// A listening TCP socket and its accepted connections.
class TcpServer {
 public:
  /// Binds, listens (address reuse on, so a restarted server gets its port
  /// back) and starts accepting on `thread` (which may be started later).
  /// Fails with InvalidArgument for a bad address, allow-list entry or
  /// option (the `where` names the field), Network when the port is taken
  /// or the address is not local. O(1).
  /// @code
  ///   auto server = dm::TcpServer::listen(net, {.local = {"127.0.0.1", 18944}}, callbacks);
  ///   if (!server) { dm::log::error("%s", server.error().message().c_str()); return; }
  /// @endcode
  static Result<std::unique_ptr<TcpServer>> listen(IoThread& thread, TcpServerOptions options,
                                                   TcpServerCallbacks callbacks);
  /// close(), then release.
  ~TcpServer();
  TcpServer(const TcpServer&) = delete;
  TcpServer& operator=(const TcpServer&) = delete;

  /// The port listened on (the ephemeral one if port 0 was asked). O(1).
  std::uint16_t port() const noexcept;
  /// Queues a copy of `bytes` for connection `id`. Fails with NotFound for
  /// an unknown or closed connection, Busy when the queue limit would be
  /// exceeded (nothing queued). Any thread. O(bytes.size()).
  Status send(ConnectionId id, std::span<const std::byte> bytes);
  /// Closes one connection; its onDisconnect runs (LocalClose) before this
  /// returns. NotFound if unknown. Any thread, callbacks included.
  Status disconnect(ConnectionId id);
  /// Stops listening and closes every connection (each gets onDisconnect
  /// with LocalClose and its unsent bytes). No callback runs after it
  /// returns. Idempotent.
  void close();

  /// Open connection ids, ascending.
  std::vector<ConnectionId> connections() const;
  /// Counters of one open connection; NotFound if unknown.
  Result<ConnectionStats> stats(ConnectionId id) const;
  TcpServerStats serverStats() const;

  struct Impl;

 private:
  explicit TcpServer(std::shared_ptr<Impl> impl);
  std::shared_ptr<Impl> impl_;
};

/// Connection state of a TcpClient.
enum class ConnectionState : std::uint8_t {
  Connecting,    ///< a connection attempt is under way
  Connected,     ///< bytes flow
  Backoff,       ///< waiting before the next attempt (reconnection on)
  Disconnected,  ///< not connected and not trying (reconnection off, or gave up)
  Closed,        ///< close() was called; final
};
const char* toString(ConnectionState state) noexcept;

/// Settings of a TcpClient.
struct TcpClientOptions {
  SocketAddress peer{"127.0.0.1", 0};  ///< server to connect to; a host name is resolved once, at connect()
  std::chrono::milliseconds connectTimeout{2000};        ///< one attempt's limit (> 0)
  bool reconnect = false;                                ///< try again after a failure or a lost connection
  std::chrono::milliseconds reconnectInitialDelay{100};  ///< first back-off delay (> 0)
  std::chrono::milliseconds reconnectMaxDelay{5000};     ///< the delay doubles up to this (>= initial)
  std::size_t sendQueueBytes = std::size_t{1} << 20;     ///< send queue limit, bytes (>= 1)
  std::size_t readChunkBytes = 64 * 1024;                ///< receive buffer, bytes (1 .. 16 MiB)
  bool noDelay = true;                                   ///< TCP_NODELAY
};

/// Callbacks of a TcpClient; each runs on the network thread, must not
/// block, and may be empty.
struct TcpClientCallbacks {
  /// Every state change; `detail` says why (the system's error, "connected
  /// to 127.0.0.1:18944", unsent bytes when a connection is lost).
  std::function<void(ConnectionState, const std::string& detail)> onState;
  std::function<void(std::span<const std::byte>)> onBytes;
};

/// Callbacks that forward to `onState(state, detail)` and `onBytes(bytes)`
/// of the object behind `weak` while it lives (a session layer over
/// TcpClient that may be destroyed first).
template <class T>
TcpClientCallbacks forwardTcpClientCallbacks(std::weak_ptr<T> weak) {
  return {.onState = [weak](ConnectionState s, const std::string& detail) {
            if (auto self = weak.lock()) self->onState(s, detail);
          },
          .onBytes = [weak](std::span<const std::byte> bytes) {
            if (auto self = weak.lock()) self->onBytes(bytes);
          }};
}

/// A TCP connection to a server, optionally re-established with exponential
/// back-off. Bytes queued when a connection is lost are discarded and
/// reported (they could leave a half-written frame on the next connection).
class TcpClient {
 public:
  /// Starts connecting (asynchronously, on `thread`). Fails with
  /// InvalidArgument for bad options, NotFound when the host name does not
  /// resolve. Connection failures are reported through onState, not here.
  /// @code
  ///   auto client = dm::TcpClient::connect(net, {.peer = {"10.0.0.7", 18944}, .reconnect = true}, cbs);
  ///   if (client && (*client)->waitConnected(std::chrono::seconds(2))) status = (*client)->send(bytes);
  /// @endcode
  static Result<std::unique_ptr<TcpClient>> connect(IoThread& thread, TcpClientOptions options,
                                                    TcpClientCallbacks callbacks);
  /// close(), then release.
  ~TcpClient();
  TcpClient(const TcpClient&) = delete;
  TcpClient& operator=(const TcpClient&) = delete;

  /// Queues a copy of `bytes`. Fails with Network when not connected, Busy
  /// when the queue limit would be exceeded (nothing queued). Any thread.
  Status send(std::span<const std::byte> bytes);
  /// Current state (may change right after the call returns).
  ConnectionState state() const noexcept;
  /// Blocks the calling thread (never the network thread) until connected;
  /// Timeout error otherwise, naming the last failure.
  Status waitConnected(std::chrono::milliseconds timeout) const;
  /// Closes for good; onState(Closed) runs before it returns, no callback
  /// after. Idempotent.
  void close();
  ConnectionStats stats() const;

  struct Impl;

 private:
  explicit TcpClient(std::shared_ptr<Impl> impl);
  std::shared_ptr<Impl> impl_;
};

}  // namespace dm
