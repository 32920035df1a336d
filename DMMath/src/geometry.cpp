// Closest-point primitives; see dm/math/geometry.hpp.
#include <dm/math/geometry.hpp>

#include <algorithm>

namespace dm {

Vec3 closestPointOnSegment(const Vec3& p, const Vec3& a, const Vec3& b, double* t) noexcept {
  const Vec3 ab = b - a;
  const double len2 = ab.squaredNorm();
  double s = 0.0;
  if (len2 > 0.0) s = std::clamp((p - a).dot(ab) / len2, 0.0, 1.0);
  if (t) *t = s;
  return a + s * ab;
}

namespace {

TriangleClosest make(const Vec3& p, const Vec3& q, const Vec3& bary, TriangleFeature f) {
  return {q, (p - q).squaredNorm(), bary, f};
}

// Closest point over the three edges: the answer for degenerate triangles,
// where the face region is empty.
TriangleClosest closestOnEdges(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  double t0 = 0, t1 = 0, t2 = 0;
  const Vec3 q0 = closestPointOnSegment(p, a, b, &t0);
  const Vec3 q1 = closestPointOnSegment(p, b, c, &t1);
  const Vec3 q2 = closestPointOnSegment(p, c, a, &t2);
  TriangleClosest best = make(p, q0, Vec3(1 - t0, t0, 0), TriangleFeature::EdgeAB);
  TriangleClosest e1 = make(p, q1, Vec3(0, 1 - t1, t1), TriangleFeature::EdgeBC);
  TriangleClosest e2 = make(p, q2, Vec3(t2, 0, 1 - t2), TriangleFeature::EdgeCA);
  if (e1.distanceSq < best.distanceSq) best = e1;
  if (e2.distanceSq < best.distanceSq) best = e2;
  return best;
}

}  // namespace

TriangleClosest closestPointOnTriangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) noexcept {
  const Vec3 ab = b - a, ac = c - a, ap = p - a;
  // A triangle with (numerically) zero area has no face region.
  const double area2 = ab.cross(ac).squaredNorm();
  const double scale = std::max(ab.squaredNorm(), ac.squaredNorm());
  if (!(area2 > 1e-24 * scale * scale)) return closestOnEdges(p, a, b, c);

  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return make(p, a, Vec3(1, 0, 0), TriangleFeature::VertexA);
  const Vec3 bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return make(p, b, Vec3(0, 1, 0), TriangleFeature::VertexB);
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) {
    const double v = d1 / (d1 - d3);
    return make(p, a + v * ab, Vec3(1 - v, v, 0), TriangleFeature::EdgeAB);
  }
  const Vec3 cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return make(p, c, Vec3(0, 0, 1), TriangleFeature::VertexC);
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) {
    const double w = d2 / (d2 - d6);
    return make(p, a + w * ac, Vec3(1 - w, 0, w), TriangleFeature::EdgeCA);
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    return make(p, b + w * (c - b), Vec3(0, 1 - w, w), TriangleFeature::EdgeBC);
  }
  // Face region. Ericson's vb / (va + vb + vc) loses the digits of a
  // sliver's thin direction; planeBarycentric() keeps them.
  const Vec3 l = planeBarycentric(p, a, b, c);
  return make(p, l[0] * a + l[1] * b + l[2] * c, l, TriangleFeature::Face);
}

Vec3 planeBarycentric(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) noexcept {
  const Vec3* v[3] = {&a, &b, &c};
  const double opposite[3] = {(c - b).squaredNorm(), (a - c).squaredNorm(), (b - a).squaredNorm()};
  const int o =
      opposite[0] >= opposite[1] && opposite[0] >= opposite[2] ? 0 : (opposite[1] >= opposite[2] ? 1 : 2);
  const int i1 = (o + 1) % 3, i2 = (o + 2) % 3;
  const Vec3 e0 = *v[i1] - *v[o], e1 = *v[i2] - *v[o], q = p - *v[o];
  const double d00 = e0.dot(e0), d01 = e0.dot(e1), d11 = e1.dot(e1);
  const double d20 = q.dot(e0), d21 = q.dot(e1);
  const double den = d00 * d11 - d01 * d01;
  Vec3 l;
  l[i1] = (d11 * d20 - d01 * d21) / den;
  l[i2] = (d00 * d21 - d01 * d20) / den;
  l[o] = 1.0 - l[i1] - l[i2];
  return l;
}

}  // namespace dm
