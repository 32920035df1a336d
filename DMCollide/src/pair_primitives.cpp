// Analytic colliders of the primitive pairs: sphere–sphere, sphere–box,
// sphere–capsule, capsule–capsule and triangle–sphere. Each reduces to the
// closest points of two cores (point, segment, box, triangle) plus radii, so
// they are exact to rounding.
#include <dm/collide/triangle.hpp>
#include <dm/math/geometry.hpp>

#include <algorithm>
#include <cmath>
#include <limits>

#include "pair_colliders.hpp"

namespace dm {

namespace detail {

SignedContact pointPair(const Vec3& cA, double rA, const Vec3& cB, double rB,
                        const Vec3& fallbackNormal) noexcept {
  SignedContact s;
  const Vec3 d = cB - cA;
  const double len = d.norm();
  s.normal = len > 0 ? Vec3(d / len) : fallbackNormal;
  s.distance = len - rA - rB;
  s.pointA = cA + rA * s.normal;
  s.pointB = cB - rB * s.normal;
  return s;
}

void reduceContacts(CollisionResult& out, std::size_t first, int maxContacts) noexcept {
  const std::size_t n = out.contacts.size() - first;
  const auto keep = static_cast<std::size_t>(std::max(1, maxContacts));
  if (n <= keep) return;
  ContactPoint* c = out.contacts.data() + first;
  // Selection sort by the greedy criterion: the first slot gets the deepest,
  // each next one the contact farthest from all kept so far.
  std::size_t deepest = 0;
  for (std::size_t i = 1; i < n; ++i)
    if (c[i].depth > c[deepest].depth) deepest = i;
  std::swap(c[0], c[deepest]);
  for (std::size_t k = 1; k < keep; ++k) {
    std::size_t best = k;
    double bestD = -1;
    for (std::size_t i = k; i < n; ++i) {
      double dmin = std::numeric_limits<double>::infinity();
      for (std::size_t j = 0; j < k; ++j)
        dmin = std::min(dmin, (c[i].position - c[j].position).squaredNorm());
      if (dmin > bestD) bestD = dmin, best = i;
    }
    std::swap(c[k], c[best]);
  }
  out.contacts.resize(first + keep);
}

namespace {

Vec3 capsuleAxis(const Isometry3& pose) { return pose.linear().col(2); }

SignedContact sphereSphere(const Shape& a, const Isometry3& pa, const Shape& b, const Isometry3& pb) {
  return pointPair(pa.translation(), static_cast<const Sphere&>(a).radius(), pb.translation(),
                   static_cast<const Sphere&>(b).radius(), Vec3::UnitZ());
}

SignedContact sphereCapsule(const Shape& a, const Isometry3& pa, const Shape& b, const Isometry3& pb) {
  const auto& cap = static_cast<const Capsule&>(b);
  const Vec3 h = capsuleAxis(pb) * cap.halfLength();
  const Vec3 q = closestPointOnSegment(pa.translation(), pb.translation() - h, pb.translation() + h);
  // Centre on the axis: any direction perpendicular to it separates.
  return pointPair(pa.translation(), static_cast<const Sphere&>(a).radius(), q, cap.radius(),
                   capsuleAxis(pb).unitOrthogonal());
}

SignedContact capsuleCapsule(const Shape& a, const Isometry3& pa, const Shape& b, const Isometry3& pb) {
  const auto& ca = static_cast<const Capsule&>(a);
  const auto& cb = static_cast<const Capsule&>(b);
  const Vec3 ha = capsuleAxis(pa) * ca.halfLength(), hb = capsuleAxis(pb) * cb.halfLength();
  const SegmentClosest sc = closestPointsSegmentSegment(pa.translation() - ha, pa.translation() + ha,
                                                        pb.translation() - hb, pb.translation() + hb);
  const Vec3& p = sc.pointA;
  const Vec3& q = sc.pointB;
  Vec3 fallback = capsuleAxis(pa).cross(capsuleAxis(pb));
  fallback = fallback.squaredNorm() > 1e-24 ? Vec3(fallback.normalized()) : capsuleAxis(pa).unitOrthogonal();
  return pointPair(p, ca.radius(), q, cb.radius(), fallback);
}

SignedContact sphereBox(const Shape& a, const Isometry3& pa, const Shape& b, const Isometry3& pb) {
  const double r = static_cast<const Sphere&>(a).radius();
  const Vec3& h = static_cast<const Box&>(b).halfExtents();
  const Mat3& rb = pb.linear();
  const Vec3 p = rb.transpose() * (pa.translation() - pb.translation());  // centre in the box frame
  const Vec3 q = p.cwiseMax(-h).cwiseMin(h);
  if ((p - q).squaredNorm() > 0) return pointPair(pa.translation(), r, pb * q, 0.0, Vec3::UnitZ());
  // Centre inside the box: leave through the nearest face.
  int axis = 0;
  double best = h[0] - std::abs(p[0]);
  for (int i = 1; i < 3; ++i)
    if (h[i] - std::abs(p[i]) < best) best = h[i] - std::abs(p[i]), axis = i;
  const double sign = p[axis] >= 0 ? 1.0 : -1.0;
  Vec3 face = p;
  face[axis] = sign * h[axis];
  SignedContact s;
  s.normal = -sign * rb.col(axis);  // the box moves away from the centre
  s.distance = -(best + r);
  s.pointA = pa.translation() + r * s.normal;
  s.pointB = pb * face;
  return s;
}

SignedContact triangleSphere(const Shape& a, const Isometry3& pa, const Shape& b, const Isometry3& pb) {
  const auto& tri = static_cast<const TriangleShape&>(a);
  const Vec3 v0 = pa * tri.vertex(0), v1 = pa * tri.vertex(1), v2 = pa * tri.vertex(2);
  const TriangleClosest c = closestPointOnTriangle(pb.translation(), v0, v1, v2);
  Vec3 n = (v1 - v0).cross(v2 - v0);
  n = n.squaredNorm() > 0 ? Vec3(n.normalized()) : Vec3::UnitZ();
  return pointPair(c.point, 0.0, pb.translation(), static_cast<const Sphere&>(b).radius(), n);
}

}  // namespace

void registerPrimitiveColliders(ColliderTable& table) {
  auto reg = [&](ShapeType x, ShapeType y, const Collider& c) {
    const Status s = table.registerCollider(x, y, c);
    DM_DEMAND(s.ok(), "built-in collider registration");
  };
  reg(ShapeType::Sphere, ShapeType::Sphere, analyticCollider<&sphereSphere>());
  reg(ShapeType::Sphere, ShapeType::Capsule, analyticCollider<&sphereCapsule>());
  reg(ShapeType::Capsule, ShapeType::Capsule, analyticCollider<&capsuleCapsule>());
  reg(ShapeType::Sphere, ShapeType::Box, analyticCollider<&sphereBox>());
  reg(ShapeType::TriangleShape, ShapeType::Sphere, analyticCollider<&triangleSphere>());
}

}  // namespace detail
}  // namespace dm
