// BonePlacementRenderer (dm/haptics/bone_placement.hpp) against ground
// truth: voxel mass properties equal the continuous box's; a box of voxels
// pushed by the device onto another never sinks in by more than a leaf
// sphere radius and the user feels k·(device − fragment) pointing out of the
// fixed box; the fragment slides sideways along the face (no friction); the
// two halves of a voxel block cut by an oblique plane are brought back
// together by a device path within one voxel of alignment; the tick is
// allocation-free, deterministic and NaN-guarded; create() names bad fields.
#include <dm/core/volume.hpp>
#include <dm/haptics/bone_placement.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <functional>
#include <limits>
#include <numbers>
#include <utility>
#include <vector>

#include "../common/alloc_counter.hpp"

namespace dm {
namespace {

constexpr double kVoxel = 1e-3;  // m
constexpr int kN = 20;           // voxels per axis

Volume labels(const std::function<bool(int, int, int)>& inside) {
  auto v = Volume::create(Vec3i(kN, kN, kN), VoxelType::U8, Affine3(Eigen::Scaling(kVoxel)));
  EXPECT_TRUE(v.ok());
  for (int k = 0; k < kN; ++k)
    for (int j = 0; j < kN; ++j)
      for (int i = 0; i < kN; ++i) v->setValue(i, j, k, inside(i, j, k) ? 1 : 0);
  return std::move(*v);
}

std::shared_ptr<const ImplicitSphereTree> treeOf(const Volume& v) {
  auto t = ImplicitSphereTree::create(v, 0.5);
  EXPECT_TRUE(t.ok());
  return *t;
}

Isometry3 translation(const Vec3& t) {
  Isometry3 p = Isometry3::Identity();
  p.translation() = t;
  return p;
}

BonePlacementOptions testOptions() {
  BonePlacementOptions o;
  o.threshold = 0.5;
  o.maxForce = std::numeric_limits<double>::infinity();
  o.maxTorque = std::numeric_limits<double>::infinity();
  o.maxContacts = 4096;  // every pair of a 20 × 20 face: no direction left unconstrained
  return o;
}

struct Boxes {
  Volume box = labels([](int, int, int) { return true; });
  std::shared_ptr<const ImplicitSphereTree> tree = treeOf(box);
  // Voxel cubes span [-0.5, 19.5] mm: the fixed box's top face is z = 19.5 mm,
  // the moving box (same frame) translated by tz has its bottom at tz − 0.5 mm.
  std::unique_ptr<BonePlacementRenderer> make(const BonePlacementOptions& o = testOptions()) const {
    auto r = BonePlacementRenderer::create(tree, Isometry3::Identity(), tree, box, o);
    EXPECT_TRUE(r.ok()) << r.error();
    return std::move(*r);
  }
};

// Drives `r` from its pose along the straight line to `to` over `ramp` ticks,
// then holds `to` for `hold` ticks; `each` sees every response.
// Σ impulse·normal / dt of the last tick's contacts: the contact force on the fragment.
Vec3 contactForce(const BonePlacementRenderer& r) {
  Vec3 sum = Vec3::Zero();
  for (const BoneContact& c : r.contacts()) sum += c.impulse * c.normal;
  return sum / 1e-3;
}

HapticResponse drive(BonePlacementRenderer& r, const Isometry3& from, const Isometry3& to, int ramp, int hold,
                     const std::function<void(const HapticResponse&)>& each = {}) {
  const Quat q0(from.linear()), q1(to.linear());
  HapticResponse out;
  for (int t = 1; t <= ramp + hold; ++t) {
    const double s = std::min(1.0, static_cast<double>(t) / ramp);
    Isometry3 pose = Isometry3::Identity();
    pose.linear() = q0.slerp(s, q1).toRotationMatrix();
    pose.translation() = (1 - s) * from.translation() + s * to.translation();
    out = r.tick({.timeNs = t * 1000000, .dt = 1e-3, .devicePose = pose});
    if (each) each(out);
  }
  return out;
}

TEST(BonePlacement, VoxelMassPropertiesEqualTheContinuousBox) {
  const Volume v = labels([](int i, int j, int k) { return i < 20 && j < 10 && k < 4; });
  const double density = 1900.0;
  auto mp = voxelMassProperties(v, 0.5, density);
  ASSERT_TRUE(mp.ok()) << mp.error();
  const double a = 20 * kVoxel, b = 10 * kVoxel, c = 4 * kVoxel;
  const double m = density * a * b * c;
  EXPECT_EQ(mp->voxels, 800u);
  EXPECT_NEAR(mp->mass, m, 1e-12 * m);
  EXPECT_LT((mp->centerOfMass - Vec3(9.5, 4.5, 1.5) * kVoxel).norm(), 1e-12);
  const Vec3 expected(m / 12 * (b * b + c * c), m / 12 * (a * a + c * c), m / 12 * (a * a + b * b));
  for (int d = 0; d < 3; ++d) EXPECT_NEAR(mp->inertia(d, d), expected[d], 1e-9 * expected[d]) << d;
  EXPECT_LT((mp->inertia - Mat3(expected.asDiagonal())).norm(), 1e-9 * expected.norm());
}

TEST(BonePlacement, PushedBoxStopsAtTheFaceAndTheUserFeelsTheCoupling) {
  const Boxes boxes;
  auto r = boxes.make();
  const double leafRadius = 0.5 * std::sqrt(3.0) * kVoxel;
  const Isometry3 start = translation({0.0003, -0.0002, 0.025});
  const Isometry3 pressed = translation({0.0003, -0.0002, 0.018});  // 2 mm into the fixed box
  r->reset(start);
  double worst = 0.0;
  const HapticResponse out = drive(*r, start, pressed, 250, 350, [&](const HapticResponse& o) {
    const double bottom = o.proxyPose.translation().z() - 0.5 * kVoxel;
    worst = std::max(worst, 19.5 * kVoxel - bottom);
  });
  EXPECT_LE(worst, leafRadius) << "the fragment sank into the fixed box";
  EXPECT_GT(out.contacts, 0);
  const Vec3 offset = pressed.translation() - out.proxyPose.translation();
  const double k = r->options().couplingStiffness;
  EXPECT_GT(offset.norm(), 1e-3);
  // Force = −k·(device − fragment) at rest, pointing out of the fixed box
  // (+z, tilted at most by the slope of the leaf-sphere bumps) along the
  // contact force on the fragment, Σ impulse·normal.
  EXPECT_LT((out.force + k * offset).norm(), 0.01 * k * offset.norm());
  EXPECT_NEAR(out.force.norm(), k * offset.norm(), 0.01 * k * offset.norm());
  EXPECT_GT(out.force.normalized().z(), 0.97);
  EXPECT_GT(out.force.normalized().dot(contactForce(*r).normalized()), 0.999);
  EXPECT_LT(r->fragmentVelocity().norm(), 1e-3);
  EXPECT_EQ(r->stackOverflows(), 0u);
}

TEST(BonePlacement, FragmentSlidesFreelyAlongTheFace) {
  const Boxes boxes;
  auto r = boxes.make();
  const Isometry3 start = translation({0.0, 0.0, 0.025});
  const Isometry3 pressed = translation({0.0, 0.0, 0.019});
  const Isometry3 slid = translation({0.005, 0.003, 0.019});
  r->reset(start);
  drive(*r, start, pressed, 150, 150);
  double worst = 0.0;
  const HapticResponse out = drive(*r, pressed, slid, 400, 350, [&](const HapticResponse& o) {
    worst = std::max(worst, 20.0 * kVoxel - o.proxyPose.translation().z());
  });
  EXPECT_LE(worst, 0.5 * std::sqrt(3.0) * kVoxel);
  const Vec3 lag = slid.translation() - out.proxyPose.translation();
  // No friction: the fragment followed the device 5.8 mm sideways and lags
  // by less than one voxel (the period of the leaf-sphere bumps it rests
  // on), and the force on the user is the normal contact force alone (tilted
  // by the slope of the bumps under the fragment, never pulling into the face).
  EXPECT_LT(std::hypot(lag.x(), lag.y()), 0.75 * kVoxel) << lag.transpose();
  EXPECT_GT(out.proxyPose.translation().x(), 0.004);
  EXPECT_GT(out.force.normalized().z(), 0.5);
  EXPECT_GT(out.force.normalized().dot(contactForce(*r).normalized()), 0.999);
}

TEST(BonePlacement, SplitFragmentIsGuidedBackToTheReferencePose) {
  // A 20³ block cut by the plane i + j/2 = 14 (voxel indices): the fixed
  // half below, the moving half above, both in the block's frame, so the
  // reference pose of the moving half is the identity.
  const auto below = [](int i, int j, int) { return i + 0.5 * j <= 14.0; };
  const Volume fixedLabels = labels(below);
  const Volume movingLabels = labels([&](int i, int j, int k) { return !below(i, j, k); });
  auto r = BonePlacementRenderer::create(treeOf(fixedLabels), Isometry3::Identity(), treeOf(movingLabels),
                                         movingLabels, testOptions());
  ASSERT_TRUE(r.ok()) << r.error();
  std::vector<Vec3> reference;
  for (int k = 0; k < kN; k += 19)
    for (int j = 0; j < kN; j += 19)
      for (int i = 0; i < kN; ++i)
        if (!below(i, j, k)) reference.push_back(Vec3(i, j, k) * kVoxel);
  ASSERT_GT(reference.size(), 8u);
  Isometry3 start = translation({0.006, 0.003, 0.001});
  start.linear() = AngleAxis(10.0 * std::numbers::pi / 180.0, Vec3::UnitZ()).toRotationMatrix();
  const Isometry3 goal = Isometry3::Identity();
  (*r)->reset(start);
  EXPECT_GT((*r)->alignmentError(reference, goal), 5 * kVoxel);
  const HapticResponse out = drive(**r, start, goal, 500, 400);
  EXPECT_GT(out.contacts, 0) << "the halves should touch at the reference pose";
  EXPECT_LT((*r)->alignmentError(reference, goal), kVoxel);
  EXPECT_NEAR((*r)->alignmentError(reference, out.proxyPose), 0.0, 1e-12);
}

// The descent tests' fragments: a block of 1 mm voxels (10 × 9 × `height`
// of a 12³ grid) and a ball of 0.4 mm voxels (radius 7 voxels in a 16³
// grid) — different depths and sizes, so the level skip is exercised.
std::pair<Result<Volume>, Result<Volume>> descentVolumes(int height) {
  auto fv = Volume::create(Vec3i(12, 12, 12), VoxelType::U8, Affine3(Eigen::Scaling(kVoxel)));
  auto mv = Volume::create(Vec3i(16, 16, 16), VoxelType::U8, Affine3(Eigen::Scaling(0.4 * kVoxel)));
  if (!fv.ok() || !mv.ok()) return {std::move(fv), std::move(mv)};
  for (int k = 0; k < 12; ++k)
    for (int j = 0; j < 12; ++j)
      for (int i = 0; i < 12; ++i) fv->setValue(i, j, k, i < 10 && j < 9 && k < height ? 1 : 0);
  for (int k = 0; k < 16; ++k)
    for (int j = 0; j < 16; ++j)
      for (int i = 0; i < 16; ++i)
        mv->setValue(i, j, k, (Vec3(i, j, k) - Vec3::Constant(7.5)).norm() < 7.0 ? 1 : 0);
  return {std::move(fv), std::move(mv)};
}

TEST(BonePlacement, TreeDescentFindsExactlyTheVoxelSpheresOverlappingBeyondTheSlop) {
  // Brute force over all occupied voxel pairs (leaf sphere radius √3/2·h)
  // against the simultaneous descent, for a block of 1 mm voxels and a ball
  // of 0.4 mm voxels (different depths and sizes exercise the level skip):
  // the pairs that act, deeper than 0.9·slop, are found, and only they —
  // with the automatic slop and with none (every overlapping pair).
  auto [fv, mv] = descentVolumes(8);
  ASSERT_TRUE(fv.ok() && mv.ok());
  for (const double slop : {-1.0, 0.0}) {
    BonePlacementOptions o = testOptions();
    o.slop = slop;
    auto r = BonePlacementRenderer::create(treeOf(*fv), translation({0.0005, 0.0, 0.0}), treeOf(*mv), *mv, o);
    ASSERT_TRUE(r.ok()) << r.error();
    Isometry3 pose = translation({0.006, 0.005, 0.0065});
    pose.linear() = AngleAxis(0.4, Vec3(1, 2, 3).normalized()).toRotationMatrix();
    (*r)->reset(pose);
    (*r)->tick({.dt = 1e-3, .devicePose = pose});  // contacts are found before the pose moves
    const double margin = 0.9 * (*r)->slop();
    EXPECT_EQ((*r)->slop() > 0, slop < 0);
    std::size_t pairs = 0;
    double deepest = 0.0;
    for (int k = 0; k < 8; ++k)
      for (int j = 0; j < 9; ++j)
        for (int i = 0; i < 10; ++i) {
          const Vec3 a = Vec3(i + 0.5, j, k) * kVoxel;
          for (int mk = 0; mk < 16; ++mk)
            for (int mj = 0; mj < 16; ++mj)
              for (int mi = 0; mi < 16; ++mi) {
                if (mv->value(mi, mj, mk) <= 0.5) continue;
                const Vec3 b = pose * (Vec3(mi, mj, mk) * 0.4 * kVoxel);
                const double depth = 0.5 * std::sqrt(3.0) * 1.4 * kVoxel - (a - b).norm();
                if (depth <= margin) continue;
                ++pairs;
                deepest = std::max(deepest, depth);
              }
        }
    ASSERT_GT(pairs, 10u);
    ASSERT_LT(pairs, 4096u);
    EXPECT_EQ((*r)->contacts().size(), pairs) << "slop " << (*r)->slop();
    EXPECT_NEAR((*r)->maxContactDepth(), deepest, 1e-12);
    EXPECT_EQ((*r)->stackOverflows(), 0u);
  }
}

TEST(BonePlacement, CoarserContactLevelFindsExactlyTheCellPairsOverlappingBeyondTheSlop) {
  // contactLevel 1: the contact elements are the trees' cells one level up
  // (2³ voxels, occupied when any voxel is), brute-forced over the trees'
  // own cells; the slop is then the resting overlap of face-adjacent cells.
  auto [fv, mv] = descentVolumes(7);
  ASSERT_TRUE(fv.ok() && mv.ok());
  const auto ft = treeOf(*fv), mt = treeOf(*mv);
  BonePlacementOptions o = testOptions();
  o.contactLevel = 1;
  const Isometry3 fixedPose = translation({0.0005, 0.0, 0.0});
  auto r = BonePlacementRenderer::create(ft, fixedPose, mt, *mv, o);
  ASSERT_TRUE(r.ok()) << r.error();
  const int lf = ft->depth() - 1, lm = mt->depth() - 1;
  const double rf = ft->cellSphere(lf, 0, 0, 0).radius, rm = mt->cellSphere(lm, 0, 0, 0).radius;
  EXPECT_NEAR(rf, std::sqrt(3.0) * kVoxel, 1e-15);
  EXPECT_NEAR((*r)->slop(), rf + rm - 2 * std::min(rf, rm) / std::sqrt(3.0), 1e-15);
  Isometry3 pose = translation({0.006, 0.005, 0.0060});
  pose.linear() = AngleAxis(0.4, Vec3(1, 2, 3).normalized()).toRotationMatrix();
  (*r)->reset(pose);
  (*r)->tick({.dt = 1e-3, .devicePose = pose});
  const double margin = 0.9 * (*r)->slop();
  std::size_t pairs = 0;
  double deepest = 0.0;
  const int nf = 1 << lf, nm = 1 << lm;
  for (int k = 0; k < nf; ++k)
    for (int j = 0; j < nf; ++j)
      for (int i = 0; i < nf; ++i) {
        if (!ft->occupied(lf, i, j, k)) continue;
        const Vec3 a = fixedPose * ft->cellSphere(lf, i, j, k).center;
        for (int mk = 0; mk < nm; ++mk)
          for (int mj = 0; mj < nm; ++mj)
            for (int mi = 0; mi < nm; ++mi) {
              if (!mt->occupied(lm, mi, mj, mk)) continue;
              const double depth = rf + rm - (a - pose * mt->cellSphere(lm, mi, mj, mk).center).norm();
              if (depth <= margin) continue;
              ++pairs;
              deepest = std::max(deepest, depth);
            }
      }
  ASSERT_GT(pairs, 5u);
  EXPECT_EQ((*r)->contacts().size(), pairs);
  EXPECT_NEAR((*r)->maxContactDepth(), deepest, 1e-12);
}

TEST(BonePlacement, AtACoarserContactLevelThePushedBoxStillStopsAndTheUserFeelsTheCoupling) {
  // Cells of 2³ voxels: the 20 mm box's faces are whole cells, so it stops
  // on the face as at the voxel level (within a cell's sphere), and at rest
  // the user feels −k·offset, which the contact holds. The cell spheres'
  // bumps are twice the voxels' (2 mm period): the device, 0.3 mm off a
  // bump's top, lets the fragment slide toward the valley until the
  // coupling's sideways pull balances the bump's slope, so the force tilts
  // (here about 33°; at most the ~40° of the bumps' slope).
  const Boxes boxes;
  BonePlacementOptions o = testOptions();
  o.contactLevel = 1;
  auto r = boxes.make(o);
  const Isometry3 start = translation({0.0003, -0.0002, 0.025});
  const Isometry3 pressed = translation({0.0003, -0.0002, 0.018});
  r->reset(start);
  double worst = 0.0;
  const HapticResponse out = drive(*r, start, pressed, 250, 350, [&](const HapticResponse& resp) {
    worst = std::max(worst, 19.5 * kVoxel - (resp.proxyPose.translation().z() - 0.5 * kVoxel));
  });
  EXPECT_LE(worst, std::sqrt(3.0) * kVoxel) << "the fragment sank into the fixed box";
  EXPECT_GT(out.contacts, 0);
  const Vec3 offset = pressed.translation() - out.proxyPose.translation();
  const double k = r->options().couplingStiffness;
  EXPECT_GT(offset.norm(), 1e-3);
  EXPECT_LT((out.force + k * offset).norm(), 0.01 * k * offset.norm());
  EXPECT_GT(out.force.normalized().z(), std::cos(45.0 * std::numbers::pi / 180));
  EXPECT_GT(out.force.normalized().dot(contactForce(*r).normalized()), 0.999);
  EXPECT_LT(r->fragmentVelocity().norm(), 1e-3);
}

TEST(BonePlacement, TickIsAllocationFree) {
  const Boxes boxes;
  auto r = boxes.make();
  const Isometry3 start = translation({0.0, 0.0, 0.0205});
  r->reset(start);
  r->tick({.dt = 1e-3, .devicePose = translation({0.0, 0.0, 0.018})});
  dm::test::tCountAllocations = true;
  const auto before = dm::test::countedAllocations();
  int contacts = 0;
  for (int t = 0; t < 50; ++t)
    contacts += r->tick({.dt = 1e-3, .devicePose = translation({0.0001 * t, 0.0, 0.018})}).contacts;
  r->setObjectPose(0, translation({0.0, 0.0, -0.0001}));
  dm::test::tCountAllocations = false;
  EXPECT_EQ(dm::test::countedAllocations(), before);
  EXPECT_GT(contacts, 0);
}

TEST(BonePlacement, SameInputsGiveBitwiseSameForces) {
  const Boxes boxes;
  auto a = boxes.make();
  auto b = boxes.make();
  Isometry3 start = translation({0.001, 0.0, 0.023});
  start.linear() = AngleAxis(0.1, Vec3(1, 1, 0).normalized()).toRotationMatrix();
  a->reset(start);
  b->reset(start);
  for (int t = 0; t < 300; ++t) {
    Isometry3 pose = translation({0.001 + 1e-5 * t, 0.0, 0.023 - 2e-5 * t});
    pose.linear() = AngleAxis(0.1 - 3e-4 * t, Vec3(1, 1, 0).normalized()).toRotationMatrix();
    const HapticResponse fa = a->tick({.dt = 1e-3, .devicePose = pose});
    const HapticResponse fb = b->tick({.dt = 1e-3, .devicePose = pose});
    ASSERT_EQ(std::memcmp(fa.force.data(), fb.force.data(), sizeof(double) * 3), 0) << t;
    ASSERT_EQ(std::memcmp(fa.torque.data(), fb.torque.data(), sizeof(double) * 3), 0) << t;
  }
  EXPECT_GT(a->contacts().size(), 0u);
}

TEST(BonePlacement, NanDevicePoseGivesZeroForceAndKeepsTheState) {
  const Boxes boxes;
  auto r = boxes.make();
  const Isometry3 start = translation({0.0, 0.0, 0.0205});
  r->reset(start);
  r->tick({.dt = 1e-3, .devicePose = translation({0.0, 0.0, 0.018})});
  const Isometry3 before = r->fragmentPose();
  Isometry3 bad = translation({std::nan(""), 0.0, 0.018});
  const HapticResponse out = r->tick({.dt = 1e-3, .devicePose = bad});
  EXPECT_EQ(out.force, Vec3::Zero());
  EXPECT_EQ(out.torque, Vec3::Zero());
  EXPECT_TRUE(r->fragmentPose().isApprox(before, 0.0));
  const HapticResponse zeroDt = r->tick({.dt = 0.0, .devicePose = translation({0.0, 0.0, 0.018})});
  EXPECT_EQ(zeroDt.force, Vec3::Zero());
  const HapticResponse next = r->tick({.dt = 1e-3, .devicePose = translation({0.0, 0.0, 0.018})});
  EXPECT_TRUE(next.force.allFinite());
  EXPECT_GT(next.force.z(), 0.0);
}

TEST(BonePlacement, CreateNamesTheBadField) {
  const Boxes boxes;
  const auto whereOf = [&](std::shared_ptr<const ImplicitSphereTree> f, const Isometry3& pose,
                           std::shared_ptr<const ImplicitSphereTree> m, const Volume& v,
                           const BonePlacementOptions& o) {
    auto r = BonePlacementRenderer::create(std::move(f), pose, std::move(m), v, o);
    EXPECT_FALSE(r.ok());
    if (r.ok()) return std::string();
    EXPECT_EQ(r.error().code, ErrorCode::InvalidArgument);
    return r.error().where;
  };
  const Isometry3 id = Isometry3::Identity();
  EXPECT_NE(whereOf(nullptr, id, boxes.tree, boxes.box, testOptions()).find(": fixed"), std::string::npos);
  EXPECT_NE(whereOf(boxes.tree, id, nullptr, boxes.box, testOptions()).find(": moving"), std::string::npos);
  Isometry3 sheared = id;
  sheared.linear()(0, 1) = 0.5;
  EXPECT_NE(whereOf(boxes.tree, sheared, boxes.tree, boxes.box, testOptions()).find("fixedPose"),
            std::string::npos);
  const Volume empty = labels([](int, int, int) { return false; });
  EXPECT_NE(whereOf(boxes.tree, id, boxes.tree, empty, testOptions()).find("movingOccupancy"),
            std::string::npos);
  BonePlacementOptions o = testOptions();
  o.couplingStiffness = 0.0;
  EXPECT_NE(whereOf(boxes.tree, id, boxes.tree, boxes.box, o).find("options.couplingStiffness"),
            std::string::npos);
  o = testOptions();
  o.maxContacts = 0;
  EXPECT_NE(whereOf(boxes.tree, id, boxes.tree, boxes.box, o).find("options.maxContacts"), std::string::npos);
  o = testOptions();
  o.density = std::nan("");
  EXPECT_NE(whereOf(boxes.tree, id, boxes.tree, boxes.box, o).find("options.density"), std::string::npos);
  o = testOptions();
  o.contactLevel = 5;
  EXPECT_NE(whereOf(boxes.tree, id, boxes.tree, boxes.box, o).find("options.contactLevel"),
            std::string::npos);
}

}  // namespace
}  // namespace dm
