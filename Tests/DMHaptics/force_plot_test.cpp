// The force plot draws each component where its value maps: a ramp of fz
// from 0 to 10 N over 1 s must put blue pixels on the straight line between
// the plot's (t = 0, 0 N) and (t = 1, 10 N) corners.
#include <dm/haptics/force_plot.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

namespace dm {
namespace {

bool isBlue(const Image& img, int x, int y) {
  return img.at<std::uint8_t>(x, y, 0) == 30 && img.at<std::uint8_t>(x, y, 1) == 60 &&
         img.at<std::uint8_t>(x, y, 2) == 220;
}

TEST(ForcePlot, RampIsDrawnOnItsLine) {
  std::vector<ProbeSample> samples(101);
  for (int i = 0; i <= 100; ++i) {
    samples[i].t = 0.01 * i;
    samples[i].response.force = Vec3(0, 0, 0.1 * i);
  }
  const auto img = plotForceTrace(samples, 600, 300);
  ASSERT_TRUE(img.ok()) << img.error().message();
  ASSERT_EQ(img->width(), 600);
  ASSERT_EQ(img->height(), 300);
  // The plot area (see force_plot.cpp): x in [70, 580], y in [34, 266]; |F| = fz is drawn
  // over it in black afterwards, so look for blue or black along the line, and blue somewhere.
  int onLine = 0, blue = 0;
  for (int k = 1; k < 10; ++k) {
    const double u = 0.1 * k;
    const int x = 70 + static_cast<int>(u * 510 + 0.5);
    const int y = 266 - static_cast<int>(u * 232 + 0.5);
    for (int dy = -2; dy <= 2; ++dy) {
      const bool black = img->at<std::uint8_t>(x, y + dy, 0) == 0 && img->at<std::uint8_t>(x, y + dy, 2) == 0;
      if (black || isBlue(*img, x, y + dy)) {
        ++onLine;
        break;
      }
    }
  }
  for (int y = 0; y < 300; ++y)
    for (int x = 0; x < 600; ++x) blue += isBlue(*img, x, y);
  EXPECT_EQ(onLine, 9);
  EXPECT_GT(blue, 10);  // at least the legend swatch and label
}

TEST(ForcePlot, RefusesEmptyAndTinyPlots) {
  EXPECT_FALSE(plotForceTrace({}).ok());
  std::vector<ProbeSample> one(1);
  EXPECT_FALSE(plotForceTrace(one, 100, 50).ok());
  EXPECT_TRUE(plotForceTrace(one).ok());  // one sample, zero force: still a plot
}

// plotSeries: points are crosses centred where (x, y) maps, over the data's
// x range and a y range that includes 0.
TEST(PlotSeries, PointsLandWhereTheyMapAndBadSeriesAreRefused) {
  const std::vector<double> x = {1.0, 2.0, 3.0}, y = {2.0, 4.0, 8.0};
  const PlotSeries series[] = {{"MEASURED", {30, 60, 220}, x, y, true}};
  const auto img = plotSeries(series, {.xUnit = "mm", .yUnit = "N"}, 600, 300);
  ASSERT_TRUE(img.ok()) << img.error().message();
  // x in [1, 3] → [70, 580]; y in [0, 8] → [266, 34].
  for (std::size_t i = 0; i < x.size(); ++i) {
    const int px = 70 + static_cast<int>((x[i] - 1.0) / 2.0 * 510 + 0.5);
    const int py = 266 - static_cast<int>(y[i] / 8.0 * 232 + 0.5);
    EXPECT_TRUE(isBlue(*img, px, py)) << "point " << i;
    EXPECT_TRUE(isBlue(*img, px + 2, py + 2)) << "point " << i;
  }
  const std::vector<double> shorter = {1.0};
  const PlotSeries bad[] = {{"FIT", {0, 0, 0}, x, shorter}};
  const auto refused = plotSeries(bad);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().message().find("FIT"), std::string::npos) << refused.error().message();
  const std::vector<double> nan = {std::nan(""), std::nan(""), std::nan("")};
  const PlotSeries empty[] = {{"NAN", {0, 0, 0}, x, nan}};
  EXPECT_FALSE(plotSeries(empty).ok());
}

}  // namespace
}  // namespace dm
