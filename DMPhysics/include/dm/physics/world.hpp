// dm/physics/world.hpp — the physics world: particles and rigid bodies
// moved by force accumulators and per-body integrators.
//
// Model and state apart (MuJoCo's mjModel/mjData): a PhysicsWorld is the
// read-only model — bodies' mass properties, integrator choice, shapes and
// the ForceSet — built once at setup; a WorldState holds everything that
// changes (time, positions, orientations, velocities, derived bounds and the
// step's scratch memory). Stepping is `world.step(state, dt)` with a const
// world, so one model serves many states (lockstep runs, rollouts, replays),
// also from several threads at once when the user forces allow it.
//
// Step order (PhysicsWorld::step):
//   0. impulses due in [t, t + dt) change the velocities;
//   1. for each integrator kind in the order symplectic Euler, velocity
//      Verlet, RK4, its bodies are advanced together by the dm/math step
//      function; every force evaluation the method asks for is an
//      *accumulate* (dm/physics/accumulators.hpp) of all forces at the
//      current stage state; then *integrate* (see IntegratorKind);
//   2. orientations are renormalised and world AABBs of shapes updated.
// Kinds are advanced one after another: a later kind sees the earlier kinds'
// bodies at their end-of-step state (a Gauss–Seidel splitting, first-order in
// the coupling between kinds). Bodies of one kind are integrated as one
// coupled system, so choose one kind for strongly coupled bodies.
// Rotation: RK4 bodies integrate (q, ω) with the rest of their state; for
// symplectic Euler and velocity Verlet bodies, (q, ω) is integrated by an RK4
// step of Euler's equations with the torque of the step's first evaluation.
//
// Determinism: the same world, initial state and dt sequence give
// bit-identical states on the same build (fixed summation orders, no
// threads, no uninitialised data); stateHash() fingerprints a state.
// Real time: step() allocates nothing, takes no lock and never throws once
// makeState() has sized the state (user forces must do the same).
//
// @code
//   dm::PhysicsWorld world;
//   auto ball = world.addBody({.name = "ball", .mass = 0.1});
//   world.setGravity({0, 0, -9.81});
//   dm::WorldState state = world.makeState();
//   for (int i = 0; i < 1000; ++i) if (auto st = world.step(state, 1e-3); !st) return st.error();
// @endcode
#pragma once

#include <dm/core/result.hpp>
#include <dm/core/types.hpp>
#include <dm/math/integrators.hpp>
#include <dm/physics/accumulators.hpp>
#include <dm/physics/body.hpp>

#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace dm {

/// The dynamic part of a WorldState (what a snapshot saves and the hash
/// covers). Vectors have one entry per body, indexed by BodyId::index.
struct WorldSnapshot {
  double time = 0.0;                  ///< s
  std::uint64_t stepCount = 0;        ///< completed steps
  std::vector<Vec3> position;         ///< m, centre of mass
  std::vector<Quat> orientation;      ///< body → world, unit
  std::vector<Vec3> linearVelocity;   ///< m/s
  std::vector<Vec3> angularVelocity;  ///< rad/s, world frame
};

/// Mutable state of one run of a PhysicsWorld. Made by
/// PhysicsWorld::makeState(); copyable (a copy is an independent run).
class WorldState {
 public:
  double time() const noexcept { return s_.time; }                   ///< s
  std::uint64_t stepCount() const noexcept { return s_.stepCount; }  ///< completed steps
  std::size_t bodyCount() const noexcept { return s_.position.size(); }
  /// Centre of mass (m, world). `id` must be valid for this state (DM_ASSERT).
  const Vec3& position(BodyId id) const noexcept { return s_.position[check(id)]; }
  /// Body → world rotation (unit quaternion).
  const Quat& orientation(BodyId id) const noexcept { return s_.orientation[check(id)]; }
  /// m/s, world frame.
  const Vec3& linearVelocity(BodyId id) const noexcept { return s_.linearVelocity[check(id)]; }
  /// rad/s, world frame.
  const Vec3& angularVelocity(BodyId id) const noexcept { return s_.angularVelocity[check(id)]; }
  /// World AABB of the body's shape (m); a point box at the centre of mass
  /// for bodies without a shape. Updated at the end of every step.
  const Aabb& bounds(BodyId id) const noexcept { return bounds_[check(id)]; }
  /// Total force (N) and torque (N·m) of the last step's first evaluation.
  const Vec3& force(BodyId id) const noexcept { return force_[check(id)]; }
  const Vec3& torque(BodyId id) const noexcept { return torque_[check(id)]; }

  /// The dynamic state, for the state's whole life (one entry per body).
  const WorldSnapshot& data() const noexcept { return s_; }
  /// A copy of the dynamic state. Allocates (not for the real-time loop:
  /// keep a WorldSnapshot and use copyTo).
  WorldSnapshot snapshot() const { return s_; }
  /// Copies the dynamic state into `out`; no allocation when `out` already
  /// has this state's size.
  void copyTo(WorldSnapshot& out) const;

 private:
  friend class PhysicsWorld;
  std::uint32_t check(BodyId id) const noexcept {
    DM_ASSERT(id.index < s_.position.size(), "BodyId out of range");
    return id.index;
  }

  /// Step scratch: stage state seen by the force evaluations, packed vectors
  /// and workspaces of the dm/math steppers (per integrator kind).
  struct Scratch {
    std::vector<Vec3> stagePosition, stageLinearVelocity, stageAngularVelocity;
    std::vector<Quat> stageOrientation;
    std::vector<Vec3> force, torque;
    VecX x[2], v[2];  ///< symplectic Euler / Verlet packed positions and velocities
    SecondOrderWorkspace secondOrder[2];
    VecX rotation[2];     ///< packed (q, ω) of the rigid bodies of those kinds
    VecX firstTorque[2];  ///< their torques from the first evaluation
    Rk4Workspace rotationWs[2];
    VecX rk4State;  ///< packed (x, q, v, ω) of the RK4 bodies
    Rk4Workspace rk4Ws;
    int activeKind = 0;
    bool recordForces = false;
    bool firstEvaluation = false;
  };

  WorldSnapshot s_;
  std::vector<Aabb> bounds_;
  std::vector<Vec3> force_, torque_;
  Scratch scratch_;
};

/// FNV-1a (64-bit, offset basis 0xcbf29ce484222325, prime 0x100000001b3)
/// over the raw bytes of: time, stepCount, then for each body in index
/// order position (x, y, z), orientation (x, y, z, w), linear velocity,
/// angular velocity — every value an IEEE-754 double in host byte order.
/// Equal hashes of two runs on one machine mean bit-identical states (up to
/// hash collisions). O(bodies).
/// @code
///   dm::WorldState a = world.makeState(), b = world.makeState();
///   // ... step both with the same dt ...
///   EXPECT_EQ(dm::stateHash(a.data()), dm::stateHash(b.data()));
/// @endcode
std::uint64_t stateHash(const WorldSnapshot& state) noexcept;

/// The read-only model: bodies, forces, integrator choice. Build it with the
/// add*/set* functions (setup, may allocate), then makeState() and step().
class PhysicsWorld {
 public:
  /// Adds a body; its index is the number of bodies before. Fails with
  /// InvalidArgument (message names the body and field) as validateBodyDesc.
  /// States made before this call no longer match the world (step fails).
  /// @code
  ///   auto id = world.addBody({.name = "bob", .kind = dm::BodyKind::Particle, .mass = 0.2});
  ///   if (!id) return id.error();
  /// @endcode
  Result<BodyId> addBody(const BodyDesc& desc);

  /// Uniform gravitational acceleration (m/s², world), F = m g on every
  /// particle and rigid body. Fails on non-finite values.
  Status setGravity(const Vec3& acceleration);
  /// Adds an accumulator after validateAccumulator(). Each fails with
  /// InvalidArgument naming the accumulator (e.g. "springs[2]") and field,
  /// or NotFound for an unknown body id.
  Status addForce(const ExternalForce& force);
  Status addTorque(const ExternalTorque& torque);               ///< see addForce
  Status addDrag(const Drag& drag);                             ///< see addForce
  Status addNewtonianGravity(const NewtonianGravity& gravity);  ///< see addForce
  Status addSpring(const Spring& spring);                       ///< see addForce
  Status addImpulse(const Impulse& impulse);                    ///< see addForce; also a finite time
  /// Registers a C++ user force, evaluated after the built-in ones in
  /// registration order. Fails on an empty function.
  /// @code
  ///   world.addUserForce("wind", [](const dm::BodyStateView& s, dm::ForceOutput& out) {
  ///     for (std::size_t i = 0; i < out.force.size(); ++i) out.force[i].x() += 0.1 * s.mass[i]; });
  /// @endcode
  Status addUserForce(std::string name, UserForceFn function);
  /// Registers a C-callable user force (for plugins); `userData` is passed
  /// back unchanged and must outlive the world. Fails on a null callback.
  Status addUserForce(std::string name, DmForceCallback callback, void* userData);

  std::size_t bodyCount() const noexcept { return bodies_.size(); }
  /// Every body's description, indexed by BodyId::index.
  std::span<const BodyDesc> bodies() const noexcept { return bodies_; }
  /// The forces, by kind.
  const ForceSet& forces() const noexcept { return forces_; }
  /// The body named `name`; NotFound otherwise. O(bodies).
  Result<BodyId> findBody(std::string_view name) const;

  /// A state at the bodies' initial values, t = 0, with every buffer step()
  /// needs allocated and bounds computed. O(bodies).
  WorldState makeState() const;

  /// Advances `state` by `dt` seconds in the order given at the top of this
  /// header. Fails with InvalidArgument (state unchanged) when dt is not
  /// finite and > 0 or `state` does not match the world (body count), and
  /// with Unsupported when the step produced a non-finite value (the message
  /// names the body and field; `state` then holds the bad values: restore a
  /// snapshot and take a smaller dt or softer springs). Cost: per
  /// force evaluation O(accumulators), 1 (symplectic Euler), 2 (Verlet) or 4
  /// (RK4) evaluations per kind present. Allocates nothing.
  /// @code
  ///   dm::WorldState s = world.makeState();
  ///   if (auto st = world.step(s, 1e-3); !st) std::cerr << st.error() << '\n';
  ///   dm::Vec3 x = s.position(ball);
  /// @endcode
  Status step(WorldState& state, double dt) const;

  /// Restores `state` to `snapshot` (made from a state of this world) and
  /// recomputes the bounds; the following steps reproduce the original run
  /// bit for bit. Fails with InvalidArgument on a size mismatch or a
  /// non-finite value (naming the body and field). No allocation.
  /// @code
  ///   dm::WorldSnapshot snap = state.snapshot();
  ///   world.step(state, dt);
  ///   world.restore(state, snap);  // back to before the step
  /// @endcode
  Status restore(WorldState& state, const WorldSnapshot& snapshot) const;

  /// Sets one body's position (m), orientation and velocities (world) in
  /// `state`. Fails with NotFound for an unknown id, InvalidArgument on
  /// non-finite values or a zero quaternion; orientation is normalised.
  Status setBodyState(WorldState& state, BodyId id, const Vec3& position, const Quat& orientation,
                      const Vec3& linearVelocity, const Vec3& angularVelocity) const;

  /// Applies an impulse J (N·s, world) at world point `point` (m) now:
  /// v += J/m, and for rigid bodies ω += I_w⁻¹ ((point − x) × J). Fails with
  /// NotFound for an unknown id, InvalidArgument for a static body or
  /// non-finite input. O(1), no allocation.
  Status applyImpulse(WorldState& state, BodyId id, const Vec3& impulse, const Vec3& point) const;

  /// Σ ½ m |v|² + ½ ωᵀ I_w ω over dynamic bodies, J.
  double kineticEnergy(const WorldState& state) const noexcept;
  /// Σ m v over dynamic bodies, kg·m/s.
  Vec3 linearMomentum(const WorldState& state) const noexcept;
  /// Σ (x − about) × m v + I_w ω over dynamic bodies, kg·m²/s, world frame.
  Vec3 angularMomentum(const WorldState& state, const Vec3& about = Vec3::Zero()) const noexcept;

 private:
  struct BodyModel {  // per-body data the hot loops read
    BodyKind kind;
    double inverseMass;   // 0 for static bodies
    Mat3 inertia;         // body frame
    Mat3 inverseInertia;  // body frame (zero for particles and static bodies)
  };
  Status checkBody(BodyId id, const char* what) const;
  void evaluate(WorldState& state, double t) const;
  void updateBounds(WorldState& state) const;
  void applyImpulseAt(WorldState& state, std::uint32_t i, const Vec3& impulse, const Vec3& r) const;
  void stepSecondOrder(WorldState& state, int kind, double t, double dt) const;
  void stepRk4(WorldState& state, double t, double dt) const;

  std::vector<BodyDesc> bodies_;
  std::vector<BodyModel> model_;
  std::vector<double> masses_;
  std::vector<std::uint32_t> members_[3];       // dynamic bodies per IntegratorKind
  std::vector<std::uint32_t> rigidMembers_[2];  // rigid bodies among members_[0], members_[1]
  std::vector<Impulse> impulses_;
  ForceSet forces_;
};

}  // namespace dm
