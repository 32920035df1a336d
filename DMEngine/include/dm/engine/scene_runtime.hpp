// dm/engine/scene_runtime.hpp — a scene file, run: what `dmplatform run`
// does, as a library call user code can extend.
//
// SceneRuntime::load() reads and validates the scene file
// (docs/scene-format.md), loads its resources, and builds the engines its
// "engines" section asks for inside a dm::MasterEngine:
//   - haptics: the device (a driver from the registry, e.g. sim-haptic),
//     the god-object renderer over the touchable objects with their scene
//     materials, force shading and the force limit — or the burr renderer
//     milling the one "millable" object (voxelized bone with its critical
//     structures; docs/scene-format.md, "Bone surgery"), or the needle
//     renderer going into the soft object with "layers" (dm::HapticNeedle;
//     "Needles"), or a 6-DOF rigid tool: the VPS renderer (its point shell
//     against the touched objects voxelized; dm::VpsRenderer) or the
//     sphere-tree renderer (dm::SphereTree6DofRenderer), or a punch bonded
//     to a soft object's nodes (renderer "punch", stepped with the tissue by
//     physics), or a tool in free space (renderer "none",
//     dm::FreeSpaceRenderer) — and dm::HapticLoop
//     (device servo, effects, safety, fade) at the scene's rate;
//   - physics: every "dynamic" object a rigid body of one dm::PhysicsWorld,
//     the other objects static colliders; the god-object feels the moving
//     bodies where physics has them (HapticLocalModel) and pushes them back
//     with the tool's impulses (dm::ToolImpulseChannel), so the hand and the
//     body exchange equal and opposite momentum; every "soft" object an FEM
//     body (dm::FemBody on tetrahedra from its mesh, held faces, gravity)
//     that the god-object presses through dm::HapticTissue — felt on its
//     newest surface at the haptic rate, deformed at the physics rate;
//     every "membrane" a mass–spring body kept out of the colliding
//     objects, holding up and pushed by the dynamic ones
//     (dm::MembraneRigidCoupling);
//   - render: a headless EGL context on the render engine's own thread,
//     dm::SceneView drawing the render camera with the tool object following
//     the haptic proxy, a HUD (time, force, force plot) from dm::Overlay,
//     frames read back and written as PNG by a writer thread; a milled
//     object is drawn as its volume's surface, each frame remeshing only
//     the blocks the burr changed (dm::MillableSurfaceFeed); a soft object
//     or a membrane as its deformed surface; a second camera's "inset" in
//     the upper-right corner; with SceneRunOptions::liveFrames each frame
//     as written also to latestFrame() (a live window, dmplatform run
//     --view) and the camera turned by setViewOrbit();
//   - monitor: drains the haptic samples into the force trace;
//   - igtl: an OpenIGTLink server (dm::IgtlServer) publishing the tool and
//     handle poses (TRANSFORM), the force (SENSOR), the dynamic bodies
//     (TRANSFORM) and the rendered frames (IMAGE) to every client at its
//     rate, and answering GET_/STT_ queries; run() can wait for clients;
//   - vision: a DMVision filter graph stepped one frame per tick, its
//     "input" sources fed the rendered frames (a simulated endoscope);
//   - segmentation: DMVision's haptic-guided segmentation of a volume
//     resource, painted at the haptic tool's point at its rate, its guidance
//     force an effect of the haptic loop; the mask is written as
//     segmentation.nii.gz;
//   - scripts: each of the scene's "scripts" loaded through the loader of
//     its language (dm/engine/script.hpp; ".py" where the Python package or
//     the dmplatform program registered it) and ticked as the engine
//     "script:NAME" at the rate of the engine it names, after the others:
//     it reads the tool and the moving bodies, hears contacts and
//     punctures, holds forces on bodies and writes metrics.
// prepare() builds and loads them (a model that cannot be built fails there,
// before anything runs); run() starts them in lockstep on a virtual clock (bit-reproducible) or on
// real-time threads, for a duration or until `stop` is raised (Ctrl-C), then
// stops them and writes the outputs the scene asks for: frames/frame_NNNNN.png,
// forces.csv, forces.png, recording.dmrec (the haptic device's stream, for
// dm::loadReplay: dm/io/scene_replay.hpp) and summary.json (achieved rate and tick-time
// percentiles per engine, deadline misses, contacts, maximum and final force,
// frames; each dynamic body's final state, displacement, contact and tool
// forces of the last step, and the tool impulse it received; each soft
// body's model, solver counters, deformation and the tool's, held and
// weight forces; with the burr,
// removed volume per material, closest approach to critical structures and
// the time within the warning margin; each script's ticks, events and
// metrics).
// User code adds engines of its own (addEngine) before run().
//
// @code
//   auto rt = dm::SceneRuntime::load("examples/scenes/head_probe.json");
//   if (!rt) { std::cerr << rt.error() << '\n'; return 1; }
//   auto summary = (*rt)->run({.mode = dm::RunMode::Lockstep, .duration = 5.0, .outDir = "out"});
// @endcode
#pragma once

#include <dm/core/image.hpp>
#include <dm/core/result.hpp>
#include <dm/engine/frame_camera.hpp>
#include <dm/engine/master_engine.hpp>

#include <nlohmann/json.hpp>

#include <atomic>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace dm {

struct SceneDesc;

/// How to run.
struct SceneRunOptions {
  RunMode mode = RunMode::Lockstep;
  double duration = 10.0;        ///< s of simulation (lockstep) or wall time (real time), > 0
  std::filesystem::path outDir;  ///< empty: the scene's outputs.directory
  /// Called on the control thread about 10 times per second with the
  /// fraction done and a one-line status; may be empty.
  std::function<void(double fraction, const std::string& status)> progress;
  /// Raised (by a signal handler, another thread) to stop early; the outputs
  /// are still written. May be null.
  const std::atomic<bool>* stop = nullptr;
  /// Keep the render engine's newest frame for latestFrame() (a live view
  /// of the run); needs the scene's render engine.
  bool liveFrames = false;
};

/// A live view's turn of the render engine's camera (dmplatform run
/// --view's mouse), applied to the scene camera at every frame: the eye
/// turned about the target by `yaw` (rad, about the camera's up) and
/// `pitch` (rad, about its right axis; kept 5° off the up axis), its
/// distance times `zoom` (an orthographic camera's height too), and eye and
/// target moved along the camera's right and up axes by `panRight` and
/// `panUp` times that distance.
struct ViewOrbit {
  double yaw = 0.0, pitch = 0.0, zoom = 1.0, panRight = 0.0, panUp = 0.0;
  bool operator==(const ViewOrbit&) const = default;
};

/// What a run did.
struct SceneRunResult {
  nlohmann::json summary;       ///< what summary.json holds
  bool interrupted = false;     ///< stopped by `stop` before the duration
  double simulatedSeconds = 0;  ///< how far the clock got
  std::uint64_t frames = 0;     ///< frames written
};

/// Per-engine figures as summary.json lists them: name, rate_hz,
/// achieved_hz, ticks, deadline_misses and execution_us {p50, p99, p999,
/// max}; also for programs that run a MasterEngine of their own.
nlohmann::json engineStatsJson(const std::vector<EngineStats>& stats);

/// A loaded scene with its engines (see the file comment). Not copyable.
class SceneRuntime {
 public:
  /// Reads, validates and loads `sceneFile` and builds its engines. Every
  /// validation problem is in the error (formatSceneErrors); a resource,
  /// device or GL failure names the scene entry.
  static Result<std::unique_ptr<SceneRuntime>> load(const std::filesystem::path& sceneFile);
  /// The same from a parsed scene (its baseDir resolves relative sources).
  static Result<std::unique_ptr<SceneRuntime>> create(const SceneDesc& scene);

  ~SceneRuntime();
  SceneRuntime(const SceneRuntime&) = delete;
  SceneRuntime& operator=(const SceneRuntime&) = delete;

  /// Adds a user engine (before run()).
  Status addEngine(std::shared_ptr<Engine> engine, const EngineSchedule& schedule);
  /// The master engine (state, transitions, stats).
  MasterEngine& master();
  /// The port the OpenIGTLink engine listens on once prepare() built it
  /// (the free one picked for port 0); 0 without that engine.
  std::uint16_t igtlPort() const;
  /// The render engine's newest frame as it writes frames (the HUD and a
  /// vision overlay drawn; top row first) and its scene time, when it is newer than the one
  /// `seen` numbers (then `seen` is updated); false otherwise, and always
  /// without SceneRunOptions::liveFrames. Any thread; the pixels are shared,
  /// not copied.
  /// With `camera`, also the camera it was drawn with (FrameCamera: a
  /// pixel of it as a ray in the world).
  bool latestFrame(std::uint64_t& seen, Image& out, double& sceneTime, FrameCamera* camera = nullptr) const;
  /// Turns the render engine's camera from the next frame on (see
  /// ViewOrbit; the frames written show it too). One thread at a time, any
  /// thread, after prepare() with SceneRunOptions::liveFrames; ignored
  /// otherwise. Never blocks the render engine.
  void setViewOrbit(const ViewOrbit& orbit);
  const SceneDesc& scene() const;

  /// Builds the engines for a run with `options` (mode, output folder) and
  /// loads them, so that a scene whose models cannot be built fails here,
  /// before anything runs; a failure leaves no output folder it made. run()
  /// calls it when it was not called, with the same options.
  /// @code
  ///   if (auto s = rt->prepare(options); !s) return 2;  // a bad scene
  ///   auto r = rt->run(options);                          // a failed run
  /// @endcode
  Status prepare(const SceneRunOptions& options);
  /// Runs once (see the file comment). Fails when an engine fails (outputs
  /// written so far are kept and named in the error) or an output cannot be
  /// written, or with other mode or output folder than prepare() was given.
  Result<SceneRunResult> run(const SceneRunOptions& options);

  /// Step by step instead of run(): start() prepares (when it was not) and
  /// starts the engines (options.duration only sizes the force trace and
  /// `stop` and `progress` are not used); in lockstep advance() runs the
  /// virtual clock on by `seconds` and state() reads the engines between
  /// advances; finish() stops them and writes the outputs, as run() does
  /// after its loop (duration_s: how far it was advanced). In real time the
  /// engines run on their threads from start() to finish().
  /// @code
  ///   rt->start({.mode = dm::RunMode::Lockstep, .duration = 5.0, .outDir = "out"});
  ///   while (rt->time() < 5.0) { rt->advance(0.5); auto s = rt->state(); ... }
  ///   auto result = rt->finish();
  /// @endcode
  Status start(const SceneRunOptions& options);
  Status advance(double seconds);
  /// s the run has been advanced (lockstep) so far.
  double time() const;
  /// Between lockstep advances: {"time_s", "physics" (each body's state, as
  /// the summary's), "haptics" (the newest tick: force, proxy, contacts),
  /// "scripts" (each script's metrics so far)}.
  Result<nlohmann::json> state();
  Result<SceneRunResult> finish();

 private:
  SceneRuntime();
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace dm
