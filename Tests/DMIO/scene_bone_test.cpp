// Bone placement keys of the scene file: a segment of the generated
// calvarium CT (a curved plate) selected by value, cropped to a box and cut
// by an oblique saw plane with a kerf is exactly the voxels a brute-force
// scan of the CT picks (each keeping its world position), its largest
// component is the largest 26-connected one, and every misuse of "segment",
// "voxels" and "bone_placement" is refused at its JSON path.
#include <dm/io/scene_file.hpp>
#include <dm/io/scene_resources.hpp>
#include <dm/math/phantom.hpp>
#include <dm/math/volume_components.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "scene_test_support.hpp"

namespace scene_bone_io_test {

using dm::Json;
using dm::Vec3;

// The calvarium phantom at 1 mm, segmented above 300 HU and cut by the
// oblique plane through (0, 0, −3) mm with normal n (the osteotomy scene's).
const Vec3 kNormal = Vec3(0.925417, 0.163176, -0.342020).normalized();

Json boneScene() {
  return Json::parse(R"({
    "format": "dmplatform-scene", "version": 2, "name": "bone",
    "resources": {
      "ct": {"type": "volume", "phantom": {"kind": "calvarium", "spacing": 0.001, "half_width": 0.016,
                                           "above": 0.002, "below": 0.009}},
      "a": {"type": "volume", "segment": {"volume": "ct", "above": 300,
            "box": {"min": [-0.0125, -0.011, -0.009], "max": [0.0135, 0.012, 0.001]},
            "cuts": [{"point": [0, 0, -0.003], "normal": [-0.925417, -0.163176, 0.342020], "kerf": 0.001}]}},
      "b": {"type": "volume", "segment": {"volume": "ct", "above": 300,
            "cuts": [{"point": [0, 0, -0.003], "normal": [0.925417, 0.163176, -0.342020], "kerf": 0.001}],
            "largest_component": true}},
      "a_surface": {"type": "isosurface", "volume": "a", "level": 0.5},
      "b_surface": {"type": "isosurface", "volume": "b", "level": 0.5}
    },
    "materials": {"bone": {"color": [0.9, 0.85, 0.7]}},
    "objects": [
      {"name": "fixed", "mesh": "a_surface", "material": "bone", "haptic": true, "voxels": {"volume": "a"}},
      {"name": "moving", "mesh": "b_surface", "material": "bone"}
    ],
    "devices": [{"name": "hand", "driver": "sim-haptic"}],
    "engines": {"haptics": {"renderer": "bone-placement", "device": "hand", "objects": ["fixed"],
                            "proxy_object": "moving", "bone_placement": {"fragment": "b"}}}
  })");
}

dm::SceneDesc parsed(const Json& j) {
  std::vector<dm::Error> problems;
  auto s = dm::parseScene(j.dump(), "scene.json", "/data/scenes", &problems);
  EXPECT_TRUE(s) << dm::formatSceneErrors(problems);
  return s ? *s : dm::SceneDesc{};
}

TEST(SceneBoneFile, ASegmentIsTheVoxelsABruteForceScanPicksAtTheirWorldPositions) {
  const dm::SceneDesc scene = parsed(boneScene());
  auto res = dm::loadSceneResources(scene);
  ASSERT_TRUE(res) << res.error();
  const dm::Volume& ct = *res->volume("ct");
  const dm::Volume& a = *res->volume("a");
  const dm::SceneSegment& g = *scene.resource("a")->segment;
  // Every voxel of the CT: kept by the rule, and then a voxel of the segment
  // at the same world position; every voxel of the segment is one of them.
  std::size_t expected = 0, found = 0;
  double zMin = 1, zMax = -1;
  for (int k = 0; k < ct.dims().z(); ++k)
    for (int j = 0; j < ct.dims().y(); ++j)
      for (int i = 0; i < ct.dims().x(); ++i) {
        const Vec3 p = ct.indexToWorld() * Vec3(i, j, k);
        const bool keep = ct.value(i, j, k) > 300 && (p.array() >= g.box->min.array()).all() &&
                          (p.array() <= g.box->max.array()).all() &&
                          g.cuts[0].normal.dot(p - g.cuts[0].point) > 0.0005;
        const Vec3 q = a.worldToIndex() * p;
        const Vec3 r = q.array().round();
        ASSERT_LT((q - r).norm(), 1e-9) << "the segment's grid is the CT's";
        const bool inside = (r.array() >= 0).all() && (r.array() < a.dims().cast<double>().array()).all();
        const bool in = inside && a.value(int(r.x()), int(r.y()), int(r.z())) != 0;
        EXPECT_EQ(in, keep) << "voxel " << i << "," << j << "," << k;
        expected += keep;
        found += in;
        if (keep) {
          zMin = std::min(zMin, p.z());
          zMax = std::max(zMax, p.z());
        }
      }
  EXPECT_EQ(found, expected);
  EXPECT_GT(expected, 1000u);
  // A curved vault: over 26 mm the outer table falls about 1 mm from the apex.
  EXPECT_GT(zMax - zMin, 0.0065);
  // The segment's own voxels count: one empty voxel around them.
  std::size_t own = 0;
  for (std::size_t n = 0; n < a.voxelCount(); ++n) own += a.valueAt(n) != 0;
  EXPECT_EQ(own, expected);
  for (int axis = 0; axis < 3; ++axis) {
    bool lowFaceEmpty = true;
    for (int k = 0; k < a.dims().z(); ++k)
      for (int j = 0; j < a.dims().y(); ++j)
        for (int i = 0; i < a.dims().x(); ++i)
          if (dm::Vec3i(i, j, k)[axis] == 0 && a.value(i, j, k) != 0) lowFaceEmpty = false;
    EXPECT_TRUE(lowFaceEmpty) << "axis " << axis;
  }
}

TEST(SceneBoneFile, LargestComponentKeepsTheLargest26ConnectedPart) {
  const dm::SceneDesc scene = parsed(boneScene());
  auto res = dm::loadSceneResources(scene);
  ASSERT_TRUE(res) << res.error();
  // The same cut without largest_component, labelled here.
  dm::SceneResource all = *scene.resource("b");
  all.segment->largestComponent = false;
  auto whole = dm::makeSceneSegment(all, *res->volume("ct"));
  ASSERT_TRUE(whole) << whole.error();
  auto cc = dm::labelComponents(*whole, dm::Connectivity::TwentySix);
  ASSERT_TRUE(cc) << cc.error();
  ASSERT_GE(cc->count(), 1u);
  std::size_t kept = 0;
  const dm::Volume& b = *res->volume("b");
  for (std::size_t n = 0; n < b.voxelCount(); ++n) kept += b.valueAt(n) != 0;
  EXPECT_EQ(kept, cc->sizes[0]);
}

TEST(SceneBoneFile, ASegmentThatSelectsNothingOrMissesTheScanIsRefused) {
  dm::SceneDesc scene = parsed(boneScene());
  auto res = dm::loadSceneResources(scene);
  ASSERT_TRUE(res);
  dm::SceneResource r = *scene.resource("a");
  r.segment->value = 5000;  // above every HU of the phantom
  auto none = dm::makeSceneSegment(r, *res->volume("ct"));
  ASSERT_FALSE(none);
  EXPECT_EQ(none.error().where, "resources/a/segment");
  r = *scene.resource("a");
  r.segment->box = dm::SceneBox{Vec3(1, 1, 1), Vec3(2, 2, 2)};
  auto missed = dm::makeSceneSegment(r, *res->volume("ct"));
  ASSERT_FALSE(missed);
  EXPECT_EQ(missed.error().where, "resources/a/segment/box");
}

TEST(SceneBoneFile, TheKeysRoundTrip) {
  Json j = boneScene();
  j["engines"]["haptics"]["bone_placement"] = {
      {"fragment", "b"},
      {"threshold", 0.25},
      {"coupling_stiffness", 500},
      {"coupling_damping", 3},
      {"mass", 0.01},
      {"density", 1800},
      {"max_contacts", 2048},
      {"contact_level", 1},
      {"iterations", 12},
      {"slop", 0.0002},
      {"baumgarte", 0.3},
      {"max_torque", 0.5},
      {"coupling_angular_stiffness", 0.4},
      {"coupling_angular_damping", 0.002},
      {"target_pose", {{"position", {0.001, 0, 0}}, {"euler_deg", {0, 0, 5}}}}};
  j["resources"]["c"] = {{"type", "volume"}, {"segment", {{"volume", "ct"}, {"label", 3}}}};
  const dm::SceneDesc a = parsed(j);
  const dm::SceneBonePlacement& b = *a.engines.haptics->bonePlacement;
  EXPECT_EQ(b.maxContacts, 2048);
  EXPECT_EQ(b.slop, 0.0002);
  EXPECT_EQ(b.contactLevel, 1);
  EXPECT_EQ(a.resource("c")->segment->select, dm::SceneSegment::Select::Label);
  EXPECT_EQ(a.resource("c")->segment->value, 3.0);
  EXPECT_EQ(a.object("fixed")->voxels->volume, "a");
  const dm::SceneDesc back = parsed(dm::toJson(a));
  EXPECT_EQ(back, a);
  EXPECT_EQ(dm::toJson(back), dm::toJson(a));
}

TEST(SceneBoneFile, MisuseIsRefusedAtItsPath) {
  using scene_test::at;
  using scene_test::problemsOf;
  {  // a segment of a segment, two selections, a box upside down, a cut without its normal
    Json j = boneScene();
    j["resources"]["c"] = {{"type", "volume"},
                           {"segment",
                            {{"volume", "a"},
                             {"above", 1},
                             {"below", 2},
                             {"box", {{"min", {0, 0, 0}}, {"max", {0, -1, 1}}}},
                             {"cuts", {{{"point", {0, 0, 0}}}}}}}};
    const auto p = problemsOf(j);
    EXPECT_NE(at(p, "/resources/c/segment/volume"), nullptr);
    EXPECT_NE(at(p, "/resources/c/segment/below"), nullptr);
    EXPECT_NE(at(p, "/resources/c/segment/box/max"), nullptr);
    EXPECT_NE(at(p, "/resources/c/segment/cuts/0/normal"), nullptr);
  }
  {  // a segment that also has a source; no selection
    Json j = boneScene();
    j["resources"]["c"] = {{"type", "volume"}, {"source", "x.nii"}, {"segment", {{"volume", "ct"}}}};
    const auto p = problemsOf(j);
    EXPECT_NE(at(p, "/resources/c/source"), nullptr);
    EXPECT_NE(at(p, "/resources/c/segment"), nullptr);
  }
  {  // the block without the renderer, and voxels no renderer touches
    Json j = boneScene();
    j["engines"]["haptics"]["renderer"] = "god-object";
    j["materials"]["bone"]["haptic"] = {{"stiffness", 1000}};
    const auto p = problemsOf(j);
    EXPECT_NE(at(p, "/engines/haptics/bone_placement"), nullptr);
    EXPECT_NE(at(p, "/objects/0/voxels"), nullptr);
  }
  {  // the renderer without its block, with a proxy radius
    Json j = boneScene();
    j["engines"]["haptics"].erase("bone_placement");
    j["engines"]["haptics"]["tool_radius"] = 0.001;
    const auto p = problemsOf(j);
    EXPECT_NE(at(p, "/engines/haptics/bone_placement"), nullptr);
    EXPECT_NE(at(p, "/engines/haptics/tool_radius"), nullptr);
  }
  {  // a touched object without voxels, a fragment that is a mesh
    Json j = boneScene();
    j["objects"][0].erase("voxels");
    j["materials"]["bone"]["haptic"] = {{"stiffness", 1000}};
    j["engines"]["haptics"]["bone_placement"]["fragment"] = "a_surface";
    const auto p = problemsOf(j);
    EXPECT_NE(at(p, "/objects/0/voxels"), nullptr);
    EXPECT_NE(at(p, "/engines/haptics/bone_placement/fragment"), nullptr);
  }
  {  // two touched objects; voxels on a scaled, dynamic object whose material has a spring
    Json j = boneScene();
    j["objects"][1]["haptic"] = true;
    j["objects"][1]["voxels"] = {{"volume", "b"}};
    j["objects"][1]["scale"] = 2;
    j["objects"][1]["dynamic"] = true;
    j["objects"][1]["mass"] = 0.1;
    j["materials"]["bone"]["haptic"] = {{"stiffness", 1000}};
    j["engines"]["haptics"]["objects"] = {"fixed", "moving"};
    j["engines"]["haptics"].erase("proxy_object");
    const auto p = problemsOf(j);
    EXPECT_NE(at(p, "/engines/haptics/objects"), nullptr);
    EXPECT_NE(at(p, "/objects/1/scale"), nullptr);
    EXPECT_NE(at(p, "/objects/1/dynamic"), nullptr);
    EXPECT_NE(at(p, "/objects/0/material"), nullptr);
  }
  {  // version 1 has none of it
    Json j = boneScene();
    j["version"] = 1;
    const auto p = problemsOf(j);
    EXPECT_NE(at(p, "/resources/a/segment"), nullptr);
    EXPECT_NE(at(p, "/objects/0/voxels"), nullptr);
  }
}

}  // namespace scene_bone_io_test
