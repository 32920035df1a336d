// Sphere tree construction (octree and fitted, from meshes and voxel models),
// the stored and the implicit tree; see dm/collide/sphere_tree.hpp.
//
// Both builders work on "pieces": small point sets whose convex hulls cover
// the geometry of one cell of a grid (a triangle clipped to the cell, the
// cell's corners inside a closed mesh, the cubes of a run of occupied voxels).
// A node covers a set of pieces and its sphere is the minimal enclosing
// sphere of their points, so it contains the hull of each piece, and a
// parent's point set contains its children's.
#include <dm/collide/bvh.hpp>
#include <dm/collide/mesh_query.hpp>
#include <dm/collide/sphere_tree.hpp>
#include <dm/core/tasks.hpp>
#include <dm/math/isosurface.hpp>
#include <dm/math/mass_properties.hpp>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <deque>
#include <limits>
#include <numbers>
#include <random>
#include <string>
#include <unordered_map>

#include "surface_patch_fit.hpp"

namespace dm {

const char* toString(SphereTreeMethod method) noexcept {
  switch (method) {
    case SphereTreeMethod::Octree:
      return "octree";
    case SphereTreeMethod::Fitted:
      return "fitted";
    case SphereTreeMethod::Given:
      break;
  }
  return "given";
}

namespace {

constexpr double kPi = std::numbers::pi;
constexpr int kMaxLevels = 10;
double ballVolume(double r) { return 4.0 / 3.0 * kPi * r * r * r; }

// ------------------------------------------------- minimal enclosing ball ---

struct Ball {
  Vec3 c = Vec3::Zero();
  double r2 = -1.0;  // < 0: empty
};

// |a − b|² in plain arithmetic. The build's inner loops (Welzl's test,
// k-means) call it millions of times; the Eigen expression it replaces is
// the same code at -O2 but a chain of checked calls at the sanitizer trees'
// -O1, which made this file most of the slowest ASan tests.
inline double dist2(const Vec3& a, const Vec3& b) {
  const double *p = a.data(), *q = b.data();
  const double x = p[0] - q[0], y = p[1] - q[1], z = p[2] - q[2];
  return x * x + y * y + z * z;
}

bool inside(const Ball& b, const Vec3& p) { return dist2(p, b.c) <= b.r2 * (1.0 + 1e-10); }

Ball ballOf2(const Vec3& a, const Vec3& b) {
  const Vec3 c = 0.5 * (a + b);
  return {c, std::max((a - c).squaredNorm(), (b - c).squaredNorm())};
}

// Smallest ball with a, b, c on its boundary (the circumcircle's ball); for
// collinear points the ball of the farthest pair.
Ball ballOf3(const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 u = b - a, v = c - a;
  const Vec3 n = u.cross(v);
  const double n2 = n.squaredNorm();
  if (n2 <= 1e-24 * u.squaredNorm() * v.squaredNorm()) {
    Ball best = ballOf2(a, b);
    for (const Ball& x : {ballOf2(a, c), ballOf2(b, c)})
      if (x.r2 > best.r2) best = x;
    return best;
  }
  const Vec3 o = (u.squaredNorm() * v - v.squaredNorm() * u).cross(n) / (2.0 * n2);
  const Vec3 centre = a + o;
  return {centre,
          std::max({(a - centre).squaredNorm(), (b - centre).squaredNorm(), (c - centre).squaredNorm()})};
}

Ball ballOf4(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& d) {
  Mat3 m;
  m.row(0) = 2.0 * (b - a);
  m.row(1) = 2.0 * (c - a);
  m.row(2) = 2.0 * (d - a);
  const double scale = (b - a).squaredNorm() + (c - a).squaredNorm() + (d - a).squaredNorm();
  const double det = m.determinant();
  if (std::abs(det) > 1e-12 * std::pow(scale, 1.5)) {
    const Vec3 rhs((b - a).squaredNorm(), (c - a).squaredNorm(), (d - a).squaredNorm());
    const Vec3 centre = a + m.inverse() * rhs;
    return {centre, std::max({(a - centre).squaredNorm(), (b - centre).squaredNorm(),
                              (c - centre).squaredNorm(), (d - centre).squaredNorm()})};
  }
  // Coplanar: the smallest three-point ball that holds the fourth point.
  const std::array<Ball, 4> cand = {ballOf3(a, b, c), ballOf3(a, b, d), ballOf3(a, c, d), ballOf3(b, c, d)};
  const std::array<const Vec3*, 4> other = {&d, &c, &b, &a};
  Ball best;
  best.r2 = std::numeric_limits<double>::infinity();
  for (int i = 0; i < 4; ++i)
    if (inside(cand[i], *other[i]) && cand[i].r2 < best.r2) best = cand[i];
  if (!std::isfinite(best.r2)) best = ballOf2(a, b);  // unreachable in exact arithmetic
  return best;
}

Ball ballOfBoundary(const Vec3* r, int n) {
  switch (n) {
    case 0:
      return {};
    case 1:
      return {r[0], 0.0};
    case 2:
      return ballOf2(r[0], r[1]);
    case 3:
      return ballOf3(r[0], r[1], r[2]);
    default:
      return ballOf4(r[0], r[1], r[2], r[3]);
  }
}

// Welzl's randomized algorithm: expected O(n) on shuffled input; recursion
// depth ≤ 4 (one per boundary point).
Ball welzl(const Vec3* p, std::size_t n, Vec3* boundary, int nb) {
  Ball b = ballOfBoundary(boundary, nb);
  if (nb == 4) return b;
  for (std::size_t i = 0; i < n; ++i) {
    if (b.r2 >= 0 && inside(b, p[i])) continue;
    boundary[nb] = p[i];
    b = welzl(p, i, boundary, nb + 1);
  }
  return b;
}

// Minimal enclosing sphere of `points` (shuffled in place). The radius is
// then set to the largest distance from the centre, padded by 1e-12
// relative, so every point is inside whatever the rounding.
BoundingSphere minimalSphere(std::vector<Vec3>& points) {
  BoundingSphere s;
  if (points.empty()) return s;
  std::mt19937 rng(0x5eed);
  std::shuffle(points.begin(), points.end(), rng);
  Vec3 boundary[4];
  const Ball b = welzl(points.data(), points.size(), boundary, 0);
  double r2 = 0.0;
  for (const Vec3& q : points) r2 = std::max(r2, dist2(q, b.c));
  s.center = b.c;
  s.radius = std::sqrt(r2) * (1.0 + 1e-12);
  return s;
}

// ---------------------------------------------------------------- pieces ---

// One facet of a piece: a triangle clipped to the piece's cell, its points
// [first, first + count) of the piece's own (from start[i]).
struct PieceFacet {
  Vec3 areaVector = Vec3::Zero();
  double area = 0.0;
  Vec3 areaMoment = Vec3::Zero();
  std::uint32_t first = 0, count = 0;
};

// Pieces in CSR form: piece i has points [start[i], start[i+1]) and lies in
// cell `cell[i]` of a 2^gridLevel grid. Its surface (the triangles clipped
// to the cell; none for solid corners and voxels) has the points
// [start[i], surfaceEnd[i]), the area vector Σ area·n, the area and the
// area moment Σ area·centroid, from which the nodes' SurfacePatches are fitted.
struct Pieces {
  int gridLevel = 0;
  std::vector<Vec3> points;
  std::vector<std::uint32_t> start{0};
  std::vector<std::uint32_t> surfaceEnd;
  std::vector<Vec3i> cell;
  std::vector<Vec3> centroid;
  std::vector<double> radius;  // ball about the centroid holding the piece's points
  std::vector<Vec3> areaVector, areaMoment;
  std::vector<double> area;
  // The surface of piece i facet by facet (one clipped triangle each, for
  // the nodes' creases): facets [facetStart[i], facetStart[i + 1]).
  std::vector<std::uint32_t> facetStart{0};
  std::vector<PieceFacet> facets;
  bool anySurface = false;
  std::size_t size() const { return cell.size(); }
};

// One cell's share of a piece before merging by cell: a clipped triangle
// (surface) or solid corners and voxel cubes (no area).
struct Record {
  std::uint64_t key;
  std::uint32_t first, count;
  Vec3 areaVector = Vec3::Zero();
  double area = 0.0;
  Vec3 areaMoment = Vec3::Zero();
  bool surface = false;
};

// A surface record of the convex polygon raw[first, first + n): its area
// vector, area and area moment by a fan from the first vertex.
Record surfaceRecord(std::uint64_t key, const std::vector<Vec3>& raw, std::uint32_t first, std::uint32_t n) {
  Record r{key, first, n};
  r.surface = true;
  const Vec3& q0 = raw[first];
  for (std::uint32_t i = 1; i + 1 < n; ++i) {
    const Vec3 a = 0.5 * (raw[first + i] - q0).cross(raw[first + i + 1] - q0);
    const double an = a.norm();
    r.areaVector += a;
    r.area += an;
    r.areaMoment += an * (q0 + raw[first + i] + raw[first + i + 1]) / 3.0;
  }
  return r;
}

std::uint64_t linearKey(const Vec3i& c, int r) {
  return static_cast<std::uint64_t>(c.x()) +
         static_cast<std::uint64_t>(r) * (static_cast<std::uint64_t>(c.y()) +
                                          static_cast<std::uint64_t>(r) * static_cast<std::uint64_t>(c.z()));
}
Vec3i keyCell(std::uint64_t key, int r) {
  const auto ur = static_cast<std::uint64_t>(r);
  return {static_cast<int>(key % ur), static_cast<int>((key / ur) % ur), static_cast<int>(key / ur / ur)};
}

std::uint64_t spreadBits(std::uint64_t x) {
  std::uint64_t out = 0;
  for (int b = 0; b < 21; ++b) out |= ((x >> b) & 1u) << (3 * b);
  return out;
}
std::uint64_t morton(const Vec3i& c) {
  return spreadBits(static_cast<std::uint64_t>(c.x())) | spreadBits(static_cast<std::uint64_t>(c.y())) << 1 |
         spreadBits(static_cast<std::uint64_t>(c.z())) << 2;
}

Error tooMany(const char* where, std::size_t limit) {
  return fail(ErrorCode::InvalidArgument,
              "the sphere tree needs more than " + std::to_string(limit) + " pieces", where,
              "use fewer levels or raise SphereTreeOptions::maxPieces");
}

// Merges records of the same cell into pieces, ordered by Morton code.
Result<Pieces> mergeRecords(std::vector<Record>& records, const std::vector<Vec3>& raw, int gridLevel,
                            const char* where, std::size_t maxPieces) {
  const int r = 1 << gridLevel;
  // By cell, a cell's surface records first (their points lead the piece's).
  std::sort(records.begin(), records.end(), [](const Record& a, const Record& b) {
    return a.key != b.key ? a.key < b.key : (a.surface && !b.surface);
  });
  Pieces out;
  out.gridLevel = gridLevel;
  out.points.reserve(raw.size());
  for (std::size_t i = 0; i < records.size();) {
    const std::uint64_t key = records[i].key;
    Vec3 sum = Vec3::Zero(), areaVector = Vec3::Zero(), areaMoment = Vec3::Zero();
    double area = 0.0;
    const std::size_t first = out.points.size();
    std::size_t surfaceEnd = first;
    for (; i < records.size() && records[i].key == key; ++i) {
      const Record& rec = records[i];
      const auto at = static_cast<std::uint32_t>(out.points.size() - first);
      for (std::uint32_t k = 0; k < rec.count; ++k) out.points.push_back(raw[rec.first + k]);
      if (!rec.surface) continue;
      surfaceEnd = out.points.size();
      areaVector += rec.areaVector;
      area += rec.area;
      areaMoment += rec.areaMoment;
      out.facets.push_back({rec.areaVector, rec.area, rec.areaMoment, at, rec.count});
    }
    out.facetStart.push_back(static_cast<std::uint32_t>(out.facets.size()));
    for (std::size_t k = first; k < out.points.size(); ++k) sum += out.points[k];
    out.start.push_back(static_cast<std::uint32_t>(out.points.size()));
    out.surfaceEnd.push_back(static_cast<std::uint32_t>(surfaceEnd - first));  // a count until reordered
    out.cell.push_back(keyCell(key, r));
    out.centroid.push_back(sum / static_cast<double>(out.points.size() - first));
    out.areaVector.push_back(areaVector);
    out.area.push_back(area);
    out.areaMoment.push_back(areaMoment);
    out.anySurface = out.anySurface || area > 0.0;
    if (out.cell.size() > maxPieces) return tooMany(where, maxPieces);
  }
  // Morton order makes every octree cell a contiguous range of pieces.
  std::vector<std::uint32_t> order(out.size());
  std::vector<std::uint64_t> codes(out.size());
  for (std::size_t i = 0; i < order.size(); ++i)
    order[i] = static_cast<std::uint32_t>(i), codes[i] = morton(out.cell[i]);
  std::sort(order.begin(), order.end(),
            [&](std::uint32_t a, std::uint32_t b) { return codes[a] < codes[b]; });
  Pieces sorted;
  sorted.gridLevel = gridLevel;
  sorted.anySurface = out.anySurface;
  sorted.points.reserve(out.points.size());
  for (std::uint32_t i : order) {
    sorted.surfaceEnd.push_back(static_cast<std::uint32_t>(sorted.points.size()) + out.surfaceEnd[i]);
    sorted.points.insert(sorted.points.end(), out.points.begin() + out.start[i],
                         out.points.begin() + out.start[i + 1]);
    sorted.start.push_back(static_cast<std::uint32_t>(sorted.points.size()));
    sorted.cell.push_back(out.cell[i]);
    sorted.centroid.push_back(out.centroid[i]);
    sorted.areaVector.push_back(out.areaVector[i]);
    sorted.area.push_back(out.area[i]);
    sorted.areaMoment.push_back(out.areaMoment[i]);
    sorted.facets.insert(sorted.facets.end(), out.facets.begin() + out.facetStart[i],
                         out.facets.begin() + out.facetStart[i + 1]);
    sorted.facetStart.push_back(static_cast<std::uint32_t>(sorted.facets.size()));
  }
  sorted.radius.resize(sorted.size());
  for (std::size_t i = 0; i < sorted.size(); ++i) {
    double r2 = 0.0;
    for (std::uint32_t k = sorted.start[i]; k < sorted.start[i + 1]; ++k)
      r2 = std::max(r2, dist2(sorted.points[k], sorted.centroid[i]));
    sorted.radius[i] = std::sqrt(r2);
  }
  return sorted;
}

// Sutherland–Hodgman clip of a convex polygon to x[axis] ≥ v (keepAbove) or
// ≤ v. The cut points get exactly v on the axis, so neighbouring cells share
// their cut edges.
int clipPolygon(const Vec3* in, int n, Vec3* out, int axis, double v, bool keepAbove) {
  int m = 0;
  for (int i = 0; i < n; ++i) {
    const double* p = in[(i + n - 1) % n].data();
    const double* q = in[i].data();
    const bool pin = keepAbove ? p[axis] >= v : p[axis] <= v;
    const bool qin = keepAbove ? q[axis] >= v : q[axis] <= v;
    if (pin != qin) {
      const double t = (v - p[axis]) / (q[axis] - p[axis]);
      double* x = out[m++].data();
      for (int k = 0; k < 3; ++k) x[k] = p[k] + t * (q[k] - p[k]);
      x[axis] = v;
    }
    if (qin) out[m++] = in[i];
  }
  return m;
}

struct Grid {
  Vec3 lo = Vec3::Zero();
  Vec3 h = Vec3::Ones();  // cell size
  int r = 1;
  Vec3 corner(const Vec3i& c) const {
    return {lo.x() + c.x() * h.x(), lo.y() + c.y() * h.y(), lo.z() + c.z() * h.z()};
  }
  int cellOf(double x, int axis, double bias) const {
    const double f = std::floor((x - lo[axis]) / h[axis] + bias);
    return static_cast<int>(std::clamp(f, 0.0, static_cast<double>(r - 1)));
  }
};

Grid meshGrid(const Aabb& bounds, int gridLevel) {
  Grid g;
  const Vec3 ext = bounds.sizes();
  const double big = std::max(ext.maxCoeff(), 1e-300);
  Vec3 lo = bounds.min(), hi = bounds.max();
  for (int a = 0; a < 3; ++a) {
    const double pad = 1e-9 * big + 0.5 * std::max(0.0, 1e-6 * big - ext[a]);
    lo[a] -= pad, hi[a] += pad;
  }
  g.r = 1 << gridLevel;
  g.lo = lo;
  g.h = (hi - lo) / g.r;
  return g;
}

struct MeshSource {
  double volume = 0.0;  // enclosed volume, 0 if open
};

// Clips the triangle v to every cell of `g` it meets and calls
// emit(cell, polygon, n) with each non-empty piece (at most 9 vertices);
// false when emit returned false (stop).
template <class Emit>
bool clipToCells(const Vec3 (&v)[3], const Grid& g, Emit&& emit) {
  Vec3 bufA[16], bufB[16];
  Vec3i c0, c1;
  for (int a = 0; a < 3; ++a) {
    const double mn = std::min({v[0][a], v[1][a], v[2][a]}), mx = std::max({v[0][a], v[1][a], v[2][a]});
    c0[a] = g.cellOf(mn, a, -1e-9);
    c1[a] = g.cellOf(mx, a, 1e-9);
  }
  for (int z = c0.z(); z <= c1.z(); ++z)
    for (int y = c0.y(); y <= c1.y(); ++y)
      for (int x = c0.x(); x <= c1.x(); ++x) {
        const Vec3i c(x, y, z);
        const Vec3 lo = g.corner(c), hi = g.corner(c + Vec3i::Ones());
        int n = 3;
        std::copy(v, v + 3, bufA);
        for (int a = 0; a < 3 && n > 0; ++a) {
          n = clipPolygon(bufA, n, bufB, a, lo[a], true);
          n = n > 0 ? clipPolygon(bufB, n, bufA, a, hi[a], false) : 0;
        }
        if (n > 0 && !emit(c, bufA, n)) return false;
      }
  return true;
}

Result<Pieces> meshPieces(const Mesh& mesh, int gridLevel, const SphereTreeOptions& opt, const char* where) {
  const Grid g = meshGrid(mesh.bounds(), gridLevel);
  std::vector<Record> records;
  std::vector<Vec3> raw;
  for (const Triangle& t : mesh.triangles) {
    const Vec3 v[3] = {mesh.positions[t[0]], mesh.positions[t[1]], mesh.positions[t[2]]};
    const bool all = clipToCells(v, g, [&](const Vec3i& c, const Vec3* poly, int n) {
      const auto first = static_cast<std::uint32_t>(raw.size());
      raw.insert(raw.end(), poly, poly + n);
      records.push_back(surfaceRecord(linearKey(c, g.r), raw, first, static_cast<std::uint32_t>(n)));
      return records.size() <= opt.maxPieces;
    });
    if (!all) return tooMany(where, opt.maxPieces);
  }
  if (!opt.solid) return mergeRecords(records, raw, gridLevel, where, opt.maxPieces);

  // Solid: the corners of surface cells inside the mesh, and every cell with
  // no surface in it that is inside (one signed-distance query per connected
  // empty region, which is all inside or all outside).
  const std::size_t r = static_cast<std::size_t>(g.r);
  if (r * r * r > (std::size_t{1} << 24))
    return fail(ErrorCode::InvalidArgument,
                "a solid sphere tree of " + std::to_string(opt.levels) + " levels needs a grid of " +
                    std::to_string(r) + "³ cells",
                where, "use fewer levels (at most 9 octree, 7 fitted) for solid trees");
  auto bvh = MeshBvh::build(mesh);
  if (!bvh) return bvh.error();
  if (!bvh->isClosed())
    return fail(ErrorCode::InvalidArgument, "a solid sphere tree needs a closed mesh", where,
                "close the mesh or build a surface tree (solid = false)");
  const Isometry3 id = Isometry3::Identity();
  auto isInside = [&](const Vec3& p) { return closestPointOnMesh(*bvh, id, p).distance < 0; };
  std::vector<std::uint8_t> state(r * r * r, 0);  // 1 surface, 2 inside, 3 outside
  for (const Record& rec : records) state[rec.key] = 1;
  std::unordered_map<std::uint64_t, bool> cornerInside;
  std::vector<std::uint64_t> surfaceCells;
  for (std::size_t k = 0; k < state.size(); ++k)
    if (state[k] == 1) surfaceCells.push_back(k);
  for (std::uint64_t key : surfaceCells) {
    const Vec3i c = keyCell(key, g.r);
    const std::uint32_t first = static_cast<std::uint32_t>(raw.size());
    for (int q = 0; q < 8; ++q) {
      const Vec3i cc = c + Vec3i(q & 1, (q >> 1) & 1, (q >> 2) & 1);
      const std::uint64_t ck = linearKey(cc, g.r + 1);
      auto it = cornerInside.find(ck);
      if (it == cornerInside.end()) it = cornerInside.emplace(ck, isInside(g.corner(cc))).first;
      if (it->second) raw.push_back(g.corner(cc));
    }
    if (raw.size() > first) records.push_back({key, first, static_cast<std::uint32_t>(raw.size() - first)});
  }
  std::vector<std::uint64_t> queue;
  for (std::size_t seed = 0; seed < state.size(); ++seed) {
    if (state[seed] != 0) continue;
    const Vec3i sc = keyCell(seed, g.r);
    const std::uint8_t mark = isInside(g.corner(sc) + 0.5 * g.h) ? 2 : 3;
    queue.assign(1, seed);
    state[seed] = mark;
    while (!queue.empty()) {
      const std::uint64_t key = queue.back();
      queue.pop_back();
      const Vec3i c = keyCell(key, g.r);
      if (mark == 2) {
        const std::uint32_t first = static_cast<std::uint32_t>(raw.size());
        for (int q = 0; q < 8; ++q) raw.push_back(g.corner(c + Vec3i(q & 1, (q >> 1) & 1, (q >> 2) & 1)));
        records.push_back({key, first, 8});
        if (records.size() > opt.maxPieces) return tooMany(where, opt.maxPieces);
      }
      for (int a = 0; a < 3; ++a)
        for (int s : {-1, 1}) {
          Vec3i n = c;
          n[a] += s;
          if (n[a] < 0 || n[a] >= g.r) continue;
          const std::uint64_t nk = linearKey(n, g.r);
          if (state[nk] != 0) continue;
          state[nk] = mark;
          queue.push_back(nk);
        }
    }
  }
  return mergeRecords(records, raw, gridLevel, where, opt.maxPieces);
}

// Occupied voxels as pieces: per grid cell and voxel row (j, k), the cubes of
// the first and last qualifying voxel (the hull of a row of cubes is the hull
// of its two end cubes). Cells are over the occupied voxels' index box.
Result<Pieces> volumePieces(const Volume& vol, int gridLevel, const SphereTreeOptions& opt, const char* where,
                            double& occupiedVolume, Grid& g) {
  const Vec3i d = vol.dims();
  auto occ = [&](int i, int j, int k) { return vol.contains(i, j, k) && vol.value(i, j, k) > opt.threshold; };
  Vec3i lo = d, hi = Vec3i::Constant(-1);
  std::size_t count = 0;
  for (int k = 0; k < d.z(); ++k)
    for (int j = 0; j < d.y(); ++j)
      for (int i = 0; i < d.x(); ++i)
        if (occ(i, j, k)) {
          ++count;
          lo = lo.cwiseMin(Vec3i(i, j, k));
          hi = hi.cwiseMax(Vec3i(i, j, k));
        }
  if (count == 0)
    return fail(ErrorCode::InvalidArgument,
                "no voxel is above the threshold " + std::to_string(opt.threshold), where,
                "lower SphereTreeOptions::threshold (occupied: value > threshold)");
  occupiedVolume = static_cast<double>(count) * std::abs(vol.indexToWorld().linear().determinant());
  g.r = 1 << gridLevel;
  g.lo = lo.cast<double>() - Vec3::Constant(0.5);
  g.h = (hi - lo + Vec3i::Ones()).cast<double>() / g.r;
  const Affine3& a = vol.indexToWorld();
  std::vector<Record> records;
  std::vector<Vec3> raw;
  auto qualifies = [&](int i, int j, int k) {
    if (!occ(i, j, k)) return false;
    if (opt.solid) return true;
    return !occ(i - 1, j, k) || !occ(i + 1, j, k) || !occ(i, j - 1, k) || !occ(i, j + 1, k) ||
           !occ(i, j, k - 1) || !occ(i, j, k + 1);
  };
  auto emit = [&](int cx, int cy, int cz, int i0, int i1, int j, int k) {
    const std::uint32_t first = static_cast<std::uint32_t>(raw.size());
    for (int i : {i0, i1}) {
      for (int q = 0; q < 8; ++q)
        raw.push_back(
            a * Vec3(i + ((q & 1) ? 0.5 : -0.5), j + ((q & 2) ? 0.5 : -0.5), k + ((q & 4) ? 0.5 : -0.5)));
      if (i0 == i1) break;
    }
    records.push_back(
        {linearKey(Vec3i(cx, cy, cz), g.r), first, static_cast<std::uint32_t>(raw.size() - first)});
  };
  for (int k = lo.z(); k <= hi.z(); ++k)
    for (int j = lo.y(); j <= hi.y(); ++j) {
      const int cy = g.cellOf(j, 1, 0.0), cz = g.cellOf(k, 2, 0.0);
      int runCell = -1, i0 = 0, i1 = 0;
      for (int i = lo.x(); i <= hi.x(); ++i) {
        if (!qualifies(i, j, k)) continue;
        const int cx = g.cellOf(i, 0, 0.0);
        if (cx != runCell) {
          if (runCell >= 0) emit(runCell, cy, cz, i0, i1, j, k);
          runCell = cx, i0 = i;
        }
        i1 = i;
      }
      if (runCell >= 0) emit(runCell, cy, cz, i0, i1, j, k);
      if (records.size() > opt.maxPieces) return tooMany(where, opt.maxPieces);
    }
  return mergeRecords(records, raw, gridLevel, where, opt.maxPieces);
}

// The smooth surface of a voxel model as surface pieces indexed like its
// voxel pieces `voxels` (grid `g`, index space): the isosurface `iso`
// (world) clipped to the cells in index space, each polygon mapped back to
// the world and given to every voxel piece within a voxel of its cell. The
// isosurface crosses the edge from a surface voxel's centre to its outside
// neighbour's, up to a voxel from the centre and so often in another cell:
// without the reach such a voxel's node would hold no surface and collide
// through its sphere, which stands out of the surface by up to a voxel.
Pieces voxelSurfacePieces(const Volume& vol, const Pieces& voxels, const Grid& g, const Mesh& iso) {
  std::unordered_map<std::uint64_t, std::uint32_t> pieceOf;
  for (std::size_t k = 0; k < voxels.size(); ++k)
    pieceOf.emplace(linearKey(voxels.cell[k], g.r), static_cast<std::uint32_t>(k));
  const Affine3& toWorld = vol.indexToWorld();
  const Affine3 toIndex = toWorld.inverse();
  const Vec3i reach = g.h.cwiseInverse().array().ceil().cast<int>();  // cells per voxel, per axis
  // The pieces' grid grown by the reach on every side (the same cells): the
  // surface beside the outermost voxels lies outside the voxels' index box.
  Grid wide = g;
  const int margin = reach.maxCoeff();
  wide.r = g.r + 2 * margin;
  wide.lo = g.lo - static_cast<double>(margin) * g.h;
  std::vector<Record> records;  // key: the voxel piece
  std::vector<Vec3> raw;
  for (const Triangle& t : iso.triangles) {
    const Vec3 v[3] = {toIndex * iso.positions[t[0]], toIndex * iso.positions[t[1]],
                       toIndex * iso.positions[t[2]]};
    clipToCells(v, wide, [&](const Vec3i& wc, const Vec3* poly, int n) {
      const Vec3i c = wc - Vec3i::Constant(margin);
      std::uint32_t first = 0;
      bool stored = false;
      for (int dz = -reach.z(); dz <= reach.z(); ++dz)
        for (int dy = -reach.y(); dy <= reach.y(); ++dy)
          for (int dx = -reach.x(); dx <= reach.x(); ++dx) {
            const Vec3i nc = c + Vec3i(dx, dy, dz);
            if ((nc.array() < 0).any() || (nc.array() >= g.r).any()) continue;
            const auto it = pieceOf.find(linearKey(nc, g.r));
            if (it == pieceOf.end()) continue;
            if (!stored) {
              first = static_cast<std::uint32_t>(raw.size());
              for (int i = 0; i < n; ++i) raw.push_back(toWorld * poly[i]);
              stored = true;
            }
            records.push_back(surfaceRecord(it->second, raw, first, static_cast<std::uint32_t>(n)));
          }
      return true;
    });
  }
  std::stable_sort(records.begin(), records.end(),
                   [](const Record& a, const Record& b) { return a.key < b.key; });
  Pieces out;
  out.gridLevel = voxels.gridLevel;
  out.cell = voxels.cell;
  out.areaVector.assign(voxels.size(), Vec3::Zero());
  out.areaMoment.assign(voxels.size(), Vec3::Zero());
  out.area.assign(voxels.size(), 0.0);
  std::size_t r = 0;
  for (std::size_t k = 0; k < voxels.size(); ++k) {
    const std::size_t first = out.points.size();
    for (; r < records.size() && records[r].key == k; ++r) {
      const Record& rec = records[r];
      out.facets.push_back({rec.areaVector, rec.area, rec.areaMoment,
                            static_cast<std::uint32_t>(out.points.size() - first), rec.count});
      out.points.insert(out.points.end(), raw.begin() + rec.first, raw.begin() + rec.first + rec.count);
      out.areaVector[k] += rec.areaVector;
      out.area[k] += rec.area;
      out.areaMoment[k] += rec.areaMoment;
    }
    out.start.push_back(static_cast<std::uint32_t>(out.points.size()));
    out.surfaceEnd.push_back(out.start.back());
    out.facetStart.push_back(static_cast<std::uint32_t>(out.facets.size()));
    out.anySurface = out.anySurface || out.area[k] > 0.0;
  }
  return out;
}

// ------------------------------------------------------------- builders ---

// Nodes of a tree under construction: the pieces of node n are
// order[range[n].first .. range[n].second).
struct Build {
  std::vector<SphereTreeNode> nodes;
  std::vector<std::pair<std::uint32_t, std::uint32_t>> range;
  std::vector<std::uint32_t> order;   // the pieces of the nodes' ranges
  std::vector<SurfacePatch> patches;  // one per node when the pieces hold surface
};

void gatherPoints(const Pieces& p, const std::uint32_t* order, std::uint32_t b, std::uint32_t e,
                  std::vector<Vec3>& pts) {
  pts.clear();
  for (std::uint32_t i = b; i < e; ++i)
    pts.insert(pts.end(), p.points.begin() + p.start[order[i]], p.points.begin() + p.start[order[i] + 1]);
}

BoundingSphere sphereOfRange(const Pieces& p, const std::uint32_t* order, std::uint32_t b, std::uint32_t e,
                             std::vector<Vec3>& scratch) {
  gatherPoints(p, order, b, e, scratch);
  return minimalSphere(scratch);
}

// Computes the spheres of nodes [first, last) from their piece ranges.
void computeSpheres(Build& t, const Pieces& p, const std::vector<std::uint32_t>& order, std::size_t first,
                    std::size_t last) {
  parallelFor(first, last, 4, [&](std::size_t b, std::size_t e) {
    std::vector<Vec3> scratch;
    for (std::size_t n = b; n < e; ++n) {
      const BoundingSphere s = sphereOfRange(p, order.data(), t.range[n].first, t.range[n].second, scratch);
      t.nodes[n].center = s.center;
      t.nodes[n].radius = s.radius;
    }
  });
}

// Mesh vertices whose normal is within this angle (cos) of a node's take
// part in the node's fit: a smooth neighbourhood, not the far side of an
// edge sharper than 30° or of a thin wall.
constexpr double kFitCrease = 0.866;

// A neighbourhood holding more vertices than this is already a few
// triangles across inside the node: the node's own surface fits it.
constexpr std::size_t kMaxFitPoints = 256;

// A node of more facets than this is many triangles across: its surface
// is no crease of a few flat faces worth a contact of its own (the box's
// edge nodes hold tens; the levels above a fine mesh's leaves, thousands).
constexpr std::size_t kMaxCreaseFacets = 4096;

// The mesh's vertices with their area-weighted normals, binned on a grid of
// cell `h` and sorted by cell, so that the vertices near a point are a few
// binary searches away.
struct VertexGrid {
  double h = 1.0;
  Vec3 lo = Vec3::Zero();
  std::vector<std::uint64_t> keys;  // sorted
  std::vector<std::uint32_t> ids;   // vertex of keys[i]
  std::vector<Vec3> normal;         // per vertex, unit (zero where the faces cancel)
  static std::uint64_t pack(const Vec3i& c) {
    const auto u = [](int x) { return static_cast<std::uint64_t>(x) & 0x1fffffu; };
    return u(c.x()) | u(c.y()) << 21 | u(c.z()) << 42;
  }
  Vec3i cellOf(const Vec3& x) const { return ((x - lo) / h).array().floor().cast<int>(); }
};

VertexGrid vertexGrid(const Mesh& mesh, double h) {
  VertexGrid g;
  g.h = h;
  g.normal.assign(mesh.positions.size(), Vec3::Zero());
  for (const Triangle& t : mesh.triangles) {
    const Vec3 &a = mesh.positions[t[0]], &b = mesh.positions[t[1]], &c = mesh.positions[t[2]];
    const Vec3 n = (b - a).cross(c - a);  // twice the area vector
    for (int k = 0; k < 3; ++k) g.normal[t[k]] += n;
  }
  for (Vec3& n : g.normal) n = n.norm() > 0.0 ? Vec3(n.normalized()) : Vec3(Vec3::Zero());
  g.lo = mesh.bounds().min() - Vec3::Constant(h);
  std::vector<std::pair<std::uint64_t, std::uint32_t>> entries;
  entries.reserve(mesh.positions.size());
  for (std::size_t k = 0; k < mesh.positions.size(); ++k)
    entries.emplace_back(VertexGrid::pack(g.cellOf(mesh.positions[k])), static_cast<std::uint32_t>(k));
  std::sort(entries.begin(), entries.end());
  for (const auto& [key, id] : entries) g.keys.push_back(key), g.ids.push_back(id);
  return g;
}

// The SurfacePatch of every node (pieces with surface only). A node's
// frame, raise and deviation come from its own surface. A node smaller than
// fitRadius (which spans a few of the mesh's triangles) has its quadric
// fitted over its neighbourhood, the mesh vertices within 2·fitRadius of its
// centroid whose normals are within the crease of its own, weighted by a
// Gaussian of scale fitRadius (moving least squares: enough vertices to fix
// a quadric across anisotropic triangles, the near ones count; they lie
// on the shape the mesh samples; a facet's interior lies up to its sagitta
// inside), so that it follows the smooth shape around it rather than one
// flat facet, whose normal is up to half a facet off the shape's. A larger
// node, or one whose neighbourhood is dense, is fitted over its own surface.
// O(nodes · kMaxFitPoints).
void computePatches(Build& t, const Pieces& p, const Mesh& mesh, double fitRadius) {
  const VertexGrid grid = vertexGrid(mesh, 2.0 * fitRadius);
  t.patches.assign(t.nodes.size(), SurfacePatch{});
  parallelFor(std::size_t{0}, t.nodes.size(), 4, [&](std::size_t b, std::size_t e) {
    std::vector<Vec3> own, fit;
    std::vector<detail::Facet> facets;
    for (std::size_t n = b; n < e; ++n) {
      const auto [rb, re] = t.range[n];
      own.clear();
      fit.clear();
      Vec3 areaVector = Vec3::Zero(), areaMoment = Vec3::Zero();
      double area = 0.0;
      for (std::uint32_t i = rb; i < re; ++i) {
        const std::uint32_t k = t.order[i];
        own.insert(own.end(), p.points.begin() + p.start[k], p.points.begin() + p.surfaceEnd[k]);
        areaVector += p.areaVector[k];
        area += p.area[k];
        areaMoment += p.areaMoment[k];
      }
      if (area > 0.0 && areaVector.norm() > 1e-12 * area && t.nodes[n].radius < fitRadius) {
        const Vec3 origin = areaMoment / area, normal = areaVector.normalized();
        const Vec3i c = grid.cellOf(origin);
        for (int dz = -1; dz <= 1 && fit.size() <= kMaxFitPoints; ++dz)
          for (int dy = -1; dy <= 1; ++dy)
            for (int dx = -1; dx <= 1; ++dx) {
              const auto [kb, ke] = std::equal_range(grid.keys.begin(), grid.keys.end(),
                                                     VertexGrid::pack(c + Vec3i(dx, dy, dz)));
              for (auto it = kb; it != ke; ++it) {
                const std::uint32_t k = grid.ids[static_cast<std::size_t>(it - grid.keys.begin())];
                if (grid.normal[k].dot(normal) >= kFitCrease &&
                    (mesh.positions[k] - origin).norm() <= 2.0 * fitRadius)
                  fit.push_back(mesh.positions[k]);
              }
            }
        if (fit.size() > kMaxFitPoints) fit.clear();
      }
      t.patches[n] = detail::fitSurfacePatch(areaVector, area, areaMoment, own, fit, fitRadius);
      facets.clear();
      for (std::uint32_t i = rb; i < re && facets.size() <= kMaxCreaseFacets; ++i) {
        const std::uint32_t k = t.order[i];
        for (std::uint32_t f = p.facetStart[k]; f < p.facetStart[k + 1]; ++f) {
          const PieceFacet& pf = p.facets[f];
          facets.push_back({pf.areaVector, pf.area, pf.areaMoment,
                            std::span<const Vec3>(p.points.data() + p.start[k] + pf.first, pf.count)});
        }
      }
      if (facets.size() >= 2 && facets.size() <= kMaxCreaseFacets) detail::fitCrease(t.patches[n], facets);
    }
  });
}

std::uint64_t cellPrefix(const Pieces& p, std::uint32_t piece, int level) {
  return morton(p.cell[piece]) >> (3 * (p.gridLevel - level));
}

Build octreeBuild(const Pieces& p, int levels) {
  Build t;
  std::vector<std::uint32_t> order(p.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = static_cast<std::uint32_t>(i);
  t.nodes.push_back({});
  t.range.push_back({0, static_cast<std::uint32_t>(p.size())});
  std::size_t levelBegin = 0;
  for (int l = 0; l + 1 < levels; ++l) {
    const std::size_t levelEnd = t.nodes.size();
    for (std::size_t n = levelBegin; n < levelEnd; ++n) {
      t.nodes[n].firstChild = static_cast<std::uint32_t>(t.nodes.size());
      auto [b, e] = t.range[n];
      while (b < e) {
        const std::uint64_t prefix = cellPrefix(p, b, l + 1);
        std::uint32_t m = b;
        while (m < e && cellPrefix(p, m, l + 1) == prefix) ++m;
        SphereTreeNode child;
        child.level = static_cast<std::uint8_t>(l + 1);
        t.nodes.push_back(child);
        t.range.push_back({b, m});
        ++t.nodes[n].childCount;
        b = m;
      }
    }
    levelBegin = levelEnd;
  }
  computeSpheres(t, p, order, 0, t.nodes.size());
  t.order = std::move(order);
  return t;
}

// k-means split of the pieces order[b, e) into at most k clusters; writes the
// cluster of each piece to `label` (indexed from b) and returns the count.
struct Split {
  std::vector<int> label;
  int k = 0;
  double cost = std::numeric_limits<double>::infinity();
};

// Σ r³ of the clusters' spheres, estimated from the pieces' bounding balls
// (centre: the middle of the clusters' ball bounds), O(k·n): cheap enough to
// compare candidate partitions. The final spheres are exact (Welzl).
double splitCost(const Pieces& p, const std::uint32_t* order, std::uint32_t b, std::uint32_t e,
                 const std::vector<int>& label, int k) {
  // Two passes over the pieces, all clusters at once (a pass per cluster
  // made this the tree build's hot spot).
  std::vector<Aabb> box(static_cast<std::size_t>(k));
  for (std::uint32_t i = b; i < e; ++i) {
    const Vec3 r = Vec3::Constant(p.radius[order[i]]);
    Aabb& x = box[static_cast<std::size_t>(label[i - b])];
    x.extend(p.centroid[order[i]] - r);
    x.extend(p.centroid[order[i]] + r);
  }
  std::vector<double> radius(static_cast<std::size_t>(k), 0.0);
  for (std::uint32_t i = b; i < e; ++i) {
    const std::size_t c = static_cast<std::size_t>(label[i - b]);
    radius[c] = std::max(radius[c], (p.centroid[order[i]] - box[c].center()).norm() + p.radius[order[i]]);
  }
  double cost = 0.0;
  for (std::size_t c = 0; c < box.size(); ++c)
    if (!box[c].isEmpty()) cost += radius[c] * radius[c] * radius[c];
  return cost;
}

// Relabels clusters 0..k'-1 dropping empty ones; returns k'.
int compact(std::vector<int>& label, int k) {
  std::vector<int> map(static_cast<std::size_t>(k), -1);
  int next = 0;
  for (int& l : label) {
    if (map[static_cast<std::size_t>(l)] < 0) map[static_cast<std::size_t>(l)] = next++;
    l = map[static_cast<std::size_t>(l)];
  }
  return next;
}

Split kmeansSplit(const Pieces& p, const std::uint32_t* order, std::uint32_t b, std::uint32_t e, int k,
                  int iterations) {
  const std::size_t n = e - b;
  // The node's piece centroids, gathered once: every pass below reads them.
  std::vector<Vec3> gathered(n);
  for (std::uint32_t i = b; i < e; ++i) gathered[i - b] = p.centroid[order[i]];
  auto centroid = [&](std::uint32_t i) -> const Vec3& { return gathered[i - b]; };
  std::vector<std::vector<int>> starts;
  // Start 1: the octant split of the pieces' centroid box (when it gives ≤ k).
  Aabb box;
  for (std::uint32_t i = b; i < e; ++i) box.extend(centroid(i));
  {
    std::vector<int> label(n);
    const Vec3 mid = box.center();
    for (std::uint32_t i = b; i < e; ++i) {
      const Vec3& c = centroid(i);
      label[i - b] = (c.x() > mid.x()) | (c.y() > mid.y()) << 1 | (c.z() > mid.z()) << 2;
    }
    if (compact(label, 8) <= k) starts.push_back(std::move(label));
  }
  // Start 2: farthest-point seeds.
  {
    std::vector<Vec3> seeds{centroid(b)};
    std::vector<double> d2(n, std::numeric_limits<double>::infinity());
    while (static_cast<int>(seeds.size()) < k) {
      std::size_t far = 0;
      for (std::uint32_t i = b; i < e; ++i) {
        d2[i - b] = std::min(d2[i - b], dist2(centroid(i), seeds.back()));
        if (d2[i - b] > d2[far]) far = i - b;
      }
      if (d2[far] <= 0) break;
      seeds.push_back(centroid(b + static_cast<std::uint32_t>(far)));
    }
    std::vector<int> label(n);
    for (std::uint32_t i = b; i < e; ++i) {
      int best = 0;
      for (int s = 1; s < static_cast<int>(seeds.size()); ++s)
        if (dist2(centroid(i), seeds[static_cast<std::size_t>(s)]) <
            dist2(centroid(i), seeds[static_cast<std::size_t>(best)]))
          best = s;
      label[i - b] = best;
    }
    compact(label, static_cast<int>(seeds.size()));
    starts.push_back(std::move(label));
  }
  Split best;
  for (std::vector<int>& label : starts) {
    int kk = 1 + *std::max_element(label.begin(), label.end());
    for (int it = 0;; ++it) {
      const double cost = splitCost(p, order, b, e, label, kk);
      if (cost < best.cost) best = {label, kk, cost};
      if (it >= iterations) break;
      // Lloyd step: means, then nearest mean.
      std::vector<Vec3> mean(static_cast<std::size_t>(kk), Vec3::Zero());
      std::vector<int> count(static_cast<std::size_t>(kk), 0);
      for (std::uint32_t i = b; i < e; ++i) {
        mean[static_cast<std::size_t>(label[i - b])] += centroid(i);
        ++count[static_cast<std::size_t>(label[i - b])];
      }
      for (int c = 0; c < kk; ++c)
        mean[static_cast<std::size_t>(c)] /= std::max(1, count[static_cast<std::size_t>(c)]);
      bool changed = false;
      for (std::uint32_t i = b; i < e; ++i) {
        int nearest = 0;
        for (int c = 1; c < kk; ++c)
          if (dist2(centroid(i), mean[static_cast<std::size_t>(c)]) <
              dist2(centroid(i), mean[static_cast<std::size_t>(nearest)]))
            nearest = c;
        changed = changed || nearest != label[i - b];
        label[i - b] = nearest;
      }
      if (!changed) break;
      kk = compact(label, kk);
    }
  }
  return best;
}

// Number of non-empty octree cells of `level` (what the octree tree has).
std::size_t octreeCellCount(const Pieces& p, int level) {
  std::vector<std::uint64_t> prefix(p.size());
  for (std::size_t i = 0; i < p.size(); ++i) prefix[i] = cellPrefix(p, static_cast<std::uint32_t>(i), level);
  std::sort(prefix.begin(), prefix.end());
  return static_cast<std::size_t>(std::unique(prefix.begin(), prefix.end()) - prefix.begin());
}

// Children per node of a level so that the next level has about `target`
// nodes, as the octree tree would: shares proportional to the node's piece
// count (pieces are equal-sized cells, so this is the covered area or
// volume), each in [1, min(8, pieces)], rounded by largest remainder.
std::vector<int> childQuota(const Build& t, std::size_t begin, std::size_t end, std::size_t target) {
  const std::size_t n = end - begin;
  double total = 0.0;
  for (std::size_t i = begin; i < end; ++i) total += t.range[i].second - t.range[i].first;
  std::vector<int> k(n), cap(n);
  std::vector<double> rest(n);
  std::size_t sum = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const double pieces = t.range[begin + i].second - t.range[begin + i].first;
    cap[i] = static_cast<int>(std::min(8.0, pieces));
    const double q = static_cast<double>(target) * pieces / total;
    k[i] = std::clamp(static_cast<int>(q), 1, std::max(1, cap[i]));
    rest[i] = q - k[i];
    sum += static_cast<std::size_t>(k[i]);
  }
  std::vector<std::size_t> byRest(n);
  for (std::size_t i = 0; i < n; ++i) byRest[i] = i;
  std::sort(byRest.begin(), byRest.end(), [&](std::size_t a, std::size_t b) { return rest[a] > rest[b]; });
  for (std::size_t j = 0; j < n && sum < target; ++j)
    if (k[byRest[j]] < cap[byRest[j]]) ++k[byRest[j]], ++sum;
  return k;
}

Build fittedBuild(const Pieces& p, int levels, int iterations) {
  Build t;
  std::vector<std::uint32_t> order(p.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = static_cast<std::uint32_t>(i);
  t.nodes.push_back({});
  t.range.push_back({0, static_cast<std::uint32_t>(p.size())});
  std::size_t levelBegin = 0;
  for (int l = 0; l + 1 < levels; ++l) {
    const std::size_t levelEnd = t.nodes.size();
    // Splits of the nodes of this level are independent: compute them in
    // parallel, then append the children in node order.
    const std::vector<int> quota = childQuota(t, levelBegin, levelEnd, octreeCellCount(p, l + 1));
    std::vector<Split> splits(levelEnd - levelBegin);
    parallelFor(levelBegin, levelEnd, 1, [&](std::size_t nb, std::size_t ne) {
      for (std::size_t n = nb; n < ne; ++n) {
        const auto [b, e] = t.range[n];
        const int k = quota[n - levelBegin];
        Split& s = splits[n - levelBegin];
        if (k <= 1 || e - b <= 1) {
          s.k = 1;
          s.label.assign(e - b, 0);
        } else {
          s = kmeansSplit(p, order.data(), b, e, k, iterations);
        }
      }
    });
    // Reorder each node's pieces by cluster (labels are per position, so
    // permute through a copy) and append the children.
    std::vector<std::uint32_t> copy = order;
    for (std::size_t n = levelBegin; n < levelEnd; ++n) {
      const Split& s = splits[n - levelBegin];
      const auto [b, e] = t.range[n];
      t.nodes[n].firstChild = static_cast<std::uint32_t>(t.nodes.size());
      std::uint32_t w = b;
      for (int c = 0; c < s.k; ++c) {
        const std::uint32_t cb = w;
        for (std::uint32_t i = b; i < e; ++i)
          if (s.label[i - b] == c) order[w++] = copy[i];
        if (w == cb) continue;
        SphereTreeNode child;
        child.level = static_cast<std::uint8_t>(l + 1);
        t.nodes.push_back(child);
        t.range.push_back({cb, w});
        ++t.nodes[n].childCount;
      }
    }
    levelBegin = levelEnd;
  }
  computeSpheres(t, p, order, 0, t.nodes.size());
  t.order = std::move(order);
  return t;
}

Status checkLevels(const SphereTreeOptions& opt, const char* where) {
  if (opt.levels < 1 || opt.levels > kMaxLevels)
    return fail(ErrorCode::InvalidArgument, "levels = " + std::to_string(opt.levels) + " is outside 1..10",
                where, "pass SphereTreeOptions::levels between 1 and 10");
  return ok();
}

Result<std::shared_ptr<const SphereTree>> finish(Build&& t, double referenceVolume, SphereTreeMethod method) {
  if (!(referenceVolume > 0)) referenceVolume = ballVolume(t.nodes[0].radius);
  if (!(referenceVolume > 0)) referenceVolume = std::numeric_limits<double>::min();
  return SphereTree::fromNodes(std::move(t.nodes), std::move(t.patches), referenceVolume, method);
}

// The patches' fits reach over about two triangles (see computePatches),
// measured across them: the median of the triangles' shortest edges (the
// normals of a sliver's fan change across it, not along it).
double patchFitRadius(const Mesh& mesh) {
  std::vector<double> shortest;
  shortest.reserve(mesh.triangles.size());
  for (const Triangle& tri : mesh.triangles) {
    const Vec3 &a = mesh.positions[tri[0]], &b = mesh.positions[tri[1]], &c = mesh.positions[tri[2]];
    shortest.push_back(std::min({(b - a).norm(), (c - b).norm(), (a - c).norm()}));
  }
  if (shortest.empty()) return 1e-12;
  std::nth_element(shortest.begin(), shortest.begin() + static_cast<std::ptrdiff_t>(shortest.size() / 2),
                   shortest.end());
  return std::max(2.0 * shortest[shortest.size() / 2], 1e-12);
}

Result<std::shared_ptr<const SphereTree>> buildFromMesh(const Mesh& mesh, const SphereTreeOptions& opt,
                                                        SphereTreeMethod method, const char* where) {
  if (Status s = checkLevels(opt, where); !s) return s.error();
  if (mesh.empty())
    return fail(ErrorCode::InvalidArgument, "the mesh has no triangles", where, "pass a non-empty mesh");
  if (Status s = mesh.validate(); !s) return s.error().within(where);
  double volume = 0.0;
  if (auto mp = computeMassProperties(mesh); mp) volume = mp->volume;
  const bool fitted = method == SphereTreeMethod::Fitted;
  const int gridLevel = std::min(kMaxLevels, opt.levels - 1 + (fitted ? 2 : 0));
  auto pieces = meshPieces(mesh, gridLevel, opt, where);
  if (!pieces) return pieces.error();
  if (pieces->size() == 0)
    return fail(ErrorCode::InvalidArgument, "the mesh's triangles cover no point", where,
                "pass a valid mesh");
  Build t =
      fitted ? fittedBuild(*pieces, opt.levels, opt.fittedIterations) : octreeBuild(*pieces, opt.levels);
  if (pieces->anySurface) computePatches(t, *pieces, mesh, patchFitRadius(mesh));
  return finish(std::move(t), volume, method);
}

Result<std::shared_ptr<const SphereTree>> buildFromVolume(const Volume& vol, const SphereTreeOptions& opt,
                                                          SphereTreeMethod method, const char* where) {
  if (Status s = checkLevels(opt, where); !s) return s.error();
  if (vol.empty()) return fail(ErrorCode::InvalidArgument, "the volume is empty", where, "pass a volume");
  const bool fitted = method == SphereTreeMethod::Fitted;
  const int gridLevel = std::min(kMaxLevels, opt.levels - 1 + (fitted ? 2 : 0));
  double occupied = 0.0;
  Grid grid;
  auto pieces = volumePieces(vol, gridLevel, opt, where, occupied, grid);
  if (!pieces) return pieces.error();
  Build t =
      fitted ? fittedBuild(*pieces, opt.levels, opt.fittedIterations) : octreeBuild(*pieces, opt.levels);
  // The patches: the smooth surface the voxels sample, the isosurface at the
  // threshold (trilinear between voxel centres, closed at the grid border
  // like the occupancy), not the voxels' staircase of cube faces.
  auto iso = extractIsosurface(vol, {.iso = opt.threshold, .computeNormals = false, .closeBorders = true});
  if (!iso) return iso.error().within(where);
  const Pieces surface = voxelSurfacePieces(vol, *pieces, grid, *iso);
  if (surface.anySurface) computePatches(t, surface, *iso, patchFitRadius(*iso));
  return finish(std::move(t), occupied, method);
}

}  // namespace

// ---------------------------------------------------------- SphereTree ---

Result<std::shared_ptr<const SphereTree>> SphereTree::fromNodes(std::vector<SphereTreeNode> nodes,
                                                                double referenceVolume,
                                                                SphereTreeMethod method) {
  return fromNodes(std::move(nodes), {}, referenceVolume, method);
}

namespace {
// Why crease `c` is not a valid SurfacePatch::Crease ("" when it is).
std::string creaseProblem(const SurfacePatch::Crease& c) {
  if (c.planes == 0) return "";
  if (c.planes != 2 && c.planes != 3) return "crease.planes is neither 0, 2 nor 3";
  for (int i = 0; i < c.planes; ++i)
    if (!c.normal[i].allFinite() || std::abs(c.normal[i].norm() - 1.0) > 1e-6 || !std::isfinite(c.offset[i]))
      return "a crease plane's normal is not a unit vector or its offset is not finite";
  if (!(c.deviation >= 0) || !(c.reach >= 0) || !std::isfinite(c.deviation) || !std::isfinite(c.reach))
    return "crease.deviation or crease.reach is negative or not finite";
  return "";
}

// Why patch `p` is not a valid SurfacePatch ("" when it is).
std::string patchProblem(const SurfacePatch& p) {
  const auto unit = [](const Vec3& v) { return std::abs(v.norm() - 1.0) < 1e-6; };
  if (!p.origin.allFinite() || !p.normal.allFinite() || !p.tangentU.allFinite() || !p.tangentV.allFinite() ||
      !std::all_of(p.coeff.begin(), p.coeff.end(), [](double c) { return std::isfinite(c); }) ||
      !std::isfinite(p.halfWidth) || !std::isfinite(p.deviation) || !std::isfinite(p.coherence))
    return "a field is not finite";
  if (const std::string c = creaseProblem(p.crease); !c.empty()) return c;
  if (p.normal.isZero()) return "";  // a node without smooth surface (none, or a thin wall's crease)
  if (!unit(p.normal) || !unit(p.tangentU) || !unit(p.tangentV))
    return "normal or tangent is not a unit vector";
  if (std::abs(p.normal.dot(p.tangentU)) > 1e-6 || (p.normal.cross(p.tangentU) - p.tangentV).norm() > 1e-6)
    return "(tangentU, tangentV, normal) is not a right-handed orthonormal frame";
  if (p.halfWidth < 0 || p.deviation < 0) return "halfWidth or deviation is negative";
  if (p.coherence < 0 || p.coherence > 1) return "coherence is outside [0, 1]";
  return "";
}
}  // namespace

Result<std::shared_ptr<const SphereTree>> SphereTree::fromNodes(std::vector<SphereTreeNode> nodes,
                                                                std::vector<SurfacePatch> patches,
                                                                double referenceVolume,
                                                                SphereTreeMethod method) {
  const char* where = "dm::SphereTree::fromNodes";
  if (!patches.empty() && patches.size() != nodes.size())
    return fail(ErrorCode::InvalidArgument,
                formatString("%zu patches for %zu nodes", patches.size(), nodes.size()), where,
                "pass one SurfacePatch per node, or none");
  for (std::size_t i = 0; i < patches.size(); ++i)
    if (std::string why = patchProblem(patches[i]); !why.empty())
      return fail(ErrorCode::InvalidArgument, "patch " + std::to_string(i) + ": " + why, where,
                  "give every node a valid SurfacePatch (zero normal: no surface)");
  auto bad = [&](std::size_t i, const std::string& what) {
    return fail(ErrorCode::InvalidArgument, "node " + std::to_string(i) + ": " + what, where,
                "store the nodes breadth-first with contiguous children (see SphereTreeNode)");
  };
  if (nodes.empty()) return fail(ErrorCode::InvalidArgument, "no nodes", where, "pass at least a root");
  if (nodes.size() > (std::size_t{1} << 31)) return bad(nodes.size(), "too many nodes");
  if (!(referenceVolume > 0) || !std::isfinite(referenceVolume))
    return fail(ErrorCode::InvalidArgument, "referenceVolume must be positive and finite", where,
                "pass the source's volume in m³");
  if (nodes[0].level != 0) return bad(0, "the root's level is not 0");
  const int deepest = nodes.back().level;
  std::size_t expected = 1;
  for (std::size_t i = 0; i < nodes.size(); ++i) {
    const SphereTreeNode& n = nodes[i];
    if (!n.center.allFinite() || !std::isfinite(n.radius) || n.radius < 0)
      return bad(i, "non-finite centre or radius");
    if (i > 0 && n.level < nodes[i - 1].level) return bad(i, "levels are not breadth-first");
    if (n.childCount > 8) return bad(i, "more than 8 children");
    if ((n.childCount == 0) != (n.level == deepest))
      return bad(i, "leaves must be exactly the deepest level");
    if (n.childCount == 0) continue;
    if (n.firstChild != expected) return bad(i, "children do not follow the previous node's children");
    expected += n.childCount;
    if (expected > nodes.size()) return bad(i, "child range past the end");
    for (std::size_t c = n.firstChild; c < expected; ++c)
      if (nodes[c].level != n.level + 1) return bad(c, "level is not its parent's + 1");
  }
  if (expected != nodes.size()) return bad(expected, "node is nobody's child");

  auto tree = std::shared_ptr<SphereTree>(new SphereTree());
  tree->method_ = method;
  tree->referenceVolume_ = referenceVolume;
  for (std::size_t i = nodes.size(); i-- > 0;) {
    SphereTreeNode& n = nodes[i];
    double b = n.radius;
    for (std::uint32_t c = n.firstChild; c < n.firstChild + n.childCount; ++c)
      b = std::max(b, (nodes[c].center - n.center).norm() + nodes[c].boundRadius);
    n.boundRadius = n.childCount ? b * (1.0 + 1e-12) : n.radius;
    if (n.childCount == 0) {
      tree->bounds_.extend(n.center - Vec3::Constant(n.radius));
      tree->bounds_.extend(n.center + Vec3::Constant(n.radius));
    }
  }
  for (std::size_t i = 0; i < nodes.size(); ++i)
    if (i == 0 || nodes[i].level != nodes[i - 1].level)
      tree->levelStart_.push_back(static_cast<std::uint32_t>(i));
  tree->levelStart_.push_back(static_cast<std::uint32_t>(nodes.size()));
  tree->nodes_ = std::move(nodes);
  tree->patches_ = std::move(patches);
  return std::shared_ptr<const SphereTree>(std::move(tree));
}

std::span<const SphereTreeNode> SphereTree::level(int l) const noexcept {
  if (l < 0 || l >= levelCount()) return {};
  return {nodes_.data() + levelStart_[static_cast<std::size_t>(l)],
          nodes_.data() + levelStart_[static_cast<std::size_t>(l) + 1]};
}

int SphereTree::children(NodeId node, NodeId out[8]) const noexcept {
  const SphereTreeNode& n = nodes_[node];
  for (int c = 0; c < n.childCount; ++c) out[c] = n.firstChild + static_cast<NodeId>(c);
  return n.childCount;
}

BoundingSphere SphereTree::sphere(NodeId node) const noexcept {
  return {nodes_[node].center, nodes_[node].radius};
}

BoundingSphere SphereTree::bound(NodeId node) const noexcept {
  return {nodes_[node].center, nodes_[node].boundRadius};
}

std::vector<SphereTreeLevelStats> SphereTree::levelStats() const {
  std::vector<SphereTreeLevelStats> out;
  for (int l = 0; l < levelCount(); ++l) {
    SphereTreeLevelStats s;
    s.level = l;
    double volume = 0.0, sum = 0.0;
    for (const SphereTreeNode& n : level(l)) {
      ++s.count;
      volume += ballVolume(n.radius);
      sum += n.radius;
      s.maxRadius = std::max(s.maxRadius, n.radius);
    }
    s.tightness = volume / referenceVolume_;
    s.meanRadius = s.count ? sum / static_cast<double>(s.count) : 0.0;
    out.push_back(s);
  }
  return out;
}

Result<std::shared_ptr<const SphereTree>> buildSphereTreeOctree(const Mesh& mesh,
                                                                const SphereTreeOptions& options) {
  return buildFromMesh(mesh, options, SphereTreeMethod::Octree, "dm::buildSphereTreeOctree(mesh)");
}

Result<std::shared_ptr<const SphereTree>> buildSphereTreeFitted(const Mesh& mesh,
                                                                const SphereTreeOptions& options) {
  return buildFromMesh(mesh, options, SphereTreeMethod::Fitted, "dm::buildSphereTreeFitted(mesh)");
}

Result<std::shared_ptr<const SphereTree>> buildSphereTreeOctree(const Volume& volume,
                                                                const SphereTreeOptions& options) {
  return buildFromVolume(volume, options, SphereTreeMethod::Octree, "dm::buildSphereTreeOctree(volume)");
}

Result<std::shared_ptr<const SphereTree>> buildSphereTreeFitted(const Volume& volume,
                                                                const SphereTreeOptions& options) {
  return buildFromVolume(volume, options, SphereTreeMethod::Fitted, "dm::buildSphereTreeFitted(volume)");
}

// -------------------------------------------------- ImplicitSphereTree ---

Result<std::shared_ptr<const ImplicitSphereTree>> ImplicitSphereTree::create(const Volume& volume,
                                                                             double threshold) {
  const char* where = "dm::ImplicitSphereTree::create";
  if (volume.empty()) return fail(ErrorCode::InvalidArgument, "the volume is empty", where, "pass a volume");
  const Vec3i d = volume.dims();
  const int maxDim = d.maxCoeff();
  if (maxDim > (1 << kMaxDepth))
    return fail(ErrorCode::InvalidArgument,
                "the volume's largest dimension " + std::to_string(maxDim) + " exceeds " +
                    std::to_string(1 << kMaxDepth),
                where, "resample or crop the volume");
  int depth = 0;
  while ((1 << depth) < maxDim) ++depth;
  auto tree = std::shared_ptr<ImplicitSphereTree>(new ImplicitSphereTree());
  tree->depth_ = depth;
  tree->indexToWorld_ = volume.indexToWorld();
  // Level l has ⌈dims / 2^(D−l)⌉ cells per axis: the cells of the padded
  // cube that hold voxels at all.
  tree->bits_.resize(static_cast<std::size_t>(depth) + 1);
  for (int l = 0; l <= depth; ++l) {
    const Vec3i n = ((d - Vec3i::Ones()).array() / (1 << (depth - l))).matrix() + Vec3i::Ones();
    tree->levelDims_.push_back(n);
    const std::size_t cells =
        static_cast<std::size_t>(n.x()) * static_cast<std::size_t>(n.y()) * static_cast<std::size_t>(n.z());
    tree->bits_[static_cast<std::size_t>(l)].assign((cells + 63) / 64, 0);
  }
  auto setBit = [&](int l, int i, int j, int k) {
    const std::size_t b = tree->bitIndex(l, i, j, k);
    tree->bits_[static_cast<std::size_t>(l)][b / 64] |= std::uint64_t{1} << (b % 64);
  };
  std::size_t count = 0;
  Vec3i lo = d, hi = Vec3i::Constant(-1);
  for (int k = 0; k < d.z(); ++k)
    for (int j = 0; j < d.y(); ++j)
      for (int i = 0; i < d.x(); ++i)
        if (volume.value(i, j, k) > threshold) {
          ++count;
          lo = lo.cwiseMin(Vec3i(i, j, k));
          hi = hi.cwiseMax(Vec3i(i, j, k));
          for (int l = depth; l >= 0; --l) setBit(l, i >> (depth - l), j >> (depth - l), k >> (depth - l));
        }
  if (count == 0)
    return fail(ErrorCode::InvalidArgument, "no voxel is above the threshold " + std::to_string(threshold),
                where, "lower the threshold (occupied: value > threshold)");
  const Mat3 a = volume.indexToWorld().linear();
  double diag = 0.0;
  for (const Vec3& v : {Vec3(1, 1, 1), Vec3(1, 1, -1), Vec3(1, -1, 1), Vec3(-1, 1, 1)})
    diag = std::max(diag, (a * v).norm());
  tree->halfDiagonal_ = 0.5 * diag;
  tree->referenceVolume_ = static_cast<double>(count) * std::abs(a.determinant());
  for (const auto& level : tree->bits_) {
    std::size_t c = 0;
    for (std::uint64_t w : level) c += static_cast<std::size_t>(std::popcount(w));
    tree->occupiedCount_.push_back(c);
  }
  // Leaf spheres lie within halfDiagonal of the hull of the voxel centres.
  for (int q = 0; q < 8; ++q) {
    const Vec3 corner((q & 1) ? hi.x() : lo.x(), (q & 2) ? hi.y() : lo.y(), (q & 4) ? hi.z() : lo.z());
    const Vec3 w = volume.indexToWorld() * corner;
    tree->bounds_.extend(w - Vec3::Constant(tree->halfDiagonal_));
    tree->bounds_.extend(w + Vec3::Constant(tree->halfDiagonal_));
  }
  return std::shared_ptr<const ImplicitSphereTree>(std::move(tree));
}

BoundingSphere ImplicitSphereTree::cellSphere(int level, int i, int j, int k) const noexcept {
  const double s = std::ldexp(1.0, depth_ - level);
  const Vec3 centre = Vec3(i, j, k) * s + Vec3::Constant(0.5 * (s - 1.0));
  return {indexToWorld_ * centre, s * halfDiagonal_};
}

BoundingSphere ImplicitSphereTree::sphere(NodeId node) const noexcept {
  int l, i, j, k;
  unpack(node, l, i, j, k);
  return cellSphere(l, i, j, k);
}

int ImplicitSphereTree::children(NodeId node, NodeId out[8]) const noexcept {
  int l, i, j, k;
  unpack(node, l, i, j, k);
  if (l >= depth_) return 0;
  int n = 0;
  for (int q = 0; q < 8; ++q) {
    const int ci = 2 * i + (q & 1), cj = 2 * j + ((q >> 1) & 1), ck = 2 * k + ((q >> 2) & 1);
    if (occupied(l + 1, ci, cj, ck)) out[n++] = nodeId(l + 1, ci, cj, ck);
  }
  return n;
}

std::vector<SphereTreeLevelStats> ImplicitSphereTree::levelStats() const {
  std::vector<SphereTreeLevelStats> out;
  for (int l = 0; l <= depth_; ++l) {
    SphereTreeLevelStats s;
    s.level = l;
    s.count = occupiedCount_[static_cast<std::size_t>(l)];
    s.maxRadius = s.meanRadius = std::ldexp(1.0, depth_ - l) * halfDiagonal_;
    s.tightness = static_cast<double>(s.count) * ballVolume(s.maxRadius) / referenceVolume_;
    out.push_back(s);
  }
  return out;
}

}  // namespace dm
