// dm/haptics/needle.hpp — feeling a needle go into FEM tissue at 1 kHz:
// the tenting, the pop, the cutting and the shaft's friction on the hand.
//
// dm::HapticNeedle joins a dm::NeedleInsertion (physics thread, e.g. 100 Hz
// with its FemBody) to the haptic loop (1 kHz) through two triple buffers,
// so neither thread waits for the other:
//  * needle pose, haptics → physics: each tick the device pose, through the
//    needle's mounting (tip and axis in the device frame) and the tissue's
//    pose, becomes the needle's tip and direction in the tissue frame; the
//    physics step takes the newest one (NeedleInsertion::step);
//  * local model, physics → haptics: after each step the coupling with the
//    tissue frozen (dm::NeedleLocalModel: the shaft's points with their
//    stick positions and friction limits, the held membrane, the track's
//    end, the cutting force) is published; every tick evaluates it at the
//    device's pose. So the puncture is felt in the tick the tip's force
//    reaches the threshold (the model breaks the membrane itself; the
//    physics breaks it at the same pose a step later), friction reverses in
//    the tick the hand does, and the tissue's motion arrives with each step.
// The force on the hand is the tissue's force on the needle (the hand holds
// the needle), the torque its moment about the device point; each is
// clamped to its limit and zeroed if not finite (dm::sanitizeWrench).
//
// Between physics steps the shaft's coupling points yield along the track
// with their share of the needle's motion (NeedleLocalModel::shaftYield,
// the tissue's stiffness there in series with the points' springs), as the
// membrane does under the tip: where the hand reverses and the points stick,
// the force follows the tissue instead of stepping back at each physics
// step (frozen points gave a 0.3 N sawtooth at 100 Hz in
// examples/scenes/needle_insertion.json; the first two steps after a
// reversal, before the track's stiffness is measured, use the tissue's
// under the tip and keep a third of it).
//
// Threads: tick() on the haptic thread (no allocation, lock, log or throw);
// step() on one physics thread. It is a HapticRenderer, so a HapticLoop
// (real time or lockstep) drives it like any renderer; its one object is
// the tissue (setObjectPose(0, pose) moves it).
//
// @code
//   auto needle = dm::NeedleInsertion::create(body, layerOfTet, layers);
//   auto felt = dm::HapticNeedle::create(*needle, {.tip = {0, 0, 0}, .axis = {0, 0, -1}, .maxForce = 6});
//   // haptic thread (HapticLoop): out = felt->tick(in);
//   // physics thread, 100 Hz:     felt->step(0.01);
// @endcode
#pragma once

#include <dm/core/pose.hpp>
#include <dm/core/result.hpp>
#include <dm/core/triple_buffer.hpp>
#include <dm/core/types.hpp>
#include <dm/haptics/renderer.hpp>
#include <dm/physics/needle.hpp>

#include <atomic>
#include <cstdint>
#include <memory>
#include <string_view>

namespace dm {

/// Options of HapticNeedle::create().
struct HapticNeedleOptions {
  Vec3 tip = Vec3::Zero();     ///< m, the needle's tip in the device frame
  Vec3 axis = -Vec3::UnitZ();  ///< the shaft's direction at the tip, handle → tip, device frame (normalised)
  /// Device frame: toward a curved needle's centre (the part ⊥ axis is
  /// used, normalised); not parallel to axis. Unused by a straight needle.
  Vec3 normal = Vec3::UnitX();
  Isometry3 tissuePose = Isometry3::Identity();  ///< the tissue's (body's) frame → world, rigid
  double maxForce = 8.0;                         ///< N, > 0: the largest force sent to the hand
  double maxTorque = 0.3;                        ///< N·m, ≥ 0: the largest torque (0 for a 3-DOF device)
};

/// See the file comment. Not copyable or movable (the buffers are shared
/// by two threads).
class HapticNeedle final : public HapticRenderer {
 public:
  /// `needle` must outlive this and be stepped only through step() while
  /// it is in use. Fails (InvalidArgument naming the option) on a
  /// non-finite tip, a zero or non-finite axis, a normal parallel to it or
  /// not finite, a non-rigid tissue pose, a
  /// maxForce that is not positive and finite or a negative or NaN maxTorque.
  static Result<std::unique_ptr<HapticNeedle>> create(NeedleInsertion& needle,
                                                      const HapticNeedleOptions& options = {});
  HapticNeedle(const HapticNeedle&) = delete;
  HapticNeedle& operator=(const HapticNeedle&) = delete;

  // --- haptic thread -------------------------------------------------------
  std::string_view name() const noexcept override { return "needle"; }
  /// Takes the newest model as it was published (undoing the slips and the
  /// local puncture the ticks since made). The pose comes with the next tick.
  void reset(const Isometry3& devicePose) noexcept override;
  HapticResponse tick(const HapticInput& input) noexcept override;
  std::size_t objectCount() const noexcept override { return 1; }
  /// Object 0 is the tissue: its frame → world.
  void setObjectPose(std::size_t index, const Isometry3& pose) noexcept override;

  // --- physics thread ------------------------------------------------------
  /// Steps the needle (and its body) by h at the newest pose the haptic
  /// thread published, then publishes the local model. Before the first
  /// tick there is no pose: the body steps alone. Fails as
  /// NeedleInsertion::step does; the model is then not published.
  Result<FemStepReport> step(double h);
  std::uint64_t publishedModels() const noexcept { return published_.load(std::memory_order_relaxed); }

 private:
  struct Pose {
    bool valid = false;
    Isometry3 needle = Isometry3::Identity();  // the needle's frame in the tissue's (NeedleShaft::fromPose)
  };
  HapticNeedle(NeedleInsertion& needle, const HapticNeedleOptions& options);

  NeedleInsertion* needle_;
  HapticNeedleOptions options_;
  Isometry3 mount_ = Isometry3::Identity();     // the needle's frame in the device's
  Isometry3 toTissue_ = Isometry3::Identity();  // world → the tissue's frame (options_.tissuePose⁻¹)
  TripleBuffer<NeedleLocalModel> models_;
  TripleBuffer<Pose> poses_;
  NeedleLocalModel working_;  // haptic thread: the newest model, as the ticks move it
  std::atomic<std::uint64_t> published_{0};
};

}  // namespace dm
