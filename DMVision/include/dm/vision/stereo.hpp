// dm/vision/stereo.hpp — stereo cameras: chessboard calibration,
// rectification, semi-global matching, point clouds and disparity scoring.
//
// The pipeline is OpenCV's (findChessboardCorners + cornerSubPix,
// stereoCalibrate, stereoRectify + initUndistortRectifyMap + remap,
// StereoSGBM, reprojectImageTo3D) behind dm:: types: images are dm::Image,
// matrices are Eigen, lengths are metres (the chessboard square size sets the
// scale of T, Q and the point cloud). Camera frames follow OpenCV: x right,
// y down, z forward; pixel (0, 0) is the centre of the top-left pixel.
//
// Disparity maps are F32 images in pixels (left x − right x); pixels without
// a match are NaN.
//
// @code
//   auto pairs = dm::readStereoImageList("opencv:stereo_calib.xml");
//   auto calib = dm::calibrateStereo(*pairs, dm::ChessboardSpec{9, 6, 0.025});
//   auto rect = dm::rectifyStereo(*calib);
// @endcode
#pragma once

#include <dm/core/image.hpp>
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>

#include <Eigen/Core>

#include <cstddef>
#include <filesystem>
#include <string>
#include <vector>

namespace dm {

/// A planar chessboard target: inner-corner counts and square size.
struct ChessboardSpec {
  int cols = 9;               ///< inner corners per row (OpenCV's patternSize.width)
  int rows = 6;               ///< inner corners per column (patternSize.height)
  double squareSize = 0.025;  ///< edge of one square, metres
};

/// One left/right image file pair.
struct StereoPair {
  std::filesystem::path left;
  std::filesystem::path right;
};

/// Reads an OpenCV image-list file (e.g. stereo_calib.xml: <imagelist> with
/// alternating left and right names). Relative names resolve against the
/// list file's folder; `listFile` itself goes through dm::FileSystem
/// ("opencv:stereo_calib.xml" works). O(entries). Fails with NotFound when
/// the list is missing, Parse when it is not an OpenCV storage file, has no
/// <imagelist> or an odd number of names.
/// @code
///   auto pairs = dm::readStereoImageList("opencv:stereo_calib.xml");
///   if (!pairs) return pairs.error();
///   std::printf("%zu pairs\n", pairs->size());
/// @endcode
Result<std::vector<StereoPair>> readStereoImageList(const std::string& listFile);

/// Reads an image file as 8-bit gray or BGR (OpenCV imread; any format
/// OpenCV decodes). Fails with NotFound naming the file when it is missing
/// and Parse when it cannot be decoded.
/// @code
///   auto left = dm::readImageFile("opencv:aloeL.jpg", false);   // BGR
///   if (!left) return left.error();
///   std::printf("%dx%d\n", left->width(), left->height());
/// @endcode
Result<Image> readImageFile(const std::filesystem::path& file, bool gray);

/// Inner chessboard corners of `image` (U8, 1 or 3 channels), in pixels,
/// row by row as OpenCV orders them, refined to sub-pixel accuracy
/// (cornerSubPix, 11×11 window). O(pixels). Fails with NotFound when the
/// board is not (completely) visible, InvalidArgument on a bad image/spec.
/// @code
///   auto img = dm::readImageFile("left01.jpg", true);
///   auto corners = dm::findChessboardCorners(*img, {9, 6, 0.025});
///   if (corners) std::printf("%zu corners\n", corners->size());
/// @endcode
Result<std::vector<Vec2>> findChessboardCorners(const Image& image, const ChessboardSpec& board);

/// Options of calibrateStereo().
struct StereoCalibrationOptions {
  int minPairs = 3;  ///< fewer pairs with the board found in both images is an error
  /// Also fail (instead of skipping the pair with a warning) when a board is
  /// not found in one image of a pair.
  bool requireAllPairs = false;
};

/// Intrinsics and relative pose of a calibrated stereo rig.
struct StereoCalibration {
  int imageWidth = 0, imageHeight = 0;  ///< pixels, same for both cameras
  Mat3 leftMatrix = Mat3::Identity();   ///< K of the left camera, pixels
  Mat3 rightMatrix = Mat3::Identity();  ///< K of the right camera, pixels
  std::vector<double> leftDistortion;   ///< k1 k2 p1 p2 k3 (OpenCV model)
  std::vector<double> rightDistortion;  ///< k1 k2 p1 p2 k3
  Mat3 rotation = Mat3::Identity();     ///< R: x_right = R x_left + T
  Vec3 translation = Vec3::Zero();      ///< T, metres
  Mat3 essential = Mat3::Zero();        ///< E = [T]× R
  Mat3 fundamental = Mat3::Zero();      ///< F: x_rightᵀ F x_left = 0 (pixels)
  double rms = 0.0;                     ///< RMS reprojection error over both cameras, pixels
  std::vector<double> perViewErrors;    ///< RMS reprojection error per used pair, pixels
  std::vector<StereoPair> usedPairs;    ///< pairs whose boards were found in both images
  std::vector<std::vector<Vec2>> leftCorners, rightCorners;  ///< detected corners per used pair
};

/// Detects the board in every pair and runs stereoCalibrate (intrinsics of
/// both cameras, 5-parameter distortion, R, T, E, F). Pairs where the board
/// is not found in one image are skipped with a warning that names the
/// file. O(pairs · pixels + iterations · pairs · corners). Fails with
/// NotFound naming a missing file, InvalidArgument when images of a pair
/// differ in size, and with InvalidArgument saying how many valid pairs
/// were found when fewer than options.minPairs.
/// @code
///   auto calib = dm::calibrateStereo(*pairs, {9, 6, 0.025});
///   if (!calib) return calib.error();
///   std::printf("RMS %.3f px, baseline %.1f mm\n", calib->rms, 1e3 * calib->translation.norm());
/// @endcode
Result<StereoCalibration> calibrateStereo(const std::vector<StereoPair>& pairs, const ChessboardSpec& board,
                                          const StereoCalibrationOptions& options = {});

/// Rectification of a calibrated rig: both images are remapped so that
/// epipolar lines are image rows. Maps are F32 two-channel images (x, y
/// source coordinates per destination pixel).
struct StereoRectification {
  int imageWidth = 0, imageHeight = 0;
  Mat3 leftRotation = Mat3::Identity(), rightRotation = Mat3::Identity();             ///< R1, R2
  Eigen::Matrix<double, 3, 4> leftProjection = Eigen::Matrix<double, 3, 4>::Zero();   ///< P1
  Eigen::Matrix<double, 3, 4> rightProjection = Eigen::Matrix<double, 3, 4>::Zero();  ///< P2
  Mat4 q = Mat4::Identity();  ///< disparity-to-depth matrix Q (metres)
  Image leftMap, rightMap;    ///< F32, 2 channels, imageWidth × imageHeight
};

/// stereoRectify (zero-disparity principal points, `alpha` in [0, 1]: 0
/// keeps only valid pixels, 1 keeps all source pixels) and the undistort-
/// rectify maps. O(pixels). Fails with InvalidArgument on an uncalibrated
/// input or alpha outside [0, 1] (−1 is OpenCV's default scaling).
/// @code
///   auto rect = dm::rectifyStereo(*calib);
///   auto pair = dm::rectifyImages(*rect, left, right);
///   auto disp = dm::computeDisparity(pair->left, pair->right);
/// @endcode
Result<StereoRectification> rectifyStereo(const StereoCalibration& calibration, double alpha = 0.0);

/// Two rectified images.
struct RectifiedPair {
  Image left, right;
};

/// Remaps a left/right pair (same size as the calibration, any channel
/// count and pixel type) with bilinear interpolation. O(pixels). Fails with
/// InvalidArgument on a size mismatch.
/// @code
///   auto pair = dm::rectifyImages(*rect, *left, *right);
///   if (!pair) return pair.error();
///   auto disp = dm::computeDisparity(pair->left, pair->right);
/// @endcode
Result<RectifiedPair> rectifyImages(const StereoRectification& rectification, const Image& left,
                                    const Image& right);

/// Maps pixel positions of the original left (or right) image into the
/// rectified image (undistortPoints with R1/P1 or R2/P2). O(points). Fails
/// with InvalidArgument when the calibration's matrices are unusable.
/// @code
///   auto l = dm::rectifyPoints(*calib, *rect, calib->leftCorners[0], true);
///   auto r = dm::rectifyPoints(*calib, *rect, calib->rightCorners[0], false);
///   double dy = (*l)[0].y() - (*r)[0].y();   // ~0 after rectification
/// @endcode
Result<std::vector<Vec2>> rectifyPoints(const StereoCalibration& calibration,
                                        const StereoRectification& rectification,
                                        const std::vector<Vec2>& points, bool left);

/// Semi-global matching parameters (cv::StereoSGBM). P1/P2 of 0 mean
/// 8·channels·blockSize² and 32·channels·blockSize² (OpenCV's advice).
struct SgbmOptions {
  int minDisparity = 0;         ///< smallest disparity searched, pixels
  int numDisparities = 128;     ///< search range, pixels; a positive multiple of 16
  int blockSize = 5;            ///< odd matching block edge, 1..255 pixels
  int p1 = 0, p2 = 0;           ///< smoothness penalties (p2 > p1); 0 = automatic
  int disp12MaxDiff = 1;        ///< left-right check tolerance, pixels; < 0 disables
  int preFilterCap = 63;        ///< x-derivative clip of the prefilter
  int uniquenessRatio = 10;     ///< best match must beat the second by this percentage
  int speckleWindowSize = 100;  ///< blobs smaller than this (pixels) become invalid; 0 disables
  int speckleRange = 2;         ///< max disparity variation inside a blob, pixels
  enum class Mode { Sgbm, FullDp, Sgbm3Way, Hh4 } mode = Mode::Sgbm;  ///< 5 paths, 8 paths, 3-way, 4 paths
};

/// Disparity of a rectified pair (U8, 1 or 3 channels, same size) by
/// semi-global matching: F32 image in pixels, NaN where no match survived
/// the uniqueness, left-right and speckle checks. O(pixels ·
/// numDisparities) time, O(width · numDisparities) extra memory per row
/// (Sgbm3Way/Hh4) or O(pixels · numDisparities) (FullDp). Fails with
/// InvalidArgument on mismatched/unsupported images or bad options.
/// @code
///   dm::SgbmOptions o{.numDisparities = 64, .blockSize = 3};
///   auto disp = dm::computeDisparity(left, right, o);
///   if (disp) std::printf("%.1f px\n", disp->at<float>(320, 240));
/// @endcode
Result<Image> computeDisparity(const Image& left, const Image& right, const SgbmOptions& options = {});

/// 3-D points (left rectified camera frame, metres when Q came from a
/// calibration in metres) of every pixel with a finite disparity greater than
/// `minDisparity` (cv::reprojectImageTo3D). Row-major order. O(pixels).
/// Fails with InvalidArgument unless `disparity` is F32 with one channel.
/// @code
///   auto cloud = dm::disparityToPoints(*disp, rect->q);
///   if (cloud) std::printf("%zu points\n", cloud->size());
/// @endcode
Result<std::vector<Vec3>> disparityToPoints(const Image& disparity, const Mat4& q, double minDisparity = 0.0);

/// Scores of a disparity map against ground truth.
struct DisparityScore {
  std::size_t validTruth = 0;    ///< ground-truth pixels with a known disparity
  double coverage = 0.0;         ///< fraction of those with a finite estimate
  double badPixelRate = 0.0;     ///< fraction of covered pixels with |d − gt| > threshold
  double badPixelRateAll = 0.0;  ///< same over all valid truth pixels, missing estimates counted bad
  double meanAbsError = 0.0;     ///< mean |d − gt| over covered pixels, pixels
};

/// Compares `disparity` (F32, pixels, NaN = none) with `truth` (U8 or U16
/// ground truth storing disparity × truthScale; 0 = unknown, as Middlebury
/// does) of the same size. O(pixels). Fails with InvalidArgument on size or
/// type mismatch, truthScale ≤ 0, or no valid truth pixel.
/// @code
///   auto gt = dm::readImageFile("aloeGT.png", true);
///   auto s = dm::scoreDisparity(*disp, *gt, 1.0, 1.0);
///   std::printf("bad 1px: %.1f %%\n", 100 * s->badPixelRate);
/// @endcode
Result<DisparityScore> scoreDisparity(const Image& disparity, const Image& truth, double truthScale,
                                      double threshold = 1.0);

}  // namespace dm
