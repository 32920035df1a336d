// The scene file's "fluids" (v2; docs/scene-format.md, "Fluids"): a fluid
// with its container, region, blocks, inlets and suction tips reads as
// written with its defaults (blood, drawn as a liquid surface), with its
// look (surface optics or spheres), round-trips through its canonical
// JSON, and each mistake is refused at its JSON pointer — a fluid without
// the physics engine that steps it, a region too large to hold, a block or
// an inlet outside the region (their fluid would be recycled at once), a
// tip with both or neither of "at" and "center", a tip at the tool without
// a haptics engine, a window that stops before it starts, unknown keys.
#include <dm/io/scene_file.hpp>

#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "scene_test_support.hpp"

namespace scene_fluid_io_test {

using dm::Json;
using dm::Vec3;

Json fluidScene() {
  return Json::parse(R"({
    "format": "dmplatform-scene", "version": 2, "name": "bleeding",
    "engines": {"physics": {"rate_hz": 500}},
    "fluids": [{
      "name": "blood", "spacing": 0.005,
      "container": {"min": [0, 0, 0], "max": [0.1, 0.1, 0.1]},
      "region": {"min": [-0.05, -0.05, -0.05], "max": [0.15, 0.15, 0.2]},
      "blocks": [{"min": [0, 0, 0], "max": [0.1, 0.1, 0.01]}],
      "inlets": [{"name": "cut", "center": [0.05, 0.05, 0.02], "normal": [0, 0, 2], "radius": 0.002,
                  "flow_rate": 2e-6, "pressure": 2000, "start": 0.5}],
      "suction": [{"name": "tip", "center": [0.02, 0.02, 0.01], "radius": 0.006, "flow_rate": 5e-6,
                   "start": 1, "stop": 3}]
    }]
  })");
}

TEST(SceneFluidFile, ReadsTheFluidItsSourcesAndItsDefaults) {
  auto s = scene_test::parsed(fluidScene());
  ASSERT_TRUE(s);
  ASSERT_EQ(s->fluids.size(), 1u);
  const dm::SceneFluid& f = s->fluids[0];
  EXPECT_EQ(f.name, "blood");
  EXPECT_EQ(f.spacing, 0.005);
  EXPECT_EQ(f.density, 1060.0);  // blood, unless the scene says
  EXPECT_EQ(f.viscosity, 3.5e-6);
  ASSERT_TRUE(f.container.has_value());
  EXPECT_EQ(f.container->max, Vec3(0.1, 0.1, 0.1));
  EXPECT_EQ(f.region.min, Vec3(-0.05, -0.05, -0.05));
  ASSERT_EQ(f.blocks.size(), 1u);
  ASSERT_EQ(f.inlets.size(), 1u);
  EXPECT_EQ(f.inlets[0].normal, Vec3(0, 0, 1));  // normalised
  EXPECT_EQ(f.inlets[0].pressure, 2000.0);
  EXPECT_EQ(f.inlets[0].start, 0.5);
  EXPECT_FALSE(f.inlets[0].stop.has_value());
  ASSERT_EQ(f.suction.size(), 1u);
  EXPECT_FALSE(f.suction[0].atTool);
  EXPECT_EQ(f.suction[0].stop, 3.0);
  // Drawn as a liquid surface unless the scene says spheres.
  EXPECT_EQ(f.look.style, dm::SceneFluidLook::Style::Surface);
  EXPECT_FALSE(f.look.absorption.has_value());
  EXPECT_EQ(f.look.smoothing, 3);
}

TEST(SceneFluidFile, ReadsTheLookOfItsSurfaceOrItsSpheres) {
  Json j = fluidScene();
  j["fluids"][0]["look"] = Json::parse(R"({"style": "surface", "absorption": [700, 3900, 3900],
                                           "fresnel": 0.025, "specular": 0.5, "shininess": 80,
                                           "refraction": 6, "smoothing": 5})");
  auto s = scene_test::parsed(j);
  ASSERT_TRUE(s);
  const dm::SceneFluidLook& look = s->fluids[0].look;
  EXPECT_EQ(look.absorption, Vec3(700, 3900, 3900));
  EXPECT_EQ(look.fresnel, 0.025);
  EXPECT_EQ(look.specular, 0.5);
  EXPECT_EQ(look.shininess, 80.0);
  EXPECT_EQ(look.refraction, 6.0);
  EXPECT_EQ(look.smoothing, 5);
  scene_test::expectRoundTrip(j);
  j["fluids"][0]["look"] = Json::parse(R"({"style": "spheres"})");
  auto spheres = scene_test::parsed(j);
  ASSERT_TRUE(spheres);
  EXPECT_EQ(spheres->fluids[0].look.style, dm::SceneFluidLook::Style::Spheres);
  scene_test::expectRoundTrip(j);
}

TEST(SceneFluidFile, RefusesALookItCannotDraw) {
  Json j = fluidScene();
  j["fluids"][0]["look"] = Json::parse(R"({"style": "blobs", "absorption": [1, -2, 3], "fresnel": 2,
                                           "smoothing": 40, "gloss": 1})");
  std::vector<dm::Error> p = scene_test::problemsOf(j);
  EXPECT_NE(scene_test::at(p, "/fluids/0/look/style"), nullptr);
  scene_test::expectAt(p, "/fluids/0/look/absorption", "1/m");
  EXPECT_NE(scene_test::at(p, "/fluids/0/look/fresnel"), nullptr);
  EXPECT_NE(scene_test::at(p, "/fluids/0/look/smoothing"), nullptr);
  EXPECT_NE(scene_test::at(p, "/fluids/0/look/gloss"), nullptr);
  EXPECT_EQ(p.size(), 5u) << dm::formatSceneErrors(p);
  // The surface's optics mean nothing to spheres: said, not ignored.
  j["fluids"][0]["look"] = Json::parse(R"({"style": "spheres", "refraction": 4})");
  p = scene_test::problemsOf(j);
  scene_test::expectAt(p, "/fluids/0/look/refraction", "drawn as spheres");
  EXPECT_EQ(p.size(), 1u) << dm::formatSceneErrors(p);
}

TEST(SceneFluidFile, RoundTripsThroughItsCanonicalJson) {
  const Json j = scene_test::expectRoundTrip(fluidScene());
  ASSERT_TRUE(j.contains("fluids"));
  Json k = j;
  k["fluids"][0]["inlets"][0]["flow_rate"] = 3e-6;  // a sweep's parameter
  auto other = scene_test::parsed(k);
  ASSERT_TRUE(other);
  EXPECT_FALSE(*other == *scene_test::parsed(j));
}

TEST(SceneFluidFile, RefusesEachMistakeAtItsPointer) {
  Json j = fluidScene();
  Json& f = j["fluids"][0];
  f["colour"] = "red";
  f["blocks"].push_back(Json::parse(R"({"min": [0, 0, 0], "max": [0.3, 0.1, 0.01]})"));
  f["blocks"].push_back(Json::parse(R"({"min": [0.1, 0, 0], "max": [0.05, 0.1, 0.01]})"));
  f["inlets"].push_back(Json::parse(R"({"name": "far", "center": [1, 0, 0], "flow_rate": 1e-6})"));
  f["inlets"].push_back(Json::parse(R"({"name": "cut", "center": [0, 0, 0], "flow_rate": 1e-6})"));
  f["inlets"].push_back(Json::parse(R"({"name": "late", "center": [0, 0, 0], "flow_rate": 1e-6,
                                        "start": 2, "stop": 1})"));
  f["suction"].push_back(Json::parse(R"({"name": "both", "at": "tool", "center": [0, 0, 0], "radius": 0.01,
                                         "flow_rate": 1e-6})"));
  f["suction"].push_back(Json::parse(R"({"name": "neither", "radius": 0.01, "flow_rate": 1e-6})"));
  f["suction"].push_back(Json::parse(R"({"name": "hand", "at": "tool", "radius": 0.01, "flow_rate": 1e-6})"));
  f["suction"].push_back(Json::parse(R"({"name": "big", "center": [0, 0, 0], "radius": 0.01,
                                         "flow_rate": 5})"));
  const std::vector<dm::Error> p = scene_test::problemsOf(j);
  EXPECT_NE(scene_test::at(p, "/fluids/0/colour"), nullptr);
  scene_test::expectAt(p, "/fluids/0/blocks/1", "outside the fluid's region");
  scene_test::expectAt(p, "/fluids/0/blocks/2/max", "not above min");
  scene_test::expectAt(p, "/fluids/0/inlets/1/center", "outside the fluid's region");
  scene_test::expectAt(p, "/fluids/0/inlets/2/name", "duplicate");
  scene_test::expectAt(p, "/fluids/0/inlets/3/stop", "not after start");
  scene_test::expectAt(p, "/fluids/0/suction/1", "both");
  scene_test::expectAt(p, "/fluids/0/suction/2", "neither");
  scene_test::expectAt(p, "/fluids/0/suction/3/at", "no haptics engine");
  EXPECT_NE(scene_test::at(p, "/fluids/0/suction/4/flow_rate"), nullptr);
  EXPECT_EQ(p.size(), 10u) << dm::formatSceneErrors(p);
}

// "objects": static, soft and dynamic objects the fluid flows around, by
// name; a name that is no object, a name twice, the haptic proxy and a
// non-string are refused at their entries.
TEST(SceneFluidFile, ObjectsItFlowsAroundAreNamedOnceAndNotTheProxy) {
  Json j = fluidScene();
  j["resources"] = Json::parse(R"({"ball": {"type": "shape", "shape": "sphere", "radius": 0.01}})");
  j["objects"] = Json::parse(R"([{"name": "organ", "mesh": "ball"},
                                  {"name": "marble", "mesh": "ball", "dynamic": true, "mass": 0.01}])");
  j["fluids"][0]["objects"] = {"organ", "marble"};
  const Json round = scene_test::expectRoundTrip(j);
  EXPECT_EQ(round["fluids"][0]["objects"], Json({"organ", "marble"}));
  auto scene = scene_test::parsed(j);
  ASSERT_TRUE(scene);
  EXPECT_EQ(scene->fluids[0].objects, std::vector<std::string>({"organ", "marble"}));

  j["objects"].push_back(Json::parse(R"({"name": "probe", "mesh": "ball"})"));
  j["materials"] = Json::parse(R"({"tissue": {"haptic": {"stiffness": 500}}})");
  j["objects"][0]["material"] = "tissue";
  j["objects"][0]["haptic"] = true;
  j["engines"]["haptics"] =
      Json::parse(R"({"device": "hand", "objects": ["organ"], "proxy_object": "probe"})");
  j["devices"] = Json::parse(R"([{"name": "hand", "driver": "sim-haptic"}])");
  j["fluids"][0]["objects"] = Json::parse(R"(["organ", "organ", "kidney", "probe", 3])");
  const std::vector<dm::Error> p = scene_test::problemsOf(j);
  scene_test::expectAt(p, "/fluids/0/objects/1", "listed twice");
  scene_test::expectAt(p, "/fluids/0/objects/2", "no object \"kidney\"");
  scene_test::expectAt(p, "/fluids/0/objects/3", "haptic proxy");
  scene_test::expectAt(p, "/fluids/0/objects/4", "expected an object name");
  EXPECT_EQ(p.size(), 4u) << dm::formatSceneErrors(p);
}

TEST(SceneFluidFile, NeedsThePhysicsEngineAndARegionItCanHold) {
  Json j = fluidScene();
  j["engines"].erase("physics");
  j["fluids"][0]["spacing"] = 0.0005;  // 0.2 × 0.2 × 0.25 m at 0.5 mm: 8e7 particles
  const std::vector<dm::Error> p = scene_test::problemsOf(j);
  scene_test::expectAt(p, "/fluids/0", "physics engine");
  scene_test::expectAt(p, "/fluids/0/region", "particles");
  EXPECT_EQ(p.size(), 2u) << dm::formatSceneErrors(p);
}

TEST(SceneFluidFile, IsAVersionTwoKey) {
  Json j = fluidScene();
  j["version"] = 1;
  const std::vector<dm::Error> p = scene_test::problemsOf(j);
  EXPECT_NE(scene_test::at(p, "/fluids"), nullptr);
}

}  // namespace scene_fluid_io_test
