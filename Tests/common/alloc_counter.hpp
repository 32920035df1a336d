// Allocation counting for real-time checks in tests: replaces the global
// operator new/delete (every form, or GCC flags mismatched pairs) with
// malloc/free wrappers that count the calls made on threads whose
// dm::test::tCountAllocations flag is set.
//
// Include it in exactly ONE source file of a test executable: replacement
// operators are not inline and must be defined once per program. Other files
// of the same executable that only read the counter define
// DM_ALLOC_COUNTER_DECLARE_ONLY before including it.
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

#ifndef DM_ALLOC_COUNTER_DECLARE_ONLY
// Every form below pairs malloc with free, but once GCC 12 inlines these
// replacements (at -O1 under the sanitizers) it sees a free() of memory from
// "operator new" and warns (-Wmismatched-new-delete) about its own view.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
#endif
void* operator new(std::size_t n) { return dm::test::countedAlloc(n, alignof(std::max_align_t)); }
void* operator new[](std::size_t n) { return dm::test::countedAlloc(n, alignof(std::max_align_t)); }
void* operator new(std::size_t n, std::align_val_t a) {
  return dm::test::countedAlloc(n, static_cast<std::size_t>(a));
}
void* operator new[](std::size_t n, std::align_val_t a) {
  return dm::test::countedAlloc(n, static_cast<std::size_t>(a));
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }
void operator delete(void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete[](void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete(void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }
// The nothrow forms too: under ASan an unreplaced nothrow new would come
// from ASan's allocator and be freed by the delete above (a mismatch).
void* operator new(std::size_t n, const std::nothrow_t&) noexcept {
  try {
    return dm::test::countedAlloc(n, alignof(std::max_align_t));
  } catch (...) {
    return nullptr;
  }
}
void* operator new[](std::size_t n, const std::nothrow_t&) noexcept {
  try {
    return dm::test::countedAlloc(n, alignof(std::max_align_t));
  } catch (...) {
    return nullptr;
  }
}
void operator delete(void* p, const std::nothrow_t&) noexcept { std::free(p); }
void operator delete[](void* p, const std::nothrow_t&) noexcept { std::free(p); }
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic pop
#endif
#endif  // DM_ALLOC_COUNTER_DECLARE_ONLY
