#include <dm/math/mass_properties.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <numbers>
#include <utility>
#include <vector>

#include "math_test_support.hpp"

namespace {

using dm::Mat3;
using dm::Vec3;

using dm::test::kPi;

/// Box [lo, lo + size] (per-axis sizes), 8 vertices, 12 triangles CCW from outside.
dm::Mesh box(const Vec3& lo, const Vec3& size) {
  dm::Mesh m;
  for (int c = 0; c < 8; ++c)
    m.positions.push_back(lo +
                          Vec3(size.x() * (c & 1), size.y() * ((c >> 1) & 1), size.z() * ((c >> 2) & 1)));
  const int quads[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4},
                           {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  for (const auto& q : quads) {
    const auto u = [&](int i) { return static_cast<std::uint32_t>(q[i]); };
    m.triangles.push_back({u(0), u(1), u(2)});
    m.triangles.push_back({u(0), u(2), u(3)});
  }
  return m;
}

/// Icosahedron subdivided `levels` times, vertices on the sphere of radius r.
dm::Mesh icosphere(double r, int levels) {
  const double t = (1 + std::sqrt(5.0)) / 2;
  dm::Mesh m;
  for (const Vec3& v :
       {Vec3(-1, t, 0), Vec3(1, t, 0), Vec3(-1, -t, 0), Vec3(1, -t, 0), Vec3(0, -1, t), Vec3(0, 1, t),
        Vec3(0, -1, -t), Vec3(0, 1, -t), Vec3(t, 0, -1), Vec3(t, 0, 1), Vec3(-t, 0, -1), Vec3(-t, 0, 1)})
    m.positions.push_back(r * v.normalized());
  m.triangles = {{0, 11, 5},  {0, 5, 1},  {0, 1, 7},  {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
                 {11, 10, 2}, {10, 7, 6}, {7, 1, 8},  {3, 9, 4},  {3, 4, 2},   {3, 2, 6}, {3, 6, 8},
                 {3, 8, 9},   {4, 9, 5},  {2, 4, 11}, {6, 2, 10}, {8, 6, 7},   {9, 8, 1}};
  for (int l = 0; l < levels; ++l) {
    std::map<std::pair<std::uint32_t, std::uint32_t>, std::uint32_t> mid;
    const auto midpoint = [&](std::uint32_t a, std::uint32_t b) {
      const auto key = std::minmax(a, b);
      auto it = mid.find(key);
      if (it != mid.end()) return it->second;
      const auto idx = static_cast<std::uint32_t>(m.positions.size());
      m.positions.push_back(r * (m.positions[a] + m.positions[b]).normalized());
      mid.emplace(key, idx);
      return idx;
    };
    std::vector<dm::Triangle> next;
    for (const auto& tri : m.triangles) {
      const std::uint32_t a = midpoint(tri[0], tri[1]), b = midpoint(tri[1], tri[2]),
                          c = midpoint(tri[2], tri[0]);
      next.push_back({tri[0], a, c});
      next.push_back({tri[1], b, a});
      next.push_back({tri[2], c, b});
      next.push_back({a, b, c});
    }
    m.triangles = std::move(next);
  }
  return m;
}

/// Torus around z of radii R (axis to tube centre) and r (tube), n × m quads.
dm::Mesh torus(double R, double r, int n, int m) {
  dm::Mesh mesh;
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < m; ++j) {
      const double u = 2 * kPi * i / n, v = 2 * kPi * j / m;
      mesh.positions.emplace_back((R + r * std::cos(v)) * std::cos(u), (R + r * std::cos(v)) * std::sin(u),
                                  r * std::sin(v));
    }
  const auto id = [&](int i, int j) { return static_cast<std::uint32_t>((i % n) * m + (j % m)); };
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < m; ++j) {
      mesh.triangles.push_back({id(i, j), id(i + 1, j), id(i + 1, j + 1)});
      mesh.triangles.push_back({id(i, j), id(i + 1, j + 1), id(i, j + 1)});
    }
  return mesh;
}

void flip(dm::Mesh& m) {
  for (auto& t : m.triangles) std::swap(t[1], t[2]);
}

using dm::test::merged;

/// Relative Frobenius distance of two matrices.
double relDiff(const Mat3& a, const Mat3& b) { return (a - b).norm() / b.norm(); }

Mat3 boxInertia(double mass, const Vec3& s) {
  return Vec3(mass / 12 * (s.y() * s.y() + s.z() * s.z()), mass / 12 * (s.x() * s.x() + s.z() * s.z()),
              mass / 12 * (s.x() * s.x() + s.y() * s.y()))
      .asDiagonal();
}

void expectRotation(const Mat3& r) {
  EXPECT_LT((r.transpose() * r - Mat3::Identity()).norm(), 1e-12);
  EXPECT_NEAR(r.determinant(), 1.0, 1e-12);
}

TEST(MassProperties, AxisAlignedBoxIsExact) {
  const Vec3 lo(0.3, -1.2, 2.0), s(0.2, 0.5, 1.1);
  const double rho = 7850;  // steel
  auto mp = dm::computeMassProperties(box(lo, s), rho);
  ASSERT_TRUE(mp) << mp.error();
  const double v = s.prod();
  EXPECT_NEAR(mp->volume, v, 1e-15);
  EXPECT_NEAR(mp->mass, rho * v, 1e-11);
  EXPECT_LT((mp->centroid - (lo + s / 2)).norm(), 1e-14);
  EXPECT_LT(relDiff(mp->inertia, boxInertia(rho * v, s)), 1e-13) << mp->inertia;
  // Principal moments ascending: the smallest is about the longest axis (z).
  EXPECT_NEAR(mp->principalMoments[0], rho * v / 12 * (s.x() * s.x() + s.y() * s.y()), 1e-12);
  EXPECT_NEAR(mp->principalMoments[2], rho * v / 12 * (s.y() * s.y() + s.z() * s.z()), 1e-12);
  EXPECT_NEAR(std::abs(mp->principalAxes(2, 0)), 1.0, 1e-12);
  EXPECT_NEAR(std::abs(mp->principalAxes(0, 2)), 1.0, 1e-12);
  expectRotation(mp->principalAxes);
}

TEST(MassProperties, RotatedTranslatedBoxMatchesRotatedTensor) {
  const Vec3 s(0.04, 0.1, 0.25);
  const double rho = 1100;
  const dm::Mat3 rot = dm::Quat(dm::AngleAxis(0.7, Vec3(1, 2, -0.5).normalized())).toRotationMatrix();
  const Vec3 shift(-3.0, 0.25, 12.5);
  dm::Mesh m = box(-s / 2, s);
  dm::Affine3 tf = dm::Affine3::Identity();
  tf.linear() = rot;
  tf.translation() = shift;
  m.transform(tf);
  auto mp = dm::computeMassProperties(m, rho);
  ASSERT_TRUE(mp) << mp.error();
  const double mass = rho * s.prod();
  EXPECT_NEAR(mp->mass, mass, 1e-12 * mass);
  EXPECT_LT((mp->centroid - shift).norm(), 1e-13);
  const Mat3 expected = rot * boxInertia(mass, s) * rot.transpose();
  EXPECT_LT(relDiff(mp->inertia, expected), 1e-12);
  // Principal frame: diagonalises the tensor, is a rotation, and its axes are
  // the box's axes (distinct moments): longest edge (z) first.
  expectRotation(mp->principalAxes);
  const Mat3 d = mp->principalAxes.transpose() * mp->inertia * mp->principalAxes;
  EXPECT_LT((d - Mat3(mp->principalMoments.asDiagonal())).norm(), 1e-12 * d.norm());
  EXPECT_NEAR(std::abs(mp->principalAxes.col(0).dot(rot.col(2))), 1.0, 1e-12);
  EXPECT_NEAR(std::abs(mp->principalAxes.col(1).dot(rot.col(1))), 1.0, 1e-12);
  EXPECT_NEAR(std::abs(mp->principalAxes.col(2).dot(rot.col(0))), 1.0, 1e-12);
}

TEST(MassProperties, ParallelAxisTheoremAboutACorner) {
  const Vec3 s(1.0, 2.0, 3.0);
  auto mp = dm::computeMassProperties(box(Vec3::Zero(), s), 2.0);
  ASSERT_TRUE(mp) << mp.error();
  const double m = 2.0 * s.prod();
  // Solid box about its corner: I_xx = m (b² + c²)/3, I_xy = −m a b / 4.
  Mat3 expected;
  expected << m * (s.y() * s.y() + s.z() * s.z()) / 3, -m * s.x() * s.y() / 4, -m * s.x() * s.z() / 4,  //
      -m * s.x() * s.y() / 4, m * (s.x() * s.x() + s.z() * s.z()) / 3, -m * s.y() * s.z() / 4,          //
      -m * s.x() * s.z() / 4, -m * s.y() * s.z() / 4, m * (s.x() * s.x() + s.y() * s.y()) / 3;
  EXPECT_LT(relDiff(dm::inertiaAboutPoint(*mp, Vec3::Zero()), expected), 1e-14);
  EXPECT_LT(relDiff(dm::inertiaAboutPoint(*mp, mp->centroid), mp->inertia), 1e-15);
}

TEST(MassProperties, DensityScalesMassAndInertiaOnly) {
  const dm::Mesh m = torus(0.3, 0.1, 24, 12);
  auto a = dm::computeMassProperties(m, 1.0);
  auto b = dm::computeMassProperties(m, 250.0);
  ASSERT_TRUE(a && b);
  EXPECT_DOUBLE_EQ(b->volume, a->volume);
  EXPECT_NEAR(b->mass, 250.0 * a->mass, 1e-12 * b->mass);
  EXPECT_LT(relDiff(b->inertia, 250.0 * a->inertia), 1e-14);
  EXPECT_LT((b->centroid - a->centroid).norm(), 1e-15);
}

// An inscribed icosphere converges to the ball at second order in the edge
// length (which halves per level): errors fall by ~4 per level.
TEST(MassProperties, IcosphereConvergesToBallAtSecondOrder) {
  const double R = 0.05, rho = 1000;
  const double v = 4.0 / 3 * kPi * R * R * R;
  const double iBall = 0.4 * rho * v * R * R;  // 2/5 m R²
  std::printf("level triangles  volume error  inertia error  (relative to the ball)\n");
  double prevV = 0, prevI = 0;
  for (int level = 0; level <= 5; ++level) {
    const dm::Mesh m = icosphere(R, level);
    auto mp = dm::computeMassProperties(m, rho);
    ASSERT_TRUE(mp) << mp.error();
    const double errV = std::abs(mp->volume - v) / v;
    const double errI = (mp->inertia - iBall * Mat3::Identity()).norm() / (std::sqrt(3.0) * iBall);
    std::printf("%5d %9zu  %12.3e  %13.3e\n", level, m.triangles.size(), errV, errI);
    EXPECT_LT(mp->centroid.norm(), 1e-15);
    if (level >= 2) {
      EXPECT_GT(prevV / errV, 3.5) << "level " << level;
      EXPECT_LT(prevV / errV, 4.5) << "level " << level;
      EXPECT_GT(prevI / errI, 3.5) << "level " << level;
      EXPECT_LT(prevI / errI, 4.5) << "level " << level;
    }
    prevV = errV;
    prevI = errI;
  }
  EXPECT_LT(prevV, 5e-3);
  EXPECT_LT(prevI, 5e-3);
}

TEST(MassProperties, TorusConvergesToAnalytic) {
  const double R = 0.3, r = 0.08;
  const double v = 2 * kPi * kPi * R * r * r;
  double prevErr = 1;
  for (const int n : {32, 64, 128}) {
    auto mp = dm::computeMassProperties(torus(R, r, 2 * n, n), 1.0);
    ASSERT_TRUE(mp) << mp.error();
    const double m = mp->mass;
    const double iz = m * (R * R + 0.75 * r * r), ix = m * (R * R / 2 + 5.0 / 8 * r * r);
    const double errV = std::abs(mp->volume - v) / v;
    const double errI =
        std::max({std::abs(mp->inertia(0, 0) - ix) / ix, std::abs(mp->inertia(1, 1) - ix) / ix,
                  std::abs(mp->inertia(2, 2) - iz) / iz});
    std::printf("torus %4d x %3d: volume error %.3e, inertia error %.3e\n", 2 * n, n, errV, errI);
    EXPECT_LT(errI, errV) << n;  // inertia per mass converges faster than the volume
    EXPECT_LT(errV, prevErr) << n;
    prevErr = errV;
    EXPECT_LT(mp->centroid.norm(), 1e-15);
    EXPECT_LT(std::abs(mp->inertia(0, 1)) + std::abs(mp->inertia(0, 2)) + std::abs(mp->inertia(1, 2)),
              1e-14 * iz);
  }
  EXPECT_LT(prevErr, 1e-3);
}

// A 3 cm sphere 1.8 km from the origin: the same result as at the origin up
// to the rounding of its coordinates (~1e-13 m). Integrating about the origin
// would lose (1800 / 0.03)² ≈ 4e9 in relative precision of the inertia.
TEST(MassProperties, FarFromOriginKeepsPrecision) {
  const dm::Mesh near = icosphere(0.03, 3);
  dm::Mesh far = near;
  const Vec3 shift(1000.0, -700.0, 1300.0);
  for (Vec3& p : far.positions) p += shift;
  far.positions.push_back(Vec3(1e7, 1e7, 1e7));  // unused: must not matter
  auto a = dm::computeMassProperties(near, 1000);
  auto b = dm::computeMassProperties(far, 1000);
  ASSERT_TRUE(a && b);
  EXPECT_NEAR(b->volume, a->volume, 1e-9 * a->volume);
  EXPECT_LT((b->centroid - shift - a->centroid).norm(), 1e-11);
  EXPECT_LT(relDiff(b->inertia, a->inertia), 1e-9);
}

TEST(MassProperties, InwardShellMakesACavity) {
  dm::Mesh inner = box(Vec3(0.25, 0.25, 0.25), Vec3(0.5, 0.5, 0.5));
  flip(inner);
  auto mp = dm::computeMassProperties(merged(box(Vec3::Zero(), Vec3(1, 1, 1)), inner), 1.0);
  ASSERT_TRUE(mp) << mp.error();
  EXPECT_NEAR(mp->volume, 1.0 - 0.125, 1e-15);
  EXPECT_LT((mp->centroid - Vec3(0.5, 0.5, 0.5)).norm(), 1e-15);
  const double i = 1.0 / 6 - 0.125 * 0.25 / 6;  // m s² / 6 of outer minus inner
  EXPECT_LT(relDiff(mp->inertia, i * Mat3::Identity()), 1e-14);
}

TEST(MassProperties, InsideOutMeshIsAnError) {
  dm::Mesh m = icosphere(1.0, 1);
  flip(m);
  auto mp = dm::computeMassProperties(m);
  ASSERT_FALSE(mp);
  EXPECT_EQ(mp.error().code, dm::ErrorCode::InvalidArgument);
  EXPECT_NE(mp.error().what.find("inward-facing"), std::string::npos) << mp.error();
  EXPECT_NE(mp.error().what.find("signed volume is -"), std::string::npos) << mp.error();
  EXPECT_NE(mp.error().hint.find("flip"), std::string::npos) << mp.error();
}

TEST(MassProperties, OpenMeshIsAnError) {
  dm::Mesh m = box(Vec3::Zero(), Vec3(1, 1, 1));
  m.triangles.pop_back();
  auto mp = dm::computeMassProperties(m);
  ASSERT_FALSE(mp);
  EXPECT_NE(mp.error().what.find("open"), std::string::npos) << mp.error();
  EXPECT_NE(mp.error().what.find("edge ("), std::string::npos) << mp.error();
}

TEST(MassProperties, OneFlippedTriangleIsAnError) {
  dm::Mesh m = icosphere(1.0, 1);
  std::swap(m.triangles[7][0], m.triangles[7][1]);
  auto mp = dm::computeMassProperties(m);
  ASSERT_FALSE(mp);
  EXPECT_NE(mp.error().what.find("inconsistently oriented"), std::string::npos) << mp.error();
}

TEST(MassProperties, FlatClosedMeshIsAnError) {
  dm::Mesh m;  // a double-sided square: closed but encloses nothing
  m.positions = {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(1, 1, 0), Vec3(0, 1, 0)};
  m.triangles = {{0, 1, 2}, {0, 2, 3}, {0, 2, 1}, {0, 3, 2}};
  auto mp = dm::computeMassProperties(m);
  ASSERT_FALSE(mp);
  EXPECT_NE(mp.error().what.find("no volume"), std::string::npos) << mp.error();
}

TEST(MassProperties, BadInputIsAnError) {
  EXPECT_FALSE(dm::computeMassProperties(dm::Mesh{}));
  const dm::Mesh b = box(Vec3::Zero(), Vec3(1, 1, 1));
  EXPECT_FALSE(dm::computeMassProperties(b, 0.0));
  EXPECT_FALSE(dm::computeMassProperties(b, -5.0));
  EXPECT_FALSE(dm::computeMassProperties(b, std::nan("")));
  dm::Mesh bad = b;
  bad.triangles[3][1] = 99;
  auto r = dm::computeMassProperties(bad);
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().what.find("99"), std::string::npos) << r.error();
  dm::Mesh nan = b;
  nan.positions[2].x() = std::nan("");
  EXPECT_FALSE(dm::computeMassProperties(nan));
}

}  // namespace
