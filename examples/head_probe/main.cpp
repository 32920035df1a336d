// head_probe — the main job until the master engine (DMEngine) exists.
//
// Loads the Colin27 MRI head (mricron-data) through the resource manager,
// extracts the skin isosurface, checks it is a closed manifold placed where
// the scan says, then runs a 1 kHz haptic-style loop in which a simulated
// stylus tip (a mass-spring-damper "hand" following a scripted circle that
// cuts through the scalp) is pushed back by a penalty force computed from the
// volume's gradient field. The loop hands its state to this thread through a
// triple buffer and its force samples through an SPSC ring, exactly as the
// haptics and render loops will. Writes forces.csv and summary.json.
//
// The force model here is a volume penalty (depth from the first-order
// distance (v - iso) / |grad v|); the god-object of DMHaptics replaces it.
//
//   head_probe [--volume NAME] [--iso V] [--seconds S] [--lockstep] [--out DIR]
#include <dm/core/filesystem.hpp>
#include <dm/core/log.hpp>
#include <dm/core/resource.hpp>
#include <dm/core/ring.hpp>
#include <dm/core/rt_loop.hpp>
#include <dm/core/triple_buffer.hpp>
#include <dm/core/units.hpp>
#include <dm/core/volume.hpp>
#include <dm/io/volume_io.hpp>
#include <dm/math/integrators.hpp>
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

/// What the haptic loop publishes each tick (through the triple buffer).
struct ProbeState {
  std::uint64_t tick = 0;
  dm::Vec3 tip = dm::Vec3::Zero();
  dm::Vec3 force = dm::Vec3::Zero();
  double depth = 0;
};

/// One force sample for the trace (through the SPSC ring).
struct Sample {
  double t;
  float tip[3];
  float force[3];
  float depth;
};

/// Penalty force of the volume at `x`: zero outside (value <= iso), else
/// stiffness · depth along the outward normal, with depth from the
/// first-order distance (v - iso)/|∇v|. Clamped to `maxForce`, NaN-guarded.
dm::Vec3 volumeForce(const dm::Volume& vol, double iso, const dm::Vec3& x, const dm::Vec3& vel,
                     double& depth) {
  constexpr double kStiffness = 800.0;  // N/m, soft tissue (DESIGN.md's example material)
  constexpr double kDamping = 2.0;      // N·s/m
  constexpr double kMaxForce = 3.0;     // N, a typical desktop device's continuous limit
  depth = 0;
  const double v = vol.sampleWorld(x);
  if (!(v > iso)) return dm::Vec3::Zero();
  const double h = 0.5 * vol.spacing().minCoeff();
  dm::Vec3 g;
  for (int a = 0; a < 3; ++a) {
    dm::Vec3 d = dm::Vec3::Zero();
    d[a] = h;
    g[a] = (vol.sampleWorld(x + d) - vol.sampleWorld(x - d)) / (2 * h);
  }
  const double gn = g.norm();
  if (!(gn > 1e-9)) return dm::Vec3::Zero();
  const dm::Vec3 n = -g / gn;  // outward: values fall toward the outside
  depth = (v - iso) / gn;
  const double vn = vel.dot(n);
  dm::Vec3 f = (kStiffness * depth - kDamping * std::min(vn, 0.0)) * n;
  const double fn = f.norm();
  if (!std::isfinite(fn)) return dm::Vec3::Zero();
  if (fn > kMaxForce) f *= kMaxForce / fn;
  return f;
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

  // 3. The probe: the scripted hand target slides on a 15 mm circle over the
  // scalp at the head's +x side, commanded 3 mm below the skin, so the tip
  // rests on the surface where the penalty force balances the hand's pull.
  // (A penalty force on intensities cannot stop a tip pushed hard through
  // the thin scalp — T1 bone is dark — which is what DMHaptics' god-object
  // is for; the gentle hand here stays in the scalp layer.)
  double skinX = centre.x();
  for (double x = centre.x(); x < box.max().x() + 0.01; x += 0.0005)
    if (vol->sampleWorld({x, centre.y(), centre.z()}) > args.iso) skinX = x;
  const dm::Vec3 contactPoint(skinX, centre.y(), centre.z());
  constexpr double kCircle = 0.015, kCommandDepth = 0.003, kCircleHz = 0.5;
  std::printf(
      "probe: target on a %.0f mm circle at %.1f Hz, %.0f mm below the scalp at (%.1f, %.1f, %.1f) mm; "
      "1 kHz loop, %s, %.1f s\n",
      kCircle * 1e3, kCircleHz, kCommandDepth * 1e3, contactPoint.x() * 1e3, contactPoint.y() * 1e3,
      contactPoint.z() * 1e3, args.lockstep ? "lockstep on a virtual clock" : "real time", args.seconds);

  // Hand model: tip mass pulled toward the target by a spring-damper (the
  // surgeon's hand), pushed back by the surface; integrated with velocity Verlet.
  constexpr double kMass = 0.05, kHandK = 60.0, kHandB = 3.0;
  dm::VecX x(3), v(3);
  x = contactPoint + dm::Vec3(0.002, kCircle, 0);  // start 2 mm off the skin
  v.setZero();
  dm::SecondOrderWorkspace ws;  // sized here so the loop never allocates
  ws.acc.resize(3);
  ws.accNext.resize(3);
  ws.vPred.resize(3);
  dm::Vec3 contactForce = dm::Vec3::Zero();
  double depth = 0;
  dm::TripleBuffer<ProbeState> stateOut;
  dm::SpscRing<Sample, 8192> trace;
  std::atomic<std::uint64_t> traceDropped{0};

  const dm::SecondOrderRhs accel = [&](double t, const dm::VecX& px, const dm::VecX& pv, dm::VecX& a) {
    const double phase = 2 * M_PI * kCircleHz * t;
    const dm::Vec3 target =
        contactPoint + dm::Vec3(-kCommandDepth, kCircle * std::cos(phase), kCircle * std::sin(phase));
    double d = 0;
    const dm::Vec3 surface = volumeForce(*vol, args.iso, px.head<3>(), pv.head<3>(), d);
    a = (kHandK * (target - px.head<3>()) - kHandB * pv.head<3>() + surface) / kMass;
  };
  auto tick = [&](const dm::TickInfo& info) {
    const double t = static_cast<double>(info.index) * info.dt();
    dm::velocityVerletStep(accel, t, info.dt(), x, v, ws);
    contactForce = volumeForce(*vol, args.iso, x, v, depth);  // what the device would render now
    ProbeState& s = stateOut.writeBuffer();
    s.tick = info.index;
    s.tip = x;
    s.force = contactForce;
    s.depth = depth;
    stateOut.publish();
    const Sample sample{t,
                        {float(x[0]), float(x[1]), float(x[2])},
                        {float(contactForce.x()), float(contactForce.y()), float(contactForce.z())},
                        float(depth)};
    if (!trace.tryPush(sample)) traceDropped.fetch_add(1, std::memory_order_relaxed);
  };

  std::filesystem::create_directories(args.out);
  std::ofstream csv(args.out / "forces.csv");
  csv << "t_s,tip_x_m,tip_y_m,tip_z_m,fx_N,fy_N,fz_N,depth_m\n";
  double maxForce = 0, maxDepth = 0;
  std::uint64_t contactTicks = 0, samples = 0;
  auto drain = [&] {
    Sample s;
    while (trace.tryPop(s)) {
      char line[160];
      std::snprintf(line, sizeof line, "%.3f,%.5f,%.5f,%.5f,%.4f,%.4f,%.4f,%.5f\n", s.t, s.tip[0], s.tip[1],
                    s.tip[2], s.force[0], s.force[1], s.force[2], s.depth);
      csv << line;
      const double f = std::sqrt(double(s.force[0]) * s.force[0] + double(s.force[1]) * s.force[1] +
                                 double(s.force[2]) * s.force[2]);
      maxForce = std::max(maxForce, f);
      maxDepth = std::max(maxDepth, double(s.depth));
      contactTicks += f > 0;
      ++samples;
    }
  };

  dm::RealTimeLoop loop({.rate_hz = 1000, .name = "haptics"}, tick);
  const auto n = static_cast<std::uint64_t>(args.seconds * 1000);
  std::uint64_t frames = 0;
  if (args.lockstep) {
    dm::VirtualClock vclock;
    for (std::uint64_t done = 0; done < n; done += 100) {
      if (auto s = loop.runLockstep(vclock, std::min<std::uint64_t>(100, n - done)); !s) {
        std::fprintf(stderr, "head_probe: %s\n", s.error().message().c_str());
        return 1;
      }
      drain();
    }
  } else {
    if (auto s = loop.start(); !s) {
      std::fprintf(stderr, "head_probe: %s\n", s.error().message().c_str());
      return 1;
    }
    // This thread plays the 30 Hz render/monitor loop: it reads the latest
    // state without ever blocking the haptic thread.
    const auto end = Clock::now() + std::chrono::duration<double>(args.seconds);
    while (Clock::now() < end) {
      std::this_thread::sleep_for(std::chrono::milliseconds(33));
      const ProbeState& s = stateOut.read();
      ++frames;
      if (frames % 30 == 0)
        std::printf("  t=%5.2f s  tip (%6.1f, %6.1f, %6.1f) mm  |F| = %.2f N  depth %.1f mm\n", s.tick * 1e-3,
                    s.tip.x() * 1e3, s.tip.y() * 1e3, s.tip.z() * 1e3, s.force.norm(), s.depth * 1e3);
      drain();
    }
    loop.stop();
  }
  drain();
  const dm::RealTimeLoopStats st = loop.stats();
  std::printf(
      "haptic loop: %llu ticks, execution p50 %.1f us, p99 %.1f us, p99.9 %.1f us, max %.1f us; "
      "wake-up p99 %.0f us; deadline misses %llu\n",
      static_cast<unsigned long long>(st.ticks), st.execution.p50_us, st.execution.p99_us,
      st.execution.p999_us, st.execution.max_us, st.wakeup.p99_us,
      static_cast<unsigned long long>(st.deadline_misses));
  std::printf(
      "contact: %llu of %llu ticks in contact, max force %.2f N (device limit 3 N), max depth %.1f mm; "
      "trace samples dropped %llu\n",
      static_cast<unsigned long long>(contactTicks), static_cast<unsigned long long>(samples), maxForce,
      maxDepth * 1e3, static_cast<unsigned long long>(traceDropped.load()));

  nlohmann::json summary = {{"volume", path->string()},
                            {"dims", {vol->dims().x(), vol->dims().y(), vol->dims().z()}},
                            {"skin",
                             {{"vertices", skin->vertexCount()},
                              {"triangles", skin->triangleCount()},
                              {"closed", topo.isClosed},
                              {"manifold", topo.isManifold},
                              {"volume_m3", topo.volume.value_or(0.0)},
                              {"extract_ms", ms(t2, t3)}}},
                            {"haptics",
                             {{"mode", args.lockstep ? "lockstep" : "realtime"},
                              {"ticks", st.ticks},
                              {"execution_us",
                               {{"p50", st.execution.p50_us},
                                {"p99", st.execution.p99_us},
                                {"p999", st.execution.p999_us},
                                {"max", st.execution.max_us}}},
                              {"deadline_misses", st.deadline_misses},
                              {"contact_ticks", contactTicks},
                              {"max_force_N", maxForce},
                              {"max_depth_m", maxDepth}}}};
  const std::string text = summary.dump(2) + "\n";
  if (auto s = dm::writeFileAtomic(args.out / "summary.json", text.data(), text.size()); !s) {
    std::fprintf(stderr, "head_probe: %s\n", s.error().message().c_str());
    return 1;
  }
  csv.close();
  std::printf("wrote %s and %s\n", (args.out / "forces.csv").c_str(), (args.out / "summary.json").c_str());
  const bool ok = topo.isClosed && topo.isManifold && contactTicks > 0 && maxForce <= 3.0 + 1e-5;
  if (!ok) std::fprintf(stderr, "head_probe: checks failed (closed skin, contact, force limit)\n");
  return ok ? 0 : 1;
}
