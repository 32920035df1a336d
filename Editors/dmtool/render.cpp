// dmtool render SCENE.json -o OUT.png [--size WxH] [--camera NAME] [--time S]
//   [--samples N] [--platform auto|device|surfaceless] [--json]
// dmtool render --list-devices
// Renders a scene file (docs/scene-format.md) headless through EGL: loads its
// resources, uploads them (dm::SceneView) and draws one camera at one time
// into an off-screen target, then writes the PNG. --list-devices prints the
// EGL devices this machine offers (for DM_EGL_DEVICE).
#include <dm/io/image_io.hpp>
#include <dm/io/scene_file.hpp>
#include <dm/io/scene_resources.hpp>
#include <dm/renderer/context.hpp>
#include <dm/renderer/render_target.hpp>
#include <dm/renderer/scene_view.hpp>

#include <chrono>
#include <cstdio>
#include <iostream>

#include "common.hpp"

namespace dmtool {
namespace {

struct RenderCliOptions {
  std::string scene;
  std::string output;
  std::string size;
  std::string camera;
  double time = 0;
  int samples = 0;  // 0: the scene's render engine setting, else 4
  std::string platform = "auto";
  bool listDevices = false;
  bool json = false;
};

double msSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

int listDevices() {
  nlohmann::json out = nlohmann::json::array();
  for (const dm::EglDeviceInfo& d : dm::listEglDevices())
    out.push_back({{"index", d.index},
                   {"software", d.software},
                   {"drm_node", d.drmNode},
                   {"extensions", d.extensions}});
  printJson(out);
  return kExitOk;
}

int runRender(const RenderCliOptions& o) {
  if (o.listDevices) return listDevices();
  if (o.scene.empty() || o.output.empty()) {
    std::cerr << "dmtool render: give SCENE.json and -o OUT.png (or --list-devices)\n";
    return kExitUsage;
  }
  const auto t0 = std::chrono::steady_clock::now();
  std::vector<dm::Error> problems;
  auto scene = dm::readScene(resolveInput(o.scene), &problems);
  if (!scene) {
    if (problems.size() > 1) std::cerr << dm::formatSceneErrors(problems);
    return printError(scene.error());
  }
  int width = 640, height = 480, samples = 4;
  if (scene->engines.render) {
    width = scene->engines.render->width;
    height = scene->engines.render->height;
    samples = scene->engines.render->samples;
  }
  if (!o.size.empty()) {
    char tail = 0;
    if (std::sscanf(o.size.c_str(), "%dx%d%c", &width, &height, &tail) != 2 || width < 1 || height < 1 ||
        width > 16384 || height > 16384) {
      std::cerr << "dmtool render: --size is \"" << o.size << "\"; give WIDTHxHEIGHT, e.g. 1280x720\n";
      return kExitUsage;
    }
  }
  if (o.samples > 0) samples = o.samples;
  auto resources = dm::loadSceneResources(*scene);
  if (!resources) return printError(resources.error().within(o.scene));
  const double loadMs = msSince(t0);

  auto platform = dm::parseEglPlatform(o.platform);
  if (!platform) return printError(platform.error());
  auto ctx = dm::GlContext::create({.platform = *platform, .ignoreEnvironment = o.platform != "auto"});
  if (!ctx) return printError(ctx.error());
  auto view = dm::SceneView::create(*scene, *resources);
  if (!view) return printError(view.error().within(o.scene));
  auto target = dm::RenderTarget::create({.width = width, .height = height, .samples = samples});
  if (!target) return printError(target.error());
  const auto t1 = std::chrono::steady_clock::now();
  auto stats = view->render(*target, o.camera, o.time);
  if (!stats) return printError(stats.error().within(o.scene));
  auto image = target->readColor();
  if (!image) return printError(image.error());
  const double renderMs = msSince(t1);
  if (auto s = dm::writePng(*image, o.output); !s) return printError(s.error());
  if (o.json) {
    const dm::ContextInfo& info = (*ctx)->info();
    printJson({{"output", o.output},
               {"width", width},
               {"height", height},
               {"samples", target->samples()},
               {"camera", o.camera},
               {"time", o.time},
               {"gl_renderer", info.glRenderer},
               {"egl_platform", dm::toString(info.platform)},
               {"triangles", stats->meshes.triangles},
               {"draw_calls", stats->meshes.drawCalls},
               {"volumes", stats->volumes},
               {"load_ms", loadMs},
               {"render_ms", renderMs}});
  } else {
    std::printf("wrote %s (%dx%d, %zu triangles, %d volumes) in %.0f ms + %.0f ms loading, on %s\n",
                o.output.c_str(), width, height, stats->meshes.triangles, stats->volumes, renderMs, loadMs,
                (*ctx)->info().glRenderer.c_str());
  }
  return kExitOk;
}

}  // namespace

Command addRenderCommand(CLI::App& parent) {
  auto o = std::make_shared<RenderCliOptions>();
  CLI::App* app = parent.add_subcommand("render", "Render a scene file headless (EGL) to a PNG");
  app->add_option("scene", o->scene, "scene file (docs/scene-format.md)");
  app->add_option("-o,--output", o->output, "PNG to write");
  app->add_option("--size", o->size, "WIDTHxHEIGHT (default: the scene's render engine, else 640x480)");
  app->add_option("--camera", o->camera, "camera name (default: the scene's first camera)");
  app->add_option("--time", o->time, "scene time, s (camera paths)")->check(CLI::Range(0.0, 1e9));
  app->add_option("--samples", o->samples, "MSAA samples (default: the scene's, else 4)")
      ->check(CLI::Range(1, 16));
  app->add_option("--platform", o->platform, "EGL platform: auto, device or surfaceless")
      ->check(CLI::IsMember({"auto", "device", "surfaceless"}));
  app->add_flag("--list-devices", o->listDevices, "print the EGL devices as JSON and exit");
  app->add_flag("--json", o->json, "print one JSON summary on stdout");
  return {app, [o] { return runRender(*o); }};
}

}  // namespace dmtool
