// dm/physics/rigid_contact.hpp — what a PhysicsWorld needs to run rigid
// contact and joints inside its step: per-body contact materials, world
// contact settings, joint descriptions, and the per-state scratch of the
// contact pipeline.
//
// Pipeline (PhysicsWorld::step, dm/physics/world.hpp), for bodies with a
// shape whose material has `collides` set:
//   1. broad phase at the start-of-step poses: a sort-and-sweep on x of the
//      world AABBs kept in the WorldState (dm::boxesOverlap; the sort is an
//      insertion sort from the last step's order), planes
//      (unbounded shapes) paired with every bounded collider; pairs of two
//      non-dynamic bodies and pairs joined by a joint are skipped; pairs
//      are ordered bottom-up (by the lower box bottom along z, then
//      indices) so that Gauss–Seidel sweeps carry support up a stack;
//   2. narrow phase: dm::collide (DMCollide's collider table) per pair, up
//      to ContactSettings::maxContactsPerPair contacts, normals from the
//      lower to the higher body index; a pair that does not collide now but
//      had contacts in the last step keeps them as speculative contacts
//      (depth < 0) while both bodies carry their anchors apart by less than
//      ContactSettings::contactMargin (the broad phase pairs boxes that
//      close, too); a pair with no such history closer than the margin
//      (dm::distance) gets the manifold it would have if B were moved onto
//      A, moved back, as speculative contacts (a scene built touching);
//   3. the force accumulators and integrators advance every body as before;
//   4. continuous collision (bodies whose material has `ccd` set): the
//      motion of the shape from its start-of-step pose to the integrated
//      one is tested against every other collider its swept box reaches by
//      dm::conservativeAdvancement (dm::bisectImpact for pairs without a
//      distance query); at the first hit the body is moved back to its
//      pose at the time of impact and a touching contact is added, so the
//      solver (restitution, friction) handles it — a fast small body does
//      not tunnel through a thin plate;
//   5. bodies in a contact or a joint are reset to their start-of-step pose
//      and keep their integrated velocity; the ConstraintSolver (sequential
//      impulses with restitution, Coulomb friction, split-impulse position
//      correction) solves contacts and joints, warm-started by a
//      ContactCache; their poses are then advanced by
//      dm::integratePositions (semi-implicit Euler, whatever their
//      integrator kind: constrained bodies are first order). Bodies without
//      contacts or joints keep their integrator's result bit for bit.
//   6. sleeping (ContactSettings::sleep): bodies joined by contacts form
//      islands (static bodies join nothing); a dynamic body counts as still
//      while it touches something and |v|, |ω| stay below the thresholds;
//      an island whose bodies have all been still for timeToSleep falls
//      asleep: velocities zero, no integration, no narrow phase among
//      sleepers and the ground, no solver rows. An island wakes when an awake
//      dynamic body collides with one of its bodies or comes within
//      contactMargin of it, and every body wakes on
//      PhysicsWorld::applyImpulse, setBodyState (that body's island) and
//      restore (all). Bodies that a joint, an external force or torque, a
//      spring, Newtonian gravity or a pending timed impulse acts on never
//      sleep, nor does any body while the world has a user force (those
//      forces may change without the world seeing it). Sleeping is
//      deterministic like the rest; a snapshot does not hold it.
// Materials combine per contact as friction √(μa·μb) and restitution
// max(ea, eb) (Box2D's rules); a static body's material counts as well.
// Everything runs on the calling thread in a fixed order: the same model,
// state and dt give bit-identical results. No allocation once makeState()
// has reserved the scratch (ContactSettings::contactCapacity), except that a
// step with more pairs or contacts than reserved grows the buffers once, and
// a CCD query that starts overlapping lets DMCollide allocate its contact.
#pragma once

#include <dm/collide/broadphase.hpp>
#include <dm/collide/query.hpp>
#include <dm/core/types.hpp>
#include <dm/physics/body.hpp>
#include <dm/physics/constraint_solver.hpp>

#include <cstddef>
#include <cstdint>
#include <vector>

namespace dm {

/// Contact behaviour of one body (PhysicsWorld::setMaterial).
struct ContactMaterial {
  double friction = 0.5;     ///< Coulomb coefficient μ ≥ 0
  double restitution = 0.0;  ///< coefficient of restitution e in [0, 1]
  /// Continuous collision detection for this body (fast, small bodies): see
  /// step 4 in the file comment. Costs one time-of-impact query per nearby
  /// collider per step while the body moves more than half its thickness.
  bool ccd = false;
  /// False: the body's shape only gives bounds, it takes part in no contact.
  bool collides = true;
};

/// World-wide contact settings (PhysicsWorld::setContactSettings).
struct ContactSettings {
  /// False: the step runs no collision detection (joints are still solved).
  bool enabled = true;
  /// Solver settings: 20 velocity sweeps, 4 split-impulse sweeps, 1 mm slop.
  SolverOptions solver{.velocityIterations = 20, .positionIterations = 4, .slop = 0.001};
  /// Most contacts per body pair from the narrow phase (≥ 1; box–box
  /// manifolds are reduced to it).
  int maxContactsPerPair = 4;
  /// Pairs reserved by makeState() (0: 4 per collider + 1 per collider per
  /// plane); contacts reserved: maxContactsPerPair per pair.
  std::size_t pairCapacity = 0;
  /// CCD: distance at which conservative advancement reports an impact, m.
  double ccdTolerance = 1e-6;
  /// Persistent and speculative contacts (step 2): a pair that touched in
  /// the last step and now lies apart by less than this keeps its last
  /// contact points as speculative ones, and a new pair that close gets
  /// speculative contacts (they stop the bodies from closing the gap by more
  /// than it, nothing else), so resting bodies that lift by a hair at large
  /// dt, or were placed touching, do not fall in free flight. 0: off. m, ≥ 0.
  double contactMargin = 0.002;
  /// Sleeping (step 6 in the file comment); off by default, so every body is
  /// simulated every step unless asked otherwise.
  bool sleep = false;
  double sleepLinearVelocity = 0.05;   ///< |v| below which a body counts as still, m/s (≥ 0)
  double sleepAngularVelocity = 0.05;  ///< |ω| below which a rigid body counts as still, rad/s (≥ 0)
  double timeToSleep = 0.5;            ///< s an island must stay still before it sleeps (> 0)
};

/// A joint between two bodies, built from their initial poses (the BodyDesc
/// positions and orientations) by PhysicsWorld::addJoint. `a` or `b` may be
/// a default BodyId: the static world.
struct JointDesc {
  JointType type = JointType::Ball;  ///< ball, hinge, slider or fixed
  BodyId a;                          ///< first body (default: the world)
  BodyId b;                          ///< second body (default: the world)
  Vec3 anchor = Vec3::Zero();        ///< world anchor at the initial poses, m
  Vec3 axis = Vec3::UnitX();         ///< hinge / slider axis, world, nonzero
  bool limitEnabled = false;         ///< hinge angle (rad) / slider travel (m) limits
  double lower = 0.0;                ///< lower limit, rad or m
  double upper = 0.0;                ///< upper limit, rad or m
};

/// What the contact pipeline did in the last step.
struct ContactStats {
  std::size_t pairs = 0;        ///< broad-phase pairs tested by the narrow phase
  std::size_t contacts = 0;     ///< contact points solved (CCD ones included)
  std::size_t ccdHits = 0;      ///< bodies moved back to a time of impact
  std::size_t warmStarted = 0;  ///< contacts matched by the ContactCache
  std::size_t sleeping = 0;     ///< bodies asleep after the step (ContactSettings::sleep)
  SolverStats solver;           ///< the ConstraintSolver's report (zero when nothing was solved)
};

/// Per-state scratch and persistent data of the contact pipeline (owned by a
/// WorldState; copied with it). Internal: read it through WorldState.
struct RigidContactState {
  std::vector<SolverBody> bodies;           ///< one per world body, start-of-step poses
  std::vector<Isometry3> shapePoses;        ///< per collider: shape pose at `bodies` (see beginContacts)
  std::vector<std::uint8_t> colliderKind;   ///< per body, this step: 0 no collider, 1 bounded, 2 unbounded
  std::vector<ContactConstraint> contacts;  ///< the step's contacts
  std::vector<Joint> joints;                ///< the world's joints with their warm-start impulses
  std::vector<std::uint32_t> order;         ///< broad phase: bounded colliders sorted by min x (next sort's start)
  struct SweepBox {                         ///< broad phase: a collider's box, packed for the sweep
    double lo[3], hi[3];
    std::uint32_t id;
  };
  std::vector<SweepBox> sweep;  ///< broad phase: bounded colliders' boxes sorted by min x
  /// Broad phase: `sweep`'s min x, then 4 entries of +∞ (padding for 4-wide
  /// loads, which the x test rejects).
  std::vector<double> sweepLo;
  /// Broad phase: `sweep`'s y and z extents as floats, lower bounds rounded
  /// down and upper bounds plus the contact margin rounded up (a cheap test
  /// that every pair the exact one accepts passes): four runs of m + 4
  /// entries for m boxes, lo y, lo z, hi y, hi z.
  std::vector<float> sweepFilter;
  std::vector<std::uint32_t> zOrder;   ///< broad phase: colliders sorted by min z (next sort's start)
  std::vector<std::uint32_t> zRank;    ///< broad phase: per body, its place in zOrder
  std::vector<std::uint32_t> buckets;  ///< broad phase: per zOrder place, where its pairs start
  std::vector<ProxyPair> bucketed;     ///< broad phase: the pairs grouped by their lower body
  std::vector<ProxyPair> pairs;             ///< broad phase: body index pairs (a < b), bottom-up
  std::vector<std::uint8_t> constrained;    ///< per body: in a contact or joint this step
  std::vector<std::uint8_t> asleep;         ///< per body: 1 while asleep
  std::vector<std::uint8_t> sleepBlocked;   ///< per body, per step: a force or joint keeps it awake
  std::vector<double> stillTime;            ///< per body: s spent still and touching (awake bodies)
  std::vector<double> islandTime;           ///< per body: scratch, an island's least stillTime
  std::vector<std::uint32_t> island;        ///< per body: union-find parent; a sleeper's island id
  std::size_t sleeping = 0;                 ///< bodies asleep
  CollisionResult narrow;                   ///< narrow-phase result, reused
  ConstraintSolver solver;
  ContactCache cache;
  ContactStats stats;
};

}  // namespace dm
