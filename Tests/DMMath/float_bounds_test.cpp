// Tests of dm/math/float_bounds.hpp: floatDown/floatUp are the nearest
// floats below/above a double (equal when it is a float), saturate outside
// the float range on the safe side, and never exclude for NaN.
#include <dm/math/float_bounds.hpp>

#include <gtest/gtest.h>

#include <cfloat>
#include <cmath>
#include <limits>
#include <random>

namespace {

TEST(FloatBounds, NearestFloatsOnEachSide) {
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> mantissa(1.0, 2.0);
  std::uniform_int_distribution<int> exponent(-140, 120);
  for (int k = 0; k < 100000; ++k) {
    const double x = (k % 2 ? -1.0 : 1.0) * std::ldexp(mantissa(rng), exponent(rng));
    const float lo = dm::floatDown(x), hi = dm::floatUp(x);
    ASSERT_LE(double(lo), x) << x;
    ASSERT_GE(double(hi), x) << x;
    if (double(lo) == x) {
      ASSERT_EQ(lo, hi) << x;  // x is a float
    } else {
      // No float strictly between: they are neighbours.
      ASSERT_EQ(std::nextafter(lo, std::numeric_limits<float>::infinity()), hi) << x;
    }
  }
  EXPECT_EQ(dm::floatDown(0.1), 0.1f < 0.1 ? 0.1f : std::nextafter(0.1f, 0.0f));
  EXPECT_EQ(dm::floatDown(1.0), 1.0f);
  EXPECT_EQ(dm::floatUp(-2.5), -2.5f);
}

TEST(FloatBounds, SaturateOutsideTheRangeAndNeverExcludeForNaN) {
  constexpr float inf = std::numeric_limits<float>::infinity();
  EXPECT_EQ(dm::floatDown(1e300), FLT_MAX);  // a lower bound, not +∞
  EXPECT_EQ(dm::floatUp(1e300), inf);
  EXPECT_EQ(dm::floatDown(-1e300), -inf);
  EXPECT_EQ(dm::floatUp(-1e300), -FLT_MAX);
  EXPECT_EQ(dm::floatDown(std::numeric_limits<double>::infinity()), FLT_MAX);
  EXPECT_EQ(dm::floatUp(-std::numeric_limits<double>::infinity()), -FLT_MAX);
  EXPECT_EQ(dm::floatDown(std::nan("")), -inf);
  EXPECT_EQ(dm::floatUp(std::nan("")), inf);
}

}  // namespace
