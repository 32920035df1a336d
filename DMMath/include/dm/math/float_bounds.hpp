// dm/math/float_bounds.hpp — doubles rounded to floats in a chosen
// direction, for conservative float copies of double bounds (bounding-box
// trees, SIMD pretests): a comparison of bounds rounded outward passes
// whenever the exact comparison of the doubles does.
//
// Out of the float range the result saturates (FLT_MAX, ±∞) on the safe
// side; NaN gives the bound that never excludes (−∞ down, +∞ up).
#pragma once

#include <cfloat>
#include <cmath>
#include <limits>

namespace dm {

/// Largest float ≤ x (−∞ below the float range; NaN: −∞).
/// @code
///   const float lo = dm::floatDown(box.min().x()), hi = dm::floatUp(box.max().x());
/// @endcode
inline float floatDown(double x) noexcept {
  if (!(x <= double(FLT_MAX))) return x > 0 ? FLT_MAX : -std::numeric_limits<float>::infinity();
  if (x < -double(FLT_MAX)) return -std::numeric_limits<float>::infinity();
  const float f = static_cast<float>(x);
  return double(f) > x ? std::nextafter(f, -std::numeric_limits<float>::infinity()) : f;
}

/// Smallest float ≥ x (+∞ above the float range; NaN: +∞).
inline float floatUp(double x) noexcept {
  if (!(x >= -double(FLT_MAX))) return x < 0 ? -FLT_MAX : std::numeric_limits<float>::infinity();
  if (x > double(FLT_MAX)) return std::numeric_limits<float>::infinity();
  const float f = static_cast<float>(x);
  return double(f) < x ? std::nextafter(f, std::numeric_limits<float>::infinity()) : f;
}

}  // namespace dm
