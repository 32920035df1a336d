// dm/network/slip.hpp — SLIP framing (RFC 1055) for byte streams.
//
// SLIP delimits packets on a byte stream (serial line, TCP) with END (0xC0);
// a 0xC0 or 0xDB inside a packet travels as ESC ESC_END (0xDB 0xDC) or
// ESC ESC_ESC (0xDB 0xDD). encodeSlip() writes a leading END (flushes line
// noise at the receiver) and a trailing END. SlipDecoder takes the stream in
// arbitrary chunks (any split, including between ESC and its code) and yields
// complete frames; empty frames (END END) are skipped. Faults never stop the
// decoder: a frame longer than the limit, or ESC followed by anything other
// than ESC_END / ESC_ESC, drops that frame (counted, with the stream offset of
// the offending byte) and decoding resynchronises at the next END. The frame
// buffer is allocated once (up to the limit) and reused; decoding never
// allocates per byte or per frame.
//
// @code
//   std::vector<std::byte> wire = dm::encodeSlip(payload);
//   dm::SlipDecoder dec(1500);
//   dec.feed(wire, [](std::span<const std::byte> frame) { handle(frame); });
// @endcode
#pragma once

#include <dm/core/result.hpp>

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace dm {

inline constexpr std::byte kSlipEnd{0xC0};     ///< frame delimiter
inline constexpr std::byte kSlipEsc{0xDB};     ///< escape
inline constexpr std::byte kSlipEscEnd{0xDC};  ///< ESC ESC_END stands for a data 0xC0
inline constexpr std::byte kSlipEscEsc{0xDD};  ///< ESC ESC_ESC stands for a data 0xDB

/// SLIP-encodes one packet: END, the escaped bytes, END. At most 2n + 2
/// bytes. O(n).
/// @code
///   auto wire = dm::encodeSlip(std::as_bytes(std::span(text)));
/// @endcode
std::vector<std::byte> encodeSlip(std::span<const std::byte> packet);

/// Like encodeSlip() but appends to `out` (no allocation when `out` has the
/// capacity: reserve 2n + 2).
void appendSlip(std::span<const std::byte> packet, std::vector<std::byte>& out);

/// Why a SLIP frame was dropped.
enum class SlipFaultKind : std::uint8_t {
  BadEscape,  ///< ESC followed by a byte other than ESC_END / ESC_ESC (END included)
  Oversize,   ///< the frame grew past the decoder's maximum frame length
};

/// One dropped frame: what happened and where.
struct SlipFault {
  SlipFaultKind kind = SlipFaultKind::BadEscape;
  std::uint64_t streamOffset = 0;  ///< offset of the offending byte since construction / reset()
  std::uint8_t byte = 0;           ///< the byte after ESC (BadEscape) or the first byte over the limit
  /// "SLIP: ESC (0xDB) followed by 0x41 at stream byte 17; frame dropped, resynchronising at the next END".
  std::string message() const;
};

/// Running totals of a SlipDecoder.
struct SlipStats {
  std::uint64_t bytesIn = 0;         ///< every byte fed
  std::uint64_t frames = 0;          ///< frames delivered
  std::uint64_t badEscapes = 0;      ///< frames dropped for a protocol violation
  std::uint64_t oversizeFrames = 0;  ///< frames dropped for exceeding the limit
  std::uint64_t bytesDropped = 0;    ///< payload bytes of dropped frames (decoded + skipped raw)
};

/// Incremental SLIP decoder. Not thread-safe; one per stream.
class SlipDecoder {
 public:
  /// Default maximum decoded frame length: 64 KiB.
  static constexpr std::size_t kDefaultMaxFrameBytes = std::size_t{64} << 10;

  /// `maxFrameBytes` (≥ 1) bounds a decoded frame; longer frames are dropped.
  /// The buffer is reserved once: min(maxFrameBytes, 1 MiB), growing
  /// geometrically up to the limit beyond that.
  explicit SlipDecoder(std::size_t maxFrameBytes = kDefaultMaxFrameBytes);

  /// Consumes bytes from `chunk` until a frame completes, a frame is
  /// dropped, or the chunk ends; returns the number of bytes consumed. After
  /// a call, hasFrame() / hasFault() say whether it stopped for a frame or a
  /// fault. O(bytes consumed), no allocation below 1 MiB frames.
  std::size_t poll(std::span<const std::byte> chunk);

  /// True when the last poll() completed a frame; frame() views it until the
  /// next poll()/feed()/reset().
  bool hasFrame() const { return hasFrame_; }
  std::span<const std::byte> frame() const { return {buffer_.data(), hasFrame_ ? buffer_.size() : 0}; }
  /// True when the last poll() dropped a frame; lastFault() says why.
  bool hasFault() const { return hasFault_; }
  const SlipFault& lastFault() const { return lastFault_; }

  /// Feeds a whole chunk, calling onFrame(std::span<const std::byte>) for
  /// each complete frame (the span is valid during the call only).
  template <class OnFrame>
  void feed(std::span<const std::byte> chunk, OnFrame&& onFrame) {
    feed(chunk, onFrame, [](const SlipFault&) {});
  }
  /// As above, also calling onFault(const SlipFault&) for each dropped frame.
  template <class OnFrame, class OnFault>
  void feed(std::span<const std::byte> chunk, OnFrame&& onFrame, OnFault&& onFault) {
    while (!chunk.empty()) {
      chunk = chunk.subspan(poll(chunk));
      if (hasFrame_) onFrame(frame());
      if (hasFault_) onFault(lastFault_);
    }
  }

  const SlipStats& stats() const { return stats_; }
  std::size_t maxFrameBytes() const { return maxFrame_; }
  /// Forgets a partial frame and the stream offset (e.g. on reconnect); keeps stats.
  void reset();

 private:
  enum class State : std::uint8_t { Normal, Escaped, Skipping };
  void dropFrame(SlipFaultKind kind, std::uint8_t byte, std::size_t rawSkipped);

  std::vector<std::byte> buffer_;
  std::size_t maxFrame_;
  State state_ = State::Normal;
  bool hasFrame_ = false;
  bool hasFault_ = false;
  bool clearOnNext_ = false;
  std::uint64_t offset_ = 0;
  SlipFault lastFault_;
  SlipStats stats_;
};

}  // namespace dm
