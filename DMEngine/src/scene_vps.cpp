// scene_vps.cpp — a scene's VPS renderer from its "vps" block and touched
// objects (scene_vps.hpp).
#include "scene_vps.hpp"

#include <dm/collide/point_shell.hpp>
#include <dm/collide/voxel_model.hpp>
#include <dm/io/scene_file.hpp>
#include <dm/io/scene_resources.hpp>

#include <limits>

namespace dm {

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
    const SceneObject* o = scene.object(name);
    const SceneMaterial* material = o != nullptr ? scene.material(o->material) : nullptr;
    const std::shared_ptr<const Mesh> mesh = o != nullptr ? resources.mesh(o->mesh) : nullptr;
    if (o == nullptr || material == nullptr || !material->haptic || !mesh)
      return fail(ErrorCode::NotFound, "object \"" + name + "\" has no mesh or haptic material loaded",
                  "objects/" + name);
    Mesh scaled = *mesh;
    if (o->scale != 1.0) scaled.transform(Affine3(Eigen::Scaling(o->scale)));
    VoxelizeOptions vox;
    vox.voxelSize = v.voxelSize > 0 ? v.voxelSize : scaled.bounds().sizes().maxCoeff() / 128.0;
    auto model = VoxelModel::fromMesh(scaled, vox);
    if (!model) return model.error().within("objects/" + name + " (voxelized for the vps renderer)");
    HapticMaterial m;
    m.stiffness = material->haptic->stiffness;
    m.damping = material->haptic->damping;
    objects.push_back({*model, o->pose.isometry(), m});
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

}  // namespace dm
