// render_engine.hpp (private) — the render engine of a scene run: a headless
// GL context owned by whichever thread ticks it, dm::SceneView, a HUD, and a
// writer thread for the frames. Compiled only when DMRenderer exists.
#pragma once

#include <dm/core/image.hpp>
#include <dm/core/mesh.hpp>
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>
#include <dm/engine/engine.hpp>

#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace dm {

class FrameSlot;
struct ViewOrbit;
struct SceneDesc;
struct SceneResources;

/// What the render engine reads from the others each frame (render thread).
struct RenderFeed {
  /// The haptic proxy pose (world) and the force sent (world, N); false
  /// when there is no haptic engine.
  std::function<bool(Isometry3& proxy, Vec3& force)> haptics;
  /// |F| over the last seconds at the haptic rate, oldest first (copied).
  std::function<void(std::vector<float>& out, double& seconds)> recentForce;
  /// Objects the physics engine moves, and their newest poses (object →
  /// world) in that order; objectPoses returns false when no step finished
  /// since the last call (the objects stay where they were drawn).
  std::vector<std::string> movingObjects;
  std::function<bool(std::vector<Isometry3>& poses)> objectPoses;
  /// The object a burr mills, and its surface: true (and the whole surface)
  /// when it changed since the last call and on the first call
  /// (dm::MillableSurfaceFeed::update); empty when nothing is milled.
  std::string millableObject;
  std::function<Result<bool>(Mesh& surface)> millableSurface;
  /// Soft objects physics deforms, and soft object i's surface (its frame,
  /// before its scale): true when it changed since the last call and on the
  /// first call; triangles set on the first call, positions every time.
  std::vector<std::string> softObjects;
  std::function<bool(std::size_t i, Mesh& surface)> softSurface;
  /// The fluids physics steps (their name, drawn radius and colour), and
  /// fluid i's particles (world): true when a step finished since the last
  /// call.
  struct FluidLook {
    std::string name;
    double radius = 0.0;  ///< the spheres' (half the spacing)
    Vec4f color = Vec4f(0.35f, 0.01f, 0.01f, 1.0f);
    /// A liquid surface (dm::FluidLook) instead of spheres: its particles
    /// drawn 3/4 of a spacing wide (closing a cubic lattice's gaps, √2/2 of
    /// a spacing), each standing for a spacing cubed of fluid.
    bool surface = false;
    Vec3f absorption = Vec3f::Zero();  ///< 1/m per channel
    float fresnel = 0.02f, specular = 1.0f, shininess = 200.0f, refraction = 12.0f;
    int smoothing = 3;
  };
  std::vector<FluidLook> fluids;
  std::function<bool(std::size_t i, std::vector<Vec3>& positions)> fluidParticles;
  /// Where every frame goes, read back (RGBA) before the HUD and overlays
  /// are drawn (the camera's view), for the OpenIGTLink and vision engines;
  /// null: frames are read back only to be written.
  std::shared_ptr<FrameSlot> frames;
  /// Where every frame goes as written (the HUD and overlays drawn), for a
  /// live view; null: none.
  std::shared_ptr<FrameSlot> shown;
  /// A live view's turn of the camera (dm::ViewOrbit): true and the newest
  /// when it changed since the last call; may be empty.
  std::function<bool(ViewOrbit& orbit)> viewOrbit;
  /// An image drawn over the frames' lower-left corner (a vision graph's
  /// "texture" sink): true and the newest image and its frame number once
  /// there is one. Render thread; the producer never rewrites a handed-out image.
  std::function<bool(Image& image, std::int64_t& frame)> overlay;
};

/// Counters of a render engine (control thread, after stop).
struct RenderEngineStats {
  std::uint64_t frames = 0;         ///< frames rendered
  std::uint64_t framesWritten = 0;  ///< PNGs written
  std::uint64_t framesDropped = 0;  ///< real time: frames the writer could not keep up with
  std::string glRenderer;           ///< GL_RENDERER
  std::string eglPlatform;          ///< "device" or "surfaceless"
  double renderMsP50 = 0, renderMsMax = 0;
};

/// The engine (to add to the master) and its counters.
class RenderEngineHandle {
 public:
  virtual ~RenderEngineHandle() = default;
  virtual std::shared_ptr<Engine> engine() = 0;
  virtual RenderEngineStats stats() const = 0;
};

/// Builds the render engine (creates the context on the calling thread and
/// releases it). `framesDir` empty: no frames written. `blockOnWriter`:
/// wait for the PNG writer instead of dropping frames (lockstep).
Result<std::shared_ptr<RenderEngineHandle>> makeRenderEngine(const SceneDesc& scene,
                                                             const SceneResources& resources, RenderFeed feed,
                                                             const std::filesystem::path& framesDir,
                                                             int frameEvery, bool blockOnWriter);

}  // namespace dm
