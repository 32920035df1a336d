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
#pragma once

#include <array>
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
enum Type : std::uint16_t { kHapticState = 1, kHapticOutput = 2 };

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
    onRecord(RecordView{getU16(h + 8), getI64(h + 12), h + kRecordHeaderBytes, size});
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

}  // namespace dm::record
