// dm/haptics/effects.hpp — force effects the haptic loop adds on top of a
// renderer's contact force: viscosity, snap-to surface (magnetic), vibration,
// guidance springs / virtual fixtures that keep the tool in a safe region
// (sphere, box, or a corridor around a segment), and force fields given as a
// function of the device point (e.g. DMVision's segmentation guidance).
//
// Every effect reads the same world-frame HapticInput the renderer got and
// adds its force (N) and torque (N·m) to the HapticResponse. Effects are
// built at setup and put in an EffectStack (fixed capacity, add/remove at
// setup); apply() on the haptic thread never allocates, locks or throws.
//
// @code
//   dm::EffectStack effects(4);
//   effects.add(std::make_unique<dm::ViscosityEffect>(5.0));                 // 5 N·s/m
//   effects.add(std::make_unique<dm::VirtualFixture>(dm::SafeSphere{c, 0.02}, 400.0, 2.0));
//   effects.apply(input, response);                                        // haptic tick
// @endcode
#pragma once

#include <dm/collide/bvh.hpp>
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>
#include <dm/haptics/renderer.hpp>

#include <cstddef>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <variant>
#include <vector>

namespace dm {

/// A force effect; see the file comment.
class ForceEffect {
 public:
  virtual ~ForceEffect() = default;
  /// "viscosity", "snap", "vibration", "fixture".
  virtual std::string_view name() const noexcept = 0;
  /// Adds this effect's force and torque for `input` to `out`. Real-time safe.
  virtual void apply(const HapticInput& input, HapticResponse& out) const noexcept = 0;
};

/// Viscous drag F = −b·v, everywhere or only while the device point is in
/// `region` (world, m). O(1).
class ViscosityEffect final : public ForceEffect {
 public:
  /// `damping` b in N·s/m (negative or NaN counts as 0).
  explicit ViscosityEffect(double damping, std::optional<Aabb> region = std::nullopt) noexcept;
  std::string_view name() const noexcept override { return "viscosity"; }
  void apply(const HapticInput& input, HapticResponse& out) const noexcept override;
  double damping() const noexcept { return damping_; }

 private:
  double damping_;
  std::optional<Aabb> region_;
};

/// Closest surface point to a world point: returns false when there is none
/// (nothing within reach), else writes it to `closest`. Must be real-time safe.
using ClosestPointFn = std::function<bool(const Vec3& point, Vec3& closest)>;

/// Snap-to surface (magnetic): within `captureDistance` c of a surface the
/// device point p is pulled toward its closest surface point q. With
/// r = |q − p|, the force along (q − p)/r has magnitude k·r for r ≤ c/2 and
/// k·(c − r) for c/2 < r < c (a triangle profile: zero at the surface and at
/// the capture boundary, so entering or leaving the field never steps), and
/// 0 beyond. O(1) plus the closest-point query (O(log n) on a MeshBvh).
class SnapToSurfaceEffect final : public ForceEffect {
 public:
  /// Surface given by a callable. `stiffness` k in N/m, `captureDistance` c in m.
  SnapToSurfaceEffect(ClosestPointFn closest, double stiffness, double captureDistance);
  /// Surface of a triangle mesh `bvh` (kept by reference: must outlive the
  /// effect) placed at `pose` (mesh frame → world); uses dm::closestPointOnMesh.
  SnapToSurfaceEffect(const MeshBvh& bvh, const Isometry3& pose, double stiffness, double captureDistance);
  std::string_view name() const noexcept override { return "snap"; }
  void apply(const HapticInput& input, HapticResponse& out) const noexcept override;
  /// Magnitude of the snap force at distance r ≥ 0 from the surface (N).
  double magnitudeAt(double r) const noexcept;

 private:
  ClosestPointFn closest_;
  const MeshBvh* bvh_ = nullptr;
  Isometry3 pose_ = Isometry3::Identity();
  double stiffness_, capture_;
};

/// A force as a function of the device point (world, m → N). Must be real-time
/// safe: no allocation, lock or throw.
using ForceFieldFn = std::function<Vec3(const Vec3& point)>;

/// A force field F(p) at the device point p, e.g. the guidance force of
/// dm::HapticSegmentation (DMVision) that keeps the probe in homogeneous
/// tissue. A non-finite answer adds nothing. O(1) plus the field's cost.
/// @code
///   effects.add(std::make_unique<dm::ForceFieldEffect>(
///       [&seg](const dm::Vec3& p) { return seg.guidanceForce(p); }, "segmentation"));
/// @endcode
class ForceFieldEffect final : public ForceEffect {
 public:
  /// `name` is what name() reports (kept by value; default "field").
  explicit ForceFieldEffect(ForceFieldFn field, std::string name = "field");
  std::string_view name() const noexcept override { return name_; }
  void apply(const HapticInput& input, HapticResponse& out) const noexcept override;

 private:
  ForceFieldFn field_;
  std::string name_;
};

/// Vibration F = A·sin(2π·f·t + φ)·axis with t = input.timeNs in seconds. O(1).
class VibrationEffect final : public ForceEffect {
 public:
  /// `amplitude` A in N, `frequencyHz` f, `axis` (normalized here; a zero or
  /// non-finite axis gives no force), `phase` φ in rad.
  VibrationEffect(double amplitude, double frequencyHz, const Vec3& axis, double phase = 0.0) noexcept;
  std::string_view name() const noexcept override { return "vibration"; }
  void apply(const HapticInput& input, HapticResponse& out) const noexcept override;

 private:
  double amplitude_, omega_, phase_;
  Vec3 axis_;
};

/// Safe region: a ball.
struct SafeSphere {
  Vec3 center = Vec3::Zero();  ///< world, m
  double radius = 0.0;         ///< m
};
/// Safe region: a box with half extents `halfExtents` in its frame `pose` (box → world).
struct SafeBox {
  Isometry3 pose = Isometry3::Identity();
  Vec3 halfExtents = Vec3::Zero();  ///< m
};
/// Safe corridor: every point within `radius` of the segment [a, b] (a
/// cylinder around the line with round ends).
struct SafeCorridor {
  Vec3 a = Vec3::Zero(), b = Vec3::Zero();  ///< world, m
  double radius = 0.0;                      ///< m
};
using SafeRegion = std::variant<SafeSphere, SafeBox, SafeCorridor>;

/// Closest point of `region` to `p` (p itself when inside) and whether p is
/// inside (boundary included). O(1).
Vec3 closestPointInRegion(const SafeRegion& region, const Vec3& p, bool* inside = nullptr) noexcept;

/// Guidance spring / virtual fixture (forbidden-region type): no force while
/// the device point is inside `region`; outside, at distance d from it along
/// the outward normal n (from the closest region point q toward p), a spring
/// and a damper push it back: F = −max(0, k·d + b·(v·n))·n (never pulls
/// outward). O(1).
class VirtualFixture final : public ForceEffect {
 public:
  /// `stiffness` k in N/m, `damping` b in N·s/m (negatives/NaN count as 0).
  VirtualFixture(const SafeRegion& region, double stiffness, double damping = 0.0) noexcept;
  std::string_view name() const noexcept override { return "fixture"; }
  void apply(const HapticInput& input, HapticResponse& out) const noexcept override;
  const SafeRegion& region() const noexcept { return region_; }

 private:
  SafeRegion region_;
  double stiffness_, damping_;
};

/// Fixed-capacity list of effects applied in order. add()/remove() at setup
/// (not while a loop is applying the stack); apply() is real-time safe.
class EffectStack {
 public:
  /// Room for `capacity` effects (reserved now).
  explicit EffectStack(std::size_t capacity);
  /// Takes ownership of `effect` and returns a pointer to it (valid until
  /// removed). Busy when full, InvalidArgument for null.
  /// @code
  ///   auto v = stack.add(std::make_unique<dm::VibrationEffect>(0.5, 200.0, dm::Vec3::UnitZ()));
  /// @endcode
  Result<ForceEffect*> add(std::unique_ptr<ForceEffect> effect);
  /// Removes and destroys `effect`; false if it is not in the stack.
  bool remove(const ForceEffect* effect) noexcept;
  /// Removes every effect.
  void clear() noexcept;
  /// Adds every effect's force and torque to `out`. O(effects).
  void apply(const HapticInput& input, HapticResponse& out) const noexcept;
  std::size_t size() const noexcept { return effects_.size(); }
  std::size_t capacity() const noexcept { return capacity_; }
  bool empty() const noexcept { return effects_.empty(); }

 private:
  std::size_t capacity_;
  std::vector<std::unique_ptr<ForceEffect>> effects_;
};

}  // namespace dm
