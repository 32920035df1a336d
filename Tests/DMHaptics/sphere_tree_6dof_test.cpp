// SphereTree6DofRenderer: resting contact against the tree's own bound of its
// approximation error, force = K × handle depth, torque = r × F on a lever,
// a thin plate crossed in one tick, frictionless sliding, allocation-free
// ticks, determinism, validation and the NaN guard.
//
// Ground truth: the "plane" is one sphere of radius 1000 m (its surface
// departs from z = 0 by x²/2000 m: 5e-8 m at 1 cm), and the exact tools are
// sphere trees given node by node (a chain of equal spheres is a ball; a
// binary chain of spheres along x is a rod), so the union of spheres the
// method collides is known analytically.
#include <dm/collide/sphere_tree.hpp>
#include <dm/haptics/sphere_tree_6dof.hpp>
#include <dm/math/primitives.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <numbers>
#include <vector>

#include "../common/alloc_counter.hpp"
#include "haptics_test_support.hpp"

namespace dm {
namespace {

using test::ballTree;
using test::drive;

constexpr double kPlaneR = 1000.0;

Isometry3 poseAt(const Vec3& p, const Mat3& r = Mat3::Identity()) {
  Isometry3 x = Isometry3::Identity();
  x.linear() = r;
  x.translation() = p;
  return x;
}

// Rod along x, |x| ≤ h, thickness a: level l has 2^l spheres of radius
// h/2^l + a centred on the segments of a 2^l split of [−h, h].
std::shared_ptr<const SphereTree> rodTree(double h, double a, int levels) {
  std::vector<SphereTreeNode> nodes;
  for (int l = 0; l < levels; ++l) {
    const int n = 1 << l;
    const auto levelStart = static_cast<std::uint32_t>(nodes.size());
    for (int i = 0; i < n; ++i) {
      SphereTreeNode x;
      x.center = Vec3(-h + (i + 0.5) * 2.0 * h / n, 0, 0);
      x.radius = h / n + a;
      x.level = static_cast<std::uint8_t>(l);
      x.childCount = l + 1 < levels ? 2 : 0;
      x.firstChild = levelStart + static_cast<std::uint32_t>(n + 2 * i);
      nodes.push_back(x);
    }
  }
  auto t = SphereTree::fromNodes(std::move(nodes), 2 * h * std::numbers::pi * a * a);
  EXPECT_TRUE(t.ok());
  return *t;
}

// The plane z = 0 (normal +z), as the top of a huge sphere.
SphereTreeObject planeObject() {
  SphereTreeObject o;
  o.tree = ballTree(kPlaneR, 1);
  o.pose = poseAt(Vec3(0, 0, -kPlaneR));
  o.name = "plane";
  return o;
}

TEST(SphereTree6Dof, BallRestsOnPlaneAndForceIsStiffnessTimesDepth) {
  const double R = 0.01, k = 800.0;
  SphereTree6DofOptions opt;
  opt.toolLevel = 3;
  opt.linearStiffness = Vec3::Constant(k);
  auto r = SphereTree6DofRenderer::create(ballTree(R, 5), {planeObject()}, opt);
  ASSERT_TRUE(r.ok()) << r.error();
  SphereTree6DofRenderer& ren = **r;
  EXPECT_EQ(ren.name(), "spheretree");
  EXPECT_EQ(ren.objectCount(), 1u);
  const Isometry3 start = poseAt(Vec3(0.001, -0.002, 0.03));
  ren.reset(start);
  for (double depth : {0.001, 0.004, 0.008}) {
    const Isometry3 pushed = poseAt(Vec3(0.001, -0.002, R - depth));
    const HapticResponse out = drive(ren, start, pushed, 20, 10);
    EXPECT_NEAR(out.proxyPose.translation().z(), R, 1e-6) << depth;
    EXPECT_NEAR(out.proxyPose.translation().x(), 0.001, 1e-7);
    EXPECT_NEAR(out.force.z(), k * depth, 0.02 * k * depth) << depth;
    EXPECT_NEAR(out.force.z(), k * depth, 1e-3 * k * depth) << "the exact tree should be far better than 2%";
    EXPECT_NEAR(out.force.x(), 0.0, 1e-6 * k * depth);
    EXPECT_LT(out.torque.norm(), 1e-9);
    EXPECT_GE(out.contacts, 1);
    EXPECT_NEAR(out.penetration, depth, 1e-3 * depth);
    // Lifting the handle out releases the tool: zero force.
    const HapticResponse free = drive(ren, pushed, start, 20, 2);
    EXPECT_EQ(free.contacts, 0);
    EXPECT_LT(free.force.norm(), 1e-9);
  }
}

TEST(SphereTree6Dof, FittedBallOnBoxStaysWithinTheTreesApproximationError) {
  // Tool: fitted tree of an icosphere; environment: fitted tree of a box
  // whose top face is z = 0. The unions of spheres are what collide, so the
  // real ball's gap above the real face must lie within
  // [−(R − inradius), 2·(tool sphere radius + box leaf radius)] (each sphere
  // is a minimal sphere of surface pieces: every point of it is within its
  // diameter of the surface).
  const double R = 0.008, k = 1000.0;
  const Mesh ball = makeIcosphere(R, 3);
  auto tool = buildSphereTreeFitted(ball, {.levels = 5});
  ASSERT_TRUE(tool.ok()) << tool.error();
  auto box = buildSphereTreeFitted(makeBox(Vec3(0.04, 0.04, 0.01)), {.levels = 6});
  ASSERT_TRUE(box.ok()) << box.error();
  double inradius = R;
  for (const Triangle& t : ball.triangles) {
    const Vec3 a = ball.positions[t[0]], b = ball.positions[t[1]], c = ball.positions[t[2]];
    inradius = std::min(inradius, std::abs((b - a).cross(c - a).normalized().dot(a)));
  }
  for (int level : {3, 4}) {
    SphereTree6DofOptions opt;
    opt.toolLevel = level;
    opt.linearStiffness = Vec3::Constant(k);
    SphereTreeObject env{.tree = *box, .pose = poseAt(Vec3(0, 0, -0.01)), .material = {}, .name = "box"};
    auto r = SphereTree6DofRenderer::create(*tool, {env}, opt);
    ASSERT_TRUE(r.ok()) << r.error();
    const double approx = 2.0 * ((*r)->toolSphereMaxRadius() + (*r)->environmentLeafMaxRadius());
    for (const Vec3& xy : {Vec3(0, 0, 0), Vec3(0.011, -0.007, 0), Vec3(-0.02, 0.013, 0)}) {
      const Isometry3 start = poseAt(xy + Vec3(0, 0, 0.03));
      (*r)->reset(start);
      const double depth = 0.005;
      const HapticResponse out = drive(**r, start, poseAt(xy + Vec3(0, 0, R - depth)), 25, 10);
      const double gap = out.proxyPose.translation().z() - R;
      EXPECT_GE(gap, -(R - inradius) - 1e-6) << "level " << level;
      EXPECT_LE(gap, approx + 1e-6) << "level " << level;
      EXPECT_GE(out.force.z(), k * (depth - (R - inradius)) - 1e-3);
      EXPECT_LE(out.force.z(), k * (depth + approx) + 1e-3);
      EXPECT_NEAR(out.proxyPose.translation().x(), xy.x(), 0.25 * depth) << "pushed straight down";
    }
  }
}

TEST(SphereTree6Dof, BallRestsOnAVoxelSlabThroughTheImplicitTree) {
  // 32 × 32 × 4 occupied voxels of 1 mm, top face at z = 0: the leaf spheres
  // (radius ρ = √3/2 mm, centres at z = −0.5 mm) cover the face, so an
  // exact ball resting on them has its centre in [R, R + ρ − 0.5 mm].
  auto v = Volume::create(Vec3i(32, 32, 4), VoxelType::U8,
                          Affine3(Eigen::Translation3d(-0.0155, -0.0155, -0.0035) * Eigen::Scaling(0.001)));
  ASSERT_TRUE(v.ok()) << v.error();
  for (int k = 0; k < 4; ++k)
    for (int j = 0; j < 32; ++j)
      for (int i = 0; i < 32; ++i) v->setValue(i, j, k, 1);
  auto slab = ImplicitSphereTree::create(*v, 0.5);
  ASSERT_TRUE(slab.ok()) << slab.error();
  const double R = 0.005, k = 1000.0;
  SphereTree6DofOptions opt;
  opt.toolLevel = 2;
  opt.linearStiffness = Vec3::Constant(k);
  auto r = SphereTree6DofRenderer::create(ballTree(R, 3), {{.tree = *slab, .name = "slab"}}, opt);
  ASSERT_TRUE(r.ok()) << r.error();
  const double rho = (*r)->environmentLeafMaxRadius();
  EXPECT_NEAR(rho, 0.5e-3 * std::sqrt(3.0), 1e-9);
  for (const Vec3& xy : {Vec3(0.0007, -0.0013, 0), Vec3(-0.004, 0.0021, 0)}) {
    const Isometry3 start = poseAt(xy + Vec3(0, 0, 0.02));
    (*r)->reset(start);
    const HapticResponse out = drive(**r, start, poseAt(xy + Vec3(0, 0, R - 0.003)), 20, 20);
    const double h = out.proxyPose.translation().z();
    EXPECT_GE(h, R - 1e-6);
    EXPECT_LE(h, R + rho - 0.5e-3 + 1e-6);
    EXPECT_GT(out.force.z(), 0.0);
    EXPECT_GE(out.contacts, 1);
  }
}

TEST(SphereTree6Dof, RodPushedAtOneEndGivesTorqueRCrossF) {
  const double h = 0.05, a = 0.003, k = 600.0, alpha = 30.0 * std::numbers::pi / 180.0;
  const double delta = 0.001;
  auto rod = rodTree(h, a, 5);
  SphereTree6DofOptions opt;
  opt.toolLevel = 3;
  opt.linearStiffness = Vec3::Constant(k);  // angular stiffness: automatic, K ∝ M
  auto r = SphereTree6DofRenderer::create(rod, {planeObject()}, opt);
  ASSERT_TRUE(r.ok()) << r.error();
  const Mat3 rot = AngleAxis(alpha, Vec3::UnitY()).toRotationMatrix();  // +x end tilts down
  // Tip sphere of level 3 and its lever at the handle pose.
  const SphereTreeNode& tip = rod->level(3).back();
  const Vec3 lever = rot * tip.center;
  ASSERT_LT(lever.z(), 0.0);
  const double zPushed = -lever.z() + tip.radius - delta;  // tip sphere 1 mm into the plane
  const Isometry3 start = poseAt(Vec3(0.002, 0.001, zPushed + 0.02), rot);
  const Isometry3 pushed = poseAt(Vec3(0.002, 0.001, zPushed), rot);
  (*r)->reset(start);
  const HapticResponse out = drive(**r, start, pushed, 20, 20);
  // One constraint, normal +z, lever r: λ solves (1/m + |r×n|²/I) λ = δ, and
  // with K = (k/m)·M the force is (k/m)·λ·n and the torque (k/m)·λ·(r × n).
  const double m = opt.mass, I = 0.4 * m * (h + a) * (h + a);
  const Vec3 n = Vec3::UnitZ();
  const double lambda = delta / (1.0 / m + lever.cross(n).squaredNorm() / I);
  const Vec3 fExpected = (k / m) * lambda * n;
  EXPECT_NEAR(out.force.z(), fExpected.z(), 0.03 * fExpected.z());
  EXPECT_NEAR(out.force.x(), 0.0, 0.01 * fExpected.z());
  EXPECT_NEAR(out.force.y(), 0.0, 0.01 * fExpected.z());
  // r × F with the lever of the graphic tool (where the contact acts).
  const Vec3 tauExpected = (out.proxyPose.linear() * tip.center).cross(out.force);
  EXPECT_GT(tauExpected.norm(), 0.01 * h * fExpected.z());
  EXPECT_LT((out.torque - tauExpected).norm(), 0.03 * tauExpected.norm())
      << out.torque.transpose() << " vs " << tauExpected.transpose();
  // The graphic tip rests on the plane; the graphic tool turned and rose.
  const Vec3 tipWorld = out.proxyPose * tip.center;
  EXPECT_NEAR(tipWorld.z() - tip.radius, 0.0, 2e-5);
  EXPECT_GT(out.proxyPose.translation().z(), zPushed);
}

TEST(SphereTree6Dof, ThinPlateCrossedInOneTickLeavesToolOnTheNearSide) {
  const double R = 0.004, half = 0.001;
  auto plate = buildSphereTreeOctree(makeBox(Vec3(0.05, 0.05, half)), {.levels = 6});
  ASSERT_TRUE(plate.ok()) << plate.error();
  for (int linearizations : {1, 3}) {
    SphereTree6DofOptions opt;
    opt.toolLevel = 2;
    opt.maxStep = 0.1;
    opt.linearizations = linearizations;
    auto r = SphereTree6DofRenderer::create(ballTree(R, 3), {{.tree = *plate, .name = "plate"}}, opt);
    ASSERT_TRUE(r.ok()) << r.error();
    for (const Vec3& end :
         {Vec3(0.003, 0.002, -0.02), Vec3(0.03, -0.01, -0.006), Vec3(0, 0, -R - half - 0.001)}) {
      const Isometry3 start = poseAt(Vec3(0, 0, 0.012));
      (*r)->reset(start);
      HapticResponse out = (*r)->tick({.dt = 1e-3, .devicePose = start});
      ASSERT_EQ(out.contacts, 0);
      out = (*r)->tick({.timeNs = 1000000, .dt = 1e-3, .devicePose = poseAt(end)});
      EXPECT_GE(out.proxyPose.translation().z(), half + R - 1e-6)
          << "passed through, end " << end.transpose();
      EXPECT_GT(out.force.z(), 0.0);
      // Holding the handle beneath keeps the tool on top.
      out = drive(**r, poseAt(end), poseAt(end), 1, 20);
      EXPECT_GE(out.proxyPose.translation().z(), half + R - 1e-6);
    }
  }
}

TEST(SphereTree6Dof, SlidingAlongThePlaneIsFrictionless) {
  const double R = 0.01, k = 1000.0, depth = 0.003;
  SphereTree6DofOptions opt;
  opt.toolLevel = 2;
  opt.linearStiffness = Vec3::Constant(k);
  auto r = SphereTree6DofRenderer::create(ballTree(R, 3), {planeObject()}, opt);
  ASSERT_TRUE(r.ok()) << r.error();
  const Isometry3 start = poseAt(Vec3(0, 0, 0.02));
  (*r)->reset(start);
  drive(**r, start, poseAt(Vec3(0, 0, R - depth)), 10, 5);
  for (int i = 1; i <= 40; ++i) {
    const Vec3 ph(0.0005 * i, -0.00025 * i, R - depth);
    const HapticResponse out = (*r)->tick({.dt = 1e-3, .devicePose = poseAt(ph)});
    EXPECT_NEAR(out.proxyPose.translation().x(), ph.x(), 1e-7);
    EXPECT_NEAR(out.proxyPose.translation().y(), ph.y(), 1e-7);
    EXPECT_NEAR(out.proxyPose.translation().z(), R, 1e-6);
    EXPECT_LT(out.force.head<2>().norm(), 1e-4 * k * depth);
    EXPECT_NEAR(out.force.z(), k * depth, 1e-3 * k * depth);
  }
}

TEST(SphereTree6Dof, MovingObjectCarriesTheRestingTool) {
  const double R = 0.01;
  auto r = SphereTree6DofRenderer::create(ballTree(R, 3), {planeObject()}, {.toolLevel = 2});
  ASSERT_TRUE(r.ok()) << r.error();
  const Isometry3 handle = poseAt(Vec3(0, 0, R - 0.004));
  (*r)->reset(poseAt(Vec3(0, 0, 0.02)));
  drive(**r, poseAt(Vec3(0, 0, 0.02)), handle, 10, 5);
  for (int i = 1; i <= 10; ++i) {
    (*r)->setObjectPose(0, poseAt(Vec3(0, 0, -kPlaneR + 0.0002 * i)));
    const HapticResponse out = (*r)->tick({.dt = 1e-3, .devicePose = handle});
    EXPECT_NEAR(out.proxyPose.translation().z(), R + 0.0002 * i, 1e-6);
  }
  (*r)->setObjectPose(7, poseAt(Vec3::Zero()));  // ignored
  Isometry3 nanPose = poseAt(Vec3::Zero());
  nanPose.translation().x() = std::numeric_limits<double>::quiet_NaN();
  (*r)->setObjectPose(0, nanPose);  // ignored
  const HapticResponse out = (*r)->tick({.dt = 1e-3, .devicePose = handle});
  EXPECT_NEAR(out.proxyPose.translation().z(), R + 0.002, 1e-6);
}

// A contact-rich scene: fitted ball tool against a fitted icosphere (the
// trees are built once for the whole file).
Result<std::unique_ptr<SphereTree6DofRenderer>> richScene(int toolLevel) {
  static const auto tool = buildSphereTreeFitted(makeIcosphere(0.004, 3), {.levels = 5});
  static const auto env = buildSphereTreeFitted(makeIcosphere(0.02, 3), {.levels = 5});
  if (!tool) return tool.error();
  if (!env) return env.error();
  return SphereTree6DofRenderer::create(*tool, {{.tree = *env, .material = {.damping = 0.5}, .name = "ball"}},
                                        {.toolLevel = toolLevel, .maxConstraints = 64});
}

Isometry3 scriptedPose(int i) {
  const double t = i * 1e-3;
  return poseAt(
      Vec3(0.004 * std::sin(7 * t), 0.003 * std::cos(5 * t), 0.0255 - 0.006 * std::min(1.0, 10 * t)),
      AngleAxis(0.3 * std::sin(3 * t), Vec3(1, 1, 0).normalized()).toRotationMatrix());
}

TEST(SphereTree6Dof, TickDoesNotAllocate) {
  auto r = richScene(4);
  ASSERT_TRUE(r.ok()) << r.error();
  (*r)->reset(scriptedPose(0));
  (*r)->tick({.dt = 1e-3, .devicePose = scriptedPose(1)});
  int contactTicks = 0;
  test::tCountAllocations = true;
  const auto before = test::countedAllocations();
  for (int i = 2; i < 300; ++i) {
    (*r)->setObjectPose(0, poseAt(Vec3(0, 0, 1e-6 * i)));
    const HapticResponse out = (*r)->tick({.dt = 1e-3, .devicePose = scriptedPose(i)});
    contactTicks += out.contacts > 0 ? 1 : 0;
  }
  (*r)->reset(scriptedPose(0));
  const auto after = test::countedAllocations();
  test::tCountAllocations = false;
  EXPECT_EQ(after, before);
  EXPECT_GT(contactTicks, 100) << "the script must exercise contacts";
}

TEST(SphereTree6Dof, DeterministicAcrossInstances) {
  auto a = richScene(3), b = richScene(3);
  ASSERT_TRUE(a.ok() && b.ok());
  (*a)->reset(scriptedPose(0));
  (*b)->reset(scriptedPose(0));
  for (int i = 1; i < 200; ++i) {
    const HapticInput in{
        .timeNs = i, .dt = 1e-3, .devicePose = scriptedPose(i), .linearVelocity = Vec3(0, 0, -0.01)};
    const HapticResponse x = (*a)->tick(in), y = (*b)->tick(in);
    ASSERT_EQ(std::memcmp(x.force.data(), y.force.data(), sizeof(double) * 3), 0) << i;
    ASSERT_EQ(std::memcmp(x.torque.data(), y.torque.data(), sizeof(double) * 3), 0) << i;
    ASSERT_EQ(std::memcmp(x.proxyPose.data(), y.proxyPose.data(), sizeof(double) * 16), 0) << i;
    ASSERT_EQ(x.contacts, y.contacts);
  }
}

TEST(SphereTree6Dof, NanInputGivesZeroForceAndKeepsState) {
  auto r = richScene(3);
  ASSERT_TRUE(r.ok());
  (*r)->reset(scriptedPose(0));
  for (int i = 1; i < 100; ++i) (*r)->tick({.dt = 1e-3, .devicePose = scriptedPose(i)});
  const Isometry3 before = (*r)->graphicPose();
  Isometry3 bad = scriptedPose(100);
  bad(1, 1) = std::numeric_limits<double>::quiet_NaN();
  HapticResponse out = (*r)->tick({.dt = 1e-3, .devicePose = bad});
  EXPECT_TRUE(out.force.isZero());
  EXPECT_TRUE(out.torque.isZero());
  EXPECT_TRUE((*r)->graphicPose().isApprox(before, 0.0));
  out = (*r)->tick({.dt = 0.0, .devicePose = scriptedPose(100)});
  EXPECT_TRUE(out.force.isZero());
  out = (*r)->tick({.dt = 1e-3, .devicePose = scriptedPose(100)});
  EXPECT_TRUE(out.force.allFinite());
}

TEST(SphereTree6Dof, CreateNamesTheBadField) {
  auto ball = ballTree(0.01, 4);
  struct Case {
    std::shared_ptr<const SphereTree> tool;
    std::vector<SphereTreeObject> objects;
    SphereTree6DofOptions opt;
    const char* where;
  };
  SphereTreeObject noTree{.name = "gum"};
  SphereTreeObject badMat = planeObject();
  badMat.material.damping = -1;
  SphereTreeObject badPose = planeObject();
  badPose.pose.translation().y() = std::numeric_limits<double>::infinity();
  const Case cases[] = {
      {nullptr, {planeObject()}, {}, "tool"},
      {ball, {planeObject()}, {.toolLevel = 4}, "options.toolLevel"},
      {ball, {planeObject()}, {.toolLevel = 1, .mass = 0}, "options.mass"},
      {ball, {planeObject()}, {.toolLevel = 1, .maxConstraints = 0}, "options.maxConstraints"},
      {ball,
       {planeObject()},
       {.toolLevel = 1, .maxStep = std::numeric_limits<double>::quiet_NaN()},
       "options.maxStep"},
      {ball, {planeObject(), noTree}, {.toolLevel = 1}, "objects[1] (gum).tree"},
      {ball, {badMat}, {.toolLevel = 1}, "objects[0] (plane).material/damping"},
      {ball, {badPose}, {.toolLevel = 1}, "objects[0] (plane).pose"},
  };
  for (const Case& c : cases) {
    auto r = SphereTree6DofRenderer::create(c.tool, c.objects, c.opt);
    ASSERT_FALSE(r.ok()) << c.where;
    EXPECT_EQ(r.error().code, ErrorCode::InvalidArgument);
    EXPECT_EQ(r.error().where, c.where) << r.error();
  }
  EXPECT_TRUE(SphereTree6DofRenderer::create(ball, {}, {.toolLevel = 3}).ok()) << "free space is allowed";
}

}  // namespace
}  // namespace dm
