// FilterGraph: results equal the same OpenCV calls written by hand (on the
// real vtest.avi), parallel and sequential runs agree, synthetic motion is
// measured at its known velocity, buffers handed out are never overwritten,
// and every kind of mistake in a graph description is reported with its path.
#include <dm/core/filesystem.hpp>
#include <dm/io/volume_io.hpp>
#include <dm/vision/cv_image.hpp>
#include <dm/vision/filter_graph.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <numbers>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "../common/temp_dir.hpp"

namespace {

std::string dataFile(const std::string& name) {
  auto p = dm::FileSystem::global().resolve(name);
  EXPECT_TRUE(p) << p.error() << " (scripts/setup.sh installs opencv-doc and mricron-data)";
  return p ? p->string() : std::string();
}

cv::Mat matOf(const dm::Image& img) { return dm::asCvMat(img); }

bool sameMat(const cv::Mat& a, const cv::Mat& b) {
  if (a.size() != b.size() || a.type() != b.type()) return false;
  cv::Mat diff;
  cv::absdiff(a, b, diff);
  return cv::countNonZero(diff.reshape(1)) == 0;
}

/// The graph of the acceptance line: vtest.avi → gray → blur → Canny.
constexpr const char* kVideoGraph = R"({"nodes": [
  {"name": "video", "kind": "video_file", "path": "opencv:vtest.avi", "order": "bgr"},
  {"name": "gray", "kind": "color", "input": "video", "code": "gray"},
  {"name": "blur", "kind": "gaussian_blur", "input": "gray", "ksize": 5, "sigma": 1.5},
  {"name": "edges", "kind": "canny", "input": "blur", "low": 40, "high": 120},
  {"name": "out", "kind": "callback", "input": "edges"}
]})";

std::vector<cv::Mat> runVideoGraph(bool parallel, int frames) {
  auto g = dm::FilterGraph::parse(kVideoGraph);
  EXPECT_TRUE(g) << g.error();
  if (!g) return {};
  std::vector<cv::Mat> got;
  EXPECT_TRUE(g->setCallback("out", [&](const dm::GraphValue& v, std::int64_t frame) {
    EXPECT_EQ(frame, std::int64_t(got.size()));
    got.push_back(matOf(*v.image).clone());
  }));
  auto stats = g->run({.maxFrames = frames, .parallel = parallel});
  EXPECT_TRUE(stats) << stats.error();
  if (stats) {
    EXPECT_EQ(stats->frames, frames);
    EXPECT_EQ(stats->nodes.size(), 5u);
    EXPECT_EQ(stats->nodes[0].calls, frames) << "sources read exactly the frames run";
  }
  return got;
}

}  // namespace

TEST(FilterGraph, VideoPipelineEqualsTheOpenCvCallsWrittenByHand) {
  const int frames = 12;
  const auto graph = runVideoGraph(true, frames);
  ASSERT_EQ(int(graph.size()), frames);
  cv::VideoCapture cap(dataFile("opencv:vtest.avi"));
  ASSERT_TRUE(cap.isOpened());
  cv::Mat frame, gray, blur, edges;
  for (int k = 0; k < frames; ++k) {
    ASSERT_TRUE(cap.read(frame));
    cv::cvtColor(frame, gray, cv::COLOR_BGR2GRAY);
    cv::GaussianBlur(gray, blur, cv::Size(5, 5), 1.5, 1.5, cv::BORDER_REFLECT_101);
    cv::Canny(blur, edges, 40, 120);
    EXPECT_TRUE(sameMat(graph[std::size_t(k)], edges)) << "frame " << k;
    EXPECT_GT(cv::countNonZero(edges), 1000) << "a real picture has edges";
  }
  const auto sequential = runVideoGraph(false, frames);
  ASSERT_EQ(sequential.size(), graph.size());
  for (std::size_t k = 0; k < graph.size(); ++k) EXPECT_TRUE(sameMat(graph[k], sequential[k])) << k;
}

TEST(FilterGraph, DiamondBranchesJoinPerFrame) {
  // One source feeding two branches that join in absdiff: the join must see
  // both branches of the same frame.
  auto g = dm::FilterGraph::parse(R"({"nodes": [
    {"name": "src", "kind": "synthetic", "pattern": "moving_texture", "width": 96, "height": 64, "frames": 6,
     "velocity": [2, 1]},
    {"name": "a", "kind": "gaussian_blur", "input": "src", "ksize": 7, "sigma": 2},
    {"name": "b", "kind": "median_blur", "input": "src", "ksize": 3},
    {"name": "d", "kind": "absdiff", "inputs": ["a", "b"]},
    {"name": "n", "kind": "count_nonzero", "input": "d"},
    {"name": "img", "kind": "callback", "input": "src"},
    {"name": "cnt", "kind": "callback", "input": "n"}
  ]})");
  ASSERT_TRUE(g) << g.error();
  std::vector<cv::Mat> sources;
  std::vector<double> counts;
  ASSERT_TRUE(g->setCallback(
      "img", [&](const dm::GraphValue& v, std::int64_t) { sources.push_back(matOf(*v.image).clone()); }));
  ASSERT_TRUE(g->setCallback("cnt", [&](const dm::GraphValue& v, std::int64_t) {
    EXPECT_EQ(v.type, dm::PortType::Number);
    counts.push_back(v.scalar);
  }));
  auto stats = g->run();
  ASSERT_TRUE(stats) << stats.error();
  EXPECT_EQ(stats->frames, 6);
  ASSERT_EQ(counts.size(), 6u);
  ASSERT_EQ(sources.size(), 6u);
  for (std::size_t k = 0; k < 6; ++k) {
    cv::Mat a, b, d;
    cv::GaussianBlur(sources[k], a, cv::Size(7, 7), 2, 2, cv::BORDER_REFLECT_101);
    cv::medianBlur(sources[k], b, 3);
    cv::absdiff(a, b, d);
    EXPECT_EQ(counts[k], double(cv::countNonZero(d))) << "frame " << k;
  }
  // The texture moves by (2, 1) px per frame.
  EXPECT_TRUE(sameMat(sources[1](cv::Rect(10, 10, 40, 30)), sources[0](cv::Rect(8, 9, 40, 30))));
}

TEST(FilterGraph, OpticalFlowMeasuresTheKnownVelocity) {
  const double vx = 1.5, vy = -0.75;
  dm::FilterGraph g;
  g.add("src", "synthetic",
        {{"pattern", "moving_texture"},
         {"width", 160},
         {"height", 120},
         {"frames", 4},
         {"velocity", {vx, vy}},
         {"seed", 7}});
  g.add("flow", "optical_flow", {{"window", 21}, {"levels", 3}}, {"src"});
  g.add("mag", "vector_magnitude", {}, {"flow"});
  g.add("out", "callback", {}, {"flow"});
  g.add("speed", "callback", {}, {"mag"});
  std::vector<cv::Scalar> means;
  std::vector<double> speeds;
  const cv::Rect interior(24, 24, 112, 72);
  ASSERT_TRUE(g.setCallback("out", [&](const dm::GraphValue& v, std::int64_t) {
    means.push_back(cv::mean(matOf(*v.image)(interior)));
  }));
  ASSERT_TRUE(g.setCallback("speed", [&](const dm::GraphValue& v, std::int64_t) {
    speeds.push_back(cv::mean(matOf(*v.image)(interior))[0]);
  }));
  auto stats = g.run();
  ASSERT_TRUE(stats) << stats.error();
  ASSERT_EQ(means.size(), 4u);
  EXPECT_EQ(means[0][0], 0.0) << "no flow before a previous frame exists";
  for (std::size_t k = 1; k < means.size(); ++k) {
    EXPECT_NEAR(means[k][0], vx, 0.1) << "frame " << k;
    EXPECT_NEAR(means[k][1], vy, 0.1) << "frame " << k;
    EXPECT_NEAR(speeds[k], std::hypot(vx, vy), 0.15) << "frame " << k;
  }
}

TEST(FilterGraph, BackgroundSubtractionFindsTheMovingDisc) {
  // A disc crossing a textured background at 5 px per frame. With a slow
  // fixed learning rate the disc never enters the background model (each
  // pixel is white for under 6 frames, weight < 0.06 < 1 - backgroundRatio)
  // and the first frame's disc position fades within the run.
  const double r = 14;
  auto g = dm::FilterGraph::parse(R"({"nodes": [
    {"name": "src", "kind": "synthetic", "pattern": "moving_disc", "width": 320, "height": 120, "frames": 30,
     "velocity": [5, 0], "radius": 14},
    {"name": "fg", "kind": "background_subtraction", "input": "src", "learning_rate": 0.01},
    {"name": "clean", "kind": "morphology", "input": "fg", "op": "open", "size": 3},
    {"name": "out", "kind": "slot", "input": "clean"}
  ]})");
  ASSERT_TRUE(g) << g.error();
  ASSERT_TRUE(g->run());
  auto mask = g->slot("out");
  ASSERT_TRUE(mask);
  const cv::Mat m = matOf(*mask);
  const double area = cv::countNonZero(m);
  EXPECT_NEAR(area / (std::numbers::pi * r * r), 1.0, 0.15) << area << " px in " << cv::boundingRect(m);
  const cv::Moments mo = cv::moments(m, true);
  ASSERT_GT(mo.m00, 0);
  EXPECT_NEAR(mo.m10 / mo.m00, 320 / 4.0 + 5 * 29, 1.0) << "disc centre x at the last frame";
  EXPECT_NEAR(mo.m01 / mo.m00, 60.0, 1.0);
}

TEST(FilterGraph, ImagesHandedOutAreNeverOverwritten) {
  // A callback keeps each frame's dm::Image (sharing the node's buffer):
  // later frames must land in new buffers, not in the kept ones.
  auto g = dm::FilterGraph::parse(R"({"nodes": [
    {"name": "src", "kind": "synthetic", "pattern": "moving_texture", "width": 64, "height": 48, "frames": 5},
    {"name": "blur", "kind": "gaussian_blur", "input": "src", "ksize": 3, "sigma": 1},
    {"name": "keep", "kind": "callback", "input": "blur"},
    {"name": "copy", "kind": "callback", "input": "blur"},
    {"name": "last", "kind": "slot", "input": "blur"}
  ]})");
  ASSERT_TRUE(g) << g.error();
  std::vector<dm::Image> kept;
  std::vector<cv::Mat> copies;
  ASSERT_TRUE(
      g->setCallback("keep", [&](const dm::GraphValue& v, std::int64_t) { kept.push_back(*v.image); }));
  ASSERT_TRUE(g->setCallback(
      "copy", [&](const dm::GraphValue& v, std::int64_t) { copies.push_back(matOf(*v.image).clone()); }));
  ASSERT_TRUE(g->run());
  ASSERT_EQ(kept.size(), 5u);
  for (std::size_t k = 0; k < kept.size(); ++k) EXPECT_TRUE(sameMat(matOf(kept[k]), copies[k])) << k;
  auto last = g->slot("last");
  ASSERT_TRUE(last);
  EXPECT_EQ(last->data(), g->slot("last")->data()) << "slot() hands out the buffer, not a copy";
  EXPECT_TRUE(sameMat(matOf(*last), copies.back()));
  EXPECT_FALSE(g->slot("nothing"));
}

TEST(FilterGraph, VolumeSliceShowsTheVoxels) {
  auto vol = dm::readVolume(dataFile("mricron:ch2.nii.gz"));
  ASSERT_TRUE(vol) << vol.error();
  auto g = dm::FilterGraph::parse(R"({"nodes": [
    {"name": "vol", "kind": "volume_file", "path": "mricron:ch2.nii.gz"},
    {"name": "axial", "kind": "volume_slice", "input": "vol", "axis": "z", "index": 90},
    {"name": "sag", "kind": "volume_slice", "input": "vol", "axis": "x"},
    {"name": "a", "kind": "slot", "input": "axial"},
    {"name": "s", "kind": "slot", "input": "sag"}
  ]})");
  ASSERT_TRUE(g) << g.error();
  auto stats = g->run();
  ASSERT_TRUE(stats) << stats.error();
  EXPECT_EQ(stats->frames, 1);
  auto a = g->slot("a"), s = g->slot("s");
  ASSERT_TRUE(a && s);
  const dm::Vec3i d = vol->dims();
  EXPECT_EQ(a->width(), d.x());
  EXPECT_EQ(a->height(), d.y());
  EXPECT_EQ(s->width(), d.y());
  EXPECT_EQ(s->height(), d.z());
  for (auto [i, j] : {std::pair{90, 100}, std::pair{30, 150}, std::pair{120, 60}})
    EXPECT_EQ(a->at<float>(i, j), float(vol->value(i, j, 90)));
  EXPECT_EQ(s->at<float>(100, 80), float(vol->value(d.x() / 2, 100, 80)));
}

TEST(FilterGraph, FileAndCsvSinksWriteWhatTheyGet) {
  dm::test::TempDir dir("filter_graph_sinks");
  dm::FilterGraph g;
  g.add("src", "image_sequence",
        {{"files", {"opencv:left01.jpg", "opencv:left02.jpg", "opencv:left03.jpg"}}, {"mode", "gray"}});
  g.add("th", "adaptive_threshold", {{"block", 15}, {"c", 5}}, {"src"});
  g.add("png", "file", {{"pattern", (dir / "th_%02d.png").string()}, {"every", 2}}, {"th"});
  g.add("m", "mean", {}, {"src"});
  g.add("csv", "csv", {{"path", (dir / "mean.csv").string()}}, {"m"});
  auto stats = g.run();
  ASSERT_TRUE(stats) << stats.error();
  EXPECT_EQ(stats->frames, 3);
  EXPECT_TRUE(std::filesystem::exists(dir / "th_00.png"));
  EXPECT_FALSE(std::filesystem::exists(dir / "th_01.png"));
  EXPECT_TRUE(std::filesystem::exists(dir / "th_02.png"));
  const cv::Mat left3 = cv::imread(dataFile("opencv:left03.jpg"), cv::IMREAD_GRAYSCALE);
  cv::Mat expect;
  cv::adaptiveThreshold(left3, expect, 255, cv::ADAPTIVE_THRESH_MEAN_C, cv::THRESH_BINARY, 15, 5);
  EXPECT_TRUE(sameMat(cv::imread((dir / "th_02.png").string(), cv::IMREAD_UNCHANGED), expect));
  std::ifstream csv(dir / "mean.csv");
  std::string header, line;
  std::getline(csv, header);
  EXPECT_EQ(header, "frame,value");
  int rows = 0;
  while (std::getline(csv, line)) {
    const auto comma = line.find(',');
    ASSERT_NE(comma, std::string::npos);
    const cv::Mat img =
        cv::imread(dataFile("opencv:left0" + std::to_string(rows + 1) + ".jpg"), cv::IMREAD_GRAYSCALE);
    EXPECT_NEAR(std::stod(line.substr(comma + 1)), cv::mean(img)[0], 1e-6);
    ++rows;
  }
  EXPECT_EQ(rows, 3);
}

TEST(FilterGraph, ColourOrderIsTrackedThroughConversions) {
  // An RGB source (the default) and a BGR source of the same file give the
  // same gray image, and the RGB pixels are the BGR ones reversed.
  dm::FilterGraph g;
  g.add("rgb", "image_file", {{"path", "opencv:aloeL.jpg"}});
  g.add("bgr", "image_file", {{"path", "opencv:aloeL.jpg"}, {"order", "bgr"}});
  g.add("g1", "color", {{"code", "gray"}}, {"rgb"});
  g.add("g2", "color", {{"code", "gray"}}, {"bgr"});
  g.add("s1", "slot", {}, {"g1"});
  g.add("s2", "slot", {}, {"g2"});
  g.add("c1", "slot", {}, {"rgb"});
  g.add("c2", "slot", {}, {"bgr"});
  ASSERT_TRUE(g.run());
  EXPECT_TRUE(sameMat(matOf(*g.slot("s1")), matOf(*g.slot("s2"))));
  const dm::Image rgb = *g.slot("c1"), bgr = *g.slot("c2");
  EXPECT_EQ(rgb.at<std::uint8_t>(100, 50, 0), bgr.at<std::uint8_t>(100, 50, 2));
  EXPECT_EQ(rgb.at<std::uint8_t>(100, 50, 2), bgr.at<std::uint8_t>(100, 50, 0));
}

TEST(FilterGraph, EveryMistakeIsReportedWithItsPath) {
  auto g = dm::FilterGraph::parse(R"({"nodes": [
    {"name": "src", "kind": "synthetic"},
    {"name": "blur", "kind": "gausian_blur", "input": "src"},
    {"name": "med", "kind": "median_blur", "input": "src", "ksize": 4},
    {"name": "thr", "kind": "threshold", "input": "srcc", "valeu": 3},
    {"name": "vs", "kind": "volume_slice", "input": "src"},
    {"name": "two", "kind": "absdiff", "input": "src"},
    {"name": "med", "kind": "mean", "input": "src"}
  ]})",
                                  "graph.json");
  ASSERT_FALSE(g);
  const std::string m = g.error().message();
  EXPECT_NE(m.find("graph.json: /nodes/1/kind"), std::string::npos) << m;
  EXPECT_NE(m.find("did you mean \"gaussian_blur\""), std::string::npos) << m;
  EXPECT_NE(m.find("/nodes/2/ksize"), std::string::npos) << m;
  EXPECT_NE(m.find("must be odd"), std::string::npos) << m;
  EXPECT_NE(m.find("/nodes/3/input"), std::string::npos) << m;
  EXPECT_NE(m.find("did you mean \"src\""), std::string::npos) << m;
  EXPECT_NE(m.find("unknown key \"valeu\""), std::string::npos) << m;
  EXPECT_NE(m.find("needs a volume, but \"src\" (synthetic) gives an image"), std::string::npos) << m;
  EXPECT_NE(m.find("absdiff takes 2 inputs, got 1"), std::string::npos) << m;
  EXPECT_NE(m.find("\"med\" is used twice"), std::string::npos) << m;
}

TEST(FilterGraph, CyclesAndStructuralProblemsAreRefused) {
  dm::FilterGraph g;
  g.add("src", "synthetic");
  g.add("a", "absdiff", {}, {"src", "b"});
  g.add("b", "gaussian_blur", {}, {"a"});
  auto s = g.validate();
  ASSERT_FALSE(s);
  EXPECT_NE(s.error().what.find("cycle"), std::string::npos) << s.error();
  EXPECT_NE(s.error().what.find("a -> b"), std::string::npos) << s.error();

  dm::FilterGraph sinkIn;
  sinkIn.add("src", "synthetic");
  sinkIn.add("out", "slot", {}, {"src"});
  sinkIn.add("after", "gaussian_blur", {}, {"out"});
  auto s2 = sinkIn.validate();
  ASSERT_FALSE(s2);
  EXPECT_NE(s2.error().what.find("is a sink and has no output"), std::string::npos) << s2.error();

  dm::FilterGraph noSource;
  noSource.add("b", "gaussian_blur", {}, {});
  EXPECT_FALSE(noSource.validate());
  EXPECT_FALSE(dm::FilterGraph().validate());
  EXPECT_FALSE(dm::FilterGraph::parse(R"({"nodes": 3})"));
  EXPECT_FALSE(dm::FilterGraph::parse(R"({"nodes": [1]})"));
  EXPECT_FALSE(
      dm::FilterGraph::parse(R"({"nodes": [{"name": "v", "kind": "video_file", "path": "/no/such.avi"}]})"));
  dm::FilterGraph cb;
  cb.add("src", "synthetic");
  cb.add("s", "slot", {}, {"src"});
  EXPECT_FALSE(cb.setCallback("s", [](const dm::GraphValue&, std::int64_t) {}));
  EXPECT_FALSE(cb.setCallback("nope", [](const dm::GraphValue&, std::int64_t) {}));
}

TEST(FilterGraph, NodeErrorsWhileRunningNameTheNodeAndFrame) {
  // Canny needs 8-bit input; a float Sobel image is refused at frame 0.
  auto g = dm::FilterGraph::parse(R"({"nodes": [
    {"name": "src", "kind": "synthetic", "frames": 3},
    {"name": "dx", "kind": "sobel", "input": "src"},
    {"name": "edges", "kind": "canny", "input": "dx"},
    {"name": "out", "kind": "slot", "input": "edges"}
  ]})");
  ASSERT_TRUE(g) << g.error();
  auto stats = g->run();
  ASSERT_FALSE(stats);
  EXPECT_NE(stats.error().where.find("node \"edges\" (canny), frame 0"), std::string::npos) << stats.error();
  EXPECT_NE(stats.error().hint.find("convert"), std::string::npos) << stats.error();
}

TEST(FilterGraph, KindsDescribeTheirPorts) {
  const auto& kinds = dm::FilterGraph::kinds();
  EXPECT_GE(kinds.size(), 30u);
  int sources = 0, sinks = 0;
  for (const auto& k : kinds) {
    EXPECT_FALSE(k.summary.empty()) << k.kind;
    if (k.role == "source") {
      ++sources;
      EXPECT_TRUE(k.inputs.empty() && k.output) << k.kind;
    }
    if (k.role == "sink") {
      ++sinks;
      EXPECT_FALSE(k.output) << k.kind;
    }
  }
  EXPECT_GE(sources, 5);
  EXPECT_GE(sinks, 4);
}
