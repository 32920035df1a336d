// The separable exact Euclidean distance transform (volume_distance.hpp).
#include <dm/core/tasks.hpp>
#include <dm/math/volume_distance.hpp>

#include <cassert>
#include <cmath>
#include <cstddef>
#include <limits>

namespace dm {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr float kInfF = std::numeric_limits<float>::infinity();

// Squared Euclidean distance transform of one line (Felzenszwalb &
// Huttenlocher, "Distance Transforms of Sampled Functions", 2012): out[q] =
// min_p (s·(q − p))² + f[p], with f = +∞ where there is no feature. The
// lower envelope of the parabolas rooted at the finite samples is built in
// one pass and read back in another: O(n). v and z are scratch of n and
// n + 1 entries.
void edtLine(const float* f, std::ptrdiff_t stride, int n, double s, float* out, int* v, double* z) {
  int k = -1;
  auto key = [&](int q) { return static_cast<double>(f[q * stride]) + (q * s) * (q * s); };
  for (int q = 0; q < n; ++q) {
    if (!std::isfinite(f[q * stride])) continue;
    while (true) {
      if (k < 0) {
        k = 0;
        v[0] = q;
        z[0] = -kInf;
        z[1] = kInf;
        break;
      }
      const double x = (key(q) - key(v[k])) / (2.0 * s * (q - v[k]));
      if (x <= z[k]) {
        --k;
        continue;
      }
      ++k;
      v[k] = q;
      z[k] = x;
      z[k + 1] = kInf;
      break;
    }
  }
  if (k < 0) {
    for (int q = 0; q < n; ++q) out[q] = kInfF;
    return;
  }
  k = 0;
  for (int q = 0; q < n; ++q) {
    while (z[k + 1] < q * s) ++k;
    const double dq = (q - v[k]) * s;
    out[q] = static_cast<float>(dq * dq + f[v[k] * stride]);
  }
}

}  // namespace

void squaredDistanceTransform(std::span<float> f, const Vec3i& dims, const Vec3& s) {
  assert(f.size() == static_cast<std::size_t>(dims.x()) * static_cast<std::size_t>(dims.y()) *
                         static_cast<std::size_t>(dims.z()));
  const std::size_t nx = static_cast<std::size_t>(dims.x()), ny = static_cast<std::size_t>(dims.y());
  for (int axis = 0; axis < 3; ++axis) {
    const int n = dims[axis];
    if (n <= 1) continue;
    const std::size_t lines = f.size() / static_cast<std::size_t>(n);
    const std::ptrdiff_t stride = axis == 0 ? 1 : static_cast<std::ptrdiff_t>(axis == 1 ? nx : nx * ny);
    parallelFor(0, lines, 64, [&](std::size_t b, std::size_t e) {
      std::vector<int> v(static_cast<std::size_t>(n));
      std::vector<double> z(static_cast<std::size_t>(n) + 1);
      std::vector<float> line(static_cast<std::size_t>(n));
      for (std::size_t l = b; l < e; ++l) {
        const std::size_t start = axis == 0 ? l * nx : axis == 1 ? (l % nx) + (l / nx) * nx * ny : l;
        float* base = f.data() + start;
        edtLine(base, stride, n, s[axis], line.data(), v.data(), z.data());
        for (int q = 0; q < n; ++q) base[q * stride] = line[static_cast<std::size_t>(q)];
      }
    });
  }
}

std::vector<float> squaredDistanceToForeground(std::span<const std::uint8_t> foreground, const Vec3i& dims,
                                               const Vec3& spacing) {
  std::vector<float> d2(foreground.size());
  parallelFor(0, d2.size(), std::size_t{1} << 15, [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i) d2[i] = foreground[i] != 0 ? 0.0f : kInfF;
  });
  squaredDistanceTransform(d2, dims, spacing);
  return d2;
}

}  // namespace dm
