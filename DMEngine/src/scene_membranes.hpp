// scene_membranes.hpp (private) — a scene's membranes ("membrane" blocks) as
// viscoelastic mass–spring bodies the physics engine steps and the render
// engine draws deformed.
//
// Per membrane object: its triangle mesh placed in the world (pose and
// scale), a dm::MassSpringBody::fromMesh over it (a particle per vertex
// carrying its lumped area's share of the mass, a Kelvin–Voigt or Maxwell
// element per edge, optional bend elements across interior edges), the
// scene's gravity, a drag, and its boundary vertices and the vertices in
// its pinned boxes held; stepped by the linearly implicit Euler step
// (stable at the physics rate for any stiffness) together with the world's
// colliding objects, static and dynamic (dm::MembraneRigidCoupling: Coulomb
// friction, the membrane's thickness, no passing through thin ones; a
// dynamic body falls onto, rests on or pushes the membrane, and the
// membrane holds it up or pushes it back). A membrane does not meet the
// tool, soft tissue or fluids in this build (the scene parser refuses each
// of those).
//
// Data flow: step() (physics thread, before the world's step: it leaves
// the bodies it touches the velocity its contact gave them) → a
// TripleBuffer of vertex positions (object frame, before the scale) →
// latestSurface() (render thread, one reader). step() allocates nothing
// after its first call.
#pragma once

#include <dm/core/mesh.hpp>
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>

#include <nlohmann/json.hpp>

#include <memory>
#include <span>
#include <string>
#include <vector>

namespace dm {

struct SceneDesc;
struct SceneResources;
struct SceneObstacle;
class PhysicsWorld;
class WorldState;

class SceneMembranes {
 public:
  /// Every membrane of `scene` (which has engines.physics), in scene order,
  /// each meeting the colliding bodies of `world` (which outlives this).
  /// Fails naming the object (a mesh the mass–spring builder refuses: an
  /// unused vertex, no triangle; an open obstacle mesh) before anything
  /// runs.
  static Result<std::unique_ptr<SceneMembranes>> build(const SceneDesc& scene,
                                                       const SceneResources& resources,
                                                       const PhysicsWorld& world);
  ~SceneMembranes();
  SceneMembranes(const SceneMembranes&) = delete;
  SceneMembranes& operator=(const SceneMembranes&) = delete;

  /// Names of the membranes, in scene order.
  const std::vector<std::string>& names() const noexcept { return names_; }
  /// Physics thread, before the world's step: steps every membrane by h
  /// with the bodies of `state` (a state of the world given to build());
  /// fails naming the membrane whose step failed (a non-finite state).
  Status step(double h, WorldState& state);
  /// Render thread (one reader): membrane i's mesh (object frame, before
  /// the object's scale) when a step finished since the last call, and on
  /// the first call; its triangles are set on the first call and stay.
  bool latestSurface(std::size_t i, Mesh& out);
  /// Adds to force[world body index] what the membranes put on each body
  /// they meet over the last step (N, world).
  void addBodyForces(std::span<Vec3> force) const;
  /// Control thread, after the run: each membrane's size, what its pins
  /// and the objects it rests on carry, its deformation and its solver
  /// counters.
  nlohmann::json summary() const;

 private:
  struct Body;
  SceneMembranes() = default;
  std::vector<SceneObstacle> obstacles_;  // their trees outlive bodies_' couplings
  std::vector<std::unique_ptr<Body>> bodies_;
  std::vector<std::string> names_;
};

}  // namespace dm
