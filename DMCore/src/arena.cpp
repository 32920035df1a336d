#include <dm/core/arena.hpp>
#include <dm/core/assert.hpp>

#include <algorithm>
#include <cstring>
#include <utility>

namespace dm {

Arena::Arena(std::size_t capacity_bytes) : capacity_(capacity_bytes) {
  if (capacity_ == 0) return;
  data_ = static_cast<std::byte*>(::operator new (capacity_, std::align_val_t{kBaseAlignment}));
  // Touch every page now so the real-time loop never takes a first-use page fault.
  std::memset(data_, 0, capacity_);
}

Arena::~Arena() {
  if (data_ != nullptr) ::operator delete (data_, std::align_val_t{kBaseAlignment});
}

Arena::Arena(Arena&& other) noexcept
    : data_(std::exchange(other.data_, nullptr)),
      capacity_(std::exchange(other.capacity_, 0)),
      used_(std::exchange(other.used_, 0)),
      highWater_(std::exchange(other.highWater_, 0)),
      exhaustions_(std::exchange(other.exhaustions_, 0)) {}

Arena& Arena::operator=(Arena&& other) noexcept {
  if (this != &other) {
    Arena tmp(std::move(other));
    std::swap(data_, tmp.data_);
    std::swap(capacity_, tmp.capacity_);
    std::swap(used_, tmp.used_);
    std::swap(highWater_, tmp.highWater_);
    std::swap(exhaustions_, tmp.exhaustions_);
  }
  return *this;
}

void* Arena::allocateBytes(std::size_t bytes, std::size_t alignment) noexcept {
  if (bytes == 0) return nullptr;
  DM_ASSERT(alignment != 0 && (alignment & (alignment - 1)) == 0, "Arena: alignment must be a power of two");
  if (alignment == 0 || (alignment & (alignment - 1)) != 0) return nullptr;
  // Align the absolute address, so alignments above kBaseAlignment work too.
  const std::uintptr_t base = reinterpret_cast<std::uintptr_t>(data_);
  const std::uintptr_t current = base + used_;
  const std::uintptr_t aligned = (current + (alignment - 1)) & ~static_cast<std::uintptr_t>(alignment - 1);
  if (aligned < current) {  // wrapped around the address space
    ++exhaustions_;
    return nullptr;
  }
  const std::size_t offset = static_cast<std::size_t>(aligned - base);
  if (data_ == nullptr || offset > capacity_ || bytes > capacity_ - offset) {
    ++exhaustions_;
    return nullptr;
  }
  used_ = offset + bytes;
  highWater_ = std::max(highWater_, used_);
  return data_ + offset;
}

void Arena::rewind(Marker marker) noexcept {
  DM_ASSERT(marker.offset <= used_,
            "Arena::rewind: marker is past the current position (taken before reset()?)");
  if (marker.offset <= used_) used_ = marker.offset;
}

}  // namespace dm
