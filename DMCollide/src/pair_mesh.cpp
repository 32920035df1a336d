// Triangle-mesh pairs of the collider table: mesh–mesh, mesh–sphere,
// mesh–capsule and the mesh raycaster, on the MeshBvh queries of
// mesh_query.hpp. A TriangleMesh without a BVH has no collider (check()
// reports it); TriangleMesh::create() builds one.
#include <dm/collide/bvh.hpp>
#include <dm/collide/mesh_query.hpp>
#include <dm/collide/shapes.hpp>
#include <dm/math/geometry.hpp>

#include <vector>

#include "pair_colliders.hpp"

namespace dm {

Result<std::shared_ptr<const TriangleMesh>> TriangleMesh::create(std::shared_ptr<const Mesh> mesh) {
  if (!mesh) return fail(ErrorCode::InvalidArgument, "null mesh", "dm::TriangleMesh::create", "pass a mesh");
  auto bvh = MeshBvh::build(*mesh);
  if (!bvh) return bvh.error();
  auto shared = std::make_shared<const MeshBvh>(std::move(*bvh));
  return std::make_shared<const TriangleMesh>(std::move(mesh), std::move(shared));
}

namespace detail {
namespace {

const MeshBvh* bvhOf(const Shape& s) { return static_cast<const TriangleMesh&>(s).bvh().get(); }

DistanceResult toResult(const MeshDistance& m) {
  DistanceResult d;
  d.distance = m.distance;
  d.pointA = m.pointA;
  d.pointB = m.pointB;
  return d;
}

DistanceResult unsupportedDistance() {
  DistanceResult d;
  d.distance = std::numeric_limits<double>::quiet_NaN();
  d.supported = false;
  return d;
}

// --- mesh–mesh -----------------------------------------------------------

bool meshMeshHit(const Shape& a, const Isometry3& pa, const Shape& b, const Isometry3& pb, PairCache*) {
  const MeshBvh *ba = bvhOf(a), *bb = bvhOf(b);
  return ba && bb && meshMeshIntersect(*ba, pa, *bb, pb);
}

void meshMeshContactsFn(const Shape& a, const Isometry3& pa, const Shape& b, const Isometry3& pb,
                        const CollisionRequest& req, CollisionResult& out, PairCache*) {
  const MeshBvh *ba = bvhOf(a), *bb = bvhOf(b);
  if (!ba || !bb) {
    out.supported = false;
    return;
  }
  if (!req.contacts) {
    out.colliding = out.colliding || meshMeshIntersect(*ba, pa, *bb, pb);
    return;
  }
  // Reused per thread so steady-state contact queries do not allocate.
  thread_local std::vector<MeshContact> pairs;
  if (meshMeshContacts(*ba, pa, *bb, pb, pairs) == 0) return;
  out.colliding = true;
  const std::size_t first = out.contacts.size();
  for (const MeshContact& c : pairs) out.contacts.push_back({c.position, c.normal, c.depth});
  reduceContacts(out, first, req.maxContacts);
}

DistanceResult meshMeshDist(const Shape& a, const Isometry3& pa, const Shape& b, const Isometry3& pb,
                            PairCache*) {
  const MeshBvh *ba = bvhOf(a), *bb = bvhOf(b);
  if (!ba || !bb) return unsupportedDistance();
  return toResult(meshMeshDistance(*ba, pa, *bb, pb));
}

// --- mesh–sphere and mesh–capsule: the sphere/capsule is B ------------------

struct Core {
  Vec3 p0, p1;
  double radius;
};

Core coreOf(const Shape& s, const Isometry3& pose) {
  if (s.type() == ShapeType::Sphere) {
    const double r = static_cast<const Sphere&>(s).radius();
    return {pose.translation(), pose.translation(), r};
  }
  const auto& c = static_cast<const Capsule&>(s);
  const Vec3 axis = pose.linear().col(2) * c.halfLength();
  return {pose.translation() - axis, pose.translation() + axis, c.radius()};
}

MeshDistance roundMeshDistance(const MeshBvh& bvh, const Isometry3& pa, const Core& k) {
  return k.p0 == k.p1 ? sphereMeshDistance(bvh, pa, k.p0, k.radius)
                      : capsuleMeshDistance(bvh, pa, k.p0, k.p1, k.radius);
}

// A closed mesh is a solid (as for the other convex shapes, see
// pair_mesh_convex.cpp): a round shape touching no triangle but whose core
// lies inside is enclosed.
bool enclosedRound(const MeshBvh& bvh, const Isometry3& pa, const Core& k) noexcept {
  return bvh.isClosed() && closestPointOnMesh(bvh, pa, k.p0).distance < 0;
}

// Push-out of an enclosed round shape: along n from its nearest core point to
// the nearest surface point, far enough that its deepest point clears it.
// Mesh point first (A), round shape second (B), normal A→B.
SignedContact pushOutRound(const MeshDistance& d, const Core& k) noexcept {
  const Vec3 onMesh = d.pointB;
  const Vec3 gap = onMesh - closestPointOnSegment(onMesh, k.p0, k.p1);
  const Vec3 n = gap.squaredNorm() > 0 ? Vec3(gap.normalized()) : Vec3::UnitZ();
  const Vec3 deepCore = n.dot(k.p1 - k.p0) < 0 ? k.p1 : k.p0;
  const Vec3 deep = deepCore - k.radius * n;
  SignedContact s;
  s.distance = -std::max(0.0, n.dot(onMesh - deep));
  s.pointA = onMesh;
  s.pointB = deep;
  s.normal = n;
  return s;
}

bool meshRoundHit(const Shape& a, const Isometry3& pa, const Shape& b, const Isometry3& pb, PairCache*) {
  const MeshBvh* bvh = bvhOf(a);
  if (!bvh) return false;
  const Core k = coreOf(b, pb);
  const bool touches = k.p0 == k.p1 ? sphereMeshIntersect(*bvh, pa, k.p0, k.radius)
                                    : capsuleMeshIntersect(*bvh, pa, k.p0, k.p1, k.radius);
  return touches || enclosedRound(*bvh, pa, k);
}

void meshRoundContacts(const Shape& a, const Isometry3& pa, const Shape& b, const Isometry3& pb,
                       const CollisionRequest& req, CollisionResult& out, PairCache*) {
  const MeshBvh* bvh = bvhOf(a);
  if (!bvh) {
    out.supported = false;
    return;
  }
  // The deepest point of the round shape against the mesh surface: pointA is
  // on the round shape (B here), pointB on the mesh (A here).
  const Core k = coreOf(b, pb);
  const MeshDistance d = roundMeshDistance(*bvh, pa, k);
  if (d.distance > 0 && enclosedRound(*bvh, pa, k)) {
    appendContact(pushOutRound(d, k), req, out);
    return;
  }
  if (!(d.distance <= 0)) return;
  SignedContact s;
  s.distance = d.distance;
  s.pointA = d.pointB;
  s.pointB = d.pointA;
  // A -> B: from the mesh point towards the nearest point of the core.
  const Vec3 dir = closestPointOnSegment(d.pointB, k.p0, k.p1) - d.pointB;
  s.normal = dir.squaredNorm() > 0 ? Vec3(dir.normalized()) : Vec3::UnitZ();
  appendContact(s, req, out);
}

DistanceResult meshRoundDist(const Shape& a, const Isometry3& pa, const Shape& b, const Isometry3& pb,
                             PairCache*) {
  const MeshBvh* bvh = bvhOf(a);
  if (!bvh) return unsupportedDistance();
  const Core k = coreOf(b, pb);
  const MeshDistance d = roundMeshDistance(*bvh, pa, k);
  if (d.distance > 0 && enclosedRound(*bvh, pa, k)) return toDistanceResult(pushOutRound(d, k));
  DistanceResult r;
  r.distance = d.distance;
  r.pointA = d.pointB;  // on the mesh (A)
  r.pointB = d.pointA;  // on the round shape (B)
  return r;
}

std::optional<RayHit> rayMesh(const Shape& s, const Ray& ray) {
  const MeshBvh* bvh = bvhOf(s);
  if (!bvh) return std::nullopt;
  MeshRayHit h;
  if (!raycastMesh(*bvh, Isometry3::Identity(), ray.origin, ray.direction, ray.maxDistance, h))
    return std::nullopt;
  RayHit out;
  out.t = h.t;
  out.point = h.point;
  const auto& tri = static_cast<const TriangleMesh&>(s).mesh()->triangles[h.triangle];
  const auto& p = static_cast<const TriangleMesh&>(s).mesh()->positions;
  Vec3 n = (p[tri[1]] - p[tri[0]]).cross(p[tri[2]] - p[tri[0]]);
  n = n.squaredNorm() > 0 ? Vec3(n.normalized()) : Vec3::UnitZ();
  out.normal = n.dot(ray.direction) > 0 ? Vec3(-n) : n;  // facing the ray
  return out;
}

}  // namespace

void registerMeshColliders(ColliderTable& table) {
  auto reg = [&](ShapeType x, ShapeType y, const Collider& c) {
    const Status s = table.registerCollider(x, y, c);
    DM_DEMAND(s.ok(), "built-in collider registration");
  };
  reg(ShapeType::TriangleMesh, ShapeType::TriangleMesh, {&meshMeshHit, &meshMeshContactsFn, &meshMeshDist});
  const Collider round{&meshRoundHit, &meshRoundContacts, &meshRoundDist};
  reg(ShapeType::TriangleMesh, ShapeType::Sphere, round);
  reg(ShapeType::TriangleMesh, ShapeType::Capsule, round);
  DM_DEMAND(table.registerRaycaster(ShapeType::TriangleMesh, &rayMesh).ok(),
            "built-in raycaster registration");
}

}  // namespace detail
}  // namespace dm
