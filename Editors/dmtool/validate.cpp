// dmtool validate SCENE.json [--load] [--json]
// Checks a scene file against docs/scene-format.md and prints every problem
// at once, each with its JSON path and a suggestion; --load also loads its
// resources (files, isosurfaces, shapes), which catches missing files and
// unusable iso levels. Exit 0 when valid, 1 when not.
#include <dm/io/scene_file.hpp>
#include <dm/io/scene_resources.hpp>

#include <iostream>

#include "common.hpp"

namespace dmtool {
namespace {

struct ValidateCliOptions {
  std::string scene;
  bool load = false;
  bool json = false;
};

int runValidate(const ValidateCliOptions& o) {
  std::vector<dm::Error> problems;
  auto scene = dm::readScene(resolveInput(o.scene), &problems);
  if (!scene) {
    if (o.json) {
      nlohmann::json list = nlohmann::json::array();
      for (const dm::Error& e : problems.empty() ? std::vector<dm::Error>{scene.error()} : problems)
        list.push_back({{"where", e.where}, {"what", e.what}, {"hint", e.hint}});
      printJson({{"valid", false}, {"problems", list}});
    } else {
      std::cerr << (problems.empty() ? scene.error().message() + "\n" : dm::formatSceneErrors(problems));
    }
    return kExitFailure;
  }
  if (o.load) {
    auto res = dm::loadSceneResources(*scene);
    if (!res) {
      if (o.json)
        printJson(
            {{"valid", false},
             {"problems",
              {{{"where", res.error().where}, {"what", res.error().what}, {"hint", res.error().hint}}}}});
      else
        printError(res.error().within(o.scene));
      return kExitFailure;
    }
  }
  if (o.json)
    printJson({{"valid", true},
               {"name", scene->name},
               {"resources", scene->resources.size()},
               {"objects", scene->objects.size()},
               {"volumes", scene->volumes.size()},
               {"cameras", scene->cameras.size()},
               {"devices", scene->devices.size()},
               {"loaded", o.load}});
  else
    std::cout << o.scene << ": valid (" << scene->resources.size() << " resources, " << scene->objects.size()
              << " objects, " << scene->cameras.size() << " cameras" << (o.load ? ", all resources load" : "")
              << ")\n";
  return kExitOk;
}

}  // namespace

Command addValidateCommand(CLI::App& parent) {
  auto o = std::make_shared<ValidateCliOptions>();
  CLI::App* app =
      parent.add_subcommand("validate", "Check a scene file and report every problem with its JSON path");
  app->add_option("scene", o->scene, "scene file (docs/scene-format.md)")->required();
  app->add_flag("--load", o->load, "also load every resource it names");
  app->add_flag("--json", o->json, "print one JSON result on stdout");
  return {app, [o] { return runValidate(*o); }};
}

}  // namespace dmtool
