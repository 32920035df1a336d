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

  const double cell = 0.5 * spacing, r2 = cell * cell;
  std::unordered_map<SampleCell, std::vector<std::uint32_t>, SampleCellHash> cells;
  std::vector<Vec3> out;
  std::vector<Vec3> onSurface;  // the kept samples before the inset (what later ones are compared with)
  const auto cellOf = [&](const Vec3& p) {
    return SampleCell{std::int64_t(std::floor(p.x() / cell)), std::int64_t(std::floor(p.y() / cell)),
                      std::int64_t(std::floor(p.z() / cell))};
  };
  for (const Triangle& tri : mesh.triangles) {
    const Vec3 &a = mesh.positions[tri[0]], &b = mesh.positions[tri[1]], &c = mesh.positions[tri[2]];
    const Vec3 cross = (b - a).cross(c - a);
    const double area2 = cross.norm();
    if (!(area2 > 0.0)) continue;  // a degenerate triangle has no inside to point to
    const Vec3 inward = -cross / area2;
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
        out.push_back(p + inset * inward);
      }
  }
  return out;
}

}  // namespace dm
