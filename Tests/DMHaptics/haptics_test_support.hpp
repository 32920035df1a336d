// Helpers shared by the DMHaptics tests.
#pragma once

#include <dm/haptics/renderer.hpp>

namespace dm::test {

inline constexpr double kDt = 1e-3;           // s: one tick at 1 kHz
inline constexpr double kStiffness = 1000.0;  // N/m: the material of the test objects

/// The pose at `t` rotated by `r`.
inline Isometry3 at(const Vec3& t, const Mat3& r = Mat3::Identity()) {
  Isometry3 p = Isometry3::Identity();
  p.linear() = r;
  p.translation() = t;
  return p;
}

/// A device sample at `p` moving at `v`, at time 0, one 1 kHz tick after the last.
inline HapticInput input(const Vec3& p, const Vec3& v = Vec3::Zero()) {
  return {.timeNs = 0, .dt = 1e-3, .devicePose = at(p), .linearVelocity = v};
}

}  // namespace dm::test
