// Closest-point primitives; see dm/math/geometry.hpp.
#include <dm/math/geometry.hpp>

#include <algorithm>
#include <cmath>

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

// The closest-point tests below are the innermost loop of mesh distance
// queries, simplification and GJK, so they work on the coordinates as plain
// doubles: the same code as the Eigen expressions at -O2, but at the
// sanitizer trees' -O1 each expression is a chain of checked calls, which
// made them the bulk of the slowest ASan tests.
struct P3 {
  double x, y, z;
};
P3 load(const Vec3& v) { return {v.data()[0], v.data()[1], v.data()[2]}; }
P3 operator-(const P3& u, const P3& v) { return {u.x - v.x, u.y - v.y, u.z - v.z}; }
P3 cross(const P3& u, const P3& v) {
  return {u.y * v.z - u.z * v.y, u.z * v.x - u.x * v.z, u.x * v.y - u.y * v.x};
}
double dot(const P3& u, const P3& v) { return u.x * v.x + u.y * v.y + u.z * v.z; }
// o + s·d
Vec3 along(const P3& o, double s, const P3& d) { return {o.x + s * d.x, o.y + s * d.y, o.z + s * d.z}; }

TriangleClosest make(const P3& p, const Vec3& q, const Vec3& bary, TriangleFeature f) {
  const P3 d = p - load(q);
  return {q, dot(d, d), bary, f};
}

// Closest point over the three edges: the answer for degenerate triangles,
// where the face region is empty.
TriangleClosest closestOnEdges(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  double t0 = 0, t1 = 0, t2 = 0;
  const Vec3 q0 = closestPointOnSegment(p, a, b, &t0);
  const Vec3 q1 = closestPointOnSegment(p, b, c, &t1);
  const Vec3 q2 = closestPointOnSegment(p, c, a, &t2);
  const P3 pp = load(p);
  TriangleClosest best = make(pp, q0, Vec3(1 - t0, t0, 0), TriangleFeature::EdgeAB);
  TriangleClosest e1 = make(pp, q1, Vec3(0, 1 - t1, t1), TriangleFeature::EdgeBC);
  TriangleClosest e2 = make(pp, q2, Vec3(t2, 0, 1 - t2), TriangleFeature::EdgeCA);
  if (e1.distanceSq < best.distanceSq) best = e1;
  if (e2.distanceSq < best.distanceSq) best = e2;
  return best;
}

}  // namespace

TriangleClosest closestPointOnTriangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) noexcept {
  const P3 P = load(p), A = load(a), B = load(b), C = load(c);
  const P3 ab = B - A, ac = C - A, ap = P - A;
  // A triangle with (numerically) zero area has no face region.
  const P3 n = cross(ab, ac);
  const double area2 = dot(n, n);
  const double scale = std::max(dot(ab, ab), dot(ac, ac));
  if (!(area2 > 1e-24 * scale * scale)) return closestOnEdges(p, a, b, c);

  const double d1 = dot(ab, ap), d2 = dot(ac, ap);
  if (d1 <= 0 && d2 <= 0) return make(P, a, Vec3(1, 0, 0), TriangleFeature::VertexA);
  const P3 bp = P - B;
  const double d3 = dot(ab, bp), d4 = dot(ac, bp);
  if (d3 >= 0 && d4 <= d3) return make(P, b, Vec3(0, 1, 0), TriangleFeature::VertexB);
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) {
    const double v = d1 / (d1 - d3);
    return make(P, along(A, v, ab), Vec3(1 - v, v, 0), TriangleFeature::EdgeAB);
  }
  const P3 cp = P - C;
  const double d5 = dot(ab, cp), d6 = dot(ac, cp);
  if (d6 >= 0 && d5 <= d6) return make(P, c, Vec3(0, 0, 1), TriangleFeature::VertexC);
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) {
    const double w = d2 / (d2 - d6);
    return make(P, along(A, w, ac), Vec3(1 - w, 0, w), TriangleFeature::EdgeCA);
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    return make(P, along(B, w, C - B), Vec3(0, 1 - w, w), TriangleFeature::EdgeBC);
  }
  // Face region. Ericson's vb / (va + vb + vc) loses the digits of a
  // sliver's thin direction; planeBarycentric() keeps them.
  const Vec3 l = planeBarycentric(p, a, b, c);
  const Vec3 q(l[0] * A.x + l[1] * B.x + l[2] * C.x, l[0] * A.y + l[1] * B.y + l[2] * C.y,
               l[0] * A.z + l[1] * B.z + l[2] * C.z);
  return make(P, q, l, TriangleFeature::Face);
}

Vec3 planeBarycentric(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) noexcept {
  const P3 v[3] = {load(a), load(b), load(c)};
  const P3 bc = v[2] - v[1], ca = v[0] - v[2], ab = v[1] - v[0];
  const double opposite[3] = {dot(bc, bc), dot(ca, ca), dot(ab, ab)};
  const int o =
      opposite[0] >= opposite[1] && opposite[0] >= opposite[2] ? 0 : (opposite[1] >= opposite[2] ? 1 : 2);
  const int i1 = (o + 1) % 3, i2 = (o + 2) % 3;
  const P3 e0 = v[i1] - v[o], e1 = v[i2] - v[o], q = load(p) - v[o];
  const double d00 = dot(e0, e0), d01 = dot(e0, e1), d11 = dot(e1, e1);
  const double d20 = dot(q, e0), d21 = dot(q, e1);
  const double den = d00 * d11 - d01 * d01;
  double l[3];
  l[i1] = (d11 * d20 - d01 * d21) / den;
  l[i2] = (d00 * d21 - d01 * d20) / den;
  l[o] = 1.0 - l[i1] - l[i2];
  return {l[0], l[1], l[2]};
}

double solidAngle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) noexcept {
  const Vec3 ra = a - p, rb = b - p, rc = c - p;
  const double la = ra.norm(), lb = rb.norm(), lc = rc.norm();
  const double numerator = ra.dot(rb.cross(rc));
  const double denominator = la * lb * lc + ra.dot(rb) * lc + rb.dot(rc) * la + rc.dot(ra) * lb;
  return 2.0 * std::atan2(numerator, denominator);
}

}  // namespace dm
