// scene_obstacles.cpp — the colliding bodies deforming objects meet
// (scene_obstacles.hpp).
#include "scene_obstacles.hpp"

#include <dm/io/scene_file.hpp>
#include <dm/io/scene_resources.hpp>
#include <dm/math/mesh_topology.hpp>
#include <dm/math/primitives.hpp>
#include <dm/physics/world.hpp>

#include <algorithm>

namespace dm {

namespace {

// The closed mesh a body is to deforming objects, in its shape frame
// (`objectToShape` from the object's frame at its scale).
Result<MeshBvh> obstacleTree(const SceneObject& o, const SceneResource& res, const Mesh& mesh,
                             const Isometry3& objectToShape) {
  Mesh m;
  if (res.type == SceneResource::Type::Shape && res.shape == SceneResource::Shape::Plane) {
    const double depth = 0.5 * std::min(res.halfExtents.x(), res.halfExtents.y());
    m = makeBox(Vec3(res.halfExtents.x(), res.halfExtents.y(), depth));
    m.transform(Affine3(Eigen::Translation3d(0, 0, -depth)));
  } else {
    m = mesh;
  }
  if (o.scale != 1.0) m.transform(Affine3(Eigen::Scaling(o.scale)));
  m.transform(Affine3(objectToShape.matrix()));
  if (auto w = weldVertices(m, 1e-9); !w) return w.error();
  auto tree = MeshBvh::build(m);
  if (!tree) return tree.error();
  if (!tree->isClosed())
    return fail(ErrorCode::InvalidArgument,
                "its mesh is not closed, so a deforming object cannot tell inside from outside", "mesh",
                "close it (an isosurface's \"close_borders\"), or set \"collide\": false on it");
  return tree;
}

}  // namespace

Result<std::vector<SceneObstacle>> sceneObstacles(const SceneDesc& scene, const SceneResources& resources,
                                                  const PhysicsWorld& world) {
  std::vector<SceneObstacle> out;
  for (std::size_t i = 0; i < world.bodyCount(); ++i) {
    const BodyDesc& d = world.bodies()[i];
    const SceneObject* o = scene.object(d.name);
    if (o == nullptr || !o->collide) continue;
    const SceneResource* res = scene.resource(o->mesh);
    auto mesh = resources.mesh(o->mesh);
    if (res == nullptr || !mesh)
      return fail(ErrorCode::NotFound, "mesh \"" + o->mesh + "\" was not loaded", "objects/" + o->name);
    Isometry3 shape = Isometry3::Identity();  // shape frame → world, at the start
    shape.translate(d.position);
    shape.rotate(d.orientation.normalized());
    shape = shape * d.shapeOffset;
    auto tree = obstacleTree(*o, *res, *mesh, shape.inverse() * o->pose.isometry());
    if (!tree) return tree.error().within("objects/" + o->name);
    out.push_back({o->name, BodyId{static_cast<std::uint32_t>(i)}, d.kind == BodyKind::Rigid, shape,
                   std::make_unique<MeshBvh>(std::move(*tree))});
  }
  return out;
}

}  // namespace dm
