// physics_engine.hpp (private) — the physics engine of a scene run: the
// scene's objects as rigid bodies of one dm::PhysicsWorld (dynamic objects
// move, the others are static colliders), stepped at the engine's rate by
// the built-in solver or by ODE (dm::OdeWorld), with the haptic tool's
// impulses applied and the new poses handed on; and its soft objects as FEM
// bodies (soft_tissue.hpp), stepped before the rigid bodies at the same rate
// with the world's bodies as their obstacles (two-way: the tissue carries
// and pushes a dynamic body, dm::SoftRigidCoupling), pressed by the
// god-object through their HapticTissue and drawn deformed;
// its membranes as mass–spring bodies (scene_membranes.hpp), stepped next
// and drawn deformed; and its fluids (scene_fluids.hpp), stepped last.
//
// Data flow per physics tick (docs/architecture.md, "Scene runtime"):
//   haptics → ToolImpulseChannel → the impulse the tool gave each touched
//   body since the last tick, applied as a force and torque over the step;
//   step; body poses → HapticLocalModel (the god-object's objects move),
//   → a TripleBuffer the render engine reads (the drawn objects move),
//   → one the OpenIGTLink engine reads (the bodies' TRANSFORMs) and
//   → each script's (their states; the scripts' held forces come back).
// Each channel has one writer and one reader thread, so the engine runs on
// real-time threads and in lockstep alike; tick() allocates nothing but a
// fluid's growth to its high-water mark (scene_fluids.hpp).
#pragma once

#include <dm/core/result.hpp>
#include <dm/core/rt_loop.hpp>
#include <dm/core/triple_buffer.hpp>
#include <dm/core/types.hpp>
#include <dm/engine/engine.hpp>

#include <nlohmann/json.hpp>

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace dm {

struct SceneDesc;
struct SceneResources;
class HapticLocalModel;
class HapticRenderer;
class HapticTissue;
class ToolImpulseChannel;
struct Mesh;
struct ScriptFeed;
struct FluidToolSample;

/// Who reads the moving objects' poses (each has its own triple buffer).
enum class PoseReader : std::uint8_t { Render, Network };

/// The physics engine; build() it before the haptics engine, which takes
/// its hapticModel() and toolImpulses().
class PhysicsEngine final : public Engine {
 public:
  /// Bodies from `scene` (which has engines.physics): every object with
  /// "dynamic" a rigid body, every "soft" one an FEM body, every other
  /// object that collides a static one, the haptics proxy object none. `touched` are the haptics engine's
  /// objects in its order (empty without haptics). Fails naming the object
  /// (a mesh that is not closed, a bad mass) before anything runs.
  static Result<std::shared_ptr<PhysicsEngine>> build(const SceneDesc& scene, const SceneResources& resources,
                                                      std::span<const std::string> touched);
  ~PhysicsEngine() override;

  std::string_view name() const noexcept override { return "physics"; }
  bool tick(const TickInfo& info) noexcept override;
  Error error() const override { return error_; }

  /// Poses of the touched objects for the haptic loop; nullptr when none of
  /// them moves.
  HapticLocalModel* hapticModel() noexcept;
  /// Where the haptics engine puts the tool's impulses, one slot per touched
  /// object; nullptr when none of them moves.
  ToolImpulseChannel* toolImpulses() noexcept;

  /// The objects physics moves (dynamic ones), in scene order.
  const std::vector<std::string>& movingObjects() const noexcept { return movingNames_; }
  /// The objects drawn deformed: the soft objects, then the membranes, each
  /// in scene order; tissue(name) is the haptic side of a soft object (for
  /// a TissueGodObject), nullptr for any other name.
  const std::vector<std::string>& softObjects() const noexcept;
  HapticTissue* tissue(std::string_view object) noexcept;
  /// The needle renderer going into the soft object with "layers" (the
  /// haptics engine's renderer; stepped here), nullptr without one.
  HapticRenderer* needleRenderer() noexcept;
  /// The punch renderer bonded to the soft object its "punch" names (the
  /// haptics engine's renderer; stepped here), nullptr without one.
  HapticRenderer* punchRenderer() noexcept;
  /// Render thread (one reader): softObjects()[i]'s deformed surface
  /// (object frame, before its scale) when a step finished since the last
  /// call, and on the first call (SoftTissues / SceneMembranes::latestSurface).
  bool latestSurface(std::size_t i, Mesh& out);
  /// The newest poses of movingObjects() (object frame → world) when a step
  /// finished since this reader's last call; one thread per reader.
  bool latestPoses(PoseReader reader, std::vector<Isometry3>& out);

  /// Control thread, before the run: a script's channels (script_engine.hpp).
  /// Each tick then applies the forces the script holds on the moving bodies
  /// and publishes their states and the needle's punctures to it.
  Status addScriptFeed(ScriptFeed& feed);
  /// Where the haptics engine writes the tool for the fluids' tips and
  /// inlets each tick (one writer); nullptr when the scene has no fluids.
  TripleBuffer<FluidToolSample>* fluidTool() noexcept;
  /// Render thread (one reader): fluid i's particles (scene order) when a
  /// step finished since the last call, and on the first call.
  bool latestFluidParticles(std::size_t i, std::vector<Vec3>& out);
  /// Layer `layer` of soft object i's needle layers ("" when none).
  std::string layerName(std::size_t i, int layer) const;

  /// Control thread, after the run: each body's final state, the forces on
  /// it in the last step (contacts, tool) and the step counters.
  nlohmann::json summary() const;

 private:
  struct Impl;
  explicit PhysicsEngine(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
  std::vector<std::string> movingNames_;
  TickTime time_;  // scene time of a tick, also in real time
  Error error_;
};

}  // namespace dm
