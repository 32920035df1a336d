// Exact triangle predicates and triangle distances; see dm/collide/triangle.hpp.
#include <dm/collide/triangle.hpp>
#include <dm/math/geometry.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <utility>

namespace dm {

namespace {

// ---------------------------------------------------------------------------
// Exact signs by floating-point expansions (Shewchuk 1997): a value is an
// array of non-overlapping doubles whose exact sum is the value, so sums and
// products are error-free and the sign is the sign of the largest component.
// Fixed capacity, no allocation. Exact unless a product under- or overflows
// (coordinates within about 1e-100 .. 1e100 m are safe).

constexpr double kEps = 0.5 * std::numeric_limits<double>::epsilon();  // 2^-53
constexpr double kO3dBound = (7.0 + 56.0 * kEps) * kEps;
constexpr double kO2dBound = (3.0 + 16.0 * kEps) * kEps;

struct Expansion {
  int n = 0;
  std::array<double, 256> v;
};

inline void twoSum(double a, double b, double& x, double& y) noexcept {
  x = a + b;
  const double bv = x - a, av = x - bv;
  y = (a - av) + (b - bv);
}
inline void twoProduct(double a, double b, double& x, double& y) noexcept {
  x = a * b;
  y = std::fma(a, b, -x);
}

// e += b (grow_expansion_zeroelim).
void grow(Expansion& e, double b) noexcept {
  double q = b;
  int k = 0;
  for (int i = 0; i < e.n; ++i) {
    double x, y;
    twoSum(q, e.v[i], x, y);
    q = x;
    if (y != 0) e.v[k++] = y;
  }
  if (q != 0 || k == 0) e.v[k++] = q;
  e.n = k;
}
void add(Expansion& e, const Expansion& f) noexcept {
  for (int i = 0; i < f.n; ++i) grow(e, f.v[i]);
}
// out = e · b (scale_expansion_zeroelim).
void scale(const Expansion& e, double b, Expansion& out) noexcept {
  int k = 0;
  double q, h;
  twoProduct(e.v[0], b, q, h);
  if (h != 0) out.v[k++] = h;
  for (int i = 1; i < e.n; ++i) {
    double p1, p0, s;
    twoProduct(e.v[i], b, p1, p0);
    twoSum(q, p0, s, h);
    if (h != 0) out.v[k++] = h;
    twoSum(p1, s, q, h);
    if (h != 0) out.v[k++] = h;
  }
  if (q != 0 || k == 0) out.v[k++] = q;
  out.n = k;
}
// out = e · f.
void multiply(const Expansion& e, const Expansion& f, Expansion& out) noexcept {
  out.n = 0;
  Expansion t;
  for (int j = 0; j < f.n; ++j) {
    scale(e, f.v[j], t);
    add(out, t);
  }
}
void negate(Expansion& e) noexcept {
  for (int i = 0; i < e.n; ++i) e.v[i] = -e.v[i];
}
int sign(const Expansion& e) noexcept {
  for (int i = e.n - 1; i >= 0; --i)
    if (e.v[i] != 0) return e.v[i] > 0 ? 1 : -1;
  return 0;
}
Expansion difference(double a, double b) noexcept {
  Expansion e;
  double x, y;
  twoSum(a, -b, x, y);
  e.n = 0;
  if (y != 0) e.v[e.n++] = y;
  e.v[e.n++] = x;
  return e;
}
// a·d − b·c for 2-term expansions.
Expansion det2(const Expansion& a, const Expansion& b, const Expansion& c, const Expansion& d) noexcept {
  Expansion ad, bc;
  multiply(a, d, ad);
  multiply(b, c, bc);
  negate(bc);
  add(ad, bc);
  return ad;
}

int orient3dExact(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& d) noexcept {
  std::array<Expansion, 3> u, v, w;
  for (int i = 0; i < 3; ++i) {
    u[i] = difference(b[i], a[i]);
    v[i] = difference(c[i], a[i]);
    w[i] = difference(d[i], a[i]);
  }
  Expansion total, term;
  total.n = 0;
  for (int i = 0; i < 3; ++i) {
    const int j = (i + 1) % 3, k = (i + 2) % 3;
    const Expansion minor = det2(v[j], v[k], w[j], w[k]);  // (v × w)_i
    multiply(u[i], minor, term);
    add(total, term);
  }
  return sign(total);
}

int orient2dExact(double ax, double ay, double bx, double by, double cx, double cy) noexcept {
  const Expansion ux = difference(bx, ax), uy = difference(by, ay);
  const Expansion vx = difference(cx, ax), vy = difference(cy, ay);
  return sign(det2(ux, uy, vx, vy));
}

// Sign of (b − a) × (c − a) in the projection onto axes (i, j).
int orient2d(const Vec3& a, const Vec3& b, const Vec3& c, int i, int j) noexcept {
  const double ux = b[i] - a[i], uy = b[j] - a[j], vx = c[i] - a[i], vy = c[j] - a[j];
  const double l = ux * vy, r = uy * vx;
  const double det = l - r;
  const double bound = kO2dBound * (std::abs(l) + std::abs(r));
  if (det > bound) return 1;
  if (-det > bound) return -1;
  return orient2dExact(a[i], a[j], b[i], b[j], c[i], c[j]);
}

constexpr int kProj[3][2] = {{0, 1}, {1, 2}, {2, 0}};

bool degenerate(const Vec3& a, const Vec3& b, const Vec3& c) noexcept {
  for (const auto& p : kProj)
    if (orient2d(a, b, c, p[0], p[1]) != 0) return false;
  return true;
}

// Closed 2-D segment test in projection (i, j), exact.
bool onBox(const Vec3& p, const Vec3& q, const Vec3& r, int i, int j) noexcept {
  return std::min(p[i], q[i]) <= r[i] && r[i] <= std::max(p[i], q[i]) && std::min(p[j], q[j]) <= r[j] &&
         r[j] <= std::max(p[j], q[j]);
}
bool segSeg2d(const Vec3& p, const Vec3& q, const Vec3& r, const Vec3& s, int i, int j) noexcept {
  const int d1 = orient2d(p, q, r, i, j), d2 = orient2d(p, q, s, i, j);
  if (d1 * d2 > 0) return false;
  const int d3 = orient2d(r, s, p, i, j), d4 = orient2d(r, s, q, i, j);
  if (d3 * d4 > 0) return false;
  if (d1 * d2 < 0 && d3 * d4 < 0) return true;
  return (d1 == 0 && onBox(p, q, r, i, j)) || (d2 == 0 && onBox(p, q, s, i, j)) ||
         (d3 == 0 && onBox(r, s, p, i, j)) || (d4 == 0 && onBox(r, s, q, i, j));
}
// Closed point-in-triangle for a triangle non-degenerate in the projection.
bool pointInTri2d(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c, int i, int j) noexcept {
  const int s1 = orient2d(a, b, p, i, j), s2 = orient2d(b, c, p, i, j), s3 = orient2d(c, a, p, i, j);
  return (s1 >= 0 && s2 >= 0 && s3 >= 0) || (s1 <= 0 && s2 <= 0 && s3 <= 0);
}

// For coplanar input the 3-D answer is the AND over the three axis
// projections: intersecting sets stay intersecting in every projection, and
// at least one projection (the plane normal's nonzero axis, or for collinear
// input an axis not along the line) is a bijection of the plane.
bool triTri2d(const std::array<const Vec3*, 3>& t, const std::array<const Vec3*, 3>& u, int i,
              int j) noexcept {
  for (int e = 0; e < 3; ++e)
    for (int f = 0; f < 3; ++f)
      if (segSeg2d(*t[e], *t[(e + 1) % 3], *u[f], *u[(f + 1) % 3], i, j)) return true;
  if (orient2d(*u[0], *u[1], *u[2], i, j) != 0 && pointInTri2d(*t[0], *u[0], *u[1], *u[2], i, j)) return true;
  if (orient2d(*t[0], *t[1], *t[2], i, j) != 0 && pointInTri2d(*u[0], *t[0], *t[1], *t[2], i, j)) return true;
  return false;
}
bool coplanarTriTri(const std::array<const Vec3*, 3>& t, const std::array<const Vec3*, 3>& u) noexcept {
  for (const auto& p : kProj)
    if (!triTri2d(t, u, p[0], p[1])) return false;
  return true;
}

bool segSeg3d(const Vec3& p, const Vec3& q, const Vec3& r, const Vec3& s) noexcept {
  if (orient3d(p, q, r, s) != 0) return false;
  for (const auto& pr : kProj)
    if (!segSeg2d(p, q, r, s, pr[0], pr[1])) return false;
  return true;
}

// Segment against a non-degenerate triangle.
bool segTri3d(const Vec3& p, const Vec3& q, const Vec3& a, const Vec3& b, const Vec3& c) noexcept {
  const int sp = orient3d(a, b, c, p), sq = orient3d(a, b, c, q);
  if (sp * sq > 0) return false;
  if (sp == 0 && sq == 0) {
    const std::array<const Vec3*, 3> s{&p, &q, &q}, t{&a, &b, &c};
    return coplanarTriTri(s, t);
  }
  const int s1 = orient3d(p, q, a, b), s2 = orient3d(p, q, b, c), s3 = orient3d(p, q, c, a);
  return (s1 >= 0 && s2 >= 0 && s3 >= 0) || (s1 <= 0 && s2 <= 0 && s3 <= 0);
}

// Guigue & Devillers, "Fast and robust triangle-triangle overlap test using
// orientation predicates" (JGT 2003), with exact signs.
bool checkMinMax(const Vec3& p1, const Vec3& q1, const Vec3& r1, const Vec3& p2, const Vec3& q2,
                 const Vec3& r2) noexcept {
  if (orient3d(q1, q2, p2, p1) > 0) return false;
  if (orient3d(p1, r2, p2, r1) > 0) return false;
  return true;
}

bool triTri3d(const Vec3& p1, const Vec3& q1, const Vec3& r1, const Vec3& p2, const Vec3& q2, const Vec3& r2,
              int dp2, int dq2, int dr2, bool& coplanar) noexcept {
  if (dp2 > 0) {
    if (dq2 > 0) return checkMinMax(p1, r1, q1, r2, p2, q2);
    if (dr2 > 0) return checkMinMax(p1, r1, q1, q2, r2, p2);
    return checkMinMax(p1, q1, r1, p2, q2, r2);
  }
  if (dp2 < 0) {
    if (dq2 < 0) return checkMinMax(p1, q1, r1, r2, p2, q2);
    if (dr2 < 0) return checkMinMax(p1, q1, r1, q2, r2, p2);
    return checkMinMax(p1, r1, q1, p2, q2, r2);
  }
  if (dq2 < 0) {
    if (dr2 >= 0) return checkMinMax(p1, r1, q1, q2, r2, p2);
    return checkMinMax(p1, q1, r1, p2, q2, r2);
  }
  if (dq2 > 0) {
    if (dr2 > 0) return checkMinMax(p1, r1, q1, p2, q2, r2);
    return checkMinMax(p1, q1, r1, q2, r2, p2);
  }
  if (dr2 > 0) return checkMinMax(p1, q1, r1, r2, p2, q2);
  if (dr2 < 0) return checkMinMax(p1, r1, q1, r2, p2, q2);
  coplanar = true;
  return false;
}

// Exact boolean; sets `coplanar` when both are non-degenerate and coplanar.
bool intersectImpl(const Vec3& p1, const Vec3& q1, const Vec3& r1, const Vec3& p2, const Vec3& q2,
                   const Vec3& r2, bool& coplanar, bool& anyDegenerate) noexcept {
  coplanar = false;
  const bool deg1 = degenerate(p1, q1, r1), deg2 = degenerate(p2, q2, r2);
  anyDegenerate = deg1 || deg2;
  const std::array<const Vec3*, 3> t1{&p1, &q1, &r1}, t2{&p2, &q2, &r2};
  if (deg1 && deg2) {
    for (int e = 0; e < 3; ++e)
      for (int f = 0; f < 3; ++f)
        if (segSeg3d(*t1[e], *t1[(e + 1) % 3], *t2[f], *t2[(f + 1) % 3])) return true;
    return false;
  }
  if (deg1 || deg2) {
    const auto& s = deg1 ? t1 : t2;
    const auto& t = deg1 ? t2 : t1;
    for (int e = 0; e < 3; ++e)
      if (segTri3d(*s[e], *s[(e + 1) % 3], *t[0], *t[1], *t[2])) return true;
    return false;
  }

  const int dp1 = orient3d(r2, p1, p2, q2), dq1 = orient3d(r2, q1, p2, q2), dr1 = orient3d(r2, r1, p2, q2);
  if (dp1 * dq1 > 0 && dp1 * dr1 > 0) return false;
  const int dp2 = orient3d(r1, p2, p1, q1), dq2 = orient3d(r1, q2, p1, q1), dr2 = orient3d(r1, r2, p1, q1);
  if (dp2 * dq2 > 0 && dp2 * dr2 > 0) return false;

  bool result = false;
  if (dp1 > 0) {
    if (dq1 > 0)
      result = triTri3d(r1, p1, q1, p2, r2, q2, dp2, dr2, dq2, coplanar);
    else if (dr1 > 0)
      result = triTri3d(q1, r1, p1, p2, r2, q2, dp2, dr2, dq2, coplanar);
    else
      result = triTri3d(p1, q1, r1, p2, q2, r2, dp2, dq2, dr2, coplanar);
  } else if (dp1 < 0) {
    if (dq1 < 0)
      result = triTri3d(r1, p1, q1, p2, q2, r2, dp2, dq2, dr2, coplanar);
    else if (dr1 < 0)
      result = triTri3d(q1, r1, p1, p2, q2, r2, dp2, dq2, dr2, coplanar);
    else
      result = triTri3d(p1, q1, r1, p2, r2, q2, dp2, dr2, dq2, coplanar);
  } else if (dq1 < 0) {
    if (dr1 >= 0)
      result = triTri3d(q1, r1, p1, p2, r2, q2, dp2, dr2, dq2, coplanar);
    else
      result = triTri3d(p1, q1, r1, p2, q2, r2, dp2, dq2, dr2, coplanar);
  } else if (dq1 > 0) {
    if (dr1 > 0)
      result = triTri3d(p1, q1, r1, p2, r2, q2, dp2, dr2, dq2, coplanar);
    else
      result = triTri3d(q1, r1, p1, p2, q2, r2, dp2, dq2, dr2, coplanar);
  } else if (dr1 > 0) {
    result = triTri3d(r1, p1, q1, p2, q2, r2, dp2, dq2, dr2, coplanar);
  } else if (dr1 < 0) {
    result = triTri3d(r1, p1, q1, p2, r2, q2, dp2, dr2, dq2, coplanar);
  } else {
    coplanar = true;
  }
  if (coplanar) return coplanarTriTri(t1, t2);
  return result;
}

// ---------------------------------------------------------------------------
// Intersection points (double precision, classified with exact signs).

struct PointSet {
  int n = 0;
  std::array<Vec3, 16> p;
  void push(const Vec3& x) noexcept {
    if (n < static_cast<int>(p.size())) p[n++] = x;
  }
};

// Appends the part of segment [p, q] inside non-degenerate triangle (a, b, c).
void clipSegment(const Vec3& p, const Vec3& q, const Vec3& a, const Vec3& b, const Vec3& c,
                 PointSet& out) noexcept {
  const int sp = orient3d(a, b, c, p), sq = orient3d(a, b, c, q);
  if (sp * sq > 0) return;
  const Vec3 n = (b - a).cross(c - a);
  if (sp == 0 && sq == 0) {
    // In the plane: Cyrus–Beck against the three inward edge half-planes.
    double t0 = 0.0, t1 = 1.0;
    const std::array<const Vec3*, 3> v{&a, &b, &c};
    const Vec3 d = q - p;
    for (int e = 0; e < 3; ++e) {
      const Vec3 m = n.cross(*v[(e + 1) % 3] - *v[e]);  // points inside
      const double num = m.dot(p - *v[e]), den = m.dot(d);
      if (den == 0) {
        if (num < 0) return;
      } else if (den > 0) {
        t0 = std::max(t0, -num / den);
      } else {
        t1 = std::min(t1, -num / den);
      }
    }
    if (t0 > t1) return;
    out.push(p + t0 * d);
    out.push(p + t1 * d);
    return;
  }
  const int s1 = orient3d(p, q, a, b), s2 = orient3d(p, q, b, c), s3 = orient3d(p, q, c, a);
  if (!((s1 >= 0 && s2 >= 0 && s3 >= 0) || (s1 <= 0 && s2 <= 0 && s3 <= 0))) return;
  if (sp == 0) {
    out.push(p);
  } else if (sq == 0) {
    out.push(q);
  } else {
    const double dp = n.dot(p - a), dq = n.dot(q - a);
    const double t = std::clamp(dp / (dp - dq), 0.0, 1.0);
    out.push(p + t * (q - p));
  }
}

// Clips convex polygon `poly` (in the plane of triangle abc) by the triangle.
int clipPolygon(std::array<Vec3, 9>& poly, int n, const Vec3& a, const Vec3& b, const Vec3& c) noexcept {
  const Vec3 nrm = (b - a).cross(c - a);
  const std::array<const Vec3*, 3> v{&a, &b, &c};
  std::array<Vec3, 9> tmp;
  for (int e = 0; e < 3 && n > 0; ++e) {
    const Vec3 m = nrm.cross(*v[(e + 1) % 3] - *v[e]);
    int k = 0;
    for (int i = 0; i < n; ++i) {
      const Vec3& x = poly[i];
      const Vec3& y = poly[(i + 1) % n];
      const double dx = m.dot(x - *v[e]), dy = m.dot(y - *v[e]);
      if (dx >= 0 && k < 9) tmp[k++] = x;
      if (((dx >= 0) != (dy >= 0)) && k < 9) tmp[k++] = x + (dx / (dx - dy)) * (y - x);
    }
    n = k;
    for (int i = 0; i < n; ++i) poly[i] = tmp[i];
  }
  return n;
}

// The nine edge pairs of triangles a and b, keeping the closest in
// (best, r). With `stopAtSeparating`, returns true at the first pair whose
// connecting direction has both triangles' third corners on the far sides
// (then that pair is the global minimum, see closestFeatures) unless the
// pair (nearly) touches, where those side tests are rounding noise.
bool closestEdgePair(const std::array<const Vec3*, 3>& a, const std::array<const Vec3*, 3>& b, double& best,
                     TriangleDistance& r, bool stopAtSeparating) noexcept {
  double ea[3], eb[3];  // squared edge lengths
  for (int i = 0; i < 3; ++i) {
    ea[i] = (*a[(i + 1) % 3] - *a[i]).squaredNorm();
    eb[i] = (*b[(i + 1) % 3] - *b[i]).squaredNorm();
  }
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      const SegmentClosest s = closestPointsSegmentSegment(*a[i], *a[(i + 1) % 3], *b[j], *b[(j + 1) % 3]);
      if (s.distanceSq < best) {
        best = s.distanceSq;
        r.pointA = s.pointA;
        r.pointB = s.pointB;
      }
      if (!stopAtSeparating) continue;
      const Vec3 v = s.pointB - s.pointA;
      if (s.distanceSq > 1e-16 * (ea[i] + eb[j]) && v.dot(*a[(i + 2) % 3] - s.pointA) <= 0 &&
          v.dot(*b[(j + 2) % 3] - s.pointB) >= 0) {
        best = s.distanceSq;
        r.pointA = s.pointA;
        r.pointB = s.pointB;
        return true;
      }
    }
  return false;
}

TriangleDistance closestOf15(const Vec3& a0, const Vec3& a1, const Vec3& a2, const Vec3& b0, const Vec3& b1,
                             const Vec3& b2) noexcept {
  const std::array<const Vec3*, 3> a{&a0, &a1, &a2}, b{&b0, &b1, &b2};
  double best = std::numeric_limits<double>::infinity();
  TriangleDistance r;
  for (int i = 0; i < 3; ++i) {
    const TriangleClosest c = closestPointOnTriangle(*a[i], b0, b1, b2);
    if (c.distanceSq < best) {
      best = c.distanceSq;
      r.pointA = *a[i];
      r.pointB = c.point;
    }
    const TriangleClosest d = closestPointOnTriangle(*b[i], a0, a1, a2);
    if (d.distanceSq < best) {
      best = d.distanceSq;
      r.pointA = d.point;
      r.pointB = *b[i];
    }
  }
  closestEdgePair(a, b, best, r, false);
  r.distance = std::sqrt(best);
  return r;
}

// Distance of triangles known not to intersect. Their closest pair is an
// edge–edge pair or a vertex over the interior of the other face (a vertex
// closest to an edge or corner of the other triangle is an edge–edge pair
// already), so the vertex cases need only the projection and three edge
// signs, not a full closest point on the triangle. An edge–edge pair whose
// connecting direction has both triangles' third corners on the far sides
// (of the slab between the two points) is the global minimum: the points
// are each segment's optimum, so every corner of both triangles lies
// outside the slab (Larsen/Gottschalk's test, as in PQP and FCL), and the
// search stops there.
TriangleDistance closestFeatures(const Vec3& a0, const Vec3& a1, const Vec3& a2, const Vec3& b0,
                                 const Vec3& b1, const Vec3& b2) noexcept {
  const std::array<const Vec3*, 3> a{&a0, &a1, &a2}, b{&b0, &b1, &b2};
  double best = std::numeric_limits<double>::infinity();
  TriangleDistance r;
  if (closestEdgePair(a, b, best, r, true)) {
    r.distance = std::sqrt(best);
    return r;
  }
  // Vertex over the other face: p's projection inside triangle t (normal n,
  // non-zero), on the inner side of all three edges.
  auto vertexFace = [&](const Vec3& p, const std::array<const Vec3*, 3>& t, const Vec3& n, double nn,
                        bool pIsA) {
    const Vec3 w = p - *t[0];
    const double h = n.dot(w);
    if (h * h >= best * nn) return;
    if (n.dot((*t[1] - *t[0]).cross(w)) < 0 || n.dot((*t[2] - *t[1]).cross(p - *t[1])) < 0 ||
        n.dot((*t[0] - *t[2]).cross(p - *t[2])) < 0)
      return;
    const Vec3 q = p - (h / nn) * n;
    best = h * h / nn;
    r.pointA = pIsA ? p : q;
    r.pointB = pIsA ? q : p;
  };
  const Vec3 na = (a1 - a0).cross(a2 - a0), nb = (b1 - b0).cross(b2 - b0);
  const double nna = na.squaredNorm(), nnb = nb.squaredNorm();
  if (nnb > 0)
    for (int i = 0; i < 3; ++i) vertexFace(*a[i], b, nb, nnb, true);
  if (nna > 0)
    for (int i = 0; i < 3; ++i) vertexFace(*b[i], a, na, nna, false);
  r.distance = std::sqrt((r.pointA - r.pointB).squaredNorm());
  return r;
}

TriangleIntersection intersectionPoints(const Vec3& p1, const Vec3& q1, const Vec3& r1, const Vec3& p2,
                                        const Vec3& q2, const Vec3& r2, bool coplanar,
                                        bool anyDegenerate) noexcept {
  TriangleIntersection x;
  x.intersects = true;
  x.coplanar = coplanar;
  if (coplanar) {
    std::array<Vec3, 9> poly{p2, q2, r2};
    const int n = clipPolygon(poly, 3, p1, q1, r1);
    x.count = std::min(n, 6);
    for (int i = 0; i < x.count; ++i) x.points[i] = poly[i];
  } else if (!anyDegenerate) {
    PointSet s;
    const std::array<const Vec3*, 3> t1{&p1, &q1, &r1}, t2{&p2, &q2, &r2};
    for (int e = 0; e < 3; ++e) {
      clipSegment(*t1[e], *t1[(e + 1) % 3], p2, q2, r2, s);
      clipSegment(*t2[e], *t2[(e + 1) % 3], p1, q1, r1, s);
    }
    // The intersection is a segment: its endpoints are the farthest pair.
    double far = -1;
    for (int i = 0; i < s.n; ++i)
      for (int j = i; j < s.n; ++j) {
        const double d = (s.p[i] - s.p[j]).squaredNorm();
        if (d > far) {
          far = d;
          x.points[0] = s.p[i];
          x.points[1] = s.p[j];
        }
      }
    x.count = s.n > 0 ? 2 : 0;
  }
  if (x.count == 0) {
    // Degenerate input, or rounding emptied the clip: the closest pair is a
    // common point up to rounding.
    const TriangleDistance d = closestOf15(p1, q1, r1, p2, q2, r2);
    x.points[0] = 0.5 * (d.pointA + d.pointB);
    x.count = 1;
  }
  return x;
}

}  // namespace

int orient3d(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& d) noexcept {
  const double ux = b.x() - a.x(), uy = b.y() - a.y(), uz = b.z() - a.z();
  const double vx = c.x() - a.x(), vy = c.y() - a.y(), vz = c.z() - a.z();
  const double wx = d.x() - a.x(), wy = d.y() - a.y(), wz = d.z() - a.z();
  const double vywz = vy * wz, vzwy = vz * wy, vzwx = vz * wx, vxwz = vx * wz, vxwy = vx * wy, vywx = vy * wx;
  const double det = ux * (vywz - vzwy) + uy * (vzwx - vxwz) + uz * (vxwy - vywx);
  const double permanent = (std::abs(vywz) + std::abs(vzwy)) * std::abs(ux) +
                           (std::abs(vzwx) + std::abs(vxwz)) * std::abs(uy) +
                           (std::abs(vxwy) + std::abs(vywx)) * std::abs(uz);
  const double bound = kO3dBound * permanent;
  if (det > bound) return 1;
  if (-det > bound) return -1;
  return orient3dExact(a, b, c, d);
}

bool trianglesIntersect(const Vec3& a0, const Vec3& a1, const Vec3& a2, const Vec3& b0, const Vec3& b1,
                        const Vec3& b2) noexcept {
  bool coplanar = false, anyDegenerate = false;
  return intersectImpl(a0, a1, a2, b0, b1, b2, coplanar, anyDegenerate);
}

bool segmentTriangleIntersect(const Vec3& p, const Vec3& q, const Vec3& a, const Vec3& b,
                              const Vec3& c) noexcept {
  if (degenerate(a, b, c)) return segSeg3d(p, q, a, b) || segSeg3d(p, q, b, c) || segSeg3d(p, q, c, a);
  return segTri3d(p, q, a, b, c);
}

TriangleIntersection triangleIntersection(const Vec3& a0, const Vec3& a1, const Vec3& a2, const Vec3& b0,
                                          const Vec3& b1, const Vec3& b2) noexcept {
  bool coplanar = false, anyDegenerate = false;
  if (!intersectImpl(a0, a1, a2, b0, b1, b2, coplanar, anyDegenerate)) return {};
  return intersectionPoints(a0, a1, a2, b0, b1, b2, coplanar, anyDegenerate);
}

TriangleDistance triangleDistance(const Vec3& a0, const Vec3& a1, const Vec3& a2, const Vec3& b0,
                                  const Vec3& b1, const Vec3& b2) noexcept {
  bool coplanar = false, anyDegenerate = false;
  if (intersectImpl(a0, a1, a2, b0, b1, b2, coplanar, anyDegenerate)) {
    const TriangleIntersection x = intersectionPoints(a0, a1, a2, b0, b1, b2, coplanar, anyDegenerate);
    return {0.0, x.points[0], x.points[0]};
  }
  return closestFeatures(a0, a1, a2, b0, b1, b2);
}

TriangleDistance separatedTriangleDistance(const Vec3& a0, const Vec3& a1, const Vec3& a2, const Vec3& b0,
                                           const Vec3& b1, const Vec3& b2) noexcept {
  return closestFeatures(a0, a1, a2, b0, b1, b2);
}

TriangleDistance segmentTriangleDistance(const Vec3& p, const Vec3& q, const Vec3& a, const Vec3& b,
                                         const Vec3& c) noexcept {
  TriangleDistance r;
  double best = std::numeric_limits<double>::infinity();
  auto consider = [&](const Vec3& x, const Vec3& y) {
    const double d = (x - y).squaredNorm();
    if (d < best) {
      best = d;
      r.pointA = x;
      r.pointB = y;
    }
  };
  const bool degenerateTri = degenerate(a, b, c);
  if (!degenerateTri && segTri3d(p, q, a, b, c)) {
    PointSet s;
    clipSegment(p, q, a, b, c, s);
    if (s.n > 0) return {0.0, s.p[0], s.p[0]};
  }
  consider(p, closestPointOnTriangle(p, a, b, c).point);
  consider(q, closestPointOnTriangle(q, a, b, c).point);
  const std::array<const Vec3*, 3> v{&a, &b, &c};
  for (int e = 0; e < 3; ++e) {
    const SegmentClosest s = closestPointsSegmentSegment(p, q, *v[e], *v[(e + 1) % 3]);
    consider(s.pointA, s.pointB);
    if (degenerateTri && segSeg3d(p, q, *v[e], *v[(e + 1) % 3])) {
      const Vec3 m = 0.5 * (s.pointA + s.pointB);
      return {0.0, m, m};
    }
  }
  r.distance = std::sqrt(best);
  return r;
}

SegmentClosest closestPointsSegmentSegment(const Vec3& p0, const Vec3& p1, const Vec3& q0,
                                           const Vec3& q1) noexcept {
  // Ericson, Real-Time Collision Detection, 5.1.9, with the parallel and
  // zero-length cases resolved by clamping.
  const Vec3 d1 = p1 - p0, d2 = q1 - q0, r = p0 - q0;
  const double a = d1.squaredNorm(), e = d2.squaredNorm(), f = d2.dot(r);
  double s = 0.0, t = 0.0;
  if (a <= 0.0 && e <= 0.0) {
    s = t = 0.0;
  } else if (a <= 0.0) {
    t = std::clamp(f / e, 0.0, 1.0);
  } else {
    const double c = d1.dot(r);
    if (e <= 0.0) {
      s = std::clamp(-c / a, 0.0, 1.0);
    } else {
      const double b = d1.dot(d2);
      // Ericson's a e - b^2 and b f - c e, written as the Lagrange identities
      // |d1 x d2|^2 and (d1 x d2).(d2 x r): for nearly parallel segments the
      // products cancel to rounding noise (a 1e-9 rad skew leaves 1e-18 of
      // a e), which picked an arbitrary s and missed the closest pair by
      // 1e-9 relative; the cross products keep their relative accuracy.
      const Vec3 n = d1.cross(d2);
      const double denom = n.squaredNorm();
      s = denom > 0.0 ? std::clamp(n.dot(d2.cross(r)) / denom, 0.0, 1.0) : 0.0;
      t = (b * s + f) / e;
      if (t < 0.0) {
        t = 0.0;
        s = std::clamp(-c / a, 0.0, 1.0);
      } else if (t > 1.0) {
        t = 1.0;
        s = std::clamp((b - c) / a, 0.0, 1.0);
      }
    }
  }
  SegmentClosest out;
  out.s = s;
  out.t = t;
  out.pointA = p0 + s * d1;
  out.pointB = q0 + t * d2;
  out.distanceSq = (out.pointA - out.pointB).squaredNorm();
  return out;
}

bool rayTriangle(const Vec3& origin, const Vec3& direction, const Vec3& a, const Vec3& b, const Vec3& c,
                 double tMin, double tMax, RayTriangleHit& hit) noexcept {
  // Woop, Benthin, Wald, "Watertight Ray/Triangle Intersection", JCGT 2013:
  // shear the triangle into the ray's frame so the edge tests are 2-D
  // orientation tests evaluated identically for both triangles of an edge.
  int kz = 0;
  direction.cwiseAbs().maxCoeff(&kz);
  int kx = (kz + 1) % 3, ky = (kx + 1) % 3;
  if (direction[kz] < 0) std::swap(kx, ky);
  if (direction[kz] == 0) return false;
  const double sx = direction[kx] / direction[kz], sy = direction[ky] / direction[kz],
               sz = 1.0 / direction[kz];
  const Vec3 A = a - origin, B = b - origin, C = c - origin;
  const double ax = A[kx] - sx * A[kz], ay = A[ky] - sy * A[kz];
  const double bx = B[kx] - sx * B[kz], by = B[ky] - sy * B[kz];
  const double cx = C[kx] - sx * C[kz], cy = C[ky] - sy * C[kz];
  double u = cx * by - cy * bx, v = ax * cy - ay * cx, w = bx * ay - by * ax;
  if (u == 0 || v == 0 || w == 0) {
    // On an edge in double: decide in extended precision, as the paper does.
    using L = long double;
    u = static_cast<double>(L(cx) * L(by) - L(cy) * L(bx));
    v = static_cast<double>(L(ax) * L(cy) - L(ay) * L(cx));
    w = static_cast<double>(L(bx) * L(ay) - L(by) * L(ax));
  }
  if ((u < 0 || v < 0 || w < 0) && (u > 0 || v > 0 || w > 0)) return false;
  const double det = u + v + w;
  if (det == 0) return false;
  const double az = sz * A[kz], bz = sz * B[kz], cz = sz * C[kz];
  const double t = (u * az + v * bz + w * cz) / det;
  if (!(t >= tMin && t <= tMax)) return false;
  hit.t = t;
  hit.barycentric = Vec3(u / det, v / det, w / det);
  return true;
}

}  // namespace dm
