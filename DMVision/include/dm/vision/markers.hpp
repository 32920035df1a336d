// dm/vision/markers.hpp — fiducial markers: ArUco and ChArUco detection and
// pose, and registration of detected markers to a model.
//
// Detection and pose are OpenCV's aruco module (detectMarkers, solvePnP
// with IPPE_SQUARE per marker, interpolateCornersCharuco +
// estimatePoseCharucoBoard) behind dm:: types. Registration of marker
// positions to model positions reuses dm::registerPoints (Umeyama), so FRE
// and TRE follow dm/math/registration.hpp.
//
// Frames (OpenCV's): the camera looks along +z, x right, y down. A marker's
// frame has its origin at the marker centre, x to the right and y up in the
// printed marker, z out of the marker towards the viewer; its corners are
// (−L/2, L/2, 0), (L/2, L/2, 0), (L/2, −L/2, 0), (−L/2, −L/2, 0) in the
// order detectMarkers returns them (top-left, top-right, bottom-right,
// bottom-left of the printed marker). Lengths are metres, pixels are
// OpenCV's (pixel centres at integers).
//
// @code
//   auto found = dm::detectMarkers(gray, "DICT_4X4_50");
//   auto poses = dm::estimateMarkerPoses(*found, 0.05, camera);
//   auto reg = dm::registerMarkers(*poses, modelPositions);   // reg->registration.fre
// @endcode
#pragma once

#include <dm/core/image.hpp>
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>
#include <dm/math/registration.hpp>

#include <array>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace dm {

/// Pinhole camera with OpenCV's distortion model.
struct CameraIntrinsics {
  Mat3 matrix = Mat3::Identity();  ///< K: fx, fy, cx, cy in pixels
  std::vector<double> distortion;  ///< k1 k2 p1 p2 [k3 ...]; empty = none
};

/// One detected square marker.
struct MarkerDetection {
  int id = -1;
  std::array<Vec2, 4>
      corners;  ///< pixels: top-left, top-right, bottom-right, bottom-left of the printed marker
};

/// Names of the predefined dictionaries, e.g. "DICT_4X4_50", "DICT_6X6_250",
/// "DICT_ARUCO_ORIGINAL", "DICT_APRILTAG_36h11".
std::vector<std::string> markerDictionaryNames();

/// Draws marker `id` of `dictionary` as a U8 gray image of sidePixels² with
/// a one-bit black border (cv::aruco::drawMarker), for printing or tests.
/// Fails with InvalidArgument on an unknown dictionary (the message lists
/// the names), an id outside it, or sidePixels smaller than the bit grid.
/// @code
///   auto img = dm::drawMarker("DICT_4X4_50", 7, 200);
///   if (img) dm::writePng(*img, "marker7.png");
/// @endcode
Result<Image> drawMarker(std::string_view dictionary, int id, int sidePixels);

/// Detects markers of `dictionary` in `image` (U8, 1, 3 or 4 channels) with
/// OpenCV's default parameters and sub-pixel corner refinement. Sorted by id.
/// O(pixels). An image without markers gives an empty list; fails with
/// InvalidArgument on an unknown dictionary or unsupported image.
/// @code
///   auto found = dm::detectMarkers(gray, "DICT_4X4_50");
///   for (const auto& m : *found) std::printf("marker %d\n", m.id);
/// @endcode
Result<std::vector<MarkerDetection>> detectMarkers(const Image& image, std::string_view dictionary);

/// A marker's pose in the camera frame.
struct MarkerPose {
  int id = -1;
  Isometry3 cameraFromMarker = Isometry3::Identity();  ///< maps marker-frame points (m) to camera frame (m)
  double reprojectionError = 0.0;                      ///< RMS over the 4 corners, pixels
};

/// Pose of each detected marker of edge `markerLength` metres (solvePnP,
/// IPPE_SQUARE, then Levenberg–Marquardt refinement). O(markers). Fails with
/// InvalidArgument on markerLength ≤ 0 or bad intrinsics.
/// @code
///   auto poses = dm::estimateMarkerPoses(*found, 0.05, camera);
///   dm::Vec3 centre = (*poses)[0].cameraFromMarker.translation();
/// @endcode
Result<std::vector<MarkerPose>> estimateMarkerPoses(const std::vector<MarkerDetection>& markers,
                                                    double markerLength, const CameraIntrinsics& camera);

/// A ChArUco board: a chessboard whose white squares hold ArUco markers.
struct CharucoBoardSpec {
  int squaresX = 5, squaresY = 7;  ///< squares per row / column
  double squareLength = 0.04;      ///< metres
  double markerLength = 0.02;      ///< metres, < squareLength
  std::string dictionary = "DICT_4X4_50";
};

/// Positions (board frame, metres, z = 0) of the board's inner chessboard
/// corners, indexed by ChArUco corner id: (squaresX − 1)(squaresY − 1) of
/// them. Fails with InvalidArgument on a bad spec.
/// @code
///   auto corners = dm::charucoCornerPositions({5, 7, 0.04, 0.02, "DICT_4X4_50"});
///   dm::Vec3 first = (*corners)[0];   // ChArUco corner id 0, metres
/// @endcode
Result<std::vector<Vec3>> charucoCornerPositions(const CharucoBoardSpec& board);

/// Draws the board into a U8 gray image of widthPixels × heightPixels, kept
/// proportional and centred with at least `marginPixels` white margin.
/// Fails with InvalidArgument on a bad spec, sizes or margin.
/// @code
///   auto img = dm::drawCharucoBoard(board, 1000, 1400, 20);
///   if (img) dm::writePng(*img, "board.png");
/// @endcode
Result<Image> drawCharucoBoard(const CharucoBoardSpec& board, int widthPixels, int heightPixels,
                               int marginPixels = 0);

/// Detected ChArUco corners and, with enough of them, the board pose.
struct CharucoDetection {
  std::vector<int> ids;       ///< ChArUco corner ids (index into charucoCornerPositions)
  std::vector<Vec2> corners;  ///< pixels, sub-pixel refined
  int markers = 0;            ///< ArUco markers of the board that were found
  bool hasPose = false;       ///< true when ≥ 4 non-collinear corners gave a pose
  Isometry3 cameraFromBoard = Isometry3::Identity();  ///< board frame (m) → camera frame (m)
};

/// Finds the board's markers, interpolates the chessboard corners between
/// them (through the camera model when `camera` is given, else through local
/// homographies) and, with a camera, estimates the board pose. O(pixels). A
/// board that is not visible gives an empty detection (no error); fails with
/// InvalidArgument on a bad spec, image or intrinsics.
/// @code
///   auto det = dm::detectCharucoBoard(gray, board, camera);
///   if (det && det->hasPose) use(det->cameraFromBoard);
/// @endcode
Result<CharucoDetection> detectCharucoBoard(const Image& image, const CharucoBoardSpec& board,
                                            const std::optional<CameraIntrinsics>& camera);

/// Registration of detected markers to model markers.
struct MarkerRegistration {
  Registration registration;  ///< model frame → camera frame; registration.fre in metres
  std::vector<int> ids;       ///< ids used, in the order of registration.residuals
};

/// Rigidly registers the model positions `model` (marker id → marker centre
/// in the model frame, metres) to the detected marker centres
/// (cameraFromMarker translations) with dm::registerPoints. Markers present
/// in only one of the two are ignored. O(markers · log). Fails with
/// InvalidArgument when fewer than 3 ids match (the message says which ids
/// were seen) or the matched markers are collinear.
/// @code
///   auto reg = dm::registerMarkers(*poses, {{0, {0, 0, 0}}, {1, {0.1, 0, 0}}, {2, {0, 0.1, 0}}});
///   if (reg) std::printf("FRE %.2f mm\n", 1e3 * reg->registration.fre);
/// @endcode
Result<MarkerRegistration> registerMarkers(const std::vector<MarkerPose>& detected,
                                           const std::map<int, Vec3>& model);

}  // namespace dm
