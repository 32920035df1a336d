// dm/physics/soft_rigid.hpp — FEM tissue and the rigid bodies of a
// PhysicsWorld stepped together, with two-way contact between them.
//
// What it is for: bones, fragments and instruments that rest on, fall onto
// or are pushed by tissue, and push it back: a bone fragment placed on soft
// tissue sinks until the tissue carries its weight; a free instrument that
// hits an organ is slowed by it and dents it.
//
// How (one step of h):
//   1. each coupled body's pose and velocity (from the WorldState) become
//      its FemObstacle's pose and start velocity in the FemBody, an awake
//      dynamic body's with the world's gravity over the step added (gravity,
//      then contact, then positions, as rigid-body engines order them: a
//      body resting on tissue stays put at any step, where solving contact
//      before gravity lets the world's step push it g·h² into the tissue
//      each step); a dynamic body's obstacle carries its mass and inertia;
//   2. FemBody::step solves the tissue's and the bodies' velocity changes in
//      one implicit system: the contact springs (k per boundary node inside
//      the body's closed mesh, along its normal) act on both sides, so stiff
//      contact on a light body stays stable and momentum passes exactly
//      (to the solver tolerance) between tissue and body;
//   3. the bodies' velocities take the contact's change (the impulse the
//      tissue gave them), less the gravity step 1 added, and
//      PhysicsWorld::step advances the world (gravity, rigid contact,
//      joints) from there. A sleeping body is still to the tissue and is
//      woken only by a push past the world's sleep thresholds.
// The split is first order in h between the tissue contact and the world's
// own forces. Static bodies are kinematic obstacles (the tissue meets them,
// they do not move). The tissue lives in a frame of its own placed in the
// world by `tissuePose` (identity: the world frame); poses and velocities
// are carried across. A caller that steps the tissue itself (through a
// dm::HapticTissue, which adds the tool's grip to the same implicit step)
// calls beforeTissueStep, its step, afterTissueStep, then the world's step:
// what step() does. Several tissues may share one world, each with its own
// coupling, stepped one after another (a later tissue sees the velocities
// the earlier ones left).
//
// Real time: step() allocates nothing (both halves are allocation-free).
//
// @code
//   dm::SoftRigidContact bone{.body = boneId, .tree = &boneTree, .stiffness = 2e4};
//   auto coupling = dm::SoftRigidCoupling::create(world, tissue, {&bone, 1});
//   for (int i = 0; i < 100; ++i) if (auto r = coupling->step(state, 0.01); !r) return r.error();
//   dm::Wrench onBone = coupling->wrench(0);
// @endcode
#pragma once

#include <dm/core/pose.hpp>
#include <dm/core/result.hpp>
#include <dm/physics/fem.hpp>
#include <dm/physics/world.hpp>

#include <span>
#include <vector>

namespace dm {

class MeshBvh;

/// One rigid body of the world in contact with the tissue.
struct SoftRigidContact {
  BodyId body;                    ///< a rigid or static body of the world
  const MeshBvh* tree = nullptr;  ///< closed, in the body's shape frame (BodyDesc::shapeOffset); outlives the coupling
  double stiffness = 1e4;         ///< N/m per tissue node in contact (FemObstacle::stiffness)
  double friction = 0.0;          ///< N·s/m per node in contact, across the normal (FemObstacle::friction)
};

/// Steps a FemBody and a PhysicsWorld together (see the file comment).
/// Holds pointers to both: they must outlive it.
class SoftRigidCoupling {
 public:
  /// Couples `tissue` to the bodies named in `contacts`; replaces the
  /// tissue's obstacles with one per contact, in order. Fails
  /// (InvalidArgument naming contacts[i]) on a body that is not in the world
  /// or is a particle, a null or open tree, or a stiffness that is not
  /// positive and finite.
  /// `tissuePose` places the tissue's frame in the world (rigid).
  static Result<SoftRigidCoupling> create(const PhysicsWorld& world, FemBody& tissue,
                                          std::span<const SoftRigidContact> contacts,
                                          const Isometry3& tissuePose = Isometry3::Identity());

  /// One coupled step of dt seconds (see the file comment). Fails like
  /// FemBody::step (state untouched) or PhysicsWorld::step.
  Result<FemStepReport> step(WorldState& state, double dt);

  /// The halves of step() around a tissue step the caller makes: the
  /// bodies' poses and velocities from `state` into the tissue (fails on a
  /// state of another world), then, after the tissue's step, the velocity
  /// the contact gave each dynamic body back into `state`. Allocation-free.
  Status beforeTissueStep(const WorldState& state, double dt);
  void afterTissueStep(WorldState& state, double dt) const;

  std::size_t contactCount() const noexcept { return contacts_.size(); }
  /// The force (N, world) the tissue applied to contact i's body in the
  /// last step and its torque (N·m) about the body's centre of mass; zero
  /// for an index out of range.
  Wrench wrench(std::size_t i) const noexcept;

 private:
  SoftRigidCoupling() = default;
  const PhysicsWorld* world_ = nullptr;
  FemBody* tissue_ = nullptr;
  Isometry3 tissuePose_ = Isometry3::Identity();  // tissue frame → world
  std::vector<SoftRigidContact> contacts_;
  std::vector<std::uint8_t> dynamic_;  // per contact: a rigid body the tissue moves
};

}  // namespace dm
