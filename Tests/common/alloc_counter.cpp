// The replacement global operator new/delete of alloc_counter.hpp, defined
// once per test executable. dm_add_test adds this file to every test
// executable with a source that includes the header, and keeps it out of
// unity batches: compiled on its own, no test code sees (and inlines) the
// replacements.
#include "alloc_counter.hpp"

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
