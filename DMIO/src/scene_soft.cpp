// scene_soft.cpp — the scene file's soft tissue: an object's "soft" block
// (FEM material, damping, tetrahedra size, held faces), its checks against
// the other keys and the engines, and its JSON (docs/scene-format.md,
// "Soft tissue").
#include "scene_parse.hpp"

namespace dm::scene_parse {

namespace {

// Largest model a scene may ask for (FemBody holds ~0.5 kB a tetrahedron).
constexpr double kMaxTetsLimit = 4'000'000.0;

}  // namespace

void readSoft(ConfigReader& object, SceneObject& o) {
  ConfigReader r = object.child("soft");
  if (!expectObject(r)) return;
  r.knownKeys({"youngs_modulus", "poisson_ratio", "density", "damping", "voxel_size", "fixed", "max_tets"});
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
  s.voxelSize = readPositive(r, "voxel_size", {}, 0.05);
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
  before = r.errors().size();
  const double maxTets = r.number("max_tets", {.min = 1.0, .max = kMaxTetsLimit}, double(s.maxTets));
  if (r.errors().size() == before) {
    if (maxTets != std::floor(maxTets))
      r.addError(formatString("max_tets %g is not a whole number", maxTets), "max_tets");
    else
      s.maxTets = static_cast<std::size_t>(maxTets);
  }
  // Soft–rigid contact is not modelled by the scene runtime: say so rather
  // than let bodies pass through the tissue.
  for (const char* key : {"collide", "contact"})
    if (object.has(key))
      object.addError("a soft object takes part in no rigid contact (its held faces keep it in place)", key,
                      "remove \"" + std::string(key) + "\"");
  o.collide = false;
  o.soft = s;
}

void checkSoft(const SceneDesc& scene, ConfigReader root) {
  ConfigReader objects = root.child("objects");
  const auto& h = scene.engines.haptics;
  std::string dynamicBody;  // a rigid body the soft objects would not stop
  for (const SceneObject& o : scene.objects)
    if (o.dynamic && dynamicBody.empty()) dynamicBody = o.name;
  for (std::size_t i = 0; i < scene.objects.size() && objects.isArray() && i < objects.size(); ++i) {
    const SceneObject& o = scene.objects[i];
    if (!o.soft) continue;
    ConfigReader r = objects.at(i);
    if (!scene.engines.physics)
      r.addError("soft object " + inQuotes(o.name) + " but no physics engine deforms it", "soft",
                 "add \"physics\": {\"rate_hz\": 100} to \"engines\", or remove \"soft\"");
    for (const char* key : {"dynamic", "millable", "critical", "inclusion"}) {
      const bool set = std::string_view(key) == "dynamic"    ? o.dynamic
                       : std::string_view(key) == "millable" ? o.millable.has_value()
                       : std::string_view(key) == "critical" ? o.critical.has_value()
                                                             : o.inclusion.has_value();
      if (set)
        r.addError("a soft object is deformed by its FEM model, not " +
                       std::string(std::string_view(key) == "dynamic" ? "moved as a rigid body" : "milled"),
                   key, "remove \"" + std::string(key) + "\"");
    }
    if (h && h->proxyObject == o.name)
      r.addError("the haptic proxy object " + inQuotes(o.name) + " is the tool's picture, not tissue", "soft",
                 "remove \"soft\", or show the tool with another object");
    if (!o.renderMesh.empty())
      r.addError("a soft object is drawn as its deformed tetrahedra's surface", "render_mesh",
                 "remove \"render_mesh\"");
    if (const SceneResource* m = scene.resource(o.mesh);
        m != nullptr && m->type == SceneResource::Type::Shape && m->shape == SceneResource::Shape::Plane)
      r.addError("a plane (a flat rectangle) has no volume to fill with tetrahedra", "mesh",
                 "use a box shape or a closed mesh");
    for (const SceneObject& other : scene.objects)
      if (&other != &o && (other.mesh == o.mesh || other.renderMesh == o.mesh)) {
        r.addError("resource " + inQuotes(o.mesh) + " is also drawn by object " + inQuotes(other.name) +
                       ", which would deform with this soft object",
                   "mesh", "give the soft object a resource of its own");
        break;
      }
    if (!dynamicBody.empty())
      r.addError("dynamic body " + inQuotes(dynamicBody) + " would pass through soft object " +
                     inQuotes(o.name) +
                     ": contact between rigid bodies and soft tissue is not part of scene runs",
                 "soft", "run the rigid bodies and the tissue in separate scenes, or make the body static");
    if (h && std::find(h->objects.begin(), h->objects.end(), o.name) != h->objects.end() &&
        h->renderer != SceneHapticsEngine::Renderer::GodObject)
      r.addError("soft object " + inQuotes(o.name) + " is pressed by the god-object only", "soft",
                 "set the haptics engine's \"renderer\": \"god-object\"");
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
}

}  // namespace dm::scene_parse
