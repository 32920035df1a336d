// scene_membrane.cpp — an object's "membrane" block (v2): its triangle mesh
// as a viscoelastic mass–spring membrane the physics engine deforms, its
// checks against the engines and the other objects, and its JSON
// (docs/scene-format.md, "Membranes"; the runtime builds it in
// DMEngine/src/scene_membranes.cpp).
#include <algorithm>

#include "scene_parse.hpp"

namespace dm::scene_parse {

namespace {

using Model = SceneMembrane::Model;

constexpr std::array<std::string_view, 2> kModels = {"kelvin-voigt", "maxwell"};

}  // namespace

void readMembrane(ConfigReader& object, SceneObject& o) {
  ConfigReader r = object.child("membrane");
  if (!expectObject(r)) return;
  r.knownKeys({"mass", "stiffness", "damping", "model", "bend_stiffness", "bend_damping", "drag", "pinned",
               "pinned_boxes", "friction", "thickness"});
  SceneMembrane m;
  m.mass = readPositive(r, "mass", {}, 1e3);
  m.stiffness = readPositive(r, "stiffness", {}, 1e9);
  m.damping = r.number("damping", {.min = 0.0, .max = 1e6}, m.damping);
  const std::size_t before = r.errors().size();
  const std::string model = r.oneOf("model", {kModels[0], kModels[1]}, std::string(kModels[0]));
  if (r.errors().size() == before) {
    m.model = model == kModels[1] ? Model::Maxwell : Model::KelvinVoigt;
    if (m.model == Model::Maxwell && !(m.damping > 0.0))
      r.addError("a Maxwell element's damper carries its force: damping must be > 0", "damping",
                 "give \"damping\" (N·s/m) > 0, or use \"model\": \"kelvin-voigt\"");
  }
  m.bendStiffness = r.number("bend_stiffness", {.min = 0.0, .max = 1e9}, m.bendStiffness);
  m.bendDamping = r.number("bend_damping", {.min = 0.0, .max = 1e6}, m.bendDamping);
  if (r.has("bend_damping") && !(m.bendStiffness > 0.0))
    r.addError("bend damping without bend elements", "bend_damping",
               "give \"bend_stiffness\" > 0, or remove \"bend_damping\"");
  m.drag = r.number("drag", {.min = 0.0, .max = 1e4}, m.drag);
  m.friction = r.number("friction", {.min = 0.0, .max = 10.0}, m.friction);
  m.thickness = r.number("thickness", {.min = 0.0, .max = 0.1}, m.thickness);
  if (r.has("pinned")) {
    const std::size_t b = r.errors().size();
    r.oneOf("pinned", {"boundary"});
    m.pinBoundary = r.errors().size() == b;
  }
  if (r.has("pinned_boxes")) {
    ConfigReader list = r.child("pinned_boxes");
    if (expectArray(list))
      for (std::size_t i = 0; i < list.size(); ++i) {
        ConfigReader b = list.at(i);
        if (auto box = readBox(b)) m.pinnedBoxes.push_back(*box);
      }
  }
  // A membrane meets the objects that collide through its own particles
  // (its "friction" and "thickness"), not as a rigid collider.
  for (const char* key : {"collide", "contact"})
    if (object.has(key))
      object.addError("a membrane is not a rigid collider: it meets colliding objects by its particles", key,
                      "remove \"" + std::string(key) +
                          "\" (the membrane's \"friction\" and \"thickness\" set its "
                          "contact)");
  o.collide = false;
  o.membrane = m;
}

void checkMembranes(const SceneDesc& scene, ConfigReader root) {
  ConfigReader objects = root.child("objects");
  const auto& h = scene.engines.haptics;
  for (std::size_t i = 0; i < scene.objects.size() && objects.isArray() && i < objects.size(); ++i) {
    const SceneObject& o = scene.objects[i];
    if (!o.membrane) continue;
    ConfigReader r = objects.at(i);
    checkDeforming(scene, r, o, "membrane", "membrane", 200);
    if (o.soft) r.addError("an object is a membrane or soft tissue, not both", "soft", "remove one of them");
    if (h && h->proxyObject == o.name)
      r.addError("the haptic proxy object " + inQuotes(o.name) + " is the tool's picture, not a membrane",
                 "membrane", "remove \"membrane\", or show the tool with another object");
    else if (h && std::find(h->objects.begin(), h->objects.end(), o.name) != h->objects.end())
      root.child("engines").child("haptics").addError(
          "membrane " + inQuotes(o.name) +
              " cannot be touched: the haptic renderers touch rigid objects, "
              "soft tissue and bone",
          "objects", "remove " + inQuotes(o.name) + " from the haptics engine's \"objects\"");
    // It meets the colliding rigid objects, static and dynamic; soft tissue
    // would pass through it (or it through the tissue).
    for (const SceneObject& other : scene.objects) {
      if (&other == &o || !other.soft) continue;
      r.addError("membrane " + inQuotes(o.name) + " and soft object " + inQuotes(other.name) +
                     " do not meet: each would pass through the other",
                 "membrane", "remove one of them");
      break;
    }
    for (std::size_t f = 0; f < scene.fluids.size(); ++f) {
      const auto& names = scene.fluids[f].objects;
      const auto it = std::find(names.begin(), names.end(), o.name);
      if (it != names.end())
        root.child("fluids").at(f).child("objects").addError(
            "membrane " + inQuotes(o.name) + " does not meet fluids", std::to_string(it - names.begin()),
            "remove it from the fluid's \"objects\"");
    }
  }
}

void writeMembrane(const SceneObject& o, Json& object) {
  if (!o.membrane) return;
  const SceneMembrane& m = *o.membrane;
  Json j = {{"mass", m.mass},
            {"stiffness", m.stiffness},
            {"damping", m.damping},
            {"model", std::string(kModels[m.model == Model::Maxwell ? 1 : 0])},
            {"bend_stiffness", m.bendStiffness},
            {"drag", m.drag},
            {"friction", m.friction},
            {"thickness", m.thickness}};
  if (m.bendStiffness > 0.0) j["bend_damping"] = m.bendDamping;
  if (m.pinBoundary) j["pinned"] = "boundary";
  if (!m.pinnedBoxes.empty()) {
    Json boxes = Json::array();
    for (const SceneBox& b : m.pinnedBoxes) boxes.push_back(boxJson(b));
    j["pinned_boxes"] = std::move(boxes);
  }
  object["membrane"] = std::move(j);
}

}  // namespace dm::scene_parse
