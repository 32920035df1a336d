// dm/renderer/scene_view.hpp — a scene file, rendered: the bridge between
// the scene description (dm/io/scene_file.hpp + scene_resources.hpp) and the
// mesh and volume renderers.
//
// create() uploads every mesh an object uses (once per resource, shared by
// objects), registers the materials, every volume entry (with its transfer
// function), the lights and the cameras. render() draws one camera at a
// time: opaque meshes first, then the volumes, whose rays stop at the mesh
// depth so a mesh inside a volume occludes what lies behind it; a stereo
// camera renders side by side. Engines move objects with setObjectPose()
// (a dynamic object, the haptic tool) and deform them with
// updateObjectMesh(), and draw particle sets (a fluid) with setParticles():
// as spheres, or as a screen-space liquid surface (setParticleSurface()).
// dmtool render and the render engine of
// `dmplatform run` both draw scenes through this class.
// All calls need the owning GlContext current on the calling thread.
//
// @code
//   auto scene = dm::readScene("examples/scenes/head_probe.json");
//   auto res = dm::loadSceneResources(*scene);
//   auto view = dm::SceneView::create(*scene, *res);
//   auto rt = dm::RenderTarget::create({.width = 640, .height = 480});
//   view->render(*rt, "", 0.0);                     // first camera at t = 0
//   dm::writePng(*rt->readColor(), "frame.png");
// @endcode
#pragma once

#include <dm/core/result.hpp>
#include <dm/core/types.hpp>
#include <dm/io/scene_file.hpp>
#include <dm/io/scene_resources.hpp>
#include <dm/renderer/camera.hpp>
#include <dm/renderer/fluid_renderer.hpp>
#include <dm/renderer/render_target.hpp>
#include <dm/renderer/scene_renderer.hpp>
#include <dm/renderer/volume_renderer.hpp>

#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace dm {

/// Options of a SceneView.
struct SceneViewOptions {
  SceneRendererOptions meshes;                 ///< shadow map size and biases
  Vec4f background{0.02f, 0.025f, 0.035f, 1};  ///< linear clear colour
  Vec3f ambient{0.04f, 0.04f, 0.045f};         ///< constant ambient irradiance, linear
  double volumeStepVoxels = 0.5;               ///< ray-casting sample spacing
};

/// What one SceneView::render() drew.
struct SceneFrameStats {
  RenderStats meshes;  ///< the mesh passes (both eyes for stereo)
  int volumes = 0;     ///< volume entries drawn
};

/// A scene on the GPU (see the file comment). Move-only.
class SceneView {
 public:
  /// Uploads the scene. Fails naming the object, material or volume entry
  /// whose data the renderers refuse (e.g. a volume above the 3-D texture
  /// limit), or when a resource an entry names was not loaded.
  static Result<SceneView> create(const SceneDesc& scene, const SceneResources& resources,
                                  const SceneViewOptions& options = {});

  SceneView();
  SceneView(SceneView&&) noexcept;
  SceneView& operator=(SceneView&&) noexcept;
  SceneView(const SceneView&) = delete;
  SceneView& operator=(const SceneView&) = delete;
  ~SceneView();

  /// Moves object `name` (object → world; its scale from the scene stays).
  /// NotFound for an unknown name.
  Status setObjectPose(std::string_view name, const Isometry3& pose);
  /// Shows or hides object `name`.
  Status setObjectVisible(std::string_view name, bool visible);
  /// Replaces the geometry of the mesh object `name` draws (in place when the
  /// topology is unchanged, as physics deformation does). Objects sharing
  /// that resource change with it.
  Status updateObjectMesh(std::string_view name, const Mesh& mesh);
  /// Draws the particle set `name` (a fluid) as spheres of `radius` m with
  /// the Blinn–Phong colour `color` (linear) at `positions` (world),
  /// replacing what the set drew before; the spheres share one mesh and
  /// material, so they go out as one instanced draw. Fails on a radius that
  /// is not positive and finite.
  Status setParticles(std::string_view name, std::span<const Vec3> positions, double radius,
                      const Vec4f& color);
  /// Draws particle set `name` as a screen-space fluid surface (see
  /// dm::FluidRenderer) with `look`, each particle a sphere of `drawRadius`
  /// m, instead of setParticles()' spheres (the positions still come from
  /// setParticles()); nullopt draws spheres again. Surfaces are drawn after
  /// the meshes, before the volumes, so rays stop at the fluid too. Fails
  /// on a drawRadius that is not positive and finite.
  Status setParticleSurface(std::string_view name, const std::optional<FluidLook>& look, double drawRadius);
  /// World pose of object `name`, NotFound for an unknown name.
  Result<Isometry3> objectPose(std::string_view name) const;

  /// The camera `name` ("" = the first camera; the scene's default framing
  /// when it has none) at time `t` s: path keys interpolated, tracking
  /// applied. NotFound for an unknown name.
  Result<Camera> camera(std::string_view name, double t) const;
  /// True when camera `name` is a stereo camera.
  bool isStereo(std::string_view name) const;

  /// Renders camera `name` at time `t` into the whole target (clears it).
  Result<SceneFrameStats> render(const RenderTarget& target, std::string_view cameraName, double t);
  /// Renders the scene seen by `camera` (mono; an editor's or a user's own
  /// view) into the whole target (clears it).
  Result<SceneFrameStats> render(const RenderTarget& target, const Camera& camera);

  /// The renderers, for extra draw items or settings.
  SceneRenderer& meshRenderer();
  VolumeRenderer& volumeRenderer();

 private:
  struct Impl;
  // Both render()s: stereo when `stereo` (the camera entry) is given.
  Result<SceneFrameStats> renderImpl(const RenderTarget& target, const Camera& camera, const SceneCamera* stereo);
  std::unique_ptr<Impl> impl_;
};

}  // namespace dm
