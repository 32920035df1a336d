// Volume filters: Gaussian smoothing, gradients, 3-D Canny, thresholding,
// connected components and binary morphology (see volume_filters.hpp).
#include <dm/core/tasks.hpp>
#include <dm/math/volume_distance.hpp>
#include <dm/vision/volume_filters.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <numeric>
#include <string>
#include <utility>

namespace dm {

namespace {

constexpr int kMaxKernelRadius = 1024;

Status requireNonEmpty(const Volume& v, const char* where) {
  if (v.empty())
    return fail(ErrorCode::InvalidArgument, "the volume is empty", where,
                "pass a volume with at least one voxel");
  return ok();
}

Result<Volume> makeLike(const Volume& in, VoxelType type) {
  return Volume::create(in.dims(), type, in.indexToWorld());
}

// Calls fn(n) for every voxel index in parallel chunks.
template <class F>
void forEachVoxel(std::size_t count, F&& fn) {
  parallelFor(0, count, std::size_t{1} << 15, [&](std::size_t b, std::size_t e) {
    for (std::size_t n = b; n < e; ++n) fn(n);
  });
}

// Calls fn(i, j, k, n) for every voxel, in parallel over z-slices.
template <class F>
void forEachVoxelIjk(const Vec3i& dims, F&& fn) {
  const std::size_t slice = static_cast<std::size_t>(dims.x()) * static_cast<std::size_t>(dims.y());
  parallelFor(0, static_cast<std::size_t>(dims.z()), 1, [&](std::size_t kb, std::size_t ke) {
    for (std::size_t k = kb; k < ke; ++k) {
      std::size_t n = k * slice;
      for (int j = 0; j < dims.y(); ++j)
        for (int i = 0; i < dims.x(); ++i, ++n) fn(i, j, static_cast<int>(k), n);
    }
  });
}

// Per-chunk scratch of forEachLine().
struct LineScratch {
  std::vector<double> real;
};

// Calls fn(scratch, base, stride, len) for every grid line along `axis`
// (voxels base + stride·t, t < len), in parallel chunks of lines.
template <class F>
void forEachLine(const Vec3i& dims, int axis, F&& fn) {
  const auto nx = static_cast<std::size_t>(dims.x()), ny = static_cast<std::size_t>(dims.y());
  const std::size_t lines =
      nx * ny * static_cast<std::size_t>(dims.z()) / static_cast<std::size_t>(dims[axis]);
  const std::size_t stride = axis == 0 ? 1 : axis == 1 ? nx : nx * ny;
  parallelFor(0, lines, 64, [&](std::size_t b, std::size_t e) {
    LineScratch scratch;
    for (std::size_t l = b; l < e; ++l) {
      const std::size_t base = axis == 0 ? l * nx : axis == 1 ? (l % nx) + nx * ny * (l / nx) : l;
      fn(scratch, base, stride, dims[axis]);
    }
  });
}

// One 1-D Gaussian pass along `axis`: dst = w * src, replicate borders.
void convolveAxis(const float* src, float* dst, const Vec3i& dims, int axis, const std::vector<double>& w) {
  const int r = static_cast<int>(w.size()) - 1;
  forEachLine(dims, axis, [&](LineScratch& scratch, std::size_t base, std::size_t stride, int len) {
    std::vector<double>& line = scratch.real;
    line.resize(static_cast<std::size_t>(len + 2 * r));
    for (int t = -r; t < len + r; ++t)
      line[static_cast<std::size_t>(t + r)] =
          src[base + stride * static_cast<std::size_t>(std::clamp(t, 0, len - 1))];
    for (int t = 0; t < len; ++t) {
      const double* c = line.data() + t + r;
      double acc = w[0] * c[0];
      for (int d = 1; d <= r; ++d) acc += w[static_cast<std::size_t>(d)] * (c[-d] + c[d]);
      dst[base + stride * static_cast<std::size_t>(t)] = static_cast<float>(acc);
    }
  });
}

// Dilation of the foreground `fg` (0/1 per voxel) by the structuring element;
// outside the grid counts as nothing. Writes 0/1 into `out`.
void dilateMask(const std::vector<std::uint8_t>& fg, std::uint8_t* out, const Vec3i& dims, int radius,
                StructuringElement se) {
  const std::size_t n = fg.size();
  if (se == StructuringElement::Cube) {
    // A cube is the Minkowski sum of three segments: three 1-D dilations.
    std::vector<std::uint8_t> a(fg), b(n);
    for (int axis = 0; axis < 3; ++axis) {
      forEachLine(dims, axis, [&](LineScratch& scratch, std::size_t base, std::size_t stride, int len) {
        std::vector<double>& dist = scratch.real;
        dist.resize(static_cast<std::size_t>(len));
        double last = -HUGE_VAL;  // position of the last foreground voxel seen
        for (int t = 0; t < len; ++t) {
          if (a[base + stride * static_cast<std::size_t>(t)]) last = t;
          dist[static_cast<std::size_t>(t)] = t - last;
        }
        last = HUGE_VAL;
        for (int t = len - 1; t >= 0; --t) {
          if (a[base + stride * static_cast<std::size_t>(t)]) last = t;
          const double d = std::min(dist[static_cast<std::size_t>(t)], last - t);
          b[base + stride * static_cast<std::size_t>(t)] = d <= radius ? 1 : 0;
        }
      });
      std::swap(a, b);
    }
    std::copy(a.begin(), a.end(), out);
    return;
  }
  // Ball: squared Euclidean distance to the foreground (index units: exact integers).
  const std::vector<float> d2 = squaredDistanceToForeground(fg, dims);
  const double r2 = double(radius) * radius;
  forEachVoxel(n, [&](std::size_t i) { out[i] = d2[i] <= r2 ? 1 : 0; });
}

Status checkMorphology(const Volume& mask, int radius, const char* where) {
  if (auto s = requireNonEmpty(mask, where); !s) return s;
  if (radius < 0 || radius > kMaxKernelRadius)
    return fail(ErrorCode::InvalidArgument,
                formatString("radius %d voxels is outside [0, %d]", radius, kMaxKernelRadius), where,
                "pass a structuring element radius in voxels");
  return ok();
}

std::vector<std::uint8_t> foreground(const Volume& mask, bool complement) {
  std::vector<std::uint8_t> fg(mask.voxelCount());
  forEachVoxel(fg.size(), [&](std::size_t i) { fg[i] = (mask.valueAt(i) != 0.0) != complement ? 1 : 0; });
  return fg;
}

}  // namespace

Result<Volume> gaussianSmooth(const Volume& in, double sigma, double truncate) {
  constexpr const char* where = "gaussianSmooth";
  if (auto s = requireNonEmpty(in, where); !s) return std::move(s).error();
  if (!std::isfinite(sigma) || sigma < 0)
    return fail(ErrorCode::InvalidArgument, formatString("sigma %g m is negative or not finite", sigma),
                where, "pass the standard deviation in metres, e.g. 1e-3 for 1 mm");
  if (!(truncate >= 1.0 && truncate <= 10.0))
    return fail(ErrorCode::InvalidArgument, formatString("truncate %g is outside [1, 10] sigmas", truncate),
                where, "3 keeps 99.7 % of the kernel");
  const Vec3 spacing = in.spacing();
  std::array<std::vector<double>, 3> kernels;
  for (int a = 0; a < 3; ++a) {
    const double sv = sigma / spacing[a];
    if (sv < 0.1 || in.dims()[a] < 2) continue;
    const double radius = std::ceil(truncate * sv);
    if (radius > kMaxKernelRadius)
      return fail(
          ErrorCode::InvalidArgument,
          formatString("sigma %g m is %g voxels along axis %d: the kernel radius would exceed %d voxels",
                       sigma, sv, a, kMaxKernelRadius),
          where, "downsample the volume first or use a smaller sigma");
    auto& w = kernels[static_cast<std::size_t>(a)];
    w.resize(static_cast<std::size_t>(radius) + 1);
    double sum = 0;
    for (std::size_t t = 0; t < w.size(); ++t) {
      w[t] = std::exp(-0.5 * double(t) * double(t) / (sv * sv));
      sum += t == 0 ? w[t] : 2 * w[t];
    }
    for (double& x : w) x /= sum;
  }
  auto out = makeLike(in, VoxelType::F32);
  if (!out) return std::move(out).error();
  float* o = out->data<float>();
  const std::size_t n = in.voxelCount();
  forEachVoxel(n, [&](std::size_t i) { o[i] = static_cast<float>(in.valueAt(i)); });
  std::vector<float> tmp;
  float* src = o;
  for (int a = 0; a < 3; ++a) {
    const auto& w = kernels[static_cast<std::size_t>(a)];
    if (w.empty()) continue;
    if (tmp.empty()) tmp.resize(n);
    float* dst = src == o ? tmp.data() : o;
    convolveAxis(src, dst, in.dims(), a, w);
    src = dst;
  }
  if (src != o) std::copy(src, src + n, o);
  return out;
}

Result<GradientField> gradient(const Volume& in) {
  if (auto s = requireNonEmpty(in, "gradient"); !s) return std::move(s).error();
  GradientField g;
  for (Volume* c : {&g.x, &g.y, &g.z}) {
    auto v = makeLike(in, VoxelType::F32);
    if (!v) return std::move(v).error();
    *c = std::move(*v);
  }
  float* gx = g.x.data<float>();
  float* gy = g.y.data<float>();
  float* gz = g.z.data<float>();
  forEachVoxelIjk(in.dims(), [&](int i, int j, int k, std::size_t n) {
    const Vec3 d = in.gradientWorld(i, j, k);
    gx[n] = static_cast<float>(d.x());
    gy[n] = static_cast<float>(d.y());
    gz[n] = static_cast<float>(d.z());
  });
  return g;
}

Result<Volume> gradientMagnitude(const Volume& in) {
  if (auto s = requireNonEmpty(in, "gradientMagnitude"); !s) return std::move(s).error();
  auto out = makeLike(in, VoxelType::F32);
  if (!out) return std::move(out).error();
  float* o = out->data<float>();
  forEachVoxelIjk(in.dims(), [&](int i, int j, int k, std::size_t n) {
    o[n] = static_cast<float>(in.gradientWorld(i, j, k).norm());
  });
  return out;
}

Result<EdgeMap> detectEdges(const Volume& in, const EdgeOptions& options) {
  constexpr const char* where = "detectEdges";
  if (auto s = requireNonEmpty(in, where); !s) return std::move(s).error();
  if (!(options.low >= 0.0 && options.low <= options.high && options.high <= 1.0))
    return fail(
        ErrorCode::InvalidArgument,
        formatString("thresholds low %g, high %g are not 0 <= low <= high <= 1", options.low, options.high),
        where, "thresholds are fractions of the largest gradient magnitude");
  auto smooth = gaussianSmooth(in, options.sigma);
  if (!smooth) return std::move(smooth).error().within(where);
  auto grad = gradient(*smooth);
  if (!grad) return std::move(grad).error();
  *smooth = Volume();  // release early: the gradient is all that is needed now

  EdgeMap map;
  auto strength = makeLike(in, VoxelType::F32);
  if (!strength) return std::move(strength).error();
  auto edges = makeLike(in, VoxelType::U8);
  if (!edges) return std::move(edges).error();
  map.strength = std::move(*strength);
  map.edges = std::move(*edges);
  const std::size_t n = in.voxelCount();
  float* m = map.strength.data<float>();
  forEachVoxel(n, [&](std::size_t i) {
    m[i] = static_cast<float>(Vec3(grad->x.valueAt(i), grad->y.valueAt(i), grad->z.valueAt(i)).norm());
  });
  const float maxG = n ? *std::max_element(m, m + n) : 0.0f;
  map.maxGradient = maxG;
  if (!(maxG > 0.0f)) {
    std::fill(m, m + n, 0.0f);
    return map;
  }
  forEachVoxel(n, [&](std::size_t i) { m[i] /= maxG; });

  // Non-maximum suppression along the gradient, stepped one voxel in index
  // space: the world gradient direction maps to index space through A^-1.
  std::uint8_t* e = map.edges.data<std::uint8_t>();
  const Mat3 toIndex = in.worldToIndex().linear();
  const auto low = static_cast<float>(options.low);
  const auto high = static_cast<float>(options.high);
  constexpr std::uint8_t kCandidate = 1, kStrong = 2;
  forEachVoxelIjk(in.dims(), [&](int i, int j, int k, std::size_t idx) {
    e[idx] = 0;
    if (m[idx] < low || m[idx] <= 0.0f) return;
    Vec3 d = toIndex * grad->at(i, j, k);
    const double len = d.norm();
    if (!(len > 0)) return;
    d /= len;
    const Vec3 p(i, j, k);
    const double ahead = map.strength.sampleIndex(p + d), behind = map.strength.sampleIndex(p - d);
    if (m[idx] >= ahead && m[idx] > behind) e[idx] = m[idx] >= high ? kStrong : kCandidate;
  });

  // Hysteresis: strong voxels, then every candidate connected to one.
  std::vector<std::size_t> queue;
  for (std::size_t i = 0; i < n; ++i)
    if (e[i] == kStrong) queue.push_back(i);
  const auto offsets = neighbourOffsets(options.connectivity);
  const Vec3i dims = in.dims();
  for (std::size_t head = 0; head < queue.size(); ++head) {
    const std::size_t idx = queue[head];
    const int i = static_cast<int>(idx % static_cast<std::size_t>(dims.x()));
    const int j =
        static_cast<int>((idx / static_cast<std::size_t>(dims.x())) % static_cast<std::size_t>(dims.y()));
    const int k =
        static_cast<int>(idx / (static_cast<std::size_t>(dims.x()) * static_cast<std::size_t>(dims.y())));
    for (const Vec3i& o : offsets) {
      if (!in.contains(i + o.x(), j + o.y(), k + o.z())) continue;
      const std::size_t nb = in.linearIndex(i + o.x(), j + o.y(), k + o.z());
      if (e[nb] == kCandidate) {
        e[nb] = kStrong;
        queue.push_back(nb);
      }
    }
  }
  forEachVoxel(n, [&](std::size_t i) { e[i] = e[i] == kStrong ? 1 : 0; });
  return map;
}

Result<Volume> threshold(const Volume& in, double lo, double hi) {
  constexpr const char* where = "threshold";
  if (auto s = requireNonEmpty(in, where); !s) return std::move(s).error();
  if (std::isnan(lo) || std::isnan(hi) || lo > hi)
    return fail(ErrorCode::InvalidArgument, formatString("band [%g, %g] is empty or NaN", lo, hi), where,
                "pass lo <= hi; hi = +inf for a binary threshold");
  auto out = makeLike(in, VoxelType::U8);
  if (!out) return std::move(out).error();
  std::uint8_t* o = out->data<std::uint8_t>();
  forEachVoxel(in.voxelCount(), [&](std::size_t i) {
    const double v = in.valueAt(i);
    o[i] = v >= lo && v <= hi ? 1 : 0;
  });
  return out;
}

Result<Volume> dilate(const Volume& mask, int radius, StructuringElement se) {
  if (auto s = checkMorphology(mask, radius, "dilate"); !s) return std::move(s).error();
  auto out = makeLike(mask, VoxelType::U8);
  if (!out) return std::move(out).error();
  dilateMask(foreground(mask, false), out->data<std::uint8_t>(), mask.dims(), radius, se);
  return out;
}

Result<Volume> erode(const Volume& mask, int radius, StructuringElement se) {
  if (auto s = checkMorphology(mask, radius, "erode"); !s) return std::move(s).error();
  auto out = makeLike(mask, VoxelType::U8);
  if (!out) return std::move(out).error();
  // Duality within the grid: erode(A) = grid \ dilate(grid \ A).
  std::uint8_t* o = out->data<std::uint8_t>();
  dilateMask(foreground(mask, true), o, mask.dims(), radius, se);
  forEachVoxel(mask.voxelCount(), [&](std::size_t i) { o[i] = 1 - o[i]; });
  return out;
}

Result<Volume> opening(const Volume& mask, int radius, StructuringElement se) {
  auto e = erode(mask, radius, se);
  if (!e) return std::move(e).error().within("opening");
  return dilate(*e, radius, se);
}

Result<Volume> closing(const Volume& mask, int radius, StructuringElement se) {
  auto d = dilate(mask, radius, se);
  if (!d) return std::move(d).error().within("closing");
  return erode(*d, radius, se);
}

}  // namespace dm
