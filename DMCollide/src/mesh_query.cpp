// BVH traversals for mesh queries; see dm/collide/mesh_query.hpp.
#include <dm/collide/mesh_query.hpp>
#include <dm/collide/triangle.hpp>
#include <dm/core/assert.hpp>
#include <dm/math/geometry.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <utility>

#include "collide_internal.hpp"
#include "lanes.hpp"

namespace dm {

namespace {

using detail::kStack;
constexpr int kPairStack = 256;  // tree-tree DFS: <= depthA + depthB + 1 entries
static_assert(kStack > MeshBvh::kMaxDepth + 1 && kPairStack > 2 * MeshBvh::kMaxDepth + 1);
// Relative widening of box tests against the rounding of the box transform.
constexpr double kSlack = 1e-14;

struct NodeBox {
  Vec3 c, e;  // centre, half extents (exact from the float node box)
};
inline NodeBox boxOf(const BvhNode& n) noexcept {
  const Vec3 lo(n.lo[0], n.lo[1], n.lo[2]), hi(n.hi[0], n.hi[1], n.hi[2]);
  return {0.5 * (lo + hi), 0.5 * (hi - lo)};
}
inline double size(const BvhNode& n) noexcept {
  return double(n.hi[0] - n.lo[0]) + double(n.hi[1] - n.lo[1]) + double(n.hi[2] - n.lo[2]);
}

// B's local frame mapped into A's.
struct Relative {
  Mat3 r, absR;
  Vec3 t;
  explicit Relative(const Isometry3& poseA, const Isometry3& poseB) {
    const Isometry3 m = poseA.inverse(Eigen::Isometry) * poseB;
    r = m.linear();
    t = m.translation();
    absR = r.cwiseAbs();
  }
  Vec3 map(const Vec3& x) const noexcept { return r * x + t; }
};

// Separating-axis test on A's three and B's three box axes.
bool boxesOverlap(const NodeBox& a, const NodeBox& b, const Relative& m) noexcept {
  const Vec3 bc = m.r * b.c + m.t, be = m.absR * b.e;
  const Vec3 limA = a.e + be;
  const Vec3 slackA = kSlack * (a.c.cwiseAbs() + m.t.cwiseAbs() + m.absR * b.c.cwiseAbs() + limA);
  if (((bc - a.c).cwiseAbs().array() > (limA + slackA).array()).any()) return false;
  const Vec3 ac = m.r.transpose() * (a.c - m.t), ae = m.absR.transpose() * a.e;
  const Vec3 limB = b.e + ae;
  const Vec3 slackB =
      kSlack * (b.c.cwiseAbs() + m.absR.transpose() * (a.c.cwiseAbs() + m.t.cwiseAbs()) + limB);
  return !((ac - b.c).cwiseAbs().array() > (limB + slackB).array()).any();
}

// B's oriented node box mapped into A's frame.
struct MappedObb {
  Mat3 axes;
  Vec3 center, half;
};
inline MappedObb mapObb(const BvhObb& b, const Relative& m) noexcept {
  return {m.r * b.axes, m.map(b.center), b.half};
}
// A's oriented node box mapped into B's frame (the inverse of mapObb).
inline MappedObb mapObbInverse(const BvhObb& a, const Relative& m) noexcept {
  return {m.r.transpose() * a.axes, m.r.transpose() * (a.center - m.t), a.half};
}

// Lower bounds of the squared distances from oriented boxes a0 and a1 (two
// siblings, tested at once in the lanes of a D2) to box b (one frame): the
// largest gap between the boxes' projections on the centre line and on the
// 15 separating axis candidates (the 3 + 3 face normals and the 9 edge cross
// products); any unit direction's projection gap is at most the distance.
// Zero when they overlap on every axis. `best` is the distance so far: when
// the centre line alone proves both boxes farther, the rest is skipped. The
// test is symmetric, so either side may be the mapped one; `scale` is the
// size of the frames' offset (the mapping's rounding is relative to it as
// well as to the coordinates).
std::array<double, 2> obbDistanceSq(const BvhObb& a0, const BvhObb& a1, const MappedObb& b, double best,
                                    double scale) noexcept {
  using lanes::D2;
  auto pair = [](double x0, double x1) { return D2::of(x0, x1); };
  D2 ax[3][3], ha[3], ca[3], hb[3], d[3];
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) ax[i][j] = pair(a0.axes(i, j), a1.axes(i, j));
    ha[i] = pair(a0.half[i], a1.half[i]);
    ca[i] = pair(a0.center[i], a1.center[i]);
    hb[i] = D2::all(b.half[i]);
    d[i] = D2::all(b.center[i]) - ca[i];
  }
  // Rounding of the box transforms is relative to the coordinates' size.
  const D2 slack =
      D2::all(1e-12) * (max(max(abs(ca[0]), abs(ca[1])), abs(ca[2])) +
                        D2::all(b.center.cwiseAbs().maxCoeff() + scale + b.half.sum()) + ha[0] + ha[1] + ha[2]);
  // The centre line: |d| minus both boxes' support along it. Tighter than
  // the face axes for boxes apart along a diagonal.
  D2 t[3], u[3];  // centre offset in a's frame and in b's
  for (int i = 0; i < 3; ++i) {
    t[i] = ax[0][i] * d[0] + ax[1][i] * d[1] + ax[2][i] * d[2];
    u[i] = D2::all(b.axes(0, i)) * d[0] + D2::all(b.axes(1, i)) * d[1] + D2::all(b.axes(2, i)) * d[2];
  }
  const D2 zero = D2::all(0.0);
  const D2 dd = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
  D2 line = dd;  // |d| · gap
  for (int i = 0; i < 3; ++i) line = line - ha[i] * abs(t[i]) - hb[i] * abs(u[i]);
  const D2 apart = line > zero;
  const D2 lineGap = select(apart, line / sqrt(dd), zero);
  const D2 reach = D2::all(best) + slack;
  if (allOf(apart & (line * line > reach * reach * dd))) {
    const D2 g = max(zero, lineGap - slack);
    const D2 g2 = g * g;
    return {g2[0], g2[1]};
  }
  // b's axes in a's frame: r(i, j) = a_i · b_j.
  D2 r[3][3], ar[3][3];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      r[i][j] = ax[0][i] * D2::all(b.axes(0, j)) + ax[1][i] * D2::all(b.axes(1, j)) +
                ax[2][i] * D2::all(b.axes(2, j));
      ar[i][j] = abs(r[i][j]);
    }
  D2 gap = lineGap;
  for (int i = 0; i < 3; ++i) {
    gap = max(gap, abs(t[i]) - ha[i] - (ar[i][0] * hb[0] + ar[i][1] * hb[1] + ar[i][2] * hb[2]));
    gap = max(gap, abs(r[0][i] * t[0] + r[1][i] * t[1] + r[2][i] * t[2]) - hb[i] -
                       (ar[0][i] * ha[0] + ar[1][i] * ha[1] + ar[2][i] * ha[2]));
  }
  // Edge axes a_i × b_j, of length sqrt(1 − r_ij²), tracked squared; not
  // for (nearly) parallel edges, whose cross product is noise.
  D2 gapSq = gap * gap;
  const D2 parallel = D2::all(1e-6), one = D2::all(1.0);
  for (int i = 0; i < 3; ++i) {
    const int i1 = (i + 1) % 3, i2 = (i + 2) % 3;
    for (int j = 0; j < 3; ++j) {
      const int j1 = (j + 1) % 3, j2 = (j + 2) % 3;
      const D2 proj = abs(t[i2] * r[i1][j] - t[i1] * r[i2][j]);
      const D2 num = proj - ha[i1] * ar[i2][j] - ha[i2] * ar[i1][j] - hb[j1] * ar[i][j2] - hb[j2] * ar[i][j1];
      const D2 len2 = one - r[i][j] * r[i][j];
      const D2 better = (num > zero) & (len2 > parallel) & (num * num > gapSq * len2);
      gapSq = select(better, num * num / len2, gapSq);
    }
  }
  const D2 g = max(zero, sqrt(gapSq) - slack);
  const D2 g2 = g * g;
  return {g2[0], g2[1]};
}

double pointBoxDistanceSq(const Vec3& p, const BvhNode& n) noexcept {
  double d = 0;
  for (int i = 0; i < 3; ++i) {
    const double g = std::max({double(n.lo[i]) - p[i], p[i] - double(n.hi[i]), 0.0});
    d += g * g;
  }
  return d;
}

struct TriBox {
  Vec3 lo, hi;
};
inline TriBox triBox(const Vec3* c) noexcept {
  return {c[0].cwiseMin(c[1]).cwiseMin(c[2]), c[0].cwiseMax(c[1]).cwiseMax(c[2])};
}
inline double triBoxGapSq(const TriBox& a, const TriBox& b) noexcept {
  return (a.lo - b.hi).cwiseMax(b.lo - a.hi).cwiseMax(0.0).squaredNorm();
}
inline bool triBoxesDisjoint(const TriBox& a, const TriBox& b) noexcept {
  return (a.lo.array() > b.hi.array()).any() || (b.lo.array() > a.hi.array()).any();
}

Vec3 unitNormal(const Vec3* c) noexcept {
  const Vec3 n = (c[1] - c[0]).cross(c[2] - c[0]);
  const double len = n.norm();
  return len > 0 ? Vec3(n / len) : Vec3::Zero();
}

// B leaf triangles mapped into A's frame.
struct MappedLeaf {
  std::array<Vec3, 3 * 8> c;
  std::array<TriBox, 8> box;
  std::array<Vec3, 8> normal;  // unit (zero when degenerate); distance path only
  void load(const MeshBvh& b, const BvhNode& leaf, const Relative& m, bool normals = false) noexcept {
    for (std::uint32_t i = 0; i < leaf.count; ++i) {
      const Vec3* src = b.corners(leaf.first + i);
      for (int k = 0; k < 3; ++k) c[3 * i + k] = m.map(src[k]);
      box[i] = triBox(&c[3 * i]);
      if (normals) normal[i] = m.r * b.faceNormal(leaf.first + i);
    }
  }
};

// Lower bound of the distance between triangles t and u from t's plane
// (unit normal n): the gap between t's plane and u's corners when they all
// lie on one side.
inline double planeGap(const Vec3* t, const Vec3& n, const Vec3* u) noexcept {
  const double s = n.dot(t[0]);
  const double d0 = n.dot(u[0]) - s, d1 = n.dot(u[1]) - s, d2 = n.dot(u[2]) - s;
  const double lo = std::min({d0, d1, d2}), hi = std::max({d0, d1, d2});
  const double gap = lo > 0 ? lo : (hi < 0 ? -hi : 0.0);
  // Rounding of the normal and the dot products is absolute, relative to the
  // coordinates' magnitude.
  const double scale = std::max({t[0].cwiseAbs().maxCoeff(), u[0].cwiseAbs().maxCoeff(),
                                 u[1].cwiseAbs().maxCoeff(), u[2].cwiseAbs().maxCoeff()});
  return std::max(0.0, (1 - 1e-12) * gap - 1e-13 * scale);
}

// Generic overlap traversal: calls leafPair(leafA, leafB) for every pair of
// overlapping leaves until it returns true (stop).
template <class LeafPair>
void traverseOverlap(const MeshBvh& a, const MeshBvh& b, const Relative& m, LeafPair&& leafPair) {
  if (!boxesOverlap(boxOf(a.node(0)), boxOf(b.node(0)), m)) return;
  std::array<std::pair<std::uint32_t, std::uint32_t>, kPairStack> stack;
  int sp = 0;
  stack[sp++] = {0, 0};
  while (sp > 0) {
    const auto [ia, ib] = stack[--sp];
    const BvhNode& na = a.node(ia);
    const BvhNode& nb = b.node(ib);
    if (na.isLeaf() && nb.isLeaf()) {
      if (leafPair(na, nb)) return;
      continue;
    }
    const bool descendA = !na.isLeaf() && (nb.isLeaf() || size(na) >= size(nb));
    if (descendA) {
      const NodeBox bb = boxOf(nb);
      for (std::uint32_t c = na.first + 2; c-- > na.first;)
        if (boxesOverlap(boxOf(a.node(c)), bb, m)) {
          DM_ASSERT(sp < kPairStack, "traversal stack bound");
          stack[sp++] = {c, ib};
        }
    } else {
      const NodeBox ab = boxOf(na);
      for (std::uint32_t c = nb.first + 2; c-- > nb.first;)
        if (boxesOverlap(ab, boxOf(b.node(c)), m)) {
          DM_ASSERT(sp < kPairStack, "traversal stack bound");
          stack[sp++] = {ia, c};
        }
    }
  }
}

// Contact normal and depth of an intersecting pair (A's frame), see MeshContact.
void pairDepth(const Vec3* ta, const Vec3* tb, Vec3& normal, double& depth) noexcept {
  const Vec3 na = unitNormal(ta), nb = unitNormal(tb);
  double best = std::numeric_limits<double>::infinity();
  normal = Vec3::UnitZ();
  if (!na.isZero()) {
    const double s = na.dot(ta[0]);
    const double minB = std::min({na.dot(tb[0]), na.dot(tb[1]), na.dot(tb[2])});
    best = std::max(0.0, s - minB);
    normal = na;
  }
  if (!nb.isZero()) {
    const double s = nb.dot(tb[0]);
    const double maxA = std::max({nb.dot(ta[0]), nb.dot(ta[1]), nb.dot(ta[2])});
    const double d = std::max(0.0, maxA - s);
    if (d < best) {
      best = d;
      normal = -nb;
    }
  }
  depth = std::isfinite(best) ? best : 0.0;
}

// Single-tree DFS, nearer child first. `bound(node)` gives a squared lower
// bound of the query distance; `leaf(node, bestSq)` updates bestSq and
// returns true to stop.
template <class Bound, class Leaf>
void traverseNearest(const MeshBvh& bvh, double& bestSq, Bound&& bound, Leaf&& leaf) {
  const double rootBound = bound(bvh.node(0));
  if (rootBound > bestSq) return;
  std::array<std::pair<std::uint32_t, double>, kStack> stack;
  int sp = 0;
  stack[sp++] = {0, rootBound};
  while (sp > 0) {
    const auto [i, lb] = stack[--sp];
    if (lb > bestSq) continue;
    const BvhNode& n = bvh.node(i);
    if (n.isLeaf()) {
      if (leaf(n, bestSq)) return;
      continue;
    }
    const double b0 = bound(bvh.node(n.first)), b1 = bound(bvh.node(n.first + 1));
    const bool nearFirst = b0 <= b1;
    const std::uint32_t nearI = nearFirst ? n.first : n.first + 1, farI = nearFirst ? n.first + 1 : n.first;
    const double nearB = nearFirst ? b0 : b1, farB = nearFirst ? b1 : b0;
    DM_ASSERT(sp + 2 <= kStack, "traversal stack bound");
    if (farB <= bestSq) stack[sp++] = {farI, farB};
    if (nearB <= bestSq) stack[sp++] = {nearI, nearB};
  }
}

// First intersecting pair (leaf-order indices), or kNoTriangle.
std::pair<std::uint32_t, std::uint32_t> firstIntersectingPair(const MeshBvh& a, const MeshBvh& b,
                                                              const Relative& m) noexcept {
  std::pair<std::uint32_t, std::uint32_t> hit{kNoTriangle, kNoTriangle};
  MappedLeaf leafB;
  traverseOverlap(a, b, m, [&](const BvhNode& na, const BvhNode& nb) {
    leafB.load(b, nb, m);
    for (std::uint32_t i = 0; i < na.count; ++i) {
      const Vec3* ta = a.corners(na.first + i);
      const TriBox boxA = triBox(ta);
      for (std::uint32_t j = 0; j < nb.count; ++j) {
        if (triBoxesDisjoint(boxA, leafB.box[j])) continue;
        const Vec3* tb = &leafB.c[3 * j];
        if (trianglesIntersect(ta[0], ta[1], ta[2], tb[0], tb[1], tb[2])) {
          hit = {na.first + i, nb.first + j};
          return true;
        }
      }
    }
    return false;
  });
  return hit;
}

}  // namespace

bool meshMeshIntersect(const MeshBvh& a, const Isometry3& poseA, const MeshBvh& b,
                       const Isometry3& poseB) noexcept {
  if (a.triangleCount() == 0 || b.triangleCount() == 0) return false;
  return firstIntersectingPair(a, b, Relative(poseA, poseB)).first != kNoTriangle;
}

std::size_t meshMeshContacts(const MeshBvh& a, const Isometry3& poseA, const MeshBvh& b,
                             const Isometry3& poseB, std::vector<MeshContact>& contacts,
                             std::size_t maxContacts) {
  contacts.clear();
  if (a.triangleCount() == 0 || b.triangleCount() == 0 || maxContacts == 0) return 0;
  const Relative m(poseA, poseB);
  MappedLeaf leafB;
  traverseOverlap(a, b, m, [&](const BvhNode& na, const BvhNode& nb) {
    leafB.load(b, nb, m);
    for (std::uint32_t i = 0; i < na.count; ++i) {
      const Vec3* ta = a.corners(na.first + i);
      const TriBox boxA = triBox(ta);
      for (std::uint32_t j = 0; j < nb.count; ++j) {
        if (triBoxesDisjoint(boxA, leafB.box[j])) continue;
        const Vec3* tb = &leafB.c[3 * j];
        const TriangleIntersection x = triangleIntersection(ta[0], ta[1], ta[2], tb[0], tb[1], tb[2]);
        if (!x.intersects) continue;
        MeshContact c;
        Vec3 centre = Vec3::Zero();
        for (int k = 0; k < x.count; ++k) centre += x.points[k];
        centre /= x.count;
        // Ends of the intersection set: its farthest pair of points.
        int e0 = 0, e1 = 0;
        double far = -1;
        for (int p = 0; p < x.count; ++p)
          for (int q = p; q < x.count; ++q)
            if (const double d = (x.points[p] - x.points[q]).squaredNorm(); d > far) {
              far = d;
              e0 = p;
              e1 = q;
            }
        Vec3 normal = Vec3::Zero();
        pairDepth(ta, tb, normal, c.depth);
        c.position = poseA * centre;
        c.segment[0] = poseA * x.points[e0];
        c.segment[1] = poseA * x.points[e1];
        c.normal = poseA.linear() * normal;
        c.triangleA = a.originalTriangle(na.first + i);
        c.triangleB = b.originalTriangle(nb.first + j);
        contacts.push_back(c);
        if (contacts.size() >= maxContacts) return true;
      }
    }
    return false;
  });
  return contacts.size();
}

MeshDistance meshMeshDistance(const MeshBvh& a, const Isometry3& poseA, const MeshBvh& b,
                              const Isometry3& poseB, double maxDistance) noexcept {
  MeshDistance result;
  if (a.triangleCount() == 0 || b.triangleCount() == 0 || !(maxDistance >= 0)) return result;
  const Relative m(poseA, poseB);
  // Intersecting meshes: the boolean traversal finds a common point fast,
  // and otherwise no triangle pair below needs the intersection test.
  if (const auto [ia, ib] = firstIntersectingPair(a, b, m); ia != kNoTriangle) {
    const Vec3* ta = a.corners(ia);
    const Vec3* src = b.corners(ib);
    const Vec3 tb[3] = {m.map(src[0]), m.map(src[1]), m.map(src[2])};
    const TriangleIntersection x = triangleIntersection(ta[0], ta[1], ta[2], tb[0], tb[1], tb[2]);
    result.distance = 0;
    result.pointA = result.pointB = poseA * x.points[0];
    result.triangleA = a.originalTriangle(ia);
    result.triangleB = b.originalTriangle(ib);
    return result;
  }
  double best = maxDistance;  // current best distance (m)
  auto bestSq = [&] { return best * best; };
  Vec3 pa = Vec3::Zero(), pb = Vec3::Zero();
  std::uint32_t ka = kNoTriangle, kb = kNoTriangle;

  struct Item {
    std::uint32_t a, b;
    double lb;  // squared lower bound
  };
  std::array<Item, kPairStack> stack;
  int sp = 0;
  const double scale = m.t.cwiseAbs().maxCoeff();
  const double rootLb = obbDistanceSq(a.obb(0), a.obb(0), mapObb(b.obb(0), m), best, scale)[0];
  if (rootLb <= bestSq()) stack[sp++] = {0, 0, rootLb};
  MappedLeaf leafB;
  while (sp > 0) {
    const Item it = stack[--sp];
    if (it.lb > bestSq()) continue;
    const BvhNode& na = a.node(it.a);
    const BvhNode& nb = b.node(it.b);
    if (na.isLeaf() && nb.isLeaf()) {
      leafB.load(b, nb, m, true);
      for (std::uint32_t i = 0; i < na.count; ++i) {
        const Vec3* ta = a.corners(na.first + i);
        const TriBox boxA = triBox(ta);
        const Vec3& normalA = a.faceNormal(na.first + i);
        for (std::uint32_t j = 0; j < nb.count; ++j) {
          if (triBoxGapSq(boxA, leafB.box[j]) > bestSq()) continue;
          const Vec3* tb = &leafB.c[3 * j];
          // Separation along either face normal bounds the distance from below.
          const double gap = std::max(planeGap(ta, normalA, tb), planeGap(tb, leafB.normal[j], ta));
          if (gap > best) continue;
          const TriangleDistance d = separatedTriangleDistance(ta[0], ta[1], ta[2], tb[0], tb[1], tb[2]);
          if (d.distance < best || (ka == kNoTriangle && d.distance <= best)) {
            best = d.distance;
            pa = d.pointA;
            pb = d.pointB;
            ka = na.first + i;
            kb = nb.first + j;
          }
        }
      }
      continue;
    }
    const bool descendA = !na.isLeaf() && (nb.isLeaf() || size(na) >= size(nb));
    Item c0, c1;
    // Oriented boxes: on curved surfaces far tighter than the float boxes.
    // The undivided node's box is mapped into the other tree's frame once,
    // and both children are tested together in their own frame.
    if (descendA) {
      const auto lb = obbDistanceSq(a.obb(na.first), a.obb(na.first + 1), mapObb(b.obb(it.b), m), best, scale);
      c0 = {na.first, it.b, lb[0]};
      c1 = {na.first + 1, it.b, lb[1]};
    } else {
      const auto lb =
          obbDistanceSq(b.obb(nb.first), b.obb(nb.first + 1), mapObbInverse(a.obb(it.a), m), best, scale);
      c0 = {it.a, nb.first, lb[0]};
      c1 = {it.a, nb.first + 1, lb[1]};
    }
    if (c1.lb < c0.lb) std::swap(c0, c1);  // c0 nearer: pushed last, popped first
    DM_ASSERT(sp + 2 <= kPairStack, "traversal stack bound");
    if (c1.lb <= bestSq()) stack[sp++] = c1;
    if (c0.lb <= bestSq()) stack[sp++] = c0;
  }
  if (ka == kNoTriangle) return result;
  result.distance = best;
  result.pointA = poseA * pa;
  result.pointB = poseA * pb;
  result.triangleA = a.originalTriangle(ka);
  result.triangleB = b.originalTriangle(kb);
  return result;
}

MeshPointQuery closestPointOnMesh(const MeshBvh& bvh, const Isometry3& pose, const Vec3& point,
                                  double maxDistance) noexcept {
  MeshPointQuery q;
  if (bvh.triangleCount() == 0 || !(maxDistance >= 0)) return q;
  const Vec3 p = pose.inverse(Eigen::Isometry) * point;
  double bestSq = maxDistance * maxDistance;
  std::uint32_t bestK = kNoTriangle;
  TriangleClosest best{.point = Vec3::Zero(), .distanceSq = 0.0, .barycentric = Vec3::Zero()};
  traverseNearest(
      bvh, bestSq, [&](const BvhNode& n) { return pointBoxDistanceSq(p, n); },
      [&](const BvhNode& n, double& bSq) {
        for (std::uint32_t k = n.first; k < n.first + n.count; ++k) {
          const Vec3* c = bvh.corners(k);
          const TriangleClosest t = closestPointOnTriangle(p, c[0], c[1], c[2]);
          if (t.distanceSq < bSq || (bestK == kNoTriangle && t.distanceSq <= bSq)) {
            bSq = t.distanceSq;
            best = t;
            bestK = k;
          }
        }
        return false;
      });
  if (bestK == kNoTriangle) return q;
  double dist = std::sqrt(best.distanceSq);
  Vec3 normal = Vec3::Zero();
  if (bvh.isClosed()) {
    const Triangle& tri = bvh.triangleIndices(bestK);
    switch (best.feature) {
      case TriangleFeature::VertexA:
        normal = bvh.vertexNormal(tri[0]);
        break;
      case TriangleFeature::VertexB:
        normal = bvh.vertexNormal(tri[1]);
        break;
      case TriangleFeature::VertexC:
        normal = bvh.vertexNormal(tri[2]);
        break;
      case TriangleFeature::EdgeAB:
        normal = bvh.edgeNormal(bestK, 0);
        break;
      case TriangleFeature::EdgeBC:
        normal = bvh.edgeNormal(bestK, 1);
        break;
      case TriangleFeature::EdgeCA:
        normal = bvh.edgeNormal(bestK, 2);
        break;
      case TriangleFeature::Face:
        normal = bvh.faceNormal(bestK);
        break;
    }
    if ((p - best.point).dot(normal) < 0) dist = -dist;
  } else {
    normal = unitNormal(bvh.corners(bestK));
  }
  q.distance = dist;
  q.point = pose * best.point;
  q.normal = pose.linear() * normal;
  q.barycentric = best.barycentric;
  q.triangle = bvh.originalTriangle(bestK);
  return q;
}

bool raycastMesh(const MeshBvh& bvh, const Isometry3& pose, const Vec3& origin, const Vec3& direction,
                 double tMax, MeshRayHit& hit) noexcept {
  if (bvh.triangleCount() == 0 || !direction.allFinite() || direction.isZero(0.0) || !origin.allFinite() ||
      !(tMax >= 0))
    return false;
  const Isometry3 inv = pose.inverse(Eigen::Isometry);
  const Vec3 o = inv * origin, d = inv.linear() * direction;
  const Vec3 invD = d.cwiseInverse();
  double best = tMax;
  std::uint32_t bestK = kNoTriangle;
  RayTriangleHit bestHit;
  // Entry parameter of the ray into a node box (+inf on a miss), slab test.
  auto entry = [&](const BvhNode& n) {
    double t0 = 0.0, t1 = best;
    for (int i = 0; i < 3; ++i) {
      if (d[i] == 0) {
        if (o[i] < n.lo[i] || o[i] > n.hi[i]) return std::numeric_limits<double>::infinity();
        continue;
      }
      double ta = (double(n.lo[i]) - o[i]) * invD[i], tb = (double(n.hi[i]) - o[i]) * invD[i];
      if (ta > tb) std::swap(ta, tb);
      // Widen by a few ulps so that rounding never skips a box the ray grazes.
      t0 = std::max(t0, ta - 1e-12 * std::abs(ta));
      t1 = std::min(t1, tb + 1e-12 * std::abs(tb));
      if (t0 > t1) return std::numeric_limits<double>::infinity();
    }
    return t0;
  };
  std::array<std::pair<std::uint32_t, double>, kStack> stack;
  int sp = 0;
  const double rootT = entry(bvh.node(0));
  if (rootT <= best) stack[sp++] = {0, rootT};
  while (sp > 0) {
    const auto [i, tEntry] = stack[--sp];
    if (tEntry > best) continue;
    const BvhNode& n = bvh.node(i);
    if (n.isLeaf()) {
      for (std::uint32_t k = n.first; k < n.first + n.count; ++k) {
        const Vec3* c = bvh.corners(k);
        RayTriangleHit h;
        if (rayTriangle(o, d, c[0], c[1], c[2], 0.0, best, h) && (bestK == kNoTriangle || h.t < best)) {
          best = h.t;
          bestHit = h;
          bestK = k;
        }
      }
      continue;
    }
    const double t0 = entry(bvh.node(n.first)), t1 = entry(bvh.node(n.first + 1));
    const bool nearFirst = t0 <= t1;
    DM_ASSERT(sp + 2 <= kStack, "traversal stack bound");
    const std::uint32_t nearI = nearFirst ? n.first : n.first + 1, farI = nearFirst ? n.first + 1 : n.first;
    const double nearT = std::min(t0, t1), farT = std::max(t0, t1);
    if (farT <= best) stack[sp++] = {farI, farT};
    if (nearT <= best) stack[sp++] = {nearI, nearT};
  }
  if (bestK == kNoTriangle) return false;
  hit.t = best;
  hit.point = origin + best * direction;
  hit.barycentric = bestHit.barycentric;
  hit.triangle = bvh.originalTriangle(bestK);
  return true;
}

namespace {

// Closest mesh point to a local segment [s0, s1] (a point when equal);
// stops as soon as a triangle is within `stopDistance`.
struct SegmentNearest {
  TriangleDistance best;
  std::uint32_t k = kNoTriangle;
};
SegmentNearest segmentNearest(const MeshBvh& bvh, const Vec3& s0, const Vec3& s1, double stopDistance) {
  SegmentNearest r;
  double bestSq = std::numeric_limits<double>::infinity();
  const Vec3 mid = 0.5 * (s0 + s1);
  const double half = 0.5 * (s1 - s0).norm();
  const Vec3 lo = s0.cwiseMin(s1), hi = s0.cwiseMax(s1);
  const double stopSq = stopDistance > 0 ? stopDistance * stopDistance : 0.0;
  traverseNearest(
      bvh, bestSq,
      [&](const BvhNode& n) {
        // Two lower bounds: box to the segment's box, and box to the
        // midpoint minus the half length.
        double gap = 0;
        for (int i = 0; i < 3; ++i) {
          const double g = std::max({double(n.lo[i]) - hi[i], lo[i] - double(n.hi[i]), 0.0});
          gap += g * g;
        }
        const double m = std::max(0.0, std::sqrt(pointBoxDistanceSq(mid, n)) - half);
        return std::max(gap, m * m) * (1 - 1e-12);
      },
      [&](const BvhNode& n, double& bSq) {
        for (std::uint32_t k = n.first; k < n.first + n.count; ++k) {
          const Vec3* c = bvh.corners(k);
          const TriangleDistance d = segmentTriangleDistance(s0, s1, c[0], c[1], c[2]);
          if (r.k == kNoTriangle || d.distance * d.distance < bSq) {
            bSq = d.distance * d.distance;
            r.best = d;
            r.k = k;
            if (bSq <= stopSq) return true;
          }
        }
        return false;
      });
  return r;
}

MeshDistance roundedDistance(const MeshBvh& bvh, const Isometry3& pose, const Vec3& p0, const Vec3& p1,
                             double radius) {
  MeshDistance out;
  if (bvh.triangleCount() == 0) return out;
  const Isometry3 inv = pose.inverse(Eigen::Isometry);
  const SegmentNearest n = segmentNearest(bvh, inv * p0, inv * p1, 0.0);
  if (n.k == kNoTriangle) return out;
  const Vec3 onSeg = pose * n.best.pointA, onMesh = pose * n.best.pointB;
  out.distance = n.best.distance - radius;
  Vec3 dir = onMesh - onSeg;
  const double len = dir.norm();
  // Inside contact: the surface point of the rounded shape is the mesh point itself.
  out.pointA = len > 0 ? Vec3(onSeg + (radius / len) * dir) : onMesh;
  out.pointB = onMesh;
  out.triangleB = bvh.originalTriangle(n.k);
  return out;
}

}  // namespace

bool sphereMeshIntersect(const MeshBvh& bvh, const Isometry3& pose, const Vec3& center,
                         double radius) noexcept {
  if (bvh.triangleCount() == 0 || !(radius >= 0)) return false;
  const Vec3 c = pose.inverse(Eigen::Isometry) * center;
  const SegmentNearest n = segmentNearest(bvh, c, c, radius);
  return n.k != kNoTriangle && n.best.distance <= radius;
}

MeshDistance sphereMeshDistance(const MeshBvh& bvh, const Isometry3& pose, const Vec3& center,
                                double radius) noexcept {
  return roundedDistance(bvh, pose, center, center, radius);
}

bool capsuleMeshIntersect(const MeshBvh& bvh, const Isometry3& pose, const Vec3& p0, const Vec3& p1,
                          double radius) noexcept {
  if (bvh.triangleCount() == 0 || !(radius >= 0)) return false;
  const Isometry3 inv = pose.inverse(Eigen::Isometry);
  const SegmentNearest n = segmentNearest(bvh, inv * p0, inv * p1, radius);
  return n.k != kNoTriangle && n.best.distance <= radius;
}

MeshDistance capsuleMeshDistance(const MeshBvh& bvh, const Isometry3& pose, const Vec3& p0, const Vec3& p1,
                                 double radius) noexcept {
  return roundedDistance(bvh, pose, p0, p1, radius);
}

}  // namespace dm
