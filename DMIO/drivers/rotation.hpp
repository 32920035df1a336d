// Rotation matrix to quaternion for the drivers of vendor APIs that give a
// device's orientation as a matrix (OpenHaptics' transform, DHD's frame).
// Header-only and Eigen-free, so that a driver built as a plugin needs no
// DMPlatform library.
#pragma once

#include <cmath>

namespace dm::driver {

/// The unit quaternion (w, x, y, z) of rotation r (row-major 3×3), by
/// Shepperd's method (the largest of w, x, y, z first: no cancellation).
inline void quaternionOfRotation(const double r[9], double q[4]) noexcept {
  const double tr = r[0] + r[4] + r[8];
  if (tr > 0.0) {
    const double s = 2.0 * std::sqrt(tr + 1.0);
    q[0] = 0.25 * s;
    q[1] = (r[7] - r[5]) / s;
    q[2] = (r[2] - r[6]) / s;
    q[3] = (r[3] - r[1]) / s;
  } else if (r[0] > r[4] && r[0] > r[8]) {
    const double s = 2.0 * std::sqrt(1.0 + r[0] - r[4] - r[8]);
    q[0] = (r[7] - r[5]) / s;
    q[1] = 0.25 * s;
    q[2] = (r[1] + r[3]) / s;
    q[3] = (r[2] + r[6]) / s;
  } else if (r[4] > r[8]) {
    const double s = 2.0 * std::sqrt(1.0 + r[4] - r[0] - r[8]);
    q[0] = (r[2] - r[6]) / s;
    q[1] = (r[1] + r[3]) / s;
    q[2] = 0.25 * s;
    q[3] = (r[5] + r[7]) / s;
  } else {
    const double s = 2.0 * std::sqrt(1.0 + r[8] - r[0] - r[4]);
    q[0] = (r[3] - r[1]) / s;
    q[1] = (r[2] + r[6]) / s;
    q[2] = (r[5] + r[7]) / s;
    q[3] = 0.25 * s;
  }
  const double n = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  for (int i = 0; i < 4; ++i) q[i] = n > 0.0 ? q[i] / n : (i == 0 ? 1.0 : 0.0);
}

}  // namespace dm::driver
