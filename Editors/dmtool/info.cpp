// dmtool info FILE [--json] [--unit U]: what a mesh or volume file holds.
#include <dm/io/mesh_io.hpp>
#include <dm/io/resources.hpp>
#include <dm/io/volume_io.hpp>

#include <cstdio>
#include <iostream>
#include <memory>

#include "common.hpp"

namespace dmtool {
namespace {

struct InfoOptions {
  std::string file;
  bool json = false;
  std::string unit = "m";
};

int meshInfo(const InfoOptions& o, const std::filesystem::path& path) {
  dm::MeshImportOptions import;
  import.unit = o.unit;
  auto parts = dm::readMeshes(path, import);
  if (!parts) return printError(parts.error());

  std::vector<MeshSummary> summaries;
  summaries.reserve(parts->size());
  for (const dm::Mesh& p : *parts) summaries.push_back(summarize(p));
  // The totals analyse all parts as one mesh (parts stay unwelded to each
  // other, as readMeshes() returns them).
  MeshSummary total;
  if (parts->size() == 1) {
    total = summaries.front();
  } else {
    dm::Mesh all;
    for (const dm::Mesh& p : *parts) all.append(p);
    total = summarize(all);
  }
  total.name = path.filename().string();

  if (o.json) {
    nlohmann::json j;
    j["file"] = path.string();
    j["kind"] = "mesh";
    j["meshes"] = nlohmann::json::array();
    for (const MeshSummary& s : summaries) j["meshes"].push_back(toJson(s));
    j["total"] = toJson(total);
    printJson(j);
    return kExitOk;
  }
  std::cout << path.string() << ": mesh, " << summaries.size()
            << (summaries.size() == 1 ? " part\n" : " parts\n");
  if (summaries.size() > 1)
    for (const MeshSummary& s : summaries) std::cout << "part \"" << s.name << "\"\n" << toText(s);
  std::cout << "total\n" << toText(total);
  return kExitOk;
}

int volumeInfo(const InfoOptions& o, const std::filesystem::path& path) {
  auto v = dm::readVolume(path);
  if (!v) return printError(v.error());
  const dm::Vec3i d = v->dims();
  const dm::Vec3 spacing = v->spacing();
  const auto [lo, hi] = v->range();
  const Eigen::Matrix4d m = v->indexToWorld().matrix();
  if (o.json) {
    nlohmann::json j;
    j["file"] = path.string();
    j["kind"] = "volume";
    j["dims"] = {d.x(), d.y(), d.z()};
    j["spacing"] = toJson(spacing);
    j["datatype"] = dm::toString(v->type());
    j["range"] = {lo, hi};
    nlohmann::json rows = nlohmann::json::array();
    for (int r = 0; r < 4; ++r) rows.push_back({m(r, 0), m(r, 1), m(r, 2), m(r, 3)});
    j["indexToWorld"] = rows;
    printJson(j);
    return kExitOk;
  }
  std::printf(
      "%s: volume\n  dims       %d x %d x %d\n  spacing    [%.6g %.6g %.6g] m\n  datatype   %s\n"
      "  range      %.6g .. %.6g\n  index to world (m)\n",
      path.string().c_str(), d.x(), d.y(), d.z(), spacing.x(), spacing.y(), spacing.z(),
      dm::toString(v->type()), lo, hi);
  for (int r = 0; r < 4; ++r)
    std::printf("    %12.6g %12.6g %12.6g %12.6g\n", m(r, 0), m(r, 1), m(r, 2), m(r, 3));
  return kExitOk;
}

}  // namespace

Command addInfoCommand(CLI::App& parent) {
  auto o = std::make_shared<InfoOptions>();
  CLI::App* app = parent.add_subcommand(
      "info", "Print counts, bounds, topology and volume of a mesh, or dims, spacing and affine of a volume");
  app->add_option("file", o->file, "mesh (any format Assimp reads) or volume (NIfTI, MetaImage, NRRD, ...)")
      ->required();
  app->add_flag("--json", o->json, "print one JSON object on stdout");
  app->add_option("--unit", o->unit, "length unit of a mesh file: m, cm, mm, um, inch, ft")
      ->check(CLI::IsMember({"m", "cm", "mm", "um", "inch", "in", "ft"}));
  return {app, [o] {
            const std::filesystem::path path = resolveInput(o->file);
            return dm::isVolumePath(path) ? volumeInfo(*o, path) : meshInfo(*o, path);
          }};
}

}  // namespace dmtool
