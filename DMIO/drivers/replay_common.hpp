// What the replay drivers (replay-haptic, replay-controller, replay-daq,
// replay-sensor) share: the common parameters, loading one record type of a
// recording (record_format.hpp) into time-ordered frames with errors that
// name the file, record and byte, the replay clock that maps host time to
// recorded time (scaled rate, loop), sample-and-hold lookup and the identity
// a replay reports. Header-only, like the drivers' other helpers, so that a
// driver built as a plugin needs no DMPlatform library.
//
// Common parameters:
//   file    the recording (required)
//   rate    playback speed, > 0 (1 = as recorded, 2 = twice as fast)
//   loop    0 | 1: start over after the last record
//   strict  0 | 1: 1 refuses a recording with a damaged tail (a killed
//           recorder); 0 replays its complete records and reports the cut
//           in the identity's model ("…; tail cut at byte N")
#pragma once

#include <algorithm>
#include <climits>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <initializer_list>
#include <new>
#include <string>
#include <vector>

#include "driver_params.hpp"
#include "record_format.hpp"

namespace dm::driver {

/// The parameters every replay driver takes (see the file comment).
struct ReplayOptions {
  const char* file = nullptr;
  double rate = 1.0;
  bool loop = false;
  bool strict = false;
};

/// Reads the common parameters; fails through `p` when 'file' is missing.
inline ReplayOptions readReplayOptions(ParamReader& p) {
  ReplayOptions o;
  o.rate = p.number("rate", 1.0, 1e-6, 1e6);
  o.loop = p.number("loop", 0.0, 0.0, 1.0) != 0.0;
  o.strict = p.number("strict", 0.0, 0.0, 1.0) != 0.0;
  o.file = p.find("file");
  if (p.ok() && !o.file) p.failf("parameter 'file' is required");
  return o;
}

/// What loadReplay() found besides the frames.
struct ReplaySource {
  std::size_t records = 0;  ///< records of the replayed type
  std::size_t cutAt = 0;    ///< byte where a damaged tail starts; 0 for a clean end
};

/// Reads `o.file` (≤ 1 GiB) and calls decode(const record::RecordView&) for
/// every valid record of type `type`, in file order; decode returns why the
/// payload is invalid ("" when it took it). Fails through `p`, naming the
/// file and the byte: unreadable file, bad header, an invalid payload, no
/// record of `type` ("no <what> records"), or (strict) a damaged tail.
template <class Decode>
bool loadReplay(const ReplayOptions& o, std::uint16_t type, const char* what, ParamReader& p,
                ReplaySource& src, Decode&& decode) {
  std::FILE* f = std::fopen(o.file, "rb");
  if (!f) {
    p.failf("parameter 'file': cannot open '%s'", o.file);
    return false;
  }
  std::vector<unsigned char> bytes;
  unsigned char chunk[65536];
  std::size_t n;
  while ((n = std::fread(chunk, 1, sizeof chunk, f)) > 0) {
    if (bytes.size() + n > (std::size_t(1) << 30)) {
      std::fclose(f);
      p.failf("%s: larger than 1 GiB", o.file);
      return false;
    }
    bytes.insert(bytes.end(), chunk, chunk + n);
  }
  std::fclose(f);
  std::string bad;
  const auto scan = record::scan(bytes.data(), bytes.size(), [&](const record::RecordView& v) {
    if (v.type != type || !bad.empty()) return;
    std::string why = decode(v);
    if (!why.empty()) bad = record::recordPlace(v.index, v.offset) + ": " + why;
    ++src.records;
  });
  if (!scan.headerOk) {
    p.failf("%s: %s", o.file, scan.error.c_str());
    return false;
  }
  if (!bad.empty()) {
    p.failf("%s: %s", o.file, bad.c_str());
    return false;
  }
  if (!scan.tail.empty()) {
    if (o.strict) {
      p.failf("%s: %s (parameter 'strict' is 1)", o.file, scan.tail.c_str());
      return false;
    }
    src.cutAt = scan.validBytes;
  }
  if (src.records == 0) {
    p.failf("%s: no %s records (type %u)", o.file, what, static_cast<unsigned>(type));
    return false;
  }
  return true;
}

/// Maps host time to recorded time. The first call of at() (or start())
/// fixes host time `start` ↔ the first record; recorded offset =
/// rate · (now − start). Looping, the recording repeats with period
/// span + the mean record interval (1 ms for a single record), so a loop
/// is as evenly spaced as the recording.
class ReplayClock {
 public:
  /// Where host time now falls in the recording.
  struct Position {
    std::int64_t recordedNs = 0;  ///< recorded time (first record's time + offset within the cycle)
    std::int64_t cycle = 0;       ///< loop cycle (0 without loop)
    bool ended = false;           ///< without loop: past the last record
  };

  /// Sets the recorded span (first and last record time, `count` records). O(1).
  void configure(const ReplayOptions& o, std::int64_t first, std::int64_t last, std::size_t count) noexcept {
    rate_ = o.rate;
    loop_ = o.loop;
    first_ = first;
    span_ = last - first;
    period_ = count > 1 && span_ > 0 ? span_ + span_ / static_cast<std::int64_t>(count - 1) : 1'000'000;
  }
  /// Fixes the start at host time now, if not yet started.
  void start(std::int64_t now) noexcept {
    if (started_) return;
    started_ = true;
    startNs_ = now;
  }
  /// The recorded position at host time now (starts the clock). O(1).
  Position at(std::int64_t now) noexcept {
    start(now);
    Position p;
    // Clamped so that absurd host times cannot overflow the conversion.
    const double scaled = std::clamp(rate_ * static_cast<double>(now - startNs_), -4e18, 4e18);
    std::int64_t offset = static_cast<std::int64_t>(scaled);
    if (loop_ && offset > 0) {
      p.cycle = offset / period_;
      offset %= period_;
    }
    p.ended = !loop_ && offset > span_;
    p.recordedNs = first_ + offset;
    return p;
  }
  /// The host time at which the record at recorded time t of loop cycle
  /// `cycle` plays: start + (t − first + cycle · period) / rate, exact at rate 1.
  std::int64_t hostTime(std::int64_t t, std::int64_t cycle) const noexcept {
    const std::int64_t rel = t - first_ + cycle * period_;
    if (rate_ == 1.0) return startNs_ + rel;
    return startNs_ + std::llround(static_cast<double>(rel) / rate_);
  }
  /// Records per second of host time for `count` records over the span (a
  /// poll or sample rate to report); `fallback` for a single record.
  double eventRate(double count, double fallback) const noexcept {
    return span_ > 0 && count > 1 ? rate_ * (count - 1) * 1e9 / static_cast<double>(span_) : fallback;
  }
  bool loop() const noexcept { return loop_; }

 private:
  double rate_ = 1.0;
  bool loop_ = false, started_ = false;
  std::int64_t first_ = 0, span_ = 0, period_ = 1'000'000, startNs_ = 0;
};

/// Identity of a replay: vendor "DMPlatform", model "recorded <what>" (plus
/// "; tail cut at byte N" for a damaged file), serial "<records>-records".
inline void replayIdentity(DmDeviceIdentity& id, const char* driver, const char* what,
                           const ReplaySource& src) {
  copyField(id.driver, driver);
  copyField(id.vendor, "DMPlatform");
  char model[128];  // truncated into the 64-byte field
  if (src.cutAt)
    std::snprintf(model, sizeof model, "recorded %s; tail cut at byte %zu", what, src.cutAt);
  else
    std::snprintf(model, sizeof model, "recorded %s", what);
  copyField(id.model, model);
  std::snprintf(id.serial, sizeof id.serial, "%zu-records", src.records);
}

/// The latest frame with t ≤ `t` (the first frame when all are later);
/// frames sorted by time and not empty. O(log n).
template <class Frame>
const Frame& latestAtOrBefore(const std::vector<Frame>& frames, std::int64_t t) noexcept {
  auto it = std::upper_bound(frames.begin(), frames.end(), t,
                             [](std::int64_t x, const Frame& f) { return x < f.t; });
  return it == frames.begin() ? frames.front() : *(it - 1);
}

/// What every replay keeps: the frames of one record type (each with a
/// member `t`, recorded ns), where they came from, and the clock.
template <class Frame>
struct ReplayStream {
  std::vector<Frame> frames;  ///< time-ordered, not empty once loaded
  ReplaySource source;
  ReplayClock clock;

  /// loadReplay() of the records of `type` (checked to be `size` bytes, 0:
  /// any; `what` names them in messages), each passed to
  /// decode(const record::RecordView&, std::vector<Frame>&) → why invalid
  /// or ""; then sorts the frames by time (stable) and configures the clock.
  template <class Decode>
  bool load(const ReplayOptions& o, std::uint16_t type, std::uint32_t size, const char* what, ParamReader& p,
            Decode&& decode) {
    const bool loaded = loadReplay(o, type, what, p, source, [&](const record::RecordView& v) {
      std::string why = record::checkTypeAndSize(v.type, v.size, type, size, what);
      return why.empty() ? decode(v, frames) : why;
    });
    if (!loaded) return false;  // on success every record gave at least one frame
    const auto earlier = [](const Frame& a, const Frame& b) { return a.t < b.t; };
    if (!std::is_sorted(frames.begin(), frames.end(), earlier))
      std::stable_sort(frames.begin(), frames.end(), earlier);
    clock.configure(o, frames.front().t, frames.back().t, frames.size());
    return true;
  }

  /// Sample and hold at host time now (starts the clock): the latest frame
  /// at or before the recorded position, and in hostTimeNs the host time at
  /// which it plays; nullptr past the last frame without loop (end of
  /// stream). Real-time safe; O(log n).
  const Frame* playing(std::int64_t now, std::int64_t& hostTimeNs) noexcept {
    const ReplayClock::Position at = clock.at(now);
    if (at.ended) return nullptr;
    const Frame& f = latestAtOrBefore(frames, at.recordedNs);
    hostTimeNs = clock.hostTime(f.t, at.cycle);
    return &f;
  }
};

/// The open function of a replay driver: checks the parameter names
/// (`known` includes the common ones), creates a Device, reads the common
/// options and calls load(Device&, const ReplayOptions&, ParamReader&),
/// which reads the driver's own parameters and loads the recording. Returns
/// nullptr with the first message in error[errorSize] on failure.
template <class Device, class Load>
DmDevice* openReplay(const DmDeviceParam* params, std::size_t count, char* error, std::size_t errorSize,
                     std::initializer_list<const char*> known, Load&& load) {
  ParamReader p(params, count, error, errorSize);
  p.onlyKnown(known);
  auto* d = new (std::nothrow) Device();
  if (!d) {
    p.failf("out of memory");
    return nullptr;
  }
  const ReplayOptions o = readReplayOptions(p);
  if (p.ok()) load(*d, o, p);
  if (!p.ok()) {
    delete d;
    return nullptr;
  }
  return reinterpret_cast<DmDevice*>(d);
}

/// The close function of a replay driver whose instances are Device.
template <class Device>
void closeReplay(DmDevice* d) noexcept {
  delete reinterpret_cast<Device*>(d);
}

}  // namespace dm::driver
