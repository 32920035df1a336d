// dm/vision/region_growing.hpp — seeded region growing on dm::Volume.
//
// From one or more seed voxels, a breadth-first flood over 6-, 18- or
// 26-connected neighbours accepts voxels whose intensity lies in an interval
// and, optionally, within k standard deviations of the region grown so far
// (adaptive: mean and deviation updated as voxels join), whose world
// gradient magnitude stays below a bound (the region stops at edges), and
// whose centre lies inside an optional bounding ball. Memory is bounded: a
// visited bitmap (1 bit per voxel) and a queue of accepted voxel indices.
// RegionGrower keeps that scratch between calls and grows into an existing
// mask, which is how the haptic segmentation accumulates its result.
//
// @code
//   dm::RegionGrowOptions o{.lower = 90, .upper = 140, .connectivity = dm::Connectivity::TwentySix};
//   auto wm = dm::growRegion(mri, std::array{dm::Vec3i(90, 120, 100)}, o);
//   if (wm) std::printf("%.0f mL\n", wm->stats.volumeMl);
// @endcode
#pragma once

#include <dm/core/result.hpp>
#include <dm/core/types.hpp>
#include <dm/core/volume.hpp>
#include <dm/vision/volume_filters.hpp>

#include <cstddef>
#include <cstdint>
#include <limits>
#include <optional>
#include <span>
#include <vector>

namespace dm {

/// A ball in world coordinates that bounds region growth.
struct GrowBall {
  Vec3 centre = Vec3::Zero();  ///< m
  double radius = 0.0;         ///< m, >= 0
};

/// Acceptance criteria and limits of region growing. A voxel joins when it
/// is a neighbour of the region and passes every enabled test.
struct RegionGrowOptions {
  double lower = -std::numeric_limits<double>::infinity();  ///< accept value >= lower (always applied)
  double upper = std::numeric_limits<double>::infinity();   ///< accept value <= upper (always applied)
  /// Adaptive test |value − μ| <= k·max(σ, minSigma), with μ and σ the mean and
  /// standard deviation of the seeds' 3×3×3 neighbourhoods plus every voxel
  /// accepted so far (updated as the region grows, Welford).
  bool adaptive = false;
  double k = 2.5;         ///< adaptive width in standard deviations, > 0
  double minSigma = 0.0;  ///< floor of σ in the adaptive test (value units), >= 0
  /// Reject voxels whose central-difference world gradient magnitude
  /// (Volume::gradientWorld) exceeds this, in value per metre; +inf disables.
  double maxGradient = std::numeric_limits<double>::infinity();
  Connectivity connectivity = Connectivity::Six;
  std::optional<GrowBall> bound;  ///< only voxels whose centre lies inside this ball join
  std::size_t maxVoxels = std::numeric_limits<std::size_t>::max();  ///< stop after accepting this many
};

/// What one growth accepted.
struct RegionStats {
  std::size_t voxelCount = 0;  ///< voxels accepted by this growth (seeds included)
  std::size_t newVoxels = 0;   ///< of those, voxels the mask did not hold before
  double volumeM3 = 0.0;       ///< voxelCount · |det A| (A the index-to-world linear part), m³
  double volumeMl = 0.0;       ///< the same in millilitres (cm³)
  Aabb worldBounds;  ///< world box around the centres of the index box [minIndex, maxIndex], m (empty when
                     ///< none)
  Vec3i minIndex = Vec3i::Zero(), maxIndex = Vec3i::Zero();  ///< index bounds (valid when voxelCount > 0)
  double mean = 0.0, stddev = 0.0;                           ///< intensity statistics of the accepted voxels
  bool truncated = false;                                    ///< maxVoxels stopped the growth
};

/// A grown region: the U8 mask (1 inside, same geometry as the image) and its statistics.
struct RegionGrowResult {
  Volume mask;
  RegionStats stats;
};

/// Region growing with reusable scratch (visited bitmap and queue), for
/// repeated growth into one mask. Not thread-safe; one grower per thread.
class RegionGrower {
 public:
  /// Grows from `seeds` (voxel indices) over `image` and sets the accepted
  /// voxels to 1 in `mask` (U8, same dims as `image`; voxels already set stay
  /// set; set voxels are re-tested, not taken as accepted). A seed that fails
  /// the criteria starts nothing. O(accepted · neighbours) plus O(n/64) to
  /// clear the bitmap; allocates only when the scratch must grow.
  /// Fails with InvalidArgument on an empty image, a mask of another type or
  /// dims, a seed outside the grid (named by its position in `seeds`), or
  /// bad options (NaN or lower > upper, k <= 0, minSigma < 0, negative or
  /// non-finite ball).
  /// @code
  ///   dm::RegionGrower grower;
  ///   auto mask = dm::Volume::create(image.dims(), dm::VoxelType::U8, image.indexToWorld());
  ///   auto stats = grower.grow(image, std::array{seed}, {.lower = 100}, *mask);
  /// @endcode
  Result<RegionStats> grow(const Volume& image, std::span<const Vec3i> seeds,
                           const RegionGrowOptions& options, Volume& mask);

 private:
  std::vector<std::uint64_t> visited_;
  std::vector<std::size_t> queue_;
};

/// Grows a region from `seeds` into a new mask; see RegionGrower::grow for
/// the criteria, cost and failures.
/// @code
///   auto r = dm::growRegion(mri, std::array{dm::Vec3i(90, 120, 100)}, {.lower = 90, .upper = 140});
///   if (!r) return r.error();
///   double ml = r->stats.volumeMl;
/// @endcode
Result<RegionGrowResult> growRegion(const Volume& image, std::span<const Vec3i> seeds,
                                    const RegionGrowOptions& options = {});

/// The voxel whose centre is nearest to world point `p` (m), or nullopt when
/// it lies outside the grid or p is not finite. O(1).
std::optional<Vec3i> nearestVoxel(const Volume& volume, const Vec3& p) noexcept;

/// Mean and standard deviation of the voxels within `halfWidth` voxels of
/// `centre` along each axis (a (2·halfWidth + 1)³ cube, clipped to the
/// grid), and how many there were — the intensity window a user's click
/// gives (mean ± k·σ). O(halfWidth³).
struct NeighbourhoodStats {
  double mean = 0.0, stddev = 0.0;
  std::size_t count = 0;
};
NeighbourhoodStats neighbourhoodStats(const Volume& volume, const Vec3i& centre, int halfWidth = 2);

}  // namespace dm
