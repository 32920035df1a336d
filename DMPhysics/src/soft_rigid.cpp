// FEM tissue and rigid bodies in one step; see dm/physics/soft_rigid.hpp.
#include <dm/collide/bvh.hpp>
#include <dm/physics/soft_rigid.hpp>

#include <cmath>
#include <string>

namespace dm {

namespace {

// The body's shape frame in the world: position · orientation · shapeOffset.
Isometry3 shapePose(const Vec3& position, const Quat& orientation, const BodyDesc& desc) {
  Isometry3 pose = Isometry3::Identity();
  pose.translation() = position;
  pose.linear() = orientation.normalized().toRotationMatrix();
  return pose * desc.shapeOffset;
}

}  // namespace

Result<SoftRigidCoupling> SoftRigidCoupling::create(const PhysicsWorld& world, FemBody& tissue,
                                                    std::span<const SoftRigidContact> contacts) {
  std::vector<FemObstacle> obstacles;
  SoftRigidCoupling c;
  for (std::size_t i = 0; i < contacts.size(); ++i) {
    const SoftRigidContact& k = contacts[i];
    const std::string where = "SoftRigidCoupling::create: contacts[" + std::to_string(i) + "]";
    if (!k.body.valid() || k.body.index >= world.bodyCount())
      return fail(ErrorCode::InvalidArgument, "the body is not in the world", where, "use an id from addBody");
    const BodyDesc& d = world.bodies()[k.body.index];
    if (d.kind == BodyKind::Particle)
      return fail(ErrorCode::InvalidArgument, "body '" + d.name + "' is a particle", where,
                  "couple rigid or static bodies (a particle has no orientation for its mesh)");
    const bool dynamic = d.kind == BodyKind::Rigid;
    // Body-frame inertia seen from the shape frame: Rsᵀ I Rs; the centre of
    // mass (the body origin) in the shape frame: shapeOffset⁻¹ · 0.
    const Mat3 rs = d.shapeOffset.linear();
    obstacles.push_back({.tree = k.tree,
                         .pose = shapePose(d.position, d.orientation, d),
                         .stiffness = k.stiffness,
                         .mass = dynamic ? d.mass : 0.0,
                         .inertia = dynamic ? Mat3(rs.transpose() * d.inertia * rs) : Mat3::Identity(),
                         .centerOfMass = d.shapeOffset.inverse().translation()});
    c.dynamic_.push_back(dynamic ? 1 : 0);
  }
  if (Status st = tissue.setObstacles(obstacles); !st)
    return std::move(st).error().within("SoftRigidCoupling::create");
  c.world_ = &world;
  c.tissue_ = &tissue;
  c.contacts_.assign(contacts.begin(), contacts.end());
  return c;
}

Result<FemStepReport> SoftRigidCoupling::step(WorldState& state, double dt) {
  constexpr const char* where = "SoftRigidCoupling::step";
  if (state.bodyCount() != world_->bodyCount())
    return fail(ErrorCode::InvalidArgument, "the state does not belong to the coupled world", where,
                "make the state with the world's makeState()");
  for (std::size_t i = 0; i < contacts_.size(); ++i) {
    const BodyId id = contacts_[i].body;
    tissue_->setObstaclePose(i, shapePose(state.position(id), state.orientation(id), world_->bodies()[id.index]));
    tissue_->setObstacleVelocity(i, {state.linearVelocity(id), state.angularVelocity(id)});
  }
  auto report = tissue_->step(dt);
  if (!report) return std::move(report).error().within(where);
  for (std::size_t i = 0; i < contacts_.size(); ++i)
    if (dynamic_[i]) {
      const Twist v = tissue_->obstacleVelocity(i);
      state.s_.linearVelocity[contacts_[i].body.index] = v.linear;
      state.s_.angularVelocity[contacts_[i].body.index] = v.angular;
    }
  if (Status st = world_->step(state, dt); !st) return std::move(st).error().within(where);
  return report;
}

}  // namespace dm
