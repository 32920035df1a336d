// dm/math/volume_components.hpp — voxel neighbourhoods and connected
// components of a mask volume (nonzero = foreground): 6/18/26-connectivity,
// union-find labelling, the largest component. DMVision's volume filters and
// DMIO's scene segments (a bone fragment cut from a CT) share them.
//
// @code
//   auto bone = dm::largestComponent(mask, dm::Connectivity::TwentySix);
//   if (!bone) return bone.error();
// @endcode
#pragma once

#include <dm/core/result.hpp>
#include <dm/core/types.hpp>
#include <dm/core/volume.hpp>

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

namespace dm {

/// Voxel neighbourhoods: faces (6), faces + edges (18), faces + edges +
/// corners (26).
enum class Connectivity : std::uint8_t { Six = 6, Eighteen = 18, TwentySix = 26 };

/// The neighbour offsets of `c` (6, 18 or 26 of them, each component in
/// {-1, 0, 1}, never (0, 0, 0)), in a fixed order (faces first). O(1), no
/// allocation; the span stays valid for the whole program.
std::span<const Vec3i> neighbourOffsets(Connectivity c) noexcept;

/// Connected components of a mask (nonzero = foreground).
struct Components {
  /// U32 labels: 0 background, 1..count() foreground, numbered by
  /// decreasing size (ties: the component whose first voxel in memory order
  /// comes first gets the smaller label).
  Volume labels;
  std::vector<std::size_t> sizes;  ///< sizes[l - 1] = voxels of label l, non-increasing
  std::size_t count() const { return sizes.size(); }
};

/// Labels the connected components of `mask` (nonzero voxels) under
/// connectivity `c` with union-find (path halving, union by index) over the
/// already-visited half of the neighbourhood. O(n·α(n)); memory 4 bytes per
/// voxel plus the output. Fails with InvalidArgument on an empty volume.
/// @code
///   auto cc = dm::labelComponents(*dm::threshold(ct, 300.0), dm::Connectivity::Six);
///   if (!cc) return cc.error();
///   std::size_t biggest = cc->sizes.empty() ? 0 : cc->sizes[0];
/// @endcode
Result<Components> labelComponents(const Volume& mask, Connectivity c = Connectivity::TwentySix);

/// U8 mask of the largest component of `mask` under `c` (all zero when the
/// mask is empty of foreground). Same cost and failures as labelComponents.
Result<Volume> largestComponent(const Volume& mask, Connectivity c = Connectivity::TwentySix);

}  // namespace dm
