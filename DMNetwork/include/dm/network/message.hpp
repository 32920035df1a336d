// dm/network/message.hpp — the DMPlatform message model on the wire.
//
// One framing for every transport (TCP, UDP, SLIP): a fixed 28-byte
// little-endian header followed by the payload.
//
//   offset size field
//        0    4 magic        "DMNM" (0x44 0x4D 0x4E 0x4D)
//        4    1 version      1
//        5    1 flags        application-defined bits, carried as is
//        6    2 type         application-defined message type
//        8    4 sequence     per-stream counter, wraps at 2^32
//       12    4 length       payload bytes
//       16    8 timestamp    int64 ns on the sender's dm::Clock
//       24    4 checksum     CRC-32C of bytes [0, 24) followed by the payload
//
// decodeMessage() checks, in this order: size ≥ 28, magic, version, length ≤
// the configured maximum (before anything is allocated or read), that the
// datagram holds exactly 28 + length bytes, then the checksum. What holds:
// every message with one, two or three flipped bits (payload up to 600
// bytes) is rejected — a flip in magic, version or length fails those
// checks, any other is caught by CRC-32C (Hamming distance 6 up to 5243
// bits). MessageStreamDecoder frames a TCP byte stream the same way and
// refuses a header whose length exceeds the limit as soon as the 28 header
// bytes are in, without waiting for the payload. SequenceTracker classifies
// arrivals (in order, duplicate, late, gap) for unreliable transports.
//
// @code
//   auto bytes = dm::encodeMessage({.type = 7, .sequence = n, .timestampNs = clock.now()}, payload);
//   auto msg = dm::decodeMessage(*bytes);
//   if (!msg) dm::log::warn("%s", msg.error().message().c_str());
// @endcode
#pragma once

#include <dm/core/result.hpp>

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <vector>

namespace dm {

inline constexpr std::size_t kMessageHeaderBytes = 28;  ///< fixed header size
inline constexpr std::uint8_t kMessageVersion = 1;      ///< the version this build writes and reads
/// "DMNM", the first four bytes of every message.
inline constexpr std::array<std::byte, 4> kMessageMagic{std::byte{'D'}, std::byte{'M'}, std::byte{'N'},
                                                        std::byte{'M'}};

/// The application-visible header fields (magic, version, length and
/// checksum are handled by the codec).
struct MessageHeader {
  std::uint16_t type = 0;
  std::uint8_t flags = 0;
  std::uint32_t sequence = 0;
  std::int64_t timestampNs = 0;  ///< sender's dm::Clock::now(), ns
};

/// Size limits applied before anything is allocated.
struct MessageLimits {
  std::size_t maxPayloadBytes = std::size_t{16} << 20;  ///< 16 MiB; at most 2^32 - 1
};

/// A decoded message; `payload` views the caller's (or the stream decoder's) buffer.
struct MessageView {
  MessageHeader header;
  std::span<const std::byte> payload;
};

/// Header bytes [0, 24) as appendMessage() writes them for `header` and a
/// payload of `payloadBytes` — everything the checksum (and an
/// authentication tag, dm/network/auth.hpp) covers before the payload. O(1).
std::array<std::byte, 24> messageHeaderPrefix(const MessageHeader& header,
                                              std::uint32_t payloadBytes) noexcept;

/// Completes a message whose payload is already in place at
/// `out[28, 28 + payloadBytes)`: writes the header and its checksum into
/// `out[0, 28)`. Returns 28 + payloadBytes, or 0 when `out` is shorter than
/// that or the payload is 2^32 bytes or more. No allocation: the real-time
/// senders (dm/network/teleop.hpp) build datagrams on the stack with it. O(n).
std::size_t sealMessage(const MessageHeader& header, std::span<std::byte> out, std::size_t payloadBytes) noexcept;

/// Appends header + payload to `out` (no allocation when `out` has the
/// capacity). Fails with InvalidArgument when the payload exceeds
/// limits.maxPayloadBytes. O(n).
Status appendMessage(const MessageHeader& header, std::span<const std::byte> payload,
                     std::vector<std::byte>& out, const MessageLimits& limits = {});

/// Encodes one message into a new buffer of 28 + payload.size() bytes.
/// @code
///   auto bytes = dm::encodeMessage({.type = 1, .sequence = 42}, payload);
///   if (bytes) socket.send(*bytes);
/// @endcode
Result<std::vector<std::byte>> encodeMessage(const MessageHeader& header, std::span<const std::byte> payload,
                                             const MessageLimits& limits = {});

/// Decodes exactly one message occupying all of `bytes` (a datagram or a
/// SLIP frame). Fails with Parse (bad magic, truncated, trailing bytes,
/// checksum), Version (unknown version) or Unsupported (length over the
/// limit); the message names the field and its byte offset. O(n), no
/// allocation on success.
/// @code
///   auto m = dm::decodeMessage(datagram);
///   if (m) handle(m->header.type, m->payload);
/// @endcode
Result<MessageView> decodeMessage(std::span<const std::byte> bytes, const MessageLimits& limits = {});

/// Frames messages out of a byte stream (TCP) that arrives in arbitrary
/// chunks. Not thread-safe. After a failure the stream cannot be trusted to
/// be in sync: the decoder stays failed (returning the same error) until
/// reset(); the caller usually closes the connection.
///
/// @code
///   dm::MessageStreamDecoder dec;
///   if (!dec.feed(chunk)) return;                      // caller is not draining
///   while (true) { auto m = dec.next(); if (!m || !*m) break; handle(**m); }
/// @endcode
class MessageStreamDecoder {
 public:
  explicit MessageStreamDecoder(MessageLimits limits = {});

  /// Buffers `bytes`. Fails with Busy (buffering nothing) when the unread
  /// bytes would exceed 2 × (28 + maxPayloadBytes) + 64 KiB: drain with next().
  Status feed(std::span<const std::byte> bytes);
  /// The next complete message (viewing the internal buffer, valid until
  /// the next feed()/next()/reset()), std::nullopt when more bytes are
  /// needed, or the error that broke the stream. The header is validated as
  /// soon as its 28 bytes are in.
  Result<std::optional<MessageView>> next();
  /// Bytes of the stream consumed by next() so far (offset of the next message).
  std::uint64_t streamOffset() const { return consumed_; }
  std::size_t bufferedBytes() const { return buffer_.size() - read_; }
  /// Empties the buffer and clears a failure.
  void reset();

 private:
  MessageLimits limits_;
  std::vector<std::byte> buffer_;
  std::size_t read_ = 0;
  std::uint64_t consumed_ = 0;
  std::optional<Error> failure_;
};

/// How one sequence number relates to those seen before.
enum class Arrival : std::uint8_t {
  First,      ///< the first number after construction / reset()
  InOrder,    ///< exactly one after the highest so far
  Gap,        ///< ahead of the highest by more than one: `lost` numbers skipped
  Late,       ///< behind the highest, not seen before (reordered; it fills an earlier gap)
  Duplicate,  ///< seen before (within the window)
  Stale,      ///< further behind than the window: cannot tell late from duplicate
};
/// "first", "in order", "gap", ...
const char* toString(Arrival a) noexcept;

/// Result of SequenceTracker::observe().
struct ArrivalInfo {
  Arrival kind = Arrival::First;
  std::uint32_t lost = 0;  ///< for Gap: numbers skipped (highest+1 .. seq-1)
};

/// Running totals of a SequenceTracker.
struct SequenceStats {
  std::uint64_t received = 0;  ///< every observe()
  std::uint64_t inOrder = 0;
  std::uint64_t duplicates = 0;
  std::uint64_t late = 0;
  std::uint64_t stale = 0;
  std::uint64_t missing = 0;  ///< skipped numbers not (yet) arrived late: sum of gaps − late arrivals
};

/// Classifies u32 sequence numbers of an unreliable stream (UDP tele-op)
/// with serial-number arithmetic (RFC 1982), so wrap-around at 2^32 is in
/// order. Remembers the last kWindow numbers in a fixed bitmap: observe() is
/// O(1) amortised (a jump clears at most kWindow bits), never allocates or
/// locks — usable on real-time threads. A jump of ≥ 2^31 ahead reads as
/// behind (Stale); call reset() when the peer restarts its counter.
///
/// @code
///   dm::SequenceTracker seq;
///   auto a = seq.observe(msg.header.sequence);
///   if (a.kind == dm::Arrival::Gap) dm::log::warn("lost %u", a.lost);
/// @endcode
class SequenceTracker {
 public:
  static constexpr std::uint32_t kWindow = 1024;
  ArrivalInfo observe(std::uint32_t sequence) noexcept;
  /// Highest (most advanced) sequence number seen; meaningless before the first.
  std::uint32_t highest() const { return highest_; }
  const SequenceStats& stats() const { return stats_; }
  void reset() noexcept;

 private:
  bool seen(std::uint32_t s) const { return (bits_[(s % kWindow) / 64] >> (s % 64)) & 1u; }
  void mark(std::uint32_t s) { bits_[(s % kWindow) / 64] |= std::uint64_t{1} << (s % 64); }
  void unmark(std::uint32_t s) { bits_[(s % kWindow) / 64] &= ~(std::uint64_t{1} << (s % 64)); }

  std::array<std::uint64_t, kWindow / 64> bits_{};
  std::uint32_t highest_ = 0;
  bool started_ = false;
  SequenceStats stats_;
};

}  // namespace dm
