// dm/math/spline.hpp — 1-D cubic splines: natural, clamped and monotone
// (Fritsch–Carlson / PCHIP), plus vector-valued and RGBA variants for
// transfer functions (scalar → colour and opacity).
//
// All kinds are stored in Hermite form: knot values y_i and knot slopes m_i,
// with one cubic per interval [x_i, x_{i+1}]. Natural and clamped splines
// are C² (slopes from a tridiagonal solve, O(n)); the monotone spline is C¹
// and never leaves the range of the data between two knots, so a monotone
// opacity ramp stays monotone and within [min y, max y].
//
// @code
//   auto s = dm::CubicSpline::create(x, y, {.kind = dm::SplineKind::Monotone});
//   if (!s) return s.error();
//   double v = (*s)(0.3), dv = s->derivative(0.3);
// @endcode
#pragma once

#include <dm/core/result.hpp>
#include <dm/math/types.hpp>

#include <cstdint>
#include <span>
#include <vector>

namespace dm {

/// How the knot slopes are chosen.
enum class SplineKind : std::uint8_t {
  Natural,   ///< C², second derivative zero at both ends
  Clamped,   ///< C², first derivative at the ends given (SplineOptions::startSlope/endSlope)
  Monotone,  ///< C¹ PCHIP (Fritsch–Carlson/Butland slopes): no overshoot, preserves monotonicity
};

/// What happens outside [x_0, x_{n-1}].
enum class Extrapolation : std::uint8_t {
  Clamp,   ///< hold the end value; derivatives are 0 outside
  Linear,  ///< continue along the end tangent; second derivative 0 outside
};

/// Options of CubicSpline::create().
struct SplineOptions {
  SplineKind kind = SplineKind::Natural;
  double startSlope = 0.0;  ///< dy/dx at x_0 (Clamped only), units of y per unit of x
  double endSlope = 0.0;    ///< dy/dx at x_{n-1} (Clamped only)
  Extrapolation extrapolation = Extrapolation::Clamp;
};

/// An interpolating 1-D cubic spline y(x). Immutable after creation; all
/// queries are const and thread-safe. Evaluation at one point is
/// O(log n) (binary search for the interval); a NaN argument gives NaN.
class CubicSpline {
 public:
  /// Builds the spline through (x_i, y_i), i = 0..n-1, n ≥ 2 (x strictly
  /// increasing). O(n). Fails with InvalidArgument on fewer than 2 points,
  /// x/y of different lengths, NaN/Inf in x, y or the end slopes, or a
  /// non-increasing x (the message names the index).
  /// @code
  ///   auto s = dm::CubicSpline::create(xs, ys);                 // natural
  ///   auto c = dm::CubicSpline::create(xs, ys, {.kind = dm::SplineKind::Clamped, .startSlope = 1});
  /// @endcode
  static Result<CubicSpline> create(std::span<const double> x, std::span<const double> y,
                                    const SplineOptions& options = {});

  /// Value y(t).
  double operator()(double t) const noexcept { return value(t); }
  double value(double t) const noexcept;
  /// First derivative dy/dx at t.
  double derivative(double t) const noexcept;
  /// Second derivative d²y/dx² at t (piecewise linear, jumps at knots for
  /// the monotone kind; at a knot the right-hand interval's value).
  double secondDerivative(double t) const noexcept;

  /// Values at many points: out[i] = y(t[i]). Sizes must match (DM_DEMAND).
  /// Sorted t is fastest (amortised O(1) per point: the interval search
  /// starts from the previous one); any order is correct.
  void evaluate(std::span<const double> t, std::span<double> out) const;
  /// Convenience: returns a vector of values at t.
  std::vector<double> evaluate(std::span<const double> t) const;

  std::span<const double> knots() const noexcept { return x_; }
  std::span<const double> values() const noexcept { return y_; }
  /// Slopes dy/dx at the knots (the Hermite form).
  std::span<const double> slopes() const noexcept { return m_; }
  double xMin() const noexcept { return x_.front(); }
  double xMax() const noexcept { return x_.back(); }
  SplineKind kind() const noexcept { return kind_; }
  Extrapolation extrapolation() const noexcept { return extrapolation_; }

 private:
  CubicSpline() = default;
  std::size_t interval(double t) const noexcept;  // i such that x_i ≤ t < x_{i+1}, clamped to [0, n-2]
  double valueIn(std::size_t i, double t) const noexcept;

  std::vector<double> x_, y_, m_;
  SplineKind kind_ = SplineKind::Natural;
  Extrapolation extrapolation_ = Extrapolation::Clamp;
};

/// A spline with d channels sharing one set of knots, each channel an
/// independent CubicSpline built with the same options (for Clamped, the
/// same end slopes for every channel).
class VectorSpline {
 public:
  /// `values` is n×d: row i is the control point at x_i. Same checks as
  /// CubicSpline::create (the message names the channel); also d ≥ 1.
  /// @code
  ///   auto path = dm::VectorSpline::create(times, waypoints);  // waypoints n×3
  ///   dm::VecX p(3);  path->evaluate(0.5, p);
  /// @endcode
  static Result<VectorSpline> create(std::span<const double> x, const MatX& values,
                                     const SplineOptions& options = {});
  /// out (size d, resized if needed) = value of every channel at t.
  void evaluate(double t, VecX& out) const;
  VecX operator()(double t) const;
  Eigen::Index dimension() const noexcept { return static_cast<Eigen::Index>(channels_.size()); }
  const CubicSpline& channel(Eigen::Index c) const { return channels_.at(static_cast<std::size_t>(c)); }

 private:
  std::vector<CubicSpline> channels_;
};

/// Transfer function for volume rendering: scalar → RGBA, each channel a
/// spline through the control points. Default: monotone (PCHIP) channels,
/// clamped extrapolation, outputs clamped to [0, 1] (only the natural and
/// clamped kinds can overshoot; monotone channels stay inside the control
/// values already).
struct RgbaSplineOptions {
  SplineKind colorKind = SplineKind::Monotone;  ///< kind of the R, G, B channels
  SplineKind alphaKind = SplineKind::Monotone;  ///< kind of the opacity channel
  Extrapolation extrapolation = Extrapolation::Clamp;
  bool clampToUnit = true;  ///< clamp every channel to [0, 1] after evaluation
};

class RgbaSpline {
 public:
  /// Control points: scalars x (strictly increasing, n ≥ 2) and colours
  /// rgba[i] = (r, g, b, a). Fails like CubicSpline::create.
  /// @code
  ///   auto tf = dm::RgbaSpline::create(std::vector{0.0, 40.0, 200.0}, colours);
  ///   dm::Vec4 c = (*tf)(57.0);
  /// @endcode
  static Result<RgbaSpline> create(std::span<const double> x, std::span<const Vec4> rgba,
                                   const RgbaSplineOptions& options = {});
  Vec4 operator()(double t) const noexcept;
  /// Fills a lookup table: out[i] = rgba(x0 + i·(x1 − x0)/(out.size() − 1)),
  /// e.g. for a 1-D texture (convert to float at upload). O(size).
  void sample(double x0, double x1, std::span<Vec4> out) const noexcept;
  const CubicSpline& channel(int c) const { return channels_.at(static_cast<std::size_t>(c)); }

 private:
  std::vector<CubicSpline> channels_;  // r, g, b, a
  bool clamp_ = true;
};

}  // namespace dm
