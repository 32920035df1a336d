// libFuzzer target: the DMPlatform message model. The input is decoded as
// one datagram (an accepted message must re-encode to the same bytes) and
// as a TCP stream split into chunks (input byte 0 picks the chunk size).
#include <dm/network/message.hpp>

#include <cstdint>
#include <cstdlib>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const dm::MessageLimits limits{.maxPayloadBytes = 4096};
  std::span<const std::byte> in(reinterpret_cast<const std::byte*>(data), size);
  if (auto m = dm::decodeMessage(in, limits); m.ok()) {
    auto again = dm::encodeMessage(m->header, m->payload, limits);
    if (!again.ok() || !std::equal(again->begin(), again->end(), in.begin(), in.end())) std::abort();
  }
  if (size == 0) return 0;
  const std::size_t chunk = data[0] % 61 + 1;
  dm::MessageStreamDecoder dec(limits);
  std::span<const std::byte> rest = in.subspan(1);
  bool failed = false;
  while (!rest.empty() && !failed) {
    const auto part = rest.first(std::min(chunk, rest.size()));
    rest = rest.subspan(part.size());
    if (!dec.feed(part).ok()) break;
    while (true) {
      auto m = dec.next();
      if (!m.ok()) {
        failed = true;
        break;
      }
      if (!*m) break;
      if ((*m)->payload.size() > limits.maxPayloadBytes) std::abort();
    }
  }
  dm::SequenceTracker seq;
  for (std::size_t i = 0; i + 4 <= size; i += 4) {
    std::uint32_t s = 0;
    for (int k = 0; k < 4; ++k)
      s |= static_cast<std::uint32_t>(data[i + static_cast<std::size_t>(k)]) << (8 * k);
    seq.observe(s);
  }
  return 0;
}
