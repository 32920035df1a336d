// Sphere-tree pairs of the collider table: sphere tree against sphere tree
// (simultaneous descent), against every shape that has a sphere collider
// (primitives, hulls, triangle meshes, planes; the leaf spheres go through
// the existing sphere–X queries), and the sphere-tree raycaster. Stored and
// implicit trees (both ShapeType::SphereTree) are traversed through
// SphereHierarchy. A tree stands for the union of its leaf spheres:
// - intersect: true when some leaf sphere touches the other shape;
// - contacts: one per touching leaf sphere (pair of leaf spheres for two
//   trees), reduced to request.maxContacts (deepest first, then spread);
// - distance: the minimum over leaf spheres of the signed sphere–X distance
//   (two trees: over leaf pairs), so > 0 is the exact gap of the unions, a
//   lower bound of the source geometry's gap, and < 0 the deepest single
//   leaf penetration.
// Subtrees are pruned with each node's bound sphere, which encloses its leaf
// spheres. Traversal stacks are fixed arrays: no allocation except contacts
// growing out.contacts.
#include <dm/collide/sphere_tree.hpp>

#include <algorithm>
#include <cmath>
#include <limits>

#include "collide_internal.hpp"
#include "pair_colliders.hpp"

namespace dm::detail {
namespace {

using NodeId = SphereHierarchy::NodeId;
// Each step pops one entry and pushes ≤ 8; descents are ≤ 11 + 11 levels deep.
constexpr int kStackSize = 256;

const SphereHierarchy& treeOf(const Shape& s) { return static_cast<const SphereHierarchy&>(s); }

Isometry3 at(const Vec3& c) {
  Isometry3 p = Isometry3::Identity();
  p.translation() = c;
  return p;
}

// ------------------------------------------------ tree (A) vs shape (B) ---

enum class Walk { Skip, Descend, Stop };

// Depth-first over the nodes of `t`: visit(centre (world), bound radius,
// isLeaf) says whether to descend into a node, skip it or stop the walk.
template <class Visit>
void walk(const SphereHierarchy& t, const Isometry3& pa, Visit&& visit) {
  NodeId stack[kStackSize];
  int top = 0;
  stack[top++] = t.root();
  while (top > 0) {
    const NodeId n = stack[--top];
    const BoundingSphere bs = t.bound(n);
    NodeId kids[8];
    const int k = t.children(n, kids);
    const Walk w = visit(Vec3(pa * bs.center), bs.radius, k == 0);  // a leaf's bound is its sphere
    if (w == Walk::Stop) return;
    if (w == Walk::Descend)
      for (int i = 0; i < k && top < kStackSize; ++i) stack[top++] = kids[i];
  }
}

bool treeShapeHit(const Shape& a, const Isometry3& pa, const Shape& b, const Isometry3& pb, PairCache*) {
  const Aabb boxB = b.aabb(pb);
  bool hit = false;
  walk(treeOf(a), pa, [&](const Vec3& c, double r, bool leaf) {
    // Cheap rejection before the exact sphere–shape query.
    if (boxB.squaredExteriorDistance(c) > r * r || !intersect(Sphere(r), at(c), b, pb)) return Walk::Skip;
    hit = leaf;
    return leaf ? Walk::Stop : Walk::Descend;
  });
  return hit;
}

void treeShapeContacts(const Shape& a, const Isometry3& pa, const Shape& b, const Isometry3& pb,
                       const CollisionRequest& req, CollisionResult& out, PairCache*) {
  const Aabb boxB = b.aabb(pb);
  // Every touching leaf contributes; the reduction to maxContacts is last.
  CollisionRequest all = req;
  all.maxContacts = std::numeric_limits<int>::max();
  const std::size_t first = out.contacts.size();
  walk(treeOf(a), pa, [&](const Vec3& c, double r, bool leaf) {
    if (boxB.squaredExteriorDistance(c) > r * r) return Walk::Skip;
    const Sphere s(r);
    if (!leaf) return intersect(s, at(c), b, pb) ? Walk::Descend : Walk::Skip;
    bool swapped = false;
    const Collider* col = ColliderTable::global().find(s, b, swapped);
    if (!col) {
      out.supported = false;
      return Walk::Stop;
    }
    const std::size_t before = out.contacts.size();
    if (!swapped) {
      col->contacts(s, at(c), b, pb, all, out, nullptr);
    } else {
      col->contacts(b, pb, s, at(c), all, out, nullptr);
      for (std::size_t i = before; i < out.contacts.size(); ++i)
        out.contacts[i].normal = -out.contacts[i].normal;
    }
    return !req.contacts && out.colliding ? Walk::Stop : Walk::Skip;
  });
  out.separation = 0.0;  // one sphere's bound says nothing of the others
  if (out.supported && req.contacts) reduceContacts(out, first, req.maxContacts);
}

DistanceResult treeShapeDist(const Shape& a, const Isometry3& pa, const Shape& b, const Isometry3& pb,
                             PairCache*) {
  DistanceResult best;
  best.distance = kInf;
  walk(treeOf(a), pa, [&](const Vec3& c, double r, bool leaf) {
    const DistanceResult d = distance(Sphere(r), at(c), b, pb);
    if (!d.supported) {
      best = d;
      return Walk::Stop;
    }
    // The bound sphere holds every leaf sphere below, so d is a lower bound
    // of theirs (the signed distance only decreases on a superset).
    if (d.distance >= best.distance) return Walk::Skip;
    if (leaf) {
      best = d;
      return Walk::Skip;
    }
    return Walk::Descend;
  });
  return best;
}

// ------------------------------------------------------- tree vs tree ---

struct NodePair {
  NodeId a, b;
};

// Descends the node with the larger bound (a leaf is never descended).
template <class Visit>
void descend(const SphereHierarchy& ta, const Isometry3& pa, const SphereHierarchy& tb, const Isometry3& pb,
             Visit&& visit) {
  NodePair stack[kStackSize];
  int top = 0;
  stack[top++] = {ta.root(), tb.root()};
  while (top > 0) {
    const NodePair p = stack[--top];
    const BoundingSphere sa = ta.bound(p.a), sb = tb.bound(p.b);
    const Vec3 ca = pa * sa.center, cb = pb * sb.center;
    NodeId ka[8], kb[8];
    const int na = ta.children(p.a, ka), nb = tb.children(p.b, kb);
    // visit returns false to prune, and stops everything by returning false
    // with `stop` set inside.
    if (!visit(ca, sa.radius, cb, sb.radius, na == 0 && nb == 0)) continue;
    if (na == 0 && nb == 0) continue;
    const bool splitA = nb == 0 || (na > 0 && sa.radius >= sb.radius);
    if (splitA) {
      for (int i = 0; i < na && top < kStackSize; ++i) stack[top++] = {ka[i], p.b};
    } else {
      for (int i = 0; i < nb && top < kStackSize; ++i) stack[top++] = {p.a, kb[i]};
    }
  }
}

bool treeTreeHit(const Shape& a, const Isometry3& pa, const Shape& b, const Isometry3& pb, PairCache*) {
  bool hit = false;
  descend(treeOf(a), pa, treeOf(b), pb,
          [&](const Vec3& ca, double ra, const Vec3& cb, double rb, bool leaves) {
            if (hit) return false;
            const double r = ra + rb;
            if ((ca - cb).squaredNorm() > r * r) return false;
            if (leaves) hit = true;
            return !hit;
          });
  return hit;
}

void treeTreeContacts(const Shape& a, const Isometry3& pa, const Shape& b, const Isometry3& pb,
                      const CollisionRequest& req, CollisionResult& out, PairCache*) {
  const std::size_t first = out.contacts.size();
  bool done = false;
  descend(treeOf(a), pa, treeOf(b), pb,
          [&](const Vec3& ca, double ra, const Vec3& cb, double rb, bool leaves) {
            if (done) return false;
            const double r = ra + rb;
            if ((ca - cb).squaredNorm() > r * r) return false;
            if (!leaves) return true;
            out.colliding = true;
            if (!req.contacts) {
              done = true;
              return false;
            }
            const SignedContact s = pointPair(ca, ra, cb, rb, Vec3::UnitZ());
            out.contacts.push_back({0.5 * (s.pointA + s.pointB), s.normal, -s.distance});
            return false;
          });
  if (req.contacts) reduceContacts(out, first, req.maxContacts);
}

DistanceResult treeTreeDist(const Shape& a, const Isometry3& pa, const Shape& b, const Isometry3& pb,
                            PairCache*) {
  DistanceResult best;
  best.distance = kInf;
  descend(treeOf(a), pa, treeOf(b), pb,
          [&](const Vec3& ca, double ra, const Vec3& cb, double rb, bool leaves) {
            const double d = (ca - cb).norm() - ra - rb;  // lower bound for every leaf pair below
            if (d >= best.distance) return false;
            if (!leaves) return true;
            const SignedContact s = pointPair(ca, ra, cb, rb, Vec3::UnitZ());
            best.distance = s.distance;
            best.pointA = s.pointA;
            best.pointB = s.pointB;
            return false;
          });
  return best;
}

// ------------------------------------------------------------ raycast ---

std::optional<RayHit> rayTree(const Shape& shape, const Ray& ray) {
  const SphereHierarchy& t = treeOf(shape);
  std::optional<RayHit> best;
  double tMax = ray.maxDistance;
  NodeId stack[kStackSize];
  int top = 0;
  stack[top++] = t.root();
  while (top > 0) {
    const NodeId n = stack[--top];
    const BoundingSphere bs = t.bound(n);
    // Entry parameter of the ray into the sphere (0 when it starts inside).
    const Vec3 m = ray.origin - bs.center;
    const double bq = m.dot(ray.direction);
    const double cq = m.squaredNorm() - bs.radius * bs.radius;
    double tHit = 0.0;
    if (cq > 0) {
      const double disc = bq * bq - cq;
      if (disc < 0 || bq > 0) continue;
      tHit = cq / (-bq + std::sqrt(disc));
    }
    if (tHit > tMax) continue;
    NodeId kids[8];
    const int k = t.children(n, kids);
    if (k > 0) {
      for (int i = 0; i < k && top < kStackSize; ++i) stack[top++] = kids[i];
      continue;
    }
    tMax = tHit;
    const Vec3 p = ray.origin + tHit * ray.direction;
    const Vec3 normal = cq <= 0 || bs.radius <= 0 ? Vec3(-ray.direction) : Vec3((p - bs.center) / bs.radius);
    best = RayHit{tHit, p, normal};
  }
  return best;
}

}  // namespace

void registerSphereTreeColliders(ColliderTable& table) {
  auto reg = [&](ShapeType x, ShapeType y, const Collider& c) {
    const Status s = table.registerCollider(x, y, c);
    DM_DEMAND(s.ok(), "built-in collider registration");
  };
  reg(ShapeType::SphereTree, ShapeType::SphereTree, {&treeTreeHit, &treeTreeContacts, &treeTreeDist});
  const Collider withShape{&treeShapeHit, &treeShapeContacts, &treeShapeDist};
  for (ShapeType other : {ShapeType::Point, ShapeType::Segment, ShapeType::Plane, ShapeType::TriangleShape,
                          ShapeType::Sphere, ShapeType::Box, ShapeType::Capsule, ShapeType::Cylinder,
                          ShapeType::Ellipsoid, ShapeType::ConvexHull, ShapeType::TriangleMesh})
    reg(ShapeType::SphereTree, other, withShape);
  DM_DEMAND(table.registerRaycaster(ShapeType::SphereTree, &rayTree).ok(), "built-in raycaster registration");
}

}  // namespace dm::detail
