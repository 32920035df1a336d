// simplify.cpp — quadric edge collapse (Garland & Heckbert 1997), LOD chains,
// and a BVH-accelerated sampled Hausdorff distance.
#include <dm/core/tasks.hpp>
#include <dm/math/geometry.hpp>
#include <dm/math/simplify.hpp>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <queue>
#include <string>
#include <utility>
#include <vector>

#include "math_internal.hpp"

namespace dm {
namespace {

using detail::kNone;

// ---------------------------------------------------------------------------
// Bounding-volume hierarchy over triangles for closest-point queries.

class TriangleBvh {
 public:
  TriangleBvh(const std::vector<Vec3>& positions, const std::vector<Triangle>& triangles)
      : positions_(positions), triangles_(triangles) {
    const std::size_t n = positions.size();
    for (std::uint32_t t = 0; t < triangles.size(); ++t) {
      const Triangle& tri = triangles[t];
      if (tri[0] < n && tri[1] < n && tri[2] < n) prims_.push_back(t);
    }
    if (prims_.empty()) return;
    std::vector<Vec3> centroids(triangles.size());
    for (std::uint32_t t : prims_)
      centroids[t] =
          (positions[triangles[t][0]] + positions[triangles[t][1]] + positions[triangles[t][2]]) / 3.0;
    nodes_.reserve(4 * prims_.size() / kLeafSize + 2);
    nodes_.emplace_back();
    build(centroids, 0, 0, static_cast<std::uint32_t>(prims_.size()));
  }

  bool empty() const { return prims_.empty(); }

  /// min(bestSq, squared distance from p to the closest triangle); `point`
  /// receives the closest point when one closer than bestSq is found.
  double closestSq(const Vec3& p, double bestSq, Vec3& point) const {
    if (nodes_.empty()) return bestSq;
    std::array<std::uint32_t, 128> stack{};
    int top = 0;
    stack[top++] = 0;
    while (top > 0) {
      const Node& node = nodes_[stack[--top]];
      if (boxDistSq(node, p) >= bestSq) continue;
      if (node.count > 0) {
        for (std::uint32_t i = node.first; i < node.first + node.count; ++i) {
          const Triangle& tri = triangles_[prims_[i]];
          const TriangleClosest c =
              closestPointOnTriangle(p, positions_[tri[0]], positions_[tri[1]], positions_[tri[2]]);
          if (c.distanceSq < bestSq) {
            bestSq = c.distanceSq;
            point = c.point;
          }
        }
        continue;
      }
      const std::uint32_t l = node.first, r = node.first + 1;
      const double dl = boxDistSq(nodes_[l], p), dr = boxDistSq(nodes_[r], p);
      // Depth is bounded by the median split (log2 of the triangle count), so
      // 128 entries cannot overflow; DM_DEMAND documents it.
      DM_DEMAND(top + 2 <= static_cast<int>(stack.size()), "BVH deeper than its stack");
      if (dl < dr) {
        if (dr < bestSq) stack[top++] = r;
        if (dl < bestSq) stack[top++] = l;
      } else {
        if (dl < bestSq) stack[top++] = l;
        if (dr < bestSq) stack[top++] = r;
      }
    }
    return bestSq;
  }

  /// True when some triangle lies within sqrt(maxSq) of p (stops at the first).
  bool within(const Vec3& p, double maxSq) const {
    if (nodes_.empty()) return false;
    std::array<std::uint32_t, 128> stack{};
    int top = 0;
    stack[top++] = 0;
    while (top > 0) {
      const Node& node = nodes_[stack[--top]];
      if (boxDistSq(node, p) > maxSq) continue;
      if (node.count > 0) {
        for (std::uint32_t i = node.first; i < node.first + node.count; ++i) {
          const Triangle& tri = triangles_[prims_[i]];
          if (closestPointOnTriangle(p, positions_[tri[0]], positions_[tri[1]], positions_[tri[2]])
                  .distanceSq <= maxSq)
            return true;
        }
        continue;
      }
      // The nearer child first: a hit there ends the search.
      const std::uint32_t l = node.first, r = node.first + 1;
      const bool leftNearer = boxDistSq(nodes_[l], p) <= boxDistSq(nodes_[r], p);
      DM_DEMAND(top + 2 <= static_cast<int>(stack.size()), "BVH deeper than its stack");
      stack[top++] = leftNearer ? r : l;
      stack[top++] = leftNearer ? l : r;
    }
    return false;
  }

 private:
  static constexpr std::uint32_t kLeafSize = 4;
  struct Node {
    Vec3 lo, hi;
    std::uint32_t first = 0;  ///< leaf: first primitive; inner: index of the left child (right = first + 1)
    std::uint32_t count = 0;  ///< primitives in a leaf, 0 for an inner node
  };

  static double boxDistSq(const Node& n, const Vec3& p) {
    double d = 0;
    for (int k = 0; k < 3; ++k) {
      const double below = n.lo[k] - p[k], above = p[k] - n.hi[k];
      const double e = below > 0 ? below : (above > 0 ? above : 0.0);
      d += e * e;
    }
    return d;
  }

  void build(const std::vector<Vec3>& centroids, std::uint32_t index, std::uint32_t begin,
             std::uint32_t end) {
    Vec3 lo = Vec3::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
    Vec3 clo = lo, chi = hi;
    for (std::uint32_t i = begin; i < end; ++i) {
      const Triangle& tri = triangles_[prims_[i]];
      for (int c = 0; c < 3; ++c) {
        lo = lo.cwiseMin(positions_[tri[c]]);
        hi = hi.cwiseMax(positions_[tri[c]]);
      }
      clo = clo.cwiseMin(centroids[prims_[i]]);
      chi = chi.cwiseMax(centroids[prims_[i]]);
    }
    nodes_[index].lo = lo;
    nodes_[index].hi = hi;
    if (end - begin <= kLeafSize) {
      nodes_[index].first = begin;
      nodes_[index].count = end - begin;
      return;
    }
    int axis = 0;
    (chi - clo).maxCoeff(&axis);
    const std::uint32_t mid = begin + (end - begin) / 2;
    std::nth_element(
        prims_.begin() + begin, prims_.begin() + mid, prims_.begin() + end,
        [&](std::uint32_t a, std::uint32_t b) { return centroids[a][axis] < centroids[b][axis]; });
    // Children are allocated as a pair so that the right one is left + 1;
    // the median split bounds the recursion depth by log2(triangles).
    const auto left = static_cast<std::uint32_t>(nodes_.size());
    nodes_.emplace_back();
    nodes_.emplace_back();
    nodes_[index].first = left;
    nodes_[index].count = 0;
    build(centroids, left, begin, mid);
    build(centroids, left + 1, mid, end);
  }

  const std::vector<Vec3>& positions_;
  const std::vector<Triangle>& triangles_;
  std::vector<std::uint32_t> prims_;
  std::vector<Node> nodes_;
};

// ---------------------------------------------------------------------------
// Quadrics: symmetric 4x4 [A b; bᵀ c] stored as its 10 distinct entries.

struct Quadric {
  double a00 = 0, a01 = 0, a02 = 0, a11 = 0, a12 = 0, a22 = 0, b0 = 0, b1 = 0, b2 = 0, c = 0;

  static Quadric plane(const Vec3& n, double d, double w) {
    Quadric q;
    q.a00 = w * n.x() * n.x();
    q.a01 = w * n.x() * n.y();
    q.a02 = w * n.x() * n.z();
    q.a11 = w * n.y() * n.y();
    q.a12 = w * n.y() * n.z();
    q.a22 = w * n.z() * n.z();
    q.b0 = w * n.x() * d;
    q.b1 = w * n.y() * d;
    q.b2 = w * n.z() * d;
    q.c = w * d * d;
    return q;
  }
  Quadric& operator+=(const Quadric& o) {
    a00 += o.a00, a01 += o.a01, a02 += o.a02, a11 += o.a11, a12 += o.a12, a22 += o.a22;
    b0 += o.b0, b1 += o.b1, b2 += o.b2, c += o.c;
    return *this;
  }
  Mat3 A() const {
    Mat3 m;
    m << a00, a01, a02, a01, a11, a12, a02, a12, a22;
    return m;
  }
  Vec3 b() const { return {b0, b1, b2}; }
  /// vᵀAv + 2bᵀv + c, clamped at 0 against round-off.
  double error(const Vec3& v) const { return std::max(0.0, v.dot(A() * v) + 2.0 * b().dot(v) + c); }
};

/// Shape quality 4√3·area / Σ edge², 1 for equilateral, 0 for degenerate.
double triangleQuality(const Vec3& a, const Vec3& b, const Vec3& c) {
  const double s = (b - a).squaredNorm() + (c - b).squaredNorm() + (a - c).squaredNorm();
  if (s <= 0) return 0;
  return 2.0 * std::sqrt(3.0) * (b - a).cross(c - a).norm() / s;
}

constexpr double kBoundaryWeight = 1e3;  ///< penalty-plane weight relative to a face of area edge²
constexpr double kMinNormalCos = 0.2;    ///< faces may turn by up to ~78° in one collapse
constexpr double kMinQuality = 1e-3;     ///< below this a new face counts as a sliver

/// 16 bytes so that the heap stays cache-friendly. The float cost and the
/// 16-bit vertex stamps only order the work: every popped collapse is
/// recomputed and rechecked, so a rounded cost or a wrapped stamp cannot
/// produce a wrong collapse.
struct HeapEntry {
  float cost;
  std::uint32_t u, v;
  std::uint16_t stampU, stampV;
  bool operator>(const HeapEntry& o) const { return cost > o.cost; }
};
static_assert(sizeof(HeapEntry) == 16);

class Simplifier {
 public:
  Simplifier(const Mesh& mesh, const SimplifyOptions& options) : in_(mesh), opt_(options) {}

  Mesh run(std::size_t target) {
    setup();
    std::priority_queue<HeapEntry, std::vector<HeapEntry>, std::greater<>> heap;
    {
      std::vector<HeapEntry> initial;
      initial.reserve(edges_.size());
      for (const auto& [u, v] : edges_) {
        Vec3 p;
        if (!candidate(u, v, p)) continue;
        Quadric q = quadric_[u];
        q += quadric_[v];
        initial.push_back({static_cast<float>(q.error(p)), u, v, stamp_[u], stamp_[v]});
      }
      edges_ = {};
      heap = decltype(heap)(std::greater<>(), std::move(initial));  // O(E) heapify
    }
    const std::size_t start = alive_;
    const double span = start > target ? static_cast<double>(start - target) : 1.0;
    int reported = -1;
    auto progress = [&](double f) {
      if (!opt_.progress) return;
      const int pct = static_cast<int>(std::floor(std::clamp(f, 0.0, 1.0) * 100.0));
      if (pct <= reported) return;
      reported = pct;
      opt_.progress(pct / 100.0);
    };
    progress(0.0);
    while (alive_ > target && !heap.empty()) {
      const HeapEntry e = heap.top();
      heap.pop();
      if (dead_[e.u] || dead_[e.v] || stamp_[e.u] != e.stampU || stamp_[e.v] != e.stampV) continue;
      Vec3 p;
      if (!candidate(e.u, e.v, p)) continue;
      if (!allowed(e.u, e.v, p)) continue;
      collapse(e.u, e.v, p);
      neighbours(e.u, ring_);
      for (std::uint32_t w : ring_) push(heap, e.u, w);
      progress(static_cast<double>(start - alive_) / span);
    }
    progress(1.0);
    return output();
  }

 private:
  // --- setup ---------------------------------------------------------------

  void setup() {
    pos_ = in_.positions;
    const std::size_t nv = pos_.size();
    tris_.reserve(in_.triangles.size());
    for (const Triangle& t : in_.triangles)
      if (t[0] != t[1] && t[1] != t[2] && t[2] != t[0]) tris_.push_back(t);
    faceDead_.assign(tris_.size(), 0);
    alive_ = tris_.size();
    dead_.assign(nv, 0);
    stamp_.assign(nv, 0);
    boundary_.assign(nv, 0);
    locked_.assign(nv, 0);
    quadric_.assign(nv, Quadric{});
    vf_.assign(nv, {});
    for (std::uint32_t f = 0; f < tris_.size(); ++f)
      for (std::uint32_t x : tris_[f]) vf_[x].push_back(f);

    for (std::uint32_t f = 0; f < tris_.size(); ++f) {
      const Triangle& t = tris_[f];
      const Vec3 cr = (pos_[t[1]] - pos_[t[0]]).cross(pos_[t[2]] - pos_[t[0]]);
      const double len = cr.norm();
      if (len <= 0) continue;
      const Vec3 n = cr / len;
      const Quadric q = Quadric::plane(n, -n.dot(pos_[t[0]]), 0.5 * len);
      for (std::uint32_t x : t) quadric_[x] += q;
    }

    // Edges with one face are boundary, with more than two non-manifold.
    const std::vector<std::array<std::uint32_t, 3>> half = sortedEdges();
    edges_.reserve(half.size() / 2 + 1);
    for (std::size_t i = 0; i < half.size();) {
      std::size_t j = i;
      while (j < half.size() && half[j][0] == half[i][0] && half[j][1] == half[i][1]) ++j;
      const std::uint32_t a = half[i][0], b = half[i][1];
      const std::size_t faces = j - i;
      const std::uint32_t face = half[i][2];
      i = j;
      edges_.emplace_back(a, b);
      if (faces > 2) {
        if (opt_.preserveTopology || opt_.preserveBoundary) locked_[a] = locked_[b] = 1;
        continue;
      }
      if (faces != 1) continue;
      boundary_[a] = boundary_[b] = 1;
      if (!opt_.preserveBoundary) continue;
      const Triangle& t = tris_[face];
      const Vec3 edge = pos_[b] - pos_[a];
      const Vec3 fn = (pos_[t[1]] - pos_[t[0]]).cross(pos_[t[2]] - pos_[t[0]]);
      Vec3 n = edge.cross(fn);
      const double len = n.norm();
      if (len <= 0) continue;
      n /= len;
      const Quadric q = Quadric::plane(n, -n.dot(pos_[a]), kBoundaryWeight * edge.squaredNorm());
      quadric_[a] += q;
      quadric_[b] += q;
    }

    if (std::isfinite(opt_.maxError)) {
      // Original sample points (vertices, edge midpoints, face centroids and
      // three inner points per face), each attached to
      // the vertex it collapsed into, in singly linked lists.
      samples_.clear();
      witness_.clear();
      sampleHead_.assign(nv, kNone);
      sampleTail_.assign(nv, kNone);
      sampleNext_.clear();
      auto attach = [&](const Vec3& s, std::uint32_t x, std::uint32_t face) {
        const auto id = static_cast<std::uint32_t>(samples_.size());
        samples_.push_back(s);
        witness_.push_back(face);
        sampleNext_.push_back(kNone);
        if (sampleHead_[x] == kNone)
          sampleHead_[x] = id;
        else
          sampleNext_[sampleTail_[x]] = id;
        sampleTail_[x] = id;
      };
      for (std::uint32_t x = 0; x < nv; ++x)
        if (!vf_[x].empty()) attach(pos_[x], x, vf_[x].front());
      for (std::uint32_t f = 0; f < tris_.size(); ++f) {
        const Triangle& t = tris_[f];
        const Vec3 &a = pos_[t[0]], &b = pos_[t[1]], &c = pos_[t[2]];
        attach((a + b + c) / 3.0, t[0], f);
        attach((4 * a + b + c) / 6.0, t[0], f);
        attach((a + 4 * b + c) / 6.0, t[1], f);
        attach((a + b + 4 * c) / 6.0, t[2], f);
        for (int e = 0; e < 3; ++e)  // each interior edge once
          if (t[e] < t[(e + 1) % 3]) attach(0.5 * (pos_[t[e]] + pos_[t[(e + 1) % 3]]), t[e], f);
      }
      trisOriginal_ = tris_;
      originalBvh_ = std::make_unique<TriangleBvh>(in_.positions, trisOriginal_);
    }
  }

  /// Undirected edges {a < b, face}, one per face side, sorted.
  std::vector<std::array<std::uint32_t, 3>> sortedEdges() const {
    std::vector<std::array<std::uint32_t, 3>> half;
    half.reserve(tris_.size() * 3);
    for (std::uint32_t f = 0; f < tris_.size(); ++f)
      for (int c = 0; c < 3; ++c) {
        std::uint32_t a = tris_[f][c], b = tris_[f][(c + 1) % 3];
        if (a > b) std::swap(a, b);
        half.push_back({a, b, f});
      }
    std::sort(half.begin(), half.end());
    return half;
  }

  // --- candidates ----------------------------------------------------------

  void push(std::priority_queue<HeapEntry, std::vector<HeapEntry>, std::greater<>>& heap, std::uint32_t u,
            std::uint32_t v) {
    Vec3 p;
    if (!candidate(u, v, p)) return;
    Quadric q = quadric_[u];
    q += quadric_[v];
    heap.push({static_cast<float>(q.error(p)), u, v, stamp_[u], stamp_[v]});
  }

  /// Where edge (u, v) collapses to; false when it may never collapse.
  bool candidate(std::uint32_t u, std::uint32_t v, Vec3& p) const {
    if (locked_[u] || locked_[v]) return false;
    Quadric q = quadric_[u];
    q += quadric_[v];
    if (opt_.preserveBoundary && boundary_[u] != boundary_[v]) {
      p = boundary_[u] ? pos_[u] : pos_[v];
      return true;
    }
    const Vec3 a = pos_[u], b = pos_[v], d = b - a;
    const double len = d.norm();
    const Mat3 A = q.A();
    // Candidates in order of preference; ties keep the earlier one.
    std::array<Vec3, 5> cand;
    int n = 0;
    const double det = A.determinant();
    const double scale = A.trace();
    if (scale > 0 && std::abs(det) > 1e-10 * scale * scale * scale) {
      const Vec3 x = A.inverse() * (-q.b());
      if (x.allFinite() && (x - 0.5 * (a + b)).norm() <= len) cand[n++] = x;
    }
    const double dad = d.dot(A * d);
    if (dad > 1e-12 * scale * len * len) {
      const double t = std::clamp(-d.dot(A * a + q.b()) / dad, 0.0, 1.0);
      cand[n++] = a + t * d;
    }
    cand[n++] = a;
    cand[n++] = b;
    cand[n++] = 0.5 * (a + b);
    double best = std::numeric_limits<double>::infinity();
    for (int i = 0; i < n; ++i) {
      const double e = q.error(cand[i]);
      if (e < best * (1 - 1e-12) || i == 0) {
        best = e;
        p = cand[i];
      }
    }
    return true;
  }

  // --- checks --------------------------------------------------------------

  bool hasVertex(std::uint32_t f, std::uint32_t x) const {
    const Triangle& t = tris_[f];
    return t[0] == x || t[1] == x || t[2] == x;
  }

  /// The vertices sharing a face with x, sorted, into `out`.
  void neighbours(std::uint32_t x, std::vector<std::uint32_t>& out) const {
    out.clear();
    for (std::uint32_t f : vf_[x])
      for (std::uint32_t y : tris_[f])
        if (y != x) out.push_back(y);
    std::sort(out.begin(), out.end());
    out.erase(std::unique(out.begin(), out.end()), out.end());
  }

  /// True when some edge of x has exactly one face.
  bool onBoundary(std::uint32_t x) const {
    std::vector<std::uint32_t>& ends = scratchEnds_;
    ends.clear();
    for (std::uint32_t f : vf_[x])
      for (std::uint32_t y : tris_[f])
        if (y != x) ends.push_back(y);
    std::sort(ends.begin(), ends.end());
    for (std::size_t i = 0; i < ends.size();) {
      std::size_t j = i;
      while (j < ends.size() && ends[j] == ends[i]) ++j;
      if (j - i == 1) return true;
      i = j;
    }
    return false;
  }

  /// Vertex position after the virtual collapse of (u, v) to p.
  Vec3 moved(std::uint32_t x, std::uint32_t u, std::uint32_t v, const Vec3& p) const {
    return (x == u || x == v) ? p : pos_[x];
  }

  bool allowed(std::uint32_t u, std::uint32_t v, const Vec3& p) {
    // Faces on the edge, and the vertices opposite it.
    std::vector<std::uint32_t>& opposite = scratchOpposite_;
    opposite.clear();
    for (std::uint32_t f : vf_[u])
      if (hasVertex(f, v))
        for (std::uint32_t y : tris_[f])
          if (y != u && y != v) opposite.push_back(y);
    if (opposite.empty()) return false;  // no longer an edge
    const bool boundaryEdge = opposite.size() == 1;

    if (opt_.preserveBoundary) {
      if (boundary_[u] && boundary_[v] && !boundaryEdge) return false;
    }
    if (opt_.preserveTopology) {
      if (opposite.size() > 2) return false;
      // Link condition: Lk(u) ∩ Lk(v) = Lk(uv); the boundary counts as a
      // virtual vertex linked to every boundary vertex and edge.
      std::vector<std::uint32_t>&nu = scratchU_, &nv = scratchV_;
      neighbours(u, nu);
      neighbours(v, nv);
      std::size_t common = 0;
      for (std::size_t i = 0, j = 0; i < nu.size() && j < nv.size();) {
        if (nu[i] < nv[j]) {
          ++i;
        } else if (nv[j] < nu[i]) {
          ++j;
        } else {
          common += (nu[i] != u && nu[i] != v) ? 1 : 0;
          ++i, ++j;
        }
      }
      if (common != opposite.size()) return false;
      if (!boundaryEdge && onBoundary(u) && onBoundary(v)) return false;
      // A closed piece as small as a tetrahedron would fold onto itself:
      // refuse new faces that repeat an existing face's vertices.
      for (std::uint32_t f : vf_[v]) {
        if (hasVertex(f, u)) continue;
        std::array<std::uint32_t, 3> key = tris_[f];
        for (auto& x : key) x = x == v ? u : x;
        std::sort(key.begin(), key.end());
        for (std::uint32_t g : vf_[u]) {
          if (hasVertex(g, v)) continue;
          std::array<std::uint32_t, 3> other = tris_[g];
          std::sort(other.begin(), other.end());
          if (other == key) return false;
        }
      }
      // No flipped or sliver faces.
      for (std::uint32_t x : {u, v})
        for (std::uint32_t f : vf_[x]) {
          if (hasVertex(f, u) && hasVertex(f, v)) continue;
          const Triangle& t = tris_[f];
          const Vec3 a0 = pos_[t[0]], b0 = pos_[t[1]], c0 = pos_[t[2]];
          const Vec3 a1 = moved(t[0], u, v, p), b1 = moved(t[1], u, v, p), c1 = moved(t[2], u, v, p);
          const Vec3 n0 = (b0 - a0).cross(c0 - a0), n1 = (b1 - a1).cross(c1 - a1);
          const double l0 = n0.norm(), l1 = n1.norm();
          if (l1 <= 0) return false;
          if (l0 > 0 && n0.dot(n1) < kMinNormalCos * l0 * l1) return false;
          const double q1 = triangleQuality(a1, b1, c1);
          if (q1 < kMinQuality && q1 < triangleQuality(a0, b0, c0)) return false;
        }
    }
    if (originalBvh_ && !withinMaxError(u, v, p)) return false;
    return true;
  }

  /// Both directions of the distance bound, for the faces the collapse changes.
  bool withinMaxError(std::uint32_t u, std::uint32_t v, const Vec3& p) const {
    const double maxSq = opt_.maxError * opt_.maxError;
    // New surface -> original: p and sample points of the faces around p.
    if (!originalBvh_->within(p, maxSq)) return false;
    for (std::uint32_t x : {u, v})
      for (std::uint32_t f : vf_[x]) {
        if (hasVertex(f, u) && hasVertex(f, v)) continue;
        const Triangle& t = tris_[f];
        const Vec3 a = moved(t[0], u, v, p), b = moved(t[1], u, v, p), c = moved(t[2], u, v, p);
        if (!originalBvh_->within((a + b + c) / 3.0, maxSq)) return false;
        // A barycentric grid with spacing about maxError (at most 8 steps per
        // edge); the corners are vertices checked when they were placed.
        const double longest =
            std::sqrt(std::max({(b - a).squaredNorm(), (c - b).squaredNorm(), (a - c).squaredNorm()}));
        const double steps = opt_.maxError > 0 ? std::ceil(longest / opt_.maxError) : 8.0;
        const int n = static_cast<int>(std::clamp(steps, 1.0, 8.0));
        for (int i = 0; i <= n; ++i)
          for (int j = 0; i + j <= n; ++j) {
            if (i == n || j == n || i + j == 0) continue;
            const Vec3 s =
                a + (static_cast<double>(i) / n) * (b - a) + (static_cast<double>(j) / n) * (c - a);
            if (!originalBvh_->within(s, maxSq)) return false;
          }
      }
    // Original -> new surface: samples attached to u, v and their neighbours
    // must stay close to the (new) faces around their vertex.
    // Each sample remembers a face of its vertex's ring that covers it (its
    // witness); while that face is alive and untouched by this collapse the
    // sample needs no search. New witnesses are committed by collapse().
    pending_.clear();
    auto ringCovers = [&](std::uint32_t x, std::uint32_t y, std::uint32_t sample) {
      const std::uint32_t w = witness_[sample];
      if (w != kNone && !faceDead_[w] && !hasVertex(w, u) && !hasVertex(w, v)) return true;
      const Vec3& s = samples_[sample];
      for (std::uint32_t owner : {x, y}) {
        if (owner == kNone) continue;
        for (std::uint32_t f : vf_[owner]) {
          if (hasVertex(f, u) && hasVertex(f, v)) continue;
          const Triangle& t = tris_[f];
          if (closestPointOnTriangle(s, moved(t[0], u, v, p), moved(t[1], u, v, p), moved(t[2], u, v, p))
                  .distanceSq <= maxSq) {
            pending_.emplace_back(sample, f);
            return true;
          }
        }
      }
      return false;
    };
    for (std::uint32_t x : {u, v})
      for (std::uint32_t s = sampleHead_[x]; s != kNone; s = sampleNext_[s])
        if (!ringCovers(u, v, s)) return false;
    std::vector<std::uint32_t>&ring = scratchU_, &rv = scratchV_;
    neighbours(u, ring);
    neighbours(v, rv);
    ring.insert(ring.end(), rv.begin(), rv.end());
    std::sort(ring.begin(), ring.end());
    ring.erase(std::unique(ring.begin(), ring.end()), ring.end());
    for (std::uint32_t w : ring) {
      if (w == u || w == v) continue;
      for (std::uint32_t s = sampleHead_[w]; s != kNone; s = sampleNext_[s])
        if (!ringCovers(w, kNone, s)) return false;
    }
    return true;
  }

  // --- collapse ------------------------------------------------------------

  /// Collapses v into u, which moves to p.
  void collapse(std::uint32_t u, std::uint32_t v, const Vec3& p) {
    for (const auto& [sample, face] : pending_) witness_[sample] = face;
    pending_.clear();
    for (std::uint32_t f : vf_[v]) {
      if (faceDead_[f]) continue;
      if (hasVertex(f, u)) {
        faceDead_[f] = 1;
        --alive_;
        for (std::uint32_t y : tris_[f])
          if (y != v) std::erase(vf_[y], f);
      } else {
        for (auto& y : tris_[f]) y = y == v ? u : y;
        vf_[u].push_back(f);
      }
    }
    vf_[v].clear();
    vf_[v].shrink_to_fit();
    pos_[u] = p;
    quadric_[u] += quadric_[v];
    boundary_[u] = boundary_[u] | boundary_[v];
    dead_[v] = 1;
    ++stamp_[u];
    if (!sampleHead_.empty() && sampleHead_[v] != kNone) {
      if (sampleHead_[u] == kNone)
        sampleHead_[u] = sampleHead_[v];
      else
        sampleNext_[sampleTail_[u]] = sampleHead_[v];
      sampleTail_[u] = sampleTail_[v];
      sampleHead_[v] = sampleTail_[v] = kNone;
    }
  }

  Mesh output() const {
    Mesh out;
    out.name = in_.name;
    std::vector<std::uint32_t> remap(pos_.size(), kNone);
    const bool uvs = in_.uvs.size() == pos_.size(), colors = in_.colors.size() == pos_.size();
    for (std::uint32_t f = 0; f < tris_.size(); ++f) {
      if (faceDead_[f]) continue;
      Triangle t = tris_[f];
      for (auto& x : t) {
        if (remap[x] == kNone) {
          remap[x] = static_cast<std::uint32_t>(out.positions.size());
          out.positions.push_back(pos_[x]);
          if (uvs) out.uvs.push_back(in_.uvs[x]);
          if (colors) out.colors.push_back(in_.colors[x]);
        }
        x = remap[x];
      }
      out.triangles.push_back(t);
    }
    out.computeNormals();
    return out;
  }

  const Mesh& in_;
  const SimplifyOptions& opt_;
  std::vector<Vec3> pos_;
  std::vector<Triangle> tris_, trisOriginal_;
  std::vector<char> faceDead_, dead_, boundary_, locked_;
  std::vector<std::uint16_t> stamp_;
  std::vector<Quadric> quadric_;
  std::vector<std::vector<std::uint32_t>> vf_;
  std::size_t alive_ = 0;
  std::vector<Vec3> samples_;
  std::vector<std::uint32_t> sampleHead_, sampleTail_, sampleNext_, witness_;
  /// (sample, face) witnesses found by the last withinMaxError(), for collapse().
  mutable std::vector<std::pair<std::uint32_t, std::uint32_t>> pending_;
  std::unique_ptr<TriangleBvh> originalBvh_;
  // Scratch lists reused by every collapse (no allocation once warm).
  std::vector<std::uint32_t> ring_;
  std::vector<std::pair<std::uint32_t, std::uint32_t>> edges_;  ///< unique edges, until the heap is built
  mutable std::vector<std::uint32_t> scratchU_, scratchV_, scratchEnds_, scratchOpposite_;
};

/// Deterministic per-triangle random numbers in [0, 1) (SplitMix64).
double unitRandom(std::uint64_t& state) {
  std::uint64_t z = (state += 0x9E3779B97F4A7C15ull);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  z ^= z >> 31;
  return static_cast<double>(z >> 11) * 0x1.0p-53;
}

/// Largest distance from sample points of `from` to the surface of `to`.
double oneSidedDistance(const Mesh& from, const TriangleBvh& to, int samplesPerTriangle) {
  const std::size_t nv = from.positions.size();
  const std::size_t nt = from.triangles.size();
  std::vector<double> worst(nt, 0.0);
  std::vector<char> used(nv, 0);
  for (const Triangle& t : from.triangles)
    if (t[0] < nv && t[1] < nv && t[2] < nv) used[t[0]] = used[t[1]] = used[t[2]] = 1;
  std::vector<double> vertexWorst(nv, 0.0);
  // Consecutive samples are close to each other, so the previous closest
  // point (on the surface, hence an upper bound) seeds each search.
  struct Seeded {
    const TriangleBvh& bvh;
    bool have = false;
    Vec3 last = Vec3::Zero();
    double operator()(const Vec3& p) {
      const double seed = have ? (p - last).squaredNorm() : std::numeric_limits<double>::infinity();
      Vec3 c = last;
      const double d = bvh.closestSq(p, seed, c);
      last = c;
      have = true;
      return d;
    }
  };
  parallelFor(0, nv, 1024, [&](std::size_t b, std::size_t e) {
    Seeded query{to};
    for (std::size_t i = b; i < e; ++i)
      if (used[i]) vertexWorst[i] = query(from.positions[i]);
  });
  parallelFor(0, nt, 256, [&](std::size_t b, std::size_t e) {
    Seeded query{to};
    for (std::size_t i = b; i < e; ++i) {
      const Triangle& t = from.triangles[i];
      if (t[0] >= nv || t[1] >= nv || t[2] >= nv) continue;
      const Vec3 &a = from.positions[t[0]], &bb = from.positions[t[1]], &c = from.positions[t[2]];
      double w = 0;
      auto probe = [&](const Vec3& s) { w = std::max(w, query(s)); };
      probe((a + bb + c) / 3.0);
      probe(0.5 * (a + bb));
      probe(0.5 * (bb + c));
      probe(0.5 * (c + a));
      std::uint64_t state = 0x5DEECE66Dull ^ (static_cast<std::uint64_t>(i) * 0x2545F4914F6CDD1Dull);
      for (int k = 0; k < samplesPerTriangle; ++k) {
        double r1 = unitRandom(state), r2 = unitRandom(state);
        if (r1 + r2 > 1) r1 = 1 - r1, r2 = 1 - r2;
        probe(a + r1 * (bb - a) + r2 * (c - a));
      }
      worst[i] = w;
    }
  });
  double m = 0;
  for (double w : worst) m = std::max(m, w);
  for (double w : vertexWorst) m = std::max(m, w);
  return std::sqrt(m);
}

}  // namespace

double hausdorffDistance(const Mesh& a, const Mesh& b, int samplesPerTriangle) {
  const TriangleBvh ba(a.positions, a.triangles), bb(b.positions, b.triangles);
  if (ba.empty() && bb.empty()) return 0.0;
  if (ba.empty() || bb.empty()) return std::numeric_limits<double>::infinity();
  samplesPerTriangle = std::max(0, samplesPerTriangle);
  return std::max(oneSidedDistance(a, bb, samplesPerTriangle), oneSidedDistance(b, ba, samplesPerTriangle));
}

Result<Mesh> simplifyMesh(const Mesh& mesh, const SimplifyOptions& options, SimplifyReport* report) {
  const std::string where = mesh.name.empty() ? "simplifyMesh" : "simplifyMesh: mesh '" + mesh.name + "'";
  if (mesh.triangles.empty())
    return fail(ErrorCode::InvalidArgument, "mesh has no triangles", where, "pass a non-empty triangle mesh");
  if (auto s = mesh.validate(); !s) return s.error().within(where);
  if (options.targetTriangles == 0 && !(options.targetRatio > 0.0 && options.targetRatio <= 1.0))
    return fail(ErrorCode::InvalidArgument,
                "targetRatio " + std::to_string(options.targetRatio) + " is outside (0, 1]", where,
                "give the fraction of triangles to keep, e.g. 0.25, or set targetTriangles");
  if (!(options.maxError >= 0.0))
    return fail(ErrorCode::InvalidArgument,
                "maxError " + std::to_string(options.maxError) + " is negative or NaN", where,
                "give a distance in metres, or infinity for no limit");
  if (mesh.triangles.size() >= std::size_t{kNone})
    return fail(ErrorCode::InvalidArgument, "too many triangles for 32-bit indices", where);

  const std::size_t target = options.targetTriangles > 0
                                 ? options.targetTriangles
                                 : static_cast<std::size_t>(std::llround(
                                       options.targetRatio * static_cast<double>(mesh.triangles.size())));
  Simplifier s(mesh, options);
  Mesh out = s.run(std::max<std::size_t>(target, 1));
  if (report) {
    report->trianglesBefore = mesh.triangles.size();
    report->trianglesAfter = out.triangles.size();
    report->maxDistance = hausdorffDistance(out, mesh, 0);
  }
  return out;
}

Result<std::vector<MeshLod>> buildLods(const Mesh& mesh, std::span<const double> ratios,
                                       const SimplifyOptions& base) {
  double previous = 1.0;
  for (std::size_t i = 0; i < ratios.size(); ++i) {
    if (!(ratios[i] > 0.0 && ratios[i] <= 1.0) || (i > 0 && !(ratios[i] < previous)))
      return fail(ErrorCode::InvalidArgument,
                  "ratios[" + std::to_string(i) + "] = " + std::to_string(ratios[i]) +
                      " is outside (0, 1] or not below the previous level",
                  "buildLods",
                  "give strictly decreasing fractions of the input's triangles, e.g. {0.5, 0.2, 0.05}");
    previous = ratios[i];
  }
  if (mesh.triangles.empty())
    return fail(ErrorCode::InvalidArgument, "mesh has no triangles", "buildLods",
                "pass a non-empty triangle mesh");
  std::vector<MeshLod> lods;
  lods.reserve(ratios.size() + 1);
  lods.push_back({mesh, 1.0, 0.0});
  const auto inputTriangles = static_cast<double>(mesh.triangles.size());
  for (std::size_t i = 0; i < ratios.size(); ++i) {
    SimplifyOptions opt = base;
    opt.targetTriangles =
        std::max<std::size_t>(1, static_cast<std::size_t>(std::llround(ratios[i] * inputTriangles)));
    if (base.progress) {
      const double lo = static_cast<double>(i) / static_cast<double>(ratios.size());
      const double width = 1.0 / static_cast<double>(ratios.size());
      opt.progress = [&base, lo, width](double f) { base.progress(lo + width * f); };
    }
    auto next = simplifyMesh(lods.back().mesh, opt);
    if (!next) return std::move(next).error().within("buildLods: level " + std::to_string(i + 1));
    const double d = hausdorffDistance(*next, mesh, 0);
    const double ratio = static_cast<double>(next->triangles.size()) / inputTriangles;
    lods.push_back({std::move(*next), ratio, d});
  }
  return lods;
}

}  // namespace dm
