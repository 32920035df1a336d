// The scene file's soft tissue (docs/scene-format.md, "Soft tissue"): an
// object's "soft" block read and written back with its defaults, and every
// misuse — a bad value, a face that is not one, a soft object the engines
// cannot deform, keys that contradict it — an error at its JSON pointer.
#include <dm/io/scene_file.hpp>

#include <gtest/gtest.h>

#include "scene_test_support.hpp"

namespace scene_soft_test {

using dm::Json;
using namespace scene_test;

// A pad of tissue on a table, pressed by the god-object.
Json padScene() {
  return Json::parse(R"({
    "format": "dmplatform-scene", "version": 2, "name": "press",
    "resources": {
      "table": {"type": "shape", "shape": "plane", "half_extents": [0.1, 0.1]},
      "pad": {"type": "shape", "shape": "box", "half_extents": [0.03, 0.03, 0.01]},
      "tip": {"type": "shape", "shape": "sphere", "radius": 0.002}
    },
    "materials": {"tissue": {"model": "blinn-phong", "haptic": {"stiffness": 500}}},
    "objects": [
      {"name": "table", "mesh": "table"},
      {"name": "pad", "mesh": "pad", "material": "tissue", "haptic": true,
       "soft": {"youngs_modulus": 2e4, "poisson_ratio": 0.4, "density": 1050,
                "damping": {"alpha": 2, "beta": 0.01}, "voxel_size": 0.004, "fixed": ["-z", "+x"],
                "max_tets": 50000, "contact_stiffness": 3000, "contact_friction": 0.4}},
      {"name": "tool", "mesh": "tip"}
    ],
    "devices": [{"name": "hand", "driver": "sim-haptic", "config": {"path": "point"}}],
    "engines": {
      "haptics": {"device": "hand", "objects": ["pad"], "tool_radius": 0.002, "proxy_object": "tool"},
      "physics": {"rate_hz": 100}
    }
  })");
}

TEST(SceneSoft, KeysReadAndWriteBackEqual) {
  auto s = dm::parseScene(padScene().dump(), "scene.json", "/data/scenes");
  ASSERT_TRUE(s) << s.error();
  const dm::SceneObject& pad = s->objects[1];
  ASSERT_TRUE(pad.soft);
  EXPECT_EQ(pad.soft->youngsModulus, 2e4);
  EXPECT_EQ(pad.soft->poissonRatio, 0.4);
  EXPECT_EQ(pad.soft->density, 1050);
  EXPECT_EQ(pad.soft->alpha, 2);
  EXPECT_EQ(pad.soft->beta, 0.01);
  EXPECT_EQ(pad.soft->voxelSize, 0.004);
  EXPECT_EQ(pad.soft->fixedFaces, (1u << 4) | (1u << 1));  // "-z" and "+x"
  EXPECT_EQ(pad.soft->maxTets, 50000u);
  EXPECT_EQ(pad.soft->contactStiffness, 3000);
  EXPECT_EQ(pad.soft->contactFriction, 0.4);
  EXPECT_FALSE(pad.collide) << "soft objects take part in no rigid contact";
  const Json back = dm::toJson(*s);
  EXPECT_FALSE(back["objects"][1].contains("contact"));
  EXPECT_EQ(back["objects"][1]["soft"]["fixed"], Json::parse(R"(["+x", "-z"])"));
  auto again = dm::parseScene(back.dump(), "scene.json", "/data/scenes");
  ASSERT_TRUE(again) << again.error();
  EXPECT_TRUE(*s == *again);
  // Defaults: ν 0.45, water's density, no damping, nothing held.
  Json j = padScene();
  j["objects"][1]["soft"] = {{"youngs_modulus", 5000}, {"voxel_size", 0.005}};
  auto d = dm::parseScene(j.dump(), "scene.json", "/data/scenes");
  ASSERT_TRUE(d) << d.error();
  const dm::SceneSoft& soft = *d->objects[1].soft;
  EXPECT_EQ(soft.poissonRatio, 0.45);
  EXPECT_EQ(soft.density, 1000);
  EXPECT_EQ(soft.alpha, 0);
  EXPECT_EQ(soft.beta, 0);
  EXPECT_EQ(soft.fixedFaces, 0);
  EXPECT_EQ(soft.maxTets, 100000u);
  EXPECT_EQ(soft.contactStiffness, 0) << "not given: from E and the voxel size";
  EXPECT_EQ(soft.contactFriction, 0) << "not given: frictionless";
}

TEST(SceneSoft, BadValuesAreErrorsAtTheirKeys) {
  Json j = padScene();
  Json& soft = j["objects"][1]["soft"];
  soft["youngs_modulus"] = 0;
  soft["poisson_ratio"] = 0.5;
  soft["damping"] = {{"alpha", -1}, {"gamma", 1}};
  soft["voxel_size"] = 0.2;
  soft["fixed"] = Json::parse(R"(["-z", "bottom", 3, "-z"])");
  soft["max_tets"] = 10.5;
  soft["stiffness"] = 1;
  soft["contact_stiffness"] = -5;
  soft["contact_friction"] = -0.1;
  const auto problems = problemsOf(j);
  const std::string p = "/objects/1/soft";
  EXPECT_TRUE(at(problems, p + "/youngs_modulus"));
  if (const dm::Error* e = at(problems, p + "/poisson_ratio")) {
    EXPECT_NE(e->what.find("incompressible"), std::string::npos);
  }
  EXPECT_TRUE(at(problems, p + "/damping/alpha"));
  EXPECT_TRUE(at(problems, p + "/damping/gamma"));
  EXPECT_TRUE(at(problems, p + "/voxel_size"));
  if (const dm::Error* e = at(problems, p + "/fixed/1")) {
    EXPECT_NE(e->what.find("\"bottom\""), std::string::npos);
  }
  EXPECT_TRUE(at(problems, p + "/fixed/2"));
  if (const dm::Error* e = at(problems, p + "/fixed/3")) {
    EXPECT_NE(e->what.find("twice"), std::string::npos);
  }
  EXPECT_TRUE(at(problems, p + "/max_tets"));
  EXPECT_TRUE(at(problems, p + "/stiffness"));
  EXPECT_TRUE(at(problems, p + "/contact_stiffness"));
  EXPECT_TRUE(at(problems, p + "/contact_friction"));
  // A version-1 file has no soft tissue.
  Json v1 = padScene();
  v1["version"] = 1;
  v1["objects"][1].erase("soft");
  v1["objects"][1]["soft"] = {{"youngs_modulus", 5000}, {"voxel_size", 0.005}};
  const auto v1Problems = problemsOf(v1);
  EXPECT_TRUE(at(v1Problems, "/objects/1/soft"));
}

TEST(SceneSoft, ASoftObjectTheEnginesCannotDeformIsAnError) {
  {  // no physics engine
    Json j = padScene();
    j["engines"].erase("physics");
    const auto found1 = problemsOf(j);
    if (const dm::Error* e = at(found1, "/objects/1/soft")) {
      EXPECT_NE(e->what.find("no physics engine"), std::string::npos) << e->what;
    }
  }
  {  // rigid keys on tissue
    Json j = padScene();
    j["objects"][1]["dynamic"] = true;
    j["objects"][1]["mass"] = 0.1;
    j["objects"][1]["collide"] = true;
    j["objects"][1]["contact"] = {{"friction", 0.2}};
    const auto problems = problemsOf(j);
    EXPECT_TRUE(at(problems, "/objects/1/dynamic"));
    EXPECT_TRUE(at(problems, "/objects/1/collide"));
    EXPECT_TRUE(at(problems, "/objects/1/contact"));
  }
  {  // a dynamic body elsewhere meets the tissue (two-way): no problem
    Json j = padScene();
    j["resources"]["box"] = {{"type", "shape"}, {"shape", "box"}, {"half_extents", {0.01, 0.01, 0.01}}};
    j["objects"].push_back({{"name", "box"}, {"mesh", "box"}, {"dynamic", true}, {"mass", 0.1}});
    auto s = parsed(j);
    ASSERT_TRUE(s);
    EXPECT_TRUE(s->objects[3].dynamic);
  }
  {  // drawn by another object too, a render mesh, a plane
    Json j = padScene();
    j["objects"].push_back({{"name", "copy"}, {"mesh", "pad"}});
    j["objects"][1]["render_mesh"] = "tip";
    const auto problems = problemsOf(j);
    if (const dm::Error* e = at(problems, "/objects/1/mesh")) {
      EXPECT_NE(e->what.find("\"copy\""), std::string::npos) << e->what;
    }
    EXPECT_TRUE(at(problems, "/objects/1/render_mesh"));
    Json plane = padScene();
    plane["objects"][1]["mesh"] = "table";
    plane["objects"][0]["mesh"] = "pad";
    const auto found3 = problemsOf(plane);
    if (const dm::Error* e = at(found3, "/objects/1/mesh")) {
      EXPECT_NE(e->what.find("plane"), std::string::npos) << e->what;
    }
  }
  {  // the tool's picture, and a renderer that does not press tissue
    Json j = padScene();
    j["objects"][2]["soft"] = {{"youngs_modulus", 5000}, {"voxel_size", 0.001}};
    const auto found4 = problemsOf(j);
    if (const dm::Error* e = at(found4, "/objects/2/soft")) {
      EXPECT_NE(e->what.find("proxy"), std::string::npos) << e->what;
    }
    Json vps = padScene();
    vps["engines"]["haptics"]["renderer"] = "vps";
    vps["engines"]["haptics"].erase("proxy_object");
    vps["engines"]["haptics"].erase("tool_radius");
    const auto found5 = problemsOf(vps);
    if (const dm::Error* e = at(found5, "/objects/1/soft")) {
      EXPECT_NE(e->what.find("god-object"), std::string::npos) << e->what;
    }
  }
}

TEST(SceneSoft, PhysicsWithOnlySoftObjectsHasSomethingToMove) {
  // The physics engine needs something to move: a soft object is enough,
  // a static table alone is not.
  Json j = padScene();
  auto s = dm::parseScene(j.dump(), "scene.json", "/data/scenes");
  ASSERT_TRUE(s) << s.error();
  j["objects"][1].erase("soft");
  const auto found6 = problemsOf(j);
  if (const dm::Error* e = at(found6, "/engines/physics")) {
    EXPECT_NE(e->what.find("dynamic or soft"), std::string::npos) << e->what;
  }
}

// The pad with a needle going into it through two layers.
Json needleScene() {
  Json j = padScene();
  j["objects"][1]["soft"]["layers"] = Json::parse(R"([
      {"name": "skin", "thickness": 0.004, "puncture_force": 1.1, "cutting_force": 0.35, "friction": 45},
      {"name": "muscle", "puncture_force": 0.7, "cutting_force": 0.25, "friction": 30}])");
  Json& h = j["engines"]["haptics"];
  h["renderer"] = "needle";
  h.erase("tool_radius");
  h["needle"] = Json::parse(R"({"length": 0.06, "radius": 0.02, "coupling_spacing": 0.003,
      "across_stiffness": 500, "along_stiffness": 300, "tip": [0, 0, -0.03], "axis": [0, 0, -1],
      "normal": [1, 0, 0], "max_torque": 0.2})");
  return j;
}

TEST(SceneNeedle, KeysReadAndWriteBackEqual) {
  auto s = dm::parseScene(needleScene().dump(), "scene.json", "/data/scenes");
  ASSERT_TRUE(s) << s.error();
  const std::vector<dm::SceneSoftLayer>& layers = s->objects[1].soft->layers;
  ASSERT_EQ(layers.size(), 2u);
  EXPECT_EQ(layers[0].name, "skin");
  EXPECT_EQ(layers[0].thickness, 0.004);
  EXPECT_EQ(layers[0].punctureForce, 1.1);
  EXPECT_EQ(layers[0].cuttingForce, 0.35);
  EXPECT_EQ(layers[0].friction, 45);
  EXPECT_EQ(layers[1].thickness, 0.0);  // down to the bottom
  const auto& h = *s->engines.haptics;
  EXPECT_EQ(h.renderer, dm::SceneHapticsEngine::Renderer::Needle);
  EXPECT_EQ(dm::rendererName(h.renderer), "needle");
  ASSERT_TRUE(h.needle);
  EXPECT_EQ(h.needle->length, 0.06);
  EXPECT_EQ(h.needle->radius, 0.02);
  EXPECT_EQ(h.needle->couplingSpacing, 0.003);
  EXPECT_EQ(h.needle->acrossStiffness, 500);
  EXPECT_EQ(h.needle->alongStiffness, 300);
  EXPECT_EQ(h.needle->tip, dm::Vec3(0, 0, -0.03));
  EXPECT_EQ(h.needle->axis, dm::Vec3(0, 0, -1));
  EXPECT_EQ(h.needle->normal, dm::Vec3(1, 0, 0));
  EXPECT_EQ(h.needle->maxTorque, 0.2);
  const Json back = dm::toJson(*s);
  EXPECT_FALSE(back["engines"]["haptics"].contains("tool_radius"));
  EXPECT_FALSE(back["objects"][1]["soft"]["layers"][1].contains("thickness"));
  auto again = dm::parseScene(back.dump(), "scene.json", "/data/scenes");
  ASSERT_TRUE(again) << again.error();
  EXPECT_TRUE(*s == *again);
}

TEST(SceneNeedle, MisusesAreErrorsAtTheirKeys) {
  {  // the needle's own values
    Json j = needleScene();
    Json& n = j["engines"]["haptics"]["needle"];
    n["length"] = 0.1;  // more than ¾ of a 20 mm circle
    n["coupling_spacing"] = 0.2;
    n["normal"] = {0, 0, 1};
    n["stiffness"] = 3;
    const auto problems = problemsOf(j);
    const std::string p = "/engines/haptics/needle";
    EXPECT_TRUE(at(problems, p + "/length"));
    EXPECT_TRUE(at(problems, p + "/coupling_spacing"));
    EXPECT_TRUE(at(problems, p + "/normal"));
    EXPECT_TRUE(at(problems, p + "/stiffness"));
    Json straight = needleScene();
    straight["engines"]["haptics"]["needle"].erase("radius");
    const auto found = problemsOf(straight);
    if (const dm::Error* e = at(found, p + "/normal")) {
      EXPECT_NE(e->what.find("straight"), std::string::npos) << e->what;
    }
  }
  {  // layers: names, thickness of all but the last
    Json j = needleScene();
    Json& l = j["objects"][1]["soft"]["layers"];
    l[0].erase("thickness");
    l[1]["thickness"] = 0.01;
    l[1]["name"] = "skin";
    l.push_back({{"name", "bone"}, {"friction", -1}});
    const auto problems = problemsOf(j);
    const std::string p = "/objects/1/soft/layers";
    EXPECT_TRUE(at(problems, p + "/0/thickness"));
    EXPECT_TRUE(at(problems, p + "/1/name"));
    EXPECT_TRUE(at(problems, p + "/2/friction"));
  }
  {  // the renderer without its needle, or with the god-object's keys
    Json j = needleScene();
    j["engines"]["haptics"].erase("needle");
    j["engines"]["haptics"]["tool_radius"] = 0.001;
    j["engines"]["haptics"]["force_shading"] = true;
    const auto problems = problemsOf(j);
    EXPECT_TRUE(at(problems, "/engines/haptics/needle"));
    EXPECT_TRUE(at(problems, "/engines/haptics/tool_radius"));
    EXPECT_TRUE(at(problems, "/engines/haptics/force_shading"));
  }
  {  // a needle block under another renderer, and layers nothing goes into
    Json j = needleScene();
    j["engines"]["haptics"]["renderer"] = "god-object";
    const auto problems = problemsOf(j);
    EXPECT_TRUE(at(problems, "/engines/haptics/needle"));
    if (const dm::Error* e = at(problems, "/objects/1/soft/layers")) {
      EXPECT_NE(e->what.find("no needle"), std::string::npos) << e->what;
    }
  }
  {  // the needle goes into a soft object with layers, and only one
    Json j = needleScene();
    j["objects"][1]["soft"].erase("layers");
    const auto found = problemsOf(j);
    if (const dm::Error* e = at(found, "/engines/haptics/objects")) {
      EXPECT_NE(e->what.find("no needle layers"), std::string::npos) << e->what;
    }
    Json two = needleScene();
    two["objects"][0]["haptic"] = true;
    two["objects"][0]["material"] = "tissue";
    two["engines"]["haptics"]["objects"] = {"pad", "table"};
    const auto found2 = problemsOf(two);
    EXPECT_TRUE(at(found2, "/engines/haptics/objects"));
  }
  {  // the tissue's material: friction and damping are the layers' business
    Json j = needleScene();
    j["materials"]["tissue"]["haptic"]["damping"] = 0.5;
    const auto found = problemsOf(j);
    EXPECT_TRUE(at(found, "/objects/1/material"));
  }
}

TEST(SceneNeedle, LayersFromALabelVolumeReadAndWriteBack) {
  Json j = needleScene();
  j["resources"]["seg"] = {{"type", "volume"}, {"source", "seg.nii.gz"}};
  Json& soft = j["objects"][1]["soft"];
  soft["labels"] = "seg";
  soft["layers"][0].erase("thickness");
  soft["layers"][0]["label"] = 1;
  soft["layers"][1]["label"] = 3;
  auto s = dm::parseScene(j.dump(), "scene.json", "/data/scenes");
  ASSERT_TRUE(s) << s.error();
  const dm::SceneSoft& got = *s->objects[1].soft;
  EXPECT_EQ(got.labels, "seg");
  EXPECT_EQ(got.layers[0].label, 1);
  EXPECT_EQ(got.layers[1].label, 3);
  EXPECT_EQ(got.layers[0].thickness, 0.0);
  auto again = dm::parseScene(dm::toJson(*s).dump(), "scene.json", "/data/scenes");
  ASSERT_TRUE(again) << again.error();
  EXPECT_TRUE(*s == *again);
  // Misuses: a thickness beside labels, a label twice, a label that is not
  // a whole number, labels that name no volume.
  Json bad = j;
  Json& b = bad["objects"][1]["soft"];
  b["layers"][0]["thickness"] = 0.004;
  b["layers"][1]["label"] = 1;
  b["layers"].push_back({{"name", "bone"}, {"label", 2.5}});
  b["labels"] = "pad";
  const auto problems = problemsOf(bad);
  const std::string p = "/objects/1/soft";
  EXPECT_TRUE(at(problems, p + "/layers/0/thickness"));
  EXPECT_TRUE(at(problems, p + "/layers/1/label"));
  EXPECT_TRUE(at(problems, p + "/layers/2/label"));
  if (const dm::Error* e = at(problems, p + "/labels")) {
    EXPECT_NE(e->what.find("not a volume"), std::string::npos) << e->what;
  }
  Json none = padScene();
  none["objects"][1]["soft"]["labels"] = "pad";
  const auto found = problemsOf(none);
  if (const dm::Error* e = at(found, p + "/labels")) {
    EXPECT_NE(e->what.find("no layers"), std::string::npos) << e->what;
  }
}

TEST(SceneSoft, FixedBoxesAndAGradedGridReadAndWriteBack) {
  Json j = padScene();
  Json& soft = j["objects"][1]["soft"];
  soft["fixed_boxes"] = Json::parse(R"([{"min": [-0.03, -0.03, -0.01], "max": [-0.02, 0.03, 0.01]}])");
  soft["levels"] = 3;
  soft["fine_region"] = Json::parse(R"({"min": [-0.005, -0.005, 0], "max": [0.005, 0.005, 0.01]})");
  auto s = dm::parseScene(j.dump(), "scene.json", "/data/scenes");
  ASSERT_TRUE(s) << s.error();
  const dm::SceneSoft& got = *s->objects[1].soft;
  ASSERT_EQ(got.fixedBoxes.size(), 1u);
  EXPECT_EQ(got.fixedBoxes[0].min, dm::Vec3(-0.03, -0.03, -0.01));
  EXPECT_EQ(got.fixedBoxes[0].max, dm::Vec3(-0.02, 0.03, 0.01));
  EXPECT_EQ(got.levels, 3);
  ASSERT_TRUE(got.fineRegion);
  EXPECT_EQ(got.fineRegion->max, dm::Vec3(0.005, 0.005, 0.01));
  auto again = dm::parseScene(dm::toJson(*s).dump(), "scene.json", "/data/scenes");
  ASSERT_TRUE(again) << again.error();
  EXPECT_TRUE(*s == *again);
  Json bad = j;
  Json& b = bad["objects"][1]["soft"];
  b["fixed_boxes"][0]["max"] = {-0.04, 0.03, 0.01};
  b["levels"] = 2.5;
  const auto problems = problemsOf(bad);
  EXPECT_TRUE(at(problems, "/objects/1/soft/fixed_boxes/0/max"));
  EXPECT_TRUE(at(problems, "/objects/1/soft/levels"));
  Json uniform = j;
  uniform["objects"][1]["soft"].erase("levels");
  const auto found = problemsOf(uniform);
  EXPECT_TRUE(at(found, "/objects/1/soft/fine_region"));
}

TEST(SceneSoft, TissueFromAVolumeReadsAndWritesBack) {
  Json j = padScene();
  j["resources"]["seg"] = {{"type", "volume"}, {"source", "liver_mask.nii.gz"}};
  Json& soft = j["objects"][1]["soft"];
  soft.erase("voxel_size");
  soft["volume"] = "seg";
  soft["threshold"] = 0.5;
  auto s = dm::parseScene(j.dump(), "scene.json", "/data/scenes");
  ASSERT_TRUE(s) << s.error();
  const dm::SceneSoft& got = *s->objects[1].soft;
  EXPECT_EQ(got.volume, "seg");
  EXPECT_EQ(got.threshold, 0.5);
  EXPECT_EQ(got.voxelSize, 0.0);
  const Json back = dm::toJson(*s);
  EXPECT_FALSE(back["objects"][1]["soft"].contains("voxel_size"));
  auto again = dm::parseScene(back.dump(), "scene.json", "/data/scenes");
  ASSERT_TRUE(again) << again.error();
  EXPECT_TRUE(*s == *again);
  // Misuses: a voxel size beside the volume, a scale, a volume that is not
  // one, a threshold without a volume.
  Json bad = j;
  bad["objects"][1]["soft"]["voxel_size"] = 0.002;
  bad["objects"][1]["scale"] = 2;
  const auto problems = problemsOf(bad);
  EXPECT_TRUE(at(problems, "/objects/1/soft/voxel_size"));
  EXPECT_TRUE(at(problems, "/objects/1/scale"));
  Json wrong = j;
  wrong["objects"][1]["soft"]["volume"] = "pad";
  const auto found = problemsOf(wrong);
  if (const dm::Error* e = at(found, "/objects/1/soft/volume")) {
    EXPECT_NE(e->what.find("not a volume"), std::string::npos) << e->what;
  }
  Json stray = padScene();
  stray["objects"][1]["soft"]["threshold"] = 0.5;
  const auto found2 = problemsOf(stray);
  EXPECT_TRUE(at(found2, "/objects/1/soft/threshold"));
}

}  // namespace scene_soft_test

namespace scene_punch_test {

using dm::Json;
using namespace scene_test;

// The pad bonded to a punch: renderer "punch", its block naming the pad.
Json punchScene() {
  Json j = scene_soft_test::padScene();
  Json& h = j["engines"]["haptics"];
  h = {{"device", "hand"},
       {"renderer", "punch"},
       {"proxy_object", "tool"},
       {"punch",
        {{"object", "pad"},
         {"region", {{"min", {-0.005, -0.005, 0.0099}}, {"max", {0.005, 0.005, 0.0101}}}}}}};
  return j;
}

TEST(ScenePunch, KeysReadAndWriteBackEqual) {
  const Json j = punchScene();
  auto s = parsed(j);
  ASSERT_TRUE(s);
  const auto& h = *s->engines.haptics;
  EXPECT_EQ(h.renderer, dm::SceneHapticsEngine::Renderer::Punch);
  ASSERT_TRUE(h.punch);
  EXPECT_EQ(h.punch->object, "pad");
  EXPECT_EQ(h.punch->region.min, dm::Vec3(-0.005, -0.005, 0.0099));
  EXPECT_TRUE(h.objects.empty());
  const Json written = expectRoundTrip(j);
  EXPECT_FALSE(written["engines"]["haptics"].contains("objects"));
  EXPECT_EQ(written["engines"]["haptics"]["punch"]["object"], "pad");
}

TEST(ScenePunch, MisusesAreErrorsAtTheirKeys) {
  {
    Json j = punchScene();
    Json& h = j["engines"]["haptics"];
    h["objects"] = {"pad"};
    h["tool_radius"] = 0.001;
    h["punch"]["object"] = "table";
    h["punch"]["region"] = {{"min", {0, 0, 0}}, {"max", {-1, 0, 0}}};
    h["punch"]["depth"] = 3;
    const auto p = problemsOf(j);
    expectAt(p, "/engines/haptics/objects", "bonded");
    expectAt(p, "/engines/haptics/tool_radius", "bonded");
    expectAt(p, "/engines/haptics/punch/object", "is not soft");
    expectAt(p, "/engines/haptics/punch/region/max", "below min");
    expectAt(p, "/engines/haptics/punch/depth", "unknown");
  }
  {
    Json j = punchScene();
    j["engines"]["haptics"].erase("punch");
    expectAt(problemsOf(j), "/engines/haptics/punch", "needs its punch");
    Json k = punchScene();
    k["engines"]["haptics"]["punch"].erase("region");
    k["engines"]["haptics"]["punch"]["object"] = "liver";
    const auto p = problemsOf(k);
    expectAt(p, "/engines/haptics/punch/region", "missing");
    expectAt(p, "/engines/haptics/punch/object", "is not defined");
  }
  {
    // A punch block under another renderer.
    Json j = scene_soft_test::padScene();
    j["engines"]["haptics"]["punch"] = punchScene()["engines"]["haptics"]["punch"];
    expectAt(problemsOf(j), "/engines/haptics/punch", "without the punch renderer");
  }
}

}  // namespace scene_punch_test
