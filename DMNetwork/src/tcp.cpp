// tcp.cpp — dm::TcpServer and dm::TcpClient on asio. One Link class carries a
// connected socket for both: bounded send queue, gathered asynchronous
// writes, a read loop, and a single end-of-connection report.
#include <dm/core/log.hpp>
#include <dm/network/tcp.hpp>

#include <algorithm>
#include <array>
#include <condition_variable>
#include <deque>
#include <map>
#include <mutex>
#include <optional>

#include "io_thread_impl.hpp"

namespace dm {

using asio::ip::tcp;

const char* toString(DisconnectReason reason) noexcept {
  switch (reason) {
    case DisconnectReason::PeerClosed:
      return "peer closed";
    case DisconnectReason::Error:
      return "socket error";
    case DisconnectReason::LocalClose:
      return "closed locally";
  }
  return "?";
}

const char* toString(ConnectionState state) noexcept {
  switch (state) {
    case ConnectionState::Connecting:
      return "connecting";
    case ConnectionState::Connected:
      return "connected";
    case ConnectionState::Backoff:
      return "waiting to reconnect";
    case ConnectionState::Disconnected:
      return "disconnected";
    case ConnectionState::Closed:
      return "closed";
  }
  return "?";
}

namespace {

constexpr std::size_t kMaxReadChunk = std::size_t{16} << 20;
constexpr std::size_t kMaxGather = 64;  // buffers per gathered write

struct LinkCounters {
  std::atomic<std::uint64_t> bytesIn{0}, bytesOut{0}, messagesQueued{0}, messagesDropped{0}, bytesDropped{0},
      queuedBytes{0}, reconnects{0};
  // Bytes leaving the queue (written or discarded) move between two counters
  // under this lock, and a snapshot takes it too: a snapshot never sees them
  // in both (bytesOut + queuedBytes would count them twice) or in neither.
  mutable std::mutex flow;
  void leaveQueue(std::atomic<std::uint64_t>& to, std::uint64_t n) {
    std::lock_guard lock(flow);
    to.fetch_add(n, std::memory_order_relaxed);
    queuedBytes.fetch_sub(n, std::memory_order_relaxed);
  }
  ConnectionStats snapshot() const {
    std::lock_guard lock(flow);
    return {bytesIn.load(),      bytesOut.load(),    messagesQueued.load(), messagesDropped.load(),
            bytesDropped.load(), queuedBytes.load(), reconnects.load()};
  }
};

/// One connected socket. send() from any thread; everything else on the
/// network thread (or while it is stopped).
class Link : public std::enable_shared_from_this<Link> {
 public:
  Link(IoThread& thread, tcp::socket socket, std::size_t queueLimit, std::size_t chunk,
       std::shared_ptr<LinkCounters> counters, std::string name)
      : thread_(thread),
        socket_(std::move(socket)),
        queueLimit_(queueLimit),
        buffer_(chunk),
        counters_(std::move(counters)),
        name_(std::move(name)) {}

  std::function<void(std::span<const std::byte>)> onBytes;
  std::function<void(const Disconnect&)> onEnd;  ///< called exactly once

  void start() { readMore(); }

  Status send(std::span<const std::byte> bytes) {
    if (bytes.empty()) return ok();
    std::lock_guard lock(mutex_);
    if (closed_) return fail(ErrorCode::Network, "connection is closed", name_, "wait for a new connection");
    if (queuedBytes_ + bytes.size() > queueLimit_) {
      counters_->messagesDropped.fetch_add(1, std::memory_order_relaxed);
      counters_->bytesDropped.fetch_add(bytes.size(), std::memory_order_relaxed);
      return fail(ErrorCode::Busy,
                  formatString("send queue full (%zu of %zu bytes queued, %zu more asked)", queuedBytes_,
                               queueLimit_, bytes.size()),
                  name_, "the peer is not reading fast enough: drop this message or retry later");
    }
    queue_.emplace_back(bytes.begin(), bytes.end());
    queuedBytes_ += bytes.size();
    counters_->queuedBytes.fetch_add(bytes.size(), std::memory_order_relaxed);
    counters_->messagesQueued.fetch_add(1, std::memory_order_relaxed);
    if (!writing_) {
      writing_ = true;
      asio::post(thread_.impl().io, [self = shared_from_this()] { self->writeMore(); });
    }
    return ok();
  }

  /// Ends the connection once: closes the socket, discards the queue and
  /// reports. Network thread only.
  void close(DisconnectReason reason, std::string detail) {
    Disconnect d{reason, std::move(detail), 0, 0};
    {
      std::lock_guard lock(mutex_);
      if (closed_) return;
      closed_ = true;
      d.unsentBytes = queuedBytes_;
      d.unsentMessages = queue_.size() + inflightCount_;
      queue_.clear();  // in-flight buffers stay alive until their write handler
    }
    counters_->leaveQueue(counters_->bytesDropped, d.unsentBytes);
    std::error_code ignored;
    socket_.shutdown(tcp::socket::shutdown_both, ignored);
    socket_.close(ignored);
    if (d.unsentBytes > 0)
      dm::log::warn("%s: connection ended (%s) with %llu bytes in %llu sends unsent; discarded",
                    name_.c_str(), toString(reason), static_cast<unsigned long long>(d.unsentBytes),
                    static_cast<unsigned long long>(d.unsentMessages));
    if (onEnd) thread_.impl().guard("onDisconnect", [&] { onEnd(d); });
  }

  bool closed() const {
    std::lock_guard lock(mutex_);
    return closed_;
  }

  ConnectionStats stats() const { return counters_->snapshot(); }

 private:
  void readMore() {
    socket_.async_read_some(
        asio::buffer(buffer_), [self = shared_from_this()](std::error_code ec, std::size_t n) {
          if (self->closed()) return;
          if (ec) {
            if (ec == asio::error::eof)
              self->close(DisconnectReason::PeerClosed, "end of stream");
            else
              self->close(DisconnectReason::Error, ec.message());
            return;
          }
          self->counters_->bytesIn.fetch_add(n, std::memory_order_relaxed);
          if (self->onBytes)
            self->thread_.impl().guard(
                "onBytes", [&] { self->onBytes(std::span<const std::byte>(self->buffer_.data(), n)); });
          if (!self->closed()) self->readMore();
        });
  }

  void writeMore() {
    std::vector<asio::const_buffer> gather;
    {
      std::lock_guard lock(mutex_);
      inflight_.clear();
      inflightCount_ = 0;
      if (closed_ || queue_.empty()) {
        writing_ = false;
        return;
      }
      while (!queue_.empty() && inflight_.size() < kMaxGather) {
        inflight_.push_back(std::move(queue_.front()));
        queue_.pop_front();
      }
      inflightCount_ = inflight_.size();
    }
    gather.reserve(inflight_.size());
    for (const auto& b : inflight_) gather.emplace_back(b.data(), b.size());
    asio::async_write(socket_, gather, [self = shared_from_this()](std::error_code ec, std::size_t n) {
      if (self->closed()) return;
      {
        std::lock_guard lock(self->mutex_);
        self->queuedBytes_ -= n;
      }
      self->counters_->leaveQueue(self->counters_->bytesOut, n);
      if (ec) {
        self->close(DisconnectReason::Error, ec.message());
        return;
      }
      self->writeMore();
    });
  }

  IoThread& thread_;
  tcp::socket socket_;
  const std::size_t queueLimit_;
  std::vector<std::byte> buffer_;
  std::shared_ptr<LinkCounters> counters_;
  const std::string name_;

  mutable std::mutex mutex_;  // guards the fields below
  std::deque<std::vector<std::byte>> queue_;
  std::vector<std::vector<std::byte>>
      inflight_;  // touched by the network thread only, counted under the lock
  std::size_t inflightCount_ = 0;
  std::size_t queuedBytes_ = 0;  // queued plus in flight
  bool writing_ = false;
  bool closed_ = false;
};

/// One allow-list entry: an address and a prefix length.
struct Cidr {
  asio::ip::address network;
  unsigned bits = 0;

  bool contains(asio::ip::address a) const {
    if (a.is_v6() && a.to_v6().is_v4_mapped()) a = asio::ip::make_address_v4(asio::ip::v4_mapped, a.to_v6());
    if (a.is_v4() != network.is_v4()) return false;
    if (a.is_v4()) {
      const std::uint32_t mask = bits == 0 ? 0u : ~std::uint32_t{0} << (32 - bits);
      return (a.to_v4().to_uint() & mask) == (network.to_v4().to_uint() & mask);
    }
    const auto x = a.to_v6().to_bytes();
    const auto y = network.to_v6().to_bytes();
    for (unsigned i = 0; i < 16; ++i) {
      const unsigned left = bits > i * 8 ? std::min(8u, bits - i * 8) : 0u;
      const auto mask = static_cast<std::uint8_t>(left == 0 ? 0 : 0xFFu << (8 - left));
      if ((x[i] & mask) != (y[i] & mask)) return false;
    }
    return true;
  }
};

Result<Cidr> parseCidr(const std::string& text, const std::string& field) {
  const auto slash = text.find('/');
  auto address = parseAddress(text.substr(0, slash), field);
  if (!address) return address.error();
  const unsigned maxBits = address->is_v4() ? 32 : 128;
  unsigned bits = maxBits;
  if (slash != std::string::npos) {
    const std::string prefix = text.substr(slash + 1);
    const bool digits =
        !prefix.empty() && prefix.size() <= 3 &&
        std::all_of(prefix.begin(), prefix.end(), [](char c) { return c >= '0' && c <= '9'; });
    if (!digits || static_cast<unsigned>(std::stoi(prefix)) > maxBits)
      return fail(ErrorCode::InvalidArgument, "'" + text + "' has a bad prefix length", field,
                  formatString("write ADDRESS/BITS with BITS in 0..%u, e.g. 192.168.1.0/24", maxBits));
    bits = static_cast<unsigned>(std::stoi(prefix));
  }
  return Cidr{*address, bits};
}

Status checkBuffers(std::size_t queueBytes, std::size_t chunk, const char* where) {
  if (queueBytes == 0)
    return fail(ErrorCode::InvalidArgument, "sendQueueBytes is 0", where,
                "give the send queue at least 1 byte");
  if (chunk == 0 || chunk > kMaxReadChunk)
    return fail(ErrorCode::InvalidArgument, formatString("readChunkBytes is %zu", chunk), where,
                "use 1 byte .. 16 MiB (64 KiB is a good default)");
  return ok();
}

}  // namespace

// ---------------------------------------------------------------- server ---

struct TcpServer::Impl : std::enable_shared_from_this<TcpServer::Impl> {
  Impl(IoThread& t, TcpServerOptions o, TcpServerCallbacks c)
      : user(t), options(std::move(o)), callbacks(std::move(c)), acceptor(t.impl().io) {}

  void acceptMore() {
    acceptor.async_accept([self = shared_from_this()](std::error_code ec, tcp::socket socket) {
      if (self->closed.load()) return;
      if (ec) {
        if (ec == asio::error::operation_aborted) return;
        // E.g. out of file descriptors: log, and try again a little later
        // rather than spinning on the error.
        dm::log::warn("TcpServer port %u: accept failed: %s", self->port, ec.message().c_str());
        auto timer = std::make_shared<asio::steady_timer>(self->user.io(), std::chrono::milliseconds(50));
        timer->async_wait([self, timer](std::error_code) {
          if (!self->closed.load()) self->acceptMore();
        });
        return;
      }
      self->admit(std::move(socket));
      self->acceptMore();
    });
  }

  void admit(tcp::socket socket) {
    std::error_code ec;
    const tcp::endpoint remote = socket.remote_endpoint(ec);
    if (ec) return;  // already gone
    const SocketAddress peer = toSocketAddress(remote.address(), remote.port());
    const bool allowed = allow.empty() || std::any_of(allow.begin(), allow.end(), [&](const Cidr& c) {
                           return c.contains(remote.address());
                         });
    std::size_t active = 0;
    {
      std::lock_guard lock(mutex);
      active = links.size();
    }
    if (!allowed || active >= options.maxConnections) {
      refused.fetch_add(1, std::memory_order_relaxed);
      dm::log::warn("TcpServer port %u: refused connection from %s (%s)", port, describe(peer).c_str(),
                    allowed ? "connection limit reached" : "not in the allow-list");
      socket.close(ec);
      return;
    }
    if (options.noDelay) socket.set_option(tcp::no_delay(true), ec);
    const ConnectionId id = nextId++;
    auto link =
        std::make_shared<Link>(user.thread(), std::move(socket), options.sendQueueBytes,
                               options.readChunkBytes, std::make_shared<LinkCounters>(),
                               formatString("TcpServer port %u, connection %llu from %s", port,
                                            static_cast<unsigned long long>(id), describe(peer).c_str()));
    std::weak_ptr<Impl> weak = weak_from_this();
    link->onBytes = [weak, id](std::span<const std::byte> bytes) {
      if (auto s = weak.lock(); s && s->callbacks.onBytes) s->callbacks.onBytes(id, bytes);
    };
    link->onEnd = [weak, id](const Disconnect& d) {
      auto s = weak.lock();
      if (!s) return;
      {
        std::lock_guard lock(s->mutex);
        s->links.erase(id);
      }
      if (s->callbacks.onDisconnect) s->callbacks.onDisconnect(id, d);
    };
    {
      std::lock_guard lock(mutex);
      links.emplace(id, link);
    }
    accepted.fetch_add(1, std::memory_order_relaxed);
    if (callbacks.onConnect) user.thread().impl().guard("onConnect", [&] { callbacks.onConnect(id, peer); });
    if (!link->closed()) link->start();
  }

  std::shared_ptr<Link> find(ConnectionId id) const {
    std::lock_guard lock(mutex);
    auto it = links.find(id);
    return it == links.end() ? nullptr : it->second;
  }

  IoUser user;
  TcpServerOptions options;
  TcpServerCallbacks callbacks;
  tcp::acceptor acceptor;
  std::vector<Cidr> allow;
  std::uint16_t port = 0;
  ConnectionId nextId = 1;  // network thread only
  std::atomic<bool> closed{false};
  std::atomic<std::uint64_t> accepted{0}, refused{0};
  mutable std::mutex mutex;  // guards links
  std::map<ConnectionId, std::shared_ptr<Link>> links;
};

TcpServer::TcpServer(std::shared_ptr<Impl> impl) : impl_(std::move(impl)) {}

TcpServer::~TcpServer() { close(); }

Result<std::unique_ptr<TcpServer>> TcpServer::listen(IoThread& thread, TcpServerOptions options,
                                                     TcpServerCallbacks callbacks) {
  const std::string where = "TcpServer " + describe(options.local);
  if (auto s = checkBuffers(options.sendQueueBytes, options.readChunkBytes, where.c_str()); !s)
    return s.error();
  auto address = parseAddress(options.local.address, where + ": local.address");
  if (!address) return address.error();
  std::vector<Cidr> allow;
  for (std::size_t i = 0; i < options.allow.size(); ++i) {
    auto c = parseCidr(options.allow[i], where + formatString(": allow[%zu]", i));
    if (!c) return c.error();
    allow.push_back(*c);
  }
  auto impl = std::make_shared<Impl>(thread, std::move(options), std::move(callbacks));
  impl->allow = std::move(allow);
  std::error_code ec;
  const tcp::endpoint endpoint(*address, impl->options.local.port);
  impl->acceptor.open(endpoint.protocol(), ec);
  if (!ec) impl->acceptor.set_option(tcp::acceptor::reuse_address(true), ec);
  if (!ec) impl->acceptor.bind(endpoint, ec);
  if (!ec) impl->acceptor.listen(asio::socket_base::max_listen_connections, ec);
  if (ec) {
    impl->user.release();
    return fail(ErrorCode::Network, "cannot listen: " + ec.message(), where,
                ec == asio::error::address_in_use ? "another program uses this port: pick another or port 0"
                                                  : "use a local address of this machine");
  }
  impl->port = impl->acceptor.local_endpoint(ec).port();
  // The first accept is started on the network thread, like every later one.
  thread.runAndWait([&] { impl->acceptMore(); });
  return std::unique_ptr<TcpServer>(new TcpServer(std::move(impl)));
}

std::uint16_t TcpServer::port() const noexcept { return impl_->port; }

Status TcpServer::send(ConnectionId id, std::span<const std::byte> bytes) {
  auto link = impl_->find(id);
  if (!link)
    return fail(ErrorCode::NotFound,
                formatString("no open connection %llu", static_cast<unsigned long long>(id)),
                formatString("TcpServer port %u", impl_->port), "the peer disconnected; see onDisconnect");
  return link->send(bytes);
}

Status TcpServer::disconnect(ConnectionId id) {
  auto link = impl_->find(id);
  if (!link)
    return fail(ErrorCode::NotFound,
                formatString("no open connection %llu", static_cast<unsigned long long>(id)),
                formatString("TcpServer port %u", impl_->port));
  impl_->user.thread().runAndWait([&] { link->close(DisconnectReason::LocalClose, "disconnect() called"); });
  return ok();
}

void TcpServer::close() {
  Impl& m = *impl_;
  if (m.closed.load()) return;
  m.user.thread().runAndWait([&] {
    if (m.closed.exchange(true)) return;
    std::error_code ignored;
    m.acceptor.close(ignored);
    std::map<ConnectionId, std::shared_ptr<Link>> links;
    {
      std::lock_guard lock(m.mutex);
      links = m.links;
    }
    for (auto& [id, link] : links) link->close(DisconnectReason::LocalClose, "server closed");
    std::lock_guard lock(m.mutex);
    m.links.clear();
  });
  m.user.release();
}

std::vector<ConnectionId> TcpServer::connections() const {
  std::lock_guard lock(impl_->mutex);
  std::vector<ConnectionId> ids;
  for (const auto& [id, link] : impl_->links) ids.push_back(id);
  return ids;
}

Result<ConnectionStats> TcpServer::stats(ConnectionId id) const {
  auto link = impl_->find(id);
  if (!link)
    return fail(ErrorCode::NotFound,
                formatString("no open connection %llu", static_cast<unsigned long long>(id)),
                formatString("TcpServer port %u", impl_->port));
  return link->stats();
}

TcpServerStats TcpServer::serverStats() const {
  std::lock_guard lock(impl_->mutex);
  return {impl_->accepted.load(), impl_->refused.load(), impl_->links.size()};
}

// ---------------------------------------------------------------- client ---

struct TcpClient::Impl : std::enable_shared_from_this<TcpClient::Impl> {
  Impl(IoThread& t, TcpClientOptions o, TcpClientCallbacks c)
      : user(t),
        options(std::move(o)),
        callbacks(std::move(c)),
        name("TcpClient to " + describe(options.peer)),
        socket(t.impl().io),
        timer(t.impl().io),
        delay(options.reconnectInitialDelay) {}

  /// Network thread. Records and announces a state.
  void setState(ConnectionState s, const std::string& detail) {
    {
      std::lock_guard lock(mutex);
      state.store(s);
      lastDetail = detail;
    }
    changed.notify_all();
    if (callbacks.onState) user.thread().impl().guard("onState", [&] { callbacks.onState(s, detail); });
  }

  void attempt() {
    const std::uint64_t gen = ++generation;
    timedOut = false;
    std::error_code ignored;
    socket.close(ignored);
    socket = tcp::socket(user.io());
    setState(ConnectionState::Connecting, "connecting to " + describe(options.peer));
    timer.expires_after(options.connectTimeout);
    timer.async_wait([self = shared_from_this(), gen](std::error_code ec) {
      if (ec || self->closed.load() || gen != self->generation) return;
      self->timedOut = true;
      std::error_code e;
      self->socket.close(e);  // aborts the connect
    });
    asio::async_connect(
        socket, endpoints, [self = shared_from_this(), gen](std::error_code ec, const tcp::endpoint&) {
          if (self->closed.load() || gen != self->generation) return;
          self->timer.cancel();
          if (ec) {
            self->failed(self->timedOut
                             ? formatString("no answer within %lld ms",
                                            static_cast<long long>(self->options.connectTimeout.count()))
                             : ec.message());
            return;
          }
          self->connected();
        });
  }

  void connected() {
    std::error_code ec;
    if (options.noDelay) socket.set_option(tcp::no_delay(true), ec);
    if (everConnected) counters->reconnects.fetch_add(1, std::memory_order_relaxed);
    everConnected = true;
    delay = options.reconnectInitialDelay;
    auto l = std::make_shared<Link>(user.thread(), std::move(socket), options.sendQueueBytes,
                                    options.readChunkBytes, counters, name);
    socket = tcp::socket(user.io());
    std::weak_ptr<Impl> weak = weak_from_this();
    l->onBytes = [weak](std::span<const std::byte> bytes) {
      if (auto s = weak.lock(); s && s->callbacks.onBytes) s->callbacks.onBytes(bytes);
    };
    l->onEnd = [weak](const Disconnect& d) {
      if (auto s = weak.lock()) s->lost(d);
    };
    {
      std::lock_guard lock(mutex);
      link = l;
    }
    setState(ConnectionState::Connected, "connected to " + describe(options.peer));
    if (!l->closed()) l->start();
  }

  void lost(const Disconnect& d) {
    {
      std::lock_guard lock(mutex);
      link.reset();
    }
    lastUnsent = d.unsentBytes;
    if (closed.load()) return;
    std::string detail = std::string("connection lost: ") + toString(d.reason) + " (" + d.detail + ")";
    if (d.unsentBytes > 0)
      detail += formatString("; %llu unsent bytes discarded", static_cast<unsigned long long>(d.unsentBytes));
    failed(detail);
  }

  void failed(const std::string& detail) {
    if (!options.reconnect) {
      setState(ConnectionState::Disconnected, detail);
      return;
    }
    const auto wait = delay;
    delay = std::min(delay * 2, options.reconnectMaxDelay);
    setState(ConnectionState::Backoff,
             detail + formatString("; retrying in %lld ms", static_cast<long long>(wait.count())));
    const std::uint64_t gen = ++generation;
    timer.expires_after(wait);
    timer.async_wait([self = shared_from_this(), gen](std::error_code ec) {
      if (ec || self->closed.load() || gen != self->generation) return;
      self->attempt();
    });
  }

  IoUser user;
  TcpClientOptions options;
  TcpClientCallbacks callbacks;
  std::string name;
  std::vector<tcp::endpoint> endpoints;
  std::shared_ptr<LinkCounters> counters = std::make_shared<LinkCounters>();

  // Network thread only.
  tcp::socket socket;
  asio::steady_timer timer;
  std::chrono::milliseconds delay;
  std::uint64_t generation = 0;
  bool timedOut = false;
  bool everConnected = false;
  std::uint64_t lastUnsent = 0;

  std::atomic<bool> closed{false};
  std::atomic<ConnectionState> state{ConnectionState::Disconnected};
  mutable std::mutex mutex;  // guards link, lastDetail; with `changed` for waitConnected
  mutable std::condition_variable changed;
  std::shared_ptr<Link> link;
  std::string lastDetail = "not started";
};

TcpClient::TcpClient(std::shared_ptr<Impl> impl) : impl_(std::move(impl)) {}

TcpClient::~TcpClient() { close(); }

Result<std::unique_ptr<TcpClient>> TcpClient::connect(IoThread& thread, TcpClientOptions options,
                                                      TcpClientCallbacks callbacks) {
  const std::string where = "TcpClient to " + describe(options.peer);
  if (auto s = checkBuffers(options.sendQueueBytes, options.readChunkBytes, where.c_str()); !s)
    return s.error();
  if (options.peer.port == 0)
    return fail(ErrorCode::InvalidArgument, "peer.port is 0", where, "give the server's port");
  if (options.connectTimeout.count() <= 0 || options.reconnectInitialDelay.count() <= 0 ||
      options.reconnectMaxDelay < options.reconnectInitialDelay)
    return fail(
        ErrorCode::InvalidArgument,
        formatString("connectTimeout %lld ms, reconnectInitialDelay %lld ms, reconnectMaxDelay %lld ms",
                     static_cast<long long>(options.connectTimeout.count()),
                     static_cast<long long>(options.reconnectInitialDelay.count()),
                     static_cast<long long>(options.reconnectMaxDelay.count())),
        where, "times must be > 0 and reconnectMaxDelay >= reconnectInitialDelay");
  std::vector<tcp::endpoint> endpoints;
  std::error_code ec;
  const asio::ip::address numeric = asio::ip::make_address(options.peer.address, ec);
  if (!ec) {
    endpoints.emplace_back(numeric, options.peer.port);
  } else {
    // A host name: resolved once, here, on the calling thread.
    tcp::resolver resolver(thread.impl().io);
    auto results = resolver.resolve(options.peer.address, std::to_string(options.peer.port), ec);
    if (ec || results.empty())
      return fail(ErrorCode::NotFound, "cannot resolve '" + options.peer.address + "': " + ec.message(),
                  where, "check the host name, or give a numeric address");
    for (const auto& r : results) endpoints.push_back(r.endpoint());
  }
  auto impl = std::make_shared<Impl>(thread, std::move(options), std::move(callbacks));
  impl->endpoints = std::move(endpoints);
  thread.runAndWait([&] { impl->attempt(); });
  return std::unique_ptr<TcpClient>(new TcpClient(std::move(impl)));
}

Status TcpClient::send(std::span<const std::byte> bytes) {
  std::shared_ptr<Link> link;
  {
    std::lock_guard lock(impl_->mutex);
    link = impl_->link;
  }
  if (!link)
    return fail(
        ErrorCode::Network,
        std::string("not connected (") + toString(impl_->state.load()) + ": " +
            [&] {
              std::lock_guard lock(impl_->mutex);
              return impl_->lastDetail;
            }() +
            ")",
        impl_->name, "wait for onState(Connected)");
  return link->send(bytes);
}

ConnectionState TcpClient::state() const noexcept { return impl_->state.load(); }

Status TcpClient::waitConnected(std::chrono::milliseconds timeout) const {
  if (impl_->user.thread().onThread())
    return fail(ErrorCode::InvalidArgument, "waitConnected() called on the network thread", impl_->name,
                "react to onState(Connected) instead of waiting on the network thread");
  std::unique_lock lock(impl_->mutex);
  impl_->changed.wait_for(lock, timeout, [&] {
    const ConnectionState s = impl_->state.load();
    return s == ConnectionState::Connected || s == ConnectionState::Closed;
  });
  if (impl_->state.load() == ConnectionState::Connected) return ok();
  return fail(ErrorCode::Timeout,
              formatString("not connected after %lld ms (", static_cast<long long>(timeout.count())) +
                  toString(impl_->state.load()) + ": " + impl_->lastDetail + ")",
              impl_->name, "check that the server runs and that its allow-list admits this host");
}

void TcpClient::close() {
  Impl& m = *impl_;
  if (m.closed.load()) return;
  m.user.thread().runAndWait([&] {
    if (m.closed.exchange(true)) return;
    ++m.generation;
    m.timer.cancel();
    std::error_code ignored;
    m.socket.close(ignored);
    std::shared_ptr<Link> l;
    {
      std::lock_guard lock(m.mutex);
      l = m.link;
    }
    if (l) l->close(DisconnectReason::LocalClose, "close() called");
    std::string detail = "close() called";
    if (m.lastUnsent > 0)
      detail += formatString("; %llu unsent bytes discarded", static_cast<unsigned long long>(m.lastUnsent));
    m.setState(ConnectionState::Closed, detail);
  });
  m.user.release();
}

ConnectionStats TcpClient::stats() const { return impl_->counters->snapshot(); }

}  // namespace dm
