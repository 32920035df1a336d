// dm/engine/script.hpp — scripted behaviour in a scene run: the thesis's
// property scripting, in any language a loader is registered for (Python:
// the dmplatform package and the dmplatform program register ".py").
//
// A scene's "scripts" (docs/scene-format.md, "Scripts") each name a source
// file and an engine. The runtime loads each script before the run through
// the loader registered for its file's extension and ticks it as an engine
// of its own at that engine's rate, after it at equal times in lockstep (so
// a script at the physics rate sees the step of its own time), on a thread
// of its own in real time — never the haptic thread. Each tick the script:
//   - reads the newest state: the moving bodies' poses and velocities (as
//     the last physics step left them), the haptic tool (proxy, handle,
//     force, contacts, as the last haptic tick left it), the time and the
//     arguments the scene gave it;
//   - gets the events since its last tick, in time order: the tool's
//     contact began or ended (at the haptic tick it happened, with the
//     touched object for the god-object), the needle broke a membrane;
//   - sets a force and torque on a moving body, held until it sets another
//     (applied from the next physics step on), and writes metrics, which
//     the run's summary.json lists under "scripts".
// Every channel has one writer and one reader thread (triple buffers, SPSC
// rings), so the haptic and physics threads never wait for a script, and a
// lockstep run with scripts is bit-reproducible. A script's error stops the
// run like an engine's, named "script:NAME".
//
// @code
//   // A C++ script language, e.g. for tests or an in-house DSL:
//   dm::registerScriptLanguage(".tug", [](const dm::SceneScript& s) {
//     return dm::Result<std::unique_ptr<dm::ScriptInstance>>(std::make_unique<Tug>(s.args));
//   });
// @endcode
#pragma once

#include <dm/core/result.hpp>
#include <dm/core/types.hpp>

#include <nlohmann/json.hpp>

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

namespace dm {

struct SceneScript;

/// A moving body as a script sees it: world frame, SI units.
struct ScriptBody {
  Isometry3 pose = Isometry3::Identity();  ///< object frame → world
  Vec3 linearVelocity = Vec3::Zero();      ///< m/s, of the centre of mass
  Vec3 angularVelocity = Vec3::Zero();     ///< rad/s
  Vec3 centerOfMass = Vec3::Zero();        ///< m, world
};

/// The haptic tool at its newest tick: world frame, SI units.
struct ScriptTool {
  double time = 0.0;                         ///< s, scene time of the tick
  Isometry3 proxy = Isometry3::Identity();   ///< where the tool is drawn (proxy / tool body)
  Isometry3 handle = Isometry3::Identity();  ///< the device's handle
  Vec3 force = Vec3::Zero();                 ///< N, sent to the hand
  int contacts = 0;                          ///< active constraints or penetrating points
  double penetration = 0.0;                  ///< m
};

/// Something that happened since the script's last tick.
struct ScriptEvent {
  enum class Type : std::uint8_t {
    ContactBegan,  ///< the tool touched: object = the god-object's touched object ("" for other tools)
    ContactEnded,  ///< the tool let go
    Puncture,      ///< the needle broke a membrane: object = the soft object, layer = the layer broken
  };
  Type type = Type::ContactBegan;
  double time = 0.0;   ///< s, scene time it happened
  std::string object;  ///< see Type
  std::string layer;   ///< Puncture: the layer at the tip after the break ("" outside)
  double value = 0.0;  ///< ContactBegan: |F| (N) at that tick; Puncture: membranes broken so far
};
/// "contact_began", "contact_ended", "puncture".
std::string_view toString(ScriptEvent::Type type) noexcept;

/// What a script's callbacks see and change; valid during the callback, on
/// the script's thread (finish(): the control thread, after the run).
class ScriptContext {
 public:
  virtual ~ScriptContext() = default;
  /// The script's name in the scene.
  virtual const std::string& name() const noexcept = 0;
  /// s, scene time of this tick (finish(): where the run stopped).
  virtual double time() const noexcept = 0;
  /// The scene's "args" for the script.
  virtual const nlohmann::json& args() const noexcept = 0;
  /// The moving (dynamic) bodies, in scene order; empty without physics.
  virtual const std::vector<std::string>& bodies() const noexcept = 0;
  /// The body's newest state; NotFound naming it when it is not a moving body.
  virtual Result<ScriptBody> body(std::string_view name) const = 0;
  /// Holds `force` (N, through the centre of mass) and `torque` (N·m) on a
  /// moving body, world frame, from the next physics step until set again;
  /// fails naming the body or a non-finite value.
  virtual Status setBodyForce(std::string_view name, const Vec3& force, const Vec3& torque) = 0;
  /// Sets the flow rate (m³/s at zero back pressure, 0..1e-3) of inlet
  /// `inlet` of scene fluid `fluid` from the next physics step on (a cut
  /// opening, irrigation turned on; 0 closes it); its time window still
  /// applies. Fails naming an unknown fluid or inlet or a bad rate.
  virtual Status setInletFlowRate(std::string_view fluid, std::string_view inlet, double m3PerSecond) = 0;
  /// Whether the scene has a haptic tool; tool() is its newest tick (all
  /// zero before the first).
  virtual bool hasTool() const noexcept = 0;
  virtual ScriptTool tool() const = 0;
  /// A custom metric, written to summary.json's "scripts"/NAME/"metrics"
  /// (a later value replaces an earlier one).
  virtual void setMetric(const std::string& key, nlohmann::json value) = 0;
  virtual const nlohmann::json& metrics() const noexcept = 0;
};

/// A loaded script: its callbacks. A failed Status stops the run with its
/// error (the runtime adds "script:NAME").
class ScriptInstance {
 public:
  virtual ~ScriptInstance() = default;
  /// Before the first tick's events, on the script's thread.
  virtual Status start(ScriptContext&) { return ok(); }
  /// Each event since the last tick, in time order, before tick().
  virtual Status event(ScriptContext&, const ScriptEvent&) { return ok(); }
  /// Every tick of the script's engine.
  virtual Status tick(ScriptContext&) { return ok(); }
  /// After the run, also an interrupted one: last metrics (control thread).
  virtual Status finish(ScriptContext&) { return ok(); }
};

/// Makes a script from its scene entry (its resolved path, its args);
/// fails naming the file (unreadable, a syntax error, no callbacks).
using ScriptLoader = std::function<Result<std::unique_ptr<ScriptInstance>>(const SceneScript& script)>;

/// Registers (or replaces) the loader of scripts whose source ends with
/// `extension` (".py"), for this process. Thread-safe.
void registerScriptLanguage(std::string extension, ScriptLoader loader);
/// Removes it (a no-op when there is none). Thread-safe.
void unregisterScriptLanguage(std::string_view extension);
/// Loads `script` with the loader of its extension; Unsupported naming the
/// extension and the languages there are when none is registered.
Result<std::unique_ptr<ScriptInstance>> loadScript(const SceneScript& script);

}  // namespace dm
