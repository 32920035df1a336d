// dm/core/triple_buffer.hpp — latest-value exchange between two threads.
//
// One writer thread produces states (a haptic device pose, a physics
// snapshot) at its rate; one reader thread at another rate wants only the
// newest complete one. Three buffers: the writer owns one, the reader owns
// one, the third sits in the middle. publish() swaps the writer's buffer
// with the middle one and marks it fresh; the reader's update() swaps its
// buffer with the middle one if it is fresh. Both are a single atomic
// exchange: neither side ever blocks, locks or allocates, the writer always
// has a buffer to write, and the reader never sees a half-written (torn)
// value.
//
// @code
//   dm::TripleBuffer<Pose> poses;
//   poses.writeBuffer() = pose; poses.publish();      // writer thread
//   const Pose& latest = poses.read();               // reader thread
// @endcode
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <type_traits>
#include <utility>

namespace dm {

/// Single-writer single-reader latest-value buffer of T (three copies of T,
/// each on its own cache line). Not copyable or movable.
template <class T>
class TripleBuffer {
 public:
  using value_type = T;

  /// All three buffers value-initialized; the reader sees T{} until the
  /// first publish().
  TripleBuffer() requires std::is_default_constructible_v<T> : slots_{} {}
  /// All three buffers copies of `initial`.
  explicit TripleBuffer(const T& initial) : slots_{{initial}, {initial}, {initial}} {}
  TripleBuffer(const TripleBuffer&) = delete;
  TripleBuffer& operator=(const TripleBuffer&) = delete;

  /// Writer only. The buffer the writer fills next. Its contents are an
  /// older value (not necessarily the last one published): overwrite
  /// every field before publish(). O(1).
  T& writeBuffer() noexcept { return slots_[back_].value; }

  /// Writer only. Makes the write buffer the latest value and takes a new
  /// write buffer. Never blocks. O(1).
  void publish() noexcept {
    // release: the reader that acquires this index sees the whole value;
    // acquire: the buffer we take back was released by the reader, so its
    // reads of it are done before we overwrite it.
    const std::uint8_t prev =
        middle_.exchange(static_cast<std::uint8_t>(back_ | kFresh), std::memory_order_acq_rel);
    back_ = static_cast<std::uint8_t>(prev & kIndexMask);
  }

  /// Writer only. writeBuffer() = value; publish().
  void write(const T& value) {
    writeBuffer() = value;
    publish();
  }
  /// Writer only. writeBuffer() = std::move(value); publish().
  void write(T&& value) {
    writeBuffer() = std::move(value);
    publish();
  }

  /// Reader only. Takes the latest published value if one arrived since the
  /// last update(); returns whether it did. Never blocks. O(1).
  bool update() noexcept {
    // Only the reader clears the fresh bit, so if it is set now it is still
    // set at the exchange (possibly on an even newer value).
    if ((middle_.load(std::memory_order_relaxed) & kFresh) == 0) return false;
    const std::uint8_t prev = middle_.exchange(front_, std::memory_order_acq_rel);
    front_ = static_cast<std::uint8_t>(prev & kIndexMask);
    return true;
  }

  /// Reader only. The value taken by the last update() (or the initial
  /// value). Stays valid and unchanged until the next update(). O(1).
  const T& readBuffer() const noexcept { return slots_[front_].value; }

  /// Reader only. update(), then readBuffer(): the latest complete value.
  const T& read() noexcept {
    update();
    return readBuffer();
  }

  /// Any thread. Whether a published value is waiting for the reader. O(1).
  bool freshApprox() const noexcept { return (middle_.load(std::memory_order_acquire) & kFresh) != 0; }

 private:
  static constexpr std::size_t kCacheLine = 64;  // see ring.hpp
  static constexpr std::uint8_t kIndexMask = 0x3;
  static constexpr std::uint8_t kFresh = 0x4;

  struct alignas(kCacheLine) Slot {
    T value;
  };

  Slot slots_[3];
  alignas(kCacheLine) std::uint8_t back_ = 0;                // writer's buffer
  alignas(kCacheLine) std::atomic<std::uint8_t> middle_{1};  // index | kFresh
  alignas(kCacheLine) std::uint8_t front_ = 2;               // reader's buffer
};

}  // namespace dm
