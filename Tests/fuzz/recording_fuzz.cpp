// libFuzzer target: dm::parseRecording on arbitrary bytes — never crashes,
// never reads out of bounds; every record it returns lies inside the input.
#include <dm/io/recorder.hpp>

#include <cstddef>
#include <cstdint>
#include <cstdlib>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  auto r = dm::parseRecording(std::span<const std::uint8_t>(data, size), "fuzz");
  if (r.ok()) {
    std::size_t total = 12 + r->metadata.size();
    for (const dm::RecordedRecord& rec : r->records) {
      total += 20 + rec.payload.size();
      (void)dm::decodeHapticState(rec);
    }
    if (total != r->validBytes || r->validBytes > size) std::abort();
  }
  return 0;
}
