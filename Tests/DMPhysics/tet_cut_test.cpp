// TetCutter: cutting tetrahedral meshes by swept blade surfaces (the
// virtual node algorithm) — pieces, their volumes against the geometry of
// the cut, the closed cut surface, continuity and determinism.
#include <dm/physics/tet_cut.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <numbers>
#include <set>
#include <utility>
#include <vector>

namespace dm {
namespace {

// Every directed edge of the surface is used once and its reverse once: the
// surface is closed and consistently oriented.
::testing::AssertionResult isClosed(const CutSurface& s) {
  std::map<std::pair<std::uint32_t, std::uint32_t>, int> use;
  for (const Triangle& t : s.triangles)
    for (int i = 0; i < 3; ++i) ++use[{t[i], t[(i + 1) % 3]}];
  for (const auto& [e, n] : use) {
    if (n != 1)
      return ::testing::AssertionFailure()
             << "edge " << e.first << "→" << e.second << " used " << n << " times";
    const auto back = use.find({e.second, e.first});
    if (back == use.end() || back->second != 1)
      return ::testing::AssertionFailure() << "edge " << e.first << "→" << e.second << " has no twin";
  }
  return ::testing::AssertionSuccess();
}

// The node → piece map from the elements' pieces.
std::vector<std::uint32_t> pieceOfNodes(const TetCutter& c, std::size_t& pieces) {
  std::vector<std::uint32_t> pieceOf;
  pieces = c.pieces(pieceOf);
  std::vector<std::uint32_t> node(c.nodeCount(), ~0u);
  for (std::size_t e = 0; e < c.elements().size(); ++e)
    for (const std::uint32_t n : c.elements()[e].nodes) node[n] = pieceOf[e];
  return node;
}

// Per piece: the material volume of its elements and the volume its
// surface encloses at positions x (divergence theorem).
struct PieceVolumes {
  std::vector<double> material, enclosed;
};
PieceVolumes pieceVolumes(const TetCutter& c, const CutSurface& s, const std::vector<Vec3>& x) {
  std::vector<std::uint32_t> pieceOf;
  const std::size_t n = c.pieces(pieceOf);
  PieceVolumes v{std::vector<double>(n, 0.0), std::vector<double>(n, 0.0)};
  for (std::size_t e = 0; e < c.elements().size(); ++e) v.material[pieceOf[e]] += c.elementVolume(e);
  std::size_t pieces = 0;
  const std::vector<std::uint32_t> nodePiece = pieceOfNodes(c, pieces);
  std::vector<Vec3> p;
  s.evaluate(x, p);
  for (const Triangle& t : s.triangles)
    v.enclosed[nodePiece[s.vertices[t[0]].nodes[0]]] += p[t[0]].dot(p[t[1]].cross(p[t[2]])) / 6.0;
  return v;
}

// Every node is a corner of some element, and each element's fractions
// (over the copies of one original) add up to one.
void expectConsistent(const TetCutter& c) {
  std::vector<int> used(c.nodeCount(), 0);
  std::vector<double> sum(c.originalTetCount(), 0.0);
  for (const CutElement& e : c.elements()) {
    for (const std::uint32_t n : e.nodes) used[n] = 1;
    EXPECT_GT(e.fraction, 0.0);
    sum[e.source] += e.fraction;
  }
  for (std::size_t n = 0; n < used.size(); ++n) EXPECT_TRUE(used[n]) << "node " << n << " is in no element";
  for (std::size_t t = 0; t < sum.size(); ++t) EXPECT_NEAR(sum[t], 1.0, 1e-12) << "tetrahedron " << t;
}

// After a cut into two pieces, at rest: the elements consistent, the
// surface closed, each piece's surface enclosing its material (to 1e-12 of
// `volume`). The pieces' material volumes, element 0's piece first.
std::pair<double, double> twoClosedPieces(const TetCutter& c, double volume) {
  expectConsistent(c);
  const CutSurface s = c.surface();
  EXPECT_TRUE(isClosed(s));
  const PieceVolumes v = pieceVolumes(c, s, c.restPositions());
  EXPECT_EQ(v.material.size(), 2u);
  if (v.material.size() != 2) return {0.0, 0.0};
  for (int p = 0; p < 2; ++p) EXPECT_NEAR(v.enclosed[p], v.material[p], 1e-12 * volume) << "piece " << p;
  std::vector<std::uint32_t> pieceOf;
  c.pieces(pieceOf);
  return {v.material[pieceOf[0]], v.material[1 - pieceOf[0]]};
}

// A blade as long as the block is wide (along y, with margins), moved from
// (x0, z(x0)) to (x1, z(x1)) on the plane z = z0 + slope·x: its swept
// surface is that plane across the block.
std::array<CutTriangle, 2> planeSweep(double x0, double x1, double z0, double slope, double width) {
  const double m = 0.01;
  return bladeSweep(Vec3(x0, -m, z0 + slope * x0), Vec3(x0, width + m, z0 + slope * x0),
                    Vec3(x1, -m, z0 + slope * x1), Vec3(x1, width + m, z0 + slope * x1));
}

TEST(TetCut, StraightCutSeparatesABlockIntoTwoPiecesOfTheirExactVolumes) {
  // 30 × 24 × 18 mm block of 5 × 4 × 3 mm cells; the plane z = 6.1 mm +
  // 0.23 x crosses it obliquely (6.1 to 13.0 mm), away from the nodes.
  const Vec3 size(0.030, 0.024, 0.018);
  auto mesh = tetMeshBox({6, 6, 6}, size);
  ASSERT_TRUE(mesh.ok());
  auto cutter = TetCutter::create(*mesh);
  ASSERT_TRUE(cutter.ok());
  const double z0 = 0.0061, slope = 0.23;
  const std::vector<Vec3> x = cutter->restPositions();
  auto up = cutter->cut(planeSweep(-0.01, size.x() + 0.01, z0, slope, size.y()), x);
  ASSERT_TRUE(up.ok()) << up.error().message();
  EXPECT_GT(up->edgesCrossed, 0u);
  EXPECT_EQ(up->tetsSplit, cutter->splitTetCount());
  expectConsistent(*cutter);

  const CutSurface s = cutter->surface();
  EXPECT_TRUE(isClosed(s));
  const PieceVolumes v = pieceVolumes(*cutter, s, cutter->restPositions());
  ASSERT_EQ(v.material.size(), 2u);
  // The piece under the plane holds node 0 (the origin); its volume is
  // width · ∫ (z0 + slope·x) dx over the length.
  std::vector<std::uint32_t> pieceOf;
  cutter->pieces(pieceOf);
  const std::uint32_t below = pieceOf[0];
  const double total = size.prod();
  const double under = size.y() * size.x() * (z0 + slope * size.x() / 2);
  EXPECT_NEAR(v.material[below], under, 1e-12 * total);
  EXPECT_NEAR(v.material[1 - below], total - under, 1e-12 * total);
  EXPECT_NEAR(v.material[0] + v.material[1], mesh->totalVolume(), 1e-12 * total);
  // Each piece's surface encloses exactly its material.
  for (int p = 0; p < 2; ++p) EXPECT_NEAR(v.enclosed[p], v.material[p], 1e-12 * total) << "piece " << p;
  // Pull the pieces apart: each stays closed, and nothing of one follows the other.
  std::vector<Vec3> moved = cutter->restPositions();
  std::size_t pieces = 0;
  const auto nodePiece = pieceOfNodes(*cutter, pieces);
  for (std::size_t i = 0; i < moved.size(); ++i)
    if (nodePiece[i] != below) moved[i] += Vec3(0.001, -0.002, 0.02);
  const PieceVolumes w = pieceVolumes(*cutter, s, moved);
  for (int p = 0; p < 2; ++p) EXPECT_NEAR(w.enclosed[p], v.material[p], 1e-12 * total) << "piece " << p;
}

TEST(TetCut, PartialCutLeavesOnePieceWithAClosedSurfaceAndOpensOnlyWhereTheBladeWent) {
  // A vertical blade pushed across the whole width but only 10.5 of the
  // 18 mm down: a slit, not a separation.
  const Vec3 size(0.030, 0.024, 0.018);
  auto mesh = tetMeshBox({6, 6, 6}, size);
  ASSERT_TRUE(mesh.ok());
  auto cutter = TetCutter::create(*mesh);
  ASSERT_TRUE(cutter.ok());
  const double cutX = 0.0131, bottom = size.z() - 0.0105;
  const std::vector<Vec3> x = cutter->restPositions();
  auto up = cutter->cut(
      bladeSweep(Vec3(cutX, -0.01, bottom), Vec3(cutX, -0.01, size.z() + 0.01),
                 Vec3(cutX, size.y() + 0.01, bottom), Vec3(cutX, size.y() + 0.01, size.z() + 0.01)),
      x);
  ASSERT_TRUE(up.ok());
  expectConsistent(*cutter);
  std::vector<std::uint32_t> pieceOf;
  EXPECT_EQ(cutter->pieces(pieceOf), 1u);
  const CutSurface s = cutter->surface();
  EXPECT_TRUE(isClosed(s));
  const PieceVolumes v = pieceVolumes(*cutter, s, cutter->restPositions());
  EXPECT_NEAR(v.enclosed[0], size.prod(), 1e-12 * size.prod());
  // The slit opened: virtual nodes, each a copy of a node on the slit's
  // plane's cells (within a cell of x = cutX) above the crack front.
  ASSERT_GT(cutter->nodeCount(), cutter->originalNodeCount());
  const std::vector<Vec3> rest = cutter->restPositions();
  for (std::size_t i = cutter->originalNodeCount(); i < cutter->nodeCount(); ++i) {
    EXPECT_LT(std::abs(rest[i].x() - cutX), 0.005 + 1e-12) << "node " << i;
    EXPECT_GT(rest[i].z(), bottom - 0.003 - 1e-12) << "node " << i;
  }
  // Each new node starts from a node of the same original.
  for (const auto& up2 : up->newNodes)
    EXPECT_EQ(cutter->nodeOrigin()[up2.node], cutter->nodeOrigin()[up2.source]);
}

TEST(TetCut, ABladeMovedInSmallStepsCutsLikeOneSweepAndTheCrackFollowsIt) {
  const Vec3 size(0.030, 0.024, 0.018);
  auto mesh = tetMeshBox({6, 6, 6}, size);
  ASSERT_TRUE(mesh.ok());
  auto once = TetCutter::create(*mesh);
  auto steps = TetCutter::create(*mesh);
  ASSERT_TRUE(once.ok() && steps.ok());
  const double z0 = 0.0061, slope = 0.23, from = -0.01, to = size.x() + 0.01;
  ASSERT_TRUE(once->cut(planeSweep(from, to, z0, slope, size.y()), once->restPositions()).ok());
  const int n = 40;
  std::size_t lastSplit = 0;
  std::vector<std::uint32_t> pieceOf;
  for (int i = 0; i < n; ++i) {
    const double a = from + (to - from) * i / n, b = from + (to - from) * (i + 1) / n;
    auto up = steps->cut(planeSweep(a, b, z0, slope, size.y()), steps->restPositions());
    ASSERT_TRUE(up.ok());
    EXPECT_GE(steps->splitTetCount(), lastSplit);
    lastSplit = steps->splitTetCount();
    // One piece until the blade has left the block.
    if (b < size.x() - 0.005) {
      EXPECT_EQ(steps->pieces(pieceOf), 1u) << "step " << i;
    }
    for (const std::uint32_t e : up->changedElements) EXPECT_LT(e, steps->elements().size());
    expectConsistent(*steps);
    EXPECT_TRUE(isClosed(steps->surface())) << "step " << i;
  }
  EXPECT_EQ(steps->pieces(pieceOf), 2u);
  EXPECT_EQ(steps->splitTetCount(), once->splitTetCount());
  EXPECT_EQ(steps->nodeCount(), once->nodeCount());
  EXPECT_EQ(steps->crossedEdgeCount(), once->crossedEdgeCount());
  ASSERT_EQ(steps->elements().size(), once->elements().size());
  // Element indices differ with the order the tetrahedra split in; the
  // material per original tetrahedron agrees.
  std::vector<double> a(mesh->tetCount(), 0.0), b(mesh->tetCount(), 0.0);
  std::vector<int> ca(mesh->tetCount(), 0), cb(mesh->tetCount(), 0);
  for (std::size_t e = 0; e < once->elements().size(); ++e) {
    a[once->elements()[e].source] += once->elementVolume(e) * once->elementVolume(e);
    ++ca[once->elements()[e].source];
    b[steps->elements()[e].source] += steps->elementVolume(e) * steps->elementVolume(e);
    ++cb[steps->elements()[e].source];
  }
  for (std::size_t t = 0; t < a.size(); ++t) {
    EXPECT_EQ(ca[t], cb[t]) << "tetrahedron " << t;
    EXPECT_NEAR(a[t], b[t], 1e-12 * std::pow(size.prod() / mesh->tetCount(), 2)) << "tetrahedron " << t;
  }
}

TEST(TetCut, CurvedCutTakesOutACylinderSectionWithinTheInterpolationBound) {
  // A vertical blade (the block's full height) swept round a quarter circle
  // of radius R about the block's corner edge, in 64 steps: it cuts out a
  // quarter cylinder of volume π R² H / 4. Within each element the cut is
  // planar through the crossings, which lie on the cylinder: chords of
  // length ≤ h across arcs of radius R, so the piece's volume is within
  // (arc length)·H·h²/(8R) of the cylinder's, a relative h²/(4R²).
  const Vec3 size(0.032, 0.032, 0.012);
  auto mesh = tetMeshBox({8, 8, 3}, size);
  ASSERT_TRUE(mesh.ok());
  auto cutter = TetCutter::create(*mesh);
  ASSERT_TRUE(cutter.ok());
  const double R = 0.0191, H = size.z(), m = 0.002;
  const int n = 64;
  const double half = std::numbers::pi / 2;
  for (int i = 0; i < n; ++i) {
    // From outside the block (−y) to outside (−x), past the quarter.
    const double a0 = -0.1 + (half + 0.2) * i / n, a1 = -0.1 + (half + 0.2) * (i + 1) / n;
    const Vec3 p0(R * std::cos(a0), R * std::sin(a0), 0), p1(R * std::cos(a1), R * std::sin(a1), 0);
    auto up = cutter->cut(
        bladeSweep(p0 - Vec3(0, 0, m), p0 + Vec3(0, 0, H + m), p1 - Vec3(0, 0, m), p1 + Vec3(0, 0, H + m)),
        cutter->restPositions());
    ASSERT_TRUE(up.ok());
  }
  const auto [inner, outer] = twoClosedPieces(*cutter, size.prod());  // element 0 holds the corner (0, 0, 0)
  const double exact = std::numbers::pi * R * R * H / 4;
  const double h = size.x() / 8;
  EXPECT_NEAR(inner, exact, exact * h * h / (4 * R * R)) << "relative error " << (inner - exact) / exact;
  EXPECT_NEAR(inner + outer, size.prod(), 1e-12 * size.prod());
}

TEST(TetCut, AThinSheetOneElementThickIsCutThrough) {
  // 40 × 40 × 1 mm: one layer of cells; a blade drawn diagonally across it.
  const Vec3 size(0.040, 0.040, 0.001);
  auto mesh = tetMeshBox({10, 10, 1}, size);
  ASSERT_TRUE(mesh.ok());
  auto cutter = TetCutter::create(*mesh);
  ASSERT_TRUE(cutter.ok());
  // The line y = 0.0013 + 0.9 x, blade vertical through the sheet.
  auto at = [](double x) { return Vec3(x, 0.0013 + 0.9 * x, 0); };
  const Vec3 up(0, 0, 0.003), down(0, 0, -0.002);
  ASSERT_TRUE(cutter
                  ->cut(bladeSweep(at(-0.005) + down, at(-0.005) + up, at(0.05) + down, at(0.05) + up),
                        cutter->restPositions())
                  .ok());
  const auto [under, over] = twoClosedPieces(*cutter, size.prod());
  // The part above the line: the triangle cut off the square's corner
  // (0, 0.0013) … (0.04, 0.0373) … (0, 0.04) plus the strip over y = 0.0373.
  const double L = size.x(), y0 = 0.0013, y1 = 0.0013 + 0.9 * L;
  const double above = (L * (L - y1) + L * (y1 - y0) / 2) * size.z();
  EXPECT_NEAR(under, size.prod() - above, 1e-12 * size.prod());
  EXPECT_NEAR(over, above, 1e-12 * size.prod());
}

TEST(TetCut, CutsFollowTheDeformedBody) {
  // The block stretched to twice its length along x: a plane at x' = 0.03
  // in the deformed body is x = 0.015 in the material.
  const Vec3 size(0.030, 0.012, 0.012);
  auto mesh = tetMeshBox({6, 3, 3}, size);
  ASSERT_TRUE(mesh.ok());
  auto cutter = TetCutter::create(*mesh);
  ASSERT_TRUE(cutter.ok());
  std::vector<Vec3> x = cutter->restPositions();
  for (Vec3& p : x) p.x() *= 2.0;
  const double cx = 0.0311;  // deformed; x = 0.01555 in the material
  const double m = 0.01;
  ASSERT_TRUE(cutter
                  ->cut(bladeSweep(Vec3(cx, -m, -m), Vec3(cx, -m, size.z() + m), Vec3(cx, size.y() + m, -m),
                                   Vec3(cx, size.y() + m, size.z() + m)),
                        x)
                  .ok());
  std::vector<std::uint32_t> pieceOf;
  ASSERT_EQ(cutter->pieces(pieceOf), 2u);
  double left = 0.0;
  for (std::size_t e = 0; e < cutter->elements().size(); ++e)
    if (pieceOf[e] == pieceOf[0]) left += cutter->elementVolume(e);
  EXPECT_NEAR(left, (cx / 2) * size.y() * size.z(), 1e-12 * size.prod());
}

TEST(TetCut, SameCutsGiveBitwiseTheSameMeshAndSurface) {
  auto mesh = tetMeshBox({5, 5, 5}, Vec3(0.02, 0.02, 0.02));
  ASSERT_TRUE(mesh.ok());
  auto a = TetCutter::create(*mesh), b = TetCutter::create(*mesh);
  ASSERT_TRUE(a.ok() && b.ok());
  for (TetCutter* c : {&*a, &*b})
    for (int i = 0; i < 12; ++i) {
      const double t0 = i / 12.0, t1 = (i + 1) / 12.0;
      auto p = [](double t) { return Vec3(-0.002 + 0.024 * t, 0.0071 + 0.004 * std::sin(5 * t), 0.0); };
      ASSERT_TRUE(c->cut(bladeSweep(p(t0) - Vec3(0, 0, 0.001), p(t0) + Vec3(0, 0, 0.013),
                                    p(t1) - Vec3(0, 0, 0.001), p(t1) + Vec3(0, 0, 0.013)),
                         c->restPositions())
                      .ok());
    }
  ASSERT_EQ(a->elements().size(), b->elements().size());
  for (std::size_t e = 0; e < a->elements().size(); ++e) {
    EXPECT_EQ(a->elements()[e].nodes, b->elements()[e].nodes);
    EXPECT_EQ(a->elements()[e].fraction, b->elements()[e].fraction);
  }
  const CutSurface sa = a->surface(), sb = b->surface();
  ASSERT_EQ(sa.triangles, sb.triangles);
  ASSERT_EQ(sa.vertices.size(), sb.vertices.size());
  for (std::size_t i = 0; i < sa.vertices.size(); ++i) {
    EXPECT_EQ(sa.vertices[i].nodes, sb.vertices[i].nodes);
    EXPECT_EQ(sa.vertices[i].weights, sb.vertices[i].weights);
  }
  EXPECT_TRUE(isClosed(sa));
}

TEST(TetCut, BadInputIsRefusedByName) {
  auto mesh = tetMeshBox({2, 2, 2}, Vec3(0.01, 0.01, 0.01));
  ASSERT_TRUE(mesh.ok());
  auto bad = TetCutter::create(*mesh, {.snap = 0.3});
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().message().find("snap"), std::string::npos);
  TetMesh hanging = *mesh;
  hanging.hanging.push_back({0, {1, 2}});
  auto h = TetCutter::create(hanging);
  ASSERT_FALSE(h.ok());
  EXPECT_NE(h.error().message().find("hanging"), std::string::npos);
  auto c = TetCutter::create(*mesh);
  ASSERT_TRUE(c.ok());
  std::vector<Vec3> x = c->restPositions();
  const auto sweep =
      bladeSweep(Vec3(0.005, -1, -1), Vec3(0.005, -1, 1), Vec3(0.005, 1, -1), Vec3(0.005, 1, 1));
  auto r = c->cut(sweep, std::span<const Vec3>(x).first(3));
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message().find("positions"), std::string::npos);
  x[4].y() = std::nan("");
  r = c->cut(sweep, x);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message().find("position 4"), std::string::npos);
  x = c->restPositions();
  auto nanSweep = sweep;
  nanSweep[1][2].z() = INFINITY;
  r = c->cut(nanSweep, x);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message().find("triangle 1"), std::string::npos);
  EXPECT_EQ(c->crossedEdgeCount(), 0u);  // nothing changed
  const TearSplit outside{.element = 9999, .normal = Vec3::UnitX()};
  r = c->tear({&outside, 1}, x);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message().find("element 9999"), std::string::npos);
  const TearSplit flat{.element = 0, .normal = Vec3::Zero()};
  r = c->tear({&flat, 1}, x);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message().find("normal"), std::string::npos);
  EXPECT_EQ(c->crossedEdgeCount(), 0u);
}

}  // namespace
}  // namespace dm
