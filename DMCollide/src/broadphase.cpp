// Broad-phase names, the factory, the brute-force reference every other
// broad phase is tested against, and the pieces the accelerated broad phases
// share (broadphase_impl.hpp): the box validity rule and the pair radix sort.
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
