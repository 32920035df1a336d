// A scene script on real-time threads: the script engine reads the tool the
// haptic thread publishes and the bodies physics publishes, takes contact
// events from the one and punctures from the other, and hands its held
// forces back to physics, all while those threads run. Run under TSan in
// CI: any unsynchronised access between the three threads is a failure.
// The outcome checks are loose (a sanitizer slows the threads).
#include <dm/engine/scene_runtime.hpp>
#include <dm/engine/script.hpp>
#include <dm/io/scene_file.hpp>

#include <gtest/gtest.h>

#include "../common/temp_dir.hpp"
#include "scene_run_support.hpp"

namespace scene_script_concurrency_test {

using nlohmann::json;

// Counts the events by type and the ticks that read a tool force; holds a
// small force along +x on every moving body.
class Counter final : public dm::ScriptInstance {
 public:
  dm::Status event(dm::ScriptContext& c, const dm::ScriptEvent& e) override {
    const std::string type(dm::toString(e.type));
    c.setMetric(type, c.metrics().value(type, 0) + 1);
    return dm::ok();
  }
  dm::Status tick(dm::ScriptContext& c) override {
    for (const std::string& b : c.bodies())
      if (auto s = c.setBodyForce(b, dm::Vec3(0.05, 0, 0), dm::Vec3::Zero()); !s) return s;
    if (c.hasTool() && c.tool().force.squaredNorm() > 0.0)
      c.setMetric("forced_ticks", c.metrics().value("forced_ticks", 0) + 1);
    return dm::ok();
  }
};

json runRealTime(dm::SceneDesc scene, double seconds, const std::string& name) {
  dm::registerScriptLanguage(".count", [](const dm::SceneScript&) {
    return dm::Result<std::unique_ptr<dm::ScriptInstance>>(std::make_unique<Counter>());
  });
  scene.scripts.push_back({.name = "count", .source = "c.count", .path = "c.count", .engine = "physics"});
  const dm::test::TempDir tmp(name);
  auto rt = dm::SceneRuntime::create(scene);
  EXPECT_TRUE(rt) << rt.error();
  json summary;
  if (rt) {
    auto r = (*rt)->run({.mode = dm::RunMode::RealTime, .duration = seconds, .outDir = tmp.path()});
    EXPECT_TRUE(r) << r.error();
    if (r) summary = r->summary;
  }
  dm::unregisterScriptLanguage(".count");
  return summary;
}

TEST(SceneScriptRealTime, AScriptPushesTheBoxWhileTheToolTouchesIt) {
  const json s = runRealTime(scene_run::bundledScene("box_push.json"), 2.0, "script_rt_box");
  ASSERT_TRUE(s.contains("scripts")) << s.dump(2);
  const json& m = s["scripts"]["count"]["metrics"];
  EXPECT_GT(s["scripts"]["count"]["ticks"].get<int>(), 100);
  EXPECT_GE(m.value("contact_began", 0), 1) << m.dump(2);  // the hand meets the box at about 1.3 s
  EXPECT_GT(m.value("forced_ticks", 0), 0) << m.dump(2);
}

TEST(SceneScriptRealTime, PuncturesArriveFromThePhysicsThread) {
  const json s = runRealTime(scene_run::bundledScene("needle_insertion.json"), 3.0, "script_rt_needle");
  ASSERT_TRUE(s.contains("scripts")) << s.dump(2);
  const json& n = s.at("physics").at("soft").at(0).at("needle");
  EXPECT_EQ(s["scripts"]["count"]["metrics"].value("puncture", 0), n.at("punctures").get<int>());
}

}  // namespace scene_script_concurrency_test
