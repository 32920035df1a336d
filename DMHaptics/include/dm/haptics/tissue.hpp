// dm/haptics/tissue.hpp — feeling and deforming FEM tissue with the
// god-object: forces from the soft-body state, tissue deformed by the tool.
//
// dm::HapticTissue joins a dm::FemBody (physics thread, e.g. 100 Hz) to a
// dm::GodObjectRenderer object (haptic thread, 1 kHz) through two triple
// buffers, so neither thread waits for the other:
//  * surface, physics → haptics: after each FEM step the body's boundary
//    tree (dm::MeshBvh over FemBody::surfaceTriangles(), every node a
//    vertex) is refitted to the new positions in a spare copy and published;
//    the haptic thread hands the newest one to GodObjectRenderer::
//    deformObject() before its tick, which carries a touching proxy with
//    the surface;
//  * grip, haptics → physics: after the tick, the god-object's contact
//    (triangle, barycentric point, normal) and the device point are
//    published; the next FEM step pulls the touched point toward the device
//    point, offset by the tip radius, with a spring of the haptic
//    stiffness, integrated implicitly (FemBody::setContactSpring). At
//    equilibrium the tissue feels exactly the force the hand feels, reversed:
//    k·(device − surface) = −k·(proxy − device); the haptic spring and the
//    tissue's point stiffness k_t act in series, F = d / (1/k + 1/k_t) for a
//    device pressed d below the rest surface.
// The spring on the tissue is implicit because an explicit one (the last
// haptic force applied as a nodal load) is unstable: a spring of hundreds of
// N/m on nodes of a few milligrams at 100 Hz.
// Frames: the body's coordinates are the object's local frame; forces and
// points are converted with the object's pose in the renderer.
//
// Threads: applyTo() and publishGrip() on the haptic thread (no allocation,
// lock, log or throw); step() on one physics thread. dm::TissueGodObject
// makes the pair one HapticRenderer, so a HapticLoop (real time or lockstep)
// drives it like any renderer.
//
// @code
//   auto tissue = dm::HapticTissue::create(body, {.stiffness = 800, .tipRadius = 0.002});
//   objects.push_back({.bvh = (*tissue)->restTree(), .material = {.stiffness = 800}});
//   // haptic tick:  tissue->applyTo(*godObject, 0); out = godObject->tick(in);
//   //               tissue->publishGrip(*godObject, 0, in.devicePose.translation());
//   // physics tick: tissue->step(0.01);
// @endcode
#pragma once

#include <dm/collide/bvh.hpp>
#include <dm/core/result.hpp>
#include <dm/core/triple_buffer.hpp>
#include <dm/core/types.hpp>
#include <dm/haptics/god_object.hpp>
#include <dm/physics/fem.hpp>

#include <array>
#include <atomic>
#include <cstdint>
#include <memory>
#include <span>
#include <string_view>
#include <vector>

namespace dm {

/// Options of HapticTissue::create().
struct HapticTissueOptions {
  /// N/m, > 0: the haptic material's stiffness for this object (the spring
  /// between proxy and device, which the tissue feels reversed).
  double stiffness = 800.0;
  /// m, >= 0: the god-object's proxyRadius plus its skin (the device point
  /// sits this far from the surface point it pulls, along the normal).
  double tipRadius = 0.0;
  BvhBuildOptions tree;  ///< options of the boundary tree
};

/// See the file comment. Not copyable or movable (the renderer points into
/// its buffers).
class HapticTissue {
 public:
  /// Builds the boundary tree of `body` at its current positions and the
  /// exchange buffers. `body` must outlive the HapticTissue and be stepped
  /// only through step() while it is in use. Fails (InvalidArgument) on a
  /// stiffness that is not positive and finite, a negative or non-finite
  /// tipRadius, or a body without boundary triangles.
  static Result<std::unique_ptr<HapticTissue>> create(FemBody& body, const HapticTissueOptions& options = {});
  HapticTissue(const HapticTissue&) = delete;
  HapticTissue& operator=(const HapticTissue&) = delete;

  /// The boundary tree at creation (local frame), for GodObjectObject::bvh.
  /// Its vertices are the body's nodes, its triangles surfaceTriangles().
  std::shared_ptr<const MeshBvh> restTree() const noexcept { return rest_; }

  // --- haptic thread -------------------------------------------------------
  /// Hands the newest surface physics published since the last call to
  /// renderer.deformObject(object, ...); true if it did. Call before the
  /// renderer's tick. Real-time safe.
  bool applyTo(GodObjectRenderer& renderer, std::size_t object) noexcept;
  /// Publishes the tool's grip after the renderer's tick: the contact of
  /// `object` (if the proxy touches it) and the device point (world, m).
  /// Real-time safe.
  void publishGrip(const GodObjectRenderer& renderer, std::size_t object, const Vec3& devicePoint) noexcept;

  // --- physics thread ------------------------------------------------------
  /// Takes the newest grip (as the body's contact spring, or none), steps
  /// the body by h (FemBody::step) and publishes its refitted surface.
  /// Fails as FemBody::step does; the surface is then not published.
  Result<FemStepReport> step(double h);
  /// The force (N, body frame) the tool applied to the tissue at the last
  /// step's end; zero without contact.
  Vec3 toolForce() const noexcept { return body_->contactSpringForce(); }
  /// Steps taken with the tool in contact / surfaces published, so far.
  std::uint64_t grippedSteps() const noexcept { return grippedSteps_; }
  std::uint64_t publishedSurfaces() const noexcept { return published_.load(std::memory_order_relaxed); }

 private:
  struct Grip {
    bool active = false;
    std::array<std::uint32_t, 3> nodes{};  // the touched triangle's nodes
    Vec3 weights = Vec3::Zero();           // barycentric on them
    Vec3 anchor = Vec3::Zero();   // body frame, m
  };
  HapticTissue(FemBody& body, const HapticTissueOptions& options, MeshBvh rest);

  FemBody* body_;
  HapticTissueOptions options_;
  std::shared_ptr<const MeshBvh> rest_;
  TripleBuffer<MeshBvh> surfaces_;
  TripleBuffer<Grip> grips_;
  std::uint64_t grippedSteps_ = 0;
  std::atomic<std::uint64_t> published_{0};
};

/// Which renderer object a HapticTissue deforms.
struct TissueBinding {
  HapticTissue* tissue = nullptr;
  std::size_t object = 0;  ///< object index in the GodObjectRenderer
};

/// The god-object with its tissues as one HapticRenderer: each tick hands
/// the newest surfaces to the renderer (HapticTissue::applyTo), ticks it and
/// publishes the grips at the device point (publishGrip). Poses and reset
/// go to the god-object. Real-time safe like its parts.
/// @code
///   dm::TissueGodObject felt(*godObject, {{tissue.get(), 0}});
///   auto loop = dm::HapticLoop::create({.device = *device, .renderer = felt});
/// @endcode
class TissueGodObject final : public HapticRenderer {
 public:
  /// `renderer` and every tissue must outlive this; bindings with a null
  /// tissue or an object index out of range are dropped.
  TissueGodObject(GodObjectRenderer& renderer, std::span<const TissueBinding> tissues);
  std::string_view name() const noexcept override { return "godobject-tissue"; }
  void reset(const Isometry3& devicePose) noexcept override { renderer_->reset(devicePose); }
  HapticResponse tick(const HapticInput& input) noexcept override;
  std::size_t objectCount() const noexcept override { return renderer_->objectCount(); }
  void setObjectPose(std::size_t index, const Isometry3& pose) noexcept override {
    renderer_->setObjectPose(index, pose);
  }
  GodObjectRenderer& godObject() noexcept { return *renderer_; }

 private:
  GodObjectRenderer* renderer_;
  std::vector<TissueBinding> tissues_;
};

}  // namespace dm
