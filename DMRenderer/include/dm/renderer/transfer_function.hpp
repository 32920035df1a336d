// dm/renderer/transfer_function.hpp — 1-D transfer functions for volume
// rendering: voxel value (in the volume's own units, e.g. MRI intensity or
// Hounsfield units) → linear RGB colour and opacity.
//
// Control points are interpolated channel by channel by DMMath's RgbaSpline
// (monotone PCHIP cubics by default: C¹, no overshoot between control
// points, every channel clamped to [0, 1]); values outside the control range
// take the end points' colours.
//
// Opacity is given PER UNIT LENGTH: a control point's alpha is the opacity of
// a slab `opacityUnitLength` metres thick (1 mm by default) of material with
// that value. A ray-caster taking samples `step` metres apart uses the
// corrected per-sample opacity 1 − (1 − α)^(step / unitLength)
// (correctOpacity()), so images do not change with the step size.
//
// @code
//   auto tf = dm::TransferFunction::create({{0, {0, 0, 0, 0}}, {80, {0.9, 0.7, 0.6, 0.05}}, {255, {1, 1, 1,
//   0.8}}}); if (!tf) return tf.error(); dm::Vec4 rgba = (*tf)(120.0);                 // colour and opacity
//   per mm at value 120
// @endcode
#pragma once

#include <dm/core/result.hpp>
#include <dm/core/types.hpp>
#include <dm/math/spline.hpp>

#include <span>
#include <vector>

namespace dm {

/// One control point: a voxel value and its colour.
struct TfControlPoint {
  double value = 0;       ///< voxel value, the volume's units
  Vec4 rgba{0, 0, 0, 0};  ///< linear r, g, b in [0, 1]; a = opacity per unit length in [0, 1]
};

/// Options of TransferFunction::create().
struct TransferFunctionOptions {
  double opacityUnitLength = 1e-3;              ///< m; alpha is the opacity of a slab this thick
  SplineKind colorKind = SplineKind::Monotone;  ///< interpolation of r, g, b
  SplineKind alphaKind = SplineKind::Monotone;  ///< interpolation of the opacity
};

/// A value → RGBA map built from control points. Immutable; queries are
/// const and thread-safe.
class TransferFunction {
 public:
  /// Checks control points: at least 2, values finite and strictly
  /// increasing, every channel finite and within [0, 1]. InvalidArgument
  /// naming the point index and channel ("point 3: alpha is 1.2").
  static Status validate(std::span<const TfControlPoint> points);

  /// Validates (see validate()), checks opacityUnitLength > 0 and builds the
  /// splines. O(n).
  /// @code
  ///   auto tf = dm::TransferFunction::create(points, {.opacityUnitLength = 0.5e-3});
  ///   if (!tf) std::cerr << tf.error() << '\n';
  /// @endcode
  static Result<TransferFunction> create(std::vector<TfControlPoint> points,
                                         const TransferFunctionOptions& options = {});

  /// Colour and opacity (per unit length) at a voxel value; every channel in
  /// [0, 1]. O(log n).
  Vec4 operator()(double value) const noexcept { return spline_(value); }

  /// Lookup table of `n` ≥ 2 RGBA float entries sampling [lo, hi] evenly
  /// (entry i at lo + i·(hi − lo)/(n − 1)); opacity per unit length.
  /// InvalidArgument for n < 2 or more than 1<<20, or a non-finite/empty range. O(n).
  Result<std::vector<Vec4f>> bake(int n, double lo, double hi) const;
  /// The same over the control points' own value range.
  Result<std::vector<Vec4f>> bake(int n) const { return bake(n, valueMin(), valueMax()); }

  /// Per-sample opacity for samples `step` metres apart from opacity
  /// `alpha` per `unitLength` metres: 1 − (1 − α)^(step / unitLength).
  static double correctOpacity(double alpha, double step, double unitLength) noexcept;

  std::span<const TfControlPoint> points() const noexcept { return points_; }
  double valueMin() const noexcept { return points_.front().value; }
  double valueMax() const noexcept { return points_.back().value; }
  double opacityUnitLength() const noexcept { return unitLength_; }

  // ---- presets for T1-weighted MRI, in the volume's units: `lo` is the
  // background (air) intensity and `hi` the brightest tissue (white matter
  // or fat), e.g. Volume::range(). Fail only on a non-finite or empty range.

  /// Skin surface: everything above ~18% of the range, skin-coloured and
  /// nearly opaque, so the head's outer surface is shown.
  static Result<TransferFunction> mriSkin(double lo, double hi);
  /// Brain: grey and white matter (~40..100% of the range) in pink to white,
  /// semi-transparent; CSF and skin faint.
  static Result<TransferFunction> mriBrain(double lo, double hi);
  /// Linear grey ramp from (lo, transparent black) to (hi, opaque white).
  static Result<TransferFunction> greyRamp(double lo, double hi);

 private:
  std::vector<TfControlPoint> points_;
  RgbaSpline spline_;
  double unitLength_ = 1e-3;
};

}  // namespace dm
