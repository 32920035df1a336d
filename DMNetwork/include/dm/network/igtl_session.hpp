// dm/network/igtl_session.hpp — the OpenIGTLink session layer: framing a
// TCP byte stream into messages, typed handlers, query answering and
// subscriptions, over dm::TcpServer / dm::TcpClient.
//
// Framing (igtl::StreamFramer, one per connection): the 58-byte header is
// checked with igtl::decodeHeader as soon as it is in, so a body size above
// DecodeOptions::maxBodyBytes is refused before a single body byte is
// buffered; then the body is collected and its CRC-64 checked. A bad header
// or CRC means the stream cannot be resynchronised: the session logs the
// reason (peer, type, field), counts it (IgtlStats::malformed) and closes
// that connection. A framed message whose content fails typed decoding (a
// TRANSFORM of 40 bytes, a bad extended header) is logged and counted
// (IgtlStats::typedDecodeFailures); the connection stays up. Nothing throws;
// at most one message (≤ 58 + maxBodyBytes) is buffered per connection.
//
// Handlers (IgtlHandlers) run on the network thread and must not block; the
// MessageView and the value are valid only during the call. IgtlServer also
// answers queries by itself (see IgtlServer): GET_<T> with the latest
// publish()ed message, STT_<T>/STP_<T> (un)subscribe the connection and are
// answered RTS_<T>.
//
// Threads: send(), broadcast(), publish(), stats() may be called from any
// thread; they copy the bytes into the transport's bounded queue, so they
// allocate (real-time threads hand messages over through a ring). A full
// queue is reported (ErrorCode::Busy), never waited for. Destroy servers
// and clients before their IoThread.
//
// @code
//   dm::IoThread net; (void)net.start();
//   dm::IgtlHandlers h;
//   h.onTransform = [](dm::ConnectionId, const dm::igtl::MessageView& m, const dm::Affine3& t) { use(m, t); };
//   auto server = dm::IgtlServer::listen(net, {.tcp = {.local = {"0.0.0.0", 18944}}}, h);
//   (void)(*server)->publish(*dm::igtl::encodeTransform({.deviceName = "Probe"}, probe));
// @endcode
#pragma once

#include <dm/core/result.hpp>
#include <dm/network/igtl.hpp>
#include <dm/network/tcp.hpp>

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <utility>
#include <vector>

namespace dm {

namespace igtl {

/// Splits a byte stream into OpenIGTLink messages. Not thread-safe (one per
/// connection, fed from the network thread).
class StreamFramer {
 public:
  /// Called for each framed message: a MessageView (viewing the framer's
  /// buffer or the fed chunk, valid during the call), or the error of a
  /// message whose header and CRC are good but whose extended header or
  /// metadata are not (the stream stays in sync).
  using OnMessage = std::function<void(const Result<MessageView>&)>;

  explicit StreamFramer(DecodeOptions options = {});

  /// Consumes `bytes` (any chunking) and calls `onMessage` for every whole
  /// message. Fails on a bad header (version, empty type, body size over
  /// options.maxBodyBytes: refused with only the header buffered) or a CRC
  /// mismatch (when options.verifyCrc); the framer then stays failed, drops
  /// its buffer and ignores further bytes until reset(). `onMessage` may
  /// call stop() to end the call early (the rest of `bytes` is dropped).
  /// O(bytes.size()) plus the decoding.
  /// @code
  ///   dm::igtl::StreamFramer framer;
  ///   if (auto s = framer.feed(chunk, [&](const auto& m) { if (m) dispatch(*m); }); !s) closeConnection();
  /// @endcode
  Status feed(std::span<const std::byte> bytes, const OnMessage& onMessage);
  /// Makes the current feed() return after the message being delivered.
  void stop() noexcept { stopped_ = true; }
  /// Forgets everything buffered and the failure (for a new connection).
  void reset() noexcept;
  bool failed() const noexcept { return failed_; }
  /// Bytes held now (a partial header or a partial message).
  std::size_t bufferedBytes() const noexcept { return buffer_.size(); }
  /// Messages framed so far (good or not).
  std::uint64_t messages() const noexcept { return messages_; }
  const DecodeOptions& options() const noexcept { return options_; }

 private:
  Status fault(Error e);
  bool deliver(std::span<const std::byte> message, const Header& header, const OnMessage& onMessage,
               Status& status);

  DecodeOptions options_;
  std::vector<std::byte> buffer_;
  std::size_t need_ = 0;  // bytes of the message in buffer_ once its header is in (0: header not yet in)
  Header header_;         // of the message in buffer_
  std::uint64_t messages_ = 0;
  bool failed_ = false;
  bool stopped_ = false;
};

}  // namespace igtl

/// A typed handler: connection (0 at a client), the whole message (header
/// with type, device name, timestamp; metadata for v2/v3) and the value.
template <class T>
using IgtlHandler = std::function<void(ConnectionId, const igtl::MessageView&, const T&)>;

/// What a session does with received messages. Every handler is optional;
/// each runs on the network thread. A known type whose handlers are all
/// empty goes to onRaw undecoded.
struct IgtlHandlers {
  IgtlHandler<Affine3> onTransform;  ///< TRANSFORM, translation in metres
  IgtlHandler<Pose> onPosition;      ///< POSITION
  IgtlHandler<Volume> onVolume;      ///< IMAGE with 1 component
  IgtlHandler<Image> onImage;        ///< IMAGE with size z = 1 (1-4 channels of uint8/uint16/float32)
  IgtlHandler<igtl::StatusInfo> onStatus;
  IgtlHandler<igtl::StringInfo> onString;
  IgtlHandler<std::vector<igtl::Point>> onPoints;  ///< POINT
  IgtlHandler<Mesh> onPolyData;                    ///< POLYDATA
  IgtlHandler<igtl::SensorInfo> onSensor;          ///< SENSOR
  IgtlHandler<igtl::CommandInfo> onCommand;        ///< COMMAND and RTS_COMMAND (header.type tells)
  /// GET_/STT_/STP_/RTS_ messages. At a server, after the session has
  /// answered the query (when answerQueries is on).
  IgtlHandler<igtl::Query> onQuery;
  /// Any other type (TDATA, SENSOR, ...), known types without a handler,
  /// and data messages with an empty body (the "no data" answer to a GET_).
  std::function<void(ConnectionId, const igtl::MessageView&)> onRaw;
};

/// Session counters (IgtlServer: per connection or summed over all, closed
/// ones included; IgtlClient: summed over its connections).
struct IgtlStats {
  std::uint64_t messagesIn = 0;           ///< messages framed (header and CRC good)
  std::uint64_t messagesOut = 0;          ///< messages accepted by the transport (sent, answers, publishes)
  std::uint64_t malformed = 0;            ///< bad header or CRC: the connection was closed
  std::uint64_t typedDecodeFailures = 0;  ///< content refused by the typed decoder; connection kept
  std::uint64_t queriesAnswered = 0;      ///< GET_/STT_/STP_ answered (server)
  std::uint64_t sendFailures = 0;         ///< messages refused by the transport (Busy, closed)
  std::uint64_t throttled = 0;            ///< publishes not sent to a subscriber because of its resolution
};

/// Result of sending one message to several connections.
struct IgtlFanout {
  std::size_t sent = 0;       ///< connections whose queue took the message
  std::size_t throttled = 0;  ///< subscribers skipped because of their STT_ resolution
  /// Connections that refused it, with why (ErrorCode::Busy: queue full).
  std::vector<std::pair<ConnectionId, Error>> failures;
};

/// Who IgtlServer::publish() sends to besides storing for GET_.
enum class IgtlPublishTo : std::uint8_t {
  Subscribers,  ///< the connections that sent STT_ for the type
  Everyone,     ///< and every connection not subscribed to it
};

/// Settings of an IgtlServer.
struct IgtlServerOptions {
  TcpServerOptions tcp;        ///< address (port 0: ephemeral), allow-list, queue limits
  igtl::DecodeOptions decode;  ///< body size limit, CRC check
  std::size_t maxImageBytes = igtl::kDefaultMaxImageBytes;  ///< whole decoded image or volume
  bool answerQueries = true;  ///< answer GET_/STT_/STP_ (off: they only reach onQuery)
  /// Also called on the network thread (may be empty).
  std::function<void(ConnectionId, const SocketAddress&)> onConnect;
  std::function<void(ConnectionId, const Disconnect&)> onDisconnect;
};

/// OpenIGTLink server: accepts connections, frames and dispatches their
/// messages, answers queries from what was published.
///
/// Queries (OpenIGTLink v2 query convention):
///  * GET_<T> [device]: the latest published message of type T with that
///    device name, or with an empty name the latest of type T of any
///    device; when there is none, a message of type T with the query's
///    device name and an empty body (body size 0), as the protocol
///    description asks. GET_TRANS means TRANSFORM, GET_CAPABIL CAPABILITY.
///  * STT_<T> [device]: subscribes the connection to type T (of that
///    device, or of every device when the name is empty): every later
///    publish() of a match is also sent to it, at most once per resolution
///    (STT_TDATA / STT_QTDATA) — publishes that come sooner are skipped for
///    that subscriber, not delayed. Answered RTS_<T> status 0 (1 when the
///    STT_ body is malformed). A new STT_ replaces the old subscription.
///  * STP_<T>: unsubscribes, answered RTS_<T> status 0.
/// Answers carry the query's device name, header version and message id
/// (an empty GET_ answer always has version 1: no extended header).
class IgtlServer {
 public:
  /// Listens on options.tcp.local. Fails like TcpServer::listen.
  /// @code
  ///   auto server = dm::IgtlServer::listen(net, {.tcp = {.local = {"127.0.0.1", 0}}}, handlers);
  ///   if (!server) dm::log::error("%s", server.error().message().c_str());
  /// @endcode
  static Result<std::unique_ptr<IgtlServer>> listen(IoThread& thread, IgtlServerOptions options,
                                                    IgtlHandlers handlers);
  /// close(), then release.
  ~IgtlServer();
  IgtlServer(const IgtlServer&) = delete;
  IgtlServer& operator=(const IgtlServer&) = delete;

  std::uint16_t port() const noexcept;
  /// Sends one whole encoded message (from the igtl::encode* functions) to
  /// one connection. Fails with InvalidArgument when `message` is not one
  /// OpenIGTLink message (header checked, size = 58 + body size), NotFound
  /// for an unknown connection, Busy when its send queue is full. Any thread.
  Status send(ConnectionId connection, std::span<const std::byte> message);
  /// Sends one message to every open connection. Fails (InvalidArgument)
  /// only for a malformed `message`; per-connection refusals are listed.
  Result<IgtlFanout> broadcast(std::span<const std::byte> message);
  /// Stores `message` as the latest of its (type, device name) for GET_
  /// queries and sends it to the subscribers of its type (as their STT_
  /// asked); with IgtlPublishTo::Everyone also to every connection not
  /// subscribed to that type (a streaming server, as PLUS is: 3D Slicer
  /// shows what arrives without asking). Fails like broadcast(). Any
  /// thread. O(message size + connections).
  /// @code
  ///   auto t = dm::igtl::encodeTransform({.deviceName = "Needle"}, needle.isometry());
  ///   if (t) if (auto f = server->publish(*t); f && !f->failures.empty()) slowPeers(f->failures);
  /// @endcode
  Result<IgtlFanout> publish(std::span<const std::byte> message,
                             IgtlPublishTo to = IgtlPublishTo::Subscribers);
  /// Closes one connection. NotFound if unknown.
  Status disconnect(ConnectionId connection);
  /// Bytes accepted for the open connections and not yet written to their
  /// sockets (0: everything sent went out). Any thread.
  std::uint64_t queuedBytes() const;
  /// Stops listening and closes every connection. Idempotent; no handler
  /// runs after it returns.
  void close();

  std::vector<ConnectionId> connections() const;
  /// Counters of one open connection; NotFound otherwise.
  Result<IgtlStats> stats(ConnectionId connection) const;
  /// Counters summed over all connections, closed ones included.
  IgtlStats stats() const;

  struct Impl;

 private:
  explicit IgtlServer(std::shared_ptr<Impl> impl);
  std::shared_ptr<Impl> impl_;
};

/// Settings of an IgtlClient.
struct IgtlClientOptions {
  TcpClientOptions tcp;  ///< peer, time-outs, reconnection, queue limit
  igtl::DecodeOptions decode;
  std::size_t maxImageBytes = igtl::kDefaultMaxImageBytes;
  /// Also called on the network thread (may be empty).
  std::function<void(ConnectionState, const std::string& detail)> onState;
};

/// OpenIGTLink client: one connection to a server (a tracker, PLUS, 3D
/// Slicer), frames and dispatches what it sends (connection id 0). A bad
/// header or CRC from the server closes the client for good (state
/// Closed): TcpClient cannot drop one connection and keep reconnecting, and
/// a server that sends garbage is not one to reconnect to blindly.
class IgtlClient {
 public:
  /// Starts connecting. Fails like TcpClient::connect.
  /// @code
  ///   auto c = dm::IgtlClient::connect(net, {.tcp = {.peer = {"10.0.0.7", 18944}}}, handlers);
  ///   if (c && (*c)->waitConnected(std::chrono::seconds(2))) (void)(*c)->send(*dm::igtl::encodeQuery({}, q));
  /// @endcode
  static Result<std::unique_ptr<IgtlClient>> connect(IoThread& thread, IgtlClientOptions options,
                                                     IgtlHandlers handlers);
  ~IgtlClient();
  IgtlClient(const IgtlClient&) = delete;
  IgtlClient& operator=(const IgtlClient&) = delete;

  /// Sends one whole encoded message. Fails with InvalidArgument for
  /// something that is not one message, Network when not connected, Busy
  /// when the send queue is full. Any thread.
  Status send(std::span<const std::byte> message);
  /// Blocks (never on the network thread) until connected; Timeout otherwise.
  Status waitConnected(std::chrono::milliseconds timeout) const;
  ConnectionState state() const noexcept;
  /// Closes for good. Idempotent; no handler runs after it returns.
  void close();
  IgtlStats stats() const;

  struct Impl;

 private:
  explicit IgtlClient(std::shared_ptr<Impl> impl);
  std::shared_ptr<Impl> impl_;
};

}  // namespace dm
