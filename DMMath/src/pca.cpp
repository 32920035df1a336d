#include <dm/math/pca.hpp>

#include <Eigen/Eigenvalues>

#include <string>

namespace dm {

Result<PcaX> pca(const MatX& rows) {
  if (rows.rows() == 0 || rows.cols() == 0)
    return fail(ErrorCode::InvalidArgument, "PCA of an empty point set", {}, "pass at least one point");
  if (!rows.allFinite()) return fail(ErrorCode::InvalidArgument, "PCA input has a NaN or Inf coordinate");
  PcaX out;
  out.mean = rows.colwise().mean().transpose();
  const MatX centred = rows.rowwise() - out.mean.transpose();
  const MatX cov = (centred.transpose() * centred) / static_cast<double>(rows.rows());
  Eigen::SelfAdjointEigenSolver<MatX> eig(cov);
  // Eigen sorts ascending; PCA reports descending variance.
  out.variances = eig.eigenvalues().reverse().cwiseMax(0.0);
  out.axes = eig.eigenvectors().rowwise().reverse();
  return out;
}

Result<Pca3> pca(std::span<const Vec3> points) {
  MatX rows(static_cast<Eigen::Index>(points.size()), 3);
  for (std::size_t i = 0; i < points.size(); ++i)
    rows.row(static_cast<Eigen::Index>(i)) = points[i].transpose();
  auto r = pca(rows);
  if (!r) return std::move(r).error();
  Pca3 out;
  out.mean = r->mean;
  out.axes = r->axes;
  out.variances = r->variances;
  if (out.axes.determinant() < 0) out.axes.col(2) = -out.axes.col(2);
  return out;
}

}  // namespace dm
