// Private helpers of the OpenIGTLink codec: big-endian field access, fixed
// string fields, error locations. Not installed.
#pragma once

#include <dm/core/units.hpp>
#include <dm/network/igtl.hpp>

#include <bit>
#include <cstring>
#include <string_view>

namespace dm::igtl::wire {

inline constexpr double kMetresPerMm = units::mm;
inline constexpr double kMmPerMetre = 1.0 / units::mm;

inline std::uint64_t getBeN(const std::byte* p, int n) {
  std::uint64_t v = 0;
  for (int i = 0; i < n; ++i) v = (v << 8) | std::to_integer<std::uint64_t>(p[i]);
  return v;
}
inline std::uint16_t getBe16(const std::byte* p) { return static_cast<std::uint16_t>(getBeN(p, 2)); }
inline std::uint32_t getBe32(const std::byte* p) { return static_cast<std::uint32_t>(getBeN(p, 4)); }
inline std::uint64_t getBe64(const std::byte* p) { return getBeN(p, 8); }
inline double getF32(const std::byte* p) { return static_cast<double>(std::bit_cast<float>(getBe32(p))); }

inline void putBeN(std::vector<std::byte>& out, std::uint64_t v, int n) {
  for (int i = n - 1; i >= 0; --i) out.push_back(static_cast<std::byte>((v >> (8 * i)) & 0xFFu));
}
inline void putBe16(std::vector<std::byte>& out, std::uint16_t v) { putBeN(out, v, 2); }
inline void putBe32(std::vector<std::byte>& out, std::uint32_t v) { putBeN(out, v, 4); }
inline void putBe64(std::vector<std::byte>& out, std::uint64_t v) { putBeN(out, v, 8); }
inline void putF32(std::vector<std::byte>& out, double v) {
  putBe32(out, std::bit_cast<std::uint32_t>(static_cast<float>(v)));
}
inline void putBytes(std::vector<std::byte>& out, std::string_view s) {
  const auto* b = reinterpret_cast<const std::byte*>(s.data());
  out.insert(out.end(), b, b + s.size());
}

/// "OpenIGTLink IMAGE message "CT", byte 70" for a byte of the content.
std::string where(const MessageView& m, std::size_t contentOffset);
/// An error located at a content byte of `m`.
Error bad(const MessageView& m, std::size_t contentOffset, ErrorCode code, std::string what,
          std::string hint = {});
/// Fails unless m.header.type == type.
Status expectType(const MessageView& m, std::string_view type);
/// A char[n] field up to its first NUL.
std::string fixedString(const std::byte* p, std::size_t n);
/// Appends `s` as a NUL-padded char[n]; fails when it is longer than n.
Status putFixedString(std::vector<std::byte>& out, std::string_view s, std::size_t n, const char* field);

}  // namespace dm::igtl::wire
