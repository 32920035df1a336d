// scene_segmentation.cpp — the scene file's segmentation engine
// ("engines"/"segmentation"): the volume it paints, where the window is
// taken, the growth's and the guidance's settings; its checks against the
// resources and the haptics engine, and its JSON (docs/scene-format.md,
// "Segmentation").
#include "scene_parse.hpp"

namespace dm::scene_parse {

void readSegmentation(ConfigReader& engines, SceneEngines& e) {
  ConfigReader r = engines.child("segmentation");
  if (!expectObject(r)) return;
  r.knownKeys({"rate_hz", "volume", "seed", "window", "window_k", "connectivity", "min_radius", "max_radius",
               "edge_sigma", "edge_threshold", "rays", "gain", "max_force", "guidance", "reference"});
  SceneSegmentationEngine g;
  g.rateHz = r.number("rate_hz", {.min = 1.0, .max = 1000.0}, g.rateHz);
  g.volume = r.string("volume");
  g.seed = readVec3(r, "seed");
  if (r.has("window") && r.has("window_k"))
    r.addError("both \"window\" and \"window_k\" are given", "window_k",
               "give the intensities, or the standard deviations around the seed's mean, not both");
  if (r.has("window")) {
    ConfigReader w = r.child("window");
    const Json& node = w.node();
    if (!node.is_array() || node.size() != 2 || !node[0].is_number() || !node[1].is_number()) {
      r.addError("expected [lower, upper] intensities", "window", "e.g. [90, 140]");
    } else {
      const std::array<double, 2> lu{node[0].get<double>(), node[1].get<double>()};
      if (!std::isfinite(lu[0]) || !std::isfinite(lu[1]) || lu[0] > lu[1])
        r.addError(formatString("window [%g, %g] is not lower <= upper", lu[0], lu[1]), "window");
      else
        g.window = lu;
    }
  }
  g.windowK = r.number("window_k", {.min = 0.1, .max = 10.0}, g.windowK);
  const std::size_t before = r.errors().size();
  g.connectivity = static_cast<int>(r.integer("connectivity", {.min = 6, .max = 26}, g.connectivity));
  if (r.errors().size() == before && g.connectivity != 6 && g.connectivity != 18 && g.connectivity != 26)
    r.addError("connectivity " + std::to_string(g.connectivity) + " is not 6, 18 or 26", "connectivity");
  g.minRadius = r.number("min_radius", {.min = 1e-5, .max = 0.1}, g.minRadius);
  const std::size_t beforeMax = r.errors().size();
  g.maxRadius = r.number("max_radius", {.min = 1e-5, .max = 0.2}, g.maxRadius);
  if (r.errors().size() == beforeMax && g.maxRadius < g.minRadius)
    r.addError(formatString("max_radius %g m is below min_radius %g m", g.maxRadius, g.minRadius),
               "max_radius");
  g.edgeSigma = r.number("edge_sigma", {.min = 0.0, .max = 0.05}, g.edgeSigma);
  const std::size_t beforeThreshold = r.errors().size();
  g.edgeThreshold = r.number("edge_threshold", {.min = 0.0, .max = 1.0}, g.edgeThreshold);
  if (r.errors().size() == beforeThreshold && !(g.edgeThreshold > 0.0))
    r.addError("edge_threshold must be above 0", "edge_threshold", "e.g. 0.25");
  g.rays = static_cast<int>(r.integer("rays", {.min = 6, .max = 4096}, g.rays));
  g.gain = r.number("gain", {.min = 0.0, .max = 1e3}, g.gain);
  g.maxForce = r.number("max_force", {.min = 0.0, .max = 100.0}, g.maxForce);
  g.guidance = r.boolean("guidance", g.guidance);
  if (r.has("reference")) {
    ConfigReader ref = r.child("reference");
    if (expectObject(ref)) {
      ref.knownKeys({"k"});
      g.referenceK = ref.number("k", {.min = 0.1, .max = 10.0}, 2.5);
    }
  }
  e.segmentation = std::move(g);
}

void checkSegmentation(const SceneDesc& scene, ConfigReader root) {
  const auto& g = scene.engines.segmentation;
  if (!g) return;
  ConfigReader r = root.child("engines").child("segmentation");
  if (!g->volume.empty()) {
    const SceneResource* res = scene.resource(g->volume);
    if (res == nullptr || res->type != SceneResource::Type::Volume)
      r.addError("resource " + inQuotes(g->volume) + (res ? " is not a volume" : " is not defined"), "volume",
                 "name a \"volume\" resource (the image to segment)");
  }
  if (!scene.engines.haptics)
    r.addError("the segmentation paints at the haptic tool, and there is no haptics engine", {},
               "add \"haptics\" under \"engines\" (\"renderer\": \"none\" for a tool in free space)");
}

void writeSegmentation(const SceneSegmentationEngine& g, Json& engines) {
  Json j = {{"rate_hz", g.rateHz},
            {"volume", g.volume},
            {"seed", toJson(g.seed)},
            {"connectivity", g.connectivity},
            {"min_radius", g.minRadius},
            {"max_radius", g.maxRadius},
            {"edge_sigma", g.edgeSigma},
            {"edge_threshold", g.edgeThreshold},
            {"rays", g.rays},
            {"gain", g.gain},
            {"max_force", g.maxForce},
            {"guidance", g.guidance}};
  if (g.window)
    j["window"] = Json::array({(*g.window)[0], (*g.window)[1]});
  else
    j["window_k"] = g.windowK;
  if (g.referenceK) j["reference"] = {{"k", *g.referenceK}};
  engines["segmentation"] = std::move(j);
}

}  // namespace dm::scene_parse
