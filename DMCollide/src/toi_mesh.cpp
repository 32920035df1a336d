// Swept point and swept sphere against a triangle mesh through its MeshBvh;
// see dm/collide/toi.hpp. Everything runs in the mesh's local frame (the
// pose is rigid, so radii and the motion parameter t are unchanged) on a
// fixed traversal stack: no allocation.
#include <dm/collide/toi.hpp>
#include <dm/collide/triangle.hpp>
#include <dm/core/assert.hpp>
#include <dm/math/geometry.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <utility>

#include "collide_internal.hpp"

namespace dm {

namespace {

using detail::kInf;
using detail::kStack;

// Parameter at which the segment o + t·d enters the node box inflated by
// `inflate`, clipped to [0, tMax]; +∞ when it misses. Unlike raycastMesh's
// slab test, this one inflates the box (swept sphere) and is shared by both
// sweeps, which need per-triangle tests raycastMesh does not offer (culling,
// sphere features).
double boxEntry(const BvhNode& n, const Vec3& o, const Vec3& d, const Vec3& invD, double inflate,
                double tMax) noexcept {
  double t0 = 0.0, t1 = tMax;
  for (int i = 0; i < 3; ++i) {
    const double lo = double(n.lo[i]) - inflate, hi = double(n.hi[i]) + inflate;
    if (d[i] == 0) {
      if (o[i] < lo || o[i] > hi) return kInf;
      continue;
    }
    double ta = (lo - o[i]) * invD[i], tb = (hi - o[i]) * invD[i];
    if (ta > tb) std::swap(ta, tb);
    // Widened by a few ulps so that rounding never skips a grazed box.
    t0 = std::max(t0, ta - 1e-12 * std::abs(ta));
    t1 = std::min(t1, tb + 1e-12 * std::abs(tb));
    if (t0 > t1) return kInf;
  }
  return t0;
}

// Depth-first traversal in order of box entry; `leaf(k, best)` tests
// leaf-order triangle k and lowers `best` (the earliest t so far, starting
// at 1) when it finds an earlier contact.
template <class LeafTest>
void traverseSweep(const MeshBvh& bvh, const Vec3& o, const Vec3& d, double inflate, double& best,
                   LeafTest&& leaf) noexcept {
  const Vec3 invD = d.cwiseInverse();
  std::array<std::pair<std::uint32_t, double>, kStack> stack;
  int sp = 0;
  const double rootT = boxEntry(bvh.node(0), o, d, invD, inflate, best);
  if (rootT <= best) stack[sp++] = {0, rootT};
  while (sp > 0) {
    const auto [i, tEntry] = stack[--sp];
    if (tEntry > best) continue;
    const BvhNode& n = bvh.node(i);
    if (n.isLeaf()) {
      for (std::uint32_t k = n.first; k < n.first + n.count; ++k) leaf(k, best);
      continue;
    }
    const double t0 = boxEntry(bvh.node(n.first), o, d, invD, inflate, best);
    const double t1 = boxEntry(bvh.node(n.first + 1), o, d, invD, inflate, best);
    const bool nearFirst = t0 <= t1;
    DM_ASSERT(sp + 2 <= kStack, "traversal stack bound");
    const std::uint32_t nearI = nearFirst ? n.first : n.first + 1, farI = nearFirst ? n.first + 1 : n.first;
    const double nearT = std::min(t0, t1), farT = std::max(t0, t1);
    if (farT <= best) stack[sp++] = {farI, farT};
    if (nearT <= best) stack[sp++] = {nearI, nearT};
  }
}

// Earliest s >= 0 with |m + s·d|² = r² for |m|² > r² (entering a sphere or,
// with the components across an edge, an infinite cylinder); +∞ when the
// path never reaches it. Stable form of the smaller quadratic root.
double entryRoot(double a, double halfB, double c) noexcept {
  if (!(a > 0) || halfB >= 0) return kInf;  // no relative motion, or moving away
  const double disc = halfB * halfB - a * c;
  if (disc < 0) return kInf;
  return c / (-halfB + std::sqrt(disc));
}

// One triangle's contact with the sphere (centre o + s·d, s in [0, 1],
// radius r), given that it starts outside (distance > r) and does reach
// depth below r: the earliest s over face interior, edges and corners.
struct FeatureHit {
  double s = kInf;
  Vec3 point = Vec3::Zero();
};
FeatureHit sphereTriangleEntry(const Vec3& o, const Vec3& d, double r, const Vec3* c) noexcept {
  FeatureHit best;
  auto offer = [&](double s, const Vec3& p) {
    if (s >= 0 && s < best.s) best = {s, p};
  };
  const Vec3 nRaw = (c[1] - c[0]).cross(c[2] - c[0]);
  const double nNorm = nRaw.norm();
  if (nNorm > 0) {
    const Vec3 n = nRaw / nNorm;
    const double h0 = n.dot(o - c[0]), hd = n.dot(d);
    const double side = h0 >= 0 ? 1.0 : -1.0;
    if (side * hd < 0) {
      const double s = (std::abs(h0) - r) / (-side * hd);
      const Vec3 p = o + s * d - side * r * n;
      if (s >= 0 && closestPointOnTriangle(p, c[0], c[1], c[2]).feature == TriangleFeature::Face) offer(s, p);
    }
  }
  for (int e = 0; e < 3; ++e) {
    const Vec3 &p0 = c[e], &p1 = c[(e + 1) % 3];
    const Vec3 edge = p1 - p0;
    const double ee = edge.squaredNorm();
    if (!(ee > 0)) continue;
    const Vec3 m = o - p0;
    const Vec3 mPerp = m - (m.dot(edge) / ee) * edge, dPerp = d - (d.dot(edge) / ee) * edge;
    const double s = entryRoot(dPerp.squaredNorm(), mPerp.dot(dPerp), mPerp.squaredNorm() - r * r);
    if (!(s < best.s)) continue;
    const double u = (o + s * d - p0).dot(edge) / ee;
    if (u >= 0 && u <= 1) offer(s, p0 + u * edge);
  }
  for (int v = 0; v < 3; ++v) {
    const Vec3 m = o - c[v];
    offer(entryRoot(d.squaredNorm(), m.dot(d), m.squaredNorm() - r * r), c[v]);
  }
  return best;
}

// Fallback when rounding hides every analytic root although the path goes
// deeper than r (e.g. a near-tangent edge): the distance to a convex set is
// convex along a line, so it falls monotonically from s = 0 to the
// segment's closest parameter sMin; bisect for where it crosses r.
FeatureHit bisectSphereTriangle(const Vec3& o, const Vec3& d, double r, const Vec3* c, double sMin) noexcept {
  double lo = 0.0, hi = sMin;
  for (int i = 0; i < 60 && hi - lo > 1e-15; ++i) {
    const double mid = 0.5 * (lo + hi);
    (closestPointOnTriangle(o + mid * d, c[0], c[1], c[2]).distanceSq > r * r ? lo : hi) = mid;
  }
  return {hi, closestPointOnTriangle(o + hi * d, c[0], c[1], c[2]).point};
}

bool validMotion(const Vec3& from, const Vec3& to) noexcept { return from.allFinite() && to.allFinite(); }

}  // namespace

SweepHit sweepPoint(const MeshBvh& bvh, const Isometry3& pose, const Vec3& from, const Vec3& to,
                    const SweepOptions& options) noexcept {
  SweepHit hit;
  if (bvh.triangleCount() == 0 || !validMotion(from, to) || from == to) return hit;
  const Isometry3 inv = pose.inverse(Eigen::Isometry);
  const Vec3 o = inv * from, d = inv.linear() * (to - from);
  double best = 1.0;
  std::uint32_t bestK = kNoTriangle;
  traverseSweep(bvh, o, d, 0.0, best, [&](std::uint32_t k, double& tBest) {
    const Vec3* c = bvh.corners(k);
    if (options.cullBackFaces && (c[1] - c[0]).cross(c[2] - c[0]).dot(d) >= 0) return;
    RayTriangleHit h;
    if (rayTriangle(o, d, c[0], c[1], c[2], 0.0, tBest, h) && (bestK == kNoTriangle || h.t < tBest)) {
      tBest = h.t;
      bestK = k;
    }
  });
  if (bestK == kNoTriangle) return hit;
  const Vec3* c = bvh.corners(bestK);
  const Vec3 n = (c[1] - c[0]).cross(c[2] - c[0]);
  hit.status = SweepStatus::Hit;
  hit.t = best;
  hit.point = from + best * (to - from);
  hit.normal = pose.linear() * (n.squaredNorm() > 0 ? Vec3(n.normalized()) : Vec3(-d.normalized()));
  hit.triangle = bvh.originalTriangle(bestK);
  return hit;
}

SweepHit sweepPoint(const TriangleMesh& mesh, const Isometry3& pose, const Vec3& from, const Vec3& to,
                    const SweepOptions& options) noexcept {
  return mesh.bvh() ? sweepPoint(*mesh.bvh(), pose, from, to, options) : SweepHit{};
}

SweepHit sweepSphere(const MeshBvh& bvh, const Isometry3& pose, double radius, const Vec3& from,
                     const Vec3& to, const SweepOptions& options) noexcept {
  if (radius == 0.0) return sweepPoint(bvh, pose, from, to, options);
  SweepHit hit;
  if (bvh.triangleCount() == 0 || !validMotion(from, to) || !(radius > 0) || !std::isfinite(radius))
    return hit;
  const double skin = std::max(options.skin, 0.0);
  const Isometry3 inv = pose.inverse(Eigen::Isometry);
  const Vec3 o = inv * from, d = inv.linear() * (to - from);
  const Vec3 end = o + d;

  double best = 1.0;
  std::uint32_t bestK = kNoTriangle;
  Vec3 bestPoint = Vec3::Zero();
  double bestStart = kInf;  // start distance of the best triangle when best == 0
  traverseSweep(bvh, o, d, radius, best, [&](std::uint32_t k, double& tBest) {
    const Vec3* c = bvh.corners(k);
    const Vec3 nRaw = (c[1] - c[0]).cross(c[2] - c[0]);
    if (options.cullBackFaces && nRaw.dot(d) >= 0) return;
    // Cheap exact reject: the path stays on one side of the triangle's plane,
    // at least radius − skin from it, so it never gets that close to the triangle.
    if (const double nNorm = nRaw.norm(); nNorm > 0) {
      const double h0 = nRaw.dot(o - c[0]) / nNorm, h1 = h0 + nRaw.dot(d) / nNorm;
      const double limit = radius - skin;
      if ((h0 >= limit && h1 >= limit) || (h0 <= -limit && h1 <= -limit)) return;
      // Nor can it touch the triangle before it touches the plane.
      const double towardPlane = h0 > 0 ? h0 - h1 : h1 - h0;  // per unit t
      if (bestK != kNoTriangle && std::abs(h0) > radius && towardPlane > 0 &&
          std::abs(h0) - radius >= tBest * towardPlane)
        return;
    }
    const TriangleClosest q0 = closestPointOnTriangle(o, c[0], c[1], c[2]);
    const double start = std::sqrt(q0.distanceSq);
    // Only triangles the sphere goes deeper than `skin` into count (see
    // SweepOptions::skin); the path's minimum distance decides it.
    const TriangleDistance path = segmentTriangleDistance(o, end, c[0], c[1], c[2]);
    if (!(path.distance < std::min(start, radius) - skin)) return;
    if (start <= radius) {
      // In contact at the start and moving deeper: t = 0, deepest first.
      if (tBest > 0 || bestK == kNoTriangle || start < bestStart) {
        tBest = 0;
        bestK = k;
        bestPoint = q0.point;
        bestStart = start;
      }
      return;
    }
    FeatureHit f = sphereTriangleEntry(o, d, radius, c);
    if (!(f.s <= 1)) {
      const double sMin = d.squaredNorm() > 0 ? (path.pointA - o).dot(d) / d.squaredNorm() : 0.0;
      f = bisectSphereTriangle(o, d, radius, c, std::clamp(sMin, 0.0, 1.0));
    }
    if (f.s < tBest || (bestK == kNoTriangle && f.s <= tBest)) {
      tBest = f.s;
      bestK = k;
      bestPoint = f.point;
    }
  });
  if (bestK == kNoTriangle) return hit;

  const Vec3 center = o + best * d;
  Vec3 n = center - bestPoint;
  if (n.squaredNorm() > 0) {
    n.normalize();
  } else {
    // Centre on the triangle: the face normal against the motion.
    const Vec3* c = bvh.corners(bestK);
    n = (c[1] - c[0]).cross(c[2] - c[0]);
    n = n.squaredNorm() > 0 ? Vec3(n.normalized()) : Vec3(-d.normalized());
    if (n.dot(d) > 0) n = -n;
  }
  hit.status = best == 0 && bestStart < radius - skin ? SweepStatus::StartPenetrating : SweepStatus::Hit;
  hit.t = best;
  hit.point = pose * bestPoint;
  hit.normal = pose.linear() * n;
  hit.triangle = bvh.originalTriangle(bestK);
  return hit;
}

SweepHit sweepSphere(const TriangleMesh& mesh, const Isometry3& pose, double radius, const Vec3& from,
                     const Vec3& to, const SweepOptions& options) noexcept {
  return mesh.bvh() ? sweepSphere(*mesh.bvh(), pose, radius, from, to, options) : SweepHit{};
}

}  // namespace dm
