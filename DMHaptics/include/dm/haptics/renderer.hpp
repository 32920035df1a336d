// dm/haptics/renderer.hpp — what every haptic rendering method shares: the
// device sample it reads each tick, the force and torque it answers with,
// the surface material it renders, and the HapticRenderer interface the
// haptic loop (dm/haptics/haptic_loop.hpp) and `dmtool probe` drive.
//
// Frames and units: everything is in the world frame of the scene, SI
// (m, s, N, N·m). The loop maps the device frame to the world before tick()
// and the force back after it. The force is the one to put on the user's
// hand: it pushes the device point (HIP) toward the proxy / tool.
//
// Methods (one header each):
//   god_object.hpp   3-DOF proxy on triangle meshes (Zilles & Salisbury 1995,
//                    Ruspini et al. 1997), friction, force shading;
//   vps.hpp          6-DOF voxel point shell with virtual coupling (McNeely
//                    et al. 1999) on dense or OpenVDB voxel models;
//   sphere_tree_6dof.hpp  6-DOF constraint-based sphere-tree method (Wang et al.);
//   effects.hpp      viscosity, snap-to surface, vibration, guidance springs;
//   FreeSpaceRenderer (here) nothing to touch, for effects alone.
//
// Real time: tick() and setObjectPose() never allocate, lock, log or throw;
// everything they need is sized when the renderer is built.
//
// @code
//   std::unique_ptr<dm::HapticRenderer> r = ...;          // e.g. a GodObjectRenderer
//   r->reset(devicePose);
//   dm::HapticResponse out = r->tick({.timeNs = t, .dt = 1e-3, .devicePose = pose});
// @endcode
#pragma once

#include <dm/core/pose.hpp>  // isRigidPose
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>

#include <cstddef>
#include <cstdint>
#include <string_view>

namespace dm {

/// Surface material as the hand feels it.
struct HapticMaterial {
  double stiffness = 1000.0;  ///< N/m, proxy–device spring (> 0)
  double damping = 0.0;       ///< N·s/m, on the device velocity while in contact (≥ 0)
  double staticFriction = 0.0;  ///< μs ≥ 0: the proxy sticks while the tangential force ≤ μs·normal force
  double dynamicFriction =
      0.0;  ///< μd, 0 ≤ μd ≤ μs: sliding proxies lag so tangential force = μd·normal force

  /// Ok, or InvalidArgument naming the field of `where` (e.g. "scene.json:/objects/2/material")
  /// that is negative, not finite, or μd > μs.
  Status validate(std::string_view where) const;
};

/// One device sample as a renderer sees it, world frame.
struct HapticInput {
  std::int64_t timeNs = 0;                       ///< sample time
  double dt = 1e-3;                              ///< s since the previous tick (> 0)
  Isometry3 devicePose = Isometry3::Identity();  ///< haptic interface point (HIP) / handle pose
  Vec3 linearVelocity = Vec3::Zero();            ///< m/s
  Vec3 angularVelocity = Vec3::Zero();           ///< rad/s
};

/// What a renderer answers for one tick.
struct HapticResponse {
  Vec3 force = Vec3::Zero();                    ///< N, on the user's hand
  Vec3 torque = Vec3::Zero();                   ///< N·m, on the user's hand, about the device point
  Isometry3 proxyPose = Isometry3::Identity();  ///< where the tool is drawn (proxy / tool body), world
  int contacts = 0;                             ///< active constraints or penetrating points
  double penetration = 0.0;  ///< m, ≥ 0: how far the device is inside (proxy–HIP distance in contact)
};

/// A haptic rendering method; see the file comment.
class HapticRenderer {
 public:
  virtual ~HapticRenderer() = default;
  /// "godobject", "vps", "spheretree", ...
  virtual std::string_view name() const noexcept = 0;
  /// Puts the proxy / tool at `devicePose` (free space assumed; a pose inside
  /// an object is resolved by the method's own rule) and clears history.
  virtual void reset(const Isometry3& devicePose) noexcept = 0;
  /// One haptic tick. Real-time safe.
  virtual HapticResponse tick(const HapticInput& input) noexcept = 0;
  /// Number of environment objects the renderer was built with.
  virtual std::size_t objectCount() const noexcept = 0;
  /// Moves environment object `index` (< objectCount()) to `pose` (its local
  /// frame → world) from the next tick on; a proxy resting on it is carried
  /// along. Out-of-range indices and non-finite poses are ignored. Real-time safe.
  virtual void setObjectPose(std::size_t index, const Isometry3& pose) noexcept = 0;
};

/// A tool in free space: nothing to touch, the proxy is the device point and
/// the force is zero — the loop's effects (a force field such as a
/// segmentation's guidance, viscosity, a fixture) give the hand its force.
class FreeSpaceRenderer final : public HapticRenderer {
 public:
  std::string_view name() const noexcept override { return "free-space"; }
  void reset(const Isometry3&) noexcept override {}
  HapticResponse tick(const HapticInput& input) noexcept override {
    HapticResponse r;
    r.proxyPose = input.devicePose;
    return r;
  }
  std::size_t objectCount() const noexcept override { return 0; }
  void setObjectPose(std::size_t, const Isometry3&) noexcept override {}
};

}  // namespace dm
