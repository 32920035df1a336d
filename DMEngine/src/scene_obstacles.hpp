// scene_obstacles.hpp (private) — the bodies of a scene's physics world that
// deforming objects meet: every object that collides, static or dynamic, as
// a closed triangle tree in its body's shape frame. Soft tissue (through
// dm::SoftRigidCoupling) and membranes (through dm::ParticleObstacles) are
// kept out of them.
#pragma once

#include <dm/collide/bvh.hpp>
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>
#include <dm/physics/body.hpp>

#include <memory>
#include <string>
#include <vector>

namespace dm {

struct SceneDesc;
struct SceneResources;
class PhysicsWorld;

/// One colliding body of the world.
struct SceneObstacle {
  std::string name;               // the scene object's
  BodyId body;                    // in the physics world
  bool dynamic = false;           // a rigid body (else static)
  Isometry3 start;                // the shape frame in the world at the start
  std::unique_ptr<MeshBvh> tree;  // closed, the body's shape frame
};

/// Every body of `world` whose scene object collides, in body order: its
/// mesh welded (shapes keep separate rim vertices for sharp normals), or for
/// a plane the slab below it that the rigid world uses. Fails naming
/// "objects/<name>" on a mesh that is missing or not closed.
Result<std::vector<SceneObstacle>> sceneObstacles(const SceneDesc& scene, const SceneResources& resources,
                                                  const PhysicsWorld& world);

}  // namespace dm
