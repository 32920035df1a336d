// scene_runtime.cpp — a scene file's engines inside a MasterEngine, the run
// loop, and the outputs.
#include <dm/collide/bvh.hpp>
#include <dm/core/filesystem.hpp>
#include <dm/core/host_cpu.hpp>
#include <dm/core/log.hpp>
#include <dm/core/plugin.hpp>
#include <dm/core/ring.hpp>
#include <dm/core/rt_memory.hpp>
#include <dm/core/triple_buffer.hpp>
#include <dm/engine/scene_runtime.hpp>
#include <dm/haptics/effects.hpp>
#include <dm/haptics/force_plot.hpp>
#include <dm/haptics/god_object.hpp>
#include <dm/haptics/haptic_loop.hpp>
#include <dm/haptics/probe.hpp>
#include <dm/haptics/tissue.hpp>
#include <dm/haptics/tool_impulse.hpp>
#include <dm/io/drivers.hpp>
#include <dm/io/haptic_device.hpp>
#include <dm/io/image_io.hpp>
#include <dm/io/recorder.hpp>
#include <dm/io/scene_file.hpp>
#include <dm/io/scene_replay.hpp>
#include <dm/io/scene_resources.hpp>

#ifdef DM_ENGINE_HAVE_NETWORK
#include <dm/core/rt_loop.hpp>
#include <dm/network/drivers.hpp>
#include <dm/network/teleop.hpp>

#include "igtl_engine.hpp"
#endif
#include "frame_slot.hpp"
#ifdef DM_ENGINE_HAVE_VISION
#include "segmentation_engine.hpp"
#include "vision_engine.hpp"
#endif
#include "physics_engine.hpp"
#include "scene_6dof.hpp"
#include "scene_fluids.hpp"
#include "script_engine.hpp"
#include "surgery.hpp"
#ifdef DM_ENGINE_HAVE_RENDERER
#include "render_engine.hpp"
#endif

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <mutex>
#include <span>
#include <thread>

namespace dm {

namespace {

using SteadyClock = std::chrono::steady_clock;

// A late frame is made up by the next ones (at most this many periods
// behind) instead of dropping a period: the render rate holds its average
// through one slow frame. Haptics never catch up.
constexpr int kRenderCatchUp = 2;
// Physics makes up a late step the same way: the impulses it applies are
// totals over time, and a skipped step would hold the bodies still.
constexpr int kPhysicsCatchUp = 2;

Status checkDuration(const SceneRunOptions& options) {
  if (options.duration > 0 && std::isfinite(options.duration)) return ok();
  return fail(ErrorCode::InvalidArgument, formatString("duration %g s", options.duration), "--duration",
              "give a positive number of seconds");
}

// The haptic engine: device servo, god-object or burr, safety — one
// HapticLoop tick per engine tick (the burr's drilled blocks then go to the
// render engine through a MillableSurfaceFeed); every tick's sample goes to
// the monitor through an SPSC ring (the haptic thread never allocates,
// locks or logs). With a physics engine, the loop applies the poses physics
// published (its local model) and the tool's reaction goes back as impulses
// on the touched objects: the god-object's at its contact point, a 6-DOF
// tool's (VPS, sphere tree) as each object's wrench.
class HapticsEngine final : public Engine {
 public:
  std::string_view name() const noexcept override { return "haptics"; }
  bool tick(const TickInfo& info) noexcept override {
    loop->tick(info);
    if (boneFeed) boneFeed->publish(burr->volume());  // the drilled blocks, to the render engine
    if (placement.renderer) {
      if (!placementStarted) placementFirstPose = placement.renderer->fragmentPose();
      placementStarted = true;
      placementMaxDepth = std::max(placementMaxDepth, placement.renderer->maxContactDepth());
    }
    const HapticLoopSample& s = loop->lastSample();
    ProbeSample p;
    p.t = time.seconds(info);  // scene time, also in real time
    p.devicePose = s.input.devicePose;
    p.response = s.response;
    p.response.force = loop->config().deviceToWorld.linear() * s.deviceForce;  // what was sent, world frame
    if (tools != nullptr && godObject != nullptr) {
      // Newton's third law: what pushes the hand pushes the object back,
      // where the proxy touches it, for as long as the command holds.
      const GodObjectContact& c = godObject->contact();
      if (c.active) {
        tools->add(c.object, -p.response.force, c.point, info.dt());
        tools->publish();
      }
    } else if (tools != nullptr && (vps != nullptr || sphereTree != nullptr)) {
      // A 6-DOF tool touches at many points: each object gets the wrench
      // the renderer says the tool put on it this tick.
      for (std::size_t k = 0; k < tools->size(); ++k) {
        const Vec3 f = vps != nullptr ? vps->objectForce(k) : sphereTree->objectForce(k);
        const Vec3 t = vps != nullptr ? vps->objectTorque(k) : sphereTree->objectTorque(k);
        if (f.squaredNorm() > 0.0 || t.squaredNorm() > 0.0) tools->addWrench(k, f, t, info.dt());
      }
      tools->publish();
    }
    if (!ring.tryPush(p)) dropped.fetch_add(1, std::memory_order_relaxed);
    if (!scripts.empty()) publishToScripts(p, s);
    if (fluidTool != nullptr) {
      FluidToolSample& out = fluidTool->writeBuffer();
      out = {.proxy = s.response.proxyPose.translation(), .force = p.response.force, .valid = true};
      fluidTool->publish();
    }
    if (recorder) {
      // The device's state this tick, stamped with the tick's scene time
      // (what a replay's lockstep tick asks the replay-haptic device for).
      HapticState state = device->state();
      state.timeNs = static_cast<std::int64_t>(std::llround(p.t * 1e9));
      if (waitForRecorder)  // lockstep: as fast as the disk, never a dropped tick
        while (!recorder->hasRoom()) std::this_thread::yield();
      (void)recorder->pushHapticState(state);  // a drop is counted (summary)
    }
    if (toolPoint) toolPoint->write(s.input.devicePose.translation());  // the device point, world
    if (streamed) {
      StreamedSample& out = streamed->writeBuffer();
      out.tool = s.response.proxyPose;
      out.handle = s.input.devicePose;  // world
      out.force = p.response.force;
      out.t = p.t;
      out.valid = true;
      streamed->publish();
    }
    return true;
  }
  // The scripts' view of this tick: the tool's state, and an event when
  // contact began or ended (with the god-object's touched object).
  void publishToScripts(const ProbeSample& p, const HapticLoopSample& s) noexcept {
    const bool touching = p.response.contacts > 0;
    int source = lastContactObject;
    if (godObject != nullptr && godObject->contact().active) source = int(godObject->contact().object);
    if (godObject == nullptr) source = -1;
    for (ScriptFeed* f : scripts) {
      ScriptToolSample& out = f->tool.writeBuffer();
      out.tool = {.time = p.t,
                  .proxy = s.response.proxyPose,
                  .handle = s.input.devicePose,
                  .force = p.response.force,
                  .contacts = p.response.contacts,
                  .penetration = p.response.penetration};
      out.valid = true;
      f->tool.publish();
      if (touching != wasTouching)
        f->push(f->toolEvents,
                {.type = touching ? ScriptEvent::Type::ContactBegan : ScriptEvent::Type::ContactEnded,
                 .time = p.t,
                 .source = source,
                 .value = touching ? p.response.force.norm() : 0.0});
    }
    wasTouching = touching;
    lastContactObject = source;
  }
  std::vector<ScriptFeed*> scripts;                    // owned by their script engines
  TripleBuffer<FluidToolSample>* fluidTool = nullptr;  // owned by the physics engine's fluids
  bool wasTouching = false;
  int lastContactObject = -1;
  std::unique_ptr<HapticDevice> device;
  std::unique_ptr<GodObjectRenderer> feltGodObject;  // inside renderer, when it presses soft tissue
  std::unique_ptr<HapticRenderer> renderer;
  std::shared_ptr<PhysicsEngine> needleOwner;  // owns the needle or punch renderer, when the loop drives that
  HapticRenderer* physicsTool = nullptr;       // that renderer
  HapticRenderer* active = nullptr;              // what the loop ticks: renderer, or the needle
  GodObjectRenderer* godObject = nullptr;        // = renderer (or inside it), when it is the god-object
  BurrRenderer* burr = nullptr;                  // = renderer, when it is the burr
  VpsRenderer* vps = nullptr;                    // = renderer, when it is VPS
  SphereTree6DofRenderer* sphereTree = nullptr;  // = renderer, when it is the sphere tree
  // The bone-placement renderer (owned by renderer) and what its summary
  // measures: the first tick's fragment pose, the deepest contact.
  struct {
    BonePlacementRenderer* renderer = nullptr;
    std::vector<Vec3> referencePoints;
    std::size_t fixedVoxels = 0;
  } placement;
  Isometry3 placementFirstPose = Isometry3::Identity();
  bool placementStarted = false;
  double placementMaxDepth = 0.0;
  std::unique_ptr<MillableSurfaceFeed> boneFeed;
  std::string milledObject;
  double boneVolume = 0.0;  // m³ before milling
  std::unique_ptr<EffectStack> effects;  // the loop's (the segmentation's guidance), or null; outlives it
  std::unique_ptr<HapticLoop> loop;
  ToolImpulseChannel* tools = nullptr;  // owned by the physics engine
  SpscRing<ProbeSample, 16384> ring;
  std::atomic<std::uint64_t> dropped{0};
  // The newest tick for a streaming engine (OpenIGTLink); null without one.
  struct StreamedSample {
    Isometry3 tool = Isometry3::Identity(), handle = Isometry3::Identity();
    Vec3 force = Vec3::Zero();
    double t = 0.0;  // scene time of the tick
    bool valid = false;
  };
  std::unique_ptr<TripleBuffer<StreamedSample>> streamed;
  // The newest tick's device point for the segmentation engine (its own
  // channel: latest() has one consumer, the render engine's); null without one.
  std::unique_ptr<TripleBuffer<Vec3>> toolPoint;
  std::unique_ptr<DeviceRecorder> recorder;  // the device's stream, when the scene records it
  bool waitForRecorder = false;              // lockstep: wait for queue room instead of dropping
  TickTime time;
};

// |F| of the last `seconds` at the haptic rate, shared by the monitor
// (writer) and the render HUD (reader); neither is a real-time thread.
struct RecentForce {
  std::mutex m;
  std::vector<float> values;  // circular
  std::size_t next = 0;
  bool full = false;
  double seconds = 2.0;
  // Appends the |F| of `samples` under one lock.
  void push(std::span<const ProbeSample> samples) {
    std::lock_guard lock(m);
    for (const ProbeSample& p : samples) {
      values[next] = static_cast<float>(p.response.force.norm());
      next = (next + 1) % values.size();
      full = full || next == 0;
    }
  }
  void copy(std::vector<float>& out, double& secs) {
    std::lock_guard lock(m);
    out.clear();
    if (full) out.insert(out.end(), values.begin() + static_cast<std::ptrdiff_t>(next), values.end());
    out.insert(out.end(), values.begin(), values.begin() + static_cast<std::ptrdiff_t>(next));
    secs = seconds * double(out.size()) / double(values.size());
  }
};

// The monitor: drains the haptic samples into the force trace.
class MonitorEngine final : public Engine {
 public:
  MonitorEngine(HapticsEngine* h, RecentForce* r) : haptics(h), recent(r) {}
  std::string_view name() const noexcept override { return "monitor"; }
  bool tick(const TickInfo&) noexcept override {
    drain();
    return true;
  }
  void drain() {
    if (haptics == nullptr) return;
    const std::size_t first = trace.size();
    ProbeSample p;
    while (haptics->ring.tryPop(p)) trace.push_back(p);
    recent->push(std::span<const ProbeSample>(trace).subspan(first));
  }
  HapticsEngine* haptics;
  RecentForce* recent;
  std::vector<ProbeSample> trace;
};

// The BVH of an object's mesh in its own frame with the scene's uniform
// scale baked in (the god-object takes rigid poses); no copy at scale 1.
Result<MeshBvh> objectBvh(const Mesh& mesh, double scale) {
  if (scale == 1.0) return MeshBvh::build(mesh);
  Mesh m = mesh;
  m.transform(Affine3(Eigen::Scaling(scale)));
  return MeshBvh::build(m);
}

#ifdef DM_ENGINE_HAVE_NETWORK
// A device with "serve": the console side of a tele-operation link inside
// this process. In real time it stands for another machine: a UDP socket
// on its "listen" address and a real-time loop of its own at the device's
// servo rate, live before the simulator's net-haptic device opens. In
// lockstep a socket's datagrams would arrive on the wall clock, so the link
// is the in-process one ("inproc:NAME", dm/network/teleop.hpp) on the
// master's virtual clock, and the master ticks the console's servo as an
// engine ("serve:NAME") before the haptics engine: the same stream, with its
// emulated delay, jitter and loss, the same on every run.
struct ServedDevice {
  std::string name;
  std::unique_ptr<HapticDevice> device;
  std::unique_ptr<TeleopDevice> link;
  std::unique_ptr<TeleopDeviceBridge> bridge;
  std::unique_ptr<RealTimeLoop> loop;  // real time
  std::shared_ptr<Engine> engine;      // lockstep
  std::string address;  // what "@name" stands for

  void step(std::int64_t nowNs) noexcept {
    bridge->step(nowNs);
    maxOutputForce = std::max(maxOutputForce, device->lastOutput().force.norm());
  }

  ServedDevice() = default;
  ServedDevice(const ServedDevice&) = delete;
  ServedDevice& operator=(const ServedDevice&) = delete;
  ~ServedDevice() {
    if (loop) loop->stop();  // before the bridge, device and link it steps
  }

  nlohmann::json summary() const {
    const TeleopStats st = link->stats();
    const auto latency = [](const LatencyStats& l) {
      return nlohmann::json{
          {"count", l.count}, {"p50_ms", 1e3 * l.p50}, {"p99_ms", 1e3 * l.p99}, {"max_ms", 1e3 * l.max}};
    };
    nlohmann::json j = {{"device", name},
                        {"address", address},
                        {"transport", loop ? "udp" : "inproc"},
                        {"sent", st.sent},
                        {"received", st.received},
                        {"lost", st.lost},
                        {"loss_ratio", st.lossRatio},
                        {"round_trip", latency(st.roundTrip)},
                        {"one_way", latency(st.oneWay)},
                        {"jitter_ms", 1e3 * st.jitter},
                        {"zeroed_steps", bridge->zeroedSteps()},
                        {"max_output_force_N", maxOutputForce}};
    if (const WaveMasterPort* w = bridge->wavePort())
      j["wave"] = {{"energy_in_J", w->receiver().energyIn()},
                   {"energy_out_J", w->receiver().energyOut()},
                   {"limited", w->receiver().stats().limited}};
    return j;
  }
  double maxOutputForce = 0.0;  // written by the loop thread, read after it stopped
};

// Opens and serves the device `d` (which has "serve"): in real time on its
// socket and loop, started here; in lockstep on an in-process link on
// `lockstepClock`, with the engine the caller adds to the master.
Result<std::unique_ptr<ServedDevice>> serveDevice(FactoryRegistry& registry, const SceneDevice& d,
                                                  const Clock* lockstepClock) {
  const std::string where = "devices/" + d.name + "/serve";
  auto listen = parseEndpoint(d.serve->listen, where + "/listen", true);
  if (!listen) return listen.error();
  auto sd = std::make_unique<ServedDevice>();
  sd->name = d.name;
  auto device = HapticDevice::open(registry, d.driver, deviceParams(d));
  if (!device) return device.error().within("devices/" + d.name);
  sd->device = std::move(*device);
  TeleopOptions options{.local = *listen, .timeoutSeconds = d.serve->timeout};
  if (lockstepClock != nullptr) {
    options.local = {"inproc:" + d.name, 0};
    options.clock = lockstepClock;
  } else {
    // On a loopback address the simulator is on this machine, with the same
    // CLOCK_MONOTONIC: one-way latencies need no offset estimate.
    options.clocksSynchronized = listen->address.starts_with("127.") || listen->address == "::1";
  }
  auto link = TeleopDevice::open(options, sd->device->info());
  if (!link) return link.error().within(where);
  sd->link = std::move(*link);
  const std::string host = listen->address.empty() || listen->address == "0.0.0.0" ? "127.0.0.1"
                           : listen->address == "::"                               ? "[::1]"
                           : listen->address.find(':') != std::string::npos ? "[" + listen->address + "]"
                                                                            : listen->address;
  sd->address =
      lockstepClock != nullptr ? options.local.address : host + ":" + std::to_string(sd->link->port());
  sd->bridge = std::make_unique<TeleopDeviceBridge>(
      *sd->device, *sd->link,
      TeleopBridgeOptions{.timeoutSeconds = d.serve->timeout, .waveImpedance = d.serve->waveImpedance});
  ServedDevice* raw = sd.get();
  if (lockstepClock != nullptr) {
    sd->engine = makeFunctionEngine("serve:" + d.name, [raw](const TickInfo& t) {
      raw->step(t.start_ns);
      return true;
    });
    return sd;
  }
  sd->loop = std::make_unique<RealTimeLoop>(
      RealTimeLoopConfig{.rate_hz = sd->device->info().servoRateHz, .name = "dm-served"},
      [raw](const TickInfo& t) { raw->step(t.start_ns); });
  if (auto s = sd->loop->start(); !s) return s.error().within(where);
  return sd;
}
#endif

}  // namespace

struct SceneRuntime::Impl {
  SceneDesc scene;
  SceneResources resources;
  MasterEngine master;
  std::shared_ptr<HapticsEngine> haptics;
  std::shared_ptr<PhysicsEngine> physics;
  std::shared_ptr<MonitorEngine> monitor;
  RecentForce recent;
  FactoryRegistry registry;
  std::unique_ptr<PluginLinker> linker;
#ifdef DM_ENGINE_HAVE_RENDERER
  std::shared_ptr<RenderEngineHandle> render;
#endif
  std::vector<std::pair<std::shared_ptr<Engine>, EngineSchedule>> userEngines;
  std::vector<std::shared_ptr<ScriptEngine>> scripts;
#ifdef DM_ENGINE_HAVE_NETWORK
  std::vector<std::unique_ptr<ServedDevice>> served;  // destroyed before the registry and linker
  std::shared_ptr<IgtlEngineHandle> igtl;
#endif
#ifdef DM_ENGINE_HAVE_VISION
  std::shared_ptr<VisionEngineHandle> vision;
  std::shared_ptr<SegmentationEngineHandle> segmentation;
#endif
  // A run between start() and finish().
  struct Running {
    bool started = false;
    bool finished = false;
    bool lockstep = true;
    double duration = 0.0;  // run()'s; 0 for a run stepped by advance()
    Result<HostCpuTimes> hostBefore = HostCpuTimes{};
    PageFaults faultsBefore{};
    bool lockedMemory = false;  // this run locked the process's memory (and unlocks it)
    SteadyClock::time_point wallStart{};
    double done = 0.0;  // s of the run so far
    Status status = ok();
    bool interrupted = false;
  } running;
  std::shared_ptr<FrameSlot> frames;  // the render engine's newest view, before the HUD (OpenIGTLink, vision)
  std::shared_ptr<FrameSlot> shown;   // its newest frame as written (SceneRunOptions::liveFrames)
  std::shared_ptr<TripleBuffer<ViewOrbit>> orbit;  // a live view's turn of the camera → render
  bool prepared = false;
  RunMode preparedMode = RunMode::Lockstep;
  std::filesystem::path preparedOut;
  bool ran = false;

  Status buildHaptics(bool lockstep);
  Result<std::unique_ptr<GodObjectRenderer>> buildGodObject();
  Status buildEngines(bool lockstep, const SceneRunOptions& options, const std::filesystem::path& out);
  Status buildIgtl(std::shared_ptr<FrameSlot> slot);
  Status startRecording(bool lockstep, const std::filesystem::path& out);
  Status buildScripts(double monitorRate);
};

// The scene's scripts, each an engine at the rate of the one it names,
// added after every other engine: at equal lockstep times a script sees
// the haptic tick and physics step of its own time.
Status SceneRuntime::Impl::buildScripts(double monitorRate) {
  for (const SceneScript& sc : scene.scripts) {
    auto instance = loadScript(sc);
    if (!instance) return instance.error();
    ScriptNames names;
    if (scene.engines.haptics) names.touched = scene.engines.haptics->objects;
    if (physics) {
      names.soft = physics->softObjects();
      names.layer = [p = physics.get()](std::size_t i, int layer) { return p->layerName(i, layer); };
      for (const SceneFluid& f : scene.fluids)
        for (const SceneFluidInlet& in : f.inlets) names.inlets.emplace_back(f.name, in.name);
    }
    auto e = std::make_shared<ScriptEngine>(sc, std::move(*instance),
                                            physics ? physics->movingObjects() : std::vector<std::string>(),
                                            haptics != nullptr, std::move(names));
    if (physics)
      if (auto s = physics->addScriptFeed(e->feed()); !s) return s.error().within("scripts/" + sc.name);
    if (haptics) haptics->scripts.push_back(&e->feed());
    const SceneEngines& en = scene.engines;
    const double rate = sc.engine == "physics" && en.physics ? en.physics->rateHz
                        : sc.engine == "render" && en.render ? en.render->rateHz
                        : sc.engine == "vision" && en.vision ? en.vision->rateHz
                        : sc.engine == "igtl" && en.igtl     ? en.igtl->rateHz
                                                             : monitorRate;
    if (auto s = master.addEngine(e, {.rateHz = rate}); !s) return s.error().within("scripts/" + sc.name);
    scripts.push_back(std::move(e));
  }
  return ok();
}

// The haptic device's stream to out/recording.dmrec, from the first tick:
// the header holds what a replay needs (dm::sceneRecordingMetadata).
Status SceneRuntime::Impl::startRecording(bool lockstep, const std::filesystem::path& out) {
  const SceneDevice* dev = scene.device(scene.engines.haptics->device);
  if (dev == nullptr || !haptics) return ok();  // (refused earlier)
  const nlohmann::json meta = sceneRecordingMetadata(scene, *dev, haptics->device->info(), lockstep);
  auto rec = DeviceRecorder::create(out / std::string(kSceneRecordingFile),
                                    {.metadata = meta.dump(), .overwrite = true});
  if (!rec) return rec.error().within("outputs/recording");
  haptics->recorder = std::move(*rec);
  haptics->waitForRecorder = lockstep;
  return ok();
}

Status SceneRuntime::Impl::buildHaptics(bool lockstep) {
  const SceneHapticsEngine& h = *scene.engines.haptics;
  const std::string where = "engines/haptics";
  auto e = std::make_shared<HapticsEngine>();
  if (h.renderer == SceneHapticsEngine::Renderer::Burr) {
    auto b = buildSceneBurr(scene, resources);
    if (!b) return b.error();
    e->burr = b->renderer.get();
    e->renderer = std::move(b->renderer);
    e->boneFeed = std::move(b->feed);
    e->milledObject = b->object;
    e->boneVolume = b->initialVolume;
  } else if (h.renderer == SceneHapticsEngine::Renderer::GodObject) {
    auto g = buildGodObject();
    if (!g) return g.error();
    e->godObject = g->get();
    // Soft objects it touches: their surfaces come from physics each tick
    // and the grip goes back (dm::TissueGodObject).
    std::vector<TissueBinding> felt;
    for (std::size_t k = 0; k < h.objects.size() && physics; ++k)
      if (HapticTissue* t = physics->tissue(h.objects[k])) felt.push_back({t, k});
    if (felt.empty()) {
      e->renderer = std::move(*g);
    } else {
      e->feltGodObject = std::move(*g);
      e->renderer = std::make_unique<TissueGodObject>(*e->godObject, felt);
    }
  } else if (h.renderer == SceneHapticsEngine::Renderer::Needle) {
    // The needle and its tissue live in the physics engine, which steps
    // them; the loop ticks the needle's renderer.
    if (!physics || physics->needleRenderer() == nullptr)
      return fail(ErrorCode::InvalidArgument, "the needle renderer has no soft object with layers", where,
                  "name one in \"objects\" and give it \"layers\"");
    e->needleOwner = physics;
    e->physicsTool = physics->needleRenderer();
  } else if (h.renderer == SceneHapticsEngine::Renderer::Punch) {
    // The punch and its tissue live in the physics engine, which steps
    // them; the loop ticks the punch's renderer.
    if (!physics || physics->punchRenderer() == nullptr)
      return fail(ErrorCode::InvalidArgument, "the punch renderer has no soft object", where + "/punch",
                  "name a soft object in \"punch\" and add the physics engine");
    e->needleOwner = physics;
    e->physicsTool = physics->punchRenderer();
  } else if (h.renderer == SceneHapticsEngine::Renderer::Vps) {
    auto v = buildSceneVps(scene, resources);
    if (!v) return v.error();
    e->vps = v->get();
    e->renderer = std::move(*v);
  } else if (h.renderer == SceneHapticsEngine::Renderer::None) {
    e->renderer = std::make_unique<FreeSpaceRenderer>();
  } else if (h.renderer == SceneHapticsEngine::Renderer::BonePlacement) {
    auto b = buildSceneBonePlacement(scene, resources);
    if (!b) return b.error();
    e->placement.renderer = b->renderer.get();
    e->placement.referencePoints = std::move(b->referencePoints);
    e->placement.fixedVoxels = b->fixedVoxels;
    e->renderer = std::move(b->renderer);
  } else {
    auto t = buildSceneSphereTree(scene, resources);
    if (!t) return t.error();
    e->sphereTree = t->get();
    e->renderer = std::move(*t);
  }
  const SceneDevice* dev = scene.device(h.device);
  if (dev == nullptr) return fail(ErrorCode::NotFound, "no device \"" + h.device + "\"", where + "/device");
  linker = std::make_unique<PluginLinker>(registry);
  if (auto s = registerBuiltinDrivers(*linker); !s) return s.error();
  std::vector<std::pair<std::string, std::string>> params = deviceParams(*dev);
#ifdef DM_ENGINE_HAVE_NETWORK
  if (auto s = registerNetworkDrivers(*linker); !s) return s.error();
  for (const SceneDevice& d : scene.devices) {
    if (!d.serve) continue;
    auto sd = serveDevice(registry, d, lockstep ? &master.virtualClock() : nullptr);
    if (!sd) return sd.error();
    served.push_back(std::move(*sd));
  }
  for (auto& [key, value] : params)
    for (const auto& sd : served)
      if (value == "@" + sd->name) value = sd->address;
#else
  for (const SceneDevice& d : scene.devices)
    if (d.serve)
      return fail(ErrorCode::Unsupported, "this build has no DMNetwork, which serves devices",
                  "devices/" + d.name + "/serve", "build with DMNetwork (libasio-dev) or remove \"serve\"");
#endif
  auto device = HapticDevice::open(registry, dev->driver, params);
  if (!device) return device.error().within("devices/" + dev->name);

  e->device = std::move(*device);
  e->fluidTool = physics ? physics->fluidTool() : nullptr;
  e->tools = physics && (e->godObject != nullptr || e->vps != nullptr || e->sphereTree != nullptr)
                 ? physics->toolImpulses()
                 : nullptr;
  HapticLoopConfig config;
  config.loop = {.rate_hz = h.rateHz, .name = "haptics"};
  config.deviceToWorld = h.devicePose.isometry();
  config.forceLimit = h.maxForce;
  // In lockstep an overrun says how loaded this machine is, not what the
  // simulation did: count it but keep the output (bit-identical reruns).
  config.overrunFades = !lockstep;
  HapticRenderer& renderer = e->physicsTool ? *e->physicsTool : *e->renderer;
  e->active = &renderer;
#ifdef DM_ENGINE_HAVE_VISION
  if (segmentation)
    if (std::unique_ptr<ForceEffect> guidance = segmentation->guidance()) {
      e->effects = std::make_unique<EffectStack>(1);
      if (auto added = e->effects->add(std::move(guidance)); !added)
        return added.error().within("engines/segmentation");
    }
#endif
  auto loop = HapticLoop::create({.device = *e->device,
                                  .renderer = renderer,
                                  .model = physics ? physics->hapticModel() : nullptr,
                                  .effects = e->effects.get()},
                                 config);
  if (!loop) return loop.error().within(where);
  e->loop = std::move(*loop);
  haptics = e;
  return ok();
}

Result<std::unique_ptr<GodObjectRenderer>> SceneRuntime::Impl::buildGodObject() {
  const SceneHapticsEngine& h = *scene.engines.haptics;
  const std::string where = "engines/haptics";
  std::vector<GodObjectObject> objects;
  for (const std::string& name : h.objects) {
    const SceneObject* o = scene.object(name);
    if (o == nullptr) return fail(ErrorCode::NotFound, "no object \"" + name + "\"", where + "/objects");
    const SceneMaterial* mat = scene.material(o->material);
    if (mat == nullptr || !mat->haptic)
      return fail(ErrorCode::InvalidArgument, "touchable object \"" + name + "\" has no haptic material",
                  "objects/" + name + "/material",
                  "give its material a \"haptic\" block with stiffness (N/m) and friction");
    GodObjectObject g;
    if (HapticTissue* t = physics ? physics->tissue(name) : nullptr) {
      g.bvh = t->restTree();  // the FEM body's surface, deformed by physics
    } else {
      auto mesh = resources.mesh(o->mesh);
      if (!mesh)
        return fail(ErrorCode::NotFound, "mesh \"" + o->mesh + "\" was not loaded", "objects/" + name);
      auto bvh = objectBvh(*mesh, o->scale);
      if (!bvh) return bvh.error().within("objects/" + name);
      g.bvh = std::make_shared<const MeshBvh>(std::move(*bvh));
    }
    g.pose = o->pose.isometry();
    g.material = {.stiffness = mat->haptic->stiffness,
                  .damping = mat->haptic->damping,
                  .staticFriction = mat->haptic->staticFriction,
                  .dynamicFriction = mat->haptic->dynamicFriction};
    objects.push_back(std::move(g));
  }
  GodObjectOptions go;
  go.proxyRadius = h.toolRadius;
  go.forceShading = h.forceShading;
  if (h.maxForce > 0) go.maxForce = h.maxForce;
  auto renderer = GodObjectRenderer::create(std::move(objects), go);
  if (!renderer) return renderer.error().within(where);
  return std::move(*renderer);
}

nlohmann::json engineStatsJson(const std::vector<EngineStats>& stats) {
  nlohmann::json engines = nlohmann::json::array();
  for (const EngineStats& e : stats)
    engines.push_back({{"name", e.name},
                       {"rate_hz", e.rateHz},
                       {"achieved_hz", e.achievedHz},
                       {"ticks", e.ticks},
                       {"deadline_misses", e.deadlineMisses},
                       {"execution_us",
                        {{"p50", e.execution.p50_us},
                         {"p99", e.execution.p99_us},
                         {"p999", e.execution.p999_us},
                         {"max", e.execution.max_us}}},
                       {"wakeup_us",
                        {{"p50", e.wakeup.p50_us},
                         {"p99", e.wakeup.p99_us},
                         {"p999", e.wakeup.p999_us},
                         {"max", e.wakeup.max_us}}}});
  return engines;
}

SceneRuntime::SceneRuntime() : impl_(std::make_unique<Impl>()) {}
SceneRuntime::~SceneRuntime() {
  if (impl_ && impl_->master.state() != SimState::Stopped && impl_->master.state() != SimState::Created)
    (void)impl_->master.stop("runtime destroyed");
  if (impl_ && impl_->running.lockedMemory && !impl_->running.finished) unlockProcessMemory();
}

Status SceneRuntime::Impl::buildEngines(bool lockstep, const SceneRunOptions& options,
                                        const std::filesystem::path& out) {
  // Engines: physics is built first (the haptic loop takes its local model
  // and tool channel), haptics added first (at equal lockstep times it
  // ticks before physics, which then sees that tick's impulse), then
  // physics, the monitor, the renderer, and user engines.
  if (scene.engines.physics) {
    const std::vector<std::string> touched =
        scene.engines.haptics ? scene.engines.haptics->objects : std::vector<std::string>();
    auto p = PhysicsEngine::build(scene, resources, touched);
    if (!p) return p.error();
    physics = *p;
  }
  // The segmentation before the haptic loop, which takes its guidance.
  if (scene.engines.segmentation) {
#ifdef DM_ENGINE_HAVE_VISION
    auto g = makeSegmentationEngine(scene, resources);
    if (!g) return g.error();
    segmentation = *g;
#else
    return fail(ErrorCode::Unsupported, "this build has no DMVision, which the segmentation engine needs",
                "engines/segmentation", "build with DMVision (libopencv-dev) or remove it");
#endif
  }
  if (scene.engines.haptics) {
    if (auto s = buildHaptics(lockstep); !s) return s.error();
#ifdef DM_ENGINE_HAVE_NETWORK
    // Lockstep: a served console's servo before the haptics engine, which
    // then reads what its link delivered by that time.
    for (const auto& sd : served)
      if (sd->engine)
        if (auto s = master.addEngine(sd->engine, {.rateHz = sd->device->info().servoRateHz}); !s)
          return s.error();
#endif
    if (auto s = master.addEngine(haptics, {.rateHz = scene.engines.haptics->rateHz, .priority = 80}); !s)
      return s.error();
    if (scene.outputs.recording)
      if (auto s = startRecording(lockstep, out); !s) return s.error();
  }
  if (physics)
    if (auto s = master.addEngine(
            physics, {.rateHz = scene.engines.physics->rateHz, .priority = 60, .catchUp = kPhysicsCatchUp});
        !s)
      return s.error();
  const double hapticRate = scene.engines.haptics ? scene.engines.haptics->rateHz : 1000.0;
  recent.values.assign(static_cast<std::size_t>(std::max(2.0, hapticRate * recent.seconds)), 0.0f);
  monitor = std::make_shared<MonitorEngine>(haptics.get(), &recent);
  monitor->trace.reserve(haptics ? static_cast<std::size_t>(options.duration * hapticRate * 1.05) + 64 : 0);
  const double monitorRate = scene.engines.monitor ? scene.engines.monitor->rateHz : 30.0;
  if (auto s = master.addEngine(monitor, {.rateHz = monitorRate}); !s) return s.error();
  // The vision graph first: whether it takes rendered frames decides
  // whether the render engine reads them back.
  bool visionWantsFrames = false;
  if (scene.engines.vision) {
#ifdef DM_ENGINE_HAVE_VISION
    auto v = makeVisionEngine(scene, out);
    if (!v) return v.error();
    vision = *v;
    visionWantsFrames = !vision->inputs().empty();
#else
    return fail(ErrorCode::Unsupported, "this build has no DMVision, which the vision engine needs",
                "engines/vision", "build with DMVision (libopencv-dev) or remove it");
#endif
  }
  // (frames: render → OpenIGTLink and vision)
  if (scene.engines.render) {
#ifdef DM_ENGINE_HAVE_RENDERER
    RenderFeed feed;
    if (physics) {
      feed.movingObjects = physics->movingObjects();
      feed.objectPoses = [p = physics.get()](std::vector<Isometry3>& poses) {
        return p->latestPoses(PoseReader::Render, poses);
      };
      feed.softObjects = physics->softObjects();
      feed.softSurface = [p = physics.get()](std::size_t i, Mesh& surface) {
        return p->latestSurface(i, surface);
      };
      for (const SceneFluid& f : scene.fluids) {
        const SceneFluidLook& look = f.look;
        // Unset, the absorption lets a layer 1 mm thick transmit the colour.
        Vec3 absorption = Vec3::Zero();
        for (int c = 0; c < 3; ++c) absorption[c] = -std::log(std::clamp(f.color[c], 1e-4, 1.0)) / 1e-3;
        feed.fluids.push_back(
            {.name = f.name,
             .radius = 0.5 * f.spacing,
             .color = Vec4f(float(f.color.x()), float(f.color.y()), float(f.color.z()), 1.0f),
             .surface = look.style == SceneFluidLook::Style::Surface,
             .absorption = look.absorption.value_or(absorption).cast<float>(),
             .fresnel = float(look.fresnel),
             .specular = float(look.specular),
             .shininess = float(look.shininess),
             .refraction = float(look.refraction),
             .smoothing = look.smoothing});
      }
      if (!feed.fluids.empty())
        feed.fluidParticles = [p = physics.get()](std::size_t i, std::vector<Vec3>& positions) {
          return p->latestFluidParticles(i, positions);
        };
    }
    if (haptics) {
      HapticsEngine* h = haptics.get();
      feed.haptics = [h](Isometry3& proxy, Vec3& force) {
        const HapticLoopSample& s = h->loop->latest();
        proxy = s.response.proxyPose;
        force = h->loop->config().deviceToWorld.linear() * s.deviceForce;
        return true;
      };
      feed.recentForce = [r = &recent](std::vector<float>& v, double& secs) { r->copy(v, secs); };
      if (h->boneFeed) {
        feed.millableObject = h->milledObject;
        feed.millableSurface = [f = h->boneFeed.get()](Mesh& surface) { return f->update(surface); };
      }
    }
#ifdef DM_ENGINE_HAVE_VISION
    if (vision && !scene.engines.vision->overlay.empty())
      feed.overlay = [v = vision.get()](Image& image, std::int64_t& frame) {
        return v->overlay(image, frame);
      };
#endif
    if ((scene.engines.igtl && !scene.engines.igtl->image.empty()) || visionWantsFrames) {
      frames = std::make_shared<FrameSlot>();
      feed.frames = frames;
    }
    if (options.liveFrames) {
      shown = std::make_shared<FrameSlot>();
      feed.shown = shown;
      orbit = std::make_shared<TripleBuffer<ViewOrbit>>();
      feed.viewOrbit = [o = orbit](ViewOrbit& newest) {
        if (!o->update()) return false;
        newest = o->readBuffer();
        return true;
      };
    }
    auto made = makeRenderEngine(scene, resources, std::move(feed),
                                 scene.outputs.frames ? out / "frames" : std::filesystem::path(),
                                 scene.outputs.frameEvery, lockstep);
    if (!made) return made.error();
    render = *made;
    if (auto s = master.addEngine(render->engine(),
                                  {.rateHz = scene.engines.render->rateHz, .catchUp = kRenderCatchUp});
        !s)
      return s.error();
#else
    (void)out;
    return fail(ErrorCode::Unsupported, "this build has no DMRenderer (EGL was not found at configure time)",
                "engines/render",
                "install libegl-dev libegl1-mesa-dev libgl1-mesa-dri and rebuild, or remove it");
#endif
  }
  if (scene.engines.igtl)
    if (auto s = buildIgtl(frames); !s) return s.error();
#ifdef DM_ENGINE_HAVE_VISION
  if (vision) {
    vision->setFrames(frames);
    if (auto s = master.addEngine(vision->engine(), {.rateHz = scene.engines.vision->rateHz}); !s)
      return s.error();
  }
  if (segmentation && haptics) {  // (the scene reader asks for a haptics engine)
    haptics->toolPoint =
        std::make_unique<TripleBuffer<Vec3>>(Vec3::Constant(std::numeric_limits<double>::quiet_NaN()));
    segmentation->setTool([b = haptics->toolPoint.get()] { return b->read(); });
    if (auto s = master.addEngine(segmentation->engine(), {.rateHz = scene.engines.segmentation->rateHz}); !s)
      return s.error();
  }
#endif
  if (auto s = buildScripts(monitorRate); !s) return s.error();
  for (auto& [engine, schedule] : userEngines)
    if (auto s = master.addEngine(engine, schedule); !s) return s.error();

  return ok();
}

// The OpenIGTLink engine, after the render engine (in lockstep it then
// streams the frame of the same time); listening from here on.
Status SceneRuntime::Impl::buildIgtl(std::shared_ptr<FrameSlot> slot) {
#ifdef DM_ENGINE_HAVE_NETWORK
  const SceneIgtlEngine& g = *scene.engines.igtl;
  IgtlFeed feed;
  feed.frames = std::move(slot);
  if (haptics && (!g.tool.empty() || !g.handle.empty() || !g.force.empty())) {
    haptics->streamed = std::make_unique<TripleBuffer<HapticsEngine::StreamedSample>>();
    feed.haptics = [b = haptics->streamed.get()](Isometry3& tool, Isometry3& handle, Vec3& force, double& t) {
      const HapticsEngine::StreamedSample& s = b->read();
      tool = s.tool;
      handle = s.handle;
      force = s.force;
      t = s.t;
      return s.valid;
    };
  }
  if (physics && g.bodies) {
    feed.bodies = physics->movingObjects();
    feed.bodyPoses = [p = physics.get()](std::vector<Isometry3>& poses) {
      return p->latestPoses(PoseReader::Network, poses);
    };
  }
  std::size_t frameBytes = 0;
  if (scene.engines.render && !g.image.empty())
    frameBytes = std::size_t(scene.engines.render->width) * std::size_t(scene.engines.render->height) * 3;
  auto made = makeIgtlEngine(g, std::move(feed), frameBytes);
  if (!made) return made.error();
  igtl = *made;
  return master.addEngine(igtl->engine(), {.rateHz = g.rateHz});
#else
  (void)slot;
  return fail(ErrorCode::Unsupported, "this build has no DMNetwork, which the OpenIGTLink engine needs",
              "engines/igtl", "build with DMNetwork (libasio-dev) or remove it");
#endif
}

Result<std::unique_ptr<SceneRuntime>> SceneRuntime::load(const std::filesystem::path& sceneFile) {
  std::vector<Error> problems;
  auto scene = readScene(sceneFile, &problems);
  if (!scene) {
    if (problems.size() > 1) {
      Error e = scene.error();
      e.what = formatString("%zu problems:\n", problems.size()) + formatSceneErrors(problems);
      return e;
    }
    return scene.error();
  }
  return create(*scene);
}

Result<std::unique_ptr<SceneRuntime>> SceneRuntime::create(const SceneDesc& scene) {
  std::unique_ptr<SceneRuntime> rt(new SceneRuntime());
  rt->impl_->scene = scene;
  auto res = loadSceneResources(scene);
  if (!res) return res.error();
  rt->impl_->resources = std::move(*res);
  return rt;
}

Status SceneRuntime::addEngine(std::shared_ptr<Engine> engine, const EngineSchedule& schedule) {
  if (!engine) return fail(ErrorCode::InvalidArgument, "null engine", "SceneRuntime::addEngine");
  impl_->userEngines.emplace_back(std::move(engine), schedule);
  return ok();
}

MasterEngine& SceneRuntime::master() { return impl_->master; }

bool SceneRuntime::latestFrame(std::uint64_t& seen, Image& out, double& sceneTime,
                               FrameCamera* camera) const {
  return impl_->shown && impl_->shown->takeIfNewer(seen, out, sceneTime, camera);
}

void SceneRuntime::setViewOrbit(const ViewOrbit& orbit) {
  if (impl_->orbit) impl_->orbit->write(orbit);
}

std::uint16_t SceneRuntime::igtlPort() const {
#ifdef DM_ENGINE_HAVE_NETWORK
  return impl_->igtl ? impl_->igtl->port() : 0;
#else
  return 0;
#endif
}
const SceneDesc& SceneRuntime::scene() const { return impl_->scene; }

Status SceneRuntime::prepare(const SceneRunOptions& options) {
  Impl& im = *impl_;
  if (im.prepared)
    return fail(ErrorCode::InvalidArgument, "a SceneRuntime is prepared once", "SceneRuntime::prepare");
  if (auto s = checkDuration(options); !s) return s.error();
  const SceneDesc& scene = im.scene;
  if (options.liveFrames && !scene.engines.render)
    return fail(ErrorCode::InvalidArgument,
                "a live view shows the render engine's frames, and the scene has none", "engines/render",
                "add \"render\": {\"rate_hz\": 30} to the scene's \"engines\"");
  const std::filesystem::path out =
      options.outDir.empty() ? std::filesystem::path(scene.outputs.directory) : options.outDir;
  // A scene that cannot be built leaves no output folder behind: it is
  // made only when it did not exist, and removed again on failure.
  std::error_code ec;
  const bool outExisted = std::filesystem::exists(out, ec);
  std::filesystem::create_directories(out, ec);
  if (ec) return fail(ErrorCode::Io, "cannot create the output folder: " + ec.message(), out.string());
  Status built = im.buildEngines(options.mode == RunMode::Lockstep, options, out);
  if (built) built = im.master.load(scene.name);
  if (!built) {
    if (!outExisted) std::filesystem::remove_all(out, ec);
    return built.error();
  }
  im.prepared = true;
  im.preparedMode = options.mode;
  im.preparedOut = out;
  return ok();
}

Status SceneRuntime::start(const SceneRunOptions& options) {
  Impl& im = *impl_;
  if (im.ran) return fail(ErrorCode::InvalidArgument, "a SceneRuntime runs once", "SceneRuntime::start");
  if (!im.prepared) {
    if (auto s = prepare(options); !s) {
      im.ran = true;
      return s.error();
    }
  }
  im.ran = true;
  const bool lockstep = options.mode == RunMode::Lockstep;
  const SceneDesc& scene = im.scene;
  const std::filesystem::path out = im.preparedOut;
  if (options.mode != im.preparedMode ||
      (!options.outDir.empty() && std::filesystem::path(options.outDir) != out))
    return fail(ErrorCode::InvalidArgument, "run() was given another mode or output folder than prepare()",
                "SceneRuntime::start", "pass the same options to both");
  if (auto s = checkDuration(options); !s) return s.error();

  if (im.haptics) im.haptics->active->reset(im.haptics->loop->config().deviceToWorld);
#ifdef DM_ENGINE_HAVE_NETWORK
  if (im.igtl && scene.engines.igtl->waitForClients > 0) {
    log::info("waiting for %d OpenIGTLink client(s) on port %u", scene.engines.igtl->waitForClients,
              unsigned{im.igtl->port()});
    if (auto s = im.igtl->waitForClients(options.stop); !s) {
      (void)im.master.stop("no OpenIGTLink clients");
      return s.error();
    }
  }
#endif
  // In real time the process's pages stay in RAM (a page read back from
  // disk in a tick is a missed deadline); a process that cannot lock runs
  // unlocked and says why.
  bool lockedMemory = false;
  if (!lockstep) {
    if (Status s = lockProcessMemory(); s)
      lockedMemory = true;
    else
      log::warn("running with the memory unlocked: %s", s.error().message().c_str());
  }
  if (auto s = im.master.start(options.mode); !s) {
    if (lockedMemory) unlockProcessMemory();
    return s.error();
  }
  // The host's CPU accounts bracket the run: steal time says the hypervisor
  // stopped this machine's CPUs, which no thread priority can prevent.
  im.running = {.started = true,
                .lockstep = lockstep,
                .hostBefore = readHostCpuTimes(),
                .faultsBefore = readPageFaults(),
                .lockedMemory = lockedMemory,
                .wallStart = SteadyClock::now()};
  return ok();
}

Status SceneRuntime::advance(double seconds) {
  Impl& im = *impl_;
  Impl::Running& r = im.running;
  if (!r.started || r.finished || !r.lockstep)
    return fail(ErrorCode::InvalidArgument, "advance() needs a lockstep run started and not finished",
                "SceneRuntime::advance", "start() it with RunMode::Lockstep first");
  if (!(seconds >= 0.0) || !std::isfinite(seconds))
    return fail(ErrorCode::InvalidArgument, formatString("advance by %g s", seconds),
                "SceneRuntime::advance");
  if (!r.status) return r.status.error();
  // 0.1 s chunks of simulated time (the master's, as run() takes them).
  for (double left = seconds; left > 0.0;) {
    const double step = std::min(0.1, left);
    if (auto st = im.master.advance(step); !st) {
      r.status = st;
      return st.error();
    }
    r.done += step;
    left -= step;
  }
  return ok();
}

double SceneRuntime::time() const { return impl_->running.done; }

Result<nlohmann::json> SceneRuntime::state() {
  Impl& im = *impl_;
  if (!im.running.started || im.running.finished || !im.running.lockstep)
    return fail(ErrorCode::InvalidArgument, "state() reads a lockstep run between advances",
                "SceneRuntime::state", "start() it with RunMode::Lockstep and read it after advance()");
  // Nothing ticks between lockstep advances: the engines' state is read here.
  nlohmann::json j = {{"time_s", im.running.done}};
  if (im.physics) j["physics"] = im.physics->summary();
  im.monitor->drain();
  if (im.haptics && !im.monitor->trace.empty()) {
    const ProbeSample& p = im.monitor->trace.back();
    const Vec3 proxy = p.response.proxyPose.translation();
    j["haptics"] = {{"time_s", p.t},
                    {"force_N", {p.response.force.x(), p.response.force.y(), p.response.force.z()}},
                    {"proxy_m", {proxy.x(), proxy.y(), proxy.z()}},
                    {"contacts", p.response.contacts}};
  }
  if (!im.scripts.empty()) {
    nlohmann::json scripts = nlohmann::json::object();
    for (std::size_t i = 0; i < im.scripts.size(); ++i)
      scripts[im.scene.scripts[i].name] = im.scripts[i]->metrics();
    j["scripts"] = std::move(scripts);
  }
  return j;
}

Result<SceneRunResult> SceneRuntime::run(const SceneRunOptions& options) {
  Impl& im = *impl_;
  if (auto s = start(options); !s) return s.error();
  Impl::Running& r = im.running;
  r.duration = options.duration;
  auto status = [&]() {
    std::string s = formatString("t = %.1f s", r.done);
    if (im.haptics && !im.monitor->trace.empty())
      s += formatString("  |F| = %.2f N", im.monitor->trace.back().response.force.norm());
    return s;
  };
  // Lockstep in 0.1 s chunks of simulated time, real time polling.
  while (r.done < options.duration) {
    if (options.stop != nullptr && options.stop->load()) {
      r.interrupted = true;
      break;
    }
    if (r.lockstep) {
      if (!advance(std::min(0.1, options.duration - r.done))) break;  // (kept in r.status)
    } else {
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
      r.done =
          std::min(options.duration, std::chrono::duration<double>(SteadyClock::now() - r.wallStart).count());
      if (auto s = im.master.poll(); !s) {
        r.status = s;
        break;
      }
    }
    if (options.progress) options.progress(r.done / options.duration, status());
  }
  return finish();
}

Result<SceneRunResult> SceneRuntime::finish() {
  Impl& im = *impl_;
  Impl::Running& r = im.running;
  if (!r.started || r.finished)
    return fail(ErrorCode::InvalidArgument, "finish() needs a started run, once", "SceneRuntime::finish");
  r.finished = true;
  if (!r.lockstep && r.duration == 0.0)  // started by hand in real time: as long as it ran
    r.done = std::chrono::duration<double>(SteadyClock::now() - r.wallStart).count();
  const bool lockstep = r.lockstep;
  const SceneDesc& scene = im.scene;
  const std::filesystem::path out = im.preparedOut;
  const double done = r.done;
  const Status& runStatus = r.status;
  const Result<HostCpuTimes>& hostBefore = r.hostBefore;
  const auto wallStart = r.wallStart;
  SceneRunResult result;
  result.interrupted = r.interrupted;
  // A run stepped by advance() lasted as long as it was advanced.
  const double duration = r.duration > 0.0 ? r.duration : done;

  result.simulatedSeconds = done;
  const std::vector<EngineStats> engineStats = im.master.stats();
  const Result<HostCpuTimes> hostAfter = readHostCpuTimes();
  const PageFaults faultsAfter = readPageFaults();
  const bool memoryLocked = processMemoryLocked();
  Status stopStatus = im.master.stop(result.interrupted ? "interrupted" : "done");
  if (r.lockedMemory) unlockProcessMemory();
  im.monitor->drain();
  Status recordStatus = ok();
  if (im.haptics && im.haptics->recorder) recordStatus = im.haptics->recorder->close();
#ifdef DM_ENGINE_HAVE_NETWORK
  nlohmann::json teleop = nlohmann::json::array();
  for (const auto& sd : im.served) {
    if (sd->loop) sd->loop->stop();  // the console side stops with the simulator
    teleop.push_back(sd->summary());
  }
#endif

  // Outputs, also after an interruption or an engine failure.
  const std::vector<ProbeSample>& trace = im.monitor->trace;
  double maxForce = 0, maxDepth = 0;
  std::uint64_t contactTicks = 0;
  for (const ProbeSample& s : trace) {
    maxForce = std::max(maxForce, s.response.force.norm());
    maxDepth = std::max(maxDepth, s.response.penetration);
    contactTicks += s.response.contacts > 0;
  }
  std::vector<std::string> written;
  if (scene.outputs.forces && im.haptics) {
    const std::string csv = formatProbeCsv(trace);
    if (auto s = writeFileAtomic(out / "forces.csv", csv.data(), csv.size()); !s) return s.error();
    written.push_back("forces.csv");
  }
  if (scene.outputs.plot && im.haptics && !trace.empty()) {
    auto plot = plotForceTrace(trace);
    if (!plot) return plot.error();
    if (auto s = writePng(*plot, out / "forces.png"); !s) return s.error();
    written.push_back("forces.png");
  }
  const nlohmann::json engines = engineStatsJson(engineStats);
  nlohmann::json summary = {{"scene", scene.name},
                            {"mode", lockstep ? "lockstep" : "realtime"},
                            {"duration_s", duration},
                            {"simulated_s", done},
                            {"wall_s", std::chrono::duration<double>(SteadyClock::now() - wallStart).count()},
                            {"interrupted", result.interrupted},
                            {"engines", engines}};
  if (hostBefore && hostAfter)
    summary["host"] = {{"cpus", hostAfter->cpus},
                       {"cpu_busy_s", hostAfter->busy_s - hostBefore->busy_s},
                       {"cpu_steal_s", hostAfter->steal_s - hostBefore->steal_s},
                       {"memory_locked", memoryLocked},
                       {"page_faults_minor", faultsAfter.minor - r.faultsBefore.minor},
                       {"page_faults_major", faultsAfter.major - r.faultsBefore.major}};
  if (im.haptics) {
    const HapticLoopStats hs = im.haptics->loop->stats();
    summary["haptics"] = {{"renderer", std::string(rendererName(scene.engines.haptics->renderer))},
                          {"device", scene.engines.haptics->device},
                          {"ticks", trace.size()},
                          {"contact_ticks", contactTicks},
                          {"final_force_N", trace.empty() ? Json::array({0.0, 0.0, 0.0})
                                                          : Json::array({trace.back().response.force.x(),
                                                                         trace.back().response.force.y(),
                                                                         trace.back().response.force.z()})},
                          {"max_force_N", maxForce},
                          {"max_depth_m", maxDepth},
                          {"safety_fault_ticks", hs.faultTicks},
                          {"trace_dropped", im.haptics->dropped.load()}};
  }
  if (im.haptics && im.haptics->burr != nullptr)
    summary["burr"] = burrSummary(*im.haptics->burr, im.haptics->boneFeed.get(), im.haptics->boneVolume);
  if (im.haptics && im.haptics->placement.renderer != nullptr) {
    const HapticsEngine& e = *im.haptics;
    const BonePlacementRenderer& b = *e.placement.renderer;
    const Isometry3 target = scene.engines.haptics->bonePlacement->target.isometry();
    const auto vec = [](const Vec3& v) { return Json::array({v.x(), v.y(), v.z()}); };
    const Quat q(b.fragmentPose().linear());
    summary["bone_placement"] = {
        {"fragment_voxels", b.massProperties().voxels},
        {"fixed_voxels", e.placement.fixedVoxels},
        {"fragment_mass_kg", b.massProperties().mass},
        {"center_of_mass_m", vec(b.massProperties().centerOfMass)},
        {"slop_m", b.slop()},
        {"reference_points", e.placement.referencePoints.size()},
        {"initial_error_m", boneAlignmentError(e.placement.referencePoints, e.placementFirstPose, target)},
        {"final_error_m", b.alignmentError(e.placement.referencePoints, target)},
        {"final_position_m", vec(b.fragmentPose().translation())},
        {"final_rotation", Json::array({q.w(), q.x(), q.y(), q.z()})},
        {"final_contacts", b.contacts().size()},
        {"max_contact_depth_m", e.placementMaxDepth},
        {"stack_overflows", b.stackOverflows()}};
  }
  if (im.physics) {
    summary["physics"] = im.physics->summary();
    summary["physics"]["rate_hz"] = scene.engines.physics->rateHz;
  }
#ifdef DM_ENGINE_HAVE_RENDERER
  if (im.render) {
    const RenderEngineStats rs = im.render->stats();
    result.frames = rs.framesWritten;
    summary["render"] = {{"gl_renderer", rs.glRenderer},
                         {"egl_platform", rs.eglPlatform},
                         {"frames", rs.frames},
                         {"frames_written", rs.framesWritten},
                         {"frames_dropped", rs.framesDropped},
                         {"frame_ms_p50", rs.renderMsP50},
                         {"frame_ms_max", rs.renderMsMax}};
    if (rs.framesWritten > 0) written.push_back("frames/");
  }
#endif
#ifdef DM_ENGINE_HAVE_NETWORK
  if (!teleop.empty()) summary["teleop"] = std::move(teleop);
  if (im.igtl) summary["igtl"] = im.igtl->summary();
#endif
#ifdef DM_ENGINE_HAVE_VISION
  if (im.vision) summary["vision"] = im.vision->summary();
  if (im.segmentation) {
    if (auto s = im.segmentation->write(out, written); !s) return s.error();
    summary["segmentation"] = im.segmentation->summary();
  }
#endif
  if (im.haptics && im.haptics->recorder) {
    summary["recording"] = {{"file", std::string(kSceneRecordingFile)},
                            {"records", im.haptics->recorder->written()},
                            {"dropped", im.haptics->recorder->dropped()}};
    written.push_back(std::string(kSceneRecordingFile));
  }
  // The scripts' last word, also after an interruption or a failure.
  Status scriptStatus = ok();
  if (!im.scripts.empty()) {
    nlohmann::json scripts = nlohmann::json::object();
    for (std::size_t i = 0; i < im.scripts.size(); ++i) {
      auto j = im.scripts[i]->finish(done);
      if (!j && scriptStatus) scriptStatus = j.error();
      scripts[scene.scripts[i].name] = j ? *j : nlohmann::json{{"error", j.error().message()}};
    }
    summary["scripts"] = std::move(scripts);
  }
  if (scene.outputs.summary) written.push_back("summary.json");
  summary["outputs"] = written;
  if (scene.outputs.summary) {
    const std::string text = summary.dump(2) + "\n";
    if (auto s = writeFileAtomic(out / "summary.json", text.data(), text.size()); !s) return s.error();
  }
  result.summary = std::move(summary);
  if (!runStatus)
    return runStatus.error().within(formatString("at t = %.3f s (outputs written to %s)", done, out.c_str()));
  if (!stopStatus) return stopStatus.error();
  if (!scriptStatus) return scriptStatus.error();
  if (!recordStatus) return recordStatus.error().within("outputs/recording");
  return result;
}

}  // namespace dm
