// The OpenCV bridge (see dm/vision/cv_image.hpp).
#include <dm/vision/cv_image.hpp>

#include <memory>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <string>

namespace dm {

int cvDepthOf(PixelType type) noexcept {
  switch (type) {
    case PixelType::U8:
      return CV_8U;
    case PixelType::U16:
      return CV_16U;
    case PixelType::F32:
      return CV_32F;
  }
  return CV_8U;
}

cv::Mat asCvMat(const Image& image) {
  if (image.empty()) return {};
  // cv::Mat has no const header; the caller owns the constness contract.
  void* data = const_cast<std::byte*>(image.data());
  return cv::Mat(image.height(), image.width(), CV_MAKETYPE(cvDepthOf(image.type()), image.channels()), data,
                 image.strideBytes());
}

cv::Mat asCvGray(const Image& image) {
  if (image.empty() || image.channels() == 2) return {};
  cv::Mat m = asCvMat(image);
  if (m.channels() == 1) return m;
  cv::Mat gray;
  cv::cvtColor(m, gray, m.channels() == 4 ? cv::COLOR_BGRA2GRAY : cv::COLOR_BGR2GRAY);
  return gray;
}

Result<Image> wrapCvMat(const cv::Mat& mat) {
  if (mat.empty()) return fail(ErrorCode::InvalidArgument, "empty cv::Mat", "wrapCvMat");
  if (mat.dims != 2)
    return fail(ErrorCode::InvalidArgument, "cv::Mat has " + std::to_string(mat.dims) + " dimensions",
                "wrapCvMat", "only 2-D images can be wrapped");
  PixelType type;
  switch (mat.depth()) {
    case CV_8U:
      type = PixelType::U8;
      break;
    case CV_16U:
      type = PixelType::U16;
      break;
    case CV_32F:
      type = PixelType::F32;
      break;
    default:
      return fail(ErrorCode::Unsupported,
                  "cv::Mat depth " + std::to_string(mat.depth()) + " has no dm::PixelType", "wrapCvMat",
                  "convert to CV_8U, CV_16U or CV_32F with Mat::convertTo first");
  }
  if (mat.channels() > 4)
    return fail(ErrorCode::Unsupported, std::to_string(mat.channels()) + " channels (at most 4)", "wrapCvMat",
                "split the channels with cv::split first");
  // The shared_ptr owns a Mat copy: that holds a reference on the Mat's buffer.
  auto owner = std::make_shared<cv::Mat>(mat);
  void* data = owner->data;  // read before the owner is moved into the call
  return Image::wrap(data, mat.cols, mat.rows, mat.channels(), type, mat.step[0], std::move(owner));
}

}  // namespace dm
