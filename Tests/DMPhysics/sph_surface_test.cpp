// Deforming surfaces (tissue) in the DFSPH fluid, against geometry and
// hydrostatics: a BoundarySurface placed on its mesh moved rigidly moves its
// samples rigidly; velocities interpolated from a linear field are the field
// at the samples, and spreading forces onto the vertices keeps their sum and
// moment; a pool's weight rests on a floor that is a surface (the loads'
// sum is M g); the floor bulging into a dome (a curved surface, one-way:
// the tissue pushes the fluid) lifts the pool's centre of mass by what the
// geometry of the dome says, loses no particle through it, and keeps the
// density; bad surfaces and states are refused naming what is wrong.
#include <dm/math/primitives.hpp>
#include <dm/physics/sph_boundary.hpp>
#include <dm/physics/sph_fluid.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <vector>

namespace sph_surface_test {

using dm::Vec3;

constexpr double kD = 0.01;   // m, spacing
constexpr double kL = 0.12;   // m, the tank's side
constexpr double kH0 = 0.08;  // m, the pool's depth over the flat floor
constexpr double kRho0 = 1000.0, kG = 9.81;
constexpr int kCells = 12;  // the floor's grid (a spacing per cell)

// A square floor [0, L]² at z = 0 facing up (the fluid above it).
dm::Mesh floorMesh() {
  dm::Mesh m = dm::makePlane(0.5 * kL, 0.5 * kL, kCells);
  for (Vec3& p : m.positions) p += Vec3(0.5 * kL, 0.5 * kL, 0.0);
  return m;
}

// The dome: z = a sin(πx/L) sin(πy/L), zero along the walls.
double dome(const Vec3& p) {
  return std::sin(std::numbers::pi * p.x() / kL) * std::sin(std::numbers::pi * p.y() / kL);
}

// A pool of depth kH0 over the floor surface; the container's own floor
// lies 3 cm lower, out of the fluid's reach. The floor is sampled at half a
// spacing (the dome stretches it by up to 1.45, and samples more than a
// spacing apart let the fluid through), d/3 under it. The pool's bottom
// layer starts a spacing above the samples, where a lattice has its next
// layer (a block started with its edge on this dense floor is thrown up by
// its first pressure solve), and settles to its edge on the floor.
constexpr double kSampling = 0.5 * kD;
constexpr double kLift = kD - kD / 3.0 - kD / 2.0;

struct Pool {
  dm::SphFluid fluid;
  dm::Mesh floor;
  std::size_t surface = 0;
};

// (The floor's samples placed on `floorAt` when given, else on the flat floor.)
Pool pool(const std::vector<Vec3>& floorAt = {}) {
  auto f = dm::SphFluid::create({.particleSpacing = kD, .viscosity = 1e-4});
  EXPECT_TRUE(f) << f.error();
  Pool p{*f, floorMesh()};
  p.fluid.addBoxBoundary({0, 0, -0.03}, {kL, kL, 0.3});
  p.fluid.addBlock({0, 0, kLift}, {kL, kL, kH0 + kLift});
  auto samples = dm::BoundarySurface::create(p.floor, kSampling, kD / 3.0);
  EXPECT_TRUE(samples) << samples.error();
  auto id = p.fluid.addSurfaceBoundary(std::move(*samples), floorAt.empty() ? p.floor.positions : floorAt);
  EXPECT_TRUE(id) << id.error();
  return p;
}

double centreHeight(const dm::SphFluid& s) {
  double z = 0.0;
  for (const Vec3& x : s.positions()) z += x.z();
  return z / double(s.size());
}

TEST(BoundarySurface, ARigidMotionOfTheMeshMovesTheSamplesRigidly) {
  const dm::Mesh ball = dm::makeIcosphere(0.03, 3);
  auto surface = dm::BoundarySurface::create(ball, kD, kD / 3.0);
  ASSERT_TRUE(surface) << surface.error();
  auto reference = dm::sampleBoundary(ball, kD, kD / 3.0);
  ASSERT_TRUE(reference) << reference.error();
  ASSERT_EQ(surface->size(), reference->size());
  std::vector<Vec3> at(surface->size());
  surface->place(ball.positions, at);
  for (std::size_t q = 0; q < at.size(); ++q) EXPECT_EQ(at[q], (*reference)[q]) << q;

  dm::Isometry3 pose = dm::Isometry3::Identity();
  pose.rotate(dm::AngleAxis(0.7, Vec3(1, 2, 3).normalized()));
  pose.translation() = Vec3(0.1, -0.2, 0.05);
  std::vector<Vec3> moved;
  for (const Vec3& v : ball.positions) moved.push_back(pose * v);
  std::vector<Vec3> placed(surface->size());
  surface->place(moved, placed);
  for (std::size_t q = 0; q < at.size(); ++q) EXPECT_LT((placed[q] - pose * at[q]).norm(), 1e-12) << q;
}

TEST(BoundarySurface, InterpolationIsExactForLinearFieldsAndSpreadingKeepsSumAndMoment) {
  const dm::Mesh ball = dm::makeIcosphere(0.03, 2);
  auto surface = dm::BoundarySurface::create(ball, kD, 0.0);  // no inset: the samples on the triangles
  ASSERT_TRUE(surface) << surface.error();
  std::vector<Vec3> at(surface->size());
  surface->place(ball.positions, at);
  dm::Mat3 a;
  a << 1, 2, 0, -1, 0.5, 3, 0, 0, -2;
  const Vec3 b(0.3, -0.1, 0.2);
  std::vector<Vec3> field;
  for (const Vec3& v : ball.positions) field.push_back(a * v + b);
  std::vector<Vec3> values(surface->size());
  surface->interpolate(field, values);
  for (std::size_t q = 0; q < at.size(); ++q) EXPECT_LT((values[q] - (a * at[q] + b)).norm(), 1e-12) << q;

  std::vector<Vec3> forces(surface->size());
  Vec3 sum = Vec3::Zero(), moment = Vec3::Zero();
  for (std::size_t q = 0; q < at.size(); ++q) {
    forces[q] = Vec3(std::sin(double(q)), std::cos(3.0 * double(q)), 0.5);
    sum += forces[q];
    moment += at[q].cross(forces[q]);
  }
  std::vector<Vec3> onVertices(ball.positions.size(), Vec3::Zero());
  surface->spread(forces, onVertices);
  Vec3 vsum = Vec3::Zero(), vmoment = Vec3::Zero();
  for (std::size_t v = 0; v < onVertices.size(); ++v) {
    vsum += onVertices[v];
    vmoment += ball.positions[v].cross(onVertices[v]);
  }
  EXPECT_LT((vsum - sum).norm(), 1e-9 * sum.norm());
  EXPECT_LT((vmoment - moment).norm(), 1e-9 * (1.0 + moment.norm()));
}

TEST(SphSurface, APoolRestsOnASurfaceFloorWithItsWeight) {
  Pool p = pool();
  for (int k = 0; k < 300; ++k) ASSERT_TRUE(p.fluid.step(0.002));
  Vec3 load = Vec3::Zero();
  for (int k = 0; k < 100; ++k) {  // averaged over 0.2 s of the settled pool
    ASSERT_TRUE(p.fluid.step(0.002));
    for (const Vec3& f : p.fluid.surfaceLoads(p.surface)) load += f / 100.0;
  }
  const double weight = p.fluid.mass() * kG;
  EXPECT_NEAR(load.z(), -weight, 0.03 * weight);
  EXPECT_LT(load.head<2>().norm(), 0.01 * weight);
}

TEST(SphSurface, AFloorBulgingIntoADomeLiftsThePoolAsItsGeometrySays) {
  Pool p = pool();
  for (int k = 0; k < 250; ++k) ASSERT_TRUE(p.fluid.step(0.002));  // settle
  const double before = centreHeight(p.fluid);
  const std::size_t n = p.fluid.size();

  // The floor rises into a dome of amplitude 4 cm over 1 s (a smooth ramp),
  // its vertices handed in with their velocities every step, as an FEM
  // body's would be; then 0.5 s to settle.
  constexpr double kAmplitude = 0.04, kRise = 1.0, kDt = 0.002;
  std::vector<Vec3> x(p.floor.positions), v(x.size());
  for (int k = 1; k <= int((kRise + 0.5) / kDt); ++k) {
    const double t = std::min(k * kDt, kRise) / kRise;
    const double s = t * t * (3.0 - 2.0 * t), ds = k * kDt < kRise ? 6.0 * t * (1.0 - t) / kRise : 0.0;
    for (std::size_t i = 0; i < x.size(); ++i) {
      x[i].z() = kAmplitude * s * dome(p.floor.positions[i]);
      v[i] = Vec3(0, 0, kAmplitude * ds * dome(p.floor.positions[i]));
    }
    ASSERT_TRUE(p.fluid.setSurfaceState(p.surface, x, v));
    ASSERT_TRUE(p.fluid.step(kDt)) << k;
  }

  // The continuum: the fluid's volume V = L² h0 lies between the deformed
  // floor (piecewise linear, as the mesh) and a level H = h0 + ΔV / L²; its
  // centre of mass is (L² H² / 2 − ∫ z_f² / 2) / V.
  double dv = 0.0, z2 = 0.0;
  for (const dm::Triangle& t : p.floor.triangles) {
    const Vec3 &a = x[t[0]], &b = x[t[1]], &c = x[t[2]];
    const double area = 0.5 * std::abs((b.x() - a.x()) * (c.y() - a.y()) - (b.y() - a.y()) * (c.x() - a.x()));
    dv += area * (a.z() + b.z() + c.z()) / 3.0;
    z2 += area *
          (a.z() * a.z() + b.z() * b.z() + c.z() * c.z() + a.z() * b.z() + b.z() * c.z() + c.z() * a.z()) /
          6.0;
  }
  const double area = kL * kL, volume = area * kH0, level = kH0 + dv / area;
  const double expected = (area * level * level / 2.0 - z2 / 2.0) / volume;
  const double after = centreHeight(p.fluid);
  // Flat: the pool settled with its edge on the floor (the d/3 inset), its
  // centre at h0 / 2; the dome lifts it by about 1.5 spacings.
  EXPECT_NEAR(before, kH0 / 2.0, 0.05 * kD);
  EXPECT_NEAR(after - before, expected - kH0 / 2.0, 0.05 * (expected - kH0 / 2.0));
  // Nothing went through the floor, nothing was lost, and the fluid kept
  // its density.
  ASSERT_EQ(p.fluid.size(), n);
  for (const Vec3& q : p.fluid.positions())
    EXPECT_GT(q.z(), kAmplitude * dome(q) - 0.1 * kD) << q.transpose();
  EXPECT_LT(p.fluid.lastStep().densityError, 2e-3);
}

// A surface's Ψ come from its samples' pairs, kept as a Verlet list between
// strains: the floor bulged into the dome, squeezed to 60 % across and
// moved sideways in 80 small steps (most of them reuse the list, some list
// it again) gives the fluid the same densities as the same floor placed at
// its final shape from the start (its pairs listed there), to rounding. Squeezed,
// samples come within reach of others that were out of it when listed: a
// pair the list missed would leave a sample's Ψ off by its whole term.
TEST(SphSurface, AFloorStrainedInSmallStepsHasTheVolumesOfOnePlacedThere) {
  constexpr double kAmplitude = 0.04, kSqueeze = 0.6;
  const Vec3 shift(0.3 * kD, -0.2 * kD, 0.0);  // a common motion: the list holds
  std::vector<Vec3> final(floorMesh().positions);
  for (Vec3& q : final)
    q = Vec3(0.5 * kL + kSqueeze * (q.x() - 0.5 * kL), q.y(), kAmplitude * dome(q)) + shift;
  const std::vector<Vec3> still(final.size(), Vec3::Zero());

  Pool gradual = pool();
  std::vector<Vec3> x(gradual.floor.positions);
  constexpr int kSteps = 80;
  for (int k = 1; k <= kSteps; ++k) {
    const double s = double(k) / kSteps;
    for (std::size_t i = 0; i < x.size(); ++i)
      x[i] = gradual.floor.positions[i] + s * (final[i] - gradual.floor.positions[i]);
    ASSERT_TRUE(gradual.fluid.setSurfaceState(gradual.surface, x, still));
  }
  gradual.fluid.refresh();

  Pool direct = pool(final);  // its samples' pairs first listed there
  direct.fluid.refresh();

  ASSERT_EQ(gradual.fluid.size(), direct.fluid.size());
  const auto a = gradual.fluid.densities(), b = direct.fluid.densities();
  std::size_t touched = 0;
  double worst = 0.0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    worst = std::max(worst, std::abs(a[i] - b[i]));
    if (a[i] > 0.0) ++touched;
  }
  EXPECT_EQ(touched, a.size());
  EXPECT_LT(worst, 1e-9 * kRho0);
}

TEST(SphSurface, BadSurfacesAndStatesAreRefusedNamingThem) {
  Pool p = pool();
  auto samples = dm::BoundarySurface::create(p.floor, kD, kD / 3.0);
  ASSERT_TRUE(samples);
  std::vector<Vec3> few(3, Vec3::Zero());
  auto r = p.fluid.addSurfaceBoundary(*samples, few);
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().message().find("3 vertices for a surface of 169"), std::string::npos) << r.error();
  std::vector<Vec3> x(p.floor.positions), v(x.size(), Vec3::Zero());
  x[7].x() = std::nan("");
  r = p.fluid.addSurfaceBoundary(*samples, x);
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().message().find("vertex 7 is not finite"), std::string::npos) << r.error();
  auto s = p.fluid.setSurfaceState(p.surface, x, v);
  ASSERT_FALSE(s);
  EXPECT_NE(s.error().message().find("surface 0: vertex 7 is not finite"), std::string::npos) << s.error();
  s = p.fluid.setSurfaceState(1, p.floor.positions, v);
  ASSERT_FALSE(s);
  EXPECT_NE(s.error().message().find("surface 1 of 1"), std::string::npos) << s.error();
  s = p.fluid.setSurfaceState(0, p.floor.positions, few);
  ASSERT_FALSE(s);
  EXPECT_NE(s.error().message().find("169 vertices and 3 velocities"), std::string::npos) << s.error();
  EXPECT_EQ(p.fluid.surfaceCount(), 1u);
}

}  // namespace sph_surface_test
