// dm/io/scene_resources.hpp — loads what a scene file's "resources" name:
// meshes and volumes from files (through the resource manager, so a file
// used twice is read once), generated volumes (CT-like phantoms,
// dm/math/phantom.hpp), isosurfaces extracted from volume resources,
// bone fragments and other segments cut from volumes, generated shapes, and
// images.
//
// The scene file itself is parsed by dm/io/scene_file.hpp; this turns its
// SceneResource entries into data-model objects shared read-only by every
// engine (the renderer uploads the meshes, haptics builds BVHs over them).
// Volumes load first, then what derives from them. The scene is held to a
// memory budget (SceneLoadOptions::maxBytes). Errors name the resource
// ("resources/skin: ...") and keep the loader's message (file, field, byte).
//
// @code
//   auto scene = dm::readScene("head_probe.json");
//   auto res = dm::loadSceneResources(*scene);
//   if (!res) return res.error();
//   std::shared_ptr<const dm::Mesh> skin = res->mesh("skin");
// @endcode
#pragma once

#include <dm/core/image.hpp>
#include <dm/core/mesh.hpp>
#include <dm/core/result.hpp>
#include <dm/core/volume.hpp>
#include <dm/io/scene_file.hpp>

#include <cstddef>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <string_view>

namespace dm {

class ResourceManager;

/// The loaded resources of a scene, by resource name.
struct SceneResources {
  std::map<std::string, std::shared_ptr<const Mesh>, std::less<>> meshes;  ///< Mesh, Isosurface, Shape
  std::map<std::string, std::shared_ptr<const Volume>, std::less<>> volumes;
  std::map<std::string, std::shared_ptr<const Image>, std::less<>> images;

  /// The mesh (file, isosurface or shape) named `name`, or null. O(log n).
  std::shared_ptr<const Mesh> mesh(std::string_view name) const;
  /// The volume named `name`, or null.
  std::shared_ptr<const Volume> volume(std::string_view name) const;
  /// The image named `name`, or null.
  std::shared_ptr<const Image> image(std::string_view name) const;
};

/// How to load.
struct SceneLoadOptions {
  /// A manager to load files through (its cache is shared with the caller);
  /// null: a private one with dm::registerIoLoaders().
  ResourceManager* resourceManager = nullptr;
  /// Called before each resource with its name and the fraction done; may be empty.
  std::function<void(std::string_view name, double fraction)> progress;
  /// The scene's memory budget, bytes: the voxels its phantoms declare are
  /// summed before any is generated, and the volumes, meshes and images
  /// count as they load (each held once); the resource that takes the total
  /// over it fails with InvalidArgument naming the total and the budget.
  /// Each file is also held to its reader's own budget before it allocates
  /// (VolumeReadOptions::maxBytes, MeshImportOptions::maxTriangles).
  std::size_t maxBytes = std::size_t{16} << 30;
};

/// Loads every resource of `scene`. Fails on the first resource that does
/// not load, naming it. Isosurfaces are extracted with closed borders
/// (watertight where the scan is cut), optionally from the volume averaged
/// over downsample³ voxel blocks (about downsample² fewer triangles: a light
/// mesh to draw), reduced to their largest component and Taubin-smoothed.
/// Shapes: icosphere (sphere), box, capsule, cylinder and plane, finer with
/// `subdivisions`. A volume with a `phantom` is generated
/// (dm::makeCalvariumPhantom), not read.
Result<SceneResources> loadSceneResources(const SceneDesc& scene, const SceneLoadOptions& options = {});

/// The volume of a resource with a `segment` made from `source` (the
/// volume it names): U8, 1 where the voxel's value is selected (above,
/// below, label), `outside` (the mask its "outside" names) is zero, a
/// nonzero voxel of `near` (its "near" mask) lies within the distance, and
/// its centre is inside the box; reduced to the largest 26-connected
/// component if asked; then on the kept side of every cut (by more than
/// half the kerf; "centroid": the plane through the centroid of what the
/// cuts divide), reduced to its largest component again; on the source's
/// grid, cropped to the kept voxels and one empty voxel around them, so
/// every voxel keeps its world position. The masks must be on the source's
/// grid. Fails naming "resources/<name>/segment/..." when a mask is missing
/// or on another grid, the box misses the volume, nothing is selected or
/// the cuts leave nothing. O(voxels of the box grown by the distance).
Result<Volume> makeSceneSegment(const SceneResource& resource, const Volume& source,
                                const Volume* outside = nullptr, const Volume* near = nullptr);

/// One part of a compound Shape resource as a Shape resource of its own (in
/// the part's frame, not yet placed by its pose): the compound's name,
/// subdivisions and source location (for errors), the part's shape and sizes.
SceneResource scenePartShape(const SceneResource& compound, const SceneResource::Part& part);

/// The generated mesh of one Shape resource (no file access). InvalidArgument
/// for a resource that is not a shape or has non-positive sizes.
Result<Mesh> makeSceneShape(const SceneResource& shape);

}  // namespace dm
