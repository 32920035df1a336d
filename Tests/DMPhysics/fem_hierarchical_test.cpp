// Tests of hierarchical (octree) tetrahedral meshes and of FemBody's hanging
// nodes: the cells cover exactly the occupied voxels and their boundary is
// the voxel boundary (area, enclosed volume); the constrained mesh passes the
// patch test (a uniform strain is reproduced exactly, reactions equal
// E·A·ε); a free body falls rigidly; the indentation stiffness and the sag
// under gravity of a graded block match the uniform voxel mesh it coarsens;
// bad hanging entries and options are refused with the entry named.
#include <dm/physics/fem.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include "physics_test_support.hpp"

namespace dm {
namespace {

using dm::test::kG;

double triangleArea(const TetMesh& m, const Triangle& t) {
  return 0.5 * (m.nodes[t[1]] - m.nodes[t[0]]).cross(m.nodes[t[2]] - m.nodes[t[0]]).norm();
}

// Σ area and the volume the surface encloses (divergence theorem), which is
// the solid's volume only if the faces are outward and leave no gap.
void surfaceMeasures(const TetMesh& m, double& area, double& enclosed) {
  area = enclosed = 0;
  for (const Triangle& t : tetMeshSurface(m)) {
    area += triangleArea(m, t);
    enclosed += m.nodes[t[0]].dot(m.nodes[t[1]].cross(m.nodes[t[2]])) / 6.0;
  }
}

std::vector<std::uint8_t> ballOccupancy(int n, double radius, int& count) {
  std::vector<std::uint8_t> occ(std::size_t(n * n * n), 0);
  count = 0;
  const double c = 0.5 * n;
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        const double dx = i + 0.5 - c, dy = j + 0.5 - c, dz = k + 0.5 - c;
        if (dx * dx + dy * dy + dz * dz <= radius * radius) occ[std::size_t(i + n * (j + n * k))] = 1, ++count;
      }
  return occ;
}

int exposedFaces(const std::vector<std::uint8_t>& occ, int n) {
  auto at = [&](int i, int j, int k) {
    if (i < 0 || j < 0 || k < 0 || i >= n || j >= n || k >= n) return 0;
    return int(occ[std::size_t(i + n * (j + n * k))]);
  };
  int faces = 0;
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i)
        if (at(i, j, k))
          faces += 6 - at(i - 1, j, k) - at(i + 1, j, k) - at(i, j - 1, k) - at(i, j + 1, k) - at(i, j, k - 1) -
                   at(i, j, k + 1);
  return faces;
}

TEST(FemHierarchicalMesh, BallCellsCoverTheVoxelsAndTheBoundaryIsTheVoxelBoundary) {
  int count = 0;
  const int n = 24;
  const auto occ = ballOccupancy(n, 10.5, count);
  const double h = 0.002;
  const Vec3 origin(0.01, -0.02, 0.03);
  auto fine = tetMeshFromOccupancy(occ, {n, n, n}, Vec3::Constant(h), origin);
  auto mesh = tetMeshHierarchical(occ, {n, n, n}, Vec3::Constant(h), origin, {.levels = 3});
  ASSERT_TRUE(fine && mesh) << (mesh ? "" : mesh.error().message());
  ASSERT_TRUE(mesh->validate()) << mesh->validate().error().message();
  EXPECT_FALSE(mesh->hanging.empty());
  EXPECT_LT(mesh->tetCount() * 2, fine->tetCount()) << "coarse interior cells should halve the mesh at least";
  const double voxel = h * h * h;
  EXPECT_NEAR(mesh->totalVolume(), count * voxel, 1e-9 * count * voxel);
  double area = 0, enclosed = 0;
  surfaceMeasures(*mesh, area, enclosed);
  EXPECT_NEAR(area, exposedFaces(occ, n) * h * h, 1e-9 * area) << "interface faces left in, or holes";
  EXPECT_NEAR(enclosed, count * voxel, 1e-9 * count * voxel);
  // Cells of 4 voxels fill the core (8-voxel cells would need 2:1 balanced
  // neighbours all round, which the voxel boundary 2–3 cells away forbids).
  double largest = 0;
  for (std::size_t t = 0; t < mesh->tetCount(); ++t) largest = std::max(largest, mesh->tetVolume(t));
  EXPECT_NEAR(largest, 64 * voxel / 6, 1e-9 * voxel);
}

TEST(FemHierarchicalMesh, FineRegionKeepsVoxelsAndCellsGrowTwoToOne) {
  const int n = 32;
  std::vector<std::uint8_t> occ(std::size_t(n * n * n), 1);
  const double h = 0.001;
  // Fine region: a 4 mm cube at the middle of the top face (the tool's spot).
  const Aabb region(Vec3(0.014, 0.014, 0.028), Vec3(0.018, 0.018, 0.032));
  auto mesh = tetMeshHierarchical(occ, {n, n, n}, Vec3::Constant(h), Vec3::Zero(),
                                  {.levels = 3, .fineRegion = region, .grading = 1.0});
  ASSERT_TRUE(mesh) << mesh.error().message();
  ASSERT_TRUE(mesh->validate());
  const double voxelTet = h * h * h / 6;
  std::size_t inRegion = 0;
  for (std::size_t t = 0; t < mesh->tetCount(); ++t) {
    Vec3 c = Vec3::Zero();
    for (auto i : mesh->tets[t]) c += 0.25 * mesh->nodes[i];
    if (region.contains(c)) {
      ++inRegion;
      EXPECT_NEAR(mesh->tetVolume(t), voxelTet, 1e-12 * voxelTet) << "tetrahedron " << t << " in the fine region";
    }
  }
  EXPECT_EQ(inRegion, std::size_t(4 * 4 * 4 * 6));
  // 2:1 balance: every hanging node's masters are two fine cells apart (an
  // edge of a cell one level coarser than the cells it is a corner of), so
  // across the coarse–fine step a master is at most 2·(cell side) away.
  for (const HangingNode& hn : mesh->hanging) {
    const double span = (mesh->nodes[hn.masters[0]] - mesh->nodes[hn.masters[1]]).norm();
    EXPECT_LE(span, 8 * h * std::sqrt(2.0) + 1e-12);
  }
  double area = 0, enclosed = 0;
  surfaceMeasures(*mesh, area, enclosed);
  EXPECT_NEAR(area, 6 * 0.032 * 0.032, 1e-9);
  EXPECT_NEAR(enclosed, 0.032 * 0.032 * 0.032, 1e-12);
  EXPECT_NEAR(mesh->totalVolume(), 0.032 * 0.032 * 0.032, 1e-12);
  // Far from the region the mesh is coarse: fewer than a quarter of the voxel mesh's tetrahedra.
  EXPECT_LT(mesh->tetCount() * 4, std::size_t(n * n * n * 6));
}

// A ν = 0 column, bottom clamped, top face pushed down by d and held: the
// exact static field is the uniform strain z' = z(1 − d/L), which the
// constrained space contains, so every node (hanging ones too) lands on it
// and the top's reaction is E·A·d/L. An unconstrained T-junction would leave
// an unbalanced force on the fine side and fail both.
TEST(FemHierarchicalBody, PatchTestUniformStrainIsExactAndReactionIsEAEpsilon) {
  const int nx = 8, nz = 16;
  std::vector<std::uint8_t> occ(std::size_t(nx * nx * nz), 1);
  const double h = 0.001, L = nz * h, A = (nx * h) * (nx * h), E = 1e4, d = 1e-5;
  auto mesh = tetMeshHierarchical(occ, {nx, nx, nz}, Vec3::Constant(h), Vec3::Zero(),
                                  {.levels = 2, .fineRegion = Aabb(Vec3(0, 0, 0), Vec3(0.002, 0.002, 0.002))});
  ASSERT_TRUE(mesh) << mesh.error().message();
  ASSERT_FALSE(mesh->hanging.empty());
  auto body = FemBody::create(*mesh, {.youngsModulus = E, .poissonRatio = 0.0, .density = 1.0},
                              {.alpha = 10.0}, {.tolerance = 1e-12, .maxIterations = 5000, .parallel = false});
  ASSERT_TRUE(body) << body.error().message();
  EXPECT_EQ(body->hangingCount(), mesh->hanging.size());
  std::vector<std::size_t> top;
  std::vector<Vec3> x = body->restPositions();
  for (std::size_t i = 0; i < x.size(); ++i) {
    if (body->isHanging(i)) continue;
    if (x[i].z() < 1e-12) body->setFixed(i, true);
    if (x[i].z() > L - 1e-12) body->setFixed(i, true), top.push_back(i), x[i].z() -= d;
  }
  body->setPositions(x);
  for (int s = 0; s < 20; ++s) ASSERT_TRUE(body->step(1.0));
  double worst = 0;
  for (std::size_t i = 0; i < x.size(); ++i) {
    const Vec3& p0 = body->restPositions()[i];
    const Vec3 exact(p0.x(), p0.y(), p0.z() * (1 - d / L));
    worst = std::max(worst, (body->positions()[i] - exact).norm());
  }
  EXPECT_LT(worst, 1e-6 * d) << "largest error of the uniform-strain field, m";
  std::vector<Vec3> r;
  body->computeConstraintForces(r);
  Vec3 onTop = Vec3::Zero();
  for (std::size_t i : top) onTop -= r[i];
  EXPECT_NEAR(onTop.z(), E * A * d / L, 1e-6 * E * A * d / L) << "the compressed column pushes the top plate up";
  EXPECT_NEAR(onTop.head<2>().norm(), 0.0, 1e-9 * E * A * d / L);
}

TEST(FemHierarchicalBody, FreeBodyFallsRigidlyWithGravity) {
  int count = 0;
  const int n = 16;
  const auto occ = ballOccupancy(n, 7.5, count);
  auto mesh = tetMeshHierarchical(occ, {n, n, n}, Vec3::Constant(0.002), Vec3::Zero(), {.levels = 2});
  ASSERT_TRUE(mesh && !mesh->hanging.empty());
  // Block Jacobi keeps the ball's mirror symmetry, so no sideways motion
  // appears at all; Gauss–Seidel sweeps in node order do not, and leave
  // what their tolerance allows (1e-12 relative to the fall, over 50 steps).
  for (const auto& [kind, sideways] : {std::pair{FemPreconditioner::BlockJacobi, 1e-12},
                                      std::pair{FemPreconditioner::SymmetricGaussSeidel, 1e-10}}) {
    SCOPED_TRACE(kind == FemPreconditioner::BlockJacobi ? "block Jacobi" : "symmetric Gauss-Seidel");
    auto body = FemBody::create(*mesh, {.youngsModulus = 5e3, .poissonRatio = 0.45, .density = 1000},
                                {.alpha = 0, .beta = 0.01}, {.tolerance = 1e-12, .preconditioner = kind});
    ASSERT_TRUE(body);
    body->setGravity({0, 0, -kG});
    const double dt = 0.01;
    for (int s = 0; s < 50; ++s) ASSERT_TRUE(body->step(dt));
    // Backward Euler: v_k = k·g·dt exactly, x drops by g·dt²·k(k+1)/2.
    const double drop = kG * dt * dt * 50 * 51 / 2;
    for (std::size_t i = 0; i < body->nodeCount(); ++i) {
      const Vec3 u = body->positions()[i] - body->restPositions()[i];
      ASSERT_NEAR(u.z(), -drop, 1e-9) << "node " << i << (body->isHanging(i) ? " (hanging)" : "");
      ASSERT_NEAR(u.head<2>().norm(), 0.0, sideways * drop);
    }
    EXPECT_NEAR(body->linearMomentum().z(), -body->totalMass() * kG * dt * 50, 1e-9);
    EXPECT_LT(body->elasticEnergy(), 1e-18);
  }
}

// Static response of a block clamped at its base, E = 10 kPa, ν = 0.45:
// (a) a 50 mN load at the top centre, (b) its own weight. The graded mesh
// (voxels under the load, cells up to 4 voxels away from it) against the
// uniform voxel mesh of the same block.
struct Response {
  double indent = 0, sag = 0, reaction = 0, weight = 0;
  std::size_t tets = 0;
};

Response blockResponse(int levels) {
  const int n = 16, nz = 8;
  const double h = 0.0025;
  std::vector<std::uint8_t> occ(std::size_t(n * n * nz), 1);
  const Vec3 top(n * h / 2, n * h / 2, nz * h);
  auto mesh = tetMeshHierarchical(occ, {n, n, nz}, Vec3::Constant(h), Vec3::Zero(),
                                  {.levels = levels,
                                   .fineRegion = Aabb(top - Vec3(2 * h, 2 * h, 2 * h), top + Vec3(2 * h, 2 * h, 0)),
                                   .grading = 1.0});
  EXPECT_TRUE(mesh);
  Response out;
  out.tets = mesh->tetCount();
  auto solve = [&](bool load, bool gravity) {
    auto body = FemBody::create(*mesh, {.youngsModulus = 1e4, .poissonRatio = 0.45, .density = 1000},
                                {.alpha = 5.0}, {.tolerance = 1e-10, .maxIterations = 20000});
    EXPECT_TRUE(body);
    body->fixNodesWhere([](const Vec3& p) { return p.z() < 1e-12; });
    std::size_t centre = 0;
    for (std::size_t i = 0; i < body->nodeCount(); ++i)
      if ((body->restPositions()[i] - top).norm() < 1e-9) centre = i;
    EXPECT_FALSE(body->isHanging(centre));
    if (load) body->setExternalForce(centre, {0, 0, -0.05});
    if (gravity) body->setGravity({0, 0, -kG});
    for (int s = 0; s < 8; ++s) EXPECT_TRUE(body->step(10.0));
    const double dz = body->positions()[centre].z() - top.z();
    std::vector<Vec3> r;
    body->computeConstraintForces(r);
    Vec3 sum = Vec3::Zero();
    for (const Vec3& f : r) sum += f;
    return std::tuple{dz, sum.z(), body->totalMass() * kG};
  };
  const auto [dzLoad, reactLoad, m0] = solve(true, false);
  const auto [dzSag, reactSag, weight] = solve(false, true);
  out.indent = -dzLoad;
  out.sag = -dzSag;
  out.reaction = reactSag;
  out.weight = weight;
  EXPECT_NEAR(reactLoad, 0.05, 1e-6) << "the clamp holds the applied load";
  (void)m0;
  return out;
}

TEST(FemHierarchicalBody, GradedBlockMatchesTheUniformVoxelMesh) {
  const Response uniform = blockResponse(0), graded = blockResponse(2);
  std::printf("graded %zu / uniform %zu tetrahedra; indentation %.4f / %.4f mm; sag %.3f / %.3f um\n", graded.tets,
              uniform.tets, graded.indent * 1e3, uniform.indent * 1e3, graded.sag * 1e6, uniform.sag * 1e6);
  EXPECT_LT(graded.tets * 2, uniform.tets) << graded.tets << " vs " << uniform.tets;
  // Coarse cells are stiffer (fewer modes), so the graded block gives a
  // little less, but the local indentation is set by the fine cells under the load.
  EXPECT_NEAR(graded.indent / uniform.indent, 1.0, 0.05)
      << "indentation " << graded.indent * 1e3 << " mm vs " << uniform.indent * 1e3 << " mm";
  EXPECT_NEAR(graded.sag / uniform.sag, 1.0, 0.10) << "sag " << graded.sag * 1e6 << " µm vs " << uniform.sag * 1e6;
  // The clamp carries the whole weight, hanging nodes' share included.
  EXPECT_NEAR(graded.reaction, graded.weight, 1e-6 * graded.weight);
}

TEST(FemHierarchicalMesh, BadHangingEntriesAndOptionsAreNamed) {
  auto base = tetMeshHierarchical(std::vector<std::uint8_t>(8 * 8 * 8, 1), {8, 8, 8}, Vec3::Constant(0.001),
                                  Vec3::Zero(), {.levels = 2, .fineRegion = Aabb(Vec3::Zero(), Vec3::Constant(1e-3))});
  ASSERT_TRUE(base && base->hanging.size() > 2);
  auto expectFail = [&](auto mutate, const char* needle) {
    TetMesh m = *base;
    mutate(m);
    const Status s = m.validate();
    ASSERT_FALSE(s) << needle;
    EXPECT_NE(s.error().message().find(needle), std::string::npos) << s.error().message();
    EXPECT_FALSE(FemBody::create(m, {}));
  };
  expectFail([](TetMesh& m) { m.hanging[1].masters[0] = std::uint32_t(m.nodes.size()); }, "hanging[1]");
  expectFail([](TetMesh& m) { m.hanging[0].masters[1] = m.hanging[0].masters[0]; }, "hanging[0]");
  expectFail([](TetMesh& m) { m.hanging.push_back(m.hanging[0]); }, "hangs twice");
  expectFail([](TetMesh& m) { m.nodes[m.hanging[2].node].x() += 1e-4; }, "midpoint");
  // A cycle: node 4 hangs on (5, 6) and 5 on (4, 6); all three at one
  // point, so each is at its masters' midpoint and only the cycle is wrong.
  {
    TetMesh m;
    m.nodes = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {2, 2, 2}, {2, 2, 2}, {2, 2, 2}};
    m.tets = {{0, 1, 2, 3}};
    m.hanging = {{4, {5, 6}}, {5, {4, 6}}};
    const Status s = m.validate();
    ASSERT_FALSE(s);
    EXPECT_NE(s.error().message().find("depends on itself"), std::string::npos) << s.error().message();
  }
  std::vector<std::uint8_t> occ(4 * 4 * 4, 1);
  auto bad = tetMeshHierarchical(occ, {4, 4, 4}, Vec3::Constant(0.001), Vec3::Zero(), {.levels = 11});
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.error().message().find("options.levels"), std::string::npos);
  bad = tetMeshHierarchical(occ, {4, 4, 4}, Vec3::Constant(0.001), Vec3::Zero(), {.grading = std::nan("")});
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.error().message().find("options.grading"), std::string::npos);
  bad = tetMeshHierarchical(occ, {4, 4, 5}, Vec3::Constant(0.001));
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.error().message().find("occupancy"), std::string::npos);
  bad = tetMeshHierarchical(std::vector<std::uint8_t>(64, 0), {4, 4, 4}, Vec3::Constant(0.001));
  ASSERT_FALSE(bad);
  bad = tetMeshHierarchical(occ, {4, 4, 4}, Vec3::Constant(0.001), Vec3::Zero(), {.maxTets = 5});  // one cell, six tetrahedra
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.error().message().find("maxTets"), std::string::npos);
}

}  // namespace
}  // namespace dm
