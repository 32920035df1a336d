// dm/math/integrators.hpp — ODE integrators behind one interface.
//
// First-order systems y' = f(t, y) (y a VecX) and second-order mechanical
// systems x'' = a(t, x, v) (integrated as y = [x; v]) are described by an
// OdeSystem. An Integrator advances a state from t0 to t1 under
// IntegratorOptions and reports IntegrationStats. Methods, by factory name:
//
//   name              order  kind
//   euler               1    explicit Euler, fixed step
//   symplectic-euler    1    semi-implicit Euler, fixed step, second-order systems
//   verlet              2    velocity Verlet, fixed step, second-order systems
//   rk4                 4    classic Runge–Kutta, fixed step
//   dopri5              5    Dormand–Prince 5(4), adaptive (FSAL, PI control)
//   dop853              8    Hairer's DOP853 8(5,3), adaptive
//   cvode-bdf         1..5   SUNDIALS CVODE, BDF + Newton (stiff)       — sundials.hpp
//   cvode-adams       1..12  SUNDIALS CVODE, Adams–Moulton (non-stiff)  — sundials.hpp
//   arkode-erk          4    SUNDIALS ARKODE ERKStep, adaptive explicit  — sundials.hpp
//   arkode-dirk         4    SUNDIALS ARKODE ARKStep, implicit (stiff)   — sundials.hpp
//   arkode-ark          4    SUNDIALS ARKODE ARKStep, ImEx (split rhs)   — sundials.hpp
//
// Failures are dm::Status errors (never exceptions): InvalidArgument for bad
// options, systems or states; Unsupported when the method cannot integrate
// the problem (step-size underflow, blow-up to NaN/Inf, Newton failure);
// Timeout when maxSteps is exceeded; Internal for an allocation failure
// inside SUNDIALS. Each message says what failed, where (method and t) and
// what to do.
//
// For real-time loops the fixed-step methods are also free functions taking
// a caller-owned workspace (eulerStep, rk4Step, symplecticEulerStep,
// velocityVerletStep); they allocate nothing once the workspace is sized.
//
// @code
//   auto rk = dm::makeIntegrator("dopri5");
//   dm::VecX y(1); y << 1.0;
//   auto st = (*rk)->integrate(dm::OdeSystem::firstOrder([](double, const dm::VecX& y, dm::VecX& d) { d = -y;
//   }),
//                              0.0, 1.0, y, {.rtol = 1e-8, .atol = 1e-10});
// @endcode
#pragma once

#include <dm/core/result.hpp>
#include <dm/math/types.hpp>

#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string_view>

namespace dm {

/// Right-hand side of y' = f(t, y). `dydt` arrives sized like `y`; write
/// every component. Must not resize `dydt`.
using OdeRhs = std::function<void(double t, const VecX& y, VecX& dydt)>;

/// Jacobian J = ∂f/∂y (n×n) at (t, y). `J` arrives sized n×n; write every entry.
using OdeJacobian = std::function<void(double t, const VecX& y, MatX& J)>;

/// Jacobian-vector product Jv = (∂f/∂y)(t, y) · v, for matrix-free Krylov
/// (GMRES) solves. `Jv` arrives sized like `v`.
using OdeJacobianTimes = std::function<void(double t, const VecX& y, const VecX& v, VecX& Jv)>;

/// Acceleration of a second-order system x'' = a(t, x, v): positions `x`
/// and velocities `v` (both size m) → `acc` (arrives sized m).
using SecondOrderRhs = std::function<void(double t, const VecX& x, const VecX& v, VecX& acc)>;

/// An ODE system. Fill one of: `rhs` (first order), `acceleration` (second
/// order; the state is y = [x; v] of size 2m), or `explicitRhs` + `implicitRhs`
/// (an additive split f = fE + fI for ImEx methods). Methods take what they
/// need from it: first-order methods use `rhs`, else fE + fI, else the
/// first-order form [v; a(t, x, v)] of `acceleration`; symplectic methods
/// need `acceleration`; arkode-ark needs the split. Optional Jacobians are
/// used by the implicit (SUNDIALS) methods; without them those fall back to
/// difference quotients.
struct OdeSystem {
  OdeRhs rhs;                      ///< f(t, y), first-order systems
  OdeJacobian jacobian;            ///< ∂f/∂y of the full f (optional)
  OdeJacobianTimes jacobianTimes;  ///< (∂f/∂y)·v of the full f, for GMRES (optional)
  SecondOrderRhs acceleration;     ///< a(t, x, v), second-order systems
  OdeRhs explicitRhs;              ///< fE: non-stiff part of a split system
  OdeRhs implicitRhs;              ///< fI: stiff part of a split system
  OdeJacobian implicitJacobian;    ///< ∂fI/∂y (optional), used by arkode-ark

  /// y' = f(t, y), with an optional Jacobian ∂f/∂y.
  static OdeSystem firstOrder(OdeRhs f, OdeJacobian jac = {});
  /// x'' = a(t, x, v); states are y = [x; v].
  static OdeSystem secondOrder(SecondOrderRhs a);
  /// y' = fE(t, y) + fI(t, y), fE non-stiff (explicit), fI stiff (implicit),
  /// with an optional ∂fI/∂y.
  static OdeSystem split(OdeRhs fExplicit, OdeRhs fImplicit, OdeJacobian implicitJac = {});

  /// True when some form of first-order right-hand side is available.
  bool hasFirstOrderForm() const { return rhs || (explicitRhs && implicitRhs) || acceleration; }
};

/// The first-order right-hand side of `sys`, as described on OdeSystem
/// (`rhs`, else fE + fI, else [v; a(t, x, v)]); empty when the system is
/// empty. The adapters allocate their temporaries once, on first call.
OdeRhs toFirstOrder(const OdeSystem& sys);

/// Linear solver for the Newton iterations of implicit methods.
enum class LinearSolverKind : std::uint8_t {
  Dense,  ///< dense LU on the n×n Newton matrix (user Jacobian or difference quotients)
  Gmres,  ///< matrix-free SPGMR, unpreconditioned (user J·v, user J, or difference quotients)
};

/// Options for Integrator::integrate. Fields not used by a method are ignored.
struct IntegratorOptions {
  /// Step [time units] of the fixed-step methods, and of the adaptive ones
  /// when `adaptive` is false; must be > 0 there.
  double h = 0.0;
  /// Relative tolerance of the adaptive methods; > 0 (and >= 10 ε).
  double rtol = 1e-6;
  /// Absolute tolerance of the adaptive methods; >= 0.
  double atol = 1e-9;
  /// Per-component absolute tolerances (size n, each >= 0), for states that
  /// mix units; overrides `atol` when non-empty.
  VecX atolPerComponent;
  /// First trial step of the adaptive methods; 0: estimated automatically.
  double initialStep = 0.0;
  /// Smallest step before failing; 0: set by round-off (16 ε |t|).
  double minStep = 0.0;
  /// Largest step; 0: unbounded.
  double maxStep = 0.0;
  /// Step limit for the whole interval (dopri5/dop853 count rejected
  /// attempts too); exceeding it fails with ErrorCode::Timeout.
  std::int64_t maxSteps = 100000;
  /// false: adaptive methods take fixed steps of size h without error
  /// control (order studies, reproducible cost). Not available for CVODE.
  bool adaptive = true;
  /// Linear solver of the implicit methods (cvode-bdf, arkode-dirk, arkode-ark).
  LinearSolverKind linearSolver = LinearSolverKind::Dense;
  /// GMRES Krylov subspace size; 0: SUNDIALS' default (5).
  int krylovDimension = 0;
};

/// Counters of one integrate() call (reset at its start, filled also on failure).
struct IntegrationStats {
  std::int64_t steps = 0;                ///< accepted steps
  std::int64_t rejectedSteps = 0;        ///< rejected attempts (error test or Newton failures)
  std::int64_t rhsEvaluations = 0;       ///< rhs / acceleration evaluations (arkode-ark: fE calls + fI calls)
  std::int64_t jacobianEvaluations = 0;  ///< Jacobian evaluations (user or difference quotient)
  std::int64_t nonlinearIterations = 0;  ///< Newton / fixed-point iterations of implicit methods
  std::int64_t linearIterations = 0;     ///< Krylov iterations (GMRES)
  double lastStep = 0.0;                 ///< size of the last accepted step
  double tReached = 0.0;                 ///< time of the returned state (t1 on success)
};

/// An ODE integration method. Public non-virtual integrate() validates the
/// call, then delegates to the method. Integrators keep no state between
/// calls (workspaces are per call), so one instance may serve several
/// threads at once.
class Integrator {
 public:
  virtual ~Integrator() = default;
  /// Factory name ("rk4", "cvode-bdf", ...).
  virtual std::string_view name() const = 0;
  /// Order of accuracy (the maximum order for variable-order methods).
  virtual int order() const = 0;
  /// True when the method controls its step size from an error estimate.
  virtual bool isAdaptive() const = 0;
  /// True when the method needs OdeSystem::acceleration (symplectic methods).
  virtual bool needsSecondOrder() const { return false; }

  /// Advances `y` from t0 to t1 (t1 >= t0; t1 == t0 is a no-op). Fixed-step
  /// methods take ceil((t1 - t0)/h) steps, the last one shortened to land on
  /// t1. `stats` (optional) is reset and filled, also on failure. On failure
  /// `y` holds the last accepted state, at stats->tReached. Cost: O(steps ·
  /// stages · (rhs + n)) for explicit methods, plus Newton solves for
  /// implicit ones.
  /// @code
  ///   dm::IntegrationStats s;
  ///   auto st = integrator.integrate(sys, 0.0, 10.0, y, {.h = 1e-3}, &s);
  ///   if (!st) std::cerr << st.error() << '\n';
  /// @endcode
  Status integrate(const OdeSystem& sys, double t0, double t1, VecX& y, const IntegratorOptions& opt = {},
                   IntegrationStats* stats = nullptr);

 private:
  /// Method body; called with validated arguments, t1 > t0, `stats` reset and non-null.
  virtual Status doIntegrate(const OdeSystem& sys, double t0, double t1, VecX& y,
                             const IntegratorOptions& opt, IntegrationStats& stats) = 0;
};

/// The integrator registered under `name` (see the table at the top of this
/// header). Fails with NotFound on an unknown name; the message lists the
/// valid names.
/// @code
///   auto integ = dm::makeIntegrator("verlet");
///   if (!integ) return integ.error();
/// @endcode
Result<std::unique_ptr<Integrator>> makeIntegrator(std::string_view name);

/// All names makeIntegrator accepts, in the order of the table above.
std::span<const std::string_view> integratorNames();

// ---------------------------------------------------------------------------
// Single steps for real-time loops. No validation, no allocation once the
// workspace has the right size (it is resized on first use), no NaN checks.

/// Workspace of eulerStep: one derivative vector.
struct EulerWorkspace {
  VecX dydt;
};

/// One explicit Euler step y ← y + h f(t, y). One rhs evaluation.
/// @code
///   dm::EulerWorkspace ws;
///   for (int i = 0; i < n; ++i) dm::eulerStep(f, i * h, h, y, ws);
/// @endcode
void eulerStep(const OdeRhs& f, double t, double h, VecX& y, EulerWorkspace& ws);

/// Workspace of rk4Step: four stage derivatives and a stage state.
struct Rk4Workspace {
  VecX k1, k2, k3, k4, tmp;
  /// Sizes every vector to n (no-op when already sized).
  void resize(Eigen::Index n);
};

/// One classic fourth-order Runge–Kutta step. Four rhs evaluations.
/// @code
///   dm::Rk4Workspace ws;
///   for (int i = 0; i < n; ++i) dm::rk4Step(f, i * h, h, y, ws);
/// @endcode
void rk4Step(const OdeRhs& f, double t, double h, VecX& y, Rk4Workspace& ws);

/// Workspace of the second-order steppers. `acc` holds a(t, x, v) at the
/// start of the next step when `accelerationValid` (velocity Verlet reuses
/// its end-of-step acceleration); call invalidate() after changing x or v
/// outside the stepper (contacts, teleports, parameter changes).
struct SecondOrderWorkspace {
  VecX acc;      ///< a(t, x, v) at the start of the next step (when accelerationValid)
  VecX accNext;  ///< scratch: end-of-step acceleration
  VecX vPred;    ///< scratch: predicted end-of-step velocity
  bool accelerationValid = false;
  void invalidate() { accelerationValid = false; }
};

/// One semi-implicit (symplectic) Euler step: v ← v + h a(t, x, v), then
/// x ← x + h v. Order 1, symplectic for a = a(x). One acceleration evaluation.
/// @code
///   dm::SecondOrderWorkspace ws;
///   dm::symplecticEulerStep(a, t, h, x, v, ws);
/// @endcode
void symplecticEulerStep(const SecondOrderRhs& a, double t, double h, VecX& x, VecX& v,
                         SecondOrderWorkspace& ws);

/// One velocity Verlet (kick-drift-kick) step. Order 2; symplectic and
/// time-reversible for a = a(x). For velocity-dependent forces the end
/// acceleration uses the predicted velocity v + h a0, which keeps order 2.
/// One acceleration evaluation per step when ws.accelerationValid, two otherwise.
/// @code
///   dm::SecondOrderWorkspace ws;
///   dm::velocityVerletStep(a, t, h, x, v, ws);
/// @endcode
void velocityVerletStep(const SecondOrderRhs& a, double t, double h, VecX& x, VecX& v,
                        SecondOrderWorkspace& ws);

}  // namespace dm
