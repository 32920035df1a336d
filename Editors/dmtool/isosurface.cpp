// dmtool isosurface VOLUME --iso V -o MESH [--method mc|mt] [--close-borders]
// [--largest-component] [--smooth N [--smooth-max-displacement M]] [--json]:
// extracts the isosurface, optionally keeps its largest piece and smooths the
// voxel staircase away (Taubin, each vertex within M metres of where it
// was), and reports its size, topology and how far smoothing moved it.
#include <dm/io/mesh_io.hpp>
#include <dm/io/volume_io.hpp>
#include <dm/math/isosurface.hpp>
#include <dm/math/mesh_filters.hpp>

#include <algorithm>
#include <iostream>
#include <limits>
#include <map>
#include <memory>
#include <vector>

#include "common.hpp"
#include "progress_bar.hpp"

namespace dmtool {
namespace {

struct IsoOptions {
  std::string volume;
  std::string output;
  double iso = 0.0;
  std::string method = "mc";
  bool closeBorders = false;
  bool largestComponent = false;
  int smooth = 0;
  double smoothMaxDisplacement = std::numeric_limits<double>::infinity();
  bool json = false;
};

/// How far smoothing moved the vertices (m).
struct SmoothReport {
  double meanDisplacement = 0, maxDisplacement = 0;
};

SmoothReport displacement(const std::vector<dm::Vec3>& before, const std::vector<dm::Vec3>& after) {
  SmoothReport r;
  for (std::size_t v = 0; v < before.size(); ++v) {
    const double d = (after[v] - before[v]).norm();
    r.meanDisplacement += d;
    r.maxDisplacement = std::max(r.maxDisplacement, d);
  }
  if (!before.empty()) r.meanDisplacement /= static_cast<double>(before.size());
  return r;
}

int runIsosurface(const IsoOptions& o) {
  const std::filesystem::path in = resolveInput(o.volume);
  auto v = dm::readVolume(in);
  if (!v) return printError(v.error());
  dm::IsosurfaceOptions iso;
  iso.iso = o.iso;
  iso.method = o.method == "mt" ? dm::IsoMethod::MarchingTetrahedra : dm::IsoMethod::MarchingCubes;
  iso.closeBorders = o.closeBorders;
  ProgressBar bar("isosurface");
  iso.progress = bar.callback();
  auto mesh = dm::extractIsosurface(*v, iso);
  bar.finish();
  if (!mesh) return printError(mesh.error());
  if (mesh->empty()) {
    const auto [lo, hi] = v->range();
    return printError(dm::fail(
        dm::ErrorCode::InvalidArgument, "the isosurface at " + std::to_string(o.iso) + " is empty",
        in.string(),
        "choose --iso inside the value range [" + std::to_string(lo) + ", " + std::to_string(hi) + "]"));
  }
  std::size_t dropped = 0;
  if (o.largestComponent) *mesh = dm::keepLargestComponent(*mesh, &dropped);
  SmoothReport moved;
  if (o.smooth > 0) {
    const std::vector<dm::Vec3> before = mesh->positions;
    if (auto s = dm::smoothMesh(*mesh, {.iterations = o.smooth, .maxDisplacement = o.smoothMaxDisplacement});
        !s)
      return printError(s.error());
    moved = displacement(before, mesh->positions);
  }
  if (auto s = dm::writeMesh(*mesh, o.output); !s) return printError(s.error());
  MeshSummary s = summarize(*mesh);
  s.name = std::filesystem::path(o.output).filename().string();
  if (o.json) {
    nlohmann::json j = toJson(s);
    j["file"] = o.output;
    j["iso"] = o.iso;
    j["method"] = o.method;
    if (o.largestComponent) j["components_dropped"] = dropped;
    if (o.smooth > 0)
      j["smooth"] = {{"iterations", o.smooth},
                     {"mean_displacement_m", moved.meanDisplacement},
                     {"max_displacement_m", moved.maxDisplacement}};
    printJson(j);
  } else {
    std::cout << o.output << ": isosurface " << o.iso << " of " << in.string() << '\n';
    if (o.largestComponent) std::cout << "  largest component kept, " << dropped << " smaller ones dropped\n";
    if (o.smooth > 0)
      std::cout << "  smoothed (" << o.smooth << " Taubin iterations): vertices moved "
                << 1e3 * moved.meanDisplacement << " mm on average, " << 1e3 * moved.maxDisplacement
                << " mm at most\n";
    std::cout << toText(s);
  }
  return kExitOk;
}

}  // namespace

Command addIsosurfaceCommand(CLI::App& parent) {
  auto o = std::make_shared<IsoOptions>();
  CLI::App* app =
      parent.add_subcommand("isosurface", "Extract the surface where a volume crosses --iso as a mesh");
  app->add_option("volume", o->volume, "volume file (NIfTI, MetaImage, NRRD, ...)")->required();
  app->add_option("--iso", o->iso, "threshold in voxel value units; inside is value > iso")
      ->required()
      ->check(finiteNumber());
  app->add_option("-o,--output", o->output, "mesh file to write (.stl, .ply, .obj)")->required();
  app->add_option("--method", o->method, "mc: marching cubes, mt: marching tetrahedra")
      ->check(CLI::IsMember({"mc", "mt"}));
  app->add_flag("--close-borders", o->closeBorders, "close the surface where it leaves the grid");
  app->add_flag("--largest-component", o->largestComponent, "keep only the largest connected piece");
  app->add_option("--smooth", o->smooth, "Taubin smoothing iterations (removes the voxel staircase), 0..100")
      ->check(CLI::Range(0, 100));
  app->add_option("--smooth-max-displacement", o->smoothMaxDisplacement,
                  "while smoothing, move no vertex further than this (metres, e.g. half a voxel)")
      ->check(CLI::PositiveNumber & finiteNumber());
  app->add_flag("--json", o->json, "print one JSON object on stdout");
  return {app, [o, app] {
            if (app->count("--smooth-max-displacement") > 0 && o->smooth == 0) {
              printError(dm::fail(dm::ErrorCode::InvalidArgument,
                                  "--smooth-max-displacement bounds smoothing, but --smooth is 0",
                                  "dmtool isosurface", "add --smooth N (e.g. 10)"));
              return kExitUsage;
            }
            return runIsosurface(*o);
          }};
}

}  // namespace dmtool
