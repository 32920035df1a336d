// A scene with the burr renderer run end to end: a scripted stylus lowers
// a 2 mm ball burr onto a bone plate (10 x 10 x 4 mm) above a critical
// structure. Without rotation the burr is a rigid probe (Hooke's law, no
// removal, the distance to the structure as geometry gives it); spinning,
// it drills, the material removed plus what remains is what there was,
// the render engine draws the drilled surface, and lockstep reruns are
// bit-identical. A bone from a CT: a scan of a block (partial-volume
// voxels) and the generated calvarium phantom (a curved vault).
#include <dm/core/volume.hpp>
#include <dm/engine/scene_runtime.hpp>
#include <dm/io/scene_file.hpp>
#include <dm/io/volume_io.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <sstream>
#include <string>
#include <vector>

#include "../DMIO/scene_test_support.hpp"

namespace scene_burr_test {

namespace fs = std::filesystem;

// The plate's top face is at z = 2 mm, the structure's top at z = 0.5 mm.
// The stylus (no virtual hand) moves along z from 4.5 mm down to 0 and back
// every 4 s: 2.25 mm/s.
std::string sceneJson(double rpm, bool render) {
  std::string s = R"({
  "format": "dmplatform-scene", "version": 2, "name": "drill",
  "resources": {
    "plate": {"type": "shape", "shape": "box", "half_extents": [0.005, 0.005, 0.002], "subdivisions": 1},
    "nerve": {"type": "shape", "shape": "box", "half_extents": [0.003, 0.003, 0.0005], "subdivisions": 1},
    "ball": {"type": "shape", "shape": "sphere", "radius": 0.001, "subdivisions": 2}
  },
  "materials": {
    "bone": {"model": "blinn-phong", "color": [0.9, 0.85, 0.7], "haptic": {"stiffness": 1500}}
  },
  "objects": [
    {"name": "skull", "mesh": "plate", "material": "bone", "haptic": true,
     "millable": {"voxel_size": 0.00025, "hardness": 5e7}},
    {"name": "nerve", "mesh": "nerve", "pose": {"position": [0, 0, 0]}, "critical": {"hardness": 1e7}},
    {"name": "tool", "mesh": "ball"}
  ],
  "cameras": [{"name": "side", "position": [0.02, -0.02, 0.02], "target": [0, 0, 0], "up": [0, 0, 1]}],
  "devices": [{"name": "stylus", "driver": "sim-haptic",
               "config": {"path": "line", "from": [0, 0, 0.0045], "to": [0, 0, 0.0], "period": 4, "max_force": 8}}],
  "engines": {
    "haptics": {"rate_hz": 1000, "renderer": "burr", "device": "stylus", "objects": ["skull"],
                "proxy_object": "tool",
                "burr": {"shape": "sphere", "radius": 0.001, "rpm": )" +
                  std::to_string(rpm) + R"(, "walk": 0, "vibration": 0, "warning_distance": 0.002}},)";
  if (render)
    s += R"(
    "render": {"rate_hz": 10, "camera": "side", "width": 96, "height": 64},)";
  s += R"(
    "monitor": {"rate_hz": 30}
  },
  "outputs": {"frames": )";
  s += render ? "true" : "false";
  s += R"(, "forces": true, "plot": false, "summary": true}
})";
  return s;
}

// With `softTop` > 0, the plate's top 1.8 mm are an inclusion of that hardness (Pa).
nlohmann::json sceneDoc(double rpm, bool render, double softTop = 0) {
  nlohmann::json j = nlohmann::json::parse(sceneJson(rpm, render));
  if (softTop > 0) {
    j["resources"]["layer"] = {{"type", "shape"}, {"shape", "box"}, {"half_extents", {0.005, 0.005, 0.0009}}};
    j["objects"].push_back({{"name", "soft"},
                            {"mesh", "layer"},
                            {"pose", {{"position", {0, 0, 0.0011}}}},
                            {"inclusion", {{"hardness", softTop}}}});
  }
  return j;
}

// Runs scene `j` (relative paths under `dir`) in lockstep for `seconds`
// into `out`, emptied first; its summary.json, or null after a failure.
nlohmann::json runScene(const nlohmann::json& j, const fs::path& dir, const fs::path& out, double seconds) {
  fs::remove_all(out);
  auto scene = dm::parseScene(j.dump(), "drill.json", dir);
  EXPECT_TRUE(scene) << (scene ? "" : scene.error().message());
  if (!scene) return {};
  auto rt = dm::SceneRuntime::create(*scene);
  EXPECT_TRUE(rt) << rt.error();
  if (!rt) return {};
  auto r = (*rt)->run({.mode = dm::RunMode::Lockstep, .duration = seconds, .outDir = out});
  EXPECT_TRUE(r) << r.error();
  return r ? r->summary : nlohmann::json();
}

nlohmann::json run(double rpm, bool render, const fs::path& out, double seconds = 1.5, double softTop = 0) {
  return runScene(sceneDoc(rpm, render, softTop), fs::temp_directory_path(), out, seconds);
}

std::string readAll(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

TEST(SceneBurr, AStillBurrIsARigidProbeThatMeasuresItsDistanceToTheNerve) {
  const nlohmann::json s = run(0.0, false, fs::temp_directory_path() / "dm_scene_burr_test" / "still");
  ASSERT_TRUE(s.contains("burr"));
  const nlohmann::json& b = s["burr"];
  // The plate, 10 x 10 x 4 mm, with the nerve's part inside the plate's grid.
  EXPECT_NEAR(b["initial_m3"].get<double>(), 4.0e-7, 0.02 * 4.0e-7);
  EXPECT_EQ(b["removed_total_m3"].get<double>(), 0.0);
  // At 1.5 s the stylus is at z = 1.125 mm, the ball held on the face with
  // its centre at 3 mm: 1.875 mm of spring at 1500 N/m.
  EXPECT_NEAR(s["haptics"]["max_force_N"].get<double>(), 1500 * 1.875e-3, 0.03 * 2.8125);
  // Ball bottom at 2 mm, nerve top at 0.5 mm.
  EXPECT_NEAR(b["closest_approach_m"].get<double>(), 1.5e-3, 0.15e-3);
  // Nearer than 2 mm once the stylus is below 3.5 mm: from 0.444 s on.
  EXPECT_NEAR(b["seconds_within_warning"].get<double>(), 1.5 - 1.0 / 2.25, 0.07);
  EXPECT_EQ(b["removed_forbidden_m3"].get<double>(), 0.0);
}

TEST(SceneBurr, ASpinningBurrDrillsTheHoleTheRendererDraws) {
  const fs::path out = fs::temp_directory_path() / "dm_scene_burr_test" / "spin";
  const nlohmann::json s = run(80000.0, true, out);
  ASSERT_TRUE(s.contains("burr"));
  const nlohmann::json& b = s["burr"];
  const double removed = b["removed_total_m3"].get<double>();
  EXPECT_GT(removed, 0.1e-9);  // at least 0.1 mm³
  // Per material, the same removal summed in another order.
  EXPECT_NEAR(b["removed_m3"]["bone"].get<double>() + b["removed_m3"]["nerve"].get<double>(), removed,
              1e-12 * removed);
  // Nothing is lost: what remains and what was removed is what there was.
  EXPECT_NEAR(b["remaining_m3"].get<double>() + removed, b["initial_m3"].get<double>(),
              1e-9 * b["initial_m3"].get<double>());
  // The drilled blocks went to the render engine, which drew every frame.
  EXPECT_GT(b["surface_blocks_sent"].get<double>(), 0.0);
  EXPECT_EQ(s["render"]["frames_written"].get<int>(), 15);
  EXPECT_TRUE(fs::exists(out / "frames" / "frame_00014.png"));
  // Drilling lets the burr go deeper than the still probe, so it comes nearer the nerve.
  EXPECT_LT(b["closest_approach_m"].get<double>(), 1.45e-3);
}

TEST(SceneBurr, ASofterLayerIsDrilledFasterAndAccountedByName) {
  const fs::path base = fs::temp_directory_path() / "dm_scene_burr_test";
  const nlohmann::json hard = run(80000.0, false, base / "hard");
  const nlohmann::json soft = run(80000.0, false, base / "soft", 1.5, 2.5e7);  // half the bone's hardness
  const double hardRemoved = hard["burr"]["removed_total_m3"].get<double>();
  const nlohmann::json& s = soft["burr"];
  // The burr stays in the top layer: all it removes is the layer's.
  EXPECT_GT(s["removed_m3"]["soft"].get<double>(), 0.99 * s["removed_total_m3"].get<double>());
  // Archard: removal goes as force / hardness. The stylus follows its path
  // whatever the force, so the burr removes about what the path sweeps in
  // both, and the softer layer lets it through with less force.
  EXPECT_GE(s["removed_total_m3"].get<double>(), hardRemoved);
  EXPECT_LT(soft["haptics"]["max_force_N"].get<double>(), 0.8 * hard["haptics"]["max_force_N"].get<double>());
  EXPECT_NEAR(s["initial_m3"].get<double>(), hard["burr"]["initial_m3"].get<double>(),
              1e-6 * hard["burr"]["initial_m3"].get<double>());
}

TEST(SceneBurr, LockstepDrillingIsBitReproducible) {
  const fs::path a = fs::temp_directory_path() / "dm_scene_burr_test" / "r1";
  const fs::path c = fs::temp_directory_path() / "dm_scene_burr_test" / "r2";
  const nlohmann::json sa = run(80000.0, false, a, 1.0), sc = run(80000.0, false, c, 1.0);
  const std::string fa = readAll(a / "forces.csv"), fc = readAll(c / "forces.csv");
  EXPECT_GT(fa.size(), 1000u);
  EXPECT_EQ(fa, fc);
  EXPECT_EQ(sa["burr"]["removed_total_m3"], sc["burr"]["removed_total_m3"]);
}

// A CT-like scan (int16 HU, 0.25 mm voxels) of a bone block x, y in
// [-5.125, 5.125] mm, z in [-2, 2.5] mm in soft tissue (40 HU), each voxel
// the partial-volume mix 40 + 1460 * (fraction of the voxel inside the
// block): its side faces cut voxels in half, its top and bottom lie on
// voxel faces.
fs::path writeCtBlock(const fs::path& dir) {
  constexpr double h = 0.25e-3;
  dm::Affine3 a = dm::Affine3::Identity();
  a.linear() *= h;
  a.translation() = dm::Vec3(-5.875e-3, -5.875e-3, -2.875e-3);
  auto v = dm::Volume::create(dm::Vec3i(48, 48, 24), dm::VoxelType::I16, a);
  EXPECT_TRUE(v);
  auto cover = [&](double c, double lo, double hi) {
    return std::clamp((std::min(c + h / 2, hi) - std::max(c - h / 2, lo)) / h, 0.0, 1.0);
  };
  for (int k = 0; k < 24; ++k)
    for (int j = 0; j < 48; ++j)
      for (int i = 0; i < 48; ++i) {
        const dm::Vec3 c = a * dm::Vec3(i, j, k);
        const double f = cover(c.x(), -5.125e-3, 5.125e-3) * cover(c.y(), -5.125e-3, 5.125e-3) *
                         cover(c.z(), -2e-3, 2.5e-3);
        v->setValue(i, j, k, 40.0 + 1460.0 * f);
      }
  fs::create_directories(dir);
  const fs::path file = dir / "block_ct.nrrd";
  auto s = dm::writeVolume(*v, file);
  EXPECT_TRUE(s) << s.error();
  return file;
}

TEST(SceneBurr, ABoneFromACtScanIsItsVoxelsByThePartialVolumeLaw) {
  const fs::path dir = fs::temp_directory_path() / "dm_scene_burr_test" / "ct";
  const fs::path ct = writeCtBlock(dir);
  nlohmann::json j = nlohmann::json::parse(sceneJson(0.0, false));
  j["resources"]["ct"] = {{"type", "volume"}, {"source", ct.string()}};
  j["resources"]["ct_surface"] = {{"type", "isosurface"}, {"volume", "ct"}, {"level", 770}};
  j["objects"][0]["mesh"] = "ct_surface";
  j["objects"][0]["millable"] = {{"volume", "ct"}, {"empty", 40}, {"full", 1500}, {"hardness", 5e7}};
  const nlohmann::json s = runScene(j, dir, dir / "out", 1.5);
  ASSERT_TRUE(s.contains("burr"));
  const nlohmann::json& b = s["burr"];
  // On the scan's own grid, and every partial voxel counted by its fraction:
  // 10.25 x 10.25 x 4.5 mm.
  EXPECT_NEAR(b["voxel_size_m"].get<double>(), 0.25e-3, 1e-12);
  EXPECT_EQ(b["dims"], nlohmann::json({48, 48, 24}));
  EXPECT_NEAR(b["initial_m3"].get<double>(), 10.25e-3 * 10.25e-3 * 4.5e-3, 1e-6 * 4.728e-7);
  // The still ball rests on the top at 2.5 mm, its centre at 3.5 mm, the
  // stylus at 1.125 mm: 2.375 mm of spring at 1500 N/m.
  EXPECT_NEAR(s["haptics"]["max_force_N"].get<double>(), 1500 * 2.375e-3, 0.03 * 3.5625);
  // Ball bottom at 2.5 mm, the nerve's top at 0.5 mm.
  EXPECT_NEAR(b["closest_approach_m"].get<double>(), 2.0e-3, 0.15e-3);
  EXPECT_EQ(b["removed_total_m3"].get<double>(), 0.0);
}

// The still burr pressed along the vault's normal 6° off the apex of the
// calvarium phantom (a uniform 6 mm shell of radius 90 mm, every soft
// tissue at the scan's "empty" value so the partial-volume law is exact):
// the ball rests on the curved outer table with its centre on the ray, the
// force along the vault's normal, Hooke's law for its magnitude, and the
// distance to a vessel under the inner table on the same ray is the
// skull's thickness.
TEST(SceneBurr, AStillBurrRestsOnTheCurvedVaultOfTheCalvariumPhantom) {
  const fs::path dir = fs::temp_directory_path() / "dm_scene_burr_test" / "phantom";
  constexpr double R = 0.09, inner = 0.084, rb = 0.001, rv = 0.002;
  const double theta = 6.0 * std::numbers::pi / 180.0;
  const dm::Vec3 c(0, 0, -R), n(std::sin(theta), 0, std::cos(theta));
  auto at = [&](double radius) {
    const dm::Vec3 p = c + radius * n;
    return nlohmann::json{p.x(), p.y(), p.z()};
  };
  nlohmann::json j = nlohmann::json::parse(sceneJson(0.0, false));
  j["resources"]["ct"] = nlohmann::json::parse(R"({"type": "volume", "phantom": {
      "kind": "calvarium", "half_width": 0.016, "below": 0.012, "texture_hu": 0,
      "hu": {"air": 40, "soft_tissue": 40, "dura": 40, "brain": 40, "cortical": 1500, "diploe": 1500}}})");
  j["resources"]["ct_surface"] = {{"type", "isosurface"}, {"volume", "ct"}, {"level", 770}};
  j["resources"]["vessel"] = {{"type", "shape"}, {"shape", "cylinder"}, {"radius", rv}, {"height", 0.03}};
  j["objects"][0]["mesh"] = "ct_surface";
  j["objects"][0]["millable"] = {{"volume", "ct"}, {"empty", 40}, {"full", 1500}, {"hardness", 5e7}};
  // The vessel along y, touching the inner table from below on the ray.
  j["objects"][1] = {{"name", "vessel"},
                     {"mesh", "vessel"},
                     {"pose", {{"position", at(inner - rv)}, {"euler_deg", {90, 0, 0}}}},
                     {"critical", {{"hardness", 1e7}}}};
  // The stylus from 4.5 mm above the vault to 2 mm into it along the ray in 2 s.
  j["devices"][0]["config"]["from"] = at(R + 0.0045);
  j["devices"][0]["config"]["to"] = at(R - 0.002);
  const nlohmann::json summary = runScene(j, dir, dir / "out", 1.5);
  ASSERT_TRUE(summary.contains("burr"));
  const nlohmann::json& b = summary["burr"];
  EXPECT_NEAR(b["voxel_size_m"].get<double>(), 0.3e-3, 1e-12);
  EXPECT_EQ(b["dims"], nlohmann::json({107, 107, 67}));
  EXPECT_EQ(b["removed_total_m3"].get<double>(), 0.0);
  // At 1.5 s the stylus is 0.375 mm inside the vault, the ball's centre 1 mm
  // outside it: 1.375 mm of spring at 1500 N/m.
  const double want = 1500 * 1.375e-3;
  EXPECT_NEAR(summary["haptics"]["max_force_N"].get<double>(), want, 0.03 * want);
  // The last tick: the force along the normal, the ball on the vault.
  std::istringstream csv(readAll(dir / "out" / "forces.csv"));
  std::string line, last;
  while (std::getline(csv, line))
    if (!line.empty()) last = line;
  std::vector<double> v;
  std::istringstream fields(last);
  for (std::string f; std::getline(fields, f, ',');) v.push_back(std::stod(f));
  ASSERT_GE(v.size(), 10u);
  const dm::Vec3 force(v[1], v[2], v[3]), proxy(v[7], v[8], v[9]);
  EXPECT_GT(force.norm(), 0.95 * want);
  EXPECT_LT(std::acos(std::clamp(force.normalized().dot(n), -1.0, 1.0)) * 180.0 / std::numbers::pi, 2.0);
  EXPECT_NEAR((proxy - c).norm(), R + rb, 0.05e-3);  // within a sixth of a voxel of the true vault
  EXPECT_LT((proxy - c).normalized().cross(n).norm(), std::sin(0.5 * std::numbers::pi / 180.0));
  // Ball bottom on the vault, the vessel's top 6 mm below it on the ray.
  EXPECT_NEAR(b["closest_approach_m"].get<double>(), R - inner, 0.15e-3);
}

// The bundled burr hole on the generated calvarium (examples/scenes/
// burr_hole_ct.json), haptics alone for 3 s of its spiral: the burr drills
// bone and nothing else, the bone's books balance, and it stays as far from
// the sagittal sinus as its path allows — the spiral keeps the burr's centre
// at least 10 − 1.5 mm lateral, the sinus reaches 4 mm from the midline and
// the burr's radius is 2.5 mm: at least 2 mm between their surfaces.
TEST(SceneBurr, TheBundledCalvariumBurrHoleDrillsBoneBesideTheSinus) {
  const fs::path file = scene_test::sourceDir() / "examples/scenes/burr_hole_ct.json";
  std::ifstream in(file);
  ASSERT_TRUE(in.good()) << file;
  nlohmann::json j = nlohmann::json::parse(in);
  j["engines"].erase("render");
  j["outputs"] = {{"frames", false}, {"forces", false}, {"plot", false}, {"summary", true}};
  const nlohmann::json s =
      runScene(j, file.parent_path(), fs::temp_directory_path() / "dm_scene_burr_test" / "bundled_ct", 3.0);
  ASSERT_TRUE(s.contains("burr"));
  const nlohmann::json& b = s["burr"];
  EXPECT_EQ(b["dims"], nlohmann::json({80, 80, 55}));  // 32 mm across, 22 mm deep at 0.4 mm
  const double removed = b["removed_total_m3"].get<double>();
  EXPECT_GT(removed, 1e-9);  // at least 1 mm³ of bone
  EXPECT_NEAR(b["removed_m3"]["bone"].get<double>(), removed, 1e-12 * removed);
  EXPECT_EQ(b["removed_m3"]["sinus"].get<double>(), 0.0);
  EXPECT_EQ(b["removed_forbidden_m3"].get<double>(), 0.0);
  EXPECT_NEAR(b["remaining_m3"].get<double>() + removed, b["initial_m3"].get<double>(),
              1e-9 * b["initial_m3"].get<double>());
  EXPECT_GE(b["closest_approach_m"].get<double>(), 2.0e-3 - 0.15e-3);
  EXPECT_EQ(b["seconds_within_warning"].get<double>(), 0.0);
}

}  // namespace scene_burr_test
