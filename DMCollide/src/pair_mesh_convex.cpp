// Triangle-mesh pairs of the collider table against the convex shapes that
// have no dedicated mesh query: point, segment, triangle, box, cylinder,
// ellipsoid and convex hull. One generic implementation on the MeshBvh and
// GJK/EPA (sphere and capsule keep their exact segment–triangle queries in
// pair_mesh.cpp).
//
// The convex shape B is mapped into the mesh's local frame once per query
// (rel = poseA⁻¹·poseB), then:
//  * intersect: depth-first over the nodes whose box overlaps B's local AABB,
//    per triangle an AABB reject and gjkIntersect(triangle, B). A closed mesh
//    (MeshBvh::isClosed()) is a solid: when no triangle touches B but B's box
//    lies within the mesh bounds, one point of B is classified by the signed
//    closestPointOnMesh() (angle-weighted pseudonormals), so a shape fully
//    inside counts as colliding. Open meshes are surfaces.
//  * distance: branch and bound, nearer child first, pruned by lower bounds
//    (node box to B's box, node box to B's bounding sphere); per triangle
//    gjkDistance() with EPA, warm-started across triangles (separating
//    direction of the previous triangle, hull vertex hint of B, kept in the
//    PairCache between queries). The result is the minimum over triangles of
//    the signed triangle–B distance, i.e. exact when separated and −(largest
//    per-triangle EPA depth) when B crosses the surface — the same definition
//    as mesh–sphere (centre distance − radius is sphere–triangle EPA). B fully
//    inside a closed mesh gives distance = −(push-out depth): with pA the
//    nearest surface point, pB the nearest point of B and n = (pA − pB)/|·|,
//    the depth is n·pA − min over B of n·x (translate B by depth·n and it is
//    outside), pointB the deepest point of B.
//  * contacts: one per intersecting triangle from EPA (position midway between
//    the deepest points, normal from the triangle into B, EPA depth), reduced
//    with reduceContacts() to request.maxContacts; when B is flat (segment,
//    point, triangle: EPA has no volume) the normal is the triangle's face
//    normal and the depth how far B reaches below the triangle's plane. A
//    shape fully inside a closed mesh gives the one push-out contact above.
//    Per-triangle EPA knows nothing of the neighbours: a shape straddling an
//    inner edge of a flat region also gets, from the triangle it barely
//    overlaps, a contact pushing it sideways across that edge.
// Queries never allocate (contacts append to the caller's vector), lock or
// throw; traversal stacks are fixed arrays sized from MeshBvh::kMaxDepth.
#include <dm/collide/bvh.hpp>
#include <dm/collide/gjk.hpp>
#include <dm/collide/mesh_query.hpp>
#include <dm/collide/shapes.hpp>
#include <dm/core/assert.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include "pair_colliders.hpp"

namespace dm::detail {
namespace {

constexpr int kTraversalStack = 128;
static_assert(kTraversalStack > MeshBvh::kMaxDepth + 1, "DFS holds at most depth + 1 entries");
constexpr double kInfinity = std::numeric_limits<double>::infinity();

// Convex shape B placed in the mesh's local frame.
struct LocalConvex {
  const ConvexShape& shape;
  Isometry3 pose;  // B local → mesh local
  Vec3 lo, hi;     // B's bounds in the mesh frame, widened against rounding
  Vec3 centre;     // bounding sphere of B in the mesh frame
  double radius;

  LocalConvex(const ConvexShape& s, const Isometry3& poseMesh, const Isometry3& poseB)
      : shape(s), pose(poseMesh.inverse(Eigen::Isometry) * poseB) {
    const Aabb box = s.aabb(pose);
    // A few ulps of the coordinates' magnitude, so that the rounding of the
    // transform never prunes a triangle that B touches exactly.
    const double slack = 1e-12 * (box.max().cwiseAbs().maxCoeff() + box.min().cwiseAbs().maxCoeff());
    lo = box.min().array() - slack;
    hi = box.max().array() + slack;
    const BoundingSphere bs = s.boundingSphere();
    centre = pose * bs.center;
    radius = bs.radius * (1 + 1e-12) + slack;
  }

  bool overlaps(const BvhNode& n) const noexcept {
    return !(lo.x() > n.hi[0] || lo.y() > n.hi[1] || lo.z() > n.hi[2] || hi.x() < n.lo[0] ||
             hi.y() < n.lo[1] || hi.z() < n.lo[2]);
  }
  bool overlaps(const Vec3* c) const noexcept {
    const Vec3 tlo = c[0].cwiseMin(c[1]).cwiseMin(c[2]), thi = c[0].cwiseMax(c[1]).cwiseMax(c[2]);
    return !((lo.array() > thi.array()).any() || (tlo.array() > hi.array()).any());
  }
  // Lower bound of the distance from B to anything in the box [blo, bhi]:
  // the larger of the box–box gap and the gap from B's bounding sphere.
  double lowerBound(const Vec3& blo, const Vec3& bhi) const noexcept {
    const double box = (blo - hi).cwiseMax(lo - bhi).cwiseMax(0.0).norm();
    const double ball = (blo - centre).cwiseMax(centre - bhi).cwiseMax(0.0).norm() - radius;
    return std::max(box, ball);
  }
  double lowerBound(const BvhNode& n) const noexcept {
    return lowerBound(Vec3(n.lo[0], n.lo[1], n.lo[2]), Vec3(n.hi[0], n.hi[1], n.hi[2]));
  }
  double lowerBound(const Vec3* c) const noexcept {
    return lowerBound(c[0].cwiseMin(c[1]).cwiseMin(c[2]), c[0].cwiseMax(c[1]).cwiseMax(c[2]));
  }
  // Point of B farthest along −n, in the mesh frame.
  Vec3 deepest(const Vec3& n, std::uint32_t& hint) const noexcept {
    return pose * shape.supportCore(pose.linear().transpose() * -n, hint) - shape.margin() * n;
  }
};

const MeshBvh* meshBvh(const Shape& s) noexcept { return static_cast<const TriangleMesh&>(s).bvh().get(); }

// Calls visit(k) for each leaf-order triangle whose box overlaps B's box,
// until it returns true; returns whether it stopped.
template <class Visit>
bool forOverlappingTriangles(const MeshBvh& bvh, const LocalConvex& b, Visit&& visit) noexcept {
  if (bvh.triangleCount() == 0 || !b.overlaps(bvh.node(0))) return false;
  std::array<std::uint32_t, kTraversalStack> stack;
  int top = 0;
  stack[top++] = 0;
  while (top > 0) {
    const BvhNode& n = bvh.node(stack[--top]);
    if (n.isLeaf()) {
      for (std::uint32_t k = n.first; k < n.first + n.count; ++k)
        if (b.overlaps(bvh.corners(k)) && visit(k)) return true;
      continue;
    }
    for (std::uint32_t child = n.first; child < n.first + 2; ++child)
      if (b.overlaps(bvh.node(child))) stack[top++] = child;
  }
  return false;
}

// Signed answer of triangle k (A) against B in the mesh frame; see the file
// comment for the flat case.
SignedContact triangleAgainst(const MeshBvh& bvh, std::uint32_t k, const LocalConvex& b,
                              GjkCache& cache) noexcept {
  const Vec3* c = bvh.corners(k);
  const TriangleShape tri(c[0], c[1], c[2]);
  const GjkResult g = gjkDistance(tri, Isometry3::Identity(), b.shape, b.pose, &cache);
  SignedContact s{g.distance, g.pointA, g.pointB, g.normal};
  if (g.exact) return s;
  const Vec3 face = (c[1] - c[0]).cross(c[2] - c[0]);
  if (!(face.squaredNorm() > 0)) return s;
  const Vec3 n = face.normalized();
  const Vec3 deep = b.deepest(n, cache.hintB);
  const double depth = std::max(0.0, n.dot(c[0] - deep));
  s.distance = -depth;
  s.normal = n;
  s.pointB = deep;
  s.pointA = deep + depth * n;
  return s;
}

// True when B, touching no triangle of a closed mesh, lies inside it.
bool enclosed(const MeshBvh& bvh, const LocalConvex& b) noexcept {
  if (!bvh.isClosed()) return false;
  const Aabb& m = bvh.bounds();
  if ((b.lo.array() < m.min().array()).any() || (b.hi.array() > m.max().array()).any()) return false;
  std::uint32_t hint = 0;
  const Vec3 inB = b.pose * b.shape.supportCore(Vec3::UnitX(), hint);
  return closestPointOnMesh(bvh, Isometry3::Identity(), inB).distance < 0;
}

// Push-out answer of B enclosed by a closed mesh, from the nearest pair
// (pA on the mesh, pB on B), mesh frame.
SignedContact pushOut(const Vec3& pA, const Vec3& pB, const LocalConvex& b, std::uint32_t& hint) noexcept {
  const Vec3 gap = pA - pB;
  const Vec3 n = gap.squaredNorm() > 0 ? Vec3(gap.normalized()) : Vec3::UnitZ();
  const Vec3 deep = b.deepest(n, hint);
  SignedContact s;
  s.distance = -std::max(0.0, n.dot(pA - deep));
  s.pointA = pA;
  s.pointB = deep;
  s.normal = n;
  return s;
}

// Nearest (or deepest) triangle answer by branch and bound; distance +inf
// for an empty mesh.
SignedContact nearestTriangle(const MeshBvh& bvh, const LocalConvex& b, GjkCache& cache) noexcept {
  SignedContact best;
  best.distance = kInfinity;
  if (bvh.triangleCount() == 0) return best;
  struct Entry {
    std::uint32_t node;
    double bound;
  };
  std::array<Entry, kTraversalStack> stack;
  int top = 0;
  stack[top++] = {0, b.lowerBound(bvh.node(0))};
  while (top > 0) {
    const Entry e = stack[--top];
    // Once B penetrates some triangle, every box touching B's (bound 0) may
    // hold a deeper one; before that, boxes no nearer than the best go.
    if (best.distance > 0 ? e.bound >= best.distance : e.bound > 0) continue;
    const BvhNode& n = bvh.node(e.node);
    if (n.isLeaf()) {
      for (std::uint32_t k = n.first; k < n.first + n.count; ++k) {
        const Vec3* c = bvh.corners(k);
        if (best.distance > 0 ? b.lowerBound(c) >= best.distance : !b.overlaps(c)) continue;
        const SignedContact s = triangleAgainst(bvh, k, b, cache);
        if (s.distance < best.distance) best = s;
      }
      continue;
    }
    const Entry l{n.first, b.lowerBound(bvh.node(n.first))},
        r{n.first + 1, b.lowerBound(bvh.node(n.first + 1))};
    // Push the farther child first so the nearer one is searched first.
    const bool leftNear = l.bound <= r.bound;
    stack[top++] = leftNear ? r : l;
    stack[top++] = leftNear ? l : r;
  }
  return best;
}

void loadCache(GjkCache& local, const PairCache* pair) noexcept {
  if (pair) local = pair->gjk;
}
void storeCache(const GjkCache& local, PairCache* pair) noexcept {
  if (pair) pair->gjk = local;
}

SignedContact toWorld(const SignedContact& s, const Isometry3& poseMesh) noexcept {
  return {s.distance, poseMesh * s.pointA, poseMesh * s.pointB, poseMesh.linear() * s.normal};
}

// --- the three collider functions; A is the mesh, B the convex shape ------

bool meshConvexHit(const Shape& a, const Isometry3& pa, const Shape& b, const Isometry3& pb,
                   PairCache* cache) {
  const MeshBvh* bvh = meshBvh(a);
  if (!bvh) return false;
  const LocalConvex local(static_cast<const ConvexShape&>(b), pa, pb);
  GjkCache gjk;
  loadCache(gjk, cache);
  const bool hit = forOverlappingTriangles(*bvh, local, [&](std::uint32_t k) {
    const Vec3* c = bvh->corners(k);
    const TriangleShape tri(c[0], c[1], c[2]);
    return gjkIntersect(tri, Isometry3::Identity(), local.shape, local.pose, &gjk);
  });
  storeCache(gjk, cache);
  return hit || enclosed(*bvh, local);
}

DistanceResult meshConvexDist(const Shape& a, const Isometry3& pa, const Shape& b, const Isometry3& pb,
                              PairCache* cache) {
  const MeshBvh* bvh = meshBvh(a);
  if (!bvh) {
    DistanceResult d;
    d.supported = false;
    return d;
  }
  const LocalConvex local(static_cast<const ConvexShape&>(b), pa, pb);
  GjkCache gjk;
  loadCache(gjk, cache);
  SignedContact s = nearestTriangle(*bvh, local, gjk);
  if (s.distance > 0 && s.distance < kInfinity && enclosed(*bvh, local))
    s = pushOut(s.pointA, s.pointB, local, gjk.hintB);
  storeCache(gjk, cache);
  if (s.distance == kInfinity) return DistanceResult{};
  return toDistanceResult(toWorld(s, pa));
}

void meshConvexContacts(const Shape& a, const Isometry3& pa, const Shape& b, const Isometry3& pb,
                        const CollisionRequest& req, CollisionResult& out, PairCache* cache) {
  const MeshBvh* bvh = meshBvh(a);
  if (!bvh) {
    out.supported = false;
    return;
  }
  if (!req.contacts) {
    out.colliding = out.colliding || meshConvexHit(a, pa, b, pb, cache);
    return;
  }
  const LocalConvex local(static_cast<const ConvexShape&>(b), pa, pb);
  GjkCache gjk;
  loadCache(gjk, cache);
  const std::size_t first = out.contacts.size();
  CollisionRequest all = req;
  all.maxContacts = std::numeric_limits<int>::max();
  forOverlappingTriangles(*bvh, local, [&](std::uint32_t k) {
    const Vec3* c = bvh->corners(k);
    const TriangleShape tri(c[0], c[1], c[2]);
    if (gjkIntersect(tri, Isometry3::Identity(), local.shape, local.pose, &gjk)) {
      SignedContact s = triangleAgainst(*bvh, k, local, gjk);
      s.distance = std::min(s.distance, 0.0);  // touching within GJK's rounding
      appendContact(toWorld(s, pa), all, out);
    }
    return false;
  });
  if (out.contacts.size() == first && enclosed(*bvh, local)) {
    const SignedContact s = nearestTriangle(*bvh, local, gjk);
    appendContact(toWorld(pushOut(s.pointA, s.pointB, local, gjk.hintB), pa), all, out);
  }
  storeCache(gjk, cache);
  reduceContacts(out, first, req.maxContacts);
}

}  // namespace

void registerMeshConvexColliders(ColliderTable& table) {
  const Collider generic{&meshConvexHit, &meshConvexContacts, &meshConvexDist};
  for (ShapeType t : {ShapeType::Point, ShapeType::Segment, ShapeType::TriangleShape, ShapeType::Box,
                      ShapeType::Cylinder, ShapeType::Ellipsoid, ShapeType::ConvexHull}) {
    const Status s = table.registerCollider(ShapeType::TriangleMesh, t, generic);
    DM_DEMAND(s.ok(), "built-in collider registration");
  }
}

}  // namespace dm::detail
