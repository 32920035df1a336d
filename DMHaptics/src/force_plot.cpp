// Force-trace plot (dm/haptics/force_plot.hpp).
#include <dm/haptics/force_plot.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <string_view>
#include <vector>

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
    {'s', {0, 3, 6, 1, 6}}, {'t', {2, 7, 2, 2, 3}}, {' ', {0, 0, 0, 0, 0}}, {'A', {2, 5, 7, 5, 5}},
    {'B', {6, 5, 6, 5, 6}}, {'C', {3, 4, 4, 4, 3}}, {'D', {6, 5, 5, 5, 6}}, {'E', {7, 4, 6, 4, 7}},
    {'G', {3, 4, 5, 5, 3}}, {'H', {5, 5, 7, 5, 5}}, {'I', {7, 2, 2, 2, 7}}, {'J', {1, 1, 1, 5, 2}},
    {'K', {5, 5, 6, 5, 5}}, {'L', {4, 4, 4, 4, 7}}, {'M', {5, 7, 7, 5, 5}}, {'O', {2, 5, 5, 5, 2}},
    {'P', {6, 5, 6, 4, 4}}, {'Q', {2, 5, 5, 6, 3}}, {'R', {6, 5, 6, 5, 5}}, {'S', {3, 4, 2, 1, 6}},
    {'T', {7, 2, 2, 2, 2}}, {'U', {5, 5, 5, 5, 7}}, {'V', {5, 5, 5, 5, 2}}, {'W', {5, 5, 7, 7, 5}},
    {'m', {0, 0, 6, 7, 5}}, {'(', {1, 2, 2, 2, 1}}, {')', {4, 2, 2, 2, 4}}, {'/', {1, 1, 2, 4, 4}},
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

Result<Image> plotSeries(std::span<const PlotSeries> series, const PlotAxes& axes, int width, int height) {
  bool any = false;
  double xmin = std::numeric_limits<double>::infinity(), xmax = -xmin;
  double ymin = axes.includeZero ? 0.0 : xmin, ymax = axes.includeZero ? 0.0 : -xmin;
  for (const PlotSeries& s : series) {
    if (s.x.size() != s.y.size())
      return fail(ErrorCode::InvalidArgument,
                  formatString("series \"%.*s\" has %zu x and %zu y values", static_cast<int>(s.name.size()),
                               s.name.data(), s.x.size(), s.y.size()),
                  "plotSeries");
    for (std::size_t i = 0; i < s.x.size(); ++i) {
      if (!std::isfinite(s.x[i]) || !std::isfinite(s.y[i])) continue;
      any = true;
      xmin = std::min(xmin, s.x[i]), xmax = std::max(xmax, s.x[i]);
      ymin = std::min(ymin, s.y[i]), ymax = std::max(ymax, s.y[i]);
    }
  }
  if (!any) return fail(ErrorCode::InvalidArgument, "no samples to plot", "--plot");
  if (width < 200 || height < 120)
    return fail(ErrorCode::InvalidArgument, formatString("plot size %dx%d is below 200x120", width, height),
                "--plot");
  auto image = Image::create(width, height, 3, PixelType::U8);
  if (!image) return image.error();
  std::fill(image->data(), image->data() + image->strideBytes() * static_cast<std::size_t>(height),
            std::byte{255});
  Canvas canvas(*image);

  if (ymax - ymin < 1e-9) ymax = ymin + 1.0;
  if (xmax - xmin < 1e-9) xmax = xmin + 1e-9;
  const int left = 70, right = width - 20, top = 34, bottom = height - 34;
  const auto px = [&](double x) {
    return left + static_cast<int>(std::lround((x - xmin) / (xmax - xmin) * (right - left)));
  };
  const auto py = [&](double y) {
    return bottom - static_cast<int>(std::lround((y - ymin) / (ymax - ymin) * (bottom - top)));
  };

  const Rgb grid{225, 225, 225}, axis{0, 0, 0};
  char buf[32];
  const double ys = niceStep(ymax - ymin, 6);
  for (double y = std::ceil(ymin / ys) * ys; y <= ymax + 1e-12; y += ys) {
    canvas.line(left, py(y), right, py(y), grid);
    canvas.text(4, py(y) - 5, format(buf, sizeof buf, y), axis);
  }
  const double xs = niceStep(xmax - xmin, 8);
  for (double x = std::ceil(xmin / xs) * xs; x <= xmax + 1e-12; x += xs) {
    canvas.line(px(x), top, px(x), bottom, grid);
    canvas.text(px(x) - 8, bottom + 8, format(buf, sizeof buf, x), axis);
  }
  canvas.line(left, top, left, bottom, axis);
  if (ymin <= 0.0 && ymax >= 0.0) canvas.line(left, py(0.0), right, py(0.0), axis);
  canvas.text(4, 8, axes.yUnit, axis);
  canvas.text(right - 8 * static_cast<int>(axes.xUnit.size()), bottom + 20, axes.xUnit, axis);

  int legend = left + 20;
  for (const PlotSeries& s : series) {
    if (s.points) {
      canvas.line(legend + 9, 11, legend + 15, 17, s.color);
      canvas.line(legend + 9, 17, legend + 15, 11, s.color);
    } else {
      canvas.line(legend, 14, legend + 24, 14, s.color);
    }
    canvas.text(legend + 30, 9, s.name, s.color);
    legend += 50 + 8 * static_cast<int>(s.name.size());
    int x0 = 0, y0 = 0;
    bool have = false;
    for (std::size_t i = 0; i < s.x.size(); ++i) {
      if (!std::isfinite(s.x[i]) || !std::isfinite(s.y[i])) {
        have = false;
        continue;
      }
      const int x = px(s.x[i]), y = py(s.y[i]);
      if (s.points) {
        canvas.line(x - 2, y - 2, x + 2, y + 2, s.color);
        canvas.line(x - 2, y + 2, x + 2, y - 2, s.color);
        continue;
      }
      if (have) canvas.line(x0, y0, x, y, s.color);
      x0 = x, y0 = y, have = true;
    }
  }
  return image;
}

Result<Image> plotForceTrace(std::span<const ProbeSample> samples, int width, int height) {
  if (samples.empty()) return fail(ErrorCode::InvalidArgument, "no samples to plot", "--plot");
  std::vector<double> t(samples.size()), f[4];
  for (auto& v : f) v.resize(samples.size());
  const double nan = std::numeric_limits<double>::quiet_NaN();
  for (std::size_t i = 0; i < samples.size(); ++i) {
    const Vec3& force = samples[i].response.force;
    t[i] = samples[i].t;
    const bool finite = force.allFinite();
    for (int k = 0; k < 3; ++k) f[k][i] = finite ? force[k] : nan;
    f[3][i] = finite ? force.norm() : nan;
  }
  const PlotSeries series[4] = {{"FX", {220, 30, 30}, t, f[0]},
                                {"FY", {30, 160, 30}, t, f[1]},
                                {"FZ", {30, 60, 220}, t, f[2]},
                                {"|F|", {0, 0, 0}, t, f[3]}};
  return plotSeries(series, {.xUnit = "s", .yUnit = "N"}, width, height);
}

}  // namespace dm
