// A needle felt through dm::HapticNeedle, ticked at 1 kHz against FEM tissue
// stepped at 100 Hz (lockstep, one thread): the hand feels the pop in the
// tick the tip's force reaches the membrane's threshold, then the cutting
// force and the friction the physics computes; the force is clamped and
// NaN-guarded; a tick allocates nothing; bad options are named.
#include <dm/haptics/needle.hpp>
#include <dm/physics/fem.hpp>
#include <dm/physics/needle.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "../common/alloc_counter.hpp"
#include "haptics_test_support.hpp"

namespace dm {
namespace {

using dm::test::at;

// A 40 × 40 × 30 mm block of 5 mm cells, base fixed, one layer.
struct Tissue {
  FemBody body;
  std::vector<std::uint8_t> layerOf;
};
Tissue makeTissue() {
  auto mesh = tetMeshBox({8, 8, 6}, Vec3(0.04, 0.04, 0.03));
  EXPECT_TRUE(mesh.ok());
  auto body = FemBody::create(*mesh, {.youngsModulus = 3e4, .poissonRatio = 0.45, .density = 1000.0},
                              {.alpha = 30.0, .beta = 0.002});
  EXPECT_TRUE(body.ok());
  body->fixNodesWhere([](const Vec3& p) { return p.z() < 1e-9; });
  return {std::move(*body), std::vector<std::uint8_t>(mesh->tets.size(), 0)};
}

const NeedleLayer kTissue{.punctureForce = 1.0, .cuttingForce = 0.3, .friction = 40.0};
// The needle points down the device's −z; the tissue is moved 10 cm along x
// in the world, so the frames differ.
const Isometry3 kTissuePose = at(Vec3(0.1, 0.0, 0.0));
const Vec3 kEntryWorld = Vec3(0.1203, 0.0196, 0.03);

// Device pose with the needle's tip `depth` below the block's top.
Isometry3 deviceAt(double depth) { return at(kEntryWorld + Vec3(0, 0, -depth)); }

TEST(HapticNeedle, PopIsFeltInTheTickItHappensThenCuttingAndFriction) {
  Tissue t = makeTissue();
  auto needle = NeedleInsertion::create(t.body, t.layerOf, {&kTissue, 1});
  ASSERT_TRUE(needle.ok());
  auto felt = HapticNeedle::create(*needle, {.tissuePose = kTissuePose, .maxForce = 8.0});
  ASSERT_TRUE(felt.ok()) << felt.error().message();
  // 10 mm/s for 1.8 s: 1 kHz ticks, a 10 ms physics step every 10 ticks.
  std::vector<double> felt1k, physics;
  int popTick = -1;
  std::size_t punctures = 0;
  for (int i = 0; i < 1800; ++i) {
    const double depth = -0.002 + 1e-5 * i;
    const HapticResponse r = (*felt)->tick({.dt = 1e-3, .devicePose = deviceAt(depth)});
    felt1k.push_back(r.force.z());  // up: resists the insertion
    if (i % 10 == 9) {
      ASSERT_TRUE((*felt)->step(0.01).ok());
      physics.push_back(needle->force().z());
      if (needle->punctureCount() > punctures && popTick < 0) popTick = i;
      punctures = needle->punctureCount();
    }
  }
  ASSERT_EQ(needle->punctureCount(), 1u);
  // The peak the hand feels is the threshold (within a tick's travel of the
  // tip's spring, 2000 N/m × 10 µm), and it falls in the next tick.
  const auto peak = std::max_element(felt1k.begin(), felt1k.end());
  const std::size_t p = std::size_t(peak - felt1k.begin());
  EXPECT_GE(*peak, 0.97 * kTissue.punctureForce);
  EXPECT_LE(*peak, 1.03 * kTissue.punctureForce);
  ASSERT_LT(p + 1, felt1k.size());
  EXPECT_LT(felt1k[p + 1], *peak - 0.5) << "the pop must be felt at once";
  // The hand felt it no later than the physics broke the membrane.
  EXPECT_LE(int(p), popTick);
  // Before the pop (but for the step of first contact, before which the
  // model knows nothing of the tissue's stiffness and lets it yield), and
  // from 1 mm past it on (the tissue springs back over a few steps there,
  // which the frozen model learns step by step), the
  // ticks follow the physics: the tick before each step, at the pose that
  // step takes, evaluates the model of the step before, 0.1 mm behind; it
  // differs from what the step then computes by much less than one step's
  // change of force (0.02 N while pressing).
  double worst = 0.0;
  for (std::size_t s = 0; s < physics.size(); ++s) {
    const std::size_t tick = 10 * s + 9;
    if (tick + 10 >= p && tick < p + 100) continue;
    if (s > 0 && physics[s - 1] == 0.0)
      continue;  // the first step in contact: the tissue's stiffness is not known yet
    worst = std::max(worst, std::abs(felt1k[tick] - physics[s]));
  }
  EXPECT_LT(worst, 0.01);
  // And the force grows with depth: friction, f_cut + μL.
  EXPECT_GT(felt1k.back(), kTissue.cuttingForce + 0.8 * kTissue.friction * 0.01);
}

// A curved needle (R = 10 mm) mounted on the device with its tip 5 mm off
// the device point, its axis along the device's −y and its centre toward
// the device's +z, turned about its centre: at the step's own pose the
// hand feels exactly the physics' force and torque (moved to the world and
// about the device point), so the mounting's frames are right.
TEST(HapticNeedle, CurvedNeedleMountedOffTheDevicePointFeelsThePhysicsAtItsPose) {
  Tissue t = makeTissue();
  const double R = 0.01;
  auto needle = NeedleInsertion::create(t.body, t.layerOf, {&kTissue, 1}, {.length = 0.03, .radius = R});
  ASSERT_TRUE(needle.ok());
  const Vec3 tipInDevice(0.0, 0.0, 0.005), axis(0, -1, 0), normal(0, 0, 1);
  auto felt = HapticNeedle::create(*needle, {.tip = tipInDevice,
                                             .axis = axis,
                                             .normal = normal,
                                             .tissuePose = kTissuePose,
                                             .maxForce = 100.0,
                                             .maxTorque = 100.0});
  ASSERT_TRUE(felt.ok());
  // The needle's frame in the world at turn θ: tip on the circle about a
  // centre 5 mm above the block, in the world's xz plane.
  const Vec3 centre = kEntryWorld + Vec3(0, 0, 0.005);
  Isometry3 mount = Isometry3::Identity();  // needle frame in the device frame
  mount.linear().col(0) = normal, mount.linear().col(1) = axis.cross(normal), mount.linear().col(2) = axis;
  mount.translation() = tipInDevice;
  int compared = 0;
  for (int i = 0; i < 1500; ++i) {
    const double theta = 0.3 + 1e-3 * i;
    const Vec3 tangent(std::sin(theta), 0.0, -std::cos(theta)),
        toCentre(std::cos(theta), 0.0, std::sin(theta));
    Isometry3 needlePose = Isometry3::Identity();
    needlePose.linear().col(0) = toCentre, needlePose.linear().col(1) = tangent.cross(toCentre);
    needlePose.linear().col(2) = tangent;
    needlePose.translation() = centre - R * toCentre;
    const Isometry3 device = needlePose * mount.inverse();
    (*felt)->tick({.dt = 1e-3, .devicePose = device});
    if (i % 10 != 0) continue;
    // A step at this tick's pose, then a tick at the same pose with the
    // model it published (but at the puncture's step: see NeedleLocalModel).
    const std::size_t punctures = needle->punctureCount();
    ASSERT_TRUE((*felt)->step(0.01).ok());
    const HapticResponse r = (*felt)->tick({.dt = 1e-3, .devicePose = device});
    if (needle->punctureCount() != punctures) continue;
    const Vec3 force = kTissuePose.linear() * needle->force();
    const Vec3 torque = kTissuePose.linear() * needle->wrench().torque +
                        (needlePose.translation() - device.translation()).cross(force);
    ASSERT_LT((r.force - force).norm(), 1e-9) << "tick " << i;
    ASSERT_LT((r.torque - torque).norm(), 1e-11) << "tick " << i;
    compared += needle->activeCouplingCount() > 0;
  }
  EXPECT_EQ(needle->punctureCount(), 1u);
  EXPECT_GT(compared, 50);
}

TEST(HapticNeedle, ForceIsClampedAndNotFiniteIsZero) {
  Tissue t = makeTissue();
  auto needle = NeedleInsertion::create(t.body, t.layerOf, {&kTissue, 1});
  ASSERT_TRUE(needle.ok());
  auto felt = HapticNeedle::create(*needle, {.tissuePose = kTissuePose, .maxForce = 0.4, .maxTorque = 0.0});
  ASSERT_TRUE(felt.ok());
  HapticResponse r;
  for (int i = 0; i < 600; ++i) {
    r = (*felt)->tick({.dt = 1e-3, .devicePose = deviceAt(-0.002 + 1e-5 * i)});
    if (i % 10 == 9) {
      ASSERT_TRUE((*felt)->step(0.01).ok());
    }
    ASSERT_LE(r.force.norm(), 0.4 + 1e-12);
    ASSERT_EQ(r.torque.norm(), 0.0);
  }
  EXPECT_NEAR(r.force.norm(), 0.4, 1e-12);  // pressing harder than the limit
  Isometry3 bad = deviceAt(0.001);
  bad.translation().x() = NAN;
  r = (*felt)->tick({.dt = 1e-3, .devicePose = bad});
  EXPECT_EQ(r.force, Vec3::Zero());
  EXPECT_TRUE(r.torque.allFinite());
}

TEST(HapticNeedle, TickAllocatesNothing) {
  Tissue t = makeTissue();
  auto needle = NeedleInsertion::create(t.body, t.layerOf, {&kTissue, 1}, {.couplingSpacing = 5e-4});
  ASSERT_TRUE(needle.ok());
  auto felt = HapticNeedle::create(*needle, {.tissuePose = kTissuePose});
  ASSERT_TRUE(felt.ok());
  std::uint64_t counted = 0;
  for (int i = 0; i < 1200; ++i) {
    test::tCountAllocations = true;
    const auto before = test::countedAllocations();
    (*felt)->tick({.dt = 1e-3, .devicePose = deviceAt(-0.002 + 1e-5 * i)});
    counted += test::countedAllocations() - before;
    test::tCountAllocations = false;
    if (i % 10 == 9) {
      ASSERT_TRUE((*felt)->step(0.01).ok());
    }
  }
  EXPECT_EQ(counted, 0u);
  EXPECT_GT(needle->activeCouplingCount(), 10u);  // the ticks had points to evaluate
}

TEST(HapticNeedle, BadOptionsAreNamed) {
  Tissue t = makeTissue();
  auto needle = NeedleInsertion::create(t.body, t.layerOf, {&kTissue, 1});
  ASSERT_TRUE(needle.ok());
  const auto message = [&](const HapticNeedleOptions& o) {
    auto r = HapticNeedle::create(*needle, o);
    return r.ok() ? std::string("(accepted)") : r.error().message() + " " + r.error().where;
  };
  EXPECT_NE(message({.axis = Vec3::Zero()}).find("options.axis"), std::string::npos);
  EXPECT_NE(message({.tip = Vec3(NAN, 0, 0)}).find("options.tip"), std::string::npos);
  EXPECT_NE(message({.normal = Vec3(0, 0, 2)}).find("options.normal"), std::string::npos);  // along the axis
  EXPECT_NE(message({.maxForce = 0.0}).find("options.maxForce"), std::string::npos);
  EXPECT_NE(message({.maxTorque = NAN}).find("options.maxTorque"), std::string::npos);
  Isometry3 sheared = Isometry3::Identity();
  sheared.linear()(0, 1) = 0.5;
  EXPECT_NE(message({.tissuePose = sheared}).find("options.tissuePose"), std::string::npos);
}

}  // namespace
}  // namespace dm
