// dm/physics/accumulators.hpp — the forces of a PhysicsWorld.
//
// Forces are plain data, grouped by kind into a ForceSet. Each evaluation
// ("accumulate") clears every body's force and torque accumulator and runs
// the simulators in a fixed order, each adding into the accumulators:
//
//   1. body simulator     ExternalForce, ExternalTorque, Drag
//   2. gravity simulator  uniform gravity, NewtonianGravity
//   3. spring simulator   Spring (spring + damper between two anchor points)
//   4. user simulator     UserForce (std::function or C callback), in registration order
//
// The fixed order and the fixed order within each kind make the floating-point
// sums, and so whole runs, reproducible bit for bit. Impulses are events, not
// forces: the world applies them at the start of a step (PhysicsWorld::step).
//
// Units and frames: SI, world frame. Forces act at the centre of mass unless
// a point is given; a force f at a point r (world offset from the centre of
// mass) also adds the torque r × f. Anchors and points are given in the body
// frame (relative to the centre of mass) and rotate with the body.
//
// Plugins: a C-callable DmForceCallback plus a void* user pointer registers
// a force from a shared library without C++ types crossing the boundary.
//
// @code
//   dm::Spring s{.a = ground, .b = bob, .anchorB = {0, 0, 0.05}, .stiffness = 400, .restLength = 0.3};
//   if (auto st = world.addSpring(s); !st) return st.error();
//   world.setGravity({0, 0, -9.81});
// @endcode
#pragma once

#include <dm/core/result.hpp>
#include <dm/core/types.hpp>
#include <dm/physics/body.hpp>

#include <cstdint>
#include <functional>
#include <span>
#include <string>
#include <vector>

extern "C" {
/// C view of the bodies' current (stage) state handed to a DmForceCallback.
/// Arrays hold `bodyCount` entries, indexed by BodyId::index, contiguous
/// doubles: positions, linear and angular velocities 3 per body (m, m/s,
/// rad/s, world frame), orientations 4 per body (x, y, z, w), masses 1 per body.
typedef struct DmForceInput {
  double time;  ///< s, time of this evaluation (stage time inside a step)
  uint32_t bodyCount;
  const double* positions;
  const double* orientations;
  const double* linearVelocities;
  const double* angularVelocities;
  const double* masses;
} DmForceInput;

/// A C-callable force: add (never overwrite) forces (N) and torques (N·m,
/// about the centre of mass), 3 doubles per body each, world frame. Must not
/// retain the pointers; called from the simulation thread, possibly several
/// times per step (once per integrator stage).
typedef void (*DmForceCallback)(void* userData, const DmForceInput* input, double* forces, double* torques);
}

namespace dm {

/// Read-only view of every body's state at one evaluation (a step's stage).
/// Spans have one entry per body, indexed by BodyId::index.
struct BodyStateView {
  double time = 0.0;                      ///< s
  std::span<const Vec3> position;         ///< m, centre of mass
  std::span<const Quat> orientation;      ///< body → world, unit
  std::span<const Vec3> linearVelocity;   ///< m/s
  std::span<const Vec3> angularVelocity;  ///< rad/s, world frame
  std::span<const double> mass;           ///< kg (static bodies: as described)
};

/// Per-body accumulators an evaluation adds into (world frame, torque about
/// the centre of mass). One entry per body.
struct ForceOutput {
  std::span<Vec3> force;   ///< N
  std::span<Vec3> torque;  ///< N·m
};

/// A constant force (N, world frame) at a body-frame point (m, relative to
/// the centre of mass).
struct ExternalForce {
  BodyId body;
  Vec3 force = Vec3::Zero();
  Vec3 point = Vec3::Zero();
};

/// A constant torque (N·m, world frame).
struct ExternalTorque {
  BodyId body;
  Vec3 torque = Vec3::Zero();
};

/// Drag opposing the motion of a body: F = −linear·v − quadratic·|v|·v
/// (linear in N·s/m, quadratic in N·s²/m², both ≥ 0) and, for rigid bodies,
/// τ = −angular·ω (N·m·s, ≥ 0).
struct Drag {
  BodyId body;
  double linear = 0.0;
  double quadratic = 0.0;
  double angular = 0.0;
};

/// Newtonian attraction between every pair of `bodies` (every body when
/// empty; static bodies attract but do not move): F = G m₁ m₂ r / (|r|² + ε²)^{3/2} with ε the
/// `softening` length (m, ≥ 0), which bounds the force of close encounters.
/// O(n²) per evaluation for n bodies.
struct NewtonianGravity {
  double gravitationalConstant = 6.6743e-11;  ///< G, m³/(kg·s²), > 0
  double softening = 0.0;                     ///< ε, m
  std::vector<BodyId> bodies;                 ///< participants; empty: every body
};

/// Spring and damper between anchor points of two bodies (body frames, m,
/// relative to the centres of mass). With d = pB − pA between the world
/// anchors, L = |d|, u = d / L and v_rel = ṗB − ṗA, the force on A is
/// (stiffness (L − restLength) + damping (v_rel·u)) u, the opposite on B,
/// each at its anchor (so it turns rigid bodies). A zero rest length gives
/// the isotropic spring stiffness·d + damping·v_rel, defined also at L = 0.
/// stiffness = 0 is a pure damper. Use a static body as a fixed point.
struct Spring {
  BodyId a, b;
  Vec3 anchorA = Vec3::Zero();
  Vec3 anchorB = Vec3::Zero();
  double stiffness = 0.0;   ///< N/m, ≥ 0
  double restLength = 0.0;  ///< m, ≥ 0
  double damping = 0.0;     ///< N·s/m, ≥ 0
};

/// One-shot impulse (N·s, world frame) at a body-frame point (m, relative to
/// the centre of mass), applied at the start of the step whose interval
/// [t, t + dt) contains `time` (s). Changes momentum by exactly `impulse`.
struct Impulse {
  BodyId body;
  Vec3 impulse = Vec3::Zero();
  Vec3 point = Vec3::Zero();
  double time = 0.0;
};

/// A user force from C++: add into `out` from `state`. Must not allocate,
/// lock or throw if the world is stepped in a real-time loop.
using UserForceFn = std::function<void(const BodyStateView& state, ForceOutput& out)>;

/// A registered user force: a C++ callable, or a C callback + user data.
struct UserForce {
  std::string name;                    ///< for messages
  UserForceFn function;                ///< used when set
  DmForceCallback callback = nullptr;  ///< used when `function` is empty
  void* userData = nullptr;            ///< passed to `callback`
};

/// Every force of a world, by kind; evaluated by accumulateForces in the
/// order documented at the top of this header.
struct ForceSet {
  Vec3 gravity = Vec3::Zero();  ///< m/s², uniform gravitational acceleration (F = m g)
  std::vector<ExternalForce> forces;
  std::vector<ExternalTorque> torques;
  std::vector<Drag> drags;
  std::vector<NewtonianGravity> newtonian;
  std::vector<Spring> springs;
  std::vector<UserForce> user;
};

/// Checks an accumulator against a world of `bodies` (descriptions indexed
/// by BodyId::index): known body ids, finite values, non-negative
/// coefficients, no impulse or force on a static body. `where` names the
/// accumulator in the message ("springs[2]"). O(1) (NewtonianGravity: O(n)).
/// @code
///   auto st = dm::validateAccumulator(spring, world.bodies(), "springs[0]");
///   if (!st) std::cerr << st.error() << '\n';
/// @endcode
Status validateAccumulator(const ExternalForce& f, std::span<const BodyDesc> bodies,
                           const std::string& where);
/// As above, for a torque.
Status validateAccumulator(const ExternalTorque& t, std::span<const BodyDesc> bodies,
                           const std::string& where);
/// As above, for drag.
Status validateAccumulator(const Drag& d, std::span<const BodyDesc> bodies, const std::string& where);
/// As above, for Newtonian gravity (also: no body listed twice).
Status validateAccumulator(const NewtonianGravity& g, std::span<const BodyDesc> bodies,
                           const std::string& where);
/// As above, for a spring (also: a ≠ b).
Status validateAccumulator(const Spring& s, std::span<const BodyDesc> bodies, const std::string& where);
/// As above, for an impulse.
Status validateAccumulator(const Impulse& i, std::span<const BodyDesc> bodies, const std::string& where);

/// Clears `out` and adds every force of `set` evaluated at `state`, in the
/// documented order. Spans of `state` and `out` have one entry per body
/// (C callbacks see them as packed doubles: Vec3 and Quat are tightly
/// packed). O(accumulators + n² per NewtonianGravity); allocates nothing.
/// @code
///   dm::ForceOutput out{forces, torques};
///   dm::accumulateForces(set, view, out);
///   Vec3 a0 = out.force[0] / view.mass[0];
/// @endcode
void accumulateForces(const ForceSet& set, const BodyStateView& state, ForceOutput& out);

/// Adds a force `f` (N, world) acting at world offset `r` (m) from body `i`'s
/// centre of mass: force += f, torque += r × f. O(1).
inline void addForceAt(ForceOutput& out, std::uint32_t i, const Vec3& f, const Vec3& r) {
  out.force[i] += f;
  out.torque[i] += r.cross(f);
}

}  // namespace dm
