// mass_properties.cpp — Eberly's polyhedral mass properties, closedness check.
#include <dm/math/mass_properties.hpp>

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <string>
#include <utility>
#include <vector>

namespace dm {
namespace {

std::string formatDouble(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.6g", v);
  return buf;
}

/// Eberly's subexpressions of the per-triangle integrals for one coordinate
/// (w0, w1, w2 of the three corners).
struct Subexpressions {
  double f1, f2, f3, g0, g1, g2;
};

Subexpressions subexpressions(double w0, double w1, double w2) {
  Subexpressions s;
  const double temp0 = w0 + w1;
  s.f1 = temp0 + w2;
  const double temp1 = w0 * w0;
  const double temp2 = temp1 + w1 * temp0;
  s.f2 = temp2 + w2 * s.f1;
  s.f3 = w0 * temp1 + w1 * temp2 + w2 * s.f2;
  s.g0 = s.f2 + w0 * (s.f1 + w0);
  s.g1 = s.f2 + w1 * (s.f1 + w1);
  s.g2 = s.f2 + w2 * (s.f1 + w2);
  return s;
}

/// Checks that every undirected edge is traversed equally often in both
/// directions (the surface is a closed, consistently oriented 2-cycle, which is
/// what the divergence theorem needs; non-manifold but balanced edges are fine).
Status checkClosed(const Mesh& mesh, const std::string& where) {
  // key = (lo << 32 | hi); the low bit of the count word says the direction.
  std::vector<std::pair<std::uint64_t, int>> edges;
  edges.reserve(3 * mesh.triangles.size());
  for (const Triangle& t : mesh.triangles) {
    if (t[0] == t[1] || t[1] == t[2] || t[2] == t[0]) continue;
    for (std::size_t c = 0; c < 3; ++c) {
      const std::uint32_t a = t[c], b = t[(c + 1) % 3];
      const std::uint64_t key = (std::uint64_t{std::min(a, b)} << 32) | std::max(a, b);
      edges.emplace_back(key, a < b ? 1 : -1);
    }
  }
  std::sort(edges.begin(), edges.end());
  std::size_t open = 0, flipped = 0;
  std::uint64_t firstOpen = 0, firstFlipped = 0;
  for (std::size_t i = 0; i < edges.size();) {
    std::size_t j = i;
    int balance = 0;
    while (j < edges.size() && edges[j].first == edges[i].first) balance += edges[j++].second;
    if (balance != 0) {
      // An odd imbalance needs a missing triangle; an even one a flipped one.
      if (balance % 2 != 0) {
        if (open++ == 0) firstOpen = edges[i].first;
      } else if (flipped++ == 0) {
        firstFlipped = edges[i].first;
      }
    }
    i = j;
  }
  const auto edgeName = [](std::uint64_t key) {
    return "(" + std::to_string(key >> 32) + ", " + std::to_string(key & 0xffffffffu) + ")";
  };
  if (open > 0)
    return fail(ErrorCode::InvalidArgument,
                "mesh is open: " + std::to_string(open) +
                    " edge(s) lack a matching triangle on one side, e.g. edge " + edgeName(firstOpen),
                where,
                "close the holes (every edge must be shared by two triangles) or weld duplicate vertices "
                "(dm::weldVertices) if the mesh is a triangle soup");
  if (flipped > 0)
    return fail(
        ErrorCode::InvalidArgument,
        "mesh is inconsistently oriented: " + std::to_string(flipped) +
            " edge(s) are traversed twice in the same direction, e.g. edge " + edgeName(firstFlipped),
        where,
        "flip the triangles whose winding disagrees with their neighbours (all CCW seen from outside)");
  return ok();
}

}  // namespace

Result<MassProperties> computeMassProperties(const Mesh& mesh, double density) {
  const std::string where = mesh.name.empty() ? std::string("computeMassProperties")
                                              : "computeMassProperties: mesh '" + mesh.name + "'";
  if (!std::isfinite(density) || density <= 0)
    return fail(ErrorCode::InvalidArgument, "density is " + formatDouble(density) + " kg/m³", where,
                "pass a finite density > 0 in kg/m³ (e.g. 1000 for water)");
  if (mesh.empty())
    return fail(ErrorCode::InvalidArgument, "mesh has no triangles", where, "give a closed triangle mesh");
  if (auto s = mesh.validate(); !s) return s.error().within("computeMassProperties");
  if (auto s = checkClosed(mesh, where); !s) return std::move(s).error();

  // Integrals of 1, x, y, z, x², y², z², xy, yz, zx over the solid, relative to
  // the centre `ref` of the bounding box of the triangles' vertices (unused
  // vertices far away must not move it).
  Aabb box;
  for (const Triangle& t : mesh.triangles)
    for (const std::uint32_t v : t) box.extend(mesh.positions[v]);
  const Vec3 ref = box.center();
  std::array<double, 10> in{};
  for (const Triangle& t : mesh.triangles) {
    const Vec3 p0 = mesh.positions[t[0]] - ref;
    const Vec3 p1 = mesh.positions[t[1]] - ref;
    const Vec3 p2 = mesh.positions[t[2]] - ref;
    // d = (p1 − p0) × (p2 − p0), twice the area-weighted outward normal.
    const Vec3 d = (p1 - p0).cross(p2 - p0);
    const Subexpressions x = subexpressions(p0.x(), p1.x(), p2.x());
    const Subexpressions y = subexpressions(p0.y(), p1.y(), p2.y());
    const Subexpressions z = subexpressions(p0.z(), p1.z(), p2.z());
    in[0] += d.x() * x.f1;
    in[1] += d.x() * x.f2;
    in[2] += d.y() * y.f2;
    in[3] += d.z() * z.f2;
    in[4] += d.x() * x.f3;
    in[5] += d.y() * y.f3;
    in[6] += d.z() * z.f3;
    in[7] += d.x() * (p0.y() * x.g0 + p1.y() * x.g1 + p2.y() * x.g2);
    in[8] += d.y() * (p0.z() * y.g0 + p1.z() * y.g1 + p2.z() * y.g2);
    in[9] += d.z() * (p0.x() * z.g0 + p1.x() * z.g1 + p2.x() * z.g2);
  }
  constexpr std::array<double, 10> kScale = {1.0 / 6,  1.0 / 24, 1.0 / 24,  1.0 / 24,  1.0 / 60,
                                             1.0 / 60, 1.0 / 60, 1.0 / 120, 1.0 / 120, 1.0 / 120};
  for (std::size_t i = 0; i < in.size(); ++i) in[i] *= kScale[i];

  const double volume = in[0];
  // Rounding of the sum is a few ulps of the terms, whose size is bounded by
  // the bounding box; a volume below that is indistinguishable from zero.
  const double diag = box.diagonal().norm();
  const double volumeFloor = 1e-12 * diag * diag * diag;
  if (!(volume > volumeFloor)) {
    if (volume < -volumeFloor)
      return fail(ErrorCode::InvalidArgument,
                  "mesh is open or inward-facing: signed volume is " + formatDouble(volume) + " m³", where,
                  "flip the triangle winding so that triangles are counter-clockwise seen from outside, "
                  "or close the mesh");
    return fail(
        ErrorCode::InvalidArgument,
        "mesh encloses no volume: signed volume is " + formatDouble(volume) + " m³ (flat or collapsed mesh)",
        where, "give a closed mesh that bounds a solid");
  }

  MassProperties mp;
  mp.volume = volume;
  mp.mass = density * volume;
  const Vec3 c(in[1] / volume, in[2] / volume, in[3] / volume);  // relative to ref
  mp.centroid = ref + c;
  // Second moments about the centroid (parallel axis theorem from ref; |c| is
  // at most half the box, so the subtraction loses no significant digits).
  const double sxx = in[4] - volume * c.x() * c.x();
  const double syy = in[5] - volume * c.y() * c.y();
  const double szz = in[6] - volume * c.z() * c.z();
  const double sxy = in[7] - volume * c.x() * c.y();
  const double syz = in[8] - volume * c.y() * c.z();
  const double szx = in[9] - volume * c.z() * c.x();
  Mat3 inertia;
  inertia << syy + szz, -sxy, -szx,  //
      -sxy, sxx + szz, -syz,         //
      -szx, -syz, sxx + syy;
  mp.inertia = density * inertia;

  const Eigen::SelfAdjointEigenSolver<Mat3> eig(mp.inertia);
  mp.principalMoments = eig.eigenvalues();
  Mat3 axes = eig.eigenvectors();
  // Deterministic signs: the largest component of the first two axes is
  // positive; the third completes a right-handed frame.
  for (int k = 0; k < 2; ++k) {
    Eigen::Index i = 0;
    axes.col(k).cwiseAbs().maxCoeff(&i);
    if (axes(i, k) < 0) axes.col(k) = -axes.col(k);
  }
  axes.col(2) = axes.col(0).cross(axes.col(1)).normalized();
  mp.principalAxes = axes;
  return mp;
}

Mat3 inertiaAboutPoint(const MassProperties& properties, const Vec3& point) {
  const Vec3 d = point - properties.centroid;
  return properties.inertia + properties.mass * (d.squaredNorm() * Mat3::Identity() - d * d.transpose());
}

}  // namespace dm
