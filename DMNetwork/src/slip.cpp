// SLIP (RFC 1055) encoder and incremental decoder.
#include <dm/network/slip.hpp>

#include <algorithm>

namespace dm {

void appendSlip(std::span<const std::byte> packet, std::vector<std::byte>& out) {
  out.push_back(kSlipEnd);
  for (std::byte b : packet) {
    if (b == kSlipEnd) {
      out.push_back(kSlipEsc);
      out.push_back(kSlipEscEnd);
    } else if (b == kSlipEsc) {
      out.push_back(kSlipEsc);
      out.push_back(kSlipEscEsc);
    } else {
      out.push_back(b);
    }
  }
  out.push_back(kSlipEnd);
}

std::vector<std::byte> encodeSlip(std::span<const std::byte> packet) {
  std::vector<std::byte> out;
  out.reserve(packet.size() + packet.size() / 64 + 8);
  appendSlip(packet, out);
  return out;
}

std::string SlipFault::message() const {
  if (kind == SlipFaultKind::BadEscape)
    return formatString(
        "SLIP: ESC (0xDB) followed by 0x%02X at stream byte %llu (only 0xDC or 0xDD may follow ESC); frame "
        "dropped, resynchronising at the next END (0xC0)",
        static_cast<unsigned>(byte), static_cast<unsigned long long>(streamOffset));
  return formatString(
      "SLIP: frame longer than the decoder's maximum at stream byte %llu; frame dropped, resynchronising at "
      "the next END (0xC0) — raise SlipDecoder's maxFrameBytes if the peer sends larger packets",
      static_cast<unsigned long long>(streamOffset));
}

SlipDecoder::SlipDecoder(std::size_t maxFrameBytes) : maxFrame_(std::max<std::size_t>(maxFrameBytes, 1)) {
  buffer_.reserve(std::min<std::size_t>(maxFrame_, std::size_t{1} << 20));
}

void SlipDecoder::reset() {
  buffer_.clear();
  state_ = State::Normal;
  hasFrame_ = hasFault_ = clearOnNext_ = false;
  offset_ = 0;
}

void SlipDecoder::dropFrame(SlipFaultKind kind, std::uint8_t byte, std::size_t rawSkipped) {
  lastFault_ = SlipFault{kind, offset_, byte};
  if (kind == SlipFaultKind::BadEscape)
    ++stats_.badEscapes;
  else
    ++stats_.oversizeFrames;
  stats_.bytesDropped += buffer_.size() + rawSkipped;
  buffer_.clear();
  hasFault_ = true;
}

std::size_t SlipDecoder::poll(std::span<const std::byte> chunk) {
  if (clearOnNext_) buffer_.clear();
  clearOnNext_ = false;
  hasFrame_ = hasFault_ = false;
  std::size_t i = 0;
  for (; i < chunk.size(); ++i, ++offset_) {
    const std::byte b = chunk[i];
    ++stats_.bytesIn;
    if (state_ == State::Skipping) {
      if (b == kSlipEnd)
        state_ = State::Normal;
      else
        ++stats_.bytesDropped;
      continue;
    }
    if (state_ == State::Escaped) {
      std::byte decoded;
      if (b == kSlipEscEnd) {
        decoded = kSlipEnd;
      } else if (b == kSlipEscEsc) {
        decoded = kSlipEsc;
      } else {
        // ESC END ends the frame here (the END resynchronises at once);
        // ESC <other> skips to the next END.
        state_ = b == kSlipEnd ? State::Normal : State::Skipping;
        dropFrame(SlipFaultKind::BadEscape, std::to_integer<std::uint8_t>(b), b == kSlipEnd ? 0 : 1);
        ++i, ++offset_;
        return i;
      }
      state_ = State::Normal;
      if (buffer_.size() >= maxFrame_) {
        state_ = State::Skipping;
        dropFrame(SlipFaultKind::Oversize, std::to_integer<std::uint8_t>(b), 2);
        ++i, ++offset_;
        return i;
      }
      buffer_.push_back(decoded);
      continue;
    }
    if (b == kSlipEnd) {
      if (buffer_.empty()) continue;  // leading END or END END: line-noise flush, not a frame
      ++stats_.frames;
      hasFrame_ = true;
      clearOnNext_ = true;
      ++i, ++offset_;
      return i;
    }
    if (b == kSlipEsc) {
      state_ = State::Escaped;
      continue;
    }
    if (buffer_.size() >= maxFrame_) {
      state_ = State::Skipping;
      dropFrame(SlipFaultKind::Oversize, std::to_integer<std::uint8_t>(b), 1);
      ++i, ++offset_;
      return i;
    }
    buffer_.push_back(b);
  }
  return i;
}

}  // namespace dm
