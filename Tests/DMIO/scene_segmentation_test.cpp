// The segmentation engine (v2 "engines"/"segmentation"; docs/scene-format.md,
// "Segmentation") and the haptics engine's renderer "none": read as written
// (defaults, a window given or taken at the seed, the reference), through
// the canonical JSON and back, and each mistake refused at its JSON pointer
// — a resource that is not a volume, both window forms, an inverted window,
// connectivity other than 6/18/26, radii out of order, no haptics engine to
// paint at, objects or a proxy size for a tool that touches nothing, the
// engine in a version-1 file.
#include <dm/io/scene_file.hpp>

#include <gtest/gtest.h>

#include <array>
#include <string>
#include <vector>

#include "scene_test_support.hpp"

namespace scene_segmentation_io_test {

using dm::Json;
using namespace scene_test;

Json segmentationScene() {
  return Json::parse(R"({
    "format": "dmplatform-scene", "version": 2, "name": "paint",
    "resources": {
      "brain": {"type": "volume", "source": "mricron:ch2bet.nii.gz"},
      "ball": {"type": "shape", "shape": "sphere", "radius": 0.002}
    },
    "objects": [{"name": "tip", "mesh": "ball"}],
    "devices": [{"name": "hand", "driver": "sim-haptic", "config": {"path": "circle"}}],
    "engines": {
      "haptics": {"device": "hand", "renderer": "none", "proxy_object": "tip"},
      "segmentation": {"volume": "brain", "seed": [0.026, -0.012, 0.03]}
    }
  })");
}

TEST(SceneSegmentation, DefaultsAndGivenValuesReadAndRoundTrip) {
  Json j = segmentationScene();
  auto s = parsed(j);
  ASSERT_TRUE(s);
  ASSERT_TRUE(s->engines.segmentation);
  const dm::SceneSegmentationEngine& g = *s->engines.segmentation;
  EXPECT_EQ(g.volume, "brain");
  EXPECT_EQ(g.seed, dm::Vec3(0.026, -0.012, 0.03));
  EXPECT_EQ(g.rateHz, 20.0);
  EXPECT_FALSE(g.window);
  EXPECT_EQ(g.windowK, 2.5);
  EXPECT_EQ(g.connectivity, 6);
  EXPECT_TRUE(g.guidance);
  EXPECT_FALSE(g.referenceK);
  EXPECT_EQ(s->engines.haptics->renderer, dm::SceneHapticsEngine::Renderer::None);
  EXPECT_TRUE(s->engines.haptics->objects.empty());
  expectRoundTrip(j);

  j["engines"]["segmentation"] = {{"volume", "brain"},     {"seed", {0.026, -0.012, 0.03}},
                                  {"rate_hz", 10},         {"window", {90, 140}},
                                  {"connectivity", 26},    {"min_radius", 0.002},
                                  {"max_radius", 0.008},   {"edge_sigma", 0.0},
                                  {"edge_threshold", 0.3}, {"rays", 32},
                                  {"gain", 0.01},          {"max_force", 1.5},
                                  {"guidance", false},     {"reference", {{"k", 3}}}};
  auto t = parsed(j);
  ASSERT_TRUE(t);
  const dm::SceneSegmentationEngine& h = *t->engines.segmentation;
  ASSERT_TRUE(h.window);
  EXPECT_EQ(*h.window, (std::array<double, 2>{90, 140}));
  EXPECT_EQ(h.connectivity, 26);
  EXPECT_EQ(h.rays, 32);
  EXPECT_FALSE(h.guidance);
  ASSERT_TRUE(h.referenceK);
  EXPECT_EQ(*h.referenceK, 3.0);
  const Json written = expectRoundTrip(j);
  EXPECT_FALSE(written["engines"]["segmentation"].contains("window_k"));  // the window replaces it
  EXPECT_FALSE(written["engines"]["haptics"].contains("objects"));
}

TEST(SceneSegmentation, MistakesAreRefusedAtTheirPointers) {
  {
    Json j = segmentationScene();
    auto& g = j["engines"]["segmentation"];
    g["volume"] = "ball";
    g["window"] = {140, 90};
    g["window_k"] = 2;
    g["connectivity"] = 8;
    g["min_radius"] = 0.01;
    g["max_radius"] = 0.005;
    g["edge_threshold"] = 0;
    g["rays"] = 3;
    g["reference"] = {{"k", 2.5}, {"connectivity", 6}};
    g["colour"] = "red";
    const std::vector<dm::Error> p = problemsOf(j);
    expectAt(p, "/engines/segmentation/volume", "is not a volume");
    expectAt(p, "/engines/segmentation/window", "not lower <= upper");
    expectAt(p, "/engines/segmentation/window_k", "both");
    expectAt(p, "/engines/segmentation/connectivity", "not 6, 18 or 26");
    expectAt(p, "/engines/segmentation/max_radius", "below min_radius");
    expectAt(p, "/engines/segmentation/edge_threshold", "above 0");
    expectAt(p, "/engines/segmentation/rays", "outside");
    expectAt(p, "/engines/segmentation/reference/connectivity", "unknown");
    expectAt(p, "/engines/segmentation/colour", "unknown");
    EXPECT_EQ(p.size(), 9u) << dm::formatSceneErrors(p);
  }
  {
    Json j = segmentationScene();
    j["engines"]["segmentation"].erase("seed");
    j["engines"]["segmentation"]["window"] = {90};
    j["engines"].erase("haptics");
    const std::vector<dm::Error> p = problemsOf(j);
    expectAt(p, "/engines/segmentation/seed", "missing");
    expectAt(p, "/engines/segmentation/window", "[lower, upper]");
    expectAt(p, "/engines/segmentation", "no haptics engine");
  }
  {
    // A tool in free space touches nothing.
    Json j = segmentationScene();
    j["engines"]["haptics"]["objects"] = {"tip"};
    j["engines"]["haptics"]["tool_radius"] = 0.001;
    j["engines"]["haptics"]["force_shading"] = true;
    const std::vector<dm::Error> p = problemsOf(j);
    expectAt(p, "/engines/haptics/objects", "touches nothing");
    expectAt(p, "/engines/haptics/tool_radius", "touches nothing");
    expectAt(p, "/engines/haptics/force_shading", "touches nothing");
  }
  {
    Json j = segmentationScene();
    j["version"] = 1;
    const std::vector<dm::Error> p = problemsOf(j);
    expectAt(p, "/engines/segmentation", "version-2");
  }
}

TEST(SceneSegmentation, TheBundledSceneReadsAndRoundTrips) {
  auto a = dm::readScene(sourceDir() / "examples/scenes/haptic_segmentation.json");
  ASSERT_TRUE(a) << a.error();
  ASSERT_TRUE(a->engines.segmentation);
  EXPECT_TRUE(a->engines.segmentation->referenceK);
  auto b = dm::parseScene(dm::toJson(*a).dump(2), "written.json", a->baseDir);
  ASSERT_TRUE(b) << b.error();
  EXPECT_TRUE(*a == *b);
}

}  // namespace scene_segmentation_io_test
