// Deforming objects under the god-object, and FEM tissue felt and deformed
// through dm::HapticTissue, against physics: the proxy rides a surface that
// moves under it; at equilibrium the hand and the tissue feel equal and
// opposite forces, the tissue takes the static shape of that load, and the
// force is the haptic spring in series with the tissue's point stiffness.
#include <dm/collide/bvh.hpp>
#include <dm/haptics/god_object.hpp>
#include <dm/haptics/tissue.hpp>
#include <dm/math/primitives.hpp>
#include <dm/physics/fem.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <memory>
#include <vector>

#include "../common/alloc_counter.hpp"
#include "haptics_test_support.hpp"

namespace dm {
namespace {

using dm::test::at;
using dm::test::input;
using dm::test::kStiffness;

std::unique_ptr<GodObjectRenderer> rendererOn(const Mesh& mesh, std::shared_ptr<const MeshBvh>& tree,
                                              const GodObjectOptions& options = {}) {
  auto b = MeshBvh::build(mesh);
  EXPECT_TRUE(b.ok());
  tree = std::make_shared<const MeshBvh>(std::move(*b));
  auto r = GodObjectRenderer::create({{.bvh = tree, .material = {.stiffness = kStiffness}}}, options);
  EXPECT_TRUE(r.ok()) << (r.ok() ? "" : r.error().message());
  return r.ok() ? std::move(*r) : nullptr;
}

// A copy of `tree` refitted to `positions`.
MeshBvh refitted(const MeshBvh& tree, const std::vector<Vec3>& positions) {
  MeshBvh copy = tree;
  EXPECT_TRUE(copy.refit(positions).ok());
  return copy;
}

TEST(GodObjectDeform, ProxyInContactRidesTheSurfaceItTouches) {
  const Mesh slab = makeBox(Vec3(0.05, 0.05, 0.01));  // top face at z = 0.01
  std::shared_ptr<const MeshBvh> tree;
  auto r = rendererOn(slab, tree);
  ASSERT_TRUE(r);
  const Vec3 device(0.004, -0.003, 0.008);  // 2 mm below the top face
  r->reset(at(Vec3(0.004, -0.003, 0.03)));
  HapticResponse out;
  for (int i = 0; i < 30; ++i) out = r->tick(input(device));
  ASSERT_TRUE(r->contact().active);
  EXPECT_NEAR(out.force.z(), kStiffness * 0.002, 2e-3);
  const Vec3 bc = r->contact().barycentric;
  EXPECT_NEAR(bc.sum(), 1.0, 1e-12);
  // Sliding (frictionless) 6 mm along the face: the contact point stays
  // under the proxy, not where the sweep first hit.
  for (int i = 1; i <= 30; ++i) r->tick(input(device + Vec3(0.0002 * i, 0, 0)));
  for (int i = 0; i < 30; ++i) r->tick(input(device));
  for (int i = 1; i <= 30; ++i) out = r->tick(input(device + Vec3(0.0002 * i, 0, 0)));
  const Vec3 under(r->proxy().x(), r->proxy().y(), 0.01);
  EXPECT_LT((r->contact().point - under).norm(), 1e-9);
  EXPECT_NEAR(r->proxy().x(), device.x() + 0.006, 1e-6);
  for (int i = 0; i < 30; ++i) out = r->tick(input(device));

  // The top face rises 1 mm and tilts by 0.5 mm over its 10 cm: the proxy
  // is carried, so the force grows by k x the rise under the device point.
  std::vector<Vec3> moved = slab.positions;
  for (Vec3& p : moved)
    if (p.z() > 0) p.z() += 0.001 + 0.005 * p.x();
  const MeshBvh up = refitted(*tree, moved);
  ASSERT_TRUE(r->deformObject(0, &up));
  const double rise = 0.001 + 0.005 * device.x();
  EXPECT_NEAR(r->proxy().z(), 0.01 + rise, 2e-6);
  EXPECT_NEAR(r->proxy().x(), device.x(), 1e-5);  // offset turned with the tilt, not sheared
  for (int i = 0; i < 5; ++i) out = r->tick(input(device));
  EXPECT_NEAR(out.force.norm(), kStiffness * (0.002 + rise), 3e-3);
  EXPECT_NEAR(r->proxy().z() - (0.01 + 0.005 * r->proxy().x() + 0.001), 0.0, 1e-5);
}

TEST(GodObjectDeform, FreeProxyIsPushedOutOfAnInflatedObject) {
  const Mesh ball = makeIcosphere(0.01, 3);
  std::shared_ptr<const MeshBvh> tree;
  auto r = rendererOn(ball, tree, {.proxyRadius = 0.001});
  ASSERT_TRUE(r);
  const Vec3 device(0.0, 0.0, 0.013);  // free: 2 mm above the surface with a 1 mm tip
  r->reset(at(device));
  HapticResponse out = r->tick(input(device));
  EXPECT_EQ(out.contacts, 0);

  std::vector<Vec3> big = ball.positions;
  for (Vec3& p : big) p *= 1.5;  // radius 15 mm: the surface passes the proxy
  const MeshBvh inflated = refitted(*tree, big);
  ASSERT_TRUE(r->deformObject(0, &inflated));
  EXPECT_GE(r->proxy().norm(), 0.015 * 0.99 + 0.001);  // outside, tip included (facets inscribed)
  out = r->tick(input(device));
  ASSERT_GT(out.contacts, 0);
  EXPECT_GT(out.force.z(), 0.0);  // pushes the hand out, as the object grew around it
  EXPECT_NEAR(out.force.norm(), kStiffness * (r->proxy() - device).norm(), 1e-9);
  EXPECT_GE(r->proxy().norm(), 0.015 * 0.99 + 0.001);
}

TEST(GodObjectDeform, RefusesTreesThatDoNotMatchAndDoesNotAllocate) {
  const Mesh ball = makeIcosphere(0.01, 2);
  std::shared_ptr<const MeshBvh> tree;
  auto r = rendererOn(ball, tree);
  ASSERT_TRUE(r);
  auto other = MeshBvh::build(makeIcosphere(0.01, 1));
  ASSERT_TRUE(other.ok());
  EXPECT_FALSE(r->deformObject(0, nullptr));
  EXPECT_FALSE(r->deformObject(1, tree.get()));
  EXPECT_FALSE(r->deformObject(0, &*other));
  EXPECT_EQ(&r->objectTree(0), tree.get());

  // Vertex normals given at creation would not follow a deformation.
  std::vector<Vec3> normals;
  for (const Vec3& p : ball.positions) normals.push_back(p.normalized());
  auto shaded = GodObjectRenderer::create(
      {{.bvh = tree, .material = {.stiffness = kStiffness}, .vertexNormals = normals}}, {.forceShading = true});
  ASSERT_TRUE(shaded.ok());
  EXPECT_FALSE((*shaded)->deformObject(0, tree.get()));

  // Breathing sphere: deform and tick every step without allocating.
  std::vector<MeshBvh> frames;
  for (int k = 0; k < 4; ++k) {
    std::vector<Vec3> p = ball.positions;
    for (Vec3& v : p) v *= 1.0 + 0.05 * k;
    frames.push_back(refitted(*tree, p));
  }
  r->reset(at(Vec3(0, 0, 0.02)));
  const auto before = test::countedAllocations();
  int contacts = 0;
  test::tCountAllocations = true;
  for (int i = 0; i < 400; ++i) {
    if (i % 10 == 0) r->deformObject(0, &frames[std::size_t((i / 10) % 4)]);
    contacts += r->tick(input(Vec3(0, 0, 0.0095))).contacts > 0;
  }
  test::tCountAllocations = false;
  EXPECT_EQ(test::countedAllocations(), before);
  EXPECT_GT(contacts, 300);
}

// A 40 x 40 x 20 mm block of soft tissue clamped at its base.
struct Block {
  static constexpr double kTop = 0.02;
  Block(double youngs = 2e4) {
    auto mesh = tetMeshBox({8, 8, 4}, Vec3(0.04, 0.04, kTop), Vec3(-0.02, -0.02, 0.0));
    EXPECT_TRUE(mesh.ok());
    auto b = FemBody::create(*mesh, {.youngsModulus = youngs, .poissonRatio = 0.45, .density = 1000},
                             {.alpha = 5.0, .beta = 0.02});
    EXPECT_TRUE(b.ok());
    body = std::make_unique<FemBody>(std::move(*b));
    body->fixNodesWhere([](const Vec3& p) { return p.z() < 1e-9; });
  }
  std::unique_ptr<FemBody> body;
};

Vec3 pointOn(const FemBody& body, const std::array<std::uint32_t, 3>& v, const Vec3& w) {
  return w[0] * body.positions()[v[0]] + w[1] * body.positions()[v[1]] + w[2] * body.positions()[v[2]];
}

TEST(HapticTissue, HandAndTissueFeelOppositeForcesAndTheTissueTakesTheStaticShape) {
  Block block;
  auto tissue = HapticTissue::create(*block.body, {.stiffness = 800.0, .tipRadius = 1e-6});
  ASSERT_TRUE(tissue.ok()) << tissue.error().message();
  HapticTissue& t = **tissue;
  auto r = GodObjectRenderer::create({{.bvh = t.restTree(), .material = {.stiffness = 800.0}}}, {});
  ASSERT_TRUE(r.ok());
  GodObjectRenderer& god = **r;
  const TissueBinding binding{&t, 0};
  TissueGodObject felt(god, {&binding, 1});  // what a HapticLoop would tick

  // The device goes 3 mm below the top (off the mesh's nodes), then holds:
  // haptics at 1 kHz, physics at 100 Hz, lockstep.
  const Vec3 above(0.0012, -0.0007, Block::kTop + 0.005), pressed(0.0012, -0.0007, Block::kTop - 0.003);
  god.reset(at(above));
  HapticResponse out;
  std::vector<double> late;
  late.reserve(500);
  const auto allocationsBefore = test::countedAllocations();
  for (int tick = 0; tick < 4000; ++tick) {
    const double s = std::min(1.0, tick / 500.0);
    const Vec3 device = above + s * (pressed - above);
    test::tCountAllocations = true;  // the haptic thread's part never allocates
    out = felt.tick(input(device));
    test::tCountAllocations = false;
    if (tick % 10 == 9) {
      ASSERT_TRUE(t.step(0.01).ok());
    }
    if (tick >= 3500) late.push_back(out.force.norm());
  }
  EXPECT_EQ(test::countedAllocations(), allocationsBefore);
  ASSERT_TRUE(god.contact().active);
  EXPECT_GT(t.grippedSteps(), 300u);
  EXPECT_EQ(t.publishedSurfaces(), 400u);

  // Settled: the force varies by under 1 % over the last half second.
  const auto [lo, hi] = std::minmax_element(late.begin(), late.end());
  EXPECT_LT(*hi - *lo, 0.01 * *hi);

  // Third law: the spring on the tissue is the hand's force reversed.
  const Vec3 onTissue = t.toolForce();
  EXPECT_LT((onTissue + out.force).norm(), 0.02 * out.force.norm())
      << "hand " << out.force.transpose() << " tissue " << onTissue.transpose();

  // The proxy rides the deformed surface: the force is the haptic spring
  // from the device point to the touched point of the tissue as it is now,
  // well below k x 3 mm (2.4 N) since the surface gave way.
  const GodObjectContact c = god.contact();
  const Vec3 surface = pointOn(*block.body, c.vertices, c.barycentric);
  const Vec3 device = pressed;
  EXPECT_GT(Block::kTop - surface.z(), 0.001);
  EXPECT_LT((out.force - 800.0 * (surface - device)).norm(), 0.01 * out.force.norm())
      << "force " << out.force.transpose() << " surface " << surface.transpose();

  // The tissue's shape is the static response to that load: the same force
  // applied as constant nodal loads to a fresh block, settled.
  Block reference;
  for (int i = 0; i < 3; ++i)
    reference.body->setExternalForce(c.vertices[std::size_t(i)], c.barycentric[i] * onTissue);
  for (int i = 0; i < 400; ++i) {
    ASSERT_TRUE(reference.body->step(0.01).ok());
  }
  const Vec3 expected = pointOn(*reference.body, c.vertices, c.barycentric);
  const Vec3 rest = pointOn(*block.body, c.vertices, c.barycentric) - surface;  // zero: same point
  EXPECT_EQ(rest.norm(), 0.0);
  const Vec3 restPoint = c.barycentric[0] * block.body->restPositions()[c.vertices[0]] +
                         c.barycentric[1] * block.body->restPositions()[c.vertices[1]] +
                         c.barycentric[2] * block.body->restPositions()[c.vertices[2]];
  EXPECT_LT(((surface - restPoint) - (expected - restPoint)).norm(), 0.03 * (expected - restPoint).norm())
      << "haptic " << (surface - restPoint).transpose() << " static " << (expected - restPoint).transpose();

  // Series springs along the press: F_z = d / (1/k + 1/k_t) with the
  // tissue's point stiffness k_t = F_z / depression of the reference.
  const double kt = -onTissue.z() / (restPoint.z() - expected.z());
  EXPECT_NEAR(out.force.z(), 0.003 / (1.0 / 800.0 + 1.0 / kt), 0.03 * out.force.z());
  std::printf("hand %.4f N (series law %.4f N, k_t %.1f N/m); depression haptic %.4f mm, static %.4f mm\n",
              out.force.z(), 0.003 / (1.0 / 800.0 + 1.0 / kt), kt, (restPoint.z() - surface.z()) * 1e3,
              (restPoint.z() - expected.z()) * 1e3);

  // Let go: the tissue springs back to rest.
  for (int tick = 0; tick < 2000; ++tick) {
    t.applyTo(god, 0);
    out = god.tick(input(above));
    t.publishGrip(god, 0, above);
    if (tick % 10 == 9) {
      ASSERT_TRUE(t.step(0.01).ok());
    }
  }
  EXPECT_FALSE(god.contact().active);
  EXPECT_FALSE(block.body->hasContactSpring());
  double worst = 0;
  for (std::size_t i = 0; i < block.body->nodeCount(); ++i)
    worst = std::max(worst, (block.body->positions()[i] - block.body->restPositions()[i]).norm());
  EXPECT_LT(worst, 5e-5);
}

TEST(HapticTissue, ContactSpringIsStableWhereTheSameForceAppliedExplicitlyIsNot) {
  // The haptic spring's force from the last state, applied as a nodal load
  // for the next 10 ms step, against the implicit contact spring.
  auto run = [](bool implicit) {
    Block block(5e3);
    const auto& tri = block.body->surfaceTriangles();
    std::size_t top = 0;  // a boundary triangle on the top face
    for (std::size_t i = 0; i < tri.size(); ++i)
      if (block.body->positions()[tri[i][0]].z() > Block::kTop - 1e-9 &&
          block.body->positions()[tri[i][1]].z() > Block::kTop - 1e-9 &&
          block.body->positions()[tri[i][2]].z() > Block::kTop - 1e-9)
        top = i;
    const std::array<std::uint32_t, 3> v{tri[top][0], tri[top][1], tri[top][2]};
    const Vec3 w = Vec3::Constant(1.0 / 3.0);
    const Vec3 anchor = pointOn(*block.body, v, w) - Vec3(0, 0, 0.003);
    double last = 0;
    for (int step = 0; step < 100; ++step) {
      if (implicit) {
        EXPECT_TRUE(block.body->setContactSpring(v, w, anchor, 800.0).ok());
      } else {
        const Vec3 f = 800.0 * (anchor - pointOn(*block.body, v, w));
        for (int i = 0; i < 3; ++i) block.body->setExternalForce(v[std::size_t(i)], w[i] * f);
      }
      if (!block.body->step(0.01).ok()) return std::numeric_limits<double>::infinity();
      last = (pointOn(*block.body, v, w) - anchor).norm();
      if (!std::isfinite(last)) return std::numeric_limits<double>::infinity();
    }
    return last;
  };
  const double implicitGap = run(true), explicitGap = run(false);
  EXPECT_LT(implicitGap, 0.003);           // settled between rest surface and anchor
  EXPECT_GT(explicitGap, 10 * 0.003);      // the explicit coupling oscillates and grows
}

TEST(HapticTissue, BadOptionsAndSpringsAreRefused) {
  Block block;
  EXPECT_FALSE(HapticTissue::create(*block.body, {.stiffness = 0.0}).ok());
  EXPECT_FALSE(HapticTissue::create(*block.body, {.stiffness = 800.0, .tipRadius = -1.0}).ok());
  const std::array<std::uint32_t, 3> ok{0, 1, 2}, bad{0, 1, 999999};
  EXPECT_FALSE(block.body->setContactSpring(bad, Vec3::Constant(1.0 / 3), Vec3::Zero(), 1.0).ok());
  EXPECT_FALSE(block.body->setContactSpring(ok, Vec3(0.5, 0.5, 0.5), Vec3::Zero(), 1.0).ok());
  EXPECT_FALSE(block.body->setContactSpring(ok, Vec3(1.2, -0.2, 0.0), Vec3::Zero(), 1.0).ok());
  EXPECT_FALSE(block.body->setContactSpring(ok, Vec3::Constant(1.0 / 3), Vec3::Constant(NAN), 1.0).ok());
  EXPECT_FALSE(block.body->setContactSpring(ok, Vec3::Constant(1.0 / 3), Vec3::Zero(), -1.0).ok());
  EXPECT_FALSE(block.body->hasContactSpring());
  EXPECT_EQ(block.body->contactSpringForce(), Vec3::Zero());
}

}  // namespace
}  // namespace dm
