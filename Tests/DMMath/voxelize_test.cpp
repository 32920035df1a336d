// voxelizeMesh() against analytic solids: boxes (exact counts and exact
// signed distances), convex polyhedra inscribed in a sphere, a torus, nested
// and disjoint pieces, and the Colin27 skin; plus brute-force distances to
// measure the propagated SDF.
#include <dm/core/volume.hpp>
#include <dm/math/convex_hull.hpp>
#include <dm/math/geometry.hpp>
#include <dm/math/isosurface.hpp>
#include <dm/math/mass_properties.hpp>
#include <dm/math/voxelize.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numbers>
#include <utility>
#include <vector>

#include "math_test_support.hpp"

namespace {

using dm::Vec3;

/// Closed convex mesh of a box centred at `centre` with half sizes `half`, rotated by `rot`.
dm::Mesh boxMesh(const Vec3& centre, const Vec3& half, const dm::Mat3& rot = dm::Mat3::Identity()) {
  std::vector<Vec3> corners;
  for (int c = 0; c < 8; ++c)
    corners.push_back(centre + rot * Vec3((c & 1) ? half.x() : -half.x(), (c & 2) ? half.y() : -half.y(),
                                          (c & 4) ? half.z() : -half.z()));
  return dm::convexHull(corners).value();
}

/// Signed distance to a box (negative inside), in the box's frame.
double boxSdf(const Vec3& local, const Vec3& half) {
  const Vec3 q = local.cwiseAbs() - half;
  return q.cwiseMax(0.0).norm() + std::min(q.maxCoeff(), 0.0);
}

/// Convex polyhedron with `n` vertices on the sphere of radius r (Fibonacci points).
dm::Mesh sphereHull(double r, int n) {
  std::vector<Vec3> pts;
  const double golden = std::numbers::pi * (3.0 - std::sqrt(5.0));
  for (int i = 0; i < n; ++i) {
    const double z = 1.0 - 2.0 * (i + 0.5) / n, rho = std::sqrt(1 - z * z);
    pts.push_back(r * Vec3(rho * std::cos(golden * i), rho * std::sin(golden * i), z));
  }
  return dm::convexHull(pts).value();
}

/// Zero set of an analytic field f (negative inside) sampled with spacing h over [-ext, ext]^3.
template <class F>
dm::Mesh isoMesh(F&& f, double ext, double h) {
  const int n = static_cast<int>(std::ceil(2 * ext / h)) + 1;
  dm::Affine3 a = dm::Affine3::Identity();
  a.linear() *= h;
  a.translation() = Vec3::Constant(-ext);
  auto v = dm::Volume::create({n, n, n}, dm::VoxelType::F32, a).value();
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) v.setValue(i, j, k, -f(a * Vec3(i, j, k)));  // inside is value > iso
  return dm::extractIsosurface(v, {.iso = 0.0, .computeNormals = false}).value();
}

double bruteDistance(const dm::Mesh& m, const Vec3& p) {
  double best = std::numeric_limits<double>::infinity();
  for (const auto& t : m.triangles)
    best = std::min(
        best,
        dm::closestPointOnTriangle(p, m.positions[t[0]], m.positions[t[1]], m.positions[t[2]]).distanceSq);
  return std::sqrt(best);
}

/// Calls f(world centre, value) for every voxel.
template <class F>
void forEachVoxel(const dm::Volume& v, F&& f) {
  const dm::Vec3i d = v.dims();
  for (int k = 0; k < d.z(); ++k)
    for (int j = 0; j < d.y(); ++j)
      for (int i = 0; i < d.x(); ++i) f(v.indexToWorld() * Vec3(i, j, k), v.value(i, j, k));
}

using dm::test::merged;

TEST(Voxelize, GridIsTheWorldLatticeAroundTheBoundsWithPadding) {
  const dm::Mesh box = boxMesh(Vec3(0.0123, -0.004, 0.031), Vec3(0.010, 0.007, 0.005));
  const double h = 0.001;
  auto v = dm::voxelizeMesh(box, {.voxelSize = h, .paddingVoxels = 3});
  ASSERT_TRUE(v) << v.error();
  EXPECT_EQ(v->type(), dm::VoxelType::U8);
  EXPECT_NEAR((v->spacing() - Vec3::Constant(h)).norm(), 0.0, 1e-15);
  const Vec3 origin = v->indexToWorld().translation();
  for (int a = 0; a < 3; ++a) {
    EXPECT_NEAR(origin[a] / h, std::round(origin[a] / h), 1e-9) << "centres on multiples of h";
    EXPECT_NEAR(origin[a], (std::floor(box.bounds().min()[a] / h) - 3) * h, 1e-12);
    const double last = origin[a] + h * (v->dims()[a] - 1);
    EXPECT_NEAR(last, (std::ceil(box.bounds().max()[a] / h) + 3) * h, 1e-12);
  }
}

TEST(Voxelize, BoxOccupancyIsExactlyTheCentresInside) {
  // Faces off the lattice: the count per axis is the number of multiples of h inside.
  const Vec3 c(0.0123, -0.0041, 0.0307), half(0.0104, 0.0067, 0.0052);
  const double h = 0.001;
  auto v = dm::voxelizeMesh(boxMesh(c, half), {.voxelSize = h});
  ASSERT_TRUE(v) << v.error();
  std::size_t count = 0, wrong = 0;
  forEachVoxel(*v, [&](const Vec3& p, double val) {
    const bool inside = boxSdf(p - c, half) < 0;
    count += val != 0;
    wrong += (val != 0) != inside;
    EXPECT_TRUE(val == 0 || val == 1);
  });
  EXPECT_EQ(wrong, 0u);
  double expected = 1;
  for (int a = 0; a < 3; ++a)
    expected *= std::floor((c[a] + half[a]) / h) - std::ceil((c[a] - half[a]) / h) + 1;
  EXPECT_EQ(static_cast<double>(count), expected);
}

TEST(Voxelize, FacesThroughVoxelCentresAreCountedOnce) {
  // A box whose faces, edges and vertices all lie on lattice points and
  // columns: the rays graze edges and pass through vertices.
  const double h = 0.001;
  const Vec3 c(0.005, 0.003, -0.002), half(0.004, 0.003, 0.002);
  auto v = dm::voxelizeMesh(boxMesh(c, half), {.voxelSize = h, .paddingVoxels = 1});
  ASSERT_TRUE(v) << v.error();
  // Every column must have a consistent (even) crossing count: a value of 0
  // or 1 everywhere, 0 on the padding, 1 strictly inside.
  forEachVoxel(*v, [&](const Vec3& p, double val) {
    const double d = boxSdf(p - c, half);
    if (d < -1e-9) {
      EXPECT_EQ(val, 1) << p.transpose();
    } else if (d > 1e-9) {
      EXPECT_EQ(val, 0) << p.transpose();
    }
  });
}

TEST(Voxelize, BoxSignedDistanceIsExactEverywhere) {
  const Vec3 c(0.0123, -0.0041, 0.0307), half(0.0104, 0.0067, 0.0052);
  auto v =
      dm::voxelizeMesh(boxMesh(c, half), {.voxelSize = 0.001, .paddingVoxels = 6, .signedDistance = true});
  ASSERT_TRUE(v) << v.error();
  ASSERT_EQ(v->type(), dm::VoxelType::F32);
  double maxErr = 0;
  forEachVoxel(
      *v, [&](const Vec3& p, double val) { maxErr = std::max(maxErr, std::abs(val - boxSdf(p - c, half))); });
  EXPECT_LT(maxErr, 1e-6);
}

TEST(Voxelize, RotatedBoxSignedDistanceAndBand) {
  const dm::Mat3 rot = dm::AngleAxis(0.7, Vec3(1, 2, 3).normalized()).toRotationMatrix();
  const Vec3 c(-0.02, 0.011, 0.004), half(0.012, 0.008, 0.005);
  const dm::Mesh box = boxMesh(c, half, rot);
  const auto sdf = [&](const Vec3& p) { return boxSdf(rot.transpose() * (p - c), half); };
  auto exact = dm::voxelizeMesh(box, {.voxelSize = 0.0008, .paddingVoxels = 8, .signedDistance = true});
  ASSERT_TRUE(exact) << exact.error();
  double maxErr = 0;
  forEachVoxel(*exact, [&](const Vec3& p, double val) { maxErr = std::max(maxErr, std::abs(val - sdf(p))); });
  EXPECT_LT(maxErr, 1e-6);

  const double band = 0.0025;
  auto banded = dm::voxelizeMesh(
      box, {.voxelSize = 0.0008, .paddingVoxels = 8, .signedDistance = true, .bandWidth = band});
  ASSERT_TRUE(banded) << banded.error();
  double bandErr = 0;
  forEachVoxel(*banded, [&](const Vec3& p, double val) {
    bandErr = std::max(bandErr, std::abs(val - std::clamp(sdf(p), -band, band)));
  });
  EXPECT_LT(bandErr, 1e-6);

  auto occ = dm::voxelizeMesh(box, {.voxelSize = 0.0008, .paddingVoxels = 8});
  ASSERT_TRUE(occ) << occ.error();
  std::size_t wrong = 0;
  forEachVoxel(*occ, [&](const Vec3& p, double val) {
    if (std::abs(sdf(p)) > 1e-9) wrong += (val != 0) != (sdf(p) < 0);
  });
  EXPECT_EQ(wrong, 0u);
}

TEST(Voxelize, SpherePolyhedronSignAndDistance) {
  const double r = 0.03, h = 0.0025;
  const dm::Mesh sphere = sphereHull(r, 400);
  // Exact inside test of the convex polyhedron: behind every face plane.
  // Tessellation error: the gap between the sphere and the closest face plane.
  double inradius = r;
  std::vector<std::pair<Vec3, double>> planes;
  for (std::size_t t = 0; t < sphere.triangleCount(); ++t) {
    const Vec3 n = sphere.faceNormal(t);
    const double off = n.dot(sphere.positions[sphere.triangles[t][0]]);
    planes.emplace_back(n, off);
    inradius = std::min(inradius, off);
  }
  const double tessellation = r - inradius;
  auto occ = dm::voxelizeMesh(sphere, {.voxelSize = h});
  auto sdf = dm::voxelizeMesh(sphere, {.voxelSize = h, .paddingVoxels = 4, .signedDistance = true});
  ASSERT_TRUE(occ) << occ.error();
  ASSERT_TRUE(sdf) << sdf.error();
  std::size_t count = 0, wrongSign = 0;
  forEachVoxel(*occ, [&](const Vec3& p, double val) {
    double s = -1e9;
    for (const auto& [n, off] : planes) s = std::max(s, n.dot(p) - off);
    count += val != 0;
    if (std::abs(s) > 1e-12) wrongSign += (val != 0) != (s < 0);
  });
  EXPECT_EQ(wrongSign, 0u);
  // Occupied volume vs the polyhedron's: within the shell of half a voxel diagonal.
  const double volume = dm::computeMassProperties(sphere).value().volume;
  const double occupied = static_cast<double>(count) * h * h * h;
  EXPECT_LT(std::abs(occupied - volume), sphere.surfaceArea() * h * std::sqrt(3.0) / 2);

  double maxAnalytic = 0, maxBrute = 0;
  std::size_t visited = 0;
  forEachVoxel(*sdf, [&](const Vec3& p, double val) {
    maxAnalytic = std::max(maxAnalytic, std::abs(val - (p.norm() - r)));
    if (visited++ % 2 != 0) return;  // brute force on half of the voxels keeps the test fast
    const double brute = bruteDistance(sphere, p);
    maxBrute = std::max(maxBrute, std::abs(std::abs(val) - brute));
  });
  EXPECT_LT(maxAnalytic, tessellation + 1e-6);
  EXPECT_LT(maxBrute, 1e-6) << "convex: the closest-triangle transform is exact";
}

TEST(Voxelize, TorusVolumeSignAndPropagatedDistance) {
  const double R = 0.03, r = 0.012;
  const auto torusSdf = [&](const Vec3& p) { return std::hypot(std::hypot(p.x(), p.y()) - R, p.z()) - r; };
  const double hIso = 0.002;
  const dm::Mesh torus = isoMesh(torusSdf, R + r + 2 * hIso, hIso);
  const double volume = dm::computeMassProperties(torus).value().volume;
  EXPECT_NEAR(volume, 2 * std::numbers::pi * std::numbers::pi * R * r * r, 0.02 * volume);

  const double h = 0.003;
  auto occ = dm::voxelizeMesh(torus, {.voxelSize = h});
  ASSERT_TRUE(occ) << occ.error();
  std::size_t count = 0, wrongSign = 0;
  forEachVoxel(*occ, [&](const Vec3& p, double val) {
    count += val != 0;
    if (std::abs(torusSdf(p)) > hIso / 2) wrongSign += (val != 0) != (torusSdf(p) < 0);
  });
  EXPECT_EQ(wrongSign, 0u);
  EXPECT_LT(std::abs(static_cast<double>(count) * h * h * h - volume),
            torus.surfaceArea() * h * std::sqrt(3.0) / 2);

  auto sdf = dm::voxelizeMesh(torus, {.voxelSize = h, .paddingVoxels = 3, .signedDistance = true});
  ASSERT_TRUE(sdf) << sdf.error();
  double maxErr = 0, sumErr = 0;
  std::size_t n = 0, inexact = 0;
  std::size_t visited = 0;
  forEachVoxel(*sdf, [&](const Vec3& p, double val) {
    if (std::abs(torusSdf(p)) > hIso / 2) {
      EXPECT_EQ(val < 0, torusSdf(p) < 0) << p.transpose();
    }
    if (visited++ % 8 != 0) return;  // brute force on an eighth of the voxels keeps the test fast
    const double err = std::abs(val) - bruteDistance(torus, p);
    EXPECT_GT(err, -1e-6) << "never below the true distance";
    maxErr = std::max(maxErr, err);
    sumErr += err;
    inexact += err > 1e-6;
    ++n;
  });
  // The torus has a medial circle and axis where the nearest triangle jumps;
  // the transform stays within a small fraction of a voxel there.
  RecordProperty("max_error_over_h", std::to_string(maxErr / h));
  RecordProperty("inexact_fraction", std::to_string(static_cast<double>(inexact) / n));
  EXPECT_LT(maxErr, 0.05 * h);
  EXPECT_LT(static_cast<double>(inexact) / n, 0.02);
}

TEST(Voxelize, DisjointPiecesAndCavities) {
  const Vec3 ca(-0.02, 0, 0), cb(0.025, 0.003, -0.001), ha(0.01, 0.008, 0.006), hb(0.006, 0.006, 0.009);
  const dm::Mesh two = merged(boxMesh(ca, ha), boxMesh(cb, hb));
  auto sdf = dm::voxelizeMesh(two, {.voxelSize = 0.001, .signedDistance = true});
  ASSERT_TRUE(sdf) << sdf.error();
  double maxErr = 0;
  forEachVoxel(*sdf, [&](const Vec3& p, double val) {
    maxErr = std::max(maxErr, std::abs(val - std::min(boxSdf(p - ca, ha), boxSdf(p - cb, hb))));
  });
  EXPECT_LT(maxErr, 1e-6);

  // An inward-facing box inside an outward one bounds a hollow shell.
  dm::Mesh inner = boxMesh(ca, ha * 0.5);
  for (auto& t : inner.triangles) std::swap(t[1], t[2]);
  auto shell = dm::voxelizeMesh(merged(boxMesh(ca, ha), inner), {.voxelSize = 0.001});
  ASSERT_TRUE(shell) << shell.error();
  std::size_t wrong = 0;
  forEachVoxel(*shell, [&](const Vec3& p, double val) {
    const double outer = boxSdf(p - ca, ha), hole = boxSdf(p - ca, ha * 0.5);
    if (std::abs(outer) > 1e-9 && std::abs(hole) > 1e-9) wrong += (val != 0) != (outer < 0 && hole > 0);
  });
  EXPECT_EQ(wrong, 0u);
}

TEST(Voxelize, InsideOutMeshStillFillsItsInterior) {
  dm::Mesh box = boxMesh(Vec3::Zero(), Vec3(0.0045, 0.0035, 0.0025));
  for (auto& t : box.triangles) std::swap(t[1], t[2]);
  auto v = dm::voxelizeMesh(box, {.voxelSize = 0.001});
  ASSERT_TRUE(v) << v.error();
  std::size_t count = 0;
  forEachVoxel(*v, [&](const Vec3&, double val) { count += val != 0; });
  EXPECT_EQ(count, 9u * 7u * 5u);  // |x| <= 4 mm, |y| <= 3 mm, |z| <= 2 mm (off the faces)
}

TEST(Voxelize, RejectsBadInput) {
  const dm::Mesh box = boxMesh(Vec3::Zero(), Vec3(0.01, 0.01, 0.01));
  EXPECT_FALSE(dm::voxelizeMesh(box, {.voxelSize = 0}));
  EXPECT_FALSE(dm::voxelizeMesh(box, {.voxelSize = -1e-3}));
  EXPECT_FALSE(dm::voxelizeMesh(box, {.voxelSize = std::numeric_limits<double>::quiet_NaN()}));
  EXPECT_FALSE(dm::voxelizeMesh(box, {.voxelSize = 1e-3, .paddingVoxels = -1}));
  EXPECT_FALSE(dm::voxelizeMesh(box, {.voxelSize = 1e-3, .signedDistance = true, .bandWidth = -1}));
  EXPECT_FALSE(dm::voxelizeMesh(dm::Mesh{}, {.voxelSize = 1e-3}));

  dm::Mesh nan = box;
  nan.positions[3].y() = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(dm::voxelizeMesh(nan, {.voxelSize = 1e-3}));

  dm::Mesh open = box;
  open.triangles.pop_back();
  auto r = dm::voxelizeMesh(open, {.voxelSize = 1e-3});
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().what.find("3 boundary edge"), std::string::npos) << r.error();
  EXPECT_FALSE(dm::voxelizeMesh(open, {.voxelSize = 1e-3, .signedDistance = true}));
}

TEST(Voxelize, HonoursMaxBytes) {
  const dm::Mesh box = boxMesh(Vec3::Zero(), Vec3(0.0095, 0.0095, 0.0095));
  // Bounds +-9.5 mm widened to the lattice (+-10 mm) plus 2 x 2 padding: 25^3 voxels.
  const std::size_t voxels = 25 * 25 * 25;
  auto fits = dm::voxelizeMesh(box, {.voxelSize = 1e-3, .maxBytes = voxels});
  ASSERT_TRUE(fits) << fits.error();
  EXPECT_EQ(fits->voxelCount(), voxels);
  auto over = dm::voxelizeMesh(box, {.voxelSize = 1e-3, .maxBytes = voxels - 1});
  ASSERT_FALSE(over);
  EXPECT_NE(over.error().message().find("maxBytes"), std::string::npos) << over.error();
  EXPECT_FALSE(
      dm::voxelizeMesh(box, {.voxelSize = 1e-3, .signedDistance = true, .maxBytes = 4 * voxels - 1}));
  // A grid far beyond memory fails before allocating.
  EXPECT_FALSE(dm::voxelizeMesh(box, {.voxelSize = 1e-9}));
}

TEST(Voxelize, ReportsMonotoneProgressFromTheCallingThread) {
  std::vector<double> seen;
  const dm::Mesh sphere = sphereHull(0.02, 200);
  auto v = dm::voxelizeMesh(
      sphere, {.voxelSize = 5e-4, .signedDistance = true, .progress = [&](double f) { seen.push_back(f); }});
  ASSERT_TRUE(v) << v.error();
  ASSERT_FALSE(seen.empty());
  EXPECT_LE(seen.size(), 101u);
  EXPECT_EQ(seen.back(), 1.0);
  EXPECT_TRUE(std::is_sorted(seen.begin(), seen.end()));
  EXPECT_GE(seen.front(), 0.0);
}

}  // namespace
