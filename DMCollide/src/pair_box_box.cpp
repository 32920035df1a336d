// Box–box collider: separating-axis test over the 15 axes (Gottschalk et al.
// 1996; Ericson 4.4.1) and a contact manifold by clipping the incident face
// against the reference face's side planes (as in ODE's dBoxBox): up to 8
// points, reduced to the request. Distance of separated boxes uses GJK, which
// is exact (to rounding) for polytopes.
#include <dm/collide/triangle.hpp>

#include <algorithm>
#include <cmath>
#include <limits>

#include "pair_colliders.hpp"

namespace dm::detail {

namespace {

struct Sat {
  double separation = -std::numeric_limits<double>::infinity();  // > 0: separated
  int kind = 0;      // 0: face of A, 1: face of B, 2: edge × edge
  int i = 0, j = 0;  // face axis (kind 0/1) or edge axes of A and B (kind 2)
  Vec3 normal;       // world, unit, A → B
};

// Runs the test; returns false as soon as an axis separates (then `sat` is
// partial but for sat.separation: that axis' gap, a lower bound on the
// distance), else true with the axis of least penetration in `sat`.
bool separatingAxes(const Box& a, const Isometry3& pa, const Box& b, const Isometry3& pb, Sat& sat) {
  const Mat3 ra = pa.linear(), rb = pb.linear();
  const Mat3 r = ra.transpose() * rb;
  const Vec3 t = ra.transpose() * (pb.translation() - pa.translation());
  const Vec3& ha = a.halfExtents();
  const Vec3& hb = b.halfExtents();
  // The epsilon keeps near-parallel edge axes from producing false separation.
  const Mat3 absR = r.cwiseAbs().array() + 1e-14;
  const double scale = ha.maxCoeff() + hb.maxCoeff();
  const double faceBias = 1e-9 * scale;

  for (int i = 0; i < 3; ++i) {
    const double s = std::abs(t[i]) - (ha[i] + absR.row(i).dot(hb));
    if (s > 0) {
      sat.separation = s;
      return false;
    }
    if (s > sat.separation) sat = {s, 0, i, 0, (t[i] >= 0 ? 1.0 : -1.0) * ra.col(i)};
  }
  for (int j = 0; j < 3; ++j) {
    const double tj = t.dot(r.col(j));
    const double s = std::abs(tj) - (absR.col(j).dot(ha) + hb[j]);
    if (s > 0) {
      sat.separation = s;
      return false;
    }
    // Prefer A's faces on ties so the manifold is stable frame to frame.
    if (s > 0.95 * sat.separation + faceBias) sat = {s, 1, j, 0, (tj >= 0 ? 1.0 : -1.0) * rb.col(j)};
  }
  const double faceSeparation = sat.separation;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      const Vec3 l = Vec3::Unit(i).cross(r.col(j));
      const double len = l.norm();
      if (len < 1e-6) continue;  // parallel edges: covered by the face axes
      const double ra2 = ha.dot(l.cwiseAbs());
      const double rb2 = hb.dot((r.transpose() * l).cwiseAbs());
      const double tl = t.dot(l);
      const double s = (std::abs(tl) - ra2 - rb2) / len;
      if (s > 0) {
      sat.separation = s;
      return false;
    }
      if (s > 0.95 * faceSeparation + faceBias && s > sat.separation)
        sat = {s, 2, i, j, (tl >= 0 ? 1.0 : -1.0) * (ra * l / len)};
    }
  }
  return true;
}

// Clips polygon `in` (n points) by the half-space {p : dot(axis, p) <= limit}.
int clip(const Vec3* in, int n, const Vec3& axis, double limit, Vec3* out) {
  int m = 0;
  for (int k = 0; k < n; ++k) {
    const Vec3& p = in[k];
    const Vec3& q = in[(k + 1) % n];
    const double dp = axis.dot(p) - limit, dq = axis.dot(q) - limit;
    if (dp <= 0) out[m++] = p;
    if ((dp < 0 && dq > 0) || (dp > 0 && dq < 0)) out[m++] = p + (dp / (dp - dq)) * (q - p);
  }
  return m;
}

// Contacts of a face–something configuration: `ref` owns the face whose
// outward normal is `n` (pointing at the other box), `inc` is the other box.
// Normals are written A → B, flipped when `ref` is B.
void faceContacts(const Box& ref, const Isometry3& pr, int axis, const Vec3& n, const Box& inc,
                  const Isometry3& pi, bool refIsB, CollisionResult& out) {
  const Mat3 rr = pr.linear(), ri = pi.linear();
  const Vec3& hr = ref.halfExtents();
  const Vec3& hi = inc.halfExtents();
  const int u = (axis + 1) % 3, v = (axis + 2) % 3;
  const Vec3 faceCentre = pr.translation() + hr[axis] * n;
  // Incident face: the face of `inc` most anti-parallel to n.
  int j = 0;
  double bestDot = 0;
  for (int k = 0; k < 3; ++k)
    if (std::abs(n.dot(ri.col(k))) > bestDot) bestDot = std::abs(n.dot(ri.col(k))), j = k;
  const double sj = n.dot(ri.col(j)) > 0 ? -1.0 : 1.0;
  const Vec3 ic = pi.translation() + sj * hi[j] * ri.col(j);
  const Vec3 a1 = hi[(j + 1) % 3] * ri.col((j + 1) % 3), a2 = hi[(j + 2) % 3] * ri.col((j + 2) % 3);
  Vec3 poly[8] = {ic + a1 + a2, ic - a1 + a2, ic - a1 - a2, ic + a1 - a2};
  Vec3 tmp[8];
  int m = 4;
  const Vec3 cu = rr.col(u), cv = rr.col(v);
  const double ou = cu.dot(pr.translation()), ov = cv.dot(pr.translation());
  m = clip(poly, m, cu, ou + hr[u], tmp);
  m = clip(tmp, m, -cu, -ou + hr[u], poly);
  m = clip(poly, m, cv, ov + hr[v], tmp);
  m = clip(tmp, m, -cv, -ov + hr[v], poly);
  const double planeOffset = n.dot(faceCentre);
  const Vec3 normal = refIsB ? Vec3(-n) : n;
  for (int k = 0; k < m; ++k) {
    const double depth = planeOffset - n.dot(poly[k]);
    if (depth < 0) continue;
    out.contacts.push_back({poly[k] + 0.5 * depth * n, normal, depth});
  }
}

void boxBoxContacts(const Shape& sa, const Isometry3& pa, const Shape& sb, const Isometry3& pb,
                    const CollisionRequest& request, CollisionResult& out, PairCache*) {
  const auto& a = static_cast<const Box&>(sa);
  const auto& b = static_cast<const Box&>(sb);
  Sat sat;
  if (!separatingAxes(a, pa, b, pb, sat)) {
    if (!out.colliding && out.contacts.empty()) out.separation = sat.separation;
    return;
  }
  out.colliding = true;
  out.separation = 0.0;
  if (!request.contacts) return;
  const std::size_t first = out.contacts.size();
  const double depth = -sat.separation;
  if (sat.kind == 0) {
    faceContacts(a, pa, sat.i, sat.normal, b, pb, false, out);
  } else if (sat.kind == 1) {
    faceContacts(b, pb, sat.i, -sat.normal, a, pa, true, out);
  } else {
    // Edge–edge: the supporting edges of each box along ±normal.
    const Mat3 ra = pa.linear(), rb = pb.linear();
    Vec3 ca = pa.translation(), cb = pb.translation();
    for (int k = 0; k < 3; ++k) {
      if (k != sat.i) ca += (sat.normal.dot(ra.col(k)) > 0 ? 1.0 : -1.0) * a.halfExtents()[k] * ra.col(k);
      if (k != sat.j) cb += (sat.normal.dot(rb.col(k)) > 0 ? -1.0 : 1.0) * b.halfExtents()[k] * rb.col(k);
    }
    const Vec3 ea = a.halfExtents()[sat.i] * ra.col(sat.i), eb = b.halfExtents()[sat.j] * rb.col(sat.j);
    const SegmentClosest sc = closestPointsSegmentSegment(ca - ea, ca + ea, cb - eb, cb + eb);
    out.contacts.push_back({0.5 * (sc.pointA + sc.pointB), sat.normal, depth});
  }
  if (out.contacts.size() == first)  // clipping lost everything to rounding
    out.contacts.push_back({0.5 * (pa.translation() + pb.translation()), sat.normal, depth});
  reduceContacts(out, first, request.maxContacts);
}

bool boxBoxIntersect(const Shape& sa, const Isometry3& pa, const Shape& sb, const Isometry3& pb, PairCache*) {
  Sat sat;
  return separatingAxes(static_cast<const Box&>(sa), pa, static_cast<const Box&>(sb), pb, sat);
}

DistanceResult boxBoxDistance(const Shape& sa, const Isometry3& pa, const Shape& sb, const Isometry3& pb,
                              PairCache* cache) {
  const GjkResult g = gjkDistance(static_cast<const Box&>(sa), pa, static_cast<const Box&>(sb), pb,
                                  cache ? &cache->gjk : nullptr);
  DistanceResult d;
  d.distance = g.distance;
  d.pointA = g.pointA;
  d.pointB = g.pointB;
  return d;
}

}  // namespace

void registerBoxBoxCollider(ColliderTable& table) {
  const Status s = table.registerCollider(ShapeType::Box, ShapeType::Box,
                                          {&boxBoxIntersect, &boxBoxContacts, &boxBoxDistance});
  DM_DEMAND(s.ok(), "built-in collider registration");
}

}  // namespace dm::detail
