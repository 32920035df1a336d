// scene_fluid.cpp — the scene file's "fluids" (v2): particle fluids the
// physics engine steps, with their container, region of interest, starting
// blocks, inlets (cut vessels, irrigation) and suction tips; their checks
// and JSON (docs/scene-format.md, "Fluids"; the runtime's side is
// DMEngine/src/scene_fluids.hpp).
#include <algorithm>
#include <array>
#include <set>

#include "scene_parse.hpp"

namespace dm::scene_parse {

namespace {

// The most particles a region may hold (its volume over the spacing cubed):
// 4 million particles are about 2 GiB of solver state.
constexpr double kMaxRegionParticles = 4e6;
// The largest flow a source or a tip may have: 1 l/s.
constexpr double kMaxFlowRate = 1e-3;

// A box that must hold something (min < max on every axis) at `key`.
std::optional<SceneBox> readSolidBox(ConfigReader& parent, std::string_view key, bool required) {
  ConfigReader r = parent.child(key, required);
  return readBox(r, true);
}

bool inside(const SceneBox& outer, const SceneBox& inner) {
  return (inner.min.array() >= outer.min.array()).all() && (inner.max.array() <= outer.max.array()).all();
}

bool inside(const SceneBox& box, const Vec3& p) {
  return (p.array() >= box.min.array()).all() && (p.array() <= box.max.array()).all();
}

// "start" and "stop" (seconds of scene time; stop after start).
void readWindow(ConfigReader& r, double& start, std::optional<double>& stop) {
  start = r.number("start", {.min = 0.0, .max = 1e7}, 0.0);
  if (!r.has("stop")) return;
  const std::size_t before = r.errors().size();
  const double s = r.number("stop", {.min = 0.0, .max = 1e7});
  if (r.errors().size() != before) return;
  if (!(s > start))
    r.addError(formatString("stop (%g s) is not after start (%g s)", s, start), "stop");
  else
    stop = s;
}

void readInlets(ConfigReader& fr, SceneFluid& f) {
  ConfigReader list = fr.child("inlets");
  if (!expectArray(list)) return;
  std::set<std::string, std::less<>> names;
  for (std::size_t i = 0; i < list.size(); ++i) {
    ConfigReader r = list.at(i);
    if (!expectObject(r)) continue;
    r.knownKeys({"name", "center", "normal", "radius", "flow_rate", "pressure", "start", "stop"});
    SceneFluidInlet in;
    in.name = readUniqueName(r, names, "inlet");
    const std::size_t before = r.errors().size();
    in.center = readVec3(r, "center");
    if (r.errors().size() == before && !inside(f.region, in.center))
      r.addError("the inlet lies outside the fluid's region, which would recycle its fluid at once", "center",
                 "move it inside \"region\" or grow the region");
    in.normal = readDirection(r, "normal", in.normal);
    in.radius = r.number("radius", {.min = 0.0, .max = 0.1}, in.radius);
    in.flowRate = r.number("flow_rate", {.min = 0.0, .max = kMaxFlowRate});
    in.pressure = r.number("pressure", {.min = 0.0, .max = 1e6}, in.pressure);
    readWindow(r, in.start, in.stop);
    f.inlets.push_back(std::move(in));
  }
}

void readSuction(ConfigReader& fr, SceneFluid& f, const SceneDesc& scene) {
  ConfigReader list = fr.child("suction");
  if (!expectArray(list)) return;
  std::set<std::string, std::less<>> names;
  for (std::size_t i = 0; i < list.size(); ++i) {
    ConfigReader r = list.at(i);
    if (!expectObject(r)) continue;
    r.knownKeys({"name", "radius", "flow_rate", "at", "center", "start", "stop"});
    SceneFluidSuction s;
    s.name = readUniqueName(r, names, "suction tip");
    s.radius = readPositive(r, "radius", {}, 0.1);
    s.flowRate = r.number("flow_rate", {.min = 0.0, .max = kMaxFlowRate});
    if (r.has("at") == r.has("center")) {
      r.addError(
          r.has("at") ? "both \"at\" and \"center\" are given" : "neither \"at\" nor \"center\" is given", "",
          "\"at\": \"tool\" (the tip follows the haptic tool) or \"center\": [x, y, z]");
    } else if (r.has("at")) {
      const std::size_t before = r.errors().size();
      r.oneOf("at", {"tool"});
      s.atTool = r.errors().size() == before;
      if (s.atTool && !scene.engines.haptics)
        r.addError("the scene has no haptics engine, so no tool to follow", "at",
                   "add \"haptics\" under \"engines\" or give the tip a \"center\"");
    } else {
      s.center = readVec3(r, "center");
    }
    readWindow(r, s.start, s.stop);
    f.suction.push_back(std::move(s));
  }
}

// "objects": scene objects the fluid flows around. A static object's
// surface becomes a wall, a soft object's a deforming boundary, a dynamic
// body's a rigid body of the fluid (two-way); the haptic proxy is refused
// (the fluid meets the tool through suction tips).
void readObjects(ConfigReader& fr, SceneFluid& f, const SceneDesc& scene) {
  if (!fr.has("objects")) return;
  ConfigReader list = fr.child("objects");
  if (!expectArray(list)) return;
  const std::string proxy = scene.engines.haptics ? scene.engines.haptics->proxyObject : std::string();
  for (std::size_t i = 0; i < list.size(); ++i) {
    const Json& e = list.node()[i];
    const std::string key = std::to_string(i);
    if (!e.is_string()) {
      list.addError(std::string("expected an object name, got ") + e.type_name(), key);
      continue;
    }
    const std::string name = e.get<std::string>();
    const SceneObject* o = scene.object(name);
    if (o == nullptr)
      list.addError("no object \"" + name + "\"", key, "name an object under \"objects\"");
    else if (std::find(f.objects.begin(), f.objects.end(), name) != f.objects.end())
      list.addError("object \"" + name + "\" is listed twice", key);
    else if (!proxy.empty() && name == proxy)
      list.addError("object \"" + name + "\" is the haptic proxy", key,
                    "the fluid meets the tool through suction tips (\"at\": \"tool\")");
    else
      f.objects.push_back(name);
  }
}

constexpr std::array<std::string_view, 2> kLookStyles = {"surface", "spheres"};

void readLook(ConfigReader& fr, SceneFluid& f) {
  if (!fr.has("look")) return;
  ConfigReader r = fr.child("look");
  if (!expectObject(r)) return;
  r.knownKeys({"style", "absorption", "fresnel", "specular", "shininess", "refraction", "smoothing"});
  SceneFluidLook& look = f.look;
  look.style = readEnum(r, "style", kLookStyles, std::optional(look.style)).value_or(look.style);
  if (r.has("absorption")) {
    const Vec3 a = readVec3(r, "absorption");
    if (!a.allFinite() || (a.array() < 0.0).any() || (a.array() > 1e7).any())
      r.addError("absorption needs three coefficients in [0, 1e7] 1/m", "absorption",
                 "e.g. [700, 3900, 3900] for blood: 1 mm transmits half the red");
    else
      look.absorption = a;
  }
  look.fresnel = r.number("fresnel", {.min = 0.0, .max = 1.0}, look.fresnel);
  look.specular = r.number("specular", {.min = 0.0, .max = 100.0}, look.specular);
  look.shininess = r.number("shininess", {.min = 1.0, .max = 1e4}, look.shininess);
  look.refraction = r.number("refraction", {.min = 0.0, .max = 256.0}, look.refraction);
  look.smoothing = static_cast<int>(r.integer("smoothing", {.min = 0, .max = 16}, look.smoothing));
  if (look.style == SceneFluidLook::Style::Spheres)
    for (const char* key : {"absorption", "fresnel", "specular", "shininess", "refraction", "smoothing"})
      if (r.has(key))
        r.addError(std::string(key) + " shapes the surface style, and this fluid is drawn as spheres", key,
                   "remove it, or use \"style\": \"surface\"");
}

Json lookJson(const SceneFluidLook& look) {
  if (look.style == SceneFluidLook::Style::Spheres) return {{"style", enumName(look.style, kLookStyles)}};
  Json j = {{"style", enumName(look.style, kLookStyles)},
            {"fresnel", look.fresnel},
            {"specular", look.specular},
            {"shininess", look.shininess},
            {"refraction", look.refraction},
            {"smoothing", look.smoothing}};
  if (look.absorption) j["absorption"] = toJson(*look.absorption);
  return j;
}

Json windowJson(Json j, double start, const std::optional<double>& stop) {
  j["start"] = start;
  if (stop) j["stop"] = *stop;
  return j;
}

}  // namespace

void readFluids(ConfigReader& root, SceneDesc& scene) {
  ConfigReader list = root.child("fluids");
  if (!expectArray(list)) return;
  std::set<std::string, std::less<>> names;
  for (std::size_t i = 0; i < list.size(); ++i) {
    ConfigReader r = list.at(i);
    if (!expectObject(r)) continue;
    r.knownKeys({"name", "spacing", "density", "viscosity", "surface_tension", "color", "look", "container",
                 "region", "blocks", "inlets", "suction", "objects"});
    SceneFluid f;
    f.name = readUniqueName(r, names, "fluid");
    if (!scene.engines.physics)
      r.addError("a fluid needs the physics engine, which steps it", "",
                 "add \"physics\" under \"engines\" (its rate is the fluid's step)");
    f.spacing = readPositive(r, "spacing", f.spacing, 0.1);
    f.density = readPositive(r, "density", f.density, 1e5);
    f.viscosity = r.number("viscosity", {.min = 0.0, .max = 10.0}, f.viscosity);
    f.surfaceTension = r.number("surface_tension", {.min = 0.0, .max = 10.0}, f.surfaceTension);
    f.color = readColor(r, "color", Vec4(f.color.x(), f.color.y(), f.color.z(), 1.0), false).head<3>();
    readLook(r, f);
    if (r.has("container")) f.container = readSolidBox(r, "container", false);
    if (const auto region = readSolidBox(r, "region", true)) {
      f.region = *region;
      const Vec3 size = region->max - region->min;
      const double particles = size.prod() / (f.spacing * f.spacing * f.spacing);
      if (particles > kMaxRegionParticles)
        r.addError(formatString("the region holds up to %.3g particles at spacing %g m; at most %.0f",
                                particles, f.spacing, kMaxRegionParticles),
                   "region", "a larger spacing or a smaller region");
    }
    ConfigReader blocks = r.child("blocks");
    if (expectArray(blocks))
      for (std::size_t k = 0; k < blocks.size(); ++k) {
        ConfigReader br = blocks.at(k);
        if (const auto b = readBox(br, true)) {
          if (!inside(f.region, *b))
            br.addError("the block reaches outside the fluid's region, which would recycle that part at once",
                        "", "keep blocks inside \"region\"");
          f.blocks.push_back(*b);
        }
      }
    readInlets(r, f);
    readSuction(r, f, scene);
    readObjects(r, f, scene);
    scene.fluids.push_back(std::move(f));
  }
}

Json fluidsJson(const std::vector<SceneFluid>& fluids) {
  Json list = Json::array();
  for (const SceneFluid& f : fluids) {
    Json j = {{"name", f.name},
              {"spacing", f.spacing},
              {"density", f.density},
              {"viscosity", f.viscosity},
              {"surface_tension", f.surfaceTension},
              {"color", toJson(f.color)},
              {"look", lookJson(f.look)},
              {"region", boxJson(f.region)}};
    if (f.container) j["container"] = boxJson(*f.container);
    Json blocks = Json::array();
    for (const SceneBox& b : f.blocks) blocks.push_back(boxJson(b));
    j["blocks"] = std::move(blocks);
    Json inlets = Json::array();
    for (const SceneFluidInlet& in : f.inlets)
      inlets.push_back(windowJson({{"name", in.name},
                                   {"center", toJson(in.center)},
                                   {"normal", toJson(in.normal)},
                                   {"radius", in.radius},
                                   {"flow_rate", in.flowRate},
                                   {"pressure", in.pressure}},
                                  in.start, in.stop));
    j["inlets"] = std::move(inlets);
    Json suction = Json::array();
    for (const SceneFluidSuction& s : f.suction) {
      Json t = {{"name", s.name}, {"radius", s.radius}, {"flow_rate", s.flowRate}};
      if (s.atTool)
        t["at"] = "tool";
      else
        t["center"] = toJson(s.center);
      suction.push_back(windowJson(std::move(t), s.start, s.stop));
    }
    j["suction"] = std::move(suction);
    if (!f.objects.empty()) j["objects"] = f.objects;
    list.push_back(std::move(j));
  }
  return list;
}

}  // namespace dm::scene_parse
