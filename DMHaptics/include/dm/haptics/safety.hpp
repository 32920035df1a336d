// dm/haptics/safety.hpp — what keeps rendered forces stable and safe:
//
//  * the passivity bound of a sampled virtual wall (Colgate & Schenkel 1997)
//    and the material limits it implies for a device at a loop rate;
//  * the force / torque sanitiser (NaN/Inf → zero, norm clamp, reusing
//    dm::clampVectorNorm of dm/io/haptic_device.hpp);
//  * the loop-side output fade for renderer faults and overruns (the device
//    side — stale commands, loss — is dm::HapticDevice's job);
//  * the passivity observer / controller (Hannaford & Ryu 2002): it sums
//    the work the commanded force does on the user's hand and, when the
//    rendering has generated more than a threshold of energy, adds just
//    enough damping to dissipate it;
//  * pathWork(): replays a device path through a renderer in lockstep and
//    returns the work the renderer did on the user.
//
// Sign convention: "work on the user" W = Σ F·Δx with F the force on the
// hand and Δx the hand's displacement. W > 0 means the virtual environment
// delivered energy (it is active); a passive environment keeps W ≤ 0 over
// any closed path that starts and ends at rest in free space.
//
// Everything here is allocation-free and noexcept; the classes are plain
// values meant to live inside the haptic loop.
//
// @code
//   dm::HapticLimits lim = dm::limitsFor(device.info(), 1000.0);
//   dm::HapticMaterial m = dm::clampMaterial({.stiffness = 5000}, lim);  // ≤ lim.maxStiffness
//   double w = dm::pathWork(renderer, path, 1e-3);                      // J, > 0: active
// @endcode
#pragma once

#include <dm/core/types.hpp>
#include <dm/haptics/renderer.hpp>
#include <dm/io/haptic_device.hpp>

#include <limits>
#include <span>

namespace dm {

/// Largest wall stiffness K (N/m) that stays passive when rendered with
/// virtual damping `virtualDamping` B (N·s/m) at `rateHz` (period T = 1/rate)
/// on a device with physical damping `deviceDamping` b (N·s/m). Colgate &
/// Schenkel: passive iff b > K·T/2 + |B|, so K < 2·(b − |B|)·rate. Returns 0
/// when b ≤ |B| or any argument is not finite / the rate is not positive. O(1).
/// @code
///   double k = dm::passiveStiffnessBound(1.0, 0.0, 1000.0);  // 2000 N/m
/// @endcode
double passiveStiffnessBound(double deviceDamping, double virtualDamping, double rateHz) noexcept;

/// What a device can render at a given loop rate.
struct HapticLimits {
  double maxStiffness = 0.0;   ///< N/m, passive wall stiffness with zero virtual damping
  double maxDamping = 0.0;     ///< N·s/m, largest virtual damping
  double maxForce = 0.0;       ///< N
  double maxTorque = 0.0;      ///< N·m (0 for a 3-DOF device: no torque)
  double deviceDamping = 0.0;  ///< N·s/m, physical damping b implied by the device's rating
  double rateHz = 0.0;         ///< effective rate: min(loop rate, servo rate)
};

/// Limits of `info`'s device when forces are computed at `loopRateHz`.
/// Rule: a vendor's maxStiffness is the passive stiffness at its servo rate,
/// so by Colgate & Schenkel it implies a physical damping
/// b = maxStiffness / (2·servoRate). Commands reach the motors at most at the
/// servo rate, so the effective rate is r = min(loopRate, servoRate) and the
/// stiffness bound scales with it: maxStiffness(r) = passiveStiffnessBound(b, 0, r)
/// = info.maxStiffness · r / servoRate. maxDamping, maxForce and maxTorque are
/// the device's. A non-positive or non-finite loop rate gives all-zero
/// stiffness. O(1).
HapticLimits limitsFor(const HapticInfo& info, double loopRateHz) noexcept;

/// `m` with stiffness in (0, limits.maxStiffness] and damping in
/// [0, limits.maxDamping]; NaN fields become the smallest allowed value
/// (stiffness: 0 is not valid for HapticMaterial, so a NaN or non-positive
/// stiffness becomes min(1 N/m, maxStiffness)); friction coefficients are
/// made finite and non-negative with μd ≤ μs. O(1).
HapticMaterial clampMaterial(HapticMaterial m, const HapticLimits& limits) noexcept;

/// Makes a wrench safe to send: NaN/Inf in either vector zeroes that vector,
/// then each is clamped to its limit keeping its direction (dm::clampVectorNorm;
/// a limit of 0 — or negative/NaN — zeroes the vector, e.g. the torque of a
/// 3-DOF device; +infinity leaves it). Returns true if either vector was not
/// finite. O(1).
bool sanitizeWrench(Vec3& force, Vec3& torque, double forceLimit, double torqueLimit) noexcept;

/// Loop-side output fade. Each tick the loop reports whether it is faulty
/// (renderer returned NaN/Inf, tick overran its period, device lost); the
/// gain ramps linearly toward 0 while faulty and back toward 1 while healthy,
/// at 1/fadeSeconds per second, so the force never steps. apply() holds the
/// last finite wrench while faulty, so a NaN fades the previous force out
/// instead of cutting it. fadeSeconds = 0 switches instantly.
class OutputFade {
 public:
  /// `fadeSeconds` ≥ 0 (negative or NaN counts as 0).
  explicit OutputFade(double fadeSeconds = 0.005) noexcept;
  /// Starts healthy (gain 1) with a zero held wrench.
  void reset() noexcept;
  /// Sets the gain to 0 at once (device lost: the device already outputs
  /// nothing, so there is nothing to fade; the gain ramps up after).
  void cut() noexcept;
  /// One tick of `dt` seconds. `fault`: this tick is faulty; `force`/`torque`
  /// are this tick's finite wrench, or ignored when `finite` is false (the held
  /// wrench is used). Scales them in place by the new gain. O(1).
  void apply(Vec3& force, Vec3& torque, bool finite, bool fault, double dt) noexcept;
  /// Current gain in [0, 1].
  double gain() const noexcept { return gain_; }
  double fadeSeconds() const noexcept { return fadeSeconds_; }

 private:
  double fadeSeconds_ = 0.005;
  double gain_ = 1.0;
  Vec3 heldForce_ = Vec3::Zero(), heldTorque_ = Vec3::Zero();
};

/// Passivity controller settings (Hannaford & Ryu 2002).
struct PassivityConfig {
  bool enabled = true;  ///< false: observe only
  /// J, ≥ 0: energy the rendering may generate before damping is added.
  double threshold = 0.0;
  /// N·s/m, cap on the added linear damping (keeps the controller itself
  /// stable; infinity: no cap).
  double maxDamping = std::numeric_limits<double>::infinity();
  /// N·m·s/rad, cap on the added angular damping.
  double maxAngularDamping = std::numeric_limits<double>::infinity();
};

/// Passivity observer and controller for a force port and a torque port.
/// observe() adds the work the previously commanded wrench did over the
/// displacement since then (exact for a zero-order-hold output):
/// W += F·Δx + τ·Δθ. control() predicts the work of the wrench about to be
/// commanded, W + (F·v + τ·ω)·dt, and if that exceeds the threshold adds
/// damping −α·v (and −β·ω) with α (β) chosen so the prediction equals the
/// threshold (capped by the config), each port taking its own excess.
/// @code
///   dm::PassivityController pc;
///   pc.observe(lastForce, lastTorque, x - xPrev, dTheta);
///   pc.control(force, torque, v, w, dt, cfg);   // may add damping to force/torque
/// @endcode
class PassivityController {
 public:
  /// Forgets all energy.
  void reset() noexcept;
  /// Adds the work of the wrench (N, N·m) applied while the hand moved by
  /// `dx` (m) and rotated by `dtheta` (rad, rotation vector). O(1).
  void observe(const Vec3& force, const Vec3& torque, const Vec3& dx, const Vec3& dtheta) noexcept;
  /// Adds damping to `force`/`torque` if the predicted work over the next
  /// `dt` s at velocities `v` (m/s), `w` (rad/s) exceeds cfg.threshold.
  /// Returns true if it added any. Does nothing when !cfg.enabled. O(1).
  bool control(Vec3& force, Vec3& torque, const Vec3& v, const Vec3& w, double dt,
               const PassivityConfig& cfg) noexcept;
  /// J: total work done on the user so far (> 0: energy generated).
  double workOnUser() const noexcept { return linearWork_ + angularWork_; }
  /// J: the force port's and the torque port's share.
  double linearWork() const noexcept { return linearWork_; }
  double angularWork() const noexcept { return angularWork_; }
  /// Hannaford & Ryu's observed energy: −workOnUser() (negative: active).
  double observedEnergy() const noexcept { return -workOnUser(); }
  /// Last damping added (N·s/m, N·m·s/rad), 0 when none.
  double lastDamping() const noexcept { return lastAlpha_; }
  double lastAngularDamping() const noexcept { return lastBeta_; }

 private:
  double linearWork_ = 0.0, angularWork_ = 0.0;
  double lastAlpha_ = 0.0, lastBeta_ = 0.0;
};

/// Rotation vector (axis · angle, rad) of the rotation taking `from` to `to`,
/// expressed in the world frame: log(to · from⁻¹). O(1).
Vec3 rotationDelta(const Isometry3& from, const Isometry3& to) noexcept;

/// Replays `path` (device poses, world frame, one per tick of `dt` s)
/// through `renderer` in lockstep: reset at path[0], then tick k gets pose
/// path[k] with backward-difference velocities (zero at k = 0) and its
/// wrench is held (zero-order hold) while the hand moves to path[k+1].
/// Returns W = Σ F_k·(x_{k+1} − x_k) + τ_k·Δθ_k, the work the renderer did on
/// the user (J; positive = energy delivered to the user). Allocation-free
/// (as far as the renderer is). 0 for fewer than 2 poses or dt ≤ 0. O(n).
/// @code
///   double w = dm::pathWork(wall, path, 1e-3);
/// @endcode
double pathWork(HapticRenderer& renderer, std::span<const Isometry3> path, double dt) noexcept;

/// pathWork() with a PassivityController (config `pc`) between the renderer
/// and the hand: the returned work includes the added damping.
double pathWork(HapticRenderer& renderer, std::span<const Isometry3> path, double dt,
                const PassivityConfig& pc) noexcept;

}  // namespace dm
