// Helpers shared by the DMHaptics tests.
#pragma once

#include <dm/collide/sphere_tree.hpp>
#include <dm/haptics/renderer.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <memory>
#include <numbers>
#include <vector>

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

// A sphere tree whose every level is one sphere (centre c, radius r).
inline std::shared_ptr<const SphereTree> ballTree(double r, int levels, const Vec3& c = Vec3::Zero()) {
  std::vector<SphereTreeNode> nodes(static_cast<std::size_t>(levels));
  for (int l = 0; l < levels; ++l) {
    SphereTreeNode& n = nodes[static_cast<std::size_t>(l)];
    n.center = c;
    n.radius = r;
    n.level = static_cast<std::uint8_t>(l);
    n.firstChild = static_cast<std::uint32_t>(l + 1);
    n.childCount = l + 1 < levels ? 1 : 0;
  }
  auto t = SphereTree::fromNodes(std::move(nodes), 4.0 / 3.0 * std::numbers::pi * r * r * r);
  EXPECT_TRUE(t.ok());
  return *t;
}

}  // namespace dm::test
