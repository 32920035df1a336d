// GJK distance and EPA penetration; see dm/collide/gjk.hpp.
//
// Both algorithms run in A's local frame: B's support points are mapped by
// the relative pose once per query, which saves a rotation per support call.
// MPR on small hulls goes further: it copies both hulls' vertices into A's
// frame once and scans them as structure-of-arrays coordinates (above 16
// vertices, the refinement climbs the hull's edges from the last support
// instead), carrying vertex indices instead of points through the portal
// updates. The boolean GJK, with a few support calls per query, scans small
// hulls' own structure-of-arrays coordinates (ConvexHull::coordinates()) in
// place with the same scan, B's through a rotation per support. Above 8
// vertices the scan runs 4 wide where the CPU has AVX2 (GCC on x86-64,
// chosen at load time), with the same arithmetic as the SSE2 one.
#include <dm/collide/gjk.hpp>
#include <dm/math/geometry.hpp>

#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>
#include <span>
#include <type_traits>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif
#if defined(__GNUC__) && defined(__x86_64__)  // GCC and clang
#include <immintrin.h>
#define DM_GJK_AVX2 1
#endif

#include "collide_internal.hpp"

namespace dm {

namespace {

using detail::kInf;

// A point of the Minkowski difference A − B with the two support points it
// came from (all in A's frame).
struct Vertex {
  Vec3 w, a, b;
};

// A small hull's vertices in A's frame as structure-of-arrays coordinates,
// padded to a multiple of 4 with copies of vertex 0 (never chosen: ties go
// to the lower index). Worth building for the queries that call the support
// mapping a dozen times and more (MPR): each call is then a branch-free
// 2-wide scan, or on larger hulls a short climb along the hull's edges, with
// no rotation of the direction or of the answer.
constexpr std::uint32_t kFrameVertices = 64;
// Hulls up to this many vertices are scanned in place by the boolean GJK.
constexpr std::uint32_t kBooleanScanVertices = 32;
static_assert(kBooleanScanVertices <= kFrameVertices, "the scan's stack array");

#if defined(DM_GJK_AVX2)
// furthestScan() above 8 vertices, 4 wide where the CPU (and the OS) has
// AVX2, which the build does not assume: the same products and sums in the
// same order as the SSE2 scan, so the same answer. A hull of 32 vertices in
// 8 steps instead of 16.
const bool gHasAvx2 = (__builtin_cpu_init(), __builtin_cpu_supports("avx2"));

[[gnu::target("avx2"), gnu::noinline]] std::uint32_t furthestScanAvx(const double* x, const double* y,
                                                                  const double* z, std::uint32_t padded,
                                                                  const Vec3& d) noexcept {
  const __m256d dx = _mm256_set1_pd(d.x()), dy = _mm256_set1_pd(d.y()), dz = _mm256_set1_pd(d.z());
  __m256d dots[kFrameVertices / 4];
  __m256d m = _mm256_set1_pd(-std::numeric_limits<double>::infinity());
  for (std::uint32_t i = 0; i < padded; i += 4) {
    const __m256d p = _mm256_add_pd(
        _mm256_add_pd(_mm256_mul_pd(dx, _mm256_loadu_pd(x + i)), _mm256_mul_pd(dy, _mm256_loadu_pd(y + i))),
        _mm256_mul_pd(dz, _mm256_loadu_pd(z + i)));
    dots[i / 4] = p;
    m = _mm256_max_pd(m, p);
  }
  m = _mm256_max_pd(m, _mm256_permute2f128_pd(m, m, 1));
  m = _mm256_max_pd(m, _mm256_shuffle_pd(m, m, 5));
  std::uint64_t bits = 0;
  for (std::uint32_t c = 0; c < padded / 4; ++c)
    bits |= std::uint64_t(static_cast<unsigned>(_mm256_movemask_pd(_mm256_cmp_pd(dots[c], m, _CMP_EQ_OQ))))
            << (4 * c);
  return bits ? static_cast<std::uint32_t>(std::countr_zero(bits)) : 0u;
}
#endif

// Index of the vertex furthest along d (the first on ties; 0 for a NaN
// direction) among `padded` vertices with coordinates x, y, z: padded ≤
// kFrameVertices, a multiple of 4, the padding copies of vertex 0 (never
// chosen: ties go to the lower index). The largest dot product first
// (independent 2-wide maxima), then the lanes equal to it as a bit mask:
// the index comes out of registers, with no branch on the data. Up to 8
// vertices unrolled (MPR on such hulls waits on this scan at every step).
[[gnu::always_inline]] inline std::uint32_t furthestScan(const double* x, const double* y, const double* z,
                                                         std::uint32_t padded, const Vec3& d) noexcept {
#if defined(__SSE2__)
  const __m128d dx = _mm_set1_pd(d.x()), dy = _mm_set1_pd(d.y()), dz = _mm_set1_pd(d.z());
  if (padded <= 8) {  // unrolled: one max tree, one mask
    const auto dot = [&](std::uint32_t i) {
      return _mm_add_pd(_mm_add_pd(_mm_mul_pd(dx, _mm_loadu_pd(x + i)), _mm_mul_pd(dy, _mm_loadu_pd(y + i))),
                        _mm_mul_pd(dz, _mm_loadu_pd(z + i)));
    };
    const __m128d p0 = dot(0), p1 = dot(2);
    const __m128d p2 = padded == 8 ? dot(4) : p0, p3 = padded == 8 ? dot(6) : p1;
    __m128d m = _mm_max_pd(_mm_max_pd(p0, p1), _mm_max_pd(p2, p3));
    m = _mm_max_pd(m, _mm_shuffle_pd(m, m, 1));
    const unsigned bits = static_cast<unsigned>(_mm_movemask_pd(_mm_cmpeq_pd(p0, m))) |
                          static_cast<unsigned>(_mm_movemask_pd(_mm_cmpeq_pd(p1, m))) << 2 |
                          static_cast<unsigned>(_mm_movemask_pd(_mm_cmpeq_pd(p2, m))) << 4 |
                          static_cast<unsigned>(_mm_movemask_pd(_mm_cmpeq_pd(p3, m))) << 6;
    return bits ? static_cast<std::uint32_t>(std::countr_zero(bits)) : 0u;
  }
#if defined(DM_GJK_AVX2)
  if (gHasAvx2) return furthestScanAvx(x, y, z, padded, d);
#endif
  __m128d dots[kFrameVertices / 2];
  __m128d m0 = _mm_set1_pd(-std::numeric_limits<double>::infinity()), m1 = m0;
  for (std::uint32_t i = 0; i < padded; i += 4) {
    const __m128d p0 =
        _mm_add_pd(_mm_add_pd(_mm_mul_pd(dx, _mm_loadu_pd(x + i)), _mm_mul_pd(dy, _mm_loadu_pd(y + i))),
                   _mm_mul_pd(dz, _mm_loadu_pd(z + i)));
    const __m128d p1 = _mm_add_pd(
        _mm_add_pd(_mm_mul_pd(dx, _mm_loadu_pd(x + i + 2)), _mm_mul_pd(dy, _mm_loadu_pd(y + i + 2))),
        _mm_mul_pd(dz, _mm_loadu_pd(z + i + 2)));
    dots[i / 2] = p0, dots[i / 2 + 1] = p1;
    m0 = _mm_max_pd(m0, p0), m1 = _mm_max_pd(m1, p1);
  }
  m0 = _mm_max_pd(m0, m1);
  m0 = _mm_max_pd(m0, _mm_shuffle_pd(m0, m0, 1));
  std::uint64_t bits = 0;
  for (std::uint32_t c = 0; c < padded / 2; ++c)
    bits |= std::uint64_t(static_cast<unsigned>(_mm_movemask_pd(_mm_cmpeq_pd(dots[c], m0)))) << (2 * c);
  return bits ? static_cast<std::uint32_t>(std::countr_zero(bits)) : 0u;  // none: NaN direction
#else
  std::uint32_t best = 0;
  double top = d.x() * x[0] + d.y() * y[0] + d.z() * z[0];
  for (std::uint32_t i = 1; i < padded; ++i) {
    const double p = d.x() * x[i] + d.y() * y[i] + d.z() * z[i];
    if (p > top) top = p, best = i;
  }
  return best;
#endif
}

struct FrameVertices {
  alignas(16) double x[kFrameVertices];
  alignas(16) double y[kFrameVertices];
  alignas(16) double z[kFrameVertices];
  std::uint32_t n = 0;               // vertices; the padding runs to (n + 3) & ~3
  const ConvexHull* hull = nullptr;  // for its vertex adjacency

  // Above this many vertices, a search that starts next to the answer
  // (MPR's refinement: the portal normal turns a little per step) climbs
  // the hull's edges instead of scanning: a handful of dot products.
  static constexpr std::uint32_t kClimbVertices = 16;

  // Fills from hull vertices v[0, n) mapped by (r, t); false (and empty)
  // when there are too many.
  // `moved`: false when (r, t) is the identity (A's own vertices).
  bool assign(const ConvexHull& h, const Mat3& r, const Vec3& t, bool moved) noexcept {
    const std::vector<Vec3>& v = h.vertices();
    if (v.empty() || v.size() > kFrameVertices) return false;
    hull = &h;
    n = static_cast<std::uint32_t>(v.size());
    std::uint32_t i = 0;
#if defined(__SSE2__)
    // Two vertices at a time: three loads of the interleaved coordinates,
    // three shuffles to x, y and z pairs, then 2-wide transforms.
    static_assert(sizeof(Vec3) == 3 * sizeof(double));
    const double* p = v.data()->data();
    for (; i + 2 <= n; i += 2, p += 6) {
      const __m128d l0 = _mm_loadu_pd(p), l1 = _mm_loadu_pd(p + 2), l2 = _mm_loadu_pd(p + 4);
      __m128d px = _mm_shuffle_pd(l0, l1, 2), py = _mm_shuffle_pd(l0, l2, 1), pz = _mm_shuffle_pd(l1, l2, 2);
      if (moved) {
        auto row = [&](int k) {
          return _mm_add_pd(_mm_add_pd(_mm_add_pd(_mm_mul_pd(_mm_set1_pd(r(k, 0)), px),
                                                  _mm_mul_pd(_mm_set1_pd(r(k, 1)), py)),
                                       _mm_mul_pd(_mm_set1_pd(r(k, 2)), pz)),
                            _mm_set1_pd(t[k]));
        };
        const __m128d qx = row(0), qy = row(1), qz = row(2);
        px = qx, py = qy, pz = qz;
      }
      _mm_store_pd(x + i, px), _mm_store_pd(y + i, py), _mm_store_pd(z + i, pz);
    }
#endif
    for (; i < n; ++i) {
      const Vec3 q = moved ? Vec3(r * v[i] + t) : v[i];
      x[i] = q.x(), y[i] = q.y(), z[i] = q.z();
    }
    for (i = n; i < ((n + 3) & ~3u); ++i) x[i] = x[0], y[i] = y[0], z[i] = z[0];
    return true;
  }

  Vec3 operator[](std::uint32_t i) const noexcept { return Vec3(x[i], y[i], z[i]); }

  // furthest(d), starting the search from vertex `start` (a recent answer).
  // A linear function on a convex polytope has no local maximum along its
  // edges but the global one, so the climb ends at the answer (on ties, at
  // one of the tied vertices).
  std::uint32_t furthestFrom(const Vec3& d, std::uint32_t start) const noexcept {
    if (n <= kClimbVertices) return furthest(d);
    std::uint32_t cur = start;
    double best = d.x() * x[cur] + d.y() * y[cur] + d.z() * z[cur];
    for (bool moved = true; moved;) {
      moved = false;
      for (const std::uint32_t v : hull->neighbors(cur)) {
        const double p = d.x() * x[v] + d.y() * y[v] + d.z() * z[v];
        if (p > best) best = p, cur = v, moved = true;
      }
    }
    return cur;
  }

  // Index of the vertex furthest along d (the first on ties).
  std::uint32_t furthest(const Vec3& d) const noexcept { return furthestScan(x, y, z, (n + 3) & ~3u, d); }
};

// A hull's own coordinates (ConvexHull::coordinates()), searched by the
// same scan without a copy: for queries that call the support mapping only
// a few times. kMoved: (r, t) maps them into A's frame, per support (the
// direction in, the answer out).
template <bool kMoved>
struct HullCoordinates {
  const double* x;
  const double* y;
  const double* z;
  std::uint32_t padded;
  const Mat3& r;
  const Vec3& t;

  HullCoordinates(const ConvexHull& h, const Mat3& rot, const Vec3& trans) noexcept : r(rot), t(trans) {
    const std::span<const double> c = h.coordinates();
    padded = static_cast<std::uint32_t>(c.size() / 3);
    x = c.data(), y = x + padded, z = y + padded;
  }
  std::uint32_t furthest(const Vec3& d) const noexcept {
    if constexpr (kMoved) return furthestScan(x, y, z, padded, r.transpose() * d);
    return furthestScan(x, y, z, padded, d);
  }
  Vec3 operator[](std::uint32_t i) const noexcept {
    const Vec3 v(x[i], y[i], z[i]);
    if constexpr (kMoved) return r * v + t;
    return v;
  }
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
    r.noalias() = ra.transpose() * poseB.linear();  // straight into r, no temporary
    t.noalias() = ra.transpose() * (poseB.translation() - poseA.translation());
  }

  // A point inside A − B (A's frame): the difference of the shapes'
  // interior points.
  Vec3 interior() const noexcept { return A.interiorPoint() - (r * B.interiorPoint() + t); }

  // Support point of A − B along d (A's frame), without its two parts.
  Vec3 supportW(const Vec3& d) noexcept {
    return A.supportCore(d, hintA) - (r * B.supportCore(-(r.transpose() * d), hintB) + t);
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

// Support mappings of A − B for the boolean GJK and MPR. A Point is a point
// `w` of A − B with what it takes to recover the two shapes' points it came
// from.
struct ShapeSupports {  // any convex shapes
  MinkowskiPair& m;
  using Point = Vertex;
  Point operator()(const Vec3& d) const noexcept { return m.support(d); }
  Point refine(const Vec3& d, const Point& /*near*/) const noexcept { return m.support(d); }
  static Vec3 pointA(const Point& p) noexcept { return p.a; }
  static Vec3 pointB(const Point& p) noexcept { return p.b; }
};

struct ShapeSupportsW {  // any convex shapes, the point of A − B only
  MinkowskiPair& m;
  struct Point {
    Vec3 w;
  };
  Point operator()(const Vec3& d) const noexcept { return {m.supportW(d)}; }
};

// Two hulls, A's and B's vertices in A's frame through FA and FB
// (FrameVertices or HullCoordinates): points carry vertex indices.
template <class FA, class FB>
struct HullSupports {
  const FA& A;
  const FB& B;
  struct Point {
    Vec3 w;
    std::uint32_t ia = 0, ib = 0;
  };
  Point operator()(const Vec3& d) const noexcept {
    Point p;
    p.ia = A.furthest(d);
    p.ib = B.furthest(-d);
    p.w = A[p.ia] - B[p.ib];
    return p;
  }
  // The support along d, which is close to the one along the direction that
  // gave `near`.
  Point refine(const Vec3& d, const Point& near) const noexcept {
    Point p;
    p.ia = A.furthestFrom(d, near.ia);
    p.ib = B.furthestFrom(-d, near.ib);
    p.w = A[p.ia] - B[p.ib];
    return p;
  }
  Vec3 pointA(const Point& p) const noexcept { return A[p.ia]; }
  Vec3 pointB(const Point& p) const noexcept { return B[p.ib]; }
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

// ------------------------------------------------------ boolean GJK ---

enum class Quick { Separated, Overlap, Unsure };

// The boolean GJK decides typical pairs in under a dozen iterations; curved
// shapes a hair apart converge slowly, and the exact GJK is better there.
constexpr int kQuickIterations = 32;

// Boolean GJK on the cores for shapes without margin, with the simplex
// update of Muratori ("Implementing GJK", 2006): the simplex keeps only the
// Minkowski points and a search direction towards the origin, never a
// closest point, so an iteration is one support pair and a few cross
// products. Each answer is a certificate: a direction along which all of
// A − B lies clearly below the origin (separated), or a tetrahedron of A − B
// points holding the origin (overlap). A support gain within rounding of
// zero (touching), a direction that vanishes (origin on a simplex edge) or
// no decision within `maxIterations` give Unsure, and the caller runs the
// exact GJK. `sep` receives the separating direction; on overlap `p[0..3]`
// holds the tetrahedron. `Supports` is a support mapping of A − B as for
// runMpr() (its points need only `w`). The simplex starts as p[0, n): empty,
// or one point inside A − B (any point of A − B serves a certificate, and
// a free one saves a support pair when the origin is inside).
template <class Supports>
Quick quickIntersect(const Supports& support, Vec3 d, int maxIterations, Vec3& sep,
                     typename Supports::Point* p, int n, int& iterations) noexcept {
  using Point = typename Supports::Point;
  // Simplex p[0, n), p[0] the newest point. `scale`: the largest |w|² seen,
  // the magnitude rounding is relative to.
  double scale = n > 0 ? p[0].w.squaredNorm() : 0;
  constexpr double kNoise = 1e-26;  // (1e-13)²
  // Direction towards the origin from segment [a, b] where the origin
  // projects inside it; false when the origin is (nearly) on the line.
  auto segmentDirection = [&](const Vec3& ab, const Vec3& ao) {
    d = ab.cross(ao).cross(ab);
    return d.squaredNorm() > kNoise * ab.squaredNorm() * ab.squaredNorm() * scale;
  };
  // Origin region of triangle (a, b, c) with a the newest point (the
  // regions of b, c and edge bc are excluded by construction, unless b or c
  // is the interior point the simplex may start with: then a wrong guess
  // costs an iteration, never a wrong answer, since the tetrahedron test
  // checks every face through the newest point and the base's side is set
  // here). Reorders p. False: unsure.
  auto triangle = [&](const Point& va, const Point& vb, const Point& vc) {
    const Point a = va, b = vb, c = vc;
    const Vec3 ab = b.w - a.w, ac = c.w - a.w, ao = -a.w;
    const Vec3 abc = ab.cross(ac);
    if (abc.cross(ac).dot(ao) > 0) {
      if (ac.dot(ao) > 0) {
        p[0] = a, p[1] = c, n = 2;
        return segmentDirection(ac, ao);
      }
    } else if (ab.cross(abc).dot(ao) <= 0) {
      // Above or below the triangle.
      if (abc.dot(ao) > 0) {
        p[0] = a, p[1] = b, p[2] = c, d = abc;
      } else {
        p[0] = a, p[1] = c, p[2] = b, d = -abc;
      }
      n = 3;
      return abc.squaredNorm() > kNoise * ab.squaredNorm() * ac.squaredNorm();
    }
    if (ab.dot(ao) > 0) {
      p[0] = a, p[1] = b, n = 2;
      return segmentDirection(ab, ao);
    }
    p[0] = a, n = 1, d = ao;
    return true;
  };
  for (iterations = 0; iterations < maxIterations; ++iterations) {
    const Point w = support(d);
    const double dw = d.dot(w.w);
    scale = std::max(scale, w.w.squaredNorm());
    if (dw * dw <= kNoise * d.squaredNorm() * scale) return Quick::Unsure;  // touching within rounding
    if (dw < 0) {
      sep = d;
      return Quick::Separated;
    }
    for (int i = n; i > 0; --i) p[i] = p[i - 1];
    p[0] = w, ++n;
    bool sure = true;
    switch (n) {
      case 1:
        d = -w.w;
        break;
      case 2: {
        const Vec3 ab = p[1].w - w.w, ao = -w.w;
        if (ab.dot(ao) > 0) {
          sure = segmentDirection(ab, ao);
        } else {
          n = 1, d = ao;
        }
        break;
      }
      case 3:
        sure = triangle(p[0], p[1], p[2]);
        break;
      default: {
        // Base (p1, p2, p3) faces p0, so the outward normals of the faces
        // through p0 are these three; the origin is inside when behind all.
        const Vec3 a = p[0].w, ab = p[1].w - a, ac = p[2].w - a, ae = p[3].w - a, ao = -a;
        if (ab.cross(ac).dot(ao) > 0) {
          sure = triangle(p[0], p[1], p[2]);
        } else if (ac.cross(ae).dot(ao) > 0) {
          sure = triangle(p[0], p[2], p[3]);
        } else if (ae.cross(ab).dot(ao) > 0) {
          sure = triangle(p[0], p[3], p[1]);
        } else {
          return Quick::Overlap;
        }
        break;
      }
    }
    if (!sure) return Quick::Unsure;
  }
  return Quick::Unsure;
}

// ------------------------------------------------------------------ EPA ---

// The polytope is a closed triangle mesh with face adjacency, so a new
// support point removes only the connected faces that see it (found by a
// depth-first walk from the nearest face) and cones the horizon to it: each
// expansion costs O(faces removed) plus one scan of the face distances. All
// storage is fixed-size on the stack; freed face slots are reused.
constexpr int kEpaMaxVertices = 128;
constexpr int kEpaMaxFaces = 2 * kEpaMaxVertices;  // a closed triangulation has 2V − 4 faces

struct EpaFace {
  Vec3 n;                   // unit outward normal (UnitX for a degenerate sliver)
  int v[3];                 // vertex indices, CCW from outside
  int adj[3];               // face across edge k = (v[k], v[k + 1])
  std::uint8_t adjEdge[3];  // that edge's index in face adj[k]
  bool sliver;              // zero area: never the nearest, removed when reached
  bool removed;
};

struct Epa {
  Vertex vert[kEpaMaxVertices];
  EpaFace face[kEpaMaxFaces];
  // Plane offset n·v of each live face; +inf for slivers and free slots, so
  // the nearest face is a plain minimum scan over contiguous doubles.
  double dist[kEpaMaxFaces];
  int freeSlot[kEpaMaxFaces];
  int nv = 0, slots = 0, nfree = 0, live = 0;
  // Horizon of the current expansion: (face, edge) pairs left standing.
  int horizonFace[kEpaMaxFaces];
  std::uint8_t horizonEdge[kEpaMaxFaces];
  int nh = 0;
  bool overflow = false;

  int newFace(int a, int b, int c) noexcept {
    const int f = nfree > 0 ? freeSlot[--nfree] : slots++;
    EpaFace& fc = face[f];
    fc.v[0] = a, fc.v[1] = b, fc.v[2] = c;
    fc.removed = false;
    const Vec3 n = (vert[b].w - vert[a].w).cross(vert[c].w - vert[a].w);
    const double len = n.norm();
    fc.sliver = !(len > 0);
    if (!fc.sliver) {
      fc.n = n * (1.0 / len);
      dist[f] = fc.n.dot(vert[a].w);
    } else {
      fc.n = Vec3::UnitX();
      dist[f] = kInf;
    }
    ++live;
    return f;
  }

  void link(int f, int e, int g, int eg) noexcept {
    face[f].adj[e] = g, face[f].adjEdge[e] = static_cast<std::uint8_t>(eg);
    face[g].adj[eg] = f, face[g].adjEdge[eg] = static_cast<std::uint8_t>(e);
  }

  bool sees(int f, const Vec3& w, double eps) const noexcept {
    const EpaFace& fc = face[f];
    return fc.sliver || fc.n.dot(w - vert[fc.v[0]].w) > eps;
  }

  // Removes face f, which sees w, and depth-first every face connected to it
  // that sees w; records the edges of the faces left standing as the horizon.
  void carve(int f, const Vec3& w, double eps) noexcept {
    EpaFace& fc = face[f];
    fc.removed = true;
    dist[f] = kInf;
    freeSlot[nfree++] = f;
    --live;
    for (int k = 0; k < 3; ++k) {
      const int g = fc.adj[k];
      if (face[g].removed) continue;
      if (sees(g, w, eps)) {
        carve(g, w, eps);
      } else if (nh < kEpaMaxFaces) {
        horizonFace[nh] = g, horizonEdge[nh] = fc.adjEdge[k], ++nh;
      } else {
        overflow = true;  // only on a polytope rounding made non-convex
      }
    }
  }

  // Index of the live face nearest to the origin; -1 if all are slivers.
  int nearest() const noexcept {
    int best = -1;
    double d = kInf;
    for (int f = 0; f < slots; ++f)
      if (dist[f] < d) d = dist[f], best = f;
    return best;
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
  // Faces (0,1,2), (0,3,1), (0,2,3), (1,3,2); edge k of a face runs from
  // v[k] to v[k + 1], and the table names the face and edge across it.
  e.newFace(0, 1, 2), e.newFace(0, 3, 1), e.newFace(0, 2, 3), e.newFace(1, 3, 2);
  static constexpr int kAcross[4][3][2] = {
      {{1, 2}, {3, 2}, {2, 0}}, {{2, 2}, {3, 0}, {0, 0}}, {{0, 2}, {3, 1}, {1, 0}}, {{1, 1}, {2, 1}, {0, 1}}};
  for (int f = 0; f < 4; ++f)
    for (int k = 0; k < 3; ++k)
      e.face[f].adj[k] = kAcross[f][k][0], e.face[f].adjEdge[k] = std::uint8_t(kAcross[f][k][1]);

  double scale = 0;
  for (int i = 0; i < 4; ++i) scale = std::max(scale, e.vert[i].w.norm());
  const double tol = opt.epaTolerance * scale;
  const double seeEps = tol * 1e-3;

  // Horizon vertex → new face whose first vertex it is (valid when the
  // stamp matches the expansion), to link the cone's faces to each other.
  int coneAt[kEpaMaxVertices];
  int coneStamp[kEpaMaxVertices];
  std::fill(coneStamp, coneStamp + kEpaMaxVertices, -1);

  int best = e.nearest();
  EpaFace bestFace{};
  double bestDist = kInf;
  bool broken = false;
  // Least support value seen along a face normal: the depth is at most it.
  double upper = kInf;
  for (int iter = 0; iter < opt.maxEpaIterations && best >= 0; ++iter) {
    if (e.nv == kEpaMaxVertices || e.live + 2 > kEpaMaxFaces) break;
    const EpaFace& bf = e.face[best];
    const Vertex w = m.support(bf.n);
    const double h = bf.n.dot(w.w);
    upper = std::min(upper, h);
    if (h - e.dist[best] <= tol || upper - e.dist[best] <= tol) break;  // on the boundary
    const int iw = e.nv;
    e.vert[e.nv++] = w;
    bestFace = e.face[best], bestDist = e.dist[best];
    e.nh = 0;
    e.overflow = false;
    e.carve(best, w.w, seeEps);
    // Cone the horizon to w: the face on horizon edge (p, q) is (q, p, w);
    // its edge 1 (p, w) meets the cone face that starts at p.
    // A simple horizon loop of h edges replaces at least h − 2 faces, so the
    // slots suffice; anything else is rounding damage and stops here.
    bool valid = e.nh >= 3 && !e.overflow && e.live + e.nh <= kEpaMaxFaces;
    int made[kEpaMaxFaces];
    for (int j = 0; j < e.nh && valid; ++j) {
      const int g = e.horizonFace[j], eg = e.horizonEdge[j];
      const int p = e.face[g].v[eg], q = e.face[g].v[(eg + 1) % 3];
      const int f = e.newFace(q, p, iw);
      made[j] = f;
      e.link(f, 0, g, eg);
      if (coneStamp[q] == iter) valid = false;  // q starts two horizon edges: not a simple loop
      coneStamp[q] = iter, coneAt[q] = f;
    }
    for (int j = 0; j < e.nh && valid; ++j) {
      const int f = made[j];
      const int p = e.face[f].v[1];
      if (coneStamp[p] != iter) {
        valid = false;
        break;
      }
      e.link(f, 1, coneAt[p], 2);
    }
    if (!valid) {
      // Rounding broke the horizon into something other than one loop; the
      // nearest face before this expansion is still the best answer.
      broken = true;
      break;
    }
    best = e.nearest();
  }
  if (!broken) {
    if (best < 0) return out;
    bestFace = e.face[best], bestDist = e.dist[best];
  }
  const EpaFace& f = bestFace;
  const Vertex& a = e.vert[f.v[0]];
  const Vertex& b = e.vert[f.v[1]];
  const Vertex& c = e.vert[f.v[2]];
  const double fd = bestDist;
  // Barycentric coordinates of the origin's projection on the face plane,
  // not clamped to the triangle: when a flat face of the shapes is split into
  // coplanar triangles the nearest one may not hold the projection, and the
  // affine extension still maps it onto the same face of A and of B.
  // planeBarycentric() keeps a sliver's thin direction (a box edge against a
  // cylinder rim: two 0.8 m edges 1e-6 m apart), which the Gram solve from
  // vertex a lost: the witness points then missed by 9e-5 m.
  const Vec3 e0 = b.w - a.w, e1 = c.w - a.w;
  const Vec3 l = e0.cross(e1).squaredNorm() > 1e-24 * e0.squaredNorm() * e1.squaredNorm()
                     ? planeBarycentric(fd * f.n, a.w, b.w, c.w)
                     : closestPointOnTriangle(Vec3::Zero(), a.w, b.w, c.w).barycentric;
  out.n = f.n;
  out.depth = std::max(0.0, fd);
  out.pa = l[0] * a.a + l[1] * b.a + l[2] * c.a;
  out.pb = l[0] * a.b + l[1] * b.b + l[2] * c.b;
  out.exact = true;
  return out;
}

// ------------------------------------------------------------------ MPR ---

// Minkowski portal refinement (Snethen 2008; the structure of libccd's
// mpr.c): from an interior point v0 of A − B, find a portal triangle
// (v1, v2, v3) that the ray v0 → origin passes through, then push the portal
// outwards along its normal until the origin is proven inside (overlap) or
// outside (separated), and on overlap until the portal lies on the boundary
// within tolerance. The depth is the origin's distance to the final portal.
enum class MprStop { Separated, Overlap, Degenerate };

struct MprOut {
  Vec3 n;        // unit, A's frame, from A to B
  double depth;  // ≥ 0, of the cores
  Vec3 pa, pb;   // A's frame
};

// `interior`: a point inside A − B (A's frame); `scale`: the pair's size,
// which the tolerances are relative to.
template <class Supports>
MprStop runMpr(const Supports& support, Vec3 interior, double scale, const GjkOptions& opt, MprOut& out,
               Vec3& sep, int& iterations) noexcept {
  using Point = typename Supports::Point;
  const double tol = opt.mprTolerance * scale;
  Point v0;
  v0.w = interior;
  // The centres coincide: any direction is as good as another for the ray.
  if (v0.w.squaredNorm() <= 1e-24 * scale * scale) v0.w = Vec3(1e-10 * scale, 0, 0);

  // Portal discovery.
  Vec3 dir = -v0.w;
  Point v1 = support(dir);
  if (v1.w.dot(dir) <= 0) {
    sep = dir;
    return MprStop::Separated;
  }
  dir = v0.w.cross(v1.w);
  if (dir.squaredNorm() <= 1e-24 * v0.w.squaredNorm() * v1.w.squaredNorm()) {
    // The origin is on segment v0 → v1: it lies inside, |v1| below the boundary.
    const double d = v1.w.norm();
    out.n = d > 0 ? Vec3(v1.w / d) : Vec3(-v0.w.normalized());
    out.depth = d;
    out.pa = support.pointA(v1), out.pb = support.pointB(v1);
    return MprStop::Overlap;
  }
  Point v2 = support(dir);
  if (v2.w.dot(dir) <= 0) {
    sep = dir;
    return MprStop::Separated;
  }
  dir = (v1.w - v0.w).cross(v2.w - v0.w);
  if (dir.dot(v0.w) > 0) {
    std::swap(v1, v2);
    dir = -dir;
  }
  Point v3;
  for (iterations = 0;; ++iterations) {
    if (iterations == opt.maxMprIterations || dir.squaredNorm() == 0) return MprStop::Degenerate;
    v3 = support(dir);
    if (v3.w.dot(dir) <= 0) {
      sep = dir;
      return MprStop::Separated;
    }
    // The origin must lie inside the cone v0 + (v1, v2, v3); else v3
    // replaces the vertex on the wrong side and the search goes on.
    if (v1.w.cross(v3.w).dot(v0.w) < 0) {
      v2 = v3;
      dir = (v1.w - v0.w).cross(v3.w - v0.w);
    } else if (v3.w.cross(v2.w).dot(v0.w) < 0) {
      v1 = v3;
      dir = (v3.w - v0.w).cross(v2.w - v0.w);
    } else {
      break;
    }
  }

  // Refinement: the portal's outward normal points away from v0. It is
  // left unnormalised (the square root and division would sit on the
  // loop's critical path): the gain along it is |n| times the distance, so
  // it is compared with tol · |n| by squares.
  bool inside = false;
  const double tol2 = tol * tol;
  Point last = v3;  // the latest support: where the next search starts
  for (; iterations < opt.maxMprIterations; ++iterations) {
    const Vec3 n = (v2.w - v1.w).cross(v3.w - v1.w);
    const double nn = n.squaredNorm();
    if (!(nn > 0)) return MprStop::Degenerate;
    const double d1 = n.dot(v1.w);
    if (d1 >= 0) inside = true;  // the origin is behind the portal
    const Point v4 = support.refine(n, last);
    last = v4;
    const double d4 = n.dot(v4.w);
    if (!inside && d4 < 0) {  // the boundary along n is below the origin
      sep = n;
      return MprStop::Separated;
    }
    const double gain = std::min({d4 - d1, d4 - n.dot(v2.w), d4 - n.dot(v3.w)});
    if (gain <= 0 || gain * gain <= tol2 * nn) {
      if (!inside) {  // the origin is on the boundary within tolerance: touching
        sep = n;
        return MprStop::Separated;
      }
      const TriangleClosest c = closestPointOnTriangle(Vec3::Zero(), v1.w, v2.w, v3.w);
      const double d = std::sqrt(c.distanceSq);
      out.n = d > 0 ? Vec3(c.point / d) : Vec3(n / std::sqrt(nn));
      out.depth = d;
      const Vec3& l = c.barycentric;
      out.pa = l[0] * support.pointA(v1) + l[1] * support.pointA(v2) + l[2] * support.pointA(v3);
      out.pb = l[0] * support.pointB(v1) + l[1] * support.pointB(v2) + l[2] * support.pointB(v3);
      return MprStop::Overlap;
    }
    // Replace the portal vertex so that the ray v0 → origin still passes
    // through the new portal.
    const Vec3 v4v0 = v4.w.cross(v0.w);
    if (v1.w.dot(v4v0) > 0) {
      if (v2.w.dot(v4v0) > 0)
        v1 = v4;
      else
        v3 = v4;
    } else {
      if (v3.w.dot(v4v0) > 0)
        v2 = v4;
      else
        v1 = v4;
    }
  }
  return MprStop::Degenerate;
}

// MPR on the cores of the pair. Two hulls of up to kFrameVertices vertices
// go through HullSupports, with their vertices copied into A's frame; the
// copies (3 KB) live in this function's frame, out of line so that the
// other queries of gjkDistance() do not carry them.
[[gnu::noinline]] MprStop mprOnCores(MinkowskiPair& m, const GjkOptions& opt, MprOut& out, Vec3& sep,
                                     int& iterations) noexcept {
  const double scale = m.A.boundingSphere().radius + m.B.boundingSphere().radius + m.t.norm();
  const Vec3 interior = m.interior();
  if (m.A.type() == ShapeType::ConvexHull && m.B.type() == ShapeType::ConvexHull) {
    FrameVertices a, b;
    if (a.assign(static_cast<const ConvexHull&>(m.A), Mat3::Identity(), Vec3::Zero(), false) &&
        b.assign(static_cast<const ConvexHull&>(m.B), m.r, m.t, true))
      return runMpr(HullSupports<FrameVertices, FrameVertices>{a, b}, interior, scale, opt, out, sep,
                    iterations);
  }
  return runMpr(ShapeSupports{m}, interior, scale, opt, out, sep, iterations);
}

// The boolean GJK on the cores of the pair, its simplex started with the
// interior point `interior` of A − B. It calls the support mapping a few
// times only, so hulls are not copied: up to kBooleanScanVertices vertices
// they are scanned in place (HullCoordinates), B's with a rotation per
// support; larger hulls climb their edges in supportCore().
Quick quickOnCores(MinkowskiPair& m, const Vec3& interior, const Vec3& d, int maxIterations, Vec3& sep,
                   int& iterations) noexcept {
  const auto run = [&](const auto& support) {
    typename std::remove_cvref_t<decltype(support)>::Point p[4];
    p[0].w = interior;  // not a support point: its vertex indices stay 0 (unused by the boolean)
    return quickIntersect(support, d, maxIterations, sep, p, 1, iterations);
  };
  if (m.A.type() == ShapeType::ConvexHull && m.B.type() == ShapeType::ConvexHull) {
    const auto& a = static_cast<const ConvexHull&>(m.A);
    const auto& b = static_cast<const ConvexHull&>(m.B);
    if (a.vertices().size() <= kBooleanScanVertices && b.vertices().size() <= kBooleanScanVertices)
      return run(HullSupports<HullCoordinates<false>, HullCoordinates<true>>{{a, m.r, m.t}, {b, m.r, m.t}});
  }
  return run(ShapeSupportsW{m});
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
  Vec3 v = Vec3::Zero();
  int it = 0;
  if (margin == 0) {
    // The boolean GJK starts from an interior point of A − B: a simplex
    // vertex for free, so that three support pairs can prove an overlap.
    const Vec3 interior = m.interior();
    const Vec3 d = cache && cache->direction.squaredNorm() > 0
                       ? Vec3(-(poseA.linear().transpose() * cache->direction))
                       : Vec3(-interior);
    const Quick q = quickOnCores(m, interior, d, std::min(options.maxIterations, kQuickIterations), v, it);
    if (q != Quick::Unsure) {
      storeCache(cache, poseA, -v, q == Quick::Separated, m, it);
      return q == Quick::Overlap;
    }
  }
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
  Vec3 v = Vec3::Zero();
  int it = 0;
  Vec3 dir0 = startDirection(cache, poseA, m);
  // The boolean GJK first: on overlap its tetrahedron starts EPA at a
  // fraction of the cost of converging the exact GJK onto the origin; when
  // separated, its separating direction warm-starts the exact GJK.
  GjkStop stop = GjkStop::Converged;
  Quick quick = Quick::Unsure;
  GjkResult r;
  const Mat3 ra3 = poseA.linear();
  if (options.penetration && options.method == PenetrationMethod::Mpr) {
    MprOut mo;
    Vec3 sep;
    const MprStop ms = mprOnCores(m, options, mo, sep, it);
    if (ms == MprStop::Overlap) {
      storeCache(cache, poseA, v, false, m, it);
      r.distance = -mo.depth - ra - rb;
      r.normal = ra3 * mo.n;
      r.pointA = poseA * Vec3(mo.pa + ra * mo.n);
      r.pointB = poseA * Vec3(mo.pb - rb * mo.n);
      return r;
    }
    if (ms == MprStop::Separated) {
      quick = Quick::Separated;  // known: the exact GJK measures the distance
      dir0 = -sep;
    }
  }
  if (options.penetration && quick == Quick::Unsure) {
    Vec3 sep;
    quick = quickIntersect(ShapeSupports{m}, -dir0, std::min(options.maxIterations, kQuickIterations), sep,
                           s.v, 0, it);
    if (quick == Quick::Overlap) s.n = 4;
    if (quick == Quick::Separated) dir0 = -sep;
  }
  if (quick == Quick::Overlap) {
    stop = GjkStop::Overlap;
  } else {
    stop = runGjk(m, dir0, -1.0, kInf, options, s, v, it);
  }
  storeCache(cache, poseA, v, stop != GjkStop::Overlap && v.squaredNorm() > 0, m, it);

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

#undef DM_GJK_AVX2
