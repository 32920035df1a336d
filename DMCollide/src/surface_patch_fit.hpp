// Internal: the fit of a sphere-tree node's SurfacePatch (surface_patch.cpp),
// used by the mesh sphere-tree builders (sphere_tree.cpp).
#pragma once

#include <dm/collide/sphere_tree.hpp>

#include <span>

namespace dm::detail {

/// The patch of a node whose surface has the area vector Σ area·n (m²), the
/// area Σ area (m²), the area moment Σ area·centroid (m³) and the points
/// `points` (the clipped triangles' vertices, local frame). Invalid (zero
/// normal) when the node holds no surface, its normals cancel, or it has
/// fewer than 3 points. O(points).
SurfacePatch fitSurfacePatch(const Vec3& areaVector, double area, const Vec3& areaMoment,
                             std::span<const Vec3> points);

}  // namespace dm::detail
