// scene_vps.cpp — the scene file's VPS renderer: the haptics engine's "vps"
// block (the tool, its sampling, the objects' voxels, the virtual
// coupling), its checks against the renderer, the touched objects and their
// materials, and its JSON (docs/scene-format.md, "engines", "vps").
#include "scene_parse.hpp"

namespace dm::scene_parse {

void readVps(ConfigReader& haptics, SceneHapticsEngine& h) {
  ConfigReader r = haptics.child("vps");
  if (!expectObject(r)) return;
  r.knownKeys({"tool", "point_spacing", "voxel_size", "coupling_stiffness", "coupling_damping",
               "coupling_angular_stiffness", "coupling_angular_damping", "mass", "reference_contacts",
               "max_point_depth", "brake_distance", "brake_damping", "max_torque", "substeps"});
  SceneVps v;
  v.tool = r.string("tool");
  v.pointSpacing = r.number("point_spacing", {.min = 0.0, .max = 0.1}, v.pointSpacing);
  v.voxelSize = r.number("voxel_size", {.min = 0.0, .max = 0.1}, v.voxelSize);
  v.couplingStiffness = readPositive(r, "coupling_stiffness", v.couplingStiffness, 1e6);
  v.couplingDamping = r.number("coupling_damping", {.min = 0.0, .max = 1e4}, v.couplingDamping);
  v.couplingAngularStiffness = readPositive(r, "coupling_angular_stiffness", v.couplingAngularStiffness, 1e4);
  v.couplingAngularDamping =
      r.number("coupling_angular_damping", {.min = 0.0, .max = 1e2}, v.couplingAngularDamping);
  v.mass = readPositive(r, "mass", v.mass, 100.0);
  v.referenceContacts = r.number("reference_contacts", {.min = 1.0, .max = 1e6}, v.referenceContacts);
  v.maxPointDepth = readPositive(r, "max_point_depth", v.maxPointDepth, 0.1);
  v.brakeDistance = r.number("brake_distance", {.min = 0.0, .max = 0.1}, v.brakeDistance);
  v.brakeDamping = r.number("brake_damping", {.min = 0.0, .max = 1e4}, v.brakeDamping);
  v.maxTorque = readPositive(r, "max_torque", v.maxTorque, 100.0);
  v.substeps = static_cast<int>(r.integer("substeps", {.min = 1, .max = 64}, v.substeps));
  h.vps = std::move(v);
}

void checkVps(const SceneDesc& scene, ConfigReader root) {
  const auto& h = scene.engines.haptics;
  if (!h) return;
  ConfigReader haptics = root.child("engines").child("haptics");
  const bool vps = h->renderer == SceneHapticsEngine::Renderer::Vps;
  if (!vps) {
    if (h->vps)
      haptics.addError("a \"vps\" block belongs to the vps renderer", "vps",
                       "set \"renderer\": \"vps\" or remove \"vps\"");
    return;
  }
  if (!h->vps) {
    haptics.addError("the vps renderer needs its tool", "vps",
                     "add \"vps\": {\"tool\": \"<mesh resource>\"}");
    return;
  }
  for (const char* key : {"tool_radius", "force_shading"})
    if (haptics.has(key))
      haptics.addError("the vps renderer's tool is its \"vps\" block", key,
                       "remove \"" + std::string(key) + "\"");
  ConfigReader block = haptics.child("vps");
  if (const SceneResource* t = scene.resource(h->vps->tool); t == nullptr) {
    block.addError("no resource " + inQuotes(h->vps->tool), "tool", "name a mesh or shape resource");
  } else if (t->type == SceneResource::Type::Volume || t->type == SceneResource::Type::Image ||
             (t->type == SceneResource::Type::Shape && t->shape == SceneResource::Shape::Plane)) {
    block.addError("resource " + inQuotes(h->vps->tool) + " has no closed surface to sample", "tool",
                   "a tool is a mesh, an isosurface or a sphere, box, capsule or cylinder shape");
  }
  ConfigReader objects = root.child("objects");
  for (const std::string& name : h->objects) {
    const SceneObject* o = scene.object(name);
    if (o == nullptr) continue;  // (reported with the objects list)
    ConfigReader at = objects.at(static_cast<std::size_t>(o - scene.objects.data()));
    if (o->dynamic || o->soft)
      at.addError("the vps renderer touches static objects; " + inQuotes(name) + " is " +
                      (o->dynamic ? "dynamic" : "soft"),
                  o->dynamic ? "dynamic" : "soft", "touch it with the god-object, or make it static");
    if (const SceneMaterial* m = scene.material(o->material);
        m != nullptr && m->haptic && (m->haptic->staticFriction > 0 || m->haptic->dynamicFriction > 0))
      at.addError("the vps renderer has no friction, and material " + inQuotes(o->material) + " has some",
                  "material", "set its static and dynamic friction to 0, or use the god-object");
  }
}

void writeVps(const SceneVps& v, Json& haptics) {
  haptics["vps"] = {{"tool", v.tool},
                    {"point_spacing", v.pointSpacing},
                    {"voxel_size", v.voxelSize},
                    {"coupling_stiffness", v.couplingStiffness},
                    {"coupling_damping", v.couplingDamping},
                    {"coupling_angular_stiffness", v.couplingAngularStiffness},
                    {"coupling_angular_damping", v.couplingAngularDamping},
                    {"mass", v.mass},
                    {"reference_contacts", v.referenceContacts},
                    {"max_point_depth", v.maxPointDepth},
                    {"brake_distance", v.brakeDistance},
                    {"brake_damping", v.brakeDamping},
                    {"max_torque", v.maxTorque},
                    {"substeps", v.substeps}};
}

}  // namespace dm::scene_parse
