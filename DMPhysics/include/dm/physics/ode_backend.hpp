// dm/physics/ode_backend.hpp — run a PhysicsWorld's rigid-body scene on the
// Open Dynamics Engine (ODE, double precision, dWorldQuickStep) instead of
// the built-in contact solver, reading and writing the same WorldState.
//
// An OdeWorld mirrors a PhysicsWorld model when it is created: every
// particle and rigid body becomes an ODE body (mass, body-frame inertia about
// the centre of mass), every shape an ODE geom at the body's shapeOffset
// (sphere, box, capsule, cylinder, convex hull as dConvex, a compound of
// them as one geom per part at shapeOffset · the part's pose; planes and
// triangle meshes (OPCODE) on static bodies only; a convex hull and a
// triangle mesh in one world are refused: ODE 0.16 as Debian builds it has
// no collider for that pair), static bodies become body-less geoms, joints
// (ball, hinge, slider, fixed, with limits) ODE joints, and the contact
// materials ODE contact surfaces (friction √(μa·μb)
// with the friction pyramid scaled by the normal force, dContactApprox1;
// restitution max(ea, eb) above the solver's restitution threshold), exactly
// as the built-in pipeline combines them. Forces — gravity and every other
// accumulator of the world — are evaluated by dm::accumulateForces at the
// start of each step and handed to ODE as body forces and torques; timed
// impulses are applied when due, as in PhysicsWorld::step.
//
// Selecting the backend is per world: step a WorldState with
// `world.step(state, dt)` for the built-in solver or with
// `ode.step(state, dt)` for ODE. The WorldState stays the source of truth:
// every step copies its poses and velocities into ODE, steps, and copies the
// result back (time, stepCount, bounds updated), so snapshots, stateHash
// and setBodyState work the same. ODE keeps no state between steps that
// the WorldState does not hold (ODE has no warm starting across steps), and
// the random order of dWorldQuickStep's constraints is seeded from the
// state's step count: the same state steps to the same bits (ODE's
// generator is global: step one OdeWorld at a time).
// The contact forces of the last step come from ODE's joint feedback
// (lastContactForces); WorldState::contacts() stays empty on this backend.
//
// ODE headers never appear here; the library is linked privately. Not
// real-time code: ODE's contact joints allocate from its joint group (the
// group and the feedback blocks keep their memory from step to step).
//
// @code
//   auto ode = dm::OdeWorld::create(world, {.iterations = 20});
//   if (!ode) return ode.error();
//   dm::WorldState s = world.makeState();
//   for (int i = 0; i < 1000; ++i) if (auto st = ode->step(s, 1e-3); !st) return st;
// @endcode
#pragma once

#include <dm/core/result.hpp>
#include <dm/physics/world.hpp>

#include <memory>
#include <span>

namespace dm {

/// Settings of the ODE backend.
struct OdeOptions {
  int iterations = 20;         ///< dWorldQuickStep iterations (≥ 1)
  double erp = 0.2;            ///< error reduction parameter, (0, 1]
  double cfm = 1e-9;           ///< constraint force mixing, ≥ 0
  int maxContactsPerPair = 4;  ///< contacts dCollide may return per geom pair, [1, 64]
  /// Allowed penetration (m) before ODE corrects it (dWorldSetContactSurfaceLayer);
  /// negative: the PhysicsWorld's ContactSettings::solver.slop.
  double surfaceLayer = -1.0;
};

/// A PhysicsWorld's rigid-body scene on ODE (see the file comment).
/// Movable, not copyable; the PhysicsWorld must outlive it and must not get
/// new bodies or joints afterwards (create a new OdeWorld then). Forces may
/// be added later: they are evaluated from the world at every step.
class OdeWorld {
 public:
  /// Builds the ODE mirror of `world`. Fails with Unsupported, naming the
  /// body ("bodies[2] 'tube'") and the shape type, for shapes ODE cannot
  /// take (anything but sphere, box, capsule, cylinder, convex hull, and
  /// plane or triangle mesh on static bodies) and for a world with both a
  /// convex hull and a triangle mesh,
  /// with InvalidArgument for bad options (naming the field). O(bodies +
  /// joints).
  /// @code
  ///   auto ode = dm::OdeWorld::create(world);
  ///   if (!ode) dm::log::warn("%s", ode.error().message().c_str());
  /// @endcode
  static Result<OdeWorld> create(const PhysicsWorld& world, const OdeOptions& options = {});

  OdeWorld(OdeWorld&&) noexcept;
  OdeWorld& operator=(OdeWorld&&) noexcept;
  OdeWorld(const OdeWorld&) = delete;
  OdeWorld& operator=(const OdeWorld&) = delete;
  ~OdeWorld();

  /// Advances `state` (made by the mirrored world's makeState()) by `dt`
  /// seconds on ODE: impulses due, forces, collision (ODE's hash space and
  /// dCollide), dWorldQuickStep, then back into `state`. Fails with
  /// InvalidArgument for a bad dt or a state of another world (state
  /// unchanged), Unsupported when ODE produced a non-finite value (naming
  /// the body). O(bodies + contacts·iterations).
  /// @code
  ///   if (auto st = ode->step(state, 1.0 / 60); !st) return st;
  /// @endcode
  Status step(WorldState& state, double dt);

  /// Contact joints ODE created in the last step.
  std::size_t lastContactCount() const noexcept;
  /// Per world body: the sum of the last step's contact forces on it (N,
  /// world; ODE's joint feedback), zero for static bodies and before the
  /// first step.
  std::span<const Vec3> lastContactForces() const noexcept;
  /// The options in effect.
  const OdeOptions& options() const noexcept;

 private:
  struct Impl;
  explicit OdeWorld(std::unique_ptr<Impl> impl) noexcept;
  std::unique_ptr<Impl> impl_;
};

}  // namespace dm
