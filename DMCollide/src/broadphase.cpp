// Broad-phase names, the factory, the brute-force reference every other
// broad phase is tested against, and the pieces the accelerated broad phases
// share (broadphase_impl.hpp): the box validity rule, the pair radix sort and
// the pair-key hash set.
//
// PairKeySet layout: one power-of-two array of 64-bit keys, empty = ~0, home
// slot = Fibonacci hash of the key, linear probing; erase shifts the rest of
// the probe run back so no tombstones accumulate and memory stays O(size)
// (the table shrinks when it is less than 1/8 full).
#include <dm/collide/broadphase.hpp>
#include <dm/core/assert.hpp>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <string>

#include "broadphase_impl.hpp"

namespace dm {

namespace {

constexpr std::array<std::string_view, 5> kNames = {"brute-force", "sweep-and-prune", "hashed-grid",
                                                    "hierarchical-grid", "dynamic-aabb-tree"};

/// All n(n−1)/2 box tests each step. Boxes live in a dense array indexed by
/// id (ids are the world's dense object indices), with a liveness flag.
class BruteForceBroadPhase final : public BroadPhase {
 public:
  BroadPhaseKind kind() const noexcept override { return BroadPhaseKind::BruteForce; }

  void insert(ProxyId id, const Aabb& box) override {
    if (id >= boxes_.size()) {
      boxes_.resize(id + 1);
      live_.resize(id + 1, 0);
    }
    DM_ASSERT(!live_[id], "broad phase: proxy id inserted twice");
    count_ += live_[id] ? 0 : 1;
    live_[id] = 1;
    boxes_[id] = box;
  }
  void update(ProxyId id, const Aabb& box) override {
    if (id < boxes_.size() && live_[id]) boxes_[id] = box;
  }
  void remove(ProxyId id) override {
    if (id < boxes_.size() && live_[id]) {
      live_[id] = 0;
      --count_;
    }
  }
  void clear() override {
    boxes_.clear();
    live_.clear();
    count_ = 0;
  }
  std::size_t size() const noexcept override { return count_; }

  void overlappingPairs(std::vector<ProxyPair>& out) override {
    out.clear();
    const auto n = static_cast<ProxyId>(boxes_.size());
    for (ProxyId i = 0; i < n; ++i) {
      if (!live_[i]) continue;
      for (ProxyId j = i + 1; j < n; ++j)
        if (live_[j] && boxesOverlap(boxes_[i], boxes_[j])) out.push_back({i, j});
    }
  }
  void query(const Aabb& box, std::vector<ProxyId>& out) const override {
    out.clear();
    for (ProxyId i = 0; i < static_cast<ProxyId>(boxes_.size()); ++i)
      if (live_[i] && boxesOverlap(boxes_[i], box)) out.push_back(i);
  }

 private:
  std::vector<Aabb> boxes_;
  std::vector<unsigned char> live_;
  std::size_t count_ = 0;
};

}  // namespace

std::string_view broadPhaseName(BroadPhaseKind kind) noexcept {
  const auto i = static_cast<std::size_t>(kind);
  return i < kNames.size() ? kNames[i] : std::string_view("unknown");
}

Result<BroadPhaseKind> parseBroadPhaseKind(std::string_view name) {
  for (std::size_t i = 0; i < kNames.size(); ++i)
    if (kNames[i] == name) return static_cast<BroadPhaseKind>(i);
  std::string list;
  for (std::string_view n : kNames) list += (list.empty() ? "" : ", ") + std::string(n);
  return fail(ErrorCode::InvalidArgument, "unknown broad phase '" + std::string(name) + "'", "broad phase",
              "use one of: " + list);
}

namespace detail {

bool isUsableBox(const Aabb& box) noexcept {
  for (int k = 0; k < 3; ++k)
    if (!std::isfinite(box.min()[k]) || !std::isfinite(box.max()[k]) || box.min()[k] > box.max()[k])
      return false;
  return true;
}

void sortPairKeys(std::vector<std::uint64_t>& keys, std::vector<std::uint64_t>& scratch) {
  const std::size_t n = keys.size();
  if (n < 512) {
    std::sort(keys.begin(), keys.end());
  } else {
    // Squeeze (a, b) into 2w bits, w = bits of the largest id, then LSD radix
    // sort in passes of 11 bits: 3 passes for ids below 2^16.
    std::uint64_t bits = 0;
    for (std::uint64_t k : keys) bits |= k;
    const int w = std::bit_width(static_cast<std::uint32_t>(bits >> 32) | static_cast<std::uint32_t>(bits));
    for (std::uint64_t& k : keys) k = ((k >> 32) << w) | (k & 0xffffffffu);
    constexpr int kBits = 11;
    constexpr std::size_t kBuckets = std::size_t(1) << kBits;
    const int passes = (2 * w + kBits - 1) / kBits;
    std::vector<std::array<std::uint32_t, kBuckets>> hist(static_cast<std::size_t>(passes));
    for (auto& h : hist) h.fill(0);
    for (std::uint64_t k : keys)
      for (int p = 0; p < passes; ++p) ++hist[p][(k >> (p * kBits)) & (kBuckets - 1)];
    scratch.resize(n);
    for (int p = 0; p < passes; ++p) {
      auto& h = hist[p];
      std::uint32_t sum = 0;
      for (auto& c : h) {
        const std::uint32_t t = c;
        c = sum;
        sum += t;
      }
      for (std::uint64_t k : keys) scratch[h[(k >> (p * kBits)) & (kBuckets - 1)]++] = k;
      keys.swap(scratch);
    }
    const std::uint64_t lowMask = (std::uint64_t(1) << w) - 1;
    for (std::uint64_t& k : keys) k = ((k >> w) << 32) | (k & lowMask);
  }
}

void emitSortedPairs(std::vector<std::uint64_t>& keys, std::vector<std::uint64_t>& scratch,
                     std::vector<ProxyPair>& out) {
  sortPairKeys(keys, scratch);
  const std::size_t n = keys.size();
  out.resize(n);
  for (std::size_t i = 0; i < n; ++i)
    out[i] = {static_cast<ProxyId>(keys[i] >> 32), static_cast<ProxyId>(keys[i] & 0xffffffffu)};
}

bool PairKeySet::insert(std::uint64_t key) {
  DM_ASSERT(key != kEmpty, "pair key set: reserved key");
  if (2 * (size_ + 1) > slots_.size()) rehash(std::max<std::size_t>(64, 2 * slots_.size()));
  const std::size_t mask = slots_.size() - 1;
  for (std::size_t i = home(key);; i = (i + 1) & mask) {
    if (slots_[i] == key) return false;
    if (slots_[i] == kEmpty) {
      slots_[i] = key;
      ++size_;
      return true;
    }
  }
}

bool PairKeySet::contains(std::uint64_t key) const noexcept {
  if (slots_.empty()) return false;
  const std::size_t mask = slots_.size() - 1;
  for (std::size_t i = home(key);; i = (i + 1) & mask) {
    if (slots_[i] == key) return true;
    if (slots_[i] == kEmpty) return false;
  }
}

bool PairKeySet::erase(std::uint64_t key) {
  if (slots_.empty()) return false;
  const std::size_t mask = slots_.size() - 1;
  for (std::size_t i = home(key);; i = (i + 1) & mask) {
    if (slots_[i] == kEmpty) return false;
    if (slots_[i] == key) {
      eraseAt(i);
      maybeShrink();
      return true;
    }
  }
}

void PairKeySet::eraseAt(std::size_t i) noexcept {
  // Backward shift: move later members of the probe run into the hole when
  // the hole lies on their probe path (between their home and their slot).
  const std::size_t mask = slots_.size() - 1;
  std::size_t hole = i;
  for (std::size_t j = (hole + 1) & mask; slots_[j] != kEmpty; j = (j + 1) & mask) {
    const std::size_t h = home(slots_[j]);
    if (((j - h) & mask) >= ((j - hole) & mask)) {
      slots_[hole] = slots_[j];
      hole = j;
    }
  }
  slots_[hole] = kEmpty;
  --size_;
}

void PairKeySet::clear() noexcept {
  slots_.clear();
  slots_.shrink_to_fit();
  size_ = 0;
  shift_ = 64;
}

void PairKeySet::maybeShrink() {
  if (slots_.size() > 64 && 8 * size_ < slots_.size()) rehash(std::max<std::size_t>(64, 4 * size_));
}

void PairKeySet::rehash(std::size_t capacity) {
  capacity = std::bit_ceil(capacity);
  std::vector<std::uint64_t> old(capacity, kEmpty);
  old.swap(slots_);
  shift_ = 64u - static_cast<unsigned>(std::countr_zero(capacity));
  const std::size_t mask = capacity - 1;
  for (std::uint64_t k : old) {
    if (k == kEmpty) continue;
    std::size_t i = home(k);
    while (slots_[i] != kEmpty) i = (i + 1) & mask;
    slots_[i] = k;
  }
}

}  // namespace detail

std::unique_ptr<BroadPhase> makeBroadPhase(BroadPhaseKind kind, const BroadPhaseOptions& options) {
  switch (kind) {
    case BroadPhaseKind::SweepAndPrune:
      return detail::makeSweepAndPrune(options);
    case BroadPhaseKind::HashedGrid:
      return detail::makeHashedGrid(options);
    case BroadPhaseKind::HierarchicalGrid:
      return detail::makeHierarchicalGrid(options);
    case BroadPhaseKind::DynamicAabbTree:
      return detail::makeDynamicAabbTree(options);
    case BroadPhaseKind::BruteForce:
    default:
      return std::make_unique<BruteForceBroadPhase>();
  }
}

}  // namespace dm
