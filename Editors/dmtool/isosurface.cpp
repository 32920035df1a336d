// dmtool isosurface VOLUME --iso V -o MESH [--method mc|mt] [--close-borders]
// [--json]: extracts the isosurface and reports its size and topology.
#include <dm/io/mesh_io.hpp>
#include <dm/io/volume_io.hpp>
#include <dm/math/isosurface.hpp>

#include <iostream>
#include <map>
#include <memory>

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
  bool json = false;
};

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
  if (auto s = dm::writeMesh(*mesh, o.output); !s) return printError(s.error());
  MeshSummary s = summarize(*mesh);
  s.name = std::filesystem::path(o.output).filename().string();
  if (o.json) {
    nlohmann::json j = toJson(s);
    j["file"] = o.output;
    j["iso"] = o.iso;
    j["method"] = o.method;
    printJson(j);
  } else {
    std::cout << o.output << ": isosurface " << o.iso << " of " << in.string() << '\n' << toText(s);
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
  app->add_flag("--json", o->json, "print one JSON object on stdout");
  return {app, [o] { return runIsosurface(*o); }};
}

}  // namespace dmtool
