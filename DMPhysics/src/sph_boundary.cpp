// sph_boundary.cpp — boundary particles on a mesh's surface, placed again
// as it deforms (dm/physics/sph_boundary.hpp).
#include <dm/math/grid_cell.hpp>
#include <dm/physics/sph_boundary.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>
#include <unordered_map>

namespace dm {

Result<BoundarySurface> BoundarySurface::create(const Mesh& mesh, double spacing, double inset) {
  const std::string where = "sampleBoundary";
  if (!(spacing > 0.0) || !std::isfinite(spacing))
    return fail(ErrorCode::InvalidArgument, formatString("spacing %g", spacing), where,
                "the fluid's particle spacing in metres");
  if (!(inset >= 0.0) || !(inset < spacing))
    return fail(ErrorCode::InvalidArgument, formatString("inset %g with spacing %g", inset, spacing), where,
                "0 ≤ inset < spacing; a third of a spacing puts the fluid's edge on the surface");
  if (mesh.triangles.empty()) return fail(ErrorCode::InvalidArgument, "the mesh has no triangles", where);
  const std::size_t n = mesh.positions.size();
  for (std::size_t v = 0; v < n; ++v)
    if (!mesh.positions[v].allFinite())
      return fail(ErrorCode::InvalidArgument, formatString("vertex %zu is not finite", v), where);
  // The count first, from each triangle's lattice: a bound on the samples.
  double total = 0.0;
  for (std::size_t t = 0; t < mesh.triangles.size(); ++t) {
    const Triangle& tri = mesh.triangles[t];
    for (std::uint32_t i : tri)
      if (i >= n)
        return fail(ErrorCode::InvalidArgument, formatString("triangle %zu uses vertex %u of %zu", t, i, n),
                    where);
    const Vec3 &a = mesh.positions[tri[0]], &b = mesh.positions[tri[1]], &c = mesh.positions[tri[2]];
    const double longest = std::max({(b - a).norm(), (c - b).norm(), (a - c).norm()});
    const double steps = std::max(1.0, std::ceil(longest / spacing - 1e-9));
    total += (steps + 1.0) * (steps + 2.0) / 2.0;
  }
  if (total > double(kMaxBoundarySamples))
    return fail(ErrorCode::InvalidArgument,
                formatString("%.0f samples (at most %zu): the surface is too large for spacing %g", total,
                             kMaxBoundarySamples, spacing),
                where, "a larger spacing, or a smaller surface");

  BoundarySurface out;
  out.inset_ = inset;
  out.triangles_ = mesh.triangles;
  const std::size_t f = mesh.triangles.size();
  out.faceNormal_.assign(f, Vec3::Zero());
  out.vertexNormal_.assign(n, Vec3::Zero());
  // Edge numbers, once per edge shared by triangles.
  std::unordered_map<std::uint64_t, std::uint32_t> edgeIds;
  out.edges_.resize(f);
  for (std::size_t t = 0; t < f; ++t)
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t u = mesh.triangles[t][std::size_t(k)],
                          v = mesh.triangles[t][std::size_t((k + 1) % 3)];
      const std::uint64_t key = u < v ? (std::uint64_t(u) << 32) | v : (std::uint64_t(v) << 32) | u;
      out.edges_[t][std::size_t(k)] = edgeIds.try_emplace(key, std::uint32_t(edgeIds.size())).first->second;
    }
  out.edgeNormal_.assign(edgeIds.size(), Vec3::Zero());

  const double cell = 0.5 * spacing, r2 = cell * cell;
  std::unordered_map<GridCell, std::vector<std::uint32_t>, GridCellHash> cells;
  std::vector<Vec3> onSurface;  // the kept samples before the inset (what later ones are compared with)
  for (std::size_t t = 0; t < f; ++t) {
    const Triangle& tri = mesh.triangles[t];
    const Vec3 &a = mesh.positions[tri[0]], &b = mesh.positions[tri[1]], &c = mesh.positions[tri[2]];
    if (!((b - a).cross(c - a).norm() > 0.0)) continue;  // a degenerate triangle has no inside to point to
    const double longest = std::max({(b - a).norm(), (c - b).norm(), (a - c).norm()});
    const int steps = int(std::max(1.0, std::ceil(longest / spacing - 1e-9)));
    for (int i = 0; i <= steps; ++i)
      for (int j = 0; i + j <= steps; ++j) {
        const double s = double(i) / steps, u = double(j) / steps;
        const Vec3 p = a + s * (b - a) + u * (c - a);
        const GridCell k = GridCell::of(p, cell);
        bool near = false;
        for (std::int64_t dz = -1; dz <= 1 && !near; ++dz)
          for (std::int64_t dy = -1; dy <= 1 && !near; ++dy)
            for (std::int64_t dx = -1; dx <= 1 && !near; ++dx) {
              const auto it = cells.find({k.x + dx, k.y + dy, k.z + dz});
              if (it == cells.end()) continue;
              for (std::uint32_t q : it->second)
                if ((onSurface[q] - p).squaredNorm() < r2) {
                  near = true;
                  break;
                }
            }
        if (near) continue;
        cells[k].push_back(std::uint32_t(onSurface.size()));
        onSurface.push_back(p);
        // Which vertex or edge of the triangle the sample is on, if any.
        Feature feature = Feature::Face;
        if (i == 0 && j == 0)
          feature = Feature::Vertex0;
        else if (i == steps)
          feature = Feature::Vertex1;
        else if (j == steps)
          feature = Feature::Vertex2;
        else if (j == 0)
          feature = Feature::Edge01;
        else if (i == 0)
          feature = Feature::Edge20;
        else if (i + j == steps)
          feature = Feature::Edge12;
        out.samples_.push_back({std::uint32_t(t), feature, s, u});
      }
  }
  return out;
}

void BoundarySurface::place(std::span<const Vec3> vertices, std::span<Vec3> out) {
  // Outward normals: per triangle; per vertex weighted by the corners'
  // angles (Thürmer and Wüthrich's pseudo-normal); per edge the sum of its
  // triangles'. A sample on an edge or a vertex goes in along theirs, so
  // that it ends up `inset` from every face plane through it (a box's edge
  // or corner moves diagonally), not from one face's alone.
  std::fill(vertexNormal_.begin(), vertexNormal_.end(), Vec3::Zero());
  std::fill(edgeNormal_.begin(), edgeNormal_.end(), Vec3::Zero());
  for (std::size_t t = 0; t < triangles_.size(); ++t) {
    const Triangle& tri = triangles_[t];
    const Vec3 cross = (vertices[tri[1]] - vertices[tri[0]]).cross(vertices[tri[2]] - vertices[tri[0]]);
    const double area2 = cross.norm();
    faceNormal_[t] = area2 > 0.0 ? Vec3(cross / area2) : Vec3::Zero();
    if (area2 == 0.0) continue;
    for (std::size_t k = 0; k < 3; ++k) {
      const std::uint32_t v = tri[k], u = tri[(k + 1) % 3], w = tri[(k + 2) % 3];
      const Vec3 e1 = vertices[u] - vertices[v], e2 = vertices[w] - vertices[v];
      vertexNormal_[v] += std::atan2(e1.cross(e2).norm(), e1.dot(e2)) * faceNormal_[t];
      edgeNormal_[edges_[t][k]] += faceNormal_[t];
    }
  }
  for (std::size_t q = 0; q < samples_.size(); ++q) {
    const Sample& sm = samples_[q];
    const Triangle& tri = triangles_[sm.triangle];
    const Vec3 &a = vertices[tri[0]], &b = vertices[tri[1]], &c = vertices[tri[2]];
    const Vec3 p = a + sm.s * (b - a) + sm.t * (c - a);
    const Vec3& outward = faceNormal_[sm.triangle];
    if (outward.isZero()) {
      out[q] = p;
      continue;
    }
    Vec3 along = outward;
    switch (sm.feature) {
      case Feature::Face:
        break;
      case Feature::Vertex0:
        along = vertexNormal_[tri[0]];
        break;
      case Feature::Vertex1:
        along = vertexNormal_[tri[1]];
        break;
      case Feature::Vertex2:
        along = vertexNormal_[tri[2]];
        break;
      case Feature::Edge01:
        along = edgeNormal_[edges_[sm.triangle][0]];
        break;
      case Feature::Edge12:
        along = edgeNormal_[edges_[sm.triangle][1]];
        break;
      case Feature::Edge20:
        along = edgeNormal_[edges_[sm.triangle][2]];
        break;
    }
    along = along.norm() > 0.0 ? Vec3(along.normalized()) : outward;
    // `inset` from this face's plane (and from the others' through an edge
    // or corner of a symmetric solid), at most five insets deep.
    out[q] = p - inset_ / std::max(along.dot(outward), 0.2) * along;
  }
}

void BoundarySurface::interpolate(std::span<const Vec3> vertexValues, std::span<Vec3> out) const {
  for (std::size_t q = 0; q < samples_.size(); ++q) {
    const Sample& sm = samples_[q];
    const Triangle& tri = triangles_[sm.triangle];
    out[q] = (1.0 - sm.s - sm.t) * vertexValues[tri[0]] + sm.s * vertexValues[tri[1]] +
             sm.t * vertexValues[tri[2]];
  }
}

void BoundarySurface::spread(std::span<const Vec3> sampleValues, std::span<Vec3> vertexValues) const {
  for (std::size_t q = 0; q < samples_.size(); ++q) {
    const Sample& sm = samples_[q];
    const Triangle& tri = triangles_[sm.triangle];
    vertexValues[tri[0]] += (1.0 - sm.s - sm.t) * sampleValues[q];
    vertexValues[tri[1]] += sm.s * sampleValues[q];
    vertexValues[tri[2]] += sm.t * sampleValues[q];
  }
}

Result<std::vector<Vec3>> sampleBoundary(const Mesh& mesh, double spacing, double inset) {
  auto surface = BoundarySurface::create(mesh, spacing, inset);
  if (!surface) return surface.error();
  std::vector<Vec3> out(surface->size());
  surface->place(mesh.positions, out);
  return out;
}

}  // namespace dm
