// dmtool probe MODEL --path PATH.csv --renderer godobject|vps|spheretree|burr
//   [--stiffness N_per_m] [--damping Ns_per_m] [--friction MUS,MUD]
//   [--tool TOOL_MODEL] [--tool-radius M] [--rate HZ] [--threshold T]
//   [--voxel-size M] [--levels L] [--unit U] [--rpm RPM] [--bone-range EMPTY,FULL]
//   [--mesh-out MESH] -o OUT.csv [--plot OUT.png] [--json]
// Replays a device path (CSV t,x,y,z[,qw,qx,qy,qz], SI units; see
// dm/io/device_path.hpp) through a haptic renderer in lockstep
// (dm::replayDevicePath) and writes t, force, torque and proxy pose per tick
// (dm::formatProbeCsv); --plot draws the force trace.
//
// The environment is MODEL at the identity pose: a mesh (any format
// dm::readMesh reads) or a volume (dm::readVolume; solid where value >
// threshold (default 0); vps also takes a signed distance volume, negative
// inside, when --threshold is not given). The tool: godobject uses a point proxy, or a
// ball tip of --tool-radius; vps samples TOOL_MODEL (or a ball of
// --tool-radius, default 2 mm) into a point shell; spheretree builds the
// tool's sphere tree the same way. burr drills a volume with a sphere burr of
// --tool-radius (default 2 mm) at --rpm (dm::BurrRenderer): the volume is
// the bone's signed distance (negative inside), or with --bone-range the
// intensities of empty space and of full bone (partial volume between);
// --mesh-out writes the drilled bone's surface and the summary gives the
// volume removed. --rpm, --bone-range and --mesh-out belong to burr alone.
#include <dm/core/filesystem.hpp>
#include <dm/haptics/burr.hpp>
#include <dm/haptics/force_plot.hpp>
#include <dm/haptics/probe.hpp>
#include <dm/haptics/probe_renderers.hpp>
#include <dm/io/device_path.hpp>
#include <dm/io/image_io.hpp>
#include <dm/io/mesh_io.hpp>
#include <dm/io/resources.hpp>
#include <dm/io/volume_io.hpp>
#include <dm/math/isosurface.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <limits>
#include <memory>
#include <optional>

#include "common.hpp"

namespace dmtool {
namespace {

struct ProbeCliOptions {
  std::string model;
  std::string path;
  std::string renderer = "godobject";
  double stiffness = 1000.0;
  double damping = 0.0;
  std::vector<double> friction;  // μs, μd
  std::string tool;
  double toolRadius = 0.0;  // 0: per renderer default
  double rate = 1000.0;
  std::optional<double> threshold;
  double voxelSize = 0.0;  // 0: 1/128 of the model's largest extent
  int levels = 6;
  int toolLevel = 4;
  std::string unit = "m";
  std::string output;
  std::string plot;
  bool json = false;
  std::optional<double> rpm;      // burr
  std::vector<double> boneRange;  // burr: empty, full intensity
  std::string meshOut;            // burr
};

// The environment as the renderer needs it: a mesh for godobject, a voxel
// model for vps, a sphere tree for spheretree.
struct Environment {
  std::optional<dm::Mesh> mesh;
  std::optional<dm::Volume> volume;
};

dm::Result<Environment> loadModel(const std::filesystem::path& in, const ProbeCliOptions& o) {
  Environment env;
  if (dm::isVolumePath(in)) {
    auto v = dm::readVolume(in);
    if (!v) return v.error();
    env.volume = std::move(*v);
  } else {
    dm::MeshImportOptions import;
    import.unit = o.unit;
    auto m = dm::readMesh(in, import);
    if (!m) return m.error();
    env.mesh = std::move(*m);
  }
  return env;
}

dm::HapticMaterial material(const ProbeCliOptions& o) {
  dm::HapticMaterial m;
  m.stiffness = o.stiffness;
  m.damping = o.damping;
  if (o.friction.size() == 2) {
    m.staticFriction = o.friction[0];
    m.dynamicFriction = o.friction[1];
  }
  return m;
}

// The renderer --renderer names, built as dm/haptics/probe_renderers.hpp
// says (Python's dmplatform builds the same).
dm::Result<std::unique_ptr<dm::HapticRenderer>> makeRenderer(const Environment& env, const ProbeCliOptions& o,
                                                             std::shared_ptr<dm::MillableVolume>& bone) {
  if (o.renderer == "burr")
    for (auto [given, option] :
         {std::pair{!o.friction.empty(), "--friction"}, std::pair{!o.tool.empty(), "--tool"},
          std::pair{o.threshold.has_value(), "--threshold"}})
      if (given)
        return dm::fail(dm::ErrorCode::InvalidArgument, std::string(option) + " does not apply to burr", option,
                        "burr takes a sphere of --tool-radius, and --bone-range for intensity volumes");
  std::optional<dm::Mesh> tool;
  if (!o.tool.empty()) {
    dm::MeshImportOptions import;
    import.unit = o.unit;
    auto t = dm::readMesh(resolveInput(o.tool), import);
    if (!t) return t.error().within("--tool");
    tool = std::move(*t);
  }
  dm::ProbeRendererOptions options;
  options.material = material(o);
  options.threshold = o.threshold;
  options.toolRadius = o.toolRadius;
  options.tool = tool ? &*tool : nullptr;
  options.voxelSize = o.voxelSize;
  options.levels = o.levels;
  options.toolLevel = o.toolLevel;
  options.rpm = o.rpm;
  if (o.boneRange.size() == 2) options.boneRange = std::array<double, 2>{o.boneRange[0], o.boneRange[1]};
  const dm::ProbeEnvironment model{.mesh = env.mesh ? &*env.mesh : nullptr,
                                   .volume = env.volume ? &*env.volume : nullptr};
  if (o.renderer == "vps") return dm::makeVpsProbe(model, options);
  if (o.renderer == "spheretree") return dm::makeSphereTreeProbe(model, options);
  if (o.renderer == "burr") return dm::makeBurrProbe(model, options, bone);
  if (env.volume && !o.threshold)
    return dm::fail(dm::ErrorCode::InvalidArgument, "godobject on a volume needs --threshold", "--threshold",
                    "give the value above which a voxel is solid, e.g. --threshold 300 for bone in CT");
  return dm::makeGodObjectProbe(model, options);
}

int runProbe(const ProbeCliOptions& o) {
  if (o.renderer != "burr")
    for (auto [given, option] :
         {std::pair{o.rpm.has_value(), "--rpm"}, std::pair{!o.boneRange.empty(), "--bone-range"},
          std::pair{!o.meshOut.empty(), "--mesh-out"}})
      if (given)
        return printError(dm::fail(dm::ErrorCode::InvalidArgument,
                                   std::string(option) + " applies to --renderer burr only", option));
  if (!o.boneRange.empty() && o.boneRange.size() != 2)
    return printError(
        dm::fail(dm::ErrorCode::InvalidArgument, "--bone-range takes two values EMPTY,FULL", "--bone-range"));
  if (!o.friction.empty() && o.friction.size() != 2)
    return printError(
        dm::fail(dm::ErrorCode::InvalidArgument, "--friction takes two values MUS,MUD", "--friction"));
  if (dm::Status s = material(o).validate("--stiffness/--damping/--friction"); !s)
    return printError(s.error());

  auto path = dm::readDevicePathCsv(resolveInput(o.path));
  if (!path) return printError(path.error());
  const std::filesystem::path in = resolveInput(o.model);
  auto env = loadModel(in, o);
  if (!env) return printError(env.error());

  std::shared_ptr<dm::MillableVolume> bone;
  auto renderer = makeRenderer(*env, o, bone);
  if (!renderer) return printError(renderer.error().within(in.string()));

  auto samples = dm::replayDevicePath(**renderer, *path, o.rate);
  if (!samples) return printError(samples.error().within(o.path));
  const std::string csv = dm::formatProbeCsv(*samples);
  if (dm::Status s = dm::writeFileAtomic(o.output, csv.data(), csv.size()); !s)
    return printError(s.error().within(o.output));
  if (!o.meshOut.empty()) {
    auto occupancy = bone->occupancyVolume();
    if (!occupancy) return printError(occupancy.error());
    auto surface = dm::extractIsosurface(*occupancy, {.iso = 0.5, .closeBorders = true});
    if (!surface) return printError(surface.error());
    if (dm::Status s = dm::writeMesh(*surface, o.meshOut); !s) return printError(s.error().within(o.meshOut));
  }
  if (!o.plot.empty()) {
    auto image = dm::plotForceTrace(*samples);
    if (!image) return printError(image.error());
    if (dm::Status s = dm::writePng(*image, o.plot); !s) return printError(s.error().within(o.plot));
  }

  double maxForce = 0.0, maxPenetration = 0.0;
  std::size_t contactTicks = 0;
  for (const dm::ProbeSample& s : *samples) {
    maxForce = std::max(maxForce, s.response.force.norm());
    maxPenetration = std::max(maxPenetration, s.response.penetration);
    contactTicks += s.response.contacts > 0;
  }
  if (o.json) {
    nlohmann::json j;
    j["file"] = o.output;
    j["renderer"] = std::string((*renderer)->name());
    j["ticks"] = samples->size();
    j["contactTicks"] = contactTicks;
    j["maxForce"] = maxForce;
    j["maxPenetration"] = maxPenetration;
    if (!o.plot.empty()) j["plot"] = o.plot;
    if (bone) j["removedVolume"] = bone->removedVolume(0);
    if (!o.meshOut.empty()) j["mesh"] = o.meshOut;
    printJson(j);
    return kExitOk;
  }
  char line[256];
  std::snprintf(line, sizeof line,
                "%s: %zu ticks of %s at %g Hz, %zu in contact, max force %.6g N, max depth %.6g m\n",
                o.output.c_str(), samples->size(), std::string((*renderer)->name()).c_str(), o.rate,
                contactTicks, maxForce, maxPenetration);
  std::cout << line;
  return kExitOk;
}

}  // namespace

Command addProbeCommand(CLI::App& parent) {
  auto o = std::make_shared<ProbeCliOptions>();
  CLI::App* app = parent.add_subcommand("probe",
                                        "Replay a device path through a haptic renderer in lockstep and "
                                        "write force, torque and proxy per tick");
  app->add_option("model", o->model,
                  "environment: mesh (any format Assimp reads) or volume (.nii, .nrrd, ...)")
      ->required();
  app->add_option("--path", o->path, "device path CSV: t,x,y,z[,qw,qx,qy,qz] in s and m")->required();
  app->add_option(
         "--renderer", o->renderer,
         "godobject (3-DOF proxy), vps (voxel point shell), spheretree (6-DOF) or burr (drills a volume)")
      ->check(CLI::IsMember({"godobject", "vps", "spheretree", "burr"}));
  app->add_option("--stiffness", o->stiffness, "surface stiffness, N/m")->check(finiteNumber());
  app->add_option("--damping", o->damping, "surface damping, N*s/m")->check(finiteNumber());
  app->add_option("--friction", o->friction, "static and dynamic friction coefficients MUS,MUD")
      ->delimiter(',')
      ->expected(2)
      ->check(finiteNumber());
  app->add_option("--tool", o->tool, "tool mesh for vps and spheretree (default: a ball of --tool-radius)");
  app->add_option("--tool-radius", o->toolRadius,
                  "m: godobject ball tip (0 = point), default tool ball (2 mm)")
      ->check(CLI::Range(0.0, 1.0));
  app->add_option("--rate", o->rate, "tick rate, Hz")->check(CLI::Range(1.0, 1e6));
  app->add_option("--threshold", o->threshold,
                  "volumes: solid where value > threshold (default: the volume is an SDF)")
      ->check(finiteNumber());
  app->add_option("--voxel-size", o->voxelSize,
                  "vps on a mesh: voxel size, m (default: largest extent / 128)")
      ->check(CLI::Range(0.0, 1.0));
  app->add_option("--levels", o->levels, "spheretree: levels of the environment tree")
      ->check(CLI::Range(2, 10));
  app->add_option("--tool-level", o->toolLevel, "spheretree: tool tree level that collides")
      ->check(CLI::Range(1, 8));
  app->add_option("--unit", o->unit, "length unit of mesh files: m, cm, mm, um, inch, ft")
      ->check(CLI::IsMember({"m", "cm", "mm", "um", "inch", "in", "ft"}));
  app->add_option("-o,--output", o->output,
                  "CSV to write: t,fx,fy,fz,tx,ty,tz,px,py,pz,qw,qx,qy,qz,contacts,penetration")
      ->required();
  app->add_option("--plot", o->plot, "PNG of the force trace");
  app->add_flag("--json", o->json, "print one JSON summary on stdout");
  app->add_option("--rpm", o->rpm, "burr: speed, revolutions per minute (default 80000)")
      ->check(CLI::Range(0.0, 1e6));
  app->add_option(
         "--bone-range", o->boneRange,
         "burr on CT/MRI: intensities of empty space and of full bone EMPTY,FULL (partial volume between)")
      ->delimiter(',')
      ->expected(2)
      ->check(finiteNumber());
  app->add_option("--mesh-out", o->meshOut,
                  "burr: write the drilled bone's surface (any format writeMesh writes)");
  return {app, [o] { return runProbe(*o); }};
}

}  // namespace dmtool
