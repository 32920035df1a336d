// Scripts in a scene run (dm/engine/script.hpp), through a C++ script
// language the test registers (".probe"): a force a script holds on a free
// body moves it as Newton and the integrator say (semi-implicit Euler), its
// torque spins it as the sphere's inertia says; the contact events of the
// bundled box push come at the haptic tick where the hand's force starts in
// forces.csv, on the touched object, and the tool a script reads is that
// tick's; the bundled needle insertion's punctures come as events where the
// hand's force drops after reaching the skin's and the fascia's puncture
// forces, as many as the needle's summary counts; a script's error stops
// the run naming it and its time, with the outputs written; a language
// nobody registered is refused naming the script; a script opens a fluid
// inlet, which then delivers its rate; lockstep reruns match.
#include <dm/core/filesystem.hpp>
#include <dm/engine/scene_runtime.hpp>
#include <dm/engine/script.hpp>
#include <dm/io/scene_file.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "../common/temp_dir.hpp"
#include "scene_run_support.hpp"

namespace scene_script_test {

namespace fs = std::filesystem;
using dm::Vec3;
using nlohmann::json;

// A script whose behaviour its args choose:
//   "push": {"body", "force": [3], "torque": [3]} held from start();
//   "fail_at": s — tick() fails from then on;
//   "tool_at": s — records the tool the tick at that time reads;
// and every event, tick count and the last body state it read as metrics.
class ProbeScript final : public dm::ScriptInstance {
 public:
  explicit ProbeScript(json args) : args_(std::move(args)) {}
  dm::Status start(dm::ScriptContext& c) override {
    if (args_.contains("push")) {
      const json& p = args_["push"];
      return c.setBodyForce(p["body"].get<std::string>(), scene_run::vec(p["force"]),
                            scene_run::vec(p["torque"]));
    }
    return dm::ok();
  }
  dm::Status event(dm::ScriptContext& c, const dm::ScriptEvent& e) override {
    events_.push_back({{"type", std::string(dm::toString(e.type))},
                       {"time", e.time},
                       {"object", e.object},
                       {"layer", e.layer},
                       {"value", e.value},
                       {"seen_at", c.time()}});
    c.setMetric("events", events_);
    return dm::ok();
  }
  dm::Status tick(dm::ScriptContext& c) override {
    if (args_.contains("open_at") && c.time() >= args_["open_at"]["time"].get<double>() && !opened_) {
      const json& o = args_["open_at"];
      opened_ = true;
      if (auto s = c.setInletFlowRate(o["fluid"].get<std::string>(), o["inlet"].get<std::string>(),
                                      o["rate"].get<double>());
          !s)
        return s;
      c.setMetric("opened_at", c.time());
    }
    if (args_.contains("fail_at") && c.time() >= args_["fail_at"].get<double>())
      return dm::fail(dm::ErrorCode::InvalidArgument, "the probe gave up", "probe");
    if (args_.contains("tool_at") && std::abs(c.time() - args_["tool_at"].get<double>()) < 1e-9) {
      EXPECT_TRUE(c.hasTool());
      const dm::ScriptTool t = c.tool();
      c.setMetric(
          "tool",
          {{"time", t.time},
           {"force", {t.force.x(), t.force.y(), t.force.z()}},
           {"proxy", {t.proxy.translation().x(), t.proxy.translation().y(), t.proxy.translation().z()}}});
    }
    for (const std::string& name : c.bodies()) {
      auto b = c.body(name);
      if (!b) return b.error();
      const Vec3 p = b->pose.translation();
      c.setMetric(name, {{"time", c.time()},
                         {"position", {p.x(), p.y(), p.z()}},
                         {"velocity", {b->linearVelocity.x(), b->linearVelocity.y(), b->linearVelocity.z()}},
                         {"angular_velocity",
                          {b->angularVelocity.x(), b->angularVelocity.y(), b->angularVelocity.z()}}});
    }
    ++ticks_;
    return dm::ok();
  }
  dm::Status finish(dm::ScriptContext& c) override {
    c.setMetric("ticks_seen", ticks_);
    c.setMetric("finish_time", c.time());
    return dm::ok();
  }

 private:
  json args_;
  json events_ = json::array();
  int ticks_ = 0;
  bool opened_ = false;
};

// Registers ".probe" for the test's life.
struct ProbeLanguage {
  ProbeLanguage() {
    dm::registerScriptLanguage(".probe", [](const dm::SceneScript& s) {
      return dm::Result<std::unique_ptr<dm::ScriptInstance>>(std::make_unique<ProbeScript>(s.args));
    });
  }
  ~ProbeLanguage() { dm::unregisterScriptLanguage(".probe"); }
};

dm::SceneScript probe(const std::string& engine, json args) {
  dm::SceneScript s;
  s.name = "probe";
  s.source = "probe.probe";
  s.path = "probe.probe";
  s.engine = engine;
  s.args = std::move(args);
  return s;
}

// A 0.1 kg ball of 1 cm radius, free in zero gravity.
dm::SceneDesc freeBall() {
  const std::string text = R"({
    "format": "dmplatform-scene", "version": 2, "name": "free_ball",
    "resources": { "ball": { "type": "shape", "shape": "sphere", "radius": 0.01 } },
    "materials": { "m": { "model": "blinn-phong", "color": [0.5, 0.5, 0.5] } },
    "objects": [ { "name": "ball", "mesh": "ball", "material": "m", "dynamic": true, "mass": 0.1 } ],
    "engines": { "physics": { "rate_hz": 1000, "gravity": [0, 0, 0] } },
    "outputs": { "directory": "out" } })";
  std::vector<dm::Error> problems;
  auto s = dm::parseScene(text, "free_ball.json", ".", &problems);
  EXPECT_TRUE(s) << dm::formatSceneErrors(problems);
  return s ? *s : dm::SceneDesc();
}

// A script opens a closed irrigation nozzle (flow_rate 0 in the scene) at
// 0.5 s: over the 1 s that follows it delivers 20 ml/s × 1 s to the
// particle (the nozzle's jet falls freely, nothing covers its mouth); a
// script naming an inlet the scene does not have stops the run naming it.
TEST(SceneScript, AScriptOpensAFluidInlet) {
  const ProbeLanguage language;
  const dm::test::TempDir tmp("script_inlet");
  const std::string text = R"({
    "format": "dmplatform-scene", "version": 2, "name": "nozzle",
    "engines": { "physics": { "rate_hz": 500 } },
    "fluids": [ { "name": "saline", "spacing": 0.01, "density": 1000,
                  "region": { "min": [-0.1, -0.1, -0.1], "max": [0.3, 0.1, 0.3] },
                  "inlets": [ { "name": "nozzle", "center": [0, 0, 0.2], "normal": [1, 0, 0], "flow_rate": 0 } ] } ],
    "outputs": { "directory": "out" } })";
  std::vector<dm::Error> problems;
  auto parsed = dm::parseScene(text, "nozzle.json", ".", &problems);
  ASSERT_TRUE(parsed) << dm::formatSceneErrors(problems);
  dm::SceneDesc scene = *parsed;
  scene.scripts.push_back(probe(
      "physics", {{"open_at", {{"time", 0.5}, {"fluid", "saline"}, {"inlet", "nozzle"}, {"rate", 2e-5}}}}));
  const json s = scene_run::runScene(scene, 1.5, tmp.path() / "out");
  ASSERT_TRUE(s.contains("physics")) << s.dump(2);
  const json& fluid = scene_run::named(s["physics"]["fluids"], "saline");
  const json& nozzle = scene_run::named(fluid["inlets"], "nozzle");
  const double vp = fluid["particle_volume_m3"].get<double>();
  EXPECT_NEAR(nozzle["volume_m3"].get<double>(), 2e-5, vp + 1e-12);
  EXPECT_DOUBLE_EQ(s["scripts"]["probe"]["metrics"]["opened_at"].get<double>(), 0.5);
  // An inlet the scene does not have.
  dm::SceneDesc wrong = scene;
  wrong.scripts.back().args["open_at"]["inlet"] = "nozle";
  auto rt = dm::SceneRuntime::create(wrong);
  ASSERT_TRUE(rt);
  auto r = (*rt)->run({.mode = dm::RunMode::Lockstep, .duration = 1.0, .outDir = tmp.path() / "wrong"});
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().message().find("no inlet \"nozle\" of a fluid \"saline\""), std::string::npos)
      << r.error();
}

TEST(SceneScript, HeldForceAndTorqueMoveAFreeBodyAsNewtonSays) {
  const ProbeLanguage language;
  const dm::test::TempDir tmp("script_push");
  dm::SceneDesc scene = freeBall();
  const Vec3 force(0.2, 0.0, -0.1), torque(0.0, 0.0, 2e-5);
  scene.scripts.push_back(probe("physics", {{"push",
                                             {{"body", "ball"},
                                              {"force", {force.x(), force.y(), force.z()}},
                                              {"torque", {torque.x(), torque.y(), torque.z()}}}}}));
  const json s = scene_run::runScene(scene, 1.0, tmp.path() / "out");
  ASSERT_TRUE(s.contains("scripts")) << s.dump(2);
  const json& m = s["scripts"]["probe"]["metrics"];
  EXPECT_EQ(s["scripts"]["probe"]["ticks"], 1000);
  EXPECT_EQ(m["ticks_seen"], 1000);
  EXPECT_DOUBLE_EQ(m["finish_time"].get<double>(), 1.0);
  // The script's first tick (t = 0) comes after physics' first step, so the
  // force acts over the n = 999 steps after it. Semi-implicit Euler with
  // h = 1 ms: v_n = a h n, x_n = a h² n (n + 1) / 2; ω_n = (τ / I) h n.
  const double h = 1e-3, n = 999, mass = 0.1, inertia = 0.4 * mass * 0.01 * 0.01;
  const Vec3 a = force / mass;
  const json& ball = scene_run::named(s["physics"]["bodies"], "ball");
  const Vec3 x = scene_run::vec(ball["position_m"]), v = scene_run::vec(ball["velocity_m_s"]);
  const Vec3 w = scene_run::vec(ball["angular_velocity_rad_s"]);
  EXPECT_LT((v - a * h * n).norm(), 1e-12 * a.norm()) << v.transpose();
  EXPECT_LT((x - a * h * h * n * (n + 1) / 2).norm(), 1e-9) << x.transpose();
  EXPECT_NEAR(w.z(), torque.z() / inertia * h * n, 1e-9);
  // The script's last tick read the state physics left at the end.
  EXPECT_EQ(scene_run::vec(m["ball"]["position"]), x);
  EXPECT_EQ(scene_run::vec(m["ball"]["velocity"]), v);
  // Bit-identical rerun.
  const json again = scene_run::runScene(scene, 1.0, tmp.path() / "again");
  EXPECT_EQ(again["scripts"], s["scripts"]);
  EXPECT_EQ(again["physics"]["bodies"], s["physics"]["bodies"]);
}

TEST(SceneScript, ContactEventsComeAtTheTickTheHandsForceStarts) {
  const ProbeLanguage language;
  const dm::test::TempDir tmp("script_contact");
  dm::SceneDesc scene = scene_run::bundledScene("box_push.json");
  scene.outputs.recording = false;
  scene.outputs.forces = true;
  scene.scripts.push_back(probe("physics", {{"tool_at", 1.8}}));
  const json s = scene_run::runScene(scene, 2.0, tmp.path() / "out");
  ASSERT_TRUE(s.contains("scripts")) << s.dump(2);
  const json& m = s["scripts"]["probe"]["metrics"];
  const std::vector<scene_run::TraceRow> trace = scene_run::forceTrace(tmp.path() / "out" / "forces.csv");
  ASSERT_FALSE(trace.empty());
  // The god-object's first contact: the first tick with a force on the hand.
  const auto first = std::find_if(trace.begin(), trace.end(),
                                  [](const scene_run::TraceRow& r) { return r.force.norm() > 0; });
  ASSERT_NE(first, trace.end());
  ASSERT_TRUE(m.contains("events")) << m.dump(2);
  const json& events = m["events"];
  ASSERT_GE(events.size(), 1u) << events.dump(2);
  EXPECT_EQ(events[0]["type"], "contact_began");
  EXPECT_EQ(events[0]["object"], "box");
  EXPECT_NEAR(events[0]["time"].get<double>(), first->t, 1.5e-3) << events.dump(2);
  EXPECT_GE(events[0]["seen_at"].get<double>(), events[0]["time"].get<double>());
  EXPECT_LT(events[0]["seen_at"].get<double>() - events[0]["time"].get<double>(), 1.5e-3);
  // The hand meets the box face (x = -2 cm) about 1.3 s in, moving at 3 cm/s.
  EXPECT_GT(first->t, 1.0);
  EXPECT_LT(first->t, 1.6);
  // Every began/ended pair alternates, in time order.
  for (std::size_t i = 0; i < events.size(); ++i) {
    EXPECT_EQ(events[i]["type"], i % 2 == 0 ? "contact_began" : "contact_ended") << events.dump(2);
    if (i > 0) {
      EXPECT_GE(events[i]["time"].get<double>(), events[i - 1]["time"].get<double>());
    }
  }
  // The tool the script read at 1.8 s is the hand's force of that tick.
  ASSERT_TRUE(m.contains("tool")) << m.dump(2);
  const auto row = std::find_if(trace.begin(), trace.end(),
                                [](const scene_run::TraceRow& r) { return std::abs(r.t - 1.8) < 1e-6; });
  ASSERT_NE(row, trace.end());
  EXPECT_NEAR(m["tool"]["time"].get<double>(), 1.8, 1e-9);
  EXPECT_LT((scene_run::vec(m["tool"]["force"]) - row->force).norm(), 1e-5 + 1e-5 * row->force.norm());
  EXPECT_LT((scene_run::vec(m["tool"]["proxy"]) - row->proxy).norm(), 1e-6);
  EXPECT_GT(row->force.norm(), 0.1);  // pushing the box
}

TEST(SceneScript, PuncturesComeWhereTheNeedlesForceDrops) {
  const ProbeLanguage language;
  const dm::test::TempDir tmp("script_needle");
  dm::SceneDesc scene = scene_run::bundledScene("needle_insertion.json");
  scene.outputs.forces = true;
  scene.scripts.push_back(probe("monitor", json::object()));
  const json s = scene_run::runScene(scene, 3.4, tmp.path() / "out");
  ASSERT_TRUE(s.contains("scripts")) << s.dump(2);
  const json& m = s["scripts"]["probe"]["metrics"];
  ASSERT_TRUE(m.contains("events")) << m.dump(2);
  std::vector<json> punctures;
  for (const json& e : m["events"])
    if (e["type"] == "puncture") punctures.push_back(e);
  const json& needle = s["physics"]["soft"][0]["needle"];
  ASSERT_EQ(punctures.size(), needle["punctures"].get<std::size_t>()) << m.dump(2);
  ASSERT_EQ(punctures.size(), 2u) << needle.dump(2);  // the skin and the muscle's fascia
  const std::vector<scene_run::TraceRow> trace = scene_run::forceTrace(tmp.path() / "out" / "forces.csv");
  const auto maxForce = [&](double from, double to) {
    double f = 0;
    for (const scene_run::TraceRow& r : trace)
      if (r.t >= from && r.t <= to) f = std::max(f, r.force.norm());
    return f;
  };
  const double kPuncture[] = {1.2, 0.8};  // N, the layers' puncture forces (the scene)
  for (std::size_t i = 0; i < punctures.size(); ++i) {
    const double t = punctures[i]["time"].get<double>();
    EXPECT_EQ(punctures[i]["object"], "block");
    EXPECT_EQ(punctures[i]["value"].get<double>(), double(i + 1));
    const std::string layer = punctures[i]["layer"].get<std::string>();
    EXPECT_TRUE(layer == "skin" || layer == "fat" || layer == "muscle") << layer;
    // The hand held about the membrane's puncture force in the 20 ms
    // before (the tip's spring is not all of it), and less after the pop.
    const double before = maxForce(t - 0.02, t), after = maxForce(t + 0.03, t + 0.05);
    EXPECT_GT(before, 0.6 * kPuncture[i]) << "puncture " << i << " at " << t;
    EXPECT_LT(after, before) << "puncture " << i << " at " << t;
    if (i > 0) {
      EXPECT_GT(t, punctures[i - 1]["time"].get<double>());
    }
  }
}

// A run that ends on the physics tick of a puncture: the script engine may
// have ticked for the last time before physics pushed it, so finish() must
// still hand it over (the engines stop one by one; in real time the order
// is the scheduler's, which is how this was first seen under TSan).
TEST(SceneScript, APunctureOnTheLastPhysicsTickReachesTheScriptBeforeItFinishes) {
  const ProbeLanguage language;
  dm::SceneDesc scene = scene_run::bundledScene("needle_insertion.json");
  scene.scripts.push_back(probe("monitor", json::object()));
  const dm::test::TempDir tmp("script_last_puncture");
  const json full = scene_run::runScene(scene, 3.4, tmp.path() / "full");
  std::vector<double> times, seenAt;
  for (const json& e : full["scripts"]["probe"]["metrics"]["events"])
    if (e["type"] == "puncture") {
      times.push_back(e["time"].get<double>());
      seenAt.push_back(e["seen_at"].get<double>());
    }
  ASSERT_EQ(times.size(), 2u) << full.dump(2);
  // Stop 1 ms after the physics tick of the second puncture (physics at
  // 100 Hz; the monitor's script at 30 Hz, whose next tick would have seen
  // it later than that).
  const double end = times[1] + 1e-3;
  ASSERT_GT(seenAt[1], end) << full.dump(2);
  const json cut = scene_run::runScene(scene, end, tmp.path() / "cut");
  const json& needle = cut["physics"]["soft"][0]["needle"];
  ASSERT_EQ(needle["punctures"].get<int>(), 2) << needle.dump(2);
  int seen = 0;
  for (const json& e : cut["scripts"]["probe"]["metrics"]["events"])
    if (e["type"] == "puncture") ++seen;
  EXPECT_EQ(seen, 2) << cut["scripts"]["probe"].dump(2);
}

TEST(SceneScript, AFailingScriptStopsTheRunNamingItAndTheOutputsAreWritten) {
  const ProbeLanguage language;
  const dm::test::TempDir tmp("script_fail");
  dm::SceneDesc scene = freeBall();
  scene.scripts.push_back(probe("physics", {{"fail_at", 0.25}}));
  auto rt = dm::SceneRuntime::create(scene);
  ASSERT_TRUE(rt) << rt.error();
  auto r = (*rt)->run({.mode = dm::RunMode::Lockstep, .duration = 1.0, .outDir = tmp.path() / "out"});
  ASSERT_FALSE(r);
  const std::string msg = r.error().message();
  EXPECT_NE(msg.find("script:probe"), std::string::npos) << msg;
  EXPECT_NE(msg.find("tick at 0.25"), std::string::npos) << msg;
  EXPECT_NE(msg.find("the probe gave up"), std::string::npos) << msg;
  const json summary = json::parse(scene_run::fileText(tmp.path() / "out" / "summary.json"));
  EXPECT_EQ(summary["scripts"]["probe"]["metrics"]["ticks_seen"], 250);
}

TEST(SceneScript, ALanguageNobodyRegisteredIsRefusedNamingTheScript) {
  const dm::test::TempDir tmp("script_lang");
  dm::SceneDesc scene = freeBall();
  dm::SceneScript s = probe("physics", json::object());
  s.path = tmp.path() / "tug.lua";
  scene.scripts.push_back(s);
  auto rt = dm::SceneRuntime::create(scene);
  ASSERT_TRUE(rt) << rt.error();
  const auto prepared =
      (*rt)->prepare({.mode = dm::RunMode::Lockstep, .duration = 1.0, .outDir = tmp.path() / "o"});
  ASSERT_FALSE(prepared);
  EXPECT_EQ(prepared.error().code, dm::ErrorCode::Unsupported);
  EXPECT_NE(prepared.error().message().find("scripts/probe/source"), std::string::npos) << prepared.error();
  EXPECT_NE(prepared.error().message().find(".lua"), std::string::npos) << prepared.error();
  EXPECT_FALSE(fs::exists(tmp.path() / "o"));  // a scene that cannot be built leaves no output folder
}

TEST(SceneScript, SettingAForceOnABodyThatDoesNotMoveFailsNamingIt) {
  const ProbeLanguage language;
  const dm::test::TempDir tmp("script_nobody");
  dm::SceneDesc scene = freeBall();
  scene.scripts.push_back(
      probe("physics", {{"push", {{"body", "table"}, {"force", {1, 0, 0}}, {"torque", {0, 0, 0}}}}}));
  auto rt = dm::SceneRuntime::create(scene);
  ASSERT_TRUE(rt) << rt.error();
  auto r = (*rt)->run({.mode = dm::RunMode::Lockstep, .duration = 0.1, .outDir = tmp.path() / "out"});
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().message().find("no moving body \"table\""), std::string::npos) << r.error();
  EXPECT_NE(r.error().message().find("start"), std::string::npos) << r.error();
}

}  // namespace scene_script_test
