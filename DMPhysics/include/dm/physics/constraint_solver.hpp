// dm/physics/constraint_solver.hpp — contact and joint solver for rigid bodies
// (sequential impulses / projected Gauss–Seidel), working on plain arrays.
//
// What it is for: the velocity-level constraint solver that a physics world
// calls once per step after it has integrated external forces into the body
// velocities and before it integrates velocities into positions. It knows
// nothing about shapes or worlds: it takes solver bodies, contact constraints
// (built from dm::ContactPoint, dm/collide/query.hpp) and joints (ball,
// hinge, slider, fixed — the joints of surgical instruments) as spans.
//
// Algorithm (Catto 2005, "Iterative Dynamics with Temporal Coherence"; Catto
// 2006, "Fast and Simple Physics using Sequential Impulses"; Box2D's contact
// and joint solvers; Bullet's split impulses):
//   1. prepare: every constraint becomes rows J·v = target with a Jacobian J
//      (linear and angular parts per body), an effective mass 1/(J M⁻¹ Jᵀ),
//      a velocity target (restitution, position bias) and impulse bounds;
//   2. warm start: the accumulated impulses of the previous step (contacts:
//      matched by ContactCache; joints: stored in the Joint) are applied,
//      scaled by SolverOptions::warmStartFactor;
//   3. velocity iterations: each row in turn gets the impulse that makes it
//      satisfied, Δλ = m_eff·(target − J·v); the *accumulated* impulse is
//      clamped (contact normal ≥ 0, friction inside the Coulomb cone
//      |λt| ≤ μ·λn, limit rows ≥ 0) and only the clamped change applied.
//      Joint rows come first, then per contact the two friction rows and the
//      normal row, so that non-penetration is the last word of a sweep.
//      Contacts are taken manifold by manifold (consecutive contacts of one
//      body pair); up to four manifolds that share no dynamic body are solved
//      side by side in SIMD lanes (two SSE2 registers of doubles; with GCC
//      on x86-64 also one 256-bit register, in AVX2 and AVX-512 versions
//      picked at load time; lane by lane the scalar arithmetic without FMA,
//      so every version gives the same bits; the rows are 32-byte aligned
//      for the wide loads), which gives exactly the result of solving them one after
//      the other. The sweep order is the input order, each manifold joined
//      by the first independent ones of the next 8 (a wider window fills
//      the lanes no better and lets a 20-row pyramid at 1/60 s drift more);
//   4. position correction: with split impulses (default) the penetration and
//      joint drift are removed by *pseudo-velocities* (SolverBody::push*)
//      solved in separate iterations and integrated into the positions only,
//      so correction never adds kinetic energy; without them a Baumgarte bias
//      β·C/Δt is added to the velocity targets.
// Restitution applies only when the approach speed exceeds
// SolverOptions::restitutionThreshold; penetration up to SolverOptions::slop
// is tolerated (no correction) so resting contacts do not jitter.
//
// Sign conventions: contact normal n points from body A to body B (B moves
// along n to separate, as dm::ContactPoint); the relative velocity is
// v_rel = v_B(p) − v_A(p); the normal impulse λn ≥ 0 acts as +λn·n on B and
// −λn·n on A. Joint rows: impulse +λ·J_B on B, +λ·J_A on A.
// Units SI: m, kg, s, rad; impulses N·s; velocities m/s and rad/s; inertia
// kg·m². Body orientations map body → world; all vectors in the world frame
// unless named *Local (body frame).
//
// Real-time: ConstraintSolver::solve(), ContactCache::warmStart()/store()
// and the integration helpers do not allocate, lock or throw once the
// capacities are reserved (ConstraintSolver::reserve, ContactCache::reserve);
// a step larger than the reserved capacity grows the scratch once.
//
// @code
//   dm::ConstraintSolver solver;
//   solver.reserve(bodies.size(), contacts.size(), joints.size());
//   dm::integrateVelocities(bodies, {0, 0, -9.81}, dt);
//   auto stats = solver.solve(bodies, contacts, joints, dt, {});
//   dm::integratePositions(bodies, dt);
// @endcode
#pragma once

#include <dm/collide/query.hpp>
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

namespace dm {

/// Index meaning "the static world" in ContactConstraint and Joint body
/// fields: zero velocity, infinite mass, identity pose (its anchors are world
/// points, its axes world directions).
inline constexpr int kWorldBody = -1;

/// One rigid body as the solver sees it. `invMass == 0` makes it static or
/// kinematic (its velocities are then never changed by the solver).
struct SolverBody {
  Vec3 position = Vec3::Zero();         ///< centre of mass, world, m
  Quat orientation = Quat::Identity();  ///< body → world, unit
  Vec3 linearVelocity = Vec3::Zero();   ///< of the centre of mass, m/s
  Vec3 angularVelocity = Vec3::Zero();  ///< world frame, rad/s
  double invMass = 0.0;                 ///< 1/kg; 0: static or kinematic
  Mat3 invInertiaLocal = Mat3::Zero();  ///< inverse inertia about the centre of mass, body frame, 1/(kg·m²)
  Mat3 invInertia = Mat3::Zero();       ///< the same in the world frame (R·I⁻¹·Rᵀ), used by the solver
  /// Split-impulse pseudo-velocities written by ConstraintSolver::solve()
  /// (m/s, rad/s): integrated into the pose by integratePositions(), never
  /// into the velocities.
  Vec3 pushVelocity = Vec3::Zero();
  Vec3 turnVelocity = Vec3::Zero();

  /// A dynamic body of `mass` (kg > 0; ≤ 0 gives a static body) and
  /// body-frame inertia `inertiaLocal` (kg·m², about the centre of mass,
  /// invertible) at `position`/`orientation`.
  /// @code
  ///   auto box = dm::SolverBody::dynamic(2.0, dm::boxInertia(2.0, half), {0, 0, 0.1});
  /// @endcode
  static SolverBody dynamic(double mass, const Mat3& inertiaLocal, const Vec3& position,
                            const Quat& orientation = Quat::Identity());
  /// A static body (infinite mass) at a pose.
  static SolverBody fixed(const Vec3& position, const Quat& orientation = Quat::Identity());
  /// Recomputes `invInertia` = R·invInertiaLocal·Rᵀ from the orientation. O(1).
  void updateWorldInertia() noexcept;
  /// Velocity of the body point at world position `p`, m/s.
  Vec3 velocityAt(const Vec3& p) const noexcept {
    return linearVelocity + angularVelocity.cross(p - position);
  }
};

/// Inertia tensor (kg·m², body frame) of a solid box of `mass` (kg) and
/// half extents `halfExtents` (m), as dm::Box.
Mat3 boxInertia(double mass, const Vec3& halfExtents) noexcept;
/// Inertia tensor (kg·m²) of a solid sphere of `mass` (kg) and `radius` (m).
Mat3 sphereInertia(double mass, double radius) noexcept;

/// One contact point between bodies A and B (indices into the body span, or
/// kWorldBody) with its material and its accumulated impulses. A separated
/// (speculative, depth < 0) contact only stops the bodies from closing the gap
/// by more than −depth this step; restitution applies to touching ones. The
/// impulses are inputs (warm start, usually filled by ContactCache) and
/// outputs of ConstraintSolver::solve().
struct ContactConstraint {
  int bodyA = kWorldBody;
  int bodyB = kWorldBody;
  ContactPoint point;     ///< world position, unit normal from A to B, depth (m; < 0: separated by −depth)
  double friction = 0.5;  ///< Coulomb coefficient μ ≥ 0
  double restitution = 0.0;             ///< coefficient e in [0, 1]
  std::uint64_t featureKey = 0;         ///< identifies the contact across steps (0: match by position)
  double normalImpulse = 0.0;           ///< accumulated λn, N·s (≥ 0)
  Vec3 frictionImpulse = Vec3::Zero();  ///< accumulated tangential impulse on B, world, N·s

  /// A contact between bodies `a` and `b` from a narrow-phase contact.
  /// @code
  ///   for (const auto& p : hit.contacts) contacts.push_back(dm::ContactConstraint::make(0, 1, p, 0.4, 0.2));
  /// @endcode
  static ContactConstraint make(int a, int b, const ContactPoint& p, double friction = 0.5,
                                double restitution = 0.0) noexcept {
    ContactConstraint c;
    c.bodyA = a;
    c.bodyB = b;
    c.point = p;
    c.friction = friction;
    c.restitution = restitution;
    return c;
  }
};

/// Kind of a joint.
enum class JointType : std::uint8_t {
  Ball,    ///< point-to-point: 3 linear rows
  Hinge,   ///< ball + 2 angular rows (rotation about one axis), optional angle limits (rad)
  Slider,  ///< prismatic: 2 linear + 3 angular rows, optional translation limits (m)
  Fixed,   ///< weld: 3 linear + 3 angular rows
};

/// Most rows one joint produces (slider/hinge with both limits: 7).
inline constexpr int kMaxJointRows = 8;

/// A joint between bodies A and B (indices or kWorldBody). Build it with the
/// factory functions from the current body poses; they store anchors and axes
/// in each body's frame. `impulses` holds the accumulated row impulses (N·s
/// for linear rows, N·m·s for angular rows) used for warm starting.
struct Joint {
  JointType type = JointType::Ball;
  int bodyA = kWorldBody;
  int bodyB = kWorldBody;
  Vec3 anchorA = Vec3::Zero();                   ///< anchor in A's frame relative to its centre of mass, m
  Vec3 anchorB = Vec3::Zero();                   ///< anchor in B's frame, m
  Vec3 axisA = Vec3::UnitX();                    ///< hinge/slider axis in A's frame, unit
  Vec3 axisB = Vec3::UnitX();                    ///< hinge axis in B's frame, unit
  Vec3 referenceA = Vec3::UnitY();               ///< hinge: zero-angle direction ⟂ axis, A's frame
  Vec3 referenceB = Vec3::UnitY();               ///< hinge: the same direction, B's frame
  Quat relativeRotation = Quat::Identity();      ///< slider/fixed: rest value of q_A⁻¹·q_B
  bool limitEnabled = false;                     ///< hinge angle (rad) / slider translation (m) limits
  double lower = 0.0;                            ///< lower limit, rad or m
  double upper = 0.0;                            ///< upper limit, rad or m
  std::array<double, kMaxJointRows> impulses{};  ///< accumulated row impulses (warm start)

  /// Ball joint holding the bodies together at `worldAnchor` (m).
  /// @code
  ///   auto j = dm::Joint::ball(bodies, dm::kWorldBody, 0, {0, 0, 1});   // pendulum pivot
  ///   if (!j) return j.error();
  ///   joints.push_back(*j);
  /// @endcode
  static Result<Joint> ball(std::span<const SolverBody> bodies, int a, int b, const Vec3& worldAnchor);
  /// Hinge about `worldAxis` (unit) through `worldAnchor`; the angle, 0 in the
  /// current pose, is the rotation of B relative to A about the axis
  /// (right-handed), limited to [lower, upper] ⊂ (−π, π) when `limitEnabled`.
  static Result<Joint> hinge(std::span<const SolverBody> bodies, int a, int b, const Vec3& worldAnchor,
                             const Vec3& worldAxis);
  /// Slider along `worldAxis` (unit, fixed in A) with anchors at `worldAnchor`;
  /// the translation s = axis·(anchor_B − anchor_A), 0 now, is limited to
  /// [lower, upper] when `limitEnabled`. Relative rotation is locked.
  static Result<Joint> slider(std::span<const SolverBody> bodies, int a, int b, const Vec3& worldAnchor,
                              const Vec3& worldAxis);
  /// Weld keeping the current relative pose; `worldAnchor` is where the
  /// linear rows act (choose a point between the bodies).
  static Result<Joint> fixed(std::span<const SolverBody> bodies, int a, int b, const Vec3& worldAnchor);
};

/// Settings of ConstraintSolver::solve().
struct SolverOptions {
  int velocityIterations = 10;  ///< PGS sweeps over all rows (≥ 1)
  int positionIterations = 4;   ///< split-impulse sweeps (ignored without split impulses)
  /// Early exit: stop the sweeps when the largest velocity correction of a
  /// sweep (SolverStats::residual) falls below this, m/s; 0: always run all.
  double tolerance = 0.0;
  bool warmStart = true;         ///< apply the incoming accumulated impulses first
  double warmStartFactor = 1.0;  ///< scale of the warm-start impulses, [0, 1]
  bool splitImpulse = true;      ///< position correction by pseudo-velocities (else Baumgarte)
  double baumgarte = 0.2;        ///< velocity-bias fraction of the position error per step (no split), (0, 1]
  double pushFactor = 0.8;       ///< split-impulse fraction of the position error removed per step, (0, 1]
  double slop = 0.005;           ///< penetration left uncorrected, m
  double restitutionThreshold = 0.2;   ///< approach speed below which e = 0, m/s (keep > |g|·Δt)
  double maxCorrectionVelocity = 4.0;  ///< cap of the position-correction speed, m/s
};

/// What solve() did.
struct SolverStats {
  int iterations = 0;       ///< velocity sweeps run
  double residual = 0.0;    ///< largest |Δλ|/m_eff of the last sweep: velocity correction, m/s
  double maxImpulse = 0.0;  ///< largest accumulated normal or joint impulse, N·s
  int rows = 0;             ///< constraint rows solved
};

/// The solver. Holds only scratch (rows, per-body velocity copies) reused
/// between calls; everything persistent lives in the spans passed in. Not
/// thread-safe: one solver per thread.
class ConstraintSolver {
 public:
  /// Reserves scratch for `bodies`, `contacts` and `joints` so that solve()
  /// with at most these counts never allocates. O(capacity).
  void reserve(std::size_t bodies, std::size_t contacts, std::size_t joints);

  /// Solves the velocity constraints of one step of `dt` seconds in place:
  /// bodies' linear/angular velocities and push/turn velocities, contacts'
  /// and joints' accumulated impulses. Body velocities should already hold
  /// the external forces of the step (integrateVelocities()). Cost
  /// O((contacts + joints)·iterations). Fails with InvalidArgument (naming
  /// the offending field and index) on dt ≤ 0 or not finite, a body index out
  /// of range, a contact of a body with itself, a non-unit contact normal, or
  /// bad options; bodies are left untouched then.
  /// @code
  ///   auto stats = solver.solve(bodies, contacts, joints, 1.0 / 1000, {.velocityIterations = 20});
  ///   if (!stats) dm::log::warn("%s", stats.error().message().c_str());
  /// @endcode
  Result<SolverStats> solve(std::span<SolverBody> bodies, std::span<ContactConstraint> contacts,
                            std::span<Joint> joints, double dt, const SolverOptions& options);

  /// Internal joint row of the solver (exposed only so that the scratch
  /// vector can be declared here).
  struct Row {
    int a = 0, b = 0;
    double imA = 0.0, imB = 0.0;  // inverse masses of A and B
    Vec3 linA, angA, linB, angB;  // Jacobian
    Vec3 mAngA, mAngB;            // I⁻¹·angA, I⁻¹·angB
    double effMass = 0.0;
    double target = 0.0;      // velocity target, J·v = target
    double pushTarget = 0.0;  // split-impulse pseudo-velocity target
    double lo = 0.0, hi = 0.0;
    double impulse = 0.0;
    double pushImpulse = 0.0;
    double* out = nullptr;  // where the accumulated impulse goes back (joints)
  };
  /// Internal per-body velocity pair (v, ω) or pseudo-velocity pair (see Row).
  struct Velocity {
    Vec3 v, w;
  };
  /// Internal: contacts [begin, end) of one body pair (consecutive in the input).
  struct Manifold {
    std::uint32_t begin = 0, end = 0;
  };
  /// Internal: manifolds solved side by side, one per SIMD lane.
  static constexpr int kLanes = 4;
  /// Internal: the three rows (normal d = 0, tangents d = 1, 2) of contact k
  /// of each manifold of a Group, lane by lane (structure of arrays; a lane
  /// whose manifold has fewer contacts holds zeros, which the sweeps leave at
  /// zero impulse). The linear Jacobian is ∓u on A/B, so only the directions
  /// are stored; angular parts are angA = −rA × u, angB = rB × u;
  /// [d][c][lane] is component c of row d.
  struct alignas(32) WideRow {
    double u[3][3][kLanes];                          // normal, tangent 1, tangent 2
    double angA[3][3][kLanes], angB[3][3][kLanes];   // angular Jacobians
    double mAngA[3][3][kLanes], mAngB[3][3][kLanes];  // I⁻¹·angA, I⁻¹·angB
    double effMass[3][kLanes], impulse[3][kLanes];
    double imA[kLanes], imB[kLanes];  // inverse masses
    double friction[kLanes];
    double target[kLanes], pushTarget[kLanes], pushImpulse[kLanes];
  };
  /// Internal: up to kLanes manifolds that share no dynamic body, with their
  /// WideRows [rowBegin, rowEnd) and per lane its manifold (kNoManifold: an
  /// empty lane) and body indices (an empty lane names the static world).
  struct Group {
    std::uint32_t rowBegin = 0, rowEnd = 0;
    std::uint32_t manifold[kLanes];
    int a[kLanes], b[kLanes];
  };
  static constexpr std::uint32_t kNoManifold = 0xffffffffu;  ///< internal: an empty lane

 private:
  Status validate(std::span<const SolverBody> bodies, std::span<const ContactConstraint> contacts,
                  std::span<const Joint> joints, double dt, const SolverOptions& options) const;
  void buildJointRows(std::span<const SolverBody> bodies, Joint& joint, double dt, const SolverOptions& o);
  void buildContactRows(std::span<const SolverBody> bodies, std::span<const ContactConstraint> contacts,
                        double dt, const SolverOptions& o);
  void scheduleManifolds(std::span<const ContactConstraint> contacts);
  template <bool kResidual>
  double sweep();
  void pushSweep();
  // Per body (index n: the static world): velocities, pseudo-velocities and
  // mass properties, kept apart so the sweeps touch only velocities.
  std::vector<Velocity> velocity_, push_;
  std::vector<double> invMass_;
  std::vector<Mat3> invInertia_;
  std::vector<Row> jointRows_;
  std::vector<Manifold> manifolds_;
  std::vector<std::uint8_t> scheduled_;
  // Sweep order: groups of up to kLanes manifolds that share no dynamic
  // body, solved side by side in SIMD lanes (their rows in wideRows_); the
  // groups follow the input order of their first manifold.
  std::vector<Group> groups_;
  std::vector<WideRow> wideRows_;
};

/// Keeps the accumulated impulses of the contacts of the last step and hands
/// them to the matching contacts of the next one (temporal coherence). A new
/// contact matches an old one of the same body pair with the same non-zero
/// featureKey, or, for key 0, the nearest old contact whose anchor in body
/// A's frame lies within `matchDistance` and whose normal is within ~45°.
class ContactCache {
 public:
  double matchDistance = 0.01;  ///< m

  /// Reserves room for `contacts` stored contacts (no allocation afterwards).
  void reserve(std::size_t contacts);
  /// Fills normalImpulse/frictionImpulse of `contacts` from the stored ones
  /// (unmatched: zero) and returns how many matched. O(n log n), no allocation
  /// within the reserved capacity.
  /// @code
  ///   cache.warmStart(contacts, bodies);
  ///   solver.solve(bodies, contacts, joints, dt, {});
  ///   cache.store(contacts, bodies);
  /// @endcode
  int warmStart(std::span<ContactConstraint> contacts, std::span<const SolverBody> bodies);
  /// Replaces the stored contacts by `contacts` (after solve()). O(n + r log r)
  /// for r runs of consecutive contacts of one pair.
  void store(std::span<const ContactConstraint> contacts, std::span<const SolverBody> bodies);
  /// Speculative contacts for the pair (a, b) (as stored, a before b) whose
  /// shapes no longer overlap: each stored contact of the pair is carried by
  /// both bodies to their poses in `bodies`; one whose anchors moved apart by
  /// less than `margin` (m) along the normal and across it is appended to
  /// `out` with depth = its old depth − that separation (≤ 0: the solver lets
  /// the gap close, no more), friction `mu` and restitution `e`. Returns how
  /// many. O(log n + contacts of the pair); appends within `out`'s capacity.
  int persist(int a, int b, std::span<const SolverBody> bodies, double margin, double mu, double e,
              std::vector<ContactConstraint>& out) const;
  /// Forgets everything.
  void clear() noexcept {
    entries_.clear();
    runs_.clear();
  }
  std::size_t size() const noexcept { return entries_.size(); }

 private:
  struct Entry {
    int a = 0, b = 0;
    std::uint64_t key = 0;
    Vec3 localA;        // anchor in A's frame
    Vec3 localB;        // the same point in B's frame
    Vec3 normalLocalA;  // normal in A's frame
    double depth = 0.0;
    Vec3 normal;  // world
    double normalImpulse = 0.0;
    Vec3 frictionLocalA;  // friction impulse in A's frame
  };
  struct Run {  // consecutive input contacts [begin, end) of one pair
    int a = 0, b = 0;
    std::uint32_t begin = 0, end = 0;
  };
  // The runs of pair (a, b), [first, last); `hint`: where they may start
  // (checked, then searched for if not).
  std::pair<const Run*, const Run*> runsOf(int a, int b, const Run* hint = nullptr) const noexcept;
  std::vector<Entry> entries_;  // in input order
  std::vector<Run> runs_;       // entries_' pair runs, sorted by pair (a, b), a pair's by begin
  std::vector<std::uint8_t> used_;
};

/// Adds `gravity` (m/s²) · dt to the velocity of every dynamic body
/// (invMass > 0). O(n), no allocation.
/// @code
///   dm::integrateVelocities(bodies, {0, 0, -9.81}, dt);
/// @endcode
void integrateVelocities(std::span<SolverBody> bodies, const Vec3& gravity, double dt) noexcept;

/// Semi-implicit Euler position update of every body (kinematic ones move
/// with their velocities too): x += (v + push)·dt,
/// q ← normalize(q + ½·dt·(ω + turn)⊗q), then refreshes `invInertia` and
/// clears the push/turn velocities. Gyroscopic torque is not modelled.
/// O(n), no allocation.
void integratePositions(std::span<SolverBody> bodies, double dt) noexcept;

}  // namespace dm
