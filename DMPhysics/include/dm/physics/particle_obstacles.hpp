// dm/physics/particle_obstacles.hpp — the particles of a mass–spring body
// kept out of closed, fixed obstacles, with Coulomb friction.
//
// What it is for: a membrane (fascia, a drape, a flap of skin) that falls
// onto, rests on or is draped over an organ, a bone or an instrument that
// does not move, and slides on it or holds by friction.
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
//   - velocity: the normal component into the obstacle is removed (Δvₙ, a
//     perfectly inelastic contact), and the tangential slip is reduced by
//     μ·Δvₙ — Coulomb's law over the step: it stops (static friction) when
//     that is enough, else slides on with μ·Δvₙ less;
//   - position: on the surface, offset by `thickness` along its normal, and
//     along it where the step began plus h times the new tangential
//     velocity (a particle held by static friction does not creep).
// A particle resting on a slope of angle θ sticks iff tan θ ≤ μ and
// otherwise slides at g (sin θ − μ cos θ), exactly, at any step.
// The force on each obstacle is the momentum the contacts took from the
// particles over the step: −Σ m Δv / h after a symplectic step, and
// −Σ m (1 + h·drag) Δv / h after an implicit one, whose drag acted at the
// step's end velocity, which the contact changed (at rest: the weight it
// carries, exactly, where m Δv alone would read m g / (1 + h·drag)).
// The obstacles are fixed (kinematic): nothing moves them, and a moving
// rigid body is not one — a light particle cannot push a heavy body through
// a velocity filter (its effective stiffness would be m/h²); such bodies
// need the body in the implicit solve, as dm::SoftRigidCoupling does for
// FEM tissue. The particles do not meet each other (no self-collision).
//
// Real time: resolve() allocates nothing. O(particles × obstacles near
// them × log triangles).
//
// @code
//   dm::ParticleObstacle organ{.tree = &organTree, .pose = organPose, .friction = 0.4};
//   auto contacts = dm::ParticleObstacles::create({&organ, 1}, 0.5e-3);
//   for (int i = 0; i < 500; ++i) {
//     if (auto r = sheet.stepImplicit(2e-3); !r) return r.error();
//     contacts->resolve(sheet, 2e-3);
//   }
//   dm::Vec3 carried = contacts->force(0);  // N, world
// @endcode
#pragma once

#include <dm/core/result.hpp>
#include <dm/core/types.hpp>

#include <span>
#include <vector>

namespace dm {

class MassSpringBody;
class MeshBvh;

/// Which step of the body ParticleObstacles::resolve() follows.
enum class ParticleStep { Implicit, Symplectic };

/// One fixed obstacle the particles are kept out of.
struct ParticleObstacle {
  const MeshBvh* tree = nullptr;           ///< closed, local frame; outlives its use
  Isometry3 pose = Isometry3::Identity();  ///< local → world, rigid
  double friction = 0.0;                   ///< Coulomb coefficient μ, finite, ≥ 0
};

/// Keeps the free particles of a MassSpringBody out of fixed obstacles (see
/// the file comment). Copyable.
class ParticleObstacles {
 public:
  /// Fails (InvalidArgument naming obstacles[i] or thickness) on a null or
  /// open tree, a pose that is not a finite rotation and translation, a
  /// friction that is negative or not finite, or a thickness that is
  /// negative or not finite (m: how far the particles stay from the
  /// surfaces, e.g. half the membrane's thickness).
  static Result<ParticleObstacles> create(std::span<const ParticleObstacle> obstacles,
                                          double thickness = 0.0);

  /// After a step of h seconds of `body` (of the kind `step` says):
  /// resolves its free particles' contacts (positions and velocities set
  /// through the body) and returns how many particles were in contact. A
  /// non-positive or non-finite h changes nothing and returns 0.
  /// Allocation-free.
  std::size_t resolve(MassSpringBody& body, double h, ParticleStep step = ParticleStep::Implicit);

  std::size_t obstacleCount() const noexcept { return obstacles_.size(); }
  /// The force (N, world) the particles put on obstacle i over the last
  /// resolve(); zero for an index out of range.
  Vec3 force(std::size_t i) const noexcept { return i < force_.size() ? force_[i] : Vec3::Zero(); }
  /// Particles in contact in the last resolve().
  std::size_t contacts() const noexcept { return contacts_; }
  double thickness() const noexcept { return thickness_; }

 private:
  ParticleObstacles() = default;
  std::vector<ParticleObstacle> obstacles_;
  std::vector<Isometry3> inverse_;  // world → local, per obstacle
  std::vector<Vec3> force_;
  double thickness_ = 0.0;
  std::size_t contacts_ = 0;
  bool started_ = false;  // resolve() ran: every particle is outside (by thickness)
};

}  // namespace dm
