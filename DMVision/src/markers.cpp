// ArUco / ChArUco detection and pose on OpenCV's aruco module, and marker
// registration through dm::registerPoints (see dm/vision/markers.hpp).
#include <dm/vision/cv_image.hpp>
#include <dm/vision/markers.hpp>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <opencv2/aruco.hpp>
#include <opencv2/aruco/charuco.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/core/eigen.hpp>
#include <opencv2/imgproc.hpp>
#include <string>
#include <utility>

namespace dm {
namespace {

struct NamedDictionary {
  const char* name;
  cv::aruco::PREDEFINED_DICTIONARY_NAME value;
};

constexpr NamedDictionary kDictionaries[] = {
    {"DICT_4X4_50", cv::aruco::DICT_4X4_50},
    {"DICT_4X4_100", cv::aruco::DICT_4X4_100},
    {"DICT_4X4_250", cv::aruco::DICT_4X4_250},
    {"DICT_4X4_1000", cv::aruco::DICT_4X4_1000},
    {"DICT_5X5_50", cv::aruco::DICT_5X5_50},
    {"DICT_5X5_100", cv::aruco::DICT_5X5_100},
    {"DICT_5X5_250", cv::aruco::DICT_5X5_250},
    {"DICT_5X5_1000", cv::aruco::DICT_5X5_1000},
    {"DICT_6X6_50", cv::aruco::DICT_6X6_50},
    {"DICT_6X6_100", cv::aruco::DICT_6X6_100},
    {"DICT_6X6_250", cv::aruco::DICT_6X6_250},
    {"DICT_6X6_1000", cv::aruco::DICT_6X6_1000},
    {"DICT_7X7_50", cv::aruco::DICT_7X7_50},
    {"DICT_7X7_100", cv::aruco::DICT_7X7_100},
    {"DICT_7X7_250", cv::aruco::DICT_7X7_250},
    {"DICT_7X7_1000", cv::aruco::DICT_7X7_1000},
    {"DICT_ARUCO_ORIGINAL", cv::aruco::DICT_ARUCO_ORIGINAL},
    {"DICT_APRILTAG_16h5", cv::aruco::DICT_APRILTAG_16h5},
    {"DICT_APRILTAG_25h9", cv::aruco::DICT_APRILTAG_25h9},
    {"DICT_APRILTAG_36h10", cv::aruco::DICT_APRILTAG_36h10},
    {"DICT_APRILTAG_36h11", cv::aruco::DICT_APRILTAG_36h11},
};

Result<cv::Ptr<cv::aruco::Dictionary>> dictionaryByName(std::string_view name) {
  for (const NamedDictionary& d : kDictionaries)
    if (name == d.name) return cv::aruco::getPredefinedDictionary(d.value);
  std::string names;
  for (const NamedDictionary& d : kDictionaries) names += std::string(names.empty() ? "" : ", ") + d.name;
  return fail(ErrorCode::InvalidArgument, "unknown marker dictionary \"" + std::string(name) + "\"",
              "dictionary", "use one of " + names);
}

Status checkCamera(const CameraIntrinsics& c, const char* where) {
  const Mat3& k = c.matrix;
  if (!k.allFinite() || !(k(0, 0) > 0) || !(k(1, 1) > 0) || k(2, 2) != 1.0 || k(1, 0) != 0 || k(2, 0) != 0 ||
      k(2, 1) != 0)
    return fail(ErrorCode::InvalidArgument, "camera matrix is not an upper-triangular K with fx, fy > 0",
                where, "K = [fx s cx; 0 fy cy; 0 0 1] in pixels");
  const std::size_t n = c.distortion.size();
  if (n != 0 && n != 4 && n != 5 && n != 8 && n != 12 && n != 14)
    return fail(ErrorCode::InvalidArgument, formatString("%zu distortion coefficients", n), where,
                "OpenCV takes 4, 5, 8, 12 or 14 (or none)");
  return ok();
}

cv::Mat cameraMat(const CameraIntrinsics& c) {
  cv::Mat k;
  cv::eigen2cv(c.matrix, k);
  return k;
}

cv::Mat distortionMat(const CameraIntrinsics& c) {
  if (c.distortion.empty()) return {};
  return cv::Mat(c.distortion, true).reshape(1, 1);
}

Isometry3 toIsometry(const cv::Mat& rvec, const cv::Mat& tvec) {
  cv::Mat r;
  cv::Rodrigues(rvec, r);
  Mat3 rotation;
  Vec3 translation;
  cv::cv2eigen(r, rotation);
  cv::cv2eigen(tvec.reshape(1, 3), translation);
  Isometry3 t = Isometry3::Identity();
  t.linear() = rotation;
  t.translation() = translation;
  return t;
}

Status checkImage(const Image& image, const char* where) {
  if (image.empty() || image.type() != PixelType::U8 || image.channels() == 2)
    return fail(ErrorCode::InvalidArgument, "marker detection needs a U8 gray, BGR or BGRA image", where);
  return ok();
}

cv::Ptr<cv::aruco::DetectorParameters> detectorParameters() {
  auto p = cv::aruco::DetectorParameters::create();
  p->cornerRefinementMethod = cv::aruco::CORNER_REFINE_SUBPIX;
  return p;
}

Result<cv::Ptr<cv::aruco::CharucoBoard>> makeBoard(const CharucoBoardSpec& b) {
  auto dict = dictionaryByName(b.dictionary);
  if (!dict) return dict.error();
  if (b.squaresX < 2 || b.squaresY < 2 || !(b.squareLength > 0) || !(b.markerLength > 0) ||
      !(b.markerLength < b.squareLength))
    return fail(ErrorCode::InvalidArgument,
                formatString("ChArUco board %dx%d squares of %g m, markers %g m", b.squaresX, b.squaresY,
                             b.squareLength, b.markerLength),
                "CharucoBoardSpec", "need at least 2x2 squares and 0 < markerLength < squareLength");
  const int markersNeeded = (b.squaresX * b.squaresY) / 2;
  if (markersNeeded > (*dict)->bytesList.rows)
    return fail(ErrorCode::InvalidArgument,
                formatString("the board needs %d markers, %s has %d", markersNeeded, b.dictionary.c_str(),
                             (*dict)->bytesList.rows),
                "CharucoBoardSpec", "use a larger dictionary or a smaller board");
  try {
    return cv::aruco::CharucoBoard::create(b.squaresX, b.squaresY, static_cast<float>(b.squareLength),
                                           static_cast<float>(b.markerLength), *dict);
  } catch (const cv::Exception& e) {
    return fail(ErrorCode::InvalidArgument, "OpenCV: " + std::string(e.what()), "CharucoBoardSpec");
  }
}

}  // namespace

std::vector<std::string> markerDictionaryNames() {
  std::vector<std::string> names;
  for (const NamedDictionary& d : kDictionaries) names.emplace_back(d.name);
  return names;
}

Result<Image> drawMarker(std::string_view dictionary, int id, int sidePixels) {
  auto dict = dictionaryByName(dictionary);
  if (!dict) return dict.error();
  const int bits = (*dict)->markerSize + 2;
  if (id < 0 || id >= (*dict)->bytesList.rows)
    return fail(ErrorCode::InvalidArgument,
                formatString("marker id %d is outside %s (0..%d)", id, std::string(dictionary).c_str(),
                             (*dict)->bytesList.rows - 1),
                "drawMarker");
  if (sidePixels < bits || sidePixels > 1 << 14)
    return fail(ErrorCode::InvalidArgument, formatString("side of %d pixels", sidePixels), "drawMarker",
                formatString("give %d..16384 pixels (the marker has %d bits with its border)", bits, bits));
  cv::Mat img;
  try {
    cv::aruco::drawMarker(*dict, id, sidePixels, img, 1);
  } catch (const cv::Exception& e) {
    return fail(ErrorCode::InvalidArgument, "OpenCV: " + std::string(e.what()), "drawMarker");
  }
  return wrapCvMat(img);
}

Result<std::vector<MarkerDetection>> detectMarkers(const Image& image, std::string_view dictionary) {
  auto dict = dictionaryByName(dictionary);
  if (!dict) return dict.error();
  if (auto s = checkImage(image, "detectMarkers"); !s) return s.error();
  std::vector<std::vector<cv::Point2f>> corners;
  std::vector<int> ids;
  try {
    cv::aruco::detectMarkers(asCvGray(image), *dict, corners, ids, detectorParameters());
  } catch (const cv::Exception& e) {
    return fail(ErrorCode::InvalidArgument, "OpenCV: " + std::string(e.what()), "detectMarkers");
  }
  std::vector<MarkerDetection> out(ids.size());
  for (std::size_t i = 0; i < ids.size(); ++i) {
    out[i].id = ids[i];
    for (int k = 0; k < 4; ++k)
      out[i].corners[static_cast<std::size_t>(k)] = Vec2(corners[i][k].x, corners[i][k].y);
  }
  std::sort(out.begin(), out.end(),
            [](const MarkerDetection& a, const MarkerDetection& b) { return a.id < b.id; });
  return out;
}

Result<std::vector<MarkerPose>> estimateMarkerPoses(const std::vector<MarkerDetection>& markers,
                                                    double markerLength, const CameraIntrinsics& camera) {
  if (!(markerLength > 0) || !std::isfinite(markerLength))
    return fail(ErrorCode::InvalidArgument, formatString("marker length %g m", markerLength),
                "estimateMarkerPoses", "give the printed marker's edge in metres");
  if (auto s = checkCamera(camera, "estimateMarkerPoses"); !s) return s.error();
  const float h = static_cast<float>(markerLength / 2);
  // IPPE_SQUARE's required corner layout (marker frame, z = 0).
  const std::vector<cv::Point3f> object = {{-h, h, 0}, {h, h, 0}, {h, -h, 0}, {-h, -h, 0}};
  const cv::Mat k = cameraMat(camera), d = distortionMat(camera);
  std::vector<MarkerPose> poses;
  poses.reserve(markers.size());
  try {
    for (const MarkerDetection& m : markers) {
      std::vector<cv::Point2f> image;
      for (const Vec2& c : m.corners)
        image.emplace_back(static_cast<float>(c.x()), static_cast<float>(c.y()));
      cv::Mat rvec, tvec;
      cv::solvePnP(object, image, k, d, rvec, tvec, false, cv::SOLVEPNP_IPPE_SQUARE);
      cv::solvePnPRefineLM(object, image, k, d, rvec, tvec);
      std::vector<cv::Point2f> projected;
      cv::projectPoints(object, rvec, tvec, k, d, projected);
      double sum = 0.0;
      for (int i = 0; i < 4; ++i) {
        const cv::Point2f e = projected[i] - image[i];
        sum += e.dot(e);
      }
      poses.push_back({m.id, toIsometry(rvec, tvec), std::sqrt(sum / 4.0)});
    }
  } catch (const cv::Exception& e) {
    return fail(ErrorCode::InvalidArgument, "OpenCV: " + std::string(e.what()), "estimateMarkerPoses");
  }
  return poses;
}

Result<std::vector<Vec3>> charucoCornerPositions(const CharucoBoardSpec& board) {
  auto b = makeBoard(board);
  if (!b) return b.error();
  std::vector<Vec3> out;
  for (const cv::Point3f& p : (*b)->chessboardCorners) out.emplace_back(p.x, p.y, p.z);
  return out;
}

Result<Image> drawCharucoBoard(const CharucoBoardSpec& board, int widthPixels, int heightPixels,
                               int marginPixels) {
  auto b = makeBoard(board);
  if (!b) return b.error();
  if (widthPixels < 2 * board.squaresX || heightPixels < 2 * board.squaresY || widthPixels > 1 << 15 ||
      heightPixels > 1 << 15 || marginPixels < 0 || 2 * marginPixels >= std::min(widthPixels, heightPixels))
    return fail(ErrorCode::InvalidArgument,
                formatString("%dx%d pixels with a margin of %d", widthPixels, heightPixels, marginPixels),
                "drawCharucoBoard",
                "give at most 32768 pixels per side and margins smaller than half the image");
  cv::Mat img;
  try {
    (*b)->draw(cv::Size(widthPixels, heightPixels), img, marginPixels, 1);
  } catch (const cv::Exception& e) {
    return fail(ErrorCode::InvalidArgument, "OpenCV: " + std::string(e.what()), "drawCharucoBoard");
  }
  return wrapCvMat(img);
}

Result<CharucoDetection> detectCharucoBoard(const Image& image, const CharucoBoardSpec& board,
                                            const std::optional<CameraIntrinsics>& camera) {
  auto b = makeBoard(board);
  if (!b) return b.error();
  if (auto s = checkImage(image, "detectCharucoBoard"); !s) return s.error();
  if (camera)
    if (auto s = checkCamera(*camera, "detectCharucoBoard"); !s) return s.error();
  CharucoDetection det;
  try {
    const cv::Mat gray = asCvGray(image);
    std::vector<std::vector<cv::Point2f>> markerCorners;
    std::vector<int> markerIds;
    cv::aruco::detectMarkers(gray, (*b)->dictionary, markerCorners, markerIds, detectorParameters());
    det.markers = static_cast<int>(markerIds.size());
    if (markerIds.empty()) return det;
    const cv::Mat k = camera ? cameraMat(*camera) : cv::Mat(),
                  d = camera ? distortionMat(*camera) : cv::Mat();
    std::vector<cv::Point2f> corners;
    std::vector<int> ids;
    cv::aruco::interpolateCornersCharuco(markerCorners, markerIds, gray, *b, corners, ids,
                                         camera ? cv::InputArray(k) : cv::noArray(),
                                         camera ? cv::InputArray(d) : cv::noArray());
    for (std::size_t i = 0; i < ids.size(); ++i) {
      det.ids.push_back(ids[i]);
      det.corners.emplace_back(corners[i].x, corners[i].y);
    }
    if (camera && ids.size() >= 4) {
      cv::Mat rvec, tvec;
      det.hasPose = cv::aruco::estimatePoseCharucoBoard(corners, ids, *b, k, d, rvec, tvec, false);
      if (det.hasPose) {
        rvec.convertTo(rvec, CV_64F);
        tvec.convertTo(tvec, CV_64F);
        det.cameraFromBoard = toIsometry(rvec, tvec);
      }
    }
  } catch (const cv::Exception& e) {
    return fail(ErrorCode::InvalidArgument, "OpenCV: " + std::string(e.what()), "detectCharucoBoard");
  }
  return det;
}

Result<MarkerRegistration> registerMarkers(const std::vector<MarkerPose>& detected,
                                           const std::map<int, Vec3>& model) {
  MarkerRegistration out;
  std::vector<Vec3> source, target;
  std::string seen;
  for (const MarkerPose& p : detected) {
    seen += (seen.empty() ? "" : ", ") + std::to_string(p.id);
    auto it = model.find(p.id);
    if (it == model.end() || std::find(out.ids.begin(), out.ids.end(), p.id) != out.ids.end()) continue;
    out.ids.push_back(p.id);
    source.push_back(it->second);
    target.push_back(p.cameraFromMarker.translation());
  }
  if (out.ids.size() < 3)
    return fail(ErrorCode::InvalidArgument,
                formatString("only %zu detected markers are in the model (need 3)", out.ids.size()),
                "registerMarkers: detected ids [" + seen + "]",
                "make at least three model markers visible, or check the dictionary and ids");
  auto reg = registerPoints(source, target);
  if (!reg) return reg.error().within("registerMarkers");
  out.registration = std::move(*reg);
  return out;
}

}  // namespace dm
