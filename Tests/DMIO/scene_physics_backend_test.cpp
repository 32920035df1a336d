// The physics engine's "backend" (v2; docs/scene-format.md, "Physics
// backends"): the built-in solver by default, ODE with its settings read as
// written and round-tripped through the canonical JSON; each mistake refused
// at its JSON pointer — an unknown backend (did you mean), ODE settings with
// the built-in solver, sleeping bodies on ODE, settings out of range or
// unknown, and the keys in a version-1 file.
#include <dm/io/scene_file.hpp>

#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "scene_test_support.hpp"

namespace scene_physics_backend_io_test {

using dm::Json;
using Backend = dm::ScenePhysicsEngine::Backend;

Json odeScene() {
  return Json::parse(R"({
    "format": "dmplatform-scene", "version": 2, "name": "tray",
    "resources": {
      "cup": {"type": "shape", "shape": "cylinder", "radius": 0.02, "height": 0.05},
      "table": {"type": "shape", "shape": "plane", "half_extents": [0.5, 0.5]}
    },
    "objects": [
      {"name": "table", "mesh": "table"},
      {"name": "cup", "mesh": "cup", "dynamic": true, "mass": 0.1, "pose": {"position": [0, 0, 0.1]}}
    ],
    "engines": {"physics": {"backend": "ode",
                            "ode": {"iterations": 40, "erp": 0.4, "cfm": 1e-7, "contacts_per_pair": 8,
                                    "surface_layer": 0.0002}}}
  })");
}

TEST(ScenePhysicsBackendFile, ReadsTheOdeBackendAndItsSettingsAsWritten) {
  auto s = scene_test::parsed(odeScene());
  ASSERT_TRUE(s);
  ASSERT_TRUE(s->engines.physics);
  const dm::ScenePhysicsEngine& p = *s->engines.physics;
  EXPECT_EQ(p.backend, Backend::Ode);
  EXPECT_EQ(p.ode.iterations, 40);
  EXPECT_EQ(p.ode.erp, 0.4);
  EXPECT_EQ(p.ode.cfm, 1e-7);
  EXPECT_EQ(p.ode.contactsPerPair, 8);
  EXPECT_EQ(p.ode.surfaceLayer, 0.0002);
  scene_test::expectRoundTrip(odeScene());

  // Left out: the built-in solver; "ode" alone: ODE's defaults.
  Json builtin = odeScene();
  builtin["engines"]["physics"] = Json::object();
  auto b = scene_test::parsed(builtin);
  ASSERT_TRUE(b);
  EXPECT_EQ(b->engines.physics->backend, Backend::BuiltIn);
  scene_test::expectRoundTrip(builtin);
  Json defaults = odeScene();
  defaults["engines"]["physics"] = Json::parse(R"({"backend": "ode"})");
  auto d = scene_test::parsed(defaults);
  ASSERT_TRUE(d);
  EXPECT_EQ(d->engines.physics->ode, dm::ScenePhysicsEngine::Ode{});
  scene_test::expectRoundTrip(defaults);
}

TEST(ScenePhysicsBackendFile, RefusesEachMistakeAtItsPointer) {
  Json j = odeScene();
  j["engines"]["physics"]["backend"] = "oed";
  scene_test::expectAt(scene_test::problemsOf(j), "/engines/physics/backend", "ode");  // did you mean

  j = odeScene();
  j["engines"]["physics"]["backend"] = "builtin";
  scene_test::expectAt(scene_test::problemsOf(j), "/engines/physics/ode", "backend is the built-in solver");

  j = odeScene();
  j["engines"]["physics"]["sleep"] = true;
  scene_test::expectAt(scene_test::problemsOf(j), "/engines/physics/sleep", "no sleeping");

  j = odeScene();
  Json& o = j["engines"]["physics"]["ode"];
  o["iterations"] = 0;
  o["erp"] = 0;
  o["cfm"] = -1;
  o["contacts_per_pair"] = 65;
  o["surface_layer"] = 0.5;
  o["stepper"] = "quick";
  const std::vector<dm::Error> p = scene_test::problemsOf(j);
  const std::string at = "/engines/physics/ode/";
  EXPECT_NE(scene_test::at(p, at + "iterations"), nullptr);
  scene_test::expectAt(p, at + "erp", "never correct");
  EXPECT_NE(scene_test::at(p, at + "cfm"), nullptr);
  EXPECT_NE(scene_test::at(p, at + "contacts_per_pair"), nullptr);
  EXPECT_NE(scene_test::at(p, at + "surface_layer"), nullptr);
  EXPECT_NE(scene_test::at(p, at + "stepper"), nullptr);
  EXPECT_EQ(p.size(), 6u) << dm::formatSceneErrors(p);

  j = odeScene();
  j["engines"]["physics"]["ode"] = 3;
  EXPECT_NE(scene_test::at(scene_test::problemsOf(j), "/engines/physics/ode"), nullptr);
}

TEST(ScenePhysicsBackendFile, TheBackendIsAVersionTwoKey) {
  Json j = odeScene();
  j["version"] = 1;
  for (Json& obj : j["objects"]) obj.erase("mass");  // a v2 key too
  const std::vector<dm::Error> p = scene_test::problemsOf(j);
  scene_test::expectAt(p, "/engines/physics/backend", "version-2 key");
  scene_test::expectAt(p, "/engines/physics/ode", "version-2 key");
}

}  // namespace scene_physics_backend_io_test
