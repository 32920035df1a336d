// libFuzzer target: the authenticated-message verify path. Byte 0 picks the
// mode. Mode 0 feeds the rest as a framed message straight to verify()
// (valid tags are astronomically unlikely, so this exercises the framing,
// flag, size and NoTag/BadTag paths). Mode 1 signs the rest as a payload
// first, checks that it verifies, then damages the signed message as
// bytes 1-4 say (flip a bit at an offset, or truncate) and checks that a
// damaged message is never accepted.
#include <dm/network/auth.hpp>
#include <dm/network/message.hpp>

#include <cstdint>
#include <cstdlib>

namespace {

dm::MessageAuthenticator& authenticator() {
  static auto a = [] {
    std::vector<std::byte> key(32, std::byte{0x42});
    auto r = dm::MessageAuthenticator::fromKey(key);
    if (!r) std::abort();
    return std::move(r).value();
  }();
  return a;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  auto& auth = authenticator();
  const dm::MessageLimits limits{.maxPayloadBytes = 1 << 16};
  std::span<const std::byte> in(reinterpret_cast<const std::byte*>(data + 1), size - 1);
  dm::SequenceTracker seq;
  std::span<const std::byte> body;
  if (data[0] % 2 == 0) {
    auto m = dm::decodeMessage(in, limits);
    if (m) (void)auth.verify(*m, seq, body);
    return 0;
  }
  if (in.size() < 4) return 0;
  const std::uint32_t op = static_cast<std::uint32_t>(data[1]) | static_cast<std::uint32_t>(data[2]) << 8 |
                           static_cast<std::uint32_t>(data[3]) << 16 |
                           static_cast<std::uint32_t>(data[4]) << 24;
  const auto payload = in.subspan(4);
  std::vector<std::byte> wire;
  if (!auth.sign({.type = static_cast<std::uint16_t>(op), .sequence = op}, payload, wire, limits)) return 0;
  {
    auto m = dm::decodeMessage(wire, limits);
    if (!m || auth.verify(*m, seq, body) != dm::AuthVerdict::Accepted) std::abort();
    if (body.size() != payload.size()) std::abort();
    seq.reset();
  }
  if (op & 1u) {
    wire.resize((op >> 1) % wire.size());  // truncate
  } else {
    const std::size_t at = (op >> 4) % wire.size();
    wire[at] ^= static_cast<std::byte>(1u << ((op >> 1) & 7u));
  }
  auto m = dm::decodeMessage(wire, limits);
  if (m && auth.verify(*m, seq, body) == dm::AuthVerdict::Accepted) std::abort();
  return 0;
}
