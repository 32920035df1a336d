// Tests of dm/physics/mass_spring.hpp against analytic viscoelastic
// solutions (damped oscillator, Maxwell stress relaxation and creep,
// Kelvin–Voigt creep), static equilibrium, energy behaviour of the
// integrators, the implicit step against a dense solve of its system (its
// solution and the true residual it stops at), the same bits from every
// SIMD version of the step, exact element counts of the builders and input
// validation.
#include <dm/physics/mass_spring.hpp>

#include <dm/core/host_cpu.hpp>

#include <Eigen/Eigenvalues>
#include <gtest/gtest.h>

#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <iterator>
#include <numbers>
#include <random>
#include <string>
#include <vector>

namespace {

using dm::MassSpringBody;
using dm::SpringLayout;
using dm::SpringMaterial;
using dm::SpringModel;
using dm::Vec3;

enum class Path { Symplectic, Implicit };

void step(MassSpringBody& body, Path path, double h) {
  if (path == Path::Symplectic) {
    ASSERT_TRUE(body.stepSymplectic(h).ok());
  } else {
    auto r = body.stepImplicit(h);
    ASSERT_TRUE(r.ok()) << r.error().message();
    ASSERT_TRUE(r->converged) << r->relativeResidual;
  }
}

// Particle 0 pinned at the origin, particle 1 of mass m at (L0 + x0, 0, 0),
// one element of rest length L0.
MassSpringBody twoNode(double m, const SpringMaterial& mat, double restLength, double x0) {
  MassSpringBody body;
  EXPECT_TRUE(body.addParticle({0, 0, 0}, 1.0, true).ok());
  EXPECT_TRUE(body.addParticle({restLength + x0, 0, 0}, m).ok());
  auto e = body.addElement(0, 1, mat, restLength);
  EXPECT_TRUE(e.ok()) << e.error().message();
  return body;
}

double totalEnergy(const MassSpringBody& b) {
  return b.kineticEnergy() + b.elasticEnergy() + b.gravitationalEnergy();
}

// Upward zero crossings (linear interpolation) and peak values of a sampled
// signal.
struct Crossings {
  std::vector<double> times;
  std::vector<double> peaks;
};
Crossings analyse(const std::vector<double>& y, double h) {
  Crossings c;
  for (std::size_t i = 1; i < y.size(); ++i)
    if (y[i - 1] < 0 && y[i] >= 0) c.times.push_back(h * (double(i - 1) + y[i - 1] / (y[i - 1] - y[i])));
  for (std::size_t i = 1; i + 1 < y.size(); ++i)
    if (y[i] > y[i - 1] && y[i] >= y[i + 1] && y[i] > 0) {
      // Parabola through the three samples.
      const double a = 0.5 * (y[i - 1] + y[i + 1]) - y[i], b = 0.5 * (y[i + 1] - y[i - 1]);
      c.peaks.push_back(y[i] - b * b / (4 * a));
    }
  return c;
}

TEST(MassSpring, KelvinVoigtOscillatesAtNaturalFrequencyAndDecaysAtAnalyticRate) {
  const double m = 1.0, k = 100.0, c = 0.4, L0 = 0.5, x0 = 0.01, h = 1e-4;
  const double w0 = std::sqrt(k / m), zeta = c / (2 * std::sqrt(k * m));
  const double wd = w0 * std::sqrt(1 - zeta * zeta);
  for (Path path : {Path::Symplectic, Path::Implicit}) {
    MassSpringBody body = twoNode(m, {.stiffness = k, .damping = c}, L0, x0);
    std::vector<double> disp;
    for (int s = 0; s < 30000; ++s) {
      step(body, path, h);
      disp.push_back(body.position(1).x() - L0);
    }
    const Crossings cr = analyse(disp, h);
    ASSERT_GE(cr.times.size(), 4u);
    const double period = (cr.times.back() - cr.times.front()) / double(cr.times.size() - 1);
    EXPECT_NEAR(period, 2 * std::numbers::pi / wd, 1e-3 * period);
    ASSERT_GE(cr.peaks.size(), 4u);
    // Amplitude ratio per period: exp(−ζ ω0 T). Backward Euler adds
    // numerical damping ≈ h ω0²/2 per unit time (here 0.005 against ζω0 = 0.2).
    const double expectedRate = zeta * w0 + (path == Path::Implicit ? h * w0 * w0 / 2 : 0.0);
    const double rate =
        -std::log(cr.peaks.back() / cr.peaks.front()) / (period * double(cr.peaks.size() - 1));
    EXPECT_NEAR(rate, expectedRate, 0.01 * expectedRate)
        << (path == Path::Implicit ? "implicit" : "symplectic");
  }
}

TEST(MassSpring, MaxwellHeldStretchRelaxesExponentially) {
  const double k = 200.0, c = 20.0, L0 = 1.0, e0 = 0.05, tau = c / k;
  for (Path path : {Path::Symplectic, Path::Implicit}) {
    const double h = path == Path::Symplectic ? 1e-3 : 1e-4;
    MassSpringBody body = twoNode(1.0, {.stiffness = k, .damping = c, .model = SpringModel::Maxwell}, L0, e0);
    body.setPinned(1, true);  // held stretch
    EXPECT_NEAR(body.elementTension(0), k * e0, 1e-12);
    const int steps = int(std::lround(3 * tau / h));
    for (int s = 1; s <= steps; ++s) {
      step(body, path, h);
      if (s % int(std::lround(tau / h)) == 0) {
        const double t = s * h;
        const double expected = k * e0 * std::exp(-t / tau);
        // Exact exponential (explicit) vs backward Euler (1 + hk/c)^(−n) (implicit).
        const double tol = path == Path::Symplectic ? 1e-9 * k * e0 : 2e-3 * expected;
        EXPECT_NEAR(body.elementTension(0), expected, tol) << "t = " << t;
      }
    }
    EXPECT_NEAR(body.position(1).x(), L0 + e0, 0.0);  // pinned: did not move
    // Relaxation is in the damper: the spring part is what is left.
    EXPECT_NEAR(body.element(0).damperExtension, e0 * (1 - std::exp(-3.0)), 2e-3 * e0);
  }
}

TEST(MassSpring, UnderConstantLoadMaxwellFlowsLinearlyAndKelvinVoigtCreepsToFOverK) {
  const double m = 0.01, k = 100.0, c = 5.0, L0 = 1.0, F = 2.0;
  for (Path path : {Path::Symplectic, Path::Implicit}) {
    const double h = path == Path::Symplectic ? 1e-4 : 1e-3;
    const int steps = int(std::lround(1.0 / h));
    // Kelvin–Voigt: e(t) ≈ F/k (1 − exp(−t k/c)) (massless limit), e(∞) = F/k.
    MassSpringBody kv = twoNode(m, {.stiffness = k, .damping = c}, L0, 0.0);
    kv.setExternalForce(1, {F, 0, 0});
    for (int s = 1; s <= steps; ++s) {
      step(kv, path, h);
      if (s == int(std::lround(c / k / h))) {
        EXPECT_NEAR(kv.position(1).x() - L0, F / k * (1 - std::exp(-1.0)), 0.01 * F / k);
      }
    }
    EXPECT_NEAR(kv.position(1).x() - L0, F / k, 1e-6 * F / k);
    EXPECT_NEAR(kv.velocity(1).norm(), 0.0, 1e-6);

    // Maxwell: the spring holds F/k, the damper flows at F/c without bound.
    MassSpringBody mx = twoNode(m, {.stiffness = k, .damping = c, .model = SpringModel::Maxwell}, L0, 0.0);
    mx.setExternalForce(1, {F, 0, 0});
    double xHalf = 0;
    for (int s = 1; s <= steps; ++s) {
      step(mx, path, h);
      if (s == steps / 2) xHalf = mx.position(1).x();
    }
    EXPECT_NEAR(mx.velocity(1).x(), F / c, 0.01 * F / c);
    EXPECT_NEAR(mx.position(1).x() - xHalf, 0.5 * F / c, 0.01 * 0.5 * F / c);
    EXPECT_NEAR(mx.elementTension(0), F, 0.01 * F);
    const dm::SpringElement el = mx.element(0);
    EXPECT_NEAR(mx.position(1).x() - L0 - el.damperExtension, F / k, 0.01 * F / k);
  }
}

// An 8 × 8 sheet in the x–z plane hanging from its two top corners.
MassSpringBody hangingSheet() {
  auto sheet = MassSpringBody::makeSheet({.nx = 8,
                                          .ny = 8,
                                          .width = 0.7,
                                          .height = 0.7,
                                          .uAxis = Vec3::UnitX(),
                                          .vAxis = -Vec3::UnitZ(),
                                          .mass = 0.64,
                                          .structural = {true, 200, 0.5, SpringModel::KelvinVoigt},
                                          .shear = {true, 100, 0.5, SpringModel::KelvinVoigt},
                                          .bend = {true, 20, 0.5, SpringModel::KelvinVoigt}});
  EXPECT_TRUE(sheet.ok());
  sheet->setPinned(0, true);
  sheet->setPinned(7, true);
  sheet->setGravity({0, 0, -9.81});
  // Drag damps the slow swaying modes that the element dampers barely reach.
  EXPECT_TRUE(sheet->setDrag(5.0).ok());
  return std::move(sheet).value();
}

TEST(MassSpring, HangingSheetReachesEquilibriumWherePinsCarryTheWeight) {
  MassSpringBody implicitSheet = hangingSheet(), explicitSheet = hangingSheet();
  for (int s = 0; s < 1000; ++s) step(implicitSheet, Path::Implicit, 1e-2);
  for (int s = 0; s < 20000; ++s) step(explicitSheet, Path::Symplectic, 5e-4);

  for (const MassSpringBody* sheet : {&implicitSheet, &explicitSheet}) {
    double freeMass = 0, vmax = 0;
    for (std::size_t i = 0; i < sheet->particleCount(); ++i) {
      if (!sheet->pinned(i)) freeMass += sheet->mass(i);
      vmax = std::max(vmax, sheet->velocity(i).norm());
    }
    EXPECT_LT(vmax, 1e-6);
    // The elements pull the pins down with the weight of the free nodes,
    // shared equally by symmetry.
    const Vec3 load = sheet->elementForceOn(0) + sheet->elementForceOn(7);
    const Vec3 weight = freeMass * sheet->gravity();
    EXPECT_NEAR((load - weight).norm(), 0.0, 1e-5 * weight.norm()) << load.transpose();
    EXPECT_NEAR(sheet->elementForceOn(0).z(), sheet->elementForceOn(7).z(), 1e-5 * weight.norm());
    // And the sheet did sag: the bottom row hangs below its rest height.
    EXPECT_LT(sheet->position(60).z(), -0.7);
  }
  // Both integrators find the same equilibrium.
  for (std::size_t i = 0; i < implicitSheet.particleCount(); ++i)
    EXPECT_LT((implicitSheet.position(i) - explicitSheet.position(i)).norm(), 1e-5) << "node " << i;
}

MassSpringBody jiggledSheet(double damping, SpringModel model) {
  auto sheet = MassSpringBody::makeSheet({.nx = 5,
                                          .ny = 5,
                                          .width = 0.4,
                                          .height = 0.4,
                                          .mass = 0.25,
                                          .structural = {true, 50, damping, model},
                                          .shear = {true, 20, damping, model},
                                          .bend = {true, 5, damping, model}});
  EXPECT_TRUE(sheet.ok());
  std::mt19937 rng(7);
  std::normal_distribution<double> g(0.0, 0.3);
  for (std::size_t i = 0; i < sheet->particleCount(); ++i) sheet->setVelocity(i, {g(rng), g(rng), g(rng)});
  sheet->setPinned(0, true);
  sheet->setGravity({0, 0, -9.81});
  return std::move(sheet).value();
}

TEST(MassSpring, SymplecticEulerConservesEnergyWithoutDampingAndLosesItWithDamping) {
  // Gravity swings the sheet about its pin, so the energy exchanged between
  // kinetic and potential (the scale of the integrator's error) is the
  // largest kinetic energy seen, not the initial one.
  MassSpringBody body = jiggledSheet(0.0, SpringModel::KelvinVoigt);
  const double e0 = totalEnergy(body), scale = body.kineticEnergy();
  const int steps = 100000, window = steps / 10;
  double maxDev = 0, first = 0, last = 0, exchanged = 0;
  for (int s = 0; s < steps; ++s) {
    ASSERT_TRUE(body.stepSymplectic(1e-4).ok());
    const double e = totalEnergy(body);
    maxDev = std::max(maxDev, std::abs(e - e0));
    exchanged = std::max(exchanged, body.kineticEnergy());
    if (s < window) first += e / window;
    if (s >= steps - window) last += e / window;
  }
  EXPECT_GT(exchanged, 10 * scale);
  EXPECT_LT(maxDev, 0.01 * exchanged);                  // bounded oscillation…
  EXPECT_LT(std::abs(last - first), 1e-3 * exchanged);  // …and no drift over 10 s

  for (SpringModel model : {SpringModel::KelvinVoigt, SpringModel::Maxwell}) {
    for (Path path : {Path::Symplectic, Path::Implicit}) {
      MassSpringBody damped = jiggledSheet(0.05, model);
      const double d0 = totalEnergy(damped);
      double prev = d0, maxKinetic = 0;
      for (int s = 0; s < 2000; ++s) {
        step(damped, path, 1e-3);
        const double e = totalEnergy(damped);
        maxKinetic = std::max(maxKinetic, damped.kineticEnergy());
        EXPECT_LE(e, d0 + 0.01 * maxKinetic);
        if (path == Path::Implicit && model == SpringModel::KelvinVoigt) {
          EXPECT_LE(e, prev + 1e-9 * scale);
        }
        prev = e;
      }
      EXPECT_LT(totalEnergy(damped), d0 - 0.3 * scale) << dm::toString(model);
    }
  }
}

TEST(MassSpring, ImplicitStaysStableAtAStepWhereExplicitExplodes) {
  auto make = [] {
    auto sheet = MassSpringBody::makeSheet({.nx = 10,
                                            .ny = 10,
                                            .width = 0.1,
                                            .height = 0.1,
                                            .vAxis = -Vec3::UnitZ(),
                                            .mass = 0.1,
                                            .structural = {true, 1e4, 1.0, SpringModel::KelvinVoigt},
                                            .shear = {true, 5e3, 1.0, SpringModel::KelvinVoigt},
                                            .bend = {true, 1e3, 1.0, SpringModel::Maxwell}});
    EXPECT_TRUE(sheet.ok());
    sheet->setPinned(0, true);
    sheet->setPinned(9, true);
    sheet->setGravity({0, 0, -9.81});
    return std::move(sheet).value();
  };
  const double h = 1e-2;  // h·sqrt(k/m) ≈ 30, far beyond explicit stability (2)
  MassSpringBody expl = make(), impl = make();
  for (int s = 0; s < 200; ++s) {
    ASSERT_TRUE(expl.stepSymplectic(h).ok());
    step(impl, Path::Implicit, h);
  }
  const double explSize = expl.positions().allFinite() ? expl.positions().cwiseAbs().maxCoeff() : INFINITY;
  EXPECT_GT(explSize, 100.0);
  ASSERT_TRUE(impl.positions().allFinite());
  EXPECT_LT(impl.positions().cwiseAbs().maxCoeff(), 0.2);
  // Energy cannot exceed what gravity released: KE + elastic ≤ −ΔU_gravity.
  const MassSpringBody start = make();
  EXPECT_LT(impl.kineticEnergy() + impl.elasticEnergy(),
            start.gravitationalEnergy() - impl.gravitationalEnergy() + 1e-12);
}

TEST(MassSpring, SheetBuilderCountsElementsExactly) {
  for (auto [nx, ny] : {std::pair{7, 7}, std::pair{5, 3}, std::pair{2, 2}, std::pair{64, 33}}) {
    auto s = MassSpringBody::makeSheet({.nx = nx, .ny = ny});
    ASSERT_TRUE(s.ok());
    const std::size_t X = std::size_t(nx), Y = std::size_t(ny);
    EXPECT_EQ(s->particleCount(), X * Y);
    EXPECT_EQ(s->elementCount(SpringLayout::Structural), (X - 1) * Y + X * (Y - 1));
    EXPECT_EQ(s->elementCount(SpringLayout::Shear), 2 * (X - 1) * (Y - 1));
    EXPECT_EQ(s->elementCount(SpringLayout::Bend), (X - 2) * Y + X * (Y - 2));
    EXPECT_EQ(s->elementCount(), s->elementCount(SpringLayout::Structural) +
                                     s->elementCount(SpringLayout::Shear) +
                                     s->elementCount(SpringLayout::Bend));
    EXPECT_NEAR(s->totalMass(), 1.0, 1e-12);
  }
  auto square = MassSpringBody::makeSheet({.nx = 9, .ny = 9});
  ASSERT_TRUE(square.ok());
  EXPECT_EQ(square->elementCount(SpringLayout::Structural), 2u * 9 * 8);
  // Layout geometry: structural at the grid spacing, shear √2 times it, bend twice it.
  for (std::size_t e = 0; e < square->elementCount(); ++e) {
    const dm::SpringElement el = square->element(e);
    const double spacing = 1.0 / 8;
    const double expected = el.layout == SpringLayout::Structural ? spacing
                            : el.layout == SpringLayout::Shear    ? std::sqrt(2.0) * spacing
                                                                  : 2 * spacing;
    EXPECT_NEAR(el.restLength, expected, 1e-12);
  }
  auto noShear = MassSpringBody::makeSheet({.nx = 5, .ny = 3, .shear = {.enabled = false}});
  ASSERT_TRUE(noShear.ok());
  EXPECT_EQ(noShear->elementCount(SpringLayout::Shear), 0u);
  EXPECT_EQ(noShear->elementCount(), 22u + 14u);
}

dm::Mesh octahedron() {
  dm::Mesh m;
  m.positions = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
  m.triangles = {{0, 2, 4}, {2, 1, 4}, {1, 3, 4}, {3, 0, 4}, {2, 0, 5}, {1, 2, 5}, {3, 1, 5}, {0, 3, 5}};
  return m;
}

TEST(MassSpring, FromMeshUsesEdgesAsStructuralAndOppositeVerticesAsBend) {
  auto oct = MassSpringBody::fromMesh(octahedron(), {.mass = 0.6});
  ASSERT_TRUE(oct.ok()) << oct.error().message();
  EXPECT_EQ(oct->particleCount(), 6u);
  EXPECT_EQ(oct->elementCount(SpringLayout::Structural), 12u);
  // Every edge's two opposite vertices are an antipodal pair: 3 distinct pairs.
  ASSERT_EQ(oct->elementCount(SpringLayout::Bend), 3u);
  for (std::size_t e = 0; e < oct->elementCount(); ++e) {
    const dm::SpringElement el = oct->element(e);
    EXPECT_NEAR(el.restLength, el.layout == SpringLayout::Bend ? 2.0 : std::sqrt(2.0), 1e-12);
    if (el.layout == SpringLayout::Bend) {
      EXPECT_NEAR((oct->position(el.i) + oct->position(el.j)).norm(), 0.0, 0.0);
    }
  }
  for (std::size_t i = 0; i < 6; ++i) EXPECT_NEAR(oct->mass(i), 0.1, 1e-12);  // equal lumped areas

  // A quad of two triangles: 5 edges, one bend across the diagonal; the
  // lumped masses follow the areas (corners on the diagonal get 2/6 each).
  dm::Mesh quad;
  quad.positions = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};
  quad.triangles = {{0, 1, 2}, {0, 2, 3}};
  auto q = MassSpringBody::fromMesh(quad, {.mass = 6.0});
  ASSERT_TRUE(q.ok());
  EXPECT_EQ(q->elementCount(SpringLayout::Structural), 5u);
  EXPECT_EQ(q->elementCount(SpringLayout::Bend), 1u);
  EXPECT_NEAR(q->mass(0), 2.0, 1e-12);
  EXPECT_NEAR(q->mass(1), 1.0, 1e-12);

  // A flat membrane from a mesh stays put without loads (rest lengths from the mesh).
  ASSERT_TRUE(q->stepSymplectic(1e-3).ok());
  EXPECT_NEAR((q->position(2) - Vec3(1, 1, 0)).norm(), 0.0, 1e-15);
}

TEST(MassSpring, BadInputIsRejectedWithTheFieldNamed) {
  const auto whereOf = [](const auto& r) { return r.ok() ? std::string("(ok)") : r.error().message(); };
  EXPECT_NE(whereOf(MassSpringBody::makeSheet({.nx = 1})).find("nx"), std::string::npos);
  EXPECT_NE(whereOf(MassSpringBody::makeSheet({.ny = 100000})).find("ny"), std::string::npos);
  EXPECT_NE(whereOf(MassSpringBody::makeSheet({.width = -1})).find("width"), std::string::npos);
  EXPECT_NE(whereOf(MassSpringBody::makeSheet({.mass = NAN})).find("mass"), std::string::npos);
  EXPECT_NE(whereOf(MassSpringBody::makeSheet({.vAxis = Vec3(2, 0, 0)})).find("vAxis"), std::string::npos);
  EXPECT_NE(whereOf(MassSpringBody::makeSheet({.structural = {true, 10, 0, SpringModel::Maxwell}}))
                .find("structural.damping"),
            std::string::npos);
  EXPECT_NE(whereOf(MassSpringBody::makeSheet({.bend = {true, -5, 0, SpringModel::KelvinVoigt}}))
                .find("bend.stiffness"),
            std::string::npos);

  dm::Mesh mesh = octahedron();
  mesh.positions.push_back({5, 5, 5});  // used by no triangle
  EXPECT_NE(whereOf(MassSpringBody::fromMesh(mesh)).find("vertex 6"), std::string::npos);
  mesh = octahedron();
  mesh.triangles[3][1] = 17;
  EXPECT_FALSE(MassSpringBody::fromMesh(mesh).ok());
  EXPECT_NE(whereOf(MassSpringBody::fromMesh(octahedron(), {.mass = 0})).find("mass"), std::string::npos);

  MassSpringBody body;
  EXPECT_FALSE(body.addParticle({0, 0, 0}, 0.0).ok());
  EXPECT_FALSE(body.addParticle({NAN, 0, 0}, 1.0).ok());
  ASSERT_TRUE(body.addParticle({0, 0, 0}, 1.0).ok());
  ASSERT_TRUE(body.addParticle({1, 0, 0}, 1.0).ok());
  EXPECT_FALSE(body.addElement(0, 0, {.stiffness = 1}).ok());
  EXPECT_NE(whereOf(body.addElement(0, 2, {.stiffness = 1})).find("j"), std::string::npos);
  EXPECT_NE(whereOf(body.addElement(0, 1, {.stiffness = 1, .damping = -1})).find("damping"),
            std::string::npos);
  auto e = body.addElement(0, 1, {.stiffness = 1});
  ASSERT_TRUE(e.ok());
  EXPECT_NEAR(body.element(*e).restLength, 1.0, 0.0);
  EXPECT_NE(whereOf(body.setDrag(-1.0)).find("rate"), std::string::npos);
  EXPECT_FALSE(body.stepSymplectic(0.0).ok());
  EXPECT_FALSE(body.stepImplicit(-1.0).ok());
  EXPECT_FALSE(body.stepImplicit(NAN).ok());
  EXPECT_EQ(body.position(1), Vec3(1, 0, 0));  // a rejected step changes nothing
}

// The system A Δv = b of one implicit step of h from the body's state, as
// the header describes it, assembled densely and restricted to the free
// particles' coordinates (freeDofs: their indices in the 3n vector). With
// `asStepped`, each element block a I + b n nᵀ has a, b and n rounded to
// single precision, as the step keeps them: then A is the step's own matrix.
struct DenseSystem {
  Eigen::MatrixXd A;
  Eigen::VectorXd b;
  std::vector<Eigen::Index> freeDofs;
};
DenseSystem denseBackwardEuler(const MassSpringBody& body, double h, const std::vector<Vec3>& fext,
                               bool asStepped = false) {
  const Eigen::Index n = Eigen::Index(body.particleCount()), dofs = 3 * n;
  Eigen::MatrixXd A = Eigen::MatrixXd::Zero(dofs, dofs);
  Eigen::VectorXd b = Eigen::VectorXd::Zero(dofs);
  for (Eigen::Index i = 0; i < n; ++i) {
    const double m = body.mass(std::size_t(i));
    A.block<3, 3>(3 * i, 3 * i) += (1 + h * body.drag()) * m * Eigen::Matrix3d::Identity();
    b.segment<3>(3 * i) +=
        h * (m * (body.gravity() - body.drag() * body.velocity(std::size_t(i))) + fext[std::size_t(i)]);
  }
  for (std::size_t e = 0; e < body.elementCount(); ++e) {
    const dm::SpringElement el = body.element(e);
    const Vec3 d = body.position(el.j) - body.position(el.i);
    const double len = d.norm();
    const Vec3 nrm = d / len;
    const Vec3 w = body.velocity(el.j) - body.velocity(el.i);
    const double ext = len - el.restLength, rate = nrm.dot(w);
    double kAxial = el.stiffness, cAxial = el.damping, spring = el.stiffness * ext,
           tension = spring + el.damping * rate;
    if (el.model == SpringModel::Maxwell) {
      kAxial = el.stiffness / (1 + h * el.stiffness / el.damping);
      spring = tension = kAxial * (ext - el.damperExtension);
      cAxial = 0;
    }
    const double geo = spring > 0 ? spring / len : 0.0;
    double iso = h * h * geo, axial = h * cAxial + h * h * (kAxial - geo);
    Vec3 dir = nrm;
    if (asStepped) {
      iso = double(float(iso)), axial = double(float(axial));
      dir = nrm.cast<float>().cast<double>();
    }
    const Eigen::Matrix3d B = axial * dir * dir.transpose() + iso * Eigen::Matrix3d::Identity();
    const Vec3 onI = (h * tension + h * h * (kAxial - geo) * rate) * nrm + h * h * geo * w;
    const Eigen::Index I = 3 * Eigen::Index(el.i), J = 3 * Eigen::Index(el.j);
    A.block<3, 3>(I, I) += B, A.block<3, 3>(J, J) += B, A.block<3, 3>(I, J) -= B, A.block<3, 3>(J, I) -= B;
    b.segment<3>(I) += onI, b.segment<3>(J) -= onI;
  }
  DenseSystem sys;
  for (Eigen::Index i = 0; i < n; ++i)
    if (!body.pinned(std::size_t(i)))
      for (Eigen::Index c = 0; c < 3; ++c) sys.freeDofs.push_back(3 * i + c);
  const Eigen::Index f = Eigen::Index(sys.freeDofs.size());
  sys.A.resize(f, f);
  sys.b.resize(f);
  for (Eigen::Index r = 0; r < f; ++r) {
    sys.b[r] = b[sys.freeDofs[std::size_t(r)]];
    for (Eigen::Index c = 0; c < f; ++c)
      sys.A(r, c) = A(sys.freeDofs[std::size_t(r)], sys.freeDofs[std::size_t(c)]);
  }
  return sys;
}

// An irregular body: uneven element counts per particle, a duplicated
// element, Maxwell and Kelvin–Voigt elements, some compressed, pinned
// particles, drag and external forces (fext, which it fills).
MassSpringBody irregularBody(std::vector<Vec3>& fext) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  MassSpringBody body;
  const int n = 13;
  fext.clear();
  for (int i = 0; i < n; ++i) {
    EXPECT_TRUE(
        body.addParticle({u(rng), u(rng), u(rng)}, 0.05 + 0.02 * (u(rng) + 1), i == 3 || i == 8).ok());
    body.setVelocity(std::size_t(i), {0.3 * u(rng), 0.3 * u(rng), 0.3 * u(rng)});
    fext.push_back({0.1 * u(rng), 0.1 * u(rng), 0.1 * u(rng)});
    body.setExternalForce(std::size_t(i), fext.back());
  }
  std::uniform_int_distribution<int> pick(0, n - 1);
  for (int e = 0; e < 40; ++e) {
    const int i = pick(rng), j = pick(rng);
    if (i == j) continue;
    const SpringModel model = e % 3 == 0 ? SpringModel::Maxwell : SpringModel::KelvinVoigt;
    const double rest =
        (body.position(std::size_t(j)) - body.position(std::size_t(i))).norm() * (1 + 0.2 * u(rng));
    EXPECT_TRUE(body.addElement(std::uint32_t(i), std::uint32_t(j),
                                {true, 20 + 10 * u(rng), 0.5 + 0.4 * u(rng), model}, rest)
                    .ok());
    if (e == 7) {  // the same pair twice
      EXPECT_TRUE(body.addElement(std::uint32_t(j), std::uint32_t(i), {true, 15, 0.2, model}, rest).ok());
    }
  }
  body.setGravity({0, 0, -9.81});
  EXPECT_TRUE(body.setDrag(0.7).ok());
  return body;
}

// The implicit step against the system assembled densely from the model in
// the header and solved directly, on the irregular body.
TEST(MassSpring, ImplicitStepSolvesTheBackwardEulerSystem) {
  std::vector<Vec3> fext;
  MassSpringBody body = irregularBody(fext);
  body.setSolverOptions({.cgTolerance = 1e-12, .cgMaxIterations = 500});
  // A few steps first, so the Maxwell dampers carry state.
  for (int s = 0; s < 3; ++s) step(body, Path::Implicit, 5e-3);

  const double h = 2e-2;
  const DenseSystem sys = denseBackwardEuler(body, h, fext);
  const Eigen::MatrixXd& Af = sys.A;
  const Eigen::VectorXd& bf = sys.b;
  const std::vector<Eigen::Index>& freeDofs = sys.freeDofs;
  const Eigen::Index f = Eigen::Index(freeDofs.size());
  const Eigen::VectorXd dvFree = Af.ldlt().solve(bf);
  Eigen::VectorXd expected = body.velocities();
  for (Eigen::Index r = 0; r < f; ++r) expected[freeDofs[std::size_t(r)]] += dvFree[r];

  auto report = body.stepImplicit(h);
  ASSERT_TRUE(report.ok()) << report.error().message();
  EXPECT_TRUE(report->converged);
  // The element blocks are applied in single precision: agreement to ~1e-6
  // of the velocity change.
  EXPECT_LT((body.velocities() - expected).cwiseAbs().maxCoeff(),
            1e-6 * dvFree.cwiseAbs().maxCoeff() + 1e-12);
}

// CG stops on its recursively updated residual and skips the sweep that
// confirms the true residual when its rounding-error bound shows it needless;
// either way the true residual ‖b − A Δv‖ of the step it takes must be
// within the tolerance. Checked against the dense system on the irregular
// body and on a sheet, from loose to tight tolerances, soft and stiff.
TEST(MassSpring, ImplicitStepMeetsItsToleranceOnTheTrueResidual) {
  const auto check = [](MassSpringBody& body, const std::vector<Vec3>& fext, double h, double tol) {
    SCOPED_TRACE(::testing::Message() << "h " << h << " tolerance " << tol);
    body.setSolverOptions({.cgTolerance = tol, .cgMaxIterations = 2000});
    for (int s = 0; s < 2; ++s) step(body, Path::Implicit, h);  // a warm start, damper states
    const DenseSystem sys = denseBackwardEuler(body, h, fext, /*asStepped=*/true);
    const dm::VecX before = body.velocities();
    auto report = body.stepImplicit(h);
    ASSERT_TRUE(report.ok()) << report.error().message();
    ASSERT_TRUE(report->converged);
    Eigen::VectorXd dv(Eigen::Index(sys.freeDofs.size()));
    for (std::size_t r = 0; r < sys.freeDofs.size(); ++r)
      dv[Eigen::Index(r)] = body.velocities()[sys.freeDofs[r]] - before[sys.freeDofs[r]];
    // The dense product's own rounding, far below the tolerances checked.
    const double aNorm =
        Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(sys.A).eigenvalues().cwiseAbs().maxCoeff();
    const double rounding = 64 * 0x1p-53 * aNorm * dv.norm();
    ASSERT_LT(rounding, 0.01 * tol * sys.b.norm());
    EXPECT_LE((sys.b - sys.A * dv).norm(), tol * sys.b.norm() + rounding);
    EXPECT_LE(report->relativeResidual, tol);
  };
  for (double tol : {1e-3, 1e-6}) {
    std::vector<Vec3> fext;
    MassSpringBody body = irregularBody(fext);
    check(body, fext, 2e-2, tol);
  }
  for (double k : {50.0, 5e4}) {  // soft: the bound confirms; stiff: ill-conditioned
    for (double tol : {1e-4, 1e-7}) {
      auto sheet = MassSpringBody::makeSheet({.nx = 6,
                                              .ny = 5,
                                              .mass = 0.3,
                                              .structural = {true, k, 0.01 * k, SpringModel::KelvinVoigt},
                                              .shear = {true, 0.5 * k, 0.01 * k, SpringModel::Maxwell},
                                              .bend = {true, 0.1 * k, 0.01 * k, SpringModel::KelvinVoigt}});
      ASSERT_TRUE(sheet.ok()) << sheet.error().message();
      sheet->setPinned(0, true);
      sheet->setGravity({0, 0, -9.81});
      const std::vector<Vec3> fext(sheet->particleCount(), Vec3::Zero());
      check(*sheet, fext, 1e-2, tol);
    }
  }
}

// The implicit step is compiled once per SIMD instruction set and picked at
// run time (dm::simdLevel()); every version must give the same bits. Each
// level's run happens in a child process (DM_SIMD caps the level), which
// writes the state after a few steps for the parent to compare. A level the
// CPU does not have runs as the widest it has.
TEST(MassSpringSimd, ChildStepsAndWritesItsState) {
  const char* out = std::getenv("DM_MASS_SPRING_CHILD_OUT");
  if (!out) GTEST_SKIP() << "runs only as the child of MassSpringSimd.EveryLevelGivesTheSameBits";
  std::vector<Vec3> fext;
  MassSpringBody body = irregularBody(fext);
  body.setSolverOptions({.cgTolerance = 1e-8});
  auto sheet = MassSpringBody::makeSheet({.nx = 17, .ny = 13, .mass = 0.2});
  if (!sheet) std::_Exit(3);
  sheet->setPinned(0, true);
  sheet->setGravity({0, 0, -9.81});
  for (int s = 0; s < 4; ++s)
    if (!body.stepImplicit(1e-2) || !sheet->stepImplicit(2e-2)) std::_Exit(4);
  std::ofstream file(out, std::ios::binary);
  for (const MassSpringBody* b : {&body, &*sheet})
    for (const dm::VecX* v : {&b->positions(), &b->velocities()})
      file.write(reinterpret_cast<const char*>(v->data()), std::streamsize(v->size() * sizeof(double)));
  std::ofstream(std::string(out) + ".level") << dm::toString(dm::simdLevel());
  std::_Exit(file.flush() ? 0 : 5);
}

TEST(MassSpringSimd, EveryLevelGivesTheSameBits) {
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("dm_mass_spring_simd_" + std::to_string(getpid()));
  std::filesystem::create_directories(dir);
  const std::string self = std::filesystem::read_symlink("/proc/self/exe").string();
  std::vector<std::string> states;
  for (const char* level : {"sse2", "avx2", "avx512"}) {
    const std::string file = (dir / level).string();
    std::string outVar = "DM_MASS_SPRING_CHILD_OUT=" + file, simdVar = std::string("DM_SIMD=") + level;
    std::string filter = "--gtest_filter=MassSpringSimd.ChildStepsAndWritesItsState";
    std::vector<char*> env;
    for (char** e = environ; *e; ++e)
      if (std::strncmp(*e, "DM_SIMD=", 8) != 0) env.push_back(*e);
    env.push_back(outVar.data());
    env.push_back(simdVar.data());
    env.push_back(nullptr);
    char* argv[] = {const_cast<char*>(self.c_str()), filter.data(), nullptr};
    pid_t pid = -1;
    ASSERT_EQ(posix_spawn(&pid, self.c_str(), nullptr, nullptr, argv, env.data()), 0);
    int status = 0;
    ASSERT_EQ(waitpid(pid, &status, 0), pid);
    ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << level << ": the child failed";
    std::ifstream in(file, std::ios::binary), ran(file + ".level");
    states.emplace_back(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
    ASSERT_GT(states.back().size(), 1000u);
    std::string ranLevel;
    ran >> ranLevel;
    std::cout << "[ level    ] DM_SIMD=" << level << " ran " << ranLevel << "\n";
  }
  std::filesystem::remove_all(dir);
  EXPECT_TRUE(states[0] == states[1]) << "sse2 and avx2 differ";
  EXPECT_TRUE(states[0] == states[2]) << "sse2 and avx512 differ";
}

// The implicit step keeps per-element data in its workspace, some of it
// cached for the last step size (a Maxwell element's effective stiffness
// k/(1 + h k/c)): a body that steps, gains an element and steps again must
// step bitwise as a body built with that element from the start.
TEST(MassSpring, ImplicitStepAfterAddingAnElementMatchesAFreshBody) {
  const SpringMaterial kv{true, 40, 0.3, SpringModel::KelvinVoigt}, mx{true, 25, 0.4, SpringModel::Maxwell};
  const auto build = [&](bool withMaxwell) {
    MassSpringBody body;
    for (int i = 0; i < 7; ++i)
      EXPECT_TRUE(body.addParticle({0.3 * i, 0.1 * (i % 2), 0.05 * i * i}, 0.02 + 0.01 * i, i == 0).ok());
    for (std::uint32_t i = 0; i + 1 < 7; ++i) EXPECT_TRUE(body.addElement(i, i + 1, kv, 0.25).ok());
    EXPECT_TRUE(body.addElement(1, 4, kv, 0.8).ok());
    if (withMaxwell) {
      EXPECT_TRUE(body.addElement(6, 2, mx, 1.0).ok());
    }
    body.setGravity({0, 0, -9.81});
    return body;
  };
  MassSpringBody grown = build(false), fresh = build(true);
  step(grown, Path::Implicit, 1e-2);  // Kelvin–Voigt only: no state but x and v; fills the workspace
  ASSERT_TRUE(grown.addElement(6, 2, mx, 1.0).ok());
  for (std::size_t i = 0; i < grown.particleCount(); ++i) {
    fresh.setPosition(i, grown.position(i));
    fresh.setVelocity(i, grown.velocity(i));
  }
  for (int s = 0; s < 3; ++s) {
    step(grown, Path::Implicit, 1e-2);  // the step size it has seen
    step(fresh, Path::Implicit, 1e-2);
  }
  EXPECT_TRUE(grown.positions() == fresh.positions());
  EXPECT_TRUE(grown.velocities() == fresh.velocities());
  EXPECT_NE(grown.element(grown.elementCount() - 1).damperExtension, 0.0);  // the Maxwell damper moved
}

TEST(MassSpring, ParallelLoopsGiveBitwiseTheSerialResult) {
  auto make = [](bool parallel) {
    auto sheet = MassSpringBody::makeSheet({.nx = 48, .ny = 48, .mass = 0.4});
    EXPECT_TRUE(sheet.ok());
    sheet->setPinned(0, true);
    sheet->setPinned(47, true);
    sheet->setGravity({0, 0, -9.81});
    sheet->setSolverOptions({.parallel = parallel, .parallelMinParticles = 0});
    return std::move(sheet).value();
  };
  MassSpringBody serial = make(false), parallel = make(true);
  for (MassSpringBody* b : {&serial, &parallel}) {
    for (int s = 0; s < 10; ++s) ASSERT_TRUE(b->stepSymplectic(1e-3).ok());
    for (int s = 0; s < 3; ++s) ASSERT_TRUE(b->stepImplicit(1e-2).ok());
  }
  EXPECT_TRUE(serial.positions() == parallel.positions());
  EXPECT_TRUE(serial.velocities() == parallel.velocities());
  EXPECT_GT((serial.position(48 * 48 - 1) - Vec3(1, 1, 0)).norm(), 1e-3);  // it did move
}

}  // namespace
