// Private helpers shared by several DMMath sources (integrators, linear
// solvers, SUNDIALS wrapper, registration, convex hull, simplification). Not
// installed.
#pragma once

#include <dm/core/result.hpp>
#include <dm/math/types.hpp>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <string>
#include <utility>

namespace dm::detail {

/// "No index": an unset vertex, edge or face link.
inline constexpr std::uint32_t kNone = std::numeric_limits<std::uint32_t>::max();

/// A number in messages: 9 significant digits (%.9g).
inline std::string fmt(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.9g", v);
  return buf;
}

/// Index of the first NaN/Inf component of v, or -1.
inline Eigen::Index firstNonFinite(const VecX& v) {
  for (Eigen::Index i = 0; i < v.size(); ++i)
    if (!std::isfinite(v[i])) return i;
  return -1;
}

/// An ErrorCode::InvalidArgument error.
inline Error invalid(std::string what, const char* where, std::string hint = {}) {
  return fail(ErrorCode::InvalidArgument, std::move(what), where, std::move(hint));
}

}  // namespace dm::detail
