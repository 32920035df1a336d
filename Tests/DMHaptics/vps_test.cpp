// VpsRenderer (dm/haptics/vps.hpp) against ground truth: a sphere-tipped
// tool held still in a half-space (a voxelized box) and in a sphere (an
// analytic signed distance sampled on a grid), and on a torus's convex and
// saddle regions, settles where the coupling force equals the penalty force
// computed from the exact geometry at the settled pose; the force is normal
// to the true surface; an off-centre tip
// gives the lever-arm torque r × F; dense and OpenVDB sparse models agree;
// pre-contact braking keeps a fast tool from tunnelling through a thin
// plate; the coupled tool's kinetic energy only decays; the tick is
// allocation-free, NaN-guarded and deterministic.
#include <dm/core/volume.hpp>
#include <dm/haptics/vps.hpp>
#include <dm/math/primitives.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <functional>
#include <limits>
#include <numbers>
#include <vector>

#include "../common/alloc_counter.hpp"
#include "haptics_test_support.hpp"

namespace dm {
namespace {

using dm::test::at;
using dm::test::kDt;

// Point shell of an icosphere's vertices (radius r, 642 points at level 3)
// centred at `centre` in the tool frame, normals radial.
std::shared_ptr<const PointShell> sphereShell(double r, int levels, const Vec3& centre = Vec3::Zero()) {
  const Mesh m = makeIcosphere(r, levels);
  std::vector<Vec3> points, normals;
  for (const Vec3& p : m.positions) {
    points.push_back(p + centre);
    normals.push_back(p.normalized());
  }
  auto shell = PointShell::create(points, normals);
  EXPECT_TRUE(shell.ok());
  return *shell;
}

// Dense model of a box mesh (half extents, centred at `centre`) at voxel h.
std::shared_ptr<const VoxelModel> boxModel(const Vec3& half, const Vec3& centre, double h) {
  Mesh box = makeBox(half);
  for (Vec3& p : box.positions) p += centre;
  auto model = VoxelModel::fromMesh(box, {.voxelSize = h});
  EXPECT_TRUE(model.ok()) << (model ? "" : model.error().what);
  return *model;
}

// Dense model of a signed distance `sdf` (negative inside) sampled on the
// grid lo + h·(i, j, k) covering [lo, hi].
std::shared_ptr<const VoxelModel> sdfModel(const std::function<double(const Vec3&)>& sdf, const Vec3& lo,
                                           const Vec3& hi, double h) {
  const Vec3i dims = ((hi - lo) / h).array().ceil().cast<int>() + 1;
  Affine3 a = Affine3::Identity();
  a.linear() = h * Mat3::Identity();
  a.translation() = lo;
  auto v = Volume::create(dims, VoxelType::F32, a);
  EXPECT_TRUE(v.ok());
  for (int k = 0; k < dims.z(); ++k)
    for (int j = 0; j < dims.y(); ++j)
      for (int i = 0; i < dims.x(); ++i) v->setValue(i, j, k, sdf(lo + h * Vec3(i, j, k)));
  auto model = VoxelModel::fromSdf(*v);
  EXPECT_TRUE(model.ok());
  return *model;
}

// The analytic sphere SDF |p − c| − R on such a grid.
std::shared_ptr<const VoxelModel> sphereSdfModel(const Vec3& c, double radius, const Vec3& lo, const Vec3& hi,
                                                 double h) {
  return sdfModel([&](const Vec3& p) { return (p - c).norm() - radius; }, lo, hi, h);
}

// Holds the device still at `device` for `ticks` ticks; the last response.
HapticResponse hold(VpsRenderer& r, const Isometry3& device, int ticks) {
  HapticResponse out;
  for (int t = 0; t < ticks; ++t)
    out = r.tick({.timeNs = std::int64_t{t} * 1'000'000, .dt = kDt, .devicePose = device});
  return out;
}

// Ground truth: the force model of the file comment of vps.hpp evaluated
// with the exact geometry. `field(p)` gives the true signed distance at a
// world point and writes the true outward unit normal.
struct Wrench {
  Vec3 force = Vec3::Zero();
  Vec3 torque = Vec3::Zero();  // about the tool origin
  int contacts = 0;
};
Wrench exactWrench(const PointShell& shell, const Isometry3& pose, double stiffness, const VpsOptions& o,
                   const std::function<double(const Vec3&, Vec3&)>& field) {
  Wrench w;
  for (const Vec3& local : shell.points()) {
    const Vec3 p = pose * local;
    Vec3 n;
    const double d = field(p, n);
    if (d > 0) continue;
    ++w.contacts;
    const Vec3 f = std::min(-d, o.maxPointDepth) * n;
    w.force += f;
    w.torque += (p - pose.translation()).cross(f);
  }
  const double s = stiffness / std::max<double>(w.contacts, o.referenceContacts);
  w.force *= s;
  w.torque *= s;
  return w;
}

double angleDeg(const Vec3& a, const Vec3& b) {
  return std::atan2(a.cross(b).norm(), a.dot(b)) * 180.0 / std::numbers::pi;
}

double relError(const Vec3& got, const Vec3& want) { return (got - want).norm() / want.norm(); }

// --- static contact against ground truth ------------------------------------

TEST(Vps, SphereTipSettlesOnVoxelizedHalfSpaceWithExactForce) {
  const double r = 3e-3;
  auto tool = sphereShell(r, 3);
  // Big box whose top face is the plane z = 0; 1 mm voxels.
  auto box = boxModel(Vec3(0.02, 0.02, 0.01), Vec3(0, 0, -0.01), 1e-3);
  const HapticMaterial mat{.stiffness = 1000.0};
  const VpsOptions opt;
  auto vps = VpsRenderer::create(tool, {{box, Isometry3::Identity(), mat}}, opt);
  ASSERT_TRUE(vps.ok()) << vps.error().what;
  VpsRenderer& R = **vps;
  R.reset(at(Vec3(1e-3, 0.5e-3, r + 2e-3)));
  // Device 1.5 mm below where the free tool would touch the plane.
  const Isometry3 device = at(Vec3(1e-3, 0.5e-3, r - 1.5e-3));
  const HapticResponse out = hold(R, device, 1500);
  EXPECT_LT(R.toolVelocity().norm(), 1e-7);
  EXPECT_LT(R.toolKineticEnergy(), 1e-15);
  ASSERT_GT(out.contacts, 10);

  // Force on the hand: along the plane's normal +z, and equal to the exact
  // penalty force at the tool's settled pose.
  const auto field = [](const Vec3& p, Vec3& n) {
    n = Vec3::UnitZ();
    return p.z();
  };
  const Wrench exact = exactWrench(*tool, out.proxyPose, mat.stiffness, opt, field);
  EXPECT_EQ(out.contacts, exact.contacts);
  EXPECT_LT(angleDeg(out.force, Vec3::UnitZ()), 1.0);
  EXPECT_LT(relError(out.force, exact.force), 0.02)
      << out.force.transpose() << " vs " << exact.force.transpose();
  // Equilibrium: the coupling spring carries the contact force.
  EXPECT_LT(relError(out.force, R.contactForce()), 1e-4);
  EXPECT_NEAR(out.force.z(),
              opt.couplingStiffness * (out.proxyPose.translation().z() - device.translation().z()),
              1e-4 * out.force.norm());
  // Continuum check: a sphere cap pressed δ deep averages depth δ/2.
  const double delta = r - out.proxyPose.translation().z();
  EXPECT_NEAR(out.force.z(), mat.stiffness * delta / 2, 0.1 * mat.stiffness * delta / 2);
  std::printf("half-space: %d contacts, depth %.4f mm, force %.5f N, exact %.5f N, rel. error %.2e\n",
              out.contacts, delta * 1e3, out.force.z(), exact.force.z(), relError(out.force, exact.force));
}

TEST(Vps, SphereTipInSphereMatchesExactForceAcrossVoxelSizes) {
  const double r = 3e-3, radius = 0.02;
  auto tool = sphereShell(r, 3);
  const Vec3 centre(0, 0, -radius);  // top of the sphere at the origin
  // The device pushes 1.5 mm in along a direction 10° off the vertical.
  const Vec3 u = Vec3(std::sin(10 * std::numbers::pi / 180), 0, std::cos(10 * std::numbers::pi / 180));
  const Isometry3 device = at(centre + (radius + r - 1.5e-3) * u);
  const HapticMaterial mat{.stiffness = 1000.0};
  const VpsOptions opt;
  const auto field = [&](const Vec3& p, Vec3& n) {
    n = (p - centre).normalized();
    return (p - centre).norm() - radius;
  };
  double errors[3];
  const double sizes[3] = {0.5e-3, 0.25e-3, 0.125e-3};
  for (int s = 0; s < 3; ++s) {
    // The grid covers the contact region (the distance is extrapolated beyond).
    auto model = sphereSdfModel(centre, radius, Vec3(-2e-3, -5e-3, -3e-3), Vec3(9e-3, 5e-3, 3e-3), sizes[s]);
    auto vps = VpsRenderer::create(tool, {{model, Isometry3::Identity(), mat}}, opt);
    ASSERT_TRUE(vps.ok());
    (*vps)->reset(at(centre + (radius + r + 2e-3) * u));
    const HapticResponse out = hold(**vps, device, 1500);
    EXPECT_LT((*vps)->toolVelocity().norm(), 1e-6);
    const Wrench exact = exactWrench(*tool, out.proxyPose, mat.stiffness, opt, field);
    // The force is radial: along the true normal through the tool's centre.
    const Vec3 normal = (out.proxyPose.translation() - centre).normalized();
    EXPECT_LT(angleDeg(out.force, normal), 2.0);
    EXPECT_LT(angleDeg(out.force, u), 3.0);
    errors[s] = relError(out.force, exact.force);
    EXPECT_LT(errors[s], 0.02) << "voxel " << sizes[s];
    std::printf(
        "sphere, voxel %.3f mm: %d contacts (exact %d), force %.5f N, rel. error %.2e, angle %.3f deg\n",
        sizes[s] * 1e3, out.contacts, exact.contacts, out.force.norm(), errors[s],
        angleDeg(out.force, normal));
  }
  EXPECT_LT(errors[2], errors[0] + 1e-3);
}

// The true torus about z (R to the tube's centre line, tube radius r0):
// signed distance at p, and the outward unit normal (its gradient) in n.
double torusField(double R, double r0, const Vec3& p, Vec3& n) {
  const double rho = std::hypot(p.x(), p.y());
  const Vec3 q((rho - R) * p.x() / rho, (rho - R) * p.y() / rho, p.z());
  n = q.normalized();
  return q.norm() - r0;
}

// On a torus — the convex outside, the top, and the saddle-shaped inside
// (negative Gaussian curvature) — the settled force matches the force model
// evaluated on the exact geometry within 2 %, along the true normal within
// 2°, at 0.5 and 0.25 mm voxels.
TEST(Vps, SphereTipOnTorusMatchesExactForceOnConvexAndSaddleRegions) {
  const double r = 3e-3, R = 0.04, r0 = 0.015;
  auto tool = sphereShell(r, 3);
  const HapticMaterial mat{.stiffness = 1000.0};
  const VpsOptions opt;
  const auto field = [&](const Vec3& p, Vec3& n) { return torusField(R, r0, p, n); };
  const struct {
    const char* name;
    double v;  // angle about the tube: 0 outside, π/2 top, π inside
  } places[] = {
      {"outside", 0.2}, {"top", std::numbers::pi / 2 - 0.3}, {"inside (saddle)", std::numbers::pi - 0.2}};
  for (const auto& place : places) {
    const double u = 0.4;  // about z
    const Vec3 n(std::cos(place.v) * std::cos(u), std::cos(place.v) * std::sin(u), std::sin(place.v));
    const Vec3 onSurface = Vec3(R * std::cos(u), R * std::sin(u), 0) + r0 * n;
    const Isometry3 device = at(onSurface + (r - 1.5e-3) * n);
    for (const double h : {0.5e-3, 0.25e-3}) {
      Vec3 unused;
      auto model = sdfModel([&](const Vec3& p) { return torusField(R, r0, p, unused); },
                            onSurface - Vec3::Constant(8e-3), onSurface + Vec3::Constant(8e-3), h);
      auto vps = VpsRenderer::create(tool, {{model, Isometry3::Identity(), mat}}, opt);
      ASSERT_TRUE(vps.ok());
      (*vps)->reset(at(onSurface + (r + 2e-3) * n));
      const HapticResponse out = hold(**vps, device, 1500);
      EXPECT_LT((*vps)->toolVelocity().norm(), 1e-6) << place.name;
      const Wrench exact = exactWrench(*tool, out.proxyPose, mat.stiffness, opt, field);
      Vec3 normal;
      field(out.proxyPose.translation(), normal);
      const double err = relError(out.force, exact.force), ang = angleDeg(out.force, normal);
      std::printf(
          "torus %s, voxel %.3f mm: %d contacts (exact %d), force %.5f N, rel. error %.2e, angle %.3f deg\n",
          place.name, h * 1e3, out.contacts, exact.contacts, out.force.norm(), err, ang);
      EXPECT_LT(err, 0.02) << place.name << ", voxel " << h;
      EXPECT_LT(ang, 2.0) << place.name << ", voxel " << h;
    }
  }
}

TEST(Vps, OffCentreTipGivesLeverArmTorque) {
  const double r = 3e-3, arm = 0.02;
  // Sphere tip 20 mm along +x from the tool's origin (its centre of mass).
  auto tool = sphereShell(r, 3, Vec3(arm, 0, 0));
  auto box = boxModel(Vec3(0.035, 0.015, 0.01), Vec3(0.01, 0, -0.01), 1e-3);
  const HapticMaterial mat{.stiffness = 1000.0};
  VpsOptions opt;
  opt.couplingAngularStiffness = 0.5;
  auto vps = VpsRenderer::create(tool, {{box, Isometry3::Identity(), mat}}, opt);
  ASSERT_TRUE(vps.ok());
  (*vps)->reset(at(Vec3(0, 0, r + 2e-3)));
  const HapticResponse out = hold(**vps, at(Vec3(0, 0, r - 1e-3)), 3000);
  EXPECT_LT((*vps)->toolAngularVelocity().norm(), 1e-5);
  const auto field = [](const Vec3& p, Vec3& n) {
    n = Vec3::UnitZ();
    return p.z();
  };
  const Wrench exact = exactWrench(*tool, out.proxyPose, mat.stiffness, opt, field);
  ASSERT_GT(exact.force.norm(), 0.1);
  EXPECT_LT(relError(out.force, exact.force), 0.02);
  EXPECT_LT(relError(out.torque, exact.torque), 0.02)
      << out.torque.transpose() << " vs " << exact.torque.transpose();
  // Lever arm: the tip's centre relative to the tool origin, crossed with
  // the force (the pressure centre lies on the normal through the centre).
  const Vec3 lever = out.proxyPose.linear() * Vec3(arm, 0, 0);
  const Vec3 leverTorque = lever.cross(out.force);
  EXPECT_LT((out.torque - leverTorque).norm(), 0.03 * lever.norm() * out.force.norm())
      << out.torque.transpose() << " vs r x F " << leverTorque.transpose();
  // The angular coupling spring carries it: k_r · (rotation of the tool).
  const double angle = AngleAxis(out.proxyPose.linear()).angle();
  EXPECT_NEAR(angle * opt.couplingAngularStiffness, out.torque.norm(), 1e-3 * out.torque.norm());
}

TEST(Vps, DenseAndSparseModelsGiveTheSameForce) {
  const double r = 3e-3, radius = 0.02, h = 0.5e-3;
  auto tool = sphereShell(r, 3);
  const Vec3 centre(0, 0, -radius);
  auto dense = sphereSdfModel(centre, radius, Vec3(-6e-3, -6e-3, -4e-3), Vec3(6e-3, 6e-3, 8e-3), h);
  auto sparse = dense->toSparse(4 * h);
  ASSERT_TRUE(sparse.ok()) << sparse.error().what;
  ASSERT_EQ((*sparse)->storage(), VoxelStorage::Sparse);
  const HapticMaterial mat{.stiffness = 1500.0, .damping = 2.0};
  const Isometry3 objectPose =
      at(Vec3(1e-3, -2e-3, 0.5e-3), AngleAxis(0.3, Vec3(1, 2, 3).normalized()).matrix());
  const Isometry3 device =
      objectPose * at(Vec3(0.5e-3, 0.3e-3, r - 1.2e-3), AngleAxis(0.2, Vec3::UnitY()).matrix());
  HapticResponse outs[2];
  const std::shared_ptr<const VoxelModel> models[2] = {dense, *sparse};
  for (int m = 0; m < 2; ++m) {
    auto vps = VpsRenderer::create(tool, {{models[m], objectPose, mat}}, {});
    ASSERT_TRUE(vps.ok());
    (*vps)->reset(objectPose * at(Vec3(0, 0, r + 3e-3)));
    outs[m] = hold(**vps, device, 400);
  }
  ASSERT_GT(outs[0].contacts, 10);
  EXPECT_EQ(outs[0].contacts, outs[1].contacts);
  EXPECT_LT(relError(outs[1].force, outs[0].force), 1e-6);
  EXPECT_LT((outs[1].torque - outs[0].torque).norm(), 1e-6 * outs[0].force.norm() * r + 1e-12);
  EXPECT_LT((outs[1].proxyPose.matrix() - outs[0].proxyPose.matrix()).norm(), 1e-9);
}

// Rotating the whole scene (object and device) rotates the answer, whether
// the object is placed by create() or moved by setObjectPose().
TEST(Vps, ForceIsFrameInvariant) {
  const double r = 3e-3;
  auto tool = sphereShell(r, 3, Vec3(0.004, 0, 0));
  auto box = boxModel(Vec3(0.02, 0.02, 0.01), Vec3(0, 0, -0.01), 1e-3);
  const Isometry3 scene = at(Vec3(0.1, -0.05, 0.2), AngleAxis(1.1, Vec3(-1, 2, 0.5).normalized()).matrix());
  const Isometry3 device = at(Vec3(0.5e-3, 0, r - 1e-3), AngleAxis(0.15, Vec3::UnitY()).matrix());
  HapticResponse outs[3];
  for (int m = 0; m < 3; ++m) {
    const Isometry3 frame = m == 0 ? Isometry3::Identity() : scene;
    auto vps =
        VpsRenderer::create(tool, {{box, m == 1 ? scene : Isometry3::Identity(), {.stiffness = 800}}}, {});
    ASSERT_TRUE(vps.ok());
    if (m == 2) (*vps)->setObjectPose(0, scene);
    (*vps)->reset(frame * at(Vec3(0, 0, r + 2e-3)));
    outs[m] = hold(**vps, frame * device, 300);
  }
  ASSERT_GT(outs[0].force.norm(), 0.05);
  for (int m = 1; m < 3; ++m) {
    EXPECT_LT((outs[m].force - scene.linear() * outs[0].force).norm(), 1e-6 * outs[0].force.norm());
    EXPECT_LT((outs[m].torque - scene.linear() * outs[0].torque).norm(),
              1e-6 * outs[0].torque.norm() + 1e-12);
  }
}

// --- dynamics ----------------------------------------------------------------

// Drives the device down at 2 m/s (2 mm a tick) from 40 mm above a 1 mm
// plate to rest 1 mm into its top face (the tool, 10 g, follows closely);
// returns the lowest tool centre height seen, the final one and the final
// force on the hand.
struct PlateRun {
  double lowest = 1e9, final = 0, force = 0;
};
PlateRun plateRun(const VpsOptions& opt) {
  const double r = 2e-3, top = 0.5e-3;
  static const auto plate = boxModel(Vec3(0.015, 0.015, top), Vec3::Zero(), 0.25e-3);
  auto vps =
      VpsRenderer::create(sphereShell(r, 3), {{plate, Isometry3::Identity(), {.stiffness = 1000}}}, opt);
  EXPECT_TRUE(vps.ok());
  PlateRun run;
  const double start = 0.04, target = top + r - 1e-3, speed = 2.0;
  (*vps)->reset(at(Vec3(0, 0, start)));
  for (int t = 0; t < 600; ++t) {
    const double z = std::max(target, start - speed * kDt * (t + 1));
    const Vec3 v = z > target ? Vec3(0, 0, -speed) : Vec3::Zero();
    const HapticResponse out =
        (*vps)->tick({.dt = kDt, .devicePose = at(Vec3(0, 0, z)), .linearVelocity = v});
    run.lowest = std::min(run.lowest, out.proxyPose.translation().z());
    run.final = out.proxyPose.translation().z();
    run.force = out.force.z();
  }
  return run;
}

TEST(Vps, PreContactBrakingStopsTunnellingThroughThinPlate) {
  VpsOptions braking;
  braking.mass = 0.01;
  braking.brakeDistance = 2.5e-3;  // more than the 2 mm a point moves in a tick
  braking.brakeDamping = 100.0;
  const PlateRun withBrake = plateRun(braking);
  // Without braking the same approach passes through: the test can fail.
  VpsOptions none = braking;
  none.brakeDistance = 0.0;
  const PlateRun without = plateRun(none);
  std::printf(
      "plate: with braking tool centre lowest %.3f mm, final %.3f mm, force %.3f N; "
      "without: lowest %.3f mm, final %.3f mm, force %.3f N\n",
      withBrake.lowest * 1e3, withBrake.final * 1e3, withBrake.force, without.lowest * 1e3,
      without.final * 1e3, without.force);
  // With braking the sphere's bottom never gets 0.7 mm into the 1 mm plate,
  // and the tool comes to rest on the top face pressing back with the
  // coupling force (device 1 mm in).
  EXPECT_GT(withBrake.lowest, 1.8e-3);
  EXPECT_GT(withBrake.final, 1.8e-3);
  EXPECT_GT(withBrake.force, 0.2);
  // Without it the hollow shell jumps past the plate and ends straddling it,
  // touching nothing: the device is 1 mm inside and feels no force.
  EXPECT_LT(without.lowest, 0.0);
  EXPECT_LT(without.force, 0.02);
}

// Kinetic energy of the tool, device held still in contact after a jump:
// the windowed maximum never grows and it dies out (implicit coupling).
void expectEnergyDecays(const VpsOptions& opt, double stiffness) {
  const double r = 3e-3;
  auto tool = sphereShell(r, 3, Vec3(0.002, 0.001, 0));
  auto box = boxModel(Vec3(0.02, 0.02, 0.01), Vec3(0, 0, -0.01), 1e-3);
  auto vps = VpsRenderer::create(tool, {{box, Isometry3::Identity(), {.stiffness = stiffness}}}, opt);
  ASSERT_TRUE(vps.ok());
  (*vps)->reset(at(Vec3(0, 0, r + 1e-3)));
  const Isometry3 device =
      at(Vec3(0.3e-3, 0, r - 1.5e-3), AngleAxis(0.3, Vec3(1, 1, 0).normalized()).matrix());
  std::vector<double> energy;
  for (int t = 0; t < 2000; ++t) {
    (*vps)->tick({.dt = kDt, .devicePose = device});
    energy.push_back((*vps)->toolKineticEnergy());
  }
  const double peak = *std::max_element(energy.begin(), energy.end());
  ASSERT_GT(peak, 0);
  double previous = std::numeric_limits<double>::infinity();
  for (std::size_t w = 100; w < energy.size(); w += 100) {
    const double windowMax = *std::max_element(energy.begin() + static_cast<std::ptrdiff_t>(w),
                                               energy.begin() + static_cast<std::ptrdiff_t>(w + 100));
    EXPECT_LE(windowMax, previous * (1 + 1e-9) + 1e-18) << "window at tick " << w;
    previous = windowMax;
  }
  EXPECT_LT(energy.back(), 1e-8 * peak);
}

TEST(Vps, CouplingIsStableAt1kHzWithDefaults) { expectEnergyDecays({}, 1000.0); }

TEST(Vps, StiffCouplingAndContactStayStableAt1kHz) {
  VpsOptions stiff;
  stiff.couplingStiffness = 20000.0;
  stiff.couplingDamping = 0.0;
  stiff.couplingAngularStiffness = 50.0;
  stiff.couplingAngularDamping = 0.0;
  stiff.mass = 0.005;
  expectEnergyDecays(stiff, 50000.0);
}

// --- real-time contract ----------------------------------------------------

TEST(Vps, TickIsAllocationFreeOnDenseAndSparseModels) {
  const double r = 3e-3;
  auto tool = sphereShell(r, 3);
  auto dense =
      sphereSdfModel(Vec3(0, 0, -0.02), 0.02, Vec3(-6e-3, -6e-3, -4e-3), Vec3(6e-3, 6e-3, 8e-3), 0.5e-3);
  auto sparse = dense->toSparse(2e-3);
  ASSERT_TRUE(sparse.ok());
  VpsOptions opt;
  opt.substeps = 4;
  auto vps = VpsRenderer::create(tool,
                                 {{dense, Isometry3::Identity(), {.stiffness = 1000, .damping = 1}},
                                  {*sparse, at(Vec3(0, 0, 0.5e-3)), {.stiffness = 500}}},
                                 opt);
  ASSERT_TRUE(vps.ok());
  (*vps)->reset(at(Vec3(0, 0, r + 1e-3)));
  const auto before = test::countedAllocations();
  test::tCountAllocations = true;
  int contacts = 0;
  for (int t = 0; t < 200; ++t) {
    const HapticResponse out = (*vps)->tick({.dt = kDt,
                                             .devicePose = at(Vec3(1e-3 * std::sin(0.05 * t), 0, r - 1e-3)),
                                             .linearVelocity = Vec3(0.05 * std::cos(0.05 * t), 0, 0)});
    contacts = std::max(contacts, out.contacts);
  }
  (*vps)->setObjectPose(1, at(Vec3(0, 0, 0.2e-3)));
  test::tCountAllocations = false;
  EXPECT_EQ(test::countedAllocations(), before);
  EXPECT_GT(contacts, 10);
}

TEST(Vps, NonFiniteInputGivesZeroForceAndKeepsTheTool) {
  const double r = 3e-3;
  auto tool = sphereShell(r, 2);
  auto box = boxModel(Vec3(0.02, 0.02, 0.01), Vec3(0, 0, -0.01), 1e-3);
  auto vps = VpsRenderer::create(tool, {{box, Isometry3::Identity(), {}}}, {});
  ASSERT_TRUE(vps.ok());
  VpsRenderer& R = **vps;
  R.reset(at(Vec3(0, 0, r + 1e-3)));
  const HapticResponse inContact = hold(R, at(Vec3(0, 0, r - 1e-3)), 50);
  ASSERT_GT(inContact.force.norm(), 0.0);
  const Isometry3 pose = R.toolPose();
  const Vec3 velocity = R.toolVelocity();
  const double nan = std::numeric_limits<double>::quiet_NaN();
  Isometry3 bad = at(Vec3(0, 0, r - 1e-3));
  bad.translation().x() = nan;
  const HapticInput inputs[] = {
      {.dt = kDt, .devicePose = bad},
      {.dt = nan, .devicePose = at(Vec3(0, 0, r - 1e-3))},
      {.dt = 0.0, .devicePose = at(Vec3(0, 0, r - 1e-3))},
      {.dt = kDt, .devicePose = at(Vec3(0, 0, r - 1e-3)), .linearVelocity = Vec3(0, nan, 0)},
  };
  for (const HapticInput& in : inputs) {
    const HapticResponse out = R.tick(in);
    EXPECT_EQ(out.force, Vec3::Zero());
    EXPECT_EQ(out.torque, Vec3::Zero());
    EXPECT_TRUE(out.proxyPose.isApprox(pose, 0.0));
    EXPECT_EQ(R.toolPose().matrix(), pose.matrix());
    EXPECT_EQ(R.toolVelocity(), velocity);
  }
  // Non-finite object poses and bad indices are ignored.
  R.setObjectPose(0, bad);
  R.setObjectPose(7, Isometry3::Identity());
  const HapticResponse after = R.tick({.dt = kDt, .devicePose = at(Vec3(0, 0, r - 1e-3))});
  EXPECT_TRUE(after.force.allFinite());
  EXPECT_GT(after.force.z(), 0.0);
}

TEST(Vps, RunsAreBitwiseDeterministic) {
  const double r = 3e-3;
  auto tool = sphereShell(r, 3, Vec3(0.003, 0, 0.001));
  auto dense =
      sphereSdfModel(Vec3(0, 0, -0.02), 0.02, Vec3(-8e-3, -8e-3, -4e-3), Vec3(8e-3, 8e-3, 8e-3), 0.5e-3);
  auto run = [&] {
    auto vps =
        VpsRenderer::create(tool, {{dense, Isometry3::Identity(), {.stiffness = 1200, .damping = 0.5}}}, {});
    EXPECT_TRUE(vps.ok());
    (*vps)->reset(at(Vec3(0, 0, r + 2e-3)));
    std::uint64_t hash = 1469598103934665603ull;
    auto mix = [&](double v) {
      std::uint64_t bits;
      std::memcpy(&bits, &v, sizeof bits);
      hash = (hash ^ bits) * 1099511628211ull;
    };
    for (int t = 0; t < 500; ++t) {
      const double a = 0.01 * t;
      const HapticResponse out = (*vps)->tick(
          {.dt = kDt,
           .devicePose = at(Vec3(2e-3 * std::sin(a), 1e-3 * std::cos(3 * a), r - 1e-3 * (1 + std::sin(a))),
                            AngleAxis(0.3 * std::sin(2 * a), Vec3::UnitX()).matrix())});
      for (int k = 0; k < 3; ++k) mix(out.force[k]), mix(out.torque[k]);
      mix(out.proxyPose.translation().x());
    }
    return hash;
  };
  EXPECT_EQ(run(), run());
}

// --- validation --------------------------------------------------------------

TEST(Vps, CreateNamesTheBadField) {
  auto tool = sphereShell(3e-3, 1);
  auto box = boxModel(Vec3(0.01, 0.01, 0.01), Vec3::Zero(), 2e-3);
  const VpsObject good{box, Isometry3::Identity(), {}};
  auto whereOf = [](const Result<std::unique_ptr<VpsRenderer>>& r) {
    EXPECT_FALSE(r.ok());
    if (r.ok()) return std::string();
    EXPECT_EQ(r.error().code, ErrorCode::InvalidArgument);
    return r.error().where;
  };
  EXPECT_TRUE(VpsRenderer::create(tool, {good}, {}).ok());
  EXPECT_NE(whereOf(VpsRenderer::create(nullptr, {good}, {})).find("tool"), std::string::npos);
  EXPECT_NE(whereOf(VpsRenderer::create(tool, {good, {nullptr, Isometry3::Identity(), {}}}, {}))
                .find("objects[1].model"),
            std::string::npos);
  Isometry3 sheared = Isometry3::Identity();
  sheared.linear()(0, 1) = 0.5;
  EXPECT_NE(whereOf(VpsRenderer::create(tool, {good, good, {box, sheared, {}}}, {})).find("objects[2].pose"),
            std::string::npos);
  EXPECT_NE(whereOf(VpsRenderer::create(tool, {{box, Isometry3::Identity(), {.stiffness = -1}}}, {}))
                .find("objects[0].material/stiffness"),
            std::string::npos);
  struct Case {
    VpsOptions o;
    const char* field;
  };
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const Case cases[] = {
      {{.couplingStiffness = 0}, "couplingStiffness"},
      {{.couplingDamping = -1}, "couplingDamping"},
      {{.couplingAngularStiffness = nan}, "couplingAngularStiffness"},
      {{.couplingAngularDamping = -1}, "couplingAngularDamping"},
      {{.mass = 0}, "mass"},
      {{.inertia = -Mat3::Identity()}, "inertia"},
      {{.referenceContacts = 0.5}, "referenceContacts"},
      {{.maxPointDepth = 0}, "maxPointDepth"},
      {{.brakeDistance = -1e-3}, "brakeDistance"},
      {{.brakeDamping = nan}, "brakeDamping"},
      {{.maxForce = 0}, "maxForce"},
      {{.maxTorque = nan}, "maxTorque"},
      {{.substeps = 0}, "substeps"},
      {{.substeps = 65}, "substeps"},
  };
  for (const Case& c : cases)
    EXPECT_NE(whereOf(VpsRenderer::create(tool, {good}, c.o)).find(std::string("options.") + c.field),
              std::string::npos)
        << c.field;
}

TEST(Vps, OutputIsClampedAndInertiaDerivedFromBounds) {
  const double r = 3e-3;
  auto tool = sphereShell(r, 2);
  auto box = boxModel(Vec3(0.02, 0.02, 0.01), Vec3(0, 0, -0.01), 1e-3);
  VpsOptions opt;
  opt.maxForce = 0.1;
  auto vps = VpsRenderer::create(tool, {{box, Isometry3::Identity(), {}}}, opt);
  ASSERT_TRUE(vps.ok());
  // Solid cube of side 2r: I = m (2r)² / 6 on each axis.
  const double expected = opt.mass * 4 * r * r / 6;
  EXPECT_NEAR((*vps)->inertia()(0, 0), expected, 1e-3 * expected);
  EXPECT_NEAR((*vps)->inertia()(0, 1), 0.0, 1e-3 * expected);
  (*vps)->reset(at(Vec3(0, 0, r)));
  const HapticResponse out = hold(**vps, at(Vec3(0, 0, r - 3e-3)), 300);
  EXPECT_NEAR(out.force.norm(), 0.1, 1e-12);
  EXPECT_GT(out.penetration, 1e-3);
}

}  // namespace
}  // namespace dm
