// The 6-DOF rigid-tool renderers in a scene. VPS (dm::VpsRenderer through
// "renderer": "vps"):
// a cube tool pressed flat onto a table by a position-driven device comes to
// rest where the virtual coupling and the contact balance — two springs in
// series, F = K·k_c/(K + k_c)·d for a device d below the surface (McNeely's
// stiffness rule: a face pressed evenly feels K·depth however finely it is
// sampled) — straight up, without torque. The sphere-tree renderer on the
// same press feels the handle's spring alone. Misuse is refused naming the key.
#include <dm/collide/sphere_tree.hpp>
#include <dm/engine/scene_runtime.hpp>
#include <dm/io/scene_file.hpp>
#include <dm/io/scene_resources.hpp>

#include <gtest/gtest.h>

#include "../common/temp_dir.hpp"
#include "scene_run_support.hpp"

namespace scene_6dof_test {

using nlohmann::json;

// A 1 cm cube tool, its centre driven straight down from 15 mm above a table
// (top face at z = 0) to 3 mm: its bottom face 2 mm under the surface.
json pressScene() {
  return json::parse(R"({
    "format": "dmplatform-scene", "version": 2, "name": "vps_press",
    "resources": {
      "table": {"type": "shape", "shape": "box", "half_extents": [0.05, 0.05, 0.02]},
      "cube": {"type": "shape", "shape": "box", "half_extents": [0.005, 0.005, 0.005]}
    },
    "materials": {"steel": {"haptic": {"stiffness": 2000, "damping": 0}}},
    "objects": [
      {"name": "table", "mesh": "table", "material": "steel", "haptic": true,
       "pose": {"position": [0, 0, -0.02]}},
      {"name": "shown", "mesh": "cube", "material": "steel"}
    ],
    "devices": [{"name": "hand", "driver": "sim-haptic",
                 "config": {"path": "line", "from": [0, 0, 0.015], "to": [0, 0, 0.003], "period": 2, "loop": 0}}],
    "engines": {
      "haptics": {"renderer": "vps", "device": "hand", "objects": ["table"], "proxy_object": "shown",
                  "vps": {"tool": "cube", "coupling_stiffness": 500, "voxel_size": 0.0005}}
    },
    "outputs": {"forces": true, "summary": true}
  })");
}

dm::SceneDesc parsed(const json& j) { return scene_run::parsedScene(j.dump(), "vps.json", "."); }

// The mean force and torque of the last 0.2 s of a run's trace (the
// device held still for the last second).
std::pair<dm::Vec3, dm::Vec3> restingWrench(const std::filesystem::path& forcesCsv) {
  const std::vector<scene_run::TraceRow> rows = scene_run::forceTrace(forcesCsv);
  EXPECT_GE(rows.size(), 1900u);
  dm::Vec3 f = dm::Vec3::Zero(), torque = dm::Vec3::Zero();
  int n = 0;
  for (const scene_run::TraceRow& r : rows)
    if (r.t >= 1.8) {
      f += r.force;
      torque += r.torque;
      ++n;
    }
  EXPECT_GT(n, 150);
  return {f / std::max(n, 1), torque / std::max(n, 1)};
}

TEST(SceneVps, ACubePressedFlatRestsWhereCouplingAndContactBalance) {
  const dm::test::TempDir dir("vps_press");
  const json s = scene_run::runScene(parsed(pressScene()), 2.0, dir.path());
  ASSERT_TRUE(s.contains("haptics")) << s.dump(2);
  EXPECT_EQ(s["haptics"]["renderer"], "vps");
  const auto [f, torque] = restingWrench(dir / "forces.csv");
  const double K = 2000, kc = 500, d = 0.002;
  const double expected = K * kc / (K + kc) * d;  // 0.8 N
  // The side points within the bottom face's depth count at part depth
  // (the averaged stiffness rule), a percent or two softer.
  EXPECT_NEAR(f.z(), expected, 0.03 * expected) << "F = " << f.transpose();
  EXPECT_LT(std::hypot(f.x(), f.y()), 0.01 * expected);
  EXPECT_LT(torque.norm(), 1e-4) << "a centred flat press has no torque: " << torque.transpose();
}

// The sphere-tree renderer on the same press: the tool is held on the
// table by the non-penetration constraints, so the hand feels the handle's
// spring alone, F = k·(z_tool − z_handle), straight up. Where the tool rests
// is the model's geometry: the cube's colliding nodes (level 4 of its
// octree) on a face collide through their flat surface patches, exactly;
// those on its edges and corners through their spheres, which stand off
// the face by up to their radius (Wang et al. 2013) — the lowest of them
// sets the height.
TEST(SceneSphereTree, ACubePressedFlatFeelsTheHandleSpringAlone) {
  json j = pressScene();
  j["engines"]["haptics"]["renderer"] = "sphere-tree";
  j["engines"]["haptics"].erase("vps");
  j["engines"]["haptics"]["sphere_tree"] = {{"tool", "cube"}, {"stiffness", 500}, {"levels", 6}};
  const dm::SceneDesc scene = parsed(j);
  auto resources = dm::loadSceneResources(scene);
  ASSERT_TRUE(resources) << resources.error();
  auto tree = dm::buildSphereTreeOctree(*resources->mesh("cube"), {.levels = 5});
  ASSERT_TRUE(tree) << tree.error();
  double lowest = 0.0;  // the tool's lowest colliding point, tool frame
  const std::span<const dm::SphereTreeNode> level = (*tree)->level(4);
  const std::size_t first = static_cast<std::size_t>(level.data() - (*tree)->nodes().data());
  for (std::size_t i = 0; i < level.size(); ++i) {
    const dm::SurfacePatch& p = (*tree)->patches()[first + i];
    const bool flat = p.valid() && p.coherence >= 0.9 && p.deviation <= 0.1 * level[i].radius;
    const double z = flat ? p.support(-dm::Vec3::UnitZ()).z() : level[i].center.z() - level[i].radius;
    lowest = std::min(lowest, z);
  }
  ASSERT_LT(lowest, -0.005 + 1e-9) << "nothing of the tool reaches below its bottom face";
  const dm::test::TempDir dir("sphere_tree_press");
  const json s = scene_run::runScene(scene, 2.0, dir.path());
  ASSERT_TRUE(s.contains("haptics")) << s.dump(2);
  EXPECT_EQ(s["haptics"]["renderer"], "sphere-tree");
  const auto [f, torque] = restingWrench(dir / "forces.csv");
  const double expected = 500 * (-lowest - 0.003);  // the handle's centre 3 mm above the table
  EXPECT_NEAR(f.z(), expected, 0.02 * expected) << "F = " << f.transpose();
  EXPECT_LT(std::hypot(f.x(), f.y()), 0.01 * expected);
  EXPECT_LT(torque.norm(), 1e-4) << torque.transpose();
}

// A 6-DOF tool pushing a rigid box across a table into a wall: a 1 cm ball
// tool in a position-driven hand moves along x at the box's mid-height,
// meets the box (4 cm, 0.2 kg, Coulomb 0.3 on the table) after about 0.9 s,
// pushes it 3 cm against a static wall and presses it there, the hand 5 mm
// past the touching point. Physics takes each tick's wrench of the tool on
// the box (dm::ToolImpulseChannel::addWrench), so the box moves; at rest the
// box is in equilibrium between the tool, its contacts (table and wall) and
// its weight: the force on the hand equals what the contacts hold plus the
// weight (1 %).
json pushScene(const std::string& renderer) {
  json j = json::parse(R"({
    "format": "dmplatform-scene", "version": 2, "name": "tool_push",
    "resources": {
      "table": {"type": "shape", "shape": "plane", "half_extents": [0.2, 0.2]},
      "box": {"type": "shape", "shape": "box", "half_extents": [0.02, 0.02, 0.02]},
      "wall": {"type": "shape", "shape": "box", "half_extents": [0.01, 0.1, 0.05]},
      "ball": {"type": "shape", "shape": "sphere", "radius": 0.005, "subdivisions": 3}
    },
    "materials": {"plastic": {"haptic": {"stiffness": 2000, "damping": 0}}},
    "objects": [
      {"name": "table", "mesh": "table", "contact": {"friction": 0.3}},
      {"name": "box", "mesh": "box", "material": "plastic", "haptic": true, "dynamic": true, "mass": 0.2,
       "contact": {"friction": 0.3}, "pose": {"position": [0, 0, 0.02]}},
      {"name": "wall", "mesh": "wall", "contact": {"friction": 0.3}, "pose": {"position": [0.06, 0, 0.05]}},
      {"name": "shown", "mesh": "ball"}
    ],
    "devices": [{"name": "hand", "driver": "sim-haptic",
                 "config": {"path": "line", "from": [-0.04, 0, 0.02], "to": [0.01, 0, 0.02], "period": 3,
                            "loop": 0}}],
    "engines": {
      "haptics": {"device": "hand", "objects": ["box"], "proxy_object": "shown"},
      "physics": {"rate_hz": 1000}
    },
    "outputs": {"forces": true, "summary": true}
  })");
  j["engines"]["haptics"]["renderer"] = renderer;
  if (renderer == "vps")
    j["engines"]["haptics"]["vps"] = {{"tool", "ball"}, {"coupling_stiffness", 500}, {"voxel_size", 0.0005}};
  else
    j["engines"]["haptics"]["sphere_tree"] = {{"tool", "ball"}, {"stiffness", 500}};
  return j;
}

void expectPushedBoxBalancesTheHand(const std::string& renderer) {
  const dm::test::TempDir dir("tool_push_" + renderer);
  const json s = scene_run::runScene(parsed(pushScene(renderer)), 4.0, dir.path());
  ASSERT_TRUE(s.contains("physics")) << s.dump(2);
  const json& b = scene_run::named(s["physics"]["bodies"], "box");
  const dm::Vec3 x = scene_run::vec(b["position_m"]);
  EXPECT_NEAR(x.x(), 0.03, 1e-3) << "the box is not at the wall: " << s.dump(2);
  EXPECT_NEAR(x.y(), 0.0, 1e-3);
  EXPECT_LT(scene_run::vec(b["velocity_m_s"]).norm(), 1e-3) << "the box is not at rest";
  const dm::Vec3 hand = scene_run::vec(s["haptics"]["final_force_N"]);
  ASSERT_GT(hand.norm(), 1.0) << "the hand no longer presses";
  const dm::Vec3 expected = scene_run::vec(b["contact_force_N"]) + dm::Vec3(0, 0, -0.2 * 9.80665);
  EXPECT_LE((hand - expected).norm(), 0.01 * hand.norm())
      << renderer << ": hand " << hand.transpose() << ", table + weight " << expected.transpose();
  // The push went into the box: the impulse it received is along +x.
  EXPECT_GT(scene_run::vec(b["tool_impulse_Ns"]).x(), 0.5);
}

TEST(SceneVps, TheToolPushesARigidBoxAndTheHandFeelsWhatTheTableHolds) {
  expectPushedBoxBalancesTheHand("vps");
}

TEST(SceneSphereTree, TheToolPushesARigidBoxAndTheHandFeelsWhatTheTableHolds) {
  expectPushedBoxBalancesTheHand("sphere-tree");
}

TEST(SceneVps, MisuseIsRefusedNamingTheKey) {
  auto errorsOf = [](const json& j) {
    std::vector<dm::Error> problems;
    EXPECT_FALSE(dm::parseScene(j.dump(), "vps.json", ".", &problems));
    return dm::formatSceneErrors(problems);
  };
  json j = pressScene();
  j["engines"]["haptics"].erase("vps");
  EXPECT_NE(errorsOf(j).find("engines/haptics/vps"), std::string::npos) << errorsOf(j);
  j = pressScene();
  j["engines"]["haptics"]["vps"]["tool"] = "nothing";
  EXPECT_NE(errorsOf(j).find("engines/haptics/vps/tool"), std::string::npos);
  j = pressScene();
  j["materials"]["steel"]["haptic"]["static_friction"] = 0.3;
  j["materials"]["steel"]["haptic"]["dynamic_friction"] = 0.2;
  EXPECT_NE(errorsOf(j).find("no friction"), std::string::npos) << errorsOf(j);
  j = pressScene();
  j["engines"]["haptics"]["tool_radius"] = 0.002;
  EXPECT_NE(errorsOf(j).find("engines/haptics/tool_radius"), std::string::npos);
  j = pressScene();
  j["engines"]["haptics"]["renderer"] = "god-object";
  EXPECT_NE(errorsOf(j).find("belongs to the vps renderer"), std::string::npos);
  j = pressScene();
  j["engines"]["haptics"]["sphere_tree"] = {{"tool", "cube"}, {"tool_level", 7}, {"tool_levels", 5}};
  EXPECT_NE(errorsOf(j).find("belongs to the sphere-tree renderer"), std::string::npos) << errorsOf(j);
  EXPECT_NE(errorsOf(j).find("sphere_tree/tool_level"), std::string::npos) << errorsOf(j);
  // Round trip of every key.
  const dm::SceneDesc scene = parsed(pressScene());
  auto back = dm::parseScene(dm::toJson(scene).dump(), "vps.json", ".");
  ASSERT_TRUE(back) << back.error();
  EXPECT_EQ(back->engines.haptics, scene.engines.haptics);
}

}  // namespace scene_6dof_test
