// dm/core/assert.hpp — invariant checks.
//
// DM_ASSERT(cond, msg): internal invariant, compiled out in release (NDEBUG).
// DM_DEMAND(cond, msg): always checked; on failure prints file:line, the
// condition and the message to stderr and aborts. Neither is for user input:
// bad files, configs, devices and packets return dm::Result (result.hpp).
#pragma once

namespace dm::detail {
[[noreturn]] void assertionFailed(const char* kind, const char* expr, const char* msg, const char* file,
                                  int line) noexcept;
}  // namespace dm::detail

#define DM_DEMAND(cond, msg)                                                        \
  do {                                                                              \
    if (!(cond)) [[unlikely]]                                                       \
      ::dm::detail::assertionFailed("DM_DEMAND", #cond, (msg), __FILE__, __LINE__); \
  } while (false)

#ifdef NDEBUG
#define DM_ASSERT(cond, msg) \
  do {                       \
  } while (false && (cond))
#else
#define DM_ASSERT(cond, msg)                                                        \
  do {                                                                              \
    if (!(cond)) [[unlikely]]                                                       \
      ::dm::detail::assertionFailed("DM_ASSERT", #cond, (msg), __FILE__, __LINE__); \
  } while (false)
#endif
