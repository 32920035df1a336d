// Virtual osteotomy and bone placement — an example simulator built from the
// SDK's parts.
//
// 1. A skull region is voxelized from the Colin27 T1 head (mricron-data
//    ch2.nii.gz with its brain mask ch2bet.nii.gz): in a 50 × 50 × 40 mm box
//    over the right parietal calvaria, the voxels outside the brain, darker
//    than 50 (T1: bone and the CSF under it) and within 8 mm of the brain
//    (dm::dilate), largest 26-connected component (dm::largestComponent).
// 2. Osteotomy: an oblique saw cut (a plane through the region's centre,
//    1 mm kerf removed) splits it into two fragments; each keeps its largest
//    component.
// 3. Placement: the fixed fragment stays; the moving fragment starts
//    displaced (10 mm, 15°) and is brought back by a surgeon's recorded 6-DOF
//    hand motion (written with dm::DeviceRecorder and played by the
//    replay-haptic driver) through dm::BonePlacementRenderer (impulse-based
//    6-DOF voxel contact between the two implicit sphere trees, virtual
//    coupling to the hand) in a dm::HapticLoop at 1 kHz. The hand ends
//    `--push` mm beyond the anatomical pose, into the fixed fragment (a
//    surgeon pressing the fragment home): the contact must hold the
//    fragment at the cut while the hand feels the coupling pull back.
//    Engines of a dm::MasterEngine: "haptics" (1 kHz) and "monitor" (50 Hz,
//    the alignment error), in lockstep on a virtual clock or on real-time
//    threads.
//
// The alignment error is the RMS distance between reference points of the
// moving fragment (its six extreme voxels along ±x, ±y, ±z and its centre
// voxel) at the fragment's pose and at the anatomical pose.
//
//   dm_example_osteotomy [--out DIR] [--push MM] [--realtime]
//
// Outputs in DIR: fragments.nii.gz (labels: 1 fixed, 2 moving, at the
// anatomical pose), hand.dmrec (the recorded hand motion; hand.csv, the
// same every 10 ms for a scene's sim-haptic), forces.csv and
// forces.png (force on the hand), alignment.csv (t, RMS error, contacts)
// and summary.json (the region's box, fragment sizes and masses, initial and
// final alignment error, contact depth, the force at rest against the
// coupling's k·offset, the engines' rates; SI units).
// examples/scenes/osteotomy_colin27.json is this surgery as a scene: the
// suite checks it writes the same figures.
//
// Exit codes: 0 done, 1 failure (message on stderr), 2 bad command line.
#include <dm/collide/sphere_tree.hpp>
#include <dm/core/filesystem.hpp>
#include <dm/core/units.hpp>
#include <dm/engine/master_engine.hpp>
#include <dm/haptics/bone_placement.hpp>
#include <dm/haptics/force_plot.hpp>
#include <dm/haptics/haptic_loop.hpp>
#include <dm/haptics/probe.hpp>
#include <dm/io/drivers.hpp>
#include <dm/io/haptic_device.hpp>
#include <dm/io/image_io.hpp>
#include <dm/io/recorder.hpp>
#include <dm/io/volume_io.hpp>
#include <dm/vision/volume_filters.hpp>

#include <nlohmann/json.hpp>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <limits>
#include <numbers>
#include <string>
#include <thread>
#include <vector>

#include "../common/example_support.hpp"

namespace {

namespace fs = std::filesystem;
using dm::Vec3;
using dm::Vec3i;

struct Options {
  fs::path out = "osteotomy_out";
  double pushMm = 2.0;
  bool realtime = false;
};

constexpr double kMm = dm::units::mm;
// The region: right parietal calvaria, MNI mm.
const Vec3 kRegionMin = Vec3(0, -50, 55) * kMm;
const Vec3i kRegionDims(50, 50, 40);
constexpr double kApproach = 2.0;  // s, from the displaced start to the goal
constexpr double kHold = 1.5;      // s at the goal
constexpr double kLead = 0.2;      // s at the start before moving

// The sub-volume of `v` of `dims` voxels whose first voxel is at index `origin`.
dm::Result<dm::Volume> crop(const dm::Volume& v, const Vec3i& origin, const Vec3i& dims) {
  const dm::Affine3 a = v.indexToWorld() * dm::Affine3(Eigen::Translation3d(origin.cast<double>()));
  auto out = dm::Volume::create(dims, dm::VoxelType::U8, a);
  if (!out) return out.error();
  for (int k = 0; k < dims.z(); ++k)
    for (int j = 0; j < dims.y(); ++j)
      for (int i = 0; i < dims.x(); ++i) {
        const Vec3i s = origin + Vec3i(i, j, k);
        const bool inside = (s.array() >= 0).all() && (s.array() < v.dims().array()).all();
        out->setValue(i, j, k, inside ? v.value(s.x(), s.y(), s.z()) : 0.0);
      }
  return out;
}

struct Skull {
  dm::Volume fixed, moving, labels;  // U8 occupancies (1) and the label map, same grid
  Vec3 cutNormal = Vec3::UnitX();    // world, from the fixed side to the moving side
  std::size_t regionVoxels = 0;
  Vec3 boxMin, boxMax;  // world, m: the region's voxels, to their outer faces
};

// Steps 1 and 2 of the file comment.
dm::Result<Skull> cutSkull(const dm::Volume& head, const dm::Volume& brain) {
  const Vec3 start = head.worldToIndex() * kRegionMin;
  const Vec3i origin = start.array().round().cast<int>();
  constexpr int kNear = 8;  // mm (1 mm voxels)
  // Crop with a margin so the dilation sees the brain around the box.
  const Vec3i margin = Vec3i::Constant(kNear);
  auto headBox = crop(head, origin - margin, kRegionDims + 2 * margin);
  if (!headBox) return headBox.error();
  auto brainBox = crop(brain, origin - margin, kRegionDims + 2 * margin);
  if (!brainBox) return brainBox.error();
  auto brainMask = dm::threshold(*brainBox, 1.0);
  if (!brainMask) return brainMask.error();
  auto near = dm::dilate(*brainMask, kNear);
  if (!near) return near.error();
  auto region = dm::Volume::create(kRegionDims, dm::VoxelType::U8,
                                   headBox->indexToWorld() * dm::Affine3(Eigen::Translation3d(margin.cast<double>())));
  if (!region) return region.error();
  for (int k = 0; k < kRegionDims.z(); ++k)
    for (int j = 0; j < kRegionDims.y(); ++j)
      for (int i = 0; i < kRegionDims.x(); ++i) {
        const Vec3i s = Vec3i(i, j, k) + margin;
        const bool bone = brainMask->value(s.x(), s.y(), s.z()) == 0 && near->value(s.x(), s.y(), s.z()) != 0 &&
                          headBox->value(s.x(), s.y(), s.z()) < 50;
        region->setValue(i, j, k, bone ? 1 : 0);
      }
  auto bone = dm::largestComponent(*region);
  if (!bone) return bone.error();
  Skull skull;
  skull.boxMin = Vec3::Constant(std::numeric_limits<double>::infinity());
  skull.boxMax = -skull.boxMin;
  for (int c = 0; c < 8; ++c) {
    const Vec3 corner((c & 1) ? kRegionDims.x() : 0, (c & 2) ? kRegionDims.y() : 0,
                      (c & 4) ? kRegionDims.z() : 0);
    const Vec3 p = region->indexToWorld() * (corner - Vec3::Constant(0.5));
    skull.boxMin = skull.boxMin.cwiseMin(p);
    skull.boxMax = skull.boxMax.cwiseMax(p);
  }
  // The saw: a plane through the bone's centre, tilted 20° from the sagittal
  // plane about the anterior axis and 10° about the vertical.
  Vec3 centre = Vec3::Zero();
  for (std::size_t n = 0; n < bone->voxelCount(); ++n)
    if (bone->valueAt(n) != 0) ++skull.regionVoxels;
  if (skull.regionVoxels < 1000)
    return dm::fail(dm::ErrorCode::InvalidArgument,
                    dm::formatString("only %zu bone voxels in the region", skull.regionVoxels), "ch2.nii.gz",
                    "use the Colin27 head of mricron-data");
  for (int k = 0; k < kRegionDims.z(); ++k)
    for (int j = 0; j < kRegionDims.y(); ++j)
      for (int i = 0; i < kRegionDims.x(); ++i)
        if (bone->value(i, j, k) != 0) centre += Vec3(i, j, k);
  centre /= static_cast<double>(skull.regionVoxels);
  const Vec3 n = (dm::AngleAxis(10.0 * std::numbers::pi / 180, Vec3::UnitZ()) *
                  dm::AngleAxis(20.0 * std::numbers::pi / 180, Vec3::UnitY()) * Vec3::UnitX())
                     .normalized();  // index space = world directions here (1 mm, axis-aligned)
  auto fixedSide = dm::Volume::create(kRegionDims, dm::VoxelType::U8, bone->indexToWorld());
  auto movingSide = dm::Volume::create(kRegionDims, dm::VoxelType::U8, bone->indexToWorld());
  if (!fixedSide) return fixedSide.error();
  if (!movingSide) return movingSide.error();
  for (int k = 0; k < kRegionDims.z(); ++k)
    for (int j = 0; j < kRegionDims.y(); ++j)
      for (int i = 0; i < kRegionDims.x(); ++i) {
        if (bone->value(i, j, k) == 0) continue;
        const double s = n.dot(Vec3(i, j, k) - centre);  // voxels
        if (s < -0.5) fixedSide->setValue(i, j, k, 1);
        if (s > 0.5) movingSide->setValue(i, j, k, 1);  // |s| <= 0.5: the kerf
      }
  auto f = dm::largestComponent(*fixedSide);
  if (!f) return f.error();
  auto m = dm::largestComponent(*movingSide);
  if (!m) return m.error();
  skull.fixed = std::move(*f);
  skull.moving = std::move(*m);
  skull.cutNormal = (bone->indexToWorld().linear() * n).normalized();
  auto labels = dm::Volume::create(kRegionDims, dm::VoxelType::U8, bone->indexToWorld());
  if (!labels) return labels.error();
  for (std::size_t i = 0; i < labels->voxelCount(); ++i)
    labels->setValueAt(i, skull.fixed.valueAt(i) != 0 ? 1 : skull.moving.valueAt(i) != 0 ? 2 : 0);
  skull.labels = std::move(*labels);
  return skull;
}

// The RMS distance between the fragment's reference points moved by `pose`
// and at the anatomical pose (the identity).
double rmsError(const std::vector<Vec3>& points, const dm::Isometry3& pose) {
  return dm::boneAlignmentError(points, pose, dm::Isometry3::Identity());
}

// The recorded hand: the anatomical pose is the identity (fragment frame =
// world); the hand starts at `start`, waits kLead, moves to `goal` along a
// smooth (minimum-jerk) path over kApproach and holds it for kHold. The same
// motion every 10 ms goes to `csv` (sim-haptic's "path": "csv" rows, 17
// digits: examples/scenes/osteotomy_colin27_hand.csv is this file).
dm::Status recordHand(const fs::path& file, const fs::path& csv, const dm::Isometry3& start,
                      const dm::Isometry3& goal) {
  auto rec = dm::DeviceRecorder::create(file, {.metadata = R"({"device":"surgeon's hand, 6-DOF"})", .overwrite = true});
  if (!rec) return rec.error();
  const dm::Quat q0(start.linear()), q1(goal.linear());
  const Vec3 axis = [&] {
    const dm::AngleAxis aa(q0.inverse() * q1);
    return Vec3(q0 * (aa.angle() * aa.axis()));  // world rotation vector of the whole turn
  }();
  const auto total = static_cast<int>(std::lround((kLead + kApproach + kHold) * 1000));
  std::string rows =
      "t,x,y,z,qw,qx,qy,qz\n"
      "# The surgeon's hand of dm_example_osteotomy on the Colin27 skull: the moving fragment's pose (its "
      "frame =\n"
      "# the scan's at the identity) every 10 ms, from 10 mm and 15 deg away to the planned pose pushed past "
      "it\n"
      "# along -n (a minimum-jerk approach over 2 s after 0.2 s, held 1.5 s). Written by the program.\n";
  for (int k = 0; k <= total; ++k) {
    const double t = 1e-3 * k, u = std::clamp((t - kLead) / kApproach, 0.0, 1.0);
    const double s = u * u * u * (10 - 15 * u + 6 * u * u);            // minimum jerk
    const double ds = (30 * u * u - 60 * u * u * u + 30 * u * u * u * u) / kApproach;  // ds/dt
    dm::HapticState h;
    h.timeNs = static_cast<std::int64_t>(k) * 1'000'000;
    h.position = (1 - s) * start.translation() + s * goal.translation();
    h.orientation = q0.slerp(s, q1);
    h.linearVelocity = ds * (goal.translation() - start.translation());
    h.angularVelocity = ds * axis;
    if (k % 10 == 0) {
      const Vec3& p = h.position;
      const dm::Quat& q = h.orientation;
      rows += dm::formatString("%.3f,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g\n", h.timeNs * 1e-9, p.x(),
                               p.y(), p.z(), q.w(), q.x(), q.y(), q.z());
    }
    // The queue holds 8192 records and drains within about a millisecond.
    while (!(*rec)->pushHapticState(h)) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  if (auto s = (*rec)->close(); !s) return s;
  return dm::writeFileAtomic(csv, rows.data(), rows.size());
}

int fail(const dm::Error& e) {
  std::cerr << "dm_example_osteotomy: " << e << '\n';
  return 1;
}

int run(const Options& o) {
  auto headPath = dm::FileSystem::global().resolve("mricron:ch2.nii.gz");
  if (!headPath) return fail(headPath.error());
  auto brainPath = dm::FileSystem::global().resolve("mricron:ch2bet.nii.gz");
  if (!brainPath) return fail(brainPath.error());
  auto head = dm::readVolume(*headPath);
  if (!head) return fail(head.error());
  auto brain = dm::readVolume(*brainPath);
  if (!brain) return fail(brain.error());
  auto skull = cutSkull(*head, *brain);
  if (!skull) return fail(skull.error());
  auto fixedTree = dm::ImplicitSphereTree::create(skull->fixed, 0.5);
  if (!fixedTree) return fail(fixedTree.error());
  auto movingTree = dm::ImplicitSphereTree::create(skull->moving, 0.5);
  if (!movingTree) return fail(movingTree.error());
  dm::BonePlacementOptions bo;
  bo.threshold = 0.5;
  bo.maxContacts = 4096;
  auto renderer =
      dm::BonePlacementRenderer::create(*fixedTree, dm::Isometry3::Identity(), *movingTree, skull->moving, bo);
  if (!renderer) return fail(renderer.error());
  const std::vector<Vec3> points = dm::boneReferencePoints(skull->moving, 0.5);

  if (auto s = dm_example::makeOutputDir(o.out); !s) return fail(s.error());
  std::vector<std::string> written;
  if (auto s = dm::writeVolume(skull->labels, o.out / "fragments.nii.gz"); !s) return fail(s.error());
  written.push_back("fragments.nii.gz");

  // The hand: displaced 10 mm (out along the cut normal and sideways) and
  // turned 15°, pivoting about the fragment's centre; it ends `push` mm past
  // the anatomical pose, into the fixed fragment.
  const Vec3 pivot = points.back();
  const Vec3 side = skull->cutNormal.cross(Vec3::UnitZ()).normalized();
  dm::Isometry3 start = dm::Isometry3::Identity();
  start.linear() = dm::AngleAxis(15.0 * std::numbers::pi / 180, Vec3(0.3, 1, 0.2).normalized()).toRotationMatrix();
  start.translation() = pivot - start.linear() * pivot + (8 * skull->cutNormal + 6 * side) * kMm;
  dm::Isometry3 goal = dm::Isometry3::Identity();
  goal.translation() = -o.pushMm * kMm * skull->cutNormal;
  if (auto s = recordHand(o.out / "hand.dmrec", o.out / "hand.csv", start, goal); !s) return fail(s.error());
  written.push_back("hand.dmrec");
  written.push_back("hand.csv");

  dm::FactoryRegistry registry;
  dm::PluginLinker linker(registry);
  if (auto s = dm::registerBuiltinDrivers(linker); !s) return fail(s.error());
  auto device = dm::HapticDevice::open(registry, "replay-haptic",
                                       {{"file", (o.out / "hand.dmrec").string()}, {"max_force", "20"}});
  if (!device) return fail(device.error());
  dm::HapticLoopConfig config;
  config.loop = {.rate_hz = 1000, .name = "haptics"};
  config.overrunFades = o.realtime;  // lockstep output must not depend on the machine's load
  auto loop = dm::HapticLoop::create({.device = **device, .renderer = **renderer}, config);
  if (!loop) return fail(loop.error());

  const double duration = kLead + kApproach + kHold;
  std::vector<dm::ProbeSample> trace;
  trace.reserve(static_cast<std::size_t>(duration * 1000) + 16);
  std::int64_t startNs = -1;
  double maxDepth = 0;
  dm::HapticLoop& hl = **loop;
  dm::BonePlacementRenderer& bone = **renderer;
  auto haptics = dm::makeFunctionEngine("haptics", [&](const dm::TickInfo& t) {
    hl.tick(t);
    const dm::HapticLoopSample& s = hl.lastSample();
    if (startNs < 0) startNs = s.timeNs;
    maxDepth = std::max(maxDepth, bone.maxContactDepth());
    if (trace.size() < trace.capacity())
      trace.push_back({.t = 1e-9 * static_cast<double>(s.timeNs - startNs),
                       .devicePose = s.input.devicePose,
                       .response = s.response});
    return true;
  });
  struct Alignment {
    double t, rms;
    int contacts;
  };
  std::vector<Alignment> alignment;
  alignment.reserve(static_cast<std::size_t>(duration * 50) + 8);
  auto monitor = dm::makeFunctionEngine("monitor", [&](const dm::TickInfo& t) {
    const dm::HapticLoopSample& s = hl.latest();
    if (alignment.size() < alignment.capacity())
      alignment.push_back({1e-9 * static_cast<double>(t.scheduled_ns), rmsError(points, s.response.proxyPose),
                           s.response.contacts});
    return true;
  });
  dm::MasterEngine master;
  if (auto s = master.addEngine(haptics, {.rateHz = 1000, .priority = 80}); !s) return fail(s.error());
  if (auto s = master.addEngine(monitor, {.rateHz = 50}); !s) return fail(s.error());
  std::vector<dm::EngineStats> stats;
  if (auto s = dm_example::runEngines(master, "osteotomy", o.realtime, duration, stats); !s) return fail(s.error());
  const dm::HapticLoopStats loopStats = hl.stats();
  if (trace.empty()) return fail(dm::fail(dm::ErrorCode::Internal, "no haptic tick ran", "osteotomy"));

  // Outcomes: the last 0.5 s is the rest at the goal.
  const dm::ProbeSample& last = trace.back();
  const double finalError = rmsError(points, last.response.proxyPose);
  const double initialError = rmsError(points, start);
  double maxForce = 0;
  Vec3 restForce = Vec3::Zero(), restOffset = Vec3::Zero();
  std::size_t rest = 0;
  for (const dm::ProbeSample& s : trace) {
    maxForce = std::max(maxForce, s.response.force.norm());
    if (s.t < duration - 0.5) continue;
    restForce += s.response.force;
    // Coupling offset: the device's image of the centre of mass minus the centre.
    const Vec3 c = bone.massProperties().centerOfMass;
    restOffset += s.devicePose * c - s.response.proxyPose * c;
    ++rest;
  }
  restForce /= static_cast<double>(rest);
  restOffset /= static_cast<double>(rest);
  const Vec3 coupling = -bo.couplingStiffness * restOffset;  // what the hand should feel at rest

  if (auto s = dm_example::writeOutput(o.out / "forces.csv", dm::formatProbeCsv(trace), written); !s)
    return fail(s.error());
  auto plot = dm::plotForceTrace(trace);
  if (!plot) return fail(plot.error());
  if (auto s = dm::writePng(*plot, o.out / "forces.png"); !s) return fail(s.error());
  written.push_back("forces.png");
  std::string a = "t,rms_error_m,contacts\n";
  for (const Alignment& x : alignment) a += dm::formatString("%.3f,%.9g,%d\n", x.t, x.rms, x.contacts);
  if (auto s = dm_example::writeOutput(o.out / "alignment.csv", a, written); !s) return fail(s.error());

  std::size_t fixedVoxels = 0, movingVoxels = 0;
  for (std::size_t i = 0; i < skull->labels.voxelCount(); ++i) {
    fixedVoxels += skull->labels.valueAt(i) == 1;
    movingVoxels += skull->labels.valueAt(i) == 2;
  }
  const auto vec = [](const Vec3& v) { return nlohmann::json::array({v.x(), v.y(), v.z()}); };
  nlohmann::json summary = {{"mode", o.realtime ? "realtime" : "lockstep"},
                            {"region_voxels", skull->regionVoxels},
                            {"fixed_voxels", fixedVoxels},
                            {"moving_voxels", movingVoxels},
                            {"moving_mass_kg", bone.massProperties().mass},
                            {"cut_normal", vec(skull->cutNormal)},
                            {"push_mm", o.pushMm},
                            {"reference_points", points.size()},
                            {"region_box_m", {{"min", vec(skull->boxMin)}, {"max", vec(skull->boxMax)}}},
                            {"initial_error_m", initialError},
                            {"final_error_m", finalError},
                            {"final_contacts", last.response.contacts},
                            {"max_contact_depth_m", maxDepth},
                            {"slop_m", bone.slop()},
                            {"max_force_N", maxForce},
                            {"final_force_N", vec(last.response.force)},
                            {"rest_force_N", vec(restForce)},
                            {"rest_coupling_force_N", vec(coupling)},
                            {"rest_force_along_normal_N", restForce.dot(skull->cutNormal)},
                            {"rest_force_minus_coupling_N", (restForce - coupling).norm()},
                            {"fault_ticks", loopStats.faultTicks},
                            {"engines", dm::engineStatsJson(stats)},
                            {"outputs", written}};
  if (auto s = dm_example::writeOutput(o.out / "summary.json", summary.dump(2) + "\n", written); !s)
    return fail(s.error());
  std::printf("skull region %zu voxels cut into %zu + %zu; the fragment (%.1f g) placed from %.2f mm to %.3f mm RMS "
              "error with %d contacts; the hand %.1f mm past the goal feels %.3f N along the cut normal "
              "(coupling %.3f N); outputs in %s\n",
              skull->regionVoxels, fixedVoxels, movingVoxels, 1e3 * bone.massProperties().mass, 1e3 * initialError,
              1e3 * finalError, last.response.contacts, o.pushMm, restForce.dot(skull->cutNormal),
              coupling.dot(skull->cutNormal), o.out.string().c_str());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  CLI::App app{"Virtual osteotomy and 6-DOF bone fragment placement on the Colin27 skull"};
  app.add_option("--out", o.out, "Output directory (default osteotomy_out)");
  app.add_option("--push", o.pushMm, "How far past the anatomical pose the hand presses, mm (default 2)")
      ->check(CLI::Range(0.0, 5.0));
  app.add_flag("--realtime", o.realtime, "Real-time threads instead of lockstep on a virtual clock");
  bool parsed = false;
  const int code = dm_example::parseCommandLine(app, argc, argv, parsed);
  return parsed ? run(o) : code;
}
