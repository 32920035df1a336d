// Sweeps each fast function over its whole documented domain against a
// long-double reference (x87 80-bit, ~1e-19 relative) and checks the
// documented maximum error. The measured maxima are printed.
#include <dm/math/fast_math.hpp>

#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <numbers>
#include <random>

namespace {

struct MaxError {
  double error = 0.0;
  double at = 0.0;
  void add(long double e, double x) {
    if (!(static_cast<double>(e) <= error)) error = static_cast<double>(e), at = x;  // NaN counts as worst
  }
};

long double relError(double approx, long double ref) { return std::fabs((approx - ref) / ref); }

void report(const char* name, const MaxError& m, double bound) {
  std::printf("  %-22s max error %.3e at x = %.17g (documented bound %.1e)\n", name, m.error, m.at, bound);
}

// Calls f(x) for every binary exponent of positive doubles (subnormal
// included): the power of two itself, its neighbours, and `perExponent`
// random mantissas.
template <class F>
void everyExponent(F f, int perExponent, std::mt19937_64& rng) {
  for (int e = -1074; e <= 1023; ++e) {
    const double p = std::ldexp(1.0, e);
    f(p);
    f(std::nextafter(p, 0.0));
    if (e < 1023) f(std::nextafter(p, std::numeric_limits<double>::infinity()));
    for (int k = 0; k < perExponent && e > -1022; ++k) {
      const std::uint64_t mant = rng() & ((std::uint64_t{1} << 52) - 1);
      f(std::bit_cast<double>((std::bit_cast<std::uint64_t>(p) & ~((std::uint64_t{1} << 52) - 1)) | mant));
    }
  }
  f(std::numeric_limits<double>::max());
  f(std::numeric_limits<double>::denorm_min());
  for (int k = 0; k < 4096; ++k)  // subnormals
    f(std::bit_cast<double>(1 + rng() % (std::bit_cast<std::uint64_t>(0x1p-1022) - 1)));
}

// Calls f(x) for 2^bits jittered samples evenly covering the doubles in
// [1, 4): one full period of the bit-hack error (it is invariant under
// x → 4x, which shifts the seed's exponent by exactly one).
template <class F>
void denseMantissas(F f, int bits, std::mt19937_64& rng) {
  const std::uint64_t lo = std::bit_cast<std::uint64_t>(1.0), span = std::bit_cast<std::uint64_t>(4.0) - lo;
  const std::uint64_t n = std::uint64_t{1} << bits, step = span / n;
  for (std::uint64_t i = 0; i < n; ++i) f(std::bit_cast<double>(lo + i * step + rng() % step));
}

TEST(FastMath, InvSqrtDoubleOverAllPositiveDoubles) {
  std::mt19937_64 rng(1);
  MaxError m;
  auto check = [&](double x) {
    const long double ref = 1.0L / std::sqrt(static_cast<long double>(x));
    m.add(relError(dm::fastInvSqrt(x), ref), x);
  };
  denseMantissas(check, 21, rng);
  everyExponent(check, 64, rng);
  report("fastInvSqrt(double)", m, dm::kFastInvSqrtMaxRelError);
  EXPECT_LE(m.error, dm::kFastInvSqrtMaxRelError);
}

TEST(FastMath, SqrtDoubleOverAllPositiveDoubles) {
  std::mt19937_64 rng(2);
  MaxError m;
  auto check = [&](double x) { m.add(relError(dm::fastSqrt(x), std::sqrt(static_cast<long double>(x))), x); };
  denseMantissas(check, 21, rng);
  everyExponent(check, 64, rng);
  report("fastSqrt(double)", m, dm::kFastSqrtMaxRelError);
  EXPECT_LE(m.error, dm::kFastSqrtMaxRelError);
}

TEST(FastMath, InvSqrtAndSqrtFloatExhaustiveOverOnePeriod) {
  // Every float in [1, 4) — all mantissas for both exponent parities, which
  // is every distinct error the method can make on normal floats — plus
  // samples of every exponent including subnormals.
  MaxError mi, ms;
  auto check = [&](float x) {
    const long double s = std::sqrt(static_cast<long double>(x));
    mi.add(relError(dm::fastInvSqrt(x), 1.0L / s), x);
    ms.add(relError(dm::fastSqrt(x), s), x);
  };
  for (std::uint32_t b = std::bit_cast<std::uint32_t>(1.0f); b < std::bit_cast<std::uint32_t>(4.0f); ++b)
    check(std::bit_cast<float>(b));
  for (std::uint32_t b = 1; b < std::bit_cast<std::uint32_t>(std::numeric_limits<float>::infinity());
       b += 997)
    check(std::bit_cast<float>(b));
  check(std::numeric_limits<float>::max());
  check(std::numeric_limits<float>::denorm_min());
  report("fastInvSqrt(float)", mi, dm::kFastInvSqrtMaxRelErrorF);
  report("fastSqrt(float)", ms, dm::kFastSqrtMaxRelErrorF);
  EXPECT_LE(mi.error, dm::kFastInvSqrtMaxRelErrorF);
  EXPECT_LE(ms.error, dm::kFastSqrtMaxRelErrorF);
}

TEST(FastMath, SqrtEdgesFollowStdSqrt) {
  constexpr double inf = std::numeric_limits<double>::infinity();
  const double nan = std::numeric_limits<double>::quiet_NaN();
  EXPECT_EQ(dm::fastInvSqrt(0.0), inf);
  EXPECT_EQ(dm::fastInvSqrt(-0.0), -inf);
  EXPECT_EQ(dm::fastInvSqrt(inf), 0.0);
  EXPECT_TRUE(std::isnan(dm::fastInvSqrt(-1.0)));
  EXPECT_TRUE(std::isnan(dm::fastInvSqrt(-inf)));
  EXPECT_TRUE(std::isnan(dm::fastInvSqrt(nan)));
  EXPECT_EQ(dm::fastSqrt(0.0), 0.0);
  EXPECT_TRUE(std::signbit(dm::fastSqrt(-0.0)));
  EXPECT_EQ(dm::fastSqrt(inf), inf);
  EXPECT_TRUE(std::isnan(dm::fastSqrt(-4.0)));
  EXPECT_TRUE(std::isnan(dm::fastSqrt(nan)));
  EXPECT_EQ(dm::fastInvSqrt(0.0f), std::numeric_limits<float>::infinity());
  EXPECT_EQ(dm::fastSqrt(0.0f), 0.0f);
  EXPECT_EQ(dm::fastSqrt(std::numeric_limits<float>::infinity()), std::numeric_limits<float>::infinity());
  EXPECT_TRUE(std::isnan(dm::fastSqrt(-1.0f)));
  EXPECT_TRUE(std::isnan(dm::fastInvSqrt(std::numeric_limits<float>::quiet_NaN())));
}

TEST(FastMath, SinCosOverTheWholeDomain) {
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> jitter(0.0, 1.0);
  MaxError ms, mc;
  auto check = [&](double x) {
    const long double lx = x;
    ms.add(std::fabs(dm::fastSin(x) - std::sin(lx)), x);
    mc.add(std::fabs(dm::fastCos(x) - std::cos(lx)), x);
  };
  const double D = dm::kFastSinCosDomain, pi = std::numbers::pi;
  // The whole domain, evenly with jitter (spacing 0.4).
  const int n = 500'000;
  for (int i = 0; i < n; ++i) check(-D + 2 * D * (i + jitter(rng)) / n);
  // Densely over two periods (spacing 1.6e-5): every polynomial argument.
  for (int i = 0; i < 800'000; ++i) check(-2 * pi + 4 * pi * (i + jitter(rng)) / 800'000);
  // Around every kind of quadrant boundary (|r| = π/4, where the polynomial
  // error peaks and k switches) and multiples of π/2 (cancellation in the
  // reduction), across the domain.
  std::uniform_int_distribution<long> k(-static_cast<long>(D / (pi / 4)), static_cast<long>(D / (pi / 4)));
  for (int i = 0; i < 100'000; ++i) {
    const double x = static_cast<double>(k(rng)) * (pi / 4);
    if (std::abs(x) > D) continue;
    check(x);
    check(std::nextafter(x, -D));
    check(std::nextafter(x, D));
  }
  check(D), check(-D), check(0.0), check(-0.0), check(1e-300),
      check(std::numeric_limits<double>::denorm_min());
  report("fastSin", ms, dm::kFastSinMaxAbsError);
  report("fastCos", mc, dm::kFastCosMaxAbsError);
  EXPECT_LE(ms.error, dm::kFastSinMaxAbsError);
  EXPECT_LE(mc.error, dm::kFastCosMaxAbsError);
}

TEST(FastMath, SinCosEdges) {
  constexpr double inf = std::numeric_limits<double>::infinity();
  EXPECT_EQ(dm::fastSin(0.0), 0.0);
  EXPECT_EQ(dm::fastSin(-0.0), 0.0);  // documented: the sign of zero is not kept
  EXPECT_EQ(dm::fastCos(0.0), 1.0);
  EXPECT_EQ(dm::fastSin(1e-200), 1e-200);  // sin x = x to double precision for tiny x
  EXPECT_TRUE(std::isnan(dm::fastSin(inf)));
  EXPECT_TRUE(std::isnan(dm::fastSin(-inf)));
  EXPECT_TRUE(std::isnan(dm::fastCos(inf)));
  EXPECT_TRUE(std::isnan(dm::fastCos(std::nan(""))));
  EXPECT_TRUE(std::isnan(dm::fastSin(std::nan(""))));
  // Symmetries hold exactly (the reduction is odd in x).
  for (double x : {0.3, 1.0, 2.5, 10.0, 1234.5}) {
    EXPECT_EQ(dm::fastSin(-x), -dm::fastSin(x));
    EXPECT_EQ(dm::fastCos(-x), dm::fastCos(x));
  }
}

TEST(FastMath, ExpOverTheWholeDomain) {
  std::mt19937_64 rng(4);
  std::uniform_real_distribution<double> jitter(0.0, 1.0);
  MaxError m;
  auto check = [&](double x) { m.add(relError(dm::fastExp(x), std::exp(static_cast<long double>(x))), x); };
  const double lo = dm::kFastExpMin, hi = dm::kFastExpMax;
  const int n = 3'000'000;
  for (int i = 0; i < n; ++i) check(lo + (hi - lo) * (i + jitter(rng)) / n);
  // Densely across a few reduction intervals: every polynomial argument.
  for (int i = 0; i < 1'000'000; ++i) check(-1.5 + 3.0 * (i + jitter(rng)) / 1'000'000);
  // Around every boundary between reduction intervals, x = (j + ½)·ln 2.
  for (int j = -1021; j <= 1023; ++j) {
    const double x = (j + 0.5) * std::numbers::ln2;
    if (x < lo || x > hi) continue;
    check(x), check(std::nextafter(x, lo)), check(std::nextafter(x, hi));
  }
  check(lo), check(hi), check(0.0), check(1e-300), check(-1e-300);
  report("fastExp", m, dm::kFastExpMaxRelError);
  EXPECT_LE(m.error, dm::kFastExpMaxRelError);
}

TEST(FastMath, ExpEdgesOverflowUnderflowSubnormal) {
  constexpr double inf = std::numeric_limits<double>::infinity();
  const double tiny = std::numeric_limits<double>::denorm_min();
  EXPECT_EQ(dm::fastExp(0.0), 1.0);
  EXPECT_EQ(dm::fastExp(-0.0), 1.0);
  EXPECT_EQ(dm::fastExp(inf), inf);
  EXPECT_EQ(dm::fastExp(-inf), 0.0);
  EXPECT_TRUE(std::isnan(dm::fastExp(std::nan(""))));
  // Largest x with a finite eˣ, and just above it.
  const double xmax = 709.782712893383973096;  // ln(DBL_MAX), rounded down
  EXPECT_TRUE(std::isfinite(dm::fastExp(xmax)));
  EXPECT_LE(relError(dm::fastExp(xmax), std::exp(static_cast<long double>(xmax))), dm::kFastExpMaxRelError);
  EXPECT_EQ(dm::fastExp(709.79), inf);
  EXPECT_EQ(dm::fastExp(1e5), inf);
  EXPECT_EQ(dm::fastExp(-746.0), 0.0);
  EXPECT_EQ(dm::fastExp(-1e5), 0.0);
  // Subnormal results: within 2 units of the smallest subnormal.
  double worst = 0;
  for (int i = 0; i <= 100'000; ++i) {
    const double x = -745.1 + (745.1 - 708.4) * i / 100'000.0;
    const long double ref = std::exp(static_cast<long double>(x));
    worst = std::max(worst, static_cast<double>(std::fabs(dm::fastExp(x) - ref) / tiny));
  }
  std::printf("  fastExp subnormal range: max error %.2f × denorm_min\n", worst);
  EXPECT_LE(worst, 2.0);
}

}  // namespace
