#include <dm/math/pca.hpp>
#include <dm/math/registration.hpp>

#include <Eigen/Eigenvalues>
#include <Eigen/SVD>

#include <cmath>
#include <cstdio>
#include <limits>
#include <string>

#include "math_internal.hpp"

namespace dm {
namespace {

using detail::invalid;

Status checkFinite(std::span<const Vec3> pts, const char* name, const char* where) {
  for (std::size_t i = 0; i < pts.size(); ++i)
    if (!pts[i].allFinite())
      return invalid(formatString("%s[%zu] = (%g, %g, %g) has a NaN or Inf coordinate", name, i, pts[i].x(),
                                  pts[i].y(), pts[i].z()),
                     where, "check the fiducial localisation or tracking data");
  return ok();
}

// Weighted spread of a point set: rejects coincident and collinear layouts.
// `cov` is the weighted covariance (Σ w (p−μ)(p−μ)ᵀ / Σ w).
Status checkLayout(const Mat3& cov, double maxNorm, double tol, const char* name, const char* where) {
  Eigen::SelfAdjointEigenSolver<Mat3> eig(cov, Eigen::EigenvaluesOnly);
  const Vec3 lambda = eig.eigenvalues().cwiseMax(0.0);  // ascending
  const double s1 = std::sqrt(lambda[2]), s2 = std::sqrt(lambda[1]);
  const double roundoff = 64.0 * std::numeric_limits<double>::epsilon() * maxNorm;
  if (s1 <= roundoff)
    return invalid(formatString("%s points are all coincident (spread %.3e)", name, s1), where,
                   "use at least 3 distinct fiducials that span a triangle");
  if (s2 <= tol * s1 || s2 <= roundoff)
    return invalid(
        formatString("%s points are collinear: second principal spread %.3e is below %.1e × the first (%.3e)",
                     name, s2, tol, s1),
        where,
        "rotation about the line through collinear points is undetermined; add a fiducial off the "
        "line (at least 3 non-collinear points with non-zero weight)");
  return ok();
}

}  // namespace

Affine3 Registration::transform() const {
  Affine3 T = Affine3::Identity();
  T.linear() = scale * rotation;
  T.translation() = translation;
  return T;
}

Result<Registration> registerPoints(std::span<const Vec3> source, std::span<const Vec3> target,
                                    const RegistrationOptions& options) {
  constexpr const char* where = "registerPoints";
  const std::size_t n = source.size();
  if (target.size() != n)
    return invalid(formatString("%zu source points but %zu target points", n, target.size()), where,
                   "registration needs corresponding pairs: source[i] ↔ target[i]");
  if (n < 3)
    return invalid(
        formatString("%zu point pairs; rigid registration needs at least 3 non-collinear pairs", n), where,
        "add fiducials");
  if (Status s = checkFinite(source, "source", where); !s) return std::move(s).error();
  if (Status s = checkFinite(target, "target", where); !s) return std::move(s).error();
  const bool weighted = !options.weights.empty();
  if (weighted && options.weights.size() != n)
    return invalid(formatString("%zu weights for %zu point pairs", options.weights.size(), n), where,
                   "pass one weight per pair, or none");
  if (!(options.degeneracyTolerance >= 0.0) || !std::isfinite(options.degeneracyTolerance))
    return invalid("degeneracyTolerance must be finite and ≥ 0", where);
  std::size_t positive = 0;
  double wsum = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    const double w = weighted ? options.weights[i] : 1.0;
    if (!std::isfinite(w) || w < 0.0)
      return invalid(formatString("weight[%zu] = %g; weights must be finite and ≥ 0", i, w), where);
    positive += w > 0.0 ? 1 : 0;
    wsum += w;
  }
  if (positive < 3)
    return invalid(formatString("only %zu pairs have a positive weight; at least 3 are needed", positive),
                   where, "give at least 3 non-collinear fiducials a positive weight");
  auto weight = [&](std::size_t i) { return weighted ? options.weights[i] : 1.0; };

  Vec3 mp = Vec3::Zero(), mq = Vec3::Zero();
  double maxNormP = 0.0, maxNormQ = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    mp += weight(i) * source[i];
    mq += weight(i) * target[i];
    maxNormP = std::max(maxNormP, source[i].norm());
    maxNormQ = std::max(maxNormQ, target[i].norm());
  }
  mp /= wsum;
  mq /= wsum;
  Mat3 covP = Mat3::Zero(), covQ = Mat3::Zero(), sigma = Mat3::Zero();
  for (std::size_t i = 0; i < n; ++i) {
    const Vec3 p = source[i] - mp, q = target[i] - mq;
    covP.noalias() += weight(i) * p * p.transpose();
    covQ.noalias() += weight(i) * q * q.transpose();
    sigma.noalias() += weight(i) * q * p.transpose();
  }
  covP /= wsum;
  covQ /= wsum;
  sigma /= wsum;
  if (Status s = checkLayout(covP, maxNormP, options.degeneracyTolerance, "source", where); !s)
    return std::move(s).error();
  if (Status s = checkLayout(covQ, maxNormQ, options.degeneracyTolerance, "target", where); !s)
    return std::move(s).error();

  // Umeyama: Σ = U D Vᵀ, R = U S Vᵀ with S = diag(1, 1, det(U)det(V)).
  Eigen::JacobiSVD<Mat3> svd(sigma, Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Vec3 d = svd.singularValues();  // descending
  if (d[1] <= options.degeneracyTolerance * d[0])
    return invalid(
        formatString("the cross-covariance of the pairs has rank < 2 (singular values %.3e, %.3e, %.3e)",
                     d[0], d[1], d[2]),
        where, "the pairs do not determine a rotation; check that source[i] and target[i] correspond");
  Vec3 S = Vec3::Ones();
  Registration out;
  if (svd.matrixU().determinant() * svd.matrixV().determinant() < 0.0) {
    S[2] = -1.0;
    // Only a real reflection if the third direction carries signal; for
    // coplanar points d[2] ≈ 0 and the sign is arbitrary.
    out.reflectionAvoided = d[2] > options.degeneracyTolerance * d[0];
  }
  out.rotation = svd.matrixU() * S.asDiagonal() * svd.matrixV().transpose();
  if (options.estimateScale) out.scale = d.dot(S) / covP.trace();
  out.translation = mq - out.scale * out.rotation * mp;

  out.residuals.resize(n);
  double sq = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    const double r = (out.apply(source[i]) - target[i]).norm();
    out.residuals[i] = r;
    sq += weight(i) * r * r;
  }
  out.fre = std::sqrt(sq / wsum);
  return out;
}

Result<TreReport> targetRegistrationError(const Registration& estimated, const Affine3& truth,
                                          std::span<const Vec3> targets) {
  constexpr const char* where = "targetRegistrationError";
  if (targets.empty()) return invalid("no target points", where, "pass at least one target point");
  if (Status s = checkFinite(targets, "targets", where); !s) return std::move(s).error();
  if (!truth.matrix().allFinite() || !estimated.rotation.allFinite() || !estimated.translation.allFinite() ||
      !std::isfinite(estimated.scale))
    return invalid("a transform has NaN or Inf entries", where);
  TreReport out;
  out.errors.reserve(targets.size());
  double sq = 0.0;
  for (const Vec3& r : targets) {
    const double e = (estimated.apply(r) - truth * r).norm();
    out.errors.push_back(e);
    sq += e * e;
    out.max = std::max(out.max, e);
  }
  out.rms = std::sqrt(sq / static_cast<double>(targets.size()));
  return out;
}

Result<std::vector<double>> predictedTre(std::span<const Vec3> fiducials, std::span<const Vec3> targets,
                                         double fleRms) {
  constexpr const char* where = "predictedTre";
  if (fiducials.size() < 3)
    return invalid(
        formatString("%zu fiducials; the prediction needs at least 3 non-collinear", fiducials.size()),
        where);
  if (!std::isfinite(fleRms) || fleRms < 0.0)
    return invalid(formatString("fleRms = %g must be finite and ≥ 0", fleRms), where);
  if (Status s = checkFinite(targets, "targets", where); !s) return std::move(s).error();
  auto p = pca(fiducials);
  if (!p) return std::move(p).error().within(where);
  const Vec3& var = p->variances;  // descending, covariance divided by N
  if (var[1] <= 1e-12 * var[0])
    return invalid("fiducials are collinear; TRE is unbounded (rotation about their line is free)", where,
                   "add a fiducial off the line");
  const double n = static_cast<double>(fiducials.size());
  const double total = var.sum();
  std::vector<double> out;
  out.reserve(targets.size());
  for (const Vec3& r : targets) {
    const Vec3 c = r - p->mean;
    double sum = 0.0;
    for (int k = 0; k < 3; ++k) {
      const double along = c.dot(p->axes.col(k));
      const double d2 = c.squaredNorm() - along * along;  // squared distance from axis k
      const double f2 = total - var[k];                   // mean squared fiducial distance from axis k
      sum += d2 / f2;
    }
    out.push_back(fleRms * std::sqrt((1.0 + sum / 3.0) / n));
  }
  return out;
}

}  // namespace dm
