// dm/haptics/probe_renderers.hpp — the haptic renderers `dmtool probe`
// replays a device path through, built from an environment (a mesh or a
// volume at the identity pose) the way it builds them:
//  - godobject: the 3-DOF proxy (or a ball tip of toolRadius) on the mesh,
//    or on a volume's closed isosurface at `threshold` (required then);
//  - vps: the tool (a mesh, or a ball of toolRadius, default 2 mm) sampled
//    into a point shell at a twentieth of its size (at most half a voxel)
//    against a voxel model — a volume's occupancy above `threshold`, a
//    signed distance volume without one, or a mesh voxelized at voxelSize
//    (default: its largest extent / 128); the hand feels the virtual
//    coupling (k_c = material.stiffness) in series with a contact ten times
//    stiffer, per-point depths clamped only beyond the tool's own size;
//  - spheretree: octree sphere trees of the environment (`levels`) and of
//    the tool (to `toolLevel`), the 6-DOF constraint renderer;
//  - burr: a sphere burr of toolRadius (default 2 mm) at `rpm` drilling a
//    volume — a signed distance (negative inside) or, with boneRange, the
//    intensities of empty space and full bone.
// dmtool probe and Python's dmplatform.god_object / vps / sphere_tree / burr
// share them, so a path replays to the same bytes either way.
//
// @code
//   auto r = dm::makeVpsProbe({.volume = &sdf}, {.material = {.stiffness = 800}});
//   auto samples = dm::replayDevicePath(**r, path, 1000.0);
// @endcode
#pragma once

#include <dm/core/result.hpp>
#include <dm/core/types.hpp>
#include <dm/haptics/renderer.hpp>

#include <array>
#include <memory>
#include <optional>

namespace dm {

struct Mesh;
class Volume;
class MillableVolume;

/// The environment a probe renderer touches, at the identity pose: exactly
/// one of a mesh and a volume.
struct ProbeEnvironment {
  const Mesh* mesh = nullptr;
  const Volume* volume = nullptr;
};

/// How makeGodObjectProbe() and the others build their renderer (see the
/// file comment for what each renderer takes).
struct ProbeRendererOptions {
  HapticMaterial material;          ///< N/m (vps: the coupling), N·s/m, friction
  std::optional<double> threshold;  ///< volumes: solid where value > threshold
  double toolRadius = 0.0;          ///< m, ≥ 0; 0: a point (godobject), 2 mm (the others)
  const Mesh* tool = nullptr;       ///< vps, spheretree: the tool; nullptr: a ball of toolRadius
  double voxelSize = 0.0;           ///< vps on a mesh, m; 0: the mesh's largest extent / 128
  int levels = 6;                   ///< spheretree: levels of the environment's tree, 2..10
  int toolLevel = 4;                ///< spheretree: the tool tree's colliding level, 1..8
  std::optional<double> rpm;        ///< burr: revolutions per minute; none: dm::BurrOptions' default
  std::optional<std::array<double, 2>> boneRange;  ///< burr on CT/MRI: intensities of empty and full bone
};

/// The god-object renderer over the environment. InvalidArgument for a
/// volume without a threshold, or what building the mesh's tree fails with.
Result<std::unique_ptr<HapticRenderer>> makeGodObjectProbe(const ProbeEnvironment& env,
                                                           const ProbeRendererOptions& options);
/// The voxel point shell renderer (dm::VpsRenderer) over the environment.
Result<std::unique_ptr<HapticRenderer>> makeVpsProbe(const ProbeEnvironment& env,
                                                     const ProbeRendererOptions& options);
/// The 6-DOF sphere-tree renderer (dm::SphereTree6DofRenderer).
Result<std::unique_ptr<HapticRenderer>> makeSphereTreeProbe(const ProbeEnvironment& env,
                                                            const ProbeRendererOptions& options);
/// The burr (dm::BurrRenderer) drilling the environment's volume; `bone`
/// receives the bone it drills (for the volume removed and its surface).
/// InvalidArgument for a mesh, a tool mesh or a threshold (a burr is a
/// sphere on a volume).
Result<std::unique_ptr<HapticRenderer>> makeBurrProbe(const ProbeEnvironment& env,
                                                      const ProbeRendererOptions& options,
                                                      std::shared_ptr<MillableVolume>& bone);

}  // namespace dm
