// The DMPlatform message model: encoder, datagram decoder, stream decoder,
// sequence tracker.
#include <dm/network/crc.hpp>
#include <dm/network/message.hpp>

#include <algorithm>
#include <cstring>
#include <limits>

#include "le_bytes.hpp"

namespace dm {
namespace {

using detail::getLe;
using detail::putLe;

constexpr std::size_t kOffVersion = 4, kOffFlags = 5, kOffType = 6, kOffSeq = 8, kOffLength = 12,
                      kOffTime = 16, kOffChecksum = 24;

std::uint32_t checksumOf(const std::byte* header, std::span<const std::byte> payload) {
  return crc32c(payload, crc32c({header, kOffChecksum}));
}

std::string at(std::uint64_t base, std::size_t off) {
  return formatString("message byte %llu", static_cast<unsigned long long>(base + off));
}

// Validates the fixed header fields; `base` is the stream offset of byte 0.
Result<std::uint32_t> checkHeader(const std::byte* h, const MessageLimits& limits, std::uint64_t base) {
  if (std::memcmp(h, kMessageMagic.data(), kMessageMagic.size()) != 0)
    return fail(ErrorCode::Parse,
                formatString("magic is %02X %02X %02X %02X, expected \"DMNM\" (44 4D 4E 4D)",
                             std::to_integer<unsigned>(h[0]), std::to_integer<unsigned>(h[1]),
                             std::to_integer<unsigned>(h[2]), std::to_integer<unsigned>(h[3])),
                at(base, 0),
                "the peer does not speak the DMPlatform message model, or the stream is out of sync");
  const unsigned version = std::to_integer<unsigned>(h[kOffVersion]);
  if (version != kMessageVersion)
    return fail(ErrorCode::Version,
                formatString("version is %u, this build reads version %u", version,
                             static_cast<unsigned>(kMessageVersion)),
                at(base, kOffVersion), "update the older side");
  const auto length = static_cast<std::uint32_t>(getLe(h + kOffLength, 4));
  if (length > limits.maxPayloadBytes)
    return fail(
        ErrorCode::Unsupported,
        formatString("length field says %u payload bytes, the limit is %zu", length, limits.maxPayloadBytes),
        at(base, kOffLength), "raise MessageLimits::maxPayloadBytes if the peer legitimately sends more");
  return length;
}

Result<MessageView> finish(std::span<const std::byte> msg, std::uint32_t length, std::uint64_t base) {
  const std::byte* h = msg.data();
  const auto payload = msg.subspan(kMessageHeaderBytes, length);
  const auto stored = static_cast<std::uint32_t>(getLe(h + kOffChecksum, 4));
  const std::uint32_t computed = checksumOf(h, payload);
  if (stored != computed)
    return fail(ErrorCode::Parse,
                formatString("checksum is 0x%08X, the CRC-32C of header and %u payload bytes is 0x%08X",
                             stored, length, computed),
                at(base, kOffChecksum), "the message was corrupted in transit; drop it");
  MessageView v;
  v.header.type = static_cast<std::uint16_t>(getLe(h + kOffType, 2));
  v.header.flags = std::to_integer<std::uint8_t>(h[kOffFlags]);
  v.header.sequence = static_cast<std::uint32_t>(getLe(h + kOffSeq, 4));
  v.header.timestampNs = static_cast<std::int64_t>(getLe(h + kOffTime, 8));
  v.payload = payload;
  return v;
}

}  // namespace

std::array<std::byte, 24> messageHeaderPrefix(const MessageHeader& header,
                                              std::uint32_t payloadBytes) noexcept {
  static_assert(kOffChecksum == 24);
  std::array<std::byte, 24> h{};
  std::memcpy(h.data(), kMessageMagic.data(), kMessageMagic.size());
  h[kOffVersion] = std::byte{kMessageVersion};
  h[kOffFlags] = std::byte{header.flags};
  putLe(h.data() + kOffType, header.type, 2);
  putLe(h.data() + kOffSeq, header.sequence, 4);
  putLe(h.data() + kOffLength, payloadBytes, 4);
  putLe(h.data() + kOffTime, static_cast<std::uint64_t>(header.timestampNs), 8);
  return h;
}

Status appendMessage(const MessageHeader& header, std::span<const std::byte> payload,
                     std::vector<std::byte>& out, const MessageLimits& limits) {
  const std::size_t limit =
      std::min<std::size_t>(limits.maxPayloadBytes, std::numeric_limits<std::uint32_t>::max());
  if (payload.size() > limit)
    return fail(ErrorCode::InvalidArgument,
                formatString("payload of %zu bytes exceeds the limit of %zu", payload.size(), limit),
                "appendMessage", "split the payload or raise MessageLimits::maxPayloadBytes");
  const std::size_t start = out.size();
  out.resize(start + kMessageHeaderBytes);
  out.insert(out.end(), payload.begin(), payload.end());
  sealMessage(header, std::span<std::byte>(out).subspan(start), payload.size());
  return ok();
}

std::size_t sealMessage(const MessageHeader& header, std::span<std::byte> out, std::size_t payloadBytes) noexcept {
  if (payloadBytes > std::numeric_limits<std::uint32_t>::max() || out.size() < kMessageHeaderBytes ||
      out.size() - kMessageHeaderBytes < payloadBytes)
    return 0;
  std::byte* h = out.data();
  const auto prefix = messageHeaderPrefix(header, static_cast<std::uint32_t>(payloadBytes));
  std::memcpy(h, prefix.data(), prefix.size());
  putLe(h + kOffChecksum, checksumOf(h, out.subspan(kMessageHeaderBytes, payloadBytes)), 4);
  return kMessageHeaderBytes + payloadBytes;
}

Result<std::vector<std::byte>> encodeMessage(const MessageHeader& header, std::span<const std::byte> payload,
                                             const MessageLimits& limits) {
  std::vector<std::byte> out;
  out.reserve(kMessageHeaderBytes + payload.size());
  if (auto s = appendMessage(header, payload, out, limits); !s) return std::move(s).error();
  return out;
}

Result<MessageView> decodeMessage(std::span<const std::byte> bytes, const MessageLimits& limits) {
  if (bytes.size() < kMessageHeaderBytes)
    return fail(
        ErrorCode::Parse,
        formatString("%zu bytes is shorter than the %zu-byte header", bytes.size(), kMessageHeaderBytes),
        at(0, bytes.size()), "the datagram was truncated; drop it");
  auto length = checkHeader(bytes.data(), limits, 0);
  if (!length) return std::move(length).error();
  const std::size_t expected = kMessageHeaderBytes + *length;
  if (bytes.size() != expected)
    return fail(
        ErrorCode::Parse,
        formatString("length field says %u payload bytes, so %zu bytes in all, but the datagram has %zu",
                     *length, expected, bytes.size()),
        at(0, kOffLength), "the datagram was truncated or padded; drop it");
  return finish(bytes, *length, 0);
}

MessageStreamDecoder::MessageStreamDecoder(MessageLimits limits) : limits_(limits) {}

void MessageStreamDecoder::reset() {
  buffer_.clear();
  read_ = 0;
  consumed_ = 0;
  failure_.reset();
}

Status MessageStreamDecoder::feed(std::span<const std::byte> bytes) {
  const std::size_t cap = 2 * (kMessageHeaderBytes + limits_.maxPayloadBytes) + (std::size_t{64} << 10);
  if (bufferedBytes() + bytes.size() > cap)
    return fail(ErrorCode::Busy,
                formatString("%zu unread bytes plus %zu new exceed the %zu-byte buffer limit",
                             bufferedBytes(), bytes.size(), cap),
                formatString("stream byte %llu", static_cast<unsigned long long>(consumed_)),
                "call next() until it returns no message before feeding more");
  if (read_ > 0 && (read_ >= buffer_.size() / 2 || buffer_.size() + bytes.size() > buffer_.capacity())) {
    buffer_.erase(buffer_.begin(), buffer_.begin() + static_cast<std::ptrdiff_t>(read_));
    read_ = 0;
  }
  buffer_.insert(buffer_.end(), bytes.begin(), bytes.end());
  return ok();
}

Result<std::optional<MessageView>> MessageStreamDecoder::next() {
  if (failure_) return *failure_;
  const std::size_t avail = bufferedBytes();
  if (avail < kMessageHeaderBytes) return std::optional<MessageView>{};
  const std::span<const std::byte> rest(buffer_.data() + read_, avail);
  auto length = checkHeader(rest.data(), limits_, consumed_);
  if (!length) {
    failure_ = length.error();
    return *failure_;
  }
  const std::size_t total = kMessageHeaderBytes + *length;
  if (avail < total) return std::optional<MessageView>{};
  auto view = finish(rest.first(total), *length, consumed_);
  if (!view) {
    failure_ = view.error();
    return *failure_;
  }
  read_ += total;
  consumed_ += total;
  return std::optional<MessageView>(*view);
}

const char* toString(Arrival a) noexcept {
  switch (a) {
    case Arrival::First:
      return "first";
    case Arrival::InOrder:
      return "in order";
    case Arrival::Gap:
      return "gap";
    case Arrival::Late:
      return "late";
    case Arrival::Duplicate:
      return "duplicate";
    case Arrival::Stale:
      return "stale";
  }
  return "?";
}

void SequenceTracker::reset() noexcept {
  bits_.fill(0);
  highest_ = 0;
  started_ = false;
  stats_ = {};
}

ArrivalInfo SequenceTracker::observe(std::uint32_t sequence) noexcept {
  ++stats_.received;
  if (!started_) {
    started_ = true;
    highest_ = sequence;
    mark(sequence);
    return {Arrival::First, 0};
  }
  const auto diff = static_cast<std::int32_t>(sequence - highest_);
  if (diff > 0) {
    const auto ahead = static_cast<std::uint32_t>(diff);
    // Forget the slots that the numbers highest+1 .. sequence take over.
    if (ahead >= kWindow) {
      bits_.fill(0);
    } else {
      for (std::uint32_t s = highest_ + 1; s != sequence + 1; ++s) unmark(s);
    }
    highest_ = sequence;
    mark(sequence);
    if (ahead == 1) {
      ++stats_.inOrder;
      return {Arrival::InOrder, 0};
    }
    stats_.missing += ahead - 1;
    return {Arrival::Gap, ahead - 1};
  }
  const auto behind = static_cast<std::uint32_t>(-static_cast<std::int64_t>(diff));
  if (behind >= kWindow) {
    ++stats_.stale;
    return {Arrival::Stale, 0};
  }
  if (seen(sequence)) {
    ++stats_.duplicates;
    return {Arrival::Duplicate, 0};
  }
  mark(sequence);
  ++stats_.late;
  if (stats_.missing > 0) --stats_.missing;
  return {Arrival::Late, 0};
}

}  // namespace dm
