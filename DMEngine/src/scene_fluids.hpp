// scene_fluids.hpp (private) — a scene's particle fluids ("fluids", v2) as
// the physics engine steps them: each a dm::SphFluid with its container,
// starting blocks, region of interest (dm::FluidRegion), inlets
// (dm::FluidInlet: cut vessels and irrigation, open over their time window)
// and suction tips (dm::FluidSuction: fixed, or at the haptic tool's proxy).
//
// A fluid's "objects" are boundaries: a static object's surface (its mesh
// at its pose and scale) sampled once as walls (dm::sampleBoundary, a
// spacing apart, d/3 in); a soft object's FEM boundary as a deforming
// surface (dm::BoundarySurface at half a spacing, so that it can stretch to
// twice its area without letting the fluid through), handed the FEM nodes
// in the world and their velocities every tick before the fluid steps:
// the tissue pushes the fluid and the fluid's loads on its vertices (the
// FEM nodes) are held on the FEM body over its next step (two-way,
// explicit); a dynamic body's surface (sampled a spacing
// apart, d/3 in, in its body frame) as a rigid body of the fluid, two-way:
// its pose and velocities from the physics world before each fluid step,
// the fluid's force and torque on it back (FluidBody), which the physics
// engine holds on the body over its next step (explicit coupling). Block
// particles inside a listed object (winding number over one half) are left
// out.
//
// Per physics tick, for each fluid in scene order: the inlets whose window
// holds the tick's time emit (a tool pressing an inlet — its proxy within
// the inlet's radius plus a spacing of its centre — adds |F|/A to the
// inlet's back pressure, F the force on the hand, A the outlet's area); the
// open tips take their share (a tip at the tool moves to the proxy first);
// the region recycles its leavers; the fluid steps. The summary keeps each
// fluid's account: its particles are the starting ones plus what the inlets
// emitted minus what the tips and the region took.
//
// Data flow: haptics → toolFeed() (a TripleBuffer of the proxy's position
// and the force, written each haptic tick) → step() (physics thread) → a
// TripleBuffer of each fluid's particle positions → latestParticles()
// (render thread).
// The fluids' arrays grow to their high-water mark (bounded by the region's
// volume, which the scene check caps) and then stop allocating.
#pragma once

#include <dm/core/result.hpp>
#include <dm/core/triple_buffer.hpp>
#include <dm/core/types.hpp>

#include <nlohmann/json.hpp>

#include <memory>
#include <string>
#include <vector>

namespace dm {

struct SceneDesc;
struct SceneResources;
class SoftTissues;

/// A dynamic rigid body of the scene as the fluids see it: the physics
/// engine writes its state before each fluid step, the fluids add what they
/// did to it (summed over the fluids that name it).
struct FluidBody {
  std::string object;
  Isometry3 objectInBody = Isometry3::Identity();  // the object's mesh frame in the body frame
  Isometry3 pose = Isometry3::Identity();          // body frame (origin at the centre of mass) → world
  Vec3 linearVelocity = Vec3::Zero(), angularVelocity = Vec3::Zero();
  Vec3 force = Vec3::Zero(), torque = Vec3::Zero();  // N, N·m about the centre of mass, last step
};

/// The haptic tool as the fluids see it.
struct FluidToolSample {
  Vec3 proxy = Vec3::Zero();  ///< world
  Vec3 force = Vec3::Zero();  ///< on the hand, world
  bool valid = false;
};

class SceneFluids {
 public:
  /// Fails naming the fluid's entry ("fluids/NAME/...") for an option the
  /// solver refuses.
  /// `soft` and `bodies` (the physics engine's, outliving these fluids)
  /// give the soft objects and dynamic bodies a fluid names under
  /// "objects"; `resources` the static and dynamic ones' meshes.
  static Result<std::unique_ptr<SceneFluids>> build(const SceneDesc& scene, const SceneResources& resources,
                                                    SoftTissues& soft, std::vector<FluidBody>& bodies);
  ~SceneFluids();

  bool empty() const noexcept;
  /// Physics thread: one step of dt from scene time t.
  Status step(double t, double dt);
  /// Written by the haptics engine each tick (one writer), read here.
  TripleBuffer<FluidToolSample>& toolFeed() noexcept;
  /// Physics thread: inlet k's flow rate (the fluids' inlets in scene
  /// order), m³/s.
  void setInletFlowRate(std::size_t k, double m3PerSecond);
  /// The fluids, in scene order.
  std::size_t size() const noexcept;
  /// Render thread (one reader): fluid i's particles (world) when a step
  /// finished since the last call, and on the first call (the start).
  bool latestParticles(std::size_t i, std::vector<Vec3>& out);
  /// Control thread, after the run: each fluid's state and account.
  nlohmann::json summary() const;

 private:
  struct Impl;
  explicit SceneFluids(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace dm
