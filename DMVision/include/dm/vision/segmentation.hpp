// dm/vision/segmentation.hpp — haptic-guided segmentation of a volume.
//
// The user moves a haptic probe through a volume image. Around the probe a
// bounded ball adapts its radius to the local structure: N rays from the
// probe march through the edge map m (the normalised smoothed gradient
// magnitude of dm::detectEdges) and stop at the first edge, the first local
// maximum of m along the ray after m has exceeded a threshold; the radius is
// the smallest stop distance, clamped to [rMin, rMax]. update() grows a region
// from the probe's voxel inside that ball and adds it to a persistent mask,
// so sweeping the probe paints the structure without leaking through edges.
// guidanceForce() pushes the probe away from edges into homogeneous tissue:
// with ray_i = ρ·d_i the vector from the probe p to the ball surface along
// the unit direction d_i (ρ the adaptive radius), the per-ray term
// a·(ray_i · ∇m)/|ray_i| (∇m at p + ray_i) is the slope of the edge map
// where the ray ends; it acts along −ray_i/|ray_i| (away from a rising edge),
// and the force is its average over the N rays:
//
//     F = −(a/N) · Σ_i [(ray_i · ∇m(p + ray_i)) / |ray_i|] · ray_i/|ray_i|
//
// By symmetry F vanishes at the centre of a homogeneous region; near an
// edge it points away from it. |F| is clamped to maxForce.
//
// guidanceForce() and adaptiveRadius() are real-time safe (no allocation,
// lock or throw; the ray directions are precomputed) and read only data
// fixed at create(), so the haptic thread may call them while another
// thread runs update(). They take what dm::ForceEffect::apply takes (the
// device point, world frame, metres) and give its force (N, world frame), so
// dm::ForceFieldEffect (DMHaptics) puts the guidance in a haptic loop's
// effect stack: ForceFieldEffect([&seg](const Vec3& p) { return
// seg.guidanceForce(p); }, "segmentation").
//
// @code
//   auto seg = dm::HapticSegmentation::create(mri, {.grow = {.lower = 90, .upper = 140}});
//   seg->update(probe);                              // a few times per second
//   dm::Vec3 f = seg->guidanceForce(probe);          // every haptic tick, N
// @endcode
#pragma once

#include <dm/core/result.hpp>
#include <dm/core/types.hpp>
#include <dm/core/volume.hpp>
#include <dm/vision/region_growing.hpp>
#include <dm/vision/volume_filters.hpp>

#include <cstddef>
#include <span>
#include <vector>

namespace dm {

/// Options of HapticSegmentation.
struct HapticSegmentationOptions {
  double edgeSigma = 1e-3;      ///< m, Gaussian smoothing of the edge map (detectEdges sigma)
  int rayCount = 64;            ///< N rays, spread evenly (Fibonacci sphere), in [6, 4096]
  double minRadius = 1e-3;      ///< rMin, m, > 0
  double maxRadius = 15e-3;     ///< rMax, m, >= rMin
  double edgeThreshold = 0.25;  ///< edge strength in (0, 1] a ray must exceed to stop at an edge
  double rayStep = 0.0;         ///< m, march step along rays; 0: half the smallest voxel spacing
  double gain = 1e-3;     ///< a, N·m: force per unit slope of the (dimensionless) edge map along a ray (1/m)
  double maxForce = 2.0;  ///< N, clamp of |F|, >= 0
  RegionGrowOptions grow;  ///< criteria of the growth inside the ball; its `bound` is set by update()
};

/// What one update() did.
struct SegmentationUpdate {
  double radius = 0.0;          ///< m, the adaptive ball radius at the probe
  std::size_t grownVoxels = 0;  ///< voxels accepted in the ball this time
  std::size_t newVoxels = 0;    ///< of those, voxels not segmented before
  std::size_t totalVoxels = 0;  ///< voxels in the segmentation now
  double totalVolumeMl = 0.0;   ///< its volume, mL
};

/// Haptic-guided segmentation; see the file comment. update() is for a
/// non-real-time thread, guidanceForce() for the haptic loop.
class HapticSegmentation {
 public:
  /// Builds the edge map of `image` (detectEdges with edgeSigma), an empty
  /// U8 mask with the image's geometry and the ray directions, and keeps a
  /// copy of the image. Memory: the image copy + 4 bytes (edge map) + 1 byte
  /// (mask) + 1 bit (growth scratch) per voxel. Cost: detectEdges.
  /// Fails with InvalidArgument on an empty image or an option out of its
  /// range (named), or like detectEdges / RegionGrowOptions checks.
  /// @code
  ///   auto seg = dm::HapticSegmentation::create(ct, {.maxRadius = 0.02, .grow = {.lower = 200}});
  ///   if (!seg) return seg.error();
  ///   seg->update(tip);
  /// @endcode
  static Result<HapticSegmentation> create(const Volume& image,
                                           const HapticSegmentationOptions& options = {});

  /// Casts the rays at `probe` (world, m), grows the region from the probe's
  /// voxel inside the ball of the adaptive radius and adds it to the mask.
  /// A probe outside the grid grows nothing. Not real-time: O(N·rMax/step)
  /// for the rays plus the growth (O(voxels in the ball)) plus O(n/64).
  /// Fails with InvalidArgument when `probe` is not finite.
  Result<SegmentationUpdate> update(const Vec3& probe);

  /// The guidance force (N, world) at `probe` (world, m); see the file
  /// comment for the formula. Zero for a non-finite probe or a non-finite
  /// result; |F| <= maxForce. Real-time safe; O(N·(rMax/step + 6))
  /// trilinear samples of the edge map.
  Vec3 guidanceForce(const Vec3& probe) const noexcept;

  /// The adaptive ball radius ρ (m) at `probe`: the smallest distance along
  /// the rays to an edge (first local maximum of m after m >= threshold,
  /// refined by a parabola through three samples), rMax for rays that meet
  /// none, clamped to [rMin, rMax]. rMin for a non-finite probe.
  /// Real-time safe; O(N·rMax/step) at worst: each ray looks only as far
  /// as the nearest edge found so far (measured ~22 µs per guidanceForce
  /// with 64 rays on Colin27 at 1 mm, Bench/vision_volume_bench.cpp).
  double adaptiveRadius(const Vec3& probe) const noexcept;

  /// Distance (m) from `probe` along unit direction `dir` to the first edge
  /// as in adaptiveRadius(), or rMax when there is none. Real-time safe.
  double rayDistance(const Vec3& probe, const Vec3& dir) const noexcept;

  /// Edge-map gradient ∇m at a world point, 1/m, by central differences of
  /// trilinear samples one voxel apart. Real-time safe.
  Vec3 edgeGradient(const Vec3& world) const noexcept;

  /// The segmentation: U8, 1 = segmented, the image's geometry.
  const Volume& mask() const { return mask_; }
  /// The edge map m (F32 in [0, 1], the image's geometry).
  const Volume& edgeStrength() const { return edges_; }
  /// The unit ray directions (N of them).
  std::span<const Vec3> rayDirections() const { return rays_; }
  const HapticSegmentationOptions& options() const { return options_; }
  /// Voxels segmented so far and their volume in m³.
  std::size_t segmentedVoxels() const { return segmented_; }
  double segmentedVolume() const;
  /// Empties the mask.
  void clear();

 private:
  // Trilinear sample of the edge map at a continuous voxel index.
  double sampleEdges(const Vec3& ijk) const noexcept;
  // First ridge of m along start + t·dir (index units per metre of t), t in
  // metres; looks at most about `limit` metres far; rMax when none.
  double march(const Vec3& startIndex, const Vec3& dirIndex, double limit) const noexcept;

  HapticSegmentationOptions options_;
  Volume image_, edges_, mask_;
  std::vector<Vec3> rays_;
  RegionGrower grower_;
  double step_ = 0.0, gradStep_ = 0.0;
  std::size_t segmented_ = 0;
};

}  // namespace dm
