// dmtool voxelize MESH --voxel-size H -o VOLUME [--sdf] [--band W]
// [--padding N] [--json]: occupancy or signed distance volumes of a closed
// mesh, written as NIfTI/MetaImage/NRRD or OpenVDB (.vdb; a level set with
// --sdf).
#include <dm/io/mesh_io.hpp>
#include <dm/io/vdb.hpp>
#include <dm/io/volume_io.hpp>
#include <dm/math/voxelize.hpp>

#include <cctype>
#include <cstdint>
#include <iostream>
#include <memory>

#include "common.hpp"
#include "progress_bar.hpp"

namespace dmtool {
namespace {

struct VoxelizeCliOptions {
  std::string input;
  std::string output;
  double voxelSize = 0.0;
  bool sdf = false;
  double band = 0.0;
  int padding = 2;
  std::string unit = "m";
  bool json = false;
};

bool isVdb(const std::string& file) {
  std::string ext = std::filesystem::path(file).extension().string();
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return ext == ".vdb";
}

int runVoxelize(const VoxelizeCliOptions& o) {
  const std::filesystem::path in = resolveInput(o.input);
  dm::MeshImportOptions import;
  import.unit = o.unit;
  auto mesh = dm::readMesh(in, import);
  if (!mesh) return printError(mesh.error());
  dm::VoxelizeOptions opt;
  opt.voxelSize = o.voxelSize;
  opt.paddingVoxels = o.padding;
  opt.signedDistance = o.sdf;
  opt.bandWidth = o.band;
  ProgressBar bar("voxelize");
  opt.progress = bar.callback();
  auto v = dm::voxelizeMesh(*mesh, opt);
  bar.finish();
  if (!v) return printError(v.error().within(in.string()));

  dm::Status written = dm::ok();
  if (isVdb(o.output)) {
    dm::VdbWriteOptions w;
    w.levelSet = o.sdf;
    w.gridName = o.sdf ? "surface" : "density";
    written = dm::writeVdb(*v, o.output, w);
  } else {
    written = dm::writeVolume(*v, o.output);
  }
  if (!written) return printError(written.error());

  const dm::Vec3i d = v->dims();
  const auto [lo, hi] = v->range();
  std::size_t inside = 0;
  if (v->type() == dm::VoxelType::U8) {
    const std::uint8_t* p = v->data<std::uint8_t>();
    const std::size_t n =
        static_cast<std::size_t>(d.x()) * static_cast<std::size_t>(d.y()) * static_cast<std::size_t>(d.z());
    for (std::size_t i = 0; i < n; ++i) inside += p[i] != 0;
  } else {
    const float* p = v->data<float>();
    const std::size_t n =
        static_cast<std::size_t>(d.x()) * static_cast<std::size_t>(d.y()) * static_cast<std::size_t>(d.z());
    for (std::size_t i = 0; i < n; ++i) inside += p[i] < 0.0f;
  }
  const double h3 = o.voxelSize * o.voxelSize * o.voxelSize;
  if (o.json) {
    nlohmann::json j;
    j["file"] = o.output;
    j["dims"] = {d.x(), d.y(), d.z()};
    j["spacing"] = toJson(v->spacing());
    j["datatype"] = dm::toString(v->type());
    j["range"] = {lo, hi};
    j["insideVoxels"] = inside;
    j["insideVolume"] = static_cast<double>(inside) * h3;
    j["origin"] = toJson(v->indexToWorld().translation());
    printJson(j);
  } else {
    std::cout << o.output << ": " << d.x() << " x " << d.y() << " x " << d.z() << " voxels of " << o.voxelSize
              << " m, " << dm::toString(v->type()) << (o.sdf ? " signed distance (m)" : " occupancy") << '\n'
              << "  inside     " << inside << " voxels, " << static_cast<double>(inside) * h3 << " m^3\n"
              << "  range      " << lo << " .. " << hi << '\n';
  }
  return kExitOk;
}

}  // namespace

Command addVoxelizeCommand(CLI::App& parent) {
  auto o = std::make_shared<VoxelizeCliOptions>();
  CLI::App* app = parent.add_subcommand(
      "voxelize", "Turn a closed mesh into an occupancy (U8) or signed distance (F32, m) volume");
  app->add_option("mesh", o->input, "closed mesh file (any format Assimp reads)")->required();
  app->add_option("--voxel-size", o->voxelSize, "m, edge of the cubic voxels")
      ->required()
      ->check(CLI::PositiveNumber & finiteNumber());
  app->add_option("-o,--output", o->output, "volume file: .nii.gz, .nii, .mha, .mhd, .nrrd or .vdb")
      ->required();
  app->add_flag("--sdf", o->sdf, "signed distance in metres (negative inside) instead of occupancy");
  app->add_option("--band", o->band, "m; with --sdf, exact distance only within this band (0: everywhere)")
      ->check(CLI::NonNegativeNumber & finiteNumber());
  app->add_option("--padding", o->padding, "empty voxels around the mesh bounds")
      ->check(CLI::NonNegativeNumber);
  app->add_option("--unit", o->unit, "length unit of the mesh file: m, cm, mm, um, inch, ft")
      ->check(CLI::IsMember({"m", "cm", "mm", "um", "inch", "in", "ft"}));
  app->add_flag("--json", o->json, "print one JSON object on stdout");
  return {app, [o] { return runVoxelize(*o); }};
}

}  // namespace dmtool
