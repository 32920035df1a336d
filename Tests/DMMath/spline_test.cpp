#include <dm/math/spline.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>
#include <vector>

namespace {

using dm::CubicSpline;
using dm::SplineKind;

std::vector<double> randomKnots(int n, double x0, std::mt19937& rng) {
  std::uniform_real_distribution<double> step(0.2, 1.5);
  std::vector<double> x{x0};
  for (int i = 1; i < n; ++i) x.push_back(x.back() + step(rng));
  return x;
}

double cubic(double x) { return 2 * x * x * x - x * x + 3 * x - 1; }
double cubicD(double x) { return 6 * x * x - 2 * x + 3; }
double cubicDD(double x) { return 12 * x - 2; }

TEST(Spline, PassesThroughKnotsForEveryKind) {
  std::mt19937 rng(1);
  const std::vector<double> x = randomKnots(12, -3.0, rng);
  std::vector<double> y;
  std::normal_distribution<double> g;
  for (std::size_t i = 0; i < x.size(); ++i) y.push_back(g(rng));
  for (auto kind : {SplineKind::Natural, SplineKind::Clamped, SplineKind::Monotone}) {
    auto s = CubicSpline::create(x, y, {.kind = kind, .startSlope = 0.5, .endSlope = -2.0});
    ASSERT_TRUE(s) << s.error();
    for (std::size_t i = 0; i < x.size(); ++i) EXPECT_EQ((*s)(x[i]), y[i]) << "knot " << i;
    // Continuity of value from the left at every interior knot.
    for (std::size_t i = 1; i + 1 < x.size(); ++i)
      EXPECT_NEAR((*s)(std::nextafter(x[i], -INFINITY)), y[i], 1e-12);
  }
}

TEST(Spline, ClampedSplineReproducesACubicExactly) {
  // A clamped spline is the unique C² piecewise cubic with the given end
  // slopes; the cubic itself is one, so it must come back exactly.
  std::mt19937 rng(2);
  const std::vector<double> x = randomKnots(9, -2.0, rng);
  std::vector<double> y;
  for (double xi : x) y.push_back(cubic(xi));
  auto s = CubicSpline::create(
      x, y, {.kind = SplineKind::Clamped, .startSlope = cubicD(x.front()), .endSlope = cubicD(x.back())});
  ASSERT_TRUE(s) << s.error();
  double maxErr[3] = {0, 0, 0};
  for (int k = 0; k <= 1000; ++k) {
    const double t = x.front() + (x.back() - x.front()) * k / 1000.0;
    maxErr[0] = std::max(maxErr[0], std::abs(s->value(t) - cubic(t)) / (1 + std::abs(cubic(t))));
    maxErr[1] = std::max(maxErr[1], std::abs(s->derivative(t) - cubicD(t)) / (1 + std::abs(cubicD(t))));
    maxErr[2] =
        std::max(maxErr[2], std::abs(s->secondDerivative(t) - cubicDD(t)) / (1 + std::abs(cubicDD(t))));
  }
  EXPECT_LT(maxErr[0], 1e-13);
  EXPECT_LT(maxErr[1], 1e-12);
  EXPECT_LT(maxErr[2], 1e-11);
}

TEST(Spline, NaturalSplineReproducesLinesAndHasZeroEndCurvature) {
  std::mt19937 rng(3);
  const std::vector<double> x = randomKnots(10, 0.0, rng);
  std::vector<double> line, wavy;
  for (double xi : x) line.push_back(3.0 - 0.25 * xi), wavy.push_back(std::sin(2 * xi) + 0.1 * xi * xi);
  auto l = CubicSpline::create(x, line);
  ASSERT_TRUE(l);
  for (double t = x.front(); t <= x.back(); t += 0.01) EXPECT_NEAR(l->value(t), 3.0 - 0.25 * t, 1e-13);
  auto s = CubicSpline::create(x, wavy);
  ASSERT_TRUE(s);
  EXPECT_NEAR(s->secondDerivative(x.front()), 0.0, 1e-12);
  EXPECT_NEAR(s->secondDerivative(x.back()), 0.0, 1e-12);
  // C²: y'' is continuous across interior knots (left limit = right value).
  for (std::size_t i = 1; i + 1 < x.size(); ++i) {
    const double left = s->secondDerivative(x[i] - 1e-9), right = s->secondDerivative(x[i]);
    EXPECT_NEAR(left, right, 1e-6 * (1 + std::abs(right))) << "knot " << i;
    EXPECT_NEAR(s->derivative(x[i] - 1e-9), s->derivative(x[i]), 1e-7);
  }
}

// Max error of the spline of f over [a, b] with n uniform intervals.
template <class F>
double interpolationError(F f, double a, double b, int n, const dm::SplineOptions& o) {
  std::vector<double> x(n + 1), y(n + 1);
  for (int i = 0; i <= n; ++i) x[i] = a + (b - a) * i / n, y[i] = f(x[i]);
  auto s = CubicSpline::create(x, y, o);
  EXPECT_TRUE(s);
  double e = 0;
  for (int k = 0; k <= 20000; ++k) {
    const double t = a + (b - a) * k / 20000.0;
    e = std::max(e, std::abs(s->value(t) - f(t)));
  }
  return e;
}

TEST(Spline, InterpolationErrorConvergesWithOrderFour) {
  // Natural on [0, π]: sin'' vanishes at both ends, so the natural end
  // condition is exact and the error is O(h⁴); clamped with exact slopes is
  // O(h⁴) on any interval.
  const double pi = std::numbers::pi;
  auto sinf = [](double t) { return std::sin(t); };
  const struct {
    const char* name;
    double a, b;
    dm::SplineOptions o;
  } cases[] = {{"natural [0,pi]", 0.0, pi, {}},
               {"clamped [0.3,2.9]",
                0.3,
                2.9,
                {.kind = SplineKind::Clamped, .startSlope = std::cos(0.3), .endSlope = std::cos(2.9)}}};
  for (const auto& c : cases) {
    double prev = 0;
    for (int n : {8, 16, 32, 64}) {
      const double e = interpolationError(sinf, c.a, c.b, n, c.o);
      if (prev > 0) {
        const double order = std::log2(prev / e);
        std::printf("  %-18s n=%3d  max error %.3e  observed order %.2f\n", c.name, n, e, order);
        EXPECT_NEAR(order, 4.0, 0.25) << c.name << " n=" << n;
      }
      prev = e;
    }
  }
  // The natural end condition is wrong for sin on [0.3, 2.9] (sin'' ≠ 0 at
  // the ends), which costs two orders near the ends: O(h²).
  const double e1 = interpolationError(sinf, 0.3, 2.9, 32, {}),
               e2 = interpolationError(sinf, 0.3, 2.9, 64, {});
  EXPECT_NEAR(std::log2(e1 / e2), 2.0, 0.3);
}

TEST(Spline, MonotoneSplineConvergesWithOrderThreeOnSmoothMonotoneData) {
  // PCHIP slopes are second-order accurate on smooth strictly monotone data,
  // giving O(h³) interpolation error.
  auto f = [](double t) { return std::log1p(t) + t; };
  const double e1 = interpolationError(f, 0.0, 3.0, 32, {.kind = SplineKind::Monotone});
  const double e2 = interpolationError(f, 0.0, 3.0, 64, {.kind = SplineKind::Monotone});
  const double e3 = interpolationError(f, 0.0, 3.0, 128, {.kind = SplineKind::Monotone});
  std::printf("  monotone order %.2f, %.2f\n", std::log2(e1 / e2), std::log2(e2 / e3));
  EXPECT_GT(std::log2(e1 / e2), 2.7);
  EXPECT_GT(std::log2(e2 / e3), 2.7);
  EXPECT_LT(std::log2(e2 / e3), 3.3);
}

TEST(Spline, MonotoneSplineNeverOvershootsStepDataWhileNaturalDoes) {
  const std::vector<double> x = {0, 1, 2, 3, 4, 5, 6, 7, 8, 9};
  const std::vector<double> y = {0, 0, 0, 0, 0.1, 1, 1, 1, 1, 1};
  auto mono = CubicSpline::create(x, y, {.kind = SplineKind::Monotone});
  auto nat = CubicSpline::create(x, y);
  ASSERT_TRUE(mono && nat);
  double monoMin = 1, monoMax = 0, natMin = 1, natMax = 0, prev = -1;
  bool nonDecreasing = true;
  for (int k = 0; k <= 9000; ++k) {
    const double t = 9.0 * k / 9000.0;
    const double v = mono->value(t);
    monoMin = std::min(monoMin, v), monoMax = std::max(monoMax, v);
    nonDecreasing = nonDecreasing && v >= prev;
    EXPECT_GE(mono->derivative(t), 0.0) << t;
    prev = v;
    natMin = std::min(natMin, nat->value(t)), natMax = std::max(natMax, nat->value(t));
  }
  EXPECT_TRUE(nonDecreasing);
  EXPECT_GE(monoMin, 0.0);
  EXPECT_LE(monoMax, 1.0);
  // The C² spline rings around the step (Gibbs-like overshoot).
  EXPECT_GT(natMax, 1.05);
  EXPECT_LT(natMin, -0.01);
}

TEST(Spline, MonotoneSplineStaysWithinEachIntervalOfRandomData) {
  // PCHIP keeps every piece between its two knot values (no new extrema),
  // for monotone increasing data and for arbitrary data.
  std::mt19937 rng(4);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (int trial = 0; trial < 20; ++trial) {
    const std::vector<double> x = randomKnots(15, 0.0, rng);
    std::vector<double> up, any;
    double acc = 0;
    for (std::size_t i = 0; i < x.size(); ++i) {
      acc += u(rng) < 0.3 ? 0.0 : std::pow(u(rng), 3);  // flats and jumps
      up.push_back(acc), any.push_back(u(rng));
    }
    for (const auto* data : {&up, &any}) {
      auto s = CubicSpline::create(x, *data, {.kind = SplineKind::Monotone});
      ASSERT_TRUE(s);
      for (std::size_t i = 0; i + 1 < x.size(); ++i) {
        const double lo = std::min((*data)[i], (*data)[i + 1]), hi = std::max((*data)[i], (*data)[i + 1]);
        double prev = (*data)[i];
        for (int k = 1; k <= 50; ++k) {
          const double v = s->value(x[i] + (x[i + 1] - x[i]) * k / 50.0);
          ASSERT_GE(v, lo - 1e-14) << "trial " << trial << " interval " << i;
          ASSERT_LE(v, hi + 1e-14) << "trial " << trial << " interval " << i;
          if ((*data)[i + 1] >= (*data)[i])
            ASSERT_GE(v, prev - 1e-14);
          else
            ASSERT_LE(v, prev + 1e-14);
          prev = v;
        }
      }
    }
  }
}

TEST(Spline, ExtrapolationPolicies) {
  const std::vector<double> x = {0, 1, 3}, y = {1, 2, 0};
  auto c = CubicSpline::create(x, y, {.extrapolation = dm::Extrapolation::Clamp});
  auto l = CubicSpline::create(x, y, {.extrapolation = dm::Extrapolation::Linear});
  ASSERT_TRUE(c && l);
  EXPECT_EQ(c->value(-5), 1.0);
  EXPECT_EQ(c->value(10), 0.0);
  EXPECT_EQ(c->derivative(-5), 0.0);
  EXPECT_EQ(c->derivative(10), 0.0);
  const double m0 = l->slopes()[0], m2 = l->slopes()[2];
  EXPECT_DOUBLE_EQ(l->value(-2), 1.0 - 2.0 * m0);
  EXPECT_DOUBLE_EQ(l->value(5), 0.0 + 2.0 * m2);
  EXPECT_EQ(l->derivative(5), m2);
  EXPECT_EQ(l->secondDerivative(5), 0.0);
  // Linear extrapolation continues the tangent: C¹ at the end knots.
  EXPECT_NEAR(l->derivative(3.0 - 1e-9), l->derivative(3.0 + 1e-9), 1e-7);
  EXPECT_TRUE(std::isnan(c->value(std::nan(""))));
}

TEST(Spline, EvaluateManyMatchesPointwiseInAnyOrder) {
  std::mt19937 rng(5);
  const std::vector<double> x = randomKnots(30, -1.0, rng);
  std::vector<double> y;
  for (double xi : x) y.push_back(std::cos(xi));
  auto s = CubicSpline::create(x, y);
  ASSERT_TRUE(s);
  std::vector<double> t;
  std::uniform_real_distribution<double> u(x.front() - 2, x.back() + 2);
  for (int k = 0; k < 2000; ++k) t.push_back(u(rng));
  t.push_back(x.front()), t.push_back(x.back()), t.push_back(std::nan(""));
  auto check = [&](const std::vector<double>& ts) {
    const std::vector<double> v = s->evaluate(ts);
    for (std::size_t k = 0; k < ts.size(); ++k) {
      if (std::isnan(ts[k]))
        EXPECT_TRUE(std::isnan(v[k]));
      else
        EXPECT_EQ(v[k], s->value(ts[k])) << ts[k];
    }
  };
  check(t);
  std::sort(t.begin(), t.end() - 1);
  check(t);
}

TEST(Spline, RejectsBadInputWithIndex) {
  const std::vector<double> one = {1.0};
  EXPECT_FALSE(CubicSpline::create(one, one));
  auto r = CubicSpline::create(std::vector<double>{0, 1, 2, 2, 3}, std::vector<double>{0, 1, 2, 3, 4});
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().what.find("x[3]"), std::string::npos) << r.error();
  EXPECT_NE(r.error().what.find("strictly increasing"), std::string::npos);
  auto d = CubicSpline::create(std::vector<double>{0, 2, 1}, std::vector<double>{0, 1, 2});
  ASSERT_FALSE(d);
  EXPECT_NE(d.error().what.find("x[2]"), std::string::npos);
  auto n = CubicSpline::create(std::vector<double>{0, 1, 2}, std::vector<double>{0, NAN, 2});
  ASSERT_FALSE(n);
  EXPECT_NE(n.error().what.find("y[1]"), std::string::npos);
  auto nx = CubicSpline::create(std::vector<double>{0, NAN, 2}, std::vector<double>{0, 1, 2});
  ASSERT_FALSE(nx);
  EXPECT_NE(nx.error().what.find("x[1]"), std::string::npos);
  EXPECT_FALSE(CubicSpline::create(std::vector<double>{0, 1}, std::vector<double>{0, 1, 2}));
  EXPECT_FALSE(CubicSpline::create(std::vector<double>{0, 1}, std::vector<double>{0, 1},
                                   {.kind = SplineKind::Clamped, .startSlope = INFINITY}));
}

TEST(Spline, TwoPointsGiveALineForNaturalAndMonotone) {
  const std::vector<double> x = {1, 3}, y = {2, 6};
  for (auto kind : {SplineKind::Natural, SplineKind::Monotone}) {
    auto s = CubicSpline::create(x, y, {.kind = kind});
    ASSERT_TRUE(s);
    EXPECT_DOUBLE_EQ(s->value(2.5), 5.0);
    EXPECT_DOUBLE_EQ(s->derivative(1.7), 2.0);
    EXPECT_NEAR(s->secondDerivative(2.0), 0.0, 1e-15);
  }
}

TEST(VectorSpline, ChannelsAreIndependentSplines) {
  const std::vector<double> x = {0, 0.5, 1.5, 2, 3};
  dm::MatX v(5, 3);
  v << 0, 1, 2, 1, 0, 3, 4, 2, 1, 2, 2, 0, 5, 1, 1;
  auto s = dm::VectorSpline::create(x, v);
  ASSERT_TRUE(s) << s.error();
  EXPECT_EQ(s->dimension(), 3);
  for (int c = 0; c < 3; ++c) {
    const dm::VecX col = v.col(c);
    auto ref = CubicSpline::create(x, std::vector<double>(col.data(), col.data() + col.size()));
    ASSERT_TRUE(ref);
    for (double t = -0.5; t < 3.5; t += 0.037) EXPECT_EQ((*s)(t)[c], ref->value(t));
  }
  v(2, 1) = NAN;
  auto bad = dm::VectorSpline::create(x, v);
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.error().what.find("channel 1"), std::string::npos) << bad.error();
  EXPECT_FALSE(dm::VectorSpline::create(std::vector<double>{0, 1}, v));
}

TEST(RgbaSpline, TransferFunctionStaysInUnitRangeAndHitsControlPoints) {
  // A CT-like transfer function: transparent air, a sharp skin ramp, bone.
  const std::vector<double> x = {-1000, -200, -100, 300, 400, 2000};
  const std::vector<dm::Vec4> c = {{0, 0, 0, 0},         {0, 0, 0, 0},         {0.9, 0.6, 0.5, 0.2},
                                   {0.9, 0.6, 0.5, 0.2}, {1.0, 1.0, 0.9, 0.9}, {1.0, 1.0, 1.0, 1.0}};
  auto tf = dm::RgbaSpline::create(x, c);
  ASSERT_TRUE(tf) << tf.error();
  for (std::size_t i = 0; i < x.size(); ++i) EXPECT_LT(((*tf)(x[i]) - c[i]).norm(), 1e-15);
  std::vector<dm::Vec4> lut(1024);
  tf->sample(-1000, 2000, lut);
  EXPECT_LT((lut.front() - c.front()).norm(), 1e-15);
  EXPECT_LT((lut.back() - c.back()).norm(), 1e-15);
  for (std::size_t i = 1; i < lut.size(); ++i) {
    EXPECT_TRUE((lut[i].array() >= 0).all() && (lut[i].array() <= 1).all());
    EXPECT_GE(lut[i][3], lut[i - 1][3]);  // opacity control points are monotone, so is opacity
  }
  // A natural opacity channel rings below 0 on this ramp; unclamped it shows.
  auto nat = dm::RgbaSpline::create(x, c, {.alphaKind = dm::SplineKind::Natural, .clampToUnit = false});
  ASSERT_TRUE(nat);
  double minAlpha = 1;
  for (double t = -1000; t <= 2000; t += 1) minAlpha = std::min(minAlpha, (*nat)(t)[3]);
  EXPECT_LT(minAlpha, 0.0);
  auto mismatch = dm::RgbaSpline::create(x, std::span<const dm::Vec4>(c).first(4));
  EXPECT_FALSE(mismatch);
}

}  // namespace
