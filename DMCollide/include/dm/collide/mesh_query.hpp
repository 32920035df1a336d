// dm/collide/mesh_query.hpp — queries on triangle meshes through their
// MeshBvh: mesh–mesh boolean, contacts and distance; point–mesh closest point
// (signed for closed meshes, for haptics); raycast; sphere and capsule
// against a mesh.
//
// Frames: each mesh is given as (MeshBvh, pose) with pose mapping the mesh's
// local frame to the world; query inputs (points, rays, spheres, capsules)
// and all results are in world coordinates, metres. Mesh–mesh queries map
// B's triangles into A's frame with `poseA.inverse(Eigen::Isometry) * poseB`;
// the triangle tests are exact on those mapped coordinates (so booleans
// equal brute force over all triangle pairs done the same way), and the
// boxes are widened by a few ulps so that rounding never prunes a touching
// pair.
//
// Traversal is iterative with fixed stacks sized from MeshBvh::kMaxDepth;
// queries never allocate except meshMeshContacts(), which appends to the
// caller's vector (reuse it to keep its capacity). All functions are
// thread-safe on shared trees. Cost: O(log n) for well-separated or
// point-like queries, up to O(n·m) triangle pairs for deeply interpenetrating
// meshes (contacts) — the BVH prunes, it cannot change the output size.
//
// @code
//   auto a = dm::MeshBvh::build(meshA), b = dm::MeshBvh::build(meshB);
//   bool hit = dm::meshMeshIntersect(*a, poseA, *b, poseB);
//   dm::MeshDistance d = dm::meshMeshDistance(*a, poseA, *b, poseB);
// @endcode
#pragma once

#include <dm/collide/bvh.hpp>
#include <dm/core/types.hpp>

#include <cstddef>
#include <cstdint>
#include <limits>
#include <vector>

namespace dm {

/// Triangle index meaning "none" in query results.
inline constexpr std::uint32_t kNoTriangle = 0xffffffffu;

/// True when some triangle of A and some triangle of B intersect (closed
/// triangles, touching counts; exact on the mapped coordinates, see the
/// file comment). Stops at the first pair. No allocation.
/// @code
///   if (dm::meshMeshIntersect(tool, toolPose, organ, organPose)) alarm();
/// @endcode
bool meshMeshIntersect(const MeshBvh& a, const Isometry3& poseA, const MeshBvh& b,
                       const Isometry3& poseB) noexcept;

/// One intersecting triangle pair of meshMeshContacts().
struct MeshContact {
  Vec3 position = Vec3::Zero();  ///< world, m: middle of the intersection set of the two triangles
  /// World, unit: direction in which B moves to separate from A (the face
  /// normal of the pair's axis of least overlap, see depth).
  Vec3 normal = Vec3::UnitZ();
  /// m, >= 0: estimated penetration of the pair: the smaller overlap of the
  /// two triangles along the two face normals (A's normal, or B's reversed),
  /// i.e. the triangle–triangle separating-axis overlap restricted to the
  /// face axes — an upper bound of the pair's own penetration depth.
  /// Interpenetrating closed meshes need a volume-based depth on top.
  double depth = 0.0;
  Vec3 segment[2] = {Vec3::Zero(),
                     Vec3::Zero()};       ///< world: ends of the intersection segment (equal for a point)
  std::uint32_t triangleA = kNoTriangle;  ///< mesh triangle index in A
  std::uint32_t triangleB = kNoTriangle;  ///< mesh triangle index in B
};

/// Clears `contacts` (keeping its capacity) and appends one MeshContact per
/// intersecting triangle pair, at most `maxContacts`; returns the count.
/// Allocates only when `contacts` must grow.
/// @code
///   std::vector<dm::MeshContact> contacts;  // reused every step
///   dm::meshMeshContacts(a, poseA, b, poseB, contacts, 64);
///   for (const auto& c : contacts) applyImpulse(c.position, c.normal, c.depth);
/// @endcode
std::size_t meshMeshContacts(const MeshBvh& a, const Isometry3& poseA, const MeshBvh& b,
                             const Isometry3& poseB, std::vector<MeshContact>& contacts,
                             std::size_t maxContacts = std::numeric_limits<std::size_t>::max());

/// Result of a distance query: pointA on the first object, pointB on the
/// second (world, m); triangles are mesh triangle indices (kNoTriangle for
/// a non-mesh object or when nothing was found).
struct MeshDistance {
  double distance = std::numeric_limits<double>::infinity();  ///< m; 0 when intersecting
  Vec3 pointA = Vec3::Zero();
  Vec3 pointB = Vec3::Zero();
  std::uint32_t triangleA = kNoTriangle;
  std::uint32_t triangleB = kNoTriangle;
};

/// Minimum distance between the meshes with closest points (0 and a common
/// point when they intersect, found first by the boolean traversal). Then a
/// depth-first BVH–BVH traversal, nearer box pair first, pruned by the best
/// distance so far (the nodes' oriented boxes, MeshBvh::obb(), bounded by
/// their 15 separating axes and the centre line, two sibling boxes per test
/// in SIMD lanes; face-plane bounds per triangle pair); pairs farther than
/// `maxDistance` are not searched (result distance +inf, kNoTriangle, when
/// nothing is within it). No allocation.
/// @code
///   dm::MeshDistance d = dm::meshMeshDistance(a, poseA, b, poseB);
///   if (d.distance < 1e-3) slowDown(d.pointA, d.pointB);
/// @endcode
MeshDistance meshMeshDistance(const MeshBvh& a, const Isometry3& poseA, const MeshBvh& b,
                              const Isometry3& poseB,
                              double maxDistance = std::numeric_limits<double>::infinity()) noexcept;

/// Closest point of a mesh to a query point.
struct MeshPointQuery {
  /// m. Unsigned for open meshes; for closed meshes (MeshBvh::isClosed())
  /// negative inside, by the angle-weighted pseudonormal of the closest
  /// feature (Bærentzen & Aanæs 2005). +inf when nothing within maxDistance.
  double distance = std::numeric_limits<double>::infinity();
  Vec3 point = Vec3::Zero();  ///< world, m: closest point on the mesh
  /// World, unit: pseudonormal of the closest feature (closed meshes) or the
  /// face normal of the closest triangle (open meshes; zero if degenerate).
  Vec3 normal = Vec3::Zero();
  Vec3 barycentric = Vec3::Zero();       ///< of `point` in the triangle's corners
  std::uint32_t triangle = kNoTriangle;  ///< mesh triangle index
};

/// Closest point on the mesh surface to `point` (world), searching only
/// within `maxDistance` (m). O(log n) typical. No allocation.
/// @code
///   dm::MeshPointQuery q = dm::closestPointOnMesh(organ, organPose, probeTip);
///   if (q.distance < 0) force = -stiffness * q.distance * q.normal;  // inside
/// @endcode
MeshPointQuery closestPointOnMesh(const MeshBvh& bvh, const Isometry3& pose, const Vec3& point,
                                  double maxDistance = std::numeric_limits<double>::infinity()) noexcept;

/// First hit of a ray with a mesh.
struct MeshRayHit {
  double t = 0.0;                        ///< hit = origin + t · direction
  Vec3 point = Vec3::Zero();             ///< world, m
  Vec3 barycentric = Vec3::Zero();       ///< in the triangle's corners (u, v, w)
  std::uint32_t triangle = kNoTriangle;  ///< mesh triangle index
};

/// First intersection of the ray origin + t · direction, t in [0, tMax],
/// with the mesh (watertight ray–triangle test, both faces hit). Returns
/// false on a miss (hit untouched) or a zero/non-finite direction. No
/// allocation.
/// @code
///   dm::MeshRayHit h;
///   if (dm::raycastMesh(skin, skinPose, eye, dir, 1.0, h)) cursor = h.point;
/// @endcode
bool raycastMesh(const MeshBvh& bvh, const Isometry3& pose, const Vec3& origin, const Vec3& direction,
                 double tMax, MeshRayHit& hit) noexcept;

/// True when the closed ball (center world, radius m) touches the mesh
/// surface. Stops at the first triangle. No allocation.
bool sphereMeshIntersect(const MeshBvh& bvh, const Isometry3& pose, const Vec3& center,
                         double radius) noexcept;

/// Distance from the sphere's surface to the mesh surface: (surface
/// distance of the center) − radius, negative when the sphere crosses the
/// surface; pointA on the sphere toward the mesh, pointB on the mesh,
/// triangleB the mesh triangle. No allocation.
MeshDistance sphereMeshDistance(const MeshBvh& bvh, const Isometry3& pose, const Vec3& center,
                                double radius) noexcept;

/// True when the capsule (segment [p0, p1] world, radius m) touches the
/// mesh surface. Stops at the first triangle. No allocation.
bool capsuleMeshIntersect(const MeshBvh& bvh, const Isometry3& pose, const Vec3& p0, const Vec3& p1,
                          double radius) noexcept;

/// Distance from the capsule's surface to the mesh surface (segment–mesh
/// distance − radius, negative when crossing); pointA on the capsule
/// surface, pointB on the mesh. No allocation.
/// @code
///   dm::MeshDistance d = dm::capsuleMeshDistance(vessel, pose, tip0, tip1, 0.001);
///   if (d.distance < 0) report(d.pointB);
/// @endcode
MeshDistance capsuleMeshDistance(const MeshBvh& bvh, const Isometry3& pose, const Vec3& p0, const Vec3& p1,
                                 double radius) noexcept;

}  // namespace dm
