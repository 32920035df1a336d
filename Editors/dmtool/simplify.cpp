// dmtool simplify MESH --ratio R -o MESH [--triangles N] [--max-error E]
// [--json]: quadric-error simplification with a measured distance bound.
#include <dm/io/mesh_io.hpp>
#include <dm/math/simplify.hpp>

#include <iostream>
#include <limits>
#include <memory>

#include "common.hpp"
#include "progress_bar.hpp"

namespace dmtool {
namespace {

struct SimplifyCliOptions {
  std::string input;
  std::string output;
  double ratio = 0.5;
  std::size_t triangles = 0;
  double maxError = std::numeric_limits<double>::infinity();
  bool json = false;
};

int runSimplify(const SimplifyCliOptions& o) {
  const std::filesystem::path in = resolveInput(o.input);
  auto mesh = dm::readMesh(in);
  if (!mesh) return printError(mesh.error());
  dm::SimplifyOptions opt;
  opt.targetRatio = o.ratio;
  opt.targetTriangles = o.triangles;
  opt.maxError = o.maxError;
  ProgressBar bar("simplify");
  opt.progress = bar.callback();
  dm::SimplifyReport report;
  auto out = dm::simplifyMesh(*mesh, opt, &report);
  bar.finish();
  if (!out) return printError(out.error().within(in.string()));
  if (auto s = dm::writeMesh(*out, o.output); !s) return printError(s.error());
  MeshSummary s = summarize(*out);
  s.name = std::filesystem::path(o.output).filename().string();
  if (o.json) {
    nlohmann::json j = toJson(s);
    j["file"] = o.output;
    j["trianglesBefore"] = report.trianglesBefore;
    j["trianglesAfter"] = report.trianglesAfter;
    j["maxDistance"] = report.maxDistance;
    printJson(j);
  } else {
    std::cout << o.output << ": " << report.trianglesBefore << " -> " << report.trianglesAfter
              << " triangles, max distance " << report.maxDistance << " m\n"
              << toText(s);
  }
  return kExitOk;
}

}  // namespace

Command addSimplifyCommand(CLI::App& parent) {
  auto o = std::make_shared<SimplifyCliOptions>();
  CLI::App* app =
      parent.add_subcommand("simplify", "Reduce a mesh's triangle count by quadric edge collapses");
  app->add_option("mesh", o->input, "mesh file (any format Assimp reads)")->required();
  app->add_option("--ratio", o->ratio, "fraction of triangles to keep, (0, 1]")
      ->check(CLI::Range(0.0, 1.0) & finiteNumber());
  app->add_option("--triangles", o->triangles, "target triangle count (overrides --ratio)")
      ->check(CLI::PositiveNumber);
  app->add_option("-o,--output", o->output, "mesh file to write (.stl, .ply, .obj)")->required();
  app->add_option("--max-error", o->maxError, "m: never move the surface further than this")
      ->check(CLI::NonNegativeNumber & finiteNumber());
  app->add_flag("--json", o->json, "print one JSON object on stdout");
  return {
      app, [o]() -> int {
        if (!(o->ratio > 0.0)) {  // CLI::Range includes 0; a ratio of 0 is a usage error too
          std::cerr << "--ratio: must be > 0 (a fraction in (0, 1])\nRun with --help for more information.\n";
          return kExitUsage;
        }
        return runSimplify(*o);
      }};
}

}  // namespace dmtool
