// convex_hull.cpp — Quickhull with face merging (after J. Lloyd's QuickHull3D).
//
// The hull is a half-edge mesh of convex polygonal faces. Each face owns the
// points above it (its outside set). Repeatedly, the point farthest above some
// face (the eye) is added: the faces it sees are found by a depth-first walk
// from that face, their boundary (the horizon) is joined to the eye by a cone
// of new triangles, and new faces that are coplanar with or non-convex towards
// a neighbour within the tolerance are merged with it, so that the hull stays
// convex and later visibility tests stay well conditioned. Points of deleted
// faces are reassigned to the new faces or dropped when inside. All geometry
// is relative to the centre of the bounding box, with the tolerance relative
// to the cloud's extent.
#include <dm/math/convex_hull.hpp>

#include <algorithm>
#include <array>
#include <cfloat>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "math_internal.hpp"

namespace dm {
namespace {

using detail::kNone;
constexpr const char* kWhere = "convexHull";

std::string formatCoarse(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3g", v);
  return buf;
}

struct HalfEdge {
  std::uint32_t head = kNone;  // vertex the edge points to; its tail is prev's head
  std::uint32_t face = kNone;
  std::uint32_t next = kNone;
  std::uint32_t prev = kNone;
  std::uint32_t twin = kNone;
};

enum class Mark : std::uint8_t { kVisible, kNonConvex, kDeleted };

struct Face {
  std::uint32_t edge = kNone;  // any half-edge of the face's loop
  Vec3 normal = Vec3::Zero();  // unit, outward
  Vec3 centroid = Vec3::Zero();
  double offset = 0;  // normal · centroid
  double area = 0;    // twice the polygon's area
  Mark mark = Mark::kVisible;
  std::vector<std::uint32_t> outside;  // points above this face, assigned to it
};

/// A face being walked by computeHorizon(): entered through `edge0`, next
/// edge to look across `edge`.
struct HorizonFrame {
  std::uint32_t face, edge0, edge;
  bool done;
};

enum class MergeRule {
  kNonConvexWrtLargerFace,  // merge when the larger face sees the smaller one's centroid as not below
  kNonConvex,               // merge when either face does
};

Status internalError(const std::string& what) {
  return fail(ErrorCode::Internal, "convex hull construction lost consistency: " + what, kWhere,
              "please report this with the input points; as a workaround raise "
              "ConvexHullOptions::relativeTolerance (e.g. 1e-9)");
}

class QuickHull {
 public:
  QuickHull(std::vector<Vec3> points, double tolerance)
      : p_(std::move(points)), tol_(tolerance), stamp_(p_.size(), 0) {}

  /// Builds the hull starting from the tetrahedron `simplex` (point indices,
  /// not coplanar).
  Status build(const std::array<std::uint32_t, 4>& simplex) {
    createSimplex(simplex);
    std::size_t head = 0;
    while (head < queue_.size()) {
      const std::uint32_t f = queue_[head];
      if (f_[f].mark == Mark::kDeleted || f_[f].outside.empty()) {
        ++head;
        continue;
      }
      // Farthest point; distances may have changed since assignment if the
      // face was merged, so they are recomputed.
      std::uint32_t eye = kNone;
      double best = tol_;
      for (const std::uint32_t i : f_[f].outside) {
        const double d = distance(f, p_[i]);
        if (d > best) {
          best = d;
          eye = i;
        }
      }
      if (eye == kNone) {
        // After merging, the remaining points lie within the tolerance of the
        // face: they are on the hull.
        f_[f].outside.clear();
        ++head;
        continue;
      }
      if (auto s = addPoint(eye, f); !s) return s;
    }
    return ok();
  }

  /// The faces of the hull, triangulated without new vertices; indices into
  /// the points, counter-clockwise seen from outside.
  std::vector<Triangle> triangles() const {
    std::vector<Triangle> out;
    std::vector<std::uint32_t> poly;
    for (std::size_t f = 0; f < f_.size(); ++f) {
      if (f_[f].mark == Mark::kDeleted) continue;
      poly.clear();
      std::uint32_t h = f_[f].edge;
      do {
        poly.push_back(e_[h].head);
        h = e_[h].next;
      } while (h != f_[f].edge);
      triangulate(poly, out);
    }
    return out;
  }

 private:
  std::uint32_t tail(std::uint32_t h) const { return e_[e_[h].prev].head; }
  std::uint32_t oppositeFace(std::uint32_t h) const { return e_[e_[h].twin].face; }
  double distance(std::uint32_t f, const Vec3& x) const { return f_[f].normal.dot(x) - f_[f].offset; }
  void link(std::uint32_t a, std::uint32_t b) {
    e_[a].twin = b;
    e_[b].twin = a;
  }

  /// Newell-style normal (sum of fan cross products), area and vertex mean.
  void computeNormalAndCentroid(std::uint32_t f) {
    Face& face = f_[f];
    const std::uint32_t h0 = face.edge;
    const Vec3& p0 = p_[e_[h0].head];
    std::uint32_t h1 = e_[h0].next;
    Vec3 d2 = p_[e_[h1].head] - p0;
    Vec3 n = Vec3::Zero();
    Vec3 sum = p0 + p_[e_[h1].head];
    int count = 2;
    for (std::uint32_t h2 = e_[h1].next; h2 != h0; h2 = e_[h2].next) {
      const Vec3 d1 = d2;
      d2 = p_[e_[h2].head] - p0;
      n += d1.cross(d2);
      sum += p_[e_[h2].head];
      ++count;
    }
    const double len = n.norm();
    face.area = len;
    face.normal = len > 0 ? Vec3(n / len) : Vec3::Zero();
    face.centroid = sum / count;
    face.offset = face.normal.dot(face.centroid);
  }

  std::size_t vertexCount(std::uint32_t f) const {
    std::size_t n = 0;
    std::uint32_t h = f_[f].edge;
    do {
      ++n;
      h = e_[h].next;
    } while (h != f_[f].edge);
    return n;
  }

  /// Triangle a → b → c (counter-clockwise seen from outside). Its first
  /// half-edge goes c → a, the second a → b, the third b → c.
  std::uint32_t createTriangle(std::uint32_t a, std::uint32_t b, std::uint32_t c) {
    const auto f = static_cast<std::uint32_t>(f_.size());
    const auto e = static_cast<std::uint32_t>(e_.size());
    f_.emplace_back();
    e_.push_back(HalfEdge{a, f, e + 1, e + 2, kNone});
    e_.push_back(HalfEdge{b, f, e + 2, e, kNone});
    e_.push_back(HalfEdge{c, f, e, e + 1, kNone});
    f_[f].edge = e;
    computeNormalAndCentroid(f);
    return f;
  }

  void addPointToFace(std::uint32_t f, std::uint32_t i) {
    f_[f].outside.push_back(i);
    if (f_[f].outside.size() == 1) queue_.push_back(f);
  }

  /// Empties the outside set of `f`: points above `absorbing` (if any) go to
  /// it, the others to the unclaimed list; `skip` is dropped.
  void deletePoints(std::uint32_t f, std::uint32_t absorbing, std::uint32_t skip) {
    std::vector<std::uint32_t> pts;
    pts.swap(f_[f].outside);
    for (const std::uint32_t i : pts) {
      if (i == skip) continue;
      if (absorbing != kNone && distance(absorbing, p_[i]) > tol_)
        addPointToFace(absorbing, i);
      else
        unclaimed_.push_back(i);
    }
  }

  void createSimplex(const std::array<std::uint32_t, 4>& s) {
    // Each face of the tetrahedron, ordered so that the fourth vertex is below it.
    constexpr std::array<std::array<std::size_t, 4>, 4> kFaces = {
        {{0, 1, 2, 3}, {0, 1, 3, 2}, {0, 2, 3, 1}, {1, 2, 3, 0}}};
    for (const auto& k : kFaces) {
      const std::uint32_t a = s[k[0]], o = s[k[3]];
      std::uint32_t b = s[k[1]], c = s[k[2]];
      if ((p_[b] - p_[a]).cross(p_[c] - p_[a]).dot(p_[o] - p_[a]) > 0) std::swap(b, c);
      createTriangle(a, b, c);
    }
    for (std::uint32_t h = 0; h < 12; ++h)
      for (std::uint32_t g = 0; g < 12; ++g)
        if (e_[g].head == tail(h) && tail(g) == e_[h].head) e_[h].twin = g;
    for (std::uint32_t i = 0; i < p_.size(); ++i) {
      if (i == s[0] || i == s[1] || i == s[2] || i == s[3]) continue;
      std::uint32_t best = kNone;
      double bestDist = tol_;
      for (std::uint32_t f = 0; f < 4; ++f) {
        const double d = distance(f, p_[i]);
        if (d > bestDist) {
          bestDist = d;
          best = f;
        }
      }
      if (best != kNone) addPointToFace(best, i);
    }
  }

  /// Deletes the faces visible from the eye (depth-first from `eyeFace`,
  /// which the eye is above) and collects the horizon: the half-edges of
  /// deleted faces whose twins belong to kept faces, as one loop in order.
  void computeHorizon(std::uint32_t eye, std::uint32_t eyeFace) {
    std::vector<HorizonFrame>& stack = frames_;
    stack.clear();
    const auto enter = [&](std::uint32_t f, std::uint32_t edge0) {
      deletePoints(f, kNone, eye);
      f_[f].mark = Mark::kDeleted;
      if (edge0 == kNone)
        stack.push_back(HorizonFrame{f, f_[f].edge, f_[f].edge, false});
      else
        stack.push_back(HorizonFrame{f, edge0, e_[edge0].next, false});
    };
    enter(eyeFace, kNone);
    while (!stack.empty()) {
      HorizonFrame& top = stack.back();
      if (top.done) {
        stack.pop_back();
        continue;
      }
      const std::uint32_t h = top.edge;
      top.edge = e_[h].next;
      if (top.edge == top.edge0) top.done = true;
      const std::uint32_t opp = oppositeFace(h);
      if (f_[opp].mark != Mark::kVisible) continue;
      if (distance(opp, p_[eye]) > tol_)
        enter(opp, e_[h].twin);  // invalidates `top`
      else
        horizon_.push_back(h);
    }
  }

  Status addPoint(std::uint32_t eye, std::uint32_t eyeFace) {
    horizon_.clear();
    unclaimed_.clear();
    newFaces_.clear();
    computeHorizon(eye, eyeFace);

    // The horizon must be one simple loop, or the cone below would not close.
    const std::size_t n = horizon_.size();
    if (n < 3) return internalError("horizon of point " + std::to_string(eye) + " has fewer than 3 edges");
    ++iteration_;
    for (std::size_t k = 0; k < n; ++k) {
      const std::uint32_t h = horizon_[k];
      if (e_[h].head != tail(horizon_[(k + 1) % n]) || stamp_[e_[h].head] == iteration_)
        return internalError("horizon of point " + std::to_string(eye) + " is not a simple loop");
      stamp_[e_[h].head] = iteration_;
    }

    // Cone of triangles eye → tail → head over the horizon.
    std::uint32_t firstSide = kNone, prevSide = kNone;
    for (const std::uint32_t h : horizon_) {
      const std::uint32_t f = createTriangle(eye, tail(h), e_[h].head);
      const std::uint32_t h0 = f_[f].edge;  // head → eye
      link(h0 + 2, e_[h].twin);             // tail → head, across the horizon
      if (prevSide != kNone)
        link(h0 + 1, prevSide);  // eye → tail, next to the previous triangle's tail → eye
      else
        firstSide = h0;
      prevSide = h0;
      newFaces_.push_back(f);
    }
    link(firstSide + 1, prevSide);

    // First merge the faces that are non-convex as judged by the larger one
    // (the better conditioned plane), then any that remain non-convex.
    for (const std::uint32_t f : newFaces_)
      if (f_[f].mark == Mark::kVisible)
        while (mergeAdjacent(f, MergeRule::kNonConvexWrtLargerFace)) {
        }
    for (const std::uint32_t f : newFaces_)
      if (f_[f].mark == Mark::kNonConvex) {
        f_[f].mark = Mark::kVisible;
        while (mergeAdjacent(f, MergeRule::kNonConvex)) {
        }
      }

    // Points of the deleted faces go to the new face they are farthest above,
    // or are inside the hull.
    for (const std::uint32_t i : unclaimed_) {
      double bestDist = tol_;
      std::uint32_t best = kNone;
      for (const std::uint32_t f : newFaces_) {
        if (f_[f].mark != Mark::kVisible) continue;
        const double d = distance(f, p_[i]);
        if (d > bestDist) {
          bestDist = d;
          best = f;
          if (bestDist > 1000 * tol_) break;  // clearly outside: good enough
        }
      }
      if (best != kNone) addPointToFace(best, i);
    }
    return ok();
  }

  /// Distance of the centroid of the face across `h` from the plane of h's face.
  double oppositeFaceDistance(std::uint32_t h) const {
    return distance(e_[h].face, f_[oppositeFace(h)].centroid);
  }

  /// Merges `f` with the first neighbour that `rule` says is not convexly
  /// joined to it; returns whether it did. Under kNonConvexWrtLargerFace a
  /// face that only the smaller side finds non-convex is marked kNonConvex.
  bool mergeAdjacent(std::uint32_t f, MergeRule rule) {
    std::uint32_t h = f_[f].edge;
    bool convex = true;
    do {
      const std::uint32_t opp = oppositeFace(h);
      bool merge = false;
      if (rule == MergeRule::kNonConvex) {
        merge = oppositeFaceDistance(h) > -tol_ || oppositeFaceDistance(e_[h].twin) > -tol_;
      } else if (f_[f].area > f_[opp].area) {
        if (oppositeFaceDistance(h) > -tol_)
          merge = true;
        else if (oppositeFaceDistance(e_[h].twin) > -tol_)
          convex = false;
      } else {
        if (oppositeFaceDistance(e_[h].twin) > -tol_)
          merge = true;
        else if (oppositeFaceDistance(h) > -tol_)
          convex = false;
      }
      if (merge) {
        std::array<std::uint32_t, 3> discarded{};
        const std::size_t count = absorb(f, h, discarded);
        for (std::size_t k = 0; k < count; ++k) deletePoints(discarded[k], f, kNone);
        return true;
      }
      h = e_[h].next;
    } while (h != f_[f].edge);
    if (!convex) f_[f].mark = Mark::kNonConvex;
    return false;
  }

  /// Merges the face across `hAdj` (and the whole run of edges they share)
  /// into `f`. Returns the faces deleted: the absorbed one, plus triangles
  /// that collapsed when a vertex of degree 2 was removed.
  std::size_t absorb(std::uint32_t f, std::uint32_t hAdj, std::array<std::uint32_t, 3>& discarded) {
    const std::uint32_t opp = oppositeFace(hAdj);
    std::size_t count = 0;
    discarded[count++] = opp;
    f_[opp].mark = Mark::kDeleted;

    const std::uint32_t hOpp = e_[hAdj].twin;
    std::uint32_t hAdjPrev = e_[hAdj].prev, hAdjNext = e_[hAdj].next;
    std::uint32_t hOppPrev = e_[hOpp].prev, hOppNext = e_[hOpp].next;
    // Extend over all consecutive edges shared with `opp`.
    while (oppositeFace(hAdjPrev) == opp) {
      hAdjPrev = e_[hAdjPrev].prev;
      hOppNext = e_[hOppNext].next;
    }
    while (oppositeFace(hAdjNext) == opp) {
      hOppPrev = e_[hOppPrev].prev;
      hAdjNext = e_[hAdjNext].next;
    }
    for (std::uint32_t h = hOppNext; h != e_[hOppPrev].next; h = e_[h].next) e_[h].face = f;
    // hAdjNext stays in f whatever is removed below (unlike the shared run).
    f_[f].edge = hAdjNext;
    if (const std::uint32_t d = connect(f, hOppPrev, hAdjNext); d != kNone) discarded[count++] = d;
    if (const std::uint32_t d = connect(f, hAdjPrev, hOppNext); d != kNone) discarded[count++] = d;
    computeNormalAndCentroid(f);
    return count;
  }

  /// Makes `hPrev` → `h` consecutive in `f`. When both border the same face,
  /// their common vertex has degree 2 and is removed; if that face was a
  /// triangle it collapses and is returned for deletion.
  std::uint32_t connect(std::uint32_t f, std::uint32_t hPrev, std::uint32_t h) {
    std::uint32_t discarded = kNone;
    if (oppositeFace(hPrev) == oppositeFace(h)) {
      const std::uint32_t opp = oppositeFace(h);
      std::uint32_t hOpp;
      if (hPrev == f_[f].edge) f_[f].edge = h;
      if (vertexCount(opp) == 3) {
        // opp degenerates to two edges: h takes over the twin of its third edge.
        hOpp = e_[e_[e_[h].twin].prev].twin;
        f_[opp].mark = Mark::kDeleted;
        discarded = opp;
      } else {
        hOpp = e_[e_[h].twin].next;
        if (f_[opp].edge == e_[hOpp].prev) f_[opp].edge = hOpp;
        e_[hOpp].prev = e_[e_[hOpp].prev].prev;
        e_[e_[hOpp].prev].next = hOpp;
      }
      e_[h].prev = e_[hPrev].prev;
      e_[e_[h].prev].next = h;
      link(h, hOpp);
      if (f_[opp].mark != Mark::kDeleted) computeNormalAndCentroid(opp);
    } else {
      e_[hPrev].next = h;
      e_[h].prev = hPrev;
    }
    return discarded;
  }

  /// Whether x, u, v are collinear within the tolerance: the triangle's
  /// smallest height is at most tol_.
  bool collinear(std::uint32_t x, std::uint32_t u, std::uint32_t v) const {
    const Vec3 a = p_[u] - p_[x], b = p_[v] - p_[x];
    const double longest = std::max({a.norm(), b.norm(), (b - a).norm()});
    return a.cross(b).norm() <= tol_ * longest;
  }

  /// Triangulates the convex polygon `poly` (CCW) using only its vertices and
  /// no collinear triangles: splits it recursively along diagonals whose
  /// endpoints do not lie on a common side (collinear vertices on a side are
  /// allowed), choosing the most balanced such diagonal.
  void triangulate(const std::vector<std::uint32_t>& poly, std::vector<Triangle>& out) const {
    std::vector<std::vector<std::uint32_t>> stack{poly};
    while (!stack.empty()) {
      const std::vector<std::uint32_t> q = std::move(stack.back());
      stack.pop_back();
      const std::size_t k = q.size();
      if (k < 3) continue;
      if (k == 3) {
        out.push_back(Triangle{q[0], q[1], q[2]});
        continue;
      }
      const auto at = [&](std::size_t i) { return q[i % k]; };
      const auto valid = [&](std::size_t a, std::size_t b) {
        return !collinear(at(b), at(a), at(a + 1)) && !collinear(at(b), at(a + k - 1), at(a)) &&
               !collinear(at(a), at(b), at(b + 1)) && !collinear(at(a), at(b + k - 1), at(b));
      };
      std::size_t a = 0, b = 0;
      bool found = false;
      for (std::size_t s = 0; s < k && !found; ++s)
        for (std::size_t d = 0; d <= k / 2 && !found; ++d)
          for (const std::size_t off : {k / 2 + d, k / 2 - d}) {
            if (off < 2 || off > k - 2 || found) continue;
            if (valid(s, s + off)) {
              a = s;
              b = (s + off) % k;
              found = true;
            }
          }
      if (!found) {
        // Only reachable for a polygon that is collinear within the
        // tolerance throughout; a fan keeps the mesh closed.
        for (std::size_t i = 1; i + 1 < k; ++i) out.push_back(Triangle{q[0], q[i], q[i + 1]});
        continue;
      }
      std::vector<std::uint32_t> q1, q2;
      for (std::size_t i = a;; i = (i + 1) % k) {
        q1.push_back(q[i]);
        if (i == b) break;
      }
      for (std::size_t i = b;; i = (i + 1) % k) {
        q2.push_back(q[i]);
        if (i == a) break;
      }
      stack.push_back(std::move(q1));
      stack.push_back(std::move(q2));
    }
  }

  std::vector<Vec3> p_;  // points relative to the bounding-box centre
  double tol_;
  std::vector<HalfEdge> e_;
  std::vector<Face> f_;
  std::vector<std::uint32_t> queue_;  // faces that got outside points, FIFO
  std::vector<std::uint32_t> horizon_, unclaimed_, newFaces_;
  std::vector<std::uint32_t> stamp_;  // per point, for the horizon's simplicity check
  std::uint32_t iteration_ = 0;
  std::vector<HorizonFrame> frames_;  // depth-first stack of computeHorizon()
};

/// Checks the output: no repeated corner, every directed edge once and its
/// reverse present (closed, oriented 2-manifold), V − E + F = 2.
Status checkClosedSphere(const std::vector<Triangle>& tris, std::size_t vertices) {
  std::vector<std::uint64_t> directed;
  directed.reserve(3 * tris.size());
  for (const Triangle& t : tris) {
    if (t[0] == t[1] || t[1] == t[2] || t[2] == t[0]) return internalError("a triangle repeats a vertex");
    for (std::size_t c = 0; c < 3; ++c) directed.push_back((std::uint64_t{t[c]} << 32) | t[(c + 1) % 3]);
  }
  std::sort(directed.begin(), directed.end());
  if (std::adjacent_find(directed.begin(), directed.end()) != directed.end())
    return internalError("an edge is used twice in the same direction");
  // Closed and oriented: the set of reversed edges is the same set.
  std::vector<std::uint64_t> reversed(directed.size());
  std::transform(directed.begin(), directed.end(), reversed.begin(),
                 [](std::uint64_t e) { return (e << 32) | (e >> 32); });
  std::sort(reversed.begin(), reversed.end());
  if (reversed != directed) return internalError("the hull has a boundary edge");
  const auto euler = static_cast<long long>(vertices) - static_cast<long long>(directed.size() / 2) +
                     static_cast<long long>(tris.size());
  if (euler != 2) return internalError("Euler characteristic is " + std::to_string(euler) + ", not 2");
  return ok();
}

/// Four points spanning the cloud, or the dimension the cloud degenerates to.
struct Simplex {
  std::array<std::uint32_t, 4> vertices{};
  int dimension = 3;
};

/// Initial simplex: the extreme pair along the widest axis (dimension 0 if
/// that extent is <= `tolerance`), the point farthest from their line, the
/// point farthest from their plane (dimension 1 or 2 if <= `thickness`).
Simplex findSimplex(const std::vector<Vec3>& q, double tolerance, double thickness) {
  Simplex s;
  const std::size_t n = q.size();
  std::array<std::size_t, 3> lo{}, hi{};
  for (std::size_t i = 0; i < n; ++i)
    for (int a = 0; a < 3; ++a) {
      const auto ua = static_cast<std::size_t>(a);
      if (q[i][a] < q[lo[ua]][a]) lo[ua] = i;
      if (q[i][a] > q[hi[ua]][a]) hi[ua] = i;
    }
  std::size_t axis = 0;
  for (std::size_t a = 1; a < 3; ++a)
    if (q[hi[a]][static_cast<int>(a)] - q[lo[a]][static_cast<int>(a)] >
        q[hi[axis]][static_cast<int>(axis)] - q[lo[axis]][static_cast<int>(axis)])
      axis = a;
  const std::size_t i0 = lo[axis], i1 = hi[axis];
  if (!(q[i1][static_cast<int>(axis)] - q[i0][static_cast<int>(axis)] > tolerance)) {
    s.dimension = 0;
    return s;
  }
  const Vec3 u = (q[i1] - q[i0]).normalized();
  std::size_t i2 = i0;
  double best = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const double d = (q[i] - q[i0]).cross(u).squaredNorm();
    if (d > best) {
      best = d;
      i2 = i;
    }
  }
  if (!(std::sqrt(best) > thickness)) {
    s.dimension = 1;
    return s;
  }
  const Vec3 normal = u.cross(q[i2] - q[i0]).normalized();
  std::size_t i3 = i0;
  best = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const double d = std::abs(normal.dot(q[i] - q[i0]));
    if (d > best) {
      best = d;
      i3 = i;
    }
  }
  if (!(best > thickness)) {
    s.dimension = 2;
    return s;
  }
  s.vertices = {static_cast<std::uint32_t>(i0), static_cast<std::uint32_t>(i1),
                static_cast<std::uint32_t>(i2), static_cast<std::uint32_t>(i3)};
  return s;
}

}  // namespace

Result<Mesh> convexHull(std::span<const Vec3> points, const ConvexHullOptions& options) {
  const double relTol = options.relativeTolerance;
  if (!std::isfinite(relTol) || relTol < 0 || relTol >= 0.1)
    return fail(ErrorCode::InvalidArgument, "relativeTolerance is " + formatCoarse(relTol), kWhere,
                "pass 0 for the default or a finite value in [0, 0.1)");
  const std::size_t n = points.size();
  if (n == 0)
    return fail(ErrorCode::InvalidArgument, "no points", kWhere,
                "give at least 4 points that span 3 dimensions");
  if (n >= kNone)
    return fail(ErrorCode::InvalidArgument, std::to_string(n) + " points are too many (at most 2^32 - 2)",
                kWhere, "decimate the point cloud first");
  Aabb box;
  for (std::size_t i = 0; i < n; ++i) {
    if (!points[i].allFinite())
      return fail(ErrorCode::InvalidArgument,
                  "point " + std::to_string(i) + " has a NaN or infinite coordinate", kWhere,
                  "remove or fix the point");
    box.extend(points[i]);
  }

  // Work relative to the box centre (exact for clouds far from the origin,
  // where the points share their leading bits) with a tolerance relative to
  // the cloud's size.
  const Vec3 centre = box.center();
  std::vector<Vec3> q(n);
  for (std::size_t i = 0; i < n; ++i) q[i] = points[i] - centre;
  // The rounding level of the plane tests, and of the input coordinates
  // themselves: 3·ε·Σ max |coordinate| per axis (as in QuickHull3D).
  const double size = 0.5 * box.sizes().sum();
  const double roundoff = 3 * DBL_EPSILON * (size + centre.cwiseAbs().sum());
  const double tol = std::max(relTol * size, roundoff);
  // Thinner than this, the initial simplex's planes would be ill-conditioned.
  const double flat = std::max(tol, 100 * roundoff);

  const auto degenerate = [&](const char* what, int dimension) {
    return fail(
        ErrorCode::InvalidArgument,
        "the hull is degenerate: all " + std::to_string(n) + " points " + what + " within " +
            formatCoarse(flat) + " m (" + std::to_string(dimension) + "-dimensional)",
        kWhere,
        "a convex hull needs points that span 3 dimensions (at least 4 not in one plane); give a flat or "
        "thin object some thickness");
  };

  const auto build = [&](std::vector<Vec3> pts, double tolerance,
                         double thickness) -> Result<std::vector<Triangle>> {
    const Simplex simplex = findSimplex(pts, tolerance, thickness);
    if (simplex.dimension == 0) return degenerate("coincide", 0);
    if (simplex.dimension == 1) return degenerate("are collinear", 1);
    if (simplex.dimension == 2) return degenerate("are coplanar", 2);
    QuickHull hull(std::move(pts), tolerance);
    if (auto s = hull.build(simplex.vertices); !s) return std::move(s).error();
    return hull.triangles();
  };
  auto built = tol > roundoff ? build(q, tol, flat) : build(std::move(q), tol, flat);
  if (!built) return std::move(built).error();
  std::vector<Triangle> tris = std::move(*built);
  if (tol > roundoff) {
    // Merging with a coarse tolerance leaves faces that are only planar and
    // convex within a few tolerances, so their triangulation need not be
    // convex. The vertices it kept are hulled again at the rounding level.
    std::vector<std::uint32_t> kept;
    for (const Triangle& t : tris) kept.insert(kept.end(), t.begin(), t.end());
    std::sort(kept.begin(), kept.end());
    kept.erase(std::unique(kept.begin(), kept.end()), kept.end());
    std::vector<Vec3> sub(kept.size());
    for (std::size_t i = 0; i < kept.size(); ++i) sub[i] = q[kept[i]];
    auto fine = build(std::move(sub), roundoff, 100 * roundoff);
    if (!fine) return std::move(fine).error();
    tris = std::move(*fine);
    for (Triangle& t : tris)
      for (std::uint32_t& v : t) v = kept[v];
  }

  // Keep the hull's points, in input order.
  std::vector<std::uint32_t> remap(n, kNone);
  for (const Triangle& t : tris)
    for (const std::uint32_t v : t) remap[v] = 0;
  Mesh mesh;
  mesh.name = "convex hull";
  for (std::size_t i = 0; i < n; ++i)
    if (remap[i] != kNone) {
      remap[i] = static_cast<std::uint32_t>(mesh.positions.size());
      mesh.positions.push_back(points[i]);
    }
  for (Triangle& t : tris)
    for (std::uint32_t& v : t) v = remap[v];
  if (auto s = checkClosedSphere(tris, mesh.positions.size()); !s) return std::move(s).error();
  mesh.triangles = std::move(tris);
  return mesh;
}

}  // namespace dm
