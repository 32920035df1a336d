// The physics engine's "joints" (v2; docs/scene-format.md, "Joints"): ball,
// hinge, slider and fixed joints between rigid bodies or to the world read
// as written (axes normalised, limits kept), round-trip through the
// canonical JSON, and each mistake is refused at its JSON pointer — an
// unknown type, an object that is not a rigid body of the world (none, the
// haptic proxy, soft tissue, a static object that does not collide), a
// joint of a body to itself or of two static bodies, an axis missing or
// out of place, limits on a joint that has none or that do not hold the
// start, a repeated name, an unknown key, joints in a version-1 file.
#include <dm/io/scene_file.hpp>

#include <gtest/gtest.h>

#include <numbers>
#include <string>
#include <vector>

#include "scene_test_support.hpp"

namespace scene_joints_io_test {

using dm::Json;
using dm::SceneJoint;
using dm::Vec3;

Json jointScene() {
  return Json::parse(R"({
    "format": "dmplatform-scene", "version": 2, "name": "linkage",
    "resources": {
      "ball": {"type": "shape", "shape": "sphere", "radius": 0.01},
      "bar": {"type": "shape", "shape": "box", "half_extents": [0.1, 0.01, 0.01]}
    },
    "objects": [
      {"name": "frame", "mesh": "bar"},
      {"name": "arm", "mesh": "bar", "dynamic": true, "mass": 0.1, "pose": {"position": [0, 0, 0.5]}},
      {"name": "bob", "mesh": "ball", "dynamic": true, "mass": 0.05, "pose": {"position": [0.1, 0, 0.5]}},
      {"name": "ghost", "mesh": "ball", "collide": false, "pose": {"position": [0, 0, 1]}}
    ],
    "engines": {"physics": {"joints": [
      {"name": "shoulder", "type": "hinge", "a": "arm", "anchor": [-0.1, 0, 0.5], "axis": [0, 2, 0],
       "limits": [-1, 0.5]},
      {"name": "wrist", "type": "ball", "a": "arm", "b": "bob", "anchor": [0.1, 0, 0.5]},
      {"name": "rail", "type": "slider", "a": "frame", "b": "bob", "anchor": [0.1, 0, 0.5], "axis": [1, 0, 0]},
      {"name": "weld", "type": "fixed", "a": "bob", "b": "arm", "anchor": [0.05, 0, 0.5]}
    ]}}
  })");
}

TEST(SceneJointsFile, ReadsEachJointAsWritten) {
  auto s = scene_test::parsed(jointScene());
  ASSERT_TRUE(s);
  ASSERT_TRUE(s->engines.physics);
  const std::vector<SceneJoint>& j = s->engines.physics->joints;
  ASSERT_EQ(j.size(), 4u);
  EXPECT_EQ(j[0].name, "shoulder");
  EXPECT_EQ(j[0].type, SceneJoint::Type::Hinge);
  EXPECT_EQ(j[0].a, "arm");
  EXPECT_TRUE(j[0].b.empty());  // the world
  EXPECT_EQ(j[0].anchor, Vec3(-0.1, 0, 0.5));
  EXPECT_EQ(j[0].axis, Vec3(0, 1, 0));  // normalised
  EXPECT_TRUE(j[0].limited);
  EXPECT_EQ(j[0].lower, -1.0);
  EXPECT_EQ(j[0].upper, 0.5);
  EXPECT_EQ(j[1].type, SceneJoint::Type::Ball);
  EXPECT_EQ(j[1].b, "bob");
  EXPECT_FALSE(j[1].limited);
  EXPECT_EQ(j[2].type, SceneJoint::Type::Slider);
  EXPECT_EQ(j[2].a, "frame");  // a static body that collides is in the world
  EXPECT_EQ(j[3].type, SceneJoint::Type::Fixed);
  scene_test::expectRoundTrip(jointScene());
}

TEST(SceneJointsFile, RefusesEachMistakeAtItsPointer) {
  Json j = jointScene();
  Json& list = j["engines"]["physics"]["joints"];
  list.push_back(Json::parse(R"({"name": "a", "type": "hing", "a": "arm", "anchor": [0, 0, 0]})"));
  list.push_back(Json::parse(R"({"name": "b", "type": "ball", "a": "kidney", "anchor": [0, 0, 0]})"));
  list.push_back(Json::parse(R"({"name": "c", "type": "ball", "a": "ghost", "anchor": [0, 0, 0]})"));
  list.push_back(
      Json::parse(R"({"name": "d", "type": "ball", "a": "arm", "b": "arm", "anchor": [0, 0, 0]})"));
  list.push_back(Json::parse(R"({"name": "e", "type": "fixed", "a": "frame", "anchor": [0, 0, 0]})"));
  list.push_back(Json::parse(R"({"name": "f", "type": "hinge", "a": "arm", "anchor": [0, 0, 0]})"));
  list.push_back(Json::parse(R"({"name": "g", "type": "ball", "a": "arm", "anchor": [0, 0, 0],
                                 "axis": [0, 0, 1]})"));
  list.push_back(Json::parse(R"({"name": "h", "type": "fixed", "a": "arm", "anchor": [0, 0, 0],
                                 "limits": [-1, 1]})"));
  list.push_back(Json::parse(R"({"name": "i", "type": "slider", "a": "arm", "anchor": [0, 0, 0],
                                 "axis": [1, 0, 0], "limits": [0.1, 0.2]})"));
  list.push_back(Json::parse(R"({"name": "k", "type": "hinge", "a": "arm", "anchor": [0, 0, 0],
                                 "axis": [1, 0, 0], "limits": [-4, 1]})"));
  list.push_back(Json::parse(R"({"name": "wrist", "type": "ball", "a": "arm", "anchor": [0, 0, 0]})"));
  list.push_back(Json::parse(R"({"name": "m", "type": "ball", "a": "arm", "anchor": [0, 0, 0],
                                 "stiffness": 3})"));
  list.push_back(Json::parse(R"({"name": "n", "type": "hinge", "a": "arm", "anchor": [0, 0, 0],
                                 "axis": [0, 0, 0]})"));
  const std::vector<dm::Error> p = scene_test::problemsOf(j);
  const std::string at = "/engines/physics/joints/";
  scene_test::expectAt(p, at + "4/type", "hinge");  // did you mean
  scene_test::expectAt(p, at + "5/a", "no object \"kidney\"");
  scene_test::expectAt(p, at + "6/a", "does not collide");
  scene_test::expectAt(p, at + "7/b", "two different bodies");
  scene_test::expectAt(p, at + "8/a", "neither body moves");
  scene_test::expectAt(p, at + "9/axis", "needs an \"axis\"");
  scene_test::expectAt(p, at + "10/axis", "has no axis");
  scene_test::expectAt(p, at + "11/limits", "has no limits");
  scene_test::expectAt(p, at + "12/limits", "do not hold the start");
  scene_test::expectAt(p, at + "13/limits", "reach past");
  scene_test::expectAt(p, at + "14/name", "duplicate");
  EXPECT_NE(scene_test::at(p, at + "15/stiffness"), nullptr);
  scene_test::expectAt(p, at + "16/axis", "zero length");
  EXPECT_EQ(p.size(), 13u) << dm::formatSceneErrors(p);
}

// The tool's picture and FEM tissue are not rigid bodies of the world.
TEST(SceneJointsFile, TheHapticProxyAndSoftTissueCannotBeJoined) {
  Json j = jointScene();
  j["materials"] = Json::parse(R"({"tissue": {"haptic": {"stiffness": 500}}})");
  j["objects"].push_back(
      Json::parse(R"({"name": "probe", "mesh": "ball", "pose": {"position": [0, 0, 2]}})"));
  j["objects"].push_back(
      Json::parse(R"({"name": "liver", "mesh": "ball", "material": "tissue", "haptic": true,
                                         "pose": {"position": [0, 0, -1]},
                                         "soft": {"youngs_modulus": 5000, "poisson_ratio": 0.45,
                                                  "density": 1000, "voxel_size": 0.004, "fixed": ["-z"]}})"));
  j["engines"]["haptics"] =
      Json::parse(R"({"device": "hand", "objects": ["liver"], "proxy_object": "probe"})");
  j["devices"] = Json::parse(R"([{"name": "hand", "driver": "sim-haptic"}])");
  Json& list = j["engines"]["physics"]["joints"];
  list = Json::parse(R"([{"name": "p", "type": "ball", "a": "probe", "anchor": [0, 0, 2]},
                         {"name": "q", "type": "ball", "a": "arm", "b": "liver", "anchor": [0, 0, 0]}])");
  const std::vector<dm::Error> p = scene_test::problemsOf(j);
  scene_test::expectAt(p, "/engines/physics/joints/0/a", "haptic proxy");
  scene_test::expectAt(p, "/engines/physics/joints/1/b", "soft tissue");
}

TEST(SceneJointsFile, JointsAreAVersionTwoKey) {
  Json j = jointScene();
  j["version"] = 1;
  j["engines"]["physics"]["joints"] = Json::array();
  for (Json& o : j["objects"]) o.erase("mass");  // v1 objects: the checks below are the joints'
  const std::vector<dm::Error> p = scene_test::problemsOf(j);
  scene_test::expectAt(p, "/engines/physics/joints", "version-2 key");
}

}  // namespace scene_joints_io_test
