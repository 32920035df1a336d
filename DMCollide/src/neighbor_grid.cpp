// neighbor_grid.cpp — the uniform-grid fixed-radius neighbour search
// (dm/collide/neighbor_grid.hpp).
#include <dm/collide/neighbor_grid.hpp>
#include <dm/core/tasks.hpp>

#include <algorithm>
#include <cmath>
#include <numeric>

namespace dm {

namespace {

// Cells per axis are capped so that a key fits 21 bits each.
constexpr std::int64_t kMaxAxisCells = (std::int64_t(1) << 21) - 2;
constexpr std::uint64_t kInvalidKey = ~std::uint64_t(0);

}  // namespace

NeighborGrid::Key NeighborGrid::keyOf(const Vec3& p) const noexcept {
  const Vec3 c = (p - origin_) / radius_;
  if (!c.allFinite()) return kInvalidKey;
  const auto x = static_cast<std::int64_t>(std::floor(c.x())),
             y = static_cast<std::int64_t>(std::floor(c.y())),
             z = static_cast<std::int64_t>(std::floor(c.z()));
  if (x < 0 || y < 0 || z < 0 || x >= dims_[0] || y >= dims_[1] || z >= dims_[2]) return kInvalidKey;
  if (dense_) return Key(x + dims_[0] * (y + dims_[1] * z));
  return (Key(z) << 42) | (Key(y) << 21) | Key(x);
}

bool NeighborGrid::cellRange(std::int64_t x, std::int64_t y, std::int64_t z, std::uint32_t& begin,
                             std::uint32_t& end) const noexcept {
  if (x < 0 || y < 0 || z < 0 || x >= dims_[0] || y >= dims_[1] || z >= dims_[2]) return false;
  if (dense_) {
    const std::size_t cell = std::size_t(x + dims_[0] * (y + dims_[1] * z));
    begin = cellStart_[cell];
    end = cellStart_[cell + 1];
    return end > begin;
  }
  const Key key = (Key(z) << 42) | (Key(y) << 21) | Key(x);
  const auto it = std::lower_bound(keys_.begin(), keys_.end(), key);
  if (it == keys_.end() || *it != key) return false;
  const std::size_t k = std::size_t(it - keys_.begin());
  begin = cellStart_[k];
  end = cellStart_[k + 1];
  return true;
}

bool NeighborGrid::rowRange(std::int64_t x, std::int64_t y, std::int64_t z, std::uint32_t& begin,
                            std::uint32_t& end) const noexcept {
  if (y < 0 || z < 0 || y >= dims_[1] || z >= dims_[2] || x < -1 || x > dims_[0]) return false;
  const std::int64_t row = dims_[0] * (y + dims_[1] * z);
  const std::int64_t first = std::max<std::int64_t>(x - 1, 0),
                     last = std::min<std::int64_t>(x + 1, dims_[0] - 1);
  begin = cellStart_[std::size_t(row + first)];
  end = cellStart_[std::size_t(row + last + 1)];
  return end > begin;
}

void NeighborGrid::build(std::span<const Vec3> points, double radius, std::size_t listed) {
  radius_ = radius > 0.0 && std::isfinite(radius) ? radius : 1.0;
  const std::size_t n = std::min(points.size(), listed);
  offsets_.assign(n + 1, 0);
  list_.clear();
  order_.clear();
  Aabb box;
  for (const Vec3& p : points)
    if (p.allFinite()) box.extend(p);
  const std::size_t all = points.size();
  if (all == 0 || box.isEmpty()) {
    dims_[0] = dims_[1] = dims_[2] = 0;
    cellStart_.assign(1, 0);
    return;
  }
  origin_ = box.min();
  for (int a = 0; a < 3; ++a)
    dims_[a] = std::min<std::int64_t>(
        kMaxAxisCells, static_cast<std::int64_t>(std::floor((box.max()[a] - origin_[a]) / radius_)) + 1);
  // A point past a capped axis falls outside (kInvalidKey) and is in no list;
  // only a cloud 2 million radii wide meets the cap.
  const double cells = double(dims_[0]) * double(dims_[1]) * double(dims_[2]);
  dense_ = cells <= 8.0 * double(all) + 1024.0;

  keys_.resize(all);
  parallelFor(0, all, 4096, [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i) keys_[i] = keyOf(points[i]);
  });
  if (dense_) {
    // Stable counting sort by cell: within a cell, increasing index.
    const std::size_t ncells = std::size_t(cells);
    cellStart_.assign(ncells + 1, 0);
    for (std::size_t i = 0; i < all; ++i)
      if (keys_[i] != kInvalidKey) ++cellStart_[keys_[i] + 1];
    std::partial_sum(cellStart_.begin(), cellStart_.end(), cellStart_.begin());
    order_.resize(cellStart_.back());
    counts_.assign(cellStart_.begin(), cellStart_.end() - 1);
    for (std::size_t i = 0; i < all; ++i)
      if (keys_[i] != kInvalidKey) order_[counts_[keys_[i]]++] = std::uint32_t(i);
  } else {
    for (std::size_t i = 0; i < all; ++i)
      if (keys_[i] != kInvalidKey) order_.push_back(std::uint32_t(i));
    std::stable_sort(order_.begin(), order_.end(),
                     [&](std::uint32_t a, std::uint32_t b) { return keys_[a] < keys_[b]; });
    std::vector<Key> distinct;
    cellStart_.clear();
    for (std::size_t k = 0; k < order_.size(); ++k)
      if (k == 0 || keys_[order_[k]] != keys_[order_[k - 1]]) {
        distinct.push_back(keys_[order_[k]]);
        cellStart_.push_back(std::uint32_t(k));
      }
    cellStart_.push_back(std::uint32_t(order_.size()));
    keys_ = std::move(distinct);
  }

  // The points in cell order, as plain coordinates: a cell's candidates are
  // then read from consecutive memory instead of scattered over the cloud.
  sorted_.resize(3 * order_.size());
  parallelFor(0, order_.size(), 4096, [&](std::size_t b, std::size_t e) {
    for (std::size_t k = b; k < e; ++k)
      for (int a = 0; a < 3; ++a) sorted_[3 * k + std::size_t(a)] = points[order_[k]][a];
  });

  // One pass: each fixed chunk of points lists into its own buffer (its
  // points' lists sorted by index), then the buffers are laid end to end.
  // The chunks do not depend on the thread count, nor do the lists.
  constexpr std::size_t kChunk = 256;
  const std::size_t chunks = (n + kChunk - 1) / kChunk;
  if (chunkLists_.size() < chunks) chunkLists_.resize(chunks);
  const double r2 = radius_ * radius_;
  parallelFor(0, chunks, 1, [&](std::size_t cb, std::size_t ce) {
    for (std::size_t c = cb; c < ce; ++c) {
      std::vector<std::uint32_t>& out = chunkLists_[c];
      out.clear();
      for (std::size_t i = c * kChunk; i < std::min(n, (c + 1) * kChunk); ++i) {
        const Vec3& p = points[i];
        const double px = p.x(), py = p.y(), pz = p.z();
        const std::size_t first = out.size();
        if (p.allFinite())
          visitCells(p, [&](std::uint32_t begin, std::uint32_t end) {
            const double* q = sorted_.data() + 3 * std::size_t(begin);
            for (std::uint32_t k = begin; k < end; ++k, q += 3) {
              const double dx = q[0] - px, dy = q[1] - py, dz = q[2] - pz;
              if (dx * dx + dy * dy + dz * dz < r2 && order_[k] != i) out.push_back(order_[k]);
            }
          });
        std::sort(out.begin() + std::ptrdiff_t(first), out.end());
        offsets_[i + 1] = out.size() - first;
      }
    }
  });
  std::partial_sum(offsets_.begin(), offsets_.end(), offsets_.begin());
  list_.resize(offsets_.back());
  parallelFor(0, chunks, 1, [&](std::size_t cb, std::size_t ce) {
    for (std::size_t c = cb; c < ce; ++c)
      std::copy(chunkLists_[c].begin(), chunkLists_[c].end(),
                list_.begin() + std::ptrdiff_t(offsets_[c * kChunk]));
  });
}

}  // namespace dm
