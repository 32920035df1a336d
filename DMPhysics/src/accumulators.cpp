// Force accumulators: validation and the per-evaluation kernels.
#include <dm/physics/accumulators.hpp>

#include <cmath>

namespace dm {

namespace {

Status checkBody(BodyId id, std::span<const BodyDesc> bodies, const std::string& where, const char* field) {
  if (!id.valid())
    return fail(ErrorCode::NotFound, std::string(field) + " is an invalid (default) BodyId", where,
                "pass an id returned by PhysicsWorld::addBody");
  if (id.index >= bodies.size())
    return fail(ErrorCode::NotFound,
                std::string(field) + " names body " + std::to_string(id.index) + ", but the world has " +
                    std::to_string(bodies.size()) + " bodies",
                where, "pass an id returned by PhysicsWorld::addBody of this world");
  return ok();
}

Status checkDynamic(BodyId id, std::span<const BodyDesc> bodies, const std::string& where,
                    const char* field) {
  if (auto st = checkBody(id, bodies, where, field); !st) return st;
  if (bodies[id.index].kind == BodyKind::Static)
    return fail(ErrorCode::InvalidArgument,
                std::string(field) + " names static body " + std::to_string(id.index) + " '" +
                    bodies[id.index].name + "', which nothing can move",
                where, "apply it to a particle or rigid body");
  return ok();
}

Status checkFinite(bool finite, const std::string& where, const char* field) {
  if (finite) return ok();
  return fail(ErrorCode::InvalidArgument, std::string(field) + " is not finite", where, "give finite values");
}

Status checkCoefficient(double c, const std::string& where, const char* field) {
  if (!std::isfinite(c)) return checkFinite(false, where, field);
  if (c < 0)
    return fail(ErrorCode::InvalidArgument, std::string(field) + " is " + std::to_string(c) + " (negative)",
                where, "give a value >= 0");
  return ok();
}

}  // namespace

Status validateAccumulator(const ExternalForce& f, std::span<const BodyDesc> bodies,
                           const std::string& where) {
  if (auto st = checkDynamic(f.body, bodies, where, "body"); !st) return st;
  if (auto st = checkFinite(f.force.allFinite(), where, "force"); !st) return st;
  return checkFinite(f.point.allFinite(), where, "point");
}

Status validateAccumulator(const ExternalTorque& t, std::span<const BodyDesc> bodies,
                           const std::string& where) {
  if (auto st = checkDynamic(t.body, bodies, where, "body"); !st) return st;
  return checkFinite(t.torque.allFinite(), where, "torque");
}

Status validateAccumulator(const Drag& d, std::span<const BodyDesc> bodies, const std::string& where) {
  if (auto st = checkDynamic(d.body, bodies, where, "body"); !st) return st;
  if (auto st = checkCoefficient(d.linear, where, "linear"); !st) return st;
  if (auto st = checkCoefficient(d.quadratic, where, "quadratic"); !st) return st;
  return checkCoefficient(d.angular, where, "angular");
}

Status validateAccumulator(const NewtonianGravity& g, std::span<const BodyDesc> bodies,
                           const std::string& where) {
  if (!std::isfinite(g.gravitationalConstant) || !(g.gravitationalConstant > 0))
    return fail(ErrorCode::InvalidArgument,
                "gravitationalConstant is " + std::to_string(g.gravitationalConstant) + " (must be > 0)",
                where, "use 6.6743e-11 m³/(kg·s²) or a positive scaled value");
  if (auto st = checkCoefficient(g.softening, where, "softening"); !st) return st;
  std::vector<bool> seen(bodies.size(), false);
  for (std::size_t k = 0; k < g.bodies.size(); ++k) {
    const std::string field = "bodies[" + std::to_string(k) + "]";
    if (auto st = checkBody(g.bodies[k], bodies, where, field.c_str()); !st) return st;
    if (seen[g.bodies[k].index])
      return fail(ErrorCode::InvalidArgument,
                  field + " lists body " + std::to_string(g.bodies[k].index) + " again", where,
                  "list each body once");
    seen[g.bodies[k].index] = true;
  }
  return ok();
}

Status validateAccumulator(const Spring& s, std::span<const BodyDesc> bodies, const std::string& where) {
  if (auto st = checkBody(s.a, bodies, where, "a"); !st) return st;
  if (auto st = checkBody(s.b, bodies, where, "b"); !st) return st;
  if (s.a == s.b)
    return fail(ErrorCode::InvalidArgument, "a and b are the same body " + std::to_string(s.a.index), where,
                "connect two different bodies (use a static body as a fixed point)");
  if (auto st = checkFinite(s.anchorA.allFinite(), where, "anchorA"); !st) return st;
  if (auto st = checkFinite(s.anchorB.allFinite(), where, "anchorB"); !st) return st;
  if (auto st = checkCoefficient(s.stiffness, where, "stiffness"); !st) return st;
  if (auto st = checkCoefficient(s.restLength, where, "restLength"); !st) return st;
  return checkCoefficient(s.damping, where, "damping");
}

Status validateAccumulator(const Impulse& i, std::span<const BodyDesc> bodies, const std::string& where) {
  if (auto st = checkDynamic(i.body, bodies, where, "body"); !st) return st;
  if (auto st = checkFinite(i.impulse.allFinite(), where, "impulse"); !st) return st;
  if (auto st = checkFinite(i.point.allFinite(), where, "point"); !st) return st;
  return checkFinite(std::isfinite(i.time), where, "time");
}

namespace {

void newtonianPair(const NewtonianGravity& g, const BodyStateView& s, ForceOutput& out, std::uint32_t i,
                   std::uint32_t j) {
  const Vec3 r = s.position[j] - s.position[i];
  const double d2 = r.squaredNorm() + g.softening * g.softening;
  if (!(d2 > 0)) return;  // coincident unsoftened bodies: no defined direction
  const double inv = 1.0 / std::sqrt(d2);
  const Vec3 f = (g.gravitationalConstant * s.mass[i] * s.mass[j] * inv * inv * inv) * r;
  out.force[i] += f;
  out.force[j] -= f;
}

}  // namespace

void accumulateForces(const ForceSet& set, const BodyStateView& s, ForceOutput& out) {
  const std::size_t n = out.force.size();
  for (std::size_t i = 0; i < n; ++i) {
    out.force[i].setZero();
    out.torque[i].setZero();
  }

  // 1. Body simulator.
  for (const ExternalForce& f : set.forces) {
    const std::uint32_t i = f.body.index;
    addForceAt(out, i, f.force, s.orientation[i] * f.point);
  }
  for (const ExternalTorque& t : set.torques) out.torque[t.body.index] += t.torque;
  for (const Drag& d : set.drags) {
    const std::uint32_t i = d.body.index;
    const Vec3& v = s.linearVelocity[i];
    out.force[i] -= (d.linear + d.quadratic * v.norm()) * v;
    out.torque[i] -= d.angular * s.angularVelocity[i];
  }

  // 2. Gravity simulator. Static bodies get forces too; the integrators ignore them.
  if (!set.gravity.isZero(0.0))
    for (std::size_t i = 0; i < n; ++i) out.force[i] += s.mass[i] * set.gravity;
  for (const NewtonianGravity& g : set.newtonian) {
    if (g.bodies.empty()) {
      for (std::uint32_t i = 0; i < n; ++i)
        for (std::uint32_t j = i + 1; j < n; ++j) newtonianPair(g, s, out, i, j);
    } else {
      const std::size_t m = g.bodies.size();
      for (std::size_t a = 0; a < m; ++a)
        for (std::size_t b = a + 1; b < m; ++b)
          newtonianPair(g, s, out, g.bodies[a].index, g.bodies[b].index);
    }
  }

  // 3. Spring simulator.
  for (const Spring& sp : set.springs) {
    const std::uint32_t a = sp.a.index, b = sp.b.index;
    const Vec3 ra = s.orientation[a] * sp.anchorA;
    const Vec3 rb = s.orientation[b] * sp.anchorB;
    const Vec3 d = (s.position[b] + rb) - (s.position[a] + ra);
    const Vec3 vrel = (s.linearVelocity[b] + s.angularVelocity[b].cross(rb)) -
                      (s.linearVelocity[a] + s.angularVelocity[a].cross(ra));
    Vec3 f;
    if (sp.restLength == 0.0) {
      f = sp.stiffness * d + sp.damping * vrel;
    } else {
      const double len = d.norm();
      if (!(len > 0)) continue;  // direction undefined; the configuration is unstable anyway
      const Vec3 u = d / len;
      f = (sp.stiffness * (len - sp.restLength) + sp.damping * vrel.dot(u)) * u;
    }
    addForceAt(out, a, f, ra);
    addForceAt(out, b, -f, rb);
  }

  // 4. User simulator.
  for (const UserForce& u : set.user) {
    if (u.function) {
      u.function(s, out);
    } else {
      static_assert(sizeof(Vec3) == 3 * sizeof(double) && sizeof(Quat) == 4 * sizeof(double),
                    "the C view relies on tightly packed Eigen vectors");
      const DmForceInput in{s.time,
                            static_cast<std::uint32_t>(n),
                            s.position.empty() ? nullptr : s.position.front().data(),
                            s.orientation.empty() ? nullptr : s.orientation.front().coeffs().data(),
                            s.linearVelocity.empty() ? nullptr : s.linearVelocity.front().data(),
                            s.angularVelocity.empty() ? nullptr : s.angularVelocity.front().data(),
                            s.mass.data()};
      u.callback(u.userData, &in, n ? out.force.front().data() : nullptr,
                 n ? out.torque.front().data() : nullptr);
    }
  }
}

}  // namespace dm
