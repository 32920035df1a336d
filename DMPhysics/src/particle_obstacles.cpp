// A mass–spring body's particles kept out of fixed obstacles; see
// dm/physics/particle_obstacles.hpp.
#include <dm/collide/bvh.hpp>
#include <dm/collide/mesh_query.hpp>
#include <dm/physics/mass_spring.hpp>
#include <dm/physics/particle_obstacles.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

namespace dm {

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
    if (!o.pose.matrix().allFinite() ||
        !(o.pose.linear() * o.pose.linear().transpose()).isApprox(Mat3::Identity(), 1e-9))
      return fail(ErrorCode::InvalidArgument, "the pose is not a finite rotation and translation",
                  where + ".pose");
    if (!std::isfinite(o.friction) || o.friction < 0.0)
      return fail(ErrorCode::InvalidArgument, "friction is " + std::to_string(o.friction),
                  where + ".friction", "give a Coulomb coefficient ≥ 0");
    out.obstacles_.push_back(o);
    out.inverse_.push_back(o.pose.inverse());
  }
  out.force_.assign(obstacles.size(), Vec3::Zero());
  out.thickness_ = thickness;
  return out;
}

std::size_t ParticleObstacles::resolve(MassSpringBody& body, double h, ParticleStep step) {
  for (Vec3& f : force_) f.setZero();
  contacts_ = 0;
  if (!std::isfinite(h) || !(h > 0.0) || obstacles_.empty()) return 0;
  // Momentum per unit velocity change (over m): the implicit step's drag
  // acts at the end velocity the contact changes.
  const double inertia = step == ParticleStep::Implicit ? 1.0 + h * body.drag() : 1.0;
  constexpr std::size_t kNone = std::numeric_limits<std::size_t>::max();
  const double th = thickness_;
  for (std::size_t i = 0; i < body.particleCount(); ++i) {
    if (body.pinned(i)) continue;
    const Vec3 x = body.position(i), v = body.velocity(i);
    const Vec3 x0 = x - h * v;  // where the step began (x ← x₀ + h v)
    // The first crossing of the path, else the deepest overlap.
    std::size_t which = kNone;
    double firstT = HUGE_VAL, deepest = 0.0;
    Vec3 point = Vec3::Zero(), normal = Vec3::Zero();
    bool crossed = false;
    for (std::size_t j = 0; j < obstacles_.size(); ++j) {
      const ParticleObstacle& o = obstacles_[j];
      Aabb path(inverse_[j] * x0);
      path.extend(inverse_[j] * x);
      path.min().array() -= th;
      path.max().array() += th;
      if (!path.intersects(o.tree->bounds())) continue;
      // A crossing: the path meets the surface going in.
      MeshRayHit hit;
      if (x != x0 && raycastMesh(*o.tree, o.pose, x0, x - x0, 1.0, hit)) {
        const MeshPointQuery at = closestPointOnMesh(*o.tree, o.pose, hit.point);
        if (at.normal.allFinite() && at.normal.squaredNorm() > 0.5 && (x - x0).dot(at.normal) < 0.0) {
          if (hit.t < firstT) {
            firstT = hit.t;
            which = j, crossed = true;
            point = hit.point, normal = at.normal;
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
      const double reach = started_ ? th + (x - x0).norm() + 1e-9 : HUGE_VAL;
      const MeshPointQuery q = closestPointOnMesh(*o.tree, o.pose, x, reach);
      if (!std::isfinite(q.distance)) continue;
      const double depth = th - q.distance;
      if (!(depth > deepest) || !q.normal.allFinite() || !(q.normal.squaredNorm() > 0.5)) continue;
      deepest = depth;
      which = j;
      point = q.point, normal = q.normal;
    }
    if (which == kNone) continue;
    ++contacts_;
    // Velocity: the approach along the normal removed, the slip reduced by
    // μ times that change (stopped when it is enough).
    const double vn = v.dot(normal);
    const double dvn = std::max(0.0, -vn);
    const Vec3 slip = v - vn * normal;
    const double slipNorm = slip.norm(), budget = obstacles_[which].friction * dvn;
    const Vec3 slipAfter = slipNorm <= budget ? Vec3::Zero() : Vec3((1.0 - budget / slipNorm) * slip);
    const Vec3 vAfter = std::max(vn, 0.0) * normal + slipAfter;
    // Position: at least the thickness off the surface (further where the
    // step left it further), along it where the step began plus h times the
    // new slip.
    const Vec3 fromStart = x0 - point;
    const double height = std::max(th, (x - point).dot(normal));
    const Vec3 xAfter =
        point + height * normal + (fromStart - fromStart.dot(normal) * normal) + h * slipAfter;
    force_[which] -= inertia * body.mass(i) * (vAfter - v) / h;
    body.setPosition(i, xAfter);
    body.setVelocity(i, vAfter);
  }
  started_ = true;
  return contacts_;
}

}  // namespace dm
