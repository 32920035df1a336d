// The device recording format, header-only so that the replay driver (a
// plugin linking nothing of ours) and DM::IO's recorder share one definition.
//
// File = header, then records, append-only:
//   header  "DMREC01\n" (8 bytes) | u32 metadata length M | M bytes metadata (UTF-8 text, e.g. JSON)
//   record  u32 payload length P | u32 CRC-32 of (type, time, payload) | u16 type | u16 reserved (0)
//           | i64 time (ns) | P bytes payload
// All integers little-endian. A reader accepts records until the first one
// that is incomplete or fails its CRC — the tail a killed writer leaves —
// and reports where that tail starts. P ≤ kMaxRecordPayload.
//
// Payloads of the DMPlatform record types are defined below (haptic state,
// controller state, DAQ block, sensor reading); each has a check that a
// decoder runs before trusting the bytes. The replay drivers share their
// file loading and clock through replay_common.hpp.
#pragma once

#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>

namespace dm::record {

inline constexpr char kMagic[8] = {'D', 'M', 'R', 'E', 'C', '0', '1', '\n'};
inline constexpr std::size_t kRecordHeaderBytes = 20;
inline constexpr std::uint32_t kMaxRecordPayload = 1u << 20;
inline constexpr std::uint32_t kMaxMetadata = 1u << 20;

/// Record types written by DMPlatform (users may add their own ≥ 1000).
enum Type : std::uint16_t {
  kHapticState = 1,
  kHapticOutput = 2,
  kControllerState = 3,
  kDaqBlock = 4,
  kSensorReading = 5
};

/// CRC-32 (IEEE 802.3, reflected, as zlib's crc32), continuing from `crc`.
inline std::uint32_t crc32(const void* data, std::size_t n, std::uint32_t crc = 0) noexcept {
  static const std::array<std::uint32_t, 256> table = [] {
    std::array<std::uint32_t, 256> t{};
    for (std::uint32_t i = 0; i < 256; ++i) {
      std::uint32_t c = i;
      for (int k = 0; k < 8; ++k) c = (c & 1) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
      t[i] = c;
    }
    return t;
  }();
  const auto* p = static_cast<const unsigned char*>(data);
  crc = ~crc;
  for (std::size_t i = 0; i < n; ++i) crc = table[(crc ^ p[i]) & 0xFFu] ^ (crc >> 8);
  return ~crc;
}

inline void putU16(unsigned char* p, std::uint16_t v) noexcept {
  p[0] = static_cast<unsigned char>(v);
  p[1] = static_cast<unsigned char>(v >> 8);
}
inline void putU32(unsigned char* p, std::uint32_t v) noexcept {
  for (int i = 0; i < 4; ++i) p[i] = static_cast<unsigned char>(v >> (8 * i));
}
inline void putI64(unsigned char* p, std::int64_t v) noexcept {
  const auto u = static_cast<std::uint64_t>(v);
  for (int i = 0; i < 8; ++i) p[i] = static_cast<unsigned char>(u >> (8 * i));
}
inline void putU64(unsigned char* p, std::uint64_t v) noexcept { putI64(p, static_cast<std::int64_t>(v)); }
inline std::uint16_t getU16(const unsigned char* p) noexcept {
  return static_cast<std::uint16_t>(p[0] | (p[1] << 8));
}
inline std::uint32_t getU32(const unsigned char* p) noexcept {
  std::uint32_t v = 0;
  for (int i = 0; i < 4; ++i) v |= static_cast<std::uint32_t>(p[i]) << (8 * i);
  return v;
}
inline std::int64_t getI64(const unsigned char* p) noexcept {
  std::uint64_t v = 0;
  for (int i = 0; i < 8; ++i) v |= static_cast<std::uint64_t>(p[i]) << (8 * i);
  return static_cast<std::int64_t>(v);
}

inline std::uint64_t getU64(const unsigned char* p) noexcept { return static_cast<std::uint64_t>(getI64(p)); }

/// Writes the 20-byte header of a record into `out`.
inline void encodeRecordHeader(unsigned char* out, std::uint16_t type, std::int64_t timeNs,
                               const void* payload, std::uint32_t size) noexcept {
  putU32(out, size);
  putU16(out + 8, type);
  putU16(out + 10, 0);
  putI64(out + 12, timeNs);
  std::uint32_t crc = crc32(out + 8, 12);
  crc = crc32(payload, size, crc);
  putU32(out + 4, crc);
}

/// One record found by scan().
struct RecordView {
  std::uint16_t type = 0;
  std::int64_t timeNs = 0;
  const unsigned char* payload = nullptr;
  std::uint32_t size = 0;
  std::size_t index = 0;   ///< position among the valid records (0-based)
  std::size_t offset = 0;  ///< byte offset of the record's header in the file
};

/// What scan() found.
struct ScanResult {
  bool headerOk = false;
  std::string error;  ///< why the header is bad (headerOk false)
  std::string metadata;
  std::size_t records = 0;     ///< complete, CRC-valid records
  std::size_t validBytes = 0;  ///< offset just past the last valid record
  std::string tail;            ///< why reading stopped before the end ("" at a clean end)
};

/// Walks `bytes`, calling onRecord(const RecordView&) for every valid record
/// in order. O(size). Never reads outside [bytes, bytes + n).
template <class OnRecord>
ScanResult scan(const unsigned char* bytes, std::size_t n, OnRecord&& onRecord) {
  ScanResult r;
  if (n < 12 || std::memcmp(bytes, kMagic, 8) != 0) {
    r.error = n < 8 ? "file shorter than the 8-byte magic" : "bad magic at byte 0 (expected \"DMREC01\\n\")";
    return r;
  }
  const std::uint32_t m = getU32(bytes + 8);
  if (m > kMaxMetadata || 12 + static_cast<std::size_t>(m) > n) {
    r.error = "metadata length " + std::to_string(m) + " at byte 8 runs past the end of the file";
    return r;
  }
  r.headerOk = true;
  r.metadata.assign(reinterpret_cast<const char*>(bytes + 12), m);
  std::size_t off = 12 + m;
  r.validBytes = off;
  while (off < n) {
    if (n - off < kRecordHeaderBytes) {
      r.tail = "incomplete record header at byte " + std::to_string(off);
      break;
    }
    const std::uint32_t size = getU32(bytes + off);
    if (size > kMaxRecordPayload) {
      r.tail =
          "record length " + std::to_string(size) + " at byte " + std::to_string(off) + " exceeds the limit";
      break;
    }
    if (n - off - kRecordHeaderBytes < size) {
      r.tail = "incomplete record payload at byte " + std::to_string(off);
      break;
    }
    const unsigned char* h = bytes + off;
    std::uint32_t crc = crc32(h + 8, 12);
    crc = crc32(h + kRecordHeaderBytes, size, crc);
    if (crc != getU32(h + 4)) {
      r.tail = "CRC mismatch in the record at byte " + std::to_string(off);
      break;
    }
    onRecord(RecordView{getU16(h + 8), getI64(h + 12), h + kRecordHeaderBytes, size, r.records, off});
    ++r.records;
    off += kRecordHeaderBytes + size;
    r.validBytes = off;
  }
  return r;
}

/// Haptic state payload (the time is the record's): position[3],
/// orientation[4] (w,x,y,z), linear[3], angular[3] velocity as little-endian
/// doubles, then u32 buttons: 108 bytes.
inline constexpr std::uint32_t kHapticStateBytes = 8 * 13 + 4;

inline void encodeDoubles(unsigned char* out, const double* v, int n) noexcept {
  for (int i = 0; i < n; ++i) {
    std::uint64_t u;
    std::memcpy(&u, &v[i], 8);
    putI64(out + 8 * i, static_cast<std::int64_t>(u));
  }
}
inline void decodeDoubles(const unsigned char* in, double* v, int n) noexcept {
  for (int i = 0; i < n; ++i) {
    const auto u = static_cast<std::uint64_t>(getI64(in + 8 * i));
    std::memcpy(&v[i], &u, 8);
  }
}

/// "record N at byte B", the prefix of every payload error.
inline std::string recordPlace(std::size_t index, std::size_t offset) {
  return "record " + std::to_string(index) + " at byte " + std::to_string(offset);
}

/// Why a record of type `type` and `size` bytes is not a `what` record
/// (type `want`, `wantSize` bytes; wantSize 0: any size); "" when it is.
inline std::string checkTypeAndSize(std::uint16_t type, std::size_t size, std::uint16_t want,
                                    std::uint32_t wantSize, const char* what) {
  if (type == want && (wantSize == 0 || size == wantSize)) return {};
  return "type " + std::to_string(type) + " with " + std::to_string(size) + " bytes is not a " + what +
         " record (type " + std::to_string(want) +
         (wantSize ? ", " + std::to_string(wantSize) + " bytes)" : std::string(")"));
}

// ---- controller state ------------------------------------------------------
/// Controller state payload (the time is the record's): axes[6] as
/// little-endian doubles in [-1, 1], then buttons as two u64 (button i: bit
/// i % 64 of word i / 64): 64 bytes.
inline constexpr int kControllerAxes = 6;
inline constexpr std::uint32_t kControllerStateBytes = 8 * kControllerAxes + 16;
inline constexpr std::size_t kControllerButtonsAt = 8 * kControllerAxes;  ///< payload byte of the buttons

inline void encodeControllerState(unsigned char* out, const double* axes,
                                  const std::uint64_t* buttons) noexcept {
  encodeDoubles(out, axes, kControllerAxes);
  putU64(out + kControllerButtonsAt, buttons[0]);
  putU64(out + kControllerButtonsAt + 8, buttons[1]);
}
inline void decodeControllerState(const unsigned char* in, double* axes, std::uint64_t* buttons) noexcept {
  decodeDoubles(in, axes, kControllerAxes);
  buttons[0] = getU64(in + kControllerButtonsAt);
  buttons[1] = getU64(in + kControllerButtonsAt + 8);
}
/// Why a controller-state payload (kControllerStateBytes) is invalid; "" if valid.
inline std::string checkControllerState(const unsigned char* in) {
  double axes[kControllerAxes];
  decodeDoubles(in, axes, kControllerAxes);
  for (int i = 0; i < kControllerAxes; ++i)
    if (!(axes[i] >= -1.0 && axes[i] <= 1.0))  // NaN fails too
      return "axis " + std::to_string(i) + " (payload byte " + std::to_string(8 * i) + ") is " +
             std::to_string(axes[i]) + ", outside [-1, 1]";
  return {};
}

// ---- sensor reading ----------------------------------------------------------
/// Sensor reading payload (the time is the record's): u32 reading type
/// (DM_SENSOR_*: 0 scalar, 1 vec3, 2 quaternion, 3 pose), u32 reserved (0),
/// values[7] as little-endian doubles: 64 bytes.
inline constexpr std::uint32_t kSensorReadingBytes = 8 + 8 * 7;
inline constexpr std::uint32_t kSensorTypeCount = 4;

inline void encodeSensorReading(unsigned char* out, std::uint32_t type, const double* values) noexcept {
  putU32(out, type);
  putU32(out + 4, 0);
  encodeDoubles(out + 8, values, 7);
}
inline void decodeSensorReading(const unsigned char* in, std::uint32_t& type, double* values) noexcept {
  type = getU32(in);
  decodeDoubles(in + 8, values, 7);
}
/// Why a sensor-reading payload (kSensorReadingBytes) is invalid; "" if valid.
inline std::string checkSensorReading(const unsigned char* in) {
  std::uint32_t type = 0;
  double v[7];
  decodeSensorReading(in, type, v);
  if (type >= kSensorTypeCount)
    return "reading type " + std::to_string(type) +
           " (payload byte 0) is not 0..3 (scalar, vec3, quaternion, pose)";
  for (int i = 0; i < 7; ++i)
    if (!std::isfinite(v[i]))
      return "value " + std::to_string(i) + " (payload byte " + std::to_string(8 + 8 * i) + ") is not finite";
  return {};
}

// ---- DAQ block ---------------------------------------------------------------
/// DAQ block payload (the record's time is that of its first frame):
///   u16 channels C (1..16) | u16 frames F (≥ 1) | u32 reserved (0)
///   | u64 frames lost (overrun) just before the first frame
///   | F × (i64 time ns | u64 acquisition index | C little-endian doubles, V)
/// Indices strictly increase and times do not decrease within a block.
inline constexpr std::uint32_t kDaqBlockHeaderBytes = 16;
inline constexpr std::uint32_t kDaqMaxChannels = 16;

/// Bytes of one frame of C channels.
inline constexpr std::uint32_t daqFrameBytes(std::uint32_t channels) noexcept { return 16 + 8 * channels; }

inline void encodeDaqBlockHeader(unsigned char* out, std::uint32_t channels, std::uint32_t frames,
                                 std::uint64_t overrun) noexcept {
  putU16(out, static_cast<std::uint16_t>(channels));
  putU16(out + 2, static_cast<std::uint16_t>(frames));
  putU32(out + 4, 0);
  putU64(out + 8, overrun);
}
inline void encodeDaqFrame(unsigned char* out, std::int64_t timeNs, std::uint64_t index, const double* values,
                           std::uint32_t channels) noexcept {
  putI64(out, timeNs);
  putU64(out + 8, index);
  encodeDoubles(out + 16, values, static_cast<int>(channels));
}

/// A DAQ block payload checked by parseDaqBlock(); reads frames in place.
struct DaqBlockView {
  std::uint32_t channels = 0, frames = 0;
  std::uint64_t overrun = 0;
  const unsigned char* data = nullptr;  ///< first frame
  const unsigned char* frame(std::uint32_t f) const noexcept {
    return data + std::size_t(f) * daqFrameBytes(channels);
  }
  std::int64_t time(std::uint32_t f) const noexcept { return getI64(frame(f)); }
  std::uint64_t index(std::uint32_t f) const noexcept { return getU64(frame(f) + 8); }
  void values(std::uint32_t f, double* out) const noexcept {
    decodeDoubles(frame(f) + 16, out, static_cast<int>(channels));
  }
};

/// Checks a DAQ block payload of `size` bytes and fills `view`; returns why
/// it is invalid (naming the payload byte), "" if valid. O(size).
inline std::string parseDaqBlock(const unsigned char* in, std::size_t size, DaqBlockView& view) {
  if (size < kDaqBlockHeaderBytes)
    return "DAQ block of " + std::to_string(size) + " bytes is shorter than its 16-byte header";
  view.channels = getU16(in);
  view.frames = getU16(in + 2);
  view.overrun = getU64(in + 8);
  view.data = in + kDaqBlockHeaderBytes;
  if (view.channels < 1 || view.channels > kDaqMaxChannels)
    return "channel count " + std::to_string(view.channels) + " (payload byte 0) is not 1..16";
  if (view.frames < 1) return "frame count 0 (payload byte 2)";
  const std::size_t want = kDaqBlockHeaderBytes + std::size_t(view.frames) * daqFrameBytes(view.channels);
  if (size != want)
    return "DAQ block of " + std::to_string(view.channels) + " channels and " + std::to_string(view.frames) +
           " frames needs " + std::to_string(want) + " bytes, the record has " + std::to_string(size);
  double v[kDaqMaxChannels];
  for (std::uint32_t f = 0; f < view.frames; ++f) {
    const std::size_t at = kDaqBlockHeaderBytes + std::size_t(f) * daqFrameBytes(view.channels);
    if (f > 0 && view.index(f) <= view.index(f - 1))
      return "frame " + std::to_string(f) + " (payload byte " + std::to_string(at) + ") has index " +
             std::to_string(view.index(f)) + ", not after the previous frame's";
    if (f > 0 && view.time(f) < view.time(f - 1))
      return "frame " + std::to_string(f) + " (payload byte " + std::to_string(at) + ") goes back in time";
    view.values(f, v);
    for (std::uint32_t c = 0; c < view.channels; ++c)
      if (!std::isfinite(v[c]))
        return "frame " + std::to_string(f) + " channel " + std::to_string(c) + " (payload byte " +
               std::to_string(at + 16 + 8 * std::size_t(c)) + ") is not finite";
  }
  return {};
}

}  // namespace dm::record
