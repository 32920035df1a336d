// dm/math/volume_distance.hpp — the exact Euclidean distance transform on a
// voxel grid (Felzenszwalb & Huttenlocher's separable lower envelope of
// parabolas, O(n) whatever the distances), with a voxel size per axis. The
// one implementation: DMCollide's voxel models (a signed distance from an
// occupancy), DMVision's ball morphology and DMIO's scene segments ("near":
// the voxels within a distance of another mask) call it.
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

/// In place, on a `dims` grid (x fastest): `f` holds 0 at feature voxels
/// and +∞ elsewhere on entry, and on exit the squared distance from each
/// voxel centre to the nearest feature centre, the axes scaled by
/// `spacing` (all > 0); +∞ everywhere when there is no feature. Exact; O(n)
/// on dm::parallelFor. Requires f.size() == dims.prod().
void squaredDistanceTransform(std::span<float> f, const Vec3i& dims, const Vec3& spacing = Vec3::Ones());

/// squaredDistanceTransform() of a mask: the squared distance from every
/// voxel centre to the nearest centre of a foreground voxel
/// (`foreground[n] != 0`); in index units ((1, 1, 1)) every finite result
/// is an integer, held exactly up to 2^24. Voxels outside the grid are not
/// foreground; +∞ where the grid has none.
std::vector<float> squaredDistanceToForeground(std::span<const std::uint8_t> foreground, const Vec3i& dims,
                                               const Vec3& spacing = Vec3::Ones());

}  // namespace dm
