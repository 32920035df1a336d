// le_bytes.hpp — private: little-endian field access for the module's wire
// formats (the message model, the tele-operation payloads). Never installed.
#pragma once

#include <cstddef>
#include <cstdint>

namespace dm::detail {

/// Writes the low `n` bytes of `v` at p, least significant first.
inline void putLe(std::byte* p, std::uint64_t v, int n) noexcept {
  for (int i = 0; i < n; ++i) p[i] = static_cast<std::byte>((v >> (8 * i)) & 0xFFu);
}

/// Reads `n` bytes at p, least significant first.
inline std::uint64_t getLe(const std::byte* p, int n) noexcept {
  std::uint64_t v = 0;
  for (int i = 0; i < n; ++i) v |= std::to_integer<std::uint64_t>(p[i]) << (8 * i);
  return v;
}

}  // namespace dm::detail
