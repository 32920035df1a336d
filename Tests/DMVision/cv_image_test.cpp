// dm::Image <-> cv::Mat without copies: same memory, strides and ROIs.
#include <dm/vision/cv_image.hpp>

#include <gtest/gtest.h>

#include <cstdint>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <vector>

namespace {

TEST(CvImage, MatOverImageSharesMemoryBothWays) {
  auto img = dm::Image::create(64, 48, 3, dm::PixelType::U8);
  ASSERT_TRUE(img);
  cv::Mat m = dm::asCvMat(*img);
  EXPECT_EQ(m.type(), CV_8UC3);
  EXPECT_EQ(m.cols, 64);
  EXPECT_EQ(m.rows, 48);
  EXPECT_EQ(static_cast<const void*>(m.data), static_cast<const void*>(img->data()));
  EXPECT_EQ(m.step[0], img->strideBytes());
  m.at<cv::Vec3b>(5, 7) = cv::Vec3b(1, 2, 3);  // row 5, column 7
  EXPECT_EQ(img->at<std::uint8_t>(7, 5, 0), 1);
  EXPECT_EQ(img->at<std::uint8_t>(7, 5, 2), 3);
  img->at<std::uint8_t>(10, 20, 1) = 99;
  EXPECT_EQ(m.at<cv::Vec3b>(20, 10)[1], 99);
  // An OpenCV algorithm writing in place changes the image.
  cv::rectangle(m, cv::Rect(30, 30, 4, 4), cv::Scalar(200, 201, 202), cv::FILLED);
  EXPECT_EQ(img->at<std::uint8_t>(31, 32, 2), 202);
}

TEST(CvImage, PixelTypesMapToOpenCvDepths) {
  struct Case {
    dm::PixelType type;
    int channels;
    int cvType;
  };
  for (const Case& c : {Case{dm::PixelType::U8, 1, CV_8UC1}, Case{dm::PixelType::U16, 2, CV_16UC2},
                        Case{dm::PixelType::F32, 4, CV_32FC4}, Case{dm::PixelType::F32, 1, CV_32FC1}}) {
    auto img = dm::Image::create(5, 3, c.channels, c.type);
    ASSERT_TRUE(img);
    const cv::Mat m = dm::asCvMat(*img);
    EXPECT_EQ(m.type(), c.cvType);
    EXPECT_EQ(m.elemSize(), img->pixelBytes());
    auto back = dm::wrapCvMat(m);
    ASSERT_TRUE(back) << back.error();
    EXPECT_EQ(back->type(), c.type);
    EXPECT_EQ(back->channels(), c.channels);
  }
  EXPECT_TRUE(dm::asCvMat(dm::Image{}).empty());
}

TEST(CvImage, ViewsBecomeRoisWithTheParentStride) {
  auto img = dm::Image::create(100, 80, 1, dm::PixelType::U16);
  ASSERT_TRUE(img);
  for (int y = 0; y < 80; ++y)
    for (int x = 0; x < 100; ++x) img->at<std::uint16_t>(x, y) = static_cast<std::uint16_t>(1000 * y + x);
  const dm::Image view = img->view(10, 20, 30, 15);
  const cv::Mat m = dm::asCvMat(view);
  EXPECT_EQ(m.cols, 30);
  EXPECT_EQ(m.rows, 15);
  EXPECT_EQ(m.step[0], 200u);  // the parent's row, not 30 pixels
  EXPECT_FALSE(m.isContinuous());
  EXPECT_EQ(m.at<std::uint16_t>(0, 0), 1000 * 20 + 10);
  EXPECT_EQ(m.at<std::uint16_t>(14, 29), 1000 * 34 + 39);
  // The same region through OpenCV's own ROI is the same memory.
  const cv::Mat whole = dm::asCvMat(*img);
  const cv::Mat roi = whole(cv::Rect(10, 20, 30, 15));
  EXPECT_EQ(roi.data, m.data);
  EXPECT_EQ(cv::norm(roi, m, cv::NORM_INF), 0.0);
}

TEST(CvImage, ImageOverMatKeepsTheMatAlive) {
  dm::Image img;
  const void* data = nullptr;
  {
    cv::Mat m(40, 50, CV_32FC1, cv::Scalar(0.5f));
    data = m.data;
    auto wrapped = dm::wrapCvMat(m);
    ASSERT_TRUE(wrapped) << wrapped.error();
    img = *wrapped;
    EXPECT_EQ(static_cast<const void*>(img.data()), data);
    m.at<float>(3, 4) = 7.0f;
    EXPECT_EQ(img.at<float>(4, 3), 7.0f);
    img.at<float>(1, 2) = -2.0f;
    EXPECT_EQ(m.at<float>(2, 1), -2.0f);
  }  // the Mat is gone; its buffer lives on in the image's owner
  EXPECT_EQ(static_cast<const void*>(img.data()), data);
  EXPECT_EQ(img.at<float>(4, 3), 7.0f);
  EXPECT_EQ(img.at<float>(49, 39), 0.5f);
  // Views of the wrap share its buffer.
  EXPECT_TRUE(img.view(1, 1, 10, 10).sharesMemoryWith(img));
}

TEST(CvImage, MatRoiWrapsWithItsStride) {
  cv::Mat m(60, 70, CV_8UC4);
  cv::randu(m, 0, 255);
  const cv::Mat roi = m(cv::Rect(5, 6, 20, 10));
  auto img = dm::wrapCvMat(roi);
  ASSERT_TRUE(img) << img.error();
  EXPECT_EQ(img->width(), 20);
  EXPECT_EQ(img->height(), 10);
  EXPECT_EQ(img->channels(), 4);
  EXPECT_EQ(img->strideBytes(), 70u * 4u);
  EXPECT_EQ(static_cast<const void*>(img->data()), static_cast<const void*>(roi.data));
  for (int c = 0; c < 4; ++c) EXPECT_EQ(img->at<std::uint8_t>(19, 9, c), m.at<cv::Vec4b>(15, 24)[c]);
  // Round trip: the Mat over the wrap is the ROI.
  const cv::Mat again = dm::asCvMat(*img);
  EXPECT_EQ(again.data, roi.data);
  EXPECT_EQ(again.step[0], roi.step[0]);
}

TEST(CvImage, UnsupportedMatsAreErrors) {
  EXPECT_FALSE(dm::wrapCvMat(cv::Mat()));
  auto f64 = dm::wrapCvMat(cv::Mat(4, 4, CV_64F));
  ASSERT_FALSE(f64);
  EXPECT_EQ(f64.error().code, dm::ErrorCode::Unsupported);
  EXPECT_NE(f64.error().hint.find("convertTo"), std::string::npos);
  EXPECT_FALSE(dm::wrapCvMat(cv::Mat(4, 4, CV_8UC(5))));
  const int sizes[3] = {2, 3, 4};
  EXPECT_FALSE(dm::wrapCvMat(cv::Mat(3, sizes, CV_8U)));
}

}  // namespace
