// Shared by millable_feed_test.cpp and millable_feed_concurrency_test.cpp:
// a bone with a curved top, and the check that the render side's copy and
// surface are the bone's own.
#pragma once

#include <dm/haptics/millable_feed.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

namespace dm {
namespace millable_feed_test {

constexpr double kH = 0.25e-3;  // m, voxel

// Bone below the curved surface z = 0.3 mm·cos(x / 2 mm) on an n³ grid centred on the origin.
inline MillableVolume bone(int n) {
  Affine3 a = Affine3::Identity();
  a.linear() = Mat3::Identity() * kH;
  a.translation() = Vec3::Constant(-0.5 * (n - 1) * kH);
  auto sdf = Volume::create(Vec3i(n, n, n), VoxelType::F32, a);
  EXPECT_TRUE(sdf.ok());
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        const Vec3 p = a * Vec3(i, j, k);
        sdf->setValue(i, j, k, p.z() - 0.3e-3 * std::cos(p.x() / 2e-3));
      }
  auto v = MillableVolume::fromSdf(*sdf);
  EXPECT_TRUE(v.ok());
  return std::move(*v);
}

inline Isometry3 at(const Vec3& t) {
  Isometry3 p = Isometry3::Identity();
  p.translation() = t;
  return p;
}

// The mirror holds exactly the bone's voxels, and the surface is every block's piece of the bone.
inline void expectSame(const MillableVolume& b, const MillableSurfaceFeed& feed, const Mesh& surface) {
  const Vec3i d = b.dims();
  std::size_t differ = 0;
  for (int k = 0; k < d.z(); ++k)
    for (int j = 0; j < d.y(); ++j)
      for (int i = 0; i < d.x(); ++i) differ += b.occupancy(i, j, k) != feed.mirror().occupancy(i, j, k);
  EXPECT_EQ(differ, 0u);
  std::vector<std::uint32_t> all(static_cast<std::size_t>(b.blockDims().prod()));
  for (std::size_t n = 0; n < all.size(); ++n) all[n] = static_cast<std::uint32_t>(n);
  auto pieces = b.blockSurfaces(all);
  ASSERT_TRUE(pieces.ok());
  std::size_t triangles = 0;
  double area = 0;
  for (const Mesh& m : *pieces) {
    triangles += m.triangles.size();
    area += m.surfaceArea();
  }
  EXPECT_EQ(surface.triangles.size(), triangles);
  EXPECT_NEAR(surface.surfaceArea(), area, 1e-9 * area);
  EXPECT_TRUE(surface.validate().ok());
}

}  // namespace millable_feed_test
}  // namespace dm
