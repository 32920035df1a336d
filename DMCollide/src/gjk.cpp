// GJK distance and EPA penetration; see dm/collide/gjk.hpp.
//
// Both algorithms run in A's local frame: B's support points are mapped by
// the relative pose once per query, which saves a rotation per support call.
#include <dm/collide/gjk.hpp>
#include <dm/math/geometry.hpp>

#include <algorithm>
#include <cmath>
#include <limits>

namespace dm {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// A point of the Minkowski difference A − B with the two support points it
// came from (all in A's frame).
struct Vertex {
  Vec3 w, a, b;
};

struct MinkowskiPair {
  const ConvexShape& A;
  const ConvexShape& B;
  Mat3 r;  // B's frame → A's frame
  Vec3 t;
  std::uint32_t hintA = 0, hintB = 0;

  MinkowskiPair(const ConvexShape& a, const Isometry3& poseA, const ConvexShape& b, const Isometry3& poseB)
      : A(a), B(b) {
    const Mat3 ra = poseA.linear();
    r = ra.transpose() * poseB.linear();
    t = ra.transpose() * (poseB.translation() - poseA.translation());
  }

  // Support of A − B along d (A's frame).
  Vertex support(const Vec3& d) noexcept {
    Vertex v;
    v.a = A.supportCore(d, hintA);
    v.b = r * B.supportCore(-(r.transpose() * d), hintB) + t;
    v.w = v.a - v.b;
    return v;
  }
};

struct Simplex {
  Vertex v[4];
  double lambda[4] = {1, 0, 0, 0};
  int n = 0;
};

// Keeps the vertices of triangle (i0, i1, i2) on the feature the closest
// point lies on, with their barycentric weights.
void reduceToFeature(Simplex& s, int i0, int i1, int i2, const TriangleClosest& c) {
  const Vertex a = s.v[i0], b = s.v[i1], d = s.v[i2];
  const Vec3& l = c.barycentric;
  switch (c.feature) {
    case TriangleFeature::VertexA:
      s.v[0] = a, s.lambda[0] = 1, s.n = 1;
      break;
    case TriangleFeature::VertexB:
      s.v[0] = b, s.lambda[0] = 1, s.n = 1;
      break;
    case TriangleFeature::VertexC:
      s.v[0] = d, s.lambda[0] = 1, s.n = 1;
      break;
    case TriangleFeature::EdgeAB:
      s.v[0] = a, s.v[1] = b, s.lambda[0] = l[0], s.lambda[1] = l[1], s.n = 2;
      break;
    case TriangleFeature::EdgeBC:
      s.v[0] = b, s.v[1] = d, s.lambda[0] = l[1], s.lambda[1] = l[2], s.n = 2;
      break;
    case TriangleFeature::EdgeCA:
      s.v[0] = d, s.v[1] = a, s.lambda[0] = l[2], s.lambda[1] = l[0], s.n = 2;
      break;
    case TriangleFeature::Face:
      s.v[0] = a, s.v[1] = b, s.v[2] = d;
      s.lambda[0] = l[0], s.lambda[1] = l[1], s.lambda[2] = l[2], s.n = 3;
      break;
  }
}

// Replaces `v` by the point of the simplex closest to the origin and drops
// the vertices not needed to express it. Returns true when the origin lies
// inside the tetrahedron (the cores overlap).
bool closestOnSimplex(Simplex& s, Vec3& v) noexcept {
  switch (s.n) {
    case 1:
      s.lambda[0] = 1;
      v = s.v[0].w;
      return false;
    case 2: {
      double t = 0;
      v = closestPointOnSegment(Vec3::Zero(), s.v[0].w, s.v[1].w, &t);
      if (t <= 0) {
        s.n = 1, s.lambda[0] = 1;
      } else if (t >= 1) {
        s.v[0] = s.v[1], s.n = 1, s.lambda[0] = 1;
      } else {
        s.lambda[0] = 1 - t, s.lambda[1] = t;
      }
      return false;
    }
    case 3: {
      const TriangleClosest c = closestPointOnTriangle(Vec3::Zero(), s.v[0].w, s.v[1].w, s.v[2].w);
      v = c.point;
      reduceToFeature(s, 0, 1, 2, c);
      return false;
    }
    default: {
      // Faces of the tetrahedron with their opposite vertex. The origin is
      // outside a face when it lies on the other side of its plane than the
      // opposite vertex. A (nearly) flat tetrahedron cannot hold the origin
      // and its side tests are rounding noise, so all its faces are examined.
      static constexpr int kFaces[4][4] = {{0, 1, 2, 3}, {0, 3, 1, 2}, {0, 2, 3, 1}, {1, 3, 2, 0}};
      const Vec3 e1 = s.v[1].w - s.v[0].w, e2 = s.v[2].w - s.v[0].w, e3 = s.v[3].w - s.v[0].w;
      const double volume = e1.dot(e2.cross(e3));
      const bool flat = std::abs(volume) <= 1e-6 * e1.norm() * e2.norm() * e3.norm();
      TriangleClosest best;
      best.distanceSq = kInf;
      int bestFace = -1;
      for (int f = 0; f < 4; ++f) {
        const Vec3& p0 = s.v[kFaces[f][0]].w;
        const Vec3& p1 = s.v[kFaces[f][1]].w;
        const Vec3& p2 = s.v[kFaces[f][2]].w;
        if (!flat) {
          // Skip the face only when both side tests are clear; an opposite
          // vertex (nearly) on the face's plane says nothing.
          const Vec3 n = (p1 - p0).cross(p2 - p0);
          const Vec3 e = s.v[kFaces[f][3]].w - p0;
          const double sideOpp = n.dot(e);
          const bool clear = sideOpp * sideOpp > 1e-20 * n.squaredNorm() * e.squaredNorm();
          if (clear && (-n.dot(p0)) * sideOpp >= 0) continue;
        }
        const TriangleClosest c = closestPointOnTriangle(Vec3::Zero(), p0, p1, p2);
        if (c.distanceSq < best.distanceSq) best = c, bestFace = f;
      }
      if (bestFace < 0) {
        v.setZero();
        return true;
      }
      v = best.point;
      reduceToFeature(s, kFaces[bestFace][0], kFaces[bestFace][1], kFaces[bestFace][2], best);
      return false;
    }
  }
}

enum class GjkStop { Separated, Within, Overlap, Converged };

// GJK on the cores. Stops early when the distance is known to be above
// `stopAbove` (lower bound) or at most `stopWithin` (upper bound).
GjkStop runGjk(MinkowskiPair& m, const Vec3& dir0, double stopWithin, double stopAbove, const GjkOptions& opt,
               Simplex& s, Vec3& v, int& iterations) noexcept {
  s.n = 1;
  s.v[0] = m.support(-dir0);
  s.lambda[0] = 1;
  v = s.v[0].w;
  double scale = v.squaredNorm();
  const double within2 = stopWithin >= 0 ? stopWithin * stopWithin : -1.0;
  const double above2 = stopAbove * stopAbove;
  for (iterations = 0; iterations < opt.maxIterations; ++iterations) {
    const double vv = v.squaredNorm();
    if (vv <= within2) return GjkStop::Within;
    if (vv <= 1e-26 * scale) return GjkStop::Overlap;  // touching to rounding
    const Vertex w = m.support(-v);
    const double vw = v.dot(w.w);
    scale = std::max(scale, w.w.squaredNorm());
    if (vw > 0 && vw * vw > vv * above2) return GjkStop::Separated;
    if (vv - vw <= opt.relativeTolerance * vv) return GjkStop::Converged;
    for (int i = 0; i < s.n; ++i)
      if (s.v[i].w == w.w) return GjkStop::Converged;
    const Simplex previous = s;
    const Vec3 vPrevious = v;
    s.v[s.n++] = w;
    if (closestOnSimplex(s, v)) return GjkStop::Overlap;
    if (v.squaredNorm() >= vv) {
      // No progress: rounding floor (often a sliver tetrahedron whose side
      // tests are noise). The previous simplex is the better answer.
      s = previous;
      v = vPrevious;
      return GjkStop::Converged;
    }
  }
  return GjkStop::Converged;
}

Vec3 startDirection(const GjkCache* cache, const Isometry3& poseA, const MinkowskiPair& m) {
  if (cache && cache->direction.squaredNorm() > 0) return poseA.linear().transpose() * cache->direction;
  // Centre of A minus centre of B lies in A − B for symmetric shapes.
  if (m.t.squaredNorm() > 0) return -m.t;
  return Vec3::UnitX();
}

// ------------------------------------------------------------------ EPA ---

struct EpaFace {
  int v[3];
  Vec3 n;
  double d;
  bool alive;
};

constexpr int kEpaMaxVertices = 128;
constexpr int kEpaMaxFaces = 2 * kEpaMaxVertices;

struct Epa {
  Vertex vert[kEpaMaxVertices];
  EpaFace face[kEpaMaxFaces];
  int nv = 0, nf = 0;

  bool addFace(int a, int b, int c) {
    if (nf == kEpaMaxFaces) return false;
    EpaFace& f = face[nf++];
    f.v[0] = a, f.v[1] = b, f.v[2] = c;
    const Vec3 n = (vert[b].w - vert[a].w).cross(vert[c].w - vert[a].w);
    const double len = n.norm();
    f.alive = true;
    if (len > 0) {
      f.n = n / len;
      f.d = f.n.dot(vert[a].w);
    } else {
      // Degenerate sliver: never the closest face; removed when seen.
      f.n = Vec3::UnitX();
      f.d = kInf;
    }
    return true;
  }
};

// Completes a simplex to a tetrahedron enclosing a volume of A − B by extra
// support queries. False when A − B is flat (no volume in any direction).
bool blowUp(MinkowskiPair& m, Simplex& s) {
  const double scale = std::max({s.v[0].w.squaredNorm(), 1e-300});
  auto distinct = [&](const Vertex& w) {
    for (int i = 0; i < s.n; ++i)
      if ((w.w - s.v[i].w).squaredNorm() <= 1e-24 * scale) return false;
    return true;
  };
  if (s.n == 1) {
    static const Vec3 kAxes[6] = {Vec3::UnitX(),  -Vec3::UnitX(), Vec3::UnitY(),
                                  -Vec3::UnitY(), Vec3::UnitZ(),  -Vec3::UnitZ()};
    for (const Vec3& d : kAxes) {
      const Vertex w = m.support(d);
      if (distinct(w)) {
        s.v[s.n++] = w;
        break;
      }
    }
    if (s.n < 2) return false;
  }
  if (s.n == 2) {
    const Vec3 e = (s.v[1].w - s.v[0].w).normalized();
    Vec3 u = e.unitOrthogonal();
    const Vec3 u2 = e.cross(u);
    for (int k = 0; k < 6 && s.n < 3; ++k) {
      const double ang = k * (2.0 * 3.14159265358979323846 / 6.0);
      const Vec3 d = std::cos(ang) * u + std::sin(ang) * u2;
      const Vertex w = m.support(d);
      const Vec3 c = (w.w - s.v[0].w).cross(s.v[1].w - s.v[0].w);
      if (c.squaredNorm() > 1e-24 * scale * (s.v[1].w - s.v[0].w).squaredNorm()) s.v[s.n++] = w;
    }
    if (s.n < 3) return false;
  }
  if (s.n == 3) {
    const Vec3 n = (s.v[1].w - s.v[0].w).cross(s.v[2].w - s.v[0].w);
    const double nn = n.norm();
    if (nn == 0) return false;
    const Vertex up = m.support(n), down = m.support(-n);
    const double hu = n.dot(up.w - s.v[0].w) / nn, hd = -n.dot(down.w - s.v[0].w) / nn;
    const double tol = 1e-12 * std::sqrt(scale);
    if (std::max(hu, hd) <= tol) return false;
    s.v[s.n++] = hu >= hd ? up : down;
  }
  return true;
}

struct EpaOut {
  Vec3 n;
  double depth;
  Vec3 pa, pb;  // A's frame
  bool exact;
};

EpaOut runEpa(MinkowskiPair& m, Simplex s, const GjkOptions& opt) noexcept {
  EpaOut out{Vec3::UnitX(), 0.0, s.v[0].a, s.v[0].b, false};
  if (!blowUp(m, s)) {
    // Flat Minkowski difference: touching in a plane, depth 0 within the
    // cores. Pick the plane normal if there is one.
    if (s.n == 3) {
      const Vec3 n = (s.v[1].w - s.v[0].w).cross(s.v[2].w - s.v[0].w);
      if (n.squaredNorm() > 0) out.n = n.normalized();
    } else if (s.n == 2) {
      out.n = (s.v[1].w - s.v[0].w).unitOrthogonal();
    }
    return out;
  }
  Epa e;
  for (int i = 0; i < 4; ++i) e.vert[i] = s.v[i];
  e.nv = 4;
  // Orient the tetrahedron so its faces point outwards.
  if ((e.vert[1].w - e.vert[0].w).cross(e.vert[2].w - e.vert[0].w).dot(e.vert[3].w - e.vert[0].w) > 0)
    std::swap(e.vert[1], e.vert[2]);
  e.addFace(0, 1, 2), e.addFace(0, 3, 1), e.addFace(0, 2, 3), e.addFace(1, 3, 2);

  double scale = 0;
  for (int i = 0; i < 4; ++i) scale = std::max(scale, e.vert[i].w.norm());
  const double tol = opt.epaTolerance * scale;

  int best = -1;
  int edges[3 * kEpaMaxFaces][2];
  for (int iter = 0; iter < opt.maxEpaIterations; ++iter) {
    best = -1;
    for (int f = 0; f < e.nf; ++f)
      if (e.face[f].alive && (best < 0 || e.face[f].d < e.face[best].d)) best = f;
    if (best < 0) break;
    const EpaFace bf = e.face[best];
    if (e.nv == kEpaMaxVertices) break;
    const Vertex w = m.support(bf.n);
    if (bf.n.dot(w.w) - bf.d <= tol) break;  // the face is on the boundary
    const int iw = e.nv;
    e.vert[e.nv++] = w;
    // Remove every face that sees the new vertex; the edges left with one
    // removed neighbour form the horizon.
    int ne = 0;
    for (int f = 0; f < e.nf; ++f) {
      EpaFace& fc = e.face[f];
      if (!fc.alive) continue;
      if (fc.d != kInf && fc.n.dot(w.w - e.vert[fc.v[0]].w) <= tol * 1e-3) continue;
      fc.alive = false;
      for (int k = 0; k < 3; ++k) {
        const int a = fc.v[k], b = fc.v[(k + 1) % 3];
        bool cancelled = false;
        for (int j = 0; j < ne; ++j)
          if (edges[j][0] == b && edges[j][1] == a) {
            edges[j][0] = edges[ne - 1][0], edges[j][1] = edges[ne - 1][1];
            --ne;
            cancelled = true;
            break;
          }
        if (!cancelled) edges[ne][0] = a, edges[ne][1] = b, ++ne;
      }
    }
    bool full = false;
    for (int j = 0; j < ne && !full; ++j) full = !e.addFace(edges[j][0], edges[j][1], iw);
    // Compact dead faces so the scan stays short and capacity is reused.
    int k = 0;
    for (int f = 0; f < e.nf; ++f)
      if (e.face[f].alive) e.face[k++] = e.face[f];
    e.nf = k;
    if (full) break;
  }
  best = -1;
  for (int f = 0; f < e.nf; ++f)
    if (e.face[f].alive && (best < 0 || e.face[f].d < e.face[best].d)) best = f;
  if (best < 0 || e.face[best].d == kInf) return out;
  const EpaFace& f = e.face[best];
  const Vertex& a = e.vert[f.v[0]];
  const Vertex& b = e.vert[f.v[1]];
  const Vertex& c = e.vert[f.v[2]];
  // Barycentric coordinates of the origin's projection on the face plane,
  // not clamped to the triangle: when a flat face of the shapes is split into
  // coplanar triangles the nearest one may not hold the projection, and the
  // affine extension still maps it onto the same face of A and of B.
  Vec3 l;
  {
    const Vec3 e0 = b.w - a.w, e1 = c.w - a.w, q = f.d * f.n - a.w;
    const double d00 = e0.dot(e0), d01 = e0.dot(e1), d11 = e1.dot(e1);
    const double d20 = q.dot(e0), d21 = q.dot(e1);
    const double den = d00 * d11 - d01 * d01;
    if (den > 1e-24 * d00 * d11) {
      l[1] = (d11 * d20 - d01 * d21) / den;
      l[2] = (d00 * d21 - d01 * d20) / den;
      l[0] = 1.0 - l[1] - l[2];
    } else {
      l = closestPointOnTriangle(Vec3::Zero(), a.w, b.w, c.w).barycentric;
    }
  }
  out.n = f.n;
  out.depth = std::max(0.0, f.d);
  out.pa = l[0] * a.a + l[1] * b.a + l[2] * c.a;
  out.pb = l[0] * a.b + l[1] * b.b + l[2] * c.b;
  out.exact = true;
  return out;
}

void storeCache(GjkCache* cache, const Isometry3& poseA, const Vec3& v, bool separated,
                const MinkowskiPair& m, int iterations) {
  if (!cache) return;
  // Only a separating direction is worth keeping; after an overlap v is a
  // meaningless interior point and the centre offset is the better start.
  cache->direction = separated ? Vec3(poseA.linear() * v) : Vec3::Zero();
  cache->hintA = m.hintA;
  cache->hintB = m.hintB;
  cache->iterations = iterations;
}

}  // namespace

bool gjkIntersect(const ConvexShape& a, const Isometry3& poseA, const ConvexShape& b, const Isometry3& poseB,
                  GjkCache* cache, const GjkOptions& options) noexcept {
  MinkowskiPair m(a, poseA, b, poseB);
  if (cache) m.hintA = cache->hintA, m.hintB = cache->hintB;
  const double margin = a.margin() + b.margin();
  Simplex s;
  Vec3 v;
  int it = 0;
  const GjkStop stop = runGjk(m, startDirection(cache, poseA, m), margin, margin, options, s, v, it);
  storeCache(cache, poseA, v, stop == GjkStop::Separated || (stop == GjkStop::Converged && v.norm() > margin),
             m, it);
  switch (stop) {
    case GjkStop::Separated:
      return false;
    case GjkStop::Within:
    case GjkStop::Overlap:
      return true;
    case GjkStop::Converged:
      break;
  }
  return v.norm() <= margin;
}

GjkResult gjkDistance(const ConvexShape& a, const Isometry3& poseA, const ConvexShape& b,
                      const Isometry3& poseB, GjkCache* cache, const GjkOptions& options) noexcept {
  MinkowskiPair m(a, poseA, b, poseB);
  if (cache) m.hintA = cache->hintA, m.hintB = cache->hintB;
  const double ra = a.margin(), rb = b.margin();
  Simplex s;
  Vec3 v;
  int it = 0;
  const GjkStop stop = runGjk(m, startDirection(cache, poseA, m), -1.0, kInf, options, s, v, it);
  storeCache(cache, poseA, v, stop != GjkStop::Overlap && v.squaredNorm() > 0, m, it);

  GjkResult r;
  const Mat3 ra3 = poseA.linear();
  Vec3 pa, pb, n;
  double coreDistance = 0;
  if (stop == GjkStop::Overlap) {
    if (!options.penetration) {
      pa = s.v[0].a, pb = s.v[0].a;
      for (int i = 1; i < s.n; ++i) pa += s.lambda[i] * (s.v[i].a - s.v[0].a);
      r.pointA = r.pointB = poseA * pa;
      r.distance = -(ra + rb);
      return r;
    }
    const EpaOut e = runEpa(m, s, options);
    n = e.n, pa = e.pa, pb = e.pb;
    coreDistance = -e.depth;
    r.exact = e.exact;
  } else {
    pa.setZero(), pb.setZero();
    for (int i = 0; i < s.n; ++i) pa += s.lambda[i] * s.v[i].a, pb += s.lambda[i] * s.v[i].b;
    coreDistance = v.norm();
    n = coreDistance > 0 ? Vec3(-v / coreDistance) : Vec3::UnitX();
  }
  // Surface points: the margins extend each core along the normal.
  r.distance = coreDistance - ra - rb;
  r.normal = ra3 * n;
  r.pointA = poseA * Vec3(pa + ra * n);
  r.pointB = poseA * Vec3(pb - rb * n);
  return r;
}

}  // namespace dm
