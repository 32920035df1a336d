// A closed L-shaped prism: the square [0, 2a]² less its corner (c, 2a]²
// (0 < c < 2a), extruded over z ∈ [−h/2, h/2]. Its edge along z at (c, c)
// is concave (a groove, an inner corner in plan); the others are convex. Shared by the
// sphere-tree crease (DMCollide) and haptic accuracy (DMHaptics) tests.
#pragma once

#include <dm/core/mesh.hpp>

#include <array>

namespace dm::test {

/// The prism's mesh: 12 vertices, 20 triangles, CCW from outside. A
/// groove on a sphere tree's cell walls (c = a: the middle of its bounds)
/// is clipped into slivers: pick c off the walls.
inline Mesh lPrism(double a, double c, double h) {
  // The L in plan, counter-clockwise from above; (c, c) is the reflex vertex.
  const std::array<Vec3, 6> plan = {Vec3(0, 0, 0), Vec3(2 * a, 0, 0), Vec3(2 * a, c, 0),
                                    Vec3(c, c, 0), Vec3(c, 2 * a, 0), Vec3(0, 2 * a, 0)};
  Mesh m;
  for (const double z : {0.5 * h, -0.5 * h})
    for (const Vec3& p : plan) m.positions.push_back(p + Vec3(0, 0, z));
  // Top: a fan about the reflex vertex (3), which sees every other; bottom reversed.
  for (const std::uint32_t i : {4u, 5u, 0u, 1u}) {
    m.triangles.push_back({3, i, (i + 1) % 6});
    m.triangles.push_back({9, 6 + (i + 1) % 6, 6 + i});
  }
  for (std::uint32_t i = 0; i < 6; ++i) {  // the sides, outward
    const std::uint32_t j = (i + 1) % 6;
    m.triangles.push_back({6 + i, 6 + j, j});
    m.triangles.push_back({6 + i, j, i});
  }
  return m;
}

}  // namespace dm::test
