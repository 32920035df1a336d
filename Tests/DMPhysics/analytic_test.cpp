// Analytic checks of PhysicsWorld (dm/physics/world.hpp): trajectories,
// periods and conservation laws against closed-form solutions.
#include <dm/physics/world.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <vector>

namespace {

using dm::BodyId;
using dm::BodyKind;
using dm::IntegratorKind;
using dm::PhysicsWorld;
using dm::Vec3;
using dm::WorldState;

constexpr double kPi = std::numbers::pi;

BodyId addParticle(PhysicsWorld& w, double mass, const Vec3& x, const Vec3& v, IntegratorKind integ) {
  dm::BodyDesc d;
  d.kind = BodyKind::Particle;
  d.mass = mass;
  d.position = x;
  d.linearVelocity = v;
  d.integrator = integ;
  auto id = w.addBody(d);
  EXPECT_TRUE(id.ok());
  return *id;
}

BodyId addStatic(PhysicsWorld& w, const Vec3& x) {
  dm::BodyDesc d;
  d.kind = BodyKind::Static;
  d.position = x;
  auto id = w.addBody(d);
  EXPECT_TRUE(id.ok());
  return *id;
}

void stepN(const PhysicsWorld& w, WorldState& s, double dt, int n) {
  for (int i = 0; i < n; ++i) ASSERT_TRUE(w.step(s, dt).ok());
}

// Range of a projectile on flat ground: R = v0² sin 2θ / g. The landing point
// is interpolated linearly between the two steps around z = 0.
double projectileRange(IntegratorKind integ, double dt) {
  PhysicsWorld w;
  const double v0 = 20.0, theta = kPi / 4;
  const BodyId p = addParticle(w, 0.5, Vec3::Zero(), {v0 * std::cos(theta), 0, v0 * std::sin(theta)}, integ);
  EXPECT_TRUE(w.setGravity({0, 0, -9.81}).ok());
  WorldState s = w.makeState();
  Vec3 prev = s.position(p);
  for (int i = 0; i < 1000000; ++i) {
    EXPECT_TRUE(w.step(s, dt).ok());
    const Vec3 x = s.position(p);
    if (x.z() < 0) return prev.x() + (x.x() - prev.x()) * prev.z() / (prev.z() - x.z());
    prev = x;
  }
  return -1;
}

TEST(PhysicsAnalytic, ProjectileRangeMatchesClosedForm) {
  const double exact = 20.0 * 20.0 / 9.81;  // sin(90°) = 1
  // Verlet and RK4 are exact for constant acceleration; only the linear
  // interpolation of the landing point errs (≈ g dt² / (8 v_z) · v_x).
  EXPECT_NEAR(projectileRange(IntegratorKind::Rk4, 1e-3), exact, 1e-5 * exact);
  EXPECT_NEAR(projectileRange(IntegratorKind::VelocityVerlet, 1e-3), exact, 1e-5 * exact);
  // Symplectic Euler is first order: the error is ≈ v_x dt / 2 ≈ 7 mm here.
  const double se = projectileRange(IntegratorKind::SymplecticEuler, 1e-3);
  EXPECT_NEAR(se, exact, 1e-3 * exact);
  EXPECT_GT(std::abs(se - exact), 1e-6 * exact);  // and it is first order, not exact
}

// m ẍ = −k ẋ + m g: with τ = m/k and v∞ = g τ,
// v(t) = v∞ + (v0 − v∞) e^{−t/τ},  x(t) = x0 + v∞ t + (v0 − v∞) τ (1 − e^{−t/τ}).
TEST(PhysicsAnalytic, ProjectileWithLinearDragMatchesClosedForm) {
  const double m = 0.2, k = 0.15, dt = 1e-3, T = 2.0;
  const Vec3 g(0, 0, -9.81), v0(15, 0, 12);
  for (IntegratorKind integ : {IntegratorKind::Rk4, IntegratorKind::VelocityVerlet}) {
    PhysicsWorld w;
    const BodyId p = addParticle(w, m, Vec3::Zero(), v0, integ);
    ASSERT_TRUE(w.setGravity(g).ok());
    ASSERT_TRUE(w.addDrag({.body = p, .linear = k}).ok());
    WorldState s = w.makeState();
    stepN(w, s, dt, static_cast<int>(std::lround(T / dt)));
    const double tau = m / k;
    const Vec3 vInf = g * tau;
    const double e = std::exp(-s.time() / tau);
    const Vec3 v = vInf + (v0 - vInf) * e;
    const Vec3 x = vInf * s.time() + (v0 - vInf) * tau * (1 - e);
    // RK4: O(dt⁴) ≈ 1e-12 relative; Verlet with predicted velocity: O(dt²).
    const double tol = integ == IntegratorKind::Rk4 ? 1e-9 : 1e-5;
    EXPECT_LT((s.position(p) - x).norm(), tol * x.norm()) << dm::toString(integ);
    EXPECT_LT((s.linearVelocity(p) - v).norm(), tol * v.norm()) << dm::toString(integ);
  }
}

// Fall from rest with quadratic drag c v²: v(t) = v_t tanh(g t / v_t),
// z(t) = −(v_t² / g) ln cosh(g t / v_t), v_t = √(m g / c).
TEST(PhysicsAnalytic, FallWithQuadraticDragReachesTerminalVelocity) {
  const double m = 0.3, c = 0.02, g = 9.81, dt = 1e-3, T = 3.0;
  PhysicsWorld w;
  const BodyId p = addParticle(w, m, Vec3::Zero(), Vec3::Zero(), IntegratorKind::Rk4);
  ASSERT_TRUE(w.setGravity({0, 0, -g}).ok());
  ASSERT_TRUE(w.addDrag({.body = p, .quadratic = c}).ok());
  WorldState s = w.makeState();
  stepN(w, s, dt, static_cast<int>(std::lround(T / dt)));
  const double vt = std::sqrt(m * g / c);
  const double t = s.time();
  EXPECT_NEAR(s.linearVelocity(p).z(), -vt * std::tanh(g * t / vt), 1e-9 * vt);
  EXPECT_NEAR(s.position(p).z(), -(vt * vt / g) * std::log(std::cosh(g * t / vt)), 1e-9 * vt * t);
}

// Times of the upward zero crossings of f, linearly interpolated.
struct CrossingRecorder {
  std::vector<double> times;
  double prevT = 0, prevF = 0;
  bool first = true;
  void add(double t, double f) {
    if (!first && prevF < 0 && f >= 0) times.push_back(prevT + (t - prevT) * (-prevF) / (f - prevF));
    prevT = t;
    prevF = f;
    first = false;
  }
  double meanPeriod() const { return (times.back() - times.front()) / double(times.size() - 1); }
};

// Mass on a spring (rest length 0.3 m) to a fixed point: T = 2π √(m/k).
TEST(PhysicsAnalytic, SpringMassFrequency) {
  const double m = 0.4, k = 250.0, L0 = 0.3, A = 0.02, dt = 1e-4;
  PhysicsWorld w;
  const BodyId anchor = addStatic(w, Vec3::Zero());
  const BodyId p = addParticle(w, m, {L0 + A, 0, 0}, Vec3::Zero(), IntegratorKind::VelocityVerlet);
  ASSERT_TRUE(w.addSpring({.a = anchor, .b = p, .stiffness = k, .restLength = L0}).ok());
  WorldState s = w.makeState();
  const double T = 2 * kPi * std::sqrt(m / k);
  CrossingRecorder rec;
  while (s.time() < 6.2 * T) {
    ASSERT_TRUE(w.step(s, dt).ok());
    rec.add(s.time(), s.position(p).x() - L0);
  }
  ASSERT_GE(rec.times.size(), 5u);
  // Verlet's frequency error is (ω dt)² / 24 ≈ 2e-6 here.
  EXPECT_NEAR(rec.meanPeriod(), T, 1e-4 * T);
}

// Pendulum: a particle on a very stiff spring (rest length L) to a fixed
// point. Small-angle period 2π √(L_eff / g) (1 + θ0²/16), L_eff = L + m g / k.
TEST(PhysicsAnalytic, StiffSpringPendulumPeriod) {
  const double m = 1.0, L = 1.0, g = 9.81, k = 1e5, theta0 = 0.05, dt = 2e-4;
  const double Leff = L + m * g / k;
  PhysicsWorld w;
  const BodyId pivot = addStatic(w, Vec3::Zero());
  const BodyId bob = addParticle(w, m, {Leff * std::sin(theta0), 0, -Leff * std::cos(theta0)}, Vec3::Zero(),
                                 IntegratorKind::VelocityVerlet);
  ASSERT_TRUE(w.setGravity({0, 0, -g}).ok());
  ASSERT_TRUE(w.addSpring({.a = pivot, .b = bob, .stiffness = k, .restLength = L}).ok());
  WorldState s = w.makeState();
  const double T = 2 * kPi * std::sqrt(Leff / g) * (1 + theta0 * theta0 / 16);
  CrossingRecorder rec;
  while (s.time() < 2.3 * T) {
    ASSERT_TRUE(w.step(s, dt).ok());
    rec.add(s.time(), s.position(bob).x());
  }
  ASSERT_EQ(rec.times.size(), 2u);
  // Stated tolerance: 0.05 % (the radial spring mode and θ0⁴ terms are far smaller).
  EXPECT_NEAR(rec.times[1] - rec.times[0], T, 5e-4 * T);
}

// Damped oscillator m ẍ + c ẋ + k x = 0 (a zero-rest-length spring-damper):
// logarithmic decrement δ = ln(x_n / x_{n+1}) = 2π ζ / √(1 − ζ²), ζ = c / (2√(km)).
TEST(PhysicsAnalytic, DampedOscillatorLogDecrement) {
  const double m = 1.0, k = 100.0, c = 0.4, dt = 1e-3;
  PhysicsWorld w;
  const BodyId anchor = addStatic(w, Vec3::Zero());
  const BodyId p = addParticle(w, m, {0.1, 0, 0}, Vec3::Zero(), IntegratorKind::Rk4);
  ASSERT_TRUE(w.addSpring({.a = anchor, .b = p, .stiffness = k, .damping = c}).ok());
  WorldState s = w.makeState();
  std::vector<double> peaks;
  double x0 = s.position(p).x(), x1 = x0;
  for (int i = 0; i < 6000 && peaks.size() < 6; ++i) {
    ASSERT_TRUE(w.step(s, dt).ok());
    const double x2 = s.position(p).x();
    if (i > 0 && x1 > x0 && x1 >= x2) {
      // Parabola through three samples: the peak value without sampling error.
      const double a = 0.5 * (x0 - 2 * x1 + x2), b = 0.5 * (x2 - x0);
      peaks.push_back(x1 - b * b / (4 * a));
    }
    x0 = x1;
    x1 = x2;
  }
  ASSERT_EQ(peaks.size(), 6u);
  const double zeta = c / (2 * std::sqrt(k * m));
  const double delta = 2 * kPi * zeta / std::sqrt(1 - zeta * zeta);
  const double measured = std::log(peaks.front() / peaks.back()) / double(peaks.size() - 1);
  EXPECT_NEAR(measured, delta, 2e-3 * delta);
}

// Torque-free asymmetric rigid body with a full (non-diagonal) inertia
// tensor: kinetic energy and world angular momentum are conserved, while ω
// itself precesses.
TEST(PhysicsAnalytic, TorqueFreePrecessionConservesEnergyAndMomentum) {
  const dm::Mat3 axes = dm::AngleAxis(0.7, Vec3(1, 2, 3).normalized()).toRotationMatrix();
  const dm::Mat3 inertia = axes * Vec3(1.0, 2.0, 2.6).asDiagonal() * axes.transpose();
  for (IntegratorKind integ : {IntegratorKind::SymplecticEuler, IntegratorKind::Rk4}) {
    PhysicsWorld w;
    dm::BodyDesc d;
    d.kind = BodyKind::Rigid;
    d.integrator = integ;
    d.mass = 2.0;
    d.inertia = inertia;
    d.orientation = dm::Quat(dm::AngleAxis(0.4, Vec3(0, 1, 1).normalized()));
    d.angularVelocity = Vec3(1.5, -2.0, 2.5);
    auto id = w.addBody(d);
    ASSERT_TRUE(id.ok());
    WorldState s = w.makeState();
    const double e0 = w.kineticEnergy(s);
    const Vec3 l0 = w.angularMomentum(s, s.position(*id));
    const Vec3 w0 = s.angularVelocity(*id);
    double maxDe = 0, maxDl = 0, maxDw = 0;
    for (int i = 0; i < 10000; ++i) {
      ASSERT_TRUE(w.step(s, 1e-3).ok());
      maxDe = std::max(maxDe, std::abs(w.kineticEnergy(s) - e0));
      maxDl = std::max(maxDl, (w.angularMomentum(s, s.position(*id)) - l0).norm());
      maxDw = std::max(maxDw, (s.angularVelocity(*id) - w0).norm());
    }
    EXPECT_LT(maxDe, 1e-8 * e0) << dm::toString(integ);
    EXPECT_LT(maxDl, 1e-8 * l0.norm()) << dm::toString(integ);
    EXPECT_NEAR(s.orientation(*id).norm(), 1.0, 1e-14);
    // The motion is not trivial: ω wandered far from its start.
    EXPECT_GT(maxDw, 0.5 * w0.norm()) << dm::toString(integ);
  }
}

// Two bodies on a circular orbit about their centre of mass return to their
// start after T = 2π √(r³ / (G (m1 + m2))).
TEST(PhysicsAnalytic, NewtonianTwoBodyCircularOrbitPeriod) {
  const double G = 1.0, m1 = 1.0, m2 = 0.5, r = 1.0, M = m1 + m2;
  const double omega = std::sqrt(G * M / (r * r * r)), T = 2 * kPi / omega;
  for (IntegratorKind integ : {IntegratorKind::Rk4, IntegratorKind::VelocityVerlet}) {
    PhysicsWorld w;
    const double r1 = r * m2 / M, r2 = r * m1 / M;
    const BodyId a = addParticle(w, m1, {r1, 0, 0}, {0, omega * r1, 0}, integ);
    const BodyId b = addParticle(w, m2, {-r2, 0, 0}, {0, -omega * r2, 0}, integ);
    ASSERT_TRUE(w.addNewtonianGravity({.gravitationalConstant = G}).ok());
    WorldState s = w.makeState();
    const int n = 2000;
    double maxDr = 0;
    for (int i = 0; i < n; ++i) {
      ASSERT_TRUE(w.step(s, T / n).ok());
      maxDr = std::max(maxDr, std::abs((s.position(a) - s.position(b)).norm() - r));
    }
    const double tol = integ == IntegratorKind::Rk4 ? 1e-9 : 1e-4;
    EXPECT_LT((s.position(a) - Vec3(r1, 0, 0)).norm(), tol * r) << dm::toString(integ);
    EXPECT_LT((s.position(b) - Vec3(-r2, 0, 0)).norm(), tol * r) << dm::toString(integ);
    EXPECT_LT(maxDr, tol * r) << dm::toString(integ);
    // Newton's third law: the pair forces cancel, total momentum stays zero.
    EXPECT_LT(w.linearMomentum(s).norm(), 1e-12);
  }
}

}  // namespace
