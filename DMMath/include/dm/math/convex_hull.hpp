// dm/math/convex_hull.hpp — 3-D convex hulls of point sets (Quickhull).
//
// Quickhull (Barber, Dobkin & Huhdanpaa 1996) with the face merging of
// J. Lloyd's QuickHull3D: facets that are coplanar or non-convex within the
// tolerance are merged into convex polygons while the hull grows, which keeps
// every visibility test well conditioned on degenerate input (grids, points on
// the faces of a box, duplicates). The polygons are triangulated at the end
// without adding vertices. Used for collision proxies of tools and organs, for
// their mass properties and for rendering bounds.
#pragma once

#include <dm/core/mesh.hpp>
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>

#include <span>

namespace dm {

/// Tuning of convexHull().
struct ConvexHullOptions {
  /// Distance tolerance relative to the size of the point cloud, s = sum of
  /// the bounding box's half extents (m). Points closer than
  /// relativeTolerance · s to the hull count as on it and do not become
  /// vertices; adjacent facets that are coplanar within it are merged. 0 (the
  /// default) uses the rounding level of the coordinates and plane tests,
  /// 3·DBL_EPSILON·Σ max|coordinate| over the axes (just 3·DBL_EPSILON·s for
  /// a cloud centred at the origin); smaller values are raised to it. Larger
  /// values (e.g. 1e-4) give simpler hulls: the vertices chosen with the
  /// coarse tolerance are hulled again at the rounding level, so the result
  /// stays convex to rounding while dropped points lie within about three
  /// tolerances of it. Must be finite, >= 0 and < 0.1.
  double relativeTolerance = 0.0;
};

/// Convex hull of `points` (m) as a closed, consistently oriented triangle
/// mesh: triangles counter-clockwise seen from outside, V − E + F = 2, no
/// degenerate or duplicate triangles. `positions` are the input points that
/// are vertices of the hull (in input order, duplicates once); points on the
/// hull's faces or edges within the tolerance are not vertices. Coplanar
/// facets are merged and re-triangulated, so a cube of any point grid gives 8
/// vertices and 12 triangles. Every input point lies inside or within a few
/// tolerances of the hull. O(n log n) expected time for typical inputs
/// (O(n h) worst case for h hull vertices), O(n) memory.
/// Degenerate input is an error, not a flat hull: fails with InvalidArgument
/// when there are no points, a point is NaN or infinite (the message names its
/// index), there are more than 2³² − 2 points, the options are out of range,
/// or the points span fewer than 3 dimensions (the message says "all points
/// coincide (0-dimensional)", "collinear (1-dimensional)" or "coplanar
/// (2-dimensional)"). Fails with Internal if the construction lost
/// consistency (a bug; please report with the points).
/// @code
///   std::vector<dm::Vec3> cloud = scanTool();
///   auto hull = dm::convexHull(cloud);
///   if (!hull) return hull.error();  // e.g. a flat scan
/// @endcode
Result<Mesh> convexHull(std::span<const Vec3> points, const ConvexHullOptions& options = {});

}  // namespace dm
