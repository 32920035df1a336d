// Helpers shared by the DMHaptics tests.
#pragma once

#include <dm/haptics/renderer.hpp>

#include <algorithm>

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

/// Moves the handle in `steps` straight 1 kHz ticks from `from` to `to`
/// (slerping the orientation), then holds it `hold` ticks; the last response.
inline HapticResponse drive(HapticRenderer& r, const Isometry3& from, const Isometry3& to, int steps,
                            int hold) {
  HapticResponse out;
  const Quat q0(from.linear()), q1(to.linear());
  for (int i = 1; i <= steps + hold; ++i) {
    const double t = std::min(1.0, static_cast<double>(i) / steps);
    out = r.tick({.timeNs = i * 1000000LL,
                  .dt = kDt,
                  .devicePose = at((1 - t) * from.translation() + t * to.translation(),
                                   q0.slerp(t, q1).toRotationMatrix())});
  }
  return out;
}

}  // namespace dm::test
