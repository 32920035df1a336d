// dm/math/primitives.hpp — closed triangle meshes of analytic shapes: tool
// models (spheres, tori, boxes), stand-in anatomy and test geometry whose volume,
// area and distance are known exactly. All are welded, closed, 2-manifold
// and CCW from outside, in metres, centred at the origin.
//
// @code
//   dm::Mesh ball = dm::makeIcosphere(0.005, 3);          // 1280 triangles, r = 5 mm
//   dm::Mesh ring = dm::makeTorus(0.02, 0.004, 48, 16);   // about z
// @endcode
#pragma once

#include <dm/core/mesh.hpp>

namespace dm {

/// Icosahedron subdivided `levels` times (20·4^levels triangles), vertices
/// projected onto the sphere of `radius`. levels is clamped to [0, 8].
Mesh makeIcosphere(double radius, int levels);

/// Latitude–longitude sphere with a vertex at each pole: `rings` ≥ 2 bands
/// from pole to pole, `segments` ≥ 3 around z; 2·segments·(rings − 1)
/// triangles. Smaller counts are raised to those minima.
Mesh makeUvSphere(double radius, int rings, int segments);

/// Torus about z: `majorRadius` from the axis to the tube's centre line,
/// `minorRadius` of the tube; nu ≥ 3 steps around z, nv ≥ 3 around the tube;
/// 2·nu·nv triangles, genus 1.
Mesh makeTorus(double majorRadius, double minorRadius, int nu, int nv);

/// Axis-aligned box of the given half extents: 8 vertices, 12 triangles.
Mesh makeBox(const Vec3& halfExtents);

}  // namespace dm
