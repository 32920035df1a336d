// dm/math/pca.hpp — principal component analysis of 3-D point sets.
#pragma once

#include <dm/core/result.hpp>
#include <dm/math/types.hpp>

#include <span>

namespace dm {

/// Principal axes of a point set.
struct Pca3 {
  Vec3 mean = Vec3::Zero();       ///< centroid, same units as the input
  Mat3 axes = Mat3::Identity();   ///< columns: unit principal axes, right-handed
  Vec3 variances = Vec3::Zero();  ///< variance along each axis, descending
};

/// PCA of `points` (covariance divided by n). O(n).
/// Fails with InvalidArgument on an empty set or a non-finite coordinate.
/// @code
///   auto p = dm::pca(points);  // p->axes.col(0) is the longest direction
/// @endcode
Result<Pca3> pca(std::span<const Vec3> points);

/// PCA of the rows of an n×d matrix: mean (d), axes (d×d columns, descending),
/// variances (d). Fails on n == 0 or non-finite input.
struct PcaX {
  VecX mean;
  MatX axes;
  VecX variances;
};
Result<PcaX> pca(const MatX& rows);

}  // namespace dm
