// The scene file's surgical keys (docs/scene-format.md, "Bone surgery"):
// a millable bone, critical structures, the burr renderer's tool and a
// generated CT phantom read and written back; every misuse is an error at
// its JSON pointer.
#include <dm/io/scene_file.hpp>

#include <gtest/gtest.h>

#include "scene_test_support.hpp"

namespace scene_surgery_test {

using dm::Json;
using namespace scene_test;

// A bone plate with a nerve under it, milled by a cylinder burr.
Json burrScene() {
  return Json::parse(R"({
    "format": "dmplatform-scene", "version": 2, "name": "drill",
    "resources": {
      "plate": {"type": "shape", "shape": "box", "half_extents": [0.01, 0.01, 0.003]},
      "nerve": {"type": "shape", "shape": "cylinder", "radius": 0.001, "height": 0.02}
    },
    "materials": {"bone": {"model": "blinn-phong", "haptic": {"stiffness": 1500, "damping": 0.4}}},
    "objects": [
      {"name": "skull", "mesh": "plate", "material": "bone", "haptic": true,
       "millable": {"voxel_size": 0.0002, "hardness": 3e8}},
      {"name": "nerve", "mesh": "nerve", "critical": {"hardness": 2e7}},
      {"name": "marrow", "mesh": "plate", "scale": 0.5, "inclusion": {"hardness": 1e8}}
    ],
    "devices": [{"name": "hand", "driver": "sim-haptic", "config": {"path": "circle"}}],
    "engines": {
      "haptics": {"device": "hand", "renderer": "burr", "objects": ["skull"],
                  "burr": {"shape": "cylinder", "radius": 0.002, "half_length": 0.004, "rpm": 60000,
                           "wear": 0.2, "walk": 0.1, "vibration": 0.02, "vibration_hz": 120,
                           "warning_distance": 0.0015}}
    }
  })");
}

TEST(SceneSurgery, KeysReadAndWriteBackEqual) {
  auto s = dm::parseScene(burrScene().dump(), "scene.json", "/data/scenes");
  ASSERT_TRUE(s) << s.error();
  const dm::SceneObject& skull = s->objects[0];
  ASSERT_TRUE(skull.millable);
  EXPECT_EQ(skull.millable->voxelSize, 0.0002);
  EXPECT_EQ(skull.millable->hardness, 3e8);
  ASSERT_TRUE(s->objects[1].critical);
  EXPECT_EQ(s->objects[1].critical->hardness, 2e7);
  ASSERT_TRUE(s->objects[2].inclusion);
  EXPECT_EQ(s->objects[2].inclusion->hardness, 1e8);
  const auto& h = *s->engines.haptics;
  EXPECT_EQ(h.renderer, dm::SceneHapticsEngine::Renderer::Burr);
  ASSERT_TRUE(h.burr);
  EXPECT_EQ(h.burr->shape, dm::SceneBurr::Shape::Cylinder);
  EXPECT_EQ(h.burr->radius, 0.002);
  EXPECT_EQ(h.burr->halfLength, 0.004);
  EXPECT_EQ(h.burr->rpm, 60000);
  EXPECT_EQ(h.burr->wear, 0.2);
  EXPECT_EQ(h.burr->walk, 0.1);
  EXPECT_EQ(h.burr->vibration, 0.02);
  EXPECT_EQ(h.burr->vibrationHz, 120);
  EXPECT_EQ(h.burr->warningDistance, 0.0015);
  auto back = dm::parseScene(dm::toJson(*s).dump(), "scene.json", "/data/scenes");
  ASSERT_TRUE(back) << back.error();
  EXPECT_TRUE(*s == *back);
  // Defaults: a sphere burr at 80 000 rpm, cortical hardness.
  Json j = burrScene();
  j["objects"][0]["millable"].erase("hardness");
  j["engines"]["haptics"]["burr"] = {{"radius", 0.002}};
  auto d = dm::parseScene(j.dump(), "scene.json", "/data/scenes");
  ASSERT_TRUE(d) << d.error();
  EXPECT_EQ(d->objects[0].millable->hardness, 0.5e9);
  EXPECT_EQ(d->engines.haptics->burr->shape, dm::SceneBurr::Shape::Sphere);
  EXPECT_EQ(d->engines.haptics->burr->rpm, 80000);
}

// The bone from a CT volume's intensities instead of a voxelized mesh.
Json ctScene() {
  Json j = burrScene();
  j["resources"]["ct"] = {{"type", "volume"}, {"source", "head_ct.nrrd"}};
  j["objects"][0]["millable"] = {{"volume", "ct"}, {"empty", 100}, {"full", 1500}, {"hardness", 4e8}};
  return j;
}

TEST(SceneSurgery, ABoneFromACtVolumeReadsAndWritesBack) {
  auto s = dm::parseScene(ctScene().dump(), "scene.json", "/data/scenes");
  ASSERT_TRUE(s) << s.error();
  const dm::SceneMillable& m = *s->objects[0].millable;
  EXPECT_EQ(m.volume, "ct");
  EXPECT_EQ(m.empty, 100);
  EXPECT_EQ(m.full, 1500);
  EXPECT_EQ(m.hardness, 4e8);
  EXPECT_EQ(m.voxelSize, 0.0);
  const Json back = dm::toJson(*s);
  EXPECT_FALSE(back["objects"][0]["millable"].contains("voxel_size"));
  auto again = dm::parseScene(back.dump(), "scene.json", "/data/scenes");
  ASSERT_TRUE(again) << again.error();
  EXPECT_TRUE(*s == *again);
}

// The CT generated instead of read: a calvarium phantom.
Json phantomScene() {
  Json j = ctScene();
  j["resources"]["ct"] = Json::parse(R"({"type": "volume", "phantom": {
      "kind": "calvarium", "spacing": 0.0004, "half_width": 0.01, "radius": 0.08, "diploe": 0.003,
      "texture_hu": 0, "seed": 7, "hu": {"air": -900, "cortical": 1600}}})");
  return j;
}

TEST(SceneSurgery, AGeneratedPhantomReadsAndWritesBack) {
  auto s = dm::parseScene(phantomScene().dump(), "scene.json", "/data/scenes");
  ASSERT_TRUE(s) << s.error();
  const dm::SceneResource* ct = s->resource("ct");
  ASSERT_TRUE(ct != nullptr && ct->phantom.has_value());
  EXPECT_TRUE(ct->source.empty());
  dm::CalvariumPhantom want;  // the defaults, but for the keys given
  want.spacing = 0.0004;
  want.halfWidth = 0.01;
  want.radius = 0.08;
  want.diploe = 0.003;
  want.textureHu = 0;
  want.seed = 7;
  want.airHu = -900;
  want.corticalHu = 1600;
  EXPECT_TRUE(*ct->phantom == want);
  const Json back = dm::toJson(*s);
  EXPECT_FALSE(back["resources"]["ct"].contains("source"));
  auto again = dm::parseScene(back.dump(), "scene.json", "/data/scenes");
  ASSERT_TRUE(again) << again.error();
  EXPECT_TRUE(*s == *again);
}

TEST(SceneSurgery, EveryMisuseIsNamed) {
  struct Case {
    const char* what;
    std::function<void(Json&)> edit;
    const char* pointer;
  };
  const std::vector<Case> cases{
      {"millable in a version-1 file",
       [](Json& j) {
         j["version"] = 1;
         j["objects"][1].erase("critical");
         j["engines"]["haptics"].erase("burr");
         j["engines"]["haptics"]["renderer"] = "god-object";
       },
       "/objects/0/millable"},
      {"a sphere burr has no half length",
       [](Json& j) { j["engines"]["haptics"]["burr"]["shape"] = "sphere"; },
       "/engines/haptics/burr/half_length"},
      {"a cylinder burr needs its half length",
       [](Json& j) { j["engines"]["haptics"]["burr"].erase("half_length"); },
       "/engines/haptics/burr/half_length"},
      {"an unknown burr shape", [](Json& j) { j["engines"]["haptics"]["burr"]["shape"] = "cone"; },
       "/engines/haptics/burr/shape"},
      {"vibration at the loop's Nyquist rate",
       [](Json& j) { j["engines"]["haptics"]["burr"]["vibration_hz"] = 500; },
       "/engines/haptics/burr/vibration_hz"},
      {"a zero voxel size", [](Json& j) { j["objects"][0]["millable"]["voxel_size"] = 0; },
       "/objects/0/millable/voxel_size"},
      {"an unknown millable key", [](Json& j) { j["objects"][0]["millable"]["density"] = 1900; },
       "/objects/0/millable/density"},
      {"the burr renderer without its tool", [](Json& j) { j["engines"]["haptics"].erase("burr"); },
       "/engines/haptics/burr"},
      {"a tool radius besides the burr", [](Json& j) { j["engines"]["haptics"]["tool_radius"] = 0.001; },
       "/engines/haptics/tool_radius"},
      {"force shading on voxels", [](Json& j) { j["engines"]["haptics"]["force_shading"] = true; },
       "/engines/haptics/force_shading"},
      {"a burr block for the god-object",
       [](Json& j) {
         j["engines"]["haptics"]["renderer"] = "god-object";
         j["objects"][0].erase("millable");
         j["objects"][1].erase("critical");
       },
       "/engines/haptics/burr"},
      {"a millable object nobody mills",
       [](Json& j) {
         j["engines"]["haptics"]["renderer"] = "god-object";
         j["engines"]["haptics"].erase("burr");
         j["objects"][1].erase("critical");
       },
       "/objects/0/millable"},
      {"a critical structure without the burr",
       [](Json& j) {
         j["engines"]["haptics"]["renderer"] = "god-object";
         j["engines"]["haptics"].erase("burr");
         j["objects"][0].erase("millable");
       },
       "/objects/1/critical"},
      {"friction the burr cannot render",
       [](Json& j) { j["materials"]["bone"]["haptic"]["static_friction"] = 0.3; }, "/objects/0/material"},
      {"bone and critical at once", [](Json& j) { j["objects"][0]["critical"] = Json::object(); },
       "/objects/0/critical"},
      {"bone and inclusion at once", [](Json& j) { j["objects"][0]["inclusion"] = Json::object(); },
       "/objects/0/inclusion"},
      {"critical and inclusion at once", [](Json& j) { j["objects"][1]["inclusion"] = Json::object(); },
       "/objects/1/inclusion"},
      {"an inclusion without the burr",
       [](Json& j) {
         j["engines"]["haptics"]["renderer"] = "god-object";
         j["engines"]["haptics"].erase("burr");
         j["objects"][0].erase("millable");
         j["objects"][1].erase("critical");
       },
       "/objects/2/inclusion"},
      {"an inclusion in a version-1 file",
       [](Json& j) {
         j["version"] = 1;
         j["objects"][0].erase("millable");
         j["objects"][1].erase("critical");
         j["engines"]["haptics"].erase("burr");
         j["engines"]["haptics"]["renderer"] = "god-object";
       },
       "/objects/2/inclusion"},
      {"a moving bone",
       [](Json& j) {
         j["objects"][0]["dynamic"] = true;
         j["objects"][0]["mass"] = 0.1;
         j["engines"]["physics"] = Json::object();
       },
       "/objects/0/dynamic"},
  };
  for (const Case& c : cases) {
    Json j = burrScene();
    c.edit(j);
    const auto p = problemsOf(j);
    const dm::Error* e = at(p, c.pointer);
    EXPECT_TRUE(e != nullptr) << c.what;
  }
  // A bone from a CT volume: the intensity ramp instead of a voxel size.
  const std::vector<Case> ctCases{
      {"a voxel size besides the volume", [](Json& j) { j["objects"][0]["millable"]["voxel_size"] = 2e-4; },
       "/objects/0/millable/voxel_size"},
      {"no intensity of no bone", [](Json& j) { j["objects"][0]["millable"].erase("empty"); },
       "/objects/0/millable/empty"},
      {"full not above empty", [](Json& j) { j["objects"][0]["millable"]["full"] = 100; },
       "/objects/0/millable/full"},
      {"empty and full without a volume",
       [](Json& j) {
         j["objects"][0]["millable"].erase("volume");
         j["objects"][0]["millable"]["voxel_size"] = 2e-4;
       },
       "/objects/0/millable/empty"},
      {"an empty volume name", [](Json& j) { j["objects"][0]["millable"]["volume"] = ""; },
       "/objects/0/millable/volume"},
      {"an undefined volume", [](Json& j) { j["objects"][0]["millable"]["volume"] = "mri"; },
       "/objects/0/millable/volume"},
      {"a mesh for a volume", [](Json& j) { j["objects"][0]["millable"]["volume"] = "plate"; },
       "/objects/0/millable/volume"},
      {"a scaled CT", [](Json& j) { j["objects"][0]["scale"] = 2.0; }, "/objects/0/scale"},
  };
  for (const Case& c : ctCases) {
    Json j = ctScene();
    c.edit(j);
    EXPECT_TRUE(at(problemsOf(j), c.pointer) != nullptr) << c.what;
  }
  // A generated CT: every key checked, the phantom's own checks at the key
  // the file wrote.
  const std::vector<Case> phantomCases{
      {"a source besides the phantom", [](Json& j) { j["resources"]["ct"]["source"] = "ct.nrrd"; },
       "/resources/ct/source"},
      {"a phantom in a version-1 file", [](Json& j) { j["version"] = 1; }, "/resources/ct/phantom"},
      {"an unknown kind", [](Json& j) { j["resources"]["ct"]["phantom"]["kind"] = "femur"; },
       "/resources/ct/phantom/kind"},
      {"no kind", [](Json& j) { j["resources"]["ct"]["phantom"].erase("kind"); },
       "/resources/ct/phantom/kind"},
      {"an unknown key", [](Json& j) { j["resources"]["ct"]["phantom"]["noise_hu"] = 10; },
       "/resources/ct/phantom/noise_hu"},
      {"an unknown tissue", [](Json& j) { j["resources"]["ct"]["phantom"]["hu"]["fat"] = -100; },
       "/resources/ct/phantom/hu/fat"},
      {"a zero spacing", [](Json& j) { j["resources"]["ct"]["phantom"]["spacing"] = 0; },
       "/resources/ct/phantom/spacing"},
      {"a negative diploë", [](Json& j) { j["resources"]["ct"]["phantom"]["diploe"] = -0.001; },
       "/resources/ct/phantom/diploe"},
      {"no outer table", [](Json& j) { j["resources"]["ct"]["phantom"]["outer_table"] = 0; },
       "/resources/ct/phantom/outer_table"},
      {"a vault flatter than the patch is wide",
       [](Json& j) { j["resources"]["ct"]["phantom"]["radius"] = 0.005; }, "/resources/ct/phantom/radius"},
      {"a value no int16 holds", [](Json& j) { j["resources"]["ct"]["phantom"]["hu"]["cortical"] = 40000; },
       "/resources/ct/phantom/hu/cortical"},
      {"a negative seed", [](Json& j) { j["resources"]["ct"]["phantom"]["seed"] = -1; },
       "/resources/ct/phantom/seed"},
      {"a scan too large to generate",
       [](Json& j) {
         j["resources"]["ct"]["phantom"]["spacing"] = 2e-5;
         j["resources"]["ct"]["phantom"]["half_width"] = 0.05;
       },
       "/resources/ct/phantom/spacing"},
  };
  for (const Case& c : phantomCases) {
    Json j = phantomScene();
    c.edit(j);
    EXPECT_TRUE(at(problemsOf(j), c.pointer) != nullptr) << c.what;
  }
  // Two millable objects for one burr: the renderer mills one.
  Json j = burrScene();
  j["objects"][1] = {{"name", "jaw"},
                     {"mesh", "plate"},
                     {"material", "bone"},
                     {"haptic", true},
                     {"millable", {{"voxel_size", 0.0002}}}};
  j["engines"]["haptics"]["objects"] = {"skull", "jaw"};
  EXPECT_TRUE(at(problemsOf(j), "/engines/haptics/objects") != nullptr);
}

}  // namespace scene_surgery_test
