#include <dm/math/integrators.hpp>
#include <dm/math/sundials.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>
#include <utility>

#include "math_internal.hpp"

namespace dm {

// ---------------------------------------------------------------------------
// Systems

OdeSystem OdeSystem::firstOrder(OdeRhs f, OdeJacobian jac) {
  OdeSystem s;
  s.rhs = std::move(f);
  s.jacobian = std::move(jac);
  return s;
}

OdeSystem OdeSystem::secondOrder(SecondOrderRhs a) {
  OdeSystem s;
  s.acceleration = std::move(a);
  return s;
}

OdeSystem OdeSystem::split(OdeRhs fExplicit, OdeRhs fImplicit, OdeJacobian implicitJac) {
  OdeSystem s;
  s.explicitRhs = std::move(fExplicit);
  s.implicitRhs = std::move(fImplicit);
  s.implicitJacobian = std::move(implicitJac);
  return s;
}

OdeRhs toFirstOrder(const OdeSystem& sys) {
  if (sys.rhs) return sys.rhs;
  if (sys.explicitRhs && sys.implicitRhs) {
    return [fe = sys.explicitRhs, fi = sys.implicitRhs, tmp = VecX()](double t, const VecX& y,
                                                                      VecX& dydt) mutable {
      fe(t, y, dydt);
      tmp.resize(y.size());
      fi(t, y, tmp);
      dydt += tmp;
    };
  }
  if (sys.acceleration) {
    return [a = sys.acceleration, x = VecX(), v = VecX(), acc = VecX()](double t, const VecX& y,
                                                                        VecX& dydt) mutable {
      const Eigen::Index m = y.size() / 2;
      x = y.head(m);
      v = y.tail(m);
      acc.resize(m);
      a(t, x, v, acc);
      dydt.head(m) = v;
      dydt.tail(m) = acc;
    };
  }
  return {};
}

// ---------------------------------------------------------------------------
// Single steps

void eulerStep(const OdeRhs& f, double t, double h, VecX& y, EulerWorkspace& ws) {
  ws.dydt.resize(y.size());
  f(t, y, ws.dydt);
  y += h * ws.dydt;
}

void Rk4Workspace::resize(Eigen::Index n) {
  k1.resize(n);
  k2.resize(n);
  k3.resize(n);
  k4.resize(n);
  tmp.resize(n);
}

void rk4Step(const OdeRhs& f, double t, double h, VecX& y, Rk4Workspace& ws) {
  ws.resize(y.size());
  const double h2 = 0.5 * h;
  f(t, y, ws.k1);
  ws.tmp = y + h2 * ws.k1;
  f(t + h2, ws.tmp, ws.k2);
  ws.tmp = y + h2 * ws.k2;
  f(t + h2, ws.tmp, ws.k3);
  ws.tmp = y + h * ws.k3;
  f(t + h, ws.tmp, ws.k4);
  y += (h / 6.0) * (ws.k1 + 2.0 * ws.k2 + 2.0 * ws.k3 + ws.k4);
}

void symplecticEulerStep(const SecondOrderRhs& a, double t, double h, VecX& x, VecX& v,
                         SecondOrderWorkspace& ws) {
  ws.acc.resize(x.size());
  a(t, x, v, ws.acc);
  v += h * ws.acc;
  x += h * v;
  // The acceleration at the new state is not known; the next step evaluates it.
  ws.accelerationValid = false;
}

void velocityVerletStep(const SecondOrderRhs& a, double t, double h, VecX& x, VecX& v,
                        SecondOrderWorkspace& ws) {
  const Eigen::Index m = x.size();
  if (!ws.accelerationValid || ws.acc.size() != m) {
    ws.acc.resize(m);
    a(t, x, v, ws.acc);
  }
  // Predicted end velocity v + h a0 (O(h^2) accurate) for velocity-dependent
  // forces; the kick uses a(t + h, x1, vPred), exact Verlet when a = a(x).
  ws.vPred = v + h * ws.acc;
  v += (0.5 * h) * ws.acc;
  x += h * v;
  ws.accNext.resize(m);
  a(t + h, x, ws.vPred, ws.accNext);
  ws.acc.swap(ws.accNext);
  v += (0.5 * h) * ws.acc;
  ws.accelerationValid = true;
}

// ---------------------------------------------------------------------------
// Helpers

namespace {

using detail::firstNonFinite;
using detail::fmt;

std::string at(std::string_view method, double t) { return std::string(method) + " at t = " + fmt(t); }

/// Number of fixed steps of size h covering `span`: the ratio, or its
/// ceiling when it is not within round-off of an integer.
std::int64_t fixedStepCount(double span, double h) {
  const double r = span / h;
  if (!(r < 9e18)) return std::numeric_limits<std::int64_t>::max();  // exceeds any maxSteps
  const double rr = std::round(r);
  if (std::abs(r - rr) <= 1e-9 * std::max(1.0, r)) return std::max<std::int64_t>(1, std::llround(rr));
  return std::max<std::int64_t>(1, static_cast<std::int64_t>(std::ceil(r)));
}

Status checkRhsSize(std::string_view method, double t, const VecX& dydt, Eigen::Index n) {
  if (dydt.size() == n) return ok();
  return fail(ErrorCode::InvalidArgument,
              "the right-hand side resized its output to " + std::to_string(dydt.size()) +
                  " for a state of size " + std::to_string(n),
              at(method, t), "write every component of dydt without resizing it");
}

Status nonFiniteRhs(std::string_view method, double t, Eigen::Index i) {
  return fail(
      ErrorCode::InvalidArgument,
      "the right-hand side returned NaN/Inf (component " + std::to_string(i) + ")", at(method, t),
      "check the right-hand side at this state (division by zero, sqrt/log of a negative value, overflow)");
}

Status blowUp(std::string_view method, double t, double h, Eigen::Index i) {
  return fail(
      ErrorCode::Unsupported,
      "the solution became NaN/Inf (component " + std::to_string(i) + ") in the step of size h = " + fmt(h),
      at(method, t),
      "h exceeds the method's stability limit: reduce h, use an adaptive method (dopri5), or, if the "
      "problem is stiff, a stiff solver (cvode-bdf)");
}

Status tooManySteps(std::string_view method, double t, std::int64_t maxSteps) {
  return fail(
      ErrorCode::Timeout, "more than maxSteps = " + std::to_string(maxSteps) + " steps needed", at(method, t),
      "increase IntegratorOptions::maxSteps or h, loosen rtol/atol; if the step size collapsed the problem "
      "is stiff: use a stiff solver (cvode-bdf)");
}

// ---------------------------------------------------------------------------
// Fixed-step integrators on first-order systems

template <class Step>
Status fixedStepFirstOrder(std::string_view method, int evalsPerStep, const OdeSystem& sys, double t0,
                           double t1, VecX& y, const IntegratorOptions& opt, IntegrationStats& stats,
                           Step&& step) {
  const OdeRhs f = toFirstOrder(sys);
  const Eigen::Index n = y.size();
  const std::int64_t steps = fixedStepCount(t1 - t0, opt.h);
  if (steps > opt.maxSteps) return tooManySteps(method, t0, opt.maxSteps);
  VecX yPrev(n);
  // One probe evaluation: the steppers trust the output size, so check it
  // (and finiteness, for a precise message) before the first step.
  VecX probe = VecX::Zero(n);
  f(t0, y, probe);
  stats.rhsEvaluations += 1;
  if (auto s = checkRhsSize(method, t0, probe, n); !s) return s;
  if (const Eigen::Index j = firstNonFinite(probe); j >= 0) return nonFiniteRhs(method, t0, j);
  for (std::int64_t i = 0; i < steps; ++i) {
    const double t = t0 + static_cast<double>(i) * opt.h;
    const double h = (i + 1 == steps) ? t1 - t : opt.h;
    yPrev = y;
    step(f, t, h, y);
    stats.rhsEvaluations += evalsPerStep;
    const Eigen::Index bad = firstNonFinite(y);
    if (bad >= 0) {
      y = yPrev;
      f(t, y, probe);
      stats.rhsEvaluations += 1;
      if (const Eigen::Index j = firstNonFinite(probe); j >= 0) return nonFiniteRhs(method, t, j);
      return blowUp(method, t, h, bad);
    }
    stats.steps += 1;
    stats.lastStep = h;
    stats.tReached = (i + 1 == steps) ? t1 : t + h;
  }
  return ok();
}

class EulerIntegrator final : public Integrator {
 public:
  std::string_view name() const override { return "euler"; }
  int order() const override { return 1; }
  bool isAdaptive() const override { return false; }

 private:
  Status doIntegrate(const OdeSystem& sys, double t0, double t1, VecX& y, const IntegratorOptions& opt,
                     IntegrationStats& stats) override {
    EulerWorkspace ws;
    return fixedStepFirstOrder(
        name(), 1, sys, t0, t1, y, opt, stats,
        [&](const OdeRhs& f, double t, double h, VecX& yy) { eulerStep(f, t, h, yy, ws); });
  }
};

class Rk4Integrator final : public Integrator {
 public:
  std::string_view name() const override { return "rk4"; }
  int order() const override { return 4; }
  bool isAdaptive() const override { return false; }

 private:
  Status doIntegrate(const OdeSystem& sys, double t0, double t1, VecX& y, const IntegratorOptions& opt,
                     IntegrationStats& stats) override {
    Rk4Workspace ws;
    return fixedStepFirstOrder(
        name(), 4, sys, t0, t1, y, opt, stats,
        [&](const OdeRhs& f, double t, double h, VecX& yy) { rk4Step(f, t, h, yy, ws); });
  }
};

// ---------------------------------------------------------------------------
// Fixed-step integrators on second-order systems

class SecondOrderIntegrator : public Integrator {
 public:
  bool isAdaptive() const final { return false; }
  bool needsSecondOrder() const final { return true; }

 private:
  /// One step; returns the number of acceleration evaluations it made.
  virtual int step(const SecondOrderRhs& a, double t, double h, VecX& x, VecX& v,
                   SecondOrderWorkspace& ws) = 0;

  Status doIntegrate(const OdeSystem& sys, double t0, double t1, VecX& y, const IntegratorOptions& opt,
                     IntegrationStats& stats) final {
    const Eigen::Index m = y.size() / 2;
    const std::int64_t steps = fixedStepCount(t1 - t0, opt.h);
    if (steps > opt.maxSteps) return tooManySteps(name(), t0, opt.maxSteps);
    VecX x = y.head(m), v = y.tail(m);
    VecX xPrev(m), vPrev(m);
    auto store = [&] {
      y.head(m) = x;
      y.tail(m) = v;
    };
    // The steppers trust the output size: check it (and finiteness) once on
    // a probe, which also seeds velocity Verlet's cached acceleration.
    SecondOrderWorkspace ws;
    ws.acc = VecX::Zero(m);
    sys.acceleration(t0, x, v, ws.acc);
    stats.rhsEvaluations += 1;
    if (ws.acc.size() != m)
      return fail(ErrorCode::InvalidArgument,
                  "the acceleration resized its output to " + std::to_string(ws.acc.size()) +
                      " for positions of size " + std::to_string(m),
                  at(name(), t0), "write every component of acc without resizing it");
    if (const Eigen::Index j = firstNonFinite(ws.acc); j >= 0) return nonFiniteRhs(name(), t0, m + j);
    ws.accelerationValid = true;
    for (std::int64_t i = 0; i < steps; ++i) {
      const double t = t0 + static_cast<double>(i) * opt.h;
      const double h = (i + 1 == steps) ? t1 - t : opt.h;
      xPrev = x;
      vPrev = v;
      stats.rhsEvaluations += step(sys.acceleration, t, h, x, v, ws);
      Eigen::Index bad = firstNonFinite(x);
      if (bad < 0 && (bad = firstNonFinite(v)) >= 0) bad += m;
      if (bad >= 0) {
        x = xPrev;
        v = vPrev;
        store();
        VecX acc(m);
        sys.acceleration(t, x, v, acc);
        stats.rhsEvaluations += 1;
        if (const Eigen::Index j = firstNonFinite(acc); j >= 0) return nonFiniteRhs(name(), t, m + j);
        return blowUp(name(), t, h, bad);
      }
      stats.steps += 1;
      stats.lastStep = h;
      stats.tReached = (i + 1 == steps) ? t1 : t + h;
    }
    store();
    return ok();
  }
};

class SymplecticEulerIntegrator final : public SecondOrderIntegrator {
 public:
  std::string_view name() const override { return "symplectic-euler"; }
  int order() const override { return 1; }

 private:
  int step(const SecondOrderRhs& a, double t, double h, VecX& x, VecX& v, SecondOrderWorkspace& ws) override {
    // The probe before the first step already holds a(t0, x0, v0).
    if (ws.accelerationValid) {
      v += h * ws.acc;
      x += h * v;
      ws.accelerationValid = false;
      return 0;
    }
    symplecticEulerStep(a, t, h, x, v, ws);
    return 1;
  }
};

class VerletIntegrator final : public SecondOrderIntegrator {
 public:
  std::string_view name() const override { return "verlet"; }
  int order() const override { return 2; }

 private:
  int step(const SecondOrderRhs& a, double t, double h, VecX& x, VecX& v, SecondOrderWorkspace& ws) override {
    const int evals = ws.accelerationValid ? 1 : 2;
    velocityVerletStep(a, t, h, x, v, ws);
    return evals;
  }
};

// ---------------------------------------------------------------------------
// Adaptive embedded Runge–Kutta (Hairer's DOPRI5 and DOP853 drivers)

/// Per-component absolute tolerance and the weighted RMS norm of Hairer's codes.
struct ErrorScale {
  double rtol = 0;
  double atol = 0;
  const VecX* atolVec = nullptr;
  double atolOf(Eigen::Index i) const { return atolVec ? (*atolVec)[i] : atol; }
  /// sk_i = atol_i + rtol max(|y0_i|, |y1_i|), kept > 0 so that atol = 0 works.
  double sk(Eigen::Index i, double y0, double y1) const {
    return std::max(atolOf(i) + rtol * std::max(std::abs(y0), std::abs(y1)),
                    std::numeric_limits<double>::min());
  }
};

// Dormand & Prince (1980) 5(4), coefficients as in Hairer's dopri5.f.
struct Dopri5 {
  static constexpr std::string_view kName = "dopri5";
  static constexpr int kOrder = 5;
  static constexpr double kSafe = 0.9, kFacMin = 0.2, kFacMax = 10.0, kBeta = 0.04;
  static constexpr double kExpo = 0.2 - kBeta * 0.75;
  static constexpr double c2 = 1.0 / 5, c3 = 3.0 / 10, c4 = 4.0 / 5, c5 = 8.0 / 9;
  static constexpr double a21 = 1.0 / 5;
  static constexpr double a31 = 3.0 / 40, a32 = 9.0 / 40;
  static constexpr double a41 = 44.0 / 45, a42 = -56.0 / 15, a43 = 32.0 / 9;
  static constexpr double a51 = 19372.0 / 6561, a52 = -25360.0 / 2187, a53 = 64448.0 / 6561,
                          a54 = -212.0 / 729;
  static constexpr double a61 = 9017.0 / 3168, a62 = -355.0 / 33, a63 = 46732.0 / 5247, a64 = 49.0 / 176,
                          a65 = -5103.0 / 18656;
  static constexpr double a71 = 35.0 / 384, a73 = 500.0 / 1113, a74 = 125.0 / 192, a75 = -2187.0 / 6784,
                          a76 = 11.0 / 84;
  static constexpr double e1 = 71.0 / 57600, e3 = -71.0 / 16695, e4 = 71.0 / 1920, e5 = -17253.0 / 339200,
                          e6 = 22.0 / 525, e7 = -1.0 / 40;

  VecX k2, k3, k4, k5, k6, k7, tmp;

  void resize(Eigen::Index n) {
    for (VecX* v : {&k2, &k3, &k4, &k5, &k6, &k7, &tmp}) v->resize(n);
  }

  /// One attempt from (t, y) with k1 = f(t, y): y1 and the scaled error
  /// norm (NaN when something is non-finite). Six rhs evaluations; k7 =
  /// f(t + h, y1) becomes the next k1 (FSAL).
  double attempt(const OdeRhs& f, double t, double h, const VecX& y, const VecX& k1, VecX& y1,
                 const ErrorScale& sc) {
    tmp = y + h * (a21 * k1);
    f(t + c2 * h, tmp, k2);
    tmp = y + h * (a31 * k1 + a32 * k2);
    f(t + c3 * h, tmp, k3);
    tmp = y + h * (a41 * k1 + a42 * k2 + a43 * k3);
    f(t + c4 * h, tmp, k4);
    tmp = y + h * (a51 * k1 + a52 * k2 + a53 * k3 + a54 * k4);
    f(t + c5 * h, tmp, k5);
    tmp = y + h * (a61 * k1 + a62 * k2 + a63 * k3 + a64 * k4 + a65 * k5);
    f(t + h, tmp, k6);
    y1 = y + h * (a71 * k1 + a73 * k3 + a74 * k4 + a75 * k5 + a76 * k6);
    f(t + h, y1, k7);
    tmp = h * (e1 * k1 + e3 * k3 + e4 * k4 + e5 * k5 + e6 * k6 + e7 * k7);
    double sum = 0;
    for (Eigen::Index i = 0; i < y.size(); ++i) {
      const double r = tmp[i] / sc.sk(i, y[i], y1[i]);
      sum += r * r;
    }
    return std::sqrt(sum / static_cast<double>(y.size()));
  }
  static constexpr int kAttemptEvals = 6;

  /// Next k1 from the accepted step: k7 (FSAL, no evaluation).
  int advance(const OdeRhs&, double, const VecX&, VecX& k1) {
    k1.swap(k7);
    return 0;
  }
};

// Hairer's DOP853: Dormand & Prince 8(5,3); the coefficients are those of
// dop853.f (E. Hairer, G. Wanner), stage numbering as there.
struct Dop853 {
  static constexpr std::string_view kName = "dop853";
  static constexpr int kOrder = 8;
  static constexpr double kSafe = 0.9, kFacMin = 0.333, kFacMax = 6.0, kBeta = 0.0;
  static constexpr double kExpo = 1.0 / 8.0 - kBeta * 0.2;

  static constexpr double c2 = 0.526001519587677318785587544488e-01;
  static constexpr double c3 = 0.789002279381515978178381316732e-01;
  static constexpr double c4 = 0.118350341907227396726757197510e+00;
  static constexpr double c5 = 0.281649658092772603273242802490e+00;
  static constexpr double c6 = 0.333333333333333333333333333333e+00;
  static constexpr double c7 = 0.25e+00;
  static constexpr double c8 = 0.307692307692307692307692307692e+00;
  static constexpr double c9 = 0.651282051282051282051282051282e+00;
  static constexpr double c10 = 0.6e+00;
  static constexpr double c11 = 0.857142857142857142857142857142e+00;

  static constexpr double b1 = 5.42937341165687622380535766363e-2;
  static constexpr double b6 = 4.45031289275240888144113950566e0;
  static constexpr double b7 = 1.89151789931450038304281599044e0;
  static constexpr double b8 = -5.8012039600105847814672114227e0;
  static constexpr double b9 = 3.1116436695781989440891606237e-1;
  static constexpr double b10 = -1.52160949662516078556178806805e-1;
  static constexpr double b11 = 2.01365400804030348374776537501e-1;
  static constexpr double b12 = 4.47106157277725905176885569043e-2;

  static constexpr double bhh1 = 0.244094488188976377952755905512e+00;
  static constexpr double bhh2 = 0.733846688281611857341361741547e+00;
  static constexpr double bhh3 = 0.220588235294117647058823529412e-01;

  static constexpr double er1 = 0.1312004499419488073250102996e-01;
  static constexpr double er6 = -0.1225156446376204440720569753e+01;
  static constexpr double er7 = -0.4957589496572501915214079952e+00;
  static constexpr double er8 = 0.1664377182454986536961530415e+01;
  static constexpr double er9 = -0.3503288487499736816886487290e+00;
  static constexpr double er10 = 0.3341791187130174790297318841e+00;
  static constexpr double er11 = 0.8192320648511571246570742613e-01;
  static constexpr double er12 = -0.2235530786388629525884427845e-01;

  static constexpr double a21 = 5.26001519587677318785587544488e-2;
  static constexpr double a31 = 1.97250569845378994544595329183e-2;
  static constexpr double a32 = 5.91751709536136983633785987549e-2;
  static constexpr double a41 = 2.95875854768068491816892993775e-2;
  static constexpr double a43 = 8.87627564304205475450678981324e-2;
  static constexpr double a51 = 2.41365134159266685502369798665e-1;
  static constexpr double a53 = -8.84549479328286085344864962717e-1;
  static constexpr double a54 = 9.24834003261792003115737966543e-1;
  static constexpr double a61 = 3.7037037037037037037037037037e-2;
  static constexpr double a64 = 1.70828608729473871279604482173e-1;
  static constexpr double a65 = 1.25467687566822425016691814123e-1;
  static constexpr double a71 = 3.7109375e-2;
  static constexpr double a74 = 1.70252211019544039314978060272e-1;
  static constexpr double a75 = 6.02165389804559606850219397283e-2;
  static constexpr double a76 = -1.7578125e-2;
  static constexpr double a81 = 3.70920001185047927108779319836e-2;
  static constexpr double a84 = 1.70383925712239993810214054705e-1;
  static constexpr double a85 = 1.07262030446373284651809199168e-1;
  static constexpr double a86 = -1.53194377486244017527936158236e-2;
  static constexpr double a87 = 8.27378916381402288758473766002e-3;
  static constexpr double a91 = 6.24110958716075717114429577812e-1;
  static constexpr double a94 = -3.36089262944694129406857109825e0;
  static constexpr double a95 = -8.68219346841726006818189891453e-1;
  static constexpr double a96 = 2.75920996994467083049415600797e1;
  static constexpr double a97 = 2.01540675504778934086186788979e1;
  static constexpr double a98 = -4.34898841810699588477366255144e1;
  static constexpr double a101 = 4.77662536438264365890433908527e-1;
  static constexpr double a104 = -2.48811461997166764192642586468e0;
  static constexpr double a105 = -5.90290826836842996371446475743e-1;
  static constexpr double a106 = 2.12300514481811942347288949897e1;
  static constexpr double a107 = 1.52792336328824235832596922938e1;
  static constexpr double a108 = -3.32882109689848629194453265587e1;
  static constexpr double a109 = -2.03312017085086261358222928593e-2;
  static constexpr double a111 = -9.3714243008598732571704021658e-1;
  static constexpr double a114 = 5.18637242884406370830023853209e0;
  static constexpr double a115 = 1.09143734899672957818500254654e0;
  static constexpr double a116 = -8.14978701074692612513997267357e0;
  static constexpr double a117 = -1.85200656599969598641566180701e1;
  static constexpr double a118 = 2.27394870993505042818970056734e1;
  static constexpr double a119 = 2.49360555267965238987089396762e0;
  static constexpr double a1110 = -3.0467644718982195003823669022e0;
  static constexpr double a121 = 2.27331014751653820792359768449e0;
  static constexpr double a124 = -1.05344954667372501984066689879e1;
  static constexpr double a125 = -2.00087205822486249909675718444e0;
  static constexpr double a126 = -1.79589318631187989172765950534e1;
  static constexpr double a127 = 2.79488845294199600508499808837e1;
  static constexpr double a128 = -2.85899827713502369474065508674e0;
  static constexpr double a129 = -8.87285693353062954433549289258e0;
  static constexpr double a1210 = 1.23605671757943030647266201528e1;
  static constexpr double a1211 = 6.43392746015763530355970484046e-1;

  VecX k2, k3, k4, k5, k6, k7, k8, k9, k10, k11, k12, bk, tmp;

  void resize(Eigen::Index n) {
    for (VecX* v : {&k2, &k3, &k4, &k5, &k6, &k7, &k8, &k9, &k10, &k11, &k12, &bk, &tmp}) v->resize(n);
  }

  /// One attempt: eleven rhs evaluations (stages 2..12), y1, and Hairer's
  /// combined 5th/3rd-order error norm.
  double attempt(const OdeRhs& f, double t, double h, const VecX& y, const VecX& k1, VecX& y1,
                 const ErrorScale& sc) {
    tmp = y + h * (a21 * k1);
    f(t + c2 * h, tmp, k2);
    tmp = y + h * (a31 * k1 + a32 * k2);
    f(t + c3 * h, tmp, k3);
    tmp = y + h * (a41 * k1 + a43 * k3);
    f(t + c4 * h, tmp, k4);
    tmp = y + h * (a51 * k1 + a53 * k3 + a54 * k4);
    f(t + c5 * h, tmp, k5);
    tmp = y + h * (a61 * k1 + a64 * k4 + a65 * k5);
    f(t + c6 * h, tmp, k6);
    tmp = y + h * (a71 * k1 + a74 * k4 + a75 * k5 + a76 * k6);
    f(t + c7 * h, tmp, k7);
    tmp = y + h * (a81 * k1 + a84 * k4 + a85 * k5 + a86 * k6 + a87 * k7);
    f(t + c8 * h, tmp, k8);
    tmp = y + h * (a91 * k1 + a94 * k4 + a95 * k5 + a96 * k6 + a97 * k7 + a98 * k8);
    f(t + c9 * h, tmp, k9);
    tmp = y + h * (a101 * k1 + a104 * k4 + a105 * k5 + a106 * k6 + a107 * k7 + a108 * k8 + a109 * k9);
    f(t + c10 * h, tmp, k10);
    tmp = y + h * (a111 * k1 + a114 * k4 + a115 * k5 + a116 * k6 + a117 * k7 + a118 * k8 + a119 * k9 +
                   a1110 * k10);
    f(t + c11 * h, tmp, k11);
    tmp = y + h * (a121 * k1 + a124 * k4 + a125 * k5 + a126 * k6 + a127 * k7 + a128 * k8 + a129 * k9 +
                   a1210 * k10 + a1211 * k11);
    f(t + h, tmp, k12);
    bk = b1 * k1 + b6 * k6 + b7 * k7 + b8 * k8 + b9 * k9 + b10 * k10 + b11 * k11 + b12 * k12;
    y1 = y + h * bk;
    double err5 = 0, err3 = 0;
    for (Eigen::Index i = 0; i < y.size(); ++i) {
      const double s = sc.sk(i, y[i], y1[i]);
      const double e3 = (bk[i] - bhh1 * k1[i] - bhh2 * k9[i] - bhh3 * k12[i]) / s;
      const double e5 = (er1 * k1[i] + er6 * k6[i] + er7 * k7[i] + er8 * k8[i] + er9 * k9[i] + er10 * k10[i] +
                         er11 * k11[i] + er12 * k12[i]) /
                        s;
      err3 += e3 * e3;
      err5 += e5 * e5;
    }
    double deno = err5 + 0.01 * err3;
    if (deno <= 0.0) deno = 1.0;
    return std::abs(h) * err5 * std::sqrt(1.0 / (static_cast<double>(y.size()) * deno));
  }
  static constexpr int kAttemptEvals = 11;

  /// Next k1 = f(t1, y1): one evaluation.
  int advance(const OdeRhs& f, double t1, const VecX& y1, VecX& k1) {
    f(t1, y1, k1);
    return 1;
  }
};

/// Hairer's HINIT: a first step from the local derivative sizes.
template <class Method>
double initialStep(const OdeRhs& f, double t, const VecX& y, const VecX& f0, double hmax,
                   const ErrorScale& sc, VecX& y1, VecX& f1, IntegrationStats& stats) {
  double dnf = 0, dny = 0;
  for (Eigen::Index i = 0; i < y.size(); ++i) {
    const double s = sc.sk(i, y[i], y[i]);
    dnf += (f0[i] / s) * (f0[i] / s);
    dny += (y[i] / s) * (y[i] / s);
  }
  double h = (dnf <= 1e-10 || dny <= 1e-10) ? 1e-6 : std::sqrt(dny / dnf) * 0.01;
  h = std::min(h, hmax);
  // Explicit Euler probe for the second derivative; shrink if it overflows.
  for (int tries = 0; tries < 8; ++tries) {
    y1 = y + h * f0;
    f(t + h, y1, f1);
    stats.rhsEvaluations += 1;
    if (firstNonFinite(f1) < 0) break;
    h *= 1e-2;
  }
  if (firstNonFinite(f1) >= 0) return h;
  double der2 = 0;
  for (Eigen::Index i = 0; i < y.size(); ++i) {
    const double r = (f1[i] - f0[i]) / sc.sk(i, y[i], y[i]);
    der2 += r * r;
  }
  der2 = std::sqrt(der2) / h;
  const double der12 = std::max(std::abs(der2), std::sqrt(dnf));
  const double h1 =
      der12 <= 1e-15 ? std::max(1e-6, std::abs(h) * 1e-3) : std::pow(0.01 / der12, 1.0 / Method::kOrder);
  return std::min({100.0 * std::abs(h), h1, hmax});
}

template <class Method>
class AdaptiveRk final : public Integrator {
 public:
  std::string_view name() const override { return Method::kName; }
  int order() const override { return Method::kOrder; }
  bool isAdaptive() const override { return true; }

 private:
  Status doIntegrate(const OdeSystem& sys, double t0, double t1, VecX& y, const IntegratorOptions& opt,
                     IntegrationStats& stats) override {
    const OdeRhs f = toFirstOrder(sys);
    const Eigen::Index n = y.size();
    Method m;
    m.resize(n);
    VecX k1 = VecX::Zero(n), y1(n);
    f(t0, y, k1);
    stats.rhsEvaluations += 1;
    if (auto s = checkRhsSize(name(), t0, k1, n); !s) return s;
    if (const Eigen::Index j = firstNonFinite(k1); j >= 0) return nonFiniteRhs(name(), t0, j);

    const ErrorScale sc{opt.rtol, opt.atol,
                        opt.atolPerComponent.size() > 0 ? &opt.atolPerComponent : nullptr};
    const double span = t1 - t0;
    const double hmax = opt.maxStep > 0 ? std::min(opt.maxStep, span) : span;
    constexpr double eps = std::numeric_limits<double>::epsilon();

    if (!opt.adaptive) return fixedSteps(f, m, t0, t1, y, k1, y1, sc, opt, stats);

    double h = opt.initialStep > 0 ? std::min(opt.initialStep, hmax)
                                   : initialStep<Method>(f, t0, y, k1, hmax, sc, y1, m.tmp, stats);
    double t = t0;
    double facOld = 1e-4;
    bool rejectedLast = false, lastNonFinite = false;
    std::int64_t attempts = 0;
    for (;;) {
      if (attempts >= opt.maxSteps) return tooManySteps(name(), t, opt.maxSteps);
      const double hmin = std::max(opt.minStep, 16.0 * eps * std::max(std::abs(t), std::abs(t1)));
      if (h < hmin) {
        std::string what = "step size underflow: h = " + fmt(h) + " < minimum " + fmt(hmin);
        if (lastNonFinite) {
          what += " after non-finite stages (the right-hand side returned NaN/Inf or the solution blows up)";
          return fail(ErrorCode::Unsupported, std::move(what), at(name(), t),
                      "check the right-hand side near this t for NaN/Inf and for a finite-time singularity");
        }
        return fail(
            ErrorCode::Unsupported, std::move(what), at(name(), t),
            "the problem is stiff (or singular near this t): use a stiff solver (cvode-bdf), or loosen "
            "rtol/atol");
      }
      bool last = false;
      double hs = h;
      if (t + 1.01 * hs >= t1) {
        hs = t1 - t;
        last = true;
      }
      ++attempts;
      const double err = m.attempt(f, t, hs, y, k1, y1, sc);
      stats.rhsEvaluations += Method::kAttemptEvals;
      if (!std::isfinite(err) || firstNonFinite(y1) >= 0) {
        stats.rejectedSteps += 1;
        lastNonFinite = true;
        rejectedLast = true;
        h = hs * Method::kFacMin;
        continue;
      }
      lastNonFinite = false;
      const double fac11 = std::pow(err, Method::kExpo);
      double fac = fac11 / std::pow(facOld, Method::kBeta);
      fac = std::max(1.0 / Method::kFacMax, std::min(1.0 / Method::kFacMin, fac / Method::kSafe));
      double hnew = hs / fac;
      if (err <= 1.0) {
        facOld = std::max(err, 1e-4);
        stats.rhsEvaluations += m.advance(f, last ? t1 : t + hs, y1, k1);
        y.swap(y1);
        t = last ? t1 : t + hs;
        stats.steps += 1;
        stats.lastStep = hs;
        stats.tReached = t;
        if (last) return ok();
        hnew = std::min(hnew, hmax);
        if (rejectedLast) hnew = std::min(hnew, hs);
        rejectedLast = false;
        h = hnew;
      } else {
        stats.rejectedSteps += 1;
        rejectedLast = true;
        h = hs / std::min(1.0 / Method::kFacMin, fac11 / Method::kSafe);
      }
    }
  }

  /// Fixed steps of size opt.h without error control (for order studies).
  Status fixedSteps(const OdeRhs& f, Method& m, double t0, double t1, VecX& y, VecX& k1, VecX& y1,
                    const ErrorScale& sc, const IntegratorOptions& opt, IntegrationStats& stats) {
    const std::int64_t steps = fixedStepCount(t1 - t0, opt.h);
    if (steps > opt.maxSteps) return tooManySteps(name(), t0, opt.maxSteps);
    for (std::int64_t i = 0; i < steps; ++i) {
      const double t = t0 + static_cast<double>(i) * opt.h;
      const double h = (i + 1 == steps) ? t1 - t : opt.h;
      const double tn = (i + 1 == steps) ? t1 : t + h;
      (void)m.attempt(f, t, h, y, k1, y1, sc);
      stats.rhsEvaluations += Method::kAttemptEvals;
      if (const Eigen::Index bad = firstNonFinite(y1); bad >= 0) return blowUp(name(), t, h, bad);
      stats.rhsEvaluations += m.advance(f, tn, y1, k1);
      y.swap(y1);
      stats.steps += 1;
      stats.lastStep = h;
      stats.tReached = tn;
    }
    return ok();
  }
};

constexpr std::array<std::string_view, 11> kNames = {
    "euler",     "symplectic-euler", "verlet",     "rk4",         "dopri5",     "dop853",
    "cvode-bdf", "cvode-adams",      "arkode-erk", "arkode-dirk", "arkode-ark",
};

bool finiteNonNegative(double v) { return std::isfinite(v) && v >= 0.0; }

}  // namespace

// ---------------------------------------------------------------------------
// Integrator (validation) and the factory

Status Integrator::integrate(const OdeSystem& sys, double t0, double t1, VecX& y,
                             const IntegratorOptions& opt, IntegrationStats* stats) {
  IntegrationStats local;
  IntegrationStats& st = stats ? *stats : local;
  st = IntegrationStats{};
  st.tReached = t0;
  const std::string where = at(name(), t0);
  auto bad = [&](std::string what, std::string hint) {
    return fail(ErrorCode::InvalidArgument, std::move(what), where, std::move(hint));
  };

  if (!std::isfinite(t0) || !std::isfinite(t1))
    return bad("t0 = " + fmt(t0) + ", t1 = " + fmt(t1) + " is not finite", "pass finite times");
  if (t1 < t0) return bad("t1 = " + fmt(t1) + " < t0 = " + fmt(t0), "integrate forward in time (t1 >= t0)");
  if (y.size() == 0)
    return bad("the state is empty", "pass the initial state y(t0) with at least one component");
  if (const Eigen::Index i = firstNonFinite(y); i >= 0)
    return bad("the initial state has NaN/Inf in component " + std::to_string(i),
               "pass a finite initial state");

  if (needsSecondOrder()) {
    if (!sys.acceleration)
      return bad(
          std::string(name()) + " integrates second-order systems but OdeSystem::acceleration is empty",
          "build the system with OdeSystem::secondOrder(a), state y = [x; v], or use rk4/dopri5");
    if (y.size() % 2 != 0)
      return bad("second-order state has odd size " + std::to_string(y.size()),
                 "pass y = [x; v] with x and v of equal size");
  } else {
    if (!sys.hasFirstOrderForm())
      return bad("the system has no right-hand side",
                 "set OdeSystem::rhs (or acceleration, or explicitRhs and implicitRhs)");
    if (!sys.rhs && !(sys.explicitRhs && sys.implicitRhs) && y.size() % 2 != 0)
      return bad("second-order state has odd size " + std::to_string(y.size()),
                 "pass y = [x; v] with x and v of equal size");
  }

  const bool fixed = !isAdaptive() || !opt.adaptive;
  if (fixed && !(std::isfinite(opt.h) && opt.h > 0.0))
    return bad("step h = " + fmt(opt.h) + " must be positive and finite for fixed steps",
               "set IntegratorOptions::h, e.g. to (t1 - t0) / 1000");
  if (isAdaptive()) {
    if (!(std::isfinite(opt.rtol) && opt.rtol > 0.0))
      return bad("rtol = " + fmt(opt.rtol) + " must be positive", "use e.g. rtol = 1e-6");
    if (opt.rtol < 10.0 * std::numeric_limits<double>::epsilon())
      return bad("rtol = " + fmt(opt.rtol) + " is below double round-off", "use rtol >= 1e-14");
    if (!finiteNonNegative(opt.atol))
      return bad("atol = " + fmt(opt.atol) + " must be >= 0 and finite", "use e.g. atol = 1e-9");
    if (opt.atolPerComponent.size() != 0) {
      if (opt.atolPerComponent.size() != y.size())
        return bad("atolPerComponent has size " + std::to_string(opt.atolPerComponent.size()) +
                       " but the state has size " + std::to_string(y.size()),
                   "give one absolute tolerance per state component, or leave it empty");
      for (Eigen::Index i = 0; i < y.size(); ++i)
        if (!finiteNonNegative(opt.atolPerComponent[i]))
          return bad("atolPerComponent[" + std::to_string(i) + "] = " + fmt(opt.atolPerComponent[i]) +
                         " must be >= 0 and finite",
                     "use non-negative absolute tolerances");
    }
  }
  if (!finiteNonNegative(opt.initialStep))
    return bad("initialStep = " + fmt(opt.initialStep) + " must be >= 0", "use 0 for automatic");
  if (!finiteNonNegative(opt.minStep))
    return bad("minStep = " + fmt(opt.minStep) + " must be >= 0", "use 0 for automatic");
  if (!finiteNonNegative(opt.maxStep))
    return bad("maxStep = " + fmt(opt.maxStep) + " must be >= 0", "use 0 for unbounded");
  if (opt.maxStep > 0.0 && opt.minStep > opt.maxStep)
    return bad("minStep = " + fmt(opt.minStep) + " > maxStep = " + fmt(opt.maxStep),
               "use minStep <= maxStep");
  if (opt.maxSteps <= 0)
    return bad("maxSteps = " + std::to_string(opt.maxSteps) + " must be positive",
               "use e.g. maxSteps = 100000");
  if (opt.krylovDimension < 0)
    return bad("krylovDimension = " + std::to_string(opt.krylovDimension) + " must be >= 0",
               "use 0 for the default");

  if (t1 == t0) return ok();
  return doIntegrate(sys, t0, t1, y, opt, st);
}

std::span<const std::string_view> integratorNames() { return kNames; }

Result<std::unique_ptr<Integrator>> makeIntegrator(std::string_view name) {
  std::unique_ptr<Integrator> p;
  if (name == "euler")
    p = std::make_unique<EulerIntegrator>();
  else if (name == "symplectic-euler")
    p = std::make_unique<SymplecticEulerIntegrator>();
  else if (name == "verlet")
    p = std::make_unique<VerletIntegrator>();
  else if (name == "rk4")
    p = std::make_unique<Rk4Integrator>();
  else if (name == "dopri5")
    p = std::make_unique<AdaptiveRk<Dopri5>>();
  else if (name == "dop853")
    p = std::make_unique<AdaptiveRk<Dop853>>();
  else
    p = makeSundialsIntegrator(name);
  if (p) return p;
  std::string list;
  for (std::string_view n : kNames) {
    if (!list.empty()) list += ", ";
    list += n;
  }
  return fail(ErrorCode::NotFound, "unknown integrator \"" + std::string(name) + "\"", "makeIntegrator",
              "use one of: " + list);
}

}  // namespace dm
