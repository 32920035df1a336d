// The scene file's "scripts" (v2): a script's name, source (its language is
// its extension; resolved and confined like a resource's), the engine whose
// rate it takes and its args; what is refused, at its JSON pointer (the
// haptic thread, an engine the scene lacks, a duplicate name, a source
// without an extension or outside the allowed folders, args that are not an
// object, unknown keys, a version-1 scene); and the canonical JSON round trip.
#include <dm/io/scene_file.hpp>

#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "scene_test_support.hpp"

namespace scene_script_io_test {

using dm::Json;

Json scriptedScene() {
  return Json::parse(R"({
    "format": "dmplatform-scene", "version": 2, "name": "scripted",
    "resources": {"ball": {"type": "shape", "shape": "sphere", "radius": 0.01}},
    "materials": {"m": {"color": [0.5, 0.5, 0.5]}},
    "objects": [{"name": "ball", "mesh": "ball", "material": "m", "dynamic": true, "mass": 0.1}],
    "engines": {"physics": {"rate_hz": 500}},
    "scripts": [
      {"name": "tug", "source": "scripts/tug.py", "engine": "physics", "args": {"force_N": 0.5, "axis": [1, 0, 0]}},
      {"name": "log", "source": "log.py"}
    ]
  })");
}

TEST(SceneScriptFile, ReadsNameSourceEngineAndArgs) {
  std::vector<dm::Error> problems;
  auto s = dm::parseScene(scriptedScene().dump(), "scene.json", "/data/scenes", &problems);
  ASSERT_TRUE(s) << dm::formatSceneErrors(problems);
  ASSERT_EQ(s->scripts.size(), 2u);
  const dm::SceneScript& tug = s->scripts[0];
  EXPECT_EQ(tug.name, "tug");
  EXPECT_EQ(tug.source, "scripts/tug.py");
  EXPECT_EQ(tug.path, std::filesystem::path("/data/scenes/scripts/tug.py"));
  EXPECT_EQ(tug.engine, "physics");
  EXPECT_EQ(tug.args["force_N"], 0.5);
  EXPECT_EQ(tug.args["axis"], Json::array({1, 0, 0}));
  EXPECT_EQ(s->scripts[1].engine, "monitor");  // the default: the monitor always runs
  EXPECT_TRUE(s->scripts[1].args.is_object() && s->scripts[1].args.empty());
}

TEST(SceneScriptFile, RoundTripsThroughItsCanonicalJson) {
  std::vector<dm::Error> problems;
  auto s = dm::parseScene(scriptedScene().dump(), "scene.json", "/data/scenes", &problems);
  ASSERT_TRUE(s) << dm::formatSceneErrors(problems);
  const Json j = dm::toJson(*s);
  ASSERT_TRUE(j.contains("scripts"));
  auto again = dm::parseScene(j.dump(), "scene.json", "/data/scenes", &problems);
  ASSERT_TRUE(again) << dm::formatSceneErrors(problems);
  EXPECT_EQ(*again, *s);
  // A changed argument is a different scene (sweeps vary them).
  Json k = j;
  k["scripts"][0]["args"]["force_N"] = 0.6;
  auto other = dm::parseScene(k.dump(), "scene.json", "/data/scenes", &problems);
  ASSERT_TRUE(other);
  EXPECT_FALSE(*other == *s);
}

TEST(SceneScriptFile, RefusesEachMistakeAtItsPointer) {
  Json j = scriptedScene();
  j["scripts"] = Json::parse(R"([
    {"name": "a", "source": "a.py", "engine": "haptics"},
    {"name": "b", "source": "b.py", "engine": "render"},
    {"name": "a", "source": "c.py"},
    {"name": "d", "source": "noextension"},
    {"name": "e", "source": "e.py", "args": [1, 2]},
    {"name": "f", "source": "f.py", "rate_hz": 10},
    {"name": "g", "source": "../../../etc/passwd.py"},
    {"name": "", "source": "h.py"},
    {"name": "i", "source": "i.py", "engine": "physic"}
  ])");
  const std::vector<dm::Error> p = scene_test::problemsOf(j);
  scene_test::expectAt(p, "/scripts/0/engine", "haptic thread");
  scene_test::expectAt(p, "/scripts/1/engine", "no render engine");
  scene_test::expectAt(p, "/scripts/2/name", "duplicate");
  scene_test::expectAt(p, "/scripts/3/source", "no extension");
  scene_test::expectAt(p, "/scripts/4/args", "expected an object");
  scene_test::expectAt(p, "/scripts/5/rate_hz", "rate_hz");
  EXPECT_NE(scene_test::at(p, "/scripts/6/source"), nullptr);
  EXPECT_NE(scene_test::at(p, "/scripts/7/name"), nullptr);
  scene_test::expectAt(p, "/scripts/8/engine", "physics", true);
  EXPECT_EQ(p.size(), 9u) << dm::formatSceneErrors(p);
}

TEST(SceneScriptFile, IsAVersionTwoKey) {
  Json j = scriptedScene();
  j["version"] = 1;
  j["objects"][0].erase("mass");
  j["objects"][0]["dynamic"] = false;
  j["engines"].erase("physics");
  j["scripts"] = Json::parse(R"([{"name": "a", "source": "a.py"}])");
  const std::vector<dm::Error> p = scene_test::problemsOf(j);
  EXPECT_NE(scene_test::at(p, "/scripts"), nullptr);
}

}  // namespace scene_script_io_test
