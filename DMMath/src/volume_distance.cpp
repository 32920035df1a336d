// The separable exact Euclidean distance transform (volume_distance.hpp).
#include <dm/core/tasks.hpp>
#include <dm/math/volume_distance.hpp>

#include <algorithm>
#include <cassert>
#include <cmath>
#include <cstddef>

namespace dm {

namespace {

// Squared 1-D distance transform of one line of voxels `step` apart
// (Felzenszwalb & Huttenlocher, "Distance transforms of sampled functions",
// 2012): d[q] = min_p (step·(q − p))² + f[p]. v: len ints, z: len + 1.
void distanceTransform1d(const double* f, double* d, int len, double step, int* v, double* z) {
  int k = 0;
  v[0] = 0;
  z[0] = -HUGE_VAL;
  z[1] = HUGE_VAL;
  for (int q = 1; q < len; ++q) {
    // z[0] = -inf ends the loop at k = 0 at the latest (every f is finite).
    const double xq = step * q;
    double s = 0;
    for (;; --k) {
      const int p = v[k];
      const double xp = step * p;
      s = ((f[q] + xq * xq) - (f[p] + xp * xp)) / (2.0 * (xq - xp));
      if (s > z[k]) break;
    }
    ++k;
    v[k] = q;
    z[k] = s;
    z[k + 1] = HUGE_VAL;
  }
  k = 0;
  for (int q = 0; q < len; ++q) {
    const double xq = step * q;
    while (z[k + 1] < xq) ++k;
    const double dq = xq - step * v[k];
    d[q] = dq * dq + f[v[k]];
  }
}

}  // namespace

std::vector<float> squaredDistanceToForeground(std::span<const std::uint8_t> foreground, const Vec3i& dims,
                                               const Vec3& spacing) {
  const std::size_t n = foreground.size();
  assert(n == static_cast<std::size_t>(dims.x()) * static_cast<std::size_t>(dims.y()) *
                  static_cast<std::size_t>(dims.z()));
  std::vector<float> d2(n);
  parallelFor(0, n, std::size_t{1} << 15, [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i) d2[i] = foreground[i] != 0 ? 0.0f : kNoForeground;
  });
  if (n == 0) return d2;
  const auto nx = static_cast<std::size_t>(dims.x()), ny = static_cast<std::size_t>(dims.y());
  for (int axis = 0; axis < 3; ++axis) {
    const std::size_t lines = n / static_cast<std::size_t>(dims[axis]);
    const std::size_t stride = axis == 0 ? 1 : axis == 1 ? nx : nx * ny;
    const auto len = static_cast<std::size_t>(dims[axis]);
    parallelFor(0, lines, 64, [&](std::size_t b, std::size_t e) {
      std::vector<double> real(3 * len + 1);
      std::vector<int> index(len);
      double* f = real.data();
      double* d = f + len;
      double* z = d + len;  // len + 1 entries
      for (std::size_t l = b; l < e; ++l) {
        const std::size_t base = axis == 0 ? l * nx : axis == 1 ? (l % nx) + nx * ny * (l / nx) : l;
        bool any = false;
        for (std::size_t t = 0; t < len; ++t) {
          f[t] = d2[base + stride * t];
          any = any || f[t] < kNoForeground;
        }
        if (!any) continue;
        distanceTransform1d(f, d, static_cast<int>(len), spacing[axis], index.data(), z);
        for (std::size_t t = 0; t < len; ++t)
          d2[base + stride * t] = static_cast<float>(std::min(d[t], double(kNoForeground)));
      }
    });
  }
  return d2;
}

}  // namespace dm
