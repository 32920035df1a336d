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

/// One facet of a node's surface: a mesh triangle clipped to one of its
/// cells (area vector Σ area·n, area, area moment, its polygon's points).
struct Facet {
  Vec3 areaVector = Vec3::Zero();
  double area = 0.0;
  Vec3 areaMoment = Vec3::Zero();
  std::span<const Vec3> points;
};

/// p.crease from the node's facets: grouped by normal (within 20° of a
/// group's mean, largest first), 2 or 3 groups make the crease's planes
/// (area-weighted normal through the area centroid), convex when every
/// group's centroid lies behind every other plane, concave when in front;
/// none for 1 group, more than 3, or a mixed arrangement. A patch whose
/// normals cancel (a thin wall) gets its origin from the facets.
/// O(facets · 3 + points).
void fitCrease(SurfacePatch& p, std::span<const Facet> facets);

}  // namespace dm::detail
