// scene_vps.hpp (private) — the VPS renderer of a scene run (the haptics
// engine's "renderer": "vps", docs/scene-format.md): the tool resource
// sampled as a dm::PointShell, every touched object's mesh (scale baked in)
// voxelized into a dm::VoxelModel at its pose with its material's
// stiffness and damping, the dm::VpsOptions from the "vps" block.
#pragma once

#include <dm/core/result.hpp>
#include <dm/haptics/vps.hpp>

#include <memory>

namespace dm {

struct SceneDesc;
struct SceneResources;

/// Builds it before anything runs; fails naming the block key or the
/// object (a tool or object mesh that is not closed, a voxel grid too large).
Result<std::unique_ptr<VpsRenderer>> buildSceneVps(const SceneDesc& scene, const SceneResources& resources);

}  // namespace dm
