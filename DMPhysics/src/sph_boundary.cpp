// sph_boundary.cpp — boundary particles on a mesh's surface
// (dm/physics/sph_boundary.hpp).
#include <dm/physics/sph_boundary.hpp>

#include <cmath>
#include <cstdint>
#include <string>
#include <unordered_map>

namespace dm {

namespace {

struct SampleCell {
  std::int64_t x, y, z;
  bool operator==(const SampleCell&) const = default;
};
struct SampleCellHash {
  std::size_t operator()(const SampleCell& c) const noexcept {
    std::uint64_t h = std::uint64_t(c.x) * 0x9E3779B97F4A7C15ull;
    h ^= std::uint64_t(c.y) * 0xC2B2AE3D27D4EB4Full + (h << 6) + (h >> 2);
    h ^= std::uint64_t(c.z) * 0x165667B19E3779F9ull + (h << 6) + (h >> 2);
    return std::size_t(h);
  }
};

}  // namespace

Result<std::vector<Vec3>> sampleBoundary(const Mesh& mesh, double spacing, double inset) {
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

  // Outward normals: per triangle; per vertex weighted by the corners'
  // angles (Thürmer and Wüthrich's pseudo-normal); per edge the sum of its
  // triangles'. A sample on an edge or a vertex goes in along theirs, so
  // that it ends up `inset` from every face plane through it (a box's edge
  // or corner moves diagonally), not from one face's alone.
  const std::size_t f = mesh.triangles.size();
  std::vector<Vec3> faceNormal(f, Vec3::Zero()), vertexNormal(n, Vec3::Zero());
  std::unordered_map<std::uint64_t, Vec3> edgeNormal;
  const auto edgeKey = [](std::uint32_t u, std::uint32_t v) {
    return u < v ? (std::uint64_t(u) << 32) | v : (std::uint64_t(v) << 32) | u;
  };
  for (std::size_t t = 0; t < f; ++t) {
    const Triangle& tri = mesh.triangles[t];
    const Vec3 cross = (mesh.positions[tri[1]] - mesh.positions[tri[0]])
                           .cross(mesh.positions[tri[2]] - mesh.positions[tri[0]]);
    if (!(cross.norm() > 0.0)) continue;
    faceNormal[t] = cross.normalized();
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t v = tri[std::size_t(k)], u = tri[std::size_t((k + 1) % 3)],
                          w = tri[std::size_t((k + 2) % 3)];
      const Vec3 e1 = mesh.positions[u] - mesh.positions[v], e2 = mesh.positions[w] - mesh.positions[v];
      const double angle = std::atan2(e1.cross(e2).norm(), e1.dot(e2));
      vertexNormal[v] += angle * faceNormal[t];
      auto [it, inserted] = edgeNormal.try_emplace(edgeKey(v, u), Vec3::Zero());
      it->second += faceNormal[t];
    }
  }

  const double cell = 0.5 * spacing, r2 = cell * cell;
  std::unordered_map<SampleCell, std::vector<std::uint32_t>, SampleCellHash> cells;
  std::vector<Vec3> out;
  std::vector<Vec3> onSurface;  // the kept samples before the inset (what later ones are compared with)
  const auto cellOf = [&](const Vec3& p) {
    return SampleCell{std::int64_t(std::floor(p.x() / cell)), std::int64_t(std::floor(p.y() / cell)),
                      std::int64_t(std::floor(p.z() / cell))};
  };
  for (std::size_t t = 0; t < f; ++t) {
    const Triangle& tri = mesh.triangles[t];
    const Vec3 &a = mesh.positions[tri[0]], &b = mesh.positions[tri[1]], &c = mesh.positions[tri[2]];
    if (faceNormal[t].isZero()) continue;  // a degenerate triangle has no inside to point to
    const Vec3& outward = faceNormal[t];
    const double longest = std::max({(b - a).norm(), (c - b).norm(), (a - c).norm()});
    const int steps = int(std::max(1.0, std::ceil(longest / spacing - 1e-9)));
    for (int i = 0; i <= steps; ++i)
      for (int j = 0; i + j <= steps; ++j) {
        const Vec3 p = a + (double(i) / steps) * (b - a) + (double(j) / steps) * (c - a);
        const SampleCell k = cellOf(p);
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
        Vec3 along = outward;
        if (i == 0 && j == 0)
          along = vertexNormal[tri[0]];
        else if (i == steps)
          along = vertexNormal[tri[1]];
        else if (j == steps)
          along = vertexNormal[tri[2]];
        else if (j == 0)
          along = edgeNormal[edgeKey(tri[0], tri[1])];
        else if (i == 0)
          along = edgeNormal[edgeKey(tri[0], tri[2])];
        else if (i + j == steps)
          along = edgeNormal[edgeKey(tri[1], tri[2])];
        along = along.norm() > 0.0 ? along.normalized() : outward;
        // `inset` from this face's plane (and from the others' through an
        // edge or corner of a symmetric solid), at most five insets deep.
        out.push_back(p - inset / std::max(along.dot(outward), 0.2) * along);
      }
  }
  return out;
}

}  // namespace dm
