// dm/math/geometry.hpp — exact point/triangle primitives shared by
// voxelization, simplification error measures, collision detection and
// inside tests (a closed mesh's winding number at p is the sum of its
// triangles' solid angles over 4π: dm::windingNumber in mesh_topology.hpp).
//
// @code
//   dm::TriangleClosest c = dm::closestPointOnTriangle(p, a, b, c3);
//   double d = std::sqrt(c.distanceSq);     // m
// @endcode
#pragma once

#include <dm/core/types.hpp>

#include <cstdint>

namespace dm {

/// Which feature of a triangle a closest point lies on.
enum class TriangleFeature : std::uint8_t { VertexA, VertexB, VertexC, EdgeAB, EdgeBC, EdgeCA, Face };

/// Result of closestPointOnTriangle(): the point, its squared distance and
/// its barycentric coordinates (u, v, w) with point = u·a + v·b + w·c.
struct TriangleClosest {
  Vec3 point;
  double distanceSq = 0.0;
  Vec3 barycentric;
  TriangleFeature feature = TriangleFeature::Face;
};

/// Barycentric coordinates (u, v, w) of p's orthogonal projection on the
/// plane of triangle (a, b, c), not clamped to the triangle. Solved from the
/// two edges at the largest angle (opposite the longest edge), whose Gram
/// matrix is the best conditioned of the three: from another vertex of a
/// sliver (two 0.8 m edges 1e-6 m apart) its condition number is ~1e12 and
/// the point missed the projection by 1e-4 m. The triangle must have a
/// nonzero area.
Vec3 planeBarycentric(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) noexcept;

/// The point of triangle (a, b, c) closest to p, by Voronoi-region
/// classification (Ericson, Real-Time Collision Detection, 5.1.5). Exact for
/// degenerate triangles too (a segment or a point): the result then lies on
/// the closest edge or vertex. O(1), no allocation, never fails.
TriangleClosest closestPointOnTriangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) noexcept;

/// The point of segment [a, b] closest to p, and its parameter t in [0, 1].
/// A zero-length segment gives a with t = 0.
Vec3 closestPointOnSegment(const Vec3& p, const Vec3& a, const Vec3& b, double* t = nullptr) noexcept;

/// The solid angle (steradians, signed) that triangle (a, b, c) subtends
/// at p: positive when p sees its counter-clockwise side (Van Oosterom and
/// Strackee 1983). 0 when p lies on the triangle's plane.
double solidAngle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) noexcept;

}  // namespace dm
