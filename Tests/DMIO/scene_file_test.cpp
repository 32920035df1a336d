// Tests of the scene file parser (dm/io/scene_file.hpp): the bundled scene,
// one test per kind of error with its exact JSON path and hint, several
// errors at once, the toJson round trip and source resolution.
#include <dm/core/filesystem.hpp>
#include <dm/io/scene_file.hpp>

#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include "scene_test_support.hpp"

namespace {

namespace fs = std::filesystem;
using dm::Json;
using namespace scene_test;

// A small valid scene that the error tests break one key at a time.
Json baseScene() {
  return Json::parse(R"({
    "format": "dmplatform-scene",
    "version": 1,
    "name": "base",
    "resources": {
      "head": {"type": "volume", "source": "mricron:ch2.nii.gz"},
      "skin": {"type": "isosurface", "volume": "head", "level": 40},
      "ball": {"type": "shape", "shape": "sphere", "radius": 0.01},
      "bump": {"type": "image", "source": "bump.png"}
    },
    "materials": {
      "skin": {"model": "blinn-phong", "haptic": {"stiffness": 800, "static_friction": 0.3,
                                                   "dynamic_friction": 0.2}},
      "plain": {"model": "pbr"}
    },
    "objects": [
      {"name": "head_skin", "mesh": "skin", "material": "skin", "haptic": true},
      {"name": "ball", "mesh": "ball", "material": "plain", "dynamic": true, "mass": 0.1}
    ],
    "volumes": [
      {"name": "mri", "volume": "head", "mode": "composite",
       "transfer_function": {"points": [[0, 0, 0, 0, 0], [100, 1, 1, 1, 0.5]]}}
    ],
    "lights": [{"type": "directional", "direction": [0, 0, -1]}],
    "cameras": [{"name": "main", "position": [0, -0.5, 0], "target": [0, 0, 0]}],
    "devices": [{"name": "hand", "driver": "sim-haptic", "config": {"path": "circle"}}],
    "engines": {
      "haptics": {"device": "hand", "objects": ["head_skin"]},
      "physics": {},
      "render": {"camera": "main"}
    }
  })");
}

TEST(SceneFile, BaseSceneIsValid) {
  std::vector<dm::Error> problems;
  auto s = dm::parseScene(baseScene().dump(), "scene.json", "/data/scenes", &problems);
  ASSERT_TRUE(s) << dm::formatSceneErrors(problems);
  EXPECT_TRUE(problems.empty());
  EXPECT_EQ(s->resource("bump")->path, fs::path("/data/scenes/bump.png"));
  EXPECT_EQ(s->object("nothing"), nullptr);
  EXPECT_EQ(s->object("ball")->mass, 0.1);
}

TEST(SceneFile, BundledHeadProbeSceneHasTheValuesOfTheMainJob) {
  const fs::path file = sourceDir() / "examples/scenes/head_probe.json";
  std::vector<dm::Error> problems;
  auto s = dm::readScene(file, &problems);
  ASSERT_TRUE(s) << dm::formatSceneErrors(problems);
  EXPECT_EQ(s->name, "head_probe");
  EXPECT_EQ(fs::weakly_canonical(s->baseDir), fs::weakly_canonical(file.parent_path()));

  ASSERT_EQ(s->resources.size(), 4u);
  const dm::SceneResource* head = s->resource("head");
  ASSERT_NE(head, nullptr);
  EXPECT_EQ(head->type, dm::SceneResource::Type::Volume);
  EXPECT_EQ(head->source, "mricron:ch2.nii.gz");
  // The mount resolves to the Debian package's file when it is installed.
  auto expected = dm::FileSystem::global().resolve("mricron:ch2.nii.gz");
  EXPECT_EQ(head->path, expected ? *expected : fs::path());
  const dm::SceneResource* skin = s->resource("skin");
  ASSERT_NE(skin, nullptr);
  EXPECT_EQ(skin->type, dm::SceneResource::Type::Isosurface);
  EXPECT_EQ(skin->volume, "head");
  EXPECT_EQ(skin->level, 40.0);
  EXPECT_TRUE(skin->largestComponent);
  // The voxel staircase smoothed away within half a voxel: it excited the
  // simulated hand's 15.5 Hz resonance (docs/haptics-accuracy.md).
  EXPECT_EQ(skin->smooth, 20);
  EXPECT_EQ(skin->smoothMaxDisplacement, 0.0005);
  const dm::SceneResource* tool = s->resource("tool");
  ASSERT_NE(tool, nullptr);
  EXPECT_EQ(tool->shape, dm::SceneResource::Shape::Sphere);
  EXPECT_DOUBLE_EQ(tool->radius, 4e-3);  // the proxy's marker, drawn 4 mm

  // examples/head_probe/main.cpp: k = 800 N/m, b = 0.5 N·s/m, mu_s 0.3, mu_d 0.2.
  const dm::SceneMaterial* skinMat = s->material("skin");
  ASSERT_TRUE(skinMat && skinMat->haptic);
  EXPECT_EQ(skinMat->haptic->stiffness, 800.0);
  EXPECT_EQ(skinMat->haptic->damping, 0.5);
  EXPECT_EQ(skinMat->haptic->staticFriction, 0.3);
  EXPECT_EQ(skinMat->haptic->dynamicFriction, 0.2);
  EXPECT_EQ(s->material("steel")->model, dm::SceneMaterial::Model::Pbr);
  EXPECT_EQ(s->material("steel")->color.w(), 1.0);  // alpha defaults to opaque

  ASSERT_EQ(s->objects.size(), 2u);
  EXPECT_EQ(s->objects[0].name, "head_skin");
  // Touched at full resolution, drawn from the skin averaged over 4x4x4 voxels
  // (light enough for llvmpipe at 30 Hz beside the 1 kHz haptic loop).
  EXPECT_EQ(s->objects[0].mesh, "skin");
  EXPECT_EQ(s->objects[0].renderMesh, "skin_view");
  EXPECT_EQ(s->resource("skin_view")->downsample, 4);
  EXPECT_TRUE(s->objects[0].haptic);
  EXPECT_TRUE(s->objects[0].pose.isometry().isApprox(dm::Isometry3::Identity()));
  EXPECT_FALSE(s->objects[1].haptic);

  // A key light and a fill, unshadowed: a shadow pass costs llvmpipe more
  // than the 30 Hz frame budget (docs/performance.md).
  ASSERT_EQ(s->lights.size(), 2u);
  EXPECT_FALSE(s->lights[0].shadows);
  EXPECT_FALSE(s->lights[1].shadows);
  EXPECT_NEAR(s->lights[0].direction.norm(), 1.0, 1e-15);
  EXPECT_TRUE(s->lights[0].direction.isApprox(dm::Vec3(-0.6, -0.3, -0.5).normalized(), 1e-15));

  // The camera sits at the front (+y, anterior) right (+x) of the head and looks at it.
  ASSERT_EQ(s->cameras.size(), 1u);
  const dm::SceneCamera& cam = s->cameras[0];
  EXPECT_GT(cam.position.x(), 0.0);
  EXPECT_GT(cam.position.y(), 0.0);
  EXPECT_LT((cam.target - cam.position).dot(cam.position), 0.0);
  EXPECT_EQ(cam.fovYDeg, 35.0);

  // The device config is the main job's sim-haptic parameter list.
  const dm::SceneDevice* hand = s->device("hand");
  ASSERT_NE(hand, nullptr);
  EXPECT_EQ(hand->driver, "sim-haptic");
  const auto params = dm::deviceParams(*hand);
  const std::vector<std::pair<std::string, std::string>> want = {
      {"center", "0,0,-0.004"},  {"hand", "1"},      {"hand_damping", "4"}, {"hand_mass", "0.1"},
      {"hand_stiffness", "150"}, {"max_force", "3"}, {"path", "circle"},    {"period", "2"},
      {"radius", "0.015"}};
  EXPECT_EQ(params, want);

  ASSERT_TRUE(s->engines.haptics);
  const dm::SceneHapticsEngine& h = *s->engines.haptics;
  EXPECT_EQ(h.rateHz, 1000.0);
  EXPECT_EQ(h.renderer, dm::SceneHapticsEngine::Renderer::GodObject);
  EXPECT_EQ(h.device, "hand");
  EXPECT_EQ(h.objects, std::vector<std::string>{"head_skin"});
  EXPECT_EQ(h.proxyObject, "tool");
  EXPECT_EQ(h.maxForce, 3.0);
  EXPECT_TRUE(h.forceShading);
  // main.cpp's deviceToWorld: world x = device z, world y = device x, world z = device y.
  EXPECT_TRUE((h.devicePose.q * dm::Vec3::UnitZ()).isApprox(dm::Vec3::UnitX(), 1e-12));
  EXPECT_TRUE((h.devicePose.q * dm::Vec3::UnitX()).isApprox(dm::Vec3::UnitY(), 1e-12));
  EXPECT_TRUE((h.devicePose.q * dm::Vec3::UnitY()).isApprox(dm::Vec3::UnitZ(), 1e-12));
  ASSERT_TRUE(s->engines.render && s->engines.monitor);
  EXPECT_EQ(s->engines.render->rateHz, 30.0);
  EXPECT_EQ(s->engines.render->width, 640);
  EXPECT_EQ(s->engines.render->height, 480);
  EXPECT_EQ(s->engines.render->camera, "front_right");
  EXPECT_EQ(s->engines.monitor->rateHz, 30.0);
  EXPECT_FALSE(s->engines.physics);

  EXPECT_EQ(s->outputs.directory, "out/head_probe");
  EXPECT_TRUE(s->outputs.frames && s->outputs.forces && s->outputs.plot && s->outputs.summary);
}

TEST(SceneFile, MissingRequiredKey) {
  Json j = baseScene();
  j["objects"][0].erase("mesh");
  j.erase("format");
  const auto p = problemsOf(j);
  ASSERT_EQ(p.size(), 2u) << dm::formatSceneErrors(p);
  const dm::Error* e = at(p, "/format");
  ASSERT_TRUE(e);
  EXPECT_EQ(e->what, "missing required string");
  e = at(p, "/objects/0/mesh");
  ASSERT_TRUE(e);
  EXPECT_EQ(e->hint, "add \"mesh\": \"...\"");
}

TEST(SceneFile, WrongType) {
  Json j = baseScene();
  j["objects"][1]["scale"] = "big";
  j["lights"][0]["shadows"] = 1;
  const auto p = problemsOf(j);
  ASSERT_EQ(p.size(), 2u) << dm::formatSceneErrors(p);
  const dm::Error* e = at(p, "/objects/1/scale");
  ASSERT_TRUE(e);
  EXPECT_EQ(e->what, "expected a number, got string \"big\"");
  e = at(p, "/lights/0/shadows");
  ASSERT_TRUE(e);
  EXPECT_EQ(e->what, "expected true or false, got number 1");
}

TEST(SceneFile, OutOfRange) {
  Json j = baseScene();
  j["engines"]["haptics"]["rate_hz"] = 50000;
  j["materials"]["plain"]["roughness"] = 1.5;
  j["materials"]["plain"]["color"] = {0.5, 2.0, 0.5};
  const auto p = problemsOf(j);
  ASSERT_EQ(p.size(), 3u) << dm::formatSceneErrors(p);
  const dm::Error* e = at(p, "/engines/haptics/rate_hz");
  ASSERT_TRUE(e);
  EXPECT_EQ(e->what, "value 50000 is outside [100, 10000]");
  ASSERT_TRUE(at(p, "/materials/plain/roughness"));
  e = at(p, "/materials/plain/color/1");
  ASSERT_TRUE(e);
  EXPECT_EQ(e->hint, "colours are linear, 0..1 (not 0..255)");
}

TEST(SceneFile, ServedDevicesAndTheirReferences) {
  Json j = baseScene();
  j["devices"].push_back({{"name", "console"},
                          {"driver", "sim-haptic"},
                          {"serve", {{"listen", "127.0.0.1"}, {"timeout", 0}, {"wave_b", 1}}}});
  j["devices"].push_back({{"name", "far"}, {"driver", "net-haptic"}, {"config", {{"device", "@hand"}}}});
  j["devices"].push_back({{"name", "self"}, {"driver", "net-haptic"}, {"config", {{"device", "@nobody"}}}});
  const auto p = problemsOf(j);
  ASSERT_EQ(p.size(), 5u) << dm::formatSceneErrors(p);
  const dm::Error* e = at(p, "/devices/1/serve/listen");
  ASSERT_TRUE(e);
  EXPECT_EQ(e->what, "listen: '127.0.0.1' has no \"address:port\" form");
  ASSERT_TRUE(at(p, "/devices/1/serve/timeout"));
  ASSERT_TRUE(at(p, "/devices/1/serve/wave_b"));
  // "hand" exists but is not served; "nobody" does not exist.
  e = at(p, "/devices/2/config/device");
  ASSERT_TRUE(e);
  EXPECT_EQ(e->what, "\"@hand\" names no other device with \"serve\"");
  ASSERT_TRUE(at(p, "/devices/3/config/device"));

  Json ok = baseScene();
  ok["devices"].push_back({{"name", "console"}, {"driver", "sim-haptic"}, {"serve", Json::object()}});
  ok["devices"][0]["config"]["device"] = "@console";
  auto scene = dm::parseScene(ok.dump(), "scene.json", "/data/scenes");
  ASSERT_TRUE(scene) << scene.error();
  ASSERT_TRUE(scene->device("console")->serve);
  EXPECT_EQ(scene->device("console")->serve->listen, "127.0.0.1:0");  // the defaults
  EXPECT_EQ(scene->device("console")->serve->timeout, 0.1);
  EXPECT_EQ(scene->device("console")->serve->waveImpedance, 0.0);
}

TEST(SceneFile, UnknownKeyGetsSuggestion) {
  Json j = baseScene();
  j["objects"][0]["visibel"] = true;
  j["camera"] = Json::array();
  j["materials"]["skin"]["roughness"] = 0.5;  // a PBR key on a Blinn-Phong material
  const auto p = problemsOf(j);
  ASSERT_EQ(p.size(), 3u) << dm::formatSceneErrors(p);
  const dm::Error* e = at(p, "/objects/0/visibel");
  ASSERT_TRUE(e);
  EXPECT_EQ(e->what, "unknown key \"visibel\"");
  EXPECT_EQ(e->hint, "did you mean \"visible\"?");
  e = at(p, "/camera");
  ASSERT_TRUE(e);
  EXPECT_EQ(e->hint, "did you mean \"cameras\"?");
  ASSERT_TRUE(at(p, "/materials/skin/roughness"));
}

TEST(SceneFile, DanglingReferencesGetSuggestions) {
  Json j = baseScene();
  j["objects"][0]["mesh"] = "skni";
  j["resources"]["skin"]["volume"] = "haed";
  j["cameras"][0]["track"] = "head_skn";
  j["engines"]["haptics"]["device"] = "hnd";
  j["engines"]["render"]["camera"] = "mian";
  j["materials"]["plain"]["texture"] = "bmup";
  j["volumes"][0]["volume"] = "nothing_like_it";
  const auto p = problemsOf(j);
  ASSERT_EQ(p.size(), 7u) << dm::formatSceneErrors(p);
  const dm::Error* e = at(p, "/objects/0/mesh");
  ASSERT_TRUE(e);
  EXPECT_EQ(e->message(),
            "scene.json: /objects/0/mesh: invalid argument: no resource \"skni\" (did you mean \"skin\"?)");
  e = at(p, "/resources/skin/volume");
  ASSERT_TRUE(e);
  EXPECT_EQ(e->hint, "did you mean \"head\"?");
  e = at(p, "/cameras/0/track");
  ASSERT_TRUE(e);
  EXPECT_EQ(e->what, "no object \"head_skn\"");
  EXPECT_EQ(e->hint, "did you mean \"head_skin\"?");
  e = at(p, "/engines/haptics/device");
  ASSERT_TRUE(e);
  EXPECT_EQ(e->hint, "did you mean \"hand\"?");
  e = at(p, "/engines/render/camera");
  ASSERT_TRUE(e);
  EXPECT_EQ(e->hint, "did you mean \"main\"?");
  e = at(p, "/materials/plain/texture");
  ASSERT_TRUE(e);
  EXPECT_EQ(e->hint, "did you mean \"bump\"?");
  e = at(p, "/volumes/0/volume");
  ASSERT_TRUE(e);
  EXPECT_EQ(e->hint, "define it under \"resources\"");
}

TEST(SceneFile, HeightMapComesWithItsScaleInMetres) {
  Json j = baseScene();
  j["materials"]["skin"]["height_map"] = "bump";
  j["materials"]["skin"]["height_scale"] = 0.003;
  auto scene = dm::parseScene(j.dump(), "scene.json", "/data/scenes");
  ASSERT_TRUE(scene) << scene.error();
  const dm::SceneMaterial* skin = scene->material("skin");
  ASSERT_TRUE(skin);
  EXPECT_EQ(skin->heightMap, "bump");
  EXPECT_EQ(skin->heightScale, 0.003);

  j["materials"]["skin"].erase("height_scale");     // a map needs its depth
  j["materials"]["plain"]["height_scale"] = 0.001;  // a depth needs its map
  j["materials"]["plain"]["normal_map"] = "bump";   // (a valid key beside it)
  Json tooDeep = baseScene();
  tooDeep["materials"]["skin"]["height_map"] = "bump";
  tooDeep["materials"]["skin"]["height_scale"] = 2;  // 2 m: a unit mistake
  auto p = problemsOf(j);
  ASSERT_EQ(p.size(), 2u) << dm::formatSceneErrors(p);
  ASSERT_TRUE(at(p, "/materials/skin/height_scale"));
  const dm::Error* e = at(p, "/materials/plain/height_scale");
  ASSERT_TRUE(e);
  EXPECT_EQ(e->what, "height_scale without a height_map");
  p = problemsOf(tooDeep);
  ASSERT_EQ(p.size(), 1u) << dm::formatSceneErrors(p);
  e = at(p, "/materials/skin/height_scale");
  ASSERT_TRUE(e);
  EXPECT_EQ(e->what, "value 2 is outside [0, 1]");
}

TEST(SceneFile, ReferenceToTheWrongKindOfResource) {
  Json j = baseScene();
  j["objects"][0]["mesh"] = "head";               // a volume
  j["engines"]["haptics"]["objects"] = {"ball"};  // not touchable
  const auto p = problemsOf(j);
  ASSERT_EQ(p.size(), 2u) << dm::formatSceneErrors(p);
  const dm::Error* e = at(p, "/objects/0/mesh");
  ASSERT_TRUE(e);
  EXPECT_EQ(e->what, "resource \"head\" is a volume, not a mesh, isosurface or shape");
  EXPECT_EQ(e->hint, "use one of: \"ball\", \"skin\"");
  e = at(p, "/engines/haptics/objects/0");
  ASSERT_TRUE(e);
  EXPECT_EQ(e->what, "object \"ball\" is not touchable");
}

TEST(SceneFile, DuplicateNames) {
  Json j = baseScene();
  j["objects"][1]["name"] = "head_skin";
  auto p = problemsOf(j);
  ASSERT_EQ(p.size(), 1u) << dm::formatSceneErrors(p);
  const dm::Error* e = at(p, "/objects/1/name");
  ASSERT_TRUE(e);
  EXPECT_EQ(e->what, "duplicate name \"head_skin\" (also used by /objects/0)");

  // Resources are keyed by name: a repeated key would silently replace the first.
  std::string text = baseScene().dump();
  const std::string from = "\"resources\":{";
  text.insert(text.find(from) + from.size(), R"("skin":{"type":"volume","source":"a.nii"},)");
  std::vector<dm::Error> problems;
  auto s = dm::parseScene(text, "scene.json", "/data/scenes", &problems);
  ASSERT_FALSE(s);
  ASSERT_EQ(problems.size(), 1u) << dm::formatSceneErrors(problems);
  e = at(problems, "/resources/skin");
  ASSERT_TRUE(e);
  EXPECT_EQ(e->what, "key \"skin\" appears more than once in this object (only the last one counts)");
}

TEST(SceneFile, QuaternionsMustBeUnitEulerAnglesAreDegrees) {
  Json j = baseScene();
  j["objects"][0]["pose"] = {{"rotation", {1, 1, 0, 0}}};
  auto p = problemsOf(j);
  ASSERT_EQ(p.size(), 1u) << dm::formatSceneErrors(p);
  const dm::Error* e = at(p, "/objects/0/pose/rotation");
  ASSERT_TRUE(e);
  EXPECT_EQ(e->what, "rotation quaternion has length 1.41421, not 1");
  EXPECT_EQ(e->hint, "give a unit quaternion [w, x, y, z], or use \"euler_deg\": [rx, ry, rz]");

  // Slightly off (a rounded file) is normalised; Euler angles rotate x, then y, then z.
  j["objects"][0]["pose"] = {{"position", {0.1, 0.2, 0.3}}, {"rotation", {0.7071, 0, 0, 0.7071}}};
  j["objects"][1]["pose"] = {{"euler_deg", {0, 0, 90}}};
  auto s = dm::parseScene(j.dump(), "scene.json", "/data/scenes");
  ASSERT_TRUE(s) << s.error();
  const dm::Pose& a = s->objects[0].pose;
  EXPECT_NEAR(a.q.norm(), 1.0, 1e-15);
  EXPECT_TRUE((a * dm::Vec3::UnitX()).isApprox(dm::Vec3(0.1, 1.2, 0.3), 1e-12));
  EXPECT_TRUE((s->objects[1].pose.q * dm::Vec3::UnitX()).isApprox(dm::Vec3::UnitY(), 1e-12));
  j["objects"][1]["pose"] = {{"euler_deg", {90, 0, 90}}};
  s = dm::parseScene(j.dump(), "scene.json", "/data/scenes");
  ASSERT_TRUE(s) << s.error();
  // x then z: y → z (about x), z stays z (about z).
  EXPECT_TRUE((s->objects[1].pose.q * dm::Vec3::UnitY()).isApprox(dm::Vec3::UnitZ(), 1e-12));
  EXPECT_TRUE((s->objects[1].pose.q * dm::Vec3::UnitX()).isApprox(dm::Vec3::UnitY(), 1e-12));
}

TEST(SceneFile, TransferFunctionMustBeSorted) {
  Json j = baseScene();
  j["volumes"][0]["transfer_function"]["points"] = {{0, 0, 0, 0, 0}, {100, 1, 1, 1, 1}, {50, 1, 0, 0, 1}};
  auto p = problemsOf(j);
  ASSERT_EQ(p.size(), 1u) << dm::formatSceneErrors(p);
  const dm::Error* e = at(p, "/volumes/0/transfer_function/points/2/0");
  ASSERT_TRUE(e);
  EXPECT_EQ(e->what, "value 50 does not increase (previous point: 100)");
  EXPECT_EQ(e->hint, "sort the points by value; values must strictly increase");

  j["volumes"][0]["transfer_function"]["points"] = {{0, 0, 0, 0, 0}};
  p = problemsOf(j);
  ASSERT_EQ(p.size(), 1u) << dm::formatSceneErrors(p);
  ASSERT_TRUE(at(p, "/volumes/0/transfer_function/points"));
}

TEST(SceneFile, UnsupportedVersionStopsEarly) {
  Json j = baseScene();
  j["version"] = 3;
  j["objects"][0]["mesh"] = "skni";  // not reported: a version-3 file may mean something else
  dm::ErrorCode code{};
  const auto p = problemsOf(j, &code);
  ASSERT_EQ(p.size(), 1u) << dm::formatSceneErrors(p);
  EXPECT_EQ(code, dm::ErrorCode::Version);
  EXPECT_EQ(p[0].code, dm::ErrorCode::Version);
  EXPECT_EQ(p[0].where, "scene.json: /version");
  EXPECT_EQ(p[0].what, "unsupported scene version 3");
  EXPECT_EQ(p[0].hint, "this build reads versions 1 and 2");

  j = baseScene();
  j["format"] = "dmplatform-config";
  const auto q = problemsOf(j);
  ASSERT_EQ(q.size(), 1u);
  EXPECT_EQ(q[0].where, "scene.json: /format");
}

TEST(SceneFile, RigidBodyKeysAreCheckedAndNeedVersionTwo) {
  // Version 2 adds density, initial velocities, collide and contact; a
  // version-1 file that uses them is told so rather than read differently.
  Json j = baseScene();
  j["objects"][1]["velocity"] = {0, 0, 1};
  j["objects"][1]["contact"] = {{"friction", 0.2}};
  j["engines"]["physics"]["sleep"] = true;
  auto p = problemsOf(j);
  ASSERT_EQ(p.size(), 3u) << dm::formatSceneErrors(p);
  for (const char* where : {"/objects/1/velocity", "/objects/1/contact", "/engines/physics/sleep"}) {
    const dm::Error* e = at(p, where);
    ASSERT_TRUE(e) << where;
    EXPECT_EQ(e->hint, "set \"version\": 2");
  }

  j["version"] = 2;
  auto s = dm::parseScene(j.dump(), "scene.json", "/data/scenes");
  ASSERT_TRUE(s) << s.error();
  const dm::SceneObject& ball = s->objects[1];
  EXPECT_EQ(ball.velocity, dm::Vec3(0, 0, 1));
  EXPECT_EQ(ball.friction, 0.2);
  EXPECT_EQ(ball.restitution, 0.0);
  EXPECT_TRUE(ball.collide);
  EXPECT_TRUE(s->engines.physics->sleep);

  // One of mass and density; only dynamic objects have them or move.
  j["objects"][1]["density"] = 1000;
  j["objects"][0]["angular_velocity"] = {1, 0, 0};
  j["objects"][0]["mass"] = 2;
  j["objects"][1]["contact"]["restitution"] = 1.5;
  j["objects"][1]["contact"]["frction"] = 0.1;
  p = problemsOf(j);
  ASSERT_EQ(p.size(), 5u) << dm::formatSceneErrors(p);
  for (const char* where : {"/objects/1/density", "/objects/0/angular_velocity", "/objects/0/mass",
                            "/objects/1/contact/restitution", "/objects/1/contact/frction"})
    EXPECT_TRUE(at(p, where)) << where;

  // A dynamic object needs the physics engine, and the engine something to move.
  j = baseScene();
  j["engines"].erase("physics");
  p = problemsOf(j);
  ASSERT_EQ(p.size(), 1u) << dm::formatSceneErrors(p);
  ASSERT_TRUE(at(p, "/objects/1/dynamic"));
  EXPECT_NE(p[0].what.find("no physics engine"), std::string::npos);
  j = baseScene();
  j["objects"][1]["dynamic"] = false;
  j["objects"][1].erase("mass");
  p = problemsOf(j);
  ASSERT_EQ(p.size(), 1u) << dm::formatSceneErrors(p);
  EXPECT_TRUE(at(p, "/engines/physics"));

  // The tool's picture is no body; a plane has no volume to move.
  j = baseScene();
  j["engines"]["haptics"]["proxy_object"] = "ball";
  p = problemsOf(j);
  ASSERT_EQ(p.size(), 1u) << dm::formatSceneErrors(p);
  EXPECT_TRUE(at(p, "/objects/1/dynamic"));
  j = baseScene();
  j["resources"]["ball"] = {{"type", "shape"}, {"shape", "plane"}, {"half_extents", {0.1, 0.1}}};
  p = problemsOf(j);
  ASSERT_EQ(p.size(), 1u) << dm::formatSceneErrors(p);
  EXPECT_TRUE(at(p, "/objects/1/mesh"));
}

TEST(SceneFile, SmoothingBoundIsAVersionTwoKeyThatNeedsSmoothing) {
  Json j = baseScene();
  j["resources"]["skin"]["smooth_max_displacement"] = 0.0005;
  auto p = problemsOf(j);
  ASSERT_EQ(p.size(), 1u) << dm::formatSceneErrors(p);  // a v2 key in v1, read no further
  const dm::Error* e = at(p, "/resources/skin/smooth_max_displacement");
  ASSERT_TRUE(e);
  EXPECT_EQ(e->hint, "set \"version\": 2");

  j["version"] = 2;
  p = problemsOf(j);
  ASSERT_EQ(p.size(), 1u) << dm::formatSceneErrors(p);
  e = at(p, "/resources/skin/smooth_max_displacement");
  ASSERT_TRUE(e);
  EXPECT_NE(e->what.find("\"smooth\" is 0"), std::string::npos) << e->what;

  j["resources"]["skin"]["smooth"] = 10;
  auto s = dm::parseScene(j.dump(), "scene.json", "/data/scenes");
  ASSERT_TRUE(s) << s.error();
  EXPECT_EQ(s->resource("skin")->smoothMaxDisplacement, 0.0005);
  EXPECT_EQ(s->resource("skin")->smooth, 10);
  EXPECT_EQ(dm::toJson(*s)["resources"]["skin"]["smooth_max_displacement"], 0.0005);
  // Unbounded unless given, and then not written.
  EXPECT_FALSE(dm::toJson(*s)["resources"]["head"].contains("smooth_max_displacement"));

  for (const Json& bad : {Json(0.0), Json(-1e-3), Json(0.5), Json("half a voxel")}) {
    j["resources"]["skin"]["smooth_max_displacement"] = bad;
    p = problemsOf(j);
    ASSERT_EQ(p.size(), 1u) << bad << dm::formatSceneErrors(p);
    EXPECT_TRUE(at(p, "/resources/skin/smooth_max_displacement")) << bad;
  }
}

TEST(SceneFile, NotJsonNamesLineAndColumn) {
  std::vector<dm::Error> problems;
  auto s = dm::parseScene("{\n  \"format\": \"dmplatform-scene\",\n  \"version\" 1\n}", "scene.json", "/",
                          &problems);
  ASSERT_FALSE(s);
  EXPECT_EQ(s.error().code, dm::ErrorCode::Parse);
  // The unexpected '1' is on line 3, column 13: byte 47 counting from 1 (2 + 32 + 13).
  EXPECT_EQ(s.error().what, "invalid JSON at line 3, column 13");
  EXPECT_EQ(s.error().where, "scene.json: byte 47");
  ASSERT_EQ(problems.size(), 1u);

  s = dm::parseScene(std::string(100, '[') + std::string(100, ']'), "deep.json", "/", &problems);
  ASSERT_FALSE(s);
  EXPECT_EQ(s.error().where, "deep.json: byte 65");
  s = dm::parseScene("[1, 2]", "array.json", "/", &problems);
  ASSERT_FALSE(s);
  EXPECT_EQ(s.error().where, "array.json: /");
}

TEST(SceneFile, EveryProblemIsReportedAtOnce) {
  Json j = baseScene();
  j["objects"][0]["mesh"] = "skni";                            // dangling
  j["objects"][1]["scale"] = -1;                               // out of range
  j["materials"]["skin"]["haptic"]["dynamic_friction"] = 0.5;  // > static 0.3
  j["cameras"][0]["up"] = {0, 1, 0};                           // parallel to the view
  j["cameras"][0]["far"] = 0.001;                              // before near
  j["objects"][1].erase("mass");                               // dynamic without mass
  j["lights"][0]["direction"] = {0, 0, 0};                     // zero
  j["outputs"] = {{"frames", true}, {"frame_every", 0}};       // frame_every < 1
  const auto p = problemsOf(j);
  ASSERT_EQ(p.size(), 8u) << dm::formatSceneErrors(p);
  for (const char* where :
       {"/objects/0/mesh", "/objects/1/scale", "/materials/skin/haptic/dynamic_friction", "/cameras/0/up",
        "/cameras/0/far", "/objects/1/mass", "/lights/0/direction", "/outputs/frame_every"})
    EXPECT_TRUE(at(p, where));
  EXPECT_EQ(at(p, "/materials/skin/haptic/dynamic_friction")->what,
            "dynamic friction 0.5 is larger than static friction 0.3");
  auto s = dm::parseScene(j.dump(), "scene.json", "/data/scenes");
  ASSERT_FALSE(s);
  EXPECT_NE(s.error().what.find("(and 7 more problems:"), std::string::npos) << s.error().what;
  const std::string listing = dm::formatSceneErrors(p);
  EXPECT_EQ(std::count(listing.begin(), listing.end(), '\n'), 8);
}

TEST(SceneFile, KeysAndLimitsDependOnTheKind) {
  Json j = baseScene();
  j["resources"]["s"] = {{"type", "shape"}, {"shape", "sphere"}, {"radius", 0.01}, {"height", 0.1}};
  j["resources"]["b"] = {{"type", "shape"}, {"shape", "box"}, {"half_extents", {0.1, 0.0, 0.1}}};
  j["lights"].push_back({{"type", "spot"},
                         {"direction", {0, 0, -1}},
                         {"position", {0, 0, 1}},
                         {"inner_cone_deg", 40},
                         {"outer_cone_deg", 30}});
  j["devices"][0]["config"]["nested"] = {{"a", 1}};
  j["engines"]["render"]["samples"] = 3;
  j["engines"]["haptics"]["object"] = "head_skin";
  j["volumes"][0]["slice"] = {{"axis", "axial"}};
  j["materials"]["plain"]["texture"] = "head";
  const auto p = problemsOf(j);
  ASSERT_EQ(p.size(), 8u) << dm::formatSceneErrors(p);
  const dm::Error* e = at(p, "/resources/s/height");
  ASSERT_TRUE(e);
  EXPECT_EQ(e->hint, "remove it");
  e = at(p, "/resources/b/half_extents");
  ASSERT_TRUE(e);
  EXPECT_EQ(e->what, "half extents must be greater than 0");
  e = at(p, "/lights/1/inner_cone_deg");
  ASSERT_TRUE(e);
  EXPECT_EQ(e->what, "inner cone 40° must be > 0 and <= outer cone 30°");
  ASSERT_TRUE(at(p, "/devices/0/config/nested"));
  e = at(p, "/engines/render/samples");
  ASSERT_TRUE(e);
  EXPECT_EQ(e->what, "samples is 3, not 1, 2, 4, 8 or 16");
  ASSERT_TRUE(at(p, "/engines/haptics/object"));
  e = at(p, "/volumes/0/slice");
  ASSERT_TRUE(e);
  EXPECT_EQ(e->hint, "remove it, or set \"mode\": \"slice\"");
  e = at(p, "/materials/plain/texture");
  ASSERT_TRUE(e);
  EXPECT_EQ(e->what, "resource \"head\" is a volume, not an image");
  EXPECT_EQ(e->hint, "use one of: \"bump\"");
}

// A document in toJson's canonical form that sets every key to a non-default
// value: parsing and writing it back must give the same document.
Json fullScene() {
  return Json::parse(R"({
    "format": "dmplatform-scene", "version": 2, "name": "full",
    "resources": {
      "box": {"type": "shape", "shape": "box", "half_extents": [0.1, 0.2, 0.3], "subdivisions": 1},
      "cap": {"type": "shape", "shape": "capsule", "radius": 0.01, "height": 0.05, "subdivisions": 2},
      "cyl": {"type": "shape", "shape": "cylinder", "radius": 0.02, "height": 0.04, "subdivisions": 4},
      "floor": {"type": "shape", "shape": "plane", "half_extents": [1.0, 2.0], "subdivisions": 0},
      "ball": {"type": "shape", "shape": "sphere", "radius": 0.005, "subdivisions": 5},
      "hammer": {"type": "shape", "shape": "compound", "subdivisions": 2, "parts": [
        {"shape": "box", "half_extents": [0.1, 0.005, 0.005],
         "pose": {"position": [0.0, 0.0, 0.0], "rotation": [1.0, 0.0, 0.0, 0.0]}},
        {"shape": "cylinder", "radius": 0.015, "height": 0.04,
         "pose": {"position": [0.11, 0.0, 0.0], "rotation": [0.0, 0.6, 0.8, 0.0]}},
        {"shape": "sphere", "radius": 0.004, "pose": {"position": [-0.1, 0.0, 0.0], "rotation": [1.0, 0.0, 0.0, 0.0]}},
        {"shape": "capsule", "radius": 0.003, "height": 0.01,
         "pose": {"position": [0.0, 0.0, 0.01], "rotation": [1.0, 0.0, 0.0, 0.0]}}]},
      "liver": {"type": "mesh", "source": "meshes/liver.stl", "unit": "mm", "scale": 1.5},
      "ct": {"type": "volume", "source": "/data/scenes/ct/ct.nii.gz"},
      "iso": {"type": "isosurface", "volume": "ct", "level": 300.5, "largest_component": true, "smooth": 4,
              "smooth_max_displacement": 0.0005, "downsample": 3},
      "albedo": {"type": "image", "source": "textures/albedo.png"},
      "normals": {"type": "image", "source": "textures/normals.png"},
      "relief": {"type": "image", "source": "textures/relief.png"}
    },
    "materials": {
      "metal": {"model": "pbr", "color": [0.1, 0.2, 0.3, 0.4], "emissive": [2.0, 0.0, 0.5],
                "metallic": 0.9, "roughness": 0.1, "texture": "albedo", "normal_map": "normals",
                "height_map": "relief", "height_scale": 0.002,
                "haptic": {"stiffness": 900.0, "damping": 0.5, "static_friction": 0.0, "dynamic_friction": 0.0}},
      "tissue": {"model": "blinn-phong", "color": [0.9, 0.5, 0.4, 1.0], "emissive": [0.0, 0.0, 0.0],
                 "specular": [0.3, 0.3, 0.3], "shininess": 12.0,
                 "haptic": {"stiffness": 350.0, "damping": 1.5, "static_friction": 0.4, "dynamic_friction": 0.25}}
    },
    "objects": [
      {"name": "liver", "mesh": "liver", "material": "metal", "scale": 2.0, "visible": false, "haptic": true,
       "dynamic": false, "pose": {"position": [0.01, 0.02, 0.03], "rotation": [0.0, 0.6, 0.8, 0.0]},
       "collide": false, "contact": {"friction": 0.7, "restitution": 0.1}},
      {"name": "ball", "mesh": "ball", "material": "metal", "scale": 1.0, "visible": true, "haptic": false,
       "dynamic": true, "mass": 0.25, "pose": {"position": [0.0, 0.0, 0.5], "rotation": [1.0, 0.0, 0.0, 0.0]},
       "velocity": [0.1, 0.0, -0.2], "angular_velocity": [0.0, 0.0, 2.0], "collide": true,
       "contact": {"friction": 0.4, "restitution": 0.6}},
      {"name": "iso", "mesh": "iso", "render_mesh": "box", "scale": 1.0, "visible": true, "haptic": false,
       "dynamic": false, "pose": {"position": [0.0, 0.0, 0.0], "rotation": [1.0, 0.0, 0.0, 0.0]},
       "collide": true, "contact": {"friction": 0.5, "restitution": 0.0}},
      {"name": "tip", "mesh": "ball", "scale": 1.0, "visible": true, "haptic": false, "dynamic": false,
       "pose": {"position": [0.0, 0.0, 0.0], "rotation": [1.0, 0.0, 0.0, 0.0]}, "collide": false,
       "contact": {"friction": 0.5, "restitution": 0.0}}
    ],
    "volumes": [
      {"name": "ct_slice", "volume": "ct", "mode": "slice", "visible": false,
       "slice": {"axis": "sagittal", "position": -0.02},
       "transfer_function": {"points": [[-1000.0, 0.0, 0.0, 0.0, 0.0], [400.0, 1.0, 0.9, 0.8, 1.0]]}},
      {"name": "ct_mip", "volume": "ct", "mode": "mip", "visible": true}
    ],
    "lights": [
      {"type": "directional", "direction": [0.0, 0.6, -0.8], "color": [1.0, 0.9, 0.8], "intensity": 2.0,
       "shadows": true},
      {"type": "point", "position": [0.0, 0.0, 1.0], "range": 3.0, "color": [1.0, 1.0, 1.0], "intensity": 0.5,
       "shadows": false},
      {"type": "spot", "direction": [0.0, 0.0, -1.0], "position": [0.0, 0.0, 2.0], "range": 0.0,
       "inner_cone_deg": 10.0, "outer_cone_deg": 25.0, "color": [0.5, 0.5, 1.0], "intensity": 4.0,
       "shadows": true}
    ],
    "cameras": [
      {"name": "fly", "projection": "orthographic", "ortho_height": 0.4, "position": [1.0, 0.0, 0.0],
       "target": [0.0, 0.0, 0.0], "up": [0.0, 0.0, 1.0], "near": 0.05, "far": 20.0,
       "path": [{"t": 0.0, "position": [1.0, 0.0, 0.0], "target": [0.0, 0.0, 0.0]},
                {"t": 2.5, "position": [0.0, 1.0, 0.0], "target": [0.0, 0.0, 0.1]}],
       "stereo": {"eye_separation": 0.06, "convergence": 0.7}},
      {"name": "follow", "projection": "perspective", "fov_y_deg": 60.0, "position": [0.0, -1.0, 0.3],
       "target": [0.0, 0.0, 0.0], "up": [0.0, 0.0, 1.0], "near": 0.01, "far": 10.0, "track": "ball"}
    ],
    "devices": [
      {"name": "stylus", "driver": "replay-haptic", "config": {"file": "press.csv", "loop": true,
                                                               "offset": [0.0, 0.0, 0.01]}},
      {"name": "spare", "driver": "sim-haptic", "config": {},
       "serve": {"listen": "0.0.0.0:47000", "timeout": 0.25, "wave_impedance": 20.0}},
      {"name": "far", "driver": "net-haptic", "config": {"device": "@spare"}}
    ],
    "engines": {
      "haptics": {"rate_hz": 2000.0, "renderer": "sphere-tree", "device": "stylus", "objects": ["liver"],
                  "max_force": 5.0, "proxy_object": "tip",
                  "sphere_tree": {"tool": "ball", "levels": 5, "tool_levels": 4, "tool_level": 3, "stiffness": 800.0,
                                  "angular_stiffness": 0.5, "mass": 0.2, "inertia": 0.001, "max_constraints": 128,
                                  "solver_iterations": 40, "linearizations": 2, "margin_epsilon": 0.0002,
                                  "max_step": 0.01, "surface_tolerance": 0.2},
                  "device_pose": {"position": [0.1, 0.0, 0.0], "rotation": [0.0, 0.0, 0.0, 1.0]}},
      "physics": {"rate_hz": 500.0, "gravity": [0.0, -9.81, 0.0], "sleep": true},
      "render": {"rate_hz": 60.0, "camera": "follow", "width": 1920, "height": 1080, "samples": 4,
                 "hud": false, "inset": {"camera": "fly", "size": 0.25}},
      "monitor": {"rate_hz": 10.0},
      "igtl": {"rate_hz": 20.0, "listen": "0.0.0.0:18944", "allow": ["10.0.0.0/8"],
               "publish": {"tool": "Tool", "handle": "Handle", "force": "Force", "bodies": true, "image": "View"},
               "wait_for_clients": 2, "wait_timeout": 5.0},
      "vision": {"rate_hz": 12.0, "overlay": "view",
                 "graph": {"nodes": [{"name": "cam", "kind": "input"},
                                     {"name": "view", "kind": "texture", "input": "cam"}]}}
    },
    "outputs": {"directory": "results/run1", "frames": true, "frame_every": 5, "forces": true, "plot": false,
                "summary": false, "recording": true}
  })");
}

TEST(SceneFile, TheRenderEnginesInsetNamesACameraAndASize) {
  Json j = baseScene();
  j["version"] = 2;
  j["engines"]["render"]["inset"] = {{"camera", "main"}};
  auto s = dm::parseScene(j.dump(), "scene.json", "/data/scenes");
  ASSERT_TRUE(s) << s.error();
  EXPECT_EQ(s->engines.render->insetCamera, "main");
  EXPECT_EQ(s->engines.render->insetSize, 0.3);  // the default
  j["engines"]["render"]["inset"] = {{"camera", "mian"}, {"size", 0.95}, {"corner", "left"}};
  const std::vector<dm::Error> p = problemsOf(j);
  const dm::Error* e = at(p, "/engines/render/inset/camera");
  ASSERT_TRUE(e);
  EXPECT_EQ(e->hint, "did you mean \"main\"?");
  EXPECT_TRUE(at(p, "/engines/render/inset/size"));
  EXPECT_TRUE(at(p, "/engines/render/inset/corner"));
  EXPECT_EQ(p.size(), 3u) << dm::formatSceneErrors(p);
  j["version"] = 1;
  j["engines"]["render"]["inset"] = {{"camera", "main"}};
  const std::vector<dm::Error> v1 = problemsOf(j);
  e = at(v1, "/engines/render/inset");
  ASSERT_TRUE(e);
  EXPECT_NE(e->what.find("version-2"), std::string::npos) << e->what;
}

TEST(SceneFile, ToJsonWritesEveryKeyAndReadsBackEqual) {
  const Json full = fullScene();
  std::vector<dm::Error> problems;
  auto a = dm::parseScene(full.dump(), "full.json", "/data/scenes", &problems);
  ASSERT_TRUE(a) << dm::formatSceneErrors(problems);
  EXPECT_EQ(dm::toJson(*a), full) << dm::toJson(*a).dump(1);
  auto b = dm::parseScene(dm::toJson(*a).dump(), "written.json", "/data/scenes");
  ASSERT_TRUE(b) << b.error();
  EXPECT_TRUE(*a == *b);

  // Spot checks that values reached the right fields.
  EXPECT_EQ(a->resource("liver")->path, fs::path("/data/scenes/meshes/liver.stl"));
  EXPECT_EQ(a->resource("ct")->path, fs::path("/data/scenes/ct/ct.nii.gz"));
  EXPECT_EQ(a->resource("floor")->halfExtents, dm::Vec3(1.0, 2.0, 0.0));
  EXPECT_EQ(a->camera("fly")->path.size(), 2u);
  EXPECT_TRUE(a->camera("fly")->stereo);
  EXPECT_EQ(a->volume("ct_slice")->sliceAxis, dm::SceneVolume::Axis::Sagittal);
  EXPECT_EQ(a->engines.physics->gravity, dm::Vec3(0.0, -9.81, 0.0));
  EXPECT_EQ(dm::deviceParams(*a->device("stylus")),
            (std::vector<std::pair<std::string, std::string>>{
                {"file", "/data/scenes/press.csv"}, {"loop", "1"}, {"offset", "0.0,0.0,0.01"}}));
  ASSERT_TRUE(a->device("spare")->serve);
  EXPECT_EQ(a->device("spare")->serve->listen, "0.0.0.0:47000");
  EXPECT_EQ(a->device("spare")->serve->waveImpedance, 20.0);
  EXPECT_FALSE(a->device("stylus")->serve);
  // A change anywhere is visible to ==.
  dm::SceneDesc c = *b;
  c.objects[0].pose.q = dm::Quat(0.0, 0.8, 0.6, 0.0);
  EXPECT_FALSE(c == *a);
}

TEST(SceneFile, BundledSceneRoundTrips) {
  for (const char* name : {"head_probe.json", "head_probe_teleop.json", "box_push.json", "burr_hole.json",
                           "burr_hole_ct.json", "tooth_cavity.json", "tissue_indentation.json"}) {
    auto a = dm::readScene(sourceDir() / "examples/scenes" / name);
    ASSERT_TRUE(a) << a.error();
    auto b = dm::parseScene(dm::toJson(*a).dump(2), "written.json", a->baseDir);
    ASSERT_TRUE(b) << b.error();
    EXPECT_TRUE(*a == *b) << name;
  }
  // Euler angles and non-unit directions are written in their normalised form and stay put.
  Json j = baseScene();
  j["objects"][0]["pose"] = {{"euler_deg", {10, 20, 30}}};
  j["lights"][0]["direction"] = {1, 2, -3};
  auto c = dm::parseScene(j.dump(), "scene.json", "/data/scenes");
  ASSERT_TRUE(c) << c.error();
  auto d = dm::parseScene(dm::toJson(*c).dump(), "scene.json", "/data/scenes");
  ASSERT_TRUE(d) << d.error();
  EXPECT_TRUE(*c == *d);
}

TEST(SceneFile, DeviceFilesResolveLikeSourcesAndStayConfined) {
  // A driver's "file" (a path to follow, a recording to replay) is relative
  // to the scene and confined like a resource's source; the driver gets the
  // resolved path, the scene keeps what was written.
  Json j = baseScene();
  j["devices"][0]["config"] = {{"path", "csv"}, {"file", "paths/push.csv"}, {"loop", 0}};
  auto s = dm::parseScene(j.dump(), "scene.json", "/data/scenes");
  ASSERT_TRUE(s) << s.error();
  const dm::SceneDevice& hand = *s->device("hand");
  EXPECT_EQ(hand.config["file"], "paths/push.csv");
  const auto params = dm::deviceParams(hand);
  const auto file =
      std::find_if(params.begin(), params.end(), [](const auto& p) { return p.first == "file"; });
  ASSERT_NE(file, params.end());
  EXPECT_EQ(file->second, "/data/scenes/paths/push.csv");
  EXPECT_EQ(dm::parseScene(dm::toJson(*s).dump(), "scene.json", "/data/scenes").value(), *s);

  j["devices"][0]["config"]["file"] = "../../etc/passwd";
  const auto p = problemsOf(j);
  ASSERT_EQ(p.size(), 1u) << dm::formatSceneErrors(p);
  const dm::Error* e = at(p, "/devices/0/config/file");
  ASSERT_TRUE(e);
  EXPECT_NE(e->hint.find("DM_ALLOW_PATH"), std::string::npos) << e->hint;
}

TEST(SceneFile, SourcesResolveAgainstTheSceneDirectory) {
  Json j = baseScene();
  j["resources"]["a"] = {{"type", "mesh"}, {"source", "meshes/tool.stl"}};
  j["resources"]["b"] = {{"type", "mesh"}, {"source", "./meshes/../b.obj"}, {"unit", "mm"}};
  j["resources"]["c"] = {{"type", "volume"}, {"source", "/data/scenes/volumes/c.nrrd"}};
  auto s = dm::parseScene(j.dump(), "scene.json", "/data/scenes");
  ASSERT_TRUE(s) << s.error();
  EXPECT_EQ(s->resource("a")->source, "meshes/tool.stl");
  EXPECT_EQ(s->resource("a")->path, fs::path("/data/scenes/meshes/tool.stl"));
  EXPECT_EQ(s->resource("b")->path, fs::path("/data/scenes/b.obj"));
  EXPECT_EQ(s->resource("b")->unit, "mm");
  EXPECT_EQ(s->resource("c")->path, fs::path("/data/scenes/volumes/c.nrrd"));

  // Outside the scene's folder (and the mounts, DM_DATA_PATH and the allowed
  // roots) a source is refused (FileSystem::confine); an allowed root lets it in.
  j["resources"]["b"]["source"] = "../shared/./b.obj";
  j["resources"]["c"]["source"] = "/abs/c.nrrd";
  {
    const auto refused = problemsOf(j);
    ASSERT_EQ(refused.size(), 2u) << dm::formatSceneErrors(refused);
    for (const char* key : {"/resources/b/source", "/resources/c/source"}) {
      const dm::Error* e = at(refused, key);
      ASSERT_TRUE(e) << key;
      EXPECT_NE(e->what.find("outside the allowed folders"), std::string::npos) << e->what;
      EXPECT_NE(e->hint.find("DM_ALLOW_PATH"), std::string::npos) << e->hint;
    }
  }
  dm::FileSystem::global().allowRoot("/data/shared");
  dm::FileSystem::global().allowRoot("/abs");
  s = dm::parseScene(j.dump(), "scene.json", "/data/scenes");
  dm::FileSystem::global().disallowRoot("/data/shared");
  dm::FileSystem::global().disallowRoot("/abs");
  ASSERT_TRUE(s) << s.error();
  EXPECT_EQ(s->resource("b")->path, fs::path("/data/shared/b.obj"));
  EXPECT_EQ(s->resource("c")->path, fs::path("/abs/c.nrrd"));
  j["resources"]["b"]["source"] = "./meshes/../b.obj";
  j["resources"]["c"]["source"] = "/data/scenes/volumes/c.nrrd";

  // An unknown mount is an error now; an unknown unit too.
  j["resources"]["a"]["source"] = "nosuch:tool.stl";
  j["resources"]["b"]["unit"] = "furlong";
  const auto p = problemsOf(j);
  ASSERT_EQ(p.size(), 2u) << dm::formatSceneErrors(p);
  const dm::Error* e = at(p, "/resources/a/source");
  ASSERT_TRUE(e);
  EXPECT_EQ(e->what, "unknown mount 'nosuch:'");
  EXPECT_NE(e->hint.find("mricron:"), std::string::npos) << e->hint;
  ASSERT_TRUE(at(p, "/resources/b/unit"));

  // readScene resolves against the file's own directory.
  const fs::path dir = fs::temp_directory_path() / ("dm_scene_test_" + std::to_string(::getpid()));
  fs::create_directories(dir / "sub");
  j = baseScene();
  { std::ofstream(dir / "sub" / "scene.json") << j.dump(2); }
  auto r = dm::readScene(dir / "sub" / "scene.json");
  ASSERT_TRUE(r) << r.error();
  EXPECT_EQ(r->resource("bump")->path, dir / "sub" / "bump.png");
  // A scene file is at most 16 MiB of JSON: one larger is refused from its
  // size, naming it and the limit, before it is read.
  fs::resize_file(dir / "sub" / "scene.json", (std::uintmax_t{16} << 20) + 1);
  auto huge = dm::readScene(dir / "sub" / "scene.json");
  ASSERT_FALSE(huge);
  EXPECT_NE(huge.error().what.find("file is 16777217 bytes, more than the limit of 16777216 bytes"),
            std::string::npos)
      << huge.error();
  EXPECT_NE(huge.error().hint.find("at most 16 MiB"), std::string::npos) << huge.error();
  fs::remove_all(dir);
  auto missing = dm::readScene(dir / "nothing.json");
  ASSERT_FALSE(missing);
  EXPECT_EQ(missing.error().code, dm::ErrorCode::NotFound);
}

// A compound shape's parts: 1 to 64 primitives (no plane, no compound),
// each with its own size keys and no other's, and a version-2 key.
TEST(SceneFile, CompoundShapePartsAreCheckedAtTheirPaths) {
  Json j = Json::parse(R"({
    "format": "dmplatform-scene", "version": 2, "name": "c",
    "resources": {"c": {"type": "shape", "shape": "compound", "parts": [
      {"shape": "plane", "half_extents": [1, 1]},
      {"shape": "box", "radius": 0.1, "half_extents": [0.1, 0.1, 0.1]},
      {"shape": "cylinder", "radius": 0.1},
      {"shape": "sphere", "radius": 0.1, "pose": {"position": [0, 0]}},
      {"shape": "sphere", "radius": 0.1, "color": 3}
    ]}},
    "objects": [{"name": "c", "mesh": "c"}]
  })");
  const auto p = problemsOf(j);
  expectAt(p, "/resources/c/parts/0/shape", "\"plane\"");
  expectAt(p, "/resources/c/parts/1/radius", "no \"radius\"");
  EXPECT_TRUE(at(p, "/resources/c/parts/2/height"));
  EXPECT_TRUE(at(p, "/resources/c/parts/3/pose/position"));
  EXPECT_TRUE(at(p, "/resources/c/parts/4/color"));
  Json none = j;
  none["resources"]["c"]["parts"] = Json::array();
  expectAt(problemsOf(none), "/resources/c/parts", "1 to 64");
  Json missing = j;
  missing["resources"]["c"].erase("parts");
  expectAt(problemsOf(missing), "/resources/c/parts", "needs its parts");
  Json v1 = j;
  v1["version"] = 1;
  v1["resources"]["c"]["parts"] = Json::array({{{"shape", "sphere"}, {"radius", 0.1}}});
  expectAt(problemsOf(v1), "/resources/c/parts", "version-2");
}

}  // namespace

// The nesting budget: 64 levels. A 65th bracket is refused at its byte
// before the JSON parser sees the text (so no recursive walk can run out of
// stack); brackets inside strings do not count.
TEST(SceneFile, NestingDeeperThanSixtyFourLevelsIsRefusedAtItsByte) {
  const std::string deep = "{\"a\": " + std::string(64, '[') + std::string(64, ']') + "}";
  auto refused = dm::parseScene(deep, "deep.json", "/data/scenes");
  ASSERT_FALSE(refused);
  EXPECT_EQ(refused.error().code, dm::ErrorCode::Parse);
  EXPECT_EQ(refused.error().where, "deep.json: byte 70");  // "{" then 64 "[" after `{"a": `
  EXPECT_NE(refused.error().what.find("nested deeper than 64 levels"), std::string::npos) << refused.error();

  // 64 levels pass the budget (and fail later, as a scene, for their content).
  const std::string deepest = "{\"a\": " + std::string(63, '[') + std::string(63, ']') + "}";
  auto parsed = dm::parseScene(deepest, "ok.json", "/data/scenes");
  ASSERT_FALSE(parsed);
  EXPECT_EQ(parsed.error().what.find("nested deeper"), std::string::npos) << parsed.error();
  const std::string quoted = "{\"a\": \"" + std::string(100, '[') + "\"}";
  auto inString = dm::parseScene(quoted, "s.json", "/data/scenes");
  ASSERT_FALSE(inString);
  EXPECT_EQ(inString.error().what.find("nested deeper"), std::string::npos) << inString.error();
}
