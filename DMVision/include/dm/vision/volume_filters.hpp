// dm/vision/volume_filters.hpp — 3-D image processing on dm::Volume.
//
// Filters that turn one volume into another with the same dims and
// index-to-world affine: separable Gaussian smoothing (sigma in metres,
// anisotropic spacing honoured), central-difference gradients in world units,
// a 3-D Canny edge detector (smoothed gradient magnitude, non-maximum
// suppression along the gradient, hysteresis), thresholding, connected
// components (dm/math/volume_components.hpp, included: DMIO's scene
// segments use them too) and binary morphology with a
// ball or cube structuring element (exact, via separable distance
// transforms, O(n) whatever the radius). Every filter runs on the oneTBB
// workers (dm::parallelFor) and returns a new volume; none modifies its
// input. Masks are "nonzero = foreground" on input and U8 0/1 on output.
//
// @code
//   auto smooth = dm::gaussianSmooth(ct, 1.0 * dm::units::mm);
//   auto edges = dm::detectEdges(ct, {.sigma = 1.0 * dm::units::mm, .low = 0.1, .high = 0.25});
//   auto bone = dm::largestComponent(*dm::threshold(ct, 300.0), dm::Connectivity::TwentySix);
// @endcode
#pragma once

#include <dm/core/result.hpp>
#include <dm/core/types.hpp>
#include <dm/core/volume.hpp>
#include <dm/math/volume_components.hpp>  // Connectivity, neighbourOffsets, labelComponents, largestComponent

#include <cstddef>
#include <cstdint>
#include <limits>
#include <span>
#include <vector>

namespace dm {

/// Separable Gaussian smoothing with standard deviation `sigma` in METRES
/// (world units, as everywhere in the SDK): along index axis a the kernel
/// has sigma / spacing()[a] voxels, so anisotropic grids are smoothed
/// isotropically in world space (exact for affines with orthogonal columns;
/// for sheared ones the axes are treated as if orthogonal). The kernel is
/// truncated at `truncate` sigmas and renormalised; borders replicate the
/// edge voxel (as Volume::sampleIndex does), so a constant stays constant.
/// An axis whose sigma is below 0.1 voxel is left unsmoothed.
/// Output: F32, same dims and affine. Cost O(n·(r_x + r_y + r_z)) with r the
/// kernel radii; memory: output plus one F32 scratch volume.
/// Fails with InvalidArgument on an empty volume, sigma < 0 or not finite,
/// truncate not in [1, 10], or a kernel radius above 1024 voxels.
/// @code
///   auto smooth = dm::gaussianSmooth(mri, 1.5 * dm::units::mm);
///   if (!smooth) return smooth.error();
///   double v = smooth->value(90, 108, 90);
/// @endcode
Result<Volume> gaussianSmooth(const Volume& in, double sigma, double truncate = 3.0);

/// The gradient of a volume in world units (value per metre), one F32
/// volume per world axis, all with the input's dims and affine.
struct GradientField {
  Volume x, y, z;  ///< ∂v/∂x, ∂v/∂y, ∂v/∂z (world axes), value per metre
  /// Gradient at voxel (i, j, k) (must be inside). O(1).
  Vec3 at(int i, int j, int k) const {
    const std::size_t n = x.linearIndex(i, j, k);
    return {x.valueAt(n), y.valueAt(n), z.valueAt(n)};
  }
};

/// Central-difference gradient in world units at every voxel, exactly as
/// Volume::gradientWorld (one-sided at the border, chain rule through the
/// affine, so a linear field gives its slope everywhere on any affine).
/// O(n), three F32 output volumes. Fails with InvalidArgument on an empty
/// volume.
/// @code
///   auto g = dm::gradient(mri);
///   if (!g) return g.error();
///   dm::Vec3 slope = g->at(90, 108, 90);  // value per metre
/// @endcode
Result<GradientField> gradient(const Volume& in);

/// |∇v| in world units (value per metre) at every voxel; F32, same
/// geometry. O(n). Fails with InvalidArgument on an empty volume.
Result<Volume> gradientMagnitude(const Volume& in);

/// Options of detectEdges().
struct EdgeOptions {
  double sigma = 1e-3;  ///< m, Gaussian smoothing before differentiation (0: none)
  double low = 0.1;     ///< hysteresis low threshold, fraction of the largest gradient magnitude, in [0, 1]
  double high = 0.2;  ///< hysteresis high threshold, fraction of the largest gradient magnitude, in [low, 1]
  Connectivity connectivity = Connectivity::TwentySix;  ///< how weak edges join strong ones
};

/// Result of detectEdges().
struct EdgeMap {
  /// Edge strength m: gradient magnitude of the smoothed volume divided by
  /// its maximum, F32 in [0, 1] (all 0 for a constant volume). Continuous,
  /// so ∇m is meaningful: haptic guidance and ray casting use it.
  Volume strength;
  /// Canny edges: U8, 1 on voxels that are local maxima of the strength
  /// along the gradient direction and are >= high or connected through
  /// voxels >= low to one that is.
  Volume edges;
  double maxGradient = 0.0;  ///< the normaliser: largest |∇(smoothed v)|, value per metre
};

/// 3-D Canny edge detection: Gaussian smoothing (gaussianSmooth), gradient
/// magnitude (gradientMagnitude) normalised to [0, 1], non-maximum
/// suppression along the world gradient direction (strength compared with
/// trilinear samples one voxel step before and after), hysteresis from
/// voxels >= high through voxels >= low. O(n) plus the smoothing; memory
/// about four F32 volumes. Fails with InvalidArgument on an empty volume or
/// thresholds outside 0 <= low <= high <= 1, or like gaussianSmooth.
/// @code
///   auto e = dm::detectEdges(mri, {.sigma = 1e-3, .low = 0.1, .high = 0.3});
///   if (!e) return e.error();
///   bool onEdge = e->edges.value(90, 108, 90) != 0;
/// @endcode
Result<EdgeMap> detectEdges(const Volume& in, const EdgeOptions& options = {});

/// U8 mask: 1 where lo <= value <= hi, else 0 (binary threshold with the
/// default hi = +inf, band threshold otherwise). O(n). Fails with
/// InvalidArgument on an empty volume, NaN bounds or lo > hi.
/// @code
///   auto brain = dm::threshold(mri, 1.0);  // nonzero voxels of a skull-stripped MRI
/// @endcode
Result<Volume> threshold(const Volume& in, double lo, double hi = std::numeric_limits<double>::infinity());

/// Structuring elements of the morphology filters, of radius r in voxels.
enum class StructuringElement : std::uint8_t {
  Ball,  ///< offsets o with |o|² <= r² (index units, whatever the spacing)
  Cube,  ///< offsets with max |o_a| <= r, a (2r+1)³ cube
};

/// Binary erosion of `mask` (nonzero = foreground) by the structuring
/// element of radius `radius` voxels: a voxel stays when every voxel of the
/// element around it that lies inside the grid is foreground (outside the
/// grid neither erodes nor dilates, which keeps erode/dilate adjoint and
/// opening/closing idempotent). Exact for any radius: ball via a separable
/// squared Euclidean distance transform (dm::squaredDistanceToForeground,
/// dm/math/volume_distance.hpp), cube
/// via separable 1-D distances; O(n) either way, at most 5 bytes of scratch
/// per voxel. U8 output, same geometry. radius 0 copies the mask as 0/1.
/// Fails with InvalidArgument on an empty volume or a radius < 0 or > 1024.
/// @code
///   auto core = dm::erode(mask, 2);                                      // ball of radius 2 voxels
///   auto closed = dm::closing(mask, 1, dm::StructuringElement::Cube);   // fills 1-voxel gaps
/// @endcode
Result<Volume> erode(const Volume& mask, int radius, StructuringElement se = StructuringElement::Ball);
/// Binary dilation: a voxel becomes foreground when the element around it
/// touches a foreground voxel. Same cost and failures as erode().
Result<Volume> dilate(const Volume& mask, int radius, StructuringElement se = StructuringElement::Ball);
/// Opening: dilate(erode(mask)) — removes parts thinner than the element.
/// Idempotent. Same failures as erode().
Result<Volume> opening(const Volume& mask, int radius, StructuringElement se = StructuringElement::Ball);
/// Closing: erode(dilate(mask)) — fills gaps narrower than the element.
/// Idempotent. Same failures as erode().
Result<Volume> closing(const Volume& mask, int radius, StructuringElement se = StructuringElement::Ball);

}  // namespace dm
