// dm/collide/triangle.hpp — exact triangle primitives for mesh collision:
// triangle–triangle overlap (boolean), intersection segment (contacts),
// triangle–triangle and segment–triangle distance with closest points,
// segment–segment closest points and watertight ray–triangle.
//
// Booleans are exact: they only use the signs of 3×3 orientation
// determinants, computed in double with Shewchuk's static error bound and,
// when that cannot decide, exactly in rational arithmetic. Touching counts as
// intersecting (closed triangles). Coplanar input takes an exact 2-D path;
// degenerate triangles (collinear corners: a segment, or a point) are tested
// as the union of their edges. Points and distances are double precision.
//
// @code
//   bool hit = dm::trianglesIntersect(a0, a1, a2, b0, b1, b2);
//   dm::TriangleDistance d = dm::triangleDistance(a0, a1, a2, b0, b1, b2);
//   if (d.distance < tolerance) useContact(d.pointA, d.pointB);
// @endcode
#pragma once

#include <dm/core/types.hpp>

#include <array>

namespace dm {

/// Sign (−1, 0, +1) of (b − a) · ((c − a) × (d − a)), exactly: +1 when d
/// lies on the side of plane (a, b, c) that the normal (b − a) × (c − a)
/// points to. O(1); the exact fallback (rationals, microseconds) runs only
/// when the four points are (nearly) coplanar.
int orient3d(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& d) noexcept;

/// True when the closed triangles (a0, a1, a2) and (b0, b1, b2) share at
/// least one point (touching included), exactly. Guigue–Devillers with exact
/// orientation signs; exact 2-D path for coplanar pairs; degenerate
/// triangles as segments/points. O(1), no allocation.
/// @code
///   if (dm::trianglesIntersect(a[0], a[1], a[2], b[0], b[1], b[2])) ++overlaps;
/// @endcode
bool trianglesIntersect(const Vec3& a0, const Vec3& a1, const Vec3& a2, const Vec3& b0, const Vec3& b1,
                        const Vec3& b2) noexcept;

/// True when the closed segment [p, q] and the closed triangle (a, b, c)
/// share a point, exactly (degenerate segment and triangle included).
bool segmentTriangleIntersect(const Vec3& p, const Vec3& q, const Vec3& a, const Vec3& b,
                              const Vec3& c) noexcept;

/// Where two triangles intersect, for contact generation.
struct TriangleIntersection {
  bool intersects = false;  ///< exact, as trianglesIntersect()
  bool coplanar = false;    ///< both triangles in one plane (exactly)
  /// Number of valid entries in `points` (0 when !intersects).
  /// Non-coplanar: 2, the endpoints of the intersection segment (equal when
  /// the triangles touch at one point). Coplanar: 1..6 vertices of the
  /// convex overlap polygon, in order. A degenerate triangle: 1 point.
  int count = 0;
  std::array<Vec3, 6> points{};  ///< m, same frame as the input
};

/// The intersection set of two triangles (see TriangleIntersection). O(1).
/// @code
///   dm::TriangleIntersection x = dm::triangleIntersection(a0, a1, a2, b0, b1, b2);
///   for (int i = 0; i < x.count; ++i) addContact(x.points[i]);
/// @endcode
TriangleIntersection triangleIntersection(const Vec3& a0, const Vec3& a1, const Vec3& a2, const Vec3& b0,
                                          const Vec3& b1, const Vec3& b2) noexcept;

/// Distance between two closed sets and a pair of points realising it.
struct TriangleDistance {
  double distance = 0.0;       ///< m; 0 when the sets intersect
  Vec3 pointA = Vec3::Zero();  ///< on the first set
  Vec3 pointB = Vec3::Zero();  ///< on the second set (== pointA when intersecting)
};

/// Distance between triangles (a0, a1, a2) and (b0, b1, b2) with closest
/// points: 0 (and a common point) when they intersect exactly; otherwise the
/// minimum of the 6 vertex–triangle pairs (dm::closestPointOnTriangle) and
/// the 9 edge–edge pairs. Degenerate triangles work. O(1).
/// @code
///   dm::TriangleDistance d = dm::triangleDistance(a0, a1, a2, b0, b1, b2);
///   Vec3 normal = (d.pointB - d.pointA).normalized();  // when d.distance > 0
/// @endcode
TriangleDistance triangleDistance(const Vec3& a0, const Vec3& a1, const Vec3& a2, const Vec3& b0,
                                  const Vec3& b1, const Vec3& b2) noexcept;

/// triangleDistance() for triangles known not to intersect (e.g. after a
/// negative trianglesIntersect()): the minimum over the 6 vertex–triangle
/// and 9 edge–edge pairs, without the intersection test. For intersecting
/// triangles the result is not 0 but the smallest feature-pair distance. O(1).
TriangleDistance separatedTriangleDistance(const Vec3& a0, const Vec3& a1, const Vec3& a2, const Vec3& b0,
                                           const Vec3& b1, const Vec3& b2) noexcept;

/// Distance between segment [p, q] (pointA) and triangle (a, b, c) (pointB),
/// as triangleDistance(). O(1).
TriangleDistance segmentTriangleDistance(const Vec3& p, const Vec3& q, const Vec3& a, const Vec3& b,
                                         const Vec3& c) noexcept;

/// Closest points of segments [p0, p1] and [q0, q1]: pointA = p0 + s (p1 − p0),
/// pointB = q0 + t (q1 − q0), s, t in [0, 1]. Parallel and zero-length
/// segments give one of the closest pairs. O(1).
struct SegmentClosest {
  Vec3 pointA = Vec3::Zero(), pointB = Vec3::Zero();
  double s = 0.0, t = 0.0;
  double distanceSq = 0.0;  ///< m²
};
SegmentClosest closestPointsSegmentSegment(const Vec3& p0, const Vec3& p1, const Vec3& q0,
                                           const Vec3& q1) noexcept;

/// A ray–triangle hit: origin + t · direction = u a + v b + w c.
struct RayTriangleHit {
  double t = 0.0;                   ///< ray parameter (m when direction is unit)
  Vec3 barycentric = Vec3::Zero();  ///< (u, v, w), sum 1, all >= 0
};

/// Watertight ray–triangle test (Woop, Benthin, Wald 2013): a ray through a
/// shared edge or vertex of a closed mesh hits at least one of its triangles.
/// Hits with t in [tMin, tMax] count; edge-on and degenerate triangles miss.
/// `direction` need not be unit but must be non-zero. Returns false on a
/// miss (hit untouched). O(1).
/// @code
///   dm::RayTriangleHit h;
///   if (dm::rayTriangle(o, dir, a, b, c, 0.0, 1.0, h)) Vec3 p = o + h.t * dir;
/// @endcode
bool rayTriangle(const Vec3& origin, const Vec3& direction, const Vec3& a, const Vec3& b, const Vec3& c,
                 double tMin, double tMax, RayTriangleHit& hit) noexcept;

}  // namespace dm
