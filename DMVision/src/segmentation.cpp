// Haptic-guided segmentation (see segmentation.hpp).
#include <dm/vision/segmentation.hpp>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <utility>

namespace dm {

namespace {

// N unit directions in antipodal pairs (N rounded up to even): a Fibonacci
// spiral over the sphere for the first half and its negatives, so the set
// is exactly symmetric and the guidance force cancels in homogeneous tissue.
std::vector<Vec3> antipodalDirections(int count) {
  const int half = (count + 1) / 2;
  std::vector<Vec3> dirs;
  dirs.reserve(static_cast<std::size_t>(2 * half));
  const double golden = std::numbers::pi * (3.0 - std::sqrt(5.0));
  for (int i = 0; i < half; ++i) {
    const double z = 1.0 - (2.0 * i + 1.0) / (2.0 * half);
    const double r = std::sqrt(std::max(0.0, 1.0 - z * z));
    dirs.emplace_back(r * std::cos(golden * i), r * std::sin(golden * i), z);
  }
  for (int i = 0; i < half; ++i) dirs.push_back(-dirs[static_cast<std::size_t>(i)]);
  return dirs;
}

}  // namespace

Result<HapticSegmentation> HapticSegmentation::create(const Volume& image,
                                                      const HapticSegmentationOptions& options) {
  constexpr const char* where = "HapticSegmentationOptions";
  if (image.empty())
    return fail(ErrorCode::InvalidArgument, "the image is empty", "HapticSegmentation::create",
                "pass the volume to segment");
  const auto& o = options;
  if (o.rayCount < 6 || o.rayCount > 4096)
    return fail(ErrorCode::InvalidArgument, formatString("rayCount %d is outside [6, 4096]", o.rayCount),
                where + std::string("/rayCount"), "64 rays resolve features of about rMax/4");
  if (!(o.minRadius > 0 && o.maxRadius >= o.minRadius && std::isfinite(o.maxRadius)))
    return fail(ErrorCode::InvalidArgument,
                formatString("radius range [%g, %g] m is not 0 < rMin <= rMax", o.minRadius, o.maxRadius),
                where + std::string("/minRadius"), "radii are in metres, e.g. 1e-3 and 15e-3");
  if (!(o.edgeThreshold > 0 && o.edgeThreshold <= 1))
    return fail(ErrorCode::InvalidArgument,
                formatString("edgeThreshold %g is outside (0, 1]", o.edgeThreshold),
                where + std::string("/edgeThreshold"), "the edge map is normalised to [0, 1]");
  if (!(o.gain >= 0 && std::isfinite(o.gain) && o.maxForce >= 0 && std::isfinite(o.maxForce)))
    return fail(ErrorCode::InvalidArgument,
                formatString("gain %g N·m or maxForce %g N is negative or not finite", o.gain, o.maxForce),
                where + std::string("/gain"));
  const double minSpacing = image.spacing().minCoeff();
  const double requested = o.rayStep > 0 ? o.rayStep : 0.5 * minSpacing;
  if (!std::isfinite(o.rayStep) || o.maxRadius / requested > 4096)
    return fail(
        ErrorCode::InvalidArgument,
        formatString("rays of %g m in steps of %g m need more than 4096 samples", o.maxRadius, requested),
        where + std::string("/rayStep"), "use a larger rayStep or a smaller maxRadius");

  auto edges = detectEdges(image, {.sigma = o.edgeSigma, .low = o.edgeThreshold, .high = o.edgeThreshold});
  if (!edges) return std::move(edges).error().within("HapticSegmentation::create");
  auto mask = Volume::create(image.dims(), VoxelType::U8, image.indexToWorld());
  if (!mask) return std::move(mask).error();

  HapticSegmentation seg;
  seg.options_ = o;
  seg.image_ = image;
  seg.edges_ = std::move(edges->strength);
  seg.mask_ = std::move(*mask);
  seg.rays_ = antipodalDirections(o.rayCount);
  const double steps = std::ceil(o.maxRadius / requested);
  seg.step_ = o.maxRadius / steps;
  seg.gradStep_ = minSpacing;
  // Validates the growth options now rather than at the first update().
  if (auto s = seg.grower_.grow(seg.image_, {}, o.grow, seg.mask_); !s)
    return std::move(s).error().within(where);
  return seg;
}

double HapticSegmentation::sampleEdges(const Vec3& ijk) const noexcept {
  // Trilinear interpolation with edge extension, as Volume::sampleIndex, but
  // straight on the F32 data: this runs thousands of times per haptic tick.
  const float* m = edges_.data<float>();
  const Vec3i& d = edges_.dims();
  const std::size_t stride[3] = {1, static_cast<std::size_t>(d.x()),
                                 static_cast<std::size_t>(d.x()) * static_cast<std::size_t>(d.y())};
  std::size_t base = 0, step[3];
  double f[3];
  for (int a = 0; a < 3; ++a) {
    const double c = std::clamp(ijk[a], 0.0, static_cast<double>(d[a] - 1));
    const int i0 = std::min(static_cast<int>(c), std::max(d[a] - 2, 0));
    f[a] = d[a] > 1 ? c - i0 : 0.0;
    step[a] = d[a] > 1 ? stride[a] : 0;
    base += static_cast<std::size_t>(i0) * stride[a];
  }
  const float* p = m + base;
  const std::size_t sx = step[0], sy = step[1], sz = step[2];
  const double c00 = p[0] + f[0] * (p[sx] - p[0]);
  const double c10 = p[sy] + f[0] * (p[sy + sx] - p[sy]);
  const double c01 = p[sz] + f[0] * (p[sz + sx] - p[sz]);
  const double c11 = p[sz + sy] + f[0] * (p[sz + sy + sx] - p[sz + sy]);
  const double c0 = c00 + f[1] * (c10 - c00), c1 = c01 + f[1] * (c11 - c01);
  return c0 + f[2] * (c1 - c0);
}

double HapticSegmentation::march(const Vec3& startIndex, const Vec3& dirIndex, double limit) const noexcept {
  // Samples at t = s·step; a ridge at t <= limit is confirmed by the sample
  // after it, so marching stops two samples past the limit.
  const int steps = std::min(static_cast<int>(std::lround(options_.maxRadius / step_)),
                             static_cast<int>(limit / step_) + 2);
  const double thr = options_.edgeThreshold;
  double prev2 = 0.0, prev = sampleEdges(startIndex);
  bool crossed = prev >= thr;
  for (int s = 1; s <= steps; ++s) {
    const double t = s * step_;
    const double cur = sampleEdges(startIndex + t * dirIndex);
    if (!crossed) {
      crossed = cur >= thr;
    } else if (cur < prev) {
      // The edge is the ridge of m: the previous sample, refined by the
      // vertex of the parabola through the last three samples.
      double peak = t - step_;
      const double curvature = prev2 - 2.0 * prev + cur;
      if (s >= 2 && curvature < 0) peak += std::clamp(0.5 * (prev2 - cur) / curvature, -0.5, 0.5) * step_;
      return std::max(peak, 0.0);
    }
    prev2 = prev;
    prev = cur;
  }
  return options_.maxRadius;
}

double HapticSegmentation::rayDistance(const Vec3& probe, const Vec3& dir) const noexcept {
  if (!probe.allFinite() || !dir.allFinite()) return options_.maxRadius;
  const Affine3& w = edges_.worldToIndex();
  return march(w * probe, w.linear() * dir, options_.maxRadius);
}

double HapticSegmentation::adaptiveRadius(const Vec3& probe) const noexcept {
  if (!probe.allFinite()) return options_.minRadius;
  const Affine3& w = edges_.worldToIndex();
  const Vec3 start = w * probe;
  // Each ray only needs to look as far as the nearest edge found so far.
  double r = options_.maxRadius;
  for (const Vec3& d : rays_) r = std::min(r, march(start, w.linear() * d, r));
  return std::clamp(r, options_.minRadius, options_.maxRadius);
}

Vec3 HapticSegmentation::edgeGradient(const Vec3& world) const noexcept {
  if (!world.allFinite()) return Vec3::Zero();
  const Affine3& w = edges_.worldToIndex();
  const Vec3 centre = w * world;
  Vec3 g;
  for (int a = 0; a < 3; ++a) {
    const Vec3 h = gradStep_ * w.linear().col(a);  // gradStep_ along world axis a, in index units
    g[a] = (sampleEdges(centre + h) - sampleEdges(centre - h)) / (2.0 * gradStep_);
  }
  return g;
}

Vec3 HapticSegmentation::guidanceForce(const Vec3& probe) const noexcept {
  if (!probe.allFinite()) return Vec3::Zero();
  const double rho = adaptiveRadius(probe);
  Vec3 f = Vec3::Zero();
  // ray = rho·d, so (ray · ∇m)/|ray| = d · ∇m; it acts along −d.
  for (const Vec3& d : rays_) f -= d.dot(edgeGradient(probe + rho * d)) * d;
  f *= options_.gain / static_cast<double>(rays_.size());
  if (!f.allFinite()) return Vec3::Zero();
  const double norm = f.norm();
  if (norm > options_.maxForce) f *= options_.maxForce / norm;
  return f;
}

Result<SegmentationUpdate> HapticSegmentation::update(const Vec3& probe) {
  if (!probe.allFinite())
    return fail(ErrorCode::InvalidArgument, "the probe position is not finite", "HapticSegmentation::update",
                "check the device pose");
  SegmentationUpdate u;
  u.radius = adaptiveRadius(probe);
  if (const auto seed = nearestVoxel(image_, probe)) {
    RegionGrowOptions grow = options_.grow;
    grow.bound = GrowBall{probe, u.radius};
    auto stats = grower_.grow(image_, std::span<const Vec3i>(&*seed, 1), grow, mask_);
    if (!stats) return std::move(stats).error();
    u.grownVoxels = stats->voxelCount;
    u.newVoxels = stats->newVoxels;
    segmented_ += stats->newVoxels;
  }
  u.totalVoxels = segmented_;
  u.totalVolumeMl = segmentedVolume() * 1e6;
  return u;
}

double HapticSegmentation::segmentedVolume() const {
  return static_cast<double>(segmented_) * std::abs(mask_.indexToWorld().linear().determinant());
}

void HapticSegmentation::clear() {
  auto* m = mask_.data<std::uint8_t>();
  std::fill(m, m + mask_.voxelCount(), std::uint8_t{0});
  segmented_ = 0;
}

}  // namespace dm
