// dm/physics/world_report.hpp — readings of a WorldState for reports and
// tests (summary.json's "physics", Python's PhysicsWorld): where a joint
// stands — how far apart its anchors on the two bodies are (what the
// solver, built-in or ODE, left of the joint's error) and a slider's travel
// — and each body's contact force over the last step of the built-in solver
// (ODE's come from dm::OdeWorld::lastContactForces). Not needed to step.
#pragma once

#include <dm/physics/world.hpp>

#include <cstddef>
#include <span>

namespace dm {

/// A joint's reading in a state.
struct JointGap {
  double gap = 0.0;     ///< m: the anchors apart (a slider's off its axis only)
  double travel = 0.0;  ///< m: a slider's anchor of b from a's along the axis; 0 for the others
};

/// The reading of joint `k` (addJoint order) in `state`, a state of the
/// world that has the joint (k < state.joints().size(); checked by the
/// caller). O(1).
/// @code
///   const dm::JointGap g = dm::jointGap(state, 0);
///   if (g.gap > 1e-4) dm::log::warn("the pivot parts by %g m", g.gap);
/// @endcode
JointGap jointGap(const WorldState& state, std::size_t k) noexcept;

/// Adds to `force` (one entry per body, N, world) each body's contact force
/// over the last built-in step of length `dt`: the solver's accumulated
/// normal and friction impulses over dt (a contact's normal pushes body B
/// along +n, A the other way). Nothing when dt ≤ 0. O(contacts).
/// @code
///   std::vector<dm::Vec3> f(world.bodyCount(), dm::Vec3::Zero());
///   dm::addContactForces(state, dt, f);
/// @endcode
void addContactForces(const WorldState& state, double dt, std::span<Vec3> force) noexcept;

}  // namespace dm
