// Helpers shared by the DMNetwork tests.
#pragma once

#include <dm/core/clock.hpp>

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <vector>

namespace dm::test {

/// The bytes of a C string, without its terminating NUL.
inline std::vector<std::byte> ascii(const char* s) {
  std::vector<std::byte> b(std::strlen(s));
  std::memcpy(b.data(), s, b.size());
  return b;
}

/// The time on CLOCK_MONOTONIC, ns: the clock of the tele-operation stream.
inline std::int64_t monotonicNs() { return RealClock().now(); }

}  // namespace dm::test
