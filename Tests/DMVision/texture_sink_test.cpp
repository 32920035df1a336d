// The "texture" sink: the latest frame of a graph handed to a renderer with
// its frame number and channel order, and — when DMRenderer is built — the
// proof that a camera frame becomes a texture without conversion: OpenCV's
// BGR bytes go up as they are and the rendered pixels are the frame's RGB.
#include <dm/core/filesystem.hpp>
#include <dm/vision/cv_image.hpp>
#include <dm/vision/filter_graph.hpp>

#include <gtest/gtest.h>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include <string>
#include <vector>

#ifdef DM_TEST_WITH_RENDERER
#include <dm/math/primitives.hpp>
#include <dm/renderer/camera.hpp>
#include <dm/renderer/render_target.hpp>
#include <dm/renderer/scene_renderer.hpp>

#include "../DMRenderer/render_fixture.hpp"
#endif

namespace {

std::string videoPath() {
  auto p = dm::FileSystem::global().resolve("opencv:vtest.avi");
  EXPECT_TRUE(p) << p.error() << " (scripts/setup.sh installs opencv-doc)";
  return p ? p->string() : std::string();
}

/// Frames 0..count-1 of vtest.avi as OpenCV decodes them (BGR).
std::vector<cv::Mat> referenceFrames(int count) {
  cv::VideoCapture cap(videoPath());
  std::vector<cv::Mat> frames;
  cv::Mat f;
  while (static_cast<int>(frames.size()) < count && cap.read(f)) frames.push_back(f.clone());
  return frames;
}

/// Number of bytes in which `a` and `b` differ by more than `tolerance`.
int differingBytes(const cv::Mat& a, const cv::Mat& b, int tolerance) {
  cv::Mat diff;
  cv::absdiff(a, b, diff);
  return cv::countNonZero(diff.reshape(1) > tolerance);
}

dm::FilterGraph videoToTexture(const char* order) {
  dm::FilterGraph g;
  g.add("video", "video_file", {{"path", "opencv:vtest.avi"}, {"order", order}});
  g.add("endoscope", "texture", {}, {"video"});
  return g;
}

}  // namespace

TEST(TextureSink, HandsOutTheDecodedBgrBytesWithTheirFrameNumber) {
  const auto reference = referenceFrames(3);
  ASSERT_EQ(reference.size(), 3u);
  dm::FilterGraph g = videoToTexture("bgr");
  EXPECT_FALSE(g.texture("endoscope")) << "nothing before the first frame";
  ASSERT_TRUE(g.run({.maxFrames = 3}));
  auto t = g.texture("endoscope");
  ASSERT_TRUE(t);
  EXPECT_EQ(t->frame, 2);
  EXPECT_TRUE(t->bgr);
  const cv::Mat got = dm::asCvMat(t->image);
  ASSERT_EQ(got.size(), reference[2].size());
  ASSERT_EQ(got.type(), CV_8UC3);
  EXPECT_EQ(differingBytes(got, reference[2], 0), 0) << "the sink must not convert the decoder's bytes";
  EXPECT_EQ(g.texture("endoscope")->image.data(), t->image.data()) << "the frame is shared, not copied";
  EXPECT_FALSE(g.texture("video")) << "only sinks hold frames";

  dm::FilterGraph rgb = videoToTexture("rgb");
  ASSERT_TRUE(rgb.run({.maxFrames = 1}));
  auto r = rgb.texture("endoscope");
  ASSERT_TRUE(r);
  EXPECT_FALSE(r->bgr);
  cv::Mat expected;
  cv::cvtColor(reference[0], expected, cv::COLOR_BGR2RGB);
  EXPECT_EQ(differingBytes(dm::asCvMat(r->image), expected, 0), 0);
}

TEST(TextureSink, RefusesPixelsATextureCannotShowAndNamesTheNode) {
  for (const char* code : {"hsv", "lab"}) {
    dm::FilterGraph g;
    g.add("src", "synthetic", {{"width", 32}, {"height", 24}, {"frames", 2}});
    g.add("rgb", "color", {{"code", "rgb"}}, {"src"});
    g.add("conv", "color", {{"code", code}}, {"rgb"});
    g.add("tex", "texture", {}, {"conv"});
    auto run = g.run();
    ASSERT_FALSE(run) << code;
    const std::string msg = run.error().message();
    EXPECT_NE(msg.find("tex"), std::string::npos) << msg;
    EXPECT_NE(msg.find("8-bit gray, RGB or RGBA"), std::string::npos) << msg;
  }
  dm::FilterGraph f;
  f.add("src", "synthetic", {{"width", 32}, {"height", 24}, {"frames", 2}});
  f.add("f32", "convert", {{"to", "f32"}}, {"src"});
  f.add("tex", "texture", {}, {"f32"});
  auto run = f.run();
  ASSERT_FALSE(run);
  EXPECT_NE(run.error().message().find("CV_32F"), std::string::npos) << run.error().message();
}

#ifdef DM_TEST_WITH_RENDERER
TEST(TextureSink, CameraFramesBecomeRendererTexturesWithoutConversion) {
  DM_REQUIRE_GL();
  const auto reference = referenceFrames(2);
  ASSERT_EQ(reference.size(), 2u);
  const int w = reference[0].cols, h = reference[0].rows;
  auto scene = dm::SceneRenderer::create();
  auto target = dm::RenderTarget::create({.width = w, .height = h, .samples = 1});
  ASSERT_TRUE(scene && target);
  // A plane filling the orthographic view exactly: pixel centres land on texel centres.
  auto plane = scene->addMesh(dm::makePlane(0.5 * w / h, 0.5, 1));
  ASSERT_TRUE(plane);
  dm::Camera camera = dm::Camera::lookAt({0, 0, 2}, {0, 0, 0});
  camera.projection = dm::Camera::Projection::Orthographic;
  camera.orthoHeight = 1;
  const dm::RenderSettings settings{.background = dm::Vec4f(0, 0, 0, 1), .ambient = dm::Vec3f(0, 0, 0)};

  // The render thread's loop: upload when the graph has a newer frame.
  dm::FilterGraph g = videoToTexture("bgr");
  dm::TextureId tex;
  dm::MaterialId material;
  for (int frame = 0; frame < 2; ++frame) {
    ASSERT_TRUE(g.run({.maxFrames = 1}));
    auto t = g.texture("endoscope");
    ASSERT_TRUE(t);
    ASSERT_TRUE(t->bgr);
    if (!tex.valid()) {
      auto made = scene->addTexture(t->image, {.bgr = t->bgr, .mipmaps = false});
      ASSERT_TRUE(made) << made.error();
      tex = *made;
      auto m = scene->addMaterial(
          {.model = dm::ShadingModel::Unlit, .baseColor = dm::Vec4f(1, 1, 1, 1), .colorTexture = tex});
      ASSERT_TRUE(m);
      material = *m;
    } else {
      ASSERT_TRUE(scene->updateTexture(tex, t->image));
    }
    const dm::DrawItem item{.mesh = *plane, .material = material};
    ASSERT_TRUE(scene->render(*target, camera, {&item, 1}, {}, settings));
    auto shown = target->readColor();
    ASSERT_TRUE(shown) << shown.error();
    cv::Mat rgb;
    cv::cvtColor(dm::asCvMat(*shown), rgb, cv::COLOR_RGBA2RGB);
    cv::Mat expected;
    cv::cvtColor(reference[static_cast<std::size_t>(frame)], expected, cv::COLOR_BGR2RGB);
    // sRGB decode and re-encode may move a byte by one; nothing more.
    EXPECT_EQ(differingBytes(rgb, expected, 1), 0) << "frame " << frame;
  }
}
#endif
