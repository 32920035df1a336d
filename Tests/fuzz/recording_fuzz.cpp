// libFuzzer target: dm::parseRecording on arbitrary bytes, then every typed
// decoder (haptic state, controller state, DAQ block, sensor reading) on
// every record — never crashes, never reads out of bounds; every record it
// returns lies inside the input, and what a decoder accepts is valid
// (axes in [-1, 1], finite values, ordered DAQ frames).
#include <dm/io/recorder.hpp>

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>

namespace {

void check(bool ok) {
  if (!ok) std::abort();
}

void decodeAll(const dm::RecordedRecord& rec) {
  (void)dm::decodeHapticState(rec);
  if (auto c = dm::decodeControllerState(rec); c.ok())
    for (double a : c->axes) check(a >= -1.0 && a <= 1.0);
  if (auto s = dm::decodeSensorReading(rec); s.ok()) {
    check(static_cast<unsigned>(s->type) < 4u && s->timeNs == rec.timeNs);
    for (double v : s->values) check(std::isfinite(v));
  }
  if (auto b = dm::decodeDaqBlock(rec); b.ok()) {
    check(b->channelCount >= 1 && b->channelCount <= dm::kDaqMaxChannels && !b->frames.empty());
    for (std::size_t f = 0; f < b->frames.size(); ++f) {
      check(f == 0 ||
            (b->frames[f].index > b->frames[f - 1].index && b->frames[f].timeNs >= b->frames[f - 1].timeNs));
      for (std::size_t c = 0; c < b->channelCount; ++c) check(std::isfinite(b->frames[f].values[c]));
    }
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  auto r = dm::parseRecording(std::span<const std::uint8_t>(data, size), "fuzz");
  if (r.ok()) {
    std::size_t total = 12 + r->metadata.size();
    for (std::size_t i = 0; i < r->records.size(); ++i) {
      const dm::RecordedRecord& rec = r->records[i];
      check(rec.index == i && rec.offset == total);
      total += 20 + rec.payload.size();
      decodeAll(rec);
      // The same payload under each DMPlatform type, to reach every decoder's checks.
      dm::RecordedRecord as = rec;
      for (std::uint16_t type = 1; type <= 5; ++type) {
        as.type = type;
        decodeAll(as);
      }
    }
    check(total == r->validBytes && r->validBytes <= size);
  }
  return 0;
}
