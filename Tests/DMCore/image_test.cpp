#include <dm/core/image.hpp>

#include <gtest/gtest.h>

#include <cstdint>
#include <vector>

namespace {

TEST(Image, ViewsShareMemoryWithoutCopy) {
  auto img = dm::Image::create(8, 6, 3, dm::PixelType::U8);
  ASSERT_TRUE(img);
  EXPECT_TRUE(img->isContiguous());
  EXPECT_EQ(img->strideBytes(), 24u);
  dm::Image roi = img->view(2, 1, 4, 3);
  EXPECT_EQ(roi.width(), 4);
  EXPECT_EQ(roi.height(), 3);
  EXPECT_FALSE(roi.isContiguous());
  EXPECT_TRUE(roi.sharesMemoryWith(*img));
  roi.at<std::uint8_t>(0, 0, 2) = 77;
  EXPECT_EQ(img->at<std::uint8_t>(2, 1, 2), 77);
  dm::Image copy = roi.clone();
  EXPECT_FALSE(copy.sharesMemoryWith(*img));
  EXPECT_TRUE(copy.isContiguous());
  EXPECT_EQ(copy.at<std::uint8_t>(0, 0, 2), 77);
  // Clipped view.
  EXPECT_EQ(img->view(6, 4, 10, 10).width(), 2);
  EXPECT_TRUE(img->view(20, 20, 1, 1).empty());
}

TEST(Image, WrapsForeignStridedMemory) {
  std::vector<float> buf(5 * 16, 0.f);  // 5 rows of 16 floats, 3 used (padding)
  buf[2 * 16 + 1] = 3.5f;
  auto img = dm::Image::wrap(buf.data(), 3, 5, 1, dm::PixelType::F32, 16 * sizeof(float), nullptr);
  ASSERT_TRUE(img);
  EXPECT_FLOAT_EQ(img->at<float>(1, 2), 3.5f);
  auto bad = dm::Image::wrap(buf.data(), 20, 5, 1, dm::PixelType::F32, 16 * sizeof(float), nullptr);
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.error().what.find("stride 64 is smaller than a row of 80 bytes"), std::string::npos);
}

TEST(Image, RejectsBadSizes) {
  EXPECT_FALSE(dm::Image::create(0, 5, 1, dm::PixelType::U8));
  EXPECT_FALSE(dm::Image::create(5, 5, 5, dm::PixelType::U8));
  EXPECT_FALSE(dm::Image::create(1 << 20, 1 << 20, 4, dm::PixelType::F32));
}

}  // namespace
