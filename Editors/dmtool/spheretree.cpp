// dmtool spheretree MODEL --levels L [--method octree|fitted] [--solid]
// [--threshold T] -o tree.json [--json]: the sphere tree of a mesh (any
// format dm::readMesh reads) or of a voxel model (any volume dm::readVolume
// reads; occupied where value > threshold), written as JSON:
//   {"source": "...", "kind": "mesh"|"volume", "method": "octree"|"fitted",
//    "solid": bool, "units": "m", "referenceVolume": m³,
//    "levels": [{"level": 0, "count": 1, "tightness": t, "maxRadius": m,
//                "spheres": [[x, y, z, r], ...]}, ...]}
// Tightness = Σ sphere volumes of the level / reference volume (the mesh's
// enclosed volume, the occupied voxel volume, or the root sphere's volume for
// an open mesh); see dm/collide/sphere_tree.hpp.
#include <dm/collide/sphere_tree.hpp>
#include <dm/core/filesystem.hpp>
#include <dm/io/mesh_io.hpp>
#include <dm/io/resources.hpp>
#include <dm/io/volume_io.hpp>

#include <cstdio>
#include <iostream>
#include <memory>

#include "common.hpp"

namespace dmtool {
namespace {

struct SpheretreeCliOptions {
  std::string input;
  std::string output;
  int levels = 4;
  std::string method = "octree";
  bool solid = false;
  double threshold = 0.0;
  std::string unit = "m";
  bool json = false;
};

nlohmann::json levelJson(const dm::SphereTree& tree, const dm::SphereTreeLevelStats& s, bool withSpheres) {
  nlohmann::json j;
  j["level"] = s.level;
  j["count"] = s.count;
  j["tightness"] = s.tightness;
  j["maxRadius"] = s.maxRadius;
  j["meanRadius"] = s.meanRadius;
  if (withSpheres) {
    nlohmann::json spheres = nlohmann::json::array();
    for (const dm::SphereTreeNode& n : tree.level(s.level))
      spheres.push_back({n.center.x(), n.center.y(), n.center.z(), n.radius});
    j["spheres"] = std::move(spheres);
  }
  return j;
}

int runSpheretree(const SpheretreeCliOptions& o) {
  const std::filesystem::path in = resolveInput(o.input);
  dm::SphereTreeOptions opt;
  opt.levels = o.levels;
  opt.solid = o.solid;
  opt.threshold = o.threshold;
  const bool fitted = o.method == "fitted";
  const bool volumeIn = dm::isVolumePath(in);
  dm::Result<std::shared_ptr<const dm::SphereTree>> tree = dm::fail(dm::ErrorCode::Internal, "not built");
  if (volumeIn) {
    auto v = dm::readVolume(in);
    if (!v) return printError(v.error());  // names the file
    tree = fitted ? dm::buildSphereTreeFitted(*v, opt) : dm::buildSphereTreeOctree(*v, opt);
  } else {
    dm::MeshImportOptions import;
    import.unit = o.unit;
    auto mesh = dm::readMesh(in, import);
    if (!mesh) return printError(mesh.error());  // names the file
    tree = fitted ? dm::buildSphereTreeFitted(*mesh, opt) : dm::buildSphereTreeOctree(*mesh, opt);
  }
  if (!tree) return printError(tree.error().within(in.string()));
  const dm::SphereTree& t = **tree;
  const std::vector<dm::SphereTreeLevelStats> stats = t.levelStats();

  nlohmann::json doc;
  doc["source"] = in.string();
  doc["kind"] = volumeIn ? "volume" : "mesh";
  doc["method"] = dm::toString(t.method());
  doc["solid"] = o.solid;
  doc["units"] = "m";
  doc["referenceVolume"] = t.referenceVolume();
  doc["levels"] = nlohmann::json::array();
  for (const dm::SphereTreeLevelStats& s : stats) doc["levels"].push_back(levelJson(t, s, true));
  const std::string text = doc.dump();
  if (dm::Status s = dm::writeFileAtomic(o.output, text.data(), text.size()); !s)
    return printError(s.error().within(o.output));

  if (o.json) {
    nlohmann::json j;
    j["file"] = o.output;
    j["source"] = in.string();
    j["method"] = dm::toString(t.method());
    j["referenceVolume"] = t.referenceVolume();
    j["levels"] = nlohmann::json::array();
    for (const dm::SphereTreeLevelStats& s : stats) j["levels"].push_back(levelJson(t, s, false));
    printJson(j);
    return kExitOk;
  }
  std::cout << o.output << ": " << dm::toString(t.method()) << " sphere tree of " << in.string() << ", "
            << stats.size() << " levels, reference volume " << t.referenceVolume() << " m^3\n";
  for (const dm::SphereTreeLevelStats& s : stats) {
    char line[160];
    std::snprintf(line, sizeof line, "  level %2d  %8zu spheres  tightness %8.4f  max radius %.6g m\n",
                  s.level, s.count, s.tightness, s.maxRadius);
    std::cout << line;
  }
  return kExitOk;
}

}  // namespace

Command addSpheretreeCommand(CLI::App& parent) {
  auto o = std::make_shared<SpheretreeCliOptions>();
  CLI::App* app = parent.add_subcommand(
      "spheretree",
      "Build the sphere tree of a mesh or voxel model and write it as JSON (spheres per level, m)");
  app->add_option("model", o->input,
                  "mesh (any format Assimp reads) or volume (.nii, .nii.gz, .mha, .nrrd, ...)")
      ->required();
  app->add_option("--levels", o->levels, "levels including the root, 1..10")->check(CLI::Range(1, 10));
  app->add_option("--method", o->method, "octree (cells of the bounds) or fitted (k-means clusters, tighter)")
      ->check(CLI::IsMember({"octree", "fitted"}));
  app->add_flag("--solid", o->solid, "cover the enclosed solid (closed meshes) or every occupied voxel");
  app->add_option("--threshold", o->threshold, "volumes: a voxel is occupied where value > threshold")
      ->check(finiteNumber());
  app->add_option("-o,--output", o->output, "JSON file to write")->required();
  app->add_option("--unit", o->unit, "length unit of the mesh file: m, cm, mm, um, inch, ft")
      ->check(CLI::IsMember({"m", "cm", "mm", "um", "inch", "in", "ft"}));
  app->add_flag("--json", o->json, "print one JSON object on stdout (per level count, tightness, radii)");
  return {app, [o] { return runSpheretree(*o); }};
}

}  // namespace dmtool
