// Stereo calibration, rectification, SGBM and scoring on OpenCV (see
// dm/vision/stereo.hpp). OpenCV exceptions are caught at this boundary.
#include <dm/core/filesystem.hpp>
#include <dm/core/log.hpp>
#include <dm/vision/cv_image.hpp>
#include <dm/vision/stereo.hpp>

#include <cmath>
#include <limits>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/core/eigen.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <string>
#include <utility>

namespace dm {
namespace {

Error cvError(const cv::Exception& e, const std::string& where) {
  return fail(ErrorCode::InvalidArgument, "OpenCV: " + std::string(e.what()), where);
}

Mat3 toMat3(const cv::Mat& m) {
  Mat3 r;
  cv::cv2eigen(m, r);
  return r;
}

cv::Mat toCv(const auto& eigenMatrix) {
  cv::Mat r;
  cv::eigen2cv(eigenMatrix, r);
  return r;
}

std::vector<double> toVector(const cv::Mat& m) {
  std::vector<double> v;
  cv::Mat d;
  m.convertTo(d, CV_64F);
  for (int i = 0; i < static_cast<int>(d.total()); ++i) v.push_back(d.at<double>(i));
  return v;
}

std::vector<cv::Point2f> toCvPoints(const std::vector<Vec2>& p) {
  std::vector<cv::Point2f> out;
  out.reserve(p.size());
  for (const Vec2& x : p) out.emplace_back(static_cast<float>(x.x()), static_cast<float>(x.y()));
  return out;
}

Status checkBoard(const ChessboardSpec& b) {
  if (b.cols < 2 || b.rows < 2 || !(b.squareSize > 0.0) || !std::isfinite(b.squareSize))
    return fail(ErrorCode::InvalidArgument,
                formatString("chessboard %dx%d inner corners, square %g m", b.cols, b.rows, b.squareSize),
                "ChessboardSpec", "give at least 2x2 inner corners and a positive square size in metres");
  return ok();
}

}  // namespace

Result<std::vector<StereoPair>> readStereoImageList(const std::string& listFile) {
  auto path = FileSystem::global().resolve(listFile);
  if (!path) return path.error();
  std::vector<std::string> names;
  try {
    cv::FileStorage fs(path->string(), cv::FileStorage::READ);
    if (!fs.isOpened())
      return fail(ErrorCode::Parse, "not an OpenCV storage file (XML/YAML/JSON)", path->string());
    cv::FileNode list = fs.getFirstTopLevelNode();
    if (list.type() != cv::FileNode::SEQ)
      return fail(ErrorCode::Parse, "the first top-level node is not a list of image names", path->string(),
                  "expected <imagelist> \"left01.jpg\" \"right01.jpg\" ... </imagelist>");
    for (auto it = list.begin(); it != list.end(); ++it) names.push_back(static_cast<std::string>(*it));
  } catch (const cv::Exception& e) {
    return fail(ErrorCode::Parse, "OpenCV: " + std::string(e.what()), path->string());
  }
  if (names.empty() || names.size() % 2 != 0)
    return fail(ErrorCode::Parse,
                formatString("%zu image names; expected a non-zero even number", names.size()),
                path->string(), "list left and right images alternately");
  std::vector<StereoPair> pairs;
  const std::filesystem::path dir = path->parent_path();
  for (std::size_t i = 0; i < names.size(); i += 2) {
    auto full = [&](const std::string& n) {
      std::filesystem::path p(n);
      return p.is_absolute() ? p : dir / p;
    };
    pairs.push_back({full(names[i]), full(names[i + 1])});
  }
  return pairs;
}

Result<Image> readImageFile(const std::filesystem::path& file, bool gray) {
  auto path = FileSystem::global().resolve(file.string());
  if (!path) return path.error();
  cv::Mat m;
  try {
    m = cv::imread(path->string(), gray ? cv::IMREAD_GRAYSCALE : cv::IMREAD_COLOR);
  } catch (const cv::Exception& e) {
    return fail(ErrorCode::Parse, "OpenCV: " + std::string(e.what()), path->string());
  }
  if (m.empty())
    return fail(ErrorCode::Parse, "OpenCV could not decode the image", path->string(),
                "check that it is a complete PNG/JPEG/TIFF/... file");
  return wrapCvMat(m);
}

Result<std::vector<Vec2>> findChessboardCorners(const Image& image, const ChessboardSpec& board) {
  if (auto s = checkBoard(board); !s) return s.error();
  if (image.empty() || image.type() != PixelType::U8 || image.channels() == 2)
    return fail(ErrorCode::InvalidArgument, "chessboard detection needs a U8 gray, BGR or BGRA image",
                "findChessboardCorners");
  std::vector<cv::Point2f> corners;
  try {
    cv::Mat gray = asCvGray(image);
    const cv::Size pattern(board.cols, board.rows);
    if (!cv::findChessboardCorners(gray, pattern, corners,
                                   cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE))
      return fail(ErrorCode::NotFound, formatString("no complete %dx%d chessboard", board.cols, board.rows),
                  "findChessboardCorners",
                  "the whole board must be visible; check cols/rows (inner corners)");
    cv::cornerSubPix(gray, corners, cv::Size(11, 11), cv::Size(-1, -1),
                     cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 30, 0.01));
  } catch (const cv::Exception& e) {
    return cvError(e, "findChessboardCorners");
  }
  std::vector<Vec2> out;
  out.reserve(corners.size());
  for (const cv::Point2f& c : corners) out.emplace_back(c.x, c.y);
  return out;
}

Result<StereoCalibration> calibrateStereo(const std::vector<StereoPair>& pairs, const ChessboardSpec& board,
                                          const StereoCalibrationOptions& options) {
  if (auto s = checkBoard(board); !s) return s.error();
  StereoCalibration calib;
  for (const StereoPair& pair : pairs) {
    auto left = readImageFile(pair.left, true);
    if (!left) return left.error();
    auto right = readImageFile(pair.right, true);
    if (!right) return right.error();
    if (left->width() != right->width() || left->height() != right->height())
      return fail(ErrorCode::InvalidArgument,
                  formatString("left image is %dx%d, right image %dx%d", left->width(), left->height(),
                               right->width(), right->height()),
                  pair.left.string() + " / " + pair.right.string(),
                  "both cameras must have the same resolution");
    if (calib.imageWidth == 0) {
      calib.imageWidth = left->width();
      calib.imageHeight = left->height();
    } else if (left->width() != calib.imageWidth || left->height() != calib.imageHeight) {
      return fail(ErrorCode::InvalidArgument,
                  formatString("image is %dx%d but earlier pairs are %dx%d", left->width(), left->height(),
                               calib.imageWidth, calib.imageHeight),
                  pair.left.string(), "all pairs must come from the same cameras at one resolution");
    }
    auto cl = findChessboardCorners(*left, board);
    auto cr = cl ? findChessboardCorners(*right, board) : Result<std::vector<Vec2>>(cl.error());
    if (!cl || !cr) {
      const std::string file = (!cl ? pair.left : pair.right).string();
      const Error& e = !cl ? cl.error() : cr.error();
      if (options.requireAllPairs) return e.within(file);
      log::warn("calibrateStereo: skipping pair, %s: %s", file.c_str(), e.what.c_str());
      continue;
    }
    calib.usedPairs.push_back(pair);
    calib.leftCorners.push_back(std::move(*cl));
    calib.rightCorners.push_back(std::move(*cr));
  }
  const int found = static_cast<int>(calib.usedPairs.size());
  if (found < options.minPairs)
    return fail(
        ErrorCode::InvalidArgument,
        formatString("the %dx%d chessboard was found in both images of only %d of %zu pairs (need %d)",
                     board.cols, board.rows, found, pairs.size(), options.minPairs),
        "calibrateStereo", "check the board size (inner corners) and add pairs where it is fully visible");

  std::vector<cv::Point3f> boardPoints;
  for (int r = 0; r < board.rows; ++r)
    for (int c = 0; c < board.cols; ++c)
      boardPoints.emplace_back(static_cast<float>(c * board.squareSize),
                               static_cast<float>(r * board.squareSize), 0.0f);
  std::vector<std::vector<cv::Point3f>> objectPoints(calib.usedPairs.size(), boardPoints);
  std::vector<std::vector<cv::Point2f>> leftPoints, rightPoints;
  for (std::size_t i = 0; i < calib.usedPairs.size(); ++i) {
    leftPoints.push_back(toCvPoints(calib.leftCorners[i]));
    rightPoints.push_back(toCvPoints(calib.rightCorners[i]));
  }
  try {
    const cv::Size size(calib.imageWidth, calib.imageHeight);
    // Single-camera calibrations first give stereoCalibrate a good start; the
    // joint refinement then optimises all intrinsics with R and T.
    cv::Mat k1, d1, k2, d2, rvecs, tvecs;
    cv::calibrateCamera(objectPoints, leftPoints, size, k1, d1, rvecs, tvecs);
    cv::calibrateCamera(objectPoints, rightPoints, size, k2, d2, rvecs, tvecs);
    cv::Mat R, T, E, F, perView;
    calib.rms =
        cv::stereoCalibrate(objectPoints, leftPoints, rightPoints, k1, d1, k2, d2, size, R, T, E, F, perView,
                            cv::CALIB_USE_INTRINSIC_GUESS,
                            cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 100, 1e-6));
    calib.leftMatrix = toMat3(k1);
    calib.rightMatrix = toMat3(k2);
    calib.leftDistortion = toVector(d1);
    calib.rightDistortion = toVector(d2);
    calib.rotation = toMat3(R);
    calib.translation = Vec3(T.at<double>(0), T.at<double>(1), T.at<double>(2));
    calib.essential = toMat3(E);
    calib.fundamental = toMat3(F);
    // perViewErrors is N×2 (left, right RMS); report the pair's joint RMS.
    for (int i = 0; i < perView.rows; ++i) {
      const double l = perView.at<double>(i, 0), r = perView.at<double>(i, 1);
      calib.perViewErrors.push_back(std::sqrt(0.5 * (l * l + r * r)));
    }
  } catch (const cv::Exception& e) {
    return fail(ErrorCode::InvalidArgument, "OpenCV: " + std::string(e.what()), "calibrateStereo",
                "the views may be degenerate (all boards parallel); add views with tilted boards");
  }
  return calib;
}

namespace {

cv::Mat distortionMat(const std::vector<double>& d) {
  cv::Mat m(1, static_cast<int>(d.size()), CV_64F);
  for (std::size_t i = 0; i < d.size(); ++i) m.at<double>(static_cast<int>(i)) = d[i];
  return m;
}

}  // namespace

Result<StereoRectification> rectifyStereo(const StereoCalibration& calibration, double alpha) {
  if (calibration.imageWidth <= 0 || calibration.imageHeight <= 0)
    return fail(ErrorCode::InvalidArgument, "the calibration has no image size", "rectifyStereo",
                "pass the result of calibrateStereo()");
  if (!(alpha == -1.0 || (alpha >= 0.0 && alpha <= 1.0)))
    return fail(ErrorCode::InvalidArgument, formatString("alpha %g is outside [0, 1]", alpha),
                "rectifyStereo");
  StereoRectification rect;
  rect.imageWidth = calibration.imageWidth;
  rect.imageHeight = calibration.imageHeight;
  try {
    const cv::Size size(calibration.imageWidth, calibration.imageHeight);
    const cv::Mat k1 = toCv(calibration.leftMatrix), k2 = toCv(calibration.rightMatrix);
    const cv::Mat d1 = distortionMat(calibration.leftDistortion),
                  d2 = distortionMat(calibration.rightDistortion);
    const cv::Mat R = toCv(calibration.rotation);
    const cv::Mat T = (cv::Mat_<double>(3, 1) << calibration.translation.x(), calibration.translation.y(),
                       calibration.translation.z());
    cv::Mat R1, R2, P1, P2, Q;
    cv::stereoRectify(k1, d1, k2, d2, size, R, T, R1, R2, P1, P2, Q, cv::CALIB_ZERO_DISPARITY, alpha);
    rect.leftRotation = toMat3(R1);
    rect.rightRotation = toMat3(R2);
    cv::cv2eigen(P1, rect.leftProjection);
    cv::cv2eigen(P2, rect.rightProjection);
    cv::cv2eigen(Q, rect.q);
    cv::Mat m1, m2, unused1, unused2;
    cv::initUndistortRectifyMap(k1, d1, R1, P1, size, CV_32FC2, m1, unused1);
    cv::initUndistortRectifyMap(k2, d2, R2, P2, size, CV_32FC2, m2, unused2);
    auto lm = wrapCvMat(m1);
    if (!lm) return lm.error();
    auto rm = wrapCvMat(m2);
    if (!rm) return rm.error();
    rect.leftMap = std::move(*lm);
    rect.rightMap = std::move(*rm);
  } catch (const cv::Exception& e) {
    return cvError(e, "rectifyStereo");
  }
  return rect;
}

Result<RectifiedPair> rectifyImages(const StereoRectification& rectification, const Image& left,
                                    const Image& right) {
  for (const Image* img : {&left, &right})
    if (img->width() != rectification.imageWidth || img->height() != rectification.imageHeight)
      return fail(
          ErrorCode::InvalidArgument,
          formatString("%s image is %dx%d, the rectification is for %dx%d", img == &left ? "left" : "right",
                       img->width(), img->height(), rectification.imageWidth, rectification.imageHeight),
          "rectifyImages");
  RectifiedPair out;
  try {
    cv::Mat l, r;
    cv::remap(asCvMat(left), l, asCvMat(rectification.leftMap), cv::noArray(), cv::INTER_LINEAR);
    cv::remap(asCvMat(right), r, asCvMat(rectification.rightMap), cv::noArray(), cv::INTER_LINEAR);
    auto li = wrapCvMat(l);
    if (!li) return li.error();
    auto ri = wrapCvMat(r);
    if (!ri) return ri.error();
    out.left = std::move(*li);
    out.right = std::move(*ri);
  } catch (const cv::Exception& e) {
    return cvError(e, "rectifyImages");
  }
  return out;
}

Result<std::vector<Vec2>> rectifyPoints(const StereoCalibration& calibration,
                                        const StereoRectification& rectification,
                                        const std::vector<Vec2>& points, bool left) {
  std::vector<Vec2> result;
  if (points.empty()) return result;
  try {
    const cv::Mat k = toCv(left ? calibration.leftMatrix : calibration.rightMatrix);
    const cv::Mat d = distortionMat(left ? calibration.leftDistortion : calibration.rightDistortion);
    const cv::Mat r = toCv(left ? rectification.leftRotation : rectification.rightRotation);
    const cv::Mat p = toCv(left ? rectification.leftProjection : rectification.rightProjection);
    std::vector<cv::Point2f> in = toCvPoints(points), out;
    cv::undistortPoints(in, out, k, d, r, p);
    result.reserve(out.size());
    for (const cv::Point2f& q : out) result.emplace_back(q.x, q.y);
  } catch (const cv::Exception& e) {
    return cvError(e, "rectifyPoints");
  }
  return result;
}

Result<Image> computeDisparity(const Image& left, const Image& right, const SgbmOptions& options) {
  if (left.empty() || left.width() != right.width() || left.height() != right.height() ||
      left.channels() != right.channels() || left.type() != PixelType::U8 || right.type() != PixelType::U8 ||
      (left.channels() != 1 && left.channels() != 3))
    return fail(ErrorCode::InvalidArgument,
                formatString("left %dx%dx%d %s, right %dx%dx%d %s", left.width(), left.height(),
                             left.channels(), toString(left.type()), right.width(), right.height(),
                             right.channels(), toString(right.type())),
                "computeDisparity", "give two rectified U8 images of one size with 1 or 3 channels");
  if (options.numDisparities <= 0 || options.numDisparities % 16 != 0 || options.blockSize < 1 ||
      options.blockSize % 2 == 0 || options.blockSize > 255 || (options.p1 != 0 && options.p2 <= options.p1))
    return fail(ErrorCode::InvalidArgument,
                formatString("numDisparities %d, blockSize %d, p1 %d, p2 %d", options.numDisparities,
                             options.blockSize, options.p1, options.p2),
                "SgbmOptions",
                "numDisparities must be a positive multiple of 16, blockSize odd in 1..255 and p2 > p1");
  const int cn = left.channels();
  const int area = options.blockSize * options.blockSize;
  const int p1 = options.p1 != 0 ? options.p1 : 8 * cn * area;
  const int p2 = options.p1 != 0 ? options.p2 : 32 * cn * area;
  int mode = cv::StereoSGBM::MODE_SGBM;
  switch (options.mode) {
    case SgbmOptions::Mode::Sgbm:
      mode = cv::StereoSGBM::MODE_SGBM;
      break;
    case SgbmOptions::Mode::FullDp:
      mode = cv::StereoSGBM::MODE_HH;
      break;
    case SgbmOptions::Mode::Sgbm3Way:
      mode = cv::StereoSGBM::MODE_SGBM_3WAY;
      break;
    case SgbmOptions::Mode::Hh4:
      mode = cv::StereoSGBM::MODE_HH4;
      break;
  }
  auto out = Image::create(left.width(), left.height(), 1, PixelType::F32);
  if (!out) return out.error();
  try {
    auto sgbm = cv::StereoSGBM::create(
        options.minDisparity, options.numDisparities, options.blockSize, p1, p2, options.disp12MaxDiff,
        options.preFilterCap, options.uniquenessRatio, options.speckleWindowSize, options.speckleRange, mode);
    cv::Mat fixed;  // CV_16S, disparity × 16; (minDisparity − 1) × 16 marks no match
    sgbm->compute(asCvMat(left), asCvMat(right), fixed);
    const short invalid = static_cast<short>((options.minDisparity - 1) * 16);
    const float nan = std::numeric_limits<float>::quiet_NaN();
    for (int y = 0; y < fixed.rows; ++y) {
      const short* src = fixed.ptr<short>(y);
      float* dst = reinterpret_cast<float*>(out->row(y));
      for (int x = 0; x < fixed.cols; ++x)
        dst[x] = src[x] <= invalid ? nan : static_cast<float>(src[x]) / 16.0f;
    }
  } catch (const cv::Exception& e) {
    return cvError(e, "computeDisparity");
  }
  return out;
}

Result<std::vector<Vec3>> disparityToPoints(const Image& disparity, const Mat4& q, double minDisparity) {
  if (disparity.empty() || disparity.type() != PixelType::F32 || disparity.channels() != 1)
    return fail(ErrorCode::InvalidArgument, "disparity must be a one-channel F32 image", "disparityToPoints");
  std::vector<Vec3> points;
  try {
    const cv::Mat Q = toCv(q);
    cv::Mat xyz;
    const cv::Mat disp = asCvMat(disparity);
    cv::reprojectImageTo3D(disp, xyz, Q, false, CV_32F);
    for (int y = 0; y < disp.rows; ++y) {
      const float* d = disp.ptr<float>(y);
      const cv::Vec3f* p = xyz.ptr<cv::Vec3f>(y);
      for (int x = 0; x < disp.cols; ++x)
        if (std::isfinite(d[x]) && d[x] > minDisparity && std::isfinite(p[x][2]))
          points.emplace_back(p[x][0], p[x][1], p[x][2]);
    }
  } catch (const cv::Exception& e) {
    return cvError(e, "disparityToPoints");
  }
  return points;
}

Result<DisparityScore> scoreDisparity(const Image& disparity, const Image& truth, double truthScale,
                                      double threshold) {
  if (disparity.type() != PixelType::F32 || disparity.channels() != 1)
    return fail(ErrorCode::InvalidArgument, "disparity must be a one-channel F32 image", "scoreDisparity");
  if (truth.channels() != 1 || (truth.type() != PixelType::U8 && truth.type() != PixelType::U16))
    return fail(ErrorCode::InvalidArgument, "ground truth must be a one-channel U8 or U16 image",
                "scoreDisparity");
  if (disparity.width() != truth.width() || disparity.height() != truth.height())
    return fail(ErrorCode::InvalidArgument,
                formatString("disparity is %dx%d, ground truth %dx%d", disparity.width(), disparity.height(),
                             truth.width(), truth.height()),
                "scoreDisparity", "score at the ground truth's resolution");
  if (!(truthScale > 0.0) || !(threshold >= 0.0))
    return fail(ErrorCode::InvalidArgument,
                formatString("truthScale %g, threshold %g", truthScale, threshold), "scoreDisparity",
                "both must be positive");
  DisparityScore s;
  std::size_t covered = 0, bad = 0;
  double sumAbs = 0.0;
  for (int y = 0; y < truth.height(); ++y)
    for (int x = 0; x < truth.width(); ++x) {
      const double raw =
          truth.type() == PixelType::U8 ? truth.at<std::uint8_t>(x, y) : truth.at<std::uint16_t>(x, y);
      if (raw == 0) continue;
      ++s.validTruth;
      const float d = disparity.at<float>(x, y);
      if (!std::isfinite(d)) continue;
      ++covered;
      const double err = std::abs(static_cast<double>(d) - raw / truthScale);
      sumAbs += err;
      if (err > threshold) ++bad;
    }
  if (s.validTruth == 0)
    return fail(ErrorCode::InvalidArgument, "the ground truth has no known pixel (all 0)", "scoreDisparity");
  s.coverage = static_cast<double>(covered) / static_cast<double>(s.validTruth);
  s.badPixelRate = covered ? static_cast<double>(bad) / static_cast<double>(covered) : 1.0;
  s.badPixelRateAll = static_cast<double>(bad + (s.validTruth - covered)) / static_cast<double>(s.validTruth);
  s.meanAbsError = covered ? sumAbs / static_cast<double>(covered) : 0.0;
  return s;
}

}  // namespace dm
