// Force-trace plot (dm/haptics/force_plot.hpp).
#include <dm/haptics/force_plot.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <string_view>

namespace dm {
namespace {

using Rgb = std::array<std::uint8_t, 3>;

// 3×5 glyphs, one row per 3 bits (MSB left), rows top to bottom.
struct Glyph {
  char c;
  std::array<std::uint8_t, 5> rows;
};
constexpr Glyph kFont[] = {
    {'0', {7, 5, 5, 5, 7}}, {'1', {2, 6, 2, 2, 7}}, {'2', {7, 1, 7, 4, 7}}, {'3', {7, 1, 7, 1, 7}},
    {'4', {5, 5, 7, 1, 1}}, {'5', {7, 4, 7, 1, 7}}, {'6', {7, 4, 7, 5, 7}}, {'7', {7, 1, 1, 1, 1}},
    {'8', {7, 5, 7, 5, 7}}, {'9', {7, 5, 7, 1, 7}}, {'.', {0, 0, 0, 0, 2}}, {'-', {0, 0, 7, 0, 0}},
    {'+', {0, 2, 7, 2, 0}}, {'e', {0, 7, 7, 4, 7}}, {'F', {7, 4, 6, 4, 4}}, {'X', {5, 5, 2, 5, 5}},
    {'Y', {5, 5, 2, 2, 2}}, {'Z', {7, 1, 2, 4, 7}}, {'|', {2, 2, 2, 2, 2}}, {'N', {5, 7, 7, 7, 5}},
    {'s', {0, 3, 6, 1, 6}}, {'t', {2, 7, 2, 2, 3}}, {' ', {0, 0, 0, 0, 0}},
};

class Canvas {
 public:
  explicit Canvas(Image& image) : img_(image) {}
  void pixel(int x, int y, const Rgb& c) {
    if (x < 0 || y < 0 || x >= img_.width() || y >= img_.height()) return;
    for (int k = 0; k < 3; ++k) img_.at<std::uint8_t>(x, y, k) = c[static_cast<std::size_t>(k)];
  }
  // Bresenham.
  void line(int x0, int y0, int x1, int y1, const Rgb& c) {
    const int dx = std::abs(x1 - x0), sx = x0 < x1 ? 1 : -1;
    const int dy = -std::abs(y1 - y0), sy = y0 < y1 ? 1 : -1;
    int err = dx + dy;
    for (;;) {
      pixel(x0, y0, c);
      if (x0 == x1 && y0 == y1) return;
      const int e2 = 2 * err;
      if (e2 >= dy) err += dy, x0 += sx;
      if (e2 <= dx) err += dx, y0 += sy;
    }
  }
  // Text at 2× scale, top-left at (x, y).
  void text(int x, int y, std::string_view s, const Rgb& c) {
    for (char ch : s) {
      const Glyph* g =
          std::find_if(std::begin(kFont), std::end(kFont), [ch](const Glyph& f) { return f.c == ch; });
      if (g != std::end(kFont))
        for (int r = 0; r < 5; ++r)
          for (int b = 0; b < 3; ++b)
            if (g->rows[static_cast<std::size_t>(r)] & (4 >> b))
              for (int u = 0; u < 2; ++u)
                for (int v = 0; v < 2; ++v) pixel(x + 2 * b + u, y + 2 * r + v, c);
      x += 8;
    }
  }

 private:
  Image& img_;
};

// A "nice" grid step (1, 2 or 5 × 10^k) giving about `count` intervals over `range`.
double niceStep(double range, int count) {
  const double raw = range / count;
  const double p = std::pow(10.0, std::floor(std::log10(raw)));
  const double m = raw / p;
  return (m < 1.5 ? 1.0 : m < 3.5 ? 2.0 : m < 7.5 ? 5.0 : 10.0) * p;
}

std::string_view format(char* buf, std::size_t n, double v) {
  const int len = std::snprintf(buf, n, "%.3g", std::abs(v) < 1e-12 ? 0.0 : v);
  return {buf, static_cast<std::size_t>(std::max(len, 0))};
}

}  // namespace

Result<Image> plotForceTrace(std::span<const ProbeSample> samples, int width, int height) {
  if (samples.empty()) return fail(ErrorCode::InvalidArgument, "no samples to plot", "--plot");
  if (width < 200 || height < 120)
    return fail(ErrorCode::InvalidArgument, formatString("plot size %dx%d is below 200x120", width, height),
                "--plot");
  auto image = Image::create(width, height, 3, PixelType::U8);
  if (!image) return image.error();
  std::fill(image->data(), image->data() + image->strideBytes() * static_cast<std::size_t>(height),
            std::byte{255});
  Canvas canvas(*image);

  double fmin = 0.0, fmax = 0.0;
  for (const ProbeSample& s : samples) {
    const Vec3& f = s.response.force;
    if (!f.allFinite()) continue;
    fmin = std::min({fmin, f.minCoeff()});
    fmax = std::max({fmax, f.maxCoeff(), f.norm()});
  }
  if (fmax - fmin < 1e-9) fmax = fmin + 1.0;
  const double t0 = samples.front().t, t1 = std::max(samples.back().t, t0 + 1e-9);
  const int left = 70, right = width - 20, top = 34, bottom = height - 34;
  const auto px = [&](double t) {
    return left + static_cast<int>(std::lround((t - t0) / (t1 - t0) * (right - left)));
  };
  const auto py = [&](double f) {
    return bottom - static_cast<int>(std::lround((f - fmin) / (fmax - fmin) * (bottom - top)));
  };

  const Rgb grid{225, 225, 225}, axis{0, 0, 0};
  char buf[32];
  const double fs = niceStep(fmax - fmin, 6);
  for (double f = std::ceil(fmin / fs) * fs; f <= fmax + 1e-12; f += fs) {
    canvas.line(left, py(f), right, py(f), grid);
    canvas.text(4, py(f) - 5, format(buf, sizeof buf, f), axis);
  }
  const double ts = niceStep(t1 - t0, 8);
  for (double t = std::ceil(t0 / ts) * ts; t <= t1 + 1e-12; t += ts) {
    canvas.line(px(t), top, px(t), bottom, grid);
    canvas.text(px(t) - 8, bottom + 8, format(buf, sizeof buf, t), axis);
  }
  canvas.line(left, top, left, bottom, axis);
  canvas.line(left, py(0.0), right, py(0.0), axis);
  canvas.text(4, 8, "N", axis);
  canvas.text(right - 8, bottom + 20, "s", axis);

  const Rgb colors[4] = {{220, 30, 30}, {30, 160, 30}, {30, 60, 220}, {0, 0, 0}};
  const char* names[4] = {"FX", "FY", "FZ", "|F|"};
  for (int k = 0; k < 4; ++k) {
    canvas.line(left + 20 + 90 * k, 14, left + 44 + 90 * k, 14, colors[k]);
    canvas.text(left + 50 + 90 * k, 9, names[k], colors[k]);
    int x0 = 0, y0 = 0;
    bool have = false;
    for (const ProbeSample& s : samples) {
      const Vec3& f = s.response.force;
      if (!f.allFinite()) {
        have = false;
        continue;
      }
      const int x = px(s.t), y = py(k < 3 ? f[k] : f.norm());
      if (have) canvas.line(x0, y0, x, y, colors[k]);
      x0 = x, y0 = y, have = true;
    }
  }
  return image;
}

}  // namespace dm
