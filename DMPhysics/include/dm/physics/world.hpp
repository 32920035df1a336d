// dm/physics/world.hpp — the physics world: particles and rigid bodies
// moved by force accumulators and per-body integrators, with rigid contact
// (DMCollide + the ConstraintSolver) and joints; dm/physics/ode_backend.hpp
// steps the same model and state on ODE instead.
//
// Model and state apart (MuJoCo's mjModel/mjData): a PhysicsWorld is the
// read-only model — bodies' mass properties, integrator choice, shapes and
// the ForceSet, contact materials and joints — built once at setup; a WorldState holds everything that
// changes (time, positions, orientations, velocities, derived bounds and the
// step's scratch memory, the contact cache and joint impulses). Stepping is `world.step(state, dt)` with a
// const world, so one model serves many states (lockstep runs, rollouts, replays), also from several threads
// at once when the user forces allow it.
//
// Step order (PhysicsWorld::step):
//   0. impulses due in [t, t + dt) change the velocities;
//   1. for each integrator kind in the order symplectic Euler, velocity
//      Verlet, RK4, its bodies are advanced together by the dm/math step
//      function; every force evaluation the method asks for is an
//      *accumulate* (dm/physics/accumulators.hpp) of all forces at the
//      current stage state; then *integrate* (see IntegratorKind);
//   2. rigid contact and joints (dm/physics/rigid_contact.hpp): contacts
//      found at the start-of-step poses (broad + narrow phase, DMCollide),
//      continuous collision for `ccd` bodies, then the ConstraintSolver on
//      the bodies in contacts or joints, which are re-advanced from their
//      start-of-step poses with the solved velocities;
//   3. orientations are renormalised and world AABBs of shapes updated.
// With ContactSettings::sleep (off by default), islands of bodies at rest in
// contact fall asleep: they keep their pose, take no part in the narrow phase
// or the solver, and wake on impact, impulse or setBodyState (see
// rigid_contact.hpp, step 6).
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
#include <dm/physics/rigid_contact.hpp>

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
  /// What the contact pipeline did in the last step.
  const ContactStats& contactStats() const noexcept { return contact_.stats; }
  /// True while the body sleeps (ContactSettings::sleep; see rigid_contact.hpp).
  bool asleep(BodyId id) const noexcept {
    const std::uint32_t i = check(id);
    return i < contact_.asleep.size() && contact_.asleep[i] != 0;
  }
  /// Contacts solved in the last step, with their accumulated impulses
  /// (N·s); body indices are BodyId::index values (ContactConstraint).
  std::span<const ContactConstraint> contacts() const noexcept { return contact_.contacts; }
  /// The world's joints in addJoint order, with their accumulated impulses.
  std::span<const Joint> joints() const noexcept { return contact_.joints; }

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
  friend class OdeWorld;
  friend class SoftRigidCoupling;  // writes the contact's velocity change
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
  RigidContactState contact_;
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

  /// Sets the contact material of a body (every body starts with the
  /// defaults of ContactMaterial). Fails with NotFound for an unknown id and
  /// InvalidArgument (naming the body and field) for μ < 0, e outside
  /// [0, 1] or non-finite values. Setup only: states made before keep working.
  /// @code
  ///   world.setMaterial(ball, {.friction = 0.3, .restitution = 0.5, .ccd = true});
  /// @endcode
  Status setMaterial(BodyId id, const ContactMaterial& material);
  /// The material of a body; `id` must be valid (DM_ASSERT).
  const ContactMaterial& material(BodyId id) const noexcept;
  /// Replaces the contact settings. Fails with InvalidArgument naming the
  /// field for bad solver options, maxContactsPerPair < 1 or a ccdTolerance
  /// that is not > 0. Takes effect for states made afterwards as well as
  /// existing ones (capacities grow once if needed).
  Status setContactSettings(const ContactSettings& settings);
  /// The contact settings in effect.
  const ContactSettings& contactSettings() const noexcept { return contactSettings_; }
  /// Adds a joint built from the bodies' initial poses (see JointDesc); its
  /// index is the number of joints before. Fails with NotFound for an
  /// unknown body id and InvalidArgument (message names "joints[i]") for two
  /// identical bodies, a zero axis, lower > upper, or two non-dynamic
  /// bodies. States made before this call no longer match (step fails).
  /// @code
  ///   auto j = world.addJoint({.type = dm::JointType::Hinge, .b = bob, .anchor = {0, 0, 1}, .axis = {0, 1,
  ///   0}}); if (!j) return j.error();
  /// @endcode
  Result<std::size_t> addJoint(const JointDesc& desc);
  /// The joint descriptions in addJoint order.
  std::span<const JointDesc> joints() const noexcept { return jointDescs_; }

  std::size_t bodyCount() const noexcept { return bodies_.size(); }
  /// Every body's description, indexed by BodyId::index.
  std::span<const BodyDesc> bodies() const noexcept { return bodies_; }
  /// The forces, by kind.
  const ForceSet& forces() const noexcept { return forces_; }
  /// The timed impulses, in addImpulse order.
  std::span<const Impulse> impulses() const noexcept { return impulses_; }
  /// The body named `name`; NotFound otherwise. O(bodies).
  Result<BodyId> findBody(std::string_view name) const;
  /// Body `id` for a coupling that meets it with a mesh (soft tissue, a
  /// membrane): InvalidArgument at `where` for an id not in the world or a
  /// particle (no orientation for its mesh).
  Result<const BodyDesc*> meshedBody(BodyId id, const std::string& where) const;

  /// A state at the bodies' initial values, t = 0, with every buffer step()
  /// needs allocated (contact scratch sized by ContactSettings::pairCapacity),
  /// bounds computed and the joints' warm-start impulses at zero. O(bodies).
  WorldState makeState() const;

  /// Advances `state` by `dt` seconds in the order given at the top of this
  /// header. Fails with InvalidArgument (state unchanged) when dt is not
  /// finite and > 0 or `state` does not match the world (body or joint
  /// count), and with Unsupported when the step produced a non-finite value
  /// or the contact solver rejected it (the message names the body and
  /// field; `state` then holds the bad values: restore a snapshot and take a
  /// smaller dt or softer springs). Cost: per force evaluation
  /// O(accumulators), 1 (symplectic Euler), 2 (Verlet) or 4 (RK4)
  /// evaluations per kind present; contacts O(n log n + pairs) broad phase,
  /// one narrow-phase query per pair, O((contacts + joints)·iterations)
  /// solver. Allocates nothing once makeState() reserved the scratch (see
  /// dm/physics/rigid_contact.hpp for the exceptions).
  /// @code
  ///   dm::WorldState s = world.makeState();
  ///   if (auto st = world.step(s, 1e-3); !st) std::cerr << st.error() << '\n';
  ///   dm::Vec3 x = s.position(ball);
  /// @endcode
  Status step(WorldState& state, double dt) const;

  /// Restores `state` to `snapshot` (made from a state of this world) and
  /// recomputes the bounds; the following steps reproduce the original run
  /// bit for bit while no contact or joint is active (warm-start impulses
  /// and sleep are not in a snapshot: restore clears them and wakes every body, so constrained runs replay
  /// to solver accuracy, and two restores of one snapshot replay alike). Fails with InvalidArgument on a size
  /// mismatch or a non-finite value (naming the body and field). No allocation.
  /// @code
  ///   dm::WorldSnapshot snap = state.snapshot();
  ///   world.step(state, dt);
  ///   world.restore(state, snap);  // back to before the step
  /// @endcode
  Status restore(WorldState& state, const WorldSnapshot& snapshot) const;

  /// Sets one body's position (m), orientation and velocities (world) in
  /// `state`, waking the body's island if it sleeps. Fails with NotFound for
  /// an unknown id, InvalidArgument on non-finite values or a zero
  /// quaternion; orientation is normalised. Allocation-free unless it fails,
  /// and O(1) for an awake body (only its bounds are recomputed): a coupling
  /// may call it for each body it touches every step.
  Status setBodyState(WorldState& state, BodyId id, const Vec3& position, const Quat& orientation,
                      const Vec3& linearVelocity, const Vec3& angularVelocity) const;

  /// Applies an impulse J (N·s, world) at world point `point` (m) now:
  /// v += J/m, and for rigid bodies ω += I_w⁻¹ ((point − x) × J); a sleeping
  /// body's island wakes. Fails with
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
  void updateBound(WorldState& state, std::size_t i) const;  // body i's alone
  void applyImpulseAt(WorldState& state, std::uint32_t i, const Vec3& impulse, const Vec3& r) const;
  void stepSecondOrder(WorldState& state, int kind, double t, double dt) const;
  void stepRk4(WorldState& state, double t, double dt) const;
  // Contact pipeline (rigid_contact.cpp).
  bool contactsActive() const noexcept;
  void reserveContacts(WorldState& state) const;
  void beginContacts(WorldState& state) const;
  Status finishContacts(WorldState& state, double dt) const;
  void broadPhase(WorldState& state) const;
  void sortBottomUp(WorldState& state) const;  // broadPhase's pairs into solver order
  void narrowPhase(WorldState& state) const;
  void continuousCollision(WorldState& state) const;
  // Sleeping (rigid_contact.cpp).
  void wakeIsland(WorldState& state, std::uint32_t body) const noexcept;
  void wakeAll(WorldState& state) const noexcept;
  void holdSleepers(WorldState& state) const noexcept;
  void updateSleep(WorldState& state, double dt) const noexcept;
  bool jointed(std::uint32_t a, std::uint32_t b) const noexcept;
  bool collider(std::uint32_t i) const noexcept;

  std::vector<BodyDesc> bodies_;
  std::vector<BodyModel> model_;
  std::vector<double> masses_;
  std::vector<std::uint32_t> members_[3];       // dynamic bodies per IntegratorKind
  std::vector<std::uint32_t> rigidMembers_[2];  // rigid bodies among members_[0], members_[1]
  std::vector<Impulse> impulses_;
  ForceSet forces_;
  std::vector<ContactMaterial> materials_;  // per body
  ContactSettings contactSettings_;
  std::vector<JointDesc> jointDescs_;
  std::vector<Joint> joints_;                // built from the initial poses
  std::vector<std::uint64_t> jointedPairs_;  // (min << 32 | max) body indices, sorted
};

}  // namespace dm
