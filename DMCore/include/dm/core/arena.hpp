// dm/core/arena.hpp — per-tick bump allocator for real-time loops.
//
// A loop that needs temporaries (contact lists, scratch vectors) takes them
// from an Arena instead of the heap: the capacity is reserved (and its pages
// touched) once at construction, outside the real-time path; allocate() then
// only bumps an offset, and reset() at the start of each tick frees
// everything at once. It never grows, never throws and never calls the
// system allocator after construction: when a tick asks for more than is
// left, allocate() returns an empty span and counts an exhaustion, so the
// tick can degrade gracefully and the owner can size the arena from
// highWater(). Not thread-safe: one arena per thread (per loop).
//
// @code
//   dm::Arena arena(1 << 20);                      // 1 MiB, at startup
//   arena.reset();                                 // each tick
//   std::span<dm::Vec3> f = arena.allocate<dm::Vec3>(n);
//   if (f.empty() && n > 0) { /* exhausted: skip or degrade */ }
// @endcode
#pragma once

#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>
#include <new>
#include <span>
#include <type_traits>

namespace dm {

/// Fixed-capacity bump allocator; see the file comment.
class Arena {
 public:
  /// Alignment of the start of the buffer (bytes).
  static constexpr std::size_t kBaseAlignment = 64;

  /// A position to rewind to (see mark(), rewind(), Scope).
  struct Marker {
    std::size_t offset = 0;
  };

  /// Reserves `capacity_bytes` up front and touches every page so the first
  /// tick does not page-fault. Not real-time safe. Throws std::bad_alloc if
  /// the system has no memory (like any container at startup).
  explicit Arena(std::size_t capacity_bytes);
  ~Arena();
  Arena(Arena&& other) noexcept;
  Arena& operator=(Arena&& other) noexcept;
  Arena(const Arena&) = delete;
  Arena& operator=(const Arena&) = delete;

  /// `n` default-initialized T (contents indeterminate for trivial T),
  /// aligned to alignof(T); an empty span when n == 0 or on exhaustion (then
  /// exhaustions() is incremented). T must be trivially destructible: reset()
  /// runs no destructors. O(1) for trivially default-constructible T.
  template <class T>
  std::span<T> allocate(std::size_t n) noexcept(std::is_nothrow_default_constructible_v<T>) {
    static_assert(std::is_trivially_destructible_v<T>, "Arena never runs destructors");
    T* p = rawFor<T>(n);
    if (p == nullptr) return {};
    std::uninitialized_default_construct_n(p, n);
    return {std::launder(p), n};
  }

  /// As allocate(n), with every element a copy of `value`. O(n).
  template <class T>
  std::span<T> allocate(std::size_t n, const T& value) noexcept(std::is_nothrow_copy_constructible_v<T>) {
    static_assert(std::is_trivially_destructible_v<T>, "Arena never runs destructors");
    T* p = rawFor<T>(n);
    if (p == nullptr) return {};
    std::uninitialized_fill_n(p, n, value);
    return {std::launder(p), n};
  }

  /// `bytes` raw bytes aligned to `alignment` (a power of two, any size).
  /// nullptr when bytes == 0 (not an exhaustion), when `alignment` is not a
  /// power of two (a programming error: DM_ASSERT in debug builds), or when
  /// the arena is exhausted (counted in exhaustions()). O(1).
  void* allocateBytes(std::size_t bytes, std::size_t alignment = alignof(std::max_align_t)) noexcept;

  /// Frees everything allocated so far (keeps the statistics). O(1).
  void reset() noexcept { used_ = 0; }

  /// The current position, for a later rewind(). O(1).
  Marker mark() const noexcept { return Marker{used_}; }
  /// Frees everything allocated since `marker` was taken. The marker must
  /// come from this arena and not be past the current position (DM_ASSERT);
  /// markers taken before a reset() are invalid after it. O(1).
  void rewind(Marker marker) noexcept;

  /// RAII mark/rewind: temporaries allocated during the scope are freed at
  /// its end.
  /// @code
  ///   { dm::Arena::Scope scratch(arena); auto tmp = arena.allocate<double>(n); }
  /// @endcode
  class Scope {
   public:
    explicit Scope(Arena& arena) noexcept : arena_(arena), marker_(arena.mark()) {}
    ~Scope() { arena_.rewind(marker_); }
    Scope(const Scope&) = delete;
    Scope& operator=(const Scope&) = delete;

   private:
    Arena& arena_;
    Marker marker_;
  };

  /// Total bytes reserved.
  std::size_t capacity() const noexcept { return capacity_; }
  /// Bytes in use since the last reset(), including alignment padding.
  std::size_t used() const noexcept { return used_; }
  /// capacity() - used().
  std::size_t remaining() const noexcept { return capacity_ - used_; }
  /// Largest used() ever reached (since construction or resetStatistics()).
  std::size_t highWater() const noexcept { return highWater_; }
  /// Number of failed allocations (since construction or resetStatistics()).
  std::uint64_t exhaustions() const noexcept { return exhaustions_; }
  /// Zeroes highWater() and exhaustions().
  void resetStatistics() noexcept {
    highWater_ = used_;
    exhaustions_ = 0;
  }

 private:
  template <class T>
  T* rawFor(std::size_t n) noexcept {
    if (n == 0) return nullptr;
    if (n > std::numeric_limits<std::size_t>::max() / sizeof(T)) {
      ++exhaustions_;
      return nullptr;
    }
    return static_cast<T*>(allocateBytes(n * sizeof(T), alignof(T)));
  }

  std::byte* data_ = nullptr;
  std::size_t capacity_ = 0;
  std::size_t used_ = 0;
  std::size_t highWater_ = 0;
  std::uint64_t exhaustions_ = 0;
};

}  // namespace dm
