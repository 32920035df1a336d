// dm/physics/rod.hpp — slender elastic rods: suture threads, guidewires,
// catheters, tendons. A Cosserat rod of rigid segments joined end to end,
// stepped by a direct (block-tridiagonal) XPBD solve, so that a long thread
// stays as inextensible as its material says however many segments it has.
//
// Model. The rod is n rigid segments (position p_i of the centre, orientation
// q_i whose body z axis is the tangent, rest length l_i, a solid circular
// cross-section of radius r, density ρ). Neighbouring segments are joined at
// their ends by a joint with six constraint rows:
//  * stretch and shear: C_p = (p_i + R_i a_i) − (p_{i+1} + R_{i+1} b_{i+1}),
//    the gap between the end of segment i (a_i = +l_i/2 ẑ) and the start of
//    segment i+1 (b = −l/2 ẑ). Compliance l_c/(EA) in every direction (l_c the
//    mean of the two lengths, A = πr²): the axial part is the rod's
//    extension, exactly F/(EA) per unit length under a tension F; shear is
//    taken as stiff as stretch (for a slender rod both are orders of magnitude
//    stiffer than bending, and neither shows in its shape).
//  * bending and twist: C_r = 2 Im(q̄_rest q̄_i q_{i+1}), the rotation vector
//    (for small angles) of the relative rotation of the two segments against
//    its rest value, in the frame of segment i+1: x and y components are
//    bending, z is twist. Compliance l_c/(EI) for bending (I = πr⁴/4) and
//    l_c/(GJ) for twist (J = πr⁴/2): the discrete bending energy
//    ½ (EI/l_c) θ², i.e. ½ EI κ² per unit length with κ = θ/l_c.
// Each constraint stands for the rod's length between the two segments'
// centres (l_c); an end attachment stands for the end segment's outer half,
// so the lengths add up to the rod's and a rod held at both ends stretches
// and twists by exactly F L/(EA) and T L/(GJ).
// Ends can be free, pinned (a ball joint at a world point: the three C_p
// rows) or clamped (all six rows, against a world point and frame); moving
// the point (and frame) from step to step drags the end, as a grasper or
// needle driver does. Any segment can be grasped (held at a pose the caller
// moves: the jaws of a needle driver), and forces applied at any node.
//
// Integration (Macklin, Müller & Chentanez 2016, "XPBD: position-based
// simulation of compliant constrained dynamics"; Deul, Kugelstadt, Weiler &
// Bender 2018, "Direct position-based solver for stiff rods"). Each step of
// size h predicts every segment with its velocity and the applied forces,
// then makes `iterations` Newton-like passes over all constraints at once:
// with C the stacked constraints, J their Jacobian with respect to the
// segments' positions and world-frame rotations, W the inverse masses and
// inertias, α̃ = α/h² the compliances and g = M (x − x̃) − Jᵀλ the primal
// residual against the prediction x̃,
//     (J W Jᵀ + α̃) Δλ = −C − α̃ λ + J W g,   Δx = W (Jᵀ Δλ − g),   λ ← λ + Δλ.
// Published XPBD drops g (it is zero while J stays as it was at x̃); keeping
// it makes the passes Newton's method on the backward-Euler step, so they
// converge to it and a settled rod carries no bias from J's change over the
// step (with g dropped and three passes a step, a cantilever's tip settled
// 0.35 % of its length from the elastica with 40 and with 80 segments alike). For the rotations W is the
// inverse of the inertia plus the stiffening part of the joint forces'
// geometric stiffness (Tournier, Nesme, Gilles & Faure 2015, "Stable
// constrained dynamics"): a tensioned light segment turns back much faster
// than its inertia alone says, and without it a 1 N pull on a 3-0 suture of
// 1 cm segments diverged within three steps. Rotations are applied and
// measured with the exact exponential and logarithm maps.
// Each step starts from x + h v with the last step's λ (rescaled to the new
// h), not from x̃ with λ = 0: thanks to g that start is allowed, a settled
// rod already satisfies it, and a light segment under a point force (whose
// predicted turn can exceed a radian at 1 kHz) is not flung far from the
// solution before the first pass.
// The constraints form a chain (an end attachment, the n−1 joints, the other
// end's attachment), so J W Jᵀ is block tridiagonal with 6×6 blocks and is
// solved exactly in O(n) by block Cholesky elimination (the block Thomas
// algorithm): a pass reaches the whole rod, where Gauss–Seidel projection
// (iMSTK's and most PBD threads') needs about n passes to carry a tug from
// one end to the other and leaves a long thread stretched under load.
// Velocities are then v = Δp/h, ω = log(q q̄_prev)/h, damped by
// exp(−damping·h). At convergence XPBD is backward Euler on the elastic
// energy, so a settled rod is in exact static equilibrium: the tests compare
// it with the catenary, the elastica, Saint-Venant torsion and Hooke's law.
// The constraint force of a row is λ/h² (the attachments' reactions).
//
// Units SI: m, kg, s, N, Pa, rad. A thread starts in the shape given by its
// nodes; its rest shape is straight (a thread, a guidewire) or that initial
// shape (a pre-curved catheter or needle-shaped wire).
//
// Cost and real time: step() is serial, allocates nothing and takes no
// lock; it returns an error (and does nothing) only for a bad step size. One
// pass costs about 0.95 µs per segment on the 2-core build machine (200
// segments, one pass: 0.19 ms a step, RelWithDebInfo;
// Bench/physics_rod_bench.cpp and docs/performance.md): Bullet's rope
// makes 18 passes in that time, and with 62 it still stretches by 3.2 % in
// a swing where this rod stretches by 5e-6. With contacts (two passes) 0.4 ms.
//
// Contact: planes, spheres and capsules (tools, bone, the table), without
// friction, at the nodes (spheres of the rod's radius). Segments long
// against a curved obstacle make the polygon's corners catch on it: over a
// smooth bar the two sides' tensions differ by up to 3 % with 7.5 mm
// segments on a 1 cm bar, by under 0.1 % with 3 mm on 2 cm (l/R ≲ 0.15).
// Known limit: the node contacts do not hold a thread under tension. A 3-0
// suture wrapped half round a 2 cm bar (2 mm segments), pinned below it on
// one side, a load ramped on the other: the tension waves of the first
// steps press the arc into the bar (1.6 mm by step 13) and the thread is
// through it by step 20, with 2 or 6 passes a step. The contacts' sweep,
// alternating with the joints' direct solve, cannot carry a stiff string's
// pressure on a curve: a sweep adds to a node's λ only 2·m·δ (m a
// segment's mass, δ the overlap: the node moved as if free), a force of
// 2mδ/h², 0.3 mN per mm of overlap for 2 mm of 3-0 suture at 1 kHz, while
// the tension presses each node with T·Δθ (30 mN at 0.3 N): the force
// builds only through overlap kept over many steps, and past the bar's
// axis the normal flips. Found building a capstan test (branch
// wip/rod-contact-friction: Coulomb friction, that test and the smallest
// reproduction). Next: the active contacts as a seventh row of their
// joint's block in the direct solve.
// Not yet: friction and the capstan law, self-collision, contact with
// tissue meshes (issue 33's next slices).
//
// @code
//   std::vector<dm::Vec3> nodes;
//   for (int i = 0; i <= 100; ++i) nodes.push_back({0.003 * i, 0, 0});
//   auto rod = dm::CosseratRod::create({.nodes = nodes});   // a 0.3 m nylon suture
//   rod->pin(dm::RodEnd::Start, nodes.front());
//   for (int i = 0; i < 1000; ++i) (void)rod->step(1e-3);
// @endcode
#pragma once

#include <dm/core/result.hpp>
#include <dm/core/types.hpp>

#include <cstddef>
#include <cstdint>
#include <vector>

namespace dm {

/// What the rest shape of a CosseratRod is.
enum class RodRestShape : std::uint8_t {
  Straight,  ///< straight and untwisted (threads, guidewires)
  Initial,   ///< the shape of RodOptions::nodes (pre-curved wires)
};

/// One of the rod's two ends.
enum class RodEnd : std::uint8_t {
  Start,  ///< node 0
  End,    ///< node n
};

/// What holds an end.
enum class RodAttachment : std::uint8_t {
  Free,     ///< nothing
  Pinned,   ///< a ball joint at a world point
  Clamped,  ///< a world point and a world frame
};

/// "free" / "pinned" / "clamped".
const char* toString(RodAttachment attachment) noexcept;

/// A rod to build. The defaults are a monofilament nylon suture (USP 3-0,
/// 0.3 mm across; E ≈ 3 GPa, G ≈ 1.1 GPa, 1140 kg/m³).
struct RodOptions {
  /// The centreline, node 0 … n: n segments, 1 … 100,000. Consecutive nodes
  /// at least 1e-9 m apart; each segment's rest length is its length here.
  std::vector<Vec3> nodes;
  double radius = 1.5e-4;       ///< m, > 0
  double density = 1140;        ///< kg/m³, > 0
  double youngModulus = 3e9;    ///< E, Pa, > 0 (stretch, shear, bending)
  double shearModulus = 1.1e9;  ///< G, Pa, > 0 (twist)
  RodRestShape rest = RodRestShape::Straight;
  Vec3 gravity{0, 0, -9.81};  ///< m/s², finite
  /// Velocity decay rate, 1/s, finite ≥ 0: each step scales the segments'
  /// linear and angular velocities by exp(−damping·h) (the surrounding
  /// tissue or fluid; 0 keeps momentum exactly).
  double damping = 0;
  /// Newton passes per step, 1 … 100. One is enough at a haptic rate for
  /// most threads; more make each step closer to the exact backward-Euler one.
  int iterations = 2;
};

/// A rigid obstacle the rod does not enter: a tool shaft, a bone, the table.
/// Frictionless in this version.
struct RodObstacle {
  enum class Shape : std::uint8_t { Plane, Sphere, Capsule };
  Shape shape = Shape::Plane;
  Vec3 a = Vec3::Zero();        ///< plane: a point on it; sphere: the centre; capsule: one end of the axis
  Vec3 b = Vec3::Zero();        ///< capsule: the other end of the axis (unused otherwise; must stay zero)
  Vec3 normal = Vec3::UnitZ();  ///< plane: the side the rod stays on (normalised here)
  double radius = 0;            ///< sphere, capsule: m, > 0; plane: 0
};

/// A force and a torque, in the world frame.
struct RodWrench {
  Vec3 force = Vec3::Zero();   ///< N
  Vec3 torque = Vec3::Zero();  ///< N·m, about the end node
};

/// What one step did.
struct RodStepReport {
  /// Largest remaining gap of a pinned or clamped end, or of a joint beyond
  /// its elastic stretch (|C_p + α̃λ| over the joints), m, after the last pass.
  double positionResidual = 0;
  /// The same for the rotation rows, rad.
  double rotationResidual = 0;
  /// Deepest overlap of the rod's surface with an obstacle at the end of the
  /// step, m (0 without contact).
  double penetration = 0;
};

/// A Cosserat rod: segments, joints, end attachments, node forces and the
/// direct XPBD step. Copyable (a copy is an independent simulation); not
/// thread-safe.
class CosseratRod {
 public:
  /// Most segments a rod may have.
  static constexpr std::size_t kMaxSegments = 100000;

  /// Builds the rod at rest in the shape of `options.nodes`, every end free,
  /// velocities zero. Fails with InvalidArgument naming the field.
  static Result<CosseratRod> create(const RodOptions& options);

  std::size_t segmentCount() const noexcept { return len_.size(); }
  std::size_t nodeCount() const noexcept { return len_.size() + 1; }

  /// Node k (0 … n): the start of segment k, the end of segment n−1 for k = n;
  /// where two segments meet, the midpoint of their two joint points (they
  /// differ by the joint's elastic stretch); an attached end node is its
  /// attachment's point.
  Vec3 node(std::size_t k) const;
  /// Centre and orientation of segment i (body z: from its start to its end).
  const Vec3& segmentCenter(std::size_t i) const { return p_[i]; }
  const Quat& segmentOrientation(std::size_t i) const { return q_[i]; }
  const Vec3& segmentVelocity(std::size_t i) const { return v_[i]; }
  const Vec3& segmentAngularVelocity(std::size_t i) const { return w_[i]; }
  double segmentMass(std::size_t i) const { return mass_[i]; }
  double restLength() const noexcept { return restLength_; }
  /// Length of the polyline through the nodes, m.
  double length() const;
  /// Σ m v over the segments, kg·m/s.
  Vec3 linearMomentum() const;

  /// Bending stiffness EI (N·m²), twist stiffness GJ (N·m²), axial EA (N).
  double bendingStiffness() const noexcept { return bendK_; }
  double twistStiffness() const noexcept { return twistK_; }
  double axialStiffness() const noexcept { return axialK_; }

  /// Holds `end` at `point` (a ball joint). Call again each step to drag it.
  Status pin(RodEnd end, const Vec3& point);
  /// Holds `end` at `point` with the end segment's orientation `frame`
  /// (body z along the rod, from node 0 towards node n).
  Status clamp(RodEnd end, const Vec3& point, const Quat& frame);
  /// Lets `end` go.
  void release(RodEnd end) noexcept;
  RodAttachment attachment(RodEnd end) const noexcept { return ends_[endIndex(end)].kind; }
  /// What the attachment exerted on the rod during the last step: λ/h² of its
  /// rows (zero when free).
  RodWrench reaction(RodEnd end) const noexcept;

  /// Holds segment i in a needle driver's (or grasper's) jaws: from the next
  /// step on it sits at `center` with orientation `orientation` (body z along
  /// the rod) and the rest of the rod does not move it. Call again each step
  /// to drag it; the segment's velocity follows from the motion.
  Status grasp(std::size_t segment, const Vec3& center, const Quat& orientation);
  /// Lets a grasped segment go (it keeps the jaws' last velocity).
  void releaseGrasp(std::size_t segment) noexcept;
  bool grasped(std::size_t segment) const noexcept {
    return segment < kinematic_.size() && kinematic_[segment];
  }
  /// What the rest of the rod exerted on a grasped segment during the last
  /// step (its joints' λ/h²; torque about the segment's centre): the load the
  /// jaws hold against, the segment's own weight aside. Zero when not grasped.
  RodWrench graspLoad(std::size_t segment) const noexcept;

  /// The obstacles from the next step on (replacing the last set). Each node
  /// (a segment end, a sphere of the rod's radius) is kept out of each
  /// obstacle by a unilateral contact projected after every pass; its impulse
  /// enters the next pass's residual, so the joints and the contacts settle
  /// together, given two passes a step (the default): a stiff 3-0 suture
  /// dropped on a table then comes to rest (1e-13 m/s, the table carrying its
  /// weight) where with one pass it keeps jittering at about 6 mm/s, and one
  /// falling on a 5 mm tool shaft stays whole. Contacts are at the
  /// nodes: an obstacle thinner than a segment can pass between two, so keep
  /// segments shorter than the thinnest tool.
  /// Calling it again with as many obstacles (moved) allocates nothing and
  /// keeps the contacts' warm start. Fails, changing nothing, naming the field.
  Status setObstacles(const std::vector<RodObstacle>& obstacles);
  std::size_t obstacleCount() const noexcept { return obstacles_.size(); }
  /// The obstacles' total force on the rod during the last step, N.
  Vec3 contactForce() const noexcept;

  /// A constant force (N, world) on node k from the next step on, until
  /// changed; Vec3::Zero() removes it.
  Status setNodeForce(std::size_t k, const Vec3& force);
  /// Sets every segment's velocity and angular velocity (a thrown thread).
  Status setVelocity(const Vec3& velocity, const Vec3& angularVelocity = Vec3::Zero());
  Status setGravity(const Vec3& gravity);
  Status setDamping(double rate);
  Status setIterations(int iterations);

  /// Advances by h seconds (finite, 0 < h ≤ 1). Real-time safe.
  Result<RodStepReport> step(double h);

 private:
  struct End {
    RodAttachment kind = RodAttachment::Free;
    Vec3 point = Vec3::Zero();
    Quat frame = Quat::Identity();
  };
  static std::size_t endIndex(RodEnd end) noexcept { return end == RodEnd::Start ? 0 : 1; }
  void evaluate(double h);
  void assemble();
  void solveSystem();
  void applyCorrection();
  void projectContacts();
  void refreshContactImpulses();
  int nodeSegments(std::size_t node, std::size_t* segment, double* share, Vec3* arm) const;
  double contactGap(std::size_t node, const RodObstacle& obstacle, Vec3& normal) const;

  // Segments.
  std::vector<Vec3> p_, v_, w_, pPrev_, pStart_, force_, torque_;
  std::vector<Quat> q_, qPrev_, qStart_;
  std::vector<Vec6> kick_;        // h² f/m and h² τ of this step's applied loads
  std::vector<Mat3> invInertia_;  // K⁻¹ of the rotation: inertia plus geometric stiffness
  std::vector<Vec6> wg_;          // W g, the primal residual (rod.cpp, assemble)
  std::vector<double> len_, mass_, inertiaPerp_, inertiaAxial_;
  // Constraints c = 0 … n: c joins segment c−1 (its end) to segment c (its
  // start); c = 0 and c = n hold the attachments (the other side is the world).
  std::vector<Quat> restRel_;  // q̄_rest per constraint (identity for the ends)
  std::vector<Vec6> lambda_, rhs_, dlambda_;
  std::vector<Vec6> compliance_;    // α per row (before /h²)
  std::vector<Mat6> jl_, jr_;       // Jacobians w.r.t. the left and right segments
  std::vector<Mat6> diag_, off_;    // blocks of J W Jᵀ + α̃: (c, c) and (c, c+1)
  std::vector<Mat6> elim_;          // S_c⁻¹ B_c of the elimination
  std::vector<std::uint8_t> rows_;  // active rows per constraint (bit r: row r)
  std::vector<Vec3> nodeForce_;
  std::vector<RodObstacle> obstacles_;
  std::vector<double> contactLambda_;    // per (node, obstacle): the accumulated normal λ
  std::vector<Vec6> contactImpulse_;     // per segment: Σ J_cᵀ λ_c of its contacts
  std::vector<std::uint8_t> kinematic_;  // 1: grasped (moved by the jaws, not by the rod)
  std::vector<Vec3> graspCenter_;
  std::vector<Quat> graspFrame_;
  End ends_[2];
  RodWrench reaction_[2];
  double restLength_ = 0;
  double radius_ = 0;
  double bendK_ = 0, twistK_ = 0, axialK_ = 0;
  Vec3 gravity_{0, 0, -9.81};
  double damping_ = 0;
  int iterations_ = 2;
  double lastH_ = 0;  // the last step's h (0 before the first): λ is warm-started
};

}  // namespace dm
