// A scene's vision engine as a simulated endoscope: the render engine's
// frames go through a DMVision filter graph one frame per tick. The frames
// the graph gets are the rendered frames (pixel for pixel the PNGs the
// render engine writes), the graph's own measurement (edge pixels, CSV)
// equals the same filters run afterwards on those frames, its files land in
// the run's folder, and a graph that cannot be built fails before anything
// runs, naming its JSON path.
#include <dm/engine/scene_runtime.hpp>
#include <dm/io/image_io.hpp>
#include <dm/io/scene_file.hpp>

#include <gtest/gtest.h>

#include <fstream>
#include <sstream>

#include "../common/temp_dir.hpp"
#include "scene_run_support.hpp"

namespace scene_vision_test {

using nlohmann::json;
namespace fs = std::filesystem;

#if defined(DM_TEST_WITH_RENDERER) && defined(DM_TEST_WITH_VISION)

// The box push seen by a 160 x 120 "endoscope" at 30 Hz, its frames
// filtered at 10 Hz: the camera frame and its Canny edges to PNG files, the
// edge-pixel count per frame to a CSV.
dm::SceneDesc endoscopeBoxPush() {
  dm::SceneDesc scene = scene_run::bundledScene("box_push.json");
  scene.engines.render = dm::SceneRenderEngine{.rateHz = 30, .camera = "side", .width = 160, .height = 120};
  scene.engines.render->hud = false;  // the written frames are then the camera's view too
  scene.outputs.frames = true;
  scene.outputs.frameEvery = 1;
  scene.outputs.recording = false;
  dm::SceneVisionEngine v;
  v.rateHz = 10;
  v.graph = json::parse(R"({"nodes": [
    {"name": "endoscope", "kind": "input"},
    {"name": "raw", "kind": "file", "input": "endoscope", "pattern": "vision/camera_%03d.png"},
    {"name": "gray", "kind": "color", "input": "endoscope", "code": "gray"},
    {"name": "edges", "kind": "canny", "input": "gray", "low": 40, "high": 120},
    {"name": "edge_files", "kind": "file", "input": "edges", "pattern": "vision/edges_%03d.png"},
    {"name": "count", "kind": "count_nonzero", "input": "edges"},
    {"name": "counts", "kind": "csv", "input": "count", "path": "vision/edge_pixels.csv"}
  ]})");
  scene.engines.vision = v;
  return scene;
}

TEST(SceneVision, TheEndoscopeGraphFiltersTheRenderedFrames) {
  const dm::test::TempDir dir("vision_endoscope");
  const json s = scene_run::runScene(endoscopeBoxPush(), 1.0, dir.path());
  ASSERT_TRUE(s.contains("vision")) << s.dump(2);
  // 10 Hz over 0..1 s, each tick with a frame rendered since the last.
  const int frames = s["vision"]["frames"];
  EXPECT_EQ(frames, 10);
  EXPECT_EQ(s["vision"]["inputs"], json::array({"endoscope"}));

  // Vision frame j is the newest rendered at t = j / 10 s: render frame 3j
  // (render ticks before vision at equal times in lockstep).
  for (int j = 0; j < frames; ++j) {
    auto seen = dm::readPng(dir / "vision" / dm::formatString("camera_%03d.png", j));
    auto drawn = dm::readPng(dir / "frames" / dm::formatString("frame_%05d.png", 3 * j));
    ASSERT_TRUE(seen) << seen.error();
    ASSERT_TRUE(drawn) << drawn.error();
    ASSERT_EQ(seen->width(), 160);
    ASSERT_EQ(seen->height(), 120);
    ASSERT_EQ(seen->channels(), 3);
    int differ = 0;
    for (int y = 0; y < 120; ++y)
      for (int x = 0; x < 160; ++x)
        for (int c = 0; c < 3; ++c)
          differ += seen->at<std::uint8_t>(x, y, c) != drawn->at<std::uint8_t>(x, y, c);
    EXPECT_EQ(differ, 0) << "vision frame " << j << " is not render frame " << 3 * j;
  }

  // The CSV holds each frame's edge-pixel count, which is what the edge
  // images hold: the graph's measurement is its images'.
  std::ifstream csv(dir / "vision" / "edge_pixels.csv");
  std::string line;
  int rows = 0;
  while (std::getline(csv, line)) {
    if (line.empty() || !std::isdigit(static_cast<unsigned char>(line[0]))) continue;
    std::istringstream cells(line);
    std::string frame, value;
    std::getline(cells, frame, ',');
    std::getline(cells, value, ',');
    auto edges = dm::readPng(dir / "vision" / dm::formatString("edges_%03d.png", std::stoi(frame)));
    ASSERT_TRUE(edges) << edges.error();
    int count = 0;
    for (int y = 0; y < edges->height(); ++y)
      for (int x = 0; x < edges->width(); ++x) count += edges->at<std::uint8_t>(x, y, 0) != 0;
    EXPECT_EQ(std::stod(value), count) << "frame " << frame;
    EXPECT_GT(count, 50) << "the table and the box have edges";
    EXPECT_LT(count, 160 * 120 / 4);
    ++rows;
  }
  EXPECT_EQ(rows, frames);
}

// The graph's result drawn over the view: a half-size edge image in a
// "texture" sink, shown 1:1 in the lower-left corner of the next frames.
TEST(SceneVision, TheOverlayShowsTheGraphsNewestImageOverTheView) {
  dm::SceneDesc scene = endoscopeBoxPush();
  scene.engines.vision->graph = json::parse(R"({"nodes": [
    {"name": "endoscope", "kind": "input"},
    {"name": "small", "kind": "resize", "input": "endoscope", "width": 80, "height": 60},
    {"name": "gray", "kind": "color", "input": "small", "code": "gray"},
    {"name": "edges", "kind": "canny", "input": "gray", "low": 40, "high": 120},
    {"name": "edge_files", "kind": "file", "input": "edges", "pattern": "vision/edges_%03d.png"},
    {"name": "view", "kind": "texture", "input": "edges"}
  ]})");
  scene.engines.vision->overlay = "view";
  const dm::test::TempDir dir("vision_overlay");
  const json s = scene_run::runScene(scene, 1.0, dir.path());
  ASSERT_EQ(s["vision"]["frames"], 10);
  // Vision frame j is stepped at t = j / 10 s, after render frame 3j; render
  // frames 3j + 1 and 3j + 2 show it.
  for (int j = 0; j < 9; ++j) {
    auto edges = dm::readPng(dir / "vision" / dm::formatString("edges_%03d.png", j));
    ASSERT_TRUE(edges) << edges.error();
    int edgePixels = 0;
    for (int y = 0; y < 60; ++y)
      for (int x = 0; x < 80; ++x) edgePixels += edges->at<std::uint8_t>(x, y, 0) != 0;
    EXPECT_GT(edgePixels, 30) << "vision frame " << j << " has edges to show";
    for (int k : {3 * j + 1, 3 * j + 2}) {
      auto frame = dm::readPng(dir / "frames" / dm::formatString("frame_%05d.png", k));
      ASSERT_TRUE(frame) << frame.error();
      int differ = 0;
      for (int y = 0; y < 60; ++y)
        for (int x = 0; x < 80; ++x)
          for (int c = 0; c < 3; ++c)
            differ += frame->at<std::uint8_t>(x, 60 + y, c) != edges->at<std::uint8_t>(x, y, 0);
      EXPECT_EQ(differ, 0) << "render frame " << k << " does not show vision frame " << j;
    }
  }

  scene.engines.vision->overlay = "edges";  // a filter, not a texture sink
  auto rt = dm::SceneRuntime::create(scene);
  ASSERT_TRUE(rt) << rt.error();
  const dm::Status bad =
      (*rt)->prepare({.mode = dm::RunMode::Lockstep, .duration = 1, .outDir = dir / "bad"});
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.error().message().find("engines/vision/overlay"), std::string::npos) << bad.error();
}

TEST(SceneVision, AGraphThatCannotBeBuiltFailsBeforeTheRun) {
  dm::SceneDesc scene = endoscopeBoxPush();
  scene.engines.vision->graph["nodes"][3]["kind"] = "cany";
  const dm::test::TempDir dir("vision_bad");
  auto rt = dm::SceneRuntime::create(scene);
  ASSERT_TRUE(rt) << rt.error();
  const dm::Status s = (*rt)->prepare({.mode = dm::RunMode::Lockstep, .duration = 1, .outDir = dir / "out"});
  ASSERT_FALSE(s);
  const std::string m = s.error().message();
  EXPECT_NE(m.find("engines/vision/graph"), std::string::npos) << m;
  EXPECT_NE(m.find("canny"), std::string::npos) << "did you mean: " << m;
  EXPECT_FALSE(fs::exists(dir / "out")) << "no output folder left behind";

  scene = endoscopeBoxPush();
  scene.engines.render.reset();
  scene.outputs.frames = false;
  auto noRender = dm::SceneRuntime::create(scene);
  ASSERT_TRUE(noRender) << noRender.error();
  const dm::Status n =
      (*noRender)->prepare({.mode = dm::RunMode::Lockstep, .duration = 1, .outDir = dir / "out2"});
  ASSERT_FALSE(n);
  EXPECT_NE(n.error().message().find("render engine's frames"), std::string::npos) << n.error();
}

#endif

TEST(SceneVision, TheEngineParsesAndWritesItsGraph) {
  dm::SceneDesc scene = scene_run::bundledScene("box_push.json");
  dm::SceneVisionEngine v;
  v.graph = json::parse(R"({"nodes": [{"name": "v", "kind": "video_file", "path": "opencv:vtest.avi"}]})");
  scene.engines.vision = v;
  auto back = dm::parseScene(dm::toJson(scene).dump(), "vision.json", scene.baseDir);
  ASSERT_TRUE(back) << back.error();
  EXPECT_EQ(back->engines.vision, scene.engines.vision);
  json j = dm::toJson(scene);
  j["engines"]["vision"]["graph"] = 3;
  j["engines"]["vision"]["rate"] = 3;
  std::vector<dm::Error> problems;
  ASSERT_FALSE(dm::parseScene(j.dump(), "vision.json", scene.baseDir, &problems));
  const std::string all = dm::formatSceneErrors(problems);
  EXPECT_NE(all.find("engines/vision/graph"), std::string::npos) << all;
  EXPECT_NE(all.find("engines/vision/rate"), std::string::npos) << all;
}

}  // namespace scene_vision_test
