#include <dm/math/spline.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>

namespace dm {
namespace {

constexpr const char* kSplineWhere = "CubicSpline::create";

Status checkKnots(std::span<const double> x, std::span<const double> y) {
  if (x.size() != y.size())
    return fail(ErrorCode::InvalidArgument, formatString("%zu knots x but %zu values y", x.size(), y.size()),
                kSplineWhere, "pass one value per knot");
  if (x.size() < 2)
    return fail(ErrorCode::InvalidArgument,
                formatString("a spline needs at least 2 points, got %zu", x.size()), kSplineWhere,
                "add control points (two points give a straight line)");
  for (std::size_t i = 0; i < x.size(); ++i) {
    if (!std::isfinite(x[i]))
      return fail(ErrorCode::InvalidArgument, formatString("x[%zu] is %g (NaN or Inf)", i, x[i]),
                  kSplineWhere, "knots must be finite numbers");
    if (!std::isfinite(y[i]))
      return fail(ErrorCode::InvalidArgument, formatString("y[%zu] is %g (NaN or Inf)", i, y[i]),
                  kSplineWhere, "values must be finite numbers");
    if (i > 0 && !(x[i] > x[i - 1]))
      return fail(
          ErrorCode::InvalidArgument,
          formatString("x[%zu] = %.17g is not greater than x[%zu] = %.17g: knots must be strictly increasing",
                       i, x[i], i - 1, x[i - 1]),
          kSplineWhere, "sort the control points by x and merge duplicates");
  }
  return ok();
}

// Slopes of the C² spline (natural or clamped ends): tridiagonal system
//   h_i m_{i-1} + 2(h_{i-1} + h_i) m_i + h_{i-1} m_{i+1} = 3(h_i δ_{i-1} + h_{i-1} δ_i)
// from continuity of y'' at the interior knots, solved by the Thomas
// algorithm (the matrix is strictly diagonally dominant, so no pivoting).
void c2Slopes(std::span<const double> x, std::span<const double> y, bool clamped, double s0, double s1,
              std::vector<double>& m) {
  const std::size_t n = x.size();
  std::vector<double> a(n), b(n), c(n), r(n);
  auto h = [&](std::size_t i) { return x[i + 1] - x[i]; };
  auto delta = [&](std::size_t i) { return (y[i + 1] - y[i]) / h(i); };
  if (clamped) {
    b[0] = 1.0, c[0] = 0.0, r[0] = s0;
    a[n - 1] = 0.0, b[n - 1] = 1.0, r[n - 1] = s1;
  } else {  // y''(x_0) = 0 ⇔ 2 m_0 + m_1 = 3 δ_0, and symmetrically at the end
    b[0] = 2.0, c[0] = 1.0, r[0] = 3.0 * delta(0);
    a[n - 1] = 1.0, b[n - 1] = 2.0, r[n - 1] = 3.0 * delta(n - 2);
  }
  for (std::size_t i = 1; i + 1 < n; ++i) {
    a[i] = h(i);
    b[i] = 2.0 * (h(i - 1) + h(i));
    c[i] = h(i - 1);
    r[i] = 3.0 * (h(i) * delta(i - 1) + h(i - 1) * delta(i));
  }
  for (std::size_t i = 1; i < n; ++i) {
    const double w = a[i] / b[i - 1];
    b[i] -= w * c[i - 1];
    r[i] -= w * r[i - 1];
  }
  m.resize(n);
  m[n - 1] = r[n - 1] / b[n - 1];
  for (std::size_t i = n - 1; i-- > 0;) m[i] = (r[i] - c[i] * m[i + 1]) / b[i];
}

// PCHIP slopes (Fritsch & Carlson 1980 with the Fritsch & Butland 1984
// weighted harmonic mean, as in MATLAB's pchip): zero slope at local extrema
// of the data, harmonic mean elsewhere, so each cubic piece is monotone
// between its knots.
void monotoneSlopes(std::span<const double> x, std::span<const double> y, std::vector<double>& m) {
  const std::size_t n = x.size();
  m.assign(n, 0.0);
  std::vector<double> h(n - 1), d(n - 1);
  for (std::size_t i = 0; i + 1 < n; ++i) {
    h[i] = x[i + 1] - x[i];
    d[i] = (y[i + 1] - y[i]) / h[i];
  }
  if (n == 2) {
    m[0] = m[1] = d[0];
    return;
  }
  for (std::size_t i = 1; i + 1 < n; ++i) {
    if (d[i - 1] * d[i] <= 0.0) continue;  // extremum or flat: m = 0
    const double w1 = 2.0 * h[i] + h[i - 1], w2 = h[i] + 2.0 * h[i - 1];
    m[i] = (w1 + w2) / (w1 / d[i - 1] + w2 / d[i]);
  }
  // One-sided three-point end slopes, limited to keep the end pieces monotone.
  auto end = [](double h0, double h1, double d0, double d1) {
    double s = ((2.0 * h0 + h1) * d0 - h0 * d1) / (h0 + h1);
    if (s * d0 <= 0.0)
      s = 0.0;
    else if (d0 * d1 <= 0.0 && std::abs(s) > std::abs(3.0 * d0))
      s = 3.0 * d0;
    return s;
  };
  m[0] = end(h[0], h[1], d[0], d[1]);
  m[n - 1] = end(h[n - 2], h[n - 3], d[n - 2], d[n - 3]);
}

}  // namespace

Result<CubicSpline> CubicSpline::create(std::span<const double> x, std::span<const double> y,
                                        const SplineOptions& options) {
  if (Status s = checkKnots(x, y); !s) return std::move(s).error();
  if (options.kind == SplineKind::Clamped &&
      (!std::isfinite(options.startSlope) || !std::isfinite(options.endSlope)))
    return fail(ErrorCode::InvalidArgument,
                formatString("clamped end slopes must be finite, got %g and %g", options.startSlope,
                             options.endSlope),
                kSplineWhere);
  CubicSpline s;
  s.x_.assign(x.begin(), x.end());
  s.y_.assign(y.begin(), y.end());
  s.kind_ = options.kind;
  s.extrapolation_ = options.extrapolation;
  switch (options.kind) {
    case SplineKind::Natural:
      c2Slopes(x, y, false, 0.0, 0.0, s.m_);
      break;
    case SplineKind::Clamped:
      c2Slopes(x, y, true, options.startSlope, options.endSlope, s.m_);
      break;
    case SplineKind::Monotone:
      monotoneSlopes(x, y, s.m_);
      break;
  }
  return s;
}

std::size_t CubicSpline::interval(double t) const noexcept {
  const auto it = std::upper_bound(x_.begin() + 1, x_.end() - 1, t);
  return static_cast<std::size_t>(it - x_.begin()) - 1;
}

// Hermite cubic of interval i in power form around x_i:
//   y = y_i + d (m_i + d (c2 + d c3)),  d = t − x_i.
double CubicSpline::valueIn(std::size_t i, double t) const noexcept {
  const double h = x_[i + 1] - x_[i];
  const double delta = (y_[i + 1] - y_[i]) / h;
  const double c2 = (3.0 * delta - 2.0 * m_[i] - m_[i + 1]) / h;
  const double c3 = (m_[i] + m_[i + 1] - 2.0 * delta) / (h * h);
  const double d = t - x_[i];
  return y_[i] + d * (m_[i] + d * (c2 + d * c3));
}

double CubicSpline::value(double t) const noexcept {
  const std::size_t n = x_.size();
  if (t < x_[0]) return extrapolation_ == Extrapolation::Linear ? y_[0] + m_[0] * (t - x_[0]) : y_[0];
  if (t >= x_[n - 1]) {
    if (t == x_[n - 1]) return y_[n - 1];
    return extrapolation_ == Extrapolation::Linear ? y_[n - 1] + m_[n - 1] * (t - x_[n - 1]) : y_[n - 1];
  }
  return valueIn(interval(t), t);  // NaN falls through here and stays NaN
}

double CubicSpline::derivative(double t) const noexcept {
  const std::size_t n = x_.size();
  if (t < x_[0]) return extrapolation_ == Extrapolation::Linear ? m_[0] : 0.0;
  if (t > x_[n - 1]) return extrapolation_ == Extrapolation::Linear ? m_[n - 1] : 0.0;
  if (t == x_[n - 1]) return m_[n - 1];
  const std::size_t i = interval(t);
  const double h = x_[i + 1] - x_[i];
  const double delta = (y_[i + 1] - y_[i]) / h;
  const double c2 = (3.0 * delta - 2.0 * m_[i] - m_[i + 1]) / h;
  const double c3 = (m_[i] + m_[i + 1] - 2.0 * delta) / (h * h);
  const double d = t - x_[i];
  return m_[i] + d * (2.0 * c2 + 3.0 * c3 * d);
}

double CubicSpline::secondDerivative(double t) const noexcept {
  const std::size_t n = x_.size();
  if (t < x_[0] || t > x_[n - 1]) return 0.0;
  // At the last knot use the last interval (right end of the data).
  const std::size_t i = t == x_[n - 1] ? n - 2 : interval(t);
  const double h = x_[i + 1] - x_[i];
  const double delta = (y_[i + 1] - y_[i]) / h;
  const double c2 = (3.0 * delta - 2.0 * m_[i] - m_[i + 1]) / h;
  const double c3 = (m_[i] + m_[i + 1] - 2.0 * delta) / (h * h);
  return 2.0 * c2 + 6.0 * c3 * (t - x_[i]);
}

void CubicSpline::evaluate(std::span<const double> t, std::span<double> out) const {
  DM_DEMAND(t.size() == out.size(), "CubicSpline::evaluate: t and out must have the same size");
  const std::size_t n = x_.size();
  std::size_t i = 0;
  for (std::size_t k = 0; k < t.size(); ++k) {
    const double tk = t[k];
    if (!(tk > x_[0] && tk < x_[n - 1])) {  // outside, at the ends, or NaN
      out[k] = value(tk);
      continue;
    }
    // Sorted input: the interval is the previous one or close after it.
    if (tk < x_[i]) {
      i = interval(tk);
    } else {
      std::size_t steps = 0;
      while (tk >= x_[i + 1] && steps < 8) ++i, ++steps;
      if (tk >= x_[i + 1]) i = interval(tk);
    }
    out[k] = valueIn(i, tk);
  }
}

std::vector<double> CubicSpline::evaluate(std::span<const double> t) const {
  std::vector<double> out(t.size());
  evaluate(t, out);
  return out;
}

// ----- VectorSpline --------------------------------------------------------------

Result<VectorSpline> VectorSpline::create(std::span<const double> x, const MatX& values,
                                          const SplineOptions& options) {
  if (values.cols() < 1)
    return fail(ErrorCode::InvalidArgument, "the value matrix has no columns (dimension 0)",
                "VectorSpline::create", "pass an n×d matrix with one row per knot");
  if (static_cast<std::size_t>(values.rows()) != x.size())
    return fail(ErrorCode::InvalidArgument,
                formatString("%zu knots x but the value matrix has %td rows", x.size(), values.rows()),
                "VectorSpline::create", "pass one row of values per knot");
  VectorSpline out;
  out.channels_.reserve(static_cast<std::size_t>(values.cols()));
  std::vector<double> column(x.size());
  for (Eigen::Index c = 0; c < values.cols(); ++c) {
    for (Eigen::Index i = 0; i < values.rows(); ++i) column[static_cast<std::size_t>(i)] = values(i, c);
    auto s = CubicSpline::create(x, column, options);
    if (!s) {
      Error e = std::move(s).error();
      e.what = formatString("channel %td: ", c) + e.what;
      e.where = "VectorSpline::create";
      return e;
    }
    out.channels_.push_back(std::move(*s));
  }
  return out;
}

void VectorSpline::evaluate(double t, VecX& out) const {
  if (out.size() != dimension()) out.resize(dimension());
  for (Eigen::Index c = 0; c < dimension(); ++c) out[c] = channels_[static_cast<std::size_t>(c)].value(t);
}

VecX VectorSpline::operator()(double t) const {
  VecX out(dimension());
  evaluate(t, out);
  return out;
}

// ----- RgbaSpline --------------------------------------------------------------------

Result<RgbaSpline> RgbaSpline::create(std::span<const double> x, std::span<const Vec4> rgba,
                                      const RgbaSplineOptions& options) {
  if (x.size() != rgba.size())
    return fail(ErrorCode::InvalidArgument,
                formatString("%zu scalars x but %zu colours", x.size(), rgba.size()), "RgbaSpline::create",
                "pass one RGBA colour per control scalar");
  static constexpr const char* kChannel[4] = {"red", "green", "blue", "alpha"};
  RgbaSpline out;
  out.clamp_ = options.clampToUnit;
  out.channels_.reserve(4);
  std::vector<double> column(x.size());
  for (int c = 0; c < 4; ++c) {
    for (std::size_t i = 0; i < rgba.size(); ++i) column[i] = rgba[i][c];
    const SplineOptions so{.kind = c == 3 ? options.alphaKind : options.colorKind,
                           .extrapolation = options.extrapolation};
    auto s = CubicSpline::create(x, column, so);
    if (!s) {
      Error e = std::move(s).error();
      e.what = std::string(kChannel[c]) + " channel: " + e.what;
      e.where = "RgbaSpline::create";
      return e;
    }
    out.channels_.push_back(std::move(*s));
  }
  return out;
}

Vec4 RgbaSpline::operator()(double t) const noexcept {
  Vec4 v;
  for (int c = 0; c < 4; ++c) {
    const double u = channels_[static_cast<std::size_t>(c)].value(t);
    v[c] = clamp_ ? std::clamp(u, 0.0, 1.0) : u;
  }
  return v;
}

void RgbaSpline::sample(double x0, double x1, std::span<Vec4> out) const noexcept {
  if (out.empty()) return;
  if (out.size() == 1) {
    out[0] = (*this)(x0);
    return;
  }
  const double step = (x1 - x0) / static_cast<double>(out.size() - 1);
  for (std::size_t i = 0; i < out.size(); ++i)
    out[i] = (*this)(i + 1 == out.size() ? x1 : x0 + step * static_cast<double>(i));
}

}  // namespace dm
