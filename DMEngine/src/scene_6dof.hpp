// scene_6dof.hpp (private) — the 6-DOF rigid-tool renderers of a scene run
// (docs/scene-format.md): "vps" — the tool resource sampled as a
// dm::PointShell, every touched object's mesh (scale baked in) voxelized
// into a dm::VoxelModel at its pose with its material's stiffness and
// damping, dm::VpsOptions from the "vps" block — and "sphere-tree" — tool
// and objects as octree sphere trees (dm::buildSphereTreeOctree), the
// options from the "sphere_tree" block — and "bone-placement" — the
// "bone_placement" block's fragment volume and the touched object's voxels
// as implicit sphere trees, dm::BonePlacementOptions from the block.
#pragma once

#include <dm/core/result.hpp>
#include <dm/haptics/bone_placement.hpp>
#include <dm/haptics/sphere_tree_6dof.hpp>
#include <dm/haptics/vps.hpp>

#include <memory>
#include <vector>

namespace dm {

struct SceneDesc;
struct SceneResources;

/// Builds it before anything runs; fails naming the block key or the
/// object (a tool or object mesh that is not closed, a voxel grid too large).
Result<std::unique_ptr<VpsRenderer>> buildSceneVps(const SceneDesc& scene, const SceneResources& resources);
Result<std::unique_ptr<SphereTree6DofRenderer>> buildSceneSphereTree(const SceneDesc& scene,
                                                                     const SceneResources& resources);

/// A scene's bone-placement renderer and what its summary measures with.
struct SceneBonePlacementTool {
  std::unique_ptr<BonePlacementRenderer> renderer;
  /// The fragment's reference points (its frame): its extreme voxels along
  /// ±x, ±y, ±z and the voxel nearest its centroid, whose RMS distance
  /// between the fragment's pose and the target pose is the alignment error.
  std::vector<Vec3> referencePoints;
  std::size_t fixedVoxels = 0;  ///< occupied voxels of the touched object
};
Result<SceneBonePlacementTool> buildSceneBonePlacement(const SceneDesc& scene,
                                                       const SceneResources& resources);

}  // namespace dm
