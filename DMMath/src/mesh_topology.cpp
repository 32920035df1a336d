// mesh_topology.cpp — edge grouping, fans, components, volume; vertex welding.
#include <dm/math/geometry.hpp>
#include <dm/math/grid_cell.hpp>
#include <dm/math/mesh_topology.hpp>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <numeric>
#include <string>
#include <unordered_map>
#include <vector>

namespace dm {
namespace {

/// Union-find with path halving and union by index (the smaller index wins, so
/// roots are deterministic).
class DisjointSets {
 public:
  explicit DisjointSets(std::size_t n) : parent_(n) { std::iota(parent_.begin(), parent_.end(), 0); }
  std::size_t find(std::size_t x) {
    while (parent_[x] != x) {
      parent_[x] = parent_[parent_[x]];
      x = parent_[x];
    }
    return x;
  }
  void unite(std::size_t a, std::size_t b) {
    a = find(a);
    b = find(b);
    if (a == b) return;
    if (a < b) std::swap(a, b);
    parent_[a] = b;
  }

 private:
  std::vector<std::size_t> parent_;
};

bool isDegenerate(const Triangle& t, std::size_t n) {
  return t[0] >= n || t[1] >= n || t[2] >= n || t[0] == t[1] || t[1] == t[2] || t[2] == t[0];
}

/// One side of an undirected edge {lo, hi} as seen by a triangle.
struct EdgeSide {
  std::uint32_t hi;
  std::uint32_t triangle;
  std::uint8_t cornerLo, cornerHi;  // corner index (0..2) of lo and hi in the triangle
  bool forward;                     // the triangle goes lo → hi
};

}  // namespace

MeshTopology analyzeTopology(const Mesh& mesh) {
  MeshTopology out;
  const std::size_t n = mesh.positions.size();
  const std::size_t f = mesh.triangles.size();
  out.triangles = f;

  std::vector<std::uint8_t> good(f, 0);
  std::vector<std::size_t> edgeStart(n + 1, 0);  // CSR by lower vertex
  std::vector<std::uint8_t> referenced(n, 0);
  for (std::size_t t = 0; t < f; ++t) {
    const Triangle& tri = mesh.triangles[t];
    if (isDegenerate(tri, n)) {
      ++out.degenerateTriangles;
      continue;
    }
    good[t] = 1;
    for (int c = 0; c < 3; ++c) {
      referenced[tri[static_cast<std::size_t>(c)]] = 1;
      ++edgeStart[std::min(tri[static_cast<std::size_t>(c)], tri[static_cast<std::size_t>((c + 1) % 3)]) + 1];
    }
  }
  for (std::size_t v = 0; v < n; ++v) edgeStart[v + 1] += edgeStart[v];
  std::vector<EdgeSide> half(edgeStart[n]);
  {
    std::vector<std::size_t> fill(edgeStart.begin(), edgeStart.end() - 1);
    for (std::size_t t = 0; t < f; ++t) {
      if (!good[t]) continue;
      const Triangle& tri = mesh.triangles[t];
      for (std::uint8_t c = 0; c < 3; ++c) {
        const std::uint8_t d = static_cast<std::uint8_t>((c + 1) % 3);
        const std::uint32_t a = tri[c], b = tri[d];
        const bool forward = a < b;
        half[fill[std::min(a, b)]++] = EdgeSide{std::max(a, b), static_cast<std::uint32_t>(t),
                                                forward ? c : d, forward ? d : c, forward};
      }
    }
  }

  // Corners 3t + c; corners of one vertex joined across shared edges form its fans.
  DisjointSets fans(3 * f);
  DisjointSets pieces(n);
  for (std::size_t lo = 0; lo < n; ++lo) {
    auto* begin = half.data() + edgeStart[lo];
    auto* end = half.data() + edgeStart[lo + 1];
    std::sort(begin, end, [](const EdgeSide& a, const EdgeSide& b) {
      return a.hi != b.hi ? a.hi < b.hi : a.triangle < b.triangle;
    });
    for (auto* g = begin; g != end;) {
      auto* h = g;
      std::size_t forward = 0;
      while (h != end && h->hi == g->hi) forward += (h++)->forward ? 1 : 0;
      const std::size_t count = static_cast<std::size_t>(h - g);
      ++out.edges;
      if (count == 1) ++out.boundaryEdges;
      if (count > 2) ++out.nonManifoldEdges;
      if (count > 2 || (count == 2 && forward != 1)) ++out.misorientedEdges;
      pieces.unite(lo, g->hi);
      for (auto* e = g + 1; e != h; ++e) {
        fans.unite(3 * std::size_t{g->triangle} + g->cornerLo, 3 * std::size_t{e->triangle} + e->cornerLo);
        fans.unite(3 * std::size_t{g->triangle} + g->cornerHi, 3 * std::size_t{e->triangle} + e->cornerHi);
      }
      g = h;
    }
  }

  std::vector<std::uint32_t> fanCount(n, 0);
  for (std::size_t t = 0; t < f; ++t) {
    if (!good[t]) continue;
    for (std::size_t c = 0; c < 3; ++c)
      if (fans.find(3 * t + c) == 3 * t + c) ++fanCount[mesh.triangles[t][c]];
  }
  std::size_t goodTriangles = f - out.degenerateTriangles;
  for (std::size_t v = 0; v < n; ++v) {
    if (!referenced[v]) {
      ++out.unreferencedVertices;
      continue;
    }
    ++out.vertices;
    if (fanCount[v] > 1) ++out.nonManifoldVertices;
    if (pieces.find(v) == v) ++out.components;
  }
  out.eulerCharacteristic = static_cast<long long>(out.vertices) - static_cast<long long>(out.edges) +
                            static_cast<long long>(goodTriangles);
  out.isClosed = goodTriangles > 0 && out.boundaryEdges == 0;
  out.isManifold = out.nonManifoldEdges == 0 && out.nonManifoldVertices == 0;
  out.isOrientedConsistently = out.misorientedEdges == 0;

  // Volume relative to the bounding-box centre, which keeps the terms small.
  const Vec3 ref = mesh.positions.empty() ? Vec3::Zero() : Vec3(mesh.bounds().center());
  double volume = 0;
  Vec3 moment = Vec3::Zero();
  for (std::size_t t = 0; t < f; ++t) {
    if (!good[t]) continue;
    const Vec3 a = mesh.positions[mesh.triangles[t][0]] - ref;
    const Vec3 b = mesh.positions[mesh.triangles[t][1]] - ref;
    const Vec3 c = mesh.positions[mesh.triangles[t][2]] - ref;
    const Vec3 cr = (b - a).cross(c - a);
    out.surfaceArea += 0.5 * cr.norm();
    const double v = a.dot(b.cross(c)) / 6.0;
    volume += v;
    moment += v * (a + b + c) / 4.0;
  }
  if (out.isClosed && out.isManifold && out.isOrientedConsistently) {
    out.genus = static_cast<long long>(out.components) - out.eulerCharacteristic / 2;
    out.volume = volume;
    if (volume != 0) out.centroid = ref + moment / volume;
  }
  return out;
}

Result<WeldReport> weldVertices(Mesh& mesh, double tolerance) {
  if (!std::isfinite(tolerance) || tolerance < 0)
    return fail(ErrorCode::InvalidArgument, "weld tolerance is " + std::to_string(tolerance), "weldVertices",
                "pass a finite tolerance >= 0 in metres (0 merges exact duplicates)");
  const std::size_t n = mesh.positions.size();
  for (std::size_t v = 0; v < n; ++v)
    if (!mesh.positions[v].allFinite())
      return fail(ErrorCode::InvalidArgument, "vertex " + std::to_string(v) + " has a NaN or Inf coordinate",
                  "weldVertices", "fix or drop the vertex before welding");
  for (std::size_t t = 0; t < mesh.triangles.size(); ++t)
    for (std::uint32_t i : mesh.triangles[t])
      if (i >= n)
        return fail(ErrorCode::InvalidArgument,
                    "triangle " + std::to_string(t) + " uses vertex " + std::to_string(i) + " of " +
                        std::to_string(n),
                    "weldVertices", "run Mesh::validate() and fix the indices");
  const auto attributeSizeError = [n](const char* name, std::size_t size) {
    return fail(ErrorCode::InvalidArgument,
                std::string(name) + " has " + std::to_string(size) + " entries for " + std::to_string(n) +
                    " positions",
                "weldVertices", "give one entry per vertex or none");
  };
  if (!mesh.normals.empty() && mesh.normals.size() != n)
    return attributeSizeError("normals", mesh.normals.size());
  if (!mesh.uvs.empty() && mesh.uvs.size() != n) return attributeSizeError("uvs", mesh.uvs.size());
  if (!mesh.colors.empty() && mesh.colors.size() != n)
    return attributeSizeError("colors", mesh.colors.size());

  // Cells of size `tolerance` (exact coordinates when 0): a vertex within
  // `tolerance` of p is in p's cell or one of its 26 neighbours.
  const double inv = tolerance > 0 ? 1.0 / tolerance : 0.0;
  const auto cellOf = [&](const Vec3& p, GridCell& key) {
    if (tolerance == 0) {
      // +0.0 turns -0 into +0 so both hash alike.
      key = {std::bit_cast<std::int64_t>(p.x() + 0.0), std::bit_cast<std::int64_t>(p.y() + 0.0),
             std::bit_cast<std::int64_t>(p.z() + 0.0)};
      return true;
    }
    const Vec3 c = (p * inv).array().floor();
    if (c.cwiseAbs().maxCoeff() > 4.0e18) return false;
    key = {static_cast<std::int64_t>(c.x()), static_cast<std::int64_t>(c.y()),
           static_cast<std::int64_t>(c.z())};
    return true;
  };

  std::unordered_map<GridCell, std::uint32_t, GridCellHash> head;  // first kept vertex of a cell
  head.reserve(n);
  std::vector<std::uint32_t> nextInCell;  // per kept vertex, in order of keeping
  std::vector<std::uint32_t> kept;        // kept vertex → original index
  std::vector<std::uint32_t> target(n);   // original → new index
  const double tol2 = tolerance * tolerance;
  constexpr std::uint32_t kNoVertex = ~std::uint32_t{0};
  for (std::size_t v = 0; v < n; ++v) {
    const Vec3& p = mesh.positions[v];
    GridCell key{};
    if (!cellOf(p, key))
      return fail(ErrorCode::InvalidArgument,
                  "weld tolerance " + std::to_string(tolerance) +
                      " is too small for coordinates near vertex " + std::to_string(v),
                  "weldVertices", "use a tolerance above 1e-15 of the coordinates' magnitude, or 0");
    std::uint32_t best = kNoVertex;
    const int reach = tolerance > 0 ? 1 : 0;
    for (int dz = -reach; dz <= reach; ++dz)
      for (int dy = -reach; dy <= reach; ++dy)
        for (int dx = -reach; dx <= reach; ++dx) {
          const auto it = head.find(GridCell{key.x + dx, key.y + dy, key.z + dz});
          if (it == head.end()) continue;
          for (std::uint32_t k = it->second; k != kNoVertex; k = nextInCell[k])
            if (k < best && (mesh.positions[kept[k]] - p).squaredNorm() <= tol2) best = k;
        }
    if (best != kNoVertex) {
      target[v] = best;
      continue;
    }
    const auto newIndex = static_cast<std::uint32_t>(kept.size());
    target[v] = newIndex;
    kept.push_back(static_cast<std::uint32_t>(v));
    // Cells keep their vertices in descending order of keeping; the scan
    // above visits all of them, so the order does not matter.
    const auto [it, inserted] = head.try_emplace(key, newIndex);
    nextInCell.push_back(inserted ? kNoVertex : it->second);
    if (!inserted) it->second = newIndex;
  }

  WeldReport report;
  report.verticesRemoved = n - kept.size();
  if (report.verticesRemoved > 0) {
    std::vector<Vec3> positions(kept.size());
    for (std::size_t k = 0; k < kept.size(); ++k) positions[k] = mesh.positions[kept[k]];
    if (!mesh.normals.empty()) {
      std::vector<Vec3> sum(kept.size(), Vec3::Zero());
      for (std::size_t v = 0; v < n; ++v) sum[target[v]] += mesh.normals[v];
      for (std::size_t k = 0; k < kept.size(); ++k) {
        const double len = sum[k].norm();
        sum[k] = len > 0 && std::isfinite(len) ? Vec3(sum[k] / len) : mesh.normals[kept[k]];
      }
      mesh.normals = std::move(sum);
    }
    if (!mesh.uvs.empty()) {
      std::vector<Vec2f> uvs(kept.size());
      for (std::size_t k = 0; k < kept.size(); ++k) uvs[k] = mesh.uvs[kept[k]];
      mesh.uvs = std::move(uvs);
    }
    if (!mesh.colors.empty()) {
      std::vector<Vec4f> colors(kept.size());
      for (std::size_t k = 0; k < kept.size(); ++k) colors[k] = mesh.colors[kept[k]];
      mesh.colors = std::move(colors);
    }
    mesh.positions = std::move(positions);
  }
  std::size_t w = 0;
  for (std::size_t t = 0; t < mesh.triangles.size(); ++t) {
    Triangle tri = mesh.triangles[t];
    for (auto& i : tri) i = target[i];
    if (tri[0] == tri[1] || tri[1] == tri[2] || tri[2] == tri[0]) {
      ++report.trianglesRemoved;
      continue;
    }
    mesh.triangles[w++] = tri;
  }
  mesh.triangles.resize(w);
  return report;
}

double windingNumber(const Mesh& mesh, const Vec3& p) {
  double sum = 0.0;
  for (const Triangle& t : mesh.triangles)
    sum += solidAngle(p, mesh.positions[t[0]], mesh.positions[t[1]], mesh.positions[t[2]]);
  return sum / (4.0 * std::numbers::pi);
}

}  // namespace dm
