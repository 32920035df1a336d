// dm/core/log.hpp — logging on spdlog, with a real-time-safe path.
//
// Two ways to log, both printf-style (format strings are checked by the
// compiler):
//  * dm::log::info(...) and friends: synchronous, for ordinary threads.
//  * dm::log::rt(level, ...): for real-time threads (the haptic loop). It
//    formats into a fixed-size slot of a lock-free bounded queue and returns;
//    it never allocates, locks or blocks. A background thread drains the
//    queue into spdlog. When the queue is full the record is dropped and
//    counted (rtDropped()), never waited for. Messages longer than
//    kRtMessageBytes-1 are truncated.
//
// @code
//   dm::log::info("loaded %s (%zu triangles)", path.c_str(), n);
//   dm::log::rt(dm::log::Level::Warn, "tick %llu overran by %.1f us", tick, us);
// @endcode
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <string_view>

#if defined(__GNUC__)
#define DM_PRINTF(fmt_index, first_arg) __attribute__((format(printf, fmt_index, first_arg)))
#else
#define DM_PRINTF(fmt_index, first_arg)
#endif

namespace dm::log {

enum class Level : std::uint8_t { Trace, Debug, Info, Warn, Error, Critical, Off };

/// Size of one real-time log slot, including the terminating NUL.
inline constexpr std::size_t kRtMessageBytes = 256;
/// Number of slots in the real-time queue (power of two).
inline constexpr std::size_t kRtQueueSlots = 4096;

/// Messages below `level` are discarded (default Info; DM_LOG_LEVEL env
/// variable: trace, debug, info, warn, error, critical, off).
void setLevel(Level level) noexcept;
Level level() noexcept;
bool enabled(Level level) noexcept;

/// Synchronous logging; may block on the sink. Not for real-time threads.
void message(Level level, const char* fmt, ...) DM_PRINTF(2, 3);
void trace(const char* fmt, ...) DM_PRINTF(1, 2);
void debug(const char* fmt, ...) DM_PRINTF(1, 2);
void info(const char* fmt, ...) DM_PRINTF(1, 2);
void warn(const char* fmt, ...) DM_PRINTF(1, 2);
void error(const char* fmt, ...) DM_PRINTF(1, 2);

/// Real-time-safe logging: lock-free, allocation-free, never blocks.
/// Returns false if the record was dropped (queue full) or below the level.
bool rt(Level level, const char* fmt, ...) noexcept DM_PRINTF(2, 3);
/// Records dropped by rt() because the queue was full, since start.
std::uint64_t rtDropped() noexcept;

/// Drains the real-time queue and flushes every sink; returns when done.
void flush();

/// Ends the background thread that drains the real-time queue (after one
/// last drain), for a process that must stay single-threaded: DMIO's
/// dm-isolate helper forks a child per import from its one thread. rt()
/// records are then only written by flush(). Idempotent; not undone.
void stopDrainThread();

/// Receives every message that passes the level filter (after the default
/// console sink). Used by tools and tests; at most one; pass {} to remove.
using Sink = std::function<void(Level, std::string_view)>;
void setSink(Sink sink);

const char* toString(Level level) noexcept;

}  // namespace dm::log
