// The renderers dmtool probe and Python build from an environment
// (probe_renderers.hpp).
#include <dm/collide/bvh.hpp>
#include <dm/collide/point_shell.hpp>
#include <dm/collide/sphere_tree.hpp>
#include <dm/collide/voxel_model.hpp>
#include <dm/haptics/burr.hpp>
#include <dm/haptics/god_object.hpp>
#include <dm/haptics/probe_renderers.hpp>
#include <dm/haptics/sphere_tree_6dof.hpp>
#include <dm/haptics/vps.hpp>
#include <dm/math/isosurface.hpp>
#include <dm/math/primitives.hpp>

#include <algorithm>
#include <limits>

namespace dm {

namespace {

Status checkEnvironment(const ProbeEnvironment& env) {
  if ((env.mesh == nullptr) == (env.volume == nullptr))
    return fail(ErrorCode::InvalidArgument, "give a mesh or a volume, one of them", "model");
  return ok();
}

double largestExtent(const Aabb& box) { return box.isEmpty() ? 0.0 : box.sizes().maxCoeff(); }

// The tool: the given mesh, or a ball of the tool radius (default 2 mm).
Mesh toolMesh(const ProbeRendererOptions& o) {
  if (o.tool != nullptr) return *o.tool;
  return makeIcosphere(o.toolRadius > 0 ? o.toolRadius : 2e-3, 3);
}

Result<std::shared_ptr<const VoxelModel>> voxelModel(const ProbeEnvironment& env,
                                                     const ProbeRendererOptions& o) {
  if (env.volume != nullptr) {
    if (o.threshold) return VoxelModel::fromOccupancy(*env.volume, *o.threshold);
    return VoxelModel::fromSdf(*env.volume);
  }
  VoxelizeOptions vox;
  vox.voxelSize = o.voxelSize > 0 ? o.voxelSize : largestExtent(env.mesh->bounds()) / 128.0;
  return VoxelModel::fromMesh(*env.mesh, vox);
}

}  // namespace

Result<std::unique_ptr<HapticRenderer>> makeGodObjectProbe(const ProbeEnvironment& env,
                                                           const ProbeRendererOptions& o) {
  if (auto s = checkEnvironment(env); !s) return s.error();
  Mesh mesh;
  if (env.mesh != nullptr) {
    mesh = *env.mesh;
  } else {
    // A volume: the closed isosurface around the solid (value > threshold).
    if (!o.threshold)
      return fail(ErrorCode::InvalidArgument, "godobject on a volume needs a threshold", "threshold",
                  "give the value above which a voxel is solid, e.g. 300 for bone in CT");
    auto m = extractIsosurface(*env.volume, {.iso = *o.threshold, .closeBorders = true});
    if (!m) return m.error();
    mesh = std::move(*m);
  }
  auto bvh = MeshBvh::build(mesh);
  if (!bvh) return bvh.error();
  std::vector<GodObjectObject> objects(1);
  objects[0].bvh = std::make_shared<const MeshBvh>(std::move(*bvh));
  objects[0].material = o.material;
  auto r = GodObjectRenderer::create(std::move(objects), {.proxyRadius = o.toolRadius});
  if (!r) return r.error();
  return std::unique_ptr<HapticRenderer>(std::move(*r));
}

Result<std::unique_ptr<HapticRenderer>> makeVpsProbe(const ProbeEnvironment& env,
                                                     const ProbeRendererOptions& o) {
  if (auto s = checkEnvironment(env); !s) return s.error();
  auto model = voxelModel(env, o);
  if (!model) return model.error();
  const Mesh tool = toolMesh(o);
  const double spacing =
      std::max(largestExtent(tool.bounds()) / 20.0, (*model)->indexToWorld().linear().col(0).norm() / 2);
  auto shell = PointShell::fromMesh(tool, {.spacing = spacing});
  if (!shell) return shell.error().within("tool");
  // The hand feels the virtual coupling (k_c = stiffness) in series with
  // the contact, made ten times stiffer so that it dominates; per-point
  // depths are clamped only beyond the tool's own size.
  HapticMaterial contact = o.material;
  contact.stiffness = 10.0 * o.material.stiffness;
  VpsOptions options;
  options.couplingStiffness = o.material.stiffness;
  options.maxPointDepth = std::max(options.maxPointDepth, 0.5 * largestExtent(tool.bounds()));
  options.maxForce = options.maxTorque = std::numeric_limits<double>::infinity();
  auto r = VpsRenderer::create(*shell, {{*model, Isometry3::Identity(), contact}}, options);
  if (!r) return r.error();
  return std::unique_ptr<HapticRenderer>(std::move(*r));
}

Result<std::unique_ptr<HapticRenderer>> makeSphereTreeProbe(const ProbeEnvironment& env,
                                                            const ProbeRendererOptions& o) {
  if (auto s = checkEnvironment(env); !s) return s.error();
  SphereTreeOptions st;
  st.levels = o.levels;
  if (o.threshold) st.threshold = *o.threshold;
  auto envTree =
      env.mesh != nullptr ? buildSphereTreeOctree(*env.mesh, st) : buildSphereTreeOctree(*env.volume, st);
  if (!envTree) return envTree.error();
  SphereTreeOptions toolOptions;
  toolOptions.levels = o.toolLevel + 1;
  auto toolTree = buildSphereTreeOctree(toolMesh(o), toolOptions);
  if (!toolTree) return toolTree.error().within("tool");
  std::vector<SphereTreeObject> objects(1);
  objects[0].tree = *envTree;
  objects[0].material = o.material;
  objects[0].name = "model";
  SphereTree6DofOptions options;
  options.toolLevel = o.toolLevel;
  options.linearStiffness = Vec3::Constant(o.material.stiffness);
  auto r = SphereTree6DofRenderer::create(*toolTree, std::move(objects), options);
  if (!r) return r.error();
  return std::unique_ptr<HapticRenderer>(std::move(*r));
}

Result<std::unique_ptr<HapticRenderer>> makeBurrProbe(const ProbeEnvironment& env,
                                                      const ProbeRendererOptions& o,
                                                      std::shared_ptr<MillableVolume>& bone) {
  if (auto s = checkEnvironment(env); !s) return s.error();
  if (env.volume == nullptr)
    return fail(ErrorCode::InvalidArgument, "burr drills a volume, not a mesh", "model",
                "give a signed distance volume (negative inside) or a CT/MRI volume with a bone range");
  if (o.tool != nullptr)
    return fail(ErrorCode::InvalidArgument, "a tool mesh does not apply to burr", "tool",
                "burr takes a sphere of the tool radius");
  if (o.threshold)
    return fail(ErrorCode::InvalidArgument, "a threshold does not apply to burr", "threshold",
                "give a bone range (the intensities of empty space and full bone) for intensity volumes");
  auto made = o.boneRange ? MillableVolume::fromIntensity(*env.volume, (*o.boneRange)[0], (*o.boneRange)[1])
                          : MillableVolume::fromSdf(*env.volume);
  if (!made) return made.error();
  bone = std::make_shared<MillableVolume>(std::move(*made));
  BurrOptions options;
  options.tool = MillingTool::sphere(o.toolRadius > 0 ? o.toolRadius : 2e-3);
  options.stiffness = o.material.stiffness;
  options.damping = o.material.damping;
  if (o.rpm) options.rpm = *o.rpm;
  auto r = BurrRenderer::create(bone, options);
  if (!r) return r.error();
  return std::unique_ptr<HapticRenderer>(std::move(*r));
}

}  // namespace dm
