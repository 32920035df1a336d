// scene_6dof.hpp (private) — the 6-DOF rigid-tool renderers of a scene run
// (docs/scene-format.md): "vps" — the tool resource sampled as a
// dm::PointShell, every touched object's mesh (scale baked in) voxelized
// into a dm::VoxelModel at its pose with its material's stiffness and
// damping, dm::VpsOptions from the "vps" block — and "sphere-tree" — tool
// and objects as octree sphere trees (dm::buildSphereTreeOctree), the
// options from the "sphere_tree" block.
#pragma once

#include <dm/core/result.hpp>
#include <dm/haptics/sphere_tree_6dof.hpp>
#include <dm/haptics/vps.hpp>

#include <memory>

namespace dm {

struct SceneDesc;
struct SceneResources;

/// Builds it before anything runs; fails naming the block key or the
/// object (a tool or object mesh that is not closed, a voxel grid too large).
Result<std::unique_ptr<VpsRenderer>> buildSceneVps(const SceneDesc& scene, const SceneResources& resources);
Result<std::unique_ptr<SphereTree6DofRenderer>> buildSceneSphereTree(const SceneDesc& scene,
                                                                     const SceneResources& resources);

}  // namespace dm
