// Allocation counting for real-time checks in tests: replaces the global
// operator new/delete (every form, or GCC flags mismatched pairs) with
// malloc/free wrappers that count the calls made on threads whose
// dm::test::tCountAllocations flag is set.
//
// The replacement operators are defined once per program, in
// alloc_counter.cpp: dm_add_test (cmake/DMHelpers.cmake) compiles it, on its
// own, into every test executable with a source that includes this header.
//
// @code
//   dm::test::tCountAllocations = true;
//   const auto before = dm::test::countedAllocations();
//   loop.step();
//   dm::test::tCountAllocations = false;
//   EXPECT_EQ(dm::test::countedAllocations(), before);
// @endcode
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <new>

namespace dm::test {

/// Set on a thread to count its allocations.
inline thread_local bool tCountAllocations = false;
inline std::atomic<std::uint64_t> gCountedAllocations{0};

/// Allocations counted so far (all counting threads together).
inline std::uint64_t countedAllocations() noexcept { return gCountedAllocations.load(); }

inline void* countedAlloc(std::size_t n, std::size_t align) {
  if (tCountAllocations) gCountedAllocations.fetch_add(1, std::memory_order_relaxed);
  if (n == 0) n = 1;
  void* p = align <= alignof(std::max_align_t) ? std::malloc(n)
                                               : std::aligned_alloc(align, (n + align - 1) / align * align);
  if (p == nullptr) throw std::bad_alloc();
  return p;
}

/// Makes exactly one allocation that no optimiser may remove (a new
/// expression with its delete may be elided, and GCC does so at -O1 under
/// ThreadSanitizer): for tests that check the counter itself.
inline void allocateOnce() {
  void* volatile p = ::operator new(16);
  ::operator delete(p);
}

}  // namespace dm::test
