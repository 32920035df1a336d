// dm/math/grid_cell.hpp — the integer cell of a uniform grid that a point
// falls in, and a hash for it: the key of the hash grids that find close
// points (weldVertices, dm::BoundarySurface's half-spacing test).
//
// @code
//   std::unordered_map<dm::GridCell, std::vector<std::uint32_t>, dm::GridCellHash> cells;
//   cells[dm::GridCell::of(p, 0.001)].push_back(i);
// @endcode
#pragma once

#include <dm/core/types.hpp>

#include <cmath>
#include <cstddef>
#include <cstdint>

namespace dm {

/// A cell of edge `cell` of the grid with a corner at the origin.
struct GridCell {
  std::int64_t x = 0, y = 0, z = 0;
  bool operator==(const GridCell&) const = default;

  static GridCell of(const Vec3& p, double cell) noexcept {
    return {std::int64_t(std::floor(p.x() / cell)), std::int64_t(std::floor(p.y() / cell)),
            std::int64_t(std::floor(p.z() / cell))};
  }
};

/// Mixes the three coordinates with odd 64-bit constants (boost's
/// hash_combine steps): neighbouring cells land far apart.
struct GridCellHash {
  std::size_t operator()(const GridCell& c) const noexcept {
    std::uint64_t h = std::uint64_t(c.x) * 0x9E3779B97F4A7C15ull;
    h ^= std::uint64_t(c.y) * 0xC2B2AE3D27D4EB4Full + (h << 6) + (h >> 2);
    h ^= std::uint64_t(c.z) * 0x165667B19E3779F9ull + (h << 6) + (h >> 2);
    return std::size_t(h);
  }
};

}  // namespace dm
