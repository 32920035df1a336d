// dm/haptics/vps.hpp — 6-DOF Voxmap–PointShell haptic rendering (McNeely,
// Puterbaugh & Troy, "Six degree-of-freedom haptic rendering using voxel
// sampling", SIGGRAPH 1999; McNeely, Puterbaugh & Troy, "Voxel-based 6-DOF
// haptic rendering improvements", Haptics-e 2006): a rigid tool given by a
// PointShell (dm/collide/point_shell.hpp) touches environment objects given
// by VoxelModels (dm/collide/voxel_model.hpp, dense or OpenVDB sparse).
//
// Force model (tangent plane). Every shell point p whose signed distance in
// an object is d ≤ 0 pushes the tool along the object's outward surface
// normal n = ∇d/|∇d| with k_point·depth, depth = min(−d, maxPointDepth) (the
// distance from p to the tangent plane of the level set through p's voxel
// sample; −d for a distance field). Stiffness rule (McNeely 1999): a point
// has stiffness k_point = K/Nref, K = the object's HapticMaterial::stiffness,
// Nref = VpsOptions::referenceContacts (10 in the paper); when more than Nref
// points of one object are in contact their sum is averaged instead:
//   F = K / max(N, Nref) · Σ depth_i · n_i,   torque = Σ r_i × f_i
// (r_i from the tool's origin = centre of mass), so a flat face pressed in
// evenly feels exactly K·depth however finely it is sampled, and a single
// point feels K/Nref·depth. Averaging only makes the force drop (never jump
// up) when a point starts touching, which creates no chatter.
// The object's HapticMaterial::damping acts the same way on the approaching
// normal velocity of the contact points (per point damping/Nref, averaged).
//
// Pre-contact braking (McNeely 2006): a point just outside a surface,
// 0 < d < brakeDistance, that moves toward it (n·v_p < 0) gets a viscous
// force −b_point (n·v_p) n, b_point = brakeDamping/Nref averaged like the
// stiffness, so a fast approach slows down before it can tunnel through a
// thin wall.
//
// Virtual coupling. The tool is a rigid body (mass, inertia, pose, velocity)
// tied to the device pose by a damped 6-DOF spring (linear k_c, b_c; angular
// k_r, b_r acting on the rotation vector of R_device·R_toolᵀ). Each tick the
// point shell is sampled once at the tool pose; then the tool is integrated
// (`substeps` steps, the device pose interpolated across the tick) with
// linearly implicit Euler (Otaduy & Lin 2006): the coupling spring and
// damper, the contact stiffness Σ k J Jᵀ (J = [n; r × n]) and the contact /
// braking dampers are all taken at the end of the step, solving one 6×6 SPD
// system, so stiff couplings and contacts stay stable at 1 kHz (backward
// Euler only dissipates). The orientation is a unit quaternion, renormalised.
// The force and torque put on the user's hand are the coupling's reaction on
// the device: −(coupling force on the tool) and −(coupling torque on it),
// clamped to maxForce / maxTorque. At rest they equal the contact force and
// torque on the tool.
//
// Frames: the tool's local frame is the PointShell's; its origin is the
// tool's centre of mass and the point the device pose drives. Objects are
// placed by their pose (model frame → world). SI units throughout.
//
// Real time: tick() and setObjectPose() never allocate, lock or throw. Cost
// per tick: the shell's bounding-sphere hierarchy skips clusters farther than
// brakeDistance from each object (by the model's Lipschitz bound), then one
// trilinear distance/gradient sample per remaining point.
//
// @code
//   auto vps = dm::VpsRenderer::create(drillShell, {{skullModel, skullPose, {.stiffness = 2000}}}, {});
//   if (!vps) return vps.error();
//   dm::HapticResponse out = (*vps)->tick({.dt = 1e-3, .devicePose = pose});
// @endcode
#pragma once

#include <dm/collide/point_shell.hpp>
#include <dm/collide/voxel_model.hpp>
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>
#include <dm/haptics/renderer.hpp>

#include <cstddef>
#include <memory>
#include <string_view>
#include <vector>

namespace dm {

/// One environment object of a VpsRenderer.
struct VpsObject {
  std::shared_ptr<const VoxelModel> model;  ///< non-null; dense or sparse
  Isometry3 pose = Isometry3::Identity();   ///< model frame → world (rigid)
  HapticMaterial material;  ///< stiffness K (N/m) and contact damping (N·s/m); friction unused
};

/// Options of a VpsRenderer (SI units). The defaults suit a hand tool of a
/// few centimetres at 1 kHz.
struct VpsOptions {
  double couplingStiffness = 500.0;       ///< k_c, N/m, > 0
  double couplingDamping = 5.0;           ///< b_c, N·s/m, ≥ 0 (on device − tool velocity)
  double couplingAngularStiffness = 1.0;  ///< k_r, N·m/rad, > 0
  double couplingAngularDamping = 2e-3;   ///< b_r, N·m·s/rad, ≥ 0
  double mass = 0.05;                     ///< kg, > 0
  /// kg·m², body frame, about the tool origin; all zero: a solid box of the
  /// shell's bounds with `mass` (parallel-axis shifted to the origin).
  /// Otherwise symmetric positive definite.
  Mat3 inertia = Mat3::Zero();
  double referenceContacts = 10.0;  ///< Nref ≥ 1 of the stiffness rule (file comment)
  double maxPointDepth = 2e-3;      ///< m, > 0: per-point depth clamp
  double brakeDistance = 0.5e-3;    ///< m, ≥ 0: braking layer outside the surface (0: off)
  double brakeDamping = 20.0;       ///< N·s/m, ≥ 0: total braking viscosity (per point /Nref)
  double maxForce = 20.0;           ///< N, > 0 (∞ allowed): clamp of the force to the user
  double maxTorque = 1.0;           ///< N·m, > 0 (∞ allowed): clamp of the torque to the user
  int substeps = 1;                 ///< integration steps per tick, 1..64
};

/// Voxmap–PointShell renderer with virtual coupling (see the file comment).
class VpsRenderer final : public HapticRenderer {
 public:
  /// Builds the renderer and puts the tool at rest at the identity pose
  /// (call reset() with the device pose before the first tick). Fails with
  /// InvalidArgument, naming the field, when `tool` is null, an object's
  /// model is null, its pose is not finite or not rigid, its material is
  /// invalid (HapticMaterial::validate), or an option is out of its range
  /// (see VpsOptions). O(objects).
  /// @code
  ///   auto r = dm::VpsRenderer::create(shell, {{model, dm::Isometry3::Identity(), {}}}, {});
  ///   if (!r) return r.error();
  /// @endcode
  static Result<std::unique_ptr<VpsRenderer>> create(std::shared_ptr<const PointShell> tool,
                                                     std::vector<VpsObject> objects,
                                                     const VpsOptions& options);

  /// "vps".
  std::string_view name() const noexcept override { return "vps"; }
  /// Tool body at `devicePose`, at rest; clears the device history. A
  /// non-finite pose is ignored.
  void reset(const Isometry3& devicePose) noexcept override;
  /// One tick: sample the shell, integrate the tool over input.dt, answer
  /// the coupling's reaction on the device. The coupling dampers act on
  /// input.linearVelocity / angularVelocity − the tool's, so pass the
  /// device's velocities (zero ones damp the tool against the world). A
  /// non-finite input or dt ≤ 0 answers zero force and keeps the tool's
  /// state. proxyPose = the tool body pose; contacts = penetrating points;
  /// penetration = device–tool distance while in contact. O(shell points
  /// near the objects + hierarchy nodes visited).
  HapticResponse tick(const HapticInput& input) noexcept override;
  /// Number of objects given to create().
  std::size_t objectCount() const noexcept override { return objects_.size(); }
  /// Moves object `index` (model frame → world) from the next tick on; the
  /// tool is pushed along by the penalty forces. Out-of-range indices and
  /// non-finite or non-rigid poses are ignored. Real-time safe.
  void setObjectPose(std::size_t index, const Isometry3& pose) noexcept override;

  /// Tool body pose (local frame → world).
  Isometry3 toolPose() const noexcept;
  /// Tool body velocity, m/s, world frame.
  const Vec3& toolVelocity() const noexcept { return velocity_; }
  /// Tool body angular velocity, rad/s, world frame.
  const Vec3& toolAngularVelocity() const noexcept { return angularVelocity_; }
  /// ½ m|v|² + ½ ωᵀ I ω of the tool body, J.
  double toolKineticEnergy() const noexcept;
  /// Penalty force (N) and torque about the tool origin (N·m) on the tool
  /// from all objects, world frame, at the pose sampled by the last tick
  /// (springs only, no damping or braking).
  const Vec3& contactForce() const noexcept { return contactForce_; }
  /// See contactForce().
  const Vec3& contactTorque() const noexcept { return contactTorque_; }
  /// The penalty force (N, world) the tool put on object `index` in the
  /// last tick, at the pose it sampled — minus that object's share of
  /// contactForce() — and its torque about the world origin (N·m); zero out
  /// of range or out of contact. What a physics engine applies to a body
  /// the tool pushes (dm::ToolImpulseChannel::addWrench).
  Vec3 objectForce(std::size_t index) const noexcept {
    return index < objects_.size() ? objects_[index].force : Vec3::Zero();
  }
  /// See objectForce().
  Vec3 objectTorque(std::size_t index) const noexcept {
    return index < objects_.size() ? objects_[index].torque : Vec3::Zero();
  }
  /// Tool mass (kg) and body-frame inertia about its origin (kg·m²) in use.
  double mass() const noexcept { return mass_; }
  /// See mass().
  const Mat3& inertia() const noexcept { return inertiaBody_; }
  /// Options given to create().
  const VpsOptions& options() const noexcept { return options_; }

 private:
  struct Object {
    std::shared_ptr<const VoxelModel> model;
    Isometry3 pose;
    Isometry3 inverse;
    HapticMaterial material;
    Vec3 force;   // on the object in the last tick, world
    Vec3 torque;  // about the world origin
  };
  struct ContactSample;

  VpsRenderer() = default;
  void sampleContacts(ContactSample& out) const noexcept;
  void integrate(const ContactSample& contact, const Isometry3& device0, const Isometry3& device1,
                 const Vec3& deviceVelocity, const Vec3& deviceAngularVelocity, double dt) noexcept;

  std::shared_ptr<const PointShell> tool_;
  std::vector<Object> objects_;
  std::vector<Vec6> objectWrench_;  // per object, the last tick's (sized by create())
  VpsOptions options_;
  double mass_ = 0.0;
  Mat3 inertiaBody_ = Mat3::Identity();
  // Tool body state, world frame.
  Vec3 position_ = Vec3::Zero();
  Quat orientation_ = Quat::Identity();
  Vec3 velocity_ = Vec3::Zero();
  Vec3 angularVelocity_ = Vec3::Zero();
  Isometry3 lastDevice_ = Isometry3::Identity();
  Vec3 contactForce_ = Vec3::Zero();
  Vec3 contactTorque_ = Vec3::Zero();
};

}  // namespace dm
