// dm/collide/broadphase.hpp — broad phases: which bounding boxes overlap.
//
// A broad phase keeps one axis-aligned box per proxy and reports the pairs
// of proxies whose boxes overlap (touching counts). The collision world
// (dm/collide/world.hpp) owns the proxies — a proxy id is the world's object
// index — and swaps broad phases at run time by re-inserting every box into
// the new one. All broad phases report exactly the pair set brute force
// reports; they differ in cost:
//
// | kind              | update       | pairs                         | good for                        |
// |-------------------|--------------|-------------------------------|---------------------------------|
// | BruteForce        | O(1)         | O(n²)                         | a handful of objects, reference |
// | SweepAndPrune     | O(1)         | O(n + k), segmented, coherent | coherent motion, similar sizes  |
// | HashedGrid        | O(1)         | O(n + k), rebuilt per step    | similar sizes, uniform density  |
// | HierarchicalGrid  | O(1)         | O(n + k), levels by size      | mixed sizes                     |
// | DynamicAabbTree   | O(log n)     | O(m log n + k), m = moved     | general scenes, ray/box queries |
//
// (k = overlapping pairs; m = boxes that left their enlarged "fat" box in
// the tree and were re-inserted.) Sweep-and-prune is segmented: the plane of
// two axes is cut into square columns (twice the median box size), and each
// column keeps its own list sorted along the third axis, re-sorted by
// insertion sort each step (nearly sorted under coherent motion) and swept;
// a pair is reported once, by the column holding its overlap's corner. One
// global sorted list would make its swaps grow like n^(5/3) at fixed
// density; per column it is O(n + k), with memory O(n), no pair set kept.
// query() is O(log n + hits) on the tree and an O(n) scan on the others.
// Measured against Bullet and FCL by Bench/collide_broadphase_bench.cpp.
//
// Not real-time code: updates may allocate when the structure grows. The
// haptic loop queries a world snapshot, not a broad phase.
//
// @code
//   auto bp = dm::makeBroadPhase(dm::BroadPhaseKind::DynamicAabbTree);
//   bp->insert(0, boxA);  bp->insert(1, boxB);
//   std::vector<dm::ProxyPair> pairs;
//   bp->overlappingPairs(pairs);   // {0, 1} if the boxes overlap
// @endcode
#pragma once

#include <dm/core/result.hpp>
#include <dm/core/types.hpp>

#include <cstdint>
#include <memory>
#include <string_view>
#include <vector>

namespace dm {

/// Caller-chosen proxy id (the world uses its dense object index).
using ProxyId = std::uint32_t;

/// Two proxies whose boxes overlap; always a < b.
struct ProxyPair {
  ProxyId a = 0;
  ProxyId b = 0;
  friend bool operator==(const ProxyPair&, const ProxyPair&) = default;
  friend auto operator<=>(const ProxyPair&, const ProxyPair&) = default;
};

/// The available broad phases (see the table in the file comment).
enum class BroadPhaseKind : std::uint8_t {
  BruteForce,
  SweepAndPrune,
  HashedGrid,
  HierarchicalGrid,
  DynamicAabbTree
};

/// "brute-force", "sweep-and-prune", "hashed-grid", "hierarchical-grid", "dynamic-aabb-tree".
std::string_view broadPhaseName(BroadPhaseKind kind) noexcept;
/// Inverse of broadPhaseName(); fails with InvalidArgument listing the names.
Result<BroadPhaseKind> parseBroadPhaseKind(std::string_view name);

/// Tuning knobs; the defaults adapt to the boxes inserted.
struct BroadPhaseOptions {
  /// HashedGrid: cell edge, m; 0 = twice the mean box extent of the first
  /// overlappingPairs() call after an insert (re-chosen when the mean drifts
  /// by more than a factor 2). HierarchicalGrid: edge of the finest level.
  double cellSize = 0.0;
  /// DynamicAabbTree: stored boxes are enlarged by this fraction of their
  /// extent, and a re-inserted box further along its last displacement, so
  /// that small and steady motions need no tree update; 0 = exact boxes.
  double fatMargin = 0.1;
};

/// Interface of every broad phase. Ids are unique among live proxies; they
/// need not be dense, but dense ids keep memory low. Boxes must be finite
/// and non-empty (min ≤ max); a non-finite box is treated as overlapping
/// nothing (the accelerated kinds also treat an inverted box, min > max,
/// that way). Not thread-safe: one thread mutates and queries.
class BroadPhase {
 public:
  virtual ~BroadPhase() = default;
  virtual BroadPhaseKind kind() const noexcept = 0;

  /// Adds proxy `id` with world box `box`. Inserting a live id is a bug
  /// (DM_ASSERT in debug builds; release builds treat it as update()).
  virtual void insert(ProxyId id, const Aabb& box) = 0;
  /// Moves proxy `id` to `box`. Unknown ids are ignored.
  virtual void update(ProxyId id, const Aabb& box) = 0;
  /// Removes proxy `id`; unknown ids are ignored.
  virtual void remove(ProxyId id) = 0;
  /// Removes every proxy.
  virtual void clear() = 0;
  /// Number of live proxies.
  virtual std::size_t size() const noexcept = 0;

  /// Replaces `out` with every overlapping pair (a < b), sorted ascending.
  /// Reuse `out` between steps to keep its capacity.
  virtual void overlappingPairs(std::vector<ProxyPair>& out) = 0;
  /// Replaces `out` with the ids whose boxes overlap `box`, sorted ascending.
  virtual void query(const Aabb& box, std::vector<ProxyId>& out) const = 0;
};

/// A new, empty broad phase of `kind`.
/// @code
///   auto sap = dm::makeBroadPhase(dm::BroadPhaseKind::SweepAndPrune);
/// @endcode
std::unique_ptr<BroadPhase> makeBroadPhase(BroadPhaseKind kind, const BroadPhaseOptions& options = {});

/// True if the closed boxes overlap or touch; false if a coordinate is NaN.
/// O(1), the test every broad phase uses.
inline bool boxesOverlap(const Aabb& a, const Aabb& b) noexcept {
  return a.min().x() <= b.max().x() && b.min().x() <= a.max().x() && a.min().y() <= b.max().y() &&
         b.min().y() <= a.max().y() && a.min().z() <= b.max().z() && b.min().z() <= a.max().z();
}

}  // namespace dm
