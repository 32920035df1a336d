// vision_stereo_bench — SGBM disparity on Middlebury aloe (opencv-doc)
// through dm::computeDisparity versus the same OpenCV calls written by hand,
// and train / predict times of the dm::Classifier kinds on UCI letter.
//
// Links: DM::Vision plus OpenCV (core imgproc imgcodecs calib3d ml), with
// OpenCV's include dirs (the hand-written reference calls OpenCV directly).
// Run: build/Bench/vision_stereo_bench [iterations]
#include <dm/core/filesystem.hpp>
#include <dm/vision/classify.hpp>
#include <dm/vision/stereo.hpp>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

namespace {

double seconds(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

int main(int argc, char** argv) {
  const int iterations = argc > 1 ? std::max(1, std::atoi(argv[1])) : 5;
  auto lp = dm::FileSystem::global().resolve("opencv:aloeL.jpg");
  auto rp = dm::FileSystem::global().resolve("opencv:aloeR.jpg");
  if (!lp || !rp) {
    std::fprintf(stderr, "aloeL.jpg / aloeR.jpg missing: install the package opencv-doc\n");
    return 1;
  }
  auto left = dm::readImageFile(*lp, false);
  auto right = dm::readImageFile(*rp, false);
  if (!left || !right) {
    std::fprintf(stderr, "cannot read the aloe pair\n");
    return 1;
  }
  dm::SgbmOptions o;
  o.numDisparities = 224;  // as in stereo_test (aloe: true disparities up to 211 px)
  o.blockSize = 5;
  o.mode = dm::SgbmOptions::Mode::Sgbm3Way;

  // Hand-written OpenCV: same parameters, fixed-point output converted to
  // float pixels with the invalid marker mapped to NaN (what our API returns).
  const cv::Mat l = cv::imread(lp->string(), cv::IMREAD_COLOR),
                r = cv::imread(rp->string(), cv::IMREAD_COLOR);
  const int area = o.blockSize * o.blockSize;
  auto sgbm = cv::StereoSGBM::create(o.minDisparity, o.numDisparities, o.blockSize, 8 * 3 * area,
                                     32 * 3 * area, o.disp12MaxDiff, o.preFilterCap, o.uniquenessRatio,
                                     o.speckleWindowSize, o.speckleRange, cv::StereoSGBM::MODE_SGBM_3WAY);
  double tOurs = 0.0, tHand = 0.0;
  std::size_t sink = 0;
  for (int i = 0; i < iterations; ++i) {
    auto t0 = std::chrono::steady_clock::now();
    auto disp = dm::computeDisparity(*left, *right, o);
    tOurs += seconds(t0);
    if (!disp) {
      std::fprintf(stderr, "%s\n", disp.error().message().c_str());
      return 1;
    }
    sink += std::isfinite(disp->at<float>(600, 500)) ? 1 : 0;

    t0 = std::chrono::steady_clock::now();
    cv::Mat fixed, f;
    sgbm->compute(l, r, fixed);
    fixed.convertTo(f, CV_32F, 1.0 / 16.0);
    f.setTo(std::numeric_limits<float>::quiet_NaN(), fixed == static_cast<short>((o.minDisparity - 1) * 16));
    tHand += seconds(t0);
    sink += std::isfinite(f.at<float>(500, 600)) ? 1 : 0;
  }
  const double fpsOurs = iterations / tOurs, fpsHand = iterations / tHand;
  std::printf("SGBM aloe %dx%d, %d disparities, 3-way, %d iterations (sink %zu)\n", left->width(),
              left->height(), o.numDisparities, iterations, sink);
  std::printf("  dm::computeDisparity  %7.3f frames/s\n", fpsOurs);
  std::printf("  OpenCV by hand        %7.3f frames/s\n", fpsHand);
  std::printf("  ratio ours/hand time  %7.3f\n", fpsHand / fpsOurs);

  auto data = dm::readLetterData("opencv:letter-recognition.data");
  if (!data) {
    std::fprintf(stderr, "%s\n", data.error().message().c_str());
    return 1;
  }
  const dm::Dataset train = data->slice(0, 16000), test = data->slice(16000, 20000);
  std::printf("letter: train %zu, predict %zu samples\n", train.size(), test.size());
  for (auto kind : {dm::ClassifierKind::KNearest, dm::ClassifierKind::NormalBayes, dm::ClassifierKind::SvmRbf,
                    dm::ClassifierKind::Lda, dm::ClassifierKind::PcaKnn}) {
    auto clf = dm::Classifier::create(kind);
    auto t0 = std::chrono::steady_clock::now();
    if (!clf || !(*clf)->train(train)) return 1;
    const double tTrain = seconds(t0);
    t0 = std::chrono::steady_clock::now();
    auto pred = (*clf)->predict(test);
    const double tPredict = seconds(t0);
    if (!pred) return 1;
    std::size_t correct = 0;
    for (std::size_t i = 0; i < test.size(); ++i) correct += (*pred)[i] == test.labels[i] ? 1 : 0;
    std::printf("  %-8s train %8.3f s  predict %8.3f s (%6.2f us/sample)  accuracy %.2f %%\n",
                dm::toString(kind), tTrain, tPredict, 1e6 * tPredict / static_cast<double>(test.size()),
                100.0 * static_cast<double>(correct) / static_cast<double>(test.size()));
  }
  return 0;
}
