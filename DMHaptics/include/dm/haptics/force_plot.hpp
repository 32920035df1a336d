// dm/haptics/force_plot.hpp — line and point plots drawn into an RGB image
// with axes, grid lines, a legend and labels in a built-in 3×5 pixel font,
// ready for dm::writePng: plotSeries for any y(x) series (a
// force–displacement curve, measured points against a fit), and
// plotForceTrace, the force components and magnitude over time
// (`dmtool probe --plot`, the main job's force plot).
//
// @code
//   auto image = dm::plotForceTrace(samples);
//   if (image) dm::writePng(*image, "forces.png");
// @endcode
#pragma once

#include <dm/core/image.hpp>
#include <dm/core/result.hpp>
#include <dm/haptics/probe.hpp>

#include <array>
#include <cstdint>
#include <span>
#include <string_view>

namespace dm {

/// One series of plotSeries: y against x. Text is drawn in the built-in
/// font (digits, A–Z, . - + | ( ) / and space, lower-case e m s t); other
/// characters are left blank.
struct PlotSeries {
  std::string_view name;                 ///< legend
  std::array<std::uint8_t, 3> color{};   ///< RGB
  std::span<const double> x, y;          ///< equal sizes; a non-finite point breaks the line
  bool points = false;                   ///< crosses at the points instead of a polyline
};

/// Axis labels and range of plotSeries.
struct PlotAxes {
  std::string_view xUnit = "s";  ///< under the x axis, at its right end
  std::string_view yUnit = "N";  ///< above the y axis
  bool includeZero = true;       ///< the y range includes 0
};

/// Plots `series` into a width × height RGB8 image; the x range is the data's,
/// the y range the data's (with 0 when axes.includeZero). Fails with
/// InvalidArgument when a series' x and y sizes differ, when there is no
/// finite point, or when the image is smaller than 200 × 120.
/// @code
///   const dm::PlotSeries s[] = {{"MEASURED", {30, 60, 220}, d, f, true}, {"FIT", {220, 30, 30}, d, fit}};
///   auto image = dm::plotSeries(s, {.xUnit = "mm", .yUnit = "N"});
/// @endcode
Result<Image> plotSeries(std::span<const PlotSeries> series, const PlotAxes& axes = {}, int width = 900,
                         int height = 420);

/// Plots fx (red), fy (green), fz (blue) and |F| (black) of `samples` against
/// t into a width × height RGB8 image. Fails with InvalidArgument when there
/// are no samples or the image is smaller than 200 × 120.
Result<Image> plotForceTrace(std::span<const ProbeSample> samples, int width = 900, int height = 420);

}  // namespace dm
