// dm/network/auth.hpp — shared-secret authentication of DMPlatform messages.
//
// Command channels can require that every message carries an HMAC-SHA-256
// tag under a shared key, and refuse replays by sequence number. The tag
// rides inside an ordinary message (dm/network/message.hpp), so every
// transport and MessageStreamDecoder carry it unchanged:
//
//   offset        size field
//        0          28 message header; flags bit 0x80 (kMessageFlagAuthenticated)
//                      set; length = n + 32
//       28           n application payload
//   28 + n          32 tag = HMAC-SHA-256(key, header bytes [0, 24) ‖ payload)
//
// The tag covers magic, version, flags, type, sequence, length (including
// the tag) and timestamp — every header byte except the CRC-32C at [24, 28),
// which is itself computed over those bytes and the tag, so it cannot be
// inside the data it protects; a forged CRC fails the tag anyway.
//
// Replay rule: verify() checks the tag first (constant time, CRYPTO_memcmp)
// and only then offers the sequence number to the caller's SequenceTracker
// (one per peer and stream), so a forged message can never advance or
// poison the tracker. Duplicate and Stale (more than 1024 behind) numbers
// are refused; First, InOrder, Gap and Late are accepted. Late is accepted
// because reordering is normal on UDP and a late number is, by the
// tracker's bitmap, provably not seen before — accepting it cannot replay
// anything, while refusing it would drop genuine commands.
//
// @code
//   auto auth = dm::MessageAuthenticator::fromHex(config.key);   // ≥ 32 hex digits
//   std::vector<std::byte> wire; auth->sign({.type = 3, .sequence = n}, payload, wire);
//   dm::SequenceTracker seq; std::span<const std::byte> body;
//   if (auth->verify(*dm::decodeMessage(wire), seq, body) == dm::AuthVerdict::Accepted) run(body);
// @endcode
#pragma once

#include <dm/core/result.hpp>
#include <dm/network/message.hpp>

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string_view>
#include <vector>

namespace dm {

/// Header flag bit that marks a message whose payload ends in a 32-byte tag.
inline constexpr std::uint8_t kMessageFlagAuthenticated = 0x80;
inline constexpr std::size_t kAuthTagBytes = 32;     ///< HMAC-SHA-256 output size
inline constexpr std::size_t kAuthMinKeyBytes = 16;  ///< shorter keys are refused
using AuthTag = std::array<std::byte, kAuthTagBytes>;

/// HMAC-SHA-256 (RFC 2104 / FIPS 198-1) of `data` under `key` (any length;
/// keys longer than 64 bytes are hashed first, as the RFC says). O(n).
/// Fails with Internal only if libcrypto fails.
/// @code
///   auto tag = dm::hmacSha256(key, data);
///   if (tag) send(*tag);
/// @endcode
Result<AuthTag> hmacSha256(std::span<const std::byte> key, std::span<const std::byte> data);

/// The bytes of a key written as hex (config files): an even number of
/// [0-9a-fA-F], at least 32 digits (16 bytes). Fails with InvalidArgument
/// naming the offending character's offset or the length. Wipe the result
/// when done with it.
Result<std::vector<std::byte>> parseHexKey(std::string_view hex);

/// Outcome of MessageAuthenticator::verify().
enum class AuthVerdict : std::uint8_t {
  Accepted,  ///< tag valid, sequence number new
  NoTag,     ///< flag bit not set or payload shorter than the tag
  BadTag,    ///< tag does not match (tampered, wrong key or forged)
  Replayed,  ///< tag valid, sequence number seen before (Duplicate)
  Stale,     ///< tag valid, sequence number too far behind to tell (Stale)
};
/// "accepted", "no tag", "bad tag", "replayed", "stale".
const char* toString(AuthVerdict v) noexcept;

/// Signs and verifies messages under one shared key. Construction fetches
/// SHA-256 from libcrypto and pads the key once (RFC 2104 ipad/opad);
/// sign()/verify() then reuse one digest context. Not thread-safe (one instance per thread: copying is not
/// allowed, make one per thread from the same key); movable.
class MessageAuthenticator {
 public:
  /// Keys from raw bytes; fails with InvalidArgument when key.size() < 16.
  /// @code
  ///   auto a = dm::MessageAuthenticator::fromKey(keyBytes);
  ///   if (!a) dm::log::warn("%s", a.error().message().c_str());
  /// @endcode
  static Result<MessageAuthenticator> fromKey(std::span<const std::byte> key);
  /// Keys from a hex string (config files): an even number of [0-9a-fA-F],
  /// at least 32 digits (16 bytes). Fails with InvalidArgument naming the
  /// offending character offset or the length.
  static Result<MessageAuthenticator> fromHex(std::string_view hex);

  MessageAuthenticator(MessageAuthenticator&&) noexcept;
  MessageAuthenticator& operator=(MessageAuthenticator&&) noexcept;
  ~MessageAuthenticator();

  /// Appends an authenticated message (flag bit set, payload ‖ tag) to
  /// `out`. Fails with InvalidArgument when payload + 32 exceeds
  /// limits.maxPayloadBytes. O(n).
  Status sign(const MessageHeader& header, std::span<const std::byte> payload, std::vector<std::byte>& out,
              const MessageLimits& limits = {});
  /// Checks a decoded message: flag and size, then the tag in constant
  /// time, then (only if the tag is valid) the sequence number through
  /// `tracker`. On Accepted, `payload` views the application payload (tag
  /// removed). No throw, no lock, no allocation in our code; OpenSSL 3.0's
  /// digest init makes two small mallocs per call (its provider state), so
  /// on a hard real-time thread prefer verifying on the network thread.
  AuthVerdict verify(const MessageView& message, SequenceTracker& tracker,
                     std::span<const std::byte>& payload) noexcept;
  /// The tag check alone (no replay check); true when the tag is valid.
  bool tagValid(const MessageView& message) noexcept;

 private:
  struct Impl;
  explicit MessageAuthenticator(std::unique_ptr<Impl> impl);
  bool computeTag(const MessageHeader& header, std::uint32_t lengthField, std::span<const std::byte> payload,
                  AuthTag& out) noexcept;
  std::unique_ptr<Impl> impl_;
};

}  // namespace dm
