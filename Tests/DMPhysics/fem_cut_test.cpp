// FemBody::applyCut: FEM tissue cut while it moves — the in-place update
// against a body built from the cut mesh, the free fall of a piece cut off,
// and a stretched bar's tension released by a cut.
#include <dm/physics/blade.hpp>
#include <dm/physics/fem.hpp>
#include <dm/physics/tet_cut.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <vector>

namespace dm {
namespace {

// A blade spanning the block's width (y) and height (z) with margins, at
// x = at: a cut across a bar.
std::array<CutTriangle, 2> crossCut(double at, double width, double height, double m = 0.01) {
  return bladeSweep(Vec3(at, -m, -m), Vec3(at, -m, height + m), Vec3(at, width + m, -m),
                    Vec3(at, width + m, height + m));
}

TEST(FemCut, AnUpdatedBodyStepsLikeABodyBuiltFromTheCutMesh) {
  // A 30 × 12 × 12 mm bar clamped at x = 0 sagging under gravity, cut
  // progressively from the top by a blade moving down at x = 17.3 mm:
  // after each update the body goes on from its state.
  const Vec3 size(0.030, 0.012, 0.012);
  auto mesh = tetMeshBox({10, 4, 4}, size);
  ASSERT_TRUE(mesh.ok());
  const FemMaterial mat{.youngsModulus = 2e4, .poissonRatio = 0.4, .density = 1000};
  const FemDamping damp{.alpha = 0.0, .beta = 0.01};
  const FemSolverOptions opt{.tolerance = 1e-12, .maxIterations = 2000, .parallel = false};
  auto body = FemBody::create(*mesh, mat, damp, opt);
  ASSERT_TRUE(body.ok());
  body->fixNodesWhere([](const Vec3& p) { return p.x() < 1e-9; });
  body->setGravity({0, 0, -9.81});
  auto cutter = TetCutter::create(*mesh);
  ASSERT_TRUE(cutter.ok());
  const double h = 0.005, x = 0.0173, m = 0.01;
  double top = size.z() + m;
  std::size_t updates = 0;
  for (int i = 0; i < 24; ++i) {
    ASSERT_TRUE(body->step(h).ok());
    const double bottom = size.z() + m - (size.z() + 2 * m) * (i + 1) / 24.0;
    auto up = cutter->cut(bladeSweep(Vec3(x, -m, top), Vec3(x, size.y() + m, top), Vec3(x, -m, bottom),
                                     Vec3(x, size.y() + m, bottom)),
                          body->positions());
    ASSERT_TRUE(up.ok());
    top = bottom;
    if (up->changedElements.empty()) continue;
    ++updates;
    ASSERT_TRUE(body->applyCut(*cutter, *up).ok());
    EXPECT_EQ(body->nodeCount(), cutter->nodeCount());
    EXPECT_EQ(body->tetCount(), cutter->elements().size());
  }
  EXPECT_GT(updates, 3u);
  std::vector<std::uint32_t> pieceOf;
  ASSERT_EQ(cutter->pieces(pieceOf), 2u);
  EXPECT_NEAR(body->totalMass(), mat.density * size.prod(), 1e-12 * mat.density * size.prod());

  // The same model built from the cut mesh, in the same state.
  auto fresh = FemBody::create(cutter->mesh(), mat, damp, opt);
  ASSERT_TRUE(fresh.ok());
  for (std::size_t i = 0; i < body->nodeCount(); ++i) fresh->setFixed(i, body->isFixed(i));
  fresh->setPositions(body->positions());
  fresh->setVelocities(body->velocities());
  fresh->setGravity(body->gravity());
  for (std::size_t i = 0; i < body->nodeCount(); ++i)
    ASSERT_NEAR(fresh->masses()[i], body->masses()[i], 1e-15);
  for (int i = 0; i < 10; ++i) {
    ASSERT_TRUE(body->step(h).ok());
    ASSERT_TRUE(fresh->step(h).ok());
  }
  double worst = 0.0;
  for (std::size_t i = 0; i < body->nodeCount(); ++i)
    worst = std::max(worst, (body->positions()[i] - fresh->positions()[i]).norm());
  EXPECT_LT(worst, 1e-10);
  // And the cut-off end fell away from the clamped part.
  double endZ = 0.0;
  int count = 0;
  for (std::size_t i = 0; i < body->nodeCount(); ++i)
    if (body->restPositions()[i].x() > size.x() - 1e-9) endZ += body->positions()[i].z(), ++count;
  EXPECT_LT(endZ / count, -0.005);
}

TEST(FemCut, APieceCutOffFallsFreely) {
  // A 12 × 12 × 30 mm column clamped at its top, hanging in gravity, cut
  // across at z = 13.1 mm (in its current, stretched shape). The piece
  // below is then free: with stiffness-proportional damping only, its
  // momentum changes by exactly its weight × time (internal forces cancel),
  // and its mass is ρ × the material below the cut.
  const Vec3 size(0.012, 0.012, 0.030);
  auto mesh = tetMeshBox({4, 4, 10}, size);
  ASSERT_TRUE(mesh.ok());
  const FemMaterial mat{.youngsModulus = 3e4, .poissonRatio = 0.45, .density = 1050};
  const FemSolverOptions opt{.tolerance = 1e-10, .maxIterations = 1000};
  auto body = FemBody::create(*mesh, mat, {.alpha = 0.0, .beta = 0.005}, opt);
  ASSERT_TRUE(body.ok());
  body->fixNodesWhere([&](const Vec3& p) { return p.z() > size.z() - 1e-9; });
  const double g = 9.81, h = 0.002;
  body->setGravity({0, 0, -g});
  for (int i = 0; i < 50; ++i) ASSERT_TRUE(body->step(h).ok());
  auto cutter = TetCutter::create(*mesh);
  ASSERT_TRUE(cutter.ok());
  const double cz = 0.0131, m = 0.01;
  auto up = cutter->cut(bladeSweep(Vec3(-m, -m, cz), Vec3(-m, size.y() + m, cz), Vec3(size.x() + m, -m, cz),
                                   Vec3(size.x() + m, size.y() + m, cz)),
                        body->positions());
  ASSERT_TRUE(up.ok());
  ASSERT_TRUE(body->applyCut(*cutter, *up).ok());
  std::vector<std::uint32_t> pieceOf;
  ASSERT_EQ(cutter->pieces(pieceOf), 2u);
  const std::uint32_t lower = pieceOf[0];  // element 0 is at the bottom corner
  std::vector<int> inLower(body->nodeCount(), 0);
  double volume = 0.0;
  for (std::size_t e = 0; e < cutter->elements().size(); ++e)
    if (pieceOf[e] == lower) {
      volume += cutter->elementVolume(e);
      for (const std::uint32_t v : cutter->elements()[e].nodes) inLower[v] = 1;
    }
  auto momentum = [&] {
    Vec3 p = Vec3::Zero();
    double mass = 0.0;
    for (std::size_t i = 0; i < body->nodeCount(); ++i)
      if (inLower[i]) p += body->masses()[i] * body->velocities()[i], mass += body->masses()[i];
    return std::pair{p, mass};
  };
  const auto [p0, mass] = momentum();
  EXPECT_NEAR(mass, mat.density * volume, 1e-12 * mass);
  // The material below the cut plane, in the rest shape: the plane was
  // placed in the sagged column; its material height follows from the
  // crossings, so compare the volume with the plane's rest height bounds:
  // the column stretched by < 1 % above it.
  EXPECT_GT(volume, size.x() * size.y() * cz * 0.98);
  EXPECT_LT(volume, size.x() * size.y() * cz * 1.02);
  const int steps = 100;
  for (int i = 0; i < steps; ++i) ASSERT_TRUE(body->step(h).ok());
  const auto [p1, mass1] = momentum();
  const Vec3 expected = p0 + Vec3(0, 0, -mass * g * steps * h);
  EXPECT_NEAR((p1 - expected).norm(), 0.0, 1e-6 * mass * g * steps * h);
  EXPECT_NEAR(mass1, mass, 1e-15);
}

TEST(FemCut, CuttingAStretchedBarReleasesItsTension) {
  // A 40 mm bar clamped at both ends and stretched 10 %; cut through its
  // middle it springs back: each half, clamped at one end only, returns to
  // its rest shape (elastic energy → 0, the cut end at its rest position).
  const Vec3 size(0.040, 0.008, 0.008);
  auto mesh = tetMeshBox({10, 2, 2}, size);
  ASSERT_TRUE(mesh.ok());
  const FemMaterial mat{.youngsModulus = 2e4, .poissonRatio = 0.3, .density = 1000};
  auto body = FemBody::create(*mesh, mat, {.alpha = 20.0, .beta = 0.002});
  ASSERT_TRUE(body.ok());
  std::vector<Vec3> x = body->positions();
  for (Vec3& p : x) p.x() *= 1.1;
  body->setPositions(x);
  body->fixNodesWhere([&](const Vec3& p) { return p.x() < 1e-9 || p.x() > size.x() - 1e-9; });
  for (int i = 0; i < 100; ++i) ASSERT_TRUE(body->step(0.01).ok());
  const double stretched = body->elasticEnergy();
  ASSERT_GT(stretched, 0.0);
  auto cutter = TetCutter::create(*mesh);
  ASSERT_TRUE(cutter.ok());
  auto up = cutter->cut(crossCut(0.0221, size.y(), size.z()), body->positions());  // x = 20.1 mm of material
  ASSERT_TRUE(up.ok());
  ASSERT_TRUE(body->applyCut(*cutter, *up).ok());
  for (int i = 0; i < 300; ++i) ASSERT_TRUE(body->step(0.01).ok());
  EXPECT_LT(body->elasticEnergy(), 1e-6 * stretched);
  // Every node back at its rest position (each half hangs from its clamp
  // without load: no gravity), the right half's moved with its clamp by
  // the stretch, 4 mm.
  std::vector<std::uint32_t> pieceOf;
  ASSERT_EQ(cutter->pieces(pieceOf), 2u);
  std::vector<std::uint32_t> nodePiece(body->nodeCount());
  for (std::size_t e = 0; e < pieceOf.size(); ++e)
    for (const std::uint32_t v : cutter->elements()[e].nodes) nodePiece[v] = pieceOf[e];
  const std::uint32_t left = pieceOf[0];
  double worst = 0.0;
  for (std::size_t i = 0; i < body->nodeCount(); ++i) {
    const Vec3 shift = nodePiece[i] == left ? Vec3::Zero() : Vec3(0.1 * size.x(), 0, 0);
    worst = std::max(worst, (body->positions()[i] - body->restPositions()[i] - shift).norm());
  }
  EXPECT_LT(worst, 1e-6);
}

TEST(FemCut, ABarInTensionTearsAtItsCriticalLoadAndTheCrackRunsThrough) {
  // A 40 × 8 × 8 mm bar (ν = 0: no lateral contraction, so the clamp at
  // x = 0 leaves the stress uniform) pulled at its free end by a uniform
  // traction F/A (each boundary triangle of that face gives a third of
  // its share to each corner: the consistent load, exact for linear
  // elements). σ = F/A everywhere, so it tears once F reaches σ_c·A. The
  // load rises in 0.5 % steps of F_c, each settled by 300 overdamped
  // 10 ms steps (α = 150/s); 0.5 s steps diverged (see the commit).
  const Vec3 size(0.040, 0.008, 0.008);
  auto mesh = tetMeshBox({10, 2, 2}, size);
  ASSERT_TRUE(mesh.ok());
  const FemMaterial mat{.youngsModulus = 2e4, .poissonRatio = 0.0, .density = 1000};
  const FemSolverOptions opt{.tolerance = 1e-10, .maxIterations = 2000};
  auto body = FemBody::create(*mesh, mat, {.alpha = 150.0, .beta = 0.0}, opt);
  auto cutter = TetCutter::create(*mesh);
  ASSERT_TRUE(body.ok() && cutter.ok());
  body->fixNodesWhere([](const Vec3& p) { return p.x() < 1e-9; });
  const double strength = 1500.0, area = size.y() * size.z(), critical = strength * area;
  std::vector<double> share(body->nodeCount(), 0.0);  // of the end face's area
  for (const Triangle& t : body->surfaceTriangles()) {
    const Vec3 &a = body->restPositions()[t[0]], &b = body->restPositions()[t[1]],
               &c = body->restPositions()[t[2]];
    if (a.x() > size.x() - 1e-9 && b.x() > size.x() - 1e-9 && c.x() > size.x() - 1e-9)
      for (const std::uint32_t v : t) share[v] += (b - a).cross(c - a).norm() / 2 / 3 / area;
  }
  auto load = [&](double f) {
    for (std::size_t i = 0; i < share.size(); ++i)
      if (share[i] > 0) body->setExternalForce(i, Vec3(f * share[i], 0, 0));
  };
  double tornAt = 0.0;
  for (int k = 0; k <= 40 && tornAt == 0.0; ++k) {
    const double f = (0.98 + 0.005 * k) * critical;
    load(f);
    for (int i = 0; i < 300; ++i) ASSERT_TRUE(body->step(0.01).ok());
    // The stress is the analytic F/A in every element.
    for (std::size_t e = 0; e < body->tetCount(); ++e) {
      const Mat3 sigma = body->elementStress(e);
      ASSERT_NEAR(sigma(0, 0), f / area, 1e-6 * f / area) << "element " << e;
      ASSERT_NEAR(sigma.norm(), std::abs(sigma(0, 0)), 1e-6 * f / area) << "element " << e;
    }
    if (!tensileTears(*body, *cutter, strength).empty()) tornAt = f;
  }
  ASSERT_GT(tornAt, 0.0);
  EXPECT_GE(tornAt, critical);
  EXPECT_LE(tornAt, 1.02 * critical);
  EXPECT_NEAR(tornAt, critical, 0.005 * critical);  // the load's step
  // Held at that load, the crack grows from the first tear across the
  // section until the end comes off in one piece and nothing tears any more.
  std::vector<std::uint32_t> pieceOf;
  int updates = 0;
  int quiet = 0;  // steps without a tear
  for (int i = 0; i < 400 && quiet < 20; ++i) {
    const auto tears = tensileTears(*body, *cutter, strength);
    quiet = tears.empty() ? quiet + 1 : 0;
    if (!tears.empty()) {
      auto up = cutter->tear(tears, body->positions());
      ASSERT_TRUE(up.ok());
      if (!up->changedElements.empty()) {
        ASSERT_TRUE(body->applyCut(*cutter, *up).ok());
        ++updates;
      }
    }
    ASSERT_TRUE(body->step(0.01).ok());
  }
  ASSERT_EQ(cutter->pieces(pieceOf), 2u) << updates << " updates";
  // The crack is a full separation: its area (half the cut surface's
  // growth over the bar's) at least the section's; how far it tilts from
  // the section (the principal directions at a coarse crack tip) is
  // printed.
  const CutSurface s = cutter->surface();
  std::vector<Vec3> at;
  s.evaluate(cutter->restPositions(), at);
  double surfaceArea = 0.0;
  for (const Triangle& t : s.triangles)
    surfaceArea += (at[t[1]] - at[t[0]]).cross(at[t[2]] - at[t[0]]).norm() / 2;
  const double barArea = 2 * (size.x() * size.y() + size.y() * size.z() + size.z() * size.x());
  const double crack = (surfaceArea - barArea) / 2;
  EXPECT_GE(crack, area * (1 - 1e-9));
  std::printf("crack area / section = %.3f after %d updates\n", crack / area, updates);
  // The piece that came off takes the load with it: the clamped piece,
  // unloaded, relaxes (its stress falls to nothing), the other accelerates
  // along the pull.
  for (int i = 0; i < 50; ++i) ASSERT_TRUE(body->step(0.01).ok());
  const std::uint32_t clamped = pieceOf[0];  // element 0 touches x = 0
  double worst = 0.0;
  for (std::size_t e = 0; e < body->tetCount(); ++e)
    if (pieceOf[e] == clamped) worst = std::max(worst, body->elementStress(e).norm());
  EXPECT_LT(worst, 0.01 * strength);
  double vx = 0.0;
  int n = 0;
  for (std::size_t i = 0; i < share.size(); ++i)
    if (share[i] > 0) vx += body->velocities()[i].x(), ++n;
  EXPECT_GT(vx / n, 0.0);
}

TEST(FemCut, AScalpelFeltAt1kHzCutsTheTissueItsFrontSweeps) {
  // A scalpel drawn at 20 mm/s across a 30 × 20 × 10 mm block clamped at
  // its bottom, its edge 6 mm into the tissue: the hand feels the tissue's
  // toughness times the engaged length (BladeResistance at 1 kHz), and the
  // front's path, every 10 ms, is the sweep that cuts the FEM body.
  const Vec3 size(0.030, 0.020, 0.010);
  auto mesh = tetMeshBox({12, 8, 4}, size);
  ASSERT_TRUE(mesh.ok());
  auto body = FemBody::create(*mesh, {.youngsModulus = 2e4, .poissonRatio = 0.45, .density = 1000},
                              {.alpha = 5.0, .beta = 0.005});
  auto cutter = TetCutter::create(*mesh);
  auto blade = BladeResistance::create({.toughness = 400.0, .stiffness = 1500.0});
  ASSERT_TRUE(body.ok() && cutter.ok() && blade.ok());
  body->fixNodesWhere([](const Vec3& p) { return p.z() < 1e-9; });
  const double depth = 0.006, y = 0.0101, speed = 0.020;
  const Vec3 u = Vec3::UnitX();
  blade->reset(Vec3(-0.003, y, size.z() - depth));
  Vec3 lastFront = blade->front();
  double felt = 0.0, firstIn = 1.0, lastIn = 0.0;
  int cuttingTicks = 0;
  Mesh surface;
  body->surfaceMesh(surface);
  const Vec3 edge(0, 0, depth + 0.004);  // from the tip up, out of the tissue
  for (int ms = 1; ms <= 1800; ++ms) {
    const Vec3 tip(-0.003 + speed * ms * 1e-3, y, size.z() - depth);
    // Engaged: the edge inside the tissue's boundary (its uncut surface at
    // the last physics step): the depth wherever the tip is under the top.
    const double w = engagedLength(tip, tip + edge, surface);
    if (tip.x() > 1e-4 && tip.x() < size.x() - 1e-4) {
      ASSERT_NEAR(w, depth, 1e-12) << ms;
    } else if (tip.x() < -1e-4 || tip.x() > size.x() + 1e-4) {
      ASSERT_EQ(w, 0.0) << ms;
    }
    if (w > 0.0) firstIn = std::min(firstIn, tip.x()), lastIn = tip.x();
    const Vec3 f = blade->tick(tip, u, w);
    if (blade->cutting()) felt += f.x(), ++cuttingTicks;
    if (ms % 10 == 0) {
      const Vec3 front = blade->front();
      const Vec3 up(0, 0, depth + 0.002);
      auto cut = cutter->cut(bladeSweep(lastFront, lastFront + up, front, front + up), body->positions());
      ASSERT_TRUE(cut.ok());
      if (!cut->changedElements.empty()) {
        ASSERT_TRUE(body->applyCut(*cutter, *cut).ok());
      }
      ASSERT_TRUE(body->step(0.01).ok());
      body->surfaceMesh(surface);
      lastFront = front;
    }
  }
  ASSERT_GT(cuttingTicks, 1000);
  EXPECT_NEAR(felt / cuttingTicks, -400.0 * depth, 1e-9);  // J·w = 2.4 N
  // The cut: the model's area is w × the front's advance, from where the
  // edge entered to J·w/k behind where it left (the tissue still held it
  // there: the last 1.6 mm stays uncut, a slit, not a cut through); the
  // mesh's crack (half the growth of its surface) is that area less the
  // strip of elements the edge only partly went through (≤ one cell,
  // 2.5 mm, along its bottom and at its end) and plus nothing.
  const CutSurface s = cutter->surface();
  std::vector<Vec3> at;
  s.evaluate(cutter->restPositions(), at);
  double surfaceArea = 0.0;
  for (const Triangle& t : s.triangles)
    surfaceArea += (at[t[1]] - at[t[0]]).cross(at[t[2]] - at[t[0]]).norm() / 2;
  const double boxArea = 2 * (size.x() * size.y() + size.y() * size.z() + size.z() * size.x());
  const double crack = (surfaceArea - boxArea) / 2;
  const double modelled = blade->cutArea();
  // (The front starts at the last tick outside, one 20 µm tick before the first inside.)
  EXPECT_NEAR(modelled, depth * (lastIn - 400.0 * depth / 1500.0 - (firstIn - speed * 1e-3)), 1e-12);
  EXPECT_LE(crack, modelled * (1 + 1e-9));
  EXPECT_GE(crack, modelled - (size.x() + depth) * 0.0025);
  std::printf("scalpel: crack %.4g m² of the modelled %.4g\n", crack, modelled);
  // The block is slit, not cut in two.
  std::vector<std::uint32_t> pieceOf;
  EXPECT_EQ(cutter->pieces(pieceOf), 1u);
}

TEST(FemCut, AnUpdateThatDoesNotFitIsRefused) {
  auto mesh = tetMeshBox({4, 2, 2}, Vec3(0.02, 0.01, 0.01));
  ASSERT_TRUE(mesh.ok());
  auto body = FemBody::create(*mesh, {});
  auto cutter = TetCutter::create(*mesh);
  ASSERT_TRUE(body.ok() && cutter.ok());
  auto up = cutter->cut(crossCut(0.0111, 0.01, 0.01), body->positions());
  ASSERT_TRUE(up.ok());
  ASSERT_FALSE(up->newNodes.empty());
  // Skipping the new nodes: refused, the body unchanged.
  CutUpdate partial = *up;
  partial.newNodes.pop_back();
  auto r = body->applyCut(*cutter, partial);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message().find("apply every update"), std::string::npos);
  EXPECT_EQ(body->nodeCount(), mesh->nodeCount());
  // A body of another mesh.
  auto other = FemBody::create(*tetMeshBox({8, 4, 4}, Vec3(0.02, 0.01, 0.01)), {});
  ASSERT_TRUE(other.ok());
  EXPECT_FALSE(other->applyCut(*cutter, *up).ok());
  ASSERT_TRUE(body->applyCut(*cutter, *up).ok());
  EXPECT_EQ(body->nodeCount(), cutter->nodeCount());
}

}  // namespace
}  // namespace dm
