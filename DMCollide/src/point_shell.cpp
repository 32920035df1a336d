// Point shells: validation, surface sampling by weighted sample elimination
// and the bounding-sphere hierarchy; see dm/collide/point_shell.hpp.
#include <dm/collide/point_shell.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <new>
#include <numeric>
#include <queue>
#include <random>
#include <string>
#include <utility>

namespace dm {

namespace {

constexpr const char* kWhere = "dm::PointShell";

std::string vecString(const Vec3& v) {
  return "(" + std::to_string(v.x()) + ", " + std::to_string(v.y()) + ", " + std::to_string(v.z()) + ")";
}

// Cell of the uniform grid used to find candidate neighbours.
struct CellEntry {
  std::array<std::int64_t, 3> cell;
  std::uint32_t index;
  bool operator<(const CellEntry& o) const noexcept { return cell < o.cell; }
};

// Weighted sample elimination (C. Yuksel, "Sample Elimination for
// Generating Poisson Disk Sample Sets", Eurographics 2015): keeps `target`
// of the candidates, removing one at a time the candidate whose neighbours
// (within 2·rmax) crowd it most. Returns the indices kept.
std::vector<std::uint32_t> eliminate(const std::vector<Vec3>& cand, std::size_t target, double area) {
  const std::size_t m = cand.size();
  std::vector<std::uint32_t> kept(m);
  std::iota(kept.begin(), kept.end(), 0u);
  if (target >= m) return kept;
  // rmax: radius of `target` disks packed hexagonally over the area; rmin
  // limits the weight near zero distance (Yuksel's β = 0.65, γ = 1.5).
  const double rmax = std::sqrt(area / (2.0 * std::sqrt(3.0) * static_cast<double>(target)));
  const double ratio = static_cast<double>(target) / static_cast<double>(m);
  const double rmin = rmax * (1.0 - std::pow(ratio, 1.5)) * 0.65;
  const double reach = 2.0 * rmax;

  Vec3 lo = cand[0];
  for (const Vec3& p : cand) lo = lo.cwiseMin(p);
  std::vector<CellEntry> cells(m);
  for (std::size_t i = 0; i < m; ++i) {
    const Vec3 c = ((cand[i] - lo) / reach).array().floor();
    cells[i] = {{static_cast<std::int64_t>(c.x()), static_cast<std::int64_t>(c.y()),
                 static_cast<std::int64_t>(c.z())},
                static_cast<std::uint32_t>(i)};
  }
  std::sort(cells.begin(), cells.end());

  // Neighbour lists (CSR) with the pairwise weights.
  std::vector<std::size_t> start(m + 1, 0);
  std::vector<std::uint32_t> nbr;
  std::vector<double> nbrWeight;
  std::vector<double> weight(m, 0.0);
  nbr.reserve(m * 24);
  nbrWeight.reserve(m * 24);
  for (std::size_t i = 0; i < m; ++i) {
    const CellEntry& me = cells[i];
    const std::uint32_t pi = me.index;
    for (std::int64_t dx = -1; dx <= 1; ++dx)
      for (std::int64_t dy = -1; dy <= 1; ++dy) {
        const CellEntry key{{me.cell[0] + dx, me.cell[1] + dy, me.cell[2] - 1}, 0};
        for (auto it = std::lower_bound(cells.begin(), cells.end(), key);
             it != cells.end() && it->cell[0] == key.cell[0] && it->cell[1] == key.cell[1] &&
             it->cell[2] <= me.cell[2] + 1;
             ++it) {
          if (it->index == pi) continue;
          const double d2 = (cand[it->index] - cand[pi]).squaredNorm();
          if (d2 >= reach * reach) continue;
          const double x = 1.0 - std::max(std::sqrt(d2), 2.0 * rmin) / reach;
          const double x2 = x * x, x4 = x2 * x2;
          const double w = x4 * x4;  // (1 − d̂/2rmax)^8
          nbr.push_back(it->index);
          nbrWeight.push_back(w);
          weight[pi] += w;
        }
      }
    start[i + 1] = nbr.size();
  }
  // CSR rows are in sorted-cell order; map point → row.
  std::vector<std::uint32_t> rowOf(m);
  for (std::size_t i = 0; i < m; ++i) rowOf[cells[i].index] = static_cast<std::uint32_t>(i);

  // Max-heap with lazy deletion: an entry is current if its weight equals
  // the point's weight and the point is alive.
  std::vector<char> alive(m, 1);
  using Entry = std::pair<double, std::uint32_t>;
  std::priority_queue<Entry> heap;
  for (std::size_t i = 0; i < m; ++i) heap.push({weight[i], static_cast<std::uint32_t>(i)});
  std::size_t count = m;
  while (count > target && !heap.empty()) {
    const auto [w, p] = heap.top();
    heap.pop();
    if (!alive[p] || w != weight[p]) continue;
    alive[p] = 0;
    --count;
    const std::uint32_t row = rowOf[p];
    for (std::size_t k = start[row]; k < start[row + 1]; ++k) {
      const std::uint32_t q = nbr[k];
      if (!alive[q]) continue;
      weight[q] -= nbrWeight[k];
      heap.push({weight[q], q});
    }
  }
  kept.clear();
  for (std::size_t i = 0; i < m; ++i)
    if (alive[i]) kept.push_back(static_cast<std::uint32_t>(i));
  return kept;
}

}  // namespace

Result<std::shared_ptr<const PointShell>> PointShell::create(std::span<const Vec3> points,
                                                             std::span<const Vec3> normals) {
  if (points.empty())
    return fail(ErrorCode::InvalidArgument, "no points", std::string(kWhere) + "::create",
                "pass at least one surface point");
  if (points.size() != normals.size())
    return fail(ErrorCode::InvalidArgument,
                std::to_string(points.size()) + " points but " + std::to_string(normals.size()) + " normals",
                std::string(kWhere) + "::create", "pass one normal per point");
  if (points.size() >= std::size_t{1} << 32)
    return fail(ErrorCode::InvalidArgument, "more than 2^32 - 1 points", std::string(kWhere) + "::create",
                "split the shell");
  std::shared_ptr<PointShell> shell(new (std::nothrow) PointShell());
  if (!shell) return fail(ErrorCode::Internal, "out of memory", std::string(kWhere) + "::create");
  shell->points_.assign(points.begin(), points.end());
  shell->normals_.resize(points.size());
  shell->original_.resize(points.size());
  for (std::size_t i = 0; i < points.size(); ++i) {
    if (!points[i].allFinite())
      return fail(ErrorCode::InvalidArgument, "point " + vecString(points[i]) + " is not finite",
                  std::string(kWhere) + "::create: points[" + std::to_string(i) + "]",
                  "remove or fix the point");
    const double len = normals[i].norm();
    if (!std::isfinite(len) || len == 0.0)
      return fail(ErrorCode::InvalidArgument,
                  "normal " + vecString(normals[i]) + (len == 0.0 ? " is zero" : " is not finite"),
                  std::string(kWhere) + "::create: normals[" + std::to_string(i) + "]",
                  "give every point a nonzero outward normal");
    shell->normals_[i] = normals[i] / len;
    shell->original_[i] = static_cast<std::uint32_t>(i);
  }
  shell->buildHierarchy();
  return std::shared_ptr<const PointShell>(std::move(shell));
}

Result<std::shared_ptr<const PointShell>> PointShell::fromMesh(const Mesh& mesh,
                                                               const PointShellOptions& options) {
  const std::string where = std::string(kWhere) + "::fromMesh";
  if (!(options.spacing > 0) || !std::isfinite(options.spacing))
    return fail(ErrorCode::InvalidArgument, "spacing " + std::to_string(options.spacing) + " m is not > 0",
                where + ": options.spacing", "pass the point spacing in metres, e.g. 0.5e-3");
  if (mesh.triangles.empty())
    return fail(ErrorCode::InvalidArgument, "mesh has no triangles", where, "pass a surface mesh");
  if (Status s = mesh.validate(); !s) return Error(s.error()).within(where);

  const std::size_t nt = mesh.triangles.size();
  std::vector<double> cumulative(nt);
  double area = 0.0;
  for (std::size_t t = 0; t < nt; ++t) {
    const Triangle& tri = mesh.triangles[t];
    const Vec3& a = mesh.positions[tri[0]];
    area += 0.5 * (mesh.positions[tri[1]] - a).cross(mesh.positions[tri[2]] - a).norm();
    cumulative[t] = area;
  }
  if (!(area > 0) || !std::isfinite(area))
    return fail(ErrorCode::InvalidArgument, "mesh has no surface area", where,
                "every triangle is degenerate; check the mesh");
  const double wanted = std::round(area / (options.spacing * options.spacing));
  if (!(wanted <= static_cast<double>(options.maxPoints)))
    return fail(ErrorCode::InvalidArgument,
                "area " + std::to_string(area) + " m² at spacing " + std::to_string(options.spacing) +
                    " m needs " + std::to_string(wanted) +
                    " points, more than maxPoints = " + std::to_string(options.maxPoints),
                where, "increase options.spacing or options.maxPoints");
  const std::size_t target = std::max<std::size_t>(1, static_cast<std::size_t>(wanted));
  const std::size_t m = target * 5;

  // Stratified area-weighted candidates: candidate c takes the triangle under
  // the area coordinate (c + u)·A/m, and a uniform point in it.
  std::mt19937_64 rng(options.seed);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  std::vector<Vec3> cand(m);
  std::vector<std::uint32_t> candTri(m);
  for (std::size_t c = 0; c < m; ++c) {
    const double s = (static_cast<double>(c) + uni(rng)) * area / static_cast<double>(m);
    std::size_t t = static_cast<std::size_t>(std::upper_bound(cumulative.begin(), cumulative.end(), s) -
                                             cumulative.begin());
    t = std::min(t, nt - 1);
    while (t > 0 && cumulative[t] == cumulative[t - 1]) --t;  // skip zero-area triangles
    const Triangle& tri = mesh.triangles[t];
    const double r1 = std::sqrt(uni(rng)), r2 = uni(rng);
    cand[c] = (1 - r1) * mesh.positions[tri[0]] + r1 * (1 - r2) * mesh.positions[tri[1]] +
              r1 * r2 * mesh.positions[tri[2]];
    candTri[c] = static_cast<std::uint32_t>(t);
  }
  const std::vector<std::uint32_t> kept = eliminate(cand, target, area);

  std::shared_ptr<PointShell> shell(new (std::nothrow) PointShell());
  if (!shell) return fail(ErrorCode::Internal, "out of memory", where);
  shell->points_.resize(kept.size());
  shell->normals_.resize(kept.size());
  shell->original_.resize(kept.size());
  for (std::size_t k = 0; k < kept.size(); ++k) {
    const std::uint32_t t = candTri[kept[k]];
    const Triangle& tri = mesh.triangles[t];
    const Vec3& a = mesh.positions[tri[0]];
    shell->points_[k] = cand[kept[k]];
    shell->normals_[k] = (mesh.positions[tri[1]] - a).cross(mesh.positions[tri[2]] - a).normalized();
    shell->original_[k] = t;
  }
  shell->areaPerPoint_ = area / static_cast<double>(kept.size());
  shell->buildHierarchy();
  return std::shared_ptr<const PointShell>(std::move(shell));
}

void PointShell::buildHierarchy() {
  const std::size_t n = points_.size();
  std::vector<std::uint32_t> perm(n);
  std::iota(perm.begin(), perm.end(), 0u);
  nodes_.clear();
  nodes_.reserve(2 * (n / kLeafSize + 1));
  nodes_.push_back({});
  struct Task {
    std::uint32_t node, begin, end;
  };
  std::vector<Task> stack{{0, 0, static_cast<std::uint32_t>(n)}};
  while (!stack.empty()) {
    const Task task = stack.back();
    stack.pop_back();
    Aabb box;
    for (std::uint32_t i = task.begin; i < task.end; ++i) box.extend(points_[perm[i]]);
    const Vec3 centre = box.center();
    double r2 = 0.0;
    for (std::uint32_t i = task.begin; i < task.end; ++i)
      r2 = std::max(r2, (points_[perm[i]] - centre).squaredNorm());
    // Rounded up so that every point tests inside despite rounding.
    const double radius = std::sqrt(r2) * (1 + 1e-12) + 1e-15;
    const std::uint32_t count = task.end - task.begin;
    if (count <= kLeafSize) {
      nodes_[task.node] = {centre, radius, task.begin, count};
      continue;
    }
    int axis = 0;
    box.sizes().maxCoeff(&axis);
    const std::uint32_t mid = task.begin + count / 2;
    std::nth_element(perm.begin() + task.begin, perm.begin() + mid, perm.begin() + task.end,
                     [&](std::uint32_t x, std::uint32_t y) { return points_[x][axis] < points_[y][axis]; });
    const auto first = static_cast<std::uint32_t>(nodes_.size());
    nodes_[task.node] = {centre, radius, first, 0};
    nodes_.push_back({});
    nodes_.push_back({});
    stack.push_back({first, task.begin, mid});
    stack.push_back({first + 1, mid, task.end});
  }
  std::vector<Vec3> p(n), nn(n);
  std::vector<std::uint32_t> orig(n);
  bounds_.setEmpty();
  for (std::size_t k = 0; k < n; ++k) {
    p[k] = points_[perm[k]];
    nn[k] = normals_[perm[k]];
    orig[k] = original_[perm[k]];
    bounds_.extend(p[k]);
  }
  points_ = std::move(p);
  normals_ = std::move(nn);
  original_ = std::move(orig);
}

}  // namespace dm
