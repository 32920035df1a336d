// FilterGraph frame by frame (step) with host-fed "input" sources, as a
// scene's vision engine drives it: stepping gives the frames run() gives,
// an input's RGBA frame reaches the graph as RGB, a missing or misnamed
// input is an error naming it, and a source's end stops the steps.
#include <dm/vision/cv_image.hpp>
#include <dm/vision/filter_graph.hpp>

#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>

namespace filter_graph_step_test {

constexpr const char* kDiscGraph = R"({"nodes": [
  {"name": "src", "kind": "synthetic", "pattern": "moving_disc", "width": 160, "height": 90, "frames": 12,
   "velocity": [4, 1], "radius": 9},
  {"name": "blur", "kind": "gaussian_blur", "input": "src", "ksize": 5, "sigma": 1.2},
  {"name": "fg", "kind": "background_subtraction", "input": "blur", "learning_rate": 0.05},
  {"name": "out", "kind": "slot", "input": "fg"}
]})";

TEST(FilterGraphStep, StepsGiveTheFramesRunGives) {
  auto ran = dm::FilterGraph::parse(kDiscGraph);
  ASSERT_TRUE(ran) << ran.error();
  ASSERT_TRUE(ran->run());
  auto stepped = dm::FilterGraph::parse(kDiscGraph);
  ASSERT_TRUE(stepped) << stepped.error();
  int frames = 0;
  for (;;) {
    auto more = stepped->step();
    ASSERT_TRUE(more) << more.error();
    if (!*more) break;
    ++frames;
  }
  EXPECT_EQ(frames, 12);
  EXPECT_FALSE(*stepped->step()) << "an ended source stays ended";
  ASSERT_TRUE(stepped->finish());
  const cv::Mat a = dm::asCvMat(*ran->slot("out")), b = dm::asCvMat(*stepped->slot("out"));
  ASSERT_EQ(a.size(), b.size());
  EXPECT_EQ(cv::norm(a, b, cv::NORM_INF), 0.0) << "the background model saw the same 12 frames";
  EXPECT_GT(cv::countNonZero(b), 100) << "the moving disc is found";
  EXPECT_EQ(stepped->nodeStats()[0].calls, 13) << "12 frames read, then the end";
}

TEST(FilterGraphStep, AnInputSourceTakesTheHostsRgbaFramesAsRgb) {
  auto g = dm::FilterGraph::parse(R"({"nodes": [
    {"name": "camera", "kind": "input"},
    {"name": "gray", "kind": "color", "input": "camera", "code": "gray"},
    {"name": "mask", "kind": "threshold", "input": "gray", "value": 100},
    {"name": "out", "kind": "slot", "input": "mask"}
  ]})");
  ASSERT_TRUE(g) << g.error();
  ASSERT_TRUE(g->validate());
  EXPECT_EQ(g->inputs(), std::vector<std::string>{"camera"});
  auto none = g->step();
  ASSERT_FALSE(none);
  EXPECT_NE(none.error().message().find("input \"camera\" was given no image"), std::string::npos)
      << none.error();

  // A rendered frame: RGBA, the left half red (gray 76 < 100), the right
  // half white; alpha 255.
  auto rgba = dm::Image::create(64, 32, 4, dm::PixelType::U8);
  ASSERT_TRUE(rgba);
  for (int y = 0; y < 32; ++y)
    for (int x = 0; x < 64; ++x) {
      const bool right = x >= 32;
      rgba->at<std::uint8_t>(x, y, 0) = 255;
      rgba->at<std::uint8_t>(x, y, 1) = right ? 255 : 0;
      rgba->at<std::uint8_t>(x, y, 2) = right ? 255 : 0;
      rgba->at<std::uint8_t>(x, y, 3) = 255;
    }
  ASSERT_TRUE(g->setInput("camera", *rgba));
  ASSERT_TRUE(*g->step());
  const cv::Mat m = dm::asCvMat(*g->slot("out"));
  ASSERT_EQ(m.cols, 64);
  EXPECT_EQ(cv::countNonZero(m.colRange(0, 32)), 0) << "red is gray 76: below the threshold";
  EXPECT_EQ(cv::countNonZero(m.colRange(32, 64)), 32 * 32);
  // The same image is read again at the next step (the newest one holds).
  ASSERT_TRUE(*g->step());
  EXPECT_EQ(g->nodeStats()[0].calls, 3);

  const dm::Status wrong = g->setInput("endoscope", *rgba);
  ASSERT_FALSE(wrong);
  EXPECT_EQ(wrong.error().code, dm::ErrorCode::NotFound);
  EXPECT_NE(wrong.error().message().find("camera"), std::string::npos) << "names the inputs there are";
  auto twoChannel = dm::Image::create(8, 8, 2, dm::PixelType::U8);
  ASSERT_TRUE(g->setInput("camera", *twoChannel));
  auto bad = g->step();
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.error().message().find("node \"camera\" (input)"), std::string::npos) << bad.error();
}

}  // namespace filter_graph_step_test
