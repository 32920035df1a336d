// dm/vision/cv_image.hpp — the OpenCV bridge: dm::Image as cv::Mat and back,
// without copying pixels.
//
// OPT-IN HEADER. This is the only public DMVision header that includes an
// OpenCV header (<opencv2/core/mat.hpp>). Include it only in translation units
// that use OpenCV themselves. DM::Vision links OpenCV PRIVATELY, so a target
// that includes this header must find OpenCV and link opencv_core itself:
//   find_package(OpenCV REQUIRED COMPONENTS core)
//   target_link_libraries(app PRIVATE DM::Vision ${OpenCV_LIBS})
//   target_include_directories(app SYSTEM PRIVATE ${OpenCV_INCLUDE_DIRS})
// Every other DMVision header (stereo, markers, classify) exposes only dm::
// and standard types.
//
// Pixel types map one to one: U8 ↔ CV_8U, U16 ↔ CV_16U, F32 ↔ CV_32F, with
// 1..4 interleaved channels (CV_8UC3 etc.). Rows keep their stride, so views
// (sub-rectangles) map to Mat ROIs and back.
//
// @code
//   auto img = dm::Image::create(640, 480, 1, dm::PixelType::U8);
//   cv::Mat m = dm::asCvMat(*img);                 // same memory
//   cv::GaussianBlur(m, m, {5, 5}, 1.0);           // writes into img
// @endcode
#pragma once

#include <dm/core/image.hpp>
#include <dm/core/result.hpp>

#include <opencv2/core/mat.hpp>

namespace dm {

/// OpenCV depth (CV_8U, CV_16U, CV_32F) of a pixel type. O(1).
int cvDepthOf(PixelType type) noexcept;

/// A cv::Mat header over `image`'s memory: same data pointer, step =
/// strideBytes(), type = depth × channels. No copy, O(1). The Mat does NOT
/// keep the memory alive: keep `image` (or a view sharing its buffer) alive
/// while the Mat is used. Writes through either are visible in the other.
/// An empty image gives an empty Mat. `const` images are exposed writable
/// because cv::Mat has no const view; do not write through it.
/// @code
///   cv::Mat m = dm::asCvMat(img);
///   cv::Mat roi = m(cv::Rect(10, 10, 32, 32));   // still the same memory
/// @endcode
cv::Mat asCvMat(const Image& image);

/// A one-channel cv::Mat of `image`: the image's own memory (as asCvMat)
/// when it has one channel, else a new gray Mat converted from BGR (3
/// channels) or BGRA (4). O(pixels) for the conversion. Empty image, or 2
/// channels (gray + alpha: no defined conversion), give an empty Mat.
/// @code
///   cv::Mat gray = dm::asCvGray(frame);
///   cv::findChessboardCorners(gray, {9, 6}, corners);
/// @endcode
cv::Mat asCvGray(const Image& image);

/// A dm::Image over `mat`'s memory: same data pointer and row stride. The
/// image holds a reference to the Mat's buffer (a cv::Mat copy — reference
/// counted, no pixel copy), so it stays valid after `mat` goes away; Mats
/// that wrap foreign memory (no allocator) are the caller's to keep alive.
/// O(1). Fails with Unsupported on depths other than 8U/16U/32F or more than
/// 4 channels (convert first with Mat::convertTo), and InvalidArgument on an
/// empty Mat or one that is not 2-D.
/// @code
///   cv::Mat frame = cv::imread("left01.jpg", cv::IMREAD_GRAYSCALE);
///   auto img = dm::wrapCvMat(frame);
///   if (img) use(*img);
/// @endcode
Result<Image> wrapCvMat(const cv::Mat& mat);

}  // namespace dm
