// head_probe — the main job until `dmplatform run` exists: the Colin27 head
// probed through the god-object.
//
// Loads the Colin27 MRI head (mricron-data) through the resource manager,
// extracts the skin isosurface, checks it is a closed manifold placed where
// the scan says, and builds its BVH. A simulated haptic device ("sim-haptic"
// with a virtual hand: a mass-spring-damper pulled along a 15 mm circle
// commanded 4 mm under the scalp, and pushed by the rendered force) is
// driven by the haptic loop (dm::HapticLoop: device servo, god-object with
// friction and force shading, safety) at 1 kHz; a 30 Hz monitor engine reads
// the loop's latest sample and drains its force trace. Both are engines of a
// dm::MasterEngine, on real-time threads or in lockstep on a virtual clock.
// Writes forces.csv (dm::formatProbeCsv columns), forces.png and summary.json.
//
//   head_probe [--volume NAME] [--iso V] [--seconds S] [--lockstep] [--out DIR]
#include <dm/collide/bvh.hpp>
#include <dm/core/filesystem.hpp>
#include <dm/core/log.hpp>
#include <dm/core/plugin.hpp>
#include <dm/core/resource.hpp>
#include <dm/core/ring.hpp>
#include <dm/core/rt_loop.hpp>
#include <dm/core/triple_buffer.hpp>
#include <dm/core/units.hpp>
#include <dm/core/volume.hpp>
#include <dm/engine/master_engine.hpp>
#include <dm/haptics/force_plot.hpp>
#include <dm/haptics/god_object.hpp>
#include <dm/haptics/haptic_loop.hpp>
#include <dm/haptics/probe.hpp>
#include <dm/io/drivers.hpp>
#include <dm/io/haptic_device.hpp>
#include <dm/io/image_io.hpp>
#include <dm/io/volume_io.hpp>
#include <dm/math/isosurface.hpp>
#include <dm/math/mesh_topology.hpp>
#include <dm/math/pca.hpp>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <future>
#include <string>
#include <thread>

namespace {

struct Args {
  std::string volume = "mricron:ch2.nii.gz";
  double iso = 40.0;
  double seconds = 3.0;
  bool lockstep = false;
  std::filesystem::path out = "out/head_probe";
};

bool parseArgs(int argc, char** argv, Args& a) {
  for (int i = 1; i < argc; ++i) {
    const std::string s = argv[i];
    auto value = [&](const char* name) -> const char* {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "head_probe: %s needs a value\n", name);
        return nullptr;
      }
      return argv[++i];
    };
    const char* v = nullptr;
    if (s == "--volume" && (v = value("--volume")))
      a.volume = v;
    else if (s == "--iso" && (v = value("--iso")))
      a.iso = std::atof(v);
    else if (s == "--seconds" && (v = value("--seconds")))
      a.seconds = std::atof(v);
    else if (s == "--out" && (v = value("--out")))
      a.out = v;
    else if (s == "--lockstep")
      a.lockstep = true;
    else {
      std::fprintf(stderr,
                   "usage: head_probe [--volume NAME] [--iso V] [--seconds S] [--lockstep] [--out DIR]\n");
      return false;
    }
  }
  if (!(a.seconds > 0) || !std::isfinite(a.iso)) {
    std::fprintf(stderr, "head_probe: --seconds must be > 0 and --iso finite\n");
    return false;
  }
  return true;
}

int fail(const dm::Error& e) {
  std::fprintf(stderr, "head_probe: %s\n", e.message().c_str());
  return 1;
}

}  // namespace

int main(int argc, char** argv) {
  Args args;
  if (!parseArgs(argc, argv, args)) return 2;
  using Clock = std::chrono::steady_clock;
  auto ms = [](Clock::time_point a, Clock::time_point b) {
    return std::chrono::duration<double, std::milli>(b - a).count();
  };

  // 1. Resolve and load the scan through the resource manager (async, like an engine would).
  auto path = dm::FileSystem::global().resolve(args.volume);
  if (!path) {
    std::fprintf(stderr, "head_probe: %s\n", path.error().message().c_str());
    return 1;
  }
  dm::ResourceManager resources;
  if (auto s = resources.registerLoader<dm::Volume>(
          {".nii", ".nii.gz", ".hdr", ".mhd", ".mha", ".nrrd", ".nhdr"},
          [](const std::filesystem::path& p, const dm::ImportOptions&) { return dm::readVolume(p); });
      !s) {
    std::fprintf(stderr, "head_probe: %s\n", s.error().message().c_str());
    return 1;
  }
  const auto t0 = Clock::now();
  std::promise<dm::Result<dm::Handle<dm::Volume>>> loaded;
  resources.loadAsync<dm::Volume>(
      *path, {}, [&](dm::Result<dm::Handle<dm::Volume>> r) { loaded.set_value(std::move(r)); });
  auto handle = loaded.get_future().get();
  if (!handle) {
    std::fprintf(stderr, "head_probe: %s\n", handle.error().message().c_str());
    return 1;
  }
  const std::shared_ptr<const dm::Volume> vol = handle->get();
  const auto t1 = Clock::now();
  const auto [lo, hi] = vol->range();
  const dm::Vec3 sp = vol->spacing() / dm::units::mm;
  std::printf("loaded %s in %.0f ms: %dx%dx%d %s voxels, spacing %.2fx%.2fx%.2f mm, values %.0f..%.0f\n",
              path->c_str(), ms(t0, t1), vol->dims().x(), vol->dims().y(), vol->dims().z(),
              dm::toString(vol->type()), sp.x(), sp.y(), sp.z(), lo, hi);
  const dm::Vec3 origin = vol->indexToWorld().translation() / dm::units::mm;
  std::printf("  voxel (0,0,0) is at (%.1f, %.1f, %.1f) mm in the scanner's RAS world\n", origin.x(),
              origin.y(), origin.z());

  // 2. Skin isosurface, checked for closedness and placement.
  const auto t2 = Clock::now();
  auto skin = dm::extractIsosurface(*vol, {.iso = args.iso, .closeBorders = true});
  if (!skin) {
    std::fprintf(stderr, "head_probe: %s\n", skin.error().message().c_str());
    return 1;
  }
  const auto t3 = Clock::now();
  const dm::MeshTopology topo = dm::analyzeTopology(*skin);
  const dm::Aabb box = skin->bounds();
  std::printf(
      "skin isosurface (iso %.0f, marching cubes) in %.0f ms: %zu vertices, %zu triangles, %s, %s, %zu "
      "components\n",
      args.iso, ms(t2, t3), skin->vertexCount(), skin->triangleCount(), topo.isClosed ? "closed" : "OPEN",
      topo.isManifold ? "manifold" : "NON-MANIFOLD", topo.components);
  std::printf("  area %.1f cm², enclosed volume %.2f L, bounds (%.0f..%.0f, %.0f..%.0f, %.0f..%.0f) mm\n",
              topo.surfaceArea * 1e4, topo.volume.value_or(0.0) * 1e3, box.min().x() * 1e3,
              box.max().x() * 1e3, box.min().y() * 1e3, box.max().y() * 1e3, box.min().z() * 1e3,
              box.max().z() * 1e3);
  auto axes = dm::pca(skin->positions);
  if (!axes) {
    std::fprintf(stderr, "head_probe: %s\n", axes.error().message().c_str());
    return 1;
  }
  const dm::Vec3 centre = axes->mean;
  const dm::Vec3 sd = axes->variances.cwiseSqrt() / dm::units::mm;
  std::printf("  principal extents (1 sd) %.0f, %.0f, %.0f mm around centre (%.1f, %.1f, %.1f) mm\n", sd.x(),
              sd.y(), sd.z(), centre.x() * 1e3, centre.y() * 1e3, centre.z() * 1e3);

  // 3. The god-object on the skin: soft-tissue stiffness, friction, force shading.
  const auto t4 = Clock::now();
  auto bvh = dm::MeshBvh::build(*skin);
  if (!bvh) return fail(bvh.error());
  std::vector<dm::GodObjectObject> objects(1);
  objects[0].bvh = std::make_shared<const dm::MeshBvh>(std::move(*bvh));
  objects[0].material = {.stiffness = 800.0, .damping = 0.5, .staticFriction = 0.3, .dynamicFriction = 0.2};
  auto renderer = dm::GodObjectRenderer::create(std::move(objects), {.forceShading = true, .maxForce = 3.0});
  if (!renderer) return fail(renderer.error());
  std::printf(
      "god-object: BVH over %zu triangles in %.0f ms; k = 800 N/m, mu_s 0.3, mu_d 0.2, force shading\n",
      skin->triangleCount(), ms(t4, Clock::now()));

  // 4. The device: sim-haptic with a virtual hand. Its circle lies in the
  // device's xy plane; deviceToWorld turns device (x, y, z) into world
  // (y, z, x) and puts the device origin on the scalp at the head's +x side,
  // so the circle slides over the skin and device z = -4 mm is under it.
  double skinX = centre.x();
  for (double x = centre.x(); x < box.max().x() + 0.01; x += 0.0005)
    if (vol->sampleWorld({x, centre.y(), centre.z()}) > args.iso) skinX = x;
  const dm::Vec3 contactPoint(skinX, centre.y(), centre.z());
  constexpr double kCircle = 0.015, kCommandDepth = 0.004;
  dm::FactoryRegistry registry;
  dm::PluginLinker linker(registry);
  if (auto s = dm::registerBuiltinDrivers(linker); !s) return fail(s.error());
  char centerParam[64];
  std::snprintf(centerParam, sizeof centerParam, "0,0,%.6f", -kCommandDepth);
  auto device = dm::HapticDevice::open(registry, "sim-haptic",
                                       {{"path", "circle"},
                                        {"center", centerParam},
                                        {"radius", std::to_string(kCircle)},
                                        {"period", "2"},
                                        {"hand", "1"},
                                        {"hand_mass", "0.1"},
                                        {"hand_stiffness", "150"},
                                        {"hand_damping", "4"},
                                        {"max_force", "3"}});
  if (!device) return fail(device.error());
  dm::HapticLoopConfig loopConfig;
  loopConfig.loop = {.rate_hz = 1000, .name = "haptics"};
  loopConfig.deviceToWorld.linear() << 0, 0, 1,  // world x = device z
      1, 0, 0,                                   // world y = device x
      0, 1, 0;                                   // world z = device y
  loopConfig.deviceToWorld.translation() = contactPoint;
  // In lockstep an overrun says how loaded this machine is, not what the
  // simulation did: count it but keep the output (bit-identical reruns).
  loopConfig.overrunFades = !args.lockstep;
  auto hapticLoop = dm::HapticLoop::create({.device = **device, .renderer = **renderer}, loopConfig);
  if (!hapticLoop) return fail(hapticLoop.error());
  std::printf(
      "probe: hand on a %.0f mm circle, 0.5 Hz, commanded %.0f mm under the scalp at (%.1f, %.1f, %.1f) mm; "
      "%s, %.1f s\n",
      kCircle * 1e3, kCommandDepth * 1e3, contactPoint.x() * 1e3, contactPoint.y() * 1e3,
      contactPoint.z() * 1e3, args.lockstep ? "lockstep on a virtual clock" : "real time", args.seconds);

  // 5. Engines: haptics at 1 kHz, the monitor at 30 Hz. The haptic engine
  // hands every tick's sample to the monitor through an SPSC ring; the
  // monitor keeps the trace (it may allocate, the haptic thread never does).
  dm::SpscRing<dm::ProbeSample, 8192> ring;
  std::atomic<std::uint64_t> dropped{0};
  std::vector<dm::ProbeSample> trace;
  trace.reserve(static_cast<std::size_t>(args.seconds * 1000) + 16);
  dm::HapticLoop& loop = **hapticLoop;
  auto haptics = dm::makeFunctionEngine("haptics", [&](const dm::TickInfo& info) {
    loop.tick(info);
    const dm::HapticLoopSample& s = loop.lastSample();
    dm::ProbeSample p;
    p.t = static_cast<double>(info.scheduled_ns) * 1e-9;
    p.devicePose = s.input.devicePose;
    p.response = s.response;
    p.response.force = loop.config().deviceToWorld.linear() * s.deviceForce;  // what was sent, world frame
    if (!ring.tryPush(p)) dropped.fetch_add(1, std::memory_order_relaxed);
    return true;
  });
  std::uint64_t frames = 0;
  auto drain = [&] {
    dm::ProbeSample p;
    while (ring.tryPop(p)) trace.push_back(p);
  };
  auto monitor = dm::makeFunctionEngine("monitor", [&](const dm::TickInfo& info) {
    drain();
    if (++frames % 30 == 0 && !trace.empty() && !args.lockstep) {
      const dm::ProbeSample& s = trace.back();
      const dm::Vec3 tip = s.response.proxyPose.translation();
      std::printf("  t=%5.2f s  proxy (%6.1f, %6.1f, %6.1f) mm  |F| = %.2f N  depth %.1f mm\n",
                  static_cast<double>(info.scheduled_ns) * 1e-9, tip.x() * 1e3, tip.y() * 1e3, tip.z() * 1e3,
                  s.response.force.norm(), s.response.penetration * 1e3);
    }
    return true;
  });
  dm::MasterEngine master;
  if (auto s = master.addEngine(haptics, {.rateHz = 1000}); !s) return fail(s.error());
  if (auto s = master.addEngine(monitor, {.rateHz = 30}); !s) return fail(s.error());
  if (auto s = master.load(args.volume); !s) return fail(s.error());
  if (auto s = master.start(args.lockstep ? dm::RunMode::Lockstep : dm::RunMode::RealTime); !s)
    return fail(s.error());
  if (args.lockstep) {
    if (auto s = master.advance(args.seconds); !s) return fail(s.error());
  } else {
    const auto end = Clock::now() + std::chrono::duration<double>(args.seconds);
    while (Clock::now() < end) {
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
      if (auto s = master.poll(); !s) return fail(s.error());
    }
  }
  const std::vector<dm::EngineStats> engineStats = master.stats();
  if (auto s = master.stop("done"); !s) return fail(s.error());
  drain();

  double maxForce = 0, maxDepth = 0;
  std::uint64_t contactTicks = 0;
  for (const dm::ProbeSample& s : trace) {
    maxForce = std::max(maxForce, s.response.force.norm());
    maxDepth = std::max(maxDepth, s.response.penetration);
    contactTicks += s.response.contacts > 0;
  }
  const dm::HapticLoopStats hs = loop.stats();
  for (const dm::EngineStats& e : engineStats)
    std::printf(
        "engine %-8s %llu ticks at %.1f Hz (scheduled %.0f Hz), execution p50 %.1f us, p99 %.1f us, "
        "p99.9 %.1f us, max %.1f us; deadline misses %llu\n",
        e.name.c_str(), static_cast<unsigned long long>(e.ticks), e.achievedHz, e.rateHz, e.execution.p50_us,
        e.execution.p99_us, e.execution.p999_us, e.execution.max_us,
        static_cast<unsigned long long>(e.deadlineMisses));
  std::printf(
      "contact: %llu of %zu ticks in contact, max force %.2f N (limit 3 N), max depth %.1f mm; "
      "safety faults %llu; trace samples dropped %llu\n",
      static_cast<unsigned long long>(contactTicks), trace.size(), maxForce, maxDepth * 1e3,
      static_cast<unsigned long long>(hs.faultTicks), static_cast<unsigned long long>(dropped.load()));

  std::filesystem::create_directories(args.out);
  const std::string csv = dm::formatProbeCsv(trace);
  if (auto s = dm::writeFileAtomic(args.out / "forces.csv", csv.data(), csv.size()); !s)
    return fail(s.error());
  if (!trace.empty()) {
    auto plot = dm::plotForceTrace(trace);
    if (!plot) return fail(plot.error());
    if (auto s = dm::writePng(*plot, args.out / "forces.png"); !s) return fail(s.error());
  }
  nlohmann::json engines = nlohmann::json::array();
  for (const dm::EngineStats& e : engineStats)
    engines.push_back({{"name", e.name},
                       {"rate_hz", e.rateHz},
                       {"achieved_hz", e.achievedHz},
                       {"ticks", e.ticks},
                       {"deadline_misses", e.deadlineMisses},
                       {"execution_us",
                        {{"p50", e.execution.p50_us},
                         {"p99", e.execution.p99_us},
                         {"p999", e.execution.p999_us},
                         {"max", e.execution.max_us}}}});
  nlohmann::json summary = {{"volume", path->string()},
                            {"dims", {vol->dims().x(), vol->dims().y(), vol->dims().z()}},
                            {"skin",
                             {{"vertices", skin->vertexCount()},
                              {"triangles", skin->triangleCount()},
                              {"closed", topo.isClosed},
                              {"manifold", topo.isManifold},
                              {"volume_m3", topo.volume.value_or(0.0)},
                              {"extract_ms", ms(t2, t3)}}},
                            {"mode", args.lockstep ? "lockstep" : "realtime"},
                            {"engines", engines},
                            {"haptics",
                             {{"renderer", "godobject"},
                              {"ticks", trace.size()},
                              {"contact_ticks", contactTicks},
                              {"max_force_N", maxForce},
                              {"max_depth_m", maxDepth},
                              {"safety_fault_ticks", hs.faultTicks},
                              {"trace_dropped", dropped.load()}}}};
  const std::string text = summary.dump(2) + "\n";
  if (auto s = dm::writeFileAtomic(args.out / "summary.json", text.data(), text.size()); !s)
    return fail(s.error());
  std::printf("wrote forces.csv, forces.png and summary.json in %s\n", args.out.c_str());
  const bool ok =
      topo.isClosed && topo.isManifold && contactTicks > 0 && maxForce <= 3.0 + 1e-5 && dropped.load() == 0;
  if (!ok) std::fprintf(stderr, "head_probe: checks failed (closed skin, contact, force limit)\n");
  return ok ? 0 : 1;
}
