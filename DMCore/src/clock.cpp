#include <dm/core/assert.hpp>
#include <dm/core/clock.hpp>

#include <chrono>

namespace dm {

std::int64_t RealClock::now() const noexcept {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

void VirtualClock::advance(std::int64_t dt_ns) noexcept {
  DM_ASSERT(dt_ns >= 0, "VirtualClock::advance: time cannot go backwards; use set() to rewind");
  if (dt_ns <= 0) return;
  nowNs_.fetch_add(dt_ns, std::memory_order_acq_rel);
}

}  // namespace dm
