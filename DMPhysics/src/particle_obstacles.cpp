// A mass–spring body's particles kept out of fixed, moved or free
// obstacles; see dm/physics/particle_obstacles.hpp.
#include <dm/collide/bvh.hpp>
#include <dm/collide/mesh_query.hpp>
#include <dm/physics/mass_spring.hpp>
#include <dm/physics/particle_obstacles.hpp>

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <utility>

namespace dm {

namespace {

bool rigidPose(const Isometry3& pose) {
  return pose.matrix().allFinite() &&
         (pose.linear() * pose.linear().transpose()).isApprox(Mat3::Identity(), 1e-9);
}

// R I⁻¹ Rᵀ and the centre of mass in the world at `pose`.
void placeBody(const ParticleObstacle& o, const Isometry3& pose, Mat3& inverseInertia, Vec3& center) {
  inverseInertia = pose.linear() * o.inverseInertia * pose.linear().transpose();
  center = pose * o.centerOfMass;
}

// 1 / (the pair's effective mass along unit d at lever r): the particle's
// 1/m plus the body's 1/M + (r × d)ᵀ I⁻¹ (r × d).
double compliance(double inverseParticle, double inverseMass, const Mat3& inverseInertia, const Vec3& r,
                  const Vec3& d) {
  const Vec3 rd = r.cross(d);
  return inverseParticle + inverseMass + rd.dot(inverseInertia * rd);
}

}  // namespace

Result<ParticleObstacles> ParticleObstacles::create(std::span<const ParticleObstacle> obstacles,
                                                    double thickness) {
  if (!std::isfinite(thickness) || thickness < 0.0)
    return fail(ErrorCode::InvalidArgument, "thickness is " + std::to_string(thickness) + " m",
                "ParticleObstacles::create: thickness", "give a finite thickness ≥ 0 m");
  ParticleObstacles out;
  for (std::size_t i = 0; i < obstacles.size(); ++i) {
    const ParticleObstacle& o = obstacles[i];
    const std::string where = "ParticleObstacles::create: obstacles[" + std::to_string(i) + "]";
    if (o.tree == nullptr || !o.tree->isClosed())
      return fail(ErrorCode::InvalidArgument, "the obstacle's mesh is missing or not closed", where,
                  "give a closed, consistently oriented mesh (inside must be told from outside)");
    if (!rigidPose(o.pose))
      return fail(ErrorCode::InvalidArgument, "the pose is not a finite rotation and translation",
                  where + ".pose");
    if (!std::isfinite(o.friction) || o.friction < 0.0)
      return fail(ErrorCode::InvalidArgument, "friction is " + std::to_string(o.friction),
                  where + ".friction", "give a Coulomb coefficient ≥ 0");
    if (!std::isfinite(o.inverseMass) || o.inverseMass < 0.0)
      return fail(ErrorCode::InvalidArgument, "inverse mass is " + std::to_string(o.inverseMass),
                  where + ".inverseMass", "give 1/kg ≥ 0 (0: a body the particles do not move)");
    if (!o.inverseInertia.allFinite() || !o.inverseInertia.isApprox(o.inverseInertia.transpose(), 1e-12) ||
        Eigen::SelfAdjointEigenSolver<Mat3>(o.inverseInertia, Eigen::EigenvaluesOnly)
                .eigenvalues()
                .minCoeff() < -1e-12 * o.inverseInertia.norm())
      return fail(ErrorCode::InvalidArgument, "the inverse inertia is not finite, symmetric and ≥ 0",
                  where + ".inverseInertia", "give the body's inverse inertia tensor in the tree's frame");
    if (!o.centerOfMass.allFinite())
      return fail(ErrorCode::InvalidArgument, "the centre of mass is not finite", where + ".centerOfMass");
    out.obstacles_.push_back(o);
    out.inverse_.push_back(o.pose.inverse());
    Motion m;
    placeBody(o, o.pose, m.inverseInertia, m.center);
    out.motion_.push_back(m);
  }
  out.force_.assign(obstacles.size(), Vec3::Zero());
  out.touchCount_.assign(obstacles.size(), 0);
  out.lentForce_.assign(obstacles.size(), Vec3::Zero());
  out.thickness_ = thickness;
  return out;
}

Status ParticleObstacles::setMotion(std::size_t i, const Isometry3& pose, const Vec3& velocity,
                                    const Vec3& spin) {
  if (i >= obstacles_.size())
    return fail(ErrorCode::InvalidArgument,
                "obstacle " + std::to_string(i) + " of " + std::to_string(obstacles_.size()),
                "ParticleObstacles::setMotion: i");
  if (!rigidPose(pose))
    return fail(ErrorCode::InvalidArgument, "the pose is not a finite rotation and translation",
                "ParticleObstacles::setMotion: pose");
  if (!velocity.allFinite() || !spin.allFinite())
    return fail(ErrorCode::InvalidArgument, "the velocity is not finite",
                "ParticleObstacles::setMotion: velocity");
  ParticleObstacle& o = obstacles_[i];
  Motion& m = motion_[i];
  m.moved = !(pose.matrix() == o.pose.matrix());  // still: its paths stay exactly the fixed case's
  m.carried = pose * inverse_[i];
  m.velocity = velocity;
  m.spin = spin;
  o.pose = pose;
  inverse_[i] = pose.inverse();
  placeBody(o, pose, m.inverseInertia, m.center);
  return ok();
}

std::size_t ParticleObstacles::resolve(MassSpringBody& body, double h, ParticleStep step) {
  const bool valid = std::isfinite(h) && h > 0.0;
  if (lent_ && valid) afterStep(body, h);  // (a caller that forgot it: the shares back first)
  for (std::size_t j = 0; j < force_.size(); ++j) force_[j] = std::exchange(lentForce_[j], Vec3::Zero());
  contacts_ = 0;
  if (!valid || obstacles_.empty()) return 0;
  if (touch_.size() != body.particleCount()) touch_.assign(body.particleCount(), Touch{});  // first call
  for (Touch& t : touch_) t.obstacle = kNoObstacle;
  if (pending_.capacity() < body.particleCount()) pending_.reserve(body.particleCount());  // first call
  pending_.clear();
  // Momentum per unit velocity change (over m): the implicit step's drag
  // acts at the end velocity the contact changes.
  const double inertia = step == ParticleStep::Implicit ? 1.0 + h * body.drag() : 1.0;
  constexpr std::size_t kNone = std::numeric_limits<std::size_t>::max();
  const double th = thickness_;
  for (std::size_t i = 0; i < body.particleCount(); ++i) {
    if (body.pinned(i)) continue;
    const Vec3 x = body.position(i), v = body.velocity(i);
    const Vec3 x0 = x - h * v;  // where the step began (x ← x₀ + h v)
    // The first crossing of the path, else the deepest overlap; a moving
    // obstacle's path starts where x₀ is carried by its motion (relative).
    std::size_t which = kNone;
    double firstT = HUGE_VAL, deepest = 0.0;
    Vec3 point = Vec3::Zero(), normal = Vec3::Zero(), start = x0;
    bool crossed = false;
    for (std::size_t j = 0; j < obstacles_.size(); ++j) {
      const ParticleObstacle& o = obstacles_[j];
      const Vec3 from = motion_[j].moved ? Vec3(motion_[j].carried * x0) : x0;
      Aabb path(inverse_[j] * from);
      path.extend(inverse_[j] * x);
      path.min().array() -= th;
      path.max().array() += th;
      if (!path.intersects(o.tree->bounds())) continue;
      // A crossing: the path meets the surface going in.
      MeshRayHit hit;
      if (x != from && raycastMesh(*o.tree, o.pose, from, x - from, 1.0, hit)) {
        const MeshPointQuery at = closestPointOnMesh(*o.tree, o.pose, hit.point);
        if (at.normal.allFinite() && at.normal.squaredNorm() > 0.5 && (x - from).dot(at.normal) < 0.0) {
          if (hit.t < firstT) {
            firstT = hit.t;
            which = j, crossed = true;
            point = hit.point, normal = at.normal, start = from;
          }
          continue;
        }
      }
      if (crossed) continue;
      Aabb end(inverse_[j] * x);
      end.min().array() -= th;
      end.max().array() += th;
      if (!end.intersects(o.tree->bounds())) continue;
      // Within reach of the surface: a particle deeper inside got there by
      // a crossing (above), or started there (the first call looks at any
      // depth). The bound keeps the query local: far from the surface it
      // ends at the tree's top.
      const double reach = started_ ? th + (x - from).norm() + 1e-9 : HUGE_VAL;
      const MeshPointQuery q = closestPointOnMesh(*o.tree, o.pose, x, reach);
      if (!std::isfinite(q.distance)) continue;
      const double depth = th - q.distance;
      if (!(depth > deepest) || !q.normal.allFinite() || !(q.normal.squaredNorm() > 0.5)) continue;
      deepest = depth;
      which = j;
      point = q.point, normal = q.normal, start = from;
    }
    if (which == kNone) continue;
    ++contacts_;
    const ParticleObstacle& o = obstacles_[which];
    const double mass = inertia * body.mass(i);
    if (o.inverseMass > 0.0) {  // a free body: its contacts are solved together below
      pending_.push_back({.particle = static_cast<std::uint32_t>(i),
                          .obstacle = static_cast<std::uint32_t>(which),
                          .point = point,
                          .normal = normal,
                          .start = start,
                          .velocity = v,
                          .inverseMass = 1.0 / mass,
                          .lentBudget = o.friction * touch_[i].lentPush - touch_[i].lentAlong});
      continue;
    }
    // A fixed or moved obstacle: the approach relative to its surface point
    // removed, the slip reduced by at most μ times that (stopped when that
    // is enough), the particle's mass m (1 + h·drag) as the implicit drag
    // acts at the velocity the contact leaves.
    const Motion& motion = motion_[which];
    const Vec3 relative = v - (motion.velocity + motion.spin.cross(point - motion.center));
    const double vn = relative.dot(normal), dvn = std::max(0.0, -vn);
    const Vec3 slip = relative - vn * normal;
    const double slipNorm = slip.norm(), budget = o.friction * dvn;
    const bool stuck = slipNorm <= budget;
    const Vec3 slipAfter = stuck ? Vec3::Zero() : Vec3((1.0 - budget / slipNorm) * slip);
    const Vec3 vAfter = v + dvn * normal + (slipAfter - slip);
    place(body, i, x, point, normal, start, stuck ? Vec3::Zero() : slipAfter, h);
    force_[which] -= mass * (vAfter - v) / h;
    body.setVelocity(i, vAfter);
  }
  for (Touch& t : touch_) t.lentPush = t.lentAlong = 0.0;  // (read into pending_ above)
  if (!pending_.empty()) solveFree(body, h);
  started_ = true;
  return contacts_;
}

void ParticleObstacles::place(MassSpringBody& body, std::size_t i, const Vec3& x, const Vec3& point,
                              const Vec3& normal, const Vec3& start, const Vec3& slip, double h) const {
  // At least the thickness off the surface (further where the step left it
  // further), along it where the step began plus h times the new slip.
  const Vec3 fromStart = start - point;
  const double height = std::max(thickness_, (x - point).dot(normal));
  body.setPosition(i, point + height * normal + (fromStart - fromStart.dot(normal) * normal) + h * slip);
}

void ParticleObstacles::solveFree(MassSpringBody& body, double h) {
  // Projected Gauss–Seidel over the contacts with free bodies, impulses
  // accumulated per contact (the normal one ≥ 0, the friction one within
  // μ times it: Catto's clamping of the totals, so a later sweep can take
  // back what an earlier one gave too much): the particles a body meets
  // together end as a simultaneous inelastic contact would leave them.
  constexpr int kSweeps = 64;
  constexpr double kSettled = 1e-10;  // m/s: the largest velocity change of a sweep, to stop
  const auto apply = [&](Pending& c, const Vec3& impulse) {
    Motion& m = motion_[c.obstacle];
    const ParticleObstacle& o = obstacles_[c.obstacle];
    c.velocity += c.inverseMass * impulse;
    m.velocity -= o.inverseMass * impulse;
    m.spin -= m.inverseInertia * (c.point - m.center).cross(impulse);
    return c.inverseMass * impulse.norm();
  };
  for (Pending& c : pending_) {  // the approach, for the record below
    const Motion& m = motion_[c.obstacle];
    c.approach = (c.velocity - (m.velocity + m.spin.cross(c.point - m.center))).dot(c.normal);
  }
  for (int sweep = 0; sweep < kSweeps; ++sweep) {
    double largest = 0.0;
    for (Pending& c : pending_) {
      const ParticleObstacle& o = obstacles_[c.obstacle];
      const Motion& m = motion_[c.obstacle];
      const Vec3 r = c.point - m.center;
      Vec3 relative = c.velocity - (m.velocity + m.spin.cross(r));
      const double dn =
          -relative.dot(c.normal) / compliance(c.inverseMass, o.inverseMass, m.inverseInertia, r, c.normal);
      const double normal = std::max(0.0, c.pushed + dn);
      largest = std::max(largest, apply(c, (normal - c.pushed) * c.normal));
      c.pushed = normal;
      relative = c.velocity - (m.velocity + m.spin.cross(r));
      const Vec3 slip = relative - relative.dot(c.normal) * c.normal;
      const double slipNorm = slip.norm();
      // Coulomb over the whole step: the lent step's push counts too.
      const double budget = std::max(0.0, o.friction * normal + c.lentBudget);
      if (!(slipNorm > 0.0) && c.friction.norm() <= budget) continue;
      Vec3 friction = c.friction;
      if (slipNorm > 0.0)
        friction -= slip / compliance(c.inverseMass, o.inverseMass, m.inverseInertia, r, slip / slipNorm);
      const double size = friction.norm();
      if (size > budget) friction *= budget / size;
      largest = std::max(largest, apply(c, friction - c.friction));
      c.friction = friction;
    }
    if (largest < kSettled) break;
  }
  constexpr double kResting = 1e-4;  // m/s: a particle leaving a body slower than this rests on it
  for (const Pending& c : pending_) {
    const ParticleObstacle& o = obstacles_[c.obstacle];
    const Motion& m = motion_[c.obstacle];
    const std::size_t i = c.particle;
    const Vec3 relative = c.velocity - (m.velocity + m.spin.cross(c.point - m.center));
    const Vec3 slip = relative - relative.dot(c.normal) * c.normal;
    // Stuck: friction held inside its cone, or nothing slid.
    const bool stuck = c.friction.norm() < o.friction * c.pushed + c.lentBudget || slip.squaredNorm() == 0.0;
    const Vec3 v = body.velocity(i);
    place(body, i, body.position(i), c.point, c.normal, c.start, stuck ? Vec3::Zero() : slip, h);
    force_[c.obstacle] -= (c.velocity - v) / (c.inverseMass * h);
    body.setVelocity(i, c.velocity);
    if (c.approach < kResting) {  // pressed or resting on it: lent to it in the next step
      touch_[i] = {.obstacle = c.obstacle, .normal = c.normal, .stuck = stuck && o.friction > 0.0};
    }
  }
}

void ParticleObstacles::beforeStep(MassSpringBody& body) {
  if (lent_ || touch_.size() != body.particleCount()) return;
  const Vec3 g = body.gravity();
  const double drag = body.drag();
  // Only the particles the membrane presses onto their body: one its
  // springs (and its weight) pull off would leave, and a share would hold
  // it. Counted first: the shares of a body add up to its effective mass.
  std::fill(touchCount_.begin(), touchCount_.end(), 0u);
  for (std::size_t i = 0; i < touch_.size(); ++i) {
    Touch& t = touch_[i];
    t.pressed = false;
    if (t.obstacle == kNoObstacle || body.pinned(i)) continue;
    const Vec3 load = body.elementForceOn(i) + body.mass(i) * g + body.externalForce(i);
    t.pressed = load.dot(t.normal) < 0.0;
    touchCount_[t.obstacle] += t.pressed;
  }
  for (std::size_t i = 0; i < touch_.size(); ++i) {
    Touch& t = touch_[i];
    if (!t.pressed) continue;
    const ParticleObstacle& o = obstacles_[t.obstacle];
    const Motion& m = motion_[t.obstacle];
    // The body's effective mass along the contact normal, split among the
    // particles pressed onto it.
    const Vec3 r = body.position(i) - m.center;
    const double share = 1.0 / (compliance(0.0, o.inverseMass, m.inverseInertia, r, t.normal) *
                                double(touchCount_[t.obstacle]));
    const double mass = body.mass(i);
    if (!body.setMass(i, mass + share)) continue;  // (a finite share > 0 always passes)
    t.share = share;
    // The share moves with the particle (its momentum then is the body's
    // less the approach the last resolve() left, which resolve() takes up
    // again after the step): the body gains what the step gives the share.
    t.reference = body.velocity(i);
    // The share's gravity and drag are its world's to apply.
    t.force = share * (drag * t.reference - g);
    body.setExternalForce(i, body.externalForce(i) + t.force);
  }
  lent_ = true;
}

void ParticleObstacles::afterStep(MassSpringBody& body, double h) {
  if (!lent_) return;
  lent_ = false;
  for (std::size_t i = 0; i < touch_.size() && i < body.particleCount(); ++i) {
    Touch& t = touch_[i];
    if (t.share <= 0.0) continue;
    const double share = t.share;
    t.share = 0.0;
    (void)body.setMass(i, body.mass(i) - share);
    body.setExternalForce(i, body.externalForce(i) - t.force);
    const ParticleObstacle& o = obstacles_[t.obstacle];
    Motion& m = motion_[t.obstacle];
    // What the share gained over the step, back to its body: a push (a
    // contact cannot pull: a gain away from the body is the particle
    // leaving it, and is dropped) and, along the surface, all of it where
    // the contact stuck, else at most μ times the push (Coulomb).
    Vec3 gained = share * (body.velocity(i) - t.reference);
    const double push = std::min(0.0, gained.dot(t.normal));
    Vec3 along = gained - gained.dot(t.normal) * t.normal;
    if (!t.stuck) {
      const double limit = o.friction * -push, size = along.norm();
      if (size > limit) along *= limit / size;
    }
    gained = push * t.normal + along;
    t.lentPush = -push;  // the friction budget of resolve()'s contact starts from it
    t.lentAlong = along.norm();
    const Vec3 r = body.position(i) - m.center;
    lentForce_[t.obstacle] += gained / h;
    m.velocity += o.inverseMass * gained;
    m.spin += m.inverseInertia * r.cross(gained);
  }
}

}  // namespace dm
