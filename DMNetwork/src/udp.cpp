// udp.cpp — dm::UdpEndpoint on asio: one receive loop with a buffer one byte
// larger than the maximum (so oversize datagrams are detected, not silently
// truncated) and a bounded send queue drained on the network thread.
#include <dm/core/log.hpp>
#include <dm/network/udp.hpp>

#include <deque>
#include <optional>
#include <utility>
#include <vector>

#include "io_thread_impl.hpp"

namespace dm {

using asio::ip::udp;

struct UdpEndpoint::Impl : std::enable_shared_from_this<UdpEndpoint::Impl> {
  Impl(IoThread& t, UdpOptions o, DatagramCallback cb)
      : user(t), options(std::move(o)), onDatagram(std::move(cb)), socket(t.impl().io) {}

  void receiveMore() {
    socket.async_receive_from(
        asio::buffer(buffer), from, [self = shared_from_this()](std::error_code ec, std::size_t n) {
          if (self->closed.load()) return;
          if (ec == asio::error::operation_aborted) return;
          if (!ec) {
            if (n > self->options.maxDatagramBytes) {
              self->oversizeDropped.fetch_add(1, std::memory_order_relaxed);
            } else {
              self->datagramsIn.fetch_add(1, std::memory_order_relaxed);
              self->bytesIn.fetch_add(n, std::memory_order_relaxed);
              if (self->onDatagram) {
                const SocketAddress sender = toSocketAddress(self->from.address(), self->from.port());
                self->user.thread().impl().guard("onDatagram", [&] {
                  self->onDatagram(std::span<const std::byte>(self->buffer.data(), n), sender);
                });
              }
            }
          }
          // Other errors (e.g. ECONNREFUSED from an earlier send's ICMP answer on
          // a connected socket) concern one datagram, not the socket: go on.
          if (!self->closed.load()) self->receiveMore();
        });
  }

  Status enqueue(const udp::endpoint& to, std::span<const std::byte> bytes, const std::string& toText) {
    if (bytes.size() > options.maxDatagramBytes)
      return fail(ErrorCode::InvalidArgument,
                  formatString("datagram of %zu bytes exceeds maxDatagramBytes %zu", bytes.size(),
                               options.maxDatagramBytes),
                  name + " -> " + toText, "split the payload or raise UdpOptions::maxDatagramBytes");
    std::lock_guard lock(mutex);
    if (closed.load()) return fail(ErrorCode::Network, "endpoint is closed", name, "open a new UdpEndpoint");
    if (queue.size() >= options.sendQueueDatagrams) {
      queueFullDropped.fetch_add(1, std::memory_order_relaxed);
      return fail(ErrorCode::Busy, formatString("send queue full (%zu datagrams)", queue.size()), name,
                  "sending faster than the network thread can: drop this datagram or retry later");
    }
    queue.emplace_back(to, std::vector<std::byte>(bytes.begin(), bytes.end()));
    if (!sending) {
      sending = true;
      asio::post(user.io(), [self = shared_from_this()] { self->sendMore(); });
    }
    return ok();
  }

  void sendMore() {
    {
      std::lock_guard lock(mutex);
      if (closed.load() || queue.empty()) {
        sending = false;
        return;
      }
      current = std::move(queue.front());
      queue.pop_front();
    }
    socket.async_send_to(asio::buffer(current.second), current.first,
                         [self = shared_from_this()](std::error_code ec, std::size_t n) {
                           if (self->closed.load()) return;
                           if (ec) {
                             self->sendErrors.fetch_add(1, std::memory_order_relaxed);
                           } else {
                             self->datagramsOut.fetch_add(1, std::memory_order_relaxed);
                             self->bytesOut.fetch_add(n, std::memory_order_relaxed);
                           }
                           self->sendMore();
                         });
  }

  IoUser user;
  UdpOptions options;
  DatagramCallback onDatagram;
  std::string name;
  udp::socket socket;
  std::vector<std::byte> buffer;  // maxDatagramBytes + 1
  udp::endpoint from;             // network thread only
  std::uint16_t port = 0;
  std::pair<udp::endpoint, std::vector<std::byte>> current;  // in flight; network thread only

  std::atomic<bool> closed{false};
  mutable std::mutex mutex;  // guards queue, sending, peer
  std::deque<std::pair<udp::endpoint, std::vector<std::byte>>> queue;
  bool sending = false;
  std::optional<udp::endpoint> peer;

  std::atomic<std::uint64_t> datagramsIn{0}, bytesIn{0}, datagramsOut{0}, bytesOut{0}, oversizeDropped{0},
      queueFullDropped{0}, sendErrors{0};
};

UdpEndpoint::UdpEndpoint(std::shared_ptr<Impl> impl) : impl_(std::move(impl)) {}

UdpEndpoint::~UdpEndpoint() { close(); }

Result<std::unique_ptr<UdpEndpoint>> UdpEndpoint::open(IoThread& thread, UdpOptions options,
                                                       DatagramCallback onDatagram) {
  const std::string where = "UdpEndpoint " + describe(options.local);
  if (options.maxDatagramBytes == 0 || options.maxDatagramBytes > kMaxUdpPayload)
    return fail(ErrorCode::InvalidArgument, formatString("maxDatagramBytes is %zu", options.maxDatagramBytes),
                where, formatString("use 1 .. %zu bytes", kMaxUdpPayload));
  if (options.sendQueueDatagrams == 0)
    return fail(ErrorCode::InvalidArgument, "sendQueueDatagrams is 0", where,
                "allow at least 1 queued datagram");
  auto address = parseAddress(options.local.address, where + ": local.address");
  if (!address) return address.error();
  auto impl = std::make_shared<Impl>(thread, std::move(options), std::move(onDatagram));
  impl->buffer.resize(impl->options.maxDatagramBytes + 1);
  std::error_code ec;
  const udp::endpoint endpoint(*address, impl->options.local.port);
  impl->socket.open(endpoint.protocol(), ec);
  if (!ec) impl->socket.bind(endpoint, ec);
  if (ec) {
    impl->user.release();
    return fail(ErrorCode::Network, "cannot bind: " + ec.message(), where,
                ec == asio::error::address_in_use ? "another program uses this port: pick another or port 0"
                                                  : "use a local address of this machine");
  }
  impl->port = impl->socket.local_endpoint(ec).port();
  impl->name = "UdpEndpoint " + describe({impl->options.local.address, impl->port});
  thread.runAndWait([&] { impl->receiveMore(); });
  return std::unique_ptr<UdpEndpoint>(new UdpEndpoint(std::move(impl)));
}

std::uint16_t UdpEndpoint::port() const noexcept { return impl_->port; }

Status UdpEndpoint::sendTo(const SocketAddress& to, std::span<const std::byte> bytes) {
  auto address = parseAddress(to.address, impl_->name + ": sendTo destination");
  if (!address) return address.error();
  if (to.port == 0)
    return fail(ErrorCode::InvalidArgument, "destination port is 0", impl_->name, "give the receiver's port");
  return impl_->enqueue(udp::endpoint(*address, to.port), bytes, describe(to));
}

Status UdpEndpoint::connect(const SocketAddress& peer) {
  auto address = parseAddress(peer.address, impl_->name + ": connect peer");
  if (!address) return address.error();
  if (peer.port == 0)
    return fail(ErrorCode::InvalidArgument, "peer port is 0", impl_->name, "give the peer's port");
  const udp::endpoint endpoint(*address, peer.port);
  std::error_code ec;
  impl_->user.thread().runAndWait([&] { impl_->socket.connect(endpoint, ec); });
  if (ec)
    return fail(ErrorCode::Network, "cannot connect to " + describe(peer) + ": " + ec.message(), impl_->name,
                "use an address reachable from the bound address (IPv4 with IPv4)");
  std::lock_guard lock(impl_->mutex);
  impl_->peer = endpoint;
  return ok();
}

Status UdpEndpoint::send(std::span<const std::byte> bytes) {
  std::optional<udp::endpoint> peer;
  {
    std::lock_guard lock(impl_->mutex);
    peer = impl_->peer;
  }
  if (!peer)
    return fail(ErrorCode::InvalidArgument, "send() before connect()", impl_->name,
                "call connect(peer) first, or use sendTo()");
  return impl_->enqueue(*peer, bytes, describe(toSocketAddress(peer->address(), peer->port())));
}

void UdpEndpoint::close() {
  Impl& m = *impl_;
  if (m.closed.load()) return;
  m.user.thread().runAndWait([&] {
    std::size_t unsent = 0;
    {
      std::lock_guard lock(m.mutex);
      if (m.closed.exchange(true)) return;
      unsent = m.queue.size();
      m.queue.clear();
    }
    std::error_code ignored;
    m.socket.close(ignored);
    if (unsent > 0) dm::log::warn("%s closed with %zu datagrams unsent; discarded", m.name.c_str(), unsent);
  });
  m.user.release();
}

UdpStats UdpEndpoint::stats() const {
  const Impl& m = *impl_;
  return {m.datagramsIn.load(),     m.bytesIn.load(),          m.datagramsOut.load(), m.bytesOut.load(),
          m.oversizeDropped.load(), m.queueFullDropped.load(), m.sendErrors.load()};
}

}  // namespace dm
