// Helpers shared by the DMMath tests.
#pragma once

#include <dm/core/mesh.hpp>
#include <dm/math/integrators.hpp>

#include <gtest/gtest.h>

#include <cstdint>
#include <initializer_list>
#include <memory>
#include <numbers>
#include <string_view>
#include <utility>

namespace dm::test {

inline constexpr double kPi = std::numbers::pi;

/// The integrator registered as `name`, or null (with a test failure).
inline std::unique_ptr<dm::Integrator> make(std::string_view name) {
  auto r = dm::makeIntegrator(name);
  EXPECT_TRUE(r) << (r ? "" : r.error().message());
  return r ? std::move(r).value() : nullptr;
}

/// A dynamic vector of `values`. Eigen's comma initializer,
/// `(VecX(n) << a, b).finished()`, makes GCC 12 report -Wmaybe-uninitialized
/// inside Eigen at -O1 (the tests' optimisation level, dm_add_test).
inline dm::VecX vecOf(std::initializer_list<double> values) {
  dm::VecX v(static_cast<Eigen::Index>(values.size()));
  Eigen::Index i = 0;
  for (const double x : values) v[i++] = x;
  return v;
}

/// The union of two meshes: `b`'s vertices appended to `a`'s, its triangles renumbered.
inline dm::Mesh merged(const dm::Mesh& a, const dm::Mesh& b) {
  dm::Mesh m = a;
  const auto offset = static_cast<std::uint32_t>(a.positions.size());
  m.positions.insert(m.positions.end(), b.positions.begin(), b.positions.end());
  for (auto t : b.triangles) m.triangles.push_back({t[0] + offset, t[1] + offset, t[2] + offset});
  return m;
}

}  // namespace dm::test
