// BurrRenderer: the god-object of a milling tool on voxel bone — the force
// on flat and curved bone against geometry, no pop-through, the cavity
// against the analytic swept volume, Archard monotonicity, the spinning
// burr's walk and vibration, passivity and bit-for-bit lockstep.
#include <dm/haptics/bone_placement.hpp>
#include <dm/haptics/burr.hpp>
#include <dm/haptics/safety.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <functional>
#include <numbers>

#include "haptics_test_support.hpp"

namespace dm {
namespace burr_test {

constexpr double kH = 0.25e-3;  // m, voxel
constexpr double kR = 1.0e-3;   // m, burr radius
constexpr int kN = 48;          // voxels a side, centred on the origin

std::shared_ptr<MillableVolume> bone(const std::function<double(const Vec3&)>& sdf, MillingMaterial m = {}) {
  Affine3 a = Affine3::Identity();
  a.linear() = Mat3::Identity() * kH;
  a.translation() = Vec3::Constant(-0.5 * (kN - 1) * kH);
  auto v = Volume::create(Vec3i(kN, kN, kN), VoxelType::F32, a);
  EXPECT_TRUE(v.ok());
  for (int k = 0; k < kN; ++k)
    for (int j = 0; j < kN; ++j)
      for (int i = 0; i < kN; ++i) v->setValue(i, j, k, sdf(a * Vec3(i, j, k)));
  auto b = MillableVolume::fromSdf(*v, std::move(m));
  EXPECT_TRUE(b.ok());
  return std::make_shared<MillableVolume>(std::move(*b));
}

std::shared_ptr<MillableVolume> slab(double top, MillingMaterial m = {}) {
  return bone([top](const Vec3& p) { return p.z() - top; }, std::move(m));
}

std::unique_ptr<BurrRenderer> burr(std::shared_ptr<MillableVolume> b, BurrOptions o) {
  auto r = BurrRenderer::create(std::move(b), std::move(o));
  EXPECT_TRUE(r.ok()) << (r.ok() ? "" : r.error().message());
  return std::move(*r);
}

BurrOptions still() { return {.tool = MillingTool::sphere(kR), .stiffness = 1000.0, .rpm = 0.0}; }

double angleDeg(const Vec3& a, const Vec3& b) {
  return std::atan2(a.cross(b).norm(), a.dot(b)) * 180.0 / std::numbers::pi;
}

HapticInput sample(const Vec3& p, std::int64_t tick, const Mat3& r = Mat3::Identity()) {
  return {.timeNs = tick * 1000000LL, .dt = test::kDt, .devicePose = test::at(p, r)};
}

TEST(BurrRenderer, OnFlatBoneTheForceIsTheNormalSpring) {
  const double top = 0.37 * kH;
  auto r = burr(slab(top), still());
  const Vec3 start(0.13e-3, -0.21e-3, 3e-3);
  r->reset(test::at(start));
  std::int64_t t = 0;
  // Press 0.5 mm below the resting height, then slide 2 mm across.
  const double deviceZ = top + kR - 0.5e-3;
  for (int i = 1; i <= 60; ++i)
    r->tick(sample(start + (Vec3(start.x(), start.y(), deviceZ) - start) * (i / 60.0), ++t));
  for (int i = 0; i <= 400; ++i) {
    const Vec3 device(start.x() + 2e-3 * i / 400.0, start.y() + 0.7e-3 * i / 400.0, deviceZ);
    const HapticResponse out = r->tick(sample(device, ++t));
    if (i % 40 != 0) continue;
    EXPECT_LT(angleDeg(out.force, Vec3::UnitZ()), 2.0) << i;
    EXPECT_NEAR(out.proxyPose.translation().z(), top + kR, kH / 8) << i;  // resting on the 0.5 level
    EXPECT_NEAR(out.force.z(), 1000.0 * 0.5e-3, 1000.0 * kH / 8) << i;
    EXPECT_EQ(out.contacts, 1);
    // Frictionless: the proxy is over the device, off only by the contact
    // normal's lattice tilt (≤ 0.5°, MillableVolume's test) over the 0.5 mm.
    const Vec3 off = out.proxyPose.translation() - device;
    EXPECT_LT(std::hypot(off.x(), off.y()), 0.5e-3 * std::tan(0.5 * std::numbers::pi / 180.0)) << i;
  }
}

TEST(BurrRenderer, OnCurvedBoneTheForceIsRadial) {
  const double rb = 3e-3;
  auto r = burr(bone([rb](const Vec3& p) { return p.norm() - rb; }), still());
  for (const Vec3& dir : {Vec3(0, 0, 1), Vec3(1, 1, 0), Vec3(0.3, -0.5, 0.8), Vec3(-0.6, 0.2, -0.4)}) {
    const Vec3 u = dir.normalized();
    r->reset(test::at(u * 5.5e-3));
    std::int64_t t = 0;
    HapticResponse out;
    for (int i = 1; i <= 100; ++i)
      out = r->tick(sample(u * (5.5e-3 - (5.5e-3 - (rb + kR - 0.4e-3)) * std::min(1.0, i / 60.0)), ++t));
    EXPECT_LT(angleDeg(out.force, u), 2.0) << dir.transpose();
    EXPECT_NEAR(out.proxyPose.translation().norm(), rb + kR, kH / 4) << dir.transpose();
  }
}

TEST(BurrRenderer, AOneVoxelPlateHoldsAt05MetresPerSecond) {
  // One layer of full voxels at z = 0 (the SDF |z| − h/2 fills exactly it).
  auto plate = bone([](const Vec3& p) { return std::abs(p.z() - 0.5 * kH) - 0.5 * kH; });
  auto r = burr(plate, still());
  const Vec3 from(0.1e-3, 0.05e-3, 4e-3);
  r->reset(test::at(from));
  HapticResponse out;
  for (int i = 1; i <= 40; ++i) {  // 0.5 mm a tick, through the plate and 4 mm past it
    out = r->tick(sample(from - Vec3(0, 0, 0.5e-3 * std::min(i, 16)), i));
    EXPECT_GT(out.proxyPose.translation().z(), 0.5 * kH + kR - kH / 4) << i;  // above the plate
  }
  EXPECT_LT(angleDeg(out.force, Vec3::UnitZ()), 2.0);
  EXPECT_GT(out.force.z(), 1000.0 * 4e-3);       // the spring over the 4 mm the hand went through
  EXPECT_EQ(plate->changedBlocks().size(), 0u);  // a still burr removes nothing
}

TEST(BurrRenderer, TheCavityIsTheSweptVolumeOfTheBurr) {
  auto b = slab(0.0, {.name = "bone", .hardness = 0.05e9});
  BurrOptions o = still();
  o.rpm = 80000.0;
  o.vibrationAmplitude = 0.0;
  o.walkCoefficient = 0.0;
  auto r = burr(b, o);
  // Down at x = −2 mm to 0.6 mm deep, then along x to +2 mm at 5 mm/s, then hold.
  const Vec3 above(-2e-3, 0.0, 2e-3), down(-2e-3, 0.0, -0.6e-3), end(2e-3, 0.0, -0.6e-3);
  r->reset(test::at(above));
  std::int64_t t = 0;
  for (int i = 1; i <= 1000; ++i) r->tick(sample(above + (down - above) * std::min(1.0, i / 500.0), ++t));
  for (int i = 1; i <= 800; ++i) r->tick(sample(down + (end - down) * (i / 800.0), ++t));
  HapticResponse last;
  for (int i = 0; i < 500; ++i) last = r->tick(sample(end, ++t));
  EXPECT_LT((last.proxyPose.translation() - end).norm(), kH / 4);  // the burr cut its way to the end
  auto pathDistance = [&](const Vec3& p) {
    auto seg = [&p](const Vec3& a, const Vec3& c) {
      const Vec3 d = c - a;
      const double s = std::clamp((p - a).dot(d) / d.squaredNorm(), 0.0, 1.0);
      return (p - a - s * d).norm();
    };
    return std::min(seg(above, down), seg(down, end));
  };
  int removed = 0;
  for (int k = 0; k < kN; ++k)
    for (int j = 0; j < kN; ++j)
      for (int i = 0; i < kN; ++i) {
        const Vec3 p = Vec3(i, j, k) * kH - Vec3::Constant(0.5 * (kN - 1) * kH);
        const double was = std::clamp(0.5 - p.z() / kH, 0.0, 1.0), o2 = b->occupancy(i, j, k),
                     d = pathDistance(p);
        if (d > kR + kH) {
          EXPECT_NEAR(o2, was, 1e-4) << "cut where the burr never was: " << p.transpose();
        }
        if (d < kR - kH && was >= 0.5) {
          EXPECT_LT(o2, 0.5) << "left inside the swept volume: " << p.transpose();
          ++removed;
        }
      }
  EXPECT_GT(removed, 500);
  // The accounting matches the grid.
  EXPECT_NEAR(b->removedVolume(0), slab(0.0)->materialVolume() - b->materialVolume(), 1e-15);
}

// Volume removed by pressing the spinning burr for 150 ticks with the device
// `depth` below the surface.
double removedAfterPressing(double depth, double rpm, double hardness) {
  auto b = slab(0.0, {.name = "bone", .hardness = hardness});
  BurrOptions o = still();
  o.rpm = rpm;
  auto r = burr(b, o);
  r->reset(test::at(Vec3(0, 0, 2e-3)));
  for (int i = 1; i <= 150; ++i)
    r->tick(sample(Vec3(0, 0, 2e-3 - (2e-3 - kR + depth) * std::min(1.0, i / 20.0)), i));
  return b->removedVolume(0);
}

TEST(BurrRenderer, RemovalIsMonotoneInForceSpeedAndSoftness) {
  const double base = removedAfterPressing(0.3e-3, 40000, 0.5e9);
  EXPECT_GT(base, 0.0);
  EXPECT_GT(removedAfterPressing(0.6e-3, 40000, 0.5e9), base);
  EXPECT_GT(removedAfterPressing(0.3e-3, 80000, 0.5e9), base);
  EXPECT_LT(removedAfterPressing(0.3e-3, 40000, 1.0e9), base);
  EXPECT_EQ(removedAfterPressing(0.3e-3, 0, 0.5e9), 0.0);
}

TEST(BurrRenderer, TheSpinningBurrWalksAndVibrates) {
  // Shaft along +x (the tool's local z turned onto x); pressed on z = 0.
  const Mat3 shaftOnX = AngleAxis(0.5 * std::numbers::pi, Vec3::UnitY()).toRotationMatrix();
  BurrOptions o = still();
  o.rpm = 60000.0;
  o.wearCoefficient = 0.0;  // no removal: the normal force stays put
  o.walkCoefficient = 0.3;
  o.vibrationAmplitude = 0.0;
  auto r = burr(slab(0.0), o);
  const Vec3 device(0, 0, kR - 0.5e-3);
  r->reset(test::at(Vec3(0, 0, 2e-3), shaftOnX));
  HapticResponse out;
  for (int i = 1; i <= 100; ++i)
    out = r->tick(
        sample(Vec3(0, 0, 2e-3) + (device - Vec3(0, 0, 2e-3)) * std::min(1.0, i / 30.0), i, shaftOnX));
  // ω̂ × n = x × z = −y.
  EXPECT_NEAR(out.force.y(), -0.3 * out.force.z(), 1e-3 * out.force.z());
  EXPECT_NEAR(out.force.x(), 0.0, 1e-3 * out.force.z());

  o.walkCoefficient = 0.0;
  o.vibrationAmplitude = 0.1;
  o.vibrationHz = 160.0;
  auto v = burr(slab(0.0), o);
  v->reset(test::at(device + Vec3(0, 0, 1e-3), shaftOnX));
  double lo = 1e9, hi = -1e9, fn = 0.0;
  for (int i = 1; i <= 200; ++i) {
    out = v->tick(sample(device, i, shaftOnX));
    if (i <= 50) continue;
    lo = std::min(lo, out.force.z());
    hi = std::max(hi, out.force.z());
    fn = v->lastTick().normalForce;
  }
  // Samples of sin(2π·160 Hz·t) at 1 kHz reach ±sin(2π·0.24).
  EXPECT_NEAR(hi - lo, 2.0 * 0.1 * fn * std::sin(2 * std::numbers::pi * 0.24), 1e-3 * fn);
  EXPECT_NEAR(0.5 * (hi + lo), fn, 1e-3 * fn);
}

TEST(BurrRenderer, AStillBurrWithDampingAboveKTOver2IsPassive) {
  // Loops into the bone and out: the sampled spring alone returns energy
  // (Colgate & Schenkel); with b = K·T > K·T/2 it does not.
  std::vector<Isometry3> path;
  for (int i = 0; i <= 2000; ++i) {
    const double a = 2 * std::numbers::pi * i / 1000.0;
    path.push_back(
        test::at(Vec3(1.5e-3 * std::cos(a), 0.4e-3 * std::sin(3 * a), kR + 0.2e-3 - 0.8e-3 * std::sin(a))));
  }
  auto bare = burr(slab(0.0), still());
  BurrOptions damped = still();
  damped.damping = damped.stiffness * test::kDt;
  auto passive = burr(slab(0.0), damped);
  EXPECT_GT(pathWork(*bare, path, test::kDt), 1e-7);
  EXPECT_LE(pathWork(*passive, path, test::kDt), 1e-12);
}

TEST(BurrRenderer, TheBoneCarriesItsFrame) {
  // The slab tilted 30° about x and moved: the force follows its normal.
  auto r = burr(slab(0.0), still());
  Isometry3 pose =
      test::at(Vec3(0.01, -0.02, 0.03), AngleAxis(std::numbers::pi / 6, Vec3::UnitX()).toRotationMatrix());
  r->setObjectPose(0, pose);
  const Vec3 n = pose.linear() * Vec3::UnitZ();
  r->reset(test::at(pose * Vec3(0, 0, 3e-3)));
  HapticResponse out;
  for (int i = 1; i <= 80; ++i)
    out = r->tick(sample(pose * Vec3(0, 0, 3e-3 - (2e-3 + 0.5e-3) * std::min(1.0, i / 50.0)), i));
  EXPECT_LT(angleDeg(out.force, n), 2.0);
  EXPECT_NEAR(out.force.norm(), 1000.0 * 0.5e-3, 1000.0 * kH / 8);
}

TEST(BurrRenderer, LockstepDrillingIsBitReproducible) {
  auto run = [](std::vector<Vec3>& forces) {
    auto b = slab(0.0, {.name = "bone", .hardness = 0.1e9});
    BurrOptions o = still();
    o.rpm = 70000.0;
    auto r = burr(b, o);
    r->reset(test::at(Vec3(0, 0, 2e-3)));
    for (int i = 1; i <= 600; ++i) {
      const double s = i / 600.0;
      forces.push_back(
          r->tick(sample(Vec3(1.5e-3 * std::sin(6 * s), 1e-3 * s, 2e-3 - 2.6e-3 * std::min(1.0, 3 * s)), i))
              .force);
    }
    auto v = b->occupancyVolume();
    return std::vector<std::byte>(v->bytes(), v->bytes() + v->byteSize());
  };
  std::vector<Vec3> f1, f2;
  const auto v1 = run(f1), v2 = run(f2);
  ASSERT_EQ(f1.size(), f2.size());
  EXPECT_EQ(std::memcmp(f1.data(), f2.data(), f1.size() * sizeof(Vec3)), 0);
  EXPECT_EQ(v1, v2);
  EXPECT_NE(v1, std::vector<std::byte>(v1.size()));  // something was there, and
  double removed = 0.0;                              // something was drilled
  for (const Vec3& f : f1) removed += f.norm();
  EXPECT_GT(removed, 0.0);
}

// Drills straight down at the origin until the burr's centre is at `depth`
// below the surface of a slab with a nerve (a forbidden cylinder along x,
// radius 0.5 mm, axis 2 mm deep); the renderer after.
std::unique_ptr<BurrRenderer> drillTowardNerve(double depth) {
  auto b = slab(0.0, {.name = "bone", .hardness = 0.05e9});
  Affine3 a = Affine3::Identity();
  a.linear() = Mat3::Identity() * kH;
  a.translation() = Vec3::Constant(-0.5 * (kN - 1) * kH);
  auto labels = Volume::create(Vec3i(kN, kN, kN), VoxelType::U8, a);
  EXPECT_TRUE(labels.ok());
  for (int k = 0; k < kN; ++k)
    for (int j = 0; j < kN; ++j)
      for (int i = 0; i < kN; ++i) {
        const Vec3 p = a * Vec3(i, j, k);
        labels->setValue(i, j, k, std::hypot(p.y(), p.z() + 2e-3) < 0.5e-3 ? 1.0 : 0.0);
      }
  EXPECT_TRUE(b->setMaterials({{.name = "bone", .hardness = 0.05e9},
                               {.name = "nerve", .hardness = 0.05e9, .forbidden = true}},
                              &*labels)
                  .ok());
  auto mask = b->forbiddenMask();
  EXPECT_TRUE(mask.ok());
  auto nerve = VoxelModel::fromOccupancy(*mask, 0.5);
  EXPECT_TRUE(nerve.ok());
  BurrOptions o = still();
  o.rpm = 80000.0;
  o.critical = {*nerve};
  o.warningDistance = 0.5e-3;
  auto r = burr(b, o);
  const Vec3 above(0, 0, 2e-3), bottom(0, 0, -depth);
  r->reset(test::at(above));
  for (int i = 1; i <= 2500; ++i) r->tick(sample(above + (bottom - above) * std::min(1.0, i / 1500.0), i));
  return r;
}

TEST(BurrRenderer, CriticalStructuresAreMeasured) {
  // Stopping 0.3 mm short of the nerve: the closest approach is that gap (to
  // the voxel model's half-voxel surface), nothing forbidden was removed, and
  // the time within 0.5 mm is the time spent there.
  auto near = drillTowardNerve(0.2e-3);
  const BurrMetrics& m = near->metrics();
  EXPECT_NEAR(m.closestApproach, 0.3e-3, 0.5 * kH);
  EXPECT_NEAR(near->lastTick().criticalDistance, 0.3e-3, 0.5 * kH);
  EXPECT_EQ(m.removedForbidden, 0.0);
  EXPECT_GT(m.removed, 0.0);
  EXPECT_GT(m.secondsWithinWarning, 0.5);  // the last second at the bottom, at least
  EXPECT_LT(m.secondsWithinWarning, 2.5);  // never more than the run
  EXPECT_EQ(m.ticks, 2500);
  // Through the nerve: inside it, and its volume removed is counted.
  auto through = drillTowardNerve(2.5e-3);
  EXPECT_LT(through->metrics().closestApproach, 0.0);
  EXPECT_GT(through->metrics().removedForbidden, 0.0);
  EXPECT_NEAR(through->metrics().removedForbidden, through->volume().removedVolume(1), 1e-15);
  EXPECT_NEAR(through->metrics().removed,
              through->volume().removedVolume(0) + through->volume().removedVolume(1), 1e-15);
}

TEST(BurrRenderer, ASawSeparatesAFragmentThatBonePlacementMoves) {
  // A 6 × 3 × 2 mm bar; a 0.4 mm saw blade (thin along x) pushed down
  // through it at x = 0.6 mm: the osteotomy made interactively.
  const Vec3 half(3e-3, 1.5e-3, 1e-3);
  auto bar = bone(
      [&half](const Vec3& p) {
        const Vec3 q = p.cwiseAbs() - half;
        return q.cwiseMax(0.0).norm() + std::min(q.maxCoeff(), 0.0);
      },
      {.name = "bone", .hardness = 0.05e9});
  BurrOptions o = still();
  o.tool = MillingTool::box(Vec3(0.2e-3, 3e-3, 3e-3));
  o.cuttingRadius = 0.02;  // a sagittal saw's blade 20 mm from its pivot
  o.rpm = 12000.0;
  auto saw = burr(bar, o);
  const Vec3 above(0.6e-3, 0, 4.5e-3), below(0.6e-3, 0, -4.5e-3);
  saw->reset(test::at(above));
  HapticResponse out;
  for (int i = 1; i <= 4000; ++i)
    out = saw->tick(sample(above + (below - above) * std::min(1.0, i / 3000.0), i));
  EXPECT_LT(out.proxyPose.translation().z(), -4e-3 + kH);  // the blade went through
  auto pieces = bar->fragments();
  ASSERT_TRUE(pieces.ok());
  ASSERT_EQ(pieces->fragments.size(), 2u);
  EXPECT_NEAR(pieces->fragments[1].centroid.x(), 1.9e-3, kH);  // the 2.2 mm piece beyond the kerf

  auto fixedVolume = bar->fragmentOccupancy(*pieces, 0), movingVolume = bar->fragmentOccupancy(*pieces, 1);
  ASSERT_TRUE(fixedVolume.ok() && movingVolume.ok());
  auto fixed = ImplicitSphereTree::create(*fixedVolume, 0.5),
       moving = ImplicitSphereTree::create(*movingVolume, 0.5);
  ASSERT_TRUE(fixed.ok() && moving.ok());
  auto place = BonePlacementRenderer::create(*fixed, Isometry3::Identity(), *moving, *movingVolume,
                                             {.threshold = 0.5});
  ASSERT_TRUE(place.ok()) << place.error().message();
  // Held where it was cut, the fragment sits in its place against the other.
  (*place)->reset(Isometry3::Identity());
  for (int i = 1; i <= 200; ++i) out = (*place)->tick(sample(Vec3::Zero(), i));
  EXPECT_LT(out.proxyPose.translation().norm(), kH);
  EXPECT_TRUE(out.force.allFinite());
}

TEST(BurrRenderer, BadOptionsAreNamed) {
  auto b = slab(0.0);
  BurrOptions o = still();
  o.stiffness = -1.0;
  auto e = BurrRenderer::create(b, o);
  ASSERT_FALSE(e.ok());
  EXPECT_EQ(e.error().where, "burr/stiffness");
  o = still();
  o.tool = MillingTool::box(Vec3(5e-3, 0.3e-3, 2e-3));
  e = BurrRenderer::create(b, o);
  ASSERT_FALSE(e.ok());
  EXPECT_EQ(e.error().where, "burr/cutting_radius");
  o.cuttingRadius = 0.02;
  EXPECT_TRUE(BurrRenderer::create(b, o).ok());
  o = still();
  o.tool.radius = std::nan("");
  e = BurrRenderer::create(b, o);
  ASSERT_FALSE(e.ok());
  EXPECT_EQ(e.error().where, "burr/tool/radius");
  o = still();
  o.warningDistance = -1.0;
  e = BurrRenderer::create(b, o);
  ASSERT_FALSE(e.ok());
  EXPECT_EQ(e.error().where, "burr/warning_distance");
  o = still();
  o.critical = {nullptr};
  e = BurrRenderer::create(b, o);
  ASSERT_FALSE(e.ok());
  EXPECT_EQ(e.error().where, "burr/critical/0");
  EXPECT_FALSE(BurrRenderer::create(nullptr, still()).ok());
}

}  // namespace burr_test
}  // namespace dm
