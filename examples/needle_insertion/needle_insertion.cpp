// Needle insertion through skin, fat and muscle, felt at 1 kHz.
//
// A 40 × 40 × 30 mm FEM block of 5 mm cells (E = 30 kPa, base fixed) whose
// tetrahedra take their layer from a label volume: skin on top (5 mm), fat
// (10 mm), muscle below. A needle held by the device goes straight down at
// --speed to --depth and back out; the haptic side (dm::HapticNeedle) ticks
// at 1 kHz on the needle's local model while the needle and the tissue are
// stepped at 100 Hz, in lockstep (one thread, a fixed order: reproducible
// bit for bit). Writes to --out:
//  - force.csv: t, depth, the force the hand feels along the needle, the
//    tip's state and layer, per tick;
//  - force.png: that force against depth;
//  - summary.json: the membranes broken (the tip's depth when the physics
//    broke each, the tissue tented in ahead of it, and the largest force
//    felt before: the hand feels the pop in the tick the tip's force reaches
//    the threshold, so that is just under it),
//    the peak force, and the fit of the force in the muscle to
//    F = f_cut + μ·L + F₀ (its slope μ: the muscle's friction per metre).
// Exit 0 on success, 1 on an error (printed), 2 on a bad command line.
#include <dm/core/filesystem.hpp>
#include <dm/core/result.hpp>
#include <dm/core/volume.hpp>
#include <dm/haptics/force_plot.hpp>
#include <dm/haptics/needle.hpp>
#include <dm/io/image_io.hpp>
#include <dm/physics/fem.hpp>
#include <dm/physics/needle.hpp>

#include <nlohmann/json.hpp>

#include <CLI/CLI.hpp>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "../common/example_support.hpp"

namespace {

struct Options {
  std::filesystem::path out = "needle_insertion_out";
  double speed = 0.01;   // m/s
  double depth = 0.022;  // m below the top
};

// The layers: skin, fat (no membrane), muscle (its fascia).
const dm::NeedleLayer kLayers[] = {{.punctureForce = 1.2, .cuttingForce = 0.4, .friction = 50.0},
                                   {.punctureForce = 0.0, .cuttingForce = 0.1, .friction = 10.0},
                                   {.punctureForce = 0.8, .cuttingForce = 0.3, .friction = 40.0}};
const char* const kLayerNames[] = {"skin", "fat", "muscle"};

int fail(const dm::Error& e) {
  std::fprintf(stderr, "needle_insertion: %s\n", e.message().c_str());
  return 1;
}

int run(const Options& o) {
  const dm::Vec3 size(0.04, 0.04, 0.03);
  auto mesh = dm::tetMeshBox({8, 8, 6}, size);
  if (!mesh) return fail(mesh.error());
  auto body = dm::FemBody::create(*mesh, {.youngsModulus = 3e4, .poissonRatio = 0.45, .density = 1000.0},
                                  {.alpha = 30.0, .beta = 0.002});
  if (!body) return fail(body.error());
  body->fixNodesWhere([](const dm::Vec3& p) { return p.z() < 1e-9; });
  // The label volume: one 5 mm voxel per cell, 1 skin (top cell), 2 fat, 3 muscle.
  dm::Affine3 voxelToWorld = dm::Affine3::Identity();
  voxelToWorld.linear() = 0.005 * dm::Mat3::Identity();
  voxelToWorld.translation() = dm::Vec3::Constant(0.0025);
  auto labels = dm::Volume::create({8, 8, 6}, dm::VoxelType::U8, voxelToWorld);
  if (!labels) return fail(labels.error());
  for (int k = 0; k < 6; ++k)
    for (int j = 0; j < 8; ++j)
      for (int i = 0; i < 8; ++i) labels->setValue(i, j, k, k == 5 ? 1 : k >= 3 ? 2 : 3);
  const std::uint8_t layerOfLabel[] = {0, 0, 1, 2};
  auto layerOf = dm::tetLayersFromLabels(*mesh, *labels, layerOfLabel);
  if (!layerOf) return fail(layerOf.error());
  auto needle = dm::NeedleInsertion::create(*body, *layerOf, kLayers, {.couplingSpacing = 5e-4});
  if (!needle) return fail(needle.error());
  auto felt = dm::HapticNeedle::create(*needle, {.maxForce = 6.0});
  if (!felt) return fail(felt.error());

  // Straight down over a point off the grid's nodes, 2 mm above the top to
  // --depth, then out; 1 kHz ticks, a 10 ms step every 10.
  const dm::Vec3 entry(0.0203, 0.0196, size.z());
  const double start = -0.002, travel = o.depth - start;
  const int ticksIn = int(std::ceil(travel / (o.speed * 1e-3)));
  std::string csv = "t_s,depth_m,force_N,tip,layer\n";
  std::vector<double> depthMm, force;
  nlohmann::json membranes = nlohmann::json::array();
  std::size_t punctures = 0;
  double peak = 0.0, sincePuncture = 0.0;
  // The muscle's stretch of the force curve, for the friction fit.
  double n = 0, sx = 0, sy = 0, sxx = 0, sxy = 0;
  for (int i = 0; i < 2 * ticksIn; ++i) {
    const double d = i < ticksIn ? start + o.speed * 1e-3 * i : o.depth - o.speed * 1e-3 * (i - ticksIn);
    dm::Isometry3 device = dm::Isometry3::Identity();
    device.translation() = entry + dm::Vec3(0, 0, -d);
    const dm::HapticResponse r =
        (*felt)->tick({.timeNs = std::int64_t(i) * 1'000'000, .dt = 1e-3, .devicePose = device});
    if (i % 10 == 9) {
      auto step = (*felt)->step(0.01);
      if (!step) return fail(step.error());
      if (needle->punctureCount() > punctures) {
        punctures = needle->punctureCount();
        membranes.push_back(
            {{"depth_m", d}, {"layer", kLayerNames[needle->tipLayer()]}, {"peak_force_N", sincePuncture}});
        sincePuncture = 0.0;
      }
    }
    const double f = r.force.z();  // up: what resists the needle going down
    peak = std::max(peak, f);
    sincePuncture = std::max(sincePuncture, f);
    csv += dm::formatString("%.3f,%.6f,%.6f,%d,%d\n", i * 1e-3, d, f, int(needle->tipState()),
                            needle->tipLayer());
    depthMm.push_back(1e3 * d);
    force.push_back(f);
    // In the muscle, cutting, 2 mm past its fascia: f = f_cut + μ·L.
    if (i < ticksIn && punctures == 2 && needle->tipState() == dm::NeedleTip::Cutting &&
        d > membranes.back()["depth_m"].get<double>() + 0.002)
      n += 1, sx += d, sy += f, sxx += d * d, sxy += d * f;
  }
  const double slope = n > 2 ? (n * sxy - sx * sy) / (n * sxx - sx * sx) : std::nan("");

  if (auto s = dm_example::makeOutputDir(o.out); !s) return fail(s.error());
  std::vector<std::string> written;
  if (auto s = dm_example::writeOutput(o.out / "force.csv", csv, written); !s) return fail(s.error());
  const dm::PlotSeries series[] = {{"FORCE", {30, 60, 220}, depthMm, force}};
  auto plot = dm::plotSeries(series, {.xUnit = "mm", .yUnit = "N"});
  if (!plot) return fail(plot.error());
  if (auto s = dm::writePng(*plot, o.out / "force.png"); !s) return fail(s.error());
  written.push_back("force.png");
  const nlohmann::json summary = {
      {"speed_m_s", o.speed},
      {"depth_m", o.depth},
      {"tetrahedra", body->tetCount()},
      {"punctures", punctures},
      {"membranes", membranes},
      {"peak_force_N", peak},
      {"thresholds_N", {{"skin", kLayers[0].punctureForce}, {"muscle", kLayers[2].punctureForce}}},
      {"muscle_friction",
       {{"configured_N_per_m", kLayers[2].friction}, {"fitted_force_slope_N_per_m", slope}}},
      {"models_published", (*felt)->publishedModels()},
      {"outputs", written}};
  if (auto s = dm_example::writeOutput(o.out / "summary.json", summary.dump(2) + "\n", written); !s)
    return fail(s.error());
  std::printf("%zu membranes broken, peak %.3f N, force slope in the muscle %.1f N/m; outputs in %s\n",
              punctures, peak, slope, o.out.string().c_str());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  CLI::App app{"Needle insertion through skin, fat and muscle (FEM tissue), felt at 1 kHz"};
  app.add_option("--out", o.out, "Output directory (default needle_insertion_out)");
  app.add_option("--speed", o.speed, "Insertion speed, m/s (default 0.01)")->check(CLI::Range(1e-4, 0.1));
  app.add_option("--depth", o.depth, "Deepest tip position below the top, m (default 0.022)")
      ->check(CLI::Range(0.001, 0.028));
  bool parsed = false;
  const int code = dm_example::parseCommandLine(app, argc, argv, parsed);
  return parsed ? run(o) : code;
}
