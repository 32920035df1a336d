// A mass–spring membrane and a world's bodies in one step; see
// dm/physics/membrane_rigid.hpp.
#include <dm/physics/membrane_rigid.hpp>

#include <cmath>
#include <string>
#include <utility>

namespace dm {

namespace {

// Where a velocity and spin take a body over h: its shape pose then.
Isometry3 advancedShapePose(const WorldState& state, BodyId id, const BodyDesc& d, const Vec3& velocity,
                            const Vec3& spin, double h) {
  Quat q = state.orientation(id);
  const double angle = h * spin.norm();
  if (angle > 0.0) q = Quat(Eigen::AngleAxisd(angle, spin / spin.norm())) * q;
  return bodyShapePose(state.position(id) + h * velocity, q, d);
}

}  // namespace

Result<MembraneRigidCoupling> MembraneRigidCoupling::create(const PhysicsWorld& world,
                                                            std::span<const MembraneRigidContact> contacts,
                                                            double thickness) {
  MembraneRigidCoupling c;
  std::vector<ParticleObstacle> obstacles;
  for (std::size_t i = 0; i < contacts.size(); ++i) {
    const MembraneRigidContact& k = contacts[i];
    const std::string where = "MembraneRigidCoupling::create: contacts[" + std::to_string(i) + "]";
    auto body = world.meshedBody(k.body, where);
    if (!body) return body.error();
    const BodyDesc& d = **body;
    const bool dynamic = d.kind == BodyKind::Rigid;
    // The body-frame inverse inertia seen from the shape frame, Rsᵀ I⁻¹ Rs;
    // the centre of mass (the body origin) in the shape frame.
    const Mat3 rs = d.shapeOffset.linear();
    obstacles.push_back(
        {.tree = k.tree,
         .pose = bodyShapePose(d.position, d.orientation, d),
         .friction = k.friction,
         .inverseMass = dynamic ? 1.0 / d.mass : 0.0,
         .inverseInertia = dynamic ? Mat3(rs.transpose() * d.inertia.inverse() * rs) : Mat3::Zero(),
         .centerOfMass = d.shapeOffset.inverse().translation()});
    c.dynamic_.push_back(dynamic ? 1 : 0);
  }
  c.given_.assign(contacts.size(), {Vec3::Zero(), Vec3::Zero()});
  auto o = ParticleObstacles::create(obstacles, thickness);
  if (!o) return std::move(o).error().within("MembraneRigidCoupling::create");
  c.obstacles_ = std::move(*o);
  c.world_ = &world;
  c.contacts_.assign(contacts.begin(), contacts.end());
  return c;
}

Result<ImplicitStepReport> MembraneRigidCoupling::step(MassSpringBody& membrane, WorldState& state,
                                                       double h) {
  const PhysicsWorld& world = *world_;
  if (state.bodyCount() != world.bodyCount())
    return fail(ErrorCode::InvalidArgument, "the state does not belong to the coupled world",
                "MembraneRigidCoupling::step", "make the state with the world's makeState()");
  if (!std::isfinite(h) || !(h > 0))
    return fail(ErrorCode::InvalidArgument, "h is " + std::to_string(h) + " s", "MembraneRigidCoupling::step",
                "give a finite time step > 0");
  ParticleObstacles& contacts = *obstacles_;
  const Vec3 gravity = h * world.forces().gravity;
  // 1. Gravity first; each body where it is now.
  for (std::size_t i = 0; i < contacts_.size(); ++i) {
    if (!dynamic_[i]) continue;
    const BodyId id = contacts_[i].body;
    const BodyDesc& d = world.bodies()[id.index];
    const bool falls = !state.asleep(id);
    const Vec3 v = falls ? Vec3(state.linearVelocity(id) + gravity) : Vec3::Zero();
    const Vec3 w = falls ? state.angularVelocity(id) : Vec3::Zero();
    if (auto s = contacts.setMotion(i, bodyShapePose(state.position(id), state.orientation(id), d), v, w); !s)
      return std::move(s).error().within("MembraneRigidCoupling::step");
    given_[i] = {v, w};
  }
  // 2. The membrane's step with the bodies' masses lent.
  contacts.beforeStep(membrane);
  auto report = membrane.stepImplicit(h);
  contacts.afterStep(membrane, h);
  if (!report) return report;
  // 3. The contacts where the bodies' new velocities take them.
  for (std::size_t i = 0; i < contacts_.size(); ++i) {
    if (!dynamic_[i]) continue;
    const BodyId id = contacts_[i].body;
    const Vec3 v = contacts.velocity(i), w = contacts.spin(i);
    if (auto s = contacts.setMotion(i, advancedShapePose(state, id, world.bodies()[id.index], v, w, h), v, w);
        !s)
      return std::move(s).error().within("MembraneRigidCoupling::step");
  }
  contacts.resolve(membrane, h);
  // 4. Back to the world, less the gravity of 1 (its step adds it).
  const ContactSettings& sleep = world.contactSettings();
  for (std::size_t i = 0; i < contacts_.size(); ++i) {
    if (!dynamic_[i]) continue;
    const BodyId id = contacts_[i].body;
    const Vec3 v = contacts.velocity(i), w = contacts.spin(i);
    if (v == given_[i].first && w == given_[i].second) continue;  // untouched: as the world left it
    if (state.asleep(id)) {
      if (v.norm() > sleep.sleepLinearVelocity || w.norm() > sleep.sleepAngularVelocity)
        (void)world.setBodyState(state, id, state.position(id), state.orientation(id), v, w);
      continue;
    }
    (void)world.setBodyState(state, id, state.position(id), state.orientation(id), v - gravity, w);
  }
  return report;
}

}  // namespace dm
