// dm/core/pose.hpp — rigid poses, twists and wrenches (SI, right-handed).
//
// A Pose maps points from a local frame to its parent frame:
// x_parent = q * x_local + p. Composition a * b applies b first.
#pragma once

#include <dm/core/types.hpp>

namespace dm {

/// Rigid transform: position p (m) and unit quaternion q.
struct Pose {
  Vec3 p = Vec3::Zero();
  Quat q = Quat::Identity();

  Pose() = default;
  Pose(const Vec3& position, const Quat& orientation) : p(position), q(orientation.normalized()) {}
  explicit Pose(const Isometry3& iso) : p(iso.translation()), q(Quat(iso.rotation()).normalized()) {}

  static Pose identity() { return {}; }
  Isometry3 isometry() const {
    Isometry3 t = Isometry3::Identity();
    t.linear() = q.toRotationMatrix();
    t.translation() = p;
    return t;
  }
  /// Maps a point from the local frame to the parent frame.
  Vec3 operator*(const Vec3& x) const { return q * x + p; }
  /// Rotates a direction (no translation).
  Vec3 rotate(const Vec3& d) const { return q * d; }
  /// Composition: (a * b)(x) == a(b(x)).
  Pose operator*(const Pose& b) const { return {q * b.p + p, (q * b.q).normalized()}; }
  Pose inverse() const {
    const Quat qi = q.conjugate();
    return {-(qi * p), qi};
  }
  /// Linear interpolation of position, spherical of orientation; t in [0, 1].
  static Pose interpolate(const Pose& a, const Pose& b, double t) {
    return {(1.0 - t) * a.p + t * b.p, a.q.slerp(t, b.q)};
  }
  bool isFinite() const { return p.allFinite() && q.coeffs().allFinite(); }
};

/// Spatial velocity: linear (m/s) and angular (rad/s), in the world frame.
struct Twist {
  Vec3 linear = Vec3::Zero();
  Vec3 angular = Vec3::Zero();
};

/// Force (N) and torque (N·m), in the world frame.
struct Wrench {
  Vec3 force = Vec3::Zero();
  Vec3 torque = Vec3::Zero();
  Wrench& operator+=(const Wrench& o) {
    force += o.force;
    torque += o.torque;
    return *this;
  }
};

/// True when `pose` is finite and its linear part a proper rotation (RᵀR = I
/// within 1e-6 per entry, det > 0): the check applied to every pose a
/// renderer, a FEM obstacle or a tool is given. O(1), real-time safe.
inline bool isRigidPose(const Isometry3& pose) noexcept {
  if (!pose.matrix().allFinite()) return false;
  const Mat3 r = pose.linear();
  return (r.transpose() * r - Mat3::Identity()).cwiseAbs().maxCoeff() < 1e-6 && r.determinant() > 0.0;
}

}  // namespace dm
