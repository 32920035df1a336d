// igtl_session.cpp — OpenIGTLink sessions: the stream framer, dispatch to
// typed handlers, and IgtlServer / IgtlClient over the TCP transports.
#include <dm/core/log.hpp>
#include <dm/network/crc.hpp>
#include <dm/network/igtl_session.hpp>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <exception>
#include <map>
#include <mutex>
#include <optional>

namespace dm {

namespace igtl {

namespace {
// A connection that once carried a large image keeps no more than this
// much buffer capacity between messages.
constexpr std::size_t kKeepCapacity = std::size_t{1} << 20;
}  // namespace

StreamFramer::StreamFramer(DecodeOptions options) : options_(options) {}

void StreamFramer::reset() noexcept {
  buffer_.clear();
  if (buffer_.capacity() > kKeepCapacity) std::vector<std::byte>().swap(buffer_);
  need_ = 0;
  failed_ = false;
  stopped_ = false;
}

Status StreamFramer::fault(Error e) {
  failed_ = true;
  std::vector<std::byte>().swap(buffer_);
  need_ = 0;
  return e;
}

bool StreamFramer::deliver(std::span<const std::byte> message, const Header& header,
                           const OnMessage& onMessage, Status& status) {
  ++messages_;
  const auto body = message.subspan(kHeaderBytes);
  if (options_.verifyCrc) {
    const std::uint64_t crc = crc64Ecma(body);
    if (crc != header.crc) {
      status = fault(fail(
          ErrorCode::Parse,
          formatString("%s message from device \"%s\": CRC field is 0x%016llX, the CRC-64 of the %zu-byte "
                       "body is 0x%016llX",
                       header.type.c_str(), header.deviceName.c_str(),
                       static_cast<unsigned long long>(header.crc), body.size(),
                       static_cast<unsigned long long>(crc)),
          "OpenIGTLink header, byte 50", "the stream is corrupted: the connection must be closed"));
      return false;
    }
  }
  // Header and CRC are good, so the stream stays in sync whatever the body
  // holds: layout errors of the extended header or metadata go to the handler.
  DecodeOptions layout = options_;
  layout.verifyCrc = false;
  const Result<MessageView> m = decodeMessage(message, layout);
  if (onMessage) onMessage(m);
  return true;
}

Status StreamFramer::feed(std::span<const std::byte> bytes, const OnMessage& onMessage) {
  if (failed_)
    return fail(ErrorCode::Parse, "the stream failed earlier and cannot be resynchronised",
                "OpenIGTLink stream", "close the connection (or reset() for a new one)");
  stopped_ = false;
  Status status = ok();
  while (!bytes.empty() && !stopped_) {
    if (buffer_.empty()) {
      // Fast path: whole messages straight from the chunk, no copy.
      if (bytes.size() < kHeaderBytes) {
        buffer_.assign(bytes.begin(), bytes.end());
        break;
      }
      auto h = decodeHeader(bytes.first(kHeaderBytes), options_);
      if (!h) return fault(std::move(h).error());
      const std::size_t total = kHeaderBytes + static_cast<std::size_t>(h->bodySize);
      if (bytes.size() >= total) {
        if (!deliver(bytes.first(total), *h, onMessage, status)) return status;
        bytes = bytes.subspan(total);
        continue;
      }
      header_ = std::move(*h);
      need_ = total;
      buffer_.assign(bytes.begin(), bytes.end());
      break;
    }
    if (need_ == 0) {
      const std::size_t take = std::min(kHeaderBytes - buffer_.size(), bytes.size());
      buffer_.insert(buffer_.end(), bytes.begin(), bytes.begin() + static_cast<std::ptrdiff_t>(take));
      bytes = bytes.subspan(take);
      if (buffer_.size() < kHeaderBytes) break;
      // The header is checked before any body byte is kept: a body size over
      // the limit is refused here, with 58 bytes buffered.
      auto h = decodeHeader(buffer_, options_);
      if (!h) return fault(std::move(h).error());
      header_ = std::move(*h);
      need_ = kHeaderBytes + static_cast<std::size_t>(header_.bodySize);
    }
    const std::size_t take = std::min(need_ - buffer_.size(), bytes.size());
    buffer_.insert(buffer_.end(), bytes.begin(), bytes.begin() + static_cast<std::ptrdiff_t>(take));
    bytes = bytes.subspan(take);
    if (buffer_.size() == need_) {
      if (!deliver(buffer_, header_, onMessage, status)) return status;
      buffer_.clear();
      if (buffer_.capacity() > kKeepCapacity) std::vector<std::byte>().swap(buffer_);
      need_ = 0;
    }
  }
  return status;
}

}  // namespace igtl

namespace {

using Bytes = std::vector<std::byte>;

std::uint64_t nowStamp() {
  return igtl::timestampFromNanos(std::chrono::duration_cast<std::chrono::nanoseconds>(
                                      std::chrono::system_clock::now().time_since_epoch())
                                      .count());
}

struct Counters {
  std::atomic<std::uint64_t> in{0}, out{0}, malformed{0}, typed{0}, answered{0}, sendFailures{0},
      throttled{0};

  IgtlStats snapshot() const {
    return {in.load(),       out.load(),          malformed.load(), typed.load(),
            answered.load(), sendFailures.load(), throttled.load()};
  }
};

bool isPowerOfTen(std::uint64_t n) {
  while (n >= 10 && n % 10 == 0) n /= 10;
  return n == 1;
}

void add(IgtlStats& a, const IgtlStats& b) {
  a.messagesIn += b.messagesIn;
  a.messagesOut += b.messagesOut;
  a.malformed += b.malformed;
  a.typedDecodeFailures += b.typedDecodeFailures;
  a.queriesAnswered += b.queriesAnswered;
  a.sendFailures += b.sendFailures;
  a.throttled += b.throttled;
}

/// The header of `message` if it is exactly one OpenIGTLink message (its
/// CRC is the sender's business: these bytes come from our encoders).
Result<igtl::Header> checkOneMessage(std::span<const std::byte> message, const char* where) {
  igtl::DecodeOptions any;
  any.maxBodyBytes = ~std::size_t{0};
  auto h = igtl::decodeHeader(message, any);
  if (!h)
    return fail(ErrorCode::InvalidArgument, "not an OpenIGTLink message: " + h.error().what, where,
                "pass the bytes of one igtl::encode*() call");
  if (message.size() - igtl::kHeaderBytes != h->bodySize)
    return fail(
        ErrorCode::InvalidArgument,
        formatString("%s message: body size field says %llu bytes, %zu follow the header", h->type.c_str(),
                     static_cast<unsigned long long>(h->bodySize), message.size() - igtl::kHeaderBytes),
        where, "pass exactly one whole message per call");
  return h;
}

/// Full type name of a query's data type: the reference library shortens
/// the names that do not fit 12 characters with a prefix.
std::string fullTypeOf(const std::string& dataType) {
  if (dataType == "TRANS") return "TRANSFORM";
  if (dataType == "CAPABIL") return "CAPABILITY";
  return dataType;
}

/// Runs a user handler; what it throws is logged and swallowed (the
/// framing must not be torn by an exception).
template <class F>
void guarded(const std::string& who, const igtl::MessageView& m, F&& f) {
  try {
    f();
  } catch (const std::exception& e) {
    log::error("%s: the handler of a %s message threw: %s", who.c_str(), m.header.type.c_str(), e.what());
  } catch (...) {
    log::error("%s: the handler of a %s message threw", who.c_str(), m.header.type.c_str());
  }
}

/// Decodes `m` for its typed handler and calls it (or onRaw). Returns the
/// typed decoder's error, if any.
std::optional<Error> dispatch(ConnectionId id, const igtl::MessageView& m, const IgtlHandlers& h,
                              std::size_t maxImageBytes, const std::string& who) {
  const std::string& type = m.header.type;
  auto typed = [&](const auto& handler, auto&& decode) -> std::optional<Error> {
    auto v = decode();
    if (!v) return std::move(v).error();
    guarded(who, m, [&] { handler(id, m, *v); });
    return std::nullopt;
  };
  auto raw = [&]() -> std::optional<Error> {
    if (h.onRaw) guarded(who, m, [&] { h.onRaw(id, m); });
    return std::nullopt;
  };
  // An empty body is the protocol's "no data" answer to a GET_: not a
  // decoding failure.
  if (m.header.bodySize == 0 && !igtl::isQueryType(type)) return raw();
  if (type == "TRANSFORM")
    return h.onTransform ? typed(h.onTransform, [&] { return igtl::decodeTransformAffine(m); }) : raw();
  if (type == "POSITION")
    return h.onPosition ? typed(h.onPosition, [&] { return igtl::decodePosition(m); }) : raw();
  if (type == "STATUS") return h.onStatus ? typed(h.onStatus, [&] { return igtl::decodeStatus(m); }) : raw();
  if (type == "STRING") return h.onString ? typed(h.onString, [&] { return igtl::decodeString(m); }) : raw();
  if (type == "POINT") return h.onPoints ? typed(h.onPoints, [&] { return igtl::decodePoints(m); }) : raw();
  if (type == "SENSOR") return h.onSensor ? typed(h.onSensor, [&] { return igtl::decodeSensor(m); }) : raw();
  if (type == "POLYDATA")
    return h.onPolyData ? typed(h.onPolyData, [&] { return igtl::decodePolyData(m); }) : raw();
  if (type == "COMMAND" || type == "RTS_COMMAND")
    return h.onCommand ? typed(h.onCommand, [&] { return igtl::decodeCommand(m); }) : raw();
  if (igtl::isQueryType(type))
    return h.onQuery ? typed(h.onQuery, [&] { return igtl::decodeQuery(m); }) : raw();
  if (type == "IMAGE") {
    if (!h.onVolume && !h.onImage) return raw();
    auto info = igtl::decodeImageInfo(m);
    if (!info) return std::move(info).error();
    bool delivered = false;
    if (h.onImage && info->size.z() == 1) {
      if (auto e = typed(h.onImage, [&] { return igtl::decodeImage(m, maxImageBytes); })) return e;
      delivered = true;
    }
    if (h.onVolume && info->components == 1) {
      if (auto e = typed(h.onVolume, [&] { return igtl::decodeVolume(m, maxImageBytes); })) return e;
      delivered = true;
    }
    if (!delivered)
      return fail(ErrorCode::Unsupported,
                  formatString("IMAGE of %d x %d x %d with %d components has no handler: onVolume takes 1 "
                               "component, onImage size z = 1",
                               info->size.x(), info->size.y(), info->size.z(), info->components),
                  "IMAGE from device \"" + m.header.deviceName + "\"", "set the handler that fits");
    return std::nullopt;
  }
  return raw();
}

void logTypedFailure(const std::string& who, const igtl::MessageView* m, const Error& e) {
  if (m != nullptr)
    log::warn("%s: %s message from device \"%s\" refused: %s; connection kept", who.c_str(),
              m->header.type.c_str(), m->header.deviceName.c_str(), e.message().c_str());
  else
    log::warn("%s: message refused: %s; connection kept", who.c_str(), e.message().c_str());
}

}  // namespace

// ---------------------------------------------------------------- server ---

struct IgtlServer::Impl {
  struct Subscription {
    std::string device;  // empty: every device
    std::chrono::milliseconds resolution{0};
    std::optional<std::chrono::steady_clock::time_point> last;
  };
  struct Connection {
    SocketAddress peer;
    std::string name;  // for logs
    igtl::StreamFramer framer;
    Counters counters;
    std::atomic<bool> closed{false};
    std::map<std::string, Subscription> subscriptions;  // full type → subscription; guarded by Impl::mutex
    explicit Connection(const igtl::DecodeOptions& o) : framer(o) {}
  };
  struct Stored {
    std::shared_ptr<const Bytes> bytes;
    std::uint64_t sequence = 0;  // publish order, for "latest of any device"
  };

  IgtlServerOptions options;
  IgtlHandlers handlers;
  std::unique_ptr<TcpServer> tcp;  // set before any callback can run (see listen)
  Counters gone;                   // counters of closed connections
  mutable std::mutex mutex;        // guards the fields below and every Connection::subscriptions
  std::map<ConnectionId, std::shared_ptr<Connection>> connections;
  std::map<std::pair<std::string, std::string>, Stored> latest;  // (type, device) → message
  std::uint64_t sequence = 0;

  std::shared_ptr<Connection> find(ConnectionId id) const {
    std::lock_guard lock(mutex);
    auto it = connections.find(id);
    return it == connections.end() ? nullptr : it->second;
  }

  Status sendTo(ConnectionId id, Connection& c, std::span<const std::byte> bytes) {
    Status s = tcp->send(id, bytes);
    if (s) {
      c.counters.out.fetch_add(1, std::memory_order_relaxed);
    } else {
      // A slow peer refuses many in a row: the 1st, 10th, 100th, ... are
      // logged, all are counted (stats().sendFailures).
      const std::uint64_t n = c.counters.sendFailures.fetch_add(1, std::memory_order_relaxed) + 1;
      if (isPowerOfTen(n))
        log::warn("%s: could not send (%llu so far): %s", c.name.c_str(), static_cast<unsigned long long>(n),
                  s.error().message().c_str());
    }
    return s;
  }

  void onConnect(ConnectionId id, const SocketAddress& peer) {
    auto c = std::make_shared<Connection>(options.decode);
    c->peer = peer;
    c->name = formatString("IgtlServer port %u, connection %llu from %s", unsigned{tcp->port()},
                           static_cast<unsigned long long>(id), describe(peer).c_str());
    {
      std::lock_guard lock(mutex);
      connections[id] = c;
    }
    if (options.onConnect) options.onConnect(id, peer);
  }

  void onDisconnect(ConnectionId id, const Disconnect& d) {
    {
      std::lock_guard lock(mutex);
      auto it = connections.find(id);
      if (it != connections.end()) {
        Connection& c = *it->second;
        c.closed = true;
        // Moved to the totals under the lock, so stats() never misses them.
        const IgtlStats s = c.counters.snapshot();
        gone.in += s.messagesIn;
        gone.out += s.messagesOut;
        gone.malformed += s.malformed;
        gone.typed += s.typedDecodeFailures;
        gone.answered += s.queriesAnswered;
        gone.sendFailures += s.sendFailures;
        gone.throttled += s.throttled;
        connections.erase(it);
      }
    }
    if (options.onDisconnect) options.onDisconnect(id, d);
  }

  void onBytes(ConnectionId id, std::span<const std::byte> bytes) {
    auto c = find(id);
    if (!c || c->closed) return;
    const Status s = c->framer.feed(bytes, [&](const Result<igtl::MessageView>& m) {
      if (c->closed) {
        c->framer.stop();  // a handler closed this connection
        return;
      }
      handle(id, *c, m);
    });
    if (!s) {
      c->counters.malformed.fetch_add(1, std::memory_order_relaxed);
      log::warn("%s: malformed stream: %s; closing the connection", c->name.c_str(),
                s.error().message().c_str());
      (void)tcp->disconnect(id);
    }
  }

  void handle(ConnectionId id, Connection& c, const Result<igtl::MessageView>& r) {
    c.counters.in.fetch_add(1, std::memory_order_relaxed);
    if (!r) {
      c.counters.typed.fetch_add(1, std::memory_order_relaxed);
      logTypedFailure(c.name, nullptr, r.error());
      return;
    }
    const igtl::MessageView& m = *r;
    const std::string& type = m.header.type;
    if (options.answerQueries && igtl::isQueryType(type) && !type.starts_with("RTS_")) {
      query(id, c, m);
      return;
    }
    if (auto e = dispatch(id, m, handlers, options.maxImageBytes, c.name)) {
      c.counters.typed.fetch_add(1, std::memory_order_relaxed);
      logTypedFailure(c.name, &m, *e);
    }
  }

  void query(ConnectionId id, Connection& c, const igtl::MessageView& m) {
    const std::string& type = m.header.type;
    const std::string full = fullTypeOf(type.substr(4));
    auto q = igtl::decodeQuery(m);
    if (!q) {
      c.counters.typed.fetch_add(1, std::memory_order_relaxed);
      logTypedFailure(c.name, &m, q.error());
      if (!type.starts_with("GET_")) ready(id, c, m, 1);
      return;
    }
    if (q->kind == igtl::QueryKind::Get) {
      answerGet(id, c, m, full);
    } else if (q->kind == igtl::QueryKind::Start) {
      {
        std::lock_guard lock(mutex);
        c.subscriptions[full] = {m.header.deviceName, std::chrono::milliseconds(q->resolutionMs),
                                 std::nullopt};
      }
      ready(id, c, m, 0);
    } else if (q->kind == igtl::QueryKind::Stop) {
      {
        std::lock_guard lock(mutex);
        c.subscriptions.erase(full);
      }
      ready(id, c, m, 0);
    }
    if (handlers.onQuery) guarded(c.name, m, [&] { handlers.onQuery(id, m, *q); });
  }

  void answerGet(ConnectionId id, Connection& c, const igtl::MessageView& m, const std::string& full) {
    std::shared_ptr<const Bytes> found;
    {
      std::lock_guard lock(mutex);
      if (!m.header.deviceName.empty()) {
        auto it = latest.find({full, m.header.deviceName});
        if (it != latest.end()) found = it->second.bytes;
      } else {
        std::uint64_t best = 0;
        for (auto it = latest.lower_bound({full, std::string()});
             it != latest.end() && it->first.first == full; ++it)
          if (it->second.sequence > best) {
            best = it->second.sequence;
            found = it->second.bytes;
          }
      }
    }
    if (found) {
      if (sendTo(id, c, *found)) c.counters.answered.fetch_add(1, std::memory_order_relaxed);
      return;
    }
    // Nothing published: the protocol asks for a message of the type with
    // an empty body (version 1: there is no extended header to carry).
    auto empty =
        igtl::encodeRaw({.version = 1, .deviceName = m.header.deviceName, .timestamp = nowStamp()}, full, {});
    if (!empty) {
      log::warn("%s: cannot answer %s: %s", c.name.c_str(), m.header.type.c_str(),
                empty.error().message().c_str());
      return;
    }
    if (sendTo(id, c, *empty)) c.counters.answered.fetch_add(1, std::memory_order_relaxed);
  }

  // Answers an STT_/STP_ with RTS_<type> and `status` (0 success, 1 error).
  void ready(ConnectionId id, Connection& c, const igtl::MessageView& m, std::uint8_t status) {
    igtl::Query q{.kind = igtl::QueryKind::Ready, .dataType = m.header.type.substr(4), .status = status};
    auto rts = igtl::encodeQuery({.version = m.header.version,
                                  .deviceName = m.header.deviceName,
                                  .timestamp = nowStamp(),
                                  .messageId = m.messageId},
                                 q);
    if (!rts) {
      log::warn("%s: cannot answer %s: %s", c.name.c_str(), m.header.type.c_str(),
                rts.error().message().c_str());
      return;
    }
    if (sendTo(id, c, *rts)) c.counters.answered.fetch_add(1, std::memory_order_relaxed);
  }

  IgtlFanout fanOut(std::span<const std::byte> bytes,
                    const std::vector<std::pair<ConnectionId, std::shared_ptr<Connection>>>& targets) {
    IgtlFanout f;
    for (const auto& [id, c] : targets) {
      Status s = tcp->send(id, bytes);
      if (s) {
        ++f.sent;
        c->counters.out.fetch_add(1, std::memory_order_relaxed);
      } else {
        c->counters.sendFailures.fetch_add(1, std::memory_order_relaxed);
        f.failures.emplace_back(id, s.error());
      }
    }
    return f;
  }
};

IgtlServer::IgtlServer(std::shared_ptr<Impl> impl) : impl_(std::move(impl)) {}
IgtlServer::~IgtlServer() { close(); }

Result<std::unique_ptr<IgtlServer>> IgtlServer::listen(IoThread& thread, IgtlServerOptions options,
                                                       IgtlHandlers handlers) {
  auto impl = std::make_shared<Impl>();
  TcpServerOptions tcpOptions = std::move(options.tcp);
  impl->options = std::move(options);
  impl->handlers = std::move(handlers);
  TcpServerCallbacks callbacks = forwardTcpServerCallbacks(std::weak_ptr<Impl>(impl));

  // Created on the network thread, so that no callback runs before
  // impl->tcp is set (TcpServer::listen runs its own set-up inline there).
  Status status = ok();
  thread.runAndWait([&] {
    auto tcp = TcpServer::listen(thread, std::move(tcpOptions), std::move(callbacks));
    if (!tcp) {
      status = tcp.error();
      return;
    }
    impl->tcp = std::move(*tcp);
  });
  if (!status) return std::move(status).error();
  return std::unique_ptr<IgtlServer>(new IgtlServer(std::move(impl)));
}

std::uint16_t IgtlServer::port() const noexcept { return impl_->tcp->port(); }

Status IgtlServer::send(ConnectionId connection, std::span<const std::byte> message) {
  if (auto h = checkOneMessage(message, "IgtlServer::send"); !h) return std::move(h).error();
  auto c = impl_->find(connection);
  if (!c)
    return fail(ErrorCode::NotFound,
                formatString("no open connection %llu", static_cast<unsigned long long>(connection)),
                formatString("IgtlServer port %u", unsigned{port()}), "the peer disconnected");
  Status s = impl_->tcp->send(connection, message);
  (s ? c->counters.out : c->counters.sendFailures).fetch_add(1, std::memory_order_relaxed);
  return s;
}

Result<IgtlFanout> IgtlServer::broadcast(std::span<const std::byte> message) {
  if (auto h = checkOneMessage(message, "IgtlServer::broadcast"); !h) return std::move(h).error();
  std::vector<std::pair<ConnectionId, std::shared_ptr<Impl::Connection>>> targets;
  {
    std::lock_guard lock(impl_->mutex);
    targets.assign(impl_->connections.begin(), impl_->connections.end());
  }
  return impl_->fanOut(message, targets);
}

Result<IgtlFanout> IgtlServer::publish(std::span<const std::byte> message, IgtlPublishTo to) {
  auto h = checkOneMessage(message, "IgtlServer::publish");
  if (!h) return std::move(h).error();
  auto stored = std::make_shared<const Bytes>(message.begin(), message.end());
  const auto now = std::chrono::steady_clock::now();
  std::vector<std::pair<ConnectionId, std::shared_ptr<Impl::Connection>>> targets;
  std::size_t throttled = 0;
  {
    std::lock_guard lock(impl_->mutex);
    impl_->latest[{h->type, h->deviceName}] = {stored, ++impl_->sequence};
    for (auto& [id, c] : impl_->connections) {
      auto it = c->subscriptions.find(h->type);
      if (it == c->subscriptions.end()) {
        if (to == IgtlPublishTo::Everyone) targets.emplace_back(id, c);
        continue;
      }
      Impl::Subscription& sub = it->second;
      if (!sub.device.empty() && sub.device != h->deviceName) continue;
      if (sub.resolution.count() > 0 && sub.last && now - *sub.last < sub.resolution) {
        ++throttled;
        c->counters.throttled.fetch_add(1, std::memory_order_relaxed);
        continue;
      }
      sub.last = now;
      targets.emplace_back(id, c);
    }
  }
  IgtlFanout f = impl_->fanOut(*stored, targets);
  f.throttled = throttled;
  return f;
}

std::uint64_t IgtlServer::queuedBytes() const {
  std::uint64_t total = 0;
  for (ConnectionId id : connections())
    if (auto st = impl_->tcp->stats(id)) total += st->queuedBytes;
  return total;
}

Status IgtlServer::disconnect(ConnectionId connection) { return impl_->tcp->disconnect(connection); }

void IgtlServer::close() {
  if (impl_ && impl_->tcp) impl_->tcp->close();
}

std::vector<ConnectionId> IgtlServer::connections() const {
  std::lock_guard lock(impl_->mutex);
  std::vector<ConnectionId> ids;
  for (const auto& [id, c] : impl_->connections) ids.push_back(id);
  return ids;
}

Result<IgtlStats> IgtlServer::stats(ConnectionId connection) const {
  auto c = impl_->find(connection);
  if (!c)
    return fail(ErrorCode::NotFound,
                formatString("no open connection %llu", static_cast<unsigned long long>(connection)),
                formatString("IgtlServer port %u", unsigned{port()}));
  return c->counters.snapshot();
}

IgtlStats IgtlServer::stats() const {
  std::lock_guard lock(impl_->mutex);
  IgtlStats total = impl_->gone.snapshot();
  for (const auto& [id, c] : impl_->connections) add(total, c->counters.snapshot());
  return total;
}

// ---------------------------------------------------------------- client ---

struct IgtlClient::Impl {
  explicit Impl(const igtl::DecodeOptions& o) : framer(o) {}

  IgtlClientOptions options;
  IgtlHandlers handlers;
  std::unique_ptr<TcpClient> tcp;  // set before any callback can run (see connect)
  std::string name;
  Counters counters;
  igtl::StreamFramer framer;         // network thread only
  std::atomic<bool> closing{false};  // set by close() or a malformed stream: no handler after it

  void onState(ConnectionState s, const std::string& detail) {
    if (s == ConnectionState::Connected) framer.reset();
    if (options.onState) options.onState(s, detail);
  }

  void onBytes(std::span<const std::byte> bytes) {
    if (closing) return;
    const Status s = framer.feed(bytes, [&](const Result<igtl::MessageView>& r) {
      if (closing) {
        framer.stop();
        return;
      }
      counters.in.fetch_add(1, std::memory_order_relaxed);
      if (!r) {
        counters.typed.fetch_add(1, std::memory_order_relaxed);
        logTypedFailure(name, nullptr, r.error());
        return;
      }
      if (auto e = dispatch(0, *r, handlers, options.maxImageBytes, name)) {
        counters.typed.fetch_add(1, std::memory_order_relaxed);
        logTypedFailure(name, &*r, *e);
      }
    });
    if (!s) {
      counters.malformed.fetch_add(1, std::memory_order_relaxed);
      log::warn("%s: malformed stream: %s; closing the client", name.c_str(), s.error().message().c_str());
      closing = true;
      tcp->close();  // on the network thread: runs inline
    }
  }
};

IgtlClient::IgtlClient(std::shared_ptr<Impl> impl) : impl_(std::move(impl)) {}
IgtlClient::~IgtlClient() { close(); }

Result<std::unique_ptr<IgtlClient>> IgtlClient::connect(IoThread& thread, IgtlClientOptions options,
                                                        IgtlHandlers handlers) {
  auto impl = std::make_shared<Impl>(options.decode);
  impl->name = "IgtlClient to " + describe(options.tcp.peer);
  TcpClientOptions tcpOptions = std::move(options.tcp);
  impl->options = std::move(options);
  impl->handlers = std::move(handlers);
  TcpClientCallbacks callbacks = forwardTcpClientCallbacks(std::weak_ptr<Impl>(impl));

  // On the network thread, so that no callback runs before impl->tcp is set.
  Status status = ok();
  thread.runAndWait([&] {
    auto tcp = TcpClient::connect(thread, std::move(tcpOptions), std::move(callbacks));
    if (!tcp) {
      status = tcp.error();
      return;
    }
    impl->tcp = std::move(*tcp);
  });
  if (!status) return std::move(status).error();
  return std::unique_ptr<IgtlClient>(new IgtlClient(std::move(impl)));
}

Status IgtlClient::send(std::span<const std::byte> message) {
  if (auto h = checkOneMessage(message, "IgtlClient::send"); !h) return std::move(h).error();
  Status s = impl_->tcp->send(message);
  (s ? impl_->counters.out : impl_->counters.sendFailures).fetch_add(1, std::memory_order_relaxed);
  return s;
}

Status IgtlClient::waitConnected(std::chrono::milliseconds timeout) const {
  return impl_->tcp->waitConnected(timeout);
}

ConnectionState IgtlClient::state() const noexcept { return impl_->tcp->state(); }

void IgtlClient::close() {
  if (!impl_ || !impl_->tcp) return;
  impl_->closing = true;  // a handler calling close() ends the dispatch of its chunk too
  impl_->tcp->close();
}

IgtlStats IgtlClient::stats() const { return impl_->counters.snapshot(); }

}  // namespace dm
