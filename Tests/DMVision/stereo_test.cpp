// Stereo calibration, rectification, SGBM and scoring on OpenCV's sample
// data (package opencv-doc): the chessboard pairs of stereo_calib.xml (9×6
// inner corners) and Middlebury's aloe pair with its ground truth.
#include <dm/core/filesystem.hpp>
#include <dm/vision/cv_image.hpp>
#include <dm/vision/stereo.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <opencv2/imgproc.hpp>
#include <optional>
#include <vector>

namespace {

constexpr double kSquare = 0.025;  // nominal square edge, metres (sets the scale of T, Q and points)

std::vector<dm::Vec2> rectifiedPoints(const dm::StereoCalibration& c, const dm::StereoRectification& r,
                                      const std::vector<dm::Vec2>& points, bool left) {
  auto p = dm::rectifyPoints(c, r, points, left);
  EXPECT_TRUE(p) << p.error();
  return p ? *p : std::vector<dm::Vec2>{};
}

std::optional<std::filesystem::path> sampleFile(const char* name) {
  auto p = dm::FileSystem::global().resolve(std::string("opencv:") + name);
  if (!p) return std::nullopt;
  return *p;
}

#define DM_REQUIRE_OPENCV_DOC(name) \
  if (!sampleFile(name))            \
  GTEST_SKIP() << "opencv:" << (name) << " is missing: install the package opencv-doc (scripts/setup.sh)"

// One calibration shared by the tests of this file (it is the slow part).
class StereoChessboard : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    if (!sampleFile("stereo_calib.xml")) return;
    auto pairs = dm::readStereoImageList("opencv:stereo_calib.xml");
    ASSERT_TRUE(pairs) << pairs.error();
    pairs_ = std::make_unique<std::vector<dm::StereoPair>>(*pairs);
    auto calib = dm::calibrateStereo(*pairs, {9, 6, kSquare});
    ASSERT_TRUE(calib) << calib.error();
    calib_ = std::make_unique<dm::StereoCalibration>(std::move(*calib));
    auto rect = dm::rectifyStereo(*calib_);
    ASSERT_TRUE(rect) << rect.error();
    rect_ = std::make_unique<dm::StereoRectification>(std::move(*rect));
  }
  static void TearDownTestSuite() {
    pairs_.reset();
    calib_.reset();
    rect_.reset();
  }
  void SetUp() override {
    DM_REQUIRE_OPENCV_DOC("stereo_calib.xml");
    ASSERT_TRUE(calib_ && rect_);
  }
  static std::unique_ptr<std::vector<dm::StereoPair>> pairs_;
  static std::unique_ptr<dm::StereoCalibration> calib_;
  static std::unique_ptr<dm::StereoRectification> rect_;
};
std::unique_ptr<std::vector<dm::StereoPair>> StereoChessboard::pairs_;
std::unique_ptr<dm::StereoCalibration> StereoChessboard::calib_;
std::unique_ptr<dm::StereoRectification> StereoChessboard::rect_;

TEST_F(StereoChessboard, CalibratesWithSubPixelReprojectionError) {
  const dm::StereoCalibration& c = *calib_;
  std::printf("stereo calibration: %zu of %zu pairs, RMS %.3f px, |T| = %.1f mm\n", c.usedPairs.size(),
              pairs_->size(), c.rms, 1e3 * c.translation.norm());
  EXPECT_EQ(c.imageWidth, 640);
  EXPECT_EQ(c.imageHeight, 480);
  EXPECT_GE(c.usedPairs.size(), 10u);
  EXPECT_LT(c.rms, 1.0);
  ASSERT_EQ(c.perViewErrors.size(), c.usedPairs.size());
  for (double e : c.perViewErrors) EXPECT_LT(e, 1.5);
  // R is a rotation; E = [T]x R and F = K2^-T E K1^-1 up to scale.
  EXPECT_NEAR(c.rotation.determinant(), 1.0, 1e-9);
  EXPECT_LT((c.rotation * c.rotation.transpose() - dm::Mat3::Identity()).norm(), 1e-9);
  dm::Mat3 tx;
  tx << 0, -c.translation.z(), c.translation.y(), c.translation.z(), 0, -c.translation.x(),
      -c.translation.y(), c.translation.x(), 0;
  const dm::Mat3 e = tx * c.rotation;
  EXPECT_LT((e / e.norm() - c.essential / c.essential.norm()).norm(), 1e-6);
  const dm::Mat3 f = c.rightMatrix.inverse().transpose() * e * c.leftMatrix.inverse();
  const double sign = (f.cwiseProduct(c.fundamental)).sum() > 0 ? 1.0 : -1.0;
  EXPECT_LT((f / f.norm() - sign * c.fundamental / c.fundamental.norm()).norm(), 1e-6);
}

TEST_F(StereoChessboard, RectifiedCornersLieOnTheSameRow) {
  // Geometric check of the rectification: corresponding corners of every
  // pair map to (nearly) the same row, and the rectified left image still
  // shows a board whose re-detected corners match the mapped ones.
  double sumDy = 0.0;
  std::size_t n = 0;
  for (std::size_t i = 0; i < calib_->usedPairs.size(); ++i) {
    const auto l = rectifiedPoints(*calib_, *rect_, calib_->leftCorners[i], true);
    const auto r = rectifiedPoints(*calib_, *rect_, calib_->rightCorners[i], false);
    ASSERT_EQ(l.size(), r.size());
    for (std::size_t k = 0; k < l.size(); ++k) {
      sumDy += std::abs(l[k].y() - r[k].y());
      EXPECT_GT(l[k].x() - r[k].x(), 0.0) << "corresponding points must have positive disparity";
      ++n;
    }
  }
  const double meanDy = sumDy / static_cast<double>(n);
  std::printf("rectification: mean |dy| = %.3f px over %zu corners\n", meanDy, n);
  EXPECT_LT(meanDy, 1.0);

  // The maps agree: corners found again in the remapped images lie on one row.
  auto left = dm::readImageFile(calib_->usedPairs[0].left, true);
  auto right = dm::readImageFile(calib_->usedPairs[0].right, true);
  ASSERT_TRUE(left && right);
  auto rectified = dm::rectifyImages(*rect_, *left, *right);
  ASSERT_TRUE(rectified) << rectified.error();
  auto cl = dm::findChessboardCorners(rectified->left, {9, 6, kSquare});
  auto cr = dm::findChessboardCorners(rectified->right, {9, 6, kSquare});
  ASSERT_TRUE(cl && cr);
  const auto mapped = rectifiedPoints(*calib_, *rect_, calib_->leftCorners[0], true);
  double dyImages = 0.0, dMapped = 0.0;
  for (std::size_t k = 0; k < cl->size(); ++k) {
    dyImages += std::abs((*cl)[k].y() - (*cr)[k].y());
    dMapped += ((*cl)[k] - mapped[k]).norm();
  }
  dyImages /= static_cast<double>(cl->size());
  dMapped /= static_cast<double>(cl->size());
  std::printf("rectified images: mean |dy| = %.3f px, re-detected vs mapped = %.3f px\n", dyImages, dMapped);
  EXPECT_LT(dyImages, 1.0);
  EXPECT_LT(dMapped, 1.0);
}

TEST_F(StereoChessboard, TriangulatedCornersHaveTheSquareSize) {
  // Q turns (x, y, disparity) of rectified corners into metric points: the
  // distance between neighbouring corners must be the square size.
  const double fx = rect_->leftProjection(0, 0);
  const double baseline = -rect_->rightProjection(0, 3) / rect_->rightProjection(0, 0);
  EXPECT_NEAR(baseline, calib_->translation.norm(), 1e-9 + 1e-6 * baseline);
  double sumErr = 0.0;
  int n = 0;
  for (std::size_t i = 0; i < calib_->usedPairs.size(); ++i) {
    const auto l = rectifiedPoints(*calib_, *rect_, calib_->leftCorners[i], true);
    const auto r = rectifiedPoints(*calib_, *rect_, calib_->rightCorners[i], false);
    std::vector<dm::Vec3> p;
    for (std::size_t k = 0; k < l.size(); ++k) {
      const dm::Vec4 h = rect_->q * dm::Vec4(l[k].x(), l[k].y(), l[k].x() - r[k].x(), 1.0);
      p.push_back(h.head<3>() / h.w());
      // Depth from the pinhole relation Z = f B / d.
      EXPECT_NEAR(p.back().z(), fx * baseline / (l[k].x() - r[k].x()), 1e-6);
    }
    for (int row = 0; row < 6; ++row)
      for (int col = 0; col + 1 < 9; ++col) {
        sumErr += std::abs((p[row * 9 + col + 1] - p[row * 9 + col]).norm() - kSquare);
        ++n;
      }
  }
  const double meanErr = sumErr / n;
  std::printf("triangulated square edge: mean |error| = %.3f mm of %.1f mm\n", 1e3 * meanErr, 1e3 * kSquare);
  EXPECT_LT(meanErr, 0.02 * kSquare);
}

TEST(Stereo, DisparityToPointsFollowsThePinholeModel) {
  // A fronto-parallel plane: constant disparity d gives Z = f B / d and
  // X = (x − cx) Z / f, Y = (y − cy) Z / f.
  const double f = 500.0, cx = 20.0, cy = 15.0, b = 0.06, d = 12.5;
  dm::Mat4 q = dm::Mat4::Zero();
  q(0, 0) = q(1, 1) = 1.0;
  q(0, 3) = -cx;
  q(1, 3) = -cy;
  q(2, 3) = f;
  q(3, 2) = 1.0 / b;
  auto disp = dm::Image::create(40, 30, 1, dm::PixelType::F32);
  ASSERT_TRUE(disp);
  for (int y = 0; y < 30; ++y)
    for (int x = 0; x < 40; ++x) disp->at<float>(x, y) = (x == 3 && y == 4) ? NAN : static_cast<float>(d);
  auto pts = dm::disparityToPoints(*disp, q);
  ASSERT_TRUE(pts) << pts.error();
  ASSERT_EQ(pts->size(), 40u * 30u - 1u);
  const double z = f * b / d;
  const dm::Vec3 first = (*pts)[0];
  EXPECT_NEAR(first.z(), z, 1e-6);
  EXPECT_NEAR(first.x(), (0 - cx) * z / f, 1e-6);
  EXPECT_NEAR(first.y(), (0 - cy) * z / f, 1e-6);
  const dm::Vec3 last = pts->back();
  EXPECT_NEAR(last.x(), (39 - cx) * z / f, 1e-6);
  EXPECT_NEAR(last.y(), (29 - cy) * z / f, 1e-6);

  auto u8 = dm::Image::create(4, 4, 1, dm::PixelType::U8);
  EXPECT_FALSE(dm::disparityToPoints(*u8, q));
}

TEST(Stereo, SgbmOnAloeMatchesMiddleburyGroundTruth) {
  // aloeGT.png is at the full 1282x1110 resolution and stores the disparity
  // in pixels (scale 1): its maximum, 211 px, is plausible for that width,
  // and the median of GT / SGBM over matched pixels is 1 (checked below).
  // Bound: SGBM (5x5 blocks, 3-way) measured 7.3 % bad pixels at 1 px over
  // the pixels it matched (~70 % of the known ground truth); asserted < 12 %.
  DM_REQUIRE_OPENCV_DOC("aloeGT.png");
  auto left = dm::readImageFile("opencv:aloeL.jpg", false);
  auto right = dm::readImageFile("opencv:aloeR.jpg", false);
  auto truth = dm::readImageFile("opencv:aloeGT.png", true);
  ASSERT_TRUE(left && right && truth);
  ASSERT_EQ(truth->width(), left->width());
  int maxGt = 0;
  for (int y = 0; y < truth->height(); ++y)
    for (int x = 0; x < truth->width(); ++x) maxGt = std::max<int>(maxGt, truth->at<std::uint8_t>(x, y));
  dm::SgbmOptions o;
  o.numDisparities = 224;  // > the largest true disparity
  o.blockSize = 5;
  o.mode = dm::SgbmOptions::Mode::Sgbm3Way;
  ASSERT_LT(maxGt, o.numDisparities);
  auto disp = dm::computeDisparity(*left, *right, o);
  ASSERT_TRUE(disp) << disp.error();
  std::vector<double> ratio;
  for (int y = 0; y < truth->height(); y += 5)
    for (int x = 0; x < truth->width(); x += 5) {
      const float d = disp->at<float>(x, y);
      const int g = truth->at<std::uint8_t>(x, y);
      if (g > 0 && std::isfinite(d) && d > 0) ratio.push_back(g / d);
    }
  ASSERT_FALSE(ratio.empty());
  std::nth_element(ratio.begin(), ratio.begin() + static_cast<std::ptrdiff_t>(ratio.size() / 2), ratio.end());
  const double medianRatio = ratio[ratio.size() / 2];
  auto s = dm::scoreDisparity(*disp, *truth, 1.0, 1.0);
  ASSERT_TRUE(s) << s.error();
  std::printf(
      "aloe SGBM: GT max %d px, median GT/SGBM %.3f; bad(1 px) %.2f %% of matched, %.2f %% of all known; "
      "coverage %.1f %%, mean |error| %.2f px\n",
      maxGt, medianRatio, 100 * s->badPixelRate, 100 * s->badPixelRateAll, 100 * s->coverage,
      s->meanAbsError);
  EXPECT_NEAR(medianRatio, 1.0, 0.02);
  EXPECT_GT(maxGt, 100);
  EXPECT_LT(s->badPixelRate, 0.12);
  EXPECT_GT(s->coverage, 0.6);
  EXPECT_LT(s->meanAbsError, 2.0);
  // A 2 px threshold forgives more.
  auto s2 = dm::scoreDisparity(*disp, *truth, 1.0, 2.0);
  ASSERT_TRUE(s2);
  EXPECT_LT(s2->badPixelRate, s->badPixelRate);
}

TEST(Stereo, ScoreCountsBadAndMissingPixels) {
  // 4 known truth pixels (value/2 = disparity): one exact, one 1.5 px off,
  // one missing (NaN), one 0.5 px off; one unknown truth pixel is ignored.
  auto truth = dm::Image::create(5, 1, 1, dm::PixelType::U8);
  auto disp = dm::Image::create(5, 1, 1, dm::PixelType::F32);
  ASSERT_TRUE(truth && disp);
  const std::uint8_t t[5] = {20, 40, 60, 0, 80};
  const float d[5] = {10.0f, 21.5f, NAN, 3.0f, 39.5f};
  for (int x = 0; x < 5; ++x) {
    truth->at<std::uint8_t>(x, 0) = t[x];
    disp->at<float>(x, 0) = d[x];
  }
  auto s = dm::scoreDisparity(*disp, *truth, 2.0, 1.0);
  ASSERT_TRUE(s) << s.error();
  EXPECT_EQ(s->validTruth, 4u);
  EXPECT_DOUBLE_EQ(s->coverage, 0.75);
  EXPECT_DOUBLE_EQ(s->badPixelRate, 1.0 / 3.0);
  EXPECT_DOUBLE_EQ(s->badPixelRateAll, 2.0 / 4.0);
  EXPECT_DOUBLE_EQ(s->meanAbsError, (0.0 + 1.5 + 0.5) / 3.0);
  EXPECT_FALSE(dm::scoreDisparity(*disp, *truth, 0.0, 1.0));
  EXPECT_FALSE(dm::scoreDisparity(*truth, *truth, 1.0, 1.0));
}

TEST(Stereo, ErrorsNameTheFileAndTheCount) {
  DM_REQUIRE_OPENCV_DOC("box.png");
  const std::vector<dm::StereoPair> missing = {{"/nonexistent/left42.jpg", "/nonexistent/right42.jpg"}};
  auto m = dm::calibrateStereo(missing, {9, 6, kSquare});
  ASSERT_FALSE(m);
  EXPECT_NE(m.error().message().find("left42.jpg"), std::string::npos) << m.error();
  // Pairs without a chessboard: skipped, then too few valid pairs.
  const auto box = *sampleFile("box.png");  // small, and no chessboard in it
  const std::vector<dm::StereoPair> noBoards = {{box, box}, {box, box}};
  auto few = dm::calibrateStereo(noBoards, {9, 6, kSquare});
  ASSERT_FALSE(few);
  EXPECT_NE(few.error().what.find("only 0 of 2 pairs"), std::string::npos) << few.error();
  dm::StereoCalibrationOptions strict;
  strict.requireAllPairs = true;
  auto named = dm::calibrateStereo(noBoards, {9, 6, kSquare}, strict);
  ASSERT_FALSE(named);
  EXPECT_NE(named.error().message().find("box.png"), std::string::npos) << named.error();
  EXPECT_FALSE(dm::readStereoImageList("/nonexistent/stereo_calib.xml"));
  EXPECT_FALSE(dm::calibrateStereo({}, {1, 6, kSquare}));
  auto img = dm::Image::create(64, 64, 1, dm::PixelType::U8);
  EXPECT_FALSE(dm::computeDisparity(*img, *img, {.numDisparities = 20}));
  EXPECT_FALSE(dm::computeDisparity(*img, *img, {.blockSize = 4}));
  EXPECT_FALSE(dm::rectifyStereo(dm::StereoCalibration{}));
}

}  // namespace

#undef DM_REQUIRE_OPENCV_DOC
