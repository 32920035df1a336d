// CRC-64/ECMA-182 (OpenIGTLink) and CRC-32C, slicing-by-8 with tables built
// at compile time: eight bytes per step, then byte at a time for the tail.
#include <dm/network/crc.hpp>

#include <array>

namespace dm {
namespace {

constexpr std::uint64_t kCrc64Poly = 0x42F0E1EBA9EA3693ull;
constexpr std::uint32_t kCrc32cPolyReflected = 0x82F63B78u;

using Crc64Tables = std::array<std::array<std::uint64_t, 256>, 8>;
using Crc32Tables = std::array<std::array<std::uint32_t, 256>, 8>;

// MSB-first: t[k][b] is the CRC of byte b followed by k zero bytes.
constexpr Crc64Tables makeCrc64Tables() {
  Crc64Tables t{};
  for (std::uint64_t i = 0; i < 256; ++i) {
    std::uint64_t c = i << 56;
    for (int b = 0; b < 8; ++b) c = (c & (std::uint64_t{1} << 63)) ? (c << 1) ^ kCrc64Poly : (c << 1);
    t[0][i] = c;
  }
  for (std::size_t k = 1; k < 8; ++k)
    for (std::size_t i = 0; i < 256; ++i) t[k][i] = (t[k - 1][i] << 8) ^ t[0][t[k - 1][i] >> 56];
  return t;
}

// Reflected (LSB-first) slicing tables.
constexpr Crc32Tables makeCrc32cTables() {
  Crc32Tables t{};
  for (std::uint32_t i = 0; i < 256; ++i) {
    std::uint32_t c = i;
    for (int b = 0; b < 8; ++b) c = (c & 1u) ? (c >> 1) ^ kCrc32cPolyReflected : (c >> 1);
    t[0][i] = c;
  }
  for (std::size_t k = 1; k < 8; ++k)
    for (std::size_t i = 0; i < 256; ++i) t[k][i] = (t[k - 1][i] >> 8) ^ t[0][t[k - 1][i] & 0xFFu];
  return t;
}

constexpr Crc64Tables kCrc64 = makeCrc64Tables();
constexpr Crc32Tables kCrc32c = makeCrc32cTables();

inline std::uint64_t byteAt(const std::byte* p, std::size_t i) {
  return std::to_integer<std::uint64_t>(p[i]);
}

}  // namespace

std::uint64_t crc64Ecma(std::span<const std::byte> data, std::uint64_t crc) noexcept {
  const std::byte* p = data.data();
  std::size_t n = data.size();
  for (; n >= 8; n -= 8, p += 8) {
    std::uint64_t word = 0;
    for (std::size_t i = 0; i < 8; ++i) word = (word << 8) | byteAt(p, i);  // big-endian load
    crc ^= word;
    crc = kCrc64[7][crc >> 56] ^ kCrc64[6][(crc >> 48) & 0xFFu] ^ kCrc64[5][(crc >> 40) & 0xFFu] ^
          kCrc64[4][(crc >> 32) & 0xFFu] ^ kCrc64[3][(crc >> 24) & 0xFFu] ^ kCrc64[2][(crc >> 16) & 0xFFu] ^
          kCrc64[1][(crc >> 8) & 0xFFu] ^ kCrc64[0][crc & 0xFFu];
  }
  for (std::size_t i = 0; i < n; ++i) crc = kCrc64[0][((crc >> 56) ^ byteAt(p, i)) & 0xFFu] ^ (crc << 8);
  return crc;
}

std::uint32_t crc32c(std::span<const std::byte> data, std::uint32_t crc) noexcept {
  const std::byte* p = data.data();
  std::size_t n = data.size();
  std::uint64_t c = ~crc & 0xFFFFFFFFu;
  for (; n >= 8; n -= 8, p += 8) {
    std::uint64_t word = 0;
    for (std::size_t i = 0; i < 8; ++i) word |= byteAt(p, i) << (8 * i);  // little-endian load
    word ^= c;
    c = kCrc32c[7][word & 0xFFu] ^ kCrc32c[6][(word >> 8) & 0xFFu] ^ kCrc32c[5][(word >> 16) & 0xFFu] ^
        kCrc32c[4][(word >> 24) & 0xFFu] ^ kCrc32c[3][(word >> 32) & 0xFFu] ^
        kCrc32c[2][(word >> 40) & 0xFFu] ^ kCrc32c[1][(word >> 48) & 0xFFu] ^ kCrc32c[0][word >> 56];
  }
  for (std::size_t i = 0; i < n; ++i) c = kCrc32c[0][(c ^ byteAt(p, i)) & 0xFFu] ^ (c >> 8);
  return ~static_cast<std::uint32_t>(c);
}

}  // namespace dm
