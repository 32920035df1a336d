// ArUco / ChArUco detection and pose on synthetic images rendered with a
// known camera and pose (the plane carrying the pattern is mapped into the
// camera by the homography K [r1 r2 t]), and marker registration.
#include <dm/vision/cv_image.hpp>
#include <dm/vision/markers.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <map>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <random>
#include <vector>

namespace {

using dm::Isometry3;
using dm::Mat3;
using dm::Vec2;
using dm::Vec3;

constexpr int kWidth = 800, kHeight = 600;

dm::CameraIntrinsics camera() {
  dm::CameraIntrinsics c;
  c.matrix << 900.0, 0.0, 400.0, 0.0, 900.0, 300.0, 0.0, 0.0, 1.0;
  return c;
}

Isometry3 pose(const Vec3& axis, double angleDeg, const Vec3& t) {
  Isometry3 p = Isometry3::Identity();
  p.linear() = dm::AngleAxis(angleDeg * M_PI / 180.0, axis.normalized()).toRotationMatrix();
  p.translation() = t;
  return p;
}

// A pose whose plane faces the camera: the marker's z axis (out of the
// printed side) points back at the camera, i.e. `pose` composed with a half
// turn about x (a marker frame equal to the camera frame would show its back).
Isometry3 facing(const Vec3& axis, double angleDeg, const Vec3& t) {
  return pose(axis, angleDeg, t) * pose({1, 0, 0}, 180.0, Vec3::Zero());
}

double rotationErrorDeg(const Mat3& a, const Mat3& b) {
  return dm::AngleAxis(a.transpose() * b).angle() * 180.0 / M_PI;
}

cv::Mat toCv(const Mat3& m) {
  cv::Mat r(3, 3, CV_64F);
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) r.at<double>(i, j) = m(i, j);
  return r;
}

// Renders `texture` (texturePixel = A · (x, y, 1) for plane points (x, y, 0)
// in metres) into `frame` as seen from `cameraFromPlane`.
void renderPlane(cv::Mat& frame, const cv::Mat& texture, const Mat3& planeToTexture,
                 const Isometry3& cameraFromPlane) {
  Mat3 rt;
  rt.col(0) = cameraFromPlane.linear().col(0);
  rt.col(1) = cameraFromPlane.linear().col(1);
  rt.col(2) = cameraFromPlane.translation();
  const Mat3 h = camera().matrix * rt * planeToTexture.inverse();
  cv::warpPerspective(texture, frame, toCv(h), frame.size(), cv::INTER_LINEAR, cv::BORDER_TRANSPARENT);
}

// A marker of edge `length` metres centred on the plane origin (x right,
// y up), drawn at 200 px with a 50 px white quiet zone.
void renderMarker(cv::Mat& frame, int id, double length, const Isometry3& cameraFromMarker) {
  auto marker = dm::drawMarker("DICT_4X4_50", id, 200);
  ASSERT_TRUE(marker) << marker.error();
  cv::Mat canvas(300, 300, CV_8U, cv::Scalar(255));
  dm::asCvMat(*marker).copyTo(canvas(cv::Rect(50, 50, 200, 200)));
  Mat3 a;
  a << 200.0 / length, 0.0, 149.5, 0.0, -200.0 / length, 149.5, 0.0, 0.0, 1.0;
  renderPlane(frame, canvas, a, cameraFromMarker);
}

Vec2 project(const Isometry3& cameraFromPlane, const Vec3& p) {
  const Vec3 c = camera().matrix * (cameraFromPlane * p);
  return c.head<2>() / c.z();
}

TEST(Markers, SingleMarkerPoseMatchesTheRenderedPose) {
  const double length = 0.05;
  const Isometry3 truths[] = {facing({1, 0, 0}, 25.0, {0.02, -0.01, 0.35}),
                              facing({0.3, 1, 0.2}, -35.0, {-0.04, 0.03, 0.30}),
                              facing({0, 0, 1}, 60.0, {0.0, 0.0, 0.40})};
  for (const Isometry3& truth : truths) {
    cv::Mat frame(kHeight, kWidth, CV_8U, cv::Scalar(255));
    renderMarker(frame, 7, length, truth);
    auto image = dm::wrapCvMat(frame);
    ASSERT_TRUE(image);
    auto found = dm::detectMarkers(*image, "DICT_4X4_50");
    ASSERT_TRUE(found) << found.error();
    ASSERT_EQ(found->size(), 1u);
    EXPECT_EQ((*found)[0].id, 7);
    const double h = length / 2;
    const Vec3 model[4] = {{-h, h, 0}, {h, h, 0}, {h, -h, 0}, {-h, -h, 0}};
    for (int k = 0; k < 4; ++k)
      EXPECT_LT(((*found)[0].corners[static_cast<std::size_t>(k)] - project(truth, model[k])).norm(), 0.5)
          << "corner " << k;
    auto poses = dm::estimateMarkerPoses(*found, length, camera());
    ASSERT_TRUE(poses) << poses.error();
    const dm::MarkerPose& p = (*poses)[0];
    const double dRot = rotationErrorDeg(p.cameraFromMarker.linear(), truth.linear());
    const double dPos = (p.cameraFromMarker.translation() - truth.translation()).norm();
    std::printf("marker pose: rotation error %.3f deg, position error %.3f mm, reprojection %.3f px\n", dRot,
                1e3 * dPos, p.reprojectionError);
    // Measured: up to 0.5 deg and 0.7 mm (mostly depth) at 0.3-0.4 m.
    EXPECT_LT(dRot, 1.0);
    EXPECT_LT(dPos, 1.5e-3);
    EXPECT_LT(p.reprojectionError, 0.5);
  }
}

TEST(Markers, CharucoBoardPoseMatchesTheRenderedPose) {
  const dm::CharucoBoardSpec spec{5, 7, 0.04, 0.02, "DICT_4X4_50"};
  auto positions = dm::charucoCornerPositions(spec);
  ASSERT_TRUE(positions) << positions.error();
  ASSERT_EQ(positions->size(), 4u * 6u);
  // 100 px per square, board exactly filling the drawing.
  auto drawing = dm::drawCharucoBoard(spec, 500, 700, 0);
  ASSERT_TRUE(drawing) << drawing.error();
  // Where the board's corners lie in the drawing: found without a camera
  // model, then fitted by a homography that must be a pure scale + flip.
  auto flat = dm::detectCharucoBoard(*drawing, spec, std::nullopt);
  ASSERT_TRUE(flat) << flat.error();
  ASSERT_EQ(flat->ids.size(), positions->size());
  EXPECT_FALSE(flat->hasPose);
  std::vector<cv::Point2f> obj, px;
  for (std::size_t i = 0; i < flat->ids.size(); ++i) {
    const Vec3& p = (*positions)[static_cast<std::size_t>(flat->ids[i])];
    obj.emplace_back(static_cast<float>(p.x()), static_cast<float>(p.y()));
    px.emplace_back(static_cast<float>(flat->corners[i].x()), static_cast<float>(flat->corners[i].y()));
  }
  const cv::Mat hFlat = cv::findHomography(obj, px);
  ASSERT_FALSE(hFlat.empty());
  Mat3 a;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) a(i, j) = hFlat.at<double>(i, j) / hFlat.at<double>(2, 2);
  EXPECT_NEAR(std::abs(a(0, 0)), 100.0 / 0.04, 2.0);
  EXPECT_NEAR(std::abs(a(1, 1)), 100.0 / 0.04, 2.0);
  EXPECT_NEAR(a(0, 1), 0.0, 2.0);
  EXPECT_NEAR(a(1, 0), 0.0, 2.0);

  cv::Mat texture = dm::asCvMat(*drawing);
  cv::Mat padded(900, 700, CV_8U, cv::Scalar(255));  // white quiet zone around the board
  texture.copyTo(padded(cv::Rect(100, 100, 500, 700)));
  Mat3 shift = Mat3::Identity();
  shift(0, 2) = shift(1, 2) = 100.0;
  const Mat3 planeToPadded = shift * a;

  const Isometry3 truths[] = {pose({1, 0.2, 0}, 30.0, {-0.08, -0.12, 0.55}),
                              pose({0.2, 1, 0.1}, -25.0, {-0.1, -0.15, 0.6})};
  for (const Isometry3& truth : truths) {
    cv::Mat frame(kHeight, kWidth, CV_8U, cv::Scalar(128));
    renderPlane(frame, padded, planeToPadded, truth);
    auto image = dm::wrapCvMat(frame);
    ASSERT_TRUE(image);
    auto det = dm::detectCharucoBoard(*image, spec, camera());
    ASSERT_TRUE(det) << det.error();
    EXPECT_EQ(det->markers, 17);
    EXPECT_EQ(det->ids.size(), 24u);
    ASSERT_TRUE(det->hasPose);
    double sum = 0.0;
    for (std::size_t i = 0; i < det->ids.size(); ++i) {
      const double e =
          (det->corners[i] - project(truth, (*positions)[static_cast<std::size_t>(det->ids[i])])).norm();
      EXPECT_LT(e, 1.0);
      sum += e;
    }
    EXPECT_LT(sum / static_cast<double>(det->ids.size()), 0.5);
    const double dRot = rotationErrorDeg(det->cameraFromBoard.linear(), truth.linear());
    const double dPos = (det->cameraFromBoard.translation() - truth.translation()).norm();
    std::printf("charuco pose: rotation error %.3f deg, position error %.3f mm\n", dRot, 1e3 * dPos);
    EXPECT_LT(dRot, 0.3);
    EXPECT_LT(dPos, 1e-3);
  }
}

TEST(Markers, RegistrationOfDetectedMarkersRecoversTheRigPose) {
  // Four markers on a rig (model frame); the camera sees the rig at `truth`.
  const double length = 0.04;
  const std::map<int, Vec3> model = {
      {3, {0.0, 0.0, 0.0}}, {7, {0.12, 0.0, 0.0}}, {11, {0.0, 0.09, 0.0}}, {20, {0.12, 0.09, 0.0}}};
  const Isometry3 truth = facing({0.4, 1, 0.1}, 20.0, {-0.06, 0.04, 0.45});
  cv::Mat frame(kHeight, kWidth, CV_8U, cv::Scalar(255));
  for (const auto& [id, p] : model) {
    Isometry3 markerInModel = Isometry3::Identity();
    markerInModel.translation() = p;
    renderMarker(frame, id, length, truth * markerInModel);
  }
  auto image = dm::wrapCvMat(frame);
  ASSERT_TRUE(image);
  auto found = dm::detectMarkers(*image, "DICT_4X4_50");
  ASSERT_TRUE(found) << found.error();
  ASSERT_EQ(found->size(), 4u);
  auto poses = dm::estimateMarkerPoses(*found, length, camera());
  ASSERT_TRUE(poses) << poses.error();
  auto reg = dm::registerMarkers(*poses, model);
  ASSERT_TRUE(reg) << reg.error();
  EXPECT_EQ(reg->ids, (std::vector<int>{3, 7, 11, 20}));
  const dm::Registration& r = reg->registration;
  const double dRot = rotationErrorDeg(r.rotation, truth.linear());
  const double dPos = (r.translation - truth.translation()).norm();
  const Vec3 target(0.06, 0.045, -0.1);  // 10 cm behind the rig's centre
  auto tre = dm::targetRegistrationError(r, dm::Affine3(truth.matrix()), std::vector<Vec3>{target});
  ASSERT_TRUE(tre) << tre.error();
  std::printf(
      "marker registration: FRE %.3f mm, rotation error %.3f deg, translation error %.3f mm, TRE %.3f mm\n",
      1e3 * r.fre, dRot, 1e3 * dPos, 1e3 * tre->max);
  EXPECT_LT(r.fre, 1e-3);
  EXPECT_LT(dRot, 0.5);
  EXPECT_LT(dPos, 3e-3);  // measured 1.6 mm: the markers' depth errors
  EXPECT_LT(tre->max, 3e-3);
}

TEST(Markers, RegistrationFreMatchesTheNoiseLevel) {
  // Perturbed marker positions (isotropic Gaussian, sigma per axis): the
  // mean FRE² must be (1 − 2/N)·3σ² (dm/math/registration.hpp) and the
  // transform must be recovered to within the noise.
  std::mt19937 rng(5);
  std::normal_distribution<double> noise(0.0, 0.5e-3);
  std::uniform_real_distribution<double> u(-0.1, 0.1);
  const int n = 8, trials = 300;
  std::map<int, Vec3> model;
  for (int i = 0; i < n; ++i) model[10 + i] = Vec3(u(rng), u(rng), u(rng));
  const Isometry3 truth = pose({1, 2, 3}, 40.0, {0.1, -0.2, 0.5});
  double sumFre2 = 0.0, maxRot = 0.0;
  for (int t = 0; t < trials; ++t) {
    std::vector<dm::MarkerPose> detected;
    for (const auto& [id, p] : model) {
      dm::MarkerPose mp;
      mp.id = id;
      mp.cameraFromMarker.translation() = truth * p + Vec3(noise(rng), noise(rng), noise(rng));
      detected.push_back(mp);
    }
    auto reg = dm::registerMarkers(detected, model);
    ASSERT_TRUE(reg) << reg.error();
    sumFre2 += reg->registration.fre * reg->registration.fre;
    maxRot = std::max(maxRot, rotationErrorDeg(reg->registration.rotation, truth.linear()));
  }
  const double expected = (1.0 - 2.0 / n) * 3.0 * 0.5e-3 * 0.5e-3;
  const double ratio = sumFre2 / trials / expected;
  std::printf("mean FRE^2 / expected = %.3f, worst rotation error %.3f deg\n", ratio, maxRot);
  EXPECT_NEAR(ratio, 1.0, 0.1);
  EXPECT_LT(maxRot, 1.0);
}

TEST(Markers, BadInputIsAnErrorThatSaysWhat) {
  auto unknown = dm::detectMarkers(dm::Image{}, "DICT_9X9_7");
  ASSERT_FALSE(unknown);
  EXPECT_NE(unknown.error().what.find("DICT_9X9_7"), std::string::npos);
  EXPECT_NE(unknown.error().hint.find("DICT_4X4_50"), std::string::npos);
  EXPECT_FALSE(dm::drawMarker("DICT_4X4_50", 50, 100));
  EXPECT_FALSE(dm::drawMarker("DICT_4X4_50", 0, 3));
  EXPECT_FALSE(dm::estimateMarkerPoses({}, -1.0, camera()));
  dm::CameraIntrinsics bad;
  bad.matrix(0, 0) = 0.0;
  EXPECT_FALSE(dm::estimateMarkerPoses({}, 0.05, bad));
  EXPECT_FALSE(dm::charucoCornerPositions({5, 7, 0.02, 0.04, "DICT_4X4_50"}));    // marker larger than square
  EXPECT_FALSE(dm::charucoCornerPositions({20, 20, 0.04, 0.02, "DICT_4X4_50"}));  // needs 200 markers

  std::vector<dm::MarkerPose> two(2);
  two[0].id = 1;
  two[1].id = 2;
  auto few = dm::registerMarkers(two, {{1, Vec3::Zero()}, {2, Vec3::UnitX()}, {3, Vec3::UnitY()}});
  ASSERT_FALSE(few);
  EXPECT_NE(few.error().what.find("only 2"), std::string::npos);
  EXPECT_NE(few.error().where.find("1, 2"), std::string::npos);

  // A blank image holds no markers: an empty list, not an error.
  cv::Mat blank(100, 100, CV_8U, cv::Scalar(255));
  auto none = dm::detectMarkers(*dm::wrapCvMat(blank), "DICT_4X4_50");
  ASSERT_TRUE(none);
  EXPECT_TRUE(none->empty());
}

}  // namespace
