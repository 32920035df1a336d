// libFuzzer target: the SLIP decoder fed in chunks. Input byte 0 picks the
// chunk size, byte 1 the frame limit. Checks: no crash, frames are non-empty
// and within the limit, and every frame re-encodes and decodes to itself.
#include <dm/network/slip.hpp>

#include <cstdint>
#include <cstdlib>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 2) return 0;
  const std::size_t chunk = data[0] % 17 + 1;
  const std::size_t limit = static_cast<std::size_t>(data[1]) * 4 + 1;
  std::span<const std::byte> in(reinterpret_cast<const std::byte*>(data + 2), size - 2);
  dm::SlipDecoder dec(limit);
  while (!in.empty()) {
    const auto part = in.first(std::min(chunk, in.size()));
    in = in.subspan(part.size());
    dec.feed(part, [&](std::span<const std::byte> frame) {
      if (frame.empty() || frame.size() > limit) std::abort();
      const auto wire = dm::encodeSlip(frame);
      dm::SlipDecoder again(limit);
      int frames = 0;
      again.feed(wire, [&](std::span<const std::byte> f) {
        ++frames;
        if (!std::equal(f.begin(), f.end(), frame.begin(), frame.end())) std::abort();
      });
      if (frames != 1) std::abort();
    });
  }
  if (dec.stats().bytesIn != size - 2) std::abort();
  return 0;
}
