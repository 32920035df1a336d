// world_report.cpp — a joint's anchors in the world from the state's
// bodies, and the contacts' forces per body (dm/physics/world_report.hpp).
#include <dm/physics/world_report.hpp>

namespace dm {

JointGap jointGap(const WorldState& state, std::size_t k) noexcept {
  const Joint& j = state.joints()[k];
  const auto rotationOf = [&](int body) -> Quat {
    return body == kWorldBody ? Quat::Identity()
                              : state.orientation(BodyId{static_cast<std::uint32_t>(body)});
  };
  const auto anchorInWorld = [&](int body, const Vec3& anchor) -> Vec3 {
    return body == kWorldBody
               ? anchor
               : Vec3(state.position(BodyId{static_cast<std::uint32_t>(body)}) + rotationOf(body) * anchor);
  };
  Vec3 gap = anchorInWorld(j.bodyB, j.anchorB) - anchorInWorld(j.bodyA, j.anchorA);
  JointGap out;
  if (j.type == JointType::Slider) {
    const Vec3 axis = rotationOf(j.bodyA) * j.axisA;
    out.travel = axis.dot(gap);
    gap -= out.travel * axis;
  }
  out.gap = gap.norm();
  return out;
}

void addContactForces(const WorldState& state, double dt, std::span<Vec3> force) noexcept {
  if (!(dt > 0.0)) return;
  for (const ContactConstraint& c : state.contacts()) {
    const Vec3 onB = (c.normalImpulse * c.point.normal + c.frictionImpulse) / dt;
    if (c.bodyB >= 0 && static_cast<std::size_t>(c.bodyB) < force.size()) force[std::size_t(c.bodyB)] += onB;
    if (c.bodyA >= 0 && static_cast<std::size_t>(c.bodyA) < force.size()) force[std::size_t(c.bodyA)] -= onB;
  }
}

}  // namespace dm
