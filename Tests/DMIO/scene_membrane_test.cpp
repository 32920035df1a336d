// An object's "membrane" block (v2; docs/scene-format.md, "Membranes"):
// read as written, round-tripped through the canonical JSON, and each
// mistake refused at its JSON pointer — a missing mass, a zero stiffness,
// a Maxwell element without damping, bend damping without bend elements,
// an unknown pinning, a pinned box upside down, a negative friction, a
// thickness past 10 cm, rigid-contact keys, a membrane that is also
// dynamic or soft, touched by the tool, listed as a fluid's object or
// joined, in a scene with soft tissue (which it does not meet), no
// physics engine, the key in a version-1 file; colliding dynamic bodies
// (which it meets) are accepted.
#include <dm/io/scene_file.hpp>

#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "scene_test_support.hpp"

namespace scene_membrane_io_test {

using dm::Json;
using dm::SceneMembrane;

Json membraneScene() {
  return Json::parse(R"({
    "format": "dmplatform-scene", "version": 2, "name": "drum",
    "resources": {
      "sheet": {"type": "shape", "shape": "plane", "half_extents": [0.05, 0.05], "subdivisions": 4},
      "skin": {"type": "shape", "shape": "plane", "half_extents": [0.02, 0.02]},
      "ball": {"type": "shape", "shape": "sphere", "radius": 0.01}
    },
    "objects": [
      {"name": "drum", "mesh": "sheet", "pose": {"position": [0, 0, 0.1]},
       "membrane": {"mass": 0.01, "stiffness": 20, "damping": 0.5, "model": "maxwell", "bend_stiffness": 2,
                    "bend_damping": 0.01, "drag": 5, "pinned": "boundary",
                    "pinned_boxes": [{"min": [-1, 0.049, -1], "max": [1, 1, 1]}], "friction": 0.4,
                    "thickness": 0.0005}},
      {"name": "flap", "mesh": "skin", "membrane": {"mass": 0.002, "stiffness": 5}}
    ],
    "engines": {"physics": {"rate_hz": 500}}
  })");
}

TEST(SceneMembraneFile, ReadsEachMembraneAsWritten) {
  auto s = scene_test::parsed(membraneScene());
  ASSERT_TRUE(s);
  ASSERT_TRUE(s->objects[0].membrane);
  const SceneMembrane& m = *s->objects[0].membrane;
  EXPECT_EQ(m.mass, 0.01);
  EXPECT_EQ(m.stiffness, 20.0);
  EXPECT_EQ(m.damping, 0.5);
  EXPECT_EQ(m.model, SceneMembrane::Model::Maxwell);
  EXPECT_EQ(m.bendStiffness, 2.0);
  EXPECT_EQ(m.bendDamping, 0.01);
  EXPECT_EQ(m.drag, 5.0);
  EXPECT_TRUE(m.pinBoundary);
  ASSERT_EQ(m.pinnedBoxes.size(), 1u);
  EXPECT_EQ(m.pinnedBoxes[0].min.y(), 0.049);
  EXPECT_EQ(m.friction, 0.4);
  EXPECT_EQ(m.thickness, 0.0005);
  EXPECT_FALSE(s->objects[0].collide);                  // not a rigid collider
  const SceneMembrane& flap = *s->objects[1].membrane;  // the defaults
  EXPECT_EQ(flap.model, SceneMembrane::Model::KelvinVoigt);
  EXPECT_EQ(flap.damping, 0.0);
  EXPECT_FALSE(flap.pinBoundary);
  EXPECT_EQ(flap.friction, 0.0);
  EXPECT_EQ(flap.thickness, 0.0);
  EXPECT_TRUE(flap.pinnedBoxes.empty());
  scene_test::expectRoundTrip(membraneScene());
}

TEST(SceneMembraneFile, RefusesEachMistakeInTheBlockAtItsPointer) {
  Json j = membraneScene();
  Json& m = j["objects"][0]["membrane"];
  m.erase("mass");
  m["stiffness"] = 0;
  m["damping"] = 0;
  m["bend_stiffness"] = 0;
  m["pinned"] = "rim";
  m["pinned_boxes"][0]["max"] = Json::array({1, 0, 1});
  m["tension"] = 3;
  m["friction"] = -0.1;
  m["thickness"] = 0.5;
  j["objects"][0]["collide"] = true;
  const std::vector<dm::Error> p = scene_test::problemsOf(j);
  const std::string at = "/objects/0/membrane/";
  EXPECT_NE(scene_test::at(p, at + "mass"), nullptr);
  scene_test::expectAt(p, at + "stiffness", "greater than 0");
  scene_test::expectAt(p, at + "damping", "Maxwell");
  scene_test::expectAt(p, at + "bend_damping", "without bend elements");
  EXPECT_NE(scene_test::at(p, at + "pinned"), nullptr);
  scene_test::expectAt(p, at + "pinned_boxes/0/max", "below min");
  EXPECT_NE(scene_test::at(p, at + "tension"), nullptr);
  EXPECT_NE(scene_test::at(p, at + "friction"), nullptr);
  EXPECT_NE(scene_test::at(p, at + "thickness"), nullptr);
  scene_test::expectAt(p, "/objects/0/collide", "not a rigid collider");
  EXPECT_EQ(p.size(), 10u) << dm::formatSceneErrors(p);
}

TEST(SceneMembraneFile, RefusesWhatAMembraneCannotBeOrMeet) {
  Json j = membraneScene();
  j["objects"][1]["dynamic"] = true;
  j["objects"][1]["mass"] = 0.1;
  j["objects"].push_back(Json::parse(R"({"name": "ball", "mesh": "ball", "dynamic": true, "mass": 0.01,
                                          "pose": {"position": [0, 0, 0.3]}})"));
  j["materials"] = Json::parse(R"({"steel": {"haptic": {"stiffness": 500}}})");
  j["objects"].push_back(
      Json::parse(R"({"name": "probe", "mesh": "ball", "pose": {"position": [0, 0, 1]}})"));
  j["devices"] = Json::parse(R"([{"name": "hand", "driver": "sim-haptic"}])");
  j["engines"]["haptics"] =
      Json::parse(R"({"device": "hand", "objects": ["drum"], "proxy_object": "probe"})");
  j["engines"]["physics"]["joints"] =
      Json::parse(R"([{"name": "j", "type": "ball", "a": "ball", "b": "drum", "anchor": [0, 0, 0.1]}])");
  j["fluids"] = Json::parse(R"([{"name": "blood", "region": {"min": [-1, -1, -1], "max": [1, 1, 1]},
                                  "objects": ["drum"]}])");
  const std::vector<dm::Error> p = scene_test::problemsOf(j);
  scene_test::expectAt(p, "/objects/1/dynamic", "not moved as a rigid body");
  scene_test::expectAt(p, "/engines/haptics/objects", "cannot be touched");
  scene_test::expectAt(p, "/engines/physics/joints/0/b", "membrane");
  scene_test::expectAt(p, "/fluids/0/objects/0", "does not meet fluids");
  for (const dm::Error& e : p) EXPECT_EQ(e.message().find("\"ball\""), std::string::npos) << e.message();

  // Colliding bodies, dynamic or static, are what it meets; one that does
  // not collide is no obstacle.
  Json aside = membraneScene();
  aside["objects"].push_back(Json::parse(R"({"name": "ball", "mesh": "ball", "dynamic": true, "mass": 0.01,
                                              "pose": {"position": [0, 0, 0.3]}})"));
  aside["objects"].push_back(Json::parse(R"({"name": "bead", "mesh": "ball", "dynamic": true, "mass": 0.01,
                                              "collide": false, "pose": {"position": [0, 0, 0.6]}})"));
  aside["objects"].push_back(Json::parse(R"({"name": "organ", "mesh": "ball"})"));
  EXPECT_TRUE(scene_test::parsed(aside));

  Json alone = membraneScene();
  alone["engines"].erase("physics");
  scene_test::expectAt(scene_test::problemsOf(alone), "/objects/0/membrane", "no physics engine");

  Json both = membraneScene();
  both["objects"][1]["soft"] =
      Json::parse(R"({"youngs_modulus": 5000, "poisson_ratio": 0.45, "density": 1000, "voxel_size": 0.004})");
  scene_test::expectAt(scene_test::problemsOf(both), "/objects/1/soft", "not both");
  scene_test::expectAt(scene_test::problemsOf(both), "/objects/0/membrane",
                       "and soft object \"flap\" do not meet");

  Json v1 = membraneScene();
  v1["version"] = 1;
  scene_test::expectAt(scene_test::problemsOf(v1), "/objects/0/membrane", "version-2 key");
}

}  // namespace scene_membrane_io_test
