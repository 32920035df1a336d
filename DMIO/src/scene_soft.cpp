// scene_soft.cpp — the scene file's soft tissue: an object's "soft" block
// (FEM material, damping, tetrahedra size, held faces, the layers a needle
// meets), the needle renderer's "needle" block and the punch renderer's
// "punch" block, their checks against the other keys and the engines, and
// their JSON (docs/scene-format.md, "Soft tissue", "Needles", "Punch").
#include <numbers>

#include "scene_parse.hpp"

namespace dm::scene_parse {

namespace {

// Largest model a scene may ask for (FemBody holds ~0.5 kB a tetrahedron).
constexpr double kMaxTetsLimit = 4'000'000.0;


// Most layers a needle meets (each tetrahedron's layer is a byte).
constexpr std::size_t kMaxLayers = 255;

void readLayers(ConfigReader& soft, SceneSoft& s) {
  ConfigReader r = soft.child("layers");
  if (!expectArray(r)) return;
  if (r.size() == 0 || r.size() > kMaxLayers) {
    r.addError(formatString("%zu layers", r.size()), {}, "give 1 to 255 layers, the top one first");
    return;
  }
  for (std::size_t i = 0; i < r.size(); ++i) {
    ConfigReader e = r.at(i);
    if (!expectObject(e)) continue;
    const bool byLabel = !s.labels.empty();
    if (byLabel)
      e.knownKeys({"name", "label", "puncture_force", "cutting_force", "friction"});
    else
      e.knownKeys({"name", "thickness", "puncture_force", "cutting_force", "friction"});
    SceneSoftLayer layer;
    const std::size_t before = e.errors().size();
    layer.name = e.string("name");
    if (e.errors().size() == before) {
      if (layer.name.empty()) e.addError("empty name", "name");
      for (const SceneSoftLayer& l : s.layers)
        if (l.name == layer.name) e.addError("layer " + inQuotes(layer.name) + " is listed twice", "name");
    }
    if (byLabel) {
      const std::size_t b = e.errors().size();
      const double label = e.number("label", {.min = 0.0, .max = 65535.0});
      if (e.errors().size() == b && label != std::floor(label))
        e.addError(formatString("label %g is not a whole number", label), "label");
      else if (e.errors().size() == b)
        layer.label = static_cast<int>(label);
      for (const SceneSoftLayer& l : s.layers)
        if (layer.label >= 0 && l.label == layer.label)
          e.addError(formatString("label %d is layer \"%s\" already", layer.label, l.name.c_str()), "label");
    } else if (i + 1 < r.size()) {
      layer.thickness = readPositive(e, "thickness", {}, 1.0);
    } else if (e.has("thickness")) {
      e.addError("the last layer reaches down to the bottom", "thickness", "remove \"thickness\"");
    }
    layer.punctureForce = e.number("puncture_force", {.min = 0.0, .max = 1000.0}, layer.punctureForce);
    layer.cuttingForce = e.number("cutting_force", {.min = 0.0, .max = 1000.0}, layer.cuttingForce);
    layer.friction = e.number("friction", {.min = 0.0, .max = 1e6}, layer.friction);
    s.layers.push_back(std::move(layer));
  }
}

}  // namespace

void readNeedle(ConfigReader& haptics, SceneHapticsEngine& h) {
  ConfigReader r = haptics.child("needle");
  if (!expectObject(r)) return;
  r.knownKeys({"length", "radius", "coupling_spacing", "across_stiffness", "along_stiffness", "tip", "axis",
               "normal", "max_torque"});
  SceneNeedle n;
  n.length = readPositive(r, "length", n.length, 1.0);
  std::size_t before = r.errors().size();
  n.radius = r.number("radius", {.min = 0.0, .max = 10.0}, n.radius);
  if (r.errors().size() == before && n.radius > 0 && n.length > 1.5 * std::numbers::pi * n.radius)
    r.addError(
        formatString("a %g m arc of radius %g m is more than three quarters of a circle", n.length, n.radius),
        "length", "shorten it to at most 1.5·π·radius");
  before = r.errors().size();
  n.couplingSpacing = readPositive(r, "coupling_spacing", n.couplingSpacing, 1.0);
  if (r.errors().size() == before && n.couplingSpacing > n.length)
    r.addError(
        formatString("coupling spacing %g m is longer than the needle (%g m)", n.couplingSpacing, n.length),
        "coupling_spacing");
  n.acrossStiffness = readPositive(r, "across_stiffness", n.acrossStiffness, 1e6);
  n.alongStiffness = readPositive(r, "along_stiffness", n.alongStiffness, 1e6);
  n.tip = readVec3(r, "tip", n.tip);
  n.axis = readDirection(r, "axis", n.axis);
  if (n.radius > 0) {
    before = r.errors().size();
    n.normal = readDirection(r, "normal", n.normal);
    if (r.errors().size() == before && n.normal.cross(n.axis).norm() < 1e-6)
      r.addError("the normal is parallel to the axis", "normal",
                 "point it from the tip toward the arc's centre, across the axis");
  } else if (r.has("normal")) {
    r.addError("a straight needle has no arc to point the normal at", "normal",
               "remove \"normal\", or give the needle a \"radius\"");
  }
  n.maxTorque = r.number("max_torque", {.min = 0.0, .max = 100.0}, n.maxTorque);
  h.needle = n;
}

void readPunch(ConfigReader& haptics, SceneHapticsEngine& h) {
  ConfigReader r = haptics.child("punch");
  if (!expectObject(r)) return;
  r.knownKeys({"object", "region"});
  ScenePunch p;
  p.object = r.string("object");
  ConfigReader region = r.child("region");
  if (isNull(region)) {
    r.addError("missing required region", "region",
               "add \"region\": {\"min\": [...], \"max\": [...]} (m, world)");
  } else if (auto box = readBox(region)) {
    p.region = *box;
  }
  h.punch = std::move(p);
}

void writePunch(const ScenePunch& p, Json& haptics) {
  haptics["punch"] = {{"object", p.object}, {"region", boxJson(p.region)}};
}

void writeNeedle(const SceneNeedle& n, Json& haptics) {
  Json j = {{"length", n.length},
            {"radius", n.radius},
            {"coupling_spacing", n.couplingSpacing},
            {"across_stiffness", n.acrossStiffness},
            {"along_stiffness", n.alongStiffness},
            {"tip", toJson(n.tip)},
            {"axis", toJson(n.axis)},
            {"max_torque", n.maxTorque}};
  if (n.radius > 0) j["normal"] = toJson(n.normal);
  haptics["needle"] = std::move(j);
}

void readSoft(ConfigReader& object, SceneObject& o) {
  ConfigReader r = object.child("soft");
  if (!expectObject(r)) return;
  r.knownKeys({"youngs_modulus", "poisson_ratio", "density", "damping", "voxel_size", "fixed", "max_tets",
               "layers", "labels", "contact_stiffness", "contact_friction", "fixed_boxes", "levels",
               "fine_region", "volume", "threshold"});
  SceneSoft s;
  s.youngsModulus = readPositive(r, "youngs_modulus", {}, 1e12);
  std::size_t before = r.errors().size();
  s.poissonRatio = r.number("poisson_ratio", {.min = 0.0, .max = 0.5}, s.poissonRatio);
  if (r.errors().size() == before && !(s.poissonRatio < 0.5))
    r.addError("a Poisson ratio of 0.5 is incompressible, which the linear elements lock on", "poisson_ratio",
               "use at most 0.49");
  s.density = readPositive(r, "density", s.density, 1e5);
  if (r.has("damping")) {
    ConfigReader d = r.child("damping");
    if (expectObject(d)) {
      d.knownKeys({"alpha", "beta"});
      s.alpha = d.number("alpha", {.min = 0.0, .max = 1e4}, s.alpha);
      s.beta = d.number("beta", {.min = 0.0, .max = 10.0}, s.beta);
    }
  }
  if (r.has("volume")) {
    // The tissue from a volume's voxels on its own grid.
    const std::size_t b = r.errors().size();
    s.volume = r.string("volume");
    if (r.errors().size() == b && s.volume.empty())
      r.addError("no volume named", "volume", "name a \"volume\" resource (a segmentation or a scan)");
    s.threshold = r.number("threshold", {.min = -1e12, .max = 1e12});
    if (r.has("voxel_size"))
      r.addError("the volume's spacing sets the tetrahedra's size", "voxel_size", "remove \"voxel_size\"");
  } else {
    if (r.has("threshold"))
      r.addError("a threshold without a volume", "threshold", "add \"volume\", or remove \"threshold\"");
    s.voxelSize = readPositive(r, "voxel_size", {}, 0.05);
  }
  if (r.has("contact_stiffness")) s.contactStiffness = readPositive(r, "contact_stiffness", {}, 1e9);
  s.contactFriction = r.number("contact_friction", {.min = 0.0, .max = 1e6}, s.contactFriction);
  if (r.has("fixed")) {
    ConfigReader f = r.child("fixed");
    if (expectArray(f)) {
      for (std::size_t i = 0; i < f.size(); ++i) {
        ConfigReader face = f.at(i);
        const Json& j = face.node();
        const auto it = j.is_string() ? std::find(SceneSoft::kFaces.begin(), SceneSoft::kFaces.end(),
                                                  j.get_ref<const std::string&>())
                                      : SceneSoft::kFaces.end();
        if (it == SceneSoft::kFaces.end()) {
          face.addError(std::string("expected a face of the bounding box, got ") +
                            (j.is_string() ? inQuotes(j.get_ref<const std::string&>()) : j.type_name()),
                        {}, "use \"-x\", \"+x\", \"-y\", \"+y\", \"-z\" or \"+z\" (object frame)");
          continue;
        }
        const auto bit = static_cast<std::uint8_t>(1u << (it - SceneSoft::kFaces.begin()));
        if ((s.fixedFaces & bit) != 0) face.addError("face " + inQuotes(*it) + " is listed twice");
        s.fixedFaces |= bit;
      }
    }
  }
  if (r.has("fixed_boxes")) {
    ConfigReader f = r.child("fixed_boxes");
    if (expectArray(f))
      for (std::size_t i = 0; i < f.size(); ++i) {
        ConfigReader b = f.at(i);
        if (auto box = readBox(b)) s.fixedBoxes.push_back(*box);
      }
  }
  if (r.has("levels")) {
    const std::size_t b = r.errors().size();
    const double levels = r.number("levels", {.min = 0.0, .max = 10.0});
    if (r.errors().size() == b && levels != std::floor(levels))
      r.addError(formatString("levels %g is not a whole number", levels), "levels");
    else if (r.errors().size() == b)
      s.levels = static_cast<int>(levels);
  }
  if (r.has("fine_region")) {
    ConfigReader b = r.child("fine_region");
    s.fineRegion = readBox(b);
    if (s.levels == 0)
      r.addError("a fine region on a uniform grid", "fine_region", "set \"levels\" > 0, or remove it");
  }
  before = r.errors().size();
  const double maxTets = r.number("max_tets", {.min = 1.0, .max = kMaxTetsLimit}, double(s.maxTets));
  if (r.errors().size() == before) {
    if (maxTets != std::floor(maxTets))
      r.addError(formatString("max_tets %g is not a whole number", maxTets), "max_tets");
    else
      s.maxTets = static_cast<std::size_t>(maxTets);
  }
  if (r.has("labels")) {
    const std::size_t b = r.errors().size();
    s.labels = r.string("labels");
    if (r.errors().size() == b && s.labels.empty())
      r.addError("no volume named", "labels", "name a \"volume\" resource of labels");
    if (!r.has("layers"))
      r.addError("labels but no layers", "labels", "add \"layers\" naming each label's layer");
  }
  if (r.has("layers")) readLayers(r, s);
  // The tissue meets every static object that collides (their "collide");
  // its own rigid-contact keys mean nothing.
  for (const char* key : {"collide", "contact"})
    if (object.has(key))
      object.addError(
          "a soft object meets the static objects that collide; its own rigid-contact keys do not apply", key,
          "remove \"" + std::string(key) +
              "\" (set \"collide\": false on an object it should pass through, "
              "\"contact_stiffness\" and \"contact_friction\" in \"soft\" for the contact's spring and "
              "friction)");
  o.collide = false;
  o.soft = s;
}

void checkDeforming(const SceneDesc& scene, ConfigReader& r, const SceneObject& o, std::string_view kind,
                    std::string_view block, int rateHz) {
  const std::string what = std::string(kind) + " " + inQuotes(o.name);
  if (!scene.engines.physics)
    r.addError(what + " but no physics engine deforms it", std::string(block),
               formatString("add \"physics\": {\"rate_hz\": %d} to \"engines\", or remove \"", rateHz) +
                   std::string(block) + "\"");
  if (o.dynamic)
    r.addError(what + " is deformed, not moved as a rigid body", "dynamic", "remove \"dynamic\"");
  for (const auto& [key, set] : {std::pair<const char*, bool>{"millable", o.millable.has_value()},
                                 {"critical", o.critical.has_value()},
                                 {"inclusion", o.inclusion.has_value()},
                                 {"voxels", o.voxels.has_value()}})
    if (set)
      r.addError(what + " is deformed, not milled or placed as bone", key,
                 "remove \"" + std::string(key) + "\"");
  if (!o.renderMesh.empty())
    r.addError(what + " is drawn as its deformed surface", "render_mesh", "remove \"render_mesh\"");
  for (const SceneObject& other : scene.objects)
    if (&other != &o && (other.mesh == o.mesh || other.renderMesh == o.mesh)) {
      r.addError("resource " + inQuotes(o.mesh) + " is also drawn by object " + inQuotes(other.name) +
                     ", which would deform with " + what,
                 "mesh", "give the " + std::string(kind) + " a resource of its own");
      break;
    }
}

void checkSoft(const SceneDesc& scene, ConfigReader root) {
  ConfigReader objects = root.child("objects");
  ConfigReader haptics = root.child("engines").child("haptics");
  const auto& h = scene.engines.haptics;
  const bool needle = h && h->renderer == SceneHapticsEngine::Renderer::Needle;
  const SceneObject* needled = nullptr;  // the soft object the needle goes into
  if (needle) {
    if (!h->needle)
      haptics.addError("the needle renderer needs its needle", "needle", "add \"needle\": {\"length\": <m>}");
    for (const char* key : {"tool_radius", "force_shading"})
      if (haptics.has(key))
        haptics.addError("the needle renderer's tool is its \"needle\" block", key,
                         "remove \"" + std::string(key) + "\"");
    const SceneObject* o = h->objects.size() == 1 ? scene.object(h->objects[0]) : nullptr;
    if (h->objects.size() != 1)
      haptics.addError(formatString("the needle goes into one soft object, not %zu", h->objects.size()),
                       "objects", "name the one soft object with \"layers\"");
    else if (o != nullptr && (!o->soft || o->soft->layers.empty()))
      haptics.addError("object " + inQuotes(o->name) + " has no needle layers", "objects",
                       "give it \"soft\": {..., \"layers\": [{\"name\": \"skin\", ...}]}");
    else
      needled = o;
    if (needled != nullptr)
      if (const SceneMaterial* m = scene.material(needled->material); m != nullptr && m->haptic) {
        const SceneHapticMaterial& hm = *m->haptic;
        if (hm.damping > 0 || hm.staticFriction > 0 || hm.dynamicFriction > 0)
          objects.at(static_cast<std::size_t>(needled - scene.objects.data()))
              .addError("the needle's friction is each layer's, and it has no damping", "material",
                        "set the damping and friction of material " + inQuotes(needled->material) +
                            " to 0 (its stiffness holds a membrane before it breaks)");
      }
  } else if (h && h->needle) {
    haptics.addError("a \"needle\" block without the needle renderer", "needle",
                     "set \"renderer\": \"needle\", or remove \"needle\"");
  }
  const bool punch = h && h->renderer == SceneHapticsEngine::Renderer::Punch;
  if (punch && !h->punch) {
    haptics.addError(
        "the punch renderer needs its punch", "punch",
        "add \"punch\": {\"object\": <soft object>, \"region\": {\"min\": [...], \"max\": [...]}}");
  } else if (!punch && h && h->punch) {
    haptics.addError("a \"punch\" block without the punch renderer", "punch",
                     "set \"renderer\": \"punch\", or remove \"punch\"");
  } else if (punch && !h->punch->object.empty()) {
    const SceneObject* o = scene.object(h->punch->object);
    if (o == nullptr || !o->soft)
      haptics.child("punch").addError(
          "object " + inQuotes(h->punch->object) + (o ? " is not soft" : " is not defined"), "object",
          "name an object with a \"soft\" block (the tissue the punch is bonded to)");
    else if (!o->soft->layers.empty())
      haptics.child("punch").addError("object " + inQuotes(o->name) + " has needle layers", "object",
                                      "a punch presses tissue without layers");
  }
  for (std::size_t i = 0; i < scene.objects.size() && objects.isArray() && i < objects.size(); ++i) {
    const SceneObject& o = scene.objects[i];
    if (!o.soft) continue;
    ConfigReader r = objects.at(i);
    checkDeforming(scene, r, o, "soft object", "soft", 100);
    if (h && h->proxyObject == o.name)
      r.addError("the haptic proxy object " + inQuotes(o.name) + " is the tool's picture, not tissue", "soft",
                 "remove \"soft\", or show the tool with another object");
    if (const SceneResource* m = scene.resource(o.mesh);
        m != nullptr && m->type == SceneResource::Type::Shape && m->shape == SceneResource::Shape::Plane)
      r.addError("a plane (a flat rectangle) has no volume to fill with tetrahedra", "mesh",
                 "use a box shape or a closed mesh");
    if (h && std::find(h->objects.begin(), h->objects.end(), o.name) != h->objects.end() &&
        h->renderer != SceneHapticsEngine::Renderer::GodObject && !needle)
      r.addError("soft object " + inQuotes(o.name) + " is touched by the god-object or the needle only",
                 "soft", "set the haptics engine's \"renderer\": \"god-object\" or \"needle\"");
    if (!o.soft->volume.empty()) {
      const SceneResource* res = scene.resource(o.soft->volume);
      if (res == nullptr || res->type != SceneResource::Type::Volume)
        r.child("soft").addError(
            "resource " + inQuotes(o.soft->volume) + (res ? " is not a volume" : " is not defined"), "volume",
            "name a \"volume\" resource");
      if (o.scale != 1.0)
        r.addError("tissue from a volume has the volume's own size", "scale",
                   "remove \"scale\" (the volume's spacing sets it)");
    }
    if (!o.soft->labels.empty()) {
      const SceneResource* res = scene.resource(o.soft->labels);
      if (res == nullptr || res->type != SceneResource::Type::Volume)
        r.child("soft").addError(
            "resource " + inQuotes(o.soft->labels) + (res ? " is not a volume" : " is not defined"), "labels",
            "name a \"volume\" resource of labels (a segmentation)");
    }
    if (!o.soft->layers.empty() && needled != &o)
      r.child("soft").addError("layers but no needle goes into " + inQuotes(o.name), "layers",
                               "set the haptics engine's \"renderer\": \"needle\" with \"objects\": [" +
                                   inQuotes(o.name) + "], or remove \"layers\"");
  }
}

void writeSoft(const SceneObject& o, Json& object) {
  if (!o.soft) return;
  const SceneSoft& s = *o.soft;
  Json fixed = Json::array();
  for (std::size_t i = 0; i < SceneSoft::kFaces.size(); ++i)
    if ((s.fixedFaces >> i) & 1u) fixed.push_back(std::string(SceneSoft::kFaces[i]));
  object["soft"] = {{"youngs_modulus", s.youngsModulus},
                    {"poisson_ratio", s.poissonRatio},
                    {"density", s.density},
                    {"damping", {{"alpha", s.alpha}, {"beta", s.beta}}},
                    {"voxel_size", s.voxelSize},
                    {"fixed", std::move(fixed)},
                    {"max_tets", s.maxTets}};
  if (s.contactStiffness > 0) object["soft"]["contact_stiffness"] = s.contactStiffness;
  if (s.contactFriction > 0) object["soft"]["contact_friction"] = s.contactFriction;
  if (!s.volume.empty()) {
    object["soft"].erase("voxel_size");
    object["soft"]["volume"] = s.volume;
    object["soft"]["threshold"] = s.threshold;
  }
  if (!s.fixedBoxes.empty()) {
    Json boxes = Json::array();
    for (const SceneBox& b : s.fixedBoxes) boxes.push_back(boxJson(b));
    object["soft"]["fixed_boxes"] = std::move(boxes);
  }
  if (s.levels > 0) object["soft"]["levels"] = s.levels;
  if (s.fineRegion) object["soft"]["fine_region"] = boxJson(*s.fineRegion);
  if (!s.layers.empty()) {
    Json layers = Json::array();
    for (std::size_t i = 0; i < s.layers.size(); ++i) {
      const SceneSoftLayer& l = s.layers[i];
      Json j = {{"name", l.name},
                {"puncture_force", l.punctureForce},
                {"cutting_force", l.cuttingForce},
                {"friction", l.friction}};
      if (!s.labels.empty())
        j["label"] = l.label;
      else if (i + 1 < s.layers.size())
        j["thickness"] = l.thickness;
      layers.push_back(std::move(j));
    }
    object["soft"]["layers"] = std::move(layers);
    if (!s.labels.empty()) object["soft"]["labels"] = s.labels;
  }
}

}  // namespace dm::scene_parse
