// Voxel models, dense storage: builders (mesh, occupancy with an exact
// Euclidean distance transform, dm::squaredDistanceTransform; SDF volume), trilinear distance/gradient
// queries and sphere-traced ray casts; see dm/collide/voxel_model.hpp. The
// OpenVDB storage is in voxel_model_vdb.cpp.
#include <dm/collide/voxel_model.hpp>
#include <dm/math/volume_distance.hpp>

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <limits>
#include <new>
#include <string>
#include <utility>

#include "collide_internal.hpp"

namespace dm {

namespace {

using detail::kInf;
constexpr float kInfF = std::numeric_limits<float>::infinity();

std::string indexString(int i, int j, int k) {
  return "(" + std::to_string(i) + ", " + std::to_string(j) + ", " + std::to_string(k) + ")";
}

Error outOfMemory(const std::string& where) {
  return fail(ErrorCode::InvalidArgument, "out of memory while building the voxel model", where,
              "use a smaller or coarser volume");
}

Status checkVolume(const Volume& v, const std::string& where) {
  if (v.empty())
    return fail(ErrorCode::InvalidArgument, "volume is empty (no voxels)", where + ": volume",
                "pass a volume with dims ≥ 1");
  if (v.voxelCount() >= (std::size_t{1} << 40))
    return fail(ErrorCode::InvalidArgument, "volume has more than 2^40 voxels", where + ": volume",
                "crop or resample it");
  return ok();
}

}  // namespace

VoxelModel::VoxelModel() noexcept : Shape(ShapeType::VoxelModel) {}
VoxelModel::~VoxelModel() = default;

Result<std::shared_ptr<VoxelModel>> VoxelModel::denseFrom(const Vec3i& dims, const Affine3& indexToWorld,
                                                          std::vector<float> distances,
                                                          std::vector<std::uint64_t> occupancy, double band) {
  std::shared_ptr<VoxelModel> m(new (std::nothrow) VoxelModel());
  if (!m) return outOfMemory("dm::VoxelModel");
  m->storage_ = VoxelStorage::Dense;
  m->dims_ = dims;
  m->indexToWorld_ = indexToWorld;
  m->distance_ = std::move(distances);
  m->occupancy_ = std::move(occupancy);
  m->band_ = band;
  m->occupiedCount_ = 0;
  for (std::uint64_t w : m->occupancy_)
    m->occupiedCount_ += static_cast<std::size_t>(__builtin_popcountll(w));
  m->finish();
  // Measured slope: the largest |Δd| / spacing between axis neighbours
  // (1 for a true distance), which bounds |∇| of the trilinear interpolant
  // by √3·slope on an orthogonal grid.
  const Vec3 s = indexToWorld.linear().colwise().norm().transpose();
  const std::size_t nx = static_cast<std::size_t>(dims.x()), ny = static_cast<std::size_t>(dims.y());
  const std::size_t stride[3] = {1, nx, nx * ny};
  const std::vector<float>& d = m->distance_;
  double slope = 0.0;
  for (int k = 0; k < dims.z(); ++k)
    for (int j = 0; j < dims.y(); ++j)
      for (int i = 0; i < dims.x(); ++i) {
        const std::size_t idx = static_cast<std::size_t>(i) +
                                nx * (static_cast<std::size_t>(j) + ny * static_cast<std::size_t>(k));
        const int at[3] = {i, j, k};
        for (int a = 0; a < 3; ++a)
          if (at[a] + 1 < dims[a])
            slope = std::max(slope, std::abs(static_cast<double>(d[idx + stride[a]]) - d[idx]) / s[a]);
      }
  // |∇_world| = |W^T ∇_index| ≤ ‖W‖·√3·slope·max spacing; outside the grid
  // the distance to the grid adds 1.
  Eigen::SelfAdjointEigenSolver<Mat3> eig;
  eig.computeDirect(indexToWorld.linear().transpose() * indexToWorld.linear(), Eigen::EigenvaluesOnly);
  const double sigmaMin = std::sqrt(std::max(eig.eigenvalues()(0), 1e-300));
  m->lipschitz_ = 1.0 + std::sqrt(3.0) * slope * s.maxCoeff() / sigmaMin;
  return m;
}

void VoxelModel::finish() {
  worldToIndex_ = indexToWorld_.inverse();
  const Vec3 s = indexToWorld_.linear().colwise().norm().transpose();
  minSpacing_ = s.minCoeff();
  bounds_.setEmpty();
  for (int c = 0; c < 8; ++c) {
    const Vec3 ijk((c & 1) ? dims_.x() - 0.5 : -0.5, (c & 2) ? dims_.y() - 0.5 : -0.5,
                   (c & 4) ? dims_.z() - 0.5 : -0.5);
    bounds_.extend(indexToWorld_ * ijk);
  }
}

Result<std::shared_ptr<const VoxelModel>> VoxelModel::fromMesh(const Mesh& mesh, VoxelizeOptions options) {
  options.signedDistance = true;
  auto sdf = voxelizeMesh(mesh, options);
  if (!sdf) return Error(sdf.error()).within("dm::VoxelModel::fromMesh");
  // voxelizeMesh clamps the field at ±bandWidth when one is given.
  return sdfModel(*sdf, options.bandWidth > 0 ? options.bandWidth : kInf, "dm::VoxelModel::fromMesh");
}

Result<std::shared_ptr<const VoxelModel>> VoxelModel::fromSdf(const Volume& sdf) {
  return sdfModel(sdf, kInf, "dm::VoxelModel::fromSdf");
}

Result<std::shared_ptr<const VoxelModel>> VoxelModel::sdfModel(const Volume& sdf, double band,
                                                               const std::string& where) {
  if (Status s = checkVolume(sdf, where); !s) return s.error();
  try {
    const std::size_t n = sdf.voxelCount();
    std::vector<float> d(n);
    std::vector<std::uint64_t> occ((n + 63) / 64, 0);
    const Vec3i& dims = sdf.dims();
    for (std::size_t idx = 0; idx < n; ++idx) {
      const double v = sdf.valueAt(idx);
      if (!std::isfinite(v)) {
        const int i = static_cast<int>(idx % static_cast<std::size_t>(dims.x()));
        const int j =
            static_cast<int>((idx / static_cast<std::size_t>(dims.x())) % static_cast<std::size_t>(dims.y()));
        const int k =
            static_cast<int>(idx / (static_cast<std::size_t>(dims.x()) * static_cast<std::size_t>(dims.y())));
        return fail(ErrorCode::InvalidArgument, "signed distance " + std::to_string(v) + " is not finite",
                    where + ": voxel " + indexString(i, j, k), "fix or regenerate the distance volume");
      }
      d[idx] = static_cast<float>(v);
      if (v < 0) occ[idx >> 6] |= std::uint64_t{1} << (idx & 63);
    }
    auto m = denseFrom(dims, sdf.indexToWorld(), std::move(d), std::move(occ), band);
    if (!m) return m.error();
    return std::shared_ptr<const VoxelModel>(std::move(*m));
  } catch (const std::bad_alloc&) {
    return outOfMemory(where);
  }
}

Result<std::shared_ptr<const VoxelModel>> VoxelModel::fromOccupancy(const Volume& volume, double threshold) {
  const std::string where = "dm::VoxelModel::fromOccupancy";
  if (Status s = checkVolume(volume, where); !s) return s.error();
  if (!std::isfinite(threshold))
    return fail(ErrorCode::InvalidArgument, "threshold is not finite", where + ": threshold",
                "pass the value at and above which a voxel is inside");
  try {
    const std::size_t n = volume.voxelCount();
    const Vec3i& dims = volume.dims();
    const std::size_t nx = static_cast<std::size_t>(dims.x()), ny = static_cast<std::size_t>(dims.y());
    std::vector<std::uint64_t> occ((n + 63) / 64, 0);
    std::size_t inside = 0;
    for (std::size_t idx = 0; idx < n; ++idx) {
      const double v = volume.valueAt(idx);
      if (std::isnan(v))
        return fail(ErrorCode::InvalidArgument, "voxel value is NaN",
                    where + ": voxel " +
                        indexString(static_cast<int>(idx % nx), static_cast<int>((idx / nx) % ny),
                                    static_cast<int>(idx / (nx * ny))),
                    "fix the volume or replace NaN by a value below the threshold");
      if (v >= threshold) {
        occ[idx >> 6] |= std::uint64_t{1} << (idx & 63);
        ++inside;
      }
    }
    if (inside == 0)
      return fail(ErrorCode::InvalidArgument,
                  "no voxel is ≥ threshold " + std::to_string(threshold) + " (value range " +
                      std::to_string(volume.range().first) + " to " + std::to_string(volume.range().second) +
                      ")",
                  where + ": threshold", "lower the threshold");
    if (inside == n)
      return fail(ErrorCode::InvalidArgument, "every voxel is ≥ threshold " + std::to_string(threshold),
                  where + ": threshold", "raise the threshold or pad the volume with outside voxels");
    auto bit = [&](std::size_t idx) { return (occ[idx >> 6] >> (idx & 63)) & 1u; };
    const Vec3 s = volume.spacing();
    const float half = static_cast<float>(0.5 * s.minCoeff());
    std::vector<float> d(n), f(n);
    // Outside voxels: distance to the nearest inside centre.
    for (std::size_t idx = 0; idx < n; ++idx) f[idx] = bit(idx) ? 0.0f : kInfF;
    squaredDistanceTransform(f, dims, s);
    for (std::size_t idx = 0; idx < n; ++idx)
      if (!bit(idx)) d[idx] = std::sqrt(f[idx]) - half;
    // Inside voxels: distance to the nearest outside centre, negated.
    for (std::size_t idx = 0; idx < n; ++idx) f[idx] = bit(idx) ? kInfF : 0.0f;
    squaredDistanceTransform(f, dims, s);
    for (std::size_t idx = 0; idx < n; ++idx)
      if (bit(idx)) d[idx] = half - std::sqrt(f[idx]);
    f = {};
    auto m = denseFrom(dims, volume.indexToWorld(), std::move(d), std::move(occ), kInf);
    if (!m) return m.error();
    return std::shared_ptr<const VoxelModel>(std::move(*m));
  } catch (const std::bad_alloc&) {
    return outOfMemory(where);
  }
}

float VoxelModel::valueAt(int i, int j, int k) const noexcept {
  if (storage_ == VoxelStorage::Sparse) return sparseValue(i, j, k);
  return distance_[static_cast<std::size_t>(i) +
                   static_cast<std::size_t>(dims_.x()) *
                       (static_cast<std::size_t>(j) +
                        static_cast<std::size_t>(dims_.y()) * static_cast<std::size_t>(k))];
}

void VoxelModel::corners(int i, int j, int k, int di, int dj, int dk, float out[8]) const noexcept {
  if (storage_ == VoxelStorage::Sparse) {
    sparseCorners(i, j, k, di, dj, dk, out);
    return;
  }
  const std::size_t nx = static_cast<std::size_t>(dims_.x());
  const std::size_t nxy = nx * static_cast<std::size_t>(dims_.y());
  const std::size_t base =
      static_cast<std::size_t>(i) + nx * static_cast<std::size_t>(j) + nxy * static_cast<std::size_t>(k);
  const std::size_t sx = static_cast<std::size_t>(di), sy = dj ? nx : 0, sz = dk ? nxy : 0;
  const float* d = distance_.data() + base;
  out[0] = d[0];
  out[1] = d[sx];
  out[2] = d[sy];
  out[3] = d[sx + sy];
  out[4] = d[sz];
  out[5] = d[sx + sz];
  out[6] = d[sy + sz];
  out[7] = d[sx + sy + sz];
}

double VoxelModel::voxelDistance(int i, int j, int k) const noexcept {
  if (i < 0 || j < 0 || k < 0 || i >= dims_.x() || j >= dims_.y() || k >= dims_.z()) return band_;
  return valueAt(i, j, k);
}

bool VoxelModel::voxelOccupied(int i, int j, int k) const noexcept {
  if (i < 0 || j < 0 || k < 0 || i >= dims_.x() || j >= dims_.y() || k >= dims_.z()) return false;
  if (storage_ == VoxelStorage::Sparse) return sparseValue(i, j, k) < 0;
  const std::size_t idx =
      static_cast<std::size_t>(i) +
      static_cast<std::size_t>(dims_.x()) *
          (static_cast<std::size_t>(j) + static_cast<std::size_t>(dims_.y()) * static_cast<std::size_t>(k));
  return (occupancy_[idx >> 6] >> (idx & 63)) & 1u;
}

double VoxelModel::distance(const Vec3& p, Vec3& gradient) const noexcept {
  const Vec3 q = worldToIndex_ * p;
  if (!q.allFinite()) {
    gradient.setZero();
    return std::numeric_limits<double>::quiet_NaN();
  }
  Vec3 qc;
  int base[3], step[3];
  double f[3];
  bool clamped = false;
  for (int a = 0; a < 3; ++a) {
    qc[a] = std::clamp(q[a], 0.0, static_cast<double>(dims_[a] - 1));
    clamped = clamped || qc[a] != q[a];
    if (dims_[a] == 1) {
      base[a] = 0, step[a] = 0, f[a] = 0.0;
      continue;
    }
    base[a] = std::min(static_cast<int>(qc[a]), dims_[a] - 2);  // qc ≥ 0: truncation is floor
    step[a] = 1;
    f[a] = qc[a] - base[a];
  }
  float c[8];
  corners(base[0], base[1], base[2], step[0], step[1], step[2], c);
  const double fx = f[0], fy = f[1], fz = f[2];
  const double c00 = c[0] + (c[1] - c[0]) * fx, c10 = c[2] + (c[3] - c[2]) * fx;
  const double c01 = c[4] + (c[5] - c[4]) * fx, c11 = c[6] + (c[7] - c[6]) * fx;
  const double c0 = c00 + (c10 - c00) * fy, c1 = c01 + (c11 - c01) * fy;
  double value = c0 + (c1 - c0) * fz;
  const double dx0 = (c[1] - c[0]) + ((c[3] - c[2]) - (c[1] - c[0])) * fy;
  const double dx1 = (c[5] - c[4]) + ((c[7] - c[6]) - (c[5] - c[4])) * fy;
  Vec3 gi(dx0 + (dx1 - dx0) * fz, (c10 - c00) + ((c11 - c01) - (c10 - c00)) * fz, c1 - c0);
  for (int a = 0; a < 3; ++a)
    if (q[a] != qc[a]) gi[a] = 0.0;  // constant along a clamped axis
  gradient = worldToIndex_.linear().transpose() * gi;
  if (clamped) {
    const Vec3 off = indexToWorld_.linear() * (q - qc);
    const double o = off.norm();
    value += o;
    if (o > 0) gradient += off / o;
  }
  return value;
}

double VoxelModel::distance(const Vec3& p) const noexcept {
  Vec3 g;
  return distance(p, g);
}

Vec3 VoxelModel::gradient(const Vec3& p) const noexcept {
  Vec3 g;
  distance(p, g);
  return g;
}

bool VoxelModel::occupied(const Vec3& p) const noexcept {
  const Vec3 q = worldToIndex_ * p;
  if (!q.allFinite()) return false;
  const Vec3 r = q.array().round();
  if ((r.array() < 0).any() || r.x() >= dims_.x() || r.y() >= dims_.y() || r.z() >= dims_.z()) return false;
  return voxelOccupied(static_cast<int>(r.x()), static_cast<int>(r.y()), static_cast<int>(r.z()));
}

std::optional<RayHit> VoxelModel::raycast(const Ray& ray) const noexcept {
  if (!ray.origin.allFinite() || !ray.direction.allFinite() || std::isnan(ray.maxDistance))
    return std::nullopt;
  const double d0 = distance(ray.origin);
  if (d0 < 0) return RayHit{0.0, ray.origin, -ray.direction};
  // Clip [0, maxDistance] to the voxel boxes, in index space.
  const Vec3 oi = worldToIndex_ * ray.origin;
  const Vec3 di = worldToIndex_.linear() * ray.direction;
  double tIn = 0.0, tOut = ray.maxDistance;
  for (int a = 0; a < 3; ++a) {
    const double lo = -0.5, hi = dims_[a] - 0.5;
    if (di[a] == 0) {
      if (oi[a] < lo || oi[a] > hi) return std::nullopt;
      continue;
    }
    double t1 = (lo - oi[a]) / di[a], t2 = (hi - oi[a]) / di[a];
    if (t1 > t2) std::swap(t1, t2);
    tIn = std::max(tIn, t1);
    tOut = std::min(tOut, t2);
  }
  if (tIn > tOut || !std::isfinite(tOut)) return std::nullopt;  // also a zero direction

  // Sphere tracing: a step of d / slope never crosses the zero level of a
  // field whose samples are (slope-)Lipschitz distances by more than the
  // interpolation error; a crossing shows as a sign change and is bisected.
  const double slope = std::max(1.0, (lipschitz_ - 1.0) / std::sqrt(3.0));
  const double minStep = 0.05 * minSpacing_;
  auto at = [&](double t) { return distance(ray.origin + t * ray.direction); };
  double tPrev = 0.0, t = tIn;
  double d = at(t);
  const std::size_t maxSteps = static_cast<std::size_t>(std::min(1e7, (tOut - tIn) / minStep + 16));
  bool crossed = d <= 0;
  for (std::size_t it = 0; !crossed && it < maxSteps; ++it) {
    if (t >= tOut) return std::nullopt;
    tPrev = t;
    t = std::min(tOut, t + std::max(d / slope, minStep));
    d = at(t);
    crossed = d <= 0;
  }
  if (!crossed) return std::nullopt;
  // Bisection on [tPrev, t]: distance(tPrev) > 0 ≥ distance(t).
  double lo = tPrev, hi = t;
  for (int it = 0; it < 60 && hi - lo > 1e-6 * minSpacing_; ++it) {
    const double mid = 0.5 * (lo + hi);
    if (at(mid) > 0)
      lo = mid;
    else
      hi = mid;
  }
  RayHit hit;
  hit.t = hi;
  hit.point = ray.origin + hi * ray.direction;
  const Vec3 g = gradient(hit.point);
  const double gn = g.norm();
  hit.normal = gn > 0 && std::isfinite(gn) ? Vec3(g / gn) : Vec3(-ray.direction);
  return hit;
}

std::size_t VoxelModel::bytes() const noexcept {
  if (storage_ == VoxelStorage::Sparse) return sparseBytes();
  return distance_.capacity() * sizeof(float) + occupancy_.capacity() * sizeof(std::uint64_t);
}

double VoxelModel::volume() const noexcept {
  return static_cast<double>(occupiedCount_) * std::abs(indexToWorld_.linear().determinant());
}

}  // namespace dm
