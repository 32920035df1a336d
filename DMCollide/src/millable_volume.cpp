// MillableVolume: fractional-occupancy voxel bone edited by milling tools
// (see dm/collide/millable_volume.hpp for the model).
#include <dm/collide/millable_volume.hpp>
#include <dm/core/assert.hpp>
#include <dm/math/isosurface.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <new>
#include <set>

#include "collide_internal.hpp"

namespace dm {

namespace {

constexpr const char* kMillWhere = "MillableVolume";

std::string millVoxelName(const Vec3i& dims, std::size_t linear) {
  const auto nx = static_cast<std::size_t>(dims.x()), ny = static_cast<std::size_t>(dims.y());
  char buf[96];
  std::snprintf(buf, sizeof buf, "voxel (%zu, %zu, %zu)", linear % nx, (linear / nx) % ny,
                linear / (nx * ny));
  return buf;
}

// Cell fraction of a voxel whose centre is at signed distance s from the
// tool's surface: the partial volume of a plane through a cell of width h.
inline double millCoverage(double s, double invH) noexcept { return std::clamp(0.5 - s * invH, 0.0, 1.0); }

}  // namespace

// --- MillingTool -----------------------------------------------------------

double MillingTool::distance(const Vec3& p, Vec3& gradient) const noexcept {
  switch (kind) {
    case Kind::Sphere: {
      const double r = p.norm();
      gradient = r > 0.0 ? Vec3(p / r) : Vec3::UnitZ();
      return r - radius;
    }
    case Kind::Cylinder:
      return detail::cylinderSignedDistance(p, radius, halfLength, &gradient);
    case Kind::Box:
      return detail::boxSignedDistance(p, halfExtents, &gradient);
    case Kind::Voxels:
      return shape ? shape->distance(p, gradient) : std::numeric_limits<double>::infinity();
  }
  return std::numeric_limits<double>::infinity();
}

double MillingTool::boundingRadius() const noexcept {
  switch (kind) {
    case Kind::Sphere:
      return radius;
    case Kind::Cylinder:
      return std::hypot(radius, halfLength);
    case Kind::Box:
      return halfExtents.norm();
    case Kind::Voxels: {
      if (!shape) return 0.0;
      const Aabb b = shape->localAabb();
      return b.min().cwiseAbs().cwiseMax(b.max().cwiseAbs()).norm();
    }
  }
  return 0.0;
}

Vec3 MillingTool::boundingHalfExtents() const noexcept {
  switch (kind) {
    case Kind::Sphere:
      return Vec3::Constant(radius);
    case Kind::Cylinder:
      return Vec3(radius, radius, halfLength);
    case Kind::Box:
      return halfExtents;
    case Kind::Voxels: {
      if (!shape) return Vec3::Zero();
      const Aabb b = shape->localAabb();
      return b.min().cwiseAbs().cwiseMax(b.max().cwiseAbs());
    }
  }
  return Vec3::Zero();
}

double MillingTool::innerRadius() const noexcept {
  switch (kind) {
    case Kind::Sphere:
      return radius;
    case Kind::Cylinder:
      return std::min(radius, halfLength);
    case Kind::Box:
      return halfExtents.minCoeff();
    case Kind::Voxels:
      return shape ? std::max(0.0, -shape->distance(Vec3::Zero())) : 0.0;
  }
  return 0.0;
}

Status MillingTool::validate(std::string_view where) const {
  const std::string at(where);
  auto positive = [&](double v, const char* field) -> Status {
    if (std::isfinite(v) && v > 0.0) return ok();
    return fail(ErrorCode::InvalidArgument, formatString("%s must be finite and > 0 (got %g)", field, v),
                at + "/" + field);
  };
  switch (kind) {
    case Kind::Sphere:
      return positive(radius, "radius");
    case Kind::Cylinder:
      if (auto s = positive(radius, "radius"); !s) return s;
      return positive(halfLength, "half_length");
    case Kind::Box:
      for (int a = 0; a < 3; ++a)
        if (auto s = positive(halfExtents[a], "half_extents"); !s) return s;
      return ok();
    case Kind::Voxels:
      if (!shape)
        return fail(ErrorCode::InvalidArgument, "a voxel tool needs its shape (a VoxelModel)", at + "/shape");
      if (innerRadius() <= 0.0)
        return fail(ErrorCode::InvalidArgument, "the voxel tool's origin is outside its shape", at + "/shape",
                    "put the tool frame's origin inside the cutting part");
      return ok();
  }
  return fail(ErrorCode::InvalidArgument, "unknown tool kind", at + "/kind");
}

// --- construction ----------------------------------------------------------

Result<MillableVolume> MillableVolume::fromFraction(const Volume& v, const char* what,
                                                    double (*fraction)(double, double, double), double a,
                                                    double b, MillingMaterial material) {
  const std::string where = std::string(kMillWhere) + "::" + what;
  if (v.empty()) return fail(ErrorCode::InvalidArgument, "volume is empty (no voxels)", where + ": volume");
  MillableVolume m;
  m.dims_ = v.dims();
  m.indexToWorld_ = v.indexToWorld();
  m.worldToIndex_ = v.worldToIndex();
  const Vec3 spacing = v.spacing();
  m.h_ = spacing.minCoeff();
  m.cellVolume_ = std::abs(v.indexToWorld().linear().determinant());
  if (!(m.h_ > 0.0) || !std::isfinite(m.cellVolume_) || !(m.cellVolume_ > 0.0))
    return fail(ErrorCode::InvalidArgument, "the volume's spacing is not positive", where + ": affine");
  const std::size_t n = v.voxelCount();
  try {
    m.occupancy_.resize(n);
    m.material_.assign(n, 0);
    m.blockDims_ = Vec3i((m.dims_.x() + kBlock - 1) / kBlock, (m.dims_.y() + kBlock - 1) / kBlock,
                         (m.dims_.z() + kBlock - 1) / kBlock);
    const auto blocks = static_cast<std::size_t>(m.blockDims_.prod());
    m.blockChanged_.assign(blocks, 0);
    m.changed_.assign(blocks, 0);
  } catch (const std::bad_alloc&) {
    return fail(ErrorCode::InvalidArgument, "out of memory for the millable volume", where + ": volume",
                "3 bytes a voxel are needed; crop the volume to the bone");
  }
  for (std::size_t i = 0; i < n; ++i) {
    const double value = v.valueAt(i);
    if (!std::isfinite(value))
      return fail(ErrorCode::InvalidArgument, "voxel value is not finite",
                  where + ": " + millVoxelName(m.dims_, i));
    const double o = fraction(value, a, b);
    m.occupancy_[i] = static_cast<std::uint16_t>(std::lround(o * kFull));
  }
  if (auto s = m.setMaterials({std::move(material)}); !s) return s.error().within(where);
  return m;
}

Result<MillableVolume> MillableVolume::fromSdf(const Volume& sdf, MillingMaterial material) {
  if (sdf.empty())
    return fail(ErrorCode::InvalidArgument, "volume is empty (no voxels)",
                std::string(kMillWhere) + "::fromSdf: volume");
  const double invH = 1.0 / sdf.spacing().minCoeff();
  return fromFraction(
      sdf, "fromSdf", [](double d, double inv, double) { return millCoverage(d, inv); }, invH, 0.0,
      std::move(material));
}

Result<MillableVolume> MillableVolume::fromIntensity(const Volume& volume, double empty, double full,
                                                     MillingMaterial material) {
  if (!std::isfinite(empty) || !std::isfinite(full) || !(empty < full))
    return fail(
        ErrorCode::InvalidArgument,
        formatString("the empty intensity (%g) must be below the full one (%g), both finite", empty, full),
        std::string(kMillWhere) + "::fromIntensity: empty, full");
  return fromFraction(
      volume, "fromIntensity",
      [](double value, double lo, double hi) { return std::clamp((value - lo) / (hi - lo), 0.0, 1.0); },
      empty, full, std::move(material));
}

Status MillableVolume::setMaterials(std::vector<MillingMaterial> materials, const Volume* labels) {
  const std::string where = std::string(kMillWhere) + "::setMaterials";
  if (materials.empty() || materials.size() > 256)
    return fail(ErrorCode::InvalidArgument,
                formatString("1 to 256 materials are needed (got %zu)", materials.size()),
                where + ": materials");
  std::set<std::string> names;
  for (std::size_t m = 0; m < materials.size(); ++m) {
    const std::string at = where + ": materials[" + std::to_string(m) + "]";
    if (materials[m].name.empty())
      return fail(ErrorCode::InvalidArgument, "material has no name", at + ".name");
    if (!names.insert(materials[m].name).second)
      return fail(ErrorCode::InvalidArgument, "material name '" + materials[m].name + "' is used twice",
                  at + ".name");
    if (!std::isfinite(materials[m].hardness) || !(materials[m].hardness > 0.0))
      return fail(ErrorCode::InvalidArgument,
                  formatString("hardness must be finite and > 0 Pa (got %g)", materials[m].hardness),
                  at + ".hardness");
  }
  std::vector<std::uint8_t> assigned;
  if (labels) {
    if (labels->dims() != dims_)
      return fail(ErrorCode::InvalidArgument,
                  formatString("label volume is %dx%dx%d, the bone %dx%dx%d", labels->dims().x(),
                               labels->dims().y(), labels->dims().z(), dims_.x(), dims_.y(), dims_.z()),
                  where + ": labels");
    assigned.resize(material_.size());
    for (std::size_t i = 0; i < assigned.size(); ++i) {
      const double l = labels->valueAt(i);
      if (!(l >= 0.0) || l != std::floor(l) || l >= static_cast<double>(materials.size()))
        return fail(ErrorCode::InvalidArgument,
                    formatString("label %g is not a material index (0..%zu)", l, materials.size() - 1),
                    where + ": labels " + millVoxelName(dims_, i));
      assigned[i] = static_cast<std::uint8_t>(l);
    }
  }
  materials_ = std::move(materials);
  hardness_.resize(materials_.size());
  for (std::size_t m = 0; m < materials_.size(); ++m) hardness_[m] = materials_[m].hardness;
  removed_.assign(materials_.size(), 0.0);
  if (labels)
    material_ = std::move(assigned);
  else
    std::fill(material_.begin(), material_.end(), std::uint8_t{0});
  return ok();
}

// --- queries ---------------------------------------------------------------

double MillableVolume::occupancy(int i, int j, int k) const noexcept {
  if (i < 0 || j < 0 || k < 0 || i >= dims_.x() || j >= dims_.y() || k >= dims_.z()) return 0.0;
  return occupancy_[index(i, j, k)] / static_cast<double>(kFull);
}

int MillableVolume::material(int i, int j, int k) const noexcept {
  if (i < 0 || j < 0 || k < 0 || i >= dims_.x() || j >= dims_.y() || k >= dims_.z()) return 0;
  return material_[index(i, j, k)];
}

double MillableVolume::materialVolume() const noexcept {
  double sum = 0.0;
  for (std::uint16_t o : occupancy_) sum += o;
  return sum / kFull * cellVolume_;
}

double MillableVolume::removedVolume(std::size_t m) const noexcept {
  return m < removed_.size() ? removed_[m] : 0.0;
}

MillableVolume::Box MillableVolume::toolBox(const MillingTool& tool, const Isometry3& pose,
                                            double grow) const noexcept {
  const double margin = grow + 0.5 * h_;
  const double reach = tool.boundingRadius() + margin;
  const Vec3 centre = worldToIndex_ * pose.translation();
  const Mat3& a = worldToIndex_.linear();
  Box b{};
  b.reach = reach;
  b.slab = tool.boundingHalfExtents() + Vec3::Constant(margin);
  b.slabs = tool.kind != MillingTool::Kind::Sphere;
  // The tool's oriented box in index space: its extent on each index axis.
  const Mat3 toolToIndex = a * pose.linear();
  int* lo[3] = {&b.i0, &b.j0, &b.k0};
  int* hi[3] = {&b.i1, &b.j1, &b.k1};
  for (int axis = 0; axis < 3; ++axis) {
    const double e = std::min(reach * a.row(axis).norm(), toolToIndex.row(axis).cwiseAbs().dot(b.slab));
    const double l = std::ceil(centre[axis] - e), u = std::floor(centre[axis] + e);
    // Clamp in double first: a far-away or non-finite pose gives an empty box.
    *lo[axis] =
        static_cast<int>(std::clamp(std::isfinite(l) ? l : 1e9, 0.0, static_cast<double>(dims_[axis])));
    *hi[axis] =
        static_cast<int>(std::clamp(std::isfinite(u) ? u : -1e9, -1.0, static_cast<double>(dims_[axis] - 1)));
  }
  return b;
}

namespace {

// Visits the occupied voxels of `box`, handing each its linear index, its
// occupancy and its centre in the tool frame.
// ⌈x⌉ and ⌊x⌋ of a value clamped to [lo − 1, hi + 1] (no libm call: the
// baseline x86-64 has no rounding instruction, and these run per row).
inline int millCeil(double x, int lo, int hi) noexcept {
  x = std::min<double>(std::max<double>(x, lo - 1), hi + 1);
  const int t = static_cast<int>(x);
  return t + (t < x ? 1 : 0);
}
inline int millFloor(double x, int lo, int hi) noexcept {
  x = std::min<double>(std::max<double>(x, lo - 1), hi + 1);
  const int t = static_cast<int>(x);
  return t - (t > x ? 1 : 0);
}

// The cells i ∈ [lo, hi] of a row whose centres base + i·cx lie within r of
// the tool's origin: |base + i·cx|² ≤ r², with b = base·cx, c2 = |base|²,
// a = |cx|². False when none.
inline bool millChord(double a, double invA, double b, double c2, double r, int lo, int hi, int& i0,
                      int& i1) noexcept {
  const double disc = b * b - a * (c2 - r * r);
  if (!(disc >= 0.0) || !(r > 0.0)) return false;
  const double root = std::sqrt(disc);
  i0 = std::max(lo, millCeil((-b - root) * invA, lo, hi));
  i1 = std::min(hi, millFloor((-b + root) * invA, lo, hi));
  return i0 <= i1;
}

// Clips the cells [i0, i1] of a row, centres base + i·cx in the tool frame,
// to the tool's oriented box |·| ≤ slab on each tool axis. False when none.
inline bool millSlabs(const Vec3& base, const Vec3& cx, const Vec3& slab, int& i0, int& i1) noexcept {
  for (int axis = 0; axis < 3; ++axis) {
    const double c = cx[axis], p = base[axis], e = slab[axis];
    if (std::abs(c) < 1e-12) {
      if (std::abs(p) > e) return false;
      continue;
    }
    const double inv = 1.0 / c;
    double lo = (-e - p) * inv, hi = (e - p) * inv;
    if (lo > hi) std::swap(lo, hi);
    i0 = std::max(i0, millCeil(lo, i0, i1));
    i1 = std::min(i1, millFloor(hi, i0, i1));
    if (i0 > i1) return false;
  }
  return true;
}

// The fraction K of a cell that the tool covers, at the cell centre's
// tool-frame position; spheres (the common burr) without a square root
// outside their one-voxel shell.
class ToolCoverage {
 public:
  ToolCoverage(const MillingTool& tool, double h) noexcept : tool_(tool), invH_(1.0 / h) {
    const double outer = tool.radius + 0.5 * h, inner = std::max(0.0, tool.radius - 0.5 * h);
    outer2_ = outer * outer;
    inner2_ = inner * inner;
  }
  double operator()(const Vec3& p) const noexcept {
    if (tool_.kind == MillingTool::Kind::Sphere) {
      const double r2 = p.squaredNorm();
      if (r2 >= outer2_) return 0.0;
      if (r2 <= inner2_) return 1.0;
      return millCoverage(std::sqrt(r2) - tool_.radius, invH_);
    }
    Vec3 g;
    return millCoverage(tool_.distance(p, g), invH_);
  }

 private:
  const MillingTool& tool_;
  double invH_, outer2_ = 0.0, inner2_ = 0.0;
};

template <class Box, class F>
void forOccupiedCells(const Box& box, const Affine3& indexToTool, const Vec3i& dims,
                      const std::vector<std::uint16_t>& occupancy, F&& f) noexcept {
  // Only the cells whose centres lie in the ball of radius box.reach about
  // the tool's origin, and in its oriented box, can be covered: each row is
  // clipped to its chord, |base + i·cx|² ≤ reach² solved for i, and to the
  // box's slabs (a long burr's box holds a tenth of its ball).
  const Vec3 cx = indexToTool.linear().col(0), cy = indexToTool.linear().col(1),
             cz = indexToTool.linear().col(2);
  const Vec3 origin = indexToTool.translation();
  const double a = cx.squaredNorm(), invA = 1.0 / a;
  const auto nx = static_cast<std::size_t>(dims.x()), nxy = nx * static_cast<std::size_t>(dims.y());
  for (int k = box.k0; k <= box.k1; ++k)
    for (int j = box.j0; j <= box.j1; ++j) {
      const Vec3 base = origin + static_cast<double>(j) * cy + static_cast<double>(k) * cz;
      int i0 = 0, i1 = -1;
      if (!millChord(a, invA, base.dot(cx), base.squaredNorm(), box.reach, box.i0, box.i1, i0, i1)) continue;
      if (box.slabs && !millSlabs(base, cx, box.slab, i0, i1)) continue;
      const std::size_t row = static_cast<std::size_t>(j) * nx + static_cast<std::size_t>(k) * nxy;
      for (int i = i0; i <= i1; ++i) {
        const std::size_t v = row + static_cast<std::size_t>(i);
        const std::uint16_t o = occupancy[v];
        if (o == 0) continue;
        f(v, o, Vec3(base + static_cast<double>(i) * cx), i, j, k);
      }
    }
}

}  // namespace

namespace {

// overlap() of a sphere of `radius` about the tool frame's origin: on each
// row the cells deeper than half a voxel inside are covered whole (K = 1,
// r = o: an integer sum), only the one-voxel shell needs a square root.
double sphereOverlap(const MillableVolume::Box& box, const Affine3& indexToTool, const Vec3i& dims,
                     const std::vector<std::uint16_t>& occupancy, double radius, double h) noexcept {
  const Vec3 cx = indexToTool.linear().col(0), cy = indexToTool.linear().col(1),
             cz = indexToTool.linear().col(2);
  const Vec3 origin = indexToTool.translation();
  const double a = cx.squaredNorm(), invA = 1.0 / a, invH = 1.0 / h, invFull = 1.0 / MillableVolume::kFull;
  const double outer = box.reach, inner = radius - 0.5 * h;
  const auto nx = static_cast<std::size_t>(dims.x()), nxy = nx * static_cast<std::size_t>(dims.y());
  std::uint64_t whole = 0;  // Σ o over the covered cells, in 1/kFull
  double shell = 0.0;
  for (int k = box.k0; k <= box.k1; ++k)
    for (int j = box.j0; j <= box.j1; ++j) {
      const Vec3 base = origin + static_cast<double>(j) * cy + static_cast<double>(k) * cz;
      const double b = base.dot(cx), c2 = base.squaredNorm();
      int i0 = 0, i1 = -1;
      if (!millChord(a, invA, b, c2, outer, box.i0, box.i1, i0, i1)) continue;
      int w0 = i1 + 1, w1 = i1;  // the covered run, empty unless the inner chord exists
      if (!millChord(a, invA, b, c2, inner, i0, i1, w0, w1)) w0 = i1 + 1, w1 = i1;
      const std::uint16_t* row =
          occupancy.data() + static_cast<std::size_t>(j) * nx + static_cast<std::size_t>(k) * nxy;
      auto edge = [&](int from, int to) {
        for (int i = from; i <= to; ++i) {
          const std::uint16_t o = row[i];
          if (o == 0) continue;
          const double r = (base + static_cast<double>(i) * cx).norm();
          shell += std::max(0.0, o * invFull + std::clamp(0.5 - (r - radius) * invH, 0.0, 1.0) - 1.0);
        }
      };
      edge(i0, std::min(i1, w0 - 1));
      for (int i = w0; i <= w1; ++i) whole += row[i];
      edge(std::max(i0, w1 + 1), i1);
    }
  return shell + static_cast<double>(whole) * invFull;
}

}  // namespace

double MillableVolume::overlap(const MillingTool& tool, const Isometry3& pose) const noexcept {
  if (occupancy_.empty()) return 0.0;
  const Box box = toolBox(tool, pose, 0.0);
  const Affine3 indexToTool = pose.inverse() * indexToWorld_;
  if (tool.kind == MillingTool::Kind::Sphere)
    return sphereOverlap(box, indexToTool, dims_, occupancy_, tool.radius, h_) * cellVolume_;
  const ToolCoverage cover(tool, h_);
  const double invFull = 1.0 / kFull;
  double sum = 0.0;
  forOccupiedCells(box, indexToTool, dims_, occupancy_,
                   [&](std::size_t, std::uint16_t o, const Vec3& p, int, int, int) {
                     const double k = cover(p);
                     sum += std::max(0.0, o * invFull + k - 1.0);
                   });
  return sum * cellVolume_;
}

Vec3 MillableVolume::contactNormal(const MillingTool& tool, const Isometry3& pose,
                                   double margin) const noexcept {
  if (occupancy_.empty() || !(margin >= 0.0)) return Vec3::Zero();
  const Box box = toolBox(tool, pose, margin);
  const Affine3 indexToTool = pose.inverse() * indexToWorld_;
  const double invH = 1.0 / h_, invFull = 1.0 / kFull;
  Vec3 sum = Vec3::Zero();
  if (tool.kind == MillingTool::Kind::Sphere) {
    // The gradient is p/r: no call, one square root.
    const double grown = tool.radius + margin;
    forOccupiedCells(box, indexToTool, dims_, occupancy_,
                     [&](std::size_t, std::uint16_t o, const Vec3& p, int, int, int) {
                       const double r = p.norm();
                       const double w = o * invFull * millCoverage(r - grown, invH);
                       if (w > 0.0 && r > 0.0) sum += (w / r) * p;
                     });
  } else {
    forOccupiedCells(box, indexToTool, dims_, occupancy_,
                     [&](std::size_t, std::uint16_t o, const Vec3& p, int, int, int) {
                       Vec3 g;
                       const double w = o * invFull * millCoverage(tool.distance(p, g) - margin, invH);
                       if (w > 0.0) sum += w * g;
                     });
  }
  const double n = sum.norm();
  if (!(n > 0.0) || !std::isfinite(n)) return Vec3::Zero();
  return pose.linear() * (-sum / n);
}

void MillableVolume::markChanged(int i, int j, int k) noexcept {
  // A voxel on a block's low face is also the last layer of the piece of the
  // block below it on that axis (blockSurfaces closes each seam with the next
  // block's first layer), so that piece changes too.
  const int bi = i / kBlock, bj = j / kBlock, bk = k / kBlock;
  const int li = bi > 0 && i % kBlock == 0 ? 1 : 0;
  const int lj = bj > 0 && j % kBlock == 0 ? 1 : 0;
  const int lk = bk > 0 && k % kBlock == 0 ? 1 : 0;
  for (int dk = 0; dk <= lk; ++dk)
    for (int dj = 0; dj <= lj; ++dj)
      for (int di = 0; di <= li; ++di) {
        const auto b = static_cast<std::size_t>(bi - di) +
                       static_cast<std::size_t>(blockDims_.x()) *
                           (static_cast<std::size_t>(bj - dj) +
                            static_cast<std::size_t>(blockDims_.y()) * static_cast<std::size_t>(bk - dk));
        if (blockChanged_[b]) continue;
        blockChanged_[b] = 1;
        DM_ASSERT(changedCount_ < changed_.size(), "a block is listed once");
        changed_[changedCount_++] = static_cast<std::uint32_t>(b);
      }
}

void MillableVolume::clearChanges() noexcept {
  for (std::size_t c = 0; c < changedCount_; ++c) blockChanged_[changed_[c]] = 0;
  changedCount_ = 0;
}

MillResult MillableVolume::mill(const MillingTool& tool, const Isometry3& pose, double work) noexcept {
  MillResult out;
  if (occupancy_.empty() || !std::isfinite(work) || !(work > 0.0)) return out;
  const Box box = toolBox(tool, pose, 0.0);
  const Affine3 indexToTool = pose.inverse() * indexToWorld_;
  const ToolCoverage cover(tool, h_);
  const double invFull = 1.0 / kFull;
  // Pass 1: the overlap Σr that shares the force.
  double total = 0.0;
  forOccupiedCells(box, indexToTool, dims_, occupancy_,
                   [&](std::size_t, std::uint16_t o, const Vec3& p, int, int, int) {
                     total += std::max(0.0, o * invFull + cover(p) - 1.0);
                   });
  if (!(total > 0.0)) return out;
  // Pass 2: Archard per cell, ΔV = W·(r/Σr)/H, capped at the overlap r.
  const double perOverlap = work / (total * cellVolume_);  // ΔV/cell volume per unit r per Pa
  forOccupiedCells(box, indexToTool, dims_, occupancy_,
                   [&](std::size_t v, std::uint16_t o, const Vec3& p, int i, int j, int k) {
                     const double r = o * invFull + cover(p) - 1.0;
                     if (!(r > 0.0)) return;
                     const std::uint8_t m = material_[v];
                     const double take = std::min(r, r * perOverlap / hardness_[m]);
                     const double next = std::max(0.0, o * invFull - take);
                     const auto q = static_cast<std::uint16_t>(std::lround(next * kFull));
                     if (q >= o) return;
                     const double dv = (o - q) * invFull * cellVolume_;
                     occupancy_[v] = q;
                     removed_[m] += dv;
                     out.removed += dv;
                     if (materials_[m].forbidden) out.removedForbidden += dv;
                     ++out.voxels;
                     markChanged(i, j, k);
                   });
  return out;
}

bool MillableVolume::blockRange(std::uint32_t b, Vec3i& lo, Vec3i& n) const noexcept {
  if (static_cast<std::size_t>(b) >= blockChanged_.size()) return false;
  const auto nx = static_cast<std::uint32_t>(blockDims_.x()), ny = static_cast<std::uint32_t>(blockDims_.y());
  lo = Vec3i(static_cast<int>(b % nx), static_cast<int>((b / nx) % ny), static_cast<int>(b / (nx * ny))) *
       kBlock;
  n = (dims_ - lo).cwiseMin(kBlock);
  return true;
}

bool MillableVolume::readBlock(std::uint32_t b, std::span<std::uint16_t, kBlockVoxels> out) const noexcept {
  Vec3i lo, n;
  if (!blockRange(b, lo, n)) return false;
  std::fill(out.begin(), out.end(), std::uint16_t{0});
  for (int k = 0; k < n.z(); ++k)
    for (int j = 0; j < n.y(); ++j) {
      const std::uint16_t* row = &occupancy_[index(lo.x(), lo.y() + j, lo.z() + k)];
      std::copy(row, row + n.x(), &out[static_cast<std::size_t>(kBlock * (j + kBlock * k))]);
    }
  return true;
}

bool MillableVolume::writeBlock(std::uint32_t b, std::span<const std::uint16_t, kBlockVoxels> in) noexcept {
  Vec3i lo, n;
  if (!blockRange(b, lo, n)) return false;
  for (int k = 0; k < n.z(); ++k)
    for (int j = 0; j < n.y(); ++j)
      for (int i = 0; i < n.x(); ++i) {
        std::uint16_t& o = occupancy_[index(lo.x() + i, lo.y() + j, lo.z() + k)];
        const std::uint16_t v = in[static_cast<std::size_t>(i + kBlock * (j + kBlock * k))];
        if (o == v) continue;
        o = v;
        markChanged(lo.x() + i, lo.y() + j, lo.z() + k);
      }
  return true;
}

// --- surfaces --------------------------------------------------------------

void MillableVolume::colorByMaterial(Mesh& mesh, std::span<const Vec4f> materialColors) const {
  mesh.colors.resize(mesh.positions.size());
  for (std::size_t v = 0; v < mesh.positions.size(); ++v) {
    // The vertex lies on an edge of its cell between an inside and an
    // outside voxel: the cell's fullest voxel is the material it shows.
    const Vec3 x = worldToIndex_ * mesh.positions[v];
    const int i0 = millFloor(x.x(), -1, dims_.x()), j0 = millFloor(x.y(), -1, dims_.y()),
              k0 = millFloor(x.z(), -1, dims_.z());
    int best = 0;
    std::uint16_t fullest = 0;
    for (int c = 0; c < 8; ++c) {
      const int i = i0 + (c & 1), j = j0 + ((c >> 1) & 1), k = k0 + (c >> 2);
      if (i < 0 || j < 0 || k < 0 || i >= dims_.x() || j >= dims_.y() || k >= dims_.z()) continue;
      const std::size_t n = index(i, j, k);
      if (occupancy_[n] > fullest) {
        fullest = occupancy_[n];
        best = material_[n];
      }
    }
    mesh.colors[v] = materialColors[static_cast<std::size_t>(best)];
  }
}

// --- fragments -------------------------------------------------------------

Result<FragmentMap> MillableVolume::fragments() const {
  const std::string where = std::string(kMillWhere) + "::fragments";
  constexpr std::uint16_t kHalf = kFull / 2 + 1;  // o ≥ 0.5
  FragmentMap map;
  auto labels = Volume::create(dims_, VoxelType::U32, indexToWorld_);
  if (!labels) return labels.error().within(where);
  std::uint32_t* label = labels->data<std::uint32_t>();
  std::vector<std::size_t> queue;
  std::vector<BoneFragment> found;
  const auto nx = static_cast<std::size_t>(dims_.x()), ny = static_cast<std::size_t>(dims_.y());
  const auto nz = static_cast<std::size_t>(dims_.z());
  const Mat3 cellOwn = indexToWorld_.linear() * indexToWorld_.linear().transpose() / 12.0;
  try {
    for (std::size_t seed = 0; seed < occupancy_.size(); ++seed) {
      if (occupancy_[seed] < kHalf || label[seed] != 0) continue;
      const auto id = static_cast<std::uint32_t>(found.size() + 1);
      BoneFragment f;
      f.lo = Vec3i::Constant(std::numeric_limits<int>::max());
      f.hi = Vec3i::Constant(-1);
      double mass = 0.0;
      Vec3 first = Vec3::Zero();
      Mat3 second = Mat3::Zero();
      const Vec3 origin =
          indexToWorld_ * Vec3(static_cast<double>(seed % nx), static_cast<double>((seed / nx) % ny),
                               static_cast<double>(seed / (nx * ny)));
      queue.clear();
      queue.push_back(seed);
      label[seed] = id;
      for (std::size_t head = 0; head < queue.size(); ++head) {
        const std::size_t v = queue[head];
        const std::size_t i = v % nx, j = (v / nx) % ny, k = v / (nx * ny);
        const Vec3i ijk(static_cast<int>(i), static_cast<int>(j), static_cast<int>(k));
        f.lo = f.lo.cwiseMin(ijk);
        f.hi = f.hi.cwiseMax(ijk);
        const double m = occupancy_[v] * (1.0 / kFull);
        const Vec3 r = indexToWorld_ * ijk.cast<double>() - origin;  // about the seed: no cancellation
        mass += m;
        first += m * r;
        second += m * r * r.transpose();
        ++f.cells;
        auto visit = [&](std::size_t w) {
          if (occupancy_[w] >= kHalf && label[w] == 0) {
            label[w] = id;
            queue.push_back(w);
          }
        };
        if (i > 0) visit(v - 1);
        if (i + 1 < nx) visit(v + 1);
        if (j > 0) visit(v - nx);
        if (j + 1 < ny) visit(v + nx);
        if (k > 0) visit(v - nx * ny);
        if (k + 1 < nz) visit(v + nx * ny);
      }
      const Vec3 mean = first / mass;
      // Covariance of the centres, Σ m (r − r̄)(r − r̄)ᵀ / Σ m, plus each
      // cell's own (a parallelepiped of edges A: A·Aᵀ/12).
      const Mat3 cov = second / mass - mean * mean.transpose() + cellOwn;
      f.volume = mass * cellVolume_;
      f.centroid = origin + mean;
      f.inertia = f.volume * (cov.trace() * Mat3::Identity() - cov);
      found.push_back(f);
    }
  } catch (const std::bad_alloc&) {
    return fail(ErrorCode::InvalidArgument, "out of memory while labelling fragments", where);
  }
  // Largest first, labels renumbered to match.
  std::vector<std::uint32_t> order(found.size());
  for (std::uint32_t f = 0; f < order.size(); ++f) order[f] = f;
  std::stable_sort(order.begin(), order.end(),
                   [&found](std::uint32_t x, std::uint32_t y) { return found[x].volume > found[y].volume; });
  std::vector<std::uint32_t> rank(found.size() + 1, 0);
  map.fragments.reserve(found.size());
  for (std::uint32_t r = 0; r < order.size(); ++r) {
    rank[order[r] + 1] = r + 1;
    map.fragments.push_back(found[order[r]]);
  }
  for (std::size_t v = 0; v < occupancy_.size(); ++v) label[v] = rank[label[v]];
  map.labels = std::move(*labels);
  return map;
}

Result<Volume> MillableVolume::fragmentOccupancy(const FragmentMap& map, std::size_t k) const {
  const std::string where = std::string(kMillWhere) + "::fragmentOccupancy";
  if (k >= map.fragments.size())
    return fail(ErrorCode::InvalidArgument,
                formatString("fragment %zu of %zu does not exist", k, map.fragments.size()), where);
  if (map.labels.dims() != dims_ || map.labels.type() != VoxelType::U32)
    return fail(ErrorCode::InvalidArgument, "the fragment map is not of this volume", where);
  const BoneFragment& f = map.fragments[k];
  const Vec3i lo = f.lo - Vec3i::Ones(), n = f.hi - f.lo + Vec3i::Constant(3);
  Affine3 a = indexToWorld_;
  a.translation() = indexToWorld_ * lo.cast<double>();
  auto v = Volume::create(n, VoxelType::F32, a);
  if (!v) return v.error().within(where);
  const std::uint32_t* label = map.labels.data<std::uint32_t>();
  const auto id = static_cast<std::uint32_t>(k + 1);
  float* out = v->data<float>();
  for (int z = 0; z < n.z(); ++z)
    for (int y = 0; y < n.y(); ++y)
      for (int x = 0; x < n.x(); ++x) {
        const int i = lo.x() + x, j = lo.y() + y, kk = lo.z() + z;
        const bool inside = i >= 0 && j >= 0 && kk >= 0 && i < dims_.x() && j < dims_.y() && kk < dims_.z();
        *out++ = inside && label[index(i, j, kk)] == id ? static_cast<float>(occupancy(i, j, kk)) : 0.0f;
      }
  return v;
}

Result<Volume> MillableVolume::forbiddenMask() const {
  auto v = Volume::create(dims_, VoxelType::U8, indexToWorld_);
  if (!v) return v.error().within(std::string(kMillWhere) + "::forbiddenMask");
  std::uint8_t* out = v->data<std::uint8_t>();
  for (std::size_t i = 0; i < occupancy_.size(); ++i)
    out[i] = materials_[material_[i]].forbidden && occupancy_[i] >= kFull / 2 + 1 ? 1 : 0;
  return v;
}

Result<Volume> MillableVolume::occupancyVolume() const {
  auto v = Volume::create(dims_, VoxelType::F32, indexToWorld_);
  if (!v) return v.error().within(std::string(kMillWhere) + "::occupancyVolume");
  float* out = v->data<float>();
  for (std::size_t i = 0; i < occupancy_.size(); ++i)
    out[i] = static_cast<float>(occupancy_[i] * (1.0 / kFull));
  return v;
}

namespace {

// Outward unit normal of the occupancy at world point p: minus the gradient
// of the occupancy smoothed by an isotropic Gaussian (σ = 0.7 of the largest
// spacing, cut at 2.9σ: 0.2 % of its mass), as the sum of the voxels'
// values times the Gaussian's derivative. Smoothing a field that varies
// along n only keeps its gradient along n, so a plane's normal is exact
// whatever the ramp's clamping and slope (a CT read with "full" below its
// cortical value is steeper); central differences of the clamped one-voxel
// ramp tilt it by up to 17° where the surface crosses voxel layers — rings
// on a skull (Tests/DMCollide/millable_volume_test.cpp). Zero where the
// smoothed field is flat.
class SmoothedNormal {
 public:
  explicit SmoothedNormal(const MillableVolume& v) : v_(v) {
    const Mat3 l = v.indexToWorld().linear();
    const Vec3 spacing(l.col(0).norm(), l.col(1).norm(), l.col(2).norm());
    for (int a = 0; a < 3; ++a) {
      sigma_[a] = 0.7 * spacing.maxCoeff() / spacing[a];  // in voxels along axis a
      reach_[a] = std::min(kMaxReach, static_cast<int>(std::ceil(2.9 * sigma_[a])));
    }
    toWorld_ = v.worldToIndex().linear().transpose();  // index gradient → world gradient
  }

  Vec3 operator()(const Vec3& p) const {
    const Vec3 q = v_.worldToIndex() * p;
    double w[3][2 * kMaxReach + 1], dw[3][2 * kMaxReach + 1];
    Vec3i first;
    for (int a = 0; a < 3; ++a) {
      first[a] = static_cast<int>(std::floor(q[a])) - reach_[a] + 1;
      for (int t = 0; t < 2 * reach_[a]; ++t) {
        const double u = q[a] - (first[a] + t);
        const double g = std::exp(-0.5 * u * u / (sigma_[a] * sigma_[a]));
        w[a][t] = g;
        dw[a][t] = -u / (sigma_[a] * sigma_[a]) * g;
      }
    }
    Vec3 grad = Vec3::Zero();
    for (int k = 0; k < 2 * reach_[2]; ++k)
      for (int j = 0; j < 2 * reach_[1]; ++j) {
        double row = 0.0, rowD = 0.0;  // Σ_i o·w_i and Σ_i o·dw_i along this row
        for (int i = 0; i < 2 * reach_[0]; ++i) {
          const double o = v_.occupancy(first[0] + i, first[1] + j, first[2] + k);
          row += o * w[0][i];
          rowD += o * dw[0][i];
        }
        grad += Vec3(rowD * w[1][j] * w[2][k], row * dw[1][j] * w[2][k], row * w[1][j] * dw[2][k]);
      }
    const Vec3 n = -(toWorld_ * grad);
    const double len = n.norm();
    return len > 0.0 && std::isfinite(len) ? Vec3(n / len) : Vec3::Zero();
  }

 private:
  static constexpr int kMaxReach = 8;  // voxels: bounds the stencil of a very anisotropic grid
  const MillableVolume& v_;
  double sigma_[3];
  int reach_[3];
  Mat3 toWorld_;
};

}  // namespace

Result<std::vector<Mesh>> MillableVolume::blockSurfaces(std::span<const std::uint32_t> blocks,
                                                        std::span<const Vec4f> materialColors) const {
  const std::string where = std::string(kMillWhere) + "::blockSurfaces";
  if (!materialColors.empty() && materialColors.size() < materials_.size())
    return fail(ErrorCode::InvalidArgument,
                formatString("%zu colours for %zu materials", materialColors.size(), materials_.size()),
                where, "give one colour per material, or none");
  const auto count = static_cast<std::size_t>(blockDims_.prod());
  const SmoothedNormal normal(*this);
  std::vector<Mesh> pieces;
  pieces.reserve(blocks.size());
  for (std::uint32_t b : blocks) {
    Vec3i first, extent;
    if (!blockRange(b, first, extent))
      return fail(ErrorCode::InvalidArgument, formatString("block %u is not one of the %zu blocks", b, count),
                  where);
    // The cells whose lowest corner is in this block: voxels [b·8, b·8 + 8]
    // (the next block's first layer closes the seam), and one layer of empty
    // space beyond the grid on its border so the bone's surface closes there.
    Vec3i lo, hi;
    for (int a = 0; a < 3; ++a) {
      lo[a] = first[a] == 0 ? -1 : first[a];
      hi[a] = std::min(first[a] + kBlock, dims_[a]);
    }
    const Vec3i n = hi - lo + Vec3i::Ones();
    Affine3 a = indexToWorld_;
    a.translation() = indexToWorld_ * lo.cast<double>();
    auto sub = Volume::create(n, VoxelType::F32, a);
    if (!sub) return sub.error().within(where);
    float* out = sub->data<float>();
    for (int k = 0; k < n.z(); ++k)
      for (int j = 0; j < n.y(); ++j)
        for (int i = 0; i < n.x(); ++i)
          *out++ = static_cast<float>(occupancy(lo.x() + i, lo.y() + j, lo.z() + k));
    auto mesh = extractIsosurface(*sub, {.iso = 0.5, .threads = 1});
    if (!mesh) return mesh.error().within(where);
    for (std::size_t v = 0; v < mesh->positions.size() && v < mesh->normals.size(); ++v)
      if (const Vec3 smooth = normal(mesh->positions[v]); smooth != Vec3::Zero()) mesh->normals[v] = smooth;
    if (!materialColors.empty()) colorByMaterial(*mesh, materialColors);
    pieces.push_back(std::move(*mesh));
  }
  return pieces;
}

}  // namespace dm
