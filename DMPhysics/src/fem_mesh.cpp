// Tetrahedral meshes for dm::FemBody: validation, the voxel and box
// builders (Kuhn split), hierarchical grids with hanging nodes, and the
// boundary surface; see dm/physics/fem.hpp.
#include <dm/collide/bvh.hpp>
#include <dm/collide/mesh_query.hpp>
#include <dm/core/assert.hpp>
#include <dm/core/volume.hpp>
#include <dm/physics/fem.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>
#include <tuple>
#include <unordered_map>
#include <utility>

#include "fem_shared.hpp"

namespace dm::femimpl {

// "%g" of a double, for error messages.
std::string num(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}

Error invalid(std::string what, std::string where, std::string hint) {
  return fail(ErrorCode::InvalidArgument, std::move(what), std::move(where), std::move(hint));
}

// Expands every entry of mesh.hanging through chains of hanging masters.
// Needs indices in range (validate() checks them first). Fails, naming the
// entry, on a cycle or on a chain that expands to more than kMaxTerms terms.
Result<ResolvedHanging> resolveHanging(const TetMesh& mesh, const char* where) {
  constexpr std::size_t kMaxTerms = 256;
  std::vector<std::int32_t> entryOf(mesh.nodes.size(), -1);
  for (std::size_t k = 0; k < mesh.hanging.size(); ++k) entryOf[mesh.hanging[k].node] = std::int32_t(k);
  ResolvedHanging out;
  struct Item {
    std::uint32_t node;
    double weight;
    std::size_t depth;
  };
  std::vector<Item> stack;
  std::vector<std::pair<std::uint32_t, double>> terms;
  for (std::size_t k = 0; k < mesh.hanging.size(); ++k) {
    const HangingNode& h = mesh.hanging[k];
    terms.clear();
    stack.assign({{h.masters[0], 0.5, 1}, {h.masters[1], 0.5, 1}});
    while (!stack.empty()) {
      const Item it = stack.back();
      stack.pop_back();
      const std::int32_t e = entryOf[it.node];
      if (e < 0) {
        terms.emplace_back(it.node, it.weight);
      } else if (it.depth > mesh.hanging.size() || it.node == h.node) {
        return invalid("hanging[" + std::to_string(k) + "] (node " + std::to_string(h.node) +
                           ") depends on itself through its masters",
                       where, "a hanging node's masters must resolve to nodes that do not hang");
      } else {
        const auto& m = mesh.hanging[std::size_t(e)].masters;
        stack.push_back({m[0], 0.5 * it.weight, it.depth + 1});
        stack.push_back({m[1], 0.5 * it.weight, it.depth + 1});
      }
      if (terms.size() + stack.size() > kMaxTerms)
        return invalid("hanging[" + std::to_string(k) + "] expands to more than " + std::to_string(kMaxTerms) +
                           " independent nodes",
                       where, "chains of hanging nodes must be short (2:1 balanced grids give ≤ 2 per level)");
    }
    std::sort(terms.begin(), terms.end());
    out.node.push_back(h.node);
    for (std::size_t t = 0; t < terms.size(); ++t) {
      if (t > 0 && terms[t].first == terms[t - 1].first)
        out.weight.back() += terms[t].second;
      else
        out.master.push_back(terms[t].first), out.weight.push_back(terms[t].second);
    }
    out.start.push_back(std::uint32_t(out.master.size()));
  }
  return out;
}

}  // namespace dm::femimpl

namespace dm {

namespace {

constexpr std::uint32_t kNoNode = std::numeric_limits<std::uint32_t>::max();

// The six Kuhn tetrahedra of the unit cube around the diagonal corner 0 →
// corner 7 (corner c = x + 2y + 4z): one per axis permutation (a, b, c),
// 0 → e_a → e_a + e_b → 7. Odd permutations have negative volume and are
// stored with their last two corners swapped. Every cube face is split by its
// diagonal through the face's lowest and highest corner, so neighbours match.
constexpr int kKuhn[6][4] = {
    {0, 1, 3, 7},  // (x, y, z) even
    {0, 1, 7, 5},  // (x, z, y) odd, swapped
    {0, 2, 7, 3},  // (y, x, z) odd, swapped
    {0, 2, 6, 7},  // (y, z, x) even
    {0, 4, 5, 7},  // (z, x, y) even
    {0, 4, 7, 6},  // (z, y, x) odd, swapped
};

// The six Kuhn tetrahedra of a cube with corners corner[c] (c = x + 2y + 4z),
// positively oriented also under a mirroring grid-to-world map.
void appendKuhnTets(const std::uint32_t (&corner)[8], bool mirrored, std::vector<Tet>& out) {
  for (const auto& t : kKuhn) {
    Tet tet{corner[t[0]], corner[t[1]], corner[t[2]], corner[t[3]]};
    if (mirrored) std::swap(tet[2], tet[3]);
    out.push_back(tet);
  }
}

// Kuhn tetrahedra of the occupied cells of a dims grid; gridToWorld maps
// node grid coordinates (0..dims) to metres. Nodes are numbered in first-use
// order; only two node layers are indexed at a time.
template <class Occupied>
Result<TetMesh> buildKuhnMesh(const Vec3i& dims, const Occupied& occupied, const Affine3& gridToWorld,
                              std::size_t maxTets, const char* where) {
  const std::size_t nx = static_cast<std::size_t>(dims.x()), ny = static_cast<std::size_t>(dims.y()),
                    nz = static_cast<std::size_t>(dims.z());
  std::size_t count = 0;
  for (std::size_t k = 0; k < nz; ++k)
    for (std::size_t j = 0; j < ny; ++j)
      for (std::size_t i = 0; i < nx; ++i) count += occupied(i, j, k) ? 1 : 0;
  if (count == 0)
    return femimpl::invalid("no voxel is occupied (occupancy is empty or below the threshold)", where,
                   "check the threshold and that the mask is not empty");
  if (count > maxTets / 6)
    return femimpl::invalid(std::to_string(count) + " occupied voxels need " + std::to_string(count * 6) +
                       " tetrahedra, more than maxTets = " + std::to_string(maxTets),
                   where, "downsample the volume or raise maxTets");
  const bool mirrored = gridToWorld.linear().determinant() < 0.0;

  TetMesh mesh;
  mesh.tets.reserve(count * 6);
  const std::size_t layerSize = (nx + 1) * (ny + 1);
  std::vector<std::uint32_t> lower(layerSize, kNoNode), upper(layerSize, kNoNode);
  for (std::size_t k = 0; k < nz; ++k) {
    std::fill(upper.begin(), upper.end(), kNoNode);
    for (std::size_t j = 0; j < ny; ++j)
      for (std::size_t i = 0; i < nx; ++i) {
        if (!occupied(i, j, k)) continue;
        std::uint32_t corner[8];
        for (int c = 0; c < 8; ++c) {
          const std::size_t ci = i + (c & 1), cj = j + ((c >> 1) & 1), ck = k + ((c >> 2) & 1);
          std::uint32_t& id = (ck == k ? lower : upper)[ci + (nx + 1) * cj];
          if (id == kNoNode) {
            id = static_cast<std::uint32_t>(mesh.nodes.size());
            mesh.nodes.push_back(gridToWorld * Vec3(double(ci), double(cj), double(ck)));
          }
          corner[c] = id;
        }
        appendKuhnTets(corner, mirrored, mesh.tets);
      }
    std::swap(lower, upper);
  }
  return mesh;
}

Status checkDims(const Vec3i& dims, const char* where) {
  for (int a = 0; a < 3; ++a)
    if (dims[a] <= 0)
      return femimpl::invalid("dims[" + std::to_string(a) + "] = " + std::to_string(dims[a]) + " is not positive",
                     where, "pass at least one cell along each axis");
  return ok();
}

Status checkPositive(const Vec3& v, const char* field, const char* where) {
  for (int a = 0; a < 3; ++a)
    if (!(v[a] > 0.0) || !std::isfinite(v[a]))
      return femimpl::invalid(
          std::string(field) + "." + "xyz"[a] + " = " + femimpl::num(v[a]) + " is not a positive finite length", where,
          "give sizes in metres, > 0");
  return ok();
}

Status checkOccupancy(std::span<const std::uint8_t> occupancy, const Vec3i& dims, const Vec3& spacing,
                      const Vec3& origin, const char* where) {
  if (Status s = checkDims(dims, where); !s) return s;
  if (Status s = checkPositive(spacing, "spacing", where); !s) return s;
  if (!origin.allFinite()) return femimpl::invalid("origin is not finite", where);
  const std::size_t nx = std::size_t(dims.x()), ny = std::size_t(dims.y()), nz = std::size_t(dims.z());
  if (occupancy.size() / nx / ny != nz || occupancy.size() != nx * ny * nz)
    return femimpl::invalid("occupancy has " + std::to_string(occupancy.size()) + " entries but dims need " +
                       std::to_string(nx) + "×" + std::to_string(ny) + "×" + std::to_string(nz),
                   where, "pass one byte per voxel, x fastest");
  return ok();
}

}  // namespace

// ---------------------------------------------------------------------------
// TetMesh
// ---------------------------------------------------------------------------

double TetMesh::tetVolume(std::size_t t) const {
  const Tet& e = tets[t];
  const Vec3& a = nodes[e[0]];
  return (nodes[e[1]] - a).dot((nodes[e[2]] - a).cross(nodes[e[3]] - a)) / 6.0;
}

double TetMesh::totalVolume() const {
  double v = 0.0;
  for (std::size_t t = 0; t < tets.size(); ++t) v += tetVolume(t);
  return v;
}

Status TetMesh::validate() const {
  constexpr const char* where = "TetMesh::validate";
  if (tets.empty()) return femimpl::invalid("the mesh has no tetrahedra", where);
  if (nodes.size() >= kNoNode) return femimpl::invalid("too many nodes (" + std::to_string(nodes.size()) + ")", where);
  for (std::size_t i = 0; i < nodes.size(); ++i)
    if (!nodes[i].allFinite()) return femimpl::invalid("nodes[" + std::to_string(i) + "] is not finite", where);
  for (std::size_t t = 0; t < tets.size(); ++t) {
    const Tet& e = tets[t];
    for (int a = 0; a < 4; ++a) {
      if (e[a] >= nodes.size())
        return femimpl::invalid("tets[" + std::to_string(t) + "][" + std::to_string(a) +
                           "] = " + std::to_string(e[a]) + " is out of range (" +
                           std::to_string(nodes.size()) + " nodes)",
                       where);
      for (int b = 0; b < a; ++b)
        if (e[a] == e[b])
          return femimpl::invalid("tets[" + std::to_string(t) + "] repeats node " + std::to_string(e[a]), where);
    }
    const double v = tetVolume(t);
    if (!(v > 0.0))
      return femimpl::invalid("tets[" + std::to_string(t) + "] has volume " + femimpl::num(v) + " m³ (must be > 0)", where,
                     "orient tetrahedra so that det[x1−x0, x2−x0, x3−x0] > 0 and drop flat ones");
  }
  if (!fractions.empty() && fractions.size() != tets.size())
    return femimpl::invalid(
        std::to_string(fractions.size()) + " fractions for " + std::to_string(tets.size()) + " tetrahedra",
        where, "give one per tetrahedron, or none (all 1)");
  for (std::size_t t = 0; t < fractions.size(); ++t)
    if (!(fractions[t] > 0.0 && fractions[t] <= 1.0))
      return femimpl::invalid(
          "fractions[" + std::to_string(t) + "] = " + femimpl::num(fractions[t]) + " is outside (0, 1]",
          where);
  if (hanging.empty()) return ok();
  std::vector<std::uint8_t> seen(nodes.size(), 0);
  for (std::size_t k = 0; k < hanging.size(); ++k) {
    const HangingNode& h = hanging[k];
    const std::string name = "hanging[" + std::to_string(k) + "]";
    for (std::uint32_t i : {h.node, h.masters[0], h.masters[1]})
      if (i >= nodes.size())
        return femimpl::invalid(name + " names node " + std::to_string(i) + ", out of range (" +
                           std::to_string(nodes.size()) + " nodes)",
                       where);
    if (h.masters[0] == h.masters[1] || h.node == h.masters[0] || h.node == h.masters[1])
      return femimpl::invalid(name + " needs two distinct masters other than node " + std::to_string(h.node), where);
    if (seen[h.node]++)
      return femimpl::invalid(name + ": node " + std::to_string(h.node) + " hangs twice", where,
                     "give one entry per hanging node");
    const Vec3 &a = nodes[h.masters[0]], &b = nodes[h.masters[1]];
    if ((nodes[h.node] - 0.5 * (a + b)).norm() > 1e-9 * (a - b).norm())
      return femimpl::invalid(name + ": node " + std::to_string(h.node) + " is not at the midpoint of its masters " +
                         std::to_string(h.masters[0]) + " and " + std::to_string(h.masters[1]),
                     where, "a hanging node lies on the coarse edge or face diagonal it splits");
  }
  if (auto r = femimpl::resolveHanging(*this, where); !r) return std::move(r).error();
  return ok();
}

Result<TetMesh> tetMeshFromOccupancy(std::span<const std::uint8_t> occupancy, const Vec3i& dims,
                                     const Vec3& spacing, const Vec3& origin,
                                     const VoxelTetOptions& options) {
  constexpr const char* where = "tetMeshFromOccupancy";
  if (Status s = checkOccupancy(occupancy, dims, spacing, origin, where); !s) return std::move(s).error();
  const std::size_t nx = std::size_t(dims.x()), ny = std::size_t(dims.y());
  Affine3 gridToWorld = Affine3::Identity();
  gridToWorld.linear() = spacing.asDiagonal();
  gridToWorld.translation() = origin;
  return buildKuhnMesh(
      dims,
      [&](std::size_t i, std::size_t j, std::size_t k) { return occupancy[i + nx * (j + ny * k)] != 0; },
      gridToWorld, options.maxTets, where);
}

Result<TetMesh> tetMeshFromVolume(const Volume& volume, const VoxelTetOptions& options) {
  constexpr const char* where = "tetMeshFromVolume";
  if (std::isnan(options.threshold)) return femimpl::invalid("threshold is NaN", where);
  if (Status s = checkDims(volume.dims(), where); !s) return std::move(s).error();
  if (Status s = checkPositive(volume.spacing(), "spacing", where); !s) return std::move(s).error();
  // Node (i, j, k) of the corner grid is index point (i − ½, j − ½, k − ½).
  const Affine3 gridToWorld = volume.indexToWorld() * Eigen::Translation3d(-0.5, -0.5, -0.5);
  const double threshold = options.threshold;
  return buildKuhnMesh(
      volume.dims(),
      [&](std::size_t i, std::size_t j, std::size_t k) {
        return volume.valueAt(volume.linearIndex(int(i), int(j), int(k))) >= threshold;
      },
      gridToWorld, options.maxTets, where);
}

Result<TetMesh> tetMeshBox(const Vec3i& cells, const Vec3& size, const Vec3& origin, std::size_t maxTets) {
  constexpr const char* where = "tetMeshBox";
  if (Status s = checkDims(cells, where); !s) return std::move(s).error();
  if (Status s = checkPositive(size, "size", where); !s) return std::move(s).error();
  if (!origin.allFinite()) return femimpl::invalid("origin is not finite", where);
  Affine3 gridToWorld = Affine3::Identity();
  gridToWorld.linear() = size.cwiseQuotient(cells.cast<double>()).asDiagonal();
  gridToWorld.translation() = origin;
  // Guard the cell count before the counting loop walks it.
  const double cellCount = double(cells.x()) * double(cells.y()) * double(cells.z());
  if (cellCount * 6.0 > double(maxTets))
    return femimpl::invalid(femimpl::num(cellCount) + " cells need " + femimpl::num(cellCount * 6.0) +
                       " tetrahedra, more than maxTets = " + std::to_string(maxTets),
                   where, "use fewer cells or raise maxTets");
  return buildKuhnMesh(
      cells, [](std::size_t, std::size_t, std::size_t) { return true; }, gridToWorld, maxTets, where);
}

Result<TetMesh> tetMeshHierarchical(std::span<const std::uint8_t> occupancy, const Vec3i& dims,
                                    const Vec3& spacing, const Vec3& origin, const HierarchicalTetOptions& options) {
  constexpr const char* where = "tetMeshHierarchical";
  if (Status s = checkOccupancy(occupancy, dims, spacing, origin, where); !s) return std::move(s).error();
  if (options.levels < 0 || options.levels > 10)
    return femimpl::invalid("options.levels = " + std::to_string(options.levels) + " is outside 0..10", where,
                   "coarsest cells are 2^levels voxels across; 2–4 is typical");
  if (!(options.grading >= 0.0) || !std::isfinite(options.grading))
    return femimpl::invalid("options.grading = " + femimpl::num(options.grading) + " is not finite and ≥ 0", where);
  const Aabb& region = options.fineRegion;
  if (!region.isEmpty() && (!region.min().allFinite() || !region.max().allFinite()))
    return femimpl::invalid("options.fineRegion is not finite", where, "give a box in metres, or an empty one");
  for (int a = 0; a < 3; ++a)
    if (dims[a] > (1 << 20))
      return femimpl::invalid("dims[" + std::to_string(a) + "] = " + std::to_string(dims[a]) + " exceeds 2^20", where,
                     "crop or downsample the grid");

  // Occupancy pyramid: level l has cells of 2^l voxels; `any` = some voxel
  // occupied, `full` = all voxels inside the grid and occupied.
  struct Level {
    Vec3i dims;
    std::vector<std::uint8_t> any, full;
    std::size_t at(int i, int j, int k) const {
      return std::size_t(i) + std::size_t(dims.x()) * (std::size_t(j) + std::size_t(dims.y()) * std::size_t(k));
    }
  };
  const int L = options.levels;
  std::vector<Level> pyr(std::size_t(L) + 1);
  pyr[0].dims = dims;
  pyr[0].any.resize(occupancy.size());
  std::size_t occupied = 0;
  for (std::size_t v = 0; v < occupancy.size(); ++v) occupied += (pyr[0].any[v] = occupancy[v] != 0);
  pyr[0].full = pyr[0].any;
  if (occupied == 0)
    return femimpl::invalid("no voxel is occupied (occupancy is empty or below the threshold)", where,
                   "check the threshold and that the mask is not empty");
  for (std::size_t l = 1; l <= std::size_t(L); ++l) {
    const Level& f = pyr[l - 1];
    Level& c = pyr[l];
    c.dims = (f.dims.array() + 1) / 2;
    c.any.assign(std::size_t(c.dims.prod()), 0);
    c.full.assign(c.any.size(), 0);
    for (int k = 0; k < c.dims.z(); ++k)
      for (int j = 0; j < c.dims.y(); ++j)
        for (int i = 0; i < c.dims.x(); ++i) {
          bool any = false, full = true;
          for (int q = 0; q < 8; ++q) {
            const int x = 2 * i + (q & 1), y = 2 * j + ((q >> 1) & 1), z = 2 * k + ((q >> 2) & 1);
            if (x >= f.dims.x() || y >= f.dims.y() || z >= f.dims.z()) {
              full = false;
              continue;
            }
            any = any || f.any[f.at(x, y, z)];
            full = full && f.full[f.at(x, y, z)];
          }
          c.any[c.at(i, j, k)] = any;
          c.full[c.at(i, j, k)] = full;
        }
  }

  // Leaves of the octree, origin in voxels. A cell stays whole when it is
  // full and at least grading·side away from the fine region.
  struct Cell {
    int x, y, z, level;
  };
  const double voxelSide = spacing.maxCoeff();
  auto nearRegion = [&](const Cell& c) {
    if (region.isEmpty()) return false;
    const double side = double(1 << c.level);
    const Vec3 lo = origin + spacing.cwiseProduct(Vec3(c.x, c.y, c.z));
    const Aabb box(lo, lo + side * spacing);
    return std::sqrt(region.squaredExteriorDistance(box)) < options.grading * side * voxelSide;
  };
  std::vector<Cell> leaves, stack;
  for (int k = 0; k < pyr[std::size_t(L)].dims.z(); ++k)
    for (int j = 0; j < pyr[std::size_t(L)].dims.y(); ++j)
      for (int i = 0; i < pyr[std::size_t(L)].dims.x(); ++i) stack.push_back({i << L, j << L, k << L, L});
  while (!stack.empty()) {
    const Cell c = stack.back();
    stack.pop_back();
    const Level& lv = pyr[std::size_t(c.level)];
    const std::size_t at = lv.at(c.x >> c.level, c.y >> c.level, c.z >> c.level);
    if (!lv.any[at]) continue;
    if (c.level == 0 || (lv.full[at] && !nearRegion(c))) {
      leaves.push_back(c);
      continue;
    }
    const int h = 1 << (c.level - 1);
    for (int q = 0; q < 8; ++q) {
      const Cell child{c.x + h * (q & 1), c.y + h * ((q >> 1) & 1), c.z + h * ((q >> 2) & 1), c.level - 1};
      if (child.x < dims.x() && child.y < dims.y() && child.z < dims.z()) stack.push_back(child);
    }
  }

  // 2:1 balance across faces and edges: split a leaf while a neighbour
  // leaf touching one of its faces or edges is more than one level finer.
  // Also split a leaf whose face is partly on the boundary and partly
  // against occupied voxels, so that each face of a coarse cell is either
  // all boundary or all interface (its surface triangles are then whole).
  std::vector<std::int8_t> levelOf(occupancy.size(), -1);
  auto voxel = [&](int x, int y, int z) { return pyr[0].at(x, y, z); };
  auto paint = [&](const Cell& c) {
    const int s = 1 << c.level;
    for (int z = c.z; z < c.z + s; ++z)
      for (int y = c.y; y < c.y + s; ++y)
        for (int x = c.x; x < c.x + s; ++x) levelOf[voxel(x, y, z)] = std::int8_t(c.level);
  };
  for (const Cell& c : leaves) paint(c);
  auto mustSplit = [&](const Cell& c) {
    const int s = 1 << c.level;
    const int lo[3] = {c.x, c.y, c.z};
    for (int d = 0; d < 27; ++d) {
      const int off[3] = {d % 3 - 1, (d / 3) % 3 - 1, d / 9 - 1};
      const int nonzero = (off[0] != 0) + (off[1] != 0) + (off[2] != 0);
      if (nonzero == 0 || nonzero == 3) continue;  // itself; corner neighbours share no edge
      int from[3], to[3];
      std::size_t cells = 1;
      for (int a = 0; a < 3; ++a) {
        from[a] = off[a] < 0 ? lo[a] - 1 : off[a] > 0 ? lo[a] + s : lo[a];
        to[a] = off[a] == 0 ? lo[a] + s : from[a] + 1;
        cells *= std::size_t(to[a] - from[a]);
        from[a] = std::max(from[a], 0);
        to[a] = std::min(to[a], dims[a]);
      }
      std::size_t filled = 0;
      for (int z = from[2]; z < to[2]; ++z)
        for (int y = from[1]; y < to[1]; ++y)
          for (int x = from[0]; x < to[0]; ++x)
            if (const int n = levelOf[voxel(x, y, z)]; n >= 0) {
              if (n < c.level - 1) return true;
              ++filled;
            }
      if (nonzero == 1 && filled > 0 && filled < cells) return true;
    }
    return false;
  };
  for (bool changed = true; changed;) {
    changed = false;
    for (std::size_t i = 0; i < leaves.size(); ++i) {
      const Cell c = leaves[i];
      if (c.level < 1 || !mustSplit(c)) continue;
      const int h = 1 << (c.level - 1);
      for (int q = 0; q < 8; ++q) {  // a split leaf was full: all children are inside and occupied
        const Cell child{c.x + h * (q & 1), c.y + h * ((q >> 1) & 1), c.z + h * ((q >> 2) & 1), c.level - 1};
        if (q == 0)
          leaves[i] = child;
        else
          leaves.push_back(child);
        paint(child);
      }
      changed = true;
    }
  }
  if (leaves.size() > options.maxTets / 6)
    return femimpl::invalid(std::to_string(leaves.size()) + " cells need " + std::to_string(leaves.size() * 6) +
                       " tetrahedra, more than maxTets = " + std::to_string(options.maxTets),
                   where, "raise levels, shrink the fine region or raise maxTets");
  std::sort(leaves.begin(), leaves.end(), [](const Cell& a, const Cell& b) {
    return std::tie(a.z, a.y, a.x) < std::tie(b.z, b.y, b.x);
  });

  // Corners on the voxel lattice, numbered in first-use order.
  TetMesh mesh;
  mesh.tets.reserve(leaves.size() * 6);
  std::unordered_map<std::uint64_t, std::uint32_t> nodeAt;
  nodeAt.reserve(leaves.size() * 2);
  auto key = [](int x, int y, int z) {
    return std::uint64_t(x) | (std::uint64_t(y) << 21) | (std::uint64_t(z) << 42);
  };
  auto node = [&](int x, int y, int z) {
    auto [it, fresh] = nodeAt.try_emplace(key(x, y, z), std::uint32_t(mesh.nodes.size()));
    if (fresh) mesh.nodes.push_back(origin + spacing.cwiseProduct(Vec3(x, y, z)));
    return it->second;
  };
  for (const Cell& c : leaves) {
    const int s = 1 << c.level;
    std::uint32_t corner[8];
    for (int q = 0; q < 8; ++q) corner[q] = node(c.x + s * (q & 1), c.y + s * ((q >> 1) & 1), c.z + s * ((q >> 2) & 1));
    appendKuhnTets(corner, false, mesh.tets);
  }

  // Hanging nodes: fine corners at the midpoint of a coarse leaf's edge, or
  // at the centre of its face (the midpoint of the face's Kuhn diagonal,
  // from its lowest to its highest corner).
  std::vector<std::uint8_t> hangs(mesh.nodes.size(), 0);
  auto constrain = [&](const int (&mid)[3], const int (&a)[3], const int (&b)[3]) {
    const auto it = nodeAt.find(key(mid[0], mid[1], mid[2]));
    if (it == nodeAt.end() || hangs[it->second]) return;
    hangs[it->second] = 1;
    mesh.hanging.push_back({it->second, {nodeAt.at(key(a[0], a[1], a[2])), nodeAt.at(key(b[0], b[1], b[2]))}});
  };
  for (const Cell& c : leaves) {
    if (c.level == 0) continue;
    const int s = 1 << c.level, h = s / 2;
    const int lo[3] = {c.x, c.y, c.z};
    for (int a = 0; a < 3; ++a) {
      const int b = (a + 1) % 3, d = (a + 2) % 3;
      for (int q = 0; q < 4; ++q) {  // the four edges along axis a
        int p0[3] = {lo[0], lo[1], lo[2]};
        p0[b] += s * (q & 1);
        p0[d] += s * (q >> 1);
        int p1[3] = {p0[0], p0[1], p0[2]}, mid[3] = {p0[0], p0[1], p0[2]};
        p1[a] += s;
        mid[a] += h;
        constrain(mid, p0, p1);
      }
      for (int side = 0; side < 2; ++side) {  // the two faces normal to axis a
        int p0[3] = {lo[0], lo[1], lo[2]};
        p0[a] += s * side;
        int p1[3] = {p0[0], p0[1], p0[2]}, mid[3] = {p0[0], p0[1], p0[2]};
        p1[b] += s, p1[d] += s;
        mid[b] += h, mid[d] += h;
        constrain(mid, p0, p1);
      }
    }
  }
  return mesh;
}

std::vector<Triangle> tetMeshSurface(const TetMesh& mesh) {
  // Outward faces of a positive tetrahedron (0, 1, 2, 3).
  constexpr int kFaces[4][3] = {{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}};
  struct Face {
    std::array<std::uint32_t, 3> key;  // sorted indices
    Triangle tri;
  };
  std::vector<Face> faces;
  faces.reserve(mesh.tets.size() * 4);
  for (const Tet& t : mesh.tets)
    for (const auto& f : kFaces) {
      Face face{{t[f[0]], t[f[1]], t[f[2]]}, {t[f[0]], t[f[1]], t[f[2]]}};
      std::sort(face.key.begin(), face.key.end());
      faces.push_back(face);
    }
  std::sort(faces.begin(), faces.end(), [](const Face& a, const Face& b) { return a.key < b.key; });
  std::vector<Face> unmatched;
  for (std::size_t i = 0; i < faces.size();) {
    std::size_t j = i + 1;
    while (j < faces.size() && faces[j].key == faces[i].key) ++j;
    if (j - i == 1) unmatched.push_back(faces[i]);
    i = j;
  }
  // Coarse–fine interfaces: a fine face inside a coarse one has hanging
  // nodes whose masters, with its other nodes, are the coarse face's three
  // nodes. Both sides are interior.
  std::vector<std::uint8_t> interior(unmatched.size(), 0);
  if (!mesh.hanging.empty()) {
    std::vector<std::int32_t> entryOf(mesh.nodes.size(), -1);
    for (std::size_t k = 0; k < mesh.hanging.size(); ++k) entryOf[mesh.hanging[k].node] = std::int32_t(k);
    for (std::size_t f = 0; f < unmatched.size(); ++f) {
      std::uint32_t support[6];
      int count = 0;
      bool hangs = false;
      for (std::uint32_t v : unmatched[f].key) {
        if (const std::int32_t e = entryOf[v]; e >= 0) {
          hangs = true;
          for (std::uint32_t m : mesh.hanging[std::size_t(e)].masters) support[count++] = m;
        } else {
          support[count++] = v;
        }
      }
      if (!hangs) continue;
      for (int a = 1; a < count; ++a)  // insertion sort of at most six
        for (int b = a; b > 0 && support[b - 1] > support[b]; --b) std::swap(support[b - 1], support[b]);
      count = int(std::unique(support, support + count) - support);
      if (count != 3) continue;
      const std::array<std::uint32_t, 3> coarse{support[0], support[1], support[2]};
      const auto it = std::lower_bound(unmatched.begin(), unmatched.end(), coarse,
                                       [](const Face& a, const std::array<std::uint32_t, 3>& k) { return a.key < k; });
      if (it == unmatched.end() || it->key != coarse) continue;
      interior[f] = 1;
      interior[std::size_t(it - unmatched.begin())] = 1;
    }
  }
  std::vector<Triangle> out;
  for (std::size_t f = 0; f < unmatched.size(); ++f)
    if (!interior[f]) out.push_back(unmatched[f].tri);
  return out;
}

}  // namespace dm
