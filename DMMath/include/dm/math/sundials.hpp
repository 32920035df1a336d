// dm/math/sundials.hpp — SUNDIALS (CVODE, ARKODE) integrators behind
// dm::Integrator. Only dm types appear here; SUNDIALS stays in sundials.cpp.
//
// All five take rtol/atol (or atolPerComponent), initialStep, minStep,
// maxStep and maxSteps from IntegratorOptions; the implicit ones also
// linearSolver (Dense or Gmres) and krylovDimension, and use
// OdeSystem::jacobian / jacobianTimes when given (difference quotients
// otherwise; arkode-ark uses implicitJacobian, the Jacobian of its implicit
// part). With Gmres and only a dense Jacobian, J is evaluated at each Newton
// setup and J·v formed from it. The ARKODE ones honour adaptive = false (fixed steps of h);
// CVODE has no fixed-step mode. SUNDIALS failure flags become dm errors
// naming the flag, the time and a remedy; SUNDIALS prints nothing.
//
// @code
//   auto bdf = dm::makeCvodeBdf();
//   dm::IntegratorOptions o; o.rtol = 1e-6; o.linearSolver = dm::LinearSolverKind::Gmres;
//   auto st = bdf->integrate(stiffSystem, 0.0, 40.0, y, o);
// @endcode
#pragma once

#include <dm/math/integrators.hpp>

#include <memory>
#include <string_view>

namespace dm {

/// CVODE, variable-order (1..5) BDF with Newton iteration: the stiff solver.
/// Linear solves by dense LU (with OdeSystem::jacobian when given) or by
/// matrix-free GMRES.
/// @code
///   auto bdf = dm::makeCvodeBdf();
///   auto st = bdf->integrate(sys, 0.0, 1.0, y, {.rtol = 1e-6, .atol = 1e-10});
/// @endcode
std::unique_ptr<Integrator> makeCvodeBdf();

/// CVODE, variable-order (1..12) Adams–Moulton with fixed-point iteration:
/// for smooth non-stiff problems at tight tolerances (no Jacobian needed).
/// @code
///   auto adams = dm::makeCvodeAdams();
///   auto st = adams->integrate(sys, 0.0, 1.0, y, {.rtol = 1e-10, .atol = 1e-12});
/// @endcode
std::unique_ptr<Integrator> makeCvodeAdams();

/// ARKODE ERKStep: adaptive explicit Runge–Kutta, order 4 (Zonneveld 5-4).
/// @code
///   auto erk = dm::makeArkodeErk();
///   auto st = erk->integrate(sys, 0.0, 1.0, y);
/// @endcode
std::unique_ptr<Integrator> makeArkodeErk();

/// ARKODE ARKStep fully implicit (SDIRK, order 4) with Newton iteration, for
/// stiff problems; the whole f is treated implicitly.
/// @code
///   auto dirk = dm::makeArkodeDirk();
///   auto st = dirk->integrate(sys, 0.0, 1.0, y);
/// @endcode
std::unique_ptr<Integrator> makeArkodeDirk();

/// ARKODE ARKStep additive ImEx Runge–Kutta (ARK4(3)6L, order 4): the
/// system must be split (OdeSystem::split): explicitRhs is integrated
/// explicitly, implicitRhs implicitly (implicitJacobian = ∂fI/∂y optional).
/// @code
///   auto ark = dm::makeArkodeArk();
///   auto st = ark->integrate(dm::OdeSystem::split(fNonStiff, fStiff), 0.0, 1.0, y);
/// @endcode
std::unique_ptr<Integrator> makeArkodeArk();

/// The SUNDIALS integrator for a factory name ("cvode-bdf", "cvode-adams",
/// "arkode-erk", "arkode-dirk", "arkode-ark"), or nullptr for any other name.
/// makeIntegrator() calls this; prefer makeIntegrator().
std::unique_ptr<Integrator> makeSundialsIntegrator(std::string_view name);

}  // namespace dm
