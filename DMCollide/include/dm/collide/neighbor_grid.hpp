// dm/collide/neighbor_grid.hpp — fixed-radius neighbour search over points
// (particles of a fluid, sample clouds): a uniform grid of cells one radius
// wide, rebuilt each step, with every point's neighbour list in one flat
// array (CSR).
//
// build() bins the points into cells of edge `radius` (cell coordinates
// relative to the points' bounding box), orders the points by cell with a
// stable counting sort when the box holds at most 8 cells per point (a
// dense table of cell starts), or by sorted 64-bit cell keys and binary
// search otherwise (sparse clouds), keeps a copy of their coordinates in
// that order (a cell's candidates are consecutive in memory; queries do not
// read the caller's points again), then lists, for each point, every other
// point within `radius` in the 27 cells around it, in increasing index
// order: the lists do not depend on the thread count, so a simulation that
// walks them in order is bit-reproducible. Counting and filling run on
// oneTBB (dm::parallelFor) over the points; memory is reused between builds
// (no allocation once the sizes stop growing). forEachWithin() queries any
// point against the last build without lists.
//
// Cost: O(n + pairs) per build. The particle neighbour search of the
// DMPlatform thesis's HOACollide; Bench/sph_fluid_bench.cpp compares it with
// nanoflann's k-d tree radius search on the same points.
//
// @code
//   dm::NeighborGrid grid;
//   grid.build(positions, 2.0 * spacing);
//   for (std::uint32_t j : grid.neighbors(i)) density += mass * kernel(positions[i] - positions[j]);
// @endcode
#pragma once

#include <dm/core/types.hpp>

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <span>
#include <vector>

namespace dm {

class NeighborGrid {
 public:
  /// Lists, for each of the first `listed` points (all by default), every
  /// other point of `points` closer than `radius` (> 0, finite; a non-finite
  /// point is in no list). The rest are found by others' lists and by
  /// forEachWithin() but get no list of their own (static boundary samples).
  /// Parallel over fixed chunks of points.
  void build(std::span<const Vec3> points, double radius,
             std::size_t listed = std::numeric_limits<std::size_t>::max());

  /// The points within radius of point i (< the listed count) at the last
  /// build, in increasing index order, without i.
  std::span<const std::uint32_t> neighbors(std::size_t i) const noexcept {
    return {list_.data() + offsets_[i], offsets_[i + 1] - offsets_[i]};
  }
  std::size_t size() const noexcept { return offsets_.empty() ? 0 : offsets_.size() - 1; }
  /// Where point i's list starts in the flat array of all lists (i ≤
  /// size()): per-pair data of a caller can be laid out the same way.
  std::size_t listOffset(std::size_t i) const noexcept { return offsets_[i]; }
  /// Directed pairs listed (each unordered pair twice).
  std::size_t pairCount() const noexcept { return list_.size(); }
  double radius() const noexcept { return radius_; }

  /// Calls f(j) for every point j of the last build within the build's
  /// radius of `p` (any point), cell by cell; allocation-free.
  template <class F>
  void forEachWithin(const Vec3& p, F&& f) const {
    const double r2 = radius_ * radius_;
    const double px = p.x(), py = p.y(), pz = p.z();
    visitCells(p, [&](std::uint32_t begin, std::uint32_t end) {
      const double* q = sorted_.data() + 3 * std::size_t(begin);
      for (std::uint32_t k = begin; k < end; ++k, q += 3) {
        const double dx = q[0] - px, dy = q[1] - py, dz = q[2] - pz;
        if (dx * dx + dy * dy + dz * dz < r2) f(order_[k]);
      }
    });
  }

 private:
  using Key = std::uint64_t;
  Key keyOf(const Vec3& p) const noexcept;
  // Calls f(begin, end) for the ranges of order_ of the 27 cells around p.
  // Calls f(begin, end) for ranges of order_ covering the 27 cells around p
  // (a dense grid: one range per row of three cells).
  template <class F>
  void visitCells(const Vec3& p, F&& f) const;
  bool cellRange(std::int64_t x, std::int64_t y, std::int64_t z, std::uint32_t& begin,
                 std::uint32_t& end) const noexcept;
  bool rowRange(std::int64_t x, std::int64_t y, std::int64_t z, std::uint32_t& begin,
                std::uint32_t& end) const noexcept;

  double radius_ = 0.0;
  Vec3 origin_ = Vec3::Zero();
  std::int64_t dims_[3] = {0, 0, 0};
  bool dense_ = true;
  std::vector<std::uint32_t> order_;      // point indices sorted by cell
  std::vector<double> sorted_;            // their coordinates (x, y, z), in that order
  std::vector<std::uint32_t> cellStart_;  // dense: per cell + 1; sparse: per distinct key + 1
  std::vector<Key> keys_;                 // per point (build), then the distinct keys (sparse)
  std::vector<std::uint32_t> counts_;     // scratch
  std::vector<std::size_t> offsets_;      // CSR, per point + 1
  std::vector<std::uint32_t> list_;
  std::vector<std::vector<std::uint32_t>> chunkLists_;  // per chunk of points, reused
};

template <class F>
void NeighborGrid::visitCells(const Vec3& p, F&& f) const {
  const Vec3 c = (p - origin_) / radius_;
  if (!c.allFinite()) return;
  const std::int64_t cx = static_cast<std::int64_t>(std::floor(c.x()));
  const std::int64_t cy = static_cast<std::int64_t>(std::floor(c.y()));
  const std::int64_t cz = static_cast<std::int64_t>(std::floor(c.z()));
  for (std::int64_t z = cz - 1; z <= cz + 1; ++z)
    for (std::int64_t y = cy - 1; y <= cy + 1; ++y) {
      std::uint32_t begin = 0, end = 0;
      if (dense_) {
        if (rowRange(cx, y, z, begin, end)) f(begin, end);
        continue;
      }
      for (std::int64_t x = cx - 1; x <= cx + 1; ++x)
        if (cellRange(x, y, z, begin, end)) f(begin, end);
    }
}

}  // namespace dm
