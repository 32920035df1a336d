// dm/math/registration.hpp — paired-point rigid (and similarity)
// registration, e.g. patient-to-image registration from fiducial markers.
//
// registerPoints() is Umeyama's closed form (IEEE PAMI 13(4), 1991): the
// rotation R (det = +1), translation t and optional isotropic scale s that
// minimise Σ w_i ‖s R p_i + t − q_i‖² over corresponding source points p_i
// and target points q_i. It reports the fiducial registration error (FRE).
// targetRegistrationError() measures TRE at target points against a known
// ground truth; predictedTre() gives Fitzpatrick's expected TRE
// (Fitzpatrick, West & Maurer, IEEE TMI 17(5), 1998) for a fiducial layout.
//
// Statistics to expect with independent isotropic fiducial localisation
// error (FLE) of RMS ⟨FLE²⟩^½ in 3-D: ⟨FRE²⟩ ≈ (1 − 2/N)⟨FLE²⟩ for rigid
// registration (3N residual coordinates, 6 fitted parameters) and
// ⟨FRE²⟩ ≈ (1 − 7/(3N))⟨FLE²⟩ with scale. A small FRE does not imply a small
// TRE; predict TRE at the surgical target instead.
//
// @code
//   auto reg = dm::registerPoints(imageFiducials, trackerFiducials);
//   if (!reg) return reg.error();
//   dm::Vec3 tip = reg->transform() * targetInImage;   // reg->fre in metres
// @endcode
#pragma once

#include <dm/core/result.hpp>
#include <dm/math/types.hpp>

#include <span>
#include <vector>

namespace dm {

/// Options of registerPoints().
struct RegistrationOptions {
  /// Also estimate an isotropic scale s (similarity transform); otherwise s = 1.
  bool estimateScale = false;
  /// Optional per-point weights w_i ≥ 0 (empty: all 1), e.g. 1/σ_i² of each
  /// fiducial's localisation error. At least 3 must be positive.
  std::span<const double> weights = {};
  /// Relative threshold for degenerate layouts: points are "collinear" when
  /// the second principal spread is below this times the first.
  double degeneracyTolerance = 1e-6;
};

/// Result of registerPoints(): q ≈ scale · rotation · p + translation.
struct Registration {
  Mat3 rotation = Mat3::Identity();  ///< proper rotation, det = +1
  Vec3 translation = Vec3::Zero();   ///< in target units (metres)
  double scale = 1.0;                ///< 1 unless estimateScale
  /// Fiducial registration error: RMS of ‖s R p_i + t − q_i‖ (weighted RMS
  /// √(Σ w_i r_i² / Σ w_i) when weights are given), target units.
  double fre = 0.0;
  std::vector<double> residuals;  ///< ‖s R p_i + t − q_i‖ per point (unweighted)
  /// True when the unconstrained least-squares optimum was a reflection
  /// (det = −1); the returned rotation is then the best proper rotation.
  /// Usually a sign of mirrored data or swapped fiducials.
  bool reflectionAvoided = false;

  /// The transform as an affine map x ↦ s R x + t.
  Affine3 transform() const;
  /// Applies the transform to one point.
  Vec3 apply(const Vec3& p) const { return scale * (rotation * p) + translation; }
};

/// Umeyama registration of corresponding points source[i] ↔ target[i]
/// (N ≥ 3, not collinear). O(N). Coplanar points are fine.
/// Fails with InvalidArgument on N < 3, different counts, NaN/Inf, bad
/// weights (negative, non-finite, count mismatch, fewer than 3 positive),
/// coincident or collinear source or target points (rotation about the line
/// would be undetermined), or a rank-deficient cross-covariance.
/// @code
///   dm::RegistrationOptions o{.estimateScale = true};
///   auto reg = dm::registerPoints(src, dst, o);
///   double s = reg->scale;
/// @endcode
Result<Registration> registerPoints(std::span<const Vec3> source, std::span<const Vec3> target,
                                    const RegistrationOptions& options = {});

/// Target registration error at known points.
struct TreReport {
  std::vector<double> errors;  ///< ‖T_est(r_j) − T_true(r_j)‖ per target, target units
  double rms = 0.0;
  double max = 0.0;
};

/// TRE of an estimated registration against the ground-truth transform
/// `truth` (x ↦ truth * x) at the points `targets` (source frame). O(M).
/// Fails on an empty target list or NaN/Inf.
/// @code
///   auto tre = dm::targetRegistrationError(*reg, groundTruth, {tumourCentre});
///   dm::log::info("TRE %.2f mm", 1e3 * tre->max);
/// @endcode
Result<TreReport> targetRegistrationError(const Registration& estimated, const Affine3& truth,
                                          std::span<const Vec3> targets);

/// Fitzpatrick's prediction of the RMS TRE of rigid point registration at
/// each target, for N fiducials (source frame) with independent, isotropic
/// FLE of RMS `fleRms` (3-D, i.e. ⟨FLE²⟩ = fleRms²):
///   ⟨TRE²(r)⟩ ≈ ⟨FLE²⟩/N · (1 + ⅓ Σ_k d_k²/f_k²),
/// d_k = distance of r from principal axis k of the fiducials, f_k = RMS
/// distance of the fiducials from that axis. First order in FLE. O(N + M).
/// Fails on N < 3, collinear fiducials, fleRms < 0 or NaN/Inf.
Result<std::vector<double>> predictedTre(std::span<const Vec3> fiducials, std::span<const Vec3> targets,
                                         double fleRms);

}  // namespace dm
