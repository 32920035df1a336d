// dm/network/udp.hpp — UDP datagrams on the network thread.
//
// A UdpEndpoint is one bound UDP socket. Datagrams arrive whole through
// onDatagram on the network thread (which must not block; the span is valid
// only during the call). Sending copies the datagram into a bounded queue
// and returns; the network thread sends it. Datagrams larger than the
// configured maximum are refused when sending (InvalidArgument) and dropped
// and counted when received, so neither side ever allocates from a size
// chosen by the peer. A full send queue answers Busy (back-pressure).
// "Connecting" fixes the peer: send() goes there and datagrams from anyone
// else are dropped (the kernel filters them).
//
// @code
//   auto udp = dm::UdpEndpoint::open(net, {.local = {"127.0.0.1", 0}}, onDatagram);
//   if (udp) status = (*udp)->sendTo({"127.0.0.1", 5005}, bytes);
//   dm::UdpStats s = (*udp)->stats();
// @endcode
#pragma once

#include <dm/core/result.hpp>
#include <dm/network/io_thread.hpp>

#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>

namespace dm {

/// Largest payload of an IPv4 UDP datagram (65535 - 8 - 20 bytes).
inline constexpr std::size_t kMaxUdpPayload = 65507;

/// Settings of a UdpEndpoint.
struct UdpOptions {
  SocketAddress local{"127.0.0.1", 0};    ///< bind address; port 0 = ephemeral (see port())
  std::size_t maxDatagramBytes = 1472;    ///< 1 .. kMaxUdpPayload; 1472 fits one Ethernet frame
  std::size_t sendQueueDatagrams = 1024;  ///< datagrams waiting to be sent (>= 1)
};

/// Counters of a UdpEndpoint.
struct UdpStats {
  std::uint64_t datagramsIn = 0, bytesIn = 0;    ///< delivered to onDatagram
  std::uint64_t datagramsOut = 0, bytesOut = 0;  ///< handed to the kernel
  std::uint64_t oversizeDropped = 0;             ///< received datagrams above maxDatagramBytes, dropped
  std::uint64_t queueFullDropped = 0;            ///< sends refused with Busy
  std::uint64_t sendErrors = 0;  ///< sends the kernel refused (e.g. no route, ICMP unreachable)
};

/// Receives one datagram on the network thread.
using DatagramCallback = std::function<void(std::span<const std::byte>, const SocketAddress& from)>;

/// One bound UDP socket.
class UdpEndpoint {
 public:
  /// Binds to `options.local` and starts receiving on `thread`. Fails with
  /// InvalidArgument for a bad address or option, Network when the port is
  /// taken.
  /// @code
  ///   auto udp = dm::UdpEndpoint::open(net, {}, onDatagram);
  ///   if (!udp) return udp.error();
  /// @endcode
  static Result<std::unique_ptr<UdpEndpoint>> open(IoThread& thread, UdpOptions options,
                                                   DatagramCallback onDatagram);
  /// close(), then release.
  ~UdpEndpoint();
  UdpEndpoint(const UdpEndpoint&) = delete;
  UdpEndpoint& operator=(const UdpEndpoint&) = delete;

  /// The bound port. O(1).
  std::uint16_t port() const noexcept;
  /// Queues one datagram to `to` (numeric address). InvalidArgument when it
  /// exceeds maxDatagramBytes or the address is bad, Busy when the queue is
  /// full, Network after close(). Any thread; O(bytes.size()).
  Status sendTo(const SocketAddress& to, std::span<const std::byte> bytes);
  /// Fixes the peer: send() goes there, datagrams from other senders are
  /// dropped by the kernel. InvalidArgument for a bad address.
  Status connect(const SocketAddress& peer);
  /// Queues one datagram to the connected peer (as sendTo); InvalidArgument
  /// when not connected.
  Status send(std::span<const std::byte> bytes);
  /// Stops receiving and sending; datagrams still queued are counted in the
  /// log. No callback runs after it returns. Idempotent.
  void close();
  UdpStats stats() const;

  struct Impl;

 private:
  explicit UdpEndpoint(std::shared_ptr<Impl> impl);
  std::shared_ptr<Impl> impl_;
};

}  // namespace dm
