// Tests of dm/collide/sphere_tree.hpp and the sphere-tree colliders: coverage
// of surfaces, solids and voxels by dense sampling (every sample lies on a
// root-to-leaf path of spheres that all contain it), the minimal spheres of
// analytic shapes, fitted trees tighter than octree trees, the implicit tree's
// cell spheres against the cell corners, and the colliders against brute
// force over the leaf spheres and against the source TriangleMesh
// (conservative: the tree reports every hit of the mesh).
#include <dm/collide/bvh.hpp>
#include <dm/collide/mesh_query.hpp>
#include <dm/collide/query.hpp>
#include <dm/collide/sphere_tree.hpp>
#include <dm/math/geometry.hpp>
#include <dm/math/primitives.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <numbers>
#include <random>
#include <vector>

#include "../common/l_prism.hpp"
#include "collide_test_support.hpp"

namespace {

using dm::BoundingSphere;
using dm::Isometry3;
using dm::SphereHierarchy;
using dm::Vec3;

constexpr double kInf = std::numeric_limits<double>::infinity();

// Vertices, points along edges and random points inside every triangle.
std::vector<Vec3> sampleSurface(const dm::Mesh& m, int perTriangle, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<Vec3> out(m.positions);
  for (const dm::Triangle& t : m.triangles) {
    const Vec3 a = m.positions[t[0]], b = m.positions[t[1]], c = m.positions[t[2]];
    for (int i = 1; i < 4; ++i) {
      const double s = i / 4.0;
      out.push_back(a + s * (b - a));
      out.push_back(b + s * (c - b));
      out.push_back(c + s * (a - c));
    }
    for (int i = 0; i < perTriangle; ++i) {
      double x = u(rng), y = u(rng);
      if (x + y > 1) x = 1 - x, y = 1 - y;
      out.push_back(a + x * (b - a) + y * (c - a));
    }
  }
  return out;
}

// Random points inside a closed mesh (rejection sampling in its bounds).
std::vector<Vec3> sampleSolid(const dm::Mesh& m, int n, std::uint64_t seed) {
  auto bvh = dm::MeshBvh::build(m);
  EXPECT_TRUE(bvh.ok());
  std::mt19937_64 rng(seed);
  const dm::Aabb box = m.bounds();
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<Vec3> out;
  while (static_cast<int>(out.size()) < n) {
    const Vec3 p = box.min() + box.sizes().cwiseProduct(Vec3(u(rng), u(rng), u(rng)));
    if (dm::closestPointOnMesh(*bvh, Isometry3::Identity(), p).distance < 0) out.push_back(p);
  }
  return out;
}

bool contains(const BoundingSphere& s, const Vec3& p, double tol) {
  return (p - s.center).norm() <= s.radius + tol;
}

// True when some root-to-leaf path has every sphere containing p: what makes
// pruning by a node's sphere valid and every level a cover.
bool onCoveringPath(const SphereHierarchy& t, SphereHierarchy::NodeId n, const Vec3& p, double tol) {
  if (!contains(t.sphere(n), p, tol)) return false;
  SphereHierarchy::NodeId kids[8];
  const int k = t.children(n, kids);
  if (k == 0) return true;
  for (int i = 0; i < k; ++i)
    if (onCoveringPath(t, kids[i], p, tol)) return true;
  return false;
}

std::size_t uncovered(const SphereHierarchy& t, const std::vector<Vec3>& pts, double tol) {
  std::size_t n = 0;
  for (const Vec3& p : pts) n += !onCoveringPath(t, t.root(), p, tol);
  return n;
}

// Leaf spheres of any hierarchy (brute-force reference for the colliders).
void leaves(const SphereHierarchy& t, SphereHierarchy::NodeId n, std::vector<BoundingSphere>& out) {
  SphereHierarchy::NodeId kids[8];
  const int k = t.children(n, kids);
  if (k == 0) out.push_back(t.sphere(n));
  for (int i = 0; i < k; ++i) leaves(t, kids[i], out);
}
std::vector<BoundingSphere> leavesOf(const SphereHierarchy& t) {
  std::vector<BoundingSphere> out;
  leaves(t, t.root(), out);
  return out;
}

Isometry3 randomTreePose(std::mt19937_64& rng, double spread) {
  std::uniform_real_distribution<double> u(-1, 1);
  Isometry3 p = Isometry3::Identity();
  p.linear() = Eigen::Quaterniond(u(rng), u(rng), u(rng), u(rng)).normalized().toRotationMatrix();
  p.translation() = spread * Vec3(u(rng), u(rng), u(rng));
  return p;
}

using dm::test::at;

const dm::Mesh& torus() {
  static const dm::Mesh m = dm::makeTorus(0.1, 0.03, 32, 12);
  return m;
}

std::shared_ptr<const dm::SphereTree> build(const dm::Mesh& m, bool fitted, int levels, bool solid = false) {
  dm::SphereTreeOptions o;
  o.levels = levels;
  o.solid = solid;
  auto t = fitted ? dm::buildSphereTreeFitted(m, o) : dm::buildSphereTreeOctree(m, o);
  EXPECT_TRUE(t.ok()) << (t.ok() ? "" : t.error().what);
  return t.ok() ? *t : nullptr;
}

// ------------------------------------------------------------ coverage ---

TEST(SphereTree, SurfaceCoverageOfBoxIcosphereTorus) {
  const dm::Mesh meshes[] = {dm::makeBox(Vec3(0.3, 0.2, 0.1)), dm::makeIcosphere(0.05, 2), torus()};
  for (const dm::Mesh& m : meshes) {
    const std::vector<Vec3> pts = sampleSurface(m, 12, 7);
    const double tol = 1e-12 * m.bounds().sizes().norm();
    for (bool fitted : {false, true}) {
      auto t = build(m, fitted, 4);
      ASSERT_TRUE(t);
      EXPECT_EQ(t->levelCount(), 4);
      EXPECT_EQ(uncovered(*t, pts, tol), 0u) << "fitted " << fitted;
      // The levels are breadth-first and every level lies in its span.
      std::size_t total = 0;
      for (int l = 0; l < 4; ++l) {
        for (const dm::SphereTreeNode& n : t->level(l)) EXPECT_EQ(n.level, l);
        total += t->level(l).size();
      }
      EXPECT_EQ(total, t->nodes().size());
    }
  }
}

TEST(SphereTree, SolidCoverageOfBoxAndTorus) {
  const dm::Mesh meshes[] = {dm::makeBox(Vec3(0.3, 0.2, 0.1)), torus()};
  for (const dm::Mesh& m : meshes) {
    std::vector<Vec3> pts = sampleSolid(m, 800, 11);
    const std::vector<Vec3> surface = sampleSurface(m, 1, 3);
    pts.insert(pts.end(), surface.begin(), surface.end());
    const double tol = 1e-12 * m.bounds().sizes().norm();
    for (bool fitted : {false, true}) {
      auto t = build(m, fitted, 4, true);
      ASSERT_TRUE(t);
      EXPECT_EQ(uncovered(*t, pts, tol), 0u) << "fitted " << fitted;
      // Spheres that cover a solid hold at least its volume on every level.
      for (const dm::SphereTreeLevelStats& s : t->levelStats()) EXPECT_GE(s.tightness, 1.0 - 1e-9) << s.level;
    }
  }
}

TEST(SphereTree, RootIsTheMinimalSphere) {
  // Minimal enclosing sphere of a box: its circumsphere; of an icosphere:
  // the sphere through its vertices.
  const Vec3 h(0.3, 0.2, 0.1);
  auto box = build(dm::makeBox(h), false, 3);
  ASSERT_TRUE(box);
  EXPECT_NEAR(box->nodes()[0].radius, h.norm(), 1e-9);
  EXPECT_LT(box->nodes()[0].center.norm(), 1e-9);
  auto ball = build(dm::makeIcosphere(0.05, 3), true, 3);
  ASSERT_TRUE(ball);
  EXPECT_NEAR(ball->nodes()[0].radius, 0.05, 1e-9);
  // Bound radii enclose the leaf spheres below.
  for (const dm::SphereTreeNode& n : ball->nodes()) EXPECT_GE(n.boundRadius, n.radius);
}

TEST(SphereTree, FittedIsTighterThanOctreeOnTheTorus) {
  auto oct = build(torus(), false, 4);
  auto fit = build(torus(), true, 4);
  ASSERT_TRUE(oct && fit);
  const auto so = oct->levelStats(), sf = fit->levelStats();
  ASSERT_EQ(so.size(), 4u);
  ASSERT_EQ(sf.size(), 4u);
  // Reference: the enclosed volume of the polygonal torus, a little below
  // the smooth torus's 2π²Rr².
  const double smooth = 2 * std::numbers::pi * std::numbers::pi * 0.1 * 0.03 * 0.03;
  EXPECT_LT(oct->referenceVolume(), smooth);
  EXPECT_GT(oct->referenceVolume(), 0.9 * smooth);
  // Same sphere budget per level (within 2 %), less sphere volume.
  for (std::size_t l = 1; l < 4; ++l) {
    EXPECT_LE(sf[l].count, so[l].count + so[l].count / 50) << l;
    EXPECT_LT(sf[l].tightness, so[l].tightness) << l;
  }
  EXPECT_LT(sf[3].tightness, 0.7 * so[3].tightness);
  // The deepest level is much tighter than the first split.
  EXPECT_LT(so[3].tightness, so[1].tightness);
  EXPECT_LT(sf[3].tightness, sf[1].tightness);
}

TEST(SphereTree, BuildErrors) {
  dm::SphereTreeOptions o;
  o.levels = 0;
  EXPECT_EQ(dm::buildSphereTreeOctree(torus(), o).error().code, dm::ErrorCode::InvalidArgument);
  o.levels = 11;
  EXPECT_FALSE(dm::buildSphereTreeFitted(torus(), o).ok());
  dm::Mesh open = dm::makeBox(Vec3::Ones());
  open.triangles.pop_back();
  o.levels = 3;
  o.solid = true;
  auto r = dm::buildSphereTreeOctree(open, o);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().what.find("closed"), std::string::npos) << r.error().what;
  EXPECT_FALSE(dm::buildSphereTreeOctree(dm::Mesh{}, {}).ok());
}

TEST(SphereTree, FromNodesChecksTheLayout) {
  std::vector<dm::SphereTreeNode> nodes(3);
  nodes[0].radius = 1.0;
  nodes[0].firstChild = 1;
  nodes[0].childCount = 2;
  for (int i : {1, 2}) {
    nodes[i].level = 1;
    nodes[i].radius = 0.5;
    nodes[i].center = Vec3(i == 1 ? -0.5 : 0.5, 0, 0);
  }
  auto ok = dm::SphereTree::fromNodes(nodes, 1.0);
  ASSERT_TRUE(ok.ok());
  EXPECT_NEAR((*ok)->nodes()[0].boundRadius, 1.0, 1e-9);
  auto bad = nodes;
  bad[2].level = 2;
  auto r = dm::SphereTree::fromNodes(bad, 1.0);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().what.find("node 2"), std::string::npos) << r.error().what;
  bad = nodes;
  bad[0].firstChild = 2;
  EXPECT_FALSE(dm::SphereTree::fromNodes(bad, 1.0).ok());
  bad = nodes;
  bad[1].radius = -1;
  EXPECT_FALSE(dm::SphereTree::fromNodes(bad, 1.0).ok());
  EXPECT_FALSE(dm::SphereTree::fromNodes(nodes, 0.0).ok());
}

// Every node of a mesh tree stores the quadric patch of its surface. On a
// sphere (a quadric) the leaves' patches carry the surface exactly: normals
// radial, the curvature 1/R, every mesh vertex of the leaf on or just under
// the patch (within its deviation), and the support point along a direction
// is the sphere's own; a box's corner leaf mixes three faces (incoherent).
TEST(SphereTree, MeshTreesStoreTheSurfaceAsQuadricPatches) {
  const double r = 0.02;
  const dm::Mesh mesh = dm::makeIcosphere(r, 6);
  auto tree = dm::buildSphereTreeFitted(mesh, {.levels = 5});
  ASSERT_TRUE(tree.ok()) << tree.error();
  const auto patches = (*tree)->patches();
  ASSERT_EQ(patches.size(), (*tree)->nodes().size());
  double sag = 0;  // the deepest point of the mesh under the sphere: a triangle's centroid
  for (const dm::Triangle& t : mesh.triangles)
    sag = std::max(sag, r - (mesh.positions[t[0]] + mesh.positions[t[1]] + mesh.positions[t[2]]).norm() / 3);
  EXPECT_LT(patches[0].coherence, 0.01) << "the root holds the whole closed sphere";
  int leaves = 0;
  for (std::size_t i = (*tree)->nodes().size() - (*tree)->level(4).size(); i < patches.size(); ++i) {
    const dm::SurfacePatch& p = patches[i];
    ASSERT_TRUE(p.valid()) << i;
    ++leaves;
    EXPECT_GT(p.coherence, 0.99);
    // The band holds the chord sag (vertices on the sphere, cut points on
    // the facets under it) and the fit's own error, spread both ways.
    EXPECT_LT(p.deviation, 2 * sag) << "the mesh's chord sag is " << sag;
    const Vec3 c = p.origin + p.coeff[0] * p.normal;  // the patch above its centroid
    EXPECT_NEAR(c.norm(), r, sag + 1e-7);
    EXPECT_LT(std::acos(std::min(1.0, p.query(c).normal.dot(c.normalized()))), 1e-3) << "radial normal";
    // Curvature 1/R, curving away from the normal (a leaf spans a few
    // 0.6 mm facets, whose flat samples bias the fit a little).
    EXPECT_NEAR(p.coeff[3], -1 / r, 0.05 / r);
    EXPECT_NEAR(p.coeff[5], -1 / r, 0.05 / r);
    EXPECT_NEAR(p.coeff[4], 0.0, 0.05 / r);
    // A point 1 mm off the sphere along its normal is 1 mm off the patch.
    const Vec3 out = c.normalized() * (r + 0.001);
    EXPECT_NEAR(p.query(out).distance, 0.001, 2 * sag);
    // The support point towards the normal is the top of the cap.
    EXPECT_NEAR((p.support(c.normalized()) - c).norm(), 0.0, 2e-5);
  }
  EXPECT_GT(leaves, 100);

  auto box = dm::buildSphereTreeOctree(dm::makeBox(Vec3(0.01, 0.01, 0.01)), {.levels = 3});
  ASSERT_TRUE(box.ok()) << box.error();
  int incoherent = 0;
  for (const dm::SurfacePatch& p : (*box)->patches()) incoherent += p.valid() && p.coherence < 0.9 ? 1 : 0;
  EXPECT_GE(incoherent, 8) << "the corner cells hold three faces";
}

// A box's edges and corners are creases of two and three convex planes,
// and a groove (the L prism's inner edge) one of two concave planes; their
// distances are the exact signed distances to those solids.
TEST(SphereTree, MeshTreesStoreEdgesAndCornersAsCreases) {
  const Vec3 h(0.02, 0.015, 0.01);
  auto box = dm::buildSphereTreeFitted(dm::makeBox(h), {.levels = 5});
  ASSERT_TRUE(box.ok()) << box.error();
  const auto boxDistance = [&](const Vec3& x) {
    const Vec3 q = x.cwiseAbs() - h;
    return q.cwiseMax(0.0).norm() + std::min(q.maxCoeff(), 0.0);
  };
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  int planes[4] = {0, 0, 0, 0}, compared = 0;
  const auto nodes = (*box)->nodes();
  for (std::size_t i = nodes.size() - (*box)->level(4).size(); i < nodes.size(); ++i) {
    const dm::SurfacePatch& p = (*box)->patches()[i];
    ++planes[p.crease.planes];
    if (!p.hasCrease()) continue;
    EXPECT_TRUE(p.crease.convex) << i;
    EXPECT_LT(p.crease.deviation, 1e-12);
    std::array<bool, 3> axisUsed{};
    for (int k = 0; k < p.crease.planes; ++k) {
      const Vec3& n = p.crease.normal[k];
      Eigen::Index axis = 0;
      n.cwiseAbs().maxCoeff(&axis);
      EXPECT_NEAR(std::abs(n[axis]), 1.0, 1e-12) << "a face's normal";
      EXPECT_NEAR(p.crease.offset[k], h[axis], 1e-12);
      axisUsed[static_cast<std::size_t>(axis)] = true;
    }
    // Points about the node where the box's other faces are farther than
    // its own planes: the crease's distance is the box's.
    for (int t = 0; t < 40; ++t) {
      const Vec3 x = p.origin + 2.0 * p.crease.reach * Vec3(unit(rng), unit(rng), unit(rng));
      bool clear = true;
      for (int a = 0; a < 3; ++a)
        if (!axisUsed[static_cast<std::size_t>(a)])
          clear = clear && std::abs(x[a]) < h[a] - std::abs(boxDistance(x)) - 1e-9;
      if (!clear) continue;
      ++compared;
      const dm::SurfacePatch::Query q = p.creaseQuery(x);
      EXPECT_NEAR(q.distance, boxDistance(x), 1e-12) << "node " << i;
      // The normal points from the nearest point of the solid to x.
      const Vec3 nearest = x - q.distance * q.normal;
      EXPECT_NEAR(boxDistance(nearest), 0.0, 1e-12);
      EXPECT_NEAR(q.normal.norm(), 1.0, 1e-12);
    }
  }
  EXPECT_GE(planes[3], 8) << "the corners";
  EXPECT_GE(planes[2], 12) << "the edges";
  EXPECT_GT(planes[0], planes[2]) << "the faces";
  EXPECT_GT(compared, 500);

  const double a = 0.0093;  // the groove (off the cells' walls) at (a, a); the L is 2 cm square
  auto l = dm::buildSphereTreeFitted(dm::test::lPrism(0.01, a, 0.01), {.levels = 5});
  ASSERT_TRUE(l.ok()) << l.error();
  const auto grooveDistance = [a](const Vec3& x) {  // near the inner edge, between the L's arms
    if (x.x() >= a && x.y() >= a) return std::min(x.x() - a, x.y() - a);
    return -std::hypot(std::max(a - x.x(), 0.0), std::max(a - x.y(), 0.0));
  };
  int grooves = 0, grooveCompared = 0;
  const auto lNodes = (*l)->nodes();
  for (std::size_t i = lNodes.size() - (*l)->level(4).size(); i < lNodes.size(); ++i) {
    const dm::SurfacePatch& p = (*l)->patches()[i];
    if (!p.hasCrease() || p.crease.convex) continue;
    ++grooves;
    ASSERT_EQ(p.crease.planes, 2) << "a groove of two faces";
    EXPECT_NEAR(std::hypot(p.origin.x() - a, p.origin.y() - a), 0.0, 2 * p.crease.reach)
        << "on the inner edge";
    for (int t = 0; t < 40; ++t) {
      const Vec3 x = p.origin + 2.0 * p.crease.reach * Vec3(unit(rng), unit(rng), unit(rng));
      if (std::abs(x.z()) > 0.004 || x.x() < 0.5 * a || x.y() < 0.5 * a || x.x() > 1.5 * a || x.y() > 1.5 * a)
        continue;  // the top, bottom and outer faces are nearer elsewhere
      ++grooveCompared;
      const dm::SurfacePatch::Query q = p.creaseQuery(x);
      EXPECT_NEAR(q.distance, grooveDistance(x), 1e-12) << "node " << i;
      EXPECT_NEAR(grooveDistance(x - q.distance * q.normal), 0.0, 1e-12);
    }
  }
  EXPECT_GE(grooves, 2) << "the inner edge is 1 cm long";
  EXPECT_GT(grooveCompared, 20);

  // A thin wall (0.4 mm thick, 4 cm wide): leaves away from its rim hold
  // both sides, whose normals cancel; their crease is the slab between.
  const double t = 0.0002;
  auto plate = dm::buildSphereTreeFitted(dm::makeBox(Vec3(0.02, 0.02, t)), {.levels = 5});
  ASSERT_TRUE(plate.ok()) << plate.error();
  int slabs = 0;
  const auto plateNodes = (*plate)->nodes();
  for (std::size_t i = plateNodes.size() - (*plate)->level(4).size(); i < plateNodes.size(); ++i) {
    const dm::SurfacePatch& p = (*plate)->patches()[i];
    if (p.origin.head<2>().cwiseAbs().maxCoeff() > 0.015) continue;  // the rim
    ++slabs;
    ASSERT_EQ(p.crease.planes, 2) << "node " << i;
    EXPECT_TRUE(p.crease.convex);
    EXPECT_NEAR(std::abs(p.crease.normal[0].z()), 1.0, 1e-12);
    EXPECT_NEAR(p.crease.normal[0].z(), -p.crease.normal[1].z(), 1e-12);
    for (const double z : {0.001, t, 0.5 * t, -0.7 * t, -0.003}) {
      const Vec3 x(p.origin.x(), p.origin.y(), z);
      EXPECT_NEAR(p.creaseQuery(x).distance, std::abs(z) - t, 1e-12) << z;
      EXPECT_NEAR(p.creaseQuery(x).normal.z(), z >= 0 ? 1.0 : -1.0, 1e-12) << z;
    }
  }
  EXPECT_GT(slabs, 20);
}

TEST(SphereTree, FromNodesChecksThePatches) {
  std::vector<dm::SphereTreeNode> nodes(1);
  nodes[0].radius = 1.0;
  dm::SurfacePatch p;
  p.normal = Vec3::UnitZ();
  p.tangentU = Vec3::UnitX();
  p.tangentV = Vec3::UnitY();
  p.coherence = 1.0;
  EXPECT_TRUE(dm::SphereTree::fromNodes(nodes, {p}, 1.0).ok());
  EXPECT_TRUE(dm::SphereTree::fromNodes(nodes, {dm::SurfacePatch{}}, 1.0).ok()) << "no surface";
  auto r = dm::SphereTree::fromNodes(nodes, {p, p}, 1.0);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().what.find("2 patches for 1 nodes"), std::string::npos) << r.error().what;
  dm::SurfacePatch bad = p;
  bad.tangentV = -bad.tangentV;
  r = dm::SphereTree::fromNodes(nodes, {bad}, 1.0);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().what.find("patch 0"), std::string::npos) << r.error().what;
  bad = p;
  bad.coeff[3] = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(dm::SphereTree::fromNodes(nodes, {bad}, 1.0).ok());
  bad = p;
  bad.coherence = 1.5;
  EXPECT_FALSE(dm::SphereTree::fromNodes(nodes, {bad}, 1.0).ok());
  dm::SurfacePatch edge = p;  // a crease of two planes
  edge.crease.planes = 2;
  edge.crease.convex = true;
  edge.crease.normal = {Vec3::UnitZ(), Vec3::UnitY(), Vec3::Zero()};
  EXPECT_TRUE(dm::SphereTree::fromNodes(nodes, {edge}, 1.0).ok());
  bad = edge;
  bad.crease.planes = 1;
  r = dm::SphereTree::fromNodes(nodes, {bad}, 1.0);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().what.find("crease.planes"), std::string::npos) << r.error().what;
  bad = edge;
  bad.crease.normal[1] = Vec3(0, 2, 0);
  EXPECT_FALSE(dm::SphereTree::fromNodes(nodes, {bad}, 1.0).ok());
  bad = edge;
  bad.crease.reach = -1;
  EXPECT_FALSE(dm::SphereTree::fromNodes(nodes, {bad}, 1.0).ok());
}

// --------------------------------------------------------- voxel models ---

// A ball of voxels in a 19 × 13 × 9 grid with anisotropic, rotated spacing.
dm::Volume ballVolume() {
  dm::Affine3 a = dm::Affine3::Identity();
  a.linear() = Eigen::AngleAxisd(0.4, Vec3(1, 2, 3).normalized()).toRotationMatrix() *
               Vec3(0.5e-3, 1e-3, 1.5e-3).asDiagonal();
  a.translation() = Vec3(0.01, -0.02, 0.03);
  auto v = dm::Volume::create({19, 13, 9}, dm::VoxelType::U8, a);
  EXPECT_TRUE(v.ok());
  for (int k = 0; k < 9; ++k)
    for (int j = 0; j < 13; ++j)
      for (int i = 0; i < 19; ++i) {
        const Vec3 p = a * Vec3(i, j, k) - a * Vec3(9, 6, 4);
        v->setValue(i, j, k, p.norm() < 5.5e-3 ? 200 : 0);
      }
  return std::move(*v);
}

// Voxel cube corners and centres of occupied voxels, world coordinates.
std::vector<Vec3> voxelPoints(const dm::Volume& v) {
  std::vector<Vec3> out;
  const dm::Vec3i d = v.dims();
  for (int k = 0; k < d.z(); ++k)
    for (int j = 0; j < d.y(); ++j)
      for (int i = 0; i < d.x(); ++i) {
        if (v.value(i, j, k) <= 100) continue;
        out.push_back(v.indexToWorld() * Vec3(i, j, k));
        for (int q = 0; q < 8; ++q)
          out.push_back(v.indexToWorld() *
                        Vec3(i + (q & 1 ? 0.5 : -0.5), j + (q & 2 ? 0.5 : -0.5), k + (q & 4 ? 0.5 : -0.5)));
      }
  return out;
}

TEST(SphereTree, VoxelTreesCoverOccupiedVoxels) {
  const dm::Volume v = ballVolume();
  const std::vector<Vec3> pts = voxelPoints(v);
  ASSERT_GT(pts.size(), 100u);
  dm::SphereTreeOptions o;
  o.levels = 4;
  o.solid = true;
  o.threshold = 100;
  auto oct = dm::buildSphereTreeOctree(v, o);
  auto fit = dm::buildSphereTreeFitted(v, o);
  ASSERT_TRUE(oct.ok() && fit.ok());
  EXPECT_EQ(uncovered(**oct, pts, 1e-15), 0u);
  EXPECT_EQ(uncovered(**fit, pts, 1e-15), 0u);
  const double voxel = std::abs(v.indexToWorld().linear().determinant());
  EXPECT_NEAR((*oct)->referenceVolume(), static_cast<double>(pts.size() / 9) * voxel, 1e-12);
  o.threshold = 255;
  EXPECT_FALSE(dm::buildSphereTreeOctree(v, o).ok());
}

TEST(SphereTree, ImplicitTreeSpheresAndOccupancy) {
  const dm::Volume v = ballVolume();
  auto t = dm::ImplicitSphereTree::create(v, 100);
  ASSERT_TRUE(t.ok()) << t.error().what;
  const dm::ImplicitSphereTree& tree = **t;
  EXPECT_EQ(tree.depth(), 5);  // 19 → 32
  EXPECT_EQ(tree.levelCount(), 6);
  const dm::Affine3& a = v.indexToWorld();
  std::size_t occupiedVoxels = 0;
  for (int l = 0; l <= tree.depth(); ++l) {
    const int n = 1 << l, s = 1 << (tree.depth() - l);
    std::size_t count = 0;
    for (int k = 0; k < n; ++k)
      for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) {
          // Brute force: any occupied voxel in the cell.
          bool any = false;
          for (int z = k * s; z < (k + 1) * s && !any; ++z)
            for (int y = j * s; y < (j + 1) * s && !any; ++y)
              for (int x = i * s; x < (i + 1) * s && !any; ++x)
                any = v.contains(x, y, z) && v.value(x, y, z) > 100;
          ASSERT_EQ(tree.occupied(l, i, j, k), any) << l << " " << i << " " << j << " " << k;
          count += any;
          // The sphere is centred in the cell and passes through its farthest
          // corner: the smallest sphere about the centre holding the cell.
          const BoundingSphere bs = tree.cellSphere(l, i, j, k);
          double far = 0.0;
          Vec3 mean = Vec3::Zero();
          for (int q = 0; q < 8; ++q) {
            const Vec3 c = a * Vec3(i * s - 0.5 + (q & 1 ? s : 0), j * s - 0.5 + (q & 2 ? s : 0),
                                    k * s - 0.5 + (q & 4 ? s : 0));
            mean += c / 8;
            far = std::max(far, (c - bs.center).norm());
          }
          EXPECT_LT((mean - bs.center).norm(), 1e-15);
          EXPECT_NEAR(bs.radius, far, 1e-15);
        }
    EXPECT_EQ(tree.levelStats()[static_cast<std::size_t>(l)].count, count);
    if (l == tree.depth()) occupiedVoxels = count;
  }
  EXPECT_EQ(tree.levelStats()[0].count, 1u);
  EXPECT_EQ(leavesOf(tree).size(), occupiedVoxels);
  EXPECT_EQ(uncovered(tree, voxelPoints(v), 1e-15), 0u);
  EXPECT_FALSE(dm::ImplicitSphereTree::create(v, 255).ok());
}

// ------------------------------------------------------------ colliders ---

TEST(SphereTreeCollide, SphereQueriesAreConservativeAgainstTheMesh) {
  auto tree = build(torus(), true, 4);
  ASSERT_TRUE(tree);
  auto mesh = dm::TriangleMesh::create(std::make_shared<const dm::Mesh>(torus()));
  ASSERT_TRUE(mesh.ok());
  const auto leafSpheres = leavesOf(*tree);
  double maxLeaf = 0.0;
  for (const auto& s : leafSpheres) maxLeaf = std::max(maxLeaf, s.radius);
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-1, 1);
  int hits = 0, misses = 0, enclosed = 0;
  for (int it = 0; it < 400; ++it) {
    const Isometry3 pt = randomTreePose(rng, 0.05);
    const double r = 0.005 + 0.02 * (u(rng) + 1);
    const Vec3 c = pt * (0.18 * Vec3(u(rng), u(rng), 0.4 * u(rng)));
    const dm::Sphere ball(r);
    const bool meshHit = dm::intersect(**mesh, pt, ball, at(c));
    const bool treeHit = dm::intersect(*tree, pt, ball, at(c));
    // Brute force over leaf spheres.
    double brute = kInf;
    const Vec3 local = pt.inverse() * c;
    for (const auto& s : leafSpheres) brute = std::min(brute, (local - s.center).norm() - s.radius - r);
    EXPECT_EQ(treeHit, brute <= 0) << it;
    // The tree covers the surface: a ball that reaches a triangle hits it.
    // A closed TriangleMesh is solid, so a ball wholly inside the tube hits
    // the mesh and not this surface tree (solid = false).
    double surface = kInf;
    for (const auto& t : torus().triangles)
      surface = std::min(surface, dm::closestPointOnTriangle(local, torus().positions[t[0]],
                                                             torus().positions[t[1]], torus().positions[t[2]])
                                      .distanceSq);
    if (std::sqrt(surface) <= r) {
      EXPECT_TRUE(meshHit) << it;
      EXPECT_TRUE(treeHit) << it;  // conservative
    } else if (meshHit) {
      ++enclosed;
      EXPECT_LT(std::hypot(std::hypot(local.x(), local.y()) - 0.1, local.z()), 0.03) << it;  // in the tube
    }
    const dm::DistanceResult md = dm::distance(**mesh, pt, ball, at(c));
    if (md.distance > 2 * maxLeaf) {
      EXPECT_FALSE(treeHit) << it;  // far: no hit
    }
    hits += treeHit, misses += !treeHit;
    const dm::DistanceResult td = dm::distance(*tree, pt, ball, at(c));
    ASSERT_TRUE(td.supported);
    EXPECT_NEAR(td.distance, brute, 1e-12);
    if (md.distance > 0) {
      EXPECT_LE(td.distance, md.distance + 1e-12);  // a lower bound
      EXPECT_GE(td.distance, md.distance - 2 * maxLeaf - 1e-12);
    }
    // Swapped order and contacts.
    EXPECT_EQ(dm::intersect(ball, at(c), *tree, pt), treeHit);
    const dm::CollisionResult cr = dm::collide(*tree, pt, ball, at(c));
    EXPECT_EQ(cr.colliding, treeHit);
    if (treeHit) {
      ASSERT_FALSE(cr.contacts.empty());
      EXPECT_LE(cr.contacts.size(), 4u);
      double deepest = 0.0;
      for (const dm::ContactPoint& k : cr.contacts) deepest = std::max(deepest, k.depth);
      EXPECT_NEAR(deepest, -brute, 1e-9);  // the deepest is kept
      EXPECT_NEAR(cr.contacts[0].normal.norm(), 1.0, 1e-12);
    }
  }
  EXPECT_GT(hits, 40);
  EXPECT_GT(misses, 40);
  // GCC and clang evaluate the u(rng) arguments in opposite orders, so each
  // draws its own balls; clang's include one inside the tube.
  RecordProperty("enclosed", enclosed);
}

TEST(SphereTreeCollide, TreeTreeAgreesWithLeafPairs) {
  auto a = build(torus(), false, 3);
  auto b = build(dm::makeIcosphere(0.04, 2), true, 3);
  ASSERT_TRUE(a && b);
  const auto la = leavesOf(*a), lb = leavesOf(*b);
  std::mt19937_64 rng(9);
  int hits = 0;
  for (int it = 0; it < 200; ++it) {
    const Isometry3 pa = randomTreePose(rng, 0.05), pb = randomTreePose(rng, 0.15);
    double brute = kInf;
    for (const auto& x : la)
      for (const auto& y : lb)
        brute = std::min(brute, (pa * x.center - pb * y.center).norm() - x.radius - y.radius);
    const bool hit = dm::intersect(*a, pa, *b, pb);
    EXPECT_EQ(hit, brute <= 0) << it;
    hits += hit;
    EXPECT_NEAR(dm::distance(*a, pa, *b, pb).distance, brute, 1e-12) << it;
    const dm::CollisionResult cr = dm::collide(*a, pa, *b, pb);
    EXPECT_EQ(cr.colliding, hit);
    double deepest = -kInf;
    for (const dm::ContactPoint& k : cr.contacts) deepest = std::max(deepest, k.depth);
    if (hit) {
      EXPECT_NEAR(deepest, -brute, 1e-12);
    }
  }
  EXPECT_GT(hits, 20);
  EXPECT_LT(hits, 180);
}

TEST(SphereTreeCollide, PlaneBoxAndRaycastAgreeWithLeafSpheres) {
  auto tree = build(dm::makeIcosphere(0.05, 2), false, 4);
  ASSERT_TRUE(tree);
  const auto ls = leavesOf(*tree);
  std::mt19937_64 rng(21);
  std::uniform_real_distribution<double> u(-1, 1);
  const dm::Box box(Vec3(0.02, 0.03, 0.01));
  for (int it = 0; it < 200; ++it) {
    const Isometry3 pt = randomTreePose(rng, 0.02);
    // Plane z ≤ h: the deepest leaf is the lowest sphere bottom.
    const double h = 0.06 * u(rng);
    const dm::Plane plane(Vec3::UnitZ(), h);
    double lowest = kInf;
    for (const auto& s : ls) lowest = std::min(lowest, (pt * s.center).z() - s.radius - h);
    EXPECT_NEAR(dm::distance(*tree, pt, plane, Isometry3::Identity()).distance, lowest, 1e-12);
    EXPECT_EQ(dm::intersect(plane, Isometry3::Identity(), *tree, pt), lowest <= 0);
    // Box through the sphere–box collider.
    const Isometry3 pb = randomTreePose(rng, 0.08);
    bool any = false;
    for (const auto& s : ls) any = any || dm::intersect(dm::Sphere(s.radius), at(pt * s.center), box, pb);
    EXPECT_EQ(dm::intersect(*tree, pt, box, pb), any) << it;
    // Ray from outside towards the tree.
    dm::Ray ray;
    ray.origin = Vec3(0.3 * u(rng), 0.3 * u(rng), 0.2);
    ray.direction = (0.03 * Vec3(u(rng), u(rng), u(rng)) - ray.origin).normalized();
    double tBest = kInf;
    for (const auto& s : ls) {
      const Vec3 m = ray.origin - pt * s.center;
      const double bq = m.dot(ray.direction), cq = m.squaredNorm() - s.radius * s.radius, disc = bq * bq - cq;
      if (disc >= 0 && bq < 0) tBest = std::min(tBest, -bq - std::sqrt(disc));
    }
    const auto hit = dm::raycast(*tree, pt, ray);
    ASSERT_EQ(hit.has_value(), std::isfinite(tBest)) << it;
    if (hit) {
      EXPECT_NEAR(hit->t, tBest, 1e-9);
    }
  }
}

TEST(SphereTreeCollide, ImplicitTreeAgainstSphere) {
  const dm::Volume v = ballVolume();
  auto t = dm::ImplicitSphereTree::create(v, 100);
  ASSERT_TRUE(t.ok());
  const auto ls = leavesOf(**t);
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(-1, 1);
  const Vec3 centre = v.indexToWorld() * Vec3(9, 6, 4);
  int hits = 0;
  for (int it = 0; it < 300; ++it) {
    const Vec3 c = centre + 0.012 * Vec3(u(rng), u(rng), u(rng));
    const dm::Sphere ball(0.001);
    double brute = kInf;
    for (const auto& s : ls) brute = std::min(brute, (c - s.center).norm() - s.radius - 0.001);
    const bool hit = dm::intersect(**t, Isometry3::Identity(), ball, at(c));
    EXPECT_EQ(hit, brute <= 0);
    hits += hit;
    EXPECT_NEAR(dm::distance(**t, Isometry3::Identity(), ball, at(c)).distance, brute, 1e-12);
  }
  EXPECT_GT(hits, 10);
}

}  // namespace
