// Waiting in tests for something another thread does: poll a condition
// every millisecond until it holds or a limit passes. Tests never assert on
// timing; the limit only keeps a broken build from hanging ctest.
#pragma once

#include <chrono>
#include <thread>

namespace dm::test {

/// Polls `done` until it returns true (→ true) or `limit` passes (→ its last value).
template <class F>
bool eventually(F&& done, std::chrono::milliseconds limit = std::chrono::milliseconds(5000)) {
  const auto end = std::chrono::steady_clock::now() + limit;
  while (!done()) {
    if (std::chrono::steady_clock::now() > end) return done();
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  return true;
}

}  // namespace dm::test
