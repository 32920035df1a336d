// Tests of dm/physics/fem.hpp against physics and geometry: Euler–Bernoulli
// cantilever deflection and its convergence under mesh refinement,
// rotation invariance of the co-rotational forces, energy behaviour with and
// without Rayleigh damping, free fall (momentum balance), and the voxel
// tetrahedralisation (volume, orientation, closed outward surface).
#include <dm/core/tasks.hpp>
#include <dm/core/volume.hpp>
#include <dm/math/mesh_topology.hpp>
#include <dm/physics/fem.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "physics_test_support.hpp"

namespace dm {
namespace {

using dm::test::kG;

// ---------------------------------------------------------------------------
// Tetrahedral meshes from voxels
// ---------------------------------------------------------------------------

// A 3D "plus" of voxels (a centre column with four arms and a cap) on a
// 5×5×4 grid: non-convex, but every voxel contact is across a full face, so
// its boundary is a closed 2-manifold.
std::vector<std::uint8_t> plusShape(Vec3i& dims, int& count) {
  dims = Vec3i(5, 5, 4);
  std::vector<std::uint8_t> occ(5 * 5 * 4, 0);
  auto set = [&](int i, int j, int k) { occ[std::size_t(i + 5 * (j + 5 * k))] = 1; };
  for (int k = 0; k < 4; ++k) set(2, 2, k);                // column
  for (int a = 0; a < 5; ++a) set(a, 2, 1), set(2, a, 1);  // two arms crossing at k = 1
  set(1, 1, 3), set(1, 2, 3), set(2, 1, 3);                // cap, face-connected to the column top
  count = 0;
  for (auto o : occ) count += o;
  return occ;
}

// Number of voxel faces between an occupied voxel and an empty one or the outside.
int exposedFaces(const std::vector<std::uint8_t>& occ, const Vec3i& dims) {
  auto at = [&](int i, int j, int k) {
    if (i < 0 || j < 0 || k < 0 || i >= dims.x() || j >= dims.y() || k >= dims.z()) return 0;
    return int(occ[std::size_t(i + dims.x() * (j + dims.y() * k))]);
  };
  int faces = 0;
  for (int k = 0; k < dims.z(); ++k)
    for (int j = 0; j < dims.y(); ++j)
      for (int i = 0; i < dims.x(); ++i)
        if (at(i, j, k))
          faces += 6 - at(i - 1, j, k) - at(i + 1, j, k) - at(i, j - 1, k) - at(i, j + 1, k) -
                   at(i, j, k - 1) - at(i, j, k + 1);
  return faces;
}

TEST(FemTetMesh, OccupancySixTetsPerVoxelVolumeAndClosedOutwardSurface) {
  Vec3i dims;
  int count = 0;
  const auto occ = plusShape(dims, count);
  const Vec3 spacing(0.002, 0.003, 0.0025);
  auto mesh = tetMeshFromOccupancy(occ, dims, spacing, Vec3(0.1, -0.2, 0.3));
  ASSERT_TRUE(mesh) << mesh.error().message();
  EXPECT_EQ(mesh->tetCount(), std::size_t(6 * count));
  ASSERT_TRUE(mesh->validate()) << mesh->validate().error().message();  // all volumes > 0
  const double voxelVolume = spacing.prod();
  EXPECT_NEAR(mesh->totalVolume(), count * voxelVolume, 1e-12 * count * voxelVolume);
  // Every tetrahedron of a voxel has 1/6 of its volume (Kuhn split).
  for (std::size_t t = 0; t < mesh->tetCount(); ++t) ASSERT_NEAR(mesh->tetVolume(t), voxelVolume / 6, 1e-15);

  Mesh surface;
  surface.positions = mesh->nodes;
  surface.triangles = tetMeshSurface(*mesh);
  // Each exposed voxel face is split into two triangles, interior faces cancel.
  EXPECT_EQ(surface.triangles.size(), std::size_t(2 * exposedFaces(occ, dims)));
  const MeshTopology topo = analyzeTopology(surface);
  EXPECT_TRUE(topo.isClosed);
  EXPECT_TRUE(topo.isManifold);
  EXPECT_TRUE(topo.isOrientedConsistently);
  EXPECT_EQ(topo.components, 1u);
  ASSERT_TRUE(topo.volume.has_value());
  // Positive enclosed volume = triangles counter-clockwise from outside.
  EXPECT_NEAR(*topo.volume, count * voxelVolume, 1e-12 * count * voxelVolume);
}

TEST(FemTetMesh, BoxSharesNodesAndIsConforming) {
  auto mesh = tetMeshBox({3, 4, 5}, Vec3(0.3, 0.2, 0.1), Vec3(1, 2, 3));
  ASSERT_TRUE(mesh) << mesh.error().message();
  EXPECT_EQ(mesh->nodeCount(), std::size_t(4 * 5 * 6));  // deduplicated grid corners
  EXPECT_EQ(mesh->tetCount(), std::size_t(6 * 3 * 4 * 5));
  EXPECT_NEAR(mesh->totalVolume(), 0.3 * 0.2 * 0.1, 1e-15);
  // Conforming: only the 2·(3·4 + 4·5 + 3·5) boundary squares have unmatched faces.
  EXPECT_EQ(tetMeshSurface(*mesh).size(), std::size_t(2 * 2 * (3 * 4 + 4 * 5 + 3 * 5)));
}

TEST(FemTetMesh, FromVolumeFollowsTheAffineEvenWhenMirrored) {
  Affine3 a = Affine3::Identity();
  a.linear() = Vec3(-0.001, 0.002, 0.0015).asDiagonal();  // mirrored x axis
  a.linear() = AngleAxis(0.4, Vec3(1, 1, 0).normalized()).toRotationMatrix() * a.linear();
  a.translation() = Vec3(0.05, 0.0, -0.02);
  auto vol = Volume::create({6, 5, 4}, VoxelType::F32, a);
  ASSERT_TRUE(vol) << vol.error().message();
  int count = 0;
  for (int k = 0; k < 4; ++k)
    for (int j = 0; j < 5; ++j)
      for (int i = 0; i < 6; ++i) {
        const double value = (i - 2.5) * (i - 2.5) + (j - 2) * (j - 2) + (k - 1.5) * (k - 1.5);  // a blob
        vol->setValue(i, j, k, 10.0 - value);
        count += 10.0 - value >= 4.0 ? 1 : 0;
      }
  auto mesh = tetMeshFromVolume(*vol, {.threshold = 4.0});
  ASSERT_TRUE(mesh) << mesh.error().message();
  ASSERT_TRUE(mesh->validate()) << mesh->validate().error().message();
  EXPECT_EQ(mesh->tetCount(), std::size_t(6 * count));
  const double voxelVolume = std::abs(a.linear().determinant());
  EXPECT_NEAR(mesh->totalVolume(), count * voxelVolume, 1e-9 * count * voxelVolume);
  // The voxel (i, j, k) is centred on indexToWorld · (i, j, k): the mesh's
  // centroid equals the occupied voxel centres' mean.
  Vec3 centres = Vec3::Zero(), centroid = Vec3::Zero();
  for (int k = 0; k < 4; ++k)
    for (int j = 0; j < 5; ++j)
      for (int i = 0; i < 6; ++i)
        if (vol->value(i, j, k) >= 4.0) centres += a * Vec3(i, j, k);
  for (std::size_t t = 0; t < mesh->tetCount(); ++t) {
    const Tet& e = mesh->tets[t];
    centroid += mesh->tetVolume(t) * 0.25 *
                (mesh->nodes[e[0]] + mesh->nodes[e[1]] + mesh->nodes[e[2]] + mesh->nodes[e[3]]);
  }
  EXPECT_LT((centroid / mesh->totalVolume() - centres / count).norm(), 1e-12);
}

TEST(FemTetMesh, BadInputNamesTheField) {
  const std::vector<std::uint8_t> empty(8, 0), full(8, 1);
  auto none = tetMeshFromOccupancy(empty, {2, 2, 2}, Vec3::Constant(0.01));
  ASSERT_FALSE(none);
  EXPECT_NE(none.error().what.find("occupied"), std::string::npos);
  auto spacing = tetMeshFromOccupancy(full, {2, 2, 2}, Vec3(0.01, -0.01, 0.01));
  ASSERT_FALSE(spacing);
  EXPECT_NE(spacing.error().what.find("spacing.y"), std::string::npos);
  auto mismatch = tetMeshFromOccupancy(full, {2, 2, 3}, Vec3::Constant(0.01));
  ASSERT_FALSE(mismatch);
  EXPECT_NE(mismatch.error().what.find("entries"), std::string::npos);
  auto cap = tetMeshFromOccupancy(full, {2, 2, 2}, Vec3::Constant(0.01), Vec3::Zero(), {.maxTets = 47});
  ASSERT_FALSE(cap);
  EXPECT_NE(cap.error().what.find("maxTets"), std::string::npos);
  EXPECT_TRUE(tetMeshFromOccupancy(full, {2, 2, 2}, Vec3::Constant(0.01), Vec3::Zero(), {.maxTets = 48}));
  auto huge = tetMeshBox({100000, 100000, 100000}, Vec3::Ones());
  ASSERT_FALSE(huge);
  EXPECT_NE(huge.error().what.find("maxTets"), std::string::npos);
  auto dims = tetMeshBox({0, 1, 1}, Vec3::Ones());
  ASSERT_FALSE(dims);
  EXPECT_NE(dims.error().what.find("dims[0]"), std::string::npos);

  auto mesh = tetMeshBox({1, 1, 1}, Vec3::Ones());
  ASSERT_TRUE(mesh);
  EXPECT_FALSE(FemBody::create(*mesh, {.youngsModulus = -1.0}));
  auto nu = FemBody::create(*mesh, {.poissonRatio = 0.5});
  ASSERT_FALSE(nu);
  EXPECT_NE(nu.error().what.find("poissonRatio"), std::string::npos);
  TetMesh flipped = *mesh;
  std::swap(flipped.tets[3][0], flipped.tets[3][1]);
  auto inverted = FemBody::create(flipped, {});
  ASSERT_FALSE(inverted);
  EXPECT_NE(inverted.error().what.find("tets[3]"), std::string::npos);
}

// ---------------------------------------------------------------------------
// FEM body
// ---------------------------------------------------------------------------

TEST(FemBody, LumpedMassAndSurfaceOfTheBody) {
  auto mesh = tetMeshBox({2, 3, 4}, Vec3(0.02, 0.03, 0.04));
  ASSERT_TRUE(mesh);
  auto body = FemBody::create(*mesh, {.density = 1100.0});
  ASSERT_TRUE(body) << body.error().message();
  EXPECT_NEAR(body->totalMass(), 1100.0 * 0.02 * 0.03 * 0.04, 1e-12);
  EXPECT_GT(body->colourCount(), 1u);
  Mesh surface;
  body->surfaceMesh(surface);
  const MeshTopology topo = analyzeTopology(surface);
  EXPECT_TRUE(topo.isClosed && topo.isOrientedConsistently);
  ASSERT_TRUE(topo.volume.has_value());
  EXPECT_NEAR(*topo.volume, 0.02 * 0.03 * 0.04, 1e-15);
}

// A rigid rotation and translation of the rest shape: the co-rotated strain is
// zero, so forces and energy vanish; plain linear FEM sees a large strain.
TEST(FemBody, RigidRotationGivesNoCorotatedForce) {
  auto mesh = tetMeshBox({3, 3, 3}, Vec3(0.03, 0.03, 0.03));
  ASSERT_TRUE(mesh);
  const FemMaterial mat{.youngsModulus = 2e4, .poissonRatio = 0.45, .density = 1000};
  auto corot = FemBody::create(*mesh, mat);
  auto linear = FemBody::create(*mesh, mat, {}, {.corotational = false});
  ASSERT_TRUE(corot && linear);
  const Isometry3 pose = Eigen::Translation3d(0.01, -0.02, 0.03) * AngleAxis(1.7, Vec3(1, 2, 3).normalized());
  std::vector<Vec3> moved;
  for (const Vec3& p : mesh->nodes) moved.push_back(pose * p);
  corot->setPositions(moved);
  linear->setPositions(moved);

  std::vector<Vec3> fc, fl;
  corot->computeElasticForces(fc);
  linear->computeElasticForces(fl);
  double maxC = 0, maxL = 0;
  for (std::size_t i = 0; i < fc.size(); ++i)
    maxC = std::max(maxC, fc[i].norm()), maxL = std::max(maxL, fl[i].norm());
  // Scale: a 1% strain on a 1 cm element gives E·A·ε ≈ 2e4 · 1e-4 · 0.01 = 2e-2 N.
  EXPECT_GT(maxL, 1e-2);
  EXPECT_LT(maxC, 1e-9 * maxL);
  EXPECT_LT(corot->elasticEnergy(), 1e-12);
  EXPECT_GT(linear->elasticEnergy(), 1e-4);

  // Stepping the rotated body (no gravity, no velocity) keeps it at rest.
  auto rep = corot->step(0.01);
  ASSERT_TRUE(rep) << rep.error().message();
  for (std::size_t i = 0; i < moved.size(); ++i) EXPECT_LT((corot->positions()[i] - moved[i]).norm(), 1e-9);
}

// Stretched free cube oscillating: backward Euler never gains energy, and
// Rayleigh damping removes nearly all of it within a few periods.
TEST(FemBody, EnergyDecaysWithDampingAndStaysBoundedWithout) {
  auto mesh = tetMeshBox({3, 3, 3}, Vec3(0.03, 0.03, 0.03));
  ASSERT_TRUE(mesh);
  const FemMaterial mat{.youngsModulus = 1e4, .poissonRatio = 0.3, .density = 1000};
  std::vector<Vec3> stretched;
  for (const Vec3& p : mesh->nodes) stretched.push_back(Vec3(1.15 * p.x(), p.y(), 0.95 * p.z()));
  // Lowest period ~ 2L·sqrt(ρ/E) ≈ 0.02 s; run 0.04 s with h = 0.2 ms.
  auto run = [&](const FemDamping& d, std::vector<double>& energy) {
    auto body = FemBody::create(*mesh, mat, d, {.tolerance = 1e-10, .maxIterations = 500});
    EXPECT_TRUE(body);
    body->setPositions(stretched);
    energy.push_back(body->elasticEnergy());
    for (int s = 0; s < 200; ++s) {
      auto rep = body->step(2e-4);
      EXPECT_TRUE(rep && rep->converged);
      energy.push_back(body->elasticEnergy() + body->kineticEnergy());
    }
    return body->linearMomentum().norm();
  };
  std::vector<double> free, damped;
  const double p0 = run({}, free);
  const double p1 = run({.alpha = 5.0, .beta = 2e-3}, damped);
  EXPECT_LT(p0, 1e-12);  // internal forces only: no net momentum
  EXPECT_LT(p1, 1e-12);
  ASSERT_GT(free[0], 1e-5);
  for (std::size_t s = 1; s < free.size(); ++s) {
    EXPECT_LE(free[s], free[0] * (1 + 1e-6)) << "step " << s;
    EXPECT_LE(damped[s], damped[s - 1] * (1 + 1e-6)) << "step " << s;
  }
  EXPECT_GT(free.back(),
            0.2 * free[0]);  // bounded and still oscillating (backward Euler's own loss is small)
  EXPECT_LT(damped.back(), 1e-2 * free.back());  // Rayleigh damping removes the rest
}

// A free, deformed, spinning body under gravity: internal forces cancel, so
// the momentum grows by M g h per step and the centre of mass falls with g.
TEST(FemBody, FreeBodyFallsWithGravity) {
  auto mesh = tetMeshBox({2, 3, 2}, Vec3(0.02, 0.03, 0.02));
  ASSERT_TRUE(mesh);
  auto body = FemBody::create(*mesh, {.youngsModulus = 5e3, .poissonRatio = 0.4}, {.beta = 1e-3},
                              {.tolerance = 1e-12, .maxIterations = 1000});
  ASSERT_TRUE(body);
  std::vector<Vec3> x, v;
  for (const Vec3& p : mesh->nodes) {
    x.push_back(Vec3(p.x() * 1.1, p.y(), p.z() + 0.2 * p.y()));
    v.push_back(Vec3(0.1, 0, 0) + Vec3(0, 0, 3.0).cross(p));  // drift + spin about z
  }
  body->setPositions(x);
  body->setVelocities(v);
  body->setGravity({0, 0, -kG});
  const Vec3 c0 = body->centerOfMass(), p0 = body->linearMomentum();
  const double h = 2e-3, M = body->totalMass();
  const int n = 100;
  for (int s = 0; s < n; ++s) ASSERT_TRUE(body->step(h));
  const double t = n * h;
  const Vec3 g(0, 0, -kG);
  EXPECT_LT((body->linearMomentum() - (p0 + M * g * t)).norm(), 1e-9 * M * kG * t);
  // Backward Euler: x_c(n) = x_c(0) + n h v_c(0) + h² g n(n+1)/2 (exact for the centre of mass).
  const Vec3 expected = c0 + t * p0 / M + h * h * g * (n * (n + 1) / 2.0);
  EXPECT_LT((body->centerOfMass() - expected).norm(), 1e-9);
  // …which is the free-fall parabola up to O(h).
  EXPECT_NEAR(body->centerOfMass().z() - c0.z(), -0.5 * kG * t * t, 0.5 * kG * t * h * 1.01);
}

// The same scene stepped on one worker thread and on all of them gives
// bit-identical states (the element colouring and the row-by-row system
// product fix the summation order), and the serial setting, which sums the
// product in another order, agrees to round-off.
TEST(FemBody, ResultDoesNotDependOnThreadCount) {
  auto mesh = tetMeshBox({8, 4, 4}, Vec3(0.08, 0.04, 0.04));
  ASSERT_TRUE(mesh);
  auto make = [&](bool parallel) {
    auto body = FemBody::create(*mesh, {.youngsModulus = 1e4}, {.alpha = 1, .beta = 1e-3},
                                {.tolerance = 1e-10, .maxIterations = 2000, .parallel = parallel});
    EXPECT_TRUE(body);
    body->fixNodesWhere([](const Vec3& p) { return p.x() < 1e-9; });
    body->setGravity({0, 0, -kG});
    body->setExternalForce(body->nodeCount() - 1, Vec3(0, 0.01, 0));
    return std::move(*body);
  };
  auto run = [](FemBody& body) {
    for (int s = 0; s < 10; ++s) ASSERT_TRUE(body.step(0.01));
  };
  FemBody oneThread = make(true), allThreads = make(true), serial = make(false);
  {
    TaskPool pool({.max_concurrency = 1});
    pool.submit([&] { run(oneThread); });
    pool.wait();
  }
  run(allThreads);
  run(serial);
  double sag = 0.0;
  for (std::size_t i = 0; i < mesh->nodeCount(); ++i) {
    ASSERT_EQ(oneThread.positions()[i], allThreads.positions()[i]) << i;
    ASSERT_EQ(oneThread.velocities()[i], allThreads.velocities()[i]) << i;
    sag = std::max(sag, (serial.positions()[i] - mesh->nodes[i]).norm());
  }
  ASSERT_GT(sag, 1e-4);
  for (std::size_t i = 0; i < mesh->nodeCount(); ++i) {
    EXPECT_LT((serial.positions()[i] - allThreads.positions()[i]).norm(), 1e-8 * sag) << i;
    if (allThreads.isFixed(i)) {
      EXPECT_EQ(allThreads.positions()[i], mesh->nodes[i]);
    }
  }
}

// Both preconditioners solve the same system: the same states to the
// solver tolerance, with symmetric Gauss–Seidel in well under half block
// Jacobi's iterations on nearly incompressible tissue (ν = 0.45).
TEST(FemBody, GaussSeidelPreconditionerMatchesJacobiInFewerIterations) {
  auto mesh = tetMeshBox({6, 6, 6}, Vec3(0.03, 0.03, 0.03));
  ASSERT_TRUE(mesh);
  std::vector<Vec3> end[2];
  long iterations[2] = {0, 0};
  const FemPreconditioner kinds[2] = {FemPreconditioner::BlockJacobi, FemPreconditioner::SymmetricGaussSeidel};
  for (int k = 0; k < 2; ++k) {
    auto body = FemBody::create(*mesh, {.youngsModulus = 1e4, .poissonRatio = 0.45}, {.alpha = 1, .beta = 0.01},
                                {.tolerance = 1e-10, .maxIterations = 5000, .preconditioner = kinds[k]});
    ASSERT_TRUE(body);
    body->fixNodesWhere([](const Vec3& p) { return p.z() < 1e-9; });
    body->setGravity({0, 0, -kG});
    for (std::size_t i = 0; i < body->nodeCount(); ++i)
      if (body->positions()[i].z() > 0.03 - 1e-9) body->setExternalForce(i, Vec3(2e-4, 0, 0));
    for (int s = 0; s < 8; ++s) {
      auto r = body->step(0.01);
      ASSERT_TRUE(r);
      ASSERT_TRUE(r->converged);
      iterations[k] += r->cgIterations;
    }
    end[k] = body->positions();
  }
  double motion = 0.0, gap = 0.0;
  for (std::size_t i = 0; i < mesh->nodeCount(); ++i) {
    motion = std::max(motion, (end[0][i] - mesh->nodes[i]).norm());
    gap = std::max(gap, (end[0][i] - end[1][i]).norm());
  }
  ASSERT_GT(motion, 1e-4);
  EXPECT_LT(gap, 1e-7 * motion);
  EXPECT_LT(2 * iterations[1], iterations[0]) << iterations[1] << " vs " << iterations[0];
}

// Cantilever under its own weight, clamped at x = 0, ν = 0: the mean
// deflection of the free end approaches Euler–Bernoulli δ = q L⁴ / (8 E I),
// q = ρ g b², I = b⁴/12, as the mesh is refined. Large implicit steps with
// damping settle to the static state.
double cantileverTipError(int across, double slenderness, int* cgIterations) {
  const double b = 0.01, L = slenderness * b;
  const double E = 1e6, rho = 1000;
  const int along = int(std::lround(slenderness * across));
  auto mesh = tetMeshBox({along, across, across}, Vec3(L, b, b));
  EXPECT_TRUE(mesh);
  auto body = FemBody::create(*mesh, {.youngsModulus = E, .poissonRatio = 0.0, .density = rho},
                              {.alpha = 1, .beta = 0.01},
                              {.tolerance = 1e-7, .maxIterations = 20000, .parallel = false});
  EXPECT_TRUE(body);
  body->fixNodesWhere([](const Vec3& p) { return p.x() < 1e-12; });
  body->setGravity({0, 0, -kG});
  *cgIterations = 0;
  for (int s = 0; s < 3; ++s) {
    auto rep = body->step(100.0);
    EXPECT_TRUE(rep && rep->converged);
    if (rep) *cgIterations += rep->cgIterations;
  }
  double tip = 0;
  int count = 0;
  for (std::size_t i = 0; i < body->nodeCount(); ++i)
    if (body->restPositions()[i].x() > L - 1e-12)
      tip += body->positions()[i].z() - body->restPositions()[i].z(), ++count;
  tip /= count;
  const double q = rho * kG * b * b, I = b * b * b * b / 12.0;
  const double euler = q * L * L * L * L / (8 * E * I);
  return (-tip - euler) / euler;
}

TEST(FemBody, CantileverConvergesToEulerBernoulli) {
  // Slenderness L/b = 8: Timoshenko shear adds ≈ 1.2 % to δ, so the 3D
  // continuum answer lies within ~2 % of Euler–Bernoulli.
  int iterations = 0;
  const double e2 = cantileverTipError(2, 8.0, &iterations);
  const double e4 = cantileverTipError(4, 8.0, &iterations);
  const double e8 = cantileverTipError(8, 8.0, &iterations);  // 24,576 tetrahedra
  // Displacement-based linear tetrahedra are too stiff (shear locking) and
  // converge from below as the mesh is refined.
  EXPECT_LT(e2, e4);
  EXPECT_LT(e4, e8);
  EXPECT_LT(e8, 0.0);
  EXPECT_LT(std::abs(e8), 0.05) << "finest mesh: tip deflection off Euler–Bernoulli by " << e8 * 100 << " %";
  // Observed convergence order of the error between h and h/2 (≈ 2 for
  // linear elements once asymptotic).
  const double order = std::log2(e4 / e8);
  EXPECT_GT(order, 1.5);
  // Richardson extrapolation with that order: the continuum limit.
  const double limit = e8 + (e8 - e4) / 3.0;
  EXPECT_LT(std::abs(limit), 0.02);
}

}  // namespace
}  // namespace dm

using dm::Vec3;

namespace {

// A column (ν = 0, so bonded faces do not constrain it and the stress is
// uniaxial) compressed by its top face at a prescribed constant speed w:
// the quasi-static Kelvin–Voigt answer is F = E·A·(d + β·w)/L on the loading
// ramp and E·A·d/L once the face stops. Light (1 kg/m³): inertia ≈ 0.
struct Column {
  static constexpr double kE = 1e4, kBeta = 0.05, kSide = 0.01, kLength = 0.02, kSpeed = 2e-3;
  dm::FemBody body;
  std::vector<std::size_t> top;
  dm::Vec3 forceOnTop() const {
    std::vector<dm::Vec3> r;
    body.computeConstraintForces(r);
    dm::Vec3 f = dm::Vec3::Zero();
    for (std::size_t i : top) f -= r[i];  // the tissue on the indenter
    return f;
  }
};

Column makeColumn() {
  auto mesh = dm::tetMeshBox({2, 2, 4}, dm::Vec3(Column::kSide, Column::kSide, Column::kLength));
  EXPECT_TRUE(mesh);
  auto body = dm::FemBody::create(*mesh, {.youngsModulus = Column::kE, .poissonRatio = 0.0, .density = 1.0},
                                  {.beta = Column::kBeta}, {.tolerance = 1e-12, .maxIterations = 2000});
  EXPECT_TRUE(body);
  Column c{std::move(*body), {}};
  c.body.fixNodesWhere([](const Vec3& p) { return p.z() < 1e-12; });
  for (std::size_t i = 0; i < mesh->nodeCount(); ++i)
    if (mesh->nodes[i].z() > Column::kLength - 1e-12) c.top.push_back(i);
  return c;
}

}  // namespace

TEST(FemBody, PrescribedFaceMotionGivesTheKelvinVoigtColumnForce) {
  Column c = makeColumn();
  ASSERT_EQ(c.top.size(), 9u);
  for (std::size_t i : c.top) {
    c.body.setFixed(i, true);
    c.body.setVelocity(i, Vec3(0, 0, -Column::kSpeed));
  }
  const double h = 5e-3, A = Column::kSide * Column::kSide;
  double t = 0;
  for (int s = 0; s < 200; ++s, t += h) ASSERT_TRUE(c.body.step(h));
  // The top moved exactly by its prescribed motion.
  for (std::size_t i : c.top)
    EXPECT_NEAR(c.body.positions()[i].z(), Column::kLength - Column::kSpeed * t, 1e-12);
  const double d = Column::kSpeed * t;
  const double loading = Column::kE * A * (d + Column::kBeta * Column::kSpeed) / Column::kLength;
  const Vec3 f = c.forceOnTop();
  EXPECT_NEAR(f.z(), loading, 2e-3 * loading) << "elastic part " << Column::kE * A * d / Column::kLength;
  EXPECT_LT(std::hypot(f.x(), f.y()), 1e-9);
  // Uniaxial: the interior follows the linear displacement profile.
  for (std::size_t i = 0; i < c.body.nodeCount(); ++i) {
    const Vec3& p0 = c.body.restPositions()[i];
    EXPECT_NEAR(c.body.positions()[i].z(), p0.z() * (1 - d / Column::kLength), 1e-7) << "node " << i;
    EXPECT_NEAR(c.body.positions()[i].x(), p0.x(), 1e-9);
  }
  // Stopped: the viscous part goes, the elastic part stays.
  for (std::size_t i : c.top) c.body.setVelocity(i, Vec3::Zero());
  for (int s = 0; s < 100; ++s) ASSERT_TRUE(c.body.step(h));
  const double holding = Column::kE * A * d / Column::kLength;
  EXPECT_NEAR(c.forceOnTop().z(), holding, 2e-3 * holding);
  // Free nodes carry no constraint force.
  std::vector<Vec3> r;
  c.body.computeConstraintForces(r);
  for (std::size_t i = 0; i < r.size(); ++i) {
    if (!c.body.isFixed(i)) {
      EXPECT_EQ(r[i], Vec3::Zero());
    }
  }
}
