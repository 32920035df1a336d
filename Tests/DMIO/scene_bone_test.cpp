// Bone placement keys of the scene file: a segment of the generated
// calvarium CT (a curved plate) selected by value, cropped to a box and cut
// by an oblique saw plane with a kerf is exactly the voxels a brute-force
// scan of the CT picks (each keeping its world position), its largest
// component is the largest 26-connected one; a segment of an MRI outside its
// brain mask and within a distance of it ("outside", "near", on an
// anisotropic grid: a curved shell) cut through its centroid is exactly what
// a brute-force scan over every pair of voxels picks; and every misuse of
// "segment", "voxels" and "bone_placement" is refused at its JSON path.
#include <dm/io/scene_file.hpp>
#include <dm/io/scene_resources.hpp>
#include <dm/math/phantom.hpp>
#include <dm/math/volume_components.hpp>

#include <gtest/gtest.h>

#include <algorithm>
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

// An MRI head in miniature on an anisotropic grid (1 x 1 x 1.5 mm): a
// brain (a ball of radius 7 mm, its mask), dark tissue (30) around it out to
// 12 mm and bright scalp (100) beyond.
struct MiniHead {
  dm::Volume head, brain;
  Vec3 centre;
};

MiniHead miniHead() {
  const dm::Vec3i dims(30, 28, 20);
  dm::Affine3 a = dm::Affine3::Identity();
  a.translate(Vec3(-0.012, 0.004, 0.050));
  a.scale(Vec3(0.001, 0.001, 0.0015));
  MiniHead h;
  h.head = *dm::Volume::create(dims, dm::VoxelType::U8, a);
  h.brain = *dm::Volume::create(dims, dm::VoxelType::U8, a);
  h.centre = a * Vec3(14.3, 13.6, 9.4);
  for (int k = 0; k < dims.z(); ++k)
    for (int j = 0; j < dims.y(); ++j)
      for (int i = 0; i < dims.x(); ++i) {
        const double r = (a * Vec3(i, j, k) - h.centre).norm();
        h.brain.setValue(i, j, k, r <= 0.007 ? 1 : 0);
        h.head.setValue(i, j, k, r <= 0.007 ? 80 : r <= 0.012 ? 30 : 100);
      }
  return h;
}

TEST(SceneBoneFile, OutsideAndNearAMaskAndACutThroughTheCentroidAreWhatABruteForceScanPicks) {
  const MiniHead h = miniHead();
  dm::SceneResource r;
  r.name = "shell";
  r.type = dm::SceneResource::Type::Volume;
  dm::SceneSegment g;
  g.volume = "head";
  g.select = dm::SceneSegment::Select::Below;
  g.value = 50;
  g.outside = "brain";
  g.near = dm::SceneSegmentNear{"brain", 0.003};
  g.largestComponent = true;
  r.segment = g;
  // Brute force: below 50, not brain, some brain voxel centre within 3 mm.
  std::vector<Vec3> brain, shell;
  const dm::Vec3i dims = h.head.dims();
  for (int k = 0; k < dims.z(); ++k)
    for (int j = 0; j < dims.y(); ++j)
      for (int i = 0; i < dims.x(); ++i)
        if (h.brain.value(i, j, k) != 0) brain.push_back(h.head.indexToWorld() * Vec3(i, j, k));
  for (int k = 0; k < dims.z(); ++k)
    for (int j = 0; j < dims.y(); ++j)
      for (int i = 0; i < dims.x(); ++i) {
        const Vec3 p = h.head.indexToWorld() * Vec3(i, j, k);
        if (h.head.value(i, j, k) >= 50 || h.brain.value(i, j, k) != 0) continue;
        double nearest = 1;
        for (const Vec3& b : brain) nearest = std::min(nearest, (p - b).norm());
        if (nearest <= 0.003 + 1e-12) shell.push_back(p);
      }
  ASSERT_GT(shell.size(), 500u);
  // The segment holds exactly these voxels (the shell is one piece).
  const auto voxelsOf = [](const dm::Volume& v) {
    std::vector<Vec3> out;
    for (int k = 0; k < v.dims().z(); ++k)
      for (int j = 0; j < v.dims().y(); ++j)
        for (int i = 0; i < v.dims().x(); ++i)
          if (v.value(i, j, k) != 0) out.push_back(v.indexToWorld() * Vec3(i, j, k));
    return out;
  };
  const auto sameSet = [](std::vector<Vec3> a, std::vector<Vec3> b) {
    const auto less = [](const Vec3& x, const Vec3& y) {
      return std::lexicographical_compare(x.data(), x.data() + 3, y.data(), y.data() + 3);
    };
    std::sort(a.begin(), a.end(), less);
    std::sort(b.begin(), b.end(), less);
    if (a.size() != b.size()) return false;
    for (std::size_t n = 0; n < a.size(); ++n)
      if ((a[n] - b[n]).norm() > 1e-9) return false;
    return true;
  };
  auto whole = dm::makeSceneSegment(r, h.head, &h.brain, &h.brain);
  ASSERT_TRUE(whole) << whole.error();
  const std::vector<Vec3> got = voxelsOf(*whole);
  EXPECT_EQ(got.size(), shell.size());
  EXPECT_TRUE(sameSet(got, shell));
  // A 2 mm band: at 1.5 mm spacing along z the anisotropy matters — an
  // index-unit distance would pick another set.
  Vec3 centroid = Vec3::Zero();
  for (const Vec3& p : shell) centroid += p;
  centroid /= static_cast<double>(shell.size());
  // Cut through the centroid, oblique, 1 mm kerf: each side is the brute
  // force's half (each half of a shell is one piece).
  const Vec3 n = Vec3(0.8, 0.3, -0.2).normalized();
  for (const double side : {1.0, -1.0}) {
    dm::SceneResource cut = r;
    cut.segment->cuts = {dm::SceneCut{.normal = side * n, .kerf = 0.001, .atCentroid = true}};
    auto half = dm::makeSceneSegment(cut, h.head, &h.brain, &h.brain);
    ASSERT_TRUE(half) << half.error();
    std::vector<Vec3> expected;
    for (const Vec3& p : shell)
      if (side * n.dot(p - centroid) > 0.0005) expected.push_back(p);
    EXPECT_GT(expected.size(), shell.size() / 3);
    EXPECT_TRUE(sameSet(voxelsOf(*half), expected)) << "side " << side;
  }
  // The masks must be on the scan's grid and given.
  dm::Volume shifted =
      *dm::Volume::create(h.brain.dims(), dm::VoxelType::U8,
                          dm::Affine3(Eigen::Translation3d(0.001, 0, 0)) * h.brain.indexToWorld());
  auto other = dm::makeSceneSegment(r, h.head, &shifted, &h.brain);
  ASSERT_FALSE(other);
  EXPECT_EQ(other.error().where, "resources/shell/segment/outside");
  auto missing = dm::makeSceneSegment(r, h.head, &h.brain, nullptr);
  ASSERT_FALSE(missing);
  EXPECT_EQ(missing.error().where, "resources/shell/segment/near/volume");
  // Cuts that leave nothing are refused at "cuts".
  dm::SceneResource away = r;
  away.segment->cuts = {dm::SceneCut{.point = h.centre + Vec3(0.05, 0, 0), .normal = Vec3::UnitX()}};
  auto empty = dm::makeSceneSegment(away, h.head, &h.brain, &h.brain);
  ASSERT_FALSE(empty);
  EXPECT_EQ(empty.error().where, "resources/shell/segment/cuts");
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
  j["resources"]["d"] = {{"type", "volume"},
                         {"segment",
                          {{"volume", "ct"},
                           {"below", 50},
                           {"outside", "ct"},
                           {"near", {{"volume", "ct"}, {"distance", 0.004}}},
                           {"largest_component", true},
                           {"cuts", {{{"point", "centroid"}, {"normal", {1, 0, 0}}, {"kerf", 0.001}}}}}}};
  const dm::SceneDesc a = parsed(j);
  const dm::SceneSegment& d = *a.resource("d")->segment;
  EXPECT_EQ(d.outside, "ct");
  ASSERT_TRUE(d.near);
  EXPECT_EQ(d.near->volume, "ct");
  EXPECT_EQ(d.near->distance, 0.004);
  EXPECT_TRUE(d.cuts.at(0).atCentroid);
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
  {  // masks that are not volumes or are segments, a point that is a word, "near" without its distance
    Json j = boneScene();
    j["resources"]["c"] = {{"type", "volume"},
                           {"segment",
                            {{"volume", "ct"},
                             {"below", 50},
                             {"outside", "a"},
                             {"near", {{"volume", "a_surface"}, {"radius", 0.002}}},
                             {"cuts", {{{"point", "middle"}, {"normal", {1, 0, 0}}}}}}}};
    const auto p = problemsOf(j);
    EXPECT_NE(at(p, "/resources/c/segment/outside"), nullptr);
    EXPECT_NE(at(p, "/resources/c/segment/near/volume"), nullptr);
    EXPECT_NE(at(p, "/resources/c/segment/near/radius"), nullptr);
    EXPECT_NE(at(p, "/resources/c/segment/near/distance"), nullptr);
    EXPECT_NE(at(p, "/resources/c/segment/cuts/0/point"), nullptr);
  }
  {  // empty mask names are not "no mask"
    Json j = boneScene();
    j["resources"]["c"] = {{"type", "volume"},
                           {"segment",
                            {{"volume", "ct"},
                             {"below", 50},
                             {"outside", ""},
                             {"near", {{"volume", ""}, {"distance", 0.002}}}}}};
    const auto p = problemsOf(j);
    EXPECT_NE(at(p, "/resources/c/segment/outside"), nullptr);
    EXPECT_NE(at(p, "/resources/c/segment/near/volume"), nullptr);
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
