// The force plot draws each component where its value maps: a ramp of fz
// from 0 to 10 N over 1 s must put blue pixels on the straight line between
// the plot's (t = 0, 0 N) and (t = 1, 10 N) corners.
#include <dm/haptics/force_plot.hpp>

#include <gtest/gtest.h>

#include <cstdint>
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

}  // namespace
}  // namespace dm
