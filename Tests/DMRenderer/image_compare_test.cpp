// Image comparison and the golden-image workflow.
#include <dm/io/image_io.hpp>
#include <dm/renderer/image_compare.hpp>

#include <cstdlib>
#include <filesystem>

#include "render_fixture.hpp"

namespace {

dm::Image solid(int w, int h, int channels, std::uint8_t v) {
  dm::Image img = *dm::Image::create(w, h, channels, dm::PixelType::U8);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < channels; ++c) img.at<std::uint8_t>(x, y, c) = v;
  return img;
}

}  // namespace

TEST(ImageCompare, CountsPixelsOverTheThreshold) {
  dm::Image a = solid(10, 10, 3, 100), b = solid(10, 10, 3, 100);
  b.at<std::uint8_t>(2, 3, 1) = 110;  // 10 over: counts at threshold 8
  b.at<std::uint8_t>(5, 5, 0) = 105;  // 5 over: does not
  auto d = dm::compareImages(a, b, {.pixelThreshold = 8, .maxFraction = 0.0});
  ASSERT_TRUE(d) << d.error();
  EXPECT_EQ(d->differing, 1u);
  EXPECT_EQ(d->total, 100u);
  EXPECT_EQ(d->maxDifference, 10);
  EXPECT_NEAR(d->meanDifference, 15.0 / 100, 1e-12);
  EXPECT_FALSE(d->passed);
  EXPECT_TRUE(dm::compareImages(a, b, {.pixelThreshold = 8, .maxFraction = 0.01})->passed);
  // The diff image marks the differing pixel red.
  EXPECT_EQ(d->diff.at<std::uint8_t>(2, 3, 0), 255);
  EXPECT_EQ(d->diff.at<std::uint8_t>(2, 3, 1), 0);
  EXPECT_NE(d->diff.at<std::uint8_t>(5, 5, 1), 0);
}

TEST(ImageCompare, IgnoresAlphaAndRefusesMismatchedImages) {
  dm::Image rgba = solid(4, 4, 4, 50), rgb = solid(4, 4, 3, 50);
  rgba.at<std::uint8_t>(1, 1, 3) = 0;
  EXPECT_EQ(dm::compareImages(rgba, rgb)->differing, 0u);
  auto size = dm::compareImages(solid(4, 4, 3, 0), solid(5, 4, 3, 0));
  ASSERT_FALSE(size);
  EXPECT_NE(size.error().what.find("4x4"), std::string::npos);
  EXPECT_FALSE(dm::compareImages(solid(4, 4, 1, 0), solid(4, 4, 3, 0)));
}

TEST(ImageCompare, CoveredPixelsCountsNonBackground) {
  dm::Image img = solid(8, 8, 4, 0);
  for (int x = 0; x < 3; ++x) img.at<std::uint8_t>(x, 2, 1) = 200;
  EXPECT_EQ(dm::countCoveredPixels(img, dm::Vec3f(0, 0, 0)), 3u);
  EXPECT_EQ(dm::countCoveredPixels(img, dm::Vec3f(0, 200, 0)), 61u);
}

TEST(Golden, MissingReferenceSaysHowToCreateIt) {
  ::unsetenv("DM_UPDATE_GOLDEN");
  const auto dir = std::filesystem::temp_directory_path() / "dm_golden_test_missing";
  std::filesystem::remove_all(dir);
  auto s = dm::checkGolden(solid(4, 4, 3, 7), dir / "none.png", dir);
  ASSERT_FALSE(s);
  EXPECT_EQ(s.error().code, dm::ErrorCode::NotFound);
  EXPECT_NE(s.error().hint.find("DM_UPDATE_GOLDEN=1"), std::string::npos);
}

TEST(Golden, UpdateWritesThenCheckPassesAndAFailureWritesActualAndDiff) {
  const auto dir = std::filesystem::temp_directory_path() / "dm_golden_test_update";
  std::filesystem::remove_all(dir);
  const auto ref = dir / "ref" / "square.png";
  {
    // Unset again however this block ends: a leftover DM_UPDATE_GOLDEN=1
    // would rewrite every later test's reference.
    struct Unset {
      ~Unset() { ::unsetenv("DM_UPDATE_GOLDEN"); }
    } unset;
    ::setenv("DM_UPDATE_GOLDEN", "1", 1);
    EXPECT_TRUE(dm::checkGolden(solid(16, 16, 3, 90), ref, dir / "out"));
  }
  EXPECT_TRUE(dm::checkGolden(solid(16, 16, 3, 95), ref, dir / "out"));  // within 8
  dm::Image changed = solid(16, 16, 3, 90);
  for (int x = 0; x < 16; ++x) changed.at<std::uint8_t>(x, 0, 0) = 0;
  auto s = dm::checkGolden(changed, ref, dir / "out", {.pixelThreshold = 8, .maxFraction = 0.01});
  ASSERT_FALSE(s);
  EXPECT_NE(s.error().what.find("16 of 256"), std::string::npos) << s.error().what;
  EXPECT_TRUE(std::filesystem::exists(dir / "out" / "square.actual.png"));
  EXPECT_TRUE(std::filesystem::exists(dir / "out" / "square.diff.png"));
  auto back = dm::readPng(dir / "out" / "square.actual.png");
  ASSERT_TRUE(back);
  EXPECT_EQ(back->at<std::uint8_t>(3, 0, 0), 0);
}
