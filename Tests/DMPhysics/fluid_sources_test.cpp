// Inlets, suction and the region of interest of the particle fluid
// (dm/physics/fluid_sources.hpp) against what they promise physically: a
// pump delivers its rate and its layers leave a spacing apart along any
// normal; a tool pressing on a cut slows it by the linear law and stops it
// at the vessel's pressure, and a pool over it presses with its hydrostatic
// pressure (the cut lifts the pool to make room; no layer is started on
// top of another particle); a vessel bleeding into a tube stops where the
// pool's pressure balances it (a manometer);
// suction takes its rate, nearest the tip first, and banks nothing while it
// draws air; a jet leaving the region of interest is recycled so that the
// particle count stays within what its residence time allows; and the mass
// account balances to the particle through all of it.
#include <dm/physics/fluid_sources.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

namespace fluid_sources_test {

using dm::Vec3;

constexpr double kD = 0.01;  // m, spacing: particle volume 1e-6 m³ (1 ml)
constexpr double kG = 9.81;

dm::SphFluid fluidWith(const Vec3& gravity, double viscosity = 1e-6) {
  auto f = dm::SphFluid::create({.particleSpacing = kD, .viscosity = viscosity, .gravity = gravity});
  EXPECT_TRUE(f) << f.error();
  return *f;
}

TEST(FluidInlet, APumpDeliversItsRateAndItsLayersLeaveASpacingApart) {
  dm::SphFluid fluid = fluidWith(Vec3::Zero());
  const Vec3 normal = Vec3(1, 1, 1).normalized();  // off the axes: the disc's lattice turns with it
  auto inlet = dm::FluidInlet::create(
      {.center = Vec3(0.1, 0.2, 0.3), .normal = Vec3(2, 2, 2), .radius = 0.015, .flowRate = 2e-5}, fluid);
  ASSERT_TRUE(inlet) << inlet.error();
  EXPECT_EQ(inlet->pointsPerLayer(), 9u);  // i² + j² ≤ 2.25 on the 1 cm lattice
  EXPECT_NEAR(inlet->outletArea(), 9e-4, 1e-15);
  const double dt = 0.005, seconds = 1.0;
  for (int k = 0; k < int(seconds / dt + 0.5); ++k) {
    inlet->emit(fluid, dt);
    ASSERT_TRUE(fluid.step(dt).ok());
  }
  // 20 ml delivered, to within the layer (9 ml) still in flight.
  EXPECT_LE(inlet->emittedVolume(), 2e-5 + 1e-12);
  EXPECT_GT(inlet->emittedVolume(), 2e-5 - 9e-6);
  EXPECT_EQ(fluid.size(), inlet->emittedParticles());
  EXPECT_NEAR(inlet->lastFlowRate(), 2e-5, 1e-18);
  // Without gravity the jet keeps the outlet's speed Q/A along the normal,
  // and its layers are one spacing apart along it.
  const double speed = 2e-5 / 9e-4;
  std::vector<double> axial;
  for (std::size_t i = 0; i < fluid.size(); ++i) {
    const Vec3 r = fluid.positions()[i] - inlet->options().center;
    if ((r - r.dot(normal) * normal).norm() < 1e-3 * kD) axial.push_back(r.dot(normal));  // the centre line
    EXPECT_NEAR(fluid.velocities()[i].dot(normal), speed, 0.05 * speed) << i;
  }
  ASSERT_GE(axial.size(), 2u);
  std::sort(axial.begin(), axial.end());
  for (std::size_t k = 1; k < axial.size(); ++k) EXPECT_NEAR(axial[k] - axial[k - 1], kD, 0.05 * kD) << k;
}

TEST(FluidInlet, PressingTheCutSlowsItLinearlyAndStopsItAtTheVesselsPressure) {
  dm::SphFluid fluid = fluidWith(Vec3::Zero());
  auto inlet = dm::FluidInlet::create({.center = Vec3::Zero(),
                                       .normal = Vec3(0, 0, 1),
                                       .radius = 0.0,
                                       .flowRate = 1e-5,
                                       .drivingPressure = 2000},
                                      fluid);
  ASSERT_TRUE(inlet);
  EXPECT_EQ(inlet->pointsPerLayer(), 1u);  // a point source
  const auto deliver = [&](double applied) {
    inlet->setAppliedPressure(applied);
    const std::size_t before = inlet->emittedParticles();
    for (int k = 0; k < 1000; ++k) {  // 1 s; the jet carries each particle clear of the mouth
      inlet->emit(fluid, 1e-3);
      EXPECT_TRUE(fluid.step(1e-3).ok());
    }
    return double(inlet->emittedParticles() - before) * 1e-6;
  };
  EXPECT_EQ(deliver(2000), 0.0);  // pressed with the vessel's pressure: stopped
  EXPECT_EQ(deliver(5000), 0.0);
  EXPECT_NEAR(deliver(500), 0.75e-5, 1e-6);  // Q0 (1 − 500/2000), to the particle in flight
  EXPECT_NEAR(deliver(0), 1e-5, 1e-6);
  EXPECT_NEAR(inlet->flowRateAt(1000), 0.5e-5, 1e-18);
  EXPECT_EQ(fluid.size(), inlet->emittedParticles());
}

// A 10 cm pool settled over a cut in the middle of its floor: the cut
// feels the pool's hydrostatic pressure at its sampling point, 1.5 spacings
// up, and bleeds at the vessel's law for it; no layer is started on top of
// the pool's particles lying over the mouth, and the flow it could not
// deliver is not stored.
TEST(FluidInlet, APoolOverACutPressesOnItWithItsHydrostaticPressure) {
  dm::SphFluid fluid = fluidWith(Vec3(0, 0, -kG), 1e-3);
  fluid.addBoxBoundary({0, 0, 0}, {0.1, 0.1, 0.3});
  ASSERT_EQ(fluid.addBlock({0, 0, 0}, {0.1, 0.1, 0.1}), 1000u);
  for (int k = 0; k < 150; ++k)
    ASSERT_TRUE(fluid.step(0.01).ok()) << k;  // 1.5 s to settle (as the column test)
  const double pv = 2000.0;
  auto inlet = dm::FluidInlet::create({.center = Vec3(0.05, 0.05, 0),
                                       .normal = Vec3(0, 0, 1),
                                       .radius = 0.015,
                                       .flowRate = 1e-4,
                                       .drivingPressure = pv},
                                      fluid);
  ASSERT_TRUE(inlet);
  // Averaged over 0.5 s: the back pressure, and ρ g times the depth of the
  // sampled particles under the surface (half a spacing over the top
  // particles away from the walls).
  double back = 0.0, hydrostatic = 0.0;
  constexpr int kSteps = 50;
  for (int k = 0; k < kSteps; ++k) {
    ASSERT_TRUE(fluid.step(0.01).ok());
    double zTop = 0.0, zSample = 0.0;
    int n = 0;
    for (const Vec3& x : fluid.positions()) {
      if (std::abs(x.x() - 0.05) < 0.03 && std::abs(x.y() - 0.05) < 0.03) zTop = std::max(zTop, x.z());
      if ((x - inlet->samplePoint()).norm() <= kD) {
        zSample += x.z();
        ++n;
      }
    }
    ASSERT_GT(n, 0);
    back += inlet->backPressure(fluid) / kSteps;
    hydrostatic += 1000.0 * kG * (zTop + 0.5 * kD - zSample / n) / kSteps;
  }
  EXPECT_NEAR(back, hydrostatic, 0.05 * hydrostatic);
  const double now = inlet->backPressure(fluid);
  inlet->setAppliedPressure(300.0);  // and a tool pressing beside it
  EXPECT_NEAR(inlet->backPressure(fluid), now + 300.0, 1e-9);
  const std::size_t start = fluid.size();
  inlet->emit(fluid, 0.005);
  EXPECT_NEAR(inlet->lastFlowRate(), 1e-4 * (1.0 - (now + 300.0) / pv), 1e-12);
  for (int k = 1; k < 60; ++k) inlet->emit(fluid, 0.005);  // 0.3 s: 14 ml or so, more than a layer (9 ml)
  // The cut lifted the column over it to make room: its layers came in, and
  // no particle was started within 3/4 of a spacing of another.
  EXPECT_GE(inlet->emittedParticles(), inlet->pointsPerLayer());
  EXPECT_EQ(fluid.size(), start + inlet->emittedParticles());
  for (std::size_t i = start; i < fluid.size(); ++i)
    for (std::size_t j = 0; j < fluid.size(); ++j) {
      if (j == i) continue;
      EXPECT_GE((fluid.positions()[i] - fluid.positions()[j]).norm(), 0.75 * kD - 1e-12) << i << " " << j;
    }
}

// A manometer: a vessel at the pressure of 8 cm of the fluid bleeds into a
// 6 × 6 cm tube through the middle of its floor, lifting the pool over the
// cut as it comes, until the pool's pressure at the cut balances the
// vessel's and the bleeding stops (without the back pressure it would
// deliver 3e-4 m³/s × 6 s = 1.8 l, a 50 cm column). It stops past the
// vessel's pressure by the last layer (2.5 mm of the tube: 25 Pa) and what
// the pool's settling after a lift adds: the pool's sampled pressure over
// the last second is p_v to 10 % (842 Pa against 785 here).
TEST(FluidInlet, AVesselBleedsIntoATubeUntilThePoolsPressureBalancesIt) {
  dm::SphFluid fluid = fluidWith(Vec3(0, 0, -kG), 1e-3);
  fluid.addBoxBoundary({0, 0, 0}, {0.06, 0.06, 0.4});
  const double pv = 1000.0 * kG * 0.08;
  auto inlet = dm::FluidInlet::create({.center = Vec3(0.03, 0.03, 0),
                                       .normal = Vec3(0, 0, 1),
                                       .radius = 0.015,
                                       .flowRate = 3e-4,
                                       .drivingPressure = pv},
                                      fluid);
  ASSERT_TRUE(inlet);
  double back = 0.0;
  std::size_t emittedLate = 0;
  for (int k = 0; k < 1200; ++k) {  // 6 s
    const std::size_t before = inlet->emittedParticles();
    inlet->emit(fluid, 0.005);
    ASSERT_TRUE(fluid.step(0.005).ok()) << k;
    if (k >= 1000) {  // the last second
      back += inlet->backPressure(fluid) / 200.0;
      emittedLate += inlet->emittedParticles() - before;
    }
  }
  EXPECT_EQ(emittedLate, 0u);  // stopped
  EXPECT_NEAR(back, pv, 0.1 * pv);
  EXPECT_LT(double(fluid.size()) * 1e-6, 3e-4 * 6.0 / 3.0);  // far less than the unchecked flow
}

TEST(FluidSuction, TakesItsRateNearestTheTipFirstAndBanksNothingInAir) {
  dm::SphFluid fluid = fluidWith(Vec3::Zero());
  fluid.addBlock({0, 0, 0}, {0.1, 0.1, 0.1});
  const Vec3 tip(0.052, 0.047, 0.05);
  // A particle's volume is its mass over the rest density (the mass is
  // calibrated to the lattice's kernel sum, so it is not d³ to the last digit).
  const double vp = fluid.particleMass() / 1000.0;
  auto suction = dm::FluidSuction::create({.center = tip, .radius = 0.03, .maxFlowRate = 25.5 * vp});
  ASSERT_TRUE(suction);
  const auto insideDistances = [&] {
    std::vector<double> r;
    for (const Vec3& x : fluid.positions())
      if ((x - tip).norm() <= 0.03) r.push_back((x - tip).norm());
    std::sort(r.begin(), r.end());
    return r;
  };
  const std::vector<double> before = insideDistances();
  ASSERT_GT(before.size(), 60u);
  EXPECT_EQ(suction->apply(fluid, 1.0), 25u);  // 25.5 particles of capacity: 25 particles, 0.5 carried over
  EXPECT_EQ(insideDistances(), std::vector<double>(before.begin() + 25, before.end()));  // the nearest went
  EXPECT_EQ(suction->apply(fluid, 1.0), 26u);                                            // 0.5 + 25.5
  EXPECT_NEAR(suction->removedVolume(), 51 * vp, 1e-15);
  // In air for ten calls, then back in the fluid: one call's capacity plus
  // at most one particle's.
  suction->setCenter(Vec3(1, 1, 1));
  for (int k = 0; k < 10; ++k) EXPECT_EQ(suction->apply(fluid, 1.0), 0u);
  suction->setCenter(tip);
  EXPECT_LE(suction->apply(fluid, 1.0), 26u);
  EXPECT_EQ(fluid.size(), 1000u - suction->removedParticles());
}

// A horizontal jet (1 m/s) from 15 cm above the region's floor leaves
// through it after at most sqrt(2 · 0.15 / g) = 0.175 s, so at most
// 100 particles/s × 0.175 s (and one in flight) are ever inside; over 3 s
// the count stays under that. A suction tip in the jet's path takes its
// share; the account balances every step.
TEST(FluidRegion, AJetLeavingTheRegionIsRecycledAndTheMassAccountBalances) {
  dm::SphFluid fluid = fluidWith(Vec3(0, 0, -kG));
  auto inlet = dm::FluidInlet::create(
      {.center = Vec3(0, 0, 0.1), .normal = Vec3(1, 0, 0), .radius = 0.0, .flowRate = 1e-4}, fluid);
  auto suction =
      dm::FluidSuction::create({.center = Vec3(0.1, 0, 0.05), .radius = 0.02, .maxFlowRate = 2e-5});
  auto region = dm::FluidRegion::create(Vec3(-0.05, -0.05, -0.05), Vec3(0.3, 0.05, 0.2));
  ASSERT_TRUE(inlet && suction && region);
  const double dt = 0.002;
  const double residence = std::sqrt(2.0 * 0.15 / kG);
  std::size_t most = 0;
  for (int k = 0; k < 1500; ++k) {
    inlet->emit(fluid, dt);
    suction->apply(fluid, dt);
    region->apply(fluid);
    ASSERT_TRUE(fluid.step(dt).ok()) << k;
    ASSERT_EQ(fluid.size() + suction->removedParticles() + region->removedParticles(),
              inlet->emittedParticles())
        << k;
    EXPECT_NEAR(fluid.mass(), fluid.particleMass() * double(fluid.size()), 1e-12);
    most = std::max(most, fluid.size());
  }
  EXPECT_LE(double(most), 100.0 * residence + 1.0);
  EXPECT_GT(region->removedParticles(), 200u);  // most of the 300 ml left through the floor
  EXPECT_GT(suction->removedParticles(), 0u);   // the tip in the jet's path took some
  EXPECT_LT(suction->removedVolume(), 2e-5 * 3.0 + 1e-6);
}

TEST(FluidSources, BadOptionsAreRefusedNamingThem) {
  dm::SphFluid fluid = fluidWith(Vec3::Zero());
  const auto refused = [](const auto& r, const char* name) {
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().code, dm::ErrorCode::InvalidArgument);
    EXPECT_NE(r.error().message().find(name), std::string::npos) << r.error();
  };
  refused(dm::FluidInlet::create({.normal = Vec3::Zero()}, fluid), "normal");
  refused(dm::FluidInlet::create({.radius = -1}, fluid), "radius");
  refused(dm::FluidInlet::create({.flowRate = std::nan("")}, fluid), "flowRate");
  refused(dm::FluidInlet::create({.drivingPressure = -5}, fluid), "drivingPressure");
  refused(dm::FluidSuction::create({.radius = 0}), "radius");
  refused(dm::FluidSuction::create({.radius = 0.01, .maxFlowRate = -1}), "maxFlowRate");
  refused(dm::FluidRegion::create(Vec3(0, 0, 0), Vec3(1, 0, 1)), "FluidRegion");
}

}  // namespace fluid_sources_test
