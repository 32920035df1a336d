// script_engine.hpp (private) — a scene's script as an engine of the run
// (dm/engine/script.hpp): its channels to the haptic and physics threads
// (ScriptFeed) and the engine that ticks it with a ScriptContext over them.
//
//   haptics ─ ScriptToolSample (triple buffer), contact events (SPSC) ─→ script
//   physics ─ body states (triple buffer), punctures (SPSC) ──────────→ script
//   script ── held forces per moving body (triple buffer) ────────────→ physics
// The writers never wait; a full event ring drops the event and counts it
// (summary "events_dropped").
#pragma once

#include <dm/core/ring.hpp>
#include <dm/core/triple_buffer.hpp>
#include <dm/engine/engine.hpp>
#include <dm/engine/script.hpp>
#include <dm/io/scene_file.hpp>

#include <atomic>
#include <functional>
#include <limits>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace dm {

/// An event as the real-time threads record it (no strings): `source` is
/// the touched object's index in the haptics engine's objects (-1: none) or
/// the soft object's in the physics engine's; `layer` the needle's tip layer.
struct ScriptEventRecord {
  ScriptEvent::Type type = ScriptEvent::Type::ContactBegan;
  double time = 0.0;
  int source = -1;
  int layer = -1;
  double value = 0.0;
};

struct ScriptToolSample {
  ScriptTool tool;
  bool valid = false;
};

/// A held force on a moving body.
struct ScriptForce {
  Vec3 force = Vec3::Zero(), torque = Vec3::Zero();
};

/// One script's channels; built before the run, sized for the moving bodies.
struct ScriptFeed {
  explicit ScriptFeed(std::size_t movingBodies, std::size_t inlets = 0)
      : bodies(std::vector<ScriptBody>(movingBodies)),
        forces(std::vector<ScriptForce>(movingBodies)),
        inletRates(std::vector<double>(inlets, std::numeric_limits<double>::quiet_NaN())) {}
  TripleBuffer<ScriptToolSample> tool;             // haptics → script
  SpscRing<ScriptEventRecord, 1024> toolEvents;    // haptics → script
  TripleBuffer<std::vector<ScriptBody>> bodies;    // physics → script
  SpscRing<ScriptEventRecord, 256> physicsEvents;  // physics → script
  TripleBuffer<std::vector<ScriptForce>> forces;   // script → physics
  TripleBuffer<std::vector<double>> inletRates;    // script → physics: per scene inlet, NaN: not set
  std::atomic<std::uint64_t> droppedEvents{0};
  // Writer side of either ring: a full ring drops the event and counts it.
  template <std::size_t N>
  void push(SpscRing<ScriptEventRecord, N>& ring, const ScriptEventRecord& e) noexcept {
    if (!ring.tryPush(e)) droppedEvents.fetch_add(1, std::memory_order_relaxed);
  }
};

/// Names the records' sources: the touched objects, the soft objects and
/// their layers.
struct ScriptNames {
  std::vector<std::string> touched;                    // haptics engine's objects
  std::vector<std::string> soft;                       // physics engine's soft objects
  std::function<std::string(std::size_t, int)> layer;  // soft object i's layer; may be empty
  /// The scene's fluid inlets, {fluid, inlet}, fluids and their inlets in
  /// scene order (the feed's inletRates order).
  std::vector<std::pair<std::string, std::string>> inlets;
};

/// The engine "script:NAME": ticks one ScriptInstance over its feed.
class ScriptEngine final : public Engine {
 public:
  /// `bodies`: the moving bodies (the feed's order); `hasTool`: whether the
  /// haptics engine writes the feed's tool.
  ScriptEngine(const SceneScript& script, std::unique_ptr<ScriptInstance> instance,
               std::vector<std::string> bodies, bool hasTool, ScriptNames names);
  ~ScriptEngine() override;

  std::string_view name() const noexcept override { return engineName_; }
  bool tick(const TickInfo& info) noexcept override;
  Error error() const override { return error_; }

  ScriptFeed& feed() noexcept { return *feed_; }
  /// The metrics set so far (control thread, between lockstep advances or after the run).
  const nlohmann::json& metrics() const noexcept;
  /// Control thread, after the run: the script's finish(), then its entry
  /// of summary.json's "scripts" (metrics, ticks, events). Events the
  /// other threads pushed after the last tick are delivered first.
  Result<nlohmann::json> finish(double time);

 private:
  struct Context;
  bool fail(Error e) noexcept;
  bool deliverEvents(Context& c);
  std::string engineName_;
  std::unique_ptr<ScriptFeed> feed_;
  std::unique_ptr<Context> context_;
  std::unique_ptr<ScriptInstance> instance_;
  ScriptNames names_;
  std::vector<ScriptEventRecord> pending_;  // this tick's events, sorted by time
  TickTime clock_;                          // scene time, also in real time
  bool started_ = false;
  std::uint64_t ticks_ = 0, events_ = 0;
  Error error_;
};

}  // namespace dm
