// SUNDIALS 6 (CVODE, ARKODE) behind dm::Integrator. Every SUNDIALS object
// lives in a Session whose destructor frees it on every path; callbacks
// never let an exception or a bad output cross into C.
#include <dm/math/sundials.hpp>

#include <arkode/arkode_arkstep.h>
#include <arkode/arkode_erkstep.h>
#include <cvode/cvode.h>
#include <cvode/cvode_ls.h>
#include <nvector/nvector_serial.h>
#include <sundials/sundials_context.h>
#include <sunlinsol/sunlinsol_dense.h>
#include <sunlinsol/sunlinsol_spgmr.h>
#include <sunmatrix/sunmatrix_dense.h>

#include <sunnonlinsol/sunnonlinsol_fixedpoint.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <string>
#include <utility>

#include "math_internal.hpp"

namespace dm {
namespace {

using detail::firstNonFinite;
using detail::fmt;

enum class Method { CvodeBdf, CvodeAdams, ArkodeErk, ArkodeDirk, ArkodeArk };

/// What the callbacks see (SUNDIALS user data), and what they report back.
struct Callbacks {
  OdeRhs f;              // full rhs (CVODE, ERK, DIRK) or fE (ARK)
  OdeRhs fi;             // fI (ARK only)
  OdeJacobian jac;       // ∂f/∂y of the implicitly treated function
  OdeJacobianTimes jtv;  // (∂f/∂y)·v of it
  Eigen::Index n = 0;
  VecX y, dydt, v, jv;
  MatX J;
  std::int64_t rhsCalls = 0;
  std::int64_t userJacCalls = 0;
  // First failure detected inside a callback (kept: later ones are consequences).
  bool failed = false;
  ErrorCode failCode = ErrorCode::InvalidArgument;
  std::string failWhat, failHint;
  double failT = 0;
  // Last error message of SUNDIALS' error handler.
  std::string sundialsMessage;

  void record(ErrorCode code, double t, std::string what, std::string hint) {
    if (failed) return;
    failed = true;
    failCode = code;
    failT = t;
    failWhat = std::move(what);
    failHint = std::move(hint);
  }
};

Callbacks& cbOf(void* p) { return *static_cast<Callbacks*>(p); }

Eigen::Map<VecX> view(N_Vector v, Eigen::Index n) { return {N_VGetArrayPointer(v), n}; }

/// Calls a user function, turning an exception into a recorded failure.
template <class Fn>
bool guarded(Callbacks& cb, double t, const char* what, Fn&& fn) {
  try {
    fn();
    return true;
  } catch (const std::exception& e) {
    cb.record(ErrorCode::InvalidArgument, t, std::string(what) + " threw: " + e.what(),
              "do not throw from ODE callbacks; dm integrators report failures as dm::Status");
  } catch (...) {
    cb.record(ErrorCode::InvalidArgument, t, std::string(what) + " threw a non-std exception",
              "do not throw from ODE callbacks; dm integrators report failures as dm::Status");
  }
  return false;
}

/// Shared body of the rhs callbacks: 0 ok, 1 recoverable (NaN/Inf: SUNDIALS
/// retries with a smaller step), -1 unrecoverable.
int evalRhs(const OdeRhs& f, sunrealtype t, N_Vector y, N_Vector ydot, Callbacks& cb) {
  cb.y = view(y, cb.n);
  cb.dydt.resize(cb.n);
  ++cb.rhsCalls;
  if (!guarded(cb, t, "the right-hand side", [&] { f(t, cb.y, cb.dydt); })) return -1;
  if (cb.dydt.size() != cb.n) {
    cb.record(ErrorCode::InvalidArgument, t,
              "the right-hand side resized its output to " + std::to_string(cb.dydt.size()) +
                  " for a state of size " + std::to_string(cb.n),
              "write every component of dydt without resizing it");
    return -1;
  }
  if (const Eigen::Index i = firstNonFinite(cb.dydt); i >= 0) {
    // Recoverable; recorded only if SUNDIALS gives up (cleared on success below).
    cb.failWhat = "the right-hand side returned NaN/Inf (component " + std::to_string(i) + ")";
    cb.failT = t;
    return 1;
  }
  view(ydot, cb.n) = cb.dydt;
  return 0;
}

int rhsFull(sunrealtype t, N_Vector y, N_Vector ydot, void* ud) {
  return evalRhs(cbOf(ud).f, t, y, ydot, cbOf(ud));
}
int rhsImplicit(sunrealtype t, N_Vector y, N_Vector ydot, void* ud) {
  return evalRhs(cbOf(ud).fi, t, y, ydot, cbOf(ud));
}

/// Evaluates the user Jacobian into cb.J; false (recorded) on failure.
bool evalJacobian(Callbacks& cb, sunrealtype t, N_Vector y) {
  cb.y = view(y, cb.n);
  cb.J.resize(cb.n, cb.n);
  ++cb.userJacCalls;
  if (!guarded(cb, t, "the Jacobian", [&] { cb.jac(t, cb.y, cb.J); })) return false;
  if (cb.J.rows() != cb.n || cb.J.cols() != cb.n) {
    cb.record(ErrorCode::InvalidArgument, t,
              "the Jacobian resized its output to " + std::to_string(cb.J.rows()) + "x" +
                  std::to_string(cb.J.cols()) + " for a state of size " + std::to_string(cb.n),
              "write every entry of the n x n matrix J without resizing it");
    return false;
  }
  if (!cb.J.allFinite()) {
    cb.failWhat = "the Jacobian has NaN/Inf entries";
    cb.failT = t;
    return false;
  }
  return true;
}

int denseJacobian(sunrealtype t, N_Vector y, N_Vector, SUNMatrix Jm, void* ud, N_Vector, N_Vector, N_Vector) {
  Callbacks& cb = cbOf(ud);
  if (!evalJacobian(cb, t, y)) return cb.failed ? -1 : 1;
  Eigen::Map<MatX>(SUNDenseMatrix_Data(Jm), cb.n, cb.n) = cb.J;
  return 0;
}

// GMRES with a user dense Jacobian: evaluate J at setup, multiply per iteration.
int jtSetupFromJacobian(sunrealtype t, N_Vector y, N_Vector, void* ud) {
  Callbacks& cb = cbOf(ud);
  if (!evalJacobian(cb, t, y)) return cb.failed ? -1 : 1;
  return 0;
}

int jtTimesFromJacobian(N_Vector v, N_Vector Jv, sunrealtype, N_Vector, N_Vector, void* ud, N_Vector) {
  Callbacks& cb = cbOf(ud);
  view(Jv, cb.n).noalias() = cb.J * view(v, cb.n);
  return 0;
}

// GMRES with a user Jacobian-vector product.
int jtTimesUser(N_Vector v, N_Vector Jv, sunrealtype t, N_Vector y, N_Vector, void* ud, N_Vector) {
  Callbacks& cb = cbOf(ud);
  cb.y = view(y, cb.n);
  cb.v = view(v, cb.n);
  cb.jv.resize(cb.n);
  if (!guarded(cb, t, "the Jacobian-vector product", [&] { cb.jtv(t, cb.y, cb.v, cb.jv); })) return -1;
  if (cb.jv.size() != cb.n) {
    cb.record(ErrorCode::InvalidArgument, t, "the Jacobian-vector product resized its output",
              "write every component of Jv without resizing it");
    return -1;
  }
  if (firstNonFinite(cb.jv) >= 0) {
    cb.failWhat = "the Jacobian-vector product returned NaN/Inf";
    cb.failT = t;
    return 1;
  }
  view(Jv, cb.n) = cb.jv;
  return 0;
}

/// Keeps SUNDIALS' error text for the dm::Error (and off stderr). Warnings
/// (code > 0, e.g. "t + h = t") are not failures and are dropped.
void errorHandler(int code, const char* module, const char* function, char* msg, void* ud) {
  if (code < 0) cbOf(ud).sundialsMessage = std::string(module) + "/" + function + ": " + msg;
}

/// Owns every SUNDIALS object of one integrate() call; frees in dependency order.
struct Session {
  SUNContext ctx = nullptr;
  N_Vector y = nullptr;
  N_Vector atol = nullptr;
  SUNMatrix A = nullptr;
  SUNLinearSolver ls = nullptr;
  SUNNonlinearSolver nls = nullptr;
  void* mem = nullptr;
  void (*freeMem)(void**) = nullptr;

  Session() = default;
  Session(const Session&) = delete;
  Session& operator=(const Session&) = delete;
  ~Session() {
    if (mem && freeMem) freeMem(&mem);
    if (nls) SUNNonlinSolFree(nls);
    if (ls) SUNLinSolFree(ls);
    if (A) SUNMatDestroy(A);
    if (atol) N_VDestroy(atol);
    if (y) N_VDestroy(y);
    if (ctx) SUNContext_Free(&ctx);
  }
};

/// Name of a return flag (SUNDIALS allocates it; freed here).
std::string flagName(Method m, int flag) {
  char* s = nullptr;
  switch (m) {
    case Method::CvodeBdf:
    case Method::CvodeAdams:
      s = CVodeGetReturnFlagName(flag);
      break;
    case Method::ArkodeErk:
      s = ERKStepGetReturnFlagName(flag);
      break;
    case Method::ArkodeDirk:
    case Method::ArkodeArk:
      s = ARKStepGetReturnFlagName(flag);
      break;
  }
  std::string out = s ? s : ("flag " + std::to_string(flag));
  std::free(s);
  return out;
}

/// The dm::Error for a failed solver call (CVode / ARKStepEvolve / ERKStepEvolve)
/// that stopped at time t; CV_TOO_MUCH_WORK also stands for our own step limit.
/// CVODE's and ARKODE's flags share values for the cases mapped here.
Error solverError(Method m, std::string_view name, int flag, double t, std::int64_t maxSteps,
                  const Callbacks& cb) {
  static_assert(CV_TOO_MUCH_WORK == ARK_TOO_MUCH_WORK && CV_TOO_MUCH_ACC == ARK_TOO_MUCH_ACC &&
                    CV_ERR_FAILURE == ARK_ERR_FAILURE && CV_CONV_FAILURE == ARK_CONV_FAILURE &&
                    CV_LINIT_FAIL == ARK_LINIT_FAIL && CV_LSETUP_FAIL == ARK_LSETUP_FAIL &&
                    CV_LSOLVE_FAIL == ARK_LSOLVE_FAIL && CV_RHSFUNC_FAIL == ARK_RHSFUNC_FAIL &&
                    CV_FIRST_RHSFUNC_ERR == ARK_FIRST_RHSFUNC_ERR &&
                    CV_REPTD_RHSFUNC_ERR == ARK_REPTD_RHSFUNC_ERR &&
                    CV_UNREC_RHSFUNC_ERR == ARK_UNREC_RHSFUNC_ERR && CV_MEM_FAIL == ARK_MEM_FAIL &&
                    CV_ILL_INPUT == ARK_ILL_INPUT && CV_TOO_CLOSE == ARK_TOO_CLOSE,
                "CVODE and ARKODE flag values differ; map them separately");
  const std::string where = std::string(name) + " at t = " + fmt(cb.failed ? cb.failT : t);
  if (cb.failed) return fail(cb.failCode, cb.failWhat, where, cb.failHint);

  const std::string tag = flagName(m, flag);
  // A NaN/Inf from the rhs at or beyond the reached time is what stopped the
  // solver (it shrinks the step and creeps towards it until a limit trips):
  // report it as the cause.
  if (!cb.failWhat.empty() && cb.failT >= t &&
      (flag == CV_TOO_MUCH_WORK || flag == CV_ERR_FAILURE || flag == CV_CONV_FAILURE ||
       flag == CV_RHSFUNC_FAIL || flag == CV_FIRST_RHSFUNC_ERR || flag == CV_REPTD_RHSFUNC_ERR ||
       flag == CV_UNREC_RHSFUNC_ERR || flag == CV_LSETUP_FAIL)) {
    return fail(
        ErrorCode::InvalidArgument, cb.failWhat + "; the solver could not step past it (" + tag + ")",
        std::string(name) + " at t = " + fmt(cb.failT),
        "check the right-hand side near this t (division by zero, sqrt/log of a negative value, overflow, "
        "a state leaving the model's domain)");
  }
  auto with = [&](std::string what) {
    what = tag + ": " + what;
    if (!cb.sundialsMessage.empty()) what += " [" + cb.sundialsMessage + "]";
    return what;
  };
  const bool adams = m == Method::CvodeAdams;
  const bool explicitOnly = m == Method::ArkodeErk;
  switch (flag) {
    case CV_TOO_MUCH_WORK:
      return fail(
          ErrorCode::Timeout, with("more than maxSteps = " + std::to_string(maxSteps) + " steps needed"),
          where,
          explicitOnly || adams
              ? "increase IntegratorOptions::maxSteps; if the step size collapsed the problem is stiff: "
                "use a stiff solver (cvode-bdf)"
              : "increase IntegratorOptions::maxSteps or loosen rtol/atol");
    case CV_TOO_MUCH_ACC:
      return fail(ErrorCode::Unsupported, with("the tolerances cannot be met in double precision"), where,
                  "loosen rtol/atol (rtol >= 1e-12, atol above the round-off of |y|)");
    case CV_ERR_FAILURE:
      return fail(
          ErrorCode::Unsupported,
          with("the error test failed repeatedly or with the step at its minimum (step size collapsed)"),
          where,
          explicitOnly || adams
              ? "the problem is probably stiff: use a stiff solver (cvode-bdf); otherwise look for a "
                "discontinuity or singularity of the right-hand side near this t"
              : "look for a discontinuity or singularity of the right-hand side near this t, or lower "
                "minStep");
    case CV_CONV_FAILURE:
      return fail(
          ErrorCode::Unsupported,
          with(adams ? "the fixed-point iteration failed to converge repeatedly"
                     : "the Newton iteration failed to converge repeatedly"),
          where,
          adams ? "the problem is stiff: use a stiff solver (cvode-bdf)"
                : "give an exact Jacobian (OdeSystem::jacobian), use the dense linear solver, or loosen "
                  "rtol/atol");
    case CV_LINIT_FAIL:
    case CV_LSETUP_FAIL:
    case CV_LSOLVE_FAIL:
      return fail(
          ErrorCode::Unsupported,
          with("the linear solver failed (singular Newton matrix or failed solve)" +
               (cb.failWhat.empty() ? std::string() : "; last callback problem: " + cb.failWhat)),
          where,
          "check the Jacobian callback (sign, finiteness), or switch linearSolver between Dense and Gmres");
    case CV_RHSFUNC_FAIL:
    case CV_FIRST_RHSFUNC_ERR:
    case CV_REPTD_RHSFUNC_ERR:
    case CV_UNREC_RHSFUNC_ERR:
      return fail(ErrorCode::InvalidArgument,
                  with(cb.failWhat.empty() ? std::string("the right-hand side failed") : cb.failWhat), where,
                  "check the right-hand side at this state (division by zero, sqrt/log of a negative value, "
                  "overflow)");
    case CV_MEM_FAIL:
      return fail(ErrorCode::Internal, with("SUNDIALS could not allocate memory"), where,
                  "reduce the system size or free memory");
    case CV_ILL_INPUT:
    case CV_TOO_CLOSE:
      return fail(ErrorCode::InvalidArgument, with("SUNDIALS rejected the input"), where,
                  "check t0 < t1 (not within round-off), the tolerances and the step bounds");
    default:
      return fail(ErrorCode::Internal, with("unexpected SUNDIALS failure"), where,
                  "please report this with the system and options");
  }
}

class SundialsIntegrator final : public Integrator {
 public:
  explicit SundialsIntegrator(Method m) : method_(m) {}

  std::string_view name() const override {
    switch (method_) {
      case Method::CvodeBdf:
        return "cvode-bdf";
      case Method::CvodeAdams:
        return "cvode-adams";
      case Method::ArkodeErk:
        return "arkode-erk";
      case Method::ArkodeDirk:
        return "arkode-dirk";
      case Method::ArkodeArk:
        return "arkode-ark";
    }
    return "sundials";
  }
  int order() const override {
    switch (method_) {
      case Method::CvodeBdf:
        return 5;
      case Method::CvodeAdams:
        return 12;
      default:
        return 4;
    }
  }
  bool isAdaptive() const override { return true; }

 private:
  Method method_;

  bool isCvode() const { return method_ == Method::CvodeBdf || method_ == Method::CvodeAdams; }
  bool isImplicit() const {
    return method_ == Method::CvodeBdf || method_ == Method::ArkodeDirk || method_ == Method::ArkodeArk;
  }

  Status doIntegrate(const OdeSystem& sys, double t0, double t1, VecX& y, const IntegratorOptions& opt,
                     IntegrationStats& stats) override;

  /// A failed setup call (before integration starts).
  Error setupError(const char* call, int flag, double t0, const Callbacks& cb) const {
    std::string what = std::string(call) + " failed: " + flagName(method_, flag);
    if (!cb.sundialsMessage.empty()) what += " [" + cb.sundialsMessage + "]";
    const bool mem = flag == CV_MEM_FAIL;
    return fail(
        mem ? ErrorCode::Internal : ErrorCode::InvalidArgument, std::move(what),
        std::string(name()) + " at t = " + fmt(t0),
        mem ? "reduce the system size or free memory" : "check the integrator options (tolerances, steps)");
  }
};

Status SundialsIntegrator::doIntegrate(const OdeSystem& sys, double t0, double t1, VecX& y,
                                       const IntegratorOptions& opt, IntegrationStats& stats) {
  const std::string where = std::string(name()) + " at t = " + fmt(t0);
  if (isCvode() && !opt.adaptive)
    return fail(ErrorCode::InvalidArgument, "CVODE has no fixed-step mode (adaptive = false)", where,
                "set adaptive = true, or use arkode-erk / arkode-dirk, which take fixed steps of h");

  Callbacks cb;
  cb.n = y.size();
  const bool gmres = opt.linearSolver == LinearSolverKind::Gmres;
  if (method_ == Method::ArkodeArk) {
    if (!(sys.explicitRhs && sys.implicitRhs))
      return fail(
          ErrorCode::InvalidArgument, "arkode-ark needs a split system (explicitRhs and implicitRhs)", where,
          "build it with OdeSystem::split(fExplicit, fImplicit), or use arkode-dirk for an unsplit system");
    cb.f = sys.explicitRhs;
    cb.fi = sys.implicitRhs;
    cb.jac = sys.implicitJacobian;
  } else {
    cb.f = toFirstOrder(sys);
    cb.jac = sys.jacobian;
    cb.jtv = sys.jacobianTimes;
  }

  Session s;
  if (SUNContext_Create(nullptr, &s.ctx) != 0 || !s.ctx)
    return fail(ErrorCode::Internal, "SUNContext_Create failed", where, "free memory");
  s.y = N_VNew_Serial(static_cast<sunindextype>(cb.n), s.ctx);
  if (!s.y)
    return fail(ErrorCode::Internal, "N_VNew_Serial failed", where, "reduce the system size or free memory");
  view(s.y, cb.n) = y;
  const bool vectorAtol = opt.atolPerComponent.size() > 0;
  if (vectorAtol) {
    s.atol = N_VNew_Serial(static_cast<sunindextype>(cb.n), s.ctx);
    if (!s.atol) return fail(ErrorCode::Internal, "N_VNew_Serial failed", where, "free memory");
    view(s.atol, cb.n) = opt.atolPerComponent;
  }

  // Linear solver for the implicit methods (Adams uses fixed-point iteration).
  if (isImplicit()) {
    if (gmres) {
      s.ls = SUNLinSol_SPGMR(s.y, SUN_PREC_NONE, opt.krylovDimension, s.ctx);
    } else {
      s.A = SUNDenseMatrix(static_cast<sunindextype>(cb.n), static_cast<sunindextype>(cb.n), s.ctx);
      if (!s.A) return fail(ErrorCode::Internal, "SUNDenseMatrix failed", where, "reduce the system size");
      s.ls = SUNLinSol_Dense(s.y, s.A, s.ctx);
    }
    if (!s.ls) return fail(ErrorCode::Internal, "creating the linear solver failed", where, "free memory");
  }
  const bool userJtv = gmres && static_cast<bool>(cb.jtv);
  const bool jtvFromJ = gmres && !cb.jtv && static_cast<bool>(cb.jac);
  const bool denseJ = !gmres && static_cast<bool>(cb.jac);

  int flag = 0;
#define DM_SUN_CHECK(call)                                \
  do {                                                    \
    flag = (call);                                        \
    if (flag < 0) return setupError(#call, flag, t0, cb); \
  } while (false)

  if (isCvode()) {
    s.mem = CVodeCreate(method_ == Method::CvodeBdf ? CV_BDF : CV_ADAMS, s.ctx);
    if (!s.mem) return fail(ErrorCode::Internal, "CVodeCreate failed", where, "free memory");
    s.freeMem = CVodeFree;
    DM_SUN_CHECK(CVodeSetErrHandlerFn(s.mem, errorHandler, &cb));
    DM_SUN_CHECK(CVodeInit(s.mem, rhsFull, t0, s.y));
    DM_SUN_CHECK(CVodeSetUserData(s.mem, &cb));
    if (vectorAtol)
      DM_SUN_CHECK(CVodeSVtolerances(s.mem, opt.rtol, s.atol));
    else
      DM_SUN_CHECK(CVodeSStolerances(s.mem, opt.rtol, opt.atol));
    DM_SUN_CHECK(CVodeSetMaxNumSteps(s.mem, static_cast<long>(opt.maxSteps)));
    if (opt.initialStep > 0) DM_SUN_CHECK(CVodeSetInitStep(s.mem, opt.initialStep));
    if (opt.minStep > 0) DM_SUN_CHECK(CVodeSetMinStep(s.mem, opt.minStep));
    if (opt.maxStep > 0) DM_SUN_CHECK(CVodeSetMaxStep(s.mem, opt.maxStep));
    DM_SUN_CHECK(CVodeSetStopTime(s.mem, t1));
    if (method_ == Method::CvodeBdf) {
      DM_SUN_CHECK(CVodeSetLinearSolver(s.mem, s.ls, s.A));
      if (denseJ) DM_SUN_CHECK(CVodeSetJacFn(s.mem, denseJacobian));
      if (userJtv) DM_SUN_CHECK(CVodeSetJacTimes(s.mem, nullptr, jtTimesUser));
      if (jtvFromJ) DM_SUN_CHECK(CVodeSetJacTimes(s.mem, jtSetupFromJacobian, jtTimesFromJacobian));
    } else {
      s.nls = SUNNonlinSol_FixedPoint(s.y, 0, s.ctx);
      if (!s.nls) return fail(ErrorCode::Internal, "SUNNonlinSol_FixedPoint failed", where, "free memory");
      DM_SUN_CHECK(CVodeSetNonlinearSolver(s.mem, s.nls));
    }
  } else if (method_ == Method::ArkodeErk) {
    s.mem = ERKStepCreate(rhsFull, t0, s.y, s.ctx);
    if (!s.mem) return fail(ErrorCode::Internal, "ERKStepCreate failed", where, "free memory");
    s.freeMem = ERKStepFree;
    DM_SUN_CHECK(ERKStepSetErrHandlerFn(s.mem, errorHandler, &cb));
    DM_SUN_CHECK(ERKStepSetUserData(s.mem, &cb));
    DM_SUN_CHECK(ERKStepSetTableNum(s.mem, ARKODE_ZONNEVELD_5_3_4));
    if (vectorAtol)
      DM_SUN_CHECK(ERKStepSVtolerances(s.mem, opt.rtol, s.atol));
    else
      DM_SUN_CHECK(ERKStepSStolerances(s.mem, opt.rtol, opt.atol));
    DM_SUN_CHECK(ERKStepSetMaxNumSteps(s.mem, static_cast<long>(opt.maxSteps)));
    if (!opt.adaptive) DM_SUN_CHECK(ERKStepSetFixedStep(s.mem, opt.h));
    if (opt.initialStep > 0) DM_SUN_CHECK(ERKStepSetInitStep(s.mem, opt.initialStep));
    if (opt.minStep > 0) DM_SUN_CHECK(ERKStepSetMinStep(s.mem, opt.minStep));
    if (opt.maxStep > 0) DM_SUN_CHECK(ERKStepSetMaxStep(s.mem, opt.maxStep));
    DM_SUN_CHECK(ERKStepSetStopTime(s.mem, t1));
  } else {
    const bool ark = method_ == Method::ArkodeArk;
    s.mem = ark ? ARKStepCreate(rhsFull, rhsImplicit, t0, s.y, s.ctx)
                : ARKStepCreate(nullptr, rhsFull, t0, s.y, s.ctx);
    if (!s.mem) return fail(ErrorCode::Internal, "ARKStepCreate failed", where, "free memory");
    s.freeMem = ARKStepFree;
    DM_SUN_CHECK(ARKStepSetErrHandlerFn(s.mem, errorHandler, &cb));
    DM_SUN_CHECK(ARKStepSetUserData(s.mem, &cb));
    if (ark)
      DM_SUN_CHECK(ARKStepSetTableNum(s.mem, ARKODE_ARK436L2SA_DIRK_6_3_4, ARKODE_ARK436L2SA_ERK_6_3_4));
    else
      DM_SUN_CHECK(ARKStepSetTableNum(s.mem, ARKODE_SDIRK_5_3_4, ARKODE_ERK_NONE));
    if (vectorAtol)
      DM_SUN_CHECK(ARKStepSVtolerances(s.mem, opt.rtol, s.atol));
    else
      DM_SUN_CHECK(ARKStepSStolerances(s.mem, opt.rtol, opt.atol));
    DM_SUN_CHECK(ARKStepSetMaxNumSteps(s.mem, static_cast<long>(opt.maxSteps)));
    if (!opt.adaptive) DM_SUN_CHECK(ARKStepSetFixedStep(s.mem, opt.h));
    if (opt.initialStep > 0) DM_SUN_CHECK(ARKStepSetInitStep(s.mem, opt.initialStep));
    if (opt.minStep > 0) DM_SUN_CHECK(ARKStepSetMinStep(s.mem, opt.minStep));
    if (opt.maxStep > 0) DM_SUN_CHECK(ARKStepSetMaxStep(s.mem, opt.maxStep));
    DM_SUN_CHECK(ARKStepSetStopTime(s.mem, t1));
    DM_SUN_CHECK(ARKStepSetLinearSolver(s.mem, s.ls, s.A));
    if (denseJ) DM_SUN_CHECK(ARKStepSetJacFn(s.mem, denseJacobian));
    if (userJtv) DM_SUN_CHECK(ARKStepSetJacTimes(s.mem, nullptr, jtTimesUser));
    if (jtvFromJ) DM_SUN_CHECK(ARKStepSetJacTimes(s.mem, jtSetupFromJacobian, jtTimesFromJacobian));
  }
#undef DM_SUN_CHECK

  // Step by step (ONE_STEP mode, the stop time keeps the last step on t1), so
  // that on failure the state handed back is the last accepted one, at its
  // time, for every package; the step limit is enforced here for the same reason.
  sunrealtype tret = t0;
  VecX yGood = y;
  double tGood = t0;
  std::int64_t taken = 0;
  bool stepLimit = false;
  while (tGood < t1) {
    if (taken >= opt.maxSteps) {
      stepLimit = true;
      break;
    }
    switch (method_) {
      case Method::CvodeBdf:
      case Method::CvodeAdams:
        flag = CVode(s.mem, t1, s.y, &tret, CV_ONE_STEP);
        break;
      case Method::ArkodeErk:
        flag = ERKStepEvolve(s.mem, t1, s.y, &tret, ARK_ONE_STEP);
        break;
      case Method::ArkodeDirk:
      case Method::ArkodeArk:
        flag = ARKStepEvolve(s.mem, t1, s.y, &tret, ARK_ONE_STEP);
        break;
    }
    if (flag < 0) break;
    ++taken;
    yGood = view(s.y, cb.n);
    tGood = (flag == CV_TSTOP_RETURN) ? t1 : tret;
  }

  // Statistics (also on failure).
  long nst = 0, natt = 0, netf = 0, nsf = 0, nje = 0, nni = 0, nli = 0;
  sunrealtype hlast = 0;
  if (isCvode()) {
    CVodeGetNumSteps(s.mem, &nst);
    CVodeGetNumErrTestFails(s.mem, &netf);
    CVodeGetNumStepSolveFails(s.mem, &nsf);
    CVodeGetNumNonlinSolvIters(s.mem, &nni);
    if (s.ls) {
      CVodeGetNumJacEvals(s.mem, &nje);
      CVodeGetNumLinIters(s.mem, &nli);
    }
    CVodeGetLastStep(s.mem, &hlast);
    stats.rejectedSteps = netf + nsf;
  } else if (method_ == Method::ArkodeErk) {
    ERKStepGetNumSteps(s.mem, &nst);
    ERKStepGetNumStepAttempts(s.mem, &natt);
    ERKStepGetLastStep(s.mem, &hlast);
    stats.rejectedSteps = natt - nst;
  } else {
    ARKStepGetNumSteps(s.mem, &nst);
    ARKStepGetNumStepAttempts(s.mem, &natt);
    ARKStepGetNumNonlinSolvIters(s.mem, &nni);
    ARKStepGetNumJacEvals(s.mem, &nje);
    ARKStepGetNumLinIters(s.mem, &nli);
    ARKStepGetLastStep(s.mem, &hlast);
    stats.rejectedSteps = natt - nst;
  }
  stats.steps = nst;
  stats.rhsEvaluations = cb.rhsCalls;
  // Dense: SUNDIALS' count (user or difference quotient); GMRES with a user J: its evaluations.
  stats.jacobianEvaluations = gmres ? cb.userJacCalls : nje;
  stats.nonlinearIterations = nni;
  stats.linearIterations = nli;
  stats.lastStep = hlast;
  stats.tReached = tGood;
  y = yGood;

  if (flag < 0) return solverError(method_, name(), flag, tGood, opt.maxSteps, cb);
  if (stepLimit) return solverError(method_, name(), CV_TOO_MUCH_WORK, tGood, opt.maxSteps, cb);
  if (cb.failed)
    return fail(cb.failCode, cb.failWhat, std::string(name()) + " at t = " + fmt(cb.failT), cb.failHint);
  return ok();
}

}  // namespace

std::unique_ptr<Integrator> makeCvodeBdf() { return std::make_unique<SundialsIntegrator>(Method::CvodeBdf); }
std::unique_ptr<Integrator> makeCvodeAdams() {
  return std::make_unique<SundialsIntegrator>(Method::CvodeAdams);
}
std::unique_ptr<Integrator> makeArkodeErk() {
  return std::make_unique<SundialsIntegrator>(Method::ArkodeErk);
}
std::unique_ptr<Integrator> makeArkodeDirk() {
  return std::make_unique<SundialsIntegrator>(Method::ArkodeDirk);
}
std::unique_ptr<Integrator> makeArkodeArk() {
  return std::make_unique<SundialsIntegrator>(Method::ArkodeArk);
}

std::unique_ptr<Integrator> makeSundialsIntegrator(std::string_view name) {
  if (name == "cvode-bdf") return makeCvodeBdf();
  if (name == "cvode-adams") return makeCvodeAdams();
  if (name == "arkode-erk") return makeArkodeErk();
  if (name == "arkode-dirk") return makeArkodeDirk();
  if (name == "arkode-ark") return makeArkodeArk();
  return nullptr;
}

}  // namespace dm
