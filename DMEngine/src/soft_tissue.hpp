// soft_tissue.hpp (private) — a scene's soft objects ("soft" blocks) as FEM
// bodies the physics engine steps, the god-object presses, fluids flow
// around and load (scene_fluids.hpp), and the render engine draws deformed.
//
// Per soft object: tetrahedra from its mesh (a box shape split into cubes
// of about voxel_size, its faces kept; any other closed mesh voxelized at
// voxel_size), a dm::FemBody in the object's frame (the scene's scale baked
// in) with the held faces fixed, gravity turned into that frame and every
// body of the physics world that collides an obstacle it cannot enter
// (dm::SoftRigidCoupling: a penalty spring per boundary node, implicit; a
// dynamic body's velocity solved with the tissue's, so the tissue carries
// and pushes it and it dents the tissue), and a
// dm::HapticTissue joining it to the god-object (stiffness of the object's
// haptic material, tip radius of the haptics engine's tool) — or, for the
// object with needle "layers", a dm::NeedleInsertion (each tetrahedron's
// layer from its depth below the top face) felt through a dm::HapticNeedle,
// the haptics engine's renderer, whose step() runs here — or, for the
// object the punch renderer's "punch" names, its nodes in the punch's region
// held and moved with the tool (a rigid indenter bonded to the tissue), the
// tissue's force on them felt by the hand.
//
// Data flow (docs/architecture.md, "Scene runtime"):
//   haptics → HapticTissue grip → step() (physics thread): the world's
//   bodies' poses and velocities in, the touched point pulled toward the
//   device point, implicitly; FEM step; the bodies' new velocities out,
//   before the world's step;
//   step() → HapticTissue surface → the god-object (haptic thread);
//   step() → a TripleBuffer of surface positions → latestSurface()
//   (render thread).
// step() allocates nothing (a failed FEM step's message aside).
#pragma once

#include <dm/core/mesh.hpp>
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>

#include <nlohmann/json.hpp>

#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace dm {

struct SceneDesc;
struct SceneResources;
struct SceneObstacle;
class FemBody;
class HapticRenderer;
class HapticTissue;
class PhysicsWorld;
class WorldState;
struct SceneHapticsEngine;
struct SceneSoftLayer;
struct TetMesh;

class SoftTissues {
 public:
  /// Every soft object of `scene` (which has engines.physics), in scene
  /// order. Fails naming the object (a mesh that cannot be filled, more
  /// tetrahedra than its max_tets, a bad material) before anything runs.
  /// `world` holds the scene's rigid and static bodies (the physics
  /// engine's; it outlives this).
  static Result<std::unique_ptr<SoftTissues>> build(const SceneDesc& scene, const SceneResources& resources,
                                                    const PhysicsWorld& world);
  ~SoftTissues();
  SoftTissues(const SoftTissues&) = delete;
  SoftTissues& operator=(const SoftTissues&) = delete;

  /// Names of the soft objects, in scene order.
  const std::vector<std::string>& names() const noexcept { return names_; }
  /// The god-object's side of soft object `name`, nullptr when it is not
  /// one or a needle goes into it.
  HapticTissue* tissue(std::string_view name) noexcept;
  /// The needle renderer (dm::HapticNeedle) going into the soft object with
  /// "layers", for the haptics engine's loop; nullptr without one. Owned
  /// here: its step() is the physics thread's.
  HapticRenderer* needle() noexcept;
  /// The punch renderer bonded to a soft object (the haptics engine's
  /// "punch"), for the haptics engine's loop; nullptr without one. Owned
  /// here: its step() is the physics thread's.
  HapticRenderer* punch() noexcept;
  /// Physics thread, after step(): the needle's membranes broken so far,
  /// the layer at its tip (-1 outside) and the soft object it goes into
  /// (index in names()); nullopt without a needle.
  struct NeedleProgress {
    std::size_t punctures = 0;
    int tipLayer = -1;
    std::size_t object = 0;
  };
  std::optional<NeedleProgress> needleProgress() const noexcept;
  /// Layer `layer` of soft object i's needle layers by name ("" when there
  /// is none). Any thread: the names are fixed at build.
  std::string layerName(std::size_t i, int layer) const;

  /// Physics thread: steps every body by h against the bodies' poses and
  /// velocities in `state`, leaving each dynamic body the velocity the
  /// tissue gave it (the world's step comes next); fails naming the object
  /// whose step failed (a blown-up state).
  Status step(double h, WorldState& state);

  /// Physics thread: soft object i's FEM nodes in the world, positions into
  /// `x` and velocities into `v` (resized to its nodes: no allocation once
  /// sized), for a fluid that flows around it.
  void worldNodes(std::size_t i, std::vector<Vec3>& x, std::vector<Vec3>& v) const;
  /// Physics thread: forces on soft object i's FEM nodes (world frame, one
  /// per node: a fluid's loads), held over its following steps until set
  /// again. Allocation-free.
  void setFluidLoads(std::size_t i, std::span<const Vec3> world);
  /// Soft object i's boundary triangles over its FEM nodes (CCW from
  /// outside); fixed at build.
  const std::vector<Triangle>& boundaryTriangles(std::size_t i) const;

  /// Render thread (one reader): soft object i's surface (object frame,
  /// before the object's scale) when a step finished since the last call,
  /// and on the first call; its triangles are set on the first call and
  /// stay, its positions are overwritten.
  bool latestSurface(std::size_t i, Mesh& out);

  /// Control thread, after the run: adds the force (N, world) each soft
  /// object's contact put on each body of the physics world in the last
  /// step to `force` (indexed by the world's body index).
  void addBodyForces(std::span<Vec3> force) const;
  /// Control thread, after the run: each body's model, solver counters,
  /// deformation and the forces on it (world frame).
  nlohmann::json summary() const;

 private:
  struct Body;
  class PunchTool;
  SoftTissues() = default;
  static void drawnSurface(const FemBody& fem, bool creases, Body& b);
  Status attachNeedle(Body& b, std::span<const std::uint8_t> layerOfTet,
                      const std::vector<SceneSoftLayer>& layers, const SceneHapticsEngine& h,
                      double tipStiffness);
  static Vec3 toolForce(const Body& b) noexcept;
  std::vector<SceneObstacle> obstacles_;  // before bodies_: their FemObstacles point into it
  std::vector<std::unique_ptr<Body>> bodies_;
  std::vector<std::string> names_;
};

}  // namespace dm
