// dm/math/primitives.hpp — triangle meshes of analytic shapes: tool models
// (spheres, tori, boxes, cylinders, capsules), stand-in anatomy, floors and
// test geometry whose volume, area and distance are known exactly. All are in
// metres, centred at the origin, CCW from outside. Icosphere, UV sphere,
// torus, box and capsule are welded, closed 2-manifolds; the cylinder is
// closed but keeps separate rim vertices for its caps and side (sharp
// normals), so it is a closed manifold once welded (weldVertices(m, 0));
// the plane is an open rectangle in z = 0.
//
// @code
//   dm::Mesh ball = dm::makeIcosphere(0.005, 3);          // 1280 triangles, r = 5 mm
//   dm::Mesh ring = dm::makeTorus(0.02, 0.004, 48, 16);   // about z
//   dm::Mesh shaft = dm::makeCylinder(0.002, 0.1, 24);    // along z
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

/// Closed cylinder of `radius` (m) about z, from z = −height/2 to +height/2,
/// with flat caps; `segments` steps around z, clamped to [3, 65536].
/// The rim vertices are duplicated so that normals are sharp there: each cap
/// has its own centre and rim (normals ±z), the side its own two rims (radial
/// normals). 4·segments + 2 vertices, 4·segments triangles; no uvs. Vertices
/// lie on the exact surface, so the volume is that of the inscribed prism,
/// (segments/2)·r²·sin(2π/segments)·height. O(segments).
/// @code
///   dm::Mesh shaft = dm::makeCylinder(0.002, 0.12, 32);  // r = 2 mm, 12 cm long
///   if (auto w = dm::weldVertices(shaft, 0); !w) return w.error();  // one rim for mass properties
///   auto mp = dm::computeMassProperties(shaft, 7900.0);
/// @endcode
Mesh makeCylinder(double radius, double height, int segments);

/// Capsule (sphere-swept segment) about z: two hemispheres of `radius` (m)
/// whose centres are at z = ±height/2 (`height` ≥ 0 is the length of the
/// cylindrical part; negative is taken as 0), joined by a cylinder.
/// `segments` around z, clamped to [3, 4096], and `rings` latitude bands per
/// hemisphere from pole to equator, clamped to [1, 2048]. Welded, closed, genus 0, with
/// smooth normals (the exact surface normals). 2·rings·segments + 2 vertices
/// and 4·rings·segments triangles (2·segments fewer and one equator when
/// height is 0, which gives a sphere). Vertices lie on the exact surface.
/// O(rings·segments).
/// @code
///   dm::Mesh probe = dm::makeCapsule(0.003, 0.05, 24, 6);  // r = 3 mm, 5 cm shaft
///   auto mp = dm::computeMassProperties(probe, 1200.0);
///   // mp->volume ≈ π r² h + 4/3 π r³
/// @endcode
Mesh makeCapsule(double radius, double height, int segments, int rings);

/// Flat rectangle [−halfX, halfX] × [−halfY, halfY] in z = 0 (m), normal +z,
/// triangles CCW seen from +z, split into divisions × divisions quads of two
/// triangles each (`divisions` clamped to [1, 4096]).
/// (divisions + 1)² vertices, 2·divisions² triangles. uvs run over [0, 1]²
/// with u = 0 at −x and v = 0 at the +y edge (image top), so an image maps
/// upright when seen from +z. Open: its outer edges are boundary edges.
/// @code
///   dm::Mesh floor = dm::makePlane(0.5, 0.3, 10);  // 1 m × 60 cm table top
///   floor.transform(tableFromLocal);
///   renderer.addMesh(floor, tableTexture);
/// @endcode
Mesh makePlane(double halfX, double halfY, int divisions);

}  // namespace dm
