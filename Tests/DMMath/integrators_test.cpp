// Integrators checked against mathematics: convergence orders fitted from
// errors at the final time, tolerance proportionality of the adaptive
// methods, energy behaviour of the symplectic ones, and the error paths.
#include <dm/math/integrators.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <string>
#include <vector>

#include "math_test_support.hpp"

namespace {

using dm::IntegrationStats;
using dm::IntegratorOptions;
using dm::OdeSystem;
using dm::VecX;
using dm::test::vecOf;

using dm::test::make;

/// Least-squares slope of log(err) against log(h).
double fittedOrder(const std::vector<double>& hs, const std::vector<double>& errs) {
  const double n = static_cast<double>(hs.size());
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  for (std::size_t i = 0; i < hs.size(); ++i) {
    const double x = std::log(hs[i]), y = std::log(errs[i]);
    sx += x;
    sy += y;
    sxx += x * x;
    sxy += x * y;
  }
  return (n * sxy - sx * sy) / (n * sxx - sx * sx);
}

// Scalar, nonlinear and non-autonomous test problem with a known solution:
//   y' = t (1 + y^2), y(0) = 0  →  y = tan(t^2 / 2).
// Nonlinear so that every elementary differential enters (a wrong tableau
// coefficient shows up as a lower order), non-autonomous so the c_i matter,
// scalar so that no cancellation between components distorts the slope.
OdeSystem tanSystem() {
  return OdeSystem::firstOrder([](double t, const VecX& y, VecX& d) { d[0] = t * (1.0 + y[0] * y[0]); });
}
VecX tanInitial() { return VecX::Zero(1); }
VecX tanExact(double t) { return VecX::Constant(1, std::tan(0.5 * t * t)); }

// Kepler problem x'' = -x / |x|^3 with eccentricity e: period 2π, starting at
// pericentre; after one period the exact state equals the initial one.
constexpr double kEcc = 0.5;
OdeSystem keplerSystem() {
  return OdeSystem::secondOrder([](double, const VecX& x, const VecX&, VecX& a) {
    const double r = x.norm();
    a = -x / (r * r * r);
  });
}
VecX keplerInitial() {
  return vecOf({1.0 - kEcc, 0.0, 0.0, std::sqrt((1.0 + kEcc) / (1.0 - kEcc))});
}
/// The exact state after half a period (t = π): apocentre, moving in -y.
/// (Errors are measured here, not after a full period, because there the
/// O(h) error of symplectic Euler cancels: it is conjugate to Verlet.)
VecX keplerHalfPeriod() {
  return vecOf({-(1.0 + kEcc), 0.0, 0.0, -std::sqrt((1.0 - kEcc) / (1.0 + kEcc))});
}

/// Final-time error of `name` with fixed steps T/n for each n.
std::vector<double> fixedStepErrors(std::string_view name, const OdeSystem& sys, const VecX& y0, double T,
                                    const VecX& exact, const std::vector<int>& ns, std::vector<double>& hs) {
  auto integ = make(name);
  std::vector<double> errs;
  hs.clear();
  for (int n : ns) {
    IntegratorOptions o;
    o.h = T / n;
    o.adaptive = false;  // adaptive methods take fixed steps of h; fixed-step ones ignore it
    VecX y = y0;
    IntegrationStats s;
    const auto st = integ->integrate(sys, 0.0, T, y, o, &s);
    EXPECT_TRUE(st) << name << ": " << (st ? "" : st.error().message());
    EXPECT_EQ(s.steps, n);
    hs.push_back(o.h);
    errs.push_back((y - exact).norm());
  }
  return errs;
}

TEST(Integrators, FactoryKnowsEveryNameAndReportsProperties) {
  for (std::string_view n : dm::integratorNames()) {
    auto integ = make(n);
    ASSERT_NE(integ, nullptr);
    EXPECT_EQ(integ->name(), n);
    EXPECT_GE(integ->order(), 1);
  }
  EXPECT_EQ(make("euler")->order(), 1);
  EXPECT_EQ(make("symplectic-euler")->order(), 1);
  EXPECT_EQ(make("verlet")->order(), 2);
  EXPECT_EQ(make("rk4")->order(), 4);
  EXPECT_EQ(make("dopri5")->order(), 5);
  EXPECT_EQ(make("dop853")->order(), 8);
  EXPECT_FALSE(make("rk4")->isAdaptive());
  EXPECT_TRUE(make("dopri5")->isAdaptive());
  EXPECT_TRUE(make("verlet")->needsSecondOrder());
  EXPECT_FALSE(make("rk4")->needsSecondOrder());
}

TEST(Integrators, UnknownNameListsTheValidOnes) {
  auto r = dm::makeIntegrator("rk45");
  ASSERT_FALSE(r);
  EXPECT_EQ(r.error().code, dm::ErrorCode::NotFound);
  EXPECT_NE(r.error().what.find("rk45"), std::string::npos);
  for (std::string_view n : dm::integratorNames()) EXPECT_NE(r.error().hint.find(n), std::string::npos) << n;
}

// ---------------------------------------------------------------------------
// Convergence orders of the fixed-step methods

TEST(IntegratorOrder, ExplicitEulerIsFirstOrder) {
  std::vector<double> hs;
  const auto errs =
      fixedStepErrors("euler", tanSystem(), tanInitial(), 1.0, tanExact(1.0), {32, 64, 128, 256}, hs);
  const double p = fittedOrder(hs, errs);
  std::printf("[order] euler: %.3f\n", p);
  EXPECT_NEAR(p, 1.0, 0.2);
}

TEST(IntegratorOrder, Rk4IsFourthOrder) {
  std::vector<double> hs;
  const auto errs =
      fixedStepErrors("rk4", tanSystem(), tanInitial(), 1.0, tanExact(1.0), {8, 16, 32, 64}, hs);
  const double p = fittedOrder(hs, errs);
  std::printf("[order] rk4: %.3f\n", p);
  EXPECT_NEAR(p, 4.0, 0.2);
}

TEST(IntegratorOrder, SymplecticEulerIsFirstOrderOnKepler) {
  std::vector<double> hs;
  const double T = std::numbers::pi;
  const auto errs = fixedStepErrors("symplectic-euler", keplerSystem(), keplerInitial(), T,
                                    keplerHalfPeriod(), {640, 1280, 2560, 5120}, hs);
  const double p = fittedOrder(hs, errs);
  std::printf("[order] symplectic-euler: %.3f\n", p);
  EXPECT_NEAR(p, 1.0, 0.2);
}

TEST(IntegratorOrder, VelocityVerletIsSecondOrderOnKepler) {
  std::vector<double> hs;
  const double T = std::numbers::pi;
  const auto errs = fixedStepErrors("verlet", keplerSystem(), keplerInitial(), T, keplerHalfPeriod(),
                                    {80, 160, 320, 640}, hs);
  const double p = fittedOrder(hs, errs);
  std::printf("[order] verlet: %.3f\n", p);
  EXPECT_NEAR(p, 2.0, 0.2);
}

TEST(IntegratorOrder, VelocityVerletStaysSecondOrderWithDamping) {
  // x'' = -x - c v (under-damped), exact solution known: the predicted
  // end-of-step velocity keeps the velocity-dependent case second order.
  const double c = 0.5, w = std::sqrt(1.0 - c * c / 4.0);
  const OdeSystem sys =
      OdeSystem::secondOrder([c](double, const VecX& x, const VecX& v, VecX& a) { a = -x - c * v; });
  const double T = 5.0;
  const double x = std::exp(-c * T / 2) * (std::cos(w * T) + c / (2 * w) * std::sin(w * T));
  const double v = -std::exp(-c * T / 2) * (1.0 / w) * std::sin(w * T);
  std::vector<double> hs;
  const auto errs = fixedStepErrors("verlet", sys, vecOf({1.0, 0.0}), T,
                                    vecOf({x, v}), {100, 200, 400, 800}, hs);
  const double p = fittedOrder(hs, errs);
  std::printf("[order] verlet (damped): %.3f\n", p);
  EXPECT_NEAR(p, 2.0, 0.2);
}

// The adaptive methods with adaptivity off (fixed h): their intrinsic order.
// Step ranges keep the errors well above round-off (>= 1e-13).
TEST(IntegratorOrder, Dopri5WithFixedStepsIsFifthOrder) {
  std::vector<double> hs;
  const double T = std::numbers::pi;
  const auto errs = fixedStepErrors("dopri5", keplerSystem(), keplerInitial(), T, keplerHalfPeriod(),
                                    {80, 160, 320, 640}, hs);
  const double p = fittedOrder(hs, errs);
  std::printf("[order] dopri5 (fixed h): %.3f  errors %.2e .. %.2e\n", p, errs.front(), errs.back());
  EXPECT_NEAR(p, 5.0, 0.25);
  EXPECT_GT(errs.back(), 1e-13);
}

TEST(IntegratorOrder, Dop853WithFixedStepsIsEighthOrder) {
  std::vector<double> hs;
  const auto errs =
      fixedStepErrors("dop853", tanSystem(), tanInitial(), 1.2, tanExact(1.2), {4, 6, 8, 12, 16}, hs);
  const double p = fittedOrder(hs, errs);
  std::printf("[order] dop853 (fixed h): %.3f  errors %.2e .. %.2e\n", p, errs.front(), errs.back());
  EXPECT_NEAR(p, 8.0, 0.3);
  EXPECT_GT(errs.back(), 1e-13);
}

TEST(IntegratorOrder, SecondOrderSystemsRunThroughFirstOrderMethods) {
  // rk4 on the Kepler problem via the [v; a] adapter: fourth order.
  std::vector<double> hs;
  const double T = std::numbers::pi;
  const auto errs = fixedStepErrors("rk4", keplerSystem(), keplerInitial(), T, keplerHalfPeriod(),
                                    {100, 200, 400, 800}, hs);
  const double p = fittedOrder(hs, errs);
  std::printf("[order] rk4 (kepler): %.3f\n", p);
  EXPECT_NEAR(p, 4.0, 0.2);
}

// ---------------------------------------------------------------------------
// Adaptive methods: accuracy follows the tolerance

TEST(IntegratorAdaptive, ErrorScalesWithToleranceOnKepler) {
  // Kepler (e = 0.5) over one period: a sensitive problem (energy errors
  // turn into a growing phase error), so the global error is a fixed
  // multiple of the per-step tolerance; what must hold is that it follows
  // the tolerance.
  const double T = 2.0 * std::numbers::pi;
  const std::vector<double> tols = {1e-6, 1e-8, 1e-10};
  for (std::string_view name : {"dopri5", "dop853"}) {
    auto integ = make(name);
    std::vector<double> errs;
    for (double tol : tols) {
      VecX y = keplerInitial();
      IntegrationStats s;
      IntegratorOptions o;
      o.rtol = tol;
      o.atol = tol;
      ASSERT_TRUE(integ->integrate(keplerSystem(), 0.0, T, y, o, &s));
      EXPECT_DOUBLE_EQ(s.tReached, T);
      const double err = (y - keplerInitial()).norm();
      std::printf("[adaptive] %s tol %.0e: error %.2e, %lld steps, %lld rejected, %lld f-evals\n",
                  std::string(name).c_str(), tol, err, static_cast<long long>(s.steps),
                  static_cast<long long>(s.rejectedSteps), static_cast<long long>(s.rhsEvaluations));
      EXPECT_LT(err, 1000.0 * tol) << name << " tol " << tol;
      errs.push_back(err);
    }
    // log(err) against log(tol): proportional (slope ~1; DOP853's stretched
    // error estimate makes it a little flatter).
    const double slope = fittedOrder(tols, errs);
    std::printf("[adaptive] %s: d log(err) / d log(tol) = %.3f\n", std::string(name).c_str(), slope);
    EXPECT_GT(slope, 0.6) << name;
    EXPECT_LT(slope, 1.3) << name;
  }
}

TEST(IntegratorAdaptive, MatchesExponentialDecayAndOscillatorToTolerance) {
  for (std::string_view name : {"dopri5", "dop853"}) {
    auto integ = make(name);
    IntegratorOptions o;
    o.rtol = 1e-9;
    o.atol = 1e-12;
    // y' = -y on [0, 5].
    VecX y = VecX::Ones(1);
    ASSERT_TRUE(integ->integrate(OdeSystem::firstOrder([](double, const VecX& u, VecX& d) { d = -u; }), 0.0,
                                 5.0, y, o));
    EXPECT_NEAR(y[0], std::exp(-5.0), 1e-9 * std::exp(-5.0) * 20 + 1e-12) << name;
    // Harmonic oscillator x'' = -x over 10 periods: x = cos t, v = -sin t.
    VecX z = vecOf({1.0, 0.0});
    const double T = 20.0 * std::numbers::pi;
    ASSERT_TRUE(integ->integrate(
        OdeSystem::secondOrder([](double, const VecX& x, const VecX&, VecX& a) { a = -x; }), 0.0, T, z, o));
    EXPECT_NEAR(z[0], 1.0, 1e-7) << name;
    EXPECT_NEAR(z[1], 0.0, 1e-7) << name;
  }
}

TEST(IntegratorAdaptive, Dop853NeedsFewerEvaluationsThanDopri5AtTightTolerance) {
  const double T = 2.0 * std::numbers::pi;
  IntegratorOptions o;
  o.rtol = 1e-11;
  o.atol = 1e-11;
  IntegrationStats s5, s8;
  VecX y5 = keplerInitial(), y8 = keplerInitial();
  ASSERT_TRUE(make("dopri5")->integrate(keplerSystem(), 0.0, T, y5, o, &s5));
  ASSERT_TRUE(make("dop853")->integrate(keplerSystem(), 0.0, T, y8, o, &s8));
  EXPECT_LT(s8.rhsEvaluations, s5.rhsEvaluations);
  EXPECT_LT((y8 - keplerInitial()).norm(), 1e-8);
}

TEST(IntegratorAdaptive, SplitSystemIsSummedForUnsplitMethods) {
  // y' = fE + fI with fE = cos t, fI = -y; y(0) = 0 → y = (sin t + cos t - e^{-t}) / 2.
  const OdeSystem sys = OdeSystem::split([](double t, const VecX&, VecX& d) { d[0] = std::cos(t); },
                                         [](double, const VecX& y, VecX& d) { d = -y; });
  VecX y = VecX::Zero(1);
  IntegratorOptions o;
  o.rtol = 1e-10;
  o.atol = 1e-12;
  ASSERT_TRUE(make("dopri5")->integrate(sys, 0.0, 3.0, y, o));
  EXPECT_NEAR(y[0], 0.5 * (std::sin(3.0) + std::cos(3.0) - std::exp(-3.0)), 1e-9);
}

TEST(IntegratorAdaptive, PerComponentAbsoluteToleranceIsHonoured) {
  // A component that starts and stays at 0 with atol 0 for it would need
  // zero error; with a per-component atol the run succeeds and is accurate.
  VecX y = vecOf({1.0, 0.0});
  IntegratorOptions o;
  o.rtol = 1e-8;
  o.atolPerComponent = vecOf({1e-10, 1e-12});
  ASSERT_TRUE(make("dopri5")->integrate(
      OdeSystem::firstOrder([](double, const VecX& u, VecX& d) { d << -u[0], u[0] - u[1]; }), 0.0, 2.0, y,
      o));
  // y1 = t e^{-t}
  EXPECT_NEAR(y[0], std::exp(-2.0), 1e-7);
  EXPECT_NEAR(y[1], 2.0 * std::exp(-2.0), 1e-7);
}

// ---------------------------------------------------------------------------
// Long-run energy behaviour on the harmonic oscillator x'' = -x

TEST(IntegratorEnergy, SymplecticMethodsKeepEnergyBoundedExplicitEulerGrows) {
  const int steps = 100000;
  const double h = 0.01;  // 10^5 steps to t = 1000 (~159 periods)
  const dm::SecondOrderRhs a = [](double, const VecX& x, const VecX&, VecX& acc) { acc = -x; };
  auto energy = [](double x, double v) { return 0.5 * (x * x + v * v); };
  const double e0 = energy(1.0, 0.0);

  struct Drift {
    double maxEarly = 0, maxLate = 0, maxAll = 0;
  };
  auto run = [&](auto&& step) {
    VecX x = VecX::Ones(1), v = VecX::Zero(1);
    dm::SecondOrderWorkspace ws;
    Drift d;
    for (int i = 0; i < steps; ++i) {
      step(i * h, x, v, ws);
      const double err = std::abs(energy(x[0], v[0]) - e0) / e0;
      d.maxAll = std::max(d.maxAll, err);
      if (i < steps / 10) d.maxEarly = std::max(d.maxEarly, err);
      if (i >= steps - steps / 10) d.maxLate = std::max(d.maxLate, err);
    }
    return d;
  };
  const Drift se = run([&](double t, VecX& x, VecX& v, dm::SecondOrderWorkspace& ws) {
    dm::symplecticEulerStep(a, t, h, x, v, ws);
  });
  const Drift vv = run([&](double t, VecX& x, VecX& v, dm::SecondOrderWorkspace& ws) {
    dm::velocityVerletStep(a, t, h, x, v, ws);
  });
  std::printf("[energy] symplectic Euler max |dE|/E %.3e (first 10%% %.3e, last 10%% %.3e)\n", se.maxAll,
              se.maxEarly, se.maxLate);
  std::printf("[energy] velocity Verlet max |dE|/E %.3e (first 10%% %.3e, last 10%% %.3e)\n", vv.maxAll,
              vv.maxEarly, vv.maxLate);
  // Bounded: O(h) for symplectic Euler, O(h^2) for Verlet, all along the run…
  EXPECT_LT(se.maxAll, 1.5 * h);
  EXPECT_LT(vv.maxAll, 0.5 * h * h);
  // …and no drift: the late oscillation is no larger than the early one.
  EXPECT_LT(se.maxLate, 1.01 * se.maxEarly);
  EXPECT_LT(vv.maxLate, 1.01 * vv.maxEarly);

  // Explicit Euler multiplies the energy by exactly (1 + h^2) per step.
  VecX y = vecOf({1.0, 0.0});
  dm::EulerWorkspace ws;
  const dm::OdeRhs f = [](double, const VecX& u, VecX& d) { d << u[1], -u[0]; };
  double prev = e0;
  bool monotone = true;
  for (int i = 0; i < steps; ++i) {
    dm::eulerStep(f, i * h, h, y, ws);
    const double e = energy(y[0], y[1]);
    monotone = monotone && e > prev;
    prev = e;
  }
  const double growth = energy(y[0], y[1]) / e0;
  std::printf("[energy] explicit Euler E(T)/E0 = %.4e (exact (1+h^2)^n = %.4e)\n", growth,
              std::pow(1.0 + h * h, steps));
  EXPECT_TRUE(monotone);
  EXPECT_GT(growth, 1e4);
  EXPECT_NEAR(growth / std::pow(1.0 + h * h, steps), 1.0, 1e-6);
}

// ---------------------------------------------------------------------------
// Single-step functions

TEST(IntegratorSteps, Rk4StepMatchesIntegrateAndReusesItsWorkspace) {
  const dm::OdeRhs f = tanSystem().rhs;
  VecX y = tanInitial();
  dm::Rk4Workspace ws;
  const double h = 0.05;
  dm::rk4Step(f, 0.0, h, y, ws);
  const double* k1 = ws.k1.data();
  const double* tmp = ws.tmp.data();
  for (int i = 1; i < 20; ++i) dm::rk4Step(f, i * h, h, y, ws);
  EXPECT_EQ(ws.k1.data(), k1);  // no reallocation after the first step
  EXPECT_EQ(ws.tmp.data(), tmp);

  VecX z = tanInitial();
  IntegratorOptions o;
  o.h = h;
  ASSERT_TRUE(make("rk4")->integrate(OdeSystem::firstOrder(f), 0.0, 1.0, z, o));
  EXPECT_LT((y - z).norm(), 1e-14);
}

TEST(IntegratorSteps, VerletReusesTheEndOfStepAcceleration) {
  int calls = 0;
  const dm::SecondOrderRhs a = [&calls](double, const VecX& x, const VecX&, VecX& acc) {
    ++calls;
    acc = -x;
  };
  VecX x = VecX::Ones(3), v = VecX::Zero(3);
  dm::SecondOrderWorkspace ws;
  for (int i = 0; i < 10; ++i) dm::velocityVerletStep(a, 0.01 * i, 0.01, x, v, ws);
  EXPECT_EQ(calls, 11);  // one priming evaluation, then one per step
  ws.invalidate();
  dm::velocityVerletStep(a, 0.1, 0.01, x, v, ws);
  EXPECT_EQ(calls, 13);
}

TEST(IntegratorSteps, LastFixedStepLandsOnT1) {
  // h does not divide the interval: 4 steps of 0.3 cover [0, 1], the last shortened to 0.1.
  VecX y = VecX::Ones(1);
  IntegrationStats s;
  IntegratorOptions o;
  o.h = 0.3;
  ASSERT_TRUE(make("euler")->integrate(
      OdeSystem::firstOrder([](double, const VecX&, VecX& d) { d[0] = 1.0; }), 0.0, 1.0, y, o, &s));
  EXPECT_EQ(s.steps, 4);
  EXPECT_NEAR(s.lastStep, 0.1, 1e-12);
  EXPECT_DOUBLE_EQ(s.tReached, 1.0);
  EXPECT_NEAR(y[0], 2.0, 1e-12);  // exact for a constant rhs
}

// ---------------------------------------------------------------------------
// Error paths

const OdeSystem kDecay = OdeSystem::firstOrder([](double, const VecX& y, VecX& d) { d = -y; });

TEST(IntegratorErrors, BadOptionsAreRejectedWithAMessage) {
  auto rk4 = make("rk4");
  auto dp = make("dopri5");
  VecX y = VecX::Ones(2);
  IntegratorOptions o;  // h = 0
  auto st = rk4->integrate(kDecay, 0.0, 1.0, y, o);
  ASSERT_FALSE(st);
  EXPECT_EQ(st.error().code, dm::ErrorCode::InvalidArgument);
  EXPECT_NE(st.error().what.find("h = 0"), std::string::npos) << st.error().message();
  EXPECT_FALSE(st.error().hint.empty());

  o.h = -0.1;
  EXPECT_FALSE(rk4->integrate(kDecay, 0.0, 1.0, y, o));
  o.h = 0.1;
  st = rk4->integrate(kDecay, 1.0, 0.0, y, o);
  ASSERT_FALSE(st);
  EXPECT_NE(st.error().what.find("t1"), std::string::npos);
  EXPECT_FALSE(rk4->integrate(kDecay, 0.0, std::nan(""), y, o));

  IntegratorOptions a;
  a.rtol = 0.0;
  EXPECT_FALSE(dp->integrate(kDecay, 0.0, 1.0, y, a));
  a = {};
  a.atol = -1.0;
  EXPECT_FALSE(dp->integrate(kDecay, 0.0, 1.0, y, a));
  a = {};
  a.atolPerComponent = VecX::Ones(3);
  st = dp->integrate(kDecay, 0.0, 1.0, y, a);
  ASSERT_FALSE(st);
  EXPECT_NE(st.error().what.find("atolPerComponent"), std::string::npos);
  a = {};
  a.maxSteps = 0;
  EXPECT_FALSE(dp->integrate(kDecay, 0.0, 1.0, y, a));
  a = {};
  a.adaptive = false;  // fixed steps need h
  EXPECT_FALSE(dp->integrate(kDecay, 0.0, 1.0, y, a));

  VecX empty;
  EXPECT_FALSE(dp->integrate(kDecay, 0.0, 1.0, empty, {}));
  VecX nan = VecX::Constant(2, std::nan(""));
  st = dp->integrate(kDecay, 0.0, 1.0, nan, {});
  ASSERT_FALSE(st);
  EXPECT_NE(st.error().what.find("NaN"), std::string::npos);
  EXPECT_FALSE(dp->integrate(OdeSystem{}, 0.0, 1.0, y, {}));
  // Nothing above touched the state.
  EXPECT_EQ(y, VecX::Ones(2));
}

TEST(IntegratorErrors, SecondOrderMethodsNeedASecondOrderSystem) {
  VecX y = VecX::Ones(2);
  IntegratorOptions o;
  o.h = 0.1;
  auto st = make("verlet")->integrate(kDecay, 0.0, 1.0, y, o);
  ASSERT_FALSE(st);
  EXPECT_NE(st.error().what.find("acceleration"), std::string::npos);
  VecX odd = VecX::Ones(3);
  st = make("symplectic-euler")->integrate(keplerSystem(), 0.0, 1.0, odd, o);
  ASSERT_FALSE(st);
  EXPECT_NE(st.error().what.find("odd"), std::string::npos);
}

TEST(IntegratorErrors, NanRightHandSideIsReportedWithItsTime) {
  // Finite until t = 0.5, NaN afterwards.
  const OdeSystem sys = OdeSystem::firstOrder([](double t, const VecX& y, VecX& d) {
    d = -y;
    if (t > 0.5) d[0] = std::nan("");
  });
  for (std::string_view name : {"euler", "rk4", "dopri5", "dop853"}) {
    VecX y = VecX::Ones(2);
    IntegratorOptions o;
    o.h = 0.01;
    IntegrationStats s;
    const auto st = make(name)->integrate(sys, 0.0, 1.0, y, o, &s);
    ASSERT_FALSE(st) << name;
    EXPECT_NE(st.error().message().find("NaN"), std::string::npos) << st.error().message();
    EXPECT_NE(st.error().where.find("t = 0.5"), std::string::npos) << st.error().message();
    // The state is the last good one, from before the NaN region (one step of slack), and finite.
    EXPECT_LE(s.tReached, 0.5 + o.h + 1e-12) << name;
    EXPECT_TRUE(y.allFinite()) << name;
  }
  // NaN right at the start.
  const OdeSystem bad =
      OdeSystem::firstOrder([](double, const VecX&, VecX& d) { d.setConstant(std::nan("")); });
  VecX y = VecX::Ones(1);
  const auto st = make("dopri5")->integrate(bad, 0.0, 1.0, y);
  ASSERT_FALSE(st);
  EXPECT_NE(st.error().what.find("NaN"), std::string::npos);
  EXPECT_NE(st.error().where.find("t = 0"), std::string::npos);
}

TEST(IntegratorErrors, ResizedOutputIsRejected) {
  const OdeSystem sys = OdeSystem::firstOrder([](double, const VecX&, VecX& d) { d = VecX::Zero(5); });
  for (std::string_view name : {"rk4", "dopri5"}) {
    VecX y = VecX::Ones(2);
    IntegratorOptions o;
    o.h = 0.1;
    const auto st = make(name)->integrate(sys, 0.0, 1.0, y, o);
    ASSERT_FALSE(st) << name;
    EXPECT_NE(st.error().what.find("size"), std::string::npos) << st.error().message();
  }
}

// y' = -1000 (y - cos t): stiff, with a smooth solution near cos t.
const OdeSystem kStiff =
    OdeSystem::firstOrder([](double t, const VecX& y, VecX& d) { d[0] = -1000.0 * (y[0] - std::cos(t)); });

TEST(IntegratorErrors, ExplicitBlowUpPointsToAStiffSolver) {
  VecX y = VecX::Zero(1);
  IntegratorOptions o;
  o.h = 0.05;  // |λ h| = 50, far outside RK4's stability region
  IntegrationStats s;
  const auto st = make("rk4")->integrate(kStiff, 0.0, 100.0, y, o, &s);
  ASSERT_FALSE(st);
  EXPECT_EQ(st.error().code, dm::ErrorCode::Unsupported);
  EXPECT_NE(st.error().hint.find("cvode-bdf"), std::string::npos) << st.error().message();
  EXPECT_TRUE(y.allFinite());
}

TEST(IntegratorErrors, StepLimitAndStepUnderflowSayWhatToDo) {
  // Stiff problem with a small step budget: dopri5 runs into maxSteps.
  VecX y = VecX::Zero(1);
  IntegratorOptions o;
  o.maxSteps = 50;
  auto st = make("dopri5")->integrate(kStiff, 0.0, 10.0, y, o);
  ASSERT_FALSE(st);
  EXPECT_EQ(st.error().code, dm::ErrorCode::Timeout);
  EXPECT_NE(st.error().hint.find("cvode-bdf"), std::string::npos) << st.error().message();

  // A fixed-step run that would need more than maxSteps is refused up front.
  o.h = 1e-4;
  st = make("rk4")->integrate(kStiff, 0.0, 10.0, y, o);
  ASSERT_FALSE(st);
  EXPECT_EQ(st.error().code, dm::ErrorCode::Timeout);

  // y' = y^2, y(0) = 1 blows up at t = 1: the step size collapses there.
  VecX z = VecX::Ones(1);
  IntegrationStats s;
  st = make("dopri5")->integrate(
      OdeSystem::firstOrder([](double, const VecX& u, VecX& d) { d = u.cwiseProduct(u); }), 0.0, 2.0, z, {},
      &s);
  ASSERT_FALSE(st);
  EXPECT_TRUE(st.error().code == dm::ErrorCode::Unsupported || st.error().code == dm::ErrorCode::Timeout);
  EXPECT_NEAR(s.tReached, 1.0, 1e-2) << st.error().message();
  const std::string& w = st.error().where;
  EXPECT_TRUE(w.find("t = 0.99") != std::string::npos || w.find("t = 1") != std::string::npos) << w;
}

TEST(IntegratorErrors, ZeroLengthIntervalIsANoOp) {
  VecX y = VecX::Ones(2);
  IntegrationStats s;
  ASSERT_TRUE(make("dopri5")->integrate(kDecay, 1.0, 1.0, y, {}, &s));
  EXPECT_EQ(s.steps, 0);
  EXPECT_EQ(y, VecX::Ones(2));
}

}  // namespace
