// SphereTreeDeformation and the sphere-tree renderer's patient changes:
// a mass on a spring oscillates at √(k/m) and settles at F/k; the network
// is reciprocal (Maxwell–Betti) and in equilibrium with its supports; a
// ball pressed into a soft "plane" (one sphere of radius 1000 m) meets two
// springs in series; a dental mirror pushes a tongue aside locally and the
// tongue springs back; a scaler releases three pieces of calculus, each at
// its bond strength, with a sudden drop of the force.
#include <dm/collide/sphere_tree.hpp>
#include <dm/haptics/sphere_tree_6dof.hpp>
#include <dm/haptics/sphere_tree_deformation.hpp>
#include <dm/math/primitives.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <complex>
#include <cstdio>
#include <numbers>
#include <vector>

#include "../common/alloc_counter.hpp"
#include "haptics_test_support.hpp"

namespace dm {
namespace {

using test::at;
using test::ballTree;

std::shared_ptr<const SphereTree> fittedTree(const Mesh& m, int levels) {
  auto t = buildSphereTreeFitted(m, {.levels = levels});
  EXPECT_TRUE(t.ok()) << t.error();
  return t ? *t : nullptr;
}

// A tongue: an ellipsoid 60 × 24 × 16 mm along x, its root (x < −22 mm) fixed.
Mesh tongueMesh() {
  Mesh m = makeIcosphere(1.0, 4);
  for (Vec3& p : m.positions) p = Vec3(0.030 * p.x(), 0.012 * p.y(), 0.008 * p.z());
  return m;
}

// The tongue's root (x < −22 mm) is fixed.
const Aabb kTongueRoot(Vec3(-1, -1, -1), Vec3(-0.022, 1, 1));
// A soft tongue: 55 masses on level 2 of its tree.
const SphereTreeDeformationOptions kTongue{.skeletonLevel = 2,
                                           .mass = 0.06,
                                           .anchorStiffness = 30,
                                           .linkStiffness = 400,
                                           .damping = 2,
                                           .fixedRegion = kTongueRoot};

TEST(SphereTreeDeformation, OneNodeOscillatesAtItsNaturalFrequencyAndSettlesAtFOverK) {
  // Skeleton level 0: one mass m on an anchor spring k. A constant force F
  // from rest: d(t) = F/k (1 − cos ωt), ω = √(k/m); the first peak, 2F/k, at
  // π/ω. Implicit Euler's own solution is known in closed form (below, to
  // 1e-9); it shifts the phase by (ωh)²/3 and damps by (1 + ω²h²)^(−1/2) a
  // step: the peak within 1.5 steps of π/ω and 20 % of its height.
  const double m = 0.05, k = 200.0, F = 1.0, h = 1e-3;
  const auto tree = ballTree(0.01, 3);
  auto def = SphereTreeDeformation::create(
      tree,
      {.skeletonLevel = 0, .mass = m, .anchorStiffness = k, .linkStiffness = 0, .damping = 0, .timeStep = h});
  ASSERT_TRUE(def.ok()) << def.error();
  SphereTreeDeformation& d = **def;
  const double omega = std::sqrt(k / m);
  // Implicit Euler from rest: d_n = F/k (1 − Re λⁿ), λ = 1 / (1 − iωh).
  const std::complex<double> lambda = 1.0 / std::complex<double>(1.0, -omega * h);
  double peak = 0.0, peakT = 0.0;
  for (int i = 1; i <= 150; ++i) {
    d.addForce(2, Vec3(0, 0, F));  // on the leaf: its weight is all on the root
    d.step(h);
    const double z = d.displacement(2).z();
    ASSERT_NEAR(z, F / k * (1.0 - std::pow(lambda, i).real()), 1e-9 * F / k) << "step " << i;
    if (z > peak) peak = z, peakT = i * h;
  }
  EXPECT_NEAR(peakT, std::numbers::pi / omega, 1.5 * h);
  EXPECT_GT(peak, 0.8 * 2 * F / k);
  EXPECT_LT(peak, 2 * F / k);

  // Damped, it settles at F/k and the support holds F.
  auto damped = SphereTreeDeformation::create(
      tree, {.skeletonLevel = 0, .mass = m, .anchorStiffness = k, .damping = 5.0, .timeStep = h});
  ASSERT_TRUE(damped.ok());
  for (int i = 0; i < 3000; ++i) {
    (*damped)->addForce(0, Vec3(F, 0, 0));
    (*damped)->step(h);
  }
  EXPECT_NEAR((*damped)->displacement(1).x(), F / k, 1e-4 * F / k);
  EXPECT_NEAR((*damped)->supportForce().x(), -F, 1e-4);
  (*damped)->reset();
  EXPECT_EQ((*damped)->displacement(1), Vec3::Zero());
}

TEST(SphereTreeDeformation, NetworkIsReciprocalLocalAndInEquilibriumWithItsRoot) {
  const auto tree = fittedTree(tongueMesh(), 4);
  ASSERT_TRUE(tree);
  const SphereTreeDeformationOptions opt{.skeletonLevel = 2,
                                         .anchorStiffness = 20,
                                         .linkStiffness = 300,
                                         .damping = 3,
                                         .fixedRegion = kTongueRoot};
  // Leaves near the tip (A) and the middle (B).
  const std::span<const SphereTreeNode> leaves = tree->level(3);
  const auto nearest = [&](const Vec3& x) {
    std::uint32_t best = 0;
    double bd = 1e9;
    for (const SphereTreeNode& n : leaves)
      if (const double dd = (n.center - x).norm(); dd < bd)
        bd = dd, best = static_cast<std::uint32_t>(&n - tree->nodes().data());
    return best;
  };
  const std::uint32_t a = nearest(Vec3(0.026, 0, 0.006)), b = nearest(Vec3(0.0, 0, 0.008));
  const auto settle = [&](std::uint32_t node, const Vec3& f) {
    auto d = SphereTreeDeformation::create(tree, opt);
    EXPECT_TRUE(d.ok()) << d.error();
    for (int i = 0; i < 4000; ++i) {
      (*d)->addForce(node, f);
      (*d)->step(1e-3);
    }
    return *d;
  };
  const Vec3 f(0, 0, -0.5);
  const auto atA = settle(a, f), atB = settle(b, f);
  // Maxwell–Betti: the displacement at B under a load at A equals the one at A under the same load at B.
  const double ba = atA->displacement(b).z(), ab = atB->displacement(a).z();
  EXPECT_LT(ba, 0.0);
  EXPECT_NEAR(ba, ab, 1e-3 * std::abs(ab));
  // Static equilibrium: the root and anchors hold the load.
  EXPECT_NEAR((atA->supportForce() + f).norm(), 0.0, 1e-3 * f.norm());
  // Local: the tip under its load moves most, the root not at all.
  const double tip = atA->displacement(a).z();
  EXPECT_LT(tip, 2.0 * ba);
  // The fixed nodes' spheres move only by the Shepard blend with free neighbours.
  for (std::size_t i = 0; i < atA->skeleton().size(); ++i)
    if (atA->fixed(i)) {
      EXPECT_LT(atA->displacement(atA->skeleton()[i]).norm(), 0.05 * std::abs(tip));
    }
  // The deformed tree stays a hierarchy: every leaf sphere (moved rigidly
  // by its displacement) within the bound of each of its ancestors.
  const std::vector<SphereTreeNode>& rn = tree->nodes();
  std::vector<std::uint32_t> parent(rn.size(), 0);
  for (std::uint32_t n = 0; n < rn.size(); ++n)
    for (std::uint32_t c = rn[n].firstChild; c < rn[n].firstChild + rn[n].childCount; ++c) parent[c] = n;
  int checked = 0;
  for (std::uint32_t l = 1; l < rn.size(); ++l) {
    if (rn[l].childCount != 0) continue;
    const BoundingSphere leaf = atA->bound(l);
    EXPECT_NEAR((leaf.center - rn[l].center - atA->displacement(l)).norm(), 0.0, 1e-15);
    EXPECT_EQ(leaf.radius, rn[l].radius);
    for (std::uint32_t up = parent[l];; up = parent[up]) {
      const BoundingSphere ub = atA->bound(up);
      EXPECT_LE((leaf.center - ub.center).norm() + leaf.radius, ub.radius * (1 + 1e-12)) << l << " in " << up;
      ++checked;
      if (up == 0) break;
    }
  }
  EXPECT_GT(checked, 500);  // ~270 leaves, 3 ancestors each
  // The graphics follow: mesh vertices bound to the skeleton move like the tree.
  const Mesh mesh = tongueMesh();
  const auto binding = atA->bind(mesh.positions);
  std::vector<Vec3> moved(mesh.positions.size());
  ASSERT_TRUE(atA->deform(binding, mesh.positions, moved));
  std::size_t tipVertex = 0;
  for (std::size_t i = 0; i < mesh.positions.size(); ++i)
    if ((mesh.positions[i] - (rn[a].center + atA->displacement(a))).norm() <
        (mesh.positions[tipVertex] - (rn[a].center + atA->displacement(a))).norm())
      tipVertex = i;
  EXPECT_NEAR(moved[tipVertex].z() - mesh.positions[tipVertex].z(), tip, 0.3 * std::abs(tip));
  for (std::size_t i = 0; i < mesh.positions.size(); ++i)
    if (mesh.positions[i].x() < -0.029) {  // the fitted (least-squares) field there: within 5 % of the tip's
      EXPECT_NEAR((moved[i] - mesh.positions[i]).norm(), 0.0, 0.05 * std::abs(tip));
    }
}

TEST(SphereTreeDeformation, BallOnASoftPlaneMeetsTwoSpringsInSeries) {
  // The soft object is a "plane" (a sphere of radius 1000 m) on one anchor
  // spring k_a; the tool spring is K. Hand D under the rest surface: the
  // surface gives way d = K D / (K + k_a), the force is K k_a D / (K + k_a).
  const double K = 1000.0, ka = 500.0, D = 0.003, R = 1000.0;
  const auto plane = ballTree(R, 2, Vec3(0, 0, -R));
  const auto tool = ballTree(0.005, 2);
  auto soft = SphereTreeDeformation::create(
      plane, {.skeletonLevel = 0, .mass = 0.02, .anchorStiffness = ka, .damping = 4.0});
  ASSERT_TRUE(soft.ok()) << soft.error();
  auto r = SphereTree6DofRenderer::create(tool, {{.tree = plane, .deformation = *soft}},
                                          {.toolLevel = 1, .linearStiffness = Vec3::Constant(K)});
  ASSERT_TRUE(r.ok()) << r.error();
  const Vec3 above(0, 0, 0.02), pressed(0, 0, 0.005 - D);
  (*r)->reset(at(above));
  const HapticResponse out = test::drive(**r, at(above), at(pressed), 200, 3000);
  const double d = K * D / (K + ka), f = K * ka * D / (K + ka);
  EXPECT_NEAR(out.force.z(), f, 0.02 * f);
  EXPECT_NEAR(-(*soft)->displacement(1).z(), d, 0.02 * d);
  EXPECT_NEAR(((*r)->objectForce(0) + out.force).norm(), 0.0, 0.01 * f);
  EXPECT_NEAR((*soft)->supportForce().z(), f, 0.02 * f);

  // Allocation-free ticks with the soft object.
  test::tCountAllocations = true;
  const auto before = test::countedAllocations();
  for (int i = 0; i < 100; ++i) (*r)->tick(test::input(pressed));
  test::tCountAllocations = false;
  EXPECT_EQ(test::countedAllocations(), before);
}

TEST(SphereTreeDeformation, MirrorPushesTheTongueAsideAndItSpringsBack) {
  // A 6 mm ball (the back of a dental mirror) pressed 5 mm into a tongue
  // fixed at its root: the tongue gives way where it is pushed, the
  // force builds smoothly and stays under the rigid K·depth, the user, the
  // tongue and its root are in equilibrium, and released it returns to rest.
  const auto tongue = fittedTree(tongueMesh(), 5);
  const auto mirror = fittedTree(makeIcosphere(0.006, 3), 4);
  ASSERT_TRUE(tongue && mirror);
  auto soft = SphereTreeDeformation::create(tongue, kTongue);
  ASSERT_TRUE(soft.ok()) << soft.error();
  auto r = SphereTree6DofRenderer::create(mirror, {{.tree = tongue, .name = "tongue", .deformation = *soft}},
                                          {.toolLevel = 3});
  ASSERT_TRUE(r.ok()) << r.error();
  // At x = 10 mm the tongue's top is at z = 8 mm · √(1 − 1/9) = 7.54 mm, sloped 5°.
  const double restTop = 0.008 * std::sqrt(1.0 - 1.0 / 9.0);
  const Vec3 press(0.010, 0, restTop), above = press + Vec3(0, 0, 0.016), pressed = press + Vec3(0, 0, 0.001);
  (*r)->reset(at(above));
  std::vector<Vec3> forces;
  double maxStep = 0.0;
  for (int i = 1; i <= 2500; ++i) {
    const double t = std::min(1.0, i / 1000.0);
    const HapticResponse out = (*r)->tick(test::input((1 - t) * above + t * pressed));
    if (!forces.empty()) maxStep = std::max(maxStep, (out.force - forces.back()).norm());
    forces.push_back(out.force);
  }
  const Vec3 f = forces.back();
  EXPECT_GT(f.z(), 0.3);
  EXPECT_LT(f.norm(), test::kStiffness * 0.005 * 0.8);  // softer than a rigid tongue
  EXPECT_LT(maxStep, 0.05);                             // smooth: no jump of more than 50 mN a tick
  // The tongue gave way: the mirror rests more than 1 mm below the rest surface.
  const double mirrorBottom = (*r)->graphicPose().translation().z() - 0.006;
  EXPECT_LT(mirrorBottom, restTop - 0.001);
  // Newton: the tongue takes what the user feels; its root and anchors hold it.
  EXPECT_NEAR(((*r)->objectForce(0) + f).norm(), 0.0, 0.02 * f.norm());
  EXPECT_NEAR(((*soft)->supportForce() - f).norm(), 0.0, 0.05 * f.norm());
  // Locally: under the mirror it sank, the middle less, the root hardly.
  const auto dz = [&](const Vec3& x) {
    const std::vector<SphereTreeNode>& nodes = tongue->nodes();
    std::uint32_t best = 0;
    for (std::uint32_t n = 0; n < nodes.size(); ++n)
      if (nodes[n].level == 4 && (nodes[n].center - x).norm() < (nodes[best].center - x).norm()) best = n;
    return (*soft)->displacement(best).z();
  };
  const double sunk = -dz(press);
  EXPECT_GT(sunk, 0.001);
  EXPECT_GT(dz(Vec3(-0.010, 0, 0.0075)), -0.5 * sunk);
  EXPECT_GT(dz(Vec3(-0.029, 0, 0)), -0.05 * sunk);
  // Lift the mirror: the tongue springs back to rest.
  test::drive(**r, at(pressed), at(above), 200, 3000);
  EXPECT_LT(std::abs(dz(press)), 0.01 * sunk);
}

// The vertex of `positions` nearest `x`, and the area-weighted normal of
// vertex v over `m`'s triangles with `positions`.
std::uint32_t vertexNear(const std::vector<Vec3>& positions, const Vec3& x) {
  std::uint32_t v = 0;
  for (std::uint32_t i = 0; i < positions.size(); ++i)
    if ((positions[i] - x).squaredNorm() < (positions[v] - x).squaredNorm()) v = i;
  return v;
}
Vec3 vertexNormal(const Mesh& m, const std::vector<Vec3>& positions, std::uint32_t v) {
  Vec3 n = Vec3::Zero();
  for (const Triangle& t : m.triangles)
    if (t[0] == v || t[1] == v || t[2] == v)
      n += (positions[t[1]] - positions[t[0]]).cross(positions[t[2]] - positions[t[0]]);
  return n.normalized();
}

TEST(SphereTreeDeformation, ForceFollowsTheBentSurfaceNotItsRestNormal) {
  // The tongue bent by 6 N at its tip; a 1 mm probe touches its top at
  // x = 12 mm with a light spring (its own 10 mN barely adds). The force on
  // a frictionless ball is along the surface normal at the contact: it must
  // match the bent mesh's normal there (the graphics), not the rest one.
  const Mesh mesh = tongueMesh();
  const auto tongue = fittedTree(mesh, 5);
  const auto probe = fittedTree(makeIcosphere(0.001, 3), 4);
  ASSERT_TRUE(tongue && probe);
  auto soft = SphereTreeDeformation::create(tongue, kTongue);
  ASSERT_TRUE(soft.ok()) << soft.error();
  const double k = 50.0;
  auto r = SphereTree6DofRenderer::create(probe, {{.tree = tongue, .deformation = *soft}},
                                          {.toolLevel = 3, .linearStiffness = Vec3::Constant(k)});
  ASSERT_TRUE(r.ok()) << r.error();
  std::uint32_t tip = 0;
  for (std::uint32_t n = 0; n < tongue->nodes().size(); ++n)
    if (tongue->nodes()[n].center.x() > tongue->nodes()[tip].center.x()) tip = n;
  const double x = 0.012, top = 0.008 * std::sqrt(1.0 - (x / 0.030) * (x / 0.030));
  Vec3 hand(x, 0, top + 0.004);
  (*r)->reset(at(hand));
  HapticResponse out;
  bool touched = false;
  for (int i = 0; i < 5000; ++i) {
    (*soft)->addForce(tip, Vec3(0, 0, -6.0));
    if (i >= 3000 && !touched) hand.z() -= 1e-5;  // settled: lower at 10 mm/s until it touches
    out = (*r)->tick(test::input(hand));
    if (i >= 3000 && !touched && out.contacts > 0) {
      touched = true;
      hand.z() -= 0.0002;  // then press 0.2 mm: 10 mN
    }
  }
  ASSERT_TRUE(touched);
  ASSERT_GT(out.contacts, 0);
  const Vec3 f = out.force.normalized();
  const Vec3 contactPoint = (*r)->graphicPose().translation() - 0.001 * f;
  std::vector<Vec3> bent(mesh.positions.size());
  ASSERT_TRUE((*soft)->deform((*soft)->bind(mesh.positions), mesh.positions, bent));
  const std::uint32_t v = vertexNear(bent, contactPoint);
  const Vec3 nBent = vertexNormal(mesh, bent, v), nRest = vertexNormal(mesh, mesh.positions, v);
  const auto degrees = [&](const Vec3& n) {
    return std::acos(std::clamp(f.dot(n), -1.0, 1.0)) * 180 / std::numbers::pi;
  };
  const double bentAngle = degrees(nBent), restAngle = degrees(nRest);
  std::printf(
      "[ tongue bent ] tip sank %.2f mm; force vs bent mesh normal %.2f deg, vs rest normal %.2f deg\n",
      -1e3 * (*soft)->displacement(tip).z(), bentAngle, restAngle);
  EXPECT_GT(-(*soft)->displacement(tip).z(), 0.002);
  EXPECT_GT(restAngle, 3.0);  // the bend is real
  EXPECT_LT(bentAngle, 1.5);
}

TEST(SphereTreeDeformation, ScalerReleasesEachCalculusAtItsBondWithASuddenDrop) {
  // A tooth (10 × 10 × 20 mm box, the face y = 0) with three calculus pieces
  // (1.2 mm balls bonded at 1.5 N) on its face; the scaler (a 1 mm ball)
  // rides along the face pressing 0.2 mm and meets them in turn. Each holds
  // it back until the push reaches the bond; then it comes off and the
  // force falls by more than 1 N within 20 ms. Between releases the force
  // is continuous.
  const double bond = 1.5, rc = 0.0012, rt = 0.001;
  const auto tooth = fittedTree(makeBox(Vec3(0.005, 0.005, 0.010)), 5);
  const auto piece = fittedTree(makeIcosphere(rc, 3), 4);
  const auto scaler = fittedTree(makeIcosphere(rt, 3), 4);
  ASSERT_TRUE(tooth && piece && scaler);
  std::vector<SphereTreeObject> objects{{.tree = tooth, .pose = at(Vec3(0, -0.005, 0)), .name = "tooth"}};
  const double xs[3] = {-0.002, 0.0012, 0.0044};
  for (const double x : xs)
    objects.push_back({.tree = piece, .pose = at(Vec3(x, rt, 0)), .name = "calculus", .releaseForce = bond});
  auto r = SphereTree6DofRenderer::create(scaler, std::move(objects), {.toolLevel = 3});
  ASSERT_TRUE(r.ok()) << r.error();
  const Vec3 from(-0.0045, rt - 0.0002, 0), to(0.0048, rt - 0.0002, 0);
  (*r)->reset(at(from + Vec3(0, 0.0002, 0)));
  std::vector<double> mag;
  std::vector<int> releasedAt;
  std::vector<double> pieceForce;  // on the piece in its release tick
  int released = 0;
  for (int i = 1; i <= 1200; ++i) {
    const double t = std::min(1.0, i / 1000.0);  // 9.3 mm/s
    const HapticResponse out = (*r)->tick(test::input((1 - t) * from + t * to));
    mag.push_back(out.force.norm());
    int now = 0;
    for (std::size_t k = 1; k <= 3; ++k) now += (*r)->objectReleased(k) ? 1 : 0;
    if (now > released) {
      pieceForce.push_back((*r)->objectForce(static_cast<std::size_t>(now)).norm());
      releasedAt.push_back(i - 1);
      released = now;
    }
  }
  ASSERT_EQ(releasedAt.size(), 3u);
  for (std::size_t k = 1; k <= 3; ++k) EXPECT_TRUE((*r)->objectReleased(k));
  EXPECT_FALSE((*r)->objectReleased(0));
  for (std::size_t k = 0; k < 3; ++k) {
    const auto u = static_cast<std::size_t>(releasedAt[k]);
    // The piece comes off at its bond (the push grows 10 mN a tick), the
    // user feeling it with the face's 0.2 N across.
    EXPECT_GT(pieceForce[k], bond);
    EXPECT_LT(pieceForce[k], bond + 0.02);
    EXPECT_NEAR(mag[u], bond, 0.3);
    EXPECT_LT(mag[u + 20], mag[u] - 1.0) << "tick " << u;
  }
  // Continuous while working: no jump over 50 mN a tick except the releases' falls.
  for (std::size_t i = 1; i < mag.size(); ++i) EXPECT_LT(mag[i] - mag[i - 1], 0.05) << "tick " << i;
}

TEST(SphereTreeDeformation, BadInputIsNamed) {
  const auto tree = ballTree(0.01, 3), other = ballTree(0.01, 3);
  const auto fails = [](const auto& r, const char* where) {
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.error().message().find(where), std::string::npos) << r.error().message();
  };
  fails(SphereTreeDeformation::create(nullptr), "tree");
  fails(SphereTreeDeformation::create(tree, {.skeletonLevel = 3}), "options.skeletonLevel");
  fails(SphereTreeDeformation::create(tree, {.skeletonLevel = 0, .mass = 0}), "options.mass");
  fails(SphereTreeDeformation::create(tree, {.skeletonLevel = 0, .linkStiffness = -1}),
        "options.linkStiffness");
  fails(SphereTreeDeformation::create(tree, {.skeletonLevel = 0, .damping = NAN}), "options.damping");
  fails(SphereTreeDeformation::create(tree, {.skeletonLevel = 0, .timeStep = 0}), "options.timeStep");
  fails(SphereTreeDeformation::create(tree, {.skeletonLevel = 0, .anchorStiffness = 0}),
        "options.anchorStiffness");
  fails(SphereTreeDeformation::create(
            tree, {.skeletonLevel = 0, .fixedRegion = Aabb(Vec3::Constant(-1), Vec3::Constant(1))}),
        "options.fixedRegion");
  auto def = SphereTreeDeformation::create(other, {.skeletonLevel = 0});
  ASSERT_TRUE(def.ok());
  fails(SphereTree6DofRenderer::create(tree, {{.tree = tree, .name = "gum", .deformation = *def}},
                                       {.toolLevel = 1}),
        "objects[0] (gum).deformation");
  fails(SphereTree6DofRenderer::create(tree, {{.tree = tree, .releaseForce = 0}}, {.toolLevel = 1}),
        "objects[0].releaseForce");
  fails(SphereTree6DofRenderer::create(tree, {{.tree = tree, .releaseForce = NAN}}, {.toolLevel = 1}),
        "objects[0].releaseForce");
}

}  // namespace
}  // namespace dm
