// The marching-cubes skin of a voxelised ball: a sphere carrying the voxel
// staircase, as a skin extracted from a scan does. Shared by the smoothing
// (DMMath) and haptic (DMHaptics) tests.
#pragma once

#include <dm/math/isosurface.hpp>

#include <gtest/gtest.h>

#include <utility>

namespace dm::test {

/// Ball of radius R (m) sampled on voxels of h (1 inside, 0 outside),
/// extracted at iso 0.5 and centred at the origin.
inline Mesh staircaseBall(double R, double h) {
  const int n = static_cast<int>(2 * R / h) + 6;
  Affine3 a = Affine3::Identity();
  a.linear() = h * Mat3::Identity();
  a.translation() = Vec3::Constant(-h * (n - 1) / 2.0);
  auto v = Volume::create({n, n, n}, VoxelType::U8, a);
  EXPECT_TRUE(v);
  if (!v) return {};
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) v->setValue(i, j, k, (a * Vec3(i, j, k)).norm() < R ? 1 : 0);
  auto m = extractIsosurface(*v, {.iso = 0.5});
  EXPECT_TRUE(m);
  return m ? std::move(*m) : Mesh{};
}

}  // namespace dm::test
