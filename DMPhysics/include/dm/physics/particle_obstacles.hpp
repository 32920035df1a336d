// dm/physics/particle_obstacles.hpp — the particles of a mass–spring body
// kept out of closed obstacles, fixed, moved or free, with Coulomb friction.
//
// What it is for: a membrane (fascia, a drape, a flap of skin) that falls
// onto, rests on or is draped over an organ, a bone or an instrument, and
// slides on it or holds by friction; and a free rigid body (a bone
// fragment, a dropped instrument) that lands on a membrane, is carried by
// it, or pushes it along.
//
// How: after each step of the body (MassSpringBody::stepImplicit or
// stepSymplectic, which move every free particle by x ← x₀ + h v), resolve()
// finds each free particle's contact and corrects it (Bridson, Fedkiw and
// Anderson 2002, the velocity and position filter of cloth contact):
//   - contact: the particle's path over the step, x₀ = x − h v to x, crosses
//     an obstacle's surface (a ray cast: thin obstacles, a plate thinner than
//     one step's travel, are not passed through), or its end x lies inside
//     the obstacle or within `thickness` of it (closest point: resting and
//     sliding contact; searched within thickness plus the step's travel, as
//     a particle deeper inside crossed the surface to get there, except in
//     the first call, which also pushes out particles that start inside at
//     any depth); the first crossing, else the deepest overlap, wins;
//   - velocity: an impulse j n along the normal removes the approach
//     relative to the obstacle's surface point (a perfectly inelastic
//     contact), and a tangential one of at most μ·j reduces the slip —
//     Coulomb's law over the step: it stops (static friction) when that is
//     enough, else slides on. Against a fixed or moved obstacle that is
//     Δvₙ = −vₙ and the slip μ·Δvₙ less, particle by particle. Against a
//     free one (inverse mass and inertia given) the body takes the opposite
//     impulses, each divided by the pair's effective mass
//     1/m + 1/M + (r × n)ᵀ I⁻¹ (r × n), and the contacts on it are solved
//     together: projected Gauss–Seidel sweeps with the impulses accumulated
//     per contact (the normal one kept ≥ 0, the friction one within its
//     cone, so a later sweep takes back what an earlier one gave too much;
//     Catto 2005) until no velocity changes by 10⁻¹⁰ m/s (64 sweeps at
//     most) — a plate that hits a sheet all over at once leaves it as a
//     simultaneous inelastic collision would, momentum passing exactly;
//   - position: on the surface, offset by `thickness` along its normal, and
//     along it where the step began (carried with the obstacle's motion
//     over the step) plus h times the new relative slip (a particle held
//     by static friction does not creep, and rides on a moving obstacle).
// A particle resting on a slope of angle θ sticks iff tan θ ≤ μ and
// otherwise slides at g (sin θ − μ cos θ), exactly, at any step.
// The force on each obstacle is the momentum the contacts took from the
// particles over the step: −Σ m Δv / h after a symplectic step, and
// −Σ m (1 + h·drag) Δv / h after an implicit one, whose drag acted at the
// step's end velocity, which the contact changed (at rest: the weight it
// carries, exactly, where m Δv alone would read m g / (1 + h·drag)); the
// particle's side of each impulse uses that same effective mass.
// Moving obstacles: setMotion() gives an obstacle its pose at the end of
// the step and its velocity (a kinematic instrument, or a rigid body of a
// world after the world's step); a contact is sought along the particle's
// path relative to it (its start carried by the obstacle's motion, so a
// thin moving plate does not pass through a sheet either).
// Free bodies resting on, or pressed into, the membrane: impulses alone
// let a body feel only the inertia of the few light particles it touches,
// never the springs behind them within a step (an effective stiffness of
// m/h² per particle: a 20 g ball falls through a 10 g sheet at 500 Hz,
// the projection stretching the sheet for free). So the body's mass is
// lent for the membrane's own step to the particles it touched in the last
// resolve() (mass splitting, as Tonge et al. 2012 do for rigid contact):
// beforeStep() gives each of the n particles the membrane presses onto
// body b (its springs, weight and external force pointing into it) the
// share 1 / (n (1/M + (r × n)ᵀ I⁻¹ (r × n))) of the body's effective mass
// along the contact normal, moving with the particle, and an external
// force cancelling the share's gravity and drag (the body's world applies
// those); the step then moves particle and share together against the
// springs, implicitly, at any stiffness; afterStep() takes the shares back
// and passes what each gained to its body as an impulse at the particle:
// a push (a contact cannot pull: a gain away from the body is dropped, the
// particle leaving it) and along the surface all of it where the contact
// stuck, else at most μ times the push (Coulomb; the rest, what the share
// slowed the particle's sliding by, is dropped: momentum passes exactly
// through pressed, stuck contacts). resolve() then handles what the step
// left — new collisions, slip, the particles' positions — with the lent
// push counted in its friction budget (Coulomb over the whole step).
// A step with a free body (PhysicsWorld or any integrator of it), in the
// order rigid-body engines use (gravity, contact, then positions):
//   1. the body's velocity gains its gravity over the step;
//   2. setMotion(its pose now, that velocity, spin); beforeStep(); the
//      membrane's step; afterStep();
//   3. setMotion(its pose at the step's end as the new velocity predicts);
//      resolve();
//   4. velocity() and spin() back to the body (PhysicsWorld::setBodyState,
//      less the gravity of step 1, which the world's step adds), and the
//      world's step moves it from there.
// First order in h between the two solvers; a resting ball stays put.
// The particles do not meet each other (no self-collision).
//
// Real time: resolve(), setMotion(), beforeStep() and afterStep() allocate
// nothing after the first resolve() (which sizes a record per particle).
// O(particles × obstacles near them × log triangles).
//
// @code
//   dm::ParticleObstacle organ{.tree = &organTree, .pose = organPose, .friction = 0.4};
//   auto contacts = dm::ParticleObstacles::create({&organ, 1}, 0.5e-3);
//   for (int i = 0; i < 500; ++i) {
//     if (auto r = sheet.stepImplicit(2e-3); !r) return r.error();
//     contacts->resolve(sheet, 2e-3);
//   }
//   dm::Vec3 carried = contacts->force(0);  // N, world
//
//   // A free 50 g fragment on the same membrane (its tree centred on its
//   // centre of mass), stepped by hand in the order above:
//   dm::ParticleObstacle fragment{.tree = &fragmentTree, .pose = pose, .friction = 0.4,
//                                 .inverseMass = 1 / 0.05, .inverseInertia = inertia.inverse()};
//   velocity += h * gravity;
//   (void)contacts->setMotion(1, pose, velocity, spin);
//   contacts->beforeStep(sheet);
//   if (auto r = sheet.stepImplicit(h); !r) return r.error();
//   contacts->afterStep(sheet, h);
//   velocity = contacts->velocity(1), spin = contacts->spin(1);
//   (void)contacts->setMotion(1, advanced(pose, velocity, spin, h), velocity, spin);
//   contacts->resolve(sheet, h);
//   velocity = contacts->velocity(1), spin = contacts->spin(1);
//   pose = advanced(pose, velocity, spin, h);
// @endcode
#pragma once

#include <dm/core/result.hpp>
#include <dm/core/types.hpp>

#include <cstdint>
#include <span>
#include <vector>

namespace dm {

class MassSpringBody;
class MeshBvh;

/// Which step of the body ParticleObstacles::resolve() follows.
enum class ParticleStep { Implicit, Symplectic };

/// One obstacle the particles are kept out of: fixed unless setMotion()
/// moves it; free (pushed back by the particles) where it has a mass.
struct ParticleObstacle {
  const MeshBvh* tree = nullptr;           ///< closed, local frame; outlives its use
  Isometry3 pose = Isometry3::Identity();  ///< local → world, rigid
  double friction = 0.0;                   ///< Coulomb coefficient μ, finite, ≥ 0
  double inverseMass = 0.0;                ///< 1/kg, ≥ 0; 0: nothing the particles do moves it
  Mat3 inverseInertia = Mat3::Zero();      ///< 1/(kg·m²), the local frame, about the centre of mass
  Vec3 centerOfMass = Vec3::Zero();        ///< m, the local frame
};

/// Keeps the free particles of a MassSpringBody out of fixed obstacles (see
/// the file comment). Copyable.
class ParticleObstacles {
 public:
  /// Fails (InvalidArgument naming obstacles[i] or thickness) on a null or
  /// open tree, a pose that is not a finite rotation and translation, a
  /// friction, inverse mass or inverse inertia that is negative or not
  /// finite (the inertia: not symmetric, or a negative eigenvalue), a
  /// centre of mass that is not finite, or a thickness that is negative or
  /// not finite (m: how far the particles stay from the surfaces, e.g. half
  /// the membrane's thickness).
  static Result<ParticleObstacles> create(std::span<const ParticleObstacle> obstacles,
                                          double thickness = 0.0);

  /// Obstacle i is now at `pose` (local → world, after the step the next
  /// resolve() follows) and moves at `velocity` (m/s, its centre of mass)
  /// and `spin` (rad/s, world). Its pose before (the last create() or
  /// setMotion()) is where the step began. Fails (InvalidArgument naming
  /// the argument) on an index out of range, a pose that is not a finite
  /// rotation and translation or a velocity that is not finite, and then
  /// changes nothing. Allocation-free.
  Status setMotion(std::size_t i, const Isometry3& pose, const Vec3& velocity, const Vec3& spin);

  /// After a step of h seconds of `body` (of the kind `step` says):
  /// resolves its free particles' contacts (positions and velocities set
  /// through the body) and returns how many particles were in contact. A
  /// non-positive or non-finite h changes nothing and returns 0.
  /// Allocation-free.
  std::size_t resolve(MassSpringBody& body, double h, ParticleStep step = ParticleStep::Implicit);

  /// Before a step of `body` (the one the last resolve() saw): lends each
  /// free obstacle's mass to the particles that touched it in the last
  /// resolve() (see the file comment). Nothing to lend (no free obstacle,
  /// no contact): changes nothing. Call afterStep() after the step, before
  /// anything else touches the body. Allocation-free.
  void beforeStep(MassSpringBody& body);
  /// After that step (of h seconds): takes the shares back (the particles'
  /// masses and external forces as they were) and adds the momentum they
  /// gained to their obstacles' velocity() and spin() (and to the next
  /// resolve()'s force()). Call resolve() next. Allocation-free.
  void afterStep(MassSpringBody& body, double h);

  std::size_t obstacleCount() const noexcept { return obstacles_.size(); }
  /// The force (N, world) the particles put on obstacle i over the last
  /// step: its resolve() and, for a free obstacle, what the shares lent
  /// before it passed on; zero for an index out of range.
  Vec3 force(std::size_t i) const noexcept { return i < force_.size() ? force_[i] : Vec3::Zero(); }
  /// Obstacle i's velocity (m/s, its centre of mass) and spin (rad/s,
  /// world): setMotion()'s, changed by the last resolve()'s contacts where
  /// it is free; zero for an index out of range.
  Vec3 velocity(std::size_t i) const noexcept {
    return i < motion_.size() ? motion_[i].velocity : Vec3::Zero();
  }
  Vec3 spin(std::size_t i) const noexcept { return i < motion_.size() ? motion_[i].spin : Vec3::Zero(); }
  /// Particles in contact in the last resolve().
  std::size_t contacts() const noexcept { return contacts_; }
  double thickness() const noexcept { return thickness_; }

 private:
  ParticleObstacles() = default;
  struct Motion {
    Vec3 velocity = Vec3::Zero(), spin = Vec3::Zero();  // world
    Isometry3 carried = Isometry3::Identity();          // the step's motion: start pose → end pose, world
    bool moved = false;                                 // carried is not the identity
    Mat3 inverseInertia = Mat3::Zero();                 // world
    Vec3 center = Vec3::Zero();                         // world, the centre of mass
  };
  // Per particle: the free obstacle it touched in the last resolve() and
  // the contact normal there; what beforeStep() lent it.
  struct Touch {
    std::uint32_t obstacle = kNoObstacle;
    Vec3 normal = Vec3::Zero();
    bool stuck = false;             // static friction held
    bool pressed = false;           // beforeStep: the membrane presses it onto the body
    double share = 0.0;             // kg lent
    Vec3 force = Vec3::Zero();      // N added to its external force
    Vec3 reference = Vec3::Zero();  // m/s: the share's velocity as part of its body, at lending
    double lentPush = 0.0;          // N·s: the normal impulse the share passed on in the last step
    double lentAlong = 0.0;         // N·s: and the tangential one (≤ μ lentPush)
  };
  static constexpr std::uint32_t kNoObstacle = 0xffffffffu;
  // A contact with a free body, solved with the others on the same bodies.
  struct Pending {
    std::uint32_t particle = 0, obstacle = 0;
    Vec3 point, normal, start;     // world
    Vec3 velocity;                 // the particle's, as the sweeps change it
    double inverseMass = 0.0;      // the particle's, 1 / (m (1 + h·drag)) after an implicit step
    double approach = 0.0;         // m/s, the relative normal velocity before any impulse
    double pushed = 0.0;           // N·s, the accumulated normal impulse, ≥ 0
    Vec3 friction = Vec3::Zero();  // N·s, the accumulated friction impulse, |·| ≤ the budget
    double lentBudget = 0.0;  // N·s: what friction the lent step's push left (μ lentPush − lentAlong)
  };
  void place(MassSpringBody& body, std::size_t i, const Vec3& x, const Vec3& point, const Vec3& normal,
             const Vec3& start, const Vec3& slip, double h) const;
  void solveFree(MassSpringBody& body, double h);
  std::vector<ParticleObstacle> obstacles_;
  std::vector<Isometry3> inverse_;  // world → local, per obstacle
  std::vector<Motion> motion_;
  std::vector<Vec3> force_;
  std::vector<Touch> touch_;               // per particle (sized by the first resolve)
  std::vector<std::uint32_t> touchCount_;  // per obstacle, particles pressed onto it (beforeStep)
  std::vector<Vec3> lentForce_;            // per obstacle, afterStep's, for the next resolve()'s force_
  std::vector<Pending> pending_;           // this resolve()'s contacts with free bodies (reserved once)
  bool lent_ = false;                      // between beforeStep and afterStep
  double thickness_ = 0.0;
  std::size_t contacts_ = 0;
  bool started_ = false;  // resolve() ran: every particle is outside (by thickness)
};

}  // namespace dm
