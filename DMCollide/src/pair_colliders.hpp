// Private: built-in pair colliders shared by query.cpp and the pair_*.cpp
// files. Not installed.
#pragma once

#include <dm/collide/query.hpp>
#include <dm/collide/voxel_model.hpp>

#include <cmath>

namespace dm::detail {

/// Signed closest/deepest-point answer of an analytic pair, world frame:
/// distance < 0 means penetration by −distance; normal is unit, A → B.
struct SignedContact {
  double distance = 0.0;
  Vec3 pointA = Vec3::Zero();
  Vec3 pointB = Vec3::Zero();
  Vec3 normal = Vec3::UnitZ();
};

inline DistanceResult toDistanceResult(const SignedContact& s) noexcept {
  DistanceResult d;
  d.distance = s.distance;
  d.pointA = s.pointA;
  d.pointB = s.pointB;
  return d;
}

/// Appends one contact (midway between the two surfaces) when the shapes
/// touch or overlap; sets out.colliding.
inline void appendContact(const SignedContact& s, const CollisionRequest& request, CollisionResult& out) {
  if (s.distance > 0) return;
  out.colliding = true;
  if (request.contacts && static_cast<int>(out.contacts.size()) < request.maxContacts)
    out.contacts.push_back({0.5 * (s.pointA + s.pointB), s.normal, -s.distance});
}

/// The three queries of a pair from one analytic signed-contact function.
template <SignedContact (*F)(const Shape&, const Isometry3&, const Shape&, const Isometry3&)>
Collider analyticCollider() {
  Collider c;
  c.intersect = [](const Shape& a, const Isometry3& pa, const Shape& b, const Isometry3& pb, PairCache*) {
    return F(a, pa, b, pb).distance <= 0;
  };
  c.contacts = [](const Shape& a, const Isometry3& pa, const Shape& b, const Isometry3& pb,
                  const CollisionRequest& req, CollisionResult& out,
                  PairCache*) { appendContact(F(a, pa, b, pb), req, out); };
  c.distance = [](const Shape& a, const Isometry3& pa, const Shape& b, const Isometry3& pb, PairCache*) {
    return toDistanceResult(F(a, pa, b, pb));
  };
  return c;
}

/// Sphere–sphere style answer for two cores reduced to points cA, cB with
/// radii rA, rB; `fallbackNormal` is used when the points coincide.
SignedContact pointPair(const Vec3& cA, double rA, const Vec3& cB, double rB,
                        const Vec3& fallbackNormal) noexcept;

/// Keeps at most `maxContacts` of the contacts from index `first` on: the
/// deepest, then repeatedly the one farthest from those kept.
void reduceContacts(CollisionResult& out, std::size_t first, int maxContacts) noexcept;

/// The VoxelModel of a shape of type VoxelModel.
inline const VoxelModel& modelOf(const Shape& s) noexcept { return static_cast<const VoxelModel&>(s); }

/// Unit normal from shape A to the model B at a point whose model gradient
/// (local frame of B) is g: the model separates by moving along −∇d.
/// `fallback` (world, unit) serves where the gradient vanishes (deep inside a
/// band-clamped field).
inline Vec3 normalFromGradient(const Isometry3& poseB, const Vec3& g, const Vec3& fallback) noexcept {
  const double n = g.norm();
  if (!(n > 1e-12) || !std::isfinite(n)) return fallback;
  return poseB.linear() * (-g / n);
}

/// Registers sphere–sphere, sphere–box, sphere–capsule, capsule–capsule,
/// triangle–sphere (pair_primitives.cpp) and box–box (pair_box_box.cpp).
void registerPrimitiveColliders(ColliderTable& table);
void registerBoxBoxCollider(ColliderTable& table);
/// Registers mesh–mesh, mesh–sphere, mesh–capsule and the mesh raycaster
/// (pair_mesh.cpp).
void registerMeshColliders(ColliderTable& table);
void registerMeshConvexColliders(ColliderTable& table);  // other convex shapes (pair_mesh_convex.cpp)
void registerSphereTreeColliders(ColliderTable& table);  // sphere trees (pair_sphere_tree.cpp)
void registerVoxelColliders(ColliderTable& table);  // point shells, voxel models (pair_voxel.cpp)
void registerVoxelConvexColliders(ColliderTable& table);  // box, hull, ... – voxel (pair_voxel_convex.cpp)

}  // namespace dm::detail
