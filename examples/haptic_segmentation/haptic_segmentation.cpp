// Haptic MRI segmentation — an example simulator built from the SDK's parts.
//
// A surgeon's probe moves through the skull-stripped Colin27 T1 brain
// (mricron-data ch2bet.nii.gz). dm::HapticSegmentation (DMVision) paints the
// white matter around the probe a few times per second, and its guidance
// force — pushing the probe away from tissue edges into homogeneous tissue —
// is rendered to the hand every haptic tick through dm::ForceFieldEffect in
// a dm::HapticLoop (safety, clamping, fade). The hand is sim-haptic's
// virtual hand (a mass–spring–damper pulled around a circle in the axial
// plane through the right corona radiata), so the guidance really moves the
// probe. Two engines in a dm::MasterEngine: "haptics" at 1 kHz and
// "segmentation" at 20 Hz, in lockstep on a virtual clock (bit-reproducible)
// or on real-time threads.
//
//   dm_example_haptic_segmentation [--volume FILE] [--out DIR] [--duration S]
//                                  [--no-guidance] [--realtime]
//
// The intensity window is taken where the surgeon starts, as a user would
// click a seed: the mean ± 2.5 σ of the 5×5×5 voxels around it. Outputs in
// DIR: segmentation.nii.gz (the painted mask), forces.csv and forces.png
// (the guidance force on the hand), slice.png (the axial slice through the
// start with the mask in red and the probe's path in green) and summary.json:
// painted volume; its precision against a reference segmentation of the same
// white matter (global adaptive region growing from the same seed,
// dm::growRegion); voxels painted outside the brain; the mean edge strength
// and adaptive radius along the path, where it painted; the engines' rates.
// examples/scenes/haptic_segmentation.json is the same simulator as a scene
// (the segmentation engine, renderer "none"): its test checks that both
// write the same figures. The integration test
// (examples/CMakeLists.txt) runs it with and without guidance and checks
// the painted volume, its precision, that nothing leaks out of the brain,
// and that guidance keeps the probe farther from edges.
//
// Exit codes: 0 done, 1 failure (message on stderr), 2 bad command line.
#include <dm/core/filesystem.hpp>
#include <dm/core/units.hpp>
#include <dm/engine/master_engine.hpp>
#include <dm/haptics/effects.hpp>
#include <dm/haptics/force_plot.hpp>
#include <dm/haptics/haptic_loop.hpp>
#include <dm/haptics/probe.hpp>
#include <dm/io/drivers.hpp>
#include <dm/io/haptic_device.hpp>
#include <dm/io/image_io.hpp>
#include <dm/io/volume_io.hpp>
#include <dm/vision/region_growing.hpp>
#include <dm/vision/segmentation.hpp>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "../common/example_support.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <string>
#include <thread>
#include <vector>

namespace {

namespace fs = std::filesystem;

struct Options {
  std::string volume = "mricron:ch2bet.nii.gz";
  fs::path out = "haptic_segmentation_out";
  double duration = 8.0;
  bool guidance = true;
  bool realtime = false;
};

// Right corona radiata, MNI (26, −12, 30) mm: white matter (as in
// Tests/DMVision/region_growing_test.cpp).
const dm::Vec3 kSeed = dm::Vec3(26, -12, 30) * dm::units::mm;
constexpr double kPathRadius = 9 * dm::units::mm;
constexpr double kPathPeriod = 4.0;  // s per turn

// The axial slice through voxel row k (dm::volumeSlice, anterior up): grey
// values, the mask in red, the probe's path in green.
dm::Result<dm::Image> slicePicture(const dm::Volume& image, const dm::Volume& mask, int k,
                                   const std::vector<dm::ProbeSample>& trace) {
  const auto [lo, hi] = image.range();
  auto grey = dm::volumeSlice(image, 2, k, std::min(lo, 0.0), hi > 0 ? hi : 1.0);
  auto painted = dm::volumeSlice(mask, 2, k, 0.0, 1.0);
  if (!grey) return grey.error();
  if (!painted) return painted.error();
  auto pic = dm::Image::create(grey->width(), grey->height(), 3, dm::PixelType::U8);
  if (!pic) return pic.error();
  for (int y = 0; y < pic->height(); ++y)
    for (int x = 0; x < pic->width(); ++x) {
      const int g = grey->at<std::uint8_t>(x, y);
      const bool red = painted->at<std::uint8_t>(x, y) != 0;
      pic->at<std::uint8_t>(x, y, 0) = static_cast<std::uint8_t>(red ? std::min(255, g / 2 + 140) : g);
      pic->at<std::uint8_t>(x, y, 1) = static_cast<std::uint8_t>(red ? g / 2 : g);
      pic->at<std::uint8_t>(x, y, 2) = static_cast<std::uint8_t>(red ? g / 2 : g);
    }
  const dm::Vec3i d = image.dims();
  for (const dm::ProbeSample& s : trace) {
    const dm::Vec3 ijk = image.worldToIndex() * s.devicePose.translation();
    const int i = static_cast<int>(std::lround(ijk.x())), j = static_cast<int>(std::lround(ijk.y()));
    if (i < 0 || j < 0 || i >= d.x() || j >= d.y()) continue;
    const int y = d.y() - 1 - j;  // as volumeSlice: the highest j on top
    pic->at<std::uint8_t>(i, y, 0) = 0;
    pic->at<std::uint8_t>(i, y, 1) = 255;
    pic->at<std::uint8_t>(i, y, 2) = 0;
  }
  return pic;
}

int fail(const dm::Error& e) {
  std::cerr << "dm_example_haptic_segmentation: " << e << '\n';
  return 1;
}

int run(const Options& o) {
  auto path = dm::FileSystem::global().resolve(o.volume);
  if (!path) return fail(path.error());
  auto brain = dm::readVolume(*path);
  if (!brain) return fail(brain.error());
  const auto seed = dm::nearestVoxel(*brain, kSeed);
  if (!seed) return fail(dm::Error{dm::ErrorCode::InvalidArgument, "the start point lies outside the volume",
                                   o.volume, "use a brain in MNI space, e.g. mricron:ch2bet.nii.gz"});

  // The reference: global adaptive growing of the same white matter.
  auto reference =
      dm::growRegion(*brain, std::array{*seed},
                     {.adaptive = true, .k = 2.5, .connectivity = dm::Connectivity::TwentySix});
  if (!reference) return fail(reference.error());

  // The surgeon's window from the start point's neighbourhood.
  const dm::NeighbourhoodStats w = dm::neighbourhoodStats(*brain, *seed);
  dm::HapticSegmentationOptions so;
  so.maxRadius = 6 * dm::units::mm;
  so.gain = 1e-2;
  so.maxForce = 1.5;
  so.grow = {.lower = w.mean - 2.5 * w.stddev,
             .upper = w.mean + 2.5 * w.stddev,
             .connectivity = dm::Connectivity::Six};
  auto seg = dm::HapticSegmentation::create(*brain, so);
  if (!seg) return fail(seg.error());

  // The hand: pulled around a circle in the axial plane through the start.
  dm::FactoryRegistry registry;
  dm::PluginLinker linker(registry);
  if (auto s = dm::registerBuiltinDrivers(linker); !s) return fail(s.error());
  const dm::Vec3 c = kSeed;
  char center[96];
  std::snprintf(center, sizeof center, "%.6f,%.6f,%.6f", c.x(), c.y(), c.z());
  auto device = dm::HapticDevice::open(registry, "sim-haptic",
                                       {{"path", "circle"},
                                        {"center", center},
                                        {"radius", std::to_string(kPathRadius)},
                                        {"period", std::to_string(kPathPeriod)},
                                        {"hand", "1"},
                                        {"hand_mass", "0.15"},
                                        {"hand_stiffness", "150"},
                                        {"hand_damping", "6"},
                                        {"max_force", "3"}});
  if (!device) return fail(device.error());

  dm::FreeSpaceRenderer renderer;  // the probe moves in free space: no contact, only the guidance
  dm::EffectStack effects(1);
  if (o.guidance) {
    const dm::HapticSegmentation* s = &*seg;
    auto added = effects.add(std::make_unique<dm::ForceFieldEffect>(
        [s](const dm::Vec3& p) { return s->guidanceForce(p); }, "segmentation"));
    if (!added) return fail(added.error());
  }
  dm::HapticLoopConfig config;
  config.loop = {.rate_hz = 1000, .name = "haptics"};
  config.overrunFades = o.realtime;  // lockstep output must not depend on the machine's load
  auto loop = dm::HapticLoop::create({.device = **device, .renderer = renderer, .effects = &effects}, config);
  if (!loop) return fail(loop.error());

  // The trace, sized up front: the haptic tick must not allocate.
  std::vector<dm::ProbeSample> trace;
  trace.reserve(static_cast<std::size_t>(o.duration * 1000) + 16);
  std::int64_t startNs = -1;
  dm::HapticLoop& hl = **loop;
  auto haptics = dm::makeFunctionEngine("haptics", [&](const dm::TickInfo& t) {
    hl.tick(t);
    const dm::HapticLoopSample& s = hl.lastSample();
    if (startNs < 0) startNs = s.timeNs;
    if (trace.size() < trace.capacity())
      trace.push_back({.t = 1e-9 * static_cast<double>(s.timeNs - startNs),
                       .devicePose = s.input.devicePose,
                       .response = s.response});
    return true;
  });
  // Painting, a few times per second, at the newest probe position; the
  // edge strength and adaptive radius there, along the path.
  std::size_t updates = 0;
  double edgeSum = 0, radiusSum = 0;
  dm::Error paintError;
  auto painting = dm::makeFunctionEngine("segmentation", [&](const dm::TickInfo&) {
    const dm::Vec3 p = hl.latest().input.devicePose.translation();
    auto u = seg->update(p);
    if (!u) {
      paintError = u.error();
      return false;
    }
    ++updates;
    edgeSum += seg->edgeStrength().sampleWorld(p);
    radiusSum += seg->adaptiveRadius(p);
    return true;
  });
  dm::MasterEngine master;
  if (auto s = master.addEngine(haptics, {.rateHz = 1000, .priority = 80}); !s) return fail(s.error());
  if (auto s = master.addEngine(painting, {.rateHz = 20}); !s) return fail(s.error());
  std::vector<dm::EngineStats> stats;
  const dm::Status ran = dm_example::runEngines(master, "haptic segmentation", o.realtime, o.duration, stats);
  if (!paintError.what.empty()) return fail(paintError);
  if (!ran) return fail(ran.error());

  // Outcomes.
  const dm::Volume& mask = seg->mask();
  std::size_t painted = 0, inReference = 0, outsideBrain = 0;
  for (std::size_t n = 0; n < mask.voxelCount(); ++n) {
    if (mask.valueAt(n) == 0) continue;
    ++painted;
    inReference += reference->mask.valueAt(n) != 0;
    outsideBrain += brain->valueAt(n) == 0;
  }
  double maxForce = 0;
  for (const dm::ProbeSample& s : trace) maxForce = std::max(maxForce, s.response.force.norm());
  if (auto s = dm_example::makeOutputDir(o.out); !s) return fail(s.error());
  std::vector<std::string> written;
  if (auto s = dm::writeVolume(mask, o.out / "segmentation.nii.gz"); !s) return fail(s.error());
  written.push_back("segmentation.nii.gz");
  if (auto s = dm_example::writeOutput(o.out / "forces.csv", dm::formatProbeCsv(trace), written); !s)
    return fail(s.error());
  if (!trace.empty()) {
    auto plot = dm::plotForceTrace(trace);
    if (!plot) return fail(plot.error());
    if (auto s = dm::writePng(*plot, o.out / "forces.png"); !s) return fail(s.error());
    written.push_back("forces.png");
  }
  auto pic = slicePicture(*brain, mask, seed->z(), trace);
  if (!pic) return fail(pic.error());
  if (auto s = dm::writePng(*pic, o.out / "slice.png"); !s) return fail(s.error());
  written.push_back("slice.png");

  const double voxelMl = reference->stats.volumeMl / static_cast<double>(reference->stats.voxelCount);
  nlohmann::json summary = {
      {"volume", o.volume},
      {"mode", o.realtime ? "realtime" : "lockstep"},
      {"guidance", o.guidance},
      {"duration_s", o.duration},
      {"window", {w.mean - 2.5 * w.stddev, w.mean + 2.5 * w.stddev}},
      {"updates", updates},
      {"painted_voxels", painted},
      {"painted_ml", static_cast<double>(painted) * voxelMl},
      {"precision", painted ? static_cast<double>(inReference) / static_cast<double>(painted) : 0.0},
      {"outside_brain_voxels", outsideBrain},
      {"reference_ml", reference->stats.volumeMl},
      {"mean_edge_strength", updates ? edgeSum / static_cast<double>(updates) : 0.0},
      {"mean_radius_mm", updates ? 1e3 * radiusSum / static_cast<double>(updates) : 0.0},
      {"max_force_N", maxForce},
      {"engines", dm::engineStatsJson(stats)},
      {"outputs", written}};
  if (auto s = dm_example::writeOutput(o.out / "summary.json", summary.dump(2) + "\n", written); !s)
    return fail(s.error());
  std::printf("painted %.2f mL of white matter (precision %.3f against the reference, %zu voxels outside the "
              "brain) in %zu updates; guidance %s: mean edge strength %.3f, mean radius %.2f mm, max force "
              "%.2f N; outputs in %s\n",
              static_cast<double>(painted) * voxelMl, summary["precision"].get<double>(), outsideBrain, updates,
              o.guidance ? "on" : "off", summary["mean_edge_strength"].get<double>(),
              summary["mean_radius_mm"].get<double>(), maxForce, o.out.string().c_str());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  CLI::App app{"Haptic MRI segmentation: paint the white matter of a T1 brain with force guidance"};
  app.add_option("--volume", o.volume, "T1 brain volume (default mricron:ch2bet.nii.gz)");
  app.add_option("--out", o.out, "Output directory (default haptic_segmentation_out)");
  app.add_option("--duration", o.duration, "Seconds to run (default 8)")->check(CLI::Range(0.1, 3600.0));
  app.add_flag("!--no-guidance", o.guidance, "Render no guidance force (the control run)");
  app.add_flag("--realtime", o.realtime, "Real-time threads instead of lockstep on a virtual clock");
  bool parsed = false;
  const int code = dm_example::parseCommandLine(app, argc, argv, parsed);
  return parsed ? run(o) : code;
}
