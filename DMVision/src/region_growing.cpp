// Seeded region growing (see region_growing.hpp).
#include <dm/vision/region_growing.hpp>

#include <algorithm>
#include <cmath>
#include <string>
#include <utility>

namespace dm {

namespace {

// Running mean and variance (Welford).
struct RunningStats {
  double count = 0, mean = 0, m2 = 0;
  void add(double v) {
    count += 1;
    const double d = v - mean;
    mean += d / count;
    m2 += d * (v - mean);
  }
  double stddev() const { return count > 1 ? std::sqrt(m2 / (count - 1)) : 0.0; }
};

Status checkOptions(const RegionGrowOptions& o) {
  constexpr const char* where = "RegionGrowOptions";
  if (std::isnan(o.lower) || std::isnan(o.upper) || o.lower > o.upper)
    return fail(ErrorCode::InvalidArgument,
                formatString("interval [%g, %g] is empty or NaN", o.lower, o.upper), where,
                "pass lower <= upper (infinite bounds are allowed)");
  if (o.adaptive && !(o.k > 0 && std::isfinite(o.k)))
    return fail(ErrorCode::InvalidArgument, formatString("k = %g is not a positive number", o.k), where,
                "typical adaptive widths are 2 to 3 standard deviations");
  if (!(o.minSigma >= 0) || std::isnan(o.maxGradient))
    return fail(ErrorCode::InvalidArgument,
                formatString("minSigma %g or maxGradient %g is negative or NaN", o.minSigma, o.maxGradient),
                where);
  if (o.bound && !(o.bound->centre.allFinite() && o.bound->radius >= 0 && std::isfinite(o.bound->radius)))
    return fail(ErrorCode::InvalidArgument, "the bounding ball is not finite or has a negative radius",
                where + std::string("/bound"), "pass a centre in metres and a radius >= 0");
  return ok();
}

}  // namespace

std::optional<Vec3i> nearestVoxel(const Volume& volume, const Vec3& p) noexcept {
  if (!p.allFinite() || volume.empty()) return std::nullopt;
  const Vec3 ijk = volume.worldToIndex() * p;
  // Compare as doubles first so huge coordinates never overflow the int cast.
  for (int a = 0; a < 3; ++a)
    if (!(ijk[a] > -0.5 && ijk[a] < volume.dims()[a] - 0.5)) return std::nullopt;
  return Vec3i(static_cast<int>(std::lround(ijk.x())), static_cast<int>(std::lround(ijk.y())),
               static_cast<int>(std::lround(ijk.z())));
}

NeighbourhoodStats neighbourhoodStats(const Volume& v, const Vec3i& c, int halfWidth) {
  double sum = 0, sum2 = 0;
  std::size_t n = 0;
  const Vec3i d = v.dims();
  for (int k = std::max(0, c.z() - halfWidth); k <= std::min(d.z() - 1, c.z() + halfWidth); ++k)
    for (int j = std::max(0, c.y() - halfWidth); j <= std::min(d.y() - 1, c.y() + halfWidth); ++j)
      for (int i = std::max(0, c.x() - halfWidth); i <= std::min(d.x() - 1, c.x() + halfWidth); ++i) {
        const double x = v.value(i, j, k);
        sum += x, sum2 += x * x, ++n;
      }
  if (n == 0) return {};
  const double mean = sum / static_cast<double>(n);
  return {mean, std::sqrt(std::max(0.0, sum2 / static_cast<double>(n) - mean * mean)), n};
}

Result<RegionStats> RegionGrower::grow(const Volume& image, std::span<const Vec3i> seeds,
                                       const RegionGrowOptions& options, Volume& mask) {
  constexpr const char* where = "RegionGrower::grow";
  if (image.empty())
    return fail(ErrorCode::InvalidArgument, "the image is empty", where, "pass a volume with voxels");
  if (mask.type() != VoxelType::U8 || mask.dims() != image.dims())
    return fail(
        ErrorCode::InvalidArgument,
        formatString("the mask is %s %dx%dx%d, the image %dx%dx%d", toString(mask.type()), mask.dims().x(),
                     mask.dims().y(), mask.dims().z(), image.dims().x(), image.dims().y(), image.dims().z()),
        where, "create the mask as U8 with the image's dims");
  if (auto s = checkOptions(options); !s) return std::move(s).error();
  for (std::size_t s = 0; s < seeds.size(); ++s)
    if (!image.contains(seeds[s].x(), seeds[s].y(), seeds[s].z()))
      return fail(
          ErrorCode::InvalidArgument,
          formatString("seed %zu (%d, %d, %d) is outside the %dx%dx%d grid", s, seeds[s].x(), seeds[s].y(),
                       seeds[s].z(), image.dims().x(), image.dims().y(), image.dims().z()),
          where, "use dm::nearestVoxel() to turn a world point into a voxel index");

  const std::size_t n = image.voxelCount();
  visited_.assign((n + 63) / 64, 0);
  queue_.clear();
  auto testAndSet = [&](std::size_t idx) {
    std::uint64_t& word = visited_[idx >> 6];
    const std::uint64_t bit = std::uint64_t{1} << (idx & 63);
    const bool was = (word & bit) != 0;
    word |= bit;
    return was;
  };

  RunningStats adapt, region;
  if (options.adaptive)
    for (const Vec3i& s : seeds)
      for (int dz = -1; dz <= 1; ++dz)
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx)
            if (image.contains(s.x() + dx, s.y() + dy, s.z() + dz))
              adapt.add(image.value(s.x() + dx, s.y() + dy, s.z() + dz));

  const Affine3& toWorld = image.indexToWorld();
  const double r2 = options.bound ? options.bound->radius * options.bound->radius : 0.0;
  const bool gradientTest = std::isfinite(options.maxGradient);
  auto accept = [&](int i, int j, int k, double v) {
    if (!(v >= options.lower && v <= options.upper)) return false;
    if (options.bound && (toWorld * Vec3(i, j, k) - options.bound->centre).squaredNorm() > r2) return false;
    if (options.adaptive && std::abs(v - adapt.mean) > options.k * std::max(adapt.stddev(), options.minSigma))
      return false;
    if (gradientTest && image.gradientWorld(i, j, k).norm() > options.maxGradient) return false;
    return true;
  };

  RegionStats stats;
  std::uint8_t* m = mask.data<std::uint8_t>();
  auto take = [&](std::size_t idx, int i, int j, int k, double v) {
    queue_.push_back(idx);
    if (!m[idx]) ++stats.newVoxels;
    m[idx] = 1;
    region.add(v);
    if (options.adaptive) adapt.add(v);
    const Vec3i ijk(i, j, k);
    if (stats.voxelCount == 0) {
      stats.minIndex = stats.maxIndex = ijk;
    } else {
      stats.minIndex = stats.minIndex.cwiseMin(ijk);
      stats.maxIndex = stats.maxIndex.cwiseMax(ijk);
    }
    ++stats.voxelCount;
  };

  for (const Vec3i& s : seeds) {
    const std::size_t idx = image.linearIndex(s.x(), s.y(), s.z());
    if (testAndSet(idx) || stats.voxelCount >= options.maxVoxels) continue;
    const double v = image.valueAt(idx);
    if (accept(s.x(), s.y(), s.z(), v)) take(idx, s.x(), s.y(), s.z(), v);
  }
  const auto offsets = neighbourOffsets(options.connectivity);
  const Vec3i dims = image.dims();
  const auto nx = static_cast<std::size_t>(dims.x());
  const std::size_t nxy = nx * static_cast<std::size_t>(dims.y());
  std::ptrdiff_t delta[26];  // linear index offsets of the neighbours
  for (std::size_t o = 0; o < offsets.size(); ++o)
    delta[o] = offsets[o].x() + static_cast<std::ptrdiff_t>(nx) * offsets[o].y() +
               static_cast<std::ptrdiff_t>(nxy) * offsets[o].z();
  for (std::size_t head = 0; head < queue_.size() && !stats.truncated; ++head) {
    const std::size_t idx = queue_[head];
    const int i = static_cast<int>(idx % nx), j = static_cast<int>((idx % nxy) / nx),
              k = static_cast<int>(idx / nxy);
    // Away from the border every neighbour exists: skip the bounds checks.
    const bool interior = i > 0 && j > 0 && k > 0 && i < dims.x() - 1 && j < dims.y() - 1 && k < dims.z() - 1;
    for (std::size_t o = 0; o < offsets.size(); ++o) {
      const int a = i + offsets[o].x(), b = j + offsets[o].y(), c = k + offsets[o].z();
      if (!interior && !image.contains(a, b, c)) continue;
      const auto nb = static_cast<std::size_t>(static_cast<std::ptrdiff_t>(idx) + delta[o]);
      if (testAndSet(nb)) continue;
      if (stats.voxelCount >= options.maxVoxels) {
        stats.truncated = true;
        break;
      }
      const double v = image.valueAt(nb);
      if (accept(a, b, c, v)) take(nb, a, b, c, v);
    }
  }

  const double voxelVolume = std::abs(toWorld.linear().determinant());
  stats.volumeM3 = static_cast<double>(stats.voxelCount) * voxelVolume;
  stats.volumeMl = stats.volumeM3 * 1e6;
  stats.mean = region.mean;
  stats.stddev = region.stddev();
  if (stats.voxelCount > 0)
    for (int c = 0; c < 8; ++c) {
      const Vec3 corner((c & 1) ? stats.maxIndex.x() : stats.minIndex.x(),
                        (c & 2) ? stats.maxIndex.y() : stats.minIndex.y(),
                        (c & 4) ? stats.maxIndex.z() : stats.minIndex.z());
      stats.worldBounds.extend(toWorld * corner);
    }
  return stats;
}

Result<RegionGrowResult> growRegion(const Volume& image, std::span<const Vec3i> seeds,
                                    const RegionGrowOptions& options) {
  if (image.empty())
    return fail(ErrorCode::InvalidArgument, "the image is empty", "growRegion", "pass a volume with voxels");
  auto mask = Volume::create(image.dims(), VoxelType::U8, image.indexToWorld());
  if (!mask) return std::move(mask).error();
  RegionGrower grower;
  auto stats = grower.grow(image, seeds, options, *mask);
  if (!stats) return std::move(stats).error();
  return RegionGrowResult{std::move(*mask), *stats};
}

}  // namespace dm
