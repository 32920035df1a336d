// Dental probing with a mirror and a scaler — an example simulator of the
// seed's two dental cases on the sphere-tree 6-DOF renderer
// (dm::SphereTree6DofRenderer), built from the SDK's parts.
//
// 1. Mirror and tongue: a tongue (an ellipsoid 60 × 24 × 16 mm, its root
//    fixed) is a soft object (dm::SphereTreeDeformation on level 2 of its
//    fitted sphere tree); the back of a dental mirror (a 6 mm ball) is
//    pressed 5 mm into it, held, and lifted. A "graphics" engine at 30 Hz
//    skins the tongue's mesh to the deformed tree (bind / deform), as a
//    renderer would draw it.
// 2. Scaler and calculus: a tooth (10 × 10 × 20 mm) carries three pieces of
//    calculus (1.2 mm balls bonded at `--bond` N); a scaler (a 1 mm ball)
//    rides along the tooth's face and meets them in turn; each comes off
//    when the push reaches its bond, and the force drops.
// The hand's motions are recorded with dm::DeviceRecorder and played by the
// replay-haptic driver through a dm::HapticLoop at 1 kHz; the engines run in
// a dm::MasterEngine, in lockstep on a virtual clock or on real-time threads.
//
//   dm_example_dental_probing [--out DIR] [--bond N] [--realtime]
//
// Outputs in DIR: mirror.dmrec and scaler.dmrec (the hand motions),
// mirror_forces.csv/.png and scaler_forces.csv/.png (force on the hand),
// tongue_pressed.ply (the tongue's mesh at the deepest press), and
// summary.json (peak force and dent, the support's reaction, the largest
// force step a tick, the residual dent after the lift; each release's time,
// force and the drop after it; the engines' rates).
//
// Exit codes: 0 done, 1 failure (message on stderr), 2 bad command line.
#include <dm/collide/sphere_tree.hpp>
#include <dm/engine/master_engine.hpp>
#include <dm/haptics/force_plot.hpp>
#include <dm/haptics/haptic_loop.hpp>
#include <dm/haptics/probe.hpp>
#include <dm/haptics/sphere_tree_6dof.hpp>
#include <dm/haptics/sphere_tree_deformation.hpp>
#include <dm/io/drivers.hpp>
#include <dm/io/haptic_device.hpp>
#include <dm/io/image_io.hpp>
#include <dm/io/mesh_io.hpp>
#include <dm/io/recorder.hpp>
#include <dm/math/primitives.hpp>

#include <nlohmann/json.hpp>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <iostream>
#include <string>
#include <thread>
#include <vector>

#include "../common/example_support.hpp"

namespace {

namespace fs = std::filesystem;
using dm::Isometry3;
using dm::Vec3;

struct Options {
  fs::path out = "dental_probing_out";
  double bond = 1.5;
  bool realtime = false;
};

Isometry3 at(const Vec3& p) {
  Isometry3 x = Isometry3::Identity();
  x.translation() = p;
  return x;
}

// Minimum-jerk blend 0 → 1 over u ∈ [0, 1], and its derivative.
double minJerk(double u) { return u * u * u * (10 - 15 * u + 6 * u * u); }
double minJerkRate(double u) { return 30 * u * u - 60 * u * u * u + 30 * u * u * u * u; }

// A hand path: positions through `points`, each leg a minimum-jerk move of
// `legs[i].first` s followed by a hold of `legs[i].second` s.
struct Path {
  std::vector<Vec3> points;
  std::vector<std::pair<double, double>> legs;
  double duration() const {
    double t = 0;
    for (const auto& [move, hold] : legs) t += move + hold;
    return t;
  }
  // Position and velocity at t.
  std::pair<Vec3, Vec3> at(double t) const {
    for (std::size_t i = 0; i < legs.size(); ++i) {
      const auto [move, hold] = legs[i];
      const Vec3 a = points[i], b = points[i + 1];
      if (t < move) {
        const double u = t / move;
        return {a + minJerk(u) * (b - a), minJerkRate(u) / move * (b - a)};
      }
      t -= move;
      if (t < hold || i + 1 == legs.size()) return {b, Vec3::Zero()};
      t -= hold;
    }
    return {points.back(), Vec3::Zero()};
  }
};

dm::Status recordHand(const fs::path& file, const Path& path) {
  auto rec = dm::DeviceRecorder::create(
      file, {.metadata = R"({"device":"dentist's hand, 6-DOF"})", .overwrite = true});
  if (!rec) return rec.error();
  const auto total = static_cast<int>(std::lround(path.duration() * 1000));
  for (int k = 0; k <= total; ++k) {
    const auto [p, v] = path.at(1e-3 * k);
    dm::HapticState h;
    h.timeNs = static_cast<std::int64_t>(k) * 1'000'000;
    h.position = p;
    h.linearVelocity = v;
    // The queue holds 8192 records and drains within about a millisecond.
    while (!(*rec)->pushHapticState(h)) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  return (*rec)->close();
}

int fail(const dm::Error& e) {
  std::cerr << "dm_example_dental_probing: " << e << '\n';
  return 1;
}

// One case: the renderer driven by the recorded hand in a HapticLoop at
// 1 kHz, with `perTick` after each haptic tick and `graphics` at 30 Hz.
struct CaseRun {
  std::vector<dm::ProbeSample> trace;
  std::vector<dm::EngineStats> stats;
};
dm::Result<CaseRun> runCase(const std::string& name, const fs::path& handFile, double duration,
                            dm::SphereTree6DofRenderer& renderer, bool realtime,
                            const std::function<void(double)>& perTick,
                            const std::function<void()>& graphics) {
  dm::FactoryRegistry registry;
  dm::PluginLinker linker(registry);
  if (auto s = dm::registerBuiltinDrivers(linker); !s) return s.error();
  auto device =
      dm::HapticDevice::open(registry, "replay-haptic", {{"file", handFile.string()}, {"max_force", "8"}});
  if (!device) return device.error();
  dm::HapticLoopConfig config;
  config.loop = {.rate_hz = 1000, .name = "haptics"};
  config.overrunFades = realtime;  // lockstep output must not depend on the machine's load
  auto loop = dm::HapticLoop::create({.device = **device, .renderer = renderer}, config);
  if (!loop) return loop.error();
  CaseRun run;
  run.trace.reserve(static_cast<std::size_t>(duration * 1000) + 16);
  std::int64_t startNs = -1;
  dm::HapticLoop& hl = **loop;
  auto haptics = dm::makeFunctionEngine("haptics", [&](const dm::TickInfo& t) {
    hl.tick(t);
    const dm::HapticLoopSample& s = hl.lastSample();
    if (startNs < 0) startNs = s.timeNs;
    const double time = 1e-9 * static_cast<double>(s.timeNs - startNs);
    if (run.trace.size() < run.trace.capacity())
      run.trace.push_back({.t = time, .devicePose = s.input.devicePose, .response = s.response});
    perTick(time);
    return true;
  });
  auto draw = dm::makeFunctionEngine("graphics", [&](const dm::TickInfo&) {
    graphics();
    return true;
  });
  dm::MasterEngine master;
  if (auto s = master.addEngine(haptics, {.rateHz = 1000, .priority = 80}); !s) return s.error();
  if (auto s = master.addEngine(draw, {.rateHz = 30}); !s) return s.error();
  if (auto s = dm_example::runEngines(master, name, realtime, duration, run.stats); !s) return s.error();
  if (run.trace.empty()) return dm::fail(dm::ErrorCode::Internal, "no haptic tick ran", name);
  return run;
}

dm::Result<std::shared_ptr<const dm::SphereTree>> fitted(const dm::Mesh& m, int levels) {
  return dm::buildSphereTreeFitted(m, {.levels = levels});
}

dm::Status writeTrace(const fs::path& dir, const std::string& stem, const std::vector<dm::ProbeSample>& trace,
                      std::vector<std::string>& written) {
  if (auto s = dm_example::writeOutput(dir / (stem + ".csv"), dm::formatProbeCsv(trace), written); !s)
    return s;
  auto plot = dm::plotForceTrace(trace);
  if (!plot) return plot.error();
  if (auto s = dm::writePng(*plot, dir / (stem + ".png")); !s) return s;
  written.push_back(stem + ".png");
  return dm::ok();
}

double largestForceStep(const std::vector<dm::ProbeSample>& trace) {
  double m = 0;
  for (std::size_t i = 1; i < trace.size(); ++i)
    m = std::max(m, (trace[i].response.force - trace[i - 1].response.force).norm());
  return m;
}

int run(const Options& o) {
  if (auto s = dm_example::makeOutputDir(o.out); !s) return fail(s.error());
  std::vector<std::string> written;
  nlohmann::json summary = {{"mode", o.realtime ? "realtime" : "lockstep"}};

  // ---- 1. Mirror and tongue ----
  dm::Mesh tongueMesh = dm::makeIcosphere(1.0, 4);
  for (Vec3& p : tongueMesh.positions) p = Vec3(0.030 * p.x(), 0.012 * p.y(), 0.008 * p.z());
  tongueMesh.normals.clear();
  auto tongue = fitted(tongueMesh, 5);
  if (!tongue) return fail(tongue.error());
  auto mirror = fitted(dm::makeIcosphere(0.006, 3), 4);
  if (!mirror) return fail(mirror.error());
  const dm::SphereTreeDeformationOptions softness{
      .skeletonLevel = 2,
      .mass = 0.06,
      .anchorStiffness = 30,
      .linkStiffness = 400,
      .damping = 2,
      .fixedRegion = dm::Aabb(Vec3(-1, -1, -1), Vec3(-0.022, 1, 1))};
  auto soft = dm::SphereTreeDeformation::create(*tongue, softness);
  if (!soft) return fail(soft.error());
  auto mirrorRenderer = dm::SphereTree6DofRenderer::create(
      *mirror, {{.tree = *tongue, .name = "tongue", .deformation = *soft}}, {.toolLevel = 3});
  if (!mirrorRenderer) return fail(mirrorRenderer.error());
  const double restTop = 0.008 * std::sqrt(1.0 - 1.0 / 9.0);  // the tongue's top at x = 10 mm
  const Vec3 press(0.010, 0, restTop);
  const Path mirrorPath{{press + Vec3(0, 0, 0.016), press + Vec3(0, 0, 0.001), press + Vec3(0, 0, 0.016)},
                        {{1.0, 1.0}, {0.5, 1.0}}};
  if (auto s = recordHand(o.out / "mirror.dmrec", mirrorPath); !s) return fail(s.error());
  written.push_back("mirror.dmrec");
  const auto binding = (*soft)->bind(tongueMesh.positions);
  std::vector<Vec3> skin(tongueMesh.positions.size());
  double maxDent = 0, lastDent = 0, peakForce = 0, peakSupport = 0, residual = 0;
  int residualTicks = 0;
  dm::Mesh pressedMesh = tongueMesh;
  dm::SphereTreeDeformation& def = **soft;
  dm::SphereTree6DofRenderer& mr = **mirrorRenderer;
  auto mirrorRun = runCase(
      "dental_probing/mirror", o.out / "mirror.dmrec", mirrorPath.duration() + 0.01, mr, o.realtime,
      [&](double t) {
        peakForce = std::max(peakForce, mr.objectForce(0).norm());
        peakSupport = std::max(peakSupport, def.supportForce().norm());
        if (t >= 1.8 && t < 2.0 && mr.objectForce(0).norm() > 0) {  // the end of the hold
          residual += (mr.objectForce(0) + def.supportForce()).norm() / mr.objectForce(0).norm();
          ++residualTicks;
        }
      },
      [&] {  // the graphics: the tongue's mesh skinned to the deformed tree
        def.deform(binding, tongueMesh.positions, skin);
        double dent = 0;
        for (std::size_t i = 0; i < skin.size(); ++i)
          dent = std::max(dent, (skin[i] - tongueMesh.positions[i]).norm());
        if (dent > maxDent) {
          maxDent = dent;
          pressedMesh.positions = skin;
        }
        lastDent = dent;
      });
  if (!mirrorRun) return fail(mirrorRun.error());
  if (auto s = writeTrace(o.out, "mirror_forces", mirrorRun->trace, written); !s) return fail(s.error());
  if (auto s = dm::writeMesh(pressedMesh, o.out / "tongue_pressed.ply"); !s) return fail(s.error());
  written.push_back("tongue_pressed.ply");
  double mirrorMax = 0;
  for (const dm::ProbeSample& s : mirrorRun->trace) mirrorMax = std::max(mirrorMax, s.response.force.norm());
  summary["mirror"] = {{"max_force_N", mirrorMax},
                       {"max_tongue_force_N", peakForce},
                       {"max_support_force_N", peakSupport},
                       {"hold_newton_residual", residualTicks > 0 ? residual / residualTicks : 1.0},
                       {"rigid_force_N", 1000.0 * 0.005},
                       {"max_dent_mm", 1e3 * maxDent},
                       {"dent_after_lift_mm", 1e3 * lastDent},
                       {"max_force_step_N", largestForceStep(mirrorRun->trace)},
                       {"skeleton_nodes", def.skeleton().size()},
                       {"engines", dm::engineStatsJson(mirrorRun->stats)}};

  // ---- 2. Scaler and calculus ----
  auto tooth = fitted(dm::makeBox(Vec3(0.005, 0.005, 0.010)), 5);
  if (!tooth) return fail(tooth.error());
  const double rc = 0.0012, rt = 0.001;
  auto piece = fitted(dm::makeIcosphere(rc, 3), 4);
  if (!piece) return fail(piece.error());
  auto scaler = fitted(dm::makeIcosphere(rt, 3), 4);
  if (!scaler) return fail(scaler.error());
  std::vector<dm::SphereTreeObject> objects{
      {.tree = *tooth, .pose = at(Vec3(0, -0.005, 0)), .name = "tooth"}};
  for (const double x : {-0.002, 0.0012, 0.0044})
    objects.push_back(
        {.tree = *piece, .pose = at(Vec3(x, rt, 0)), .name = "calculus", .releaseForce = o.bond});
  auto scalerRenderer = dm::SphereTree6DofRenderer::create(*scaler, std::move(objects), {.toolLevel = 3});
  if (!scalerRenderer) return fail(scalerRenderer.error());
  // Along the face, pressing 0.2 mm into it, at about 9 mm/s.
  const Path scalerPath{
      {Vec3(-0.0045, rt, 0.0005), Vec3(-0.0045, rt - 0.0002, 0), Vec3(0.0048, rt - 0.0002, 0)},
      {{0.1, 0.1}, {1.2, 0.3}}};
  if (auto s = recordHand(o.out / "scaler.dmrec", scalerPath); !s) return fail(s.error());
  written.push_back("scaler.dmrec");
  dm::SphereTree6DofRenderer& sr = **scalerRenderer;
  struct Release {
    double t, pieceForce;
    std::size_t tick;
  };
  std::vector<Release> releases;
  std::array<bool, 4> off{};
  std::size_t tick = 0;
  auto scalerRun = runCase(
      "dental_probing/scaler", o.out / "scaler.dmrec", scalerPath.duration() + 0.01, sr, o.realtime,
      [&](double t) {
        for (std::size_t k = 1; k <= 3; ++k) {
          if (!off[k] && sr.objectReleased(k)) {
            off[k] = true;
            releases.push_back({t, sr.objectForce(k).norm(), tick});
          }
        }
        ++tick;
      },
      [] {});
  if (!scalerRun) return fail(scalerRun.error());
  if (auto s = writeTrace(o.out, "scaler_forces", scalerRun->trace, written); !s) return fail(s.error());
  nlohmann::json rel = nlohmann::json::array();
  const std::vector<dm::ProbeSample>& st = scalerRun->trace;
  for (const Release& r : releases) {
    const double before = st[r.tick].response.force.norm();
    const double after = st[std::min(r.tick + 20, st.size() - 1)].response.force.norm();
    rel.push_back({{"t_s", r.t},
                   {"piece_force_N", r.pieceForce},
                   {"hand_force_N", before},
                   {"drop_20ms_N", before - after}});
  }
  double scalerMax = 0;
  for (const dm::ProbeSample& s : st) scalerMax = std::max(scalerMax, s.response.force.norm());
  summary["scaler"] = {{"bond_N", o.bond},
                       {"releases", rel},
                       {"max_force_N", scalerMax},
                       {"engines", dm::engineStatsJson(scalerRun->stats)}};
  summary["outputs"] = written;
  if (auto s = dm_example::writeOutput(o.out / "summary.json", summary.dump(2) + "\n", written); !s)
    return fail(s.error());
  std::printf(
      "mirror: the tongue gave %.2f mm under %.2f N (rigid: %.1f N), %.3f mm left after the lift; scaler: "
      "%zu "
      "pieces of calculus released at %.2f N bonds; outputs in %s\n",
      1e3 * maxDent, mirrorMax, 1000.0 * 0.005, 1e3 * lastDent, releases.size(), o.bond,
      o.out.string().c_str());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  CLI::App app{"Dental probing: a mirror pushing a soft tongue aside, a scaler releasing calculus"};
  app.add_option("--out", o.out, "Output directory (default dental_probing_out)");
  app.add_option("--bond", o.bond, "The calculus pieces' bond strength, N (default 1.5)")
      ->check(CLI::Range(0.5, 3.0));
  app.add_flag("--realtime", o.realtime, "Real-time threads instead of lockstep on a virtual clock");
  bool parsed = false;
  const int code = dm_example::parseCommandLine(app, argc, argv, parsed);
  return parsed ? run(o) : code;
}
