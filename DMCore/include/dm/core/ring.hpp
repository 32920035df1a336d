// dm/core/ring.hpp — lock-free single-producer single-consumer bounded ring.
//
// The way real-time loops hand items (commands, samples, events) to each
// other: exactly one thread calls tryPush/tryEmplace, exactly one other
// thread calls tryPop. Neither ever blocks, locks or allocates; a full ring
// refuses the push (returns false) and an empty ring refuses the pop.
// Storage is inline (Capacity slots, no allocation after construction); the
// producer and consumer indices live on separate cache lines, each with a
// private cached copy of the other side's index to keep cache-line traffic
// down. Indices are free-running, so all Capacity slots are usable.
//
// @code
//   dm::SpscRing<Sample, 1024> ring;       // shared by two threads
//   ring.tryPush(sample);                   // producer thread; false if full
//   Sample s; while (ring.tryPop(s)) use(s);  // consumer thread
// @endcode
#pragma once

#include <atomic>
#include <cstddef>
#include <new>
#include <optional>
#include <type_traits>
#include <utility>

namespace dm {

/// Bounded lock-free SPSC queue of T with `Capacity` slots (a power of two
/// >= 2). T may be trivially copyable or move-only. Size: about
/// Capacity * sizeof(T) + 3 cache lines; large rings belong on the heap
/// (std::make_unique). Not copyable or movable (the two threads hold
/// references to it).
template <class T, std::size_t Capacity>
class SpscRing {
  static_assert(Capacity >= 2 && (Capacity & (Capacity - 1)) == 0,
                "SpscRing: Capacity must be a power of two >= 2");
  static_assert(std::is_nothrow_destructible_v<T>, "SpscRing: T must be nothrow destructible");
  static_assert(std::is_move_constructible_v<T>, "SpscRing: T must be move constructible");

 public:
  using value_type = T;

  /// Number of slots. O(1).
  static constexpr std::size_t capacity() noexcept { return Capacity; }

  SpscRing() noexcept {}
  /// Destroys the items still queued. No other thread may use the ring then.
  ~SpscRing() {
    const std::size_t tail = tail_.load(std::memory_order_acquire);
    for (std::size_t i = head_.load(std::memory_order_acquire); i != tail; ++i) item(i)->~T();
  }
  SpscRing(const SpscRing&) = delete;
  SpscRing& operator=(const SpscRing&) = delete;

  /// Producer only. Copies `value` in; false (and no change) if full. O(1).
  bool tryPush(const T& value) noexcept(std::is_nothrow_copy_constructible_v<T>) { return tryEmplace(value); }
  /// Producer only. Moves `value` in; false (and `value` untouched) if full. O(1).
  bool tryPush(T&& value) noexcept(std::is_nothrow_move_constructible_v<T>) {
    return tryEmplace(std::move(value));
  }
  /// Producer only. Constructs an item in place from `args`; false if full.
  /// If the constructor throws, nothing is queued. O(1).
  template <class... Args>
  bool tryEmplace(Args&&... args) noexcept(std::is_nothrow_constructible_v<T, Args...>) {
    const std::size_t tail = tail_.load(std::memory_order_relaxed);
    if (tail - headCache_ == Capacity) {
      // Looks full: refresh our view of the consumer's progress. The acquire
      // pairs with the consumer's release in tryPop, so the slot's previous
      // item has been destroyed before we construct into it.
      headCache_ = head_.load(std::memory_order_acquire);
      if (tail - headCache_ == Capacity) return false;
    }
    ::new (static_cast<void*>(slots_[tail & kMask].bytes)) T(std::forward<Args>(args)...);
    tail_.store(tail + 1, std::memory_order_release);
    return true;
  }

  /// Consumer only. Moves the oldest item into `out`; false (and `out`
  /// untouched) if empty. If T's move assignment throws, the item stays
  /// queued. O(1).
  bool tryPop(T& out) noexcept(std::is_nothrow_move_assignable_v<T>) {
    const std::size_t head = head_.load(std::memory_order_relaxed);
    if (head == tailCache_) {
      // Looks empty: refresh our view of the producer's progress. The
      // acquire pairs with the producer's release in tryEmplace.
      tailCache_ = tail_.load(std::memory_order_acquire);
      if (head == tailCache_) return false;
    }
    T* p = item(head);
    out = std::move(*p);
    p->~T();
    head_.store(head + 1, std::memory_order_release);
    return true;
  }

  /// Consumer only. The oldest item, or std::nullopt if empty. O(1).
  std::optional<T> tryPop() noexcept(std::is_nothrow_move_constructible_v<T>) {
    const std::size_t head = head_.load(std::memory_order_relaxed);
    if (head == tailCache_) {
      tailCache_ = tail_.load(std::memory_order_acquire);
      if (head == tailCache_) return std::nullopt;
    }
    T* p = item(head);
    std::optional<T> result(std::in_place, std::move(*p));
    p->~T();
    head_.store(head + 1, std::memory_order_release);
    return result;
  }

  /// Number of queued items as seen at some instant during the call; exact
  /// when neither side is running. In [0, Capacity]. Any thread. O(1).
  std::size_t sizeApprox() const noexcept {
    // head first: the tail read afterwards is at least as new, so tail >= head.
    const std::size_t head = head_.load(std::memory_order_acquire);
    const std::size_t tail = tail_.load(std::memory_order_acquire);
    const std::size_t n = tail - head;
    return n > Capacity ? Capacity : n;
  }
  /// sizeApprox() == 0. Any thread. O(1).
  bool emptyApprox() const noexcept { return sizeApprox() == 0; }

 private:
  // 64 bytes: the cache line of x86-64 and most ARM cores. (Not
  // std::hardware_destructive_interference_size: GCC warns that its value
  // may change between compiler versions, which would change this layout.)
  static constexpr std::size_t kCacheLine = 64;
  static constexpr std::size_t kMask = Capacity - 1;

  struct alignas(T) Slot {
    std::byte bytes[sizeof(T)];
  };

  T* item(std::size_t index) noexcept {
    return std::launder(reinterpret_cast<T*>(slots_[index & kMask].bytes));
  }

  // Producer's line: its index and its cached copy of the consumer's.
  alignas(kCacheLine) std::atomic<std::size_t> tail_{0};
  std::size_t headCache_ = 0;
  // Consumer's line.
  alignas(kCacheLine) std::atomic<std::size_t> head_{0};
  std::size_t tailCache_ = 0;
  alignas(kCacheLine) Slot slots_[Capacity];
};

}  // namespace dm
