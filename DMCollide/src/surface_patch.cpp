// Quadric surface patches of sphere-tree nodes: the least-squares fit of a
// node's surface points and the two queries the haptic renderers use (where
// a point is relative to the patch, and the patch's support point); see
// dm/collide/sphere_tree.hpp (SurfacePatch).
#include <Eigen/Cholesky>

#include <algorithm>
#include <cmath>
#include <limits>
#include <tuple>
#include <vector>

#include "surface_patch_fit.hpp"

namespace dm {

double SurfacePatch::height(double u, double v) const noexcept {
  const std::array<double, 6>& c = coeff;
  return c[0] + c[1] * u + c[2] * v + 0.5 * (c[3] * u * u + 2.0 * c[4] * u * v + c[5] * v * v);
}

SurfacePatch::Query SurfacePatch::query(const Vec3& x) const noexcept {
  const Vec3 d = x - origin;
  const double u = d.dot(tangentU), v = d.dot(tangentV), w = d.dot(normal);
  const std::array<double, 6>& c = coeff;
  const double hu = c[1] + c[3] * u + c[4] * v, hv = c[2] + c[4] * u + c[5] * v;
  // Gradient of w − h(u, v) in (tangentU, tangentV, normal).
  const double g = std::sqrt(1.0 + hu * hu + hv * hv);
  Query q;
  q.distance = (w - height(u, v)) / g;
  q.normal = (normal - hu * tangentU - hv * tangentV) / g;
  q.lateral = std::sqrt(u * u + v * v);  // not hypot: metres, no overflow, and 10x cheaper
  return q;
}

Vec3 SurfacePatch::support(const Vec3& dir) const noexcept {
  const double du = dir.dot(tangentU), dv = dir.dot(tangentV), dn = dir.dot(normal);
  const std::array<double, 6>& c = coeff;
  // Objective f(u, v) = u·du + v·dv + h(u, v)·dn over the disc |(u, v)| ≤ halfWidth.
  const auto f = [&](double u, double v) { return u * du + v * dv + height(u, v) * dn; };
  const auto point = [&](double u, double v) {
    return Vec3(origin + u * tangentU + v * tangentV + height(u, v) * normal);
  };
  double bu = 0.0, bv = 0.0, best = f(0.0, 0.0);
  // Stationary point: ∇f = 0 ⇔ dn·H·(u, v) = −(du + dn·c₁, dv + dn·c₂), H = [c₃ c₄; c₄ c₅];
  // a maximum when dn·H is negative definite.
  const double a = dn * c[3], b = dn * c[4], e = dn * c[5];
  const double det = a * e - b * b;
  const double gu = du + dn * c[1], gv = dv + dn * c[2];
  if (a < 0.0 && det > 0.0) {
    const double u = (-gu * e + gv * b) / det, v = (-gv * a + gu * b) / det;
    const double r = std::sqrt(u * u + v * v);
    const double s = r > halfWidth ? halfWidth / r : 1.0;  // the disc's point nearest the maximum
    if (const double fs = f(s * u, s * v); fs > best) best = fs, bu = s * u, bv = s * v;
  }
  // The rim point the gradient at the centre points to (the maximum of a
  // flat, saddle or concave patch lies on the rim).
  if (const double gn = std::sqrt(gu * gu + gv * gv); gn > 0.0) {
    const double u = halfWidth * gu / gn, v = halfWidth * gv / gn;
    if (const double fr = f(u, v); fr > best) best = fr, bu = u, bv = v;
  }
  return point(bu, bv);
}

namespace {

// The point of P = {y : a_i·y ≤ b_i, i < m} (m ≤ 3, the a_i unit) nearest
// x: the projection onto the planes of an active set S, which is the
// answer when its multipliers are ≥ 0 and it lies in P (KKT); every set is
// tried (at most 7) and the nearest such point kept.
Vec3 projectOntoHalfSpaces(const Vec3& x, const Vec3* a, const double* b, int m) noexcept {
  constexpr double kFeasible = 1e-10;  // m
  Vec3 best = x;
  double bestDist = std::numeric_limits<double>::infinity();
  for (int set = 1; set < (1 << m); ++set) {
    int idx[3], k = 0;
    for (int i = 0; i < m; ++i)
      if (set & (1 << i)) idx[k++] = i;
    Eigen::Matrix3d g = Eigen::Matrix3d::Identity();
    Eigen::Vector3d r = Eigen::Vector3d::Zero();
    for (int i = 0; i < k; ++i) {
      r[i] = a[idx[i]].dot(x) - b[idx[i]];
      for (int j = 0; j < k; ++j) g(i, j) = a[idx[i]].dot(a[idx[j]]);
    }
    // Multipliers μ = G⁻¹ r, G the Gram matrix of the set's normals
    // (fixed-size arithmetic: this runs in the haptic tick).
    Eigen::Vector3d mu = Eigen::Vector3d::Zero();
    if (k == 1) {
      mu[0] = r[0];
    } else if (k == 2) {
      const double det = g(0, 0) * g(1, 1) - g(0, 1) * g(0, 1);
      if (!(det > 1e-12)) continue;  // parallel planes: no common line
      mu[0] = (g(1, 1) * r[0] - g(0, 1) * r[1]) / det;
      mu[1] = (g(0, 0) * r[1] - g(0, 1) * r[0]) / det;
    } else {
      if (!(std::abs(g.determinant()) > 1e-12)) continue;
      mu = g.inverse() * r;
    }
    bool ok = true;
    Vec3 y = x;
    for (int i = 0; i < k; ++i) {
      ok = ok && mu[i] >= -kFeasible && std::isfinite(mu[i]);
      y -= mu[i] * a[idx[i]];
    }
    for (int i = 0; i < m && ok; ++i) ok = a[i].dot(y) - b[i] <= kFeasible;
    if (const double d = (y - x).squaredNorm(); ok && d < bestDist) bestDist = d, best = y;
  }
  return best;
}

}  // namespace

SurfacePatch::Query SurfacePatch::creaseQuery(const Vec3& x) const noexcept {
  const int m = crease.planes;
  // The region the point is projected onto, as a_i·y ≤ b_i: the solid
  // (convex) or the free wedge (concave, where the solid is the union).
  const double sign = crease.convex ? 1.0 : -1.0;
  Vec3 a[3];
  double b[3], s[3];
  int lo = 0, hi = 0;
  bool inRegion = true;
  for (int i = 0; i < m; ++i) {
    a[i] = sign * crease.normal[i];
    b[i] = sign * crease.offset[i];
    s[i] = crease.normal[i].dot(x) - crease.offset[i];  // > 0: outside plane i's half-space
    inRegion = inRegion && a[i].dot(x) <= b[i];
    if (s[i] > s[hi]) hi = i;
    if (s[i] < s[lo]) lo = i;
  }
  Query q;
  Vec3 foot;
  if (inRegion) {
    // Inside a convex solid, or outside a concave one: the nearest plane
    // (the distance to a convex region's boundary from within it).
    const int i = crease.convex ? hi : lo;
    q.distance = s[i];
    q.normal = crease.normal[i];
    foot = x - s[i] * crease.normal[i];
  } else {
    foot = projectOntoHalfSpaces(x, a, b, m);
    const Vec3 d = crease.convex ? Vec3(x - foot) : Vec3(foot - x);  // outward
    const double dn = d.norm();
    q.distance = crease.convex ? dn : -dn;
    q.normal = dn > 1e-12 ? Vec3(d / dn) : crease.normal[crease.convex ? hi : lo];
  }
  q.lateral = (foot - origin).norm();
  return q;
}

namespace detail {

void fitCrease(SurfacePatch& p, std::span<const Facet> facets) {
  p.crease = {};
  // Group the facets by normal, largest first, each into the first group
  // whose mean normal is within kCreaseGroupCos of its own.
  constexpr double kCreaseGroupCos = 0.94;  // 20°
  // A face lying on a cell's wall is clipped into the cells on both sides,
  // and the neighbour's faces into this cell's walls as slivers of no
  // width, whose normals are noise: facets under 1e-9 of the node's area
  // are left out.
  double total = 0.0;
  for (const Facet& f : facets) total += f.area;
  std::vector<std::uint32_t> order;
  for (std::uint32_t f = 0; f < facets.size(); ++f)
    if (facets[f].area > 1e-9 * total && facets[f].areaVector.norm() > 1e-12 * facets[f].area)
      order.push_back(f);
  std::sort(order.begin(), order.end(), [&](std::uint32_t x, std::uint32_t y) {
    return std::tuple(facets[x].area, y) > std::tuple(facets[y].area, x);
  });
  struct Group {
    Vec3 areaVector = Vec3::Zero(), areaMoment = Vec3::Zero();
    double area = 0.0;
  };
  std::array<Group, 3> groups;
  std::vector<std::uint8_t> groupOf(facets.size(), 0);
  int count = 0;
  for (const std::uint32_t f : order) {
    const Vec3 n = facets[f].areaVector.normalized();
    int g = 0;
    while (g < count && groups[g].areaVector.normalized().dot(n) < kCreaseGroupCos) ++g;
    if (g == 3) return;  // more than three faces: no crease
    count = std::max(count, g + 1);
    groups[g].areaVector += facets[f].areaVector;
    groups[g].areaMoment += facets[f].areaMoment;
    groups[g].area += facets[f].area;
    groupOf[f] = static_cast<std::uint8_t>(g);
  }
  if (count < 2) return;
  if (!p.valid()) {  // the faces' normals cancel (a thin wall): the frame is the surface's centroid
    double area = 0.0;
    Vec3 moment = Vec3::Zero();
    for (int g = 0; g < count; ++g) area += groups[g].area, moment += groups[g].areaMoment;
    p.origin = moment / area;
  }
  SurfacePatch::Crease c;
  c.planes = static_cast<std::uint8_t>(count);
  std::array<Vec3, 3> centroid{};
  for (int g = 0; g < count; ++g) {
    c.normal[g] = groups[g].areaVector.normalized();
    centroid[g] = groups[g].areaMoment / groups[g].area;
    c.offset[g] = c.normal[g].dot(centroid[g]);
  }
  // Convex where every face's centroid lies behind or on every other
  // face's plane, concave where in front or on, and at least one strictly
  // (a face's centroid lies on another's plane where it is a strip along
  // their edge); anything else (a twisted or S-shaped surface) is no
  // crease of planes.
  double reach = 0.0;
  for (const std::uint32_t f : order)
    for (const Vec3& x : facets[f].points) {
      reach = std::max(reach, (x - p.origin).norm());
      const int g = groupOf[f];
      c.deviation = std::max(c.deviation, std::abs(c.normal[g].dot(x) - c.offset[g]));
    }
  const double tiny = 1e-6 * std::max(reach, 1e-12);
  int behind = 0, front = 0;
  for (int i = 0; i < count; ++i)
    for (int j = 0; j < count; ++j) {
      if (i == j) continue;
      const double side = c.normal[i].dot(centroid[j]) - c.offset[i];
      behind += side < -tiny ? 1 : 0;
      front += side > tiny ? 1 : 0;
    }
  if ((behind > 0) == (front > 0)) return;  // mixed, or every centroid on every plane
  c.convex = behind > 0;
  c.reach = reach;
  p.crease = c;
}

SurfacePatch fitSurfacePatch(const Vec3& areaVector, double area, const Vec3& areaMoment,
                             std::span<const Vec3> points, std::span<const Vec3> fit, double fitScale) {
  SurfacePatch p;
  const double an = areaVector.norm();
  if (!(area > 0.0) || !(an > 1e-12 * area) || points.size() < 3) return p;
  if (fit.size() < 6) fit = points, fitScale = 0.0;
  p.normal = areaVector / an;
  p.coherence = std::min(1.0, an / area);
  p.origin = areaMoment / area;
  // A tangent from the axis least aligned with the normal.
  Vec3 axis = Vec3::Zero();
  Eigen::Index least = 0;
  p.normal.cwiseAbs().minCoeff(&least);
  axis[least] = 1.0;
  p.tangentU = (axis - axis.dot(p.normal) * p.normal).normalized();
  p.tangentV = p.normal.cross(p.tangentU);

  // The loops over the points work on plain doubles: they run for every
  // node of every tree built, and the Eigen expressions they replace (a dot
  // product per coordinate, a 6×6 rank update per point) are chains of
  // checked calls in the sanitizer trees at -O1 (docs/build-time.md).
  const auto local = [&p](const Vec3& x, double& u, double& v, double& w) {
    const double *q = x.data(), *o = p.origin.data();
    const double d[3] = {q[0] - o[0], q[1] - o[1], q[2] - o[2]};
    const auto dot = [&d](const Vec3& e) {
      return d[0] * e.data()[0] + d[1] * e.data()[1] + d[2] * e.data()[2];
    };
    u = dot(p.tangentU), v = dot(p.tangentV), w = dot(p.normal);
  };
  double u = 0.0, v = 0.0, dn = 0.0;
  double width = 0.0;
  for (const Vec3& x : points) {
    local(x, u, v, dn);
    width = std::max(width, std::hypot(u, v));
  }
  p.halfWidth = width;
  double fitWidth = 0.0;  // fit in coordinates scaled to the unit disc
  for (const Vec3& x : fit) {
    local(x, u, v, dn);
    fitWidth = std::max(fitWidth, std::hypot(u, v));
  }
  const double s = fitWidth > 0.0 ? fitWidth : 1.0;

  // Least squares of w over the basis (1, ũ, ṽ, ½ũ², ũṽ, ½ṽ²), ũ = u/s; the
  // plane (the first three) when the points cannot fix a quadric.
  using Mat6 = Eigen::Matrix<double, 6, 6>;
  using Vec6 = Eigen::Matrix<double, 6, 1>;
  Mat6 ata = Mat6::Zero();
  Vec6 atb = Vec6::Zero();
  double* const A = ata.data();  // column-major: A[6·c + r] = ata(r, c)
  double* const B = atb.data();
  for (const Vec3& x : fit) {
    local(x, u, v, dn);
    u /= s, v /= s;
    const double row[6] = {1.0, u, v, 0.5 * u * u, u * v, 0.5 * v * v};
    const double w = fitScale > 0.0 ? std::exp(-(u * u + v * v) * (s * s) / (fitScale * fitScale)) : 1.0;
    for (int c = 0; c < 6; ++c) {  // the lower triangle of w·row·rowᵀ, and w·row·dn
      const double wc = w * row[c];
      for (int r = c; r < 6; ++r) A[6 * c + r] += wc * row[r];
      B[c] += wc * dn;
    }
  }
  ata.triangularView<Eigen::StrictlyUpper>() = ata.transpose();
  const auto solved = [](const auto& m, const auto& rhs, auto& out) {
    const auto ldlt = m.ldlt();
    if (ldlt.info() != Eigen::Success) return false;
    const auto dg = ldlt.vectorD().cwiseAbs();
    if (!(dg.minCoeff() > 1e-10 * dg.maxCoeff())) return false;
    out = ldlt.solve(rhs);
    return out.allFinite();
  };
  Vec6 a = Vec6::Zero();
  Eigen::Vector3d a3 = Eigen::Vector3d::Zero();
  if (fit.size() >= 6 && solved(ata, atb, a)) {
  } else if (solved(Eigen::Matrix3d(ata.topLeftCorner<3, 3>()), Eigen::Vector3d(atb.head<3>()), a3)) {
    a.head<3>() = a3;
  } else {
    a[0] = atb[0] / ata(0, 0);  // collinear points: the mean height
  }
  p.coeff = {a[0], a[1] / s, a[2] / s, a[3] / (s * s), a[4] / (s * s), a[5] / (s * s)};

  // Raise the patch above every surface point; the spread is the deviation.
  double hi = -std::numeric_limits<double>::infinity(), lo = std::numeric_limits<double>::infinity();
  for (const Vec3& x : points) {
    local(x, u, v, dn);
    const double r = dn - p.height(u, v);
    hi = std::max(hi, r);
    lo = std::min(lo, r);
  }
  p.coeff[0] += hi;
  p.deviation = hi - lo;
  return p;
}

}  // namespace detail
}  // namespace dm
