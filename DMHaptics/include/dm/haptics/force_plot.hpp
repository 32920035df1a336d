// dm/haptics/force_plot.hpp — a force-trace plot (`dmtool probe --plot`, the
// main job's force plot): force components and magnitude over time, drawn
// into an RGB image with axes, grid lines and labels in a built-in 3×5 pixel
// font, ready for dm::writePng.
//
// @code
//   auto image = dm::plotForceTrace(samples);
//   if (image) dm::writePng(*image, "forces.png");
// @endcode
#pragma once

#include <dm/core/image.hpp>
#include <dm/core/result.hpp>
#include <dm/haptics/probe.hpp>

#include <span>

namespace dm {

/// Plots fx (red), fy (green), fz (blue) and |F| (black) of `samples` against
/// t into a width × height RGB8 image. Fails with InvalidArgument when there
/// are no samples or the image is smaller than 200 × 120.
Result<Image> plotForceTrace(std::span<const ProbeSample> samples, int width = 900, int height = 420);

}  // namespace dm
