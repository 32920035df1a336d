// scene_6dof.cpp — a scene's 6-DOF rigid-tool renderers (VPS, sphere tree,
// bone placement) from their block and touched objects (scene_6dof.hpp).
#include "scene_6dof.hpp"

#include <dm/collide/point_shell.hpp>
#include <dm/collide/sphere_tree.hpp>
#include <dm/collide/voxel_model.hpp>
#include <dm/io/scene_file.hpp>
#include <dm/io/scene_resources.hpp>

#include <limits>

namespace dm {

namespace {

// A touched object's mesh (scale baked in) and haptic material; fails
// naming the object.
struct TouchedObject {
  Mesh mesh;
  Isometry3 pose;
  HapticMaterial material;
};

Result<TouchedObject> touchedObject(const SceneDesc& scene, const SceneResources& resources,
                                    const std::string& name) {
  const SceneObject* o = scene.object(name);
  const SceneMaterial* material = o != nullptr ? scene.material(o->material) : nullptr;
  const std::shared_ptr<const Mesh> mesh = o != nullptr ? resources.mesh(o->mesh) : nullptr;
  if (o == nullptr || material == nullptr || !material->haptic || !mesh)
    return fail(ErrorCode::NotFound, "object \"" + name + "\" has no mesh or haptic material loaded",
                "objects/" + name);
  TouchedObject t{*mesh, o->pose.isometry(), {}};
  if (o->scale != 1.0) t.mesh.transform(Affine3(Eigen::Scaling(o->scale)));
  t.material.stiffness = material->haptic->stiffness;
  t.material.damping = material->haptic->damping;
  return t;
}

}  // namespace

Result<std::unique_ptr<VpsRenderer>> buildSceneVps(const SceneDesc& scene, const SceneResources& resources) {
  const SceneHapticsEngine& h = *scene.engines.haptics;
  const SceneVps& v = *h.vps;
  const std::string where = "engines/haptics/vps";
  const std::shared_ptr<const Mesh> tool = resources.mesh(v.tool);
  if (!tool)
    return fail(ErrorCode::NotFound, "resource \"" + v.tool + "\" was not loaded as a mesh", where + "/tool");
  const double extent = tool->bounds().sizes().maxCoeff();
  auto shell = PointShell::fromMesh(*tool, {.spacing = v.pointSpacing > 0 ? v.pointSpacing : extent / 20.0});
  if (!shell) return shell.error().within(where + "/tool");

  std::vector<VpsObject> objects;
  for (const std::string& name : h.objects) {
    auto t = touchedObject(scene, resources, name);
    if (!t) return t.error();
    VoxelizeOptions vox;
    vox.voxelSize = v.voxelSize > 0 ? v.voxelSize : t->mesh.bounds().sizes().maxCoeff() / 128.0;
    auto model = VoxelModel::fromMesh(t->mesh, vox);
    if (!model) return model.error().within("objects/" + name + " (voxelized for the vps renderer)");
    objects.push_back({*model, t->pose, t->material});
  }

  VpsOptions o;
  o.couplingStiffness = v.couplingStiffness;
  o.couplingDamping = v.couplingDamping;
  o.couplingAngularStiffness = v.couplingAngularStiffness;
  o.couplingAngularDamping = v.couplingAngularDamping;
  o.mass = v.mass;
  o.referenceContacts = v.referenceContacts;
  o.maxPointDepth = v.maxPointDepth;
  o.brakeDistance = v.brakeDistance;
  o.brakeDamping = v.brakeDamping;
  o.maxTorque = v.maxTorque;
  o.substeps = v.substeps;
  // The engine's max_force clamps here; without one the haptic loop clamps
  // to the device's limit.
  o.maxForce = h.maxForce > 0 ? h.maxForce : std::numeric_limits<double>::infinity();
  auto r = VpsRenderer::create(*shell, std::move(objects), o);
  if (!r) return r.error().within(where);
  return std::move(*r);
}

Result<std::unique_ptr<SphereTree6DofRenderer>> buildSceneSphereTree(const SceneDesc& scene,
                                                                     const SceneResources& resources) {
  const SceneHapticsEngine& h = *scene.engines.haptics;
  const SceneSphereTree& t = *h.sphereTree;
  const std::string where = "engines/haptics/sphere_tree";
  const std::shared_ptr<const Mesh> tool = resources.mesh(t.tool);
  if (!tool)
    return fail(ErrorCode::NotFound, "resource \"" + t.tool + "\" was not loaded as a mesh", where + "/tool");
  auto toolTree = buildSphereTreeOctree(*tool, {.levels = t.toolLevels});
  if (!toolTree) return toolTree.error().within(where + "/tool");
  std::vector<SphereTreeObject> objects;
  for (const std::string& name : h.objects) {
    auto o = touchedObject(scene, resources, name);
    if (!o) return o.error();
    auto tree = buildSphereTreeOctree(o->mesh, {.levels = t.levels});
    if (!tree) return tree.error().within("objects/" + name + " (its sphere tree)");
    SphereTreeObject obj;
    obj.tree = *tree;
    obj.pose = o->pose;
    obj.material = o->material;
    obj.name = name;
    objects.push_back(std::move(obj));
  }
  SphereTree6DofOptions o;
  o.toolLevel = t.toolLevel;
  o.mass = t.mass;
  o.inertia = t.inertia;
  o.linearStiffness = Vec3::Constant(t.stiffness);
  o.angularStiffness = Vec3::Constant(t.angularStiffness);
  o.maxConstraints = t.maxConstraints;
  o.solverIterations = t.solverIterations;
  o.linearizations = t.linearizations;
  o.marginEpsilon = t.marginEpsilon;
  o.maxStep = t.maxStep;
  o.surfaceTolerance = t.surfaceTolerance;
  auto r = SphereTree6DofRenderer::create(*toolTree, std::move(objects), o);
  if (!r) return r.error().within(where);
  return std::move(*r);
}

Result<SceneBonePlacementTool> buildSceneBonePlacement(const SceneDesc& scene,
                                                       const SceneResources& resources) {
  const SceneHapticsEngine& h = *scene.engines.haptics;
  const SceneBonePlacement& b = *h.bonePlacement;
  const std::string where = "engines/haptics/bone_placement";
  const std::shared_ptr<const Volume> fragment = resources.volume(b.fragment);
  if (!fragment)
    return fail(ErrorCode::NotFound, "resource \"" + b.fragment + "\" was not loaded as a volume",
                where + "/fragment");
  auto moving = ImplicitSphereTree::create(*fragment, b.threshold);
  if (!moving) return moving.error().within(where + "/fragment");
  const SceneObject* o = h.objects.empty() ? nullptr : scene.object(h.objects.front());
  const std::shared_ptr<const Volume> fixedVolume =
      o != nullptr && o->voxels ? resources.volume(o->voxels->volume) : nullptr;
  if (!fixedVolume)
    return fail(ErrorCode::NotFound, "the touched object's voxels were not loaded", where + "/objects");
  auto fixed = ImplicitSphereTree::create(*fixedVolume, o->voxels->threshold);
  if (!fixed) return fixed.error().within("objects/" + o->name + "/voxels");

  BonePlacementOptions opt;
  opt.couplingStiffness = b.couplingStiffness;
  opt.couplingDamping = b.couplingDamping;
  opt.couplingAngularStiffness = b.couplingAngularStiffness;
  opt.couplingAngularDamping = b.couplingAngularDamping;
  opt.mass = b.mass;
  opt.density = b.density;
  opt.threshold = b.threshold;
  opt.maxContacts = b.maxContacts;
  opt.iterations = b.iterations;
  opt.contactLevel = b.contactLevel;
  opt.slop = b.slop;
  opt.baumgarte = b.baumgarte;
  // The engine's max_force clamps here; without one the haptic loop clamps
  // to the device's limit.
  opt.maxForce = h.maxForce > 0 ? h.maxForce : std::numeric_limits<double>::infinity();
  opt.maxTorque = b.maxTorque;
  auto r = BonePlacementRenderer::create(*fixed, o->pose.isometry(), *moving, *fragment, opt);
  if (!r) return r.error().within(where);
  SceneBonePlacementTool tool;
  tool.renderer = std::move(*r);
  tool.referencePoints = boneReferencePoints(*fragment, b.threshold);
  for (std::size_t i = 0; i < fixedVolume->voxelCount(); ++i)
    tool.fixedVoxels += fixedVolume->valueAt(i) > o->voxels->threshold;
  return tool;
}

}  // namespace dm
