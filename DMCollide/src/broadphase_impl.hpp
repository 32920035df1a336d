// Private: the broad-phase implementations behind dm::makeBroadPhase() and
// the pieces they share — the box validity rule, pair keys, the radix sort
// that turns a pair list into the sorted output, and an open-addressing hash
// set of pair keys. Not installed.
#pragma once

#include <dm/collide/broadphase.hpp>

#include <cstdint>
#include <memory>
#include <vector>

namespace dm::detail {

/// Sweep-and-prune: one sorted list per column of a coarse grid in the plane
/// of two axes, swept along the third (broadphase_sap.cpp).
std::unique_ptr<BroadPhase> makeSweepAndPrune(const BroadPhaseOptions& options);
/// Uniform spatial hash, one grid (broadphase_grid.cpp).
std::unique_ptr<BroadPhase> makeHashedGrid(const BroadPhaseOptions& options);
/// Spatial hash with levels of doubling cell size (broadphase_grid.cpp).
std::unique_ptr<BroadPhase> makeHierarchicalGrid(const BroadPhaseOptions& options);
/// Dynamic AABB tree with fat leaves (broadphase_tree.cpp).
std::unique_ptr<BroadPhase> makeDynamicAabbTree(const BroadPhaseOptions& options);

/// True if every coordinate is finite and min ≤ max on every axis. Other
/// boxes are kept aside by the accelerated broad phases and overlap nothing.
bool isUsableBox(const Aabb& box) noexcept;

/// A box as six doubles, the layout the grids and the tree store.
struct FlatBox {
  double lo[3], hi[3];
};

inline FlatBox toFlatBox(const Aabb& b) noexcept {
  return {{b.min().x(), b.min().y(), b.min().z()}, {b.max().x(), b.max().y(), b.max().z()}};
}

/// boxesOverlap() on FlatBoxes: closed boxes, false if a coordinate is NaN.
inline bool overlap(const FlatBox& a, const FlatBox& b) noexcept {
  return a.lo[0] <= b.hi[0] && b.lo[0] <= a.hi[0] && a.lo[1] <= b.hi[1] && b.lo[1] <= a.hi[1] &&
         a.lo[2] <= b.hi[2] && b.lo[2] <= a.hi[2];
}

/// Dense slot of a proxy id that is not in the broad phase (the grids'
/// and sweep and prune's id → slot maps).
inline constexpr std::uint32_t kNoSlot = ~std::uint32_t(0);

/// Key of the unordered pair {a, b}: the smaller id in the high 32 bits, so
/// that ascending keys are ascending ProxyPairs.
inline std::uint64_t pairKey(std::uint32_t a, std::uint32_t b) noexcept {
  return a < b ? (std::uint64_t(a) << 32) | b : (std::uint64_t(b) << 32) | a;
}

/// Sorts `keys` (pairKey values) ascending with an LSD radix sort over the
/// bits the ids use (std::sort below 512 keys). O(k) for k keys; `scratch`
/// is reused working memory.
void sortPairKeys(std::vector<std::uint64_t>& keys, std::vector<std::uint64_t>& scratch);

/// sortPairKeys(), then writes the keys as pairs to `out`.
void emitSortedPairs(std::vector<std::uint64_t>& keys, std::vector<std::uint64_t>& scratch,
                     std::vector<ProxyPair>& out);

}  // namespace dm::detail
