// Internal: the fit of a sphere-tree node's SurfacePatch (surface_patch.cpp),
// used by the mesh sphere-tree builders (sphere_tree.cpp).
#pragma once

#include <dm/collide/sphere_tree.hpp>

#include <span>

namespace dm::detail {

/// The patch of a node whose surface has the area vector Σ area·n (m²), the
/// area Σ area (m²), the area moment Σ area·centroid (m³) and the points
/// `own` (the clipped triangles' vertices, local frame): its frame, width,
/// raise and deviation. The quadric is fitted over `fit` (the node's smooth
/// neighbourhood; `own` when it has fewer than 6 points), each point
/// weighted by exp(−ρ²/fitScale²) at tangential distance ρ from the origin
/// (a moving least-squares fit: local, yet fixed by the points around it;
/// fitScale 0 weighs all alike). Invalid (zero
/// normal) when the node holds no surface, its normals cancel, or it has
/// fewer than 3 points. O(own + fit).
SurfacePatch fitSurfacePatch(const Vec3& areaVector, double area, const Vec3& areaMoment,
                             std::span<const Vec3> own, std::span<const Vec3> fit, double fitScale);

}  // namespace dm::detail
