// dm/physics/membrane_rigid.hpp — a mass–spring membrane and the bodies of
// a PhysicsWorld stepped together, with two-way contact between them.
//
// What it is for: a drape, a fascia or a flap of skin that static organs and
// bones hold up and free bodies fall onto, rest on, push along or are
// carried by: a bone fragment dropped onto a membrane stretched over a
// cavity sinks into it until the membrane carries its weight, and the
// membrane's pins carry both.
//
// How (one step of h, before the world's own step; dm::ParticleObstacles
// says why and how the membrane and a free body exchange momentum):
//   1. each awake dynamic body's velocity gains the world's gravity over
//      the step (gravity, then contact, then positions, as rigid-body
//      engines order them; dm::SoftRigidCoupling does the same), and its
//      shape pose and velocity become its obstacle's motion; a sleeping
//      body is still;
//   2. the bodies' masses are lent to the particles the membrane presses
//      onto them, the membrane steps (MassSpringBody::stepImplicit), and
//      the shares are taken back, their gain the bodies' impulses;
//   3. each dynamic body is placed where its new velocity takes it over the
//      step, and the contacts are resolved there (new collisions, friction,
//      the particles' positions), the bodies taking the opposite impulses;
//   4. the bodies' velocities, less the gravity step 1 added, go back into
//      the WorldState, and the world's step (PhysicsWorld::step or an
//      OdeWorld) moves them from there. A sleeping body is woken only by a
//      push past the world's sleep thresholds.
// Static bodies are fixed obstacles. The split is first order in h between
// the membrane and the world's own forces. Several membranes may share one
// world, each with its own coupling, stepped one after another.
//
// Real time: step() allocates nothing after its first call.
//
// @code
//   dm::MembraneRigidContact organ{.body = organId, .tree = &organTree, .friction = 0.3};
//   dm::MembraneRigidContact fragment{.body = fragmentId, .tree = &fragmentTree, .friction = 0.5};
//   const dm::MembraneRigidContact touching[] = {organ, fragment};
//   auto coupling = dm::MembraneRigidCoupling::create(world, touching, 0.5e-3);
//   for (int i = 0; i < 1000; ++i) {
//     if (auto r = coupling->step(sheet, state, 2e-3); !r) return r.error();
//     if (auto s = world.step(state, 2e-3); !s) return s.error();
//   }
//   dm::Vec3 onFragment = coupling->contacts().force(1);  // N, world
// @endcode
#pragma once

#include <dm/core/result.hpp>
#include <dm/physics/mass_spring.hpp>
#include <dm/physics/particle_obstacles.hpp>
#include <dm/physics/world.hpp>

#include <cstdint>
#include <optional>
#include <span>
#include <utility>
#include <vector>

namespace dm {

class MeshBvh;

/// One body of the world the membrane meets.
struct MembraneRigidContact {
  BodyId body;                    ///< static or rigid (not a particle)
  const MeshBvh* tree = nullptr;  ///< closed, the body's shape frame (its mesh's); outlives the coupling
  double friction = 0.0;          ///< Coulomb coefficient μ, ≥ 0
};

/// A membrane and the world's bodies stepped together (see the file
/// comment). Copyable; holds the world by pointer (it must outlive it).
class MembraneRigidCoupling {
 public:
  /// Fails (InvalidArgument naming contacts[i] or thickness) on a body not
  /// in the world, a particle body, and as ParticleObstacles::create does.
  /// thickness: m, how far the particles stay off the bodies' surfaces.
  static Result<MembraneRigidCoupling> create(const PhysicsWorld& world,
                                              std::span<const MembraneRigidContact> contacts,
                                              double thickness = 0.0);

  /// One step of h seconds of `membrane` with the bodies of `state` (before
  /// the world's own step; see the file comment). Fails as
  /// MassSpringBody::stepImplicit does, on a state of another world or a
  /// bad h, and then leaves the state as it was.
  Result<ImplicitStepReport> step(MassSpringBody& membrane, WorldState& state, double h);

  /// The contacts: force(i) is what the membrane put on contacts[i]'s body
  /// over the last step (N, world).
  const ParticleObstacles& contacts() const noexcept { return *obstacles_; }

 private:
  MembraneRigidCoupling() = default;
  const PhysicsWorld* world_ = nullptr;
  std::vector<MembraneRigidContact> contacts_;
  std::vector<std::uint8_t> dynamic_;         // per contact: a rigid body
  std::vector<std::pair<Vec3, Vec3>> given_;  // per contact: the velocity and spin step 1 gave it
  std::optional<ParticleObstacles> obstacles_;
};

}  // namespace dm
