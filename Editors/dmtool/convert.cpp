// dmtool convert IN OUT [--scale S] [--unit U] [--ascii]: mesh to mesh or
// volume to volume, format chosen by OUT's extension.
#include <dm/io/mesh_io.hpp>
#include <dm/io/resources.hpp>
#include <dm/io/volume_io.hpp>

#include <iostream>
#include <memory>

#include "common.hpp"

namespace dmtool {
namespace {

struct ConvertOptions {
  std::string input;
  std::string output;
  double scale = 1.0;
  std::string unit = "m";
  bool ascii = false;
};

int convertMesh(const ConvertOptions& o, const std::filesystem::path& in) {
  dm::MeshImportOptions import;
  import.unit = o.unit;
  import.scale = o.scale;
  auto mesh = dm::readMesh(in, import);
  if (!mesh) return printError(mesh.error());
  if (auto s = dm::writeMesh(*mesh, o.output, {.binary = !o.ascii}); !s) return printError(s.error());
  std::cout << o.output << ": " << mesh->vertexCount() << " vertices, " << mesh->triangleCount()
            << " triangles\n";
  return kExitOk;
}

int convertVolume(const ConvertOptions& o, const std::filesystem::path& in) {
  auto v = dm::readVolume(in);
  if (!v) return printError(v.error());
  if (o.scale != 1.0) {
    // Scaling the world: voxel size and placement both grow by `scale`.
    const dm::Affine3 scaled = Eigen::Scaling(o.scale) * v->indexToWorld();
    if (auto s = v->setIndexToWorld(scaled); !s) return printError(s.error());
  }
  if (auto s = dm::writeVolume(*v, o.output); !s) return printError(s.error());
  const dm::Vec3i d = v->dims();
  std::cout << o.output << ": " << d.x() << " x " << d.y() << " x " << d.z() << " voxels, "
            << dm::toString(v->type()) << '\n';
  return kExitOk;
}

}  // namespace

Command addConvertCommand(CLI::App& parent) {
  auto o = std::make_shared<ConvertOptions>();
  CLI::App* app = parent.add_subcommand(
      "convert", "Convert a mesh to STL/PLY/OBJ, or a volume to NIfTI/MetaImage/NRRD (by OUT's extension)");
  app->add_option("input", o->input, "mesh or volume file")->required();
  app->add_option("output", o->output, "file to write; its extension picks the format")->required();
  app->add_option("--scale", o->scale, "factor applied to mesh positions or to the volume's index-to-world")
      ->check(CLI::PositiveNumber & finiteNumber());
  app->add_option("--unit", o->unit, "length unit of an input mesh: m, cm, mm, um, inch, ft")
      ->check(CLI::IsMember({"m", "cm", "mm", "um", "inch", "in", "ft"}));
  app->add_flag("--ascii", o->ascii, "write ASCII STL/PLY instead of binary");
  return {app, [o]() -> int {
            const std::filesystem::path in = resolveInput(o->input);
            const bool volumeIn = dm::isVolumePath(in);
            if (volumeIn != dm::isVolumePath(o->output))
              return printError(dm::fail(dm::ErrorCode::InvalidArgument,
                                         volumeIn ? "cannot convert a volume to a mesh file"
                                                  : "cannot convert a mesh to a volume file",
                                         o->output,
                                         volumeIn ? "use `dmtool isosurface` to extract a mesh from a volume"
                                                  : "use `dmtool voxelize` to turn a mesh into a volume"));
            return volumeIn ? convertVolume(*o, in) : convertMesh(*o, in);
          }};
}

}  // namespace dmtool
