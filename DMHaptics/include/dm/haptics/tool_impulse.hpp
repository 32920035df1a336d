// dm/haptics/tool_impulse.hpp — what the haptic tool does to the objects it
// touches, handed from the haptic thread to the physics thread without loss.
//
// The hand feels F each haptic tick; by Newton's third law the object the
// tool touches feels −F at the contact point. Physics steps at its own,
// often slower rate, so it needs the tool's *impulse* over its step, not the
// last force: every haptic tick adds J += F·dt and H += p × F·dt (p the
// contact point, world) to running totals per object, and publishes the
// totals through a dm::TripleBuffer. The physics thread takes the newest
// totals and differences them with the ones it took last: what arrived
// since, however many haptic ticks that was. No tick is lost (totals, not
// samples), neither side waits, and the momentum the body receives equals
// the momentum the hand gave away.
//
// For a body with centre of mass x over a physics step of length h:
//   force  = ΔJ / h,   torque about x = (ΔH − x × ΔJ) / h.
//
// Real time: add(), publish() and take() never allocate, lock, log or throw;
// the per-object arrays are sized by the constructor.
//
// @code
//   dm::ToolImpulseChannel channel(objectCount);
//   channel.add(object, -handForce, contactPoint, dt); channel.publish();  // haptic thread
//   if (channel.take(impulses)) { ... }                                     // physics thread
// @endcode
#pragma once

#include <dm/core/triple_buffer.hpp>
#include <dm/core/types.hpp>

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

namespace dm {

/// Linear (N·s) and angular (N·m·s, about the world origin) impulse.
struct ToolImpulse {
  Vec3 linear = Vec3::Zero();
  Vec3 angular = Vec3::Zero();
};

/// Single-writer (haptic thread), single-reader (physics thread) channel of
/// running impulse totals per object; see the file comment. Not copyable or
/// movable.
class ToolImpulseChannel {
 public:
  /// Room for `objects` objects (allocated now).
  explicit ToolImpulseChannel(std::size_t objects);
  ToolImpulseChannel(const ToolImpulseChannel&) = delete;
  ToolImpulseChannel& operator=(const ToolImpulseChannel&) = delete;

  std::size_t size() const noexcept { return running_.size(); }

  /// Haptic thread: object `object` received `force` (N, world) at `point`
  /// (m, world) for `dt` seconds. Out-of-range objects, non-finite values
  /// and dt ≤ 0 are ignored (a NaN must never reach a body). O(1).
  void add(std::size_t object, const Vec3& force, const Vec3& point, double dt) noexcept;
  /// Haptic thread: object `object` received `force` (N, world) and
  /// `torque` (N·m, about the world origin) for `dt` seconds — a tool that
  /// touches it at many points at once (6-DOF renderers). Same rules as
  /// add(). O(1).
  void addWrench(std::size_t object, const Vec3& force, const Vec3& torque, double dt) noexcept;
  /// Haptic thread: makes the totals so far visible to take(). O(objects).
  void publish() noexcept;

  /// Physics thread: writes into out[i] (i < min(out.size(), size())) the
  /// impulse object i received since the previous take() and returns true,
  /// or returns false and writes zeros when nothing was published since.
  /// O(objects).
  bool take(std::span<ToolImpulse> out) noexcept;

  /// Physics thread: total impulse object `object` received up to the last
  /// take() (zero for an out-of-range index).
  ToolImpulse taken(std::size_t object) const noexcept;

 private:
  std::vector<ToolImpulse> running_;  // haptic thread
  TripleBuffer<std::vector<ToolImpulse>> totals_;
  std::vector<ToolImpulse> seen_;  // physics thread
};

}  // namespace dm
