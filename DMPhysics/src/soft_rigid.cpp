// FEM tissue and rigid bodies in one step; see dm/physics/soft_rigid.hpp.
#include <dm/collide/bvh.hpp>
#include <dm/physics/soft_rigid.hpp>

#include <cmath>
#include <string>

namespace dm {

Result<SoftRigidCoupling> SoftRigidCoupling::create(const PhysicsWorld& world, FemBody& tissue,
                                                    std::span<const SoftRigidContact> contacts,
                                                    const Isometry3& tissuePose) {
  std::vector<FemObstacle> obstacles;
  SoftRigidCoupling c;
  if (!tissuePose.matrix().allFinite() ||
      !(tissuePose.linear() * tissuePose.linear().transpose()).isApprox(Mat3::Identity(), 1e-9))
    return fail(ErrorCode::InvalidArgument, "the tissue's pose is not a finite rotation and translation",
                "SoftRigidCoupling::create: tissuePose");
  const Isometry3 worldToTissue = tissuePose.inverse();
  for (std::size_t i = 0; i < contacts.size(); ++i) {
    const SoftRigidContact& k = contacts[i];
    const std::string where = "SoftRigidCoupling::create: contacts[" + std::to_string(i) + "]";
    auto body = world.meshedBody(k.body, where);
    if (!body) return body.error();
    const BodyDesc& d = **body;
    const bool dynamic = d.kind == BodyKind::Rigid;
    // Body-frame inertia seen from the shape frame: Rsᵀ I Rs; the centre of
    // mass (the body origin) in the shape frame: shapeOffset⁻¹ · 0.
    const Mat3 rs = d.shapeOffset.linear();
    obstacles.push_back({.tree = k.tree,
                         .pose = worldToTissue * bodyShapePose(d.position, d.orientation, d),
                         .stiffness = k.stiffness,
                         .friction = k.friction,
                         .mass = dynamic ? d.mass : 0.0,
                         .inertia = dynamic ? Mat3(rs.transpose() * d.inertia * rs) : Mat3::Identity(),
                         .centerOfMass = d.shapeOffset.inverse().translation()});
    c.dynamic_.push_back(dynamic ? 1 : 0);
  }
  if (Status st = tissue.setObstacles(obstacles); !st)
    return std::move(st).error().within("SoftRigidCoupling::create");
  c.world_ = &world;
  c.tissue_ = &tissue;
  c.tissuePose_ = tissuePose;
  c.contacts_.assign(contacts.begin(), contacts.end());
  return c;
}

// A dynamic body's velocity in the tissue's solve is the one it will have
// after the world's gravity over the step (awake bodies only): gravity,
// then contact, then positions, as rigid-body engines order them. Solving
// the contact before gravity instead lets the world's step push the body
// g·h² into the tissue every step, and it rests that much too deep.
Status SoftRigidCoupling::beforeTissueStep(const WorldState& state, double dt) {
  if (state.bodyCount() != world_->bodyCount())
    return fail(ErrorCode::InvalidArgument, "the state does not belong to the coupled world",
                "SoftRigidCoupling", "make the state with the world's makeState()");
  if (!std::isfinite(dt) || !(dt > 0))
    return fail(ErrorCode::InvalidArgument, "dt is " + std::to_string(dt) + " s", "SoftRigidCoupling",
                "give a finite time step > 0");
  const Isometry3 worldToTissue = tissuePose_.inverse();
  const Mat3 toTissue = tissuePose_.linear().transpose();
  for (std::size_t i = 0; i < contacts_.size(); ++i) {
    const BodyId id = contacts_[i].body;
    const bool falls = dynamic_[i] && !state.asleep(id);
    const Vec3 v = state.linearVelocity(id) + (falls ? Vec3(dt * world_->forces().gravity) : Vec3::Zero());
    tissue_->setObstaclePose(
        i, worldToTissue * bodyShapePose(state.position(id), state.orientation(id), world_->bodies()[id.index]));
    tissue_->setObstacleVelocity(i, {toTissue * v, toTissue * state.angularVelocity(id)});
  }
  return ok();
}

void SoftRigidCoupling::afterTissueStep(WorldState& state, double dt) const {
  const Mat3 toWorld = tissuePose_.linear();
  const ContactSettings& sleep = world_->contactSettings();
  for (std::size_t i = 0; i < contacts_.size(); ++i) {
    if (!dynamic_[i]) continue;
    const BodyId id = contacts_[i].body;
    const Twist v = tissue_->obstacleVelocity(i);
    const Vec3 angular = toWorld * v.angular;
    if (state.asleep(id)) {
      // Still to the tissue; only a push past the sleep thresholds wakes it
      // (setBodyState wakes its island).
      const Vec3 linear = toWorld * v.linear;
      if (linear.norm() > sleep.sleepLinearVelocity || angular.norm() > sleep.sleepAngularVelocity)
        (void)world_->setBodyState(state, id, state.position(id), state.orientation(id), linear, angular);
      continue;
    }
    // Less the gravity beforeTissueStep added: the world's step adds it.
    state.s_.linearVelocity[id.index] = toWorld * v.linear - dt * world_->forces().gravity;
    state.s_.angularVelocity[id.index] = angular;
  }
}

Wrench SoftRigidCoupling::wrench(std::size_t i) const noexcept {
  const Wrench w = tissue_->obstacleWrench(i);
  return {tissuePose_.linear() * w.force, tissuePose_.linear() * w.torque};
}

Result<FemStepReport> SoftRigidCoupling::step(WorldState& state, double dt) {
  constexpr const char* where = "SoftRigidCoupling::step";
  if (Status st = beforeTissueStep(state, dt); !st) return std::move(st).error().within(where);
  auto report = tissue_->step(dt);
  if (!report) return std::move(report).error().within(where);
  afterTissueStep(state, dt);
  if (Status st = world_->step(state, dt); !st) return std::move(st).error().within(where);
  return report;
}

}  // namespace dm
