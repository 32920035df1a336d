// Motion interpolation, conservative advancement and the bisection resolver;
// see dm/collide/toi.hpp. The mesh sweeps are in toi_mesh.cpp.
#include <dm/collide/toi.hpp>

#include <algorithm>
#include <cmath>
#include <limits>

namespace dm {

Isometry3 Motion::at(double t) const noexcept {
  // Exact end poses, so that a query at t = 0 or 1 sees the caller's poses.
  if (t == 0.0) return start;
  if (t == 1.0) return end;
  const Quat q0(start.linear()), q1(end.linear());
  Isometry3 pose = Isometry3::Identity();
  pose.linear() = q0.slerp(t, q1).normalized().toRotationMatrix();  // shortest path, constant rate
  pose.translation() = (1.0 - t) * start.translation() + t * end.translation();
  return pose;
}

Vec3 Motion::rotationVector() const noexcept {
  if (start.linear() == end.linear()) return Vec3::Zero();
  const Quat q0(start.linear()), q1(end.linear());
  // World-frame step rotation q1·q0⁻¹; AngleAxis picks the angle in [0, π],
  // the same path as slerp(q0, q1).
  const AngleAxis step((q1 * q0.conjugate()).normalized());
  return step.axis() * step.angle();
}

double Motion::maxPointDisplacement(double radius) const noexcept {
  const double linear = displacement().norm();
  if (start.linear() == end.linear()) return linear;
  return linear + rotationVector().norm() * radius;
}

namespace {

// Plane is a convex set too, though not a ConvexShape: the separating-plane
// argument of the directional bound holds for it.
bool convexSet(const Shape& s) noexcept { return s.isConvex() || s.type() == ShapeType::Plane; }

// Radius of a sphere about the frame origin containing the shape (+∞ for
// unbounded shapes).
double frameRadius(const Shape& s) noexcept {
  const BoundingSphere bs = s.boundingSphere();
  const double r = bs.center.norm() + bs.radius;
  return std::isfinite(r) ? r : std::numeric_limits<double>::infinity();
}

// |n × ω|·r (or |ω|·r for a zero n), 0 without rotation even for r = ∞.
double rotationTerm(const Vec3& n, const Vec3& omega, double r) noexcept {
  if (omega.isZero(0.0)) return 0.0;
  return (n.isZero(0.0) ? omega.norm() : n.cross(omega).norm()) * r;
}

// Contact at pose pair (pa, pb): the deepest contact of dm::collide, or the
// distance query's points when the collider reports none (exact touching).
void fillContact(const Shape& a, const Isometry3& pa, const Shape& b, const Isometry3& pb, ToiResult& r) {
  CollisionRequest request;
  request.maxContacts = 1;
  const CollisionResult c = collide(a, pa, b, pb, request);
  if (!c.contacts.empty()) {
    const ContactPoint* deepest = &c.contacts.front();
    for (const ContactPoint& p : c.contacts)
      if (p.depth > deepest->depth) deepest = &p;
    r.point = deepest->position;
    r.normal = deepest->normal;
    r.distance = -deepest->depth;
    return;
  }
  const DistanceResult d = distance(a, pa, b, pb);
  r.point = 0.5 * (d.pointA + d.pointB);
  r.distance = std::isnan(d.distance) ? 0.0 : d.distance;
}

ToiResult finish(ToiResult r, ToiStatus status) noexcept {
  r.status = status;
  r.hit = status == ToiStatus::Hit || status == ToiStatus::Overlapping;
  if (status == ToiStatus::NoHit) r.t = 1.0;
  return r;
}

}  // namespace

ToiResult conservativeAdvancement(const Shape& a, const Motion& motionA, const Shape& b,
                                  const Motion& motionB, const ToiOptions& options, PairCache* cache) {
  ToiResult result;
  const double tolerance = std::max(options.tolerance, 1e-15);
  const Vec3 omegaA = motionA.rotationVector(), omegaB = motionB.rotationVector();
  const double rA = frameRadius(a), rB = frameRadius(b);
  // A rotating unbounded shape sweeps points at unbounded speed.
  if ((!omegaA.isZero(0.0) && std::isinf(rA)) || (!omegaB.isZero(0.0) && std::isinf(rB)))
    return finish(result, ToiStatus::Unsupported);
  const Vec3 dx = motionA.displacement() - motionB.displacement();
  const bool convex = convexSet(a) && convexSet(b);
  const double fullBound =
      dx.norm() + rotationTerm(Vec3::Zero(), omegaA, rA) + rotationTerm(Vec3::Zero(), omegaB, rB);

  PairCache local;
  PairCache* pc = cache ? cache : &local;
  // Until a separated pair gives a direction: B's approach direction.
  Vec3 normal = dx.isZero(0.0) ? Vec3(Vec3::UnitZ()) : Vec3(dx.normalized());
  double t = 0.0;
  for (int iteration = 0; iteration < options.maxIterations; ++iteration) {
    const Isometry3 pa = motionA.at(t), pb = motionB.at(t);
    const DistanceResult d = distance(a, pa, b, pb, pc);
    ++result.iterations;
    if (!d.supported || std::isnan(d.distance)) return finish(result, ToiStatus::Unsupported);
    const Vec3 gap = d.pointB - d.pointA;
    const double gapNorm = gap.norm();
    if (d.distance > 0 && gapNorm > 0) normal = gap / gapNorm;
    result.t = t;
    result.distance = d.distance;
    result.point = 0.5 * (d.pointA + d.pointB);
    result.normal = normal;
    if (d.distance < tolerance) {
      if (t == 0.0 && d.distance <= 0.0) {
        fillContact(a, pa, b, pb, result);
        return finish(result, ToiStatus::Overlapping);
      }
      return finish(result, ToiStatus::Hit);
    }
    // Rate at which the distance can shrink (per unit t), see the header.
    const double bound = convex && gapNorm > 0 ? normal.dot(dx) + rotationTerm(normal, omegaA, rA) +
                                                     rotationTerm(normal, omegaB, rB)
                                               : fullBound;
    if (!(bound > 0)) return finish(result, ToiStatus::NoHit);
    t += d.distance / bound;
    if (t > 1.0) return finish(result, ToiStatus::NoHit);
  }
  return finish(result, ToiStatus::MaxIterations);
}

ToiResult bisectImpact(const Shape& a, const Motion& motionA, const Shape& b, const Motion& motionB,
                       const BisectOptions& options) {
  ToiResult result;
  bool swapped = false;
  if (!ColliderTable::global().find(a, b, swapped)) return finish(result, ToiStatus::Unsupported);
  const int samples = std::max(options.samples, 1);
  const double tolerance = std::max(options.tolerance, 1e-15);
  PairCache cache;  // warm start across the nearby times
  auto overlaps = [&](double t) {
    ++result.iterations;
    return intersect(a, motionA.at(t), b, motionB.at(t), &cache);
  };
  if (overlaps(0.0)) {
    result.t = 0.0;
    fillContact(a, motionA.start, b, motionB.start, result);
    return finish(result, ToiStatus::Overlapping);
  }
  double lo = 0.0, hi = -1.0;
  for (int i = 1; i <= samples; ++i) {
    const double t = double(i) / samples;
    if (overlaps(t)) {
      hi = t;
      break;
    }
    lo = t;
  }
  if (hi < 0) return finish(result, ToiStatus::NoHit);
  for (int i = 0; i < options.maxIterations && hi - lo > tolerance; ++i) {
    const double mid = 0.5 * (lo + hi);
    (overlaps(mid) ? hi : lo) = mid;
  }
  result.t = hi;
  fillContact(a, motionA.at(hi), b, motionB.at(hi), result);
  return finish(result, ToiStatus::Hit);
}

}  // namespace dm
