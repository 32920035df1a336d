// Largest-component extraction and Taubin smoothing; see dm/math/mesh_filters.hpp.
#include <dm/math/mesh_filters.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

namespace dm {
namespace {

/// A compressed-row table: the entries of row r are items[offsets[r] .. offsets[r + 1]).
struct RowTable {
  std::vector<std::size_t> offsets;
  std::vector<std::uint32_t> items;
};

bool inRange(const Triangle& t, std::size_t n) { return t[0] < n && t[1] < n && t[2] < n; }

/// For every vertex, the triangles that use it (in triangle order); triangles
/// with an out-of-range index are left out. O(V + F).
RowTable vertexTriangles(const Mesh& mesh) {
  const std::size_t n = mesh.positions.size();
  RowTable table;
  table.offsets.assign(n + 1, 0);
  for (const Triangle& t : mesh.triangles)
    if (inRange(t, n))
      for (std::uint32_t v : t) ++table.offsets[v + 1];
  for (std::size_t v = 0; v < n; ++v) table.offsets[v + 1] += table.offsets[v];
  table.items.resize(table.offsets[n]);
  std::vector<std::size_t> cursor(table.offsets.begin(), table.offsets.end() - 1);
  for (std::size_t t = 0; t < mesh.triangles.size(); ++t)
    if (inRange(mesh.triangles[t], n))
      for (std::uint32_t v : mesh.triangles[t]) table.items[cursor[v]++] = static_cast<std::uint32_t>(t);
  return table;
}

template <class T>
std::vector<T> gather(const std::vector<T>& attribute, const std::vector<std::uint32_t>& keptVertices,
                      std::size_t vertexCount) {
  std::vector<T> out;
  if (attribute.size() != vertexCount) return out;
  out.reserve(keptVertices.size());
  for (std::uint32_t v : keptVertices) out.push_back(attribute[v]);
  return out;
}

/// One umbrella step out[i] = in[i] + factor · (mean of in[neighbours] − in[i]);
/// fixed vertices are copied.
void umbrellaStep(const RowTable& ring, const std::vector<char>& fixed, const std::vector<Vec3>& in,
                  std::vector<Vec3>& out, double factor) {
  for (std::size_t i = 0; i < in.size(); ++i) {
    if (fixed[i]) {
      out[i] = in[i];
      continue;
    }
    Vec3 sum = Vec3::Zero();
    for (std::size_t k = ring.offsets[i]; k < ring.offsets[i + 1]; ++k) sum += in[ring.items[k]];
    const double count = static_cast<double>(ring.offsets[i + 1] - ring.offsets[i]);
    out[i] = in[i] + factor * (sum / count - in[i]);
  }
}

}  // namespace

Mesh keepLargestComponent(const Mesh& mesh, std::size_t* removedComponents) {
  const std::size_t n = mesh.positions.size();
  const std::size_t f = mesh.triangles.size();
  const RowTable incident = vertexTriangles(mesh);

  // Flood fill over triangles that share a vertex; pieces are numbered in the
  // order of their first triangle, so the strict '>' below breaks ties to the
  // earliest piece.
  constexpr std::size_t kNoPiece = std::numeric_limits<std::size_t>::max();
  std::vector<std::size_t> piece(f, kNoPiece);
  std::vector<std::uint32_t> stack;
  std::size_t pieces = 0, best = kNoPiece, bestSize = 0;
  for (std::size_t seed = 0; seed < f; ++seed) {
    if (piece[seed] != kNoPiece || !inRange(mesh.triangles[seed], n)) continue;
    const std::size_t id = pieces++;
    std::size_t size = 0;
    piece[seed] = id;
    stack.assign(1, static_cast<std::uint32_t>(seed));
    while (!stack.empty()) {
      const std::uint32_t t = stack.back();
      stack.pop_back();
      ++size;
      for (std::uint32_t v : mesh.triangles[t])
        for (std::size_t k = incident.offsets[v]; k < incident.offsets[v + 1]; ++k) {
          const std::uint32_t u = incident.items[k];
          if (piece[u] != kNoPiece) continue;
          piece[u] = id;
          stack.push_back(u);
        }
    }
    if (size > bestSize) {
      best = id;
      bestSize = size;
    }
  }
  if (removedComponents) *removedComponents = pieces > 0 ? pieces - 1 : 0;

  Mesh out;
  out.name = mesh.name;
  if (best == kNoPiece) return out;
  constexpr std::uint32_t kUnused = std::numeric_limits<std::uint32_t>::max();
  std::vector<std::uint32_t> remap(n, kUnused);
  for (std::size_t t = 0; t < f; ++t)
    if (piece[t] == best)
      for (std::uint32_t v : mesh.triangles[t]) remap[v] = 0;
  std::vector<std::uint32_t> kept;
  for (std::size_t v = 0; v < n; ++v)
    if (remap[v] != kUnused) {
      remap[v] = static_cast<std::uint32_t>(kept.size());
      kept.push_back(static_cast<std::uint32_t>(v));
    }
  out.positions = gather(mesh.positions, kept, n);
  out.normals = gather(mesh.normals, kept, n);
  out.uvs = gather(mesh.uvs, kept, n);
  out.colors = gather(mesh.colors, kept, n);
  out.triangles.reserve(bestSize);
  for (std::size_t t = 0; t < f; ++t)
    if (piece[t] == best) {
      const Triangle& tri = mesh.triangles[t];
      out.triangles.push_back({remap[tri[0]], remap[tri[1]], remap[tri[2]]});
    }
  return out;
}

Status smoothMesh(Mesh& mesh, int iterations, double lambda, double mu) {
  return smoothMesh(mesh, {.iterations = iterations, .lambda = lambda, .mu = mu});
}

Status smoothMesh(Mesh& mesh, const SmoothOptions& options) {
  const int iterations = options.iterations;
  const double lambda = options.lambda, mu = options.mu, limit = options.maxDisplacement;
  const std::string where = mesh.name.empty() ? "smoothMesh" : "smoothMesh: mesh '" + mesh.name + "'";
  if (iterations < 0 || iterations > 1000)
    return fail(ErrorCode::InvalidArgument, formatString("iterations is %d", iterations), where,
                "use 0 to 1000; 5 to 50 is typical");
  if (!std::isfinite(lambda) || lambda <= 0)
    return fail(ErrorCode::InvalidArgument, formatString("lambda is %g", lambda), where,
                "use a value in (0, 1], e.g. 0.5");
  if (!std::isfinite(mu) || mu >= -lambda)
    return fail(ErrorCode::InvalidArgument, formatString("mu is %g with lambda %g", mu, lambda), where,
                "mu must be below -lambda (Taubin's inflation step), e.g. lambda 0.5, mu -0.53");
  if (!(limit > 0))
    return fail(ErrorCode::InvalidArgument, formatString("maxDisplacement is %g", limit), where,
                "use a distance > 0 in metres (e.g. half a voxel), or infinity for no bound");
  if (auto s = mesh.validate(); !s) return s.error().within("smoothMesh");

  const std::size_t n = mesh.positions.size();
  // One-ring table: each non-degenerate triangle lists, for each corner, the
  // other two corners. After sorting a row, a neighbour appears once per
  // triangle on the shared edge: once on a boundary, more than twice on a
  // non-manifold edge; vertices on either are pinned.
  RowTable ring;
  ring.offsets.assign(n + 1, 0);
  auto usable = [](const Triangle& t) { return t[0] != t[1] && t[1] != t[2] && t[2] != t[0]; };
  for (const Triangle& t : mesh.triangles)
    if (usable(t))
      for (std::uint32_t v : t) ring.offsets[v + 1] += 2;
  for (std::size_t v = 0; v < n; ++v) ring.offsets[v + 1] += ring.offsets[v];
  ring.items.resize(ring.offsets[n]);
  {
    std::vector<std::size_t> cursor(ring.offsets.begin(), ring.offsets.end() - 1);
    for (const Triangle& t : mesh.triangles)
      if (usable(t))
        for (int c = 0; c < 3; ++c) {
          ring.items[cursor[t[c]]++] = t[(c + 1) % 3];
          ring.items[cursor[t[c]]++] = t[(c + 2) % 3];
        }
  }
  std::vector<char> fixed(n, 0);
  std::size_t write = 0;
  for (std::size_t v = 0; v < n; ++v) {
    const std::size_t begin = ring.offsets[v], end = ring.offsets[v + 1];
    std::sort(ring.items.begin() + static_cast<std::ptrdiff_t>(begin),
              ring.items.begin() + static_cast<std::ptrdiff_t>(end));
    ring.offsets[v] = write;
    fixed[v] = begin == end;  // unreferenced
    for (std::size_t k = begin; k < end;) {
      std::size_t m = k + 1;
      while (m < end && ring.items[m] == ring.items[k]) ++m;
      if (m - k != 2) fixed[v] = 1;
      ring.items[write++] = ring.items[k];
      k = m;
    }
  }
  ring.offsets[n] = write;
  ring.items.resize(write);

  std::vector<Vec3> scratch(n);
  const bool bounded = limit < std::numeric_limits<double>::infinity();
  const std::vector<Vec3> start = bounded ? mesh.positions : std::vector<Vec3>{};
  for (int it = 0; it < iterations; ++it) {
    umbrellaStep(ring, fixed, mesh.positions, scratch, lambda);
    umbrellaStep(ring, fixed, scratch, mesh.positions, mu);
    if (!bounded) continue;
    for (std::size_t v = 0; v < n; ++v) {
      const Vec3 d = mesh.positions[v] - start[v];
      const double len = d.norm();
      if (len > limit) mesh.positions[v] = start[v] + d * (limit / len);
    }
  }
  mesh.computeNormals();
  return ok();
}

}  // namespace dm
