// dmtool phantom calvarium -o VOLUME [--spacing M] [--half-width M]
// [--above M] [--below M] [--radius M] [--texture-hu HU] [--seed N]
// [--json]: writes the CT-like calvarium phantom (dm/math/phantom.hpp,
// docs/phantoms.md) as int16 Hounsfield units in NIfTI, MetaImage or NRRD,
// for other CT tools or for a scene's volume "source".
#include <dm/io/volume_io.hpp>
#include <dm/math/phantom.hpp>

#include <iostream>
#include <memory>

#include "common.hpp"

namespace dmtool {
namespace {

struct PhantomCliOptions {
  std::string kind;
  std::string output;
  dm::CalvariumPhantom phantom;
  bool json = false;
};

int runPhantom(const PhantomCliOptions& o) {
  auto v = dm::makeCalvariumPhantom(o.phantom);
  if (!v) return printError(v.error().within("calvarium"));
  if (auto s = dm::writeVolume(*v, o.output); !s) return printError(s.error());
  const dm::Vec3i d = v->dims();
  const auto [lo, hi] = v->range();
  if (o.json) {
    nlohmann::json j;
    j["file"] = o.output;
    j["kind"] = o.kind;
    j["dims"] = {d.x(), d.y(), d.z()};
    j["spacing"] = toJson(v->spacing());
    j["origin"] = toJson(v->indexToWorld().translation());
    j["datatype"] = dm::toString(v->type());
    j["range"] = {lo, hi};
    printJson(j);
  } else {
    std::cout << o.output << ": " << o.kind << " phantom, " << d.x() << " x " << d.y() << " x " << d.z()
              << " voxels of " << o.phantom.spacing << " m, " << dm::toString(v->type()) << " HU " << lo
              << " .. " << hi << '\n';
  }
  return kExitOk;
}

}  // namespace

Command addPhantomCommand(CLI::App& parent) {
  auto o = std::make_shared<PhantomCliOptions>();
  CLI::App* app = parent.add_subcommand(
      "phantom",
      "Write a CT-like phantom in Hounsfield units (docs/phantoms.md): the calvarium of an adult skull");
  app->add_option("kind", o->kind, "which phantom: calvarium")
      ->required()
      ->check(CLI::IsMember({"calvarium"}));
  app->add_option("-o,--output", o->output, "volume file: .nii.gz, .nii, .mha, .mhd or .nrrd")->required();
  dm::CalvariumPhantom& p = o->phantom;
  const auto length = CLI::NonNegativeNumber & finiteNumber();
  app->add_option("--spacing", p.spacing, "m, voxel size")->check(CLI::PositiveNumber & finiteNumber());
  app->add_option("--half-width", p.halfWidth, "m, the scan covers |x|, |y| up to this")->check(length);
  app->add_option("--above", p.above, "m, how far the scan reaches above the vault's apex")->check(length);
  app->add_option("--below", p.below, "m, and below it")->check(length);
  app->add_option("--radius", p.radius, "m, the outer table's radius of curvature")->check(length);
  app->add_option("--texture-hu", p.textureHu, "HU, amplitude of the diploë's texture (0: uniform)")
      ->check(length);
  app->add_option("--seed", p.seed, "the texture's seed");
  app->add_flag("--json", o->json, "print one JSON object on stdout");
  return {app, [o] { return runPhantom(*o); }};
}

}  // namespace dmtool
