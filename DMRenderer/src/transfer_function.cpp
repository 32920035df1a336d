// transfer_function.cpp — validated control points → RgbaSpline, baking,
// opacity correction and MRI presets.
#include <dm/renderer/transfer_function.hpp>

#include <algorithm>
#include <cmath>
#include <utility>

namespace dm {

namespace {

constexpr const char* kChannelName[4] = {"red", "green", "blue", "alpha"};

Status checkRange(double lo, double hi, const char* where) {
  if (!std::isfinite(lo) || !std::isfinite(hi) || !(hi > lo))
    return fail(ErrorCode::InvalidArgument,
                formatString("value range [%g, %g] is empty or not finite", lo, hi), where,
                "pass lo < hi, e.g. the volume's range()");
  return ok();
}

}  // namespace

Status TransferFunction::validate(std::span<const TfControlPoint> points) {
  const char* where = "TransferFunction";
  if (points.size() < 2)
    return fail(ErrorCode::InvalidArgument, formatString("%zu control points", points.size()), where,
                "give at least 2 control points (value, rgba)");
  for (std::size_t i = 0; i < points.size(); ++i) {
    const TfControlPoint& p = points[i];
    if (!std::isfinite(p.value))
      return fail(ErrorCode::InvalidArgument, formatString("point %zu: value is %g", i, p.value), where,
                  "control point values must be finite");
    if (i > 0 && !(p.value > points[i - 1].value))
      return fail(ErrorCode::InvalidArgument,
                  formatString("point %zu: value %g does not exceed point %zu's value %g", i, p.value, i - 1,
                               points[i - 1].value),
                  where, "sort the control points by strictly increasing value and merge duplicates");
    for (int c = 0; c < 4; ++c) {
      const double v = p.rgba[c];
      if (!std::isfinite(v) || v < 0.0 || v > 1.0)
        return fail(ErrorCode::InvalidArgument, formatString("point %zu: %s is %g", i, kChannelName[c], v),
                    where, "colour and opacity channels must lie in [0, 1] (linear colour)");
    }
  }
  return ok();
}

Result<TransferFunction> TransferFunction::create(std::vector<TfControlPoint> points,
                                                  const TransferFunctionOptions& options) {
  if (auto s = validate(points); !s) return s.error();
  if (!std::isfinite(options.opacityUnitLength) || !(options.opacityUnitLength > 0))
    return fail(ErrorCode::InvalidArgument,
                formatString("opacityUnitLength is %g m", options.opacityUnitLength),
                "TransferFunctionOptions::opacityUnitLength", "use a positive length in metres, e.g. 1e-3");
  std::vector<double> x(points.size());
  std::vector<Vec4> rgba(points.size());
  for (std::size_t i = 0; i < points.size(); ++i) {
    x[i] = points[i].value;
    rgba[i] = points[i].rgba;
  }
  auto spline = RgbaSpline::create(
      x, rgba, {.colorKind = options.colorKind, .alphaKind = options.alphaKind, .clampToUnit = true});
  if (!spline) return spline.error();
  TransferFunction tf;
  tf.points_ = std::move(points);
  tf.spline_ = std::move(*spline);
  tf.unitLength_ = options.opacityUnitLength;
  return tf;
}

Result<std::vector<Vec4f>> TransferFunction::bake(int n, double lo, double hi) const {
  if (n < 2 || n > (1 << 20))
    return fail(ErrorCode::InvalidArgument, formatString("table size %d", n), "TransferFunction::bake",
                "use 2 to 1048576 entries (256..4096 is typical)");
  if (auto s = checkRange(lo, hi, "TransferFunction::bake"); !s) return s.error();
  std::vector<Vec4> table(static_cast<std::size_t>(n));
  spline_.sample(lo, hi, table);
  std::vector<Vec4f> out(table.size());
  for (std::size_t i = 0; i < table.size(); ++i) out[i] = table[i].cast<float>();
  return out;
}

double TransferFunction::correctOpacity(double alpha, double step, double unitLength) noexcept {
  const double a = std::clamp(alpha, 0.0, 1.0);
  if (a >= 1.0) return 1.0;
  return 1.0 - std::pow(1.0 - a, step / unitLength);
}

Result<TransferFunction> TransferFunction::mriSkin(double lo, double hi) {
  if (auto s = checkRange(lo, hi, "TransferFunction::mriSkin"); !s) return s.error();
  const double w = hi - lo;
  return create({{lo, {0, 0, 0, 0}},
                 {lo + 0.12 * w, {0.8, 0.5, 0.4, 0}},
                 {lo + 0.22 * w, {0.9, 0.65, 0.55, 0.6}},
                 {hi, {1.0, 0.9, 0.85, 0.9}}});
}

Result<TransferFunction> TransferFunction::mriBrain(double lo, double hi) {
  if (auto s = checkRange(lo, hi, "TransferFunction::mriBrain"); !s) return s.error();
  const double w = hi - lo;
  return create({{lo, {0, 0, 0, 0}},
                 {lo + 0.15 * w, {0.6, 0.3, 0.2, 0}},
                 {lo + 0.3 * w, {0.7, 0.4, 0.3, 0.01}},
                 {lo + 0.45 * w, {0.85, 0.45, 0.45, 0.08}},
                 {lo + 0.7 * w, {0.95, 0.75, 0.7, 0.25}},
                 {hi, {1.0, 0.97, 0.95, 0.5}}});
}

Result<TransferFunction> TransferFunction::greyRamp(double lo, double hi) {
  if (auto s = checkRange(lo, hi, "TransferFunction::greyRamp"); !s) return s.error();
  return create({{lo, {0, 0, 0, 0}}, {hi, {1, 1, 1, 1}}});
}

}  // namespace dm
