// Narrow-phase dispatch, the collider table, the generic convex (GJK/EPA),
// plane–convex and compound colliders, and ray casts; see dm/collide/query.hpp.
#include <dm/collide/query.hpp>

#include <algorithm>
#include <cmath>
#include <string>

#include "collide_internal.hpp"
#include "pair_colliders.hpp"

namespace dm {

namespace {

using detail::kInf;

GjkCache* gjkCacheOf(PairCache* cache) { return cache ? &cache->gjk : nullptr; }

// ------------------------------------------------- convex pair: GJK/EPA ---

const Collider kConvexCollider = {
    [](const Shape& a, const Isometry3& pa, const Shape& b, const Isometry3& pb, PairCache* cache) {
      return gjkIntersect(static_cast<const ConvexShape&>(a), pa, static_cast<const ConvexShape&>(b), pb,
                          gjkCacheOf(cache));
    },
    [](const Shape& a, const Isometry3& pa, const Shape& b, const Isometry3& pb, const CollisionRequest& req,
       CollisionResult& out, PairCache* cache) {
      GjkOptions opt;
      opt.penetration = req.contacts;
      const GjkResult g = gjkDistance(static_cast<const ConvexShape&>(a), pa,
                                      static_cast<const ConvexShape&>(b), pb, gjkCacheOf(cache), opt);
      detail::appendContact({g.distance, g.pointA, g.pointB, g.normal}, req, out);
    },
    [](const Shape& a, const Isometry3& pa, const Shape& b, const Isometry3& pb, PairCache* cache) {
      const GjkResult g = gjkDistance(static_cast<const ConvexShape&>(a), pa,
                                      static_cast<const ConvexShape&>(b), pb, gjkCacheOf(cache));
      return detail::toDistanceResult({g.distance, g.pointA, g.pointB, g.normal});
    },
};

// ------------------------------------------------- plane–convex (A = plane) ---

struct PlaneFrame {
  Vec3 n;    // world unit normal (outward of the half-space)
  double d;  // world offset: the half-space is n·x <= d
};

PlaneFrame worldPlane(const Shape& a, const Isometry3& pa) {
  const auto& plane = static_cast<const Plane&>(a);
  const Vec3 n = pa.linear() * plane.normal();
  return {n, plane.offset() + n.dot(pa.translation())};
}

detail::SignedContact planeConvex(const Shape& a, const Isometry3& pa, const Shape& b, const Isometry3& pb) {
  const PlaneFrame pl = worldPlane(a, pa);
  const auto& cb = static_cast<const ConvexShape&>(b);
  std::uint32_t hint = 0;
  const Vec3 p = pb * cb.supportCore(pb.linear().transpose() * -pl.n, hint) - cb.margin() * pl.n;
  detail::SignedContact s;
  s.distance = pl.n.dot(p) - pl.d;
  s.pointB = p;
  s.pointA = p - s.distance * pl.n;
  s.normal = pl.n;
  return s;
}

void planeConvexContacts(const Shape& a, const Isometry3& pa, const Shape& b, const Isometry3& pb,
                         const CollisionRequest& req, CollisionResult& out, PairCache*) {
  if (b.type() != ShapeType::Box) {
    detail::appendContact(planeConvex(a, pa, b, pb), req, out);
    return;
  }
  // A box resting on a plane touches with a face or an edge: every vertex
  // below the plane is a contact.
  const PlaneFrame pl = worldPlane(a, pa);
  const Vec3& h = static_cast<const Box&>(b).halfExtents();
  const std::size_t first = out.contacts.size();
  for (int k = 0; k < 8; ++k) {
    const Vec3 v = pb * Vec3(k & 1 ? h.x() : -h.x(), k & 2 ? h.y() : -h.y(), k & 4 ? h.z() : -h.z());
    const double s = pl.n.dot(v) - pl.d;
    if (s > 0) continue;
    out.colliding = true;
    if (req.contacts) out.contacts.push_back({v - 0.5 * s * pl.n, pl.n, -s});
  }
  detail::reduceContacts(out, first, req.maxContacts);
}

const Collider kPlaneConvexCollider = {
    [](const Shape& a, const Isometry3& pa, const Shape& b, const Isometry3& pb, PairCache*) {
      return planeConvex(a, pa, b, pb).distance <= 0;
    },
    &planeConvexContacts,
    [](const Shape& a, const Isometry3& pa, const Shape& b, const Isometry3& pb, PairCache*) {
      return detail::toDistanceResult(planeConvex(a, pa, b, pb));
    },
};

// ------------------------------------------------ compound (A = compound) ---

void collideAppend(const Shape& a, const Isometry3& pa, const Shape& b, const Isometry3& pb,
                   const CollisionRequest& req, CollisionResult& out, PairCache* cache);

const Collider kCompoundCollider = {
    [](const Shape& a, const Isometry3& pa, const Shape& b, const Isometry3& pb, PairCache* cache) {
      for (const CompoundChild& c : static_cast<const Compound&>(a).children())
        if (intersect(*c.shape, pa * c.pose, b, pb, cache)) return true;
      return false;
    },
    [](const Shape& a, const Isometry3& pa, const Shape& b, const Isometry3& pb, const CollisionRequest& req,
       CollisionResult& out, PairCache* cache) {
      const std::size_t first = out.contacts.size();
      for (const CompoundChild& c : static_cast<const Compound&>(a).children())
        collideAppend(*c.shape, pa * c.pose, b, pb, req, out, cache);
      out.separation = 0.0;  // one child's bound says nothing of the others
      detail::reduceContacts(out, first, req.maxContacts);
    },
    [](const Shape& a, const Isometry3& pa, const Shape& b, const Isometry3& pb, PairCache* cache) {
      DistanceResult best;
      best.distance = kInf;
      for (const CompoundChild& c : static_cast<const Compound&>(a).children()) {
        const DistanceResult d = distance(*c.shape, pa * c.pose, b, pb, cache);
        if (!d.supported) return d;
        if (d.distance < best.distance) best = d;
      }
      return best;
    },
};

void collideAppend(const Shape& a, const Isometry3& pa, const Shape& b, const Isometry3& pb,
                   const CollisionRequest& req, CollisionResult& out, PairCache* cache) {
  bool swapped = false;
  const Collider* c = ColliderTable::global().find(a, b, swapped);
  if (!c) {
    out.supported = false;
    return;
  }
  if (!swapped) {
    c->contacts(a, pa, b, pb, req, out, cache);
    return;
  }
  const std::size_t first = out.contacts.size();
  c->contacts(b, pb, a, pa, req, out, cache);
  for (std::size_t i = first; i < out.contacts.size(); ++i) out.contacts[i].normal = -out.contacts[i].normal;
}

// ------------------------------------------------------------- raycasts ---

std::optional<RayHit> insideHit(const Ray& ray) { return RayHit{0.0, ray.origin, -ray.direction}; }

std::optional<RayHit> raySphere(const Shape& s, const Ray& ray) {
  const double r = static_cast<const Sphere&>(s).radius();
  const double b = ray.origin.dot(ray.direction);
  const double c = ray.origin.squaredNorm() - r * r;
  if (c <= 0) return insideHit(ray);
  const double disc = b * b - c;
  if (disc < 0 || b > 0) return std::nullopt;
  const double t = c / (-b + std::sqrt(disc));  // = −b − √disc without cancellation
  if (t > ray.maxDistance) return std::nullopt;
  const Vec3 p = ray.origin + t * ray.direction;
  return RayHit{t, p, p / r};
}

std::optional<RayHit> rayBox(const Shape& s, const Ray& ray) {
  const Vec3& h = static_cast<const Box&>(s).halfExtents();
  if ((ray.origin.cwiseAbs() - h).maxCoeff() <= 0) return insideHit(ray);
  double tmin = 0, tmax = ray.maxDistance;
  int axis = -1;
  double sign = 1;
  for (int i = 0; i < 3; ++i) {
    const double o = ray.origin[i], d = ray.direction[i];
    if (d == 0) {
      if (std::abs(o) > h[i]) return std::nullopt;
      continue;
    }
    double t1 = (-h[i] - o) / d, t2 = (h[i] - o) / d;
    double s1 = -1;
    if (t1 > t2) std::swap(t1, t2), s1 = 1;
    if (t1 > tmin) tmin = t1, axis = i, sign = s1;
    tmax = std::min(tmax, t2);
    if (tmin > tmax) return std::nullopt;
  }
  if (axis < 0) return std::nullopt;
  return RayHit{tmin, ray.origin + tmin * ray.direction, sign * Vec3::Unit(axis)};
}

std::optional<RayHit> rayPlane(const Shape& s, const Ray& ray) {
  const auto& pl = static_cast<const Plane&>(s);
  const double s0 = pl.normal().dot(ray.origin) - pl.offset();
  if (s0 <= 0) return insideHit(ray);
  const double dn = pl.normal().dot(ray.direction);
  if (dn >= 0) return std::nullopt;
  const double t = -s0 / dn;
  if (t > ray.maxDistance) return std::nullopt;
  return RayHit{t, ray.origin + t * ray.direction, pl.normal()};
}

std::optional<RayHit> rayCylinder(const Shape& s, const Ray& ray) {
  const auto& cyl = static_cast<const Cylinder&>(s);
  const double r = cyl.radius(), h = cyl.halfLength();
  const Vec3& o = ray.origin;
  const Vec3& d = ray.direction;
  if (o.x() * o.x() + o.y() * o.y() <= r * r && std::abs(o.z()) <= h) return insideHit(ray);
  // Entry and exit of the infinite side surface and of the cap slab.
  double sideIn = -kInf, sideOut = kInf;
  const double a = d.x() * d.x() + d.y() * d.y();
  const double b = o.x() * d.x() + o.y() * d.y();
  const double c = o.x() * o.x() + o.y() * o.y() - r * r;
  if (a > 0) {
    const double disc = b * b - a * c;
    if (disc < 0) return std::nullopt;
    // Stable roots: q/a and c/q.
    const double q = -(b + std::copysign(std::sqrt(disc), b));
    sideIn = q / a, sideOut = q != 0 ? c / q : sideIn;
    if (sideIn > sideOut) std::swap(sideIn, sideOut);
  } else if (c > 0) {
    return std::nullopt;
  }
  double slabIn = -kInf, slabOut = kInf;
  if (d.z() != 0) {
    slabIn = (-h - o.z()) / d.z(), slabOut = (h - o.z()) / d.z();
    if (slabIn > slabOut) std::swap(slabIn, slabOut);
  } else if (std::abs(o.z()) > h) {
    return std::nullopt;
  }
  const double tIn = std::max(sideIn, slabIn), tOut = std::min(sideOut, slabOut);
  if (tIn > tOut || tOut < 0 || tIn > ray.maxDistance) return std::nullopt;
  const Vec3 p = o + tIn * d;
  const Vec3 n = sideIn >= slabIn ? Vec3(p.x() / r, p.y() / r, 0.0) : Vec3(0, 0, d.z() > 0 ? -1.0 : 1.0);
  return RayHit{tIn, p, n};
}

// Conservative advancement on the GJK distance from the ray point to the
// shape: each step moves by distance / closing speed, never past the surface.
std::optional<RayHit> rayConvex(const Shape& s, const Ray& ray) {
  const auto& shape = static_cast<const ConvexShape&>(s);
  const BoundingSphere bs = shape.boundingSphere();
  const double scale = (ray.origin - bs.center).norm() + bs.radius;
  const double tol = 1e-12 * scale;
  const Isometry3 identity = Isometry3::Identity();
  GjkCache cache;
  double t = 0;
  Vec3 normal = -ray.direction;
  for (int it = 0; it < 100; ++it) {
    const Point p(ray.origin + t * ray.direction);
    const GjkResult g = gjkDistance(p, identity, shape, identity, &cache);
    if (g.distance <= tol) {
      if (it == 0) return insideHit(ray);
      return RayHit{t, ray.origin + t * ray.direction, normal};
    }
    // Outward surface normal at the closest point. Very close to the surface
    // the direction of GJK's tiny separation vector is rounding noise; the
    // normal from 1e-7 away is accurate to ~1e-7 · curvature.
    if (g.distance > 1e-7 * scale || it == 0) normal = -g.normal;
    const double closing = ray.direction.dot(g.normal);
    if (closing <= 0) return std::nullopt;
    t += g.distance / closing;
    if (t > ray.maxDistance) return std::nullopt;
  }
  return RayHit{t, ray.origin + t * ray.direction, normal};
}

std::optional<RayHit> rayCompound(const Shape& s, const Ray& ray) {
  std::optional<RayHit> best;
  Ray r = ray;
  for (const CompoundChild& c : static_cast<const Compound&>(s).children()) {
    if (auto hit = raycast(*c.shape, c.pose, r)) {
      best = hit;
      r.maxDistance = hit->t;
    }
  }
  return best;
}

}  // namespace

// ---------------------------------------------------------------- table ---

ColliderTable::ColliderTable() {
  detail::registerPrimitiveColliders(*this);
  detail::registerBoxBoxCollider(*this);
  detail::registerMeshColliders(*this);
  detail::registerMeshConvexColliders(*this);
  detail::registerSphereTreeColliders(*this);
  detail::registerVoxelColliders(*this);
  detail::registerVoxelConvexColliders(*this);
  raycasters_[static_cast<int>(ShapeType::Sphere)] = &raySphere;
  raycasters_[static_cast<int>(ShapeType::Box)] = &rayBox;
  raycasters_[static_cast<int>(ShapeType::Plane)] = &rayPlane;
  raycasters_[static_cast<int>(ShapeType::Cylinder)] = &rayCylinder;
  raycasters_[static_cast<int>(ShapeType::Compound)] = &rayCompound;
}

ColliderTable& ColliderTable::global() noexcept {
  static ColliderTable table;
  return table;
}

Status ColliderTable::registerCollider(ShapeType a, ShapeType b, const Collider& collider) {
  const int ia = static_cast<int>(a), ib = static_cast<int>(b);
  if (ia >= kMaxShapeTypes || ib >= kMaxShapeTypes)
    return fail(ErrorCode::InvalidArgument,
                "shape type id " + std::to_string(std::max(ia, ib)) + " is out of range",
                "ColliderTable::registerCollider", "obtain ids from dm::registerShapeType()");
  if (!collider.complete())
    return fail(ErrorCode::InvalidArgument, "collider has a null function",
                "ColliderTable::registerCollider(" + std::string(shapeTypeName(a)) + ", " +
                    std::string(shapeTypeName(b)) + ")",
                "provide intersect, contacts and distance");
  entries_[ia][ib] = {collider, true, false};
  Entry& mirror = entries_[ib][ia];
  if (ia != ib && (!mirror.registered || mirror.swapped)) mirror = {collider, true, true};
  return ok();
}

Status ColliderTable::registerRaycaster(ShapeType t, RaycastFn fn) {
  const int i = static_cast<int>(t);
  if (i >= kMaxShapeTypes || !fn)
    return fail(ErrorCode::InvalidArgument, "bad shape type id or null raycaster",
                "ColliderTable::registerRaycaster(" + std::to_string(i) + ")",
                "obtain ids from dm::registerShapeType() and pass a function");
  raycasters_[i] = fn;
  return ok();
}

const Collider* ColliderTable::find(const Shape& a, const Shape& b, bool& swapped) const noexcept {
  const Entry& e = entries_[static_cast<int>(a.type())][static_cast<int>(b.type())];
  if (e.registered) {
    swapped = e.swapped;
    return &e.collider;
  }
  swapped = false;
  if (a.type() == ShapeType::Compound) return &kCompoundCollider;
  if (b.type() == ShapeType::Compound) return swapped = true, &kCompoundCollider;
  if (a.type() == ShapeType::Plane && b.isConvex()) return &kPlaneConvexCollider;
  if (b.type() == ShapeType::Plane && a.isConvex()) return swapped = true, &kPlaneConvexCollider;
  if (a.isConvex() && b.isConvex()) return &kConvexCollider;
  return nullptr;
}

RaycastFn ColliderTable::findRaycaster(ShapeType t) const noexcept {
  return raycasters_[static_cast<int>(t)];
}

Status ColliderTable::check(const Shape& a, const Shape& b) const {
  bool swapped = false;
  if (find(a, b, swapped)) return ok();
  return fail(ErrorCode::Unsupported,
              "no collider for (" + std::string(shapeTypeName(a.type())) + ", " +
                  std::string(shapeTypeName(b.type())) + ") yet",
              "dm::ColliderTable", "register one with ColliderTable::registerCollider()");
}

// ------------------------------------------------------------- queries ---

bool intersect(const Shape& a, const Isometry3& poseA, const Shape& b, const Isometry3& poseB,
               PairCache* cache) noexcept {
  bool swapped = false;
  const Collider* c = ColliderTable::global().find(a, b, swapped);
  if (!c) return false;
  return swapped ? c->intersect(b, poseB, a, poseA, cache) : c->intersect(a, poseA, b, poseB, cache);
}

void collide(const Shape& a, const Isometry3& poseA, const Shape& b, const Isometry3& poseB,
             const CollisionRequest& request, CollisionResult& out, PairCache* cache) {
  out.clear();
  collideAppend(a, poseA, b, poseB, request, out, cache);
}

CollisionResult collide(const Shape& a, const Isometry3& poseA, const Shape& b, const Isometry3& poseB,
                        const CollisionRequest& request, PairCache* cache) {
  CollisionResult out;
  collide(a, poseA, b, poseB, request, out, cache);
  return out;
}

DistanceResult distance(const Shape& a, const Isometry3& poseA, const Shape& b, const Isometry3& poseB,
                        PairCache* cache) noexcept {
  bool swapped = false;
  const Collider* c = ColliderTable::global().find(a, b, swapped);
  if (!c) {
    DistanceResult d;
    d.supported = false;
    return d;
  }
  if (!swapped) return c->distance(a, poseA, b, poseB, cache);
  DistanceResult d = c->distance(b, poseB, a, poseA, cache);
  std::swap(d.pointA, d.pointB);
  return d;
}

std::optional<RayHit> raycast(const Shape& shape, const Isometry3& pose, const Ray& ray) noexcept {
  RaycastFn fn = ColliderTable::global().findRaycaster(shape.type());
  if (!fn && shape.isConvex()) fn = &rayConvex;
  if (!fn) return std::nullopt;
  const Mat3 r = pose.linear();
  Ray local = ray;
  local.origin = r.transpose() * (ray.origin - pose.translation());
  local.direction = r.transpose() * ray.direction;
  std::optional<RayHit> hit = fn(shape, local);
  if (hit) {
    hit->point = pose * hit->point;
    hit->normal = r * hit->normal;
  }
  return hit;
}

}  // namespace dm
