// Private: constants shared by several DMCollide sources. Not installed.
#pragma once

#include <dm/collide/bvh.hpp>

#include <algorithm>
#include <cmath>
#include <limits>

namespace dm::detail {

inline constexpr double kInf = std::numeric_limits<double>::infinity();

/// Entries of the stack of a depth-first walk down one MeshBvh (mesh queries,
/// mesh sweeps): <= depth + 1.
inline constexpr int kStack = 128;
static_assert(kStack > MeshBvh::kMaxDepth + 1);

/// Signed distance (m, < 0 inside) of a box of half extents `half` centred
/// at the origin, exact inside and out; `gradient` (if given) gets its unit
/// gradient (the nearest face's normal inside).
inline double boxSignedDistance(const Vec3& p, const Vec3& half, Vec3* gradient = nullptr) noexcept {
  const Vec3 q = p.cwiseAbs() - half;
  const double inside = q.maxCoeff();
  if (inside > 0.0) {
    const Vec3 out = q.cwiseMax(0.0);
    const double d = out.norm();
    if (gradient) *gradient = (out / d).cwiseProduct(p.cwiseSign());
    return d;
  }
  if (gradient) {
    int axis = 0;
    q.maxCoeff(&axis);
    *gradient = Vec3::Zero();
    (*gradient)[axis] = p[axis] < 0.0 ? -1.0 : 1.0;
  }
  return inside;
}

/// Signed distance of a flat-ended cylinder about local z (radius r, half
/// length l), exact inside and out, and its unit gradient (if given).
/// sqrt, not hypot: lengths in metres cannot overflow, and std::hypot is a
/// libm call ~10x slower (it was a sixth of a milling tool's query time).
inline double cylinderSignedDistance(const Vec3& p, double r, double l, Vec3* gradient = nullptr) noexcept {
  const double rho = std::sqrt(p.x() * p.x() + p.y() * p.y());
  const double qr = rho - r, qz = std::abs(p.z()) - l;
  const Vec3 radial = rho > 0.0 ? Vec3(p.x() / rho, p.y() / rho, 0.0) : Vec3::UnitX();
  const Vec3 axial(0.0, 0.0, p.z() < 0.0 ? -1.0 : 1.0);
  if (qr > 0.0 && qz > 0.0) {
    const double d = std::sqrt(qr * qr + qz * qz);
    if (gradient) *gradient = (qr * radial + qz * axial) / d;
    return d;
  }
  if (gradient) *gradient = qr > qz ? radial : axial;
  return std::max(qr, qz);
}

}  // namespace dm::detail
