// dm/collide/query.hpp — narrow-phase queries between two posed shapes and
// the collider table that dispatches them.
//
// Every query takes two shapes with their poses (local → world) and answers
// in the world frame, metres. Dispatch goes through a ColliderTable indexed
// by (ShapeType, ShapeType): analytic colliders for the common primitive
// pairs (sphere, box, capsule, plane, triangle), GJK/EPA for any other pair of
// convex shapes (user shape types included), child-wise dispatch for
// compounds. A pair registered as (A, B) also serves (B, A): the shapes are
// swapped, normals flipped and points exchanged. Plugins add pairs at run time
// with ColliderTable::registerCollider() (or, from a shared library, through
// dm/collide/collider_plugin.hpp). Triangle meshes pair with every built-in
// convex shape (closed meshes count as solids there); sphere trees, point
// shells and voxel models register their own pairs (voxel models pair with
// point shells and every built-in convex shape: box, cylinder, ellipsoid,
// hull and triangle by surface sampling at the voxel size). Pairs without a
// collider (e.g. plane–mesh, plane–voxel model) report `supported = false`.
//
// @code
//   dm::Sphere ball(0.01);
//   dm::Box block(dm::Vec3(0.1, 0.1, 0.02));
//   dm::CollisionResult hit = dm::collide(ball, poseBall, block, poseBlock);
// @endcode
#pragma once

#include <dm/collide/gjk.hpp>
#include <dm/collide/shapes.hpp>
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>

#include <limits>
#include <optional>
#include <vector>

namespace dm {

/// One contact between shape A and shape B, world frame.
struct ContactPoint {
  Vec3 position = Vec3::Zero();  ///< m, midway between the two surfaces
  Vec3 normal = Vec3::UnitZ();   ///< unit, from A to B (B moves along it to separate)
  double depth = 0.0;            ///< penetration depth along normal, m (≥ 0)
};

/// What collide() computes.
struct CollisionRequest {
  bool contacts = true;  ///< false: only `colliding` is set (as intersect())
  int maxContacts = 4;   ///< upper bound on contacts returned (≥ 1; box–box gives up to 8)
};

/// Answer of collide(). Reuse one object across calls to keep the contact
/// vector's capacity (no allocation once it is large enough).
struct CollisionResult {
  bool colliding = false;
  std::vector<ContactPoint> contacts;
  bool supported = true;  ///< false: no collider is registered for the pair
  /// Not colliding: a lower bound on the distance between the shapes that the
  /// test found on its way (m; box–box: the gap along the separating axis),
  /// so a caller can skip a distance() query it would only compare with a
  /// smaller threshold. 0 when unknown or colliding.
  double separation = 0.0;
  void clear() noexcept {
    colliding = false;
    contacts.clear();
    supported = true;
    separation = 0.0;
  }
};

/// Answer of distance(), world frame.
struct DistanceResult {
  /// Signed distance, m: > 0 separated (exact distance), < 0 overlapping by
  /// −distance (penetration depth). NaN when the pair is unsupported.
  double distance = std::numeric_limits<double>::quiet_NaN();
  Vec3 pointA = Vec3::Zero();  ///< closest (deepest when overlapping) point on A, m
  Vec3 pointB = Vec3::Zero();  ///< closest (deepest when overlapping) point on B, m
  bool supported = true;       ///< false: no collider is registered for the pair
};

/// Ray origin + t·direction, 0 ≤ t ≤ maxDistance (m); `direction` unit.
struct Ray {
  Vec3 origin = Vec3::Zero();
  Vec3 direction = Vec3::UnitX();
  double maxDistance = std::numeric_limits<double>::infinity();
};

/// First hit of a ray: parameter t (m along the unit direction), point and
/// outward unit surface normal, world frame. A ray starting inside a solid
/// hits at t = 0 with normal −direction.
struct RayHit {
  double t = 0.0;
  Vec3 point = Vec3::Zero();
  Vec3 normal = Vec3::UnitZ();
};

/// Per-pair data kept by the caller between steps (warm starts).
struct PairCache {
  GjkCache gjk;
};

/// Collider function types. They receive the pair in registration order
/// (shape A of the registered type a). `cache` may be null. Real-time safe
/// implementations must not allocate, lock or throw (contacts: only append
/// to `out.contacts`, whose capacity the caller owns).
using IntersectFn = bool (*)(const Shape& a, const Isometry3& poseA, const Shape& b, const Isometry3& poseB,
                             PairCache* cache);
using ContactsFn = void (*)(const Shape& a, const Isometry3& poseA, const Shape& b, const Isometry3& poseB,
                            const CollisionRequest& request, CollisionResult& out, PairCache* cache);
using DistanceFn = DistanceResult (*)(const Shape& a, const Isometry3& poseA, const Shape& b,
                                      const Isometry3& poseB, PairCache* cache);

/// The three queries of one shape pair; plain function pointers so that they
/// can come from a plugin's C entry point.
struct Collider {
  IntersectFn intersect = nullptr;
  ContactsFn contacts = nullptr;
  DistanceFn distance = nullptr;
  bool complete() const noexcept { return intersect && contacts && distance; }
};

/// Ray query of one shape type, in the shape's local frame
/// (ray already transformed; return the hit in the local frame).
using RaycastFn = std::optional<RayHit> (*)(const Shape& shape, const Ray& localRay);

/// Registry of colliders by (ShapeType, ShapeType) and raycasters by type.
/// Lookups are lock-free array reads; registration is for start-up and
/// plugin loading and must not run concurrently with queries on the same
/// table.
class ColliderTable {
 public:
  /// A table holding the built-in colliders.
  ColliderTable();

  /// The process-wide table used by intersect(), collide(), distance() and
  /// raycast().
  static ColliderTable& global() noexcept;

  /// Registers (or replaces) the collider for (a, b); it also serves (b, a)
  /// unless a collider is registered for (b, a) itself. Fails with
  /// InvalidArgument for an id ≥ kMaxShapeTypes or a collider with a null
  /// function. O(1).
  /// @code
  ///   dm::Status s = dm::ColliderTable::global().registerCollider(
  ///       dm::ShapeType::TriangleMesh, dm::ShapeType::Sphere, {meshSphereHit, meshSphereContacts,
  ///       meshSphereDist});
  /// @endcode
  Status registerCollider(ShapeType a, ShapeType b, const Collider& collider);

  /// Registers the raycaster of shape type `t`. Fails like registerCollider.
  Status registerRaycaster(ShapeType t, RaycastFn fn);

  /// The collider serving shapes (a, b) and whether it takes them swapped;
  /// null when the pair is unsupported. Falls back, when no pair entry
  /// exists, to the compound dispatcher, to plane–convex and to GJK/EPA (both
  /// convex, user types included). O(1).
  const Collider* find(const Shape& a, const Shape& b, bool& swapped) const noexcept;
  /// The raycaster registered for type t, or null.
  RaycastFn findRaycaster(ShapeType t) const noexcept;

  /// Ok when (a, b) has a collider; else Unsupported with
  /// "no collider for (triangle-mesh, sphere) yet". For validating a pair
  /// once, outside the hot path.
  Status check(const Shape& a, const Shape& b) const;

 private:
  struct Entry {
    Collider collider;
    bool registered = false;
    bool swapped = false;
  };
  Entry entries_[kMaxShapeTypes][kMaxShapeTypes];
  RaycastFn raycasters_[kMaxShapeTypes] = {};
};

/// True if the shapes overlap or touch. No allocation. O(1) for analytic
/// pairs, O(k·support) for GJK pairs; unsupported pairs return false (check
/// them once with ColliderTable::check()).
/// @code
///   dm::PairCache cache;   // one per pair, kept between steps
///   if (dm::intersect(tool, poseTool, organ, poseOrgan, &cache)) highlight();
/// @endcode
bool intersect(const Shape& a, const Isometry3& poseA, const Shape& b, const Isometry3& poseB,
               PairCache* cache = nullptr) noexcept;

/// Contacts between the shapes into `out` (cleared first; reuse it to avoid
/// allocation). Box–box gives a clipped manifold of up to 8 points (reduced to
/// request.maxContacts), plane–box up to 4, compounds one set per child pair;
/// other pairs one deepest contact.
/// @code
///   dm::CollisionResult res;
///   dm::collide(a, poseA, b, poseB, {}, res);
///   for (const auto& c : res.contacts) push(c.position, c.normal, c.depth);
/// @endcode
void collide(const Shape& a, const Isometry3& poseA, const Shape& b, const Isometry3& poseB,
             const CollisionRequest& request, CollisionResult& out, PairCache* cache = nullptr);

/// As above, returning a fresh result.
CollisionResult collide(const Shape& a, const Isometry3& poseA, const Shape& b, const Isometry3& poseB,
                        const CollisionRequest& request = {}, PairCache* cache = nullptr);

/// Signed distance and closest points (see DistanceResult). No allocation.
/// @code
///   dm::DistanceResult d = dm::distance(a, poseA, b, poseB);
///   if (d.supported && d.distance < 0.002) slowDown();
/// @endcode
DistanceResult distance(const Shape& a, const Isometry3& poseA, const Shape& b, const Isometry3& poseB,
                        PairCache* cache = nullptr) noexcept;

/// First hit of `ray` (world frame) on the shape at `pose`, or nullopt for a
/// miss, a hit beyond ray.maxDistance or a shape type with no raycaster.
/// Analytic for sphere, box, cylinder, plane; conservative advancement on
/// the GJK distance for the other convex shapes (t to ~1e-12 relative on flat
/// faces, ~1e-8 on curved ones, where GJK converges linearly); compounds take
/// the nearest child hit.
/// @code
///   auto hit = dm::raycast(skull, poseSkull, {cameraPos, viewDir});
///   if (hit) cursor = hit->point;
/// @endcode
std::optional<RayHit> raycast(const Shape& shape, const Isometry3& pose, const Ray& ray) noexcept;

}  // namespace dm
