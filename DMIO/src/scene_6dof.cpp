// scene_6dof.cpp — the scene file's 6-DOF rigid-tool renderers: the haptics
// engine's "vps" block (the tool, its sampling, the objects' voxels, the
// virtual coupling) and "sphere_tree" block (the trees, the spring, the
// solver), their checks against the renderer, the touched objects and their
// materials, and their JSON (docs/scene-format.md, "engines").
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

void readSphereTree(ConfigReader& haptics, SceneHapticsEngine& h) {
  ConfigReader r = haptics.child("sphere_tree");
  if (!expectObject(r)) return;
  r.knownKeys({"tool", "levels", "tool_levels", "tool_level", "stiffness", "angular_stiffness", "mass",
               "inertia", "max_constraints", "solver_iterations", "linearizations", "margin_epsilon",
               "max_step", "surface_tolerance"});
  SceneSphereTree t;
  t.tool = r.string("tool");
  t.levels = static_cast<int>(r.integer("levels", {.min = 2, .max = 10}, t.levels));
  t.toolLevels = static_cast<int>(r.integer("tool_levels", {.min = 2, .max = 10}, t.toolLevels));
  const std::size_t before = r.errors().size();
  t.toolLevel = static_cast<int>(r.integer("tool_level", {.min = 0, .max = 9}, t.toolLevel));
  if (r.errors().size() == before && t.toolLevel >= t.toolLevels)
    r.addError(
        formatString("tool level %d is not one of the tool tree's %d levels", t.toolLevel, t.toolLevels),
        "tool_level", "at most tool_levels - 1");
  t.stiffness = readPositive(r, "stiffness", t.stiffness, 1e6);
  t.angularStiffness = r.number("angular_stiffness", {.min = 0.0, .max = 1e4}, t.angularStiffness);
  t.mass = readPositive(r, "mass", t.mass, 100.0);
  t.inertia = r.number("inertia", {.min = 0.0, .max = 10.0}, t.inertia);
  t.maxConstraints =
      static_cast<int>(r.integer("max_constraints", {.min = 1, .max = 65536}, t.maxConstraints));
  t.solverIterations =
      static_cast<int>(r.integer("solver_iterations", {.min = 1, .max = 10000}, t.solverIterations));
  t.linearizations = static_cast<int>(r.integer("linearizations", {.min = 1, .max = 16}, t.linearizations));
  t.marginEpsilon = r.number("margin_epsilon", {.min = 0.0, .max = 0.01}, t.marginEpsilon);
  t.maxStep = readPositive(r, "max_step", t.maxStep, 1.0);
  t.surfaceTolerance = r.number("surface_tolerance", {.min = 0.0, .max = 1.0}, t.surfaceTolerance);
  h.sphereTree = std::move(t);
}

void checkTools6Dof(const SceneDesc& scene, ConfigReader root) {
  const auto& h = scene.engines.haptics;
  if (!h) return;
  ConfigReader haptics = root.child("engines").child("haptics");
  const bool vps = h->renderer == SceneHapticsEngine::Renderer::Vps;
  const bool tree = h->renderer == SceneHapticsEngine::Renderer::SphereTree;
  if (!vps && h->vps)
    haptics.addError("a \"vps\" block belongs to the vps renderer", "vps",
                     "set \"renderer\": \"vps\" or remove \"vps\"");
  if (!tree && h->sphereTree)
    haptics.addError("a \"sphere_tree\" block belongs to the sphere-tree renderer", "sphere_tree",
                     "set \"renderer\": \"sphere-tree\" or remove \"sphere_tree\"");
  if (!vps && !tree) return;
  const char* key = vps ? "vps" : "sphere_tree";
  const std::string renderer = vps ? "vps" : "sphere-tree";
  if (vps ? !h->vps : !h->sphereTree) {
    haptics.addError("the " + renderer + " renderer needs its tool", key,
                     "add \"" + std::string(key) + "\": {\"tool\": \"<mesh resource>\"}");
    return;
  }
  for (const char* other : {"tool_radius", "force_shading"})
    if (haptics.has(other))
      haptics.addError("the " + renderer + " renderer's tool is its \"" + key + "\" block", other,
                       "remove \"" + std::string(other) + "\"");
  ConfigReader block = haptics.child(key);
  const std::string& toolName = vps ? h->vps->tool : h->sphereTree->tool;
  if (const SceneResource* t = scene.resource(toolName); t == nullptr) {
    block.addError("no resource " + inQuotes(toolName), "tool", "name a mesh or shape resource");
  } else if (t->type == SceneResource::Type::Volume || t->type == SceneResource::Type::Image ||
             (t->type == SceneResource::Type::Shape && t->shape == SceneResource::Shape::Plane)) {
    block.addError("resource " + inQuotes(toolName) + " has no closed surface to sample", "tool",
                   "a tool is a mesh, an isosurface or a sphere, box, capsule or cylinder shape");
  }
  ConfigReader objects = root.child("objects");
  for (const std::string& name : h->objects) {
    const SceneObject* o = scene.object(name);
    if (o == nullptr) continue;  // (reported with the objects list)
    ConfigReader at = objects.at(static_cast<std::size_t>(o - scene.objects.data()));
    // Dynamic objects are pushed: physics moves them and takes each tick's
    // wrench of the tool (the runtime); soft ones have no voxel model.
    if (o->soft)
      at.addError("the " + renderer + " renderer touches rigid objects; " + inQuotes(name) + " is soft", "soft",
                  "touch it with the god-object or the needle, or make it rigid");
    if (const SceneMaterial* m = scene.material(o->material);
        m != nullptr && m->haptic && (m->haptic->staticFriction > 0 || m->haptic->dynamicFriction > 0))
      at.addError("the " + renderer + " renderer has no friction, and material " + inQuotes(o->material) +
                      " has some",
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

void writeSphereTree(const SceneSphereTree& t, Json& haptics) {
  haptics["sphere_tree"] = {{"tool", t.tool},
                            {"levels", t.levels},
                            {"tool_levels", t.toolLevels},
                            {"tool_level", t.toolLevel},
                            {"stiffness", t.stiffness},
                            {"angular_stiffness", t.angularStiffness},
                            {"mass", t.mass},
                            {"inertia", t.inertia},
                            {"max_constraints", t.maxConstraints},
                            {"solver_iterations", t.solverIterations},
                            {"linearizations", t.linearizations},
                            {"margin_epsilon", t.marginEpsilon},
                            {"max_step", t.maxStep},
                            {"surface_tolerance", t.surfaceTolerance}};
}

}  // namespace dm::scene_parse
