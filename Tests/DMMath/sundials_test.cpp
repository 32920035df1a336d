// SUNDIALS integrators: stiff problems against analytic solutions and
// reference values, the cost comparison with explicit methods, non-stiff
// accuracy, fixed-step order of ARKODE, and the mapping of failures.
#include <dm/math/integrators.hpp>
#include <dm/math/sundials.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <stdexcept>
#include <string>
#include <vector>

#include "math_test_support.hpp"

namespace {

using dm::IntegrationStats;
using dm::IntegratorOptions;
using dm::LinearSolverKind;
using dm::MatX;
using dm::OdeSystem;
using dm::VecX;
using dm::test::vecOf;

using dm::test::make;

void print(const char* label, const IntegrationStats& s, double err) {
  std::printf(
      "[sundials] %-28s error %.2e  steps %lld  rejected %lld  f-evals %lld  J-evals %lld  lin-iters %lld\n",
      label, err, static_cast<long long>(s.steps), static_cast<long long>(s.rejectedSteps),
      static_cast<long long>(s.rhsEvaluations), static_cast<long long>(s.jacobianEvaluations),
      static_cast<long long>(s.linearIterations));
}

// ---------------------------------------------------------------------------
// Stiff scalar problem with an analytic solution:
//   y' = -λ (y - cos t), y(0) = 0, λ = 1000
//   y(t) = (λ² cos t + λ sin t) / (λ² + 1) - λ² / (λ² + 1) e^{-λ t}

constexpr double kLambda = 1000.0;
double stiffExact(double t) {
  const double l2 = kLambda * kLambda;
  return (l2 * std::cos(t) + kLambda * std::sin(t)) / (l2 + 1.0) - l2 / (l2 + 1.0) * std::exp(-kLambda * t);
}
OdeSystem stiffSystem(bool withJacobian) {
  OdeSystem s =
      OdeSystem::firstOrder([](double t, const VecX& y, VecX& d) { d[0] = -kLambda * (y[0] - std::cos(t)); });
  if (withJacobian) s.jacobian = [](double, const VecX&, MatX& J) { J(0, 0) = -kLambda; };
  return s;
}

TEST(Sundials, StiffSolversMatchTheAnalyticSolution) {
  const double T = 2.0;
  struct Case {
    const char* label;
    const char* name;
    LinearSolverKind ls;
    bool jac;
  };
  const Case cases[] = {
      {"cvode-bdf dense (DQ J)", "cvode-bdf", LinearSolverKind::Dense, false},
      {"cvode-bdf dense (user J)", "cvode-bdf", LinearSolverKind::Dense, true},
      {"cvode-bdf gmres (DQ Jv)", "cvode-bdf", LinearSolverKind::Gmres, false},
      {"cvode-bdf gmres (user J)", "cvode-bdf", LinearSolverKind::Gmres, true},
      {"arkode-dirk dense", "arkode-dirk", LinearSolverKind::Dense, true},
      {"arkode-dirk gmres", "arkode-dirk", LinearSolverKind::Gmres, false},
  };
  for (const Case& c : cases) {
    VecX y = VecX::Zero(1);
    IntegratorOptions o;
    o.rtol = 1e-6;
    o.atol = 1e-10;
    o.linearSolver = c.ls;
    IntegrationStats s;
    const auto st = make(c.name)->integrate(stiffSystem(c.jac), 0.0, T, y, o, &s);
    ASSERT_TRUE(st) << c.label << ": " << st.error().message();
    const double err = std::abs(y[0] - stiffExact(T));
    print(c.label, s, err);
    EXPECT_LT(err, 1e-4) << c.label;
    EXPECT_DOUBLE_EQ(s.tReached, T);
    EXPECT_GT(s.steps, 0);
    EXPECT_GT(s.nonlinearIterations, 0) << c.label;
    if (c.ls == LinearSolverKind::Dense) {
      EXPECT_GT(s.jacobianEvaluations, 0) << c.label;
    }
    if (c.ls == LinearSolverKind::Gmres) {
      EXPECT_GT(s.linearIterations, 0) << c.label;
    }
    if (c.jac) {
      EXPECT_GT(s.jacobianEvaluations, 0) << c.label;
    }
  }
}

TEST(Sundials, GmresUsesTheUserJacobianTimesVector) {
  // Matrix-free: (∂f/∂y)·v = -λ v, given as a callback; designated options.
  int jtvCalls = 0;
  OdeSystem sys = stiffSystem(false);
  sys.jacobianTimes = [&jtvCalls](double, const VecX&, const VecX& v, VecX& jv) {
    ++jtvCalls;
    jv = -kLambda * v;
  };
  VecX y = VecX::Zero(1);
  IntegrationStats s;
  const auto st = dm::makeCvodeBdf()->integrate(
      sys, 0.0, 2.0, y, {.rtol = 1e-6, .atol = 1e-10, .linearSolver = LinearSolverKind::Gmres}, &s);
  ASSERT_TRUE(st) << st.error().message();
  print("cvode-bdf gmres (user Jv)", s, std::abs(y[0] - stiffExact(2.0)));
  EXPECT_LT(std::abs(y[0] - stiffExact(2.0)), 1e-4);
  EXPECT_GT(jtvCalls, 0);
  EXPECT_GE(jtvCalls, s.linearIterations);
}

TEST(Sundials, ImexSplitsStiffAndNonStiffParts) {
  // Same problem, split: fE = λ cos t (forcing, explicit), fI = -λ y (stiff, implicit).
  const double T = 2.0;
  int jacCalls = 0;
  const OdeSystem sys = OdeSystem::split([](double t, const VecX&, VecX& d) { d[0] = kLambda * std::cos(t); },
                                         [](double, const VecX& y, VecX& d) { d[0] = -kLambda * y[0]; },
                                         [&jacCalls](double, const VecX&, MatX& J) {
                                           ++jacCalls;
                                           J(0, 0) = -kLambda;
                                         });
  for (LinearSolverKind ls : {LinearSolverKind::Dense, LinearSolverKind::Gmres}) {
    VecX y = VecX::Zero(1);
    IntegratorOptions o;
    o.rtol = 1e-6;
    o.atol = 1e-10;
    o.linearSolver = ls;
    IntegrationStats s;
    jacCalls = 0;
    const auto st = make("arkode-ark")->integrate(sys, 0.0, T, y, o, &s);
    ASSERT_TRUE(st) << st.error().message();
    const double err = std::abs(y[0] - stiffExact(T));
    print(ls == LinearSolverKind::Dense ? "arkode-ark dense" : "arkode-ark gmres (user J)", s, err);
    EXPECT_LT(err, 1e-4);
    EXPECT_GT(jacCalls, 0);  // the implicit part's Jacobian is used
  }
}

TEST(Sundials, ExplicitMethodAtTheSameCostBlowsUp) {
  const double T = 10.0;
  VecX y = VecX::Zero(1);
  IntegratorOptions o;
  o.rtol = 1e-6;
  o.atol = 1e-10;
  IntegrationStats bdf;
  ASSERT_TRUE(make("cvode-bdf")->integrate(stiffSystem(false), 0.0, T, y, o, &bdf));
  const double errBdf = std::abs(y[0] - stiffExact(T));
  print("cvode-bdf (budget)", bdf, errBdf);
  EXPECT_LT(errBdf, 1e-4);

  // RK4 with the same number of rhs evaluations: h = T / (evals / 4), far
  // beyond its stability limit |λ h| <= 2.79.
  const std::int64_t rk4Steps = std::max<std::int64_t>(1, bdf.rhsEvaluations / 4);
  IntegratorOptions f;
  f.h = T / static_cast<double>(rk4Steps);
  ASSERT_GT(kLambda * f.h, 2.79);
  VecX z = VecX::Zero(1);
  IntegrationStats rk;
  const auto st = make("rk4")->integrate(stiffSystem(false), 0.0, T, z, f, &rk);
  const bool blewUp = !st || !z.allFinite() || std::abs(z[0] - stiffExact(T)) > 1e3;
  std::printf("[sundials] rk4 with %lld steps (h = %.3g, %lld f-evals): %s\n",
              static_cast<long long>(rk4Steps), f.h, static_cast<long long>(rk.rhsEvaluations),
              st ? "finished" : st.error().message().c_str());
  EXPECT_TRUE(blewUp);
  if (!st) {
    EXPECT_NE(st.error().hint.find("cvode-bdf"), std::string::npos);
  }

  // The adaptive explicit method stays stable but pays for it in evaluations.
  VecX w = VecX::Zero(1);
  IntegrationStats dp;
  ASSERT_TRUE(make("dopri5")->integrate(stiffSystem(false), 0.0, T, w, o, &dp));
  print("dopri5 (stiff)", dp, std::abs(w[0] - stiffExact(T)));
  EXPECT_GT(dp.rhsEvaluations, 5 * bdf.rhsEvaluations);
}

// ---------------------------------------------------------------------------
// Robertson chemical kinetics (stiff, 3 species, mass conserving):
//   y1' = -0.04 y1 + 1e4 y2 y3
//   y2' =  0.04 y1 - 1e4 y2 y3 - 3e7 y2²
//   y3' =  3e7 y2²
// Reference at t = 40 (SUNDIALS cvRoberts_dns, rtol 1e-4 with tight atol,
// agreeing with Hairer–Wanner's RADAU5 to the digits given):
//   y = (7.158e-1, 9.185e-6, 2.842e-1).

OdeSystem robertson() {
  OdeSystem s = OdeSystem::firstOrder([](double, const VecX& y, VecX& d) {
    d[0] = -0.04 * y[0] + 1e4 * y[1] * y[2];
    d[2] = 3e7 * y[1] * y[1];
    d[1] = -d[0] - d[2];
  });
  s.jacobian = [](double, const VecX& y, MatX& J) {
    J << -0.04, 1e4 * y[2], 1e4 * y[1],               //
        0.04, -1e4 * y[2] - 6e7 * y[1], -1e4 * y[1],  //
        0.0, 6e7 * y[1], 0.0;
  };
  return s;
}

TEST(Sundials, RobertsonKineticsAgainstReference) {
  const VecX ref = vecOf({7.158e-1, 9.185e-6, 2.842e-1});
  struct Case {
    const char* label;
    const char* name;
    LinearSolverKind ls;
    bool jac;
  };
  const Case cases[] = {
      {"robertson cvode-bdf dense", "cvode-bdf", LinearSolverKind::Dense, true},
      {"robertson cvode-bdf dense DQ", "cvode-bdf", LinearSolverKind::Dense, false},
      {"robertson cvode-bdf gmres", "cvode-bdf", LinearSolverKind::Gmres, false},
      {"robertson arkode-dirk dense", "arkode-dirk", LinearSolverKind::Dense, true},
  };
  for (const Case& c : cases) {
    VecX y = vecOf({1.0, 0.0, 0.0});
    IntegratorOptions o;
    o.rtol = 1e-6;
    o.atolPerComponent = vecOf({1e-10, 1e-14, 1e-8});
    o.linearSolver = c.ls;
    OdeSystem sys = robertson();
    if (!c.jac) sys.jacobian = {};
    IntegrationStats s;
    const auto st = make(c.name)->integrate(sys, 0.0, 40.0, y, o, &s);
    ASSERT_TRUE(st) << c.label << ": " << st.error().message();
    const double relErr = ((y - ref).cwiseQuotient(ref)).cwiseAbs().maxCoeff();
    print(c.label, s, relErr);
    EXPECT_LT(relErr, 1e-3) << c.label << " y = " << y.transpose();
    EXPECT_NEAR(y.sum(), 1.0, 1e-6) << c.label;  // mass conservation
  }

  // An explicit method with the budget of the dense BDF run goes unstable
  // (the fast eigenvalue is about -1e4 near t = 40, and ~ -2e3 early on).
  VecX y = vecOf({1.0, 0.0, 0.0});
  IntegrationStats bdf;
  IntegratorOptions o;
  o.rtol = 1e-6;
  o.atolPerComponent = vecOf({1e-10, 1e-14, 1e-8});
  ASSERT_TRUE(make("cvode-bdf")->integrate(robertson(), 0.0, 40.0, y, o, &bdf));
  IntegratorOptions f;
  f.h = 40.0 / static_cast<double>(std::max<std::int64_t>(1, bdf.rhsEvaluations / 4));
  VecX z = vecOf({1.0, 0.0, 0.0});
  const auto st = make("rk4")->integrate(robertson(), 0.0, 40.0, z, f);
  std::printf("[sundials] robertson rk4 at BDF's budget (h = %.3g): %s\n", f.h,
              st ? "finished" : st.error().message().c_str());
  EXPECT_TRUE(!st || !z.allFinite() || ((z - ref).cwiseQuotient(ref)).cwiseAbs().maxCoeff() > 1.0);
}

// ---------------------------------------------------------------------------
// Non-stiff methods

TEST(Sundials, NonStiffMethodsMatchTheOscillator) {
  // x'' = -x over 5 periods (second-order system through the adapter).
  const OdeSystem sys = OdeSystem::secondOrder([](double, const VecX& x, const VecX&, VecX& a) { a = -x; });
  const double T = 10.0 * std::numbers::pi;
  for (const char* name : {"cvode-adams", "arkode-erk", "cvode-bdf", "arkode-dirk"}) {
    VecX y = vecOf({1.0, 0.0});
    IntegratorOptions o;
    o.rtol = 1e-9;
    o.atol = 1e-11;
    IntegrationStats s;
    const auto st = make(name)->integrate(sys, 0.0, T, y, o, &s);
    ASSERT_TRUE(st) << name << ": " << st.error().message();
    const double err = (y - vecOf({1.0, 0.0})).norm();
    print(name, s, err);
    EXPECT_LT(err, 1e-6) << name;
  }
}

TEST(Sundials, ArkodeFixedStepsShowTheirOrder) {
  // y' = t (1 + y²), y = tan(t²/2), on [0, 1] with fixed steps: ERKStep's default
  // (Zonneveld) table is fourth order.
  const OdeSystem sys =
      OdeSystem::firstOrder([](double t, const VecX& y, VecX& d) { d[0] = t * (1.0 + y[0] * y[0]); });
  for (const char* name : {"arkode-erk"}) {
    std::vector<double> logh, loge;
    for (int n : {8, 16, 32, 64}) {
      VecX y = VecX::Zero(1);
      IntegratorOptions o;
      o.adaptive = false;
      o.h = 1.0 / n;
      IntegrationStats s;
      const auto st = make(name)->integrate(sys, 0.0, 1.0, y, o, &s);
      ASSERT_TRUE(st) << name << ": " << st.error().message();
      EXPECT_EQ(s.steps, n) << name;
      logh.push_back(std::log(o.h));
      loge.push_back(std::log(std::abs(y[0] - std::tan(0.5))));
    }
    const double p = (loge.back() - loge.front()) / (logh.back() - logh.front());
    std::printf("[order] %s (fixed h): %.3f\n", name, p);
    EXPECT_NEAR(p, 4.0, 0.3) << name;
  }
}

// ---------------------------------------------------------------------------
// Failures

TEST(SundialsErrors, NanRightHandSideIsReportedWithItsTime) {
  const OdeSystem sys = OdeSystem::firstOrder([](double t, const VecX& y, VecX& d) {
    d = -y;
    if (t > 0.5) d[0] = std::nan("");
  });
  for (std::string_view name : dm::integratorNames()) {
    if (!name.starts_with("cvode") && !name.starts_with("arkode-erk") && name != "arkode-dirk") continue;
    VecX y = VecX::Ones(2);
    IntegrationStats s;
    IntegratorOptions o;
    o.maxSteps = 2000;  // the implicit solvers creep towards t = 0.5 until a limit trips
    const auto st = make(name)->integrate(sys, 0.0, 1.0, y, o, &s);
    ASSERT_FALSE(st) << name;
    EXPECT_NE(st.error().what.find("NaN"), std::string::npos) << st.error().message();
    EXPECT_NE(st.error().where.find("t = 0.5"), std::string::npos) << st.error().message();
    EXPECT_FALSE(st.error().hint.empty());
    EXPECT_LE(s.tReached, 0.5 + 1e-9) << name;
    EXPECT_TRUE(y.allFinite()) << name;
    // The returned state is the last accepted one, at tReached: y1 = e^{-t}.
    EXPECT_NEAR(y[1], std::exp(-s.tReached), 1e-5) << name;
  }
  // NaN from the very first evaluation.
  VecX y = VecX::Ones(1);
  const auto st =
      make("cvode-bdf")
          ->integrate(OdeSystem::firstOrder([](double, const VecX&, VecX& d) { d[0] = std::nan(""); }), 0.0,
                      1.0, y);
  ASSERT_FALSE(st);
  EXPECT_NE(st.error().what.find("NaN"), std::string::npos) << st.error().message();
}

TEST(SundialsErrors, CallbackProblemsBecomeErrorsNotCrashes) {
  // An exception thrown by the rhs must not cross SUNDIALS' C frames.
  VecX y = VecX::Ones(1);
  auto st = make("cvode-bdf")
                ->integrate(OdeSystem::firstOrder([](double t, const VecX&, VecX&) {
                              if (t >= 0.0) throw std::runtime_error("boom");
                            }),
                            0.0, 1.0, y);
  ASSERT_FALSE(st);
  EXPECT_NE(st.error().what.find("boom"), std::string::npos) << st.error().message();

  // A resized output.
  st = make("arkode-erk")
           ->integrate(OdeSystem::firstOrder([](double, const VecX&, VecX& d) { d = VecX::Zero(4); }), 0.0,
                       1.0, y);
  ASSERT_FALSE(st);
  EXPECT_NE(st.error().what.find("size"), std::string::npos) << st.error().message();

  // A Jacobian that throws.
  OdeSystem sys = stiffSystem(false);
  sys.jacobian = [](double, const VecX&, MatX&) { throw std::runtime_error("bad jacobian"); };
  VecX z = VecX::Zero(1);
  st = make("cvode-bdf")->integrate(sys, 0.0, 1.0, z);
  ASSERT_FALSE(st);
  EXPECT_NE(st.error().what.find("bad jacobian"), std::string::npos) << st.error().message();
}

TEST(SundialsErrors, OptionAndSystemMisuse) {
  VecX y = VecX::Ones(1);
  IntegratorOptions o;
  o.adaptive = false;
  o.h = 0.1;
  auto st = make("cvode-bdf")->integrate(stiffSystem(false), 0.0, 1.0, y, o);
  ASSERT_FALSE(st);
  EXPECT_EQ(st.error().code, dm::ErrorCode::InvalidArgument);
  EXPECT_NE(st.error().hint.find("arkode"), std::string::npos);

  st = make("arkode-ark")->integrate(stiffSystem(false), 0.0, 1.0, y);
  ASSERT_FALSE(st);
  EXPECT_NE(st.error().what.find("split"), std::string::npos);

  IntegratorOptions bad;
  bad.rtol = -1.0;
  EXPECT_FALSE(make("arkode-dirk")->integrate(stiffSystem(false), 0.0, 1.0, y, bad));
  EXPECT_FALSE(make("cvode-bdf")->integrate(stiffSystem(false), 1.0, 0.0, y));
}

TEST(SundialsErrors, StepLimitAndNonStiffSolverOnStiffProblem) {
  // maxSteps too small → Timeout naming the limit.
  VecX y = VecX::Zero(1);
  IntegratorOptions o;
  o.maxSteps = 5;
  IntegrationStats s;
  auto st = make("cvode-bdf")->integrate(stiffSystem(false), 0.0, 10.0, y, o, &s);
  ASSERT_FALSE(st);
  EXPECT_EQ(st.error().code, dm::ErrorCode::Timeout);
  EXPECT_NE(st.error().what.find("maxSteps = 5"), std::string::npos) << st.error().message();
  EXPECT_GT(s.tReached, 0.0);
  EXPECT_LT(s.tReached, 10.0);

  // Explicit ERK on the stiff problem with a modest budget: it cannot get
  // through, and the hint points to the stiff solver.
  VecX z = VecX::Zero(1);
  o.maxSteps = 200;
  st = make("arkode-erk")->integrate(stiffSystem(false), 0.0, 10.0, z, o);
  ASSERT_FALSE(st);
  EXPECT_NE(st.error().hint.find("cvode-bdf"), std::string::npos) << st.error().message();

  // Tolerances at round-off: TOO_MUCH_ACC or a step failure, not a crash.
  VecX w = VecX::Ones(1);
  IntegratorOptions tight;
  tight.rtol = 1e-15;
  tight.atol = 0.0;
  st = make("cvode-bdf")->integrate(stiffSystem(false), 0.0, 1.0, w, tight);
  if (!st) {
    EXPECT_FALSE(st.error().hint.empty());
  }
}

TEST(SundialsErrors, FactoryNamesAndProperties) {
  for (const char* name : {"cvode-bdf", "cvode-adams", "arkode-erk", "arkode-dirk", "arkode-ark"}) {
    auto a = dm::makeSundialsIntegrator(name);
    ASSERT_NE(a, nullptr) << name;
    EXPECT_EQ(a->name(), name);
    EXPECT_TRUE(a->isAdaptive());
  }
  EXPECT_EQ(dm::makeSundialsIntegrator("rk4"), nullptr);
  EXPECT_EQ(dm::makeCvodeBdf()->order(), 5);
  EXPECT_EQ(dm::makeCvodeAdams()->order(), 12);
  EXPECT_EQ(dm::makeArkodeArk()->order(), 4);
}

}  // namespace
