// The scene runtime end to end: a touchable box pressed by a scripted
// device, run in lockstep; forces against Hooke's law on the god-object,
// outputs on disk, bit-identical reruns, and Ctrl-C style interruption.
#include <dm/core/filesystem.hpp>
#include <dm/core/rt_memory.hpp>
#include <dm/engine/scene_runtime.hpp>
#include <dm/io/image_io.hpp>
#include <dm/io/scene_file.hpp>

#include <gtest/gtest.h>

#include <atomic>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <sstream>
#include <string>

namespace {

namespace fs = std::filesystem;

// A 10 cm box whose top face is at z = 5 cm; the stylus (no virtual hand:
// it follows the script exactly) sweeps along z from 6 cm to 4 cm and back
// every 2 s, so it presses 1 cm into the face at the bottom of the sweep.
std::string sceneJson(bool render) {
  std::string s = R"({
  "format": "dmplatform-scene", "version": 1, "name": "press",
  "resources": {
    "box": {"type": "shape", "shape": "box", "half_extents": [0.05, 0.05, 0.05]},
    "ball": {"type": "shape", "shape": "sphere", "radius": 0.003, "subdivisions": 2}
  },
  "materials": {
    "tissue": {"model": "blinn-phong", "color": [0.8, 0.5, 0.4],
               "haptic": {"stiffness": 500, "damping": 0, "static_friction": 0, "dynamic_friction": 0}}
  },
  "objects": [
    {"name": "block", "mesh": "box", "material": "tissue", "haptic": true},
    {"name": "tool", "mesh": "ball"}
  ],
  "cameras": [{"name": "side", "position": [0.3, -0.3, 0.2], "target": [0, 0, 0.03], "up": [0, 0, 1]}],
  "devices": [{"name": "stylus", "driver": "sim-haptic",
               "config": {"path": "line", "from": [0, 0, 0.06], "to": [0, 0, 0.04], "period": 2, "max_force": 8}}],
  "engines": {
    "haptics": {"rate_hz": 1000, "renderer": "god-object", "device": "stylus", "objects": ["block"],
                "proxy_object": "tool"},)";
  if (render)
    s += R"(
    "render": {"rate_hz": 10, "camera": "side", "width": 96, "height": 64, "samples": 1},)";
  s += R"(
    "monitor": {"rate_hz": 30}
  },
  "outputs": {"frames": )";
  s += render ? "true" : "false";
  s += R"(, "forces": true, "plot": true, "summary": true}
})";
  return s;
}

dm::SceneDesc parse(bool render) {
  auto s = dm::parseScene(sceneJson(render), "press.json", fs::temp_directory_path());
  EXPECT_TRUE(s) << (s ? "" : s.error().message());
  return *s;
}

std::string readAll(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

}  // namespace

TEST(SceneRuntime, PressingABoxFollowsHookesLawAndWritesOutputs) {
  const fs::path out = fs::temp_directory_path() / "dm_scene_runtime_test" / "a";
  fs::remove_all(out);
  auto rt = dm::SceneRuntime::create(parse(true));
  ASSERT_TRUE(rt) << rt.error();
  auto r = (*rt)->run({.mode = dm::RunMode::Lockstep, .duration = 2.0, .outDir = out});
  ASSERT_TRUE(r) << r.error();
  EXPECT_FALSE(r->interrupted);
  const nlohmann::json& s = r->summary;
  // 1 cm deep at 500 N/m: 5 N at the bottom of the sweep, straight up.
  EXPECT_NEAR(s["haptics"]["max_force_N"].get<double>(), 5.0, 0.1);
  EXPECT_NEAR(s["haptics"]["max_depth_m"].get<double>(), 0.01, 2e-4);
  // In contact while below z = 5 cm: half of the sweep.
  const auto contact = s["haptics"]["contact_ticks"].get<double>();
  EXPECT_NEAR(contact / s["haptics"]["ticks"].get<double>(), 0.5, 0.02);
  for (const auto& e : s["engines"]) {
    if (e["name"] == "haptics") {
      EXPECT_EQ(e["ticks"].get<int>(), 2000);
    }
    if (e["name"] == "render") {
      EXPECT_EQ(e["ticks"].get<int>(), 20);
    }
  }
  EXPECT_EQ(s["render"]["frames_written"].get<int>(), 20);
  EXPECT_TRUE(fs::exists(out / "forces.csv"));
  EXPECT_TRUE(fs::exists(out / "forces.png"));
  EXPECT_TRUE(fs::exists(out / "summary.json"));
  auto frame = dm::readPng(out / "frames" / "frame_00019.png");
  ASSERT_TRUE(frame) << frame.error();
  EXPECT_EQ(frame->width(), 96);
  EXPECT_EQ(frame->height(), 64);
  // The summary on disk is the one returned.
  EXPECT_EQ(nlohmann::json::parse(readAll(out / "summary.json"))["haptics"], s["haptics"]);
}

TEST(SceneRuntime, LockstepRunsAreBitIdentical) {
  const fs::path a = fs::temp_directory_path() / "dm_scene_runtime_test" / "r1";
  const fs::path b = fs::temp_directory_path() / "dm_scene_runtime_test" / "r2";
  for (const auto& out : {a, b}) {
    fs::remove_all(out);
    auto rt = dm::SceneRuntime::create(parse(false));
    ASSERT_TRUE(rt) << rt.error();
    auto r = (*rt)->run({.mode = dm::RunMode::Lockstep, .duration = 1.0, .outDir = out});
    ASSERT_TRUE(r) << r.error();
  }
  const std::string fa = readAll(a / "forces.csv"), fb = readAll(b / "forces.csv");
  EXPECT_GT(fa.size(), 1000u);
  EXPECT_EQ(fa, fb);
}

TEST(SceneRuntime, StopFlagEndsEarlyAndStillWritesOutputs) {
  const fs::path out = fs::temp_directory_path() / "dm_scene_runtime_test" / "stop";
  fs::remove_all(out);
  auto rt = dm::SceneRuntime::create(parse(false));
  ASSERT_TRUE(rt) << rt.error();
  std::atomic<bool> stop{false};
  int calls = 0;
  auto r = (*rt)->run({.mode = dm::RunMode::Lockstep,
                       .duration = 100.0,
                       .outDir = out,
                       .progress = [&](double, const std::string&) { stop = ++calls >= 3; },
                       .stop = &stop});
  ASSERT_TRUE(r) << r.error();
  EXPECT_TRUE(r->interrupted);
  EXPECT_NEAR(r->simulatedSeconds, 0.3, 1e-9);
  EXPECT_TRUE(fs::exists(out / "summary.json"));
  EXPECT_TRUE(nlohmann::json::parse(readAll(out / "summary.json"))["interrupted"].get<bool>());
  // A runtime runs once.
  EXPECT_FALSE((*rt)->run({.duration = 1.0, .outDir = out}));
}

TEST(SceneRuntime, ErrorsNameTheSceneEntry) {
  auto bad = dm::SceneRuntime::load(fs::temp_directory_path() / "no_such_scene.json");
  ASSERT_FALSE(bad);
  dm::SceneDesc scene = parse(false);
  scene.devices[0].driver = "no-such-driver";
  auto rt = dm::SceneRuntime::create(scene);
  ASSERT_TRUE(rt) << rt.error();
  auto r =
      (*rt)->run({.duration = 0.1, .outDir = fs::temp_directory_path() / "dm_scene_runtime_test" / "bad"});
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().where.find("devices/stylus"), std::string::npos) << r.error();
  // A touchable object whose material has no haptic block.
  scene = parse(false);
  scene.materials[0].haptic.reset();
  rt = dm::SceneRuntime::create(scene);
  ASSERT_TRUE(rt);
  r = (*rt)->run({.duration = 0.1, .outDir = fs::temp_directory_path() / "dm_scene_runtime_test" / "bad"});
  ASSERT_FALSE(r);
  EXPECT_EQ(r.error().where, "objects/block/material");
}

// A real-time run holds the process's memory in RAM while it runs (where
// the process may lock it: as it may after the run) and lets go after; the
// summary says so, with the page faults the run took. Lockstep locks nothing.
TEST(SceneRuntime, ARealTimeRunLocksTheMemoryWhileItRuns) {
  const fs::path out = fs::temp_directory_path() / "dm_scene_runtime_test" / "locked";
  auto rt = dm::SceneRuntime::create(parse(false));
  ASSERT_TRUE(rt) << rt.error();
  auto r = (*rt)->run({.mode = dm::RunMode::RealTime, .duration = 0.3, .outDir = out});
  ASSERT_TRUE(r) << r.error();
  EXPECT_FALSE(dm::processMemoryLocked()) << "unlocked after the run";
  const dm::Status canLock = dm::lockProcessMemory();
  dm::unlockProcessMemory();
  const nlohmann::json& host = r->summary["host"];
  EXPECT_EQ(host["memory_locked"].get<bool>(), static_cast<bool>(canLock)) << host.dump();
  EXPECT_GE(host["page_faults_minor"].get<std::int64_t>(), 0);
  EXPECT_GE(host["page_faults_major"].get<std::int64_t>(), 0);

  rt = dm::SceneRuntime::create(parse(false));
  ASSERT_TRUE(rt) << rt.error();
  r = (*rt)->run({.mode = dm::RunMode::Lockstep, .duration = 0.1, .outDir = out});
  ASSERT_TRUE(r) << r.error();
  EXPECT_FALSE(r->summary["host"]["memory_locked"].get<bool>());
}

#ifdef DM_TEST_WITH_NETWORK
// Both ends of a tele-operation link in one scene: the scripted stylus is
// served (devices/stylus/serve) and the haptic engine drives it through
// net-haptic over loopback UDP. The presses reach the simulator and the
// forces reach the stylus: up to 5 N at the bottom of the sweep, the same
// on both sides.
TEST(SceneRuntime, ServedDeviceIsDrivenOverTheNetwork) {
  dm::SceneDesc scene = parse(false);
  scene.devices[0].serve = dm::SceneDeviceServe{};
  scene.devices.push_back(
      {.name = "remote", .driver = "net-haptic", .config = {{"device", "@stylus"}, {"wait_for_state", 2}}});
  scene.engines.haptics->device = "remote";
  const fs::path out = fs::temp_directory_path() / "dm_scene_runtime_test" / "teleop";

  // Lockstep: the link is the in-process one on the virtual clock. The
  // console ticks before the haptics engine, which reads its state in the
  // same tick and answers with a force the console gets one tick later: a
  // round trip of exactly one period. Two runs give the same forces.
  std::string lockstepForces[2];
  for (std::string& forces : lockstepForces) {
    auto rt = dm::SceneRuntime::create(scene);
    ASSERT_TRUE(rt) << rt.error();
    auto r = (*rt)->run({.mode = dm::RunMode::Lockstep, .duration = 1.5, .outDir = out});
    ASSERT_TRUE(r) << r.error();
    const nlohmann::json& t = r->summary["teleop"][0];
    EXPECT_EQ(t["transport"], "inproc");
    EXPECT_EQ(t["address"], "inproc:stylus");
    EXPECT_GE(t["received"].get<int>(), 1499);  // every haptic tick's force but the last
    EXPECT_NEAR(t["round_trip"]["p50_ms"].get<double>(), 1.0, 0.016);
    EXPECT_NEAR(t["round_trip"]["max_ms"].get<double>(), 1.0, 0.016);
    const double maxForce = r->summary["haptics"]["max_force_N"].get<double>();
    EXPECT_GT(maxForce, 2.0);
    EXPECT_NEAR(t["max_output_force_N"].get<double>(), maxForce, 1e-9);
    std::ifstream csv(out / "forces.csv");
    forces.assign(std::istreambuf_iterator<char>(csv), std::istreambuf_iterator<char>());
  }
  EXPECT_GT(lockstepForces[0].size(), 1500u * 20);
  EXPECT_EQ(lockstepForces[0], lockstepForces[1]);

  auto rt = dm::SceneRuntime::create(scene);
  ASSERT_TRUE(rt) << rt.error();
  auto r = (*rt)->run({.mode = dm::RunMode::RealTime, .duration = 1.5, .outDir = out});
  ASSERT_TRUE(r) << r.error();
  const nlohmann::json& s = r->summary;
  // Hooke's law bounds the force (real-time overruns on a loaded machine
  // fade it, never raise it), and the stylus reached the box.
  const double maxForce = s["haptics"]["max_force_N"].get<double>();
  EXPECT_LT(maxForce, 5.0 + 0.1);
  EXPECT_GT(maxForce, 2.0);
  ASSERT_EQ(s["teleop"].size(), 1u) << s.dump(1);
  const nlohmann::json& t = s["teleop"][0];
  EXPECT_EQ(t["device"], "stylus");
  EXPECT_EQ(t["transport"], "udp");
  EXPECT_EQ(t["address"].get<std::string>().rfind("127.0.0.1:", 0), 0u);
  EXPECT_GT(t["received"].get<int>(), 1000);  // a force per haptic tick
  EXPECT_GT(t["round_trip"]["count"].get<int>(), 1000);
  // The stylus displayed what the simulator sent (its largest force may be
  // superseded before a late console tick applies it: within 0.1 N).
  EXPECT_NEAR(t["max_output_force_N"].get<double>(), maxForce, 0.1);
}
#endif
