// dm/math/volume_distance.hpp — the exact Euclidean distance transform of a
// mask on a voxel grid (Felzenszwalb & Huttenlocher's separable lower
// envelope of parabolas, O(n) whatever the distances), with a voxel size
// per axis. DMVision's ball morphology and DMIO's scene segments ("near":
// the voxels within a distance of another mask) share it.
//
// @code
//   std::vector<float> d2 = dm::squaredDistanceToForeground(fg, dims, Vec3(1e-3, 1e-3, 2e-3));
//   bool within8mm = d2[n] <= 8e-3 * 8e-3;
// @endcode
#pragma once

#include <dm/core/types.hpp>

#include <cstdint>
#include <span>
#include <vector>

namespace dm {

/// Squared distance from every voxel centre of a `dims` grid (x fastest) to
/// the nearest centre of a foreground voxel (`foreground[n] != 0`), the
/// axes scaled by `spacing` (all > 0; (1, 1, 1): index units, where every
/// result is an integer held exactly up to 2^24). Voxels outside the grid
/// are not foreground. Where the grid has no foreground at all the result
/// is kNoForeground. Exact; O(n) time on dm::parallelFor, 4 bytes per
/// voxel. Requires foreground.size() == dims.prod().
std::vector<float> squaredDistanceToForeground(std::span<const std::uint8_t> foreground, const Vec3i& dims,
                                               const Vec3& spacing = Vec3::Ones());

/// squaredDistanceToForeground()'s value with no foreground on the grid.
inline constexpr float kNoForeground = 1e20f;

}  // namespace dm
