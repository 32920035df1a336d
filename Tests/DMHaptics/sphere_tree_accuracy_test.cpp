// SphereTree6DofRenderer on curved surfaces: a ball tool (fitted tree of a
// fine icosphere) pressed along the true normal at points all over a
// sphere, a cylinder and a torus (fitted trees of fine meshes) and a
// voxel model of the sphere (trees of its voxels, patches of its
// isosurface), slid over the sphere and rotated in place. Ground truth is analytic: the true
// penetration of the ball into the shape, the shape's normal, and K·depth
// (the renderer's contact model: a spring between the handle and the tool
// resting on the surface). Through the trees' surface patches the force is
// within 2 % and 2° at tool levels 4 and 5; the spheres alone (the published
// method, surfaceTolerance = 0) are printed beside it for the accuracy
// document.
#include <dm/collide/sphere_tree.hpp>
#include <dm/haptics/sphere_tree_6dof.hpp>
#include <dm/math/primitives.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <numbers>
#include <vector>

#include "../common/l_prism.hpp"
#include "haptics_test_support.hpp"

namespace dm {
namespace {

using test::drive;
using test::kStiffness;                // N/m
constexpr double kToolRadius = 0.003;  // m
constexpr double kDepth = 0.001;       // m: how far the handle is pressed in

double angleBetween(const Vec3& a, const Vec3& b) { return std::atan2(a.cross(b).norm(), a.dot(b)); }

// An analytic shape: its signed distance (positive outside) and outward normal.
struct Analytic {
  std::function<double(const Vec3&)> distance;
  std::function<Vec3(const Vec3&)> normal;
};

Analytic sphereShape(double radius) {
  return {[radius](const Vec3& x) { return x.norm() - radius; },
          [](const Vec3& x) { return Vec3(x.normalized()); }};
}
Analytic cylinderShape(double radius) {  // the side, about z
  return {[radius](const Vec3& x) { return std::hypot(x.x(), x.y()) - radius; },
          [](const Vec3& x) { return Vec3(Vec3(x.x(), x.y(), 0).normalized()); }};
}
Analytic torusShape(double major, double minor) {
  const auto tube = [major](const Vec3& x) {
    const double rho = std::hypot(x.x(), x.y());
    return Vec3(x - Vec3(x.x(), x.y(), 0) * (major / rho));
  };
  return {[tube, minor](const Vec3& x) { return tube(x).norm() - minor; },
          [tube](const Vec3& x) { return Vec3(tube(x).normalized()); }};
}

struct Errors {
  double magnitude = 0;  // worst |(|F| − K·depth)| / (K·depth)
  double angle = 0;      // rad, worst angle between F and the true normal
  double inside = 0;     // m, deepest the resting ball went into the shape (≤ 0: it stayed off)
  double off = 0;        // m, farthest the resting ball stayed off the surface
  int presses = 0;
  void add(const HapticResponse& out, const Analytic& shape, const Vec3& n) {
    ++presses;
    magnitude = std::max(magnitude, std::abs(out.force.norm() - kStiffness * kDepth) / (kStiffness * kDepth));
    this->angle = std::max(this->angle, angleBetween(out.force, n));
    const double gap = shape.distance(out.proxyPose.translation()) - kToolRadius;
    inside = std::max(inside, -gap);
    off = std::max(off, gap);
  }
};

// Presses the ball kDepth into `shape` along the true normal at the surface
// points `points` (each from 4 mm off).
Errors pressAll(SphereTree6DofRenderer& r, const Analytic& shape, const std::vector<Vec3>& points) {
  Errors e;
  for (const Vec3& s : points) {
    const Vec3 n = shape.normal(s);
    const Isometry3 start = test::at(s + (kToolRadius + 0.004) * n);
    r.reset(start);
    const HapticResponse out = drive(r, start, test::at(s + (kToolRadius - kDepth) * n), 30, 30);
    EXPECT_GE(out.contacts, 1);
    e.add(out, shape, n);
  }
  return e;
}

// The tool: a fitted tree of a fine icosphere (20480 triangles, chord sag 0.2 µm).
std::shared_ptr<const SphereTree> toolTree() {
  static const auto t = buildSphereTreeFitted(makeIcosphere(kToolRadius, 5), {.levels = 6});
  EXPECT_TRUE(t.ok()) << t.error();
  return t.ok() ? *t : nullptr;
}

std::shared_ptr<const SphereTree> fitted(const Mesh& m, int levels) {
  auto t = buildSphereTreeFitted(m, {.levels = levels});
  EXPECT_TRUE(t.ok()) << t.error();
  return t.ok() ? *t : nullptr;
}

std::unique_ptr<SphereTree6DofRenderer> renderer(
    const std::shared_ptr<const SphereTree>& env, int toolLevel,
    double surfaceTolerance = SphereTree6DofOptions{}.surfaceTolerance) {
  SphereTree6DofOptions opt;
  opt.toolLevel = toolLevel;
  opt.linearStiffness = Vec3::Constant(kStiffness);
  opt.surfaceTolerance = surfaceTolerance;
  auto r = SphereTree6DofRenderer::create(toolTree(), {{.tree = env, .name = "shape"}}, opt);
  EXPECT_TRUE(r.ok()) << r.error();
  return r.ok() ? std::move(*r) : nullptr;
}

void print(const char* shape, int envLevels, int toolLevel, double tolerance, const Errors& e) {
  std::printf(
      "[ spheretree %-8s] env levels %d, tool level %d, %s: |F| %.2f %%, direction %.2f deg, "
      "inside %.1f um, off %.1f um (%d presses)\n",
      shape, envLevels, toolLevel, tolerance > 0 ? "patches" : "spheres ", 100 * e.magnitude,
      e.angle * 180 / std::numbers::pi, 1e6 * e.inside, 1e6 * e.off, e.presses);
}

// The bounds of the issue: 2 % and 2°; the ball never deeper than the
// meshes' chord sag (both are inscribed) nor farther off than 2 % of the
// depth (what the magnitude allows).
void expectWithinBounds(const Errors& e, double sag, const char* what) {
  EXPECT_LT(e.magnitude, 0.02) << what;
  EXPECT_LT(e.angle, 2 * std::numbers::pi / 180) << what;
  EXPECT_LT(e.inside, sag + 1e-7) << what;
  EXPECT_LT(e.off, 0.02 * kDepth) << what;
}

// Chord sag of a triangle of edge `edge` on a sphere of `radius` (its centroid's depth).
double sagOf(double radius, double edge) { return radius - std::sqrt(radius * radius - edge * edge / 3); }

// Points over a sphere of radius `radius`, off its symmetry lines.
std::vector<Vec3> spherePoints(double radius) {
  std::vector<Vec3> out;
  for (int i = 0; i < 6; ++i)
    for (int j = 1; j < 6; ++j) {
      const double u = 2 * std::numbers::pi * (i + 0.37) / 6, v = std::numbers::pi * (j + 0.21) / 6.5;
      out.push_back(radius * Vec3(std::sin(v) * std::cos(u), std::sin(v) * std::sin(u), std::cos(v)));
    }
  return out;
}

// Whether to sweep every level (for docs/haptics-accuracy.md) or test the
// levels the issue names.
bool sweep() { return std::getenv("DM_ACCURACY_SWEEP") != nullptr; }

constexpr double kSphereRadius = 0.02;

const Mesh& sphereMesh() {  // 20480 triangles, edges ≈ 1.2 mm
  static const Mesh m = makeIcosphere(kSphereRadius, 5);
  return m;
}

// The sag of the sphere mesh plus the tool's: how deep inscribed meshes let the ball go.
double sphereSag() { return sagOf(kSphereRadius, 1.3e-3) + sagOf(kToolRadius, 0.13e-3); }

TEST(SphereTreeAccuracy, BallPressedIntoASphereEverywhere) {
  const Analytic shape = sphereShape(kSphereRadius);
  for (const int levels : sweep() ? std::vector<int>{4, 5, 6} : std::vector<int>{5}) {
    const auto env = fitted(sphereMesh(), levels);
    ASSERT_TRUE(env && toolTree());
    for (const int toolLevel : sweep() ? std::vector<int>{3, 4, 5} : std::vector<int>{4, 5}) {
      auto r = renderer(env, toolLevel);
      ASSERT_TRUE(r);
      const Errors e = pressAll(*r, shape, spherePoints(kSphereRadius));
      print("sphere", levels, toolLevel, 0.1, e);
      expectWithinBounds(e, sphereSag(), "sphere");
      if (!sweep()) continue;
      print("sphere", levels, toolLevel, 0.0,
            pressAll(*renderer(env, toolLevel, 0.0), shape, spherePoints(kSphereRadius)));
    }
  }
}

// Without patches (the published method) the same press is far off: the
// failure the issue reported, kept as the contrast that shows what the
// patches do.
TEST(SphereTreeAccuracy, SpheresAloneStandOffTheSurface) {
  const auto env = fitted(sphereMesh(), 5);
  ASSERT_TRUE(env && toolTree());
  auto r = renderer(env, 4, 0.0);
  ASSERT_TRUE(r);
  const Errors e = pressAll(*r, sphereShape(kSphereRadius), spherePoints(kSphereRadius));
  EXPECT_GT(e.off, 10 * kDepth * 0.02);
  EXPECT_GT(e.angle, 5 * std::numbers::pi / 180);
}

// Sliding the pressed ball along a great circle (5 cm/s) and turning it in
// place (0.5 turn/s): frictionless, the force stays on the true normal at the
// tool, K times the handle's true penetration, and a ball feels no torque.
TEST(SphereTreeAccuracy, BallSlidAndTurnedOnASphere) {
  const auto env = fitted(sphereMesh(), 5);
  ASSERT_TRUE(env && toolTree());
  for (const int toolLevel : {4, 5}) {
    auto r = renderer(env, toolLevel);
    ASSERT_TRUE(r);
    const double reach = kSphereRadius + kToolRadius - kDepth;
    const auto onCircle = [&](double a) {  // a great circle tilted off the axes
      const Vec3 e1 = Vec3(1, 0.2, 0.1).normalized(), e2 = e1.cross(Vec3(0.3, -0.1, 1)).normalized();
      return Vec3(std::cos(a) * e1 + std::sin(a) * e2);
    };
    const Isometry3 start = test::at((reach + 0.005) * onCircle(0));
    r->reset(start);
    test::drive(*r, start, test::at(reach * onCircle(0)), 30, 30);
    Errors slide, turn;
    double torque = 0;
    const double speed = 0.05;  // m/s
    for (int i = 1; i <= 400; ++i) {
      const double a = speed * 1e-3 * i / reach;
      const Vec3 h = reach * onCircle(a);
      const HapticResponse out = r->tick({.timeNs = i * 1000000LL, .dt = 1e-3, .devicePose = test::at(h)});
      if (i > 20) slide.add(out, sphereShape(kSphereRadius), out.proxyPose.translation().normalized());
    }
    const Vec3 h = reach * onCircle(speed * 0.4 / reach);
    const Vec3 axis = Vec3(0.2, 1, -0.4).normalized();
    for (int i = 1; i <= 500; ++i) {
      const Mat3 rot = AngleAxis(std::numbers::pi * 1e-3 * i, axis).toRotationMatrix();
      const HapticResponse out =
          r->tick({.timeNs = i * 1000000LL, .dt = 1e-3, .devicePose = test::at(h, rot)});
      turn.add(out, sphereShape(kSphereRadius), h.normalized());
      torque = std::max(torque, out.torque.norm());
    }
    print("sphere slide", 5, toolLevel, 0.1, slide);
    print("sphere turn", 5, toolLevel, 0.1, turn);
    expectWithinBounds(slide, sphereSag(), "sliding");
    expectWithinBounds(turn, sphereSag(), "turning");
    // A ball's contact normal passes through its centre: any torque is the
    // lever of the 2° direction bound at most.
    EXPECT_LT(torque, kStiffness * kDepth * kToolRadius * std::sin(2 * std::numbers::pi / 180)) << toolLevel;
  }
}

TEST(SphereTreeAccuracy, BallPressedIntoACylinderAndATorus) {
  const double cr = 0.012, R = 0.04, r0 = 0.015;
  const Mesh cylinder = makeCylinder(cr, 0.06, 512);
  const Mesh torus = makeTorus(R, r0, 256, 128);
  std::vector<Vec3> cylPoints, torusPoints;
  for (int i = 0; i < 8; ++i) {
    const double u = 2 * std::numbers::pi * (i + 0.37) / 8;
    for (const double z : {-0.013, 0.004, 0.017})
      cylPoints.push_back(Vec3(cr * std::cos(u), cr * std::sin(u), z));
    for (int j = 0; j < 6; ++j) {
      const double v = 2 * std::numbers::pi * (j + 0.29) / 6;
      const Vec3 n(std::cos(v) * std::cos(u), std::cos(v) * std::sin(u), std::sin(v));
      torusPoints.push_back(Vec3(R * std::cos(u), R * std::sin(u), 0) + r0 * n);
    }
  }
  const double toolSag = sagOf(kToolRadius, 0.13e-3);
  const double cylSag = cr * (1 - std::cos(std::numbers::pi / 512)) + toolSag;
  const double torusSag = r0 * (1 - std::cos(std::numbers::pi / 128)) +
                          (R + r0) * (1 - std::cos(std::numbers::pi / 256)) + toolSag;
  // The torus is 11 cm across: its leaves are 2.3 times the cylinder's at
  // the same level (a quadric patch leaves a third-order error where the
  // curvature varies, as around a torus), so it gets a level more.
  for (const int levels : sweep() ? std::vector<int>{5, 6, 7} : std::vector<int>{6}) {
    const auto cylTree = fitted(cylinder, levels), torusTree = fitted(torus, levels + 1);
    ASSERT_TRUE(cylTree && torusTree && toolTree());
    for (const int toolLevel : sweep() ? std::vector<int>{4, 5} : std::vector<int>{4}) {
      const Errors c = pressAll(*renderer(cylTree, toolLevel), cylinderShape(cr), cylPoints);
      const Errors t = pressAll(*renderer(torusTree, toolLevel), torusShape(R, r0), torusPoints);
      print("cylinder", levels, toolLevel, 0.1, c);
      print("torus", levels + 1, toolLevel, 0.1, t);
      expectWithinBounds(c, cylSag, "cylinder");
      expectWithinBounds(t, torusSag, "torus");
    }
  }
}

// A box's signed distance and its gradient (outward; at a point beside an
// edge or a corner, from the nearest point of the box to it).
Analytic boxShape(const Vec3& h) {
  return {[h](const Vec3& x) {
            const Vec3 q = x.cwiseAbs() - h;
            return q.cwiseMax(0.0).norm() + std::min(q.maxCoeff(), 0.0);
          },
          [h](const Vec3& x) {
            const Vec3 q = x.cwiseAbs() - h;
            Vec3 g = Vec3::Zero();
            if (q.maxCoeff() > 0) {
              g = q.cwiseMax(0.0);
            } else if (q.maxCoeff() == 0) {  // on the surface: on an edge the bisector, a corner the diagonal
              g = (q.array() == 0).cast<double>();
            } else {
              Vec3::Index i = 0;
              q.maxCoeff(&i);
              g[i] = 1;
            }
            return Vec3(g.cwiseProduct(x.cwiseSign()).normalized());
          }};
}

constexpr double kBoxHalf[3] = {0.02, 0.015, 0.01};

// A box's edges and corners: the true normal there is the direction from
// the edge or corner to the ball's centre, which no face's normal is. The
// tree's edge and corner nodes hold creases (planes grouped from their
// facets), which the renderer touches by the tool's centre of curvature.
TEST(SphereTreeAccuracy, BallPressedIntoBoxEdgesAndCorners) {
  const Vec3 h(kBoxHalf[0], kBoxHalf[1], kBoxHalf[2]);
  const Analytic shape = boxShape(h);
  std::vector<Vec3> points;  // on edges of each direction (off their middles), and corners
  for (const double t : {-0.6, 0.1, 0.45}) {
    points.push_back(Vec3(t * h.x(), h.y(), h.z()));
    points.push_back(Vec3(-h.x(), t * h.y(), h.z()));
    points.push_back(Vec3(h.x(), -h.y(), t * h.z()));
  }
  for (const Vec3& c : {Vec3(1, 1, 1), Vec3(-1, 1, 1), Vec3(1, -1, -1), Vec3(-1, -1, -1)})
    points.push_back(c.cwiseProduct(h));
  const double toolSag = sagOf(kToolRadius, 0.13e-3);
  for (const int levels : sweep() ? std::vector<int>{5, 6, 7} : std::vector<int>{6}) {
    const auto env = fitted(makeBox(h), levels);
    ASSERT_TRUE(env && toolTree());
    for (const int toolLevel : sweep() ? std::vector<int>{3, 4, 5} : std::vector<int>{4, 5}) {
      const Errors e = pressAll(*renderer(env, toolLevel), shape, points);
      print("box edges", levels, toolLevel, 0.1, e);
      expectWithinBounds(e, toolSag, "box edges and corners");
      if (sweep())
        print("box edges", levels, toolLevel, 0.0, pressAll(*renderer(env, toolLevel, 0.0), shape, points));
    }
  }
}

// Rolling the pressed ball over an edge, from the top face round to the
// side: the force turns with the true normal at the handle, K times its
// true penetration, all the way round.
TEST(SphereTreeAccuracy, BallRolledOverABoxEdge) {
  const Vec3 h(kBoxHalf[0], kBoxHalf[1], kBoxHalf[2]);
  const Analytic shape = boxShape(h);
  const auto env = fitted(makeBox(h), 6);
  ASSERT_TRUE(env && toolTree());
  const Vec3 edge(0.003, h.y(), h.z());  // the edge along x at the top's +y side
  const double arm = kToolRadius - kDepth;
  const auto handle = [&](double a) { return Vec3(edge + arm * Vec3(0, std::sin(a), std::cos(a))); };
  for (const int toolLevel : {4, 5}) {
    auto r = renderer(env, toolLevel);
    ASSERT_TRUE(r);
    const double a0 = -0.5, a1 = 0.5 * std::numbers::pi + 0.5;  // from over the top to over the side
    const Isometry3 start = test::at(handle(a0) + Vec3(0, 0, 0.004));
    r->reset(start);
    test::drive(*r, start, test::at(handle(a0)), 30, 30);
    double magnitude = 0, angle = 0, inside = 0;
    const int ticks = 1000;  // 2.6 rad in 1 s: 5 mm/s at the handle
    for (int i = 1; i <= ticks; ++i) {
      const Vec3 hp = handle(a0 + (a1 - a0) * i / ticks);
      const HapticResponse out = r->tick({.timeNs = i * 1000000LL, .dt = 1e-3, .devicePose = test::at(hp)});
      const double expected = kStiffness * (kToolRadius - shape.distance(hp));
      magnitude = std::max(magnitude, std::abs(out.force.norm() - expected) / expected);
      angle = std::max(angle, angleBetween(out.force, shape.normal(hp)));
      inside = std::max(inside, kToolRadius - shape.distance(out.proxyPose.translation()));
    }
    std::printf(
        "[ spheretree box roll  ] env levels 6, tool level %d: |F| %.2f %%, direction %.2f deg, inside %.1f "
        "um\n",
        toolLevel, 100 * magnitude, angle * 180 / std::numbers::pi, 1e6 * inside);
    EXPECT_LT(magnitude, 0.02) << toolLevel;
    EXPECT_LT(angle, 2 * std::numbers::pi / 180) << toolLevel;
    EXPECT_LT(inside, sagOf(kToolRadius, 0.13e-3) + 1e-7) << toolLevel;
  }
}

// A groove (the L prism's inner edge, concave): the ball pressed into it
// along the bisector rests on both faces, its centre R from each, and the
// force is K·depth along the bisector.
TEST(SphereTreeAccuracy, BallPressedIntoAGroove) {
  const double c = 0.0093;  // the groove at (c, c), off the tree's cell walls
  const auto env = fitted(test::lPrism(0.01, c, 0.01), 6);
  ASSERT_TRUE(env && toolTree());
  const Vec3 m = Vec3(1, 1, 0).normalized();
  for (const int toolLevel : {4, 5}) {
    auto r = renderer(env, toolLevel);
    ASSERT_TRUE(r);
    double magnitude = 0, angle = 0, off = 0;
    for (const double z : {-0.002, 0.0007, 0.0021}) {
      const Vec3 rest(c + kToolRadius, c + kToolRadius, z);  // touching both faces
      const Isometry3 start = test::at(rest + 0.004 * m);
      r->reset(start);
      const HapticResponse out = drive(*r, start, test::at(rest - kDepth * m), 30, 30);
      magnitude =
          std::max(magnitude, std::abs(out.force.norm() - kStiffness * kDepth) / (kStiffness * kDepth));
      angle = std::max(angle, angleBetween(out.force, m));
      off = std::max(off, (out.proxyPose.translation() - rest).norm());
    }
    std::printf(
        "[ spheretree groove   ] env levels 6, tool level %d: |F| %.2f %%, direction %.2f deg, off %.1f um\n",
        toolLevel, 100 * magnitude, angle * 180 / std::numbers::pi, 1e6 * off);
    EXPECT_LT(magnitude, 0.02) << toolLevel;
    EXPECT_LT(angle, 2 * std::numbers::pi / 180) << toolLevel;
    EXPECT_LT(off, 0.02 * kDepth) << toolLevel;
  }
}

// A voxel model of the sphere as a scanner's smooth intensities give it,
// not a binary mask: the signed distance R − |x| sampled at voxel centres on
// a grid of spacing `spacing` (per axis), turned by `turn`, occupied where > 0.
Volume voxelSphere(const Vec3& spacing, const Mat3& turn) {
  const Vec3i n = (2.0 * (kSphereRadius + 0.004) * spacing.cwiseInverse()).array().ceil().cast<int>() + 1;
  Affine3 a = Affine3::Identity();
  a.linear() = turn * spacing.asDiagonal();
  a.translation() = -(a.linear() * (0.5 * (n - Vec3i::Ones()).cast<double>()));
  auto v = Volume::create(n, VoxelType::F32, a);
  EXPECT_TRUE(v.ok());
  for (int k = 0; k < n.z(); ++k)
    for (int j = 0; j < n.y(); ++j)
      for (int i = 0; i < n.x(); ++i) v->setValue(i, j, k, kSphereRadius - (a * Vec3(i, j, k)).norm());
  return std::move(*v);
}

// Trees built from that voxel model: their patches are fitted to its
// isosurface at the threshold (trilinear between voxel centres: inside the
// true sphere by at most about its chord sag over a voxel diagonal), not
// to the voxels' cubes. Before them, a ball pressed on such a tree felt the
// cubes' spheres: a third of the force sideways on a 60³ grid at 6 levels.
TEST(SphereTreeAccuracy, BallPressedIntoAVoxelSphere) {
  const Analytic shape = sphereShape(kSphereRadius);
  const double toolSag = sagOf(kToolRadius, 0.13e-3);
  struct Case {
    const char* name;
    Vec3 spacing;
    Mat3 turn;
    bool fittedTree;
  };
  const Mat3 tilt = Eigen::AngleAxisd(0.3, Vec3(1, 2, 3).normalized()).toRotationMatrix();
  const std::vector<Case> cases = {{"voxels", Vec3::Constant(0.5e-3), Mat3::Identity(), true},
                                   {"voxels~", Vec3(0.5e-3, 0.6e-3, 0.45e-3), tilt, false}};
  for (const Case& c : cases) {
    const Volume v = voxelSphere(c.spacing, c.turn);
    const double sag = sagOf(kSphereRadius, std::sqrt(3.0) * c.spacing.maxCoeff()) + toolSag;
    for (const int levels : sweep() ? std::vector<int>{5, 6, 7} : std::vector<int>{6}) {
      SphereTreeOptions opt;
      opt.levels = levels;
      auto env = c.fittedTree ? buildSphereTreeFitted(v, opt) : buildSphereTreeOctree(v, opt);
      ASSERT_TRUE(env.ok()) << env.error();
      ASSERT_EQ((*env)->patches().size(), (*env)->nodes().size());
      for (const int toolLevel : sweep() ? std::vector<int>{4, 5} : std::vector<int>{4}) {
        const Errors e = pressAll(*renderer(*env, toolLevel), shape, spherePoints(kSphereRadius));
        print(c.name, levels, toolLevel, 0.1, e);
        expectWithinBounds(e, sag, c.name);
        if (sweep())
          print(c.name, levels, toolLevel, 0.0,
                pressAll(*renderer(*env, toolLevel, 0.0), shape, spherePoints(kSphereRadius)));
      }
    }
  }
}

}  // namespace
}  // namespace dm
