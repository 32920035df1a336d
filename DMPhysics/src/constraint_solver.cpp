// Sequential-impulse contact and joint solver; see constraint_solver.hpp for
// the algorithm, conventions and references.
#include <dm/physics/constraint_solver.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

namespace dm {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// Orthonormal vectors t1, t2 with (t1, t2, n) right-handed (Frisvad/Duff et
// al. 2017 "Building an Orthonormal Basis, Revisited").
void tangentBasis(const Vec3& n, Vec3& t1, Vec3& t2) noexcept {
  const double sign = std::copysign(1.0, n.z());
  const double a = -1.0 / (sign + n.z());
  const double b = n.x() * n.y() * a;
  t1 = Vec3(1.0 + sign * n.x() * n.x() * a, sign * b, -sign * n.x());
  t2 = Vec3(b, sign + n.y() * n.y() * a, -n.y());
}

using Row = ConstraintSolver::Row;
using BodyState = ConstraintSolver::BodyState;

// Effective mass and I⁻¹·J of a row whose Jacobian is set.
void finishRow(Row& r, const std::vector<BodyState>& s) noexcept {
  const BodyState& A = s[r.a];
  const BodyState& B = s[r.b];
  r.mAngA = A.invInertia * r.angA;
  r.mAngB = B.invInertia * r.angB;
  const double k = A.invMass * r.linA.squaredNorm() + r.angA.dot(r.mAngA) + B.invMass * r.linB.squaredNorm() +
                   r.angB.dot(r.mAngB);
  r.effMass = k > 1e-300 ? 1.0 / k : 0.0;
}

double rowVelocity(const Row& r, const std::vector<BodyState>& s) noexcept {
  const BodyState& A = s[r.a];
  const BodyState& B = s[r.b];
  return r.linA.dot(A.v) + r.angA.dot(A.w) + r.linB.dot(B.v) + r.angB.dot(B.w);
}

double rowPushVelocity(const Row& r, const std::vector<BodyState>& s) noexcept {
  const BodyState& A = s[r.a];
  const BodyState& B = s[r.b];
  return r.linA.dot(A.pv) + r.angA.dot(A.pw) + r.linB.dot(B.pv) + r.angB.dot(B.pw);
}

void applyImpulse(const Row& r, std::vector<BodyState>& s, double lambda) noexcept {
  BodyState& A = s[r.a];
  BodyState& B = s[r.b];
  A.v += (A.invMass * lambda) * r.linA;
  A.w += lambda * r.mAngA;
  B.v += (B.invMass * lambda) * r.linB;
  B.w += lambda * r.mAngB;
}

void applyPush(const Row& r, std::vector<BodyState>& s, double lambda) noexcept {
  BodyState& A = s[r.a];
  BodyState& B = s[r.b];
  A.pv += (A.invMass * lambda) * r.linA;
  A.pw += lambda * r.mAngA;
  B.pv += (B.invMass * lambda) * r.linB;
  B.pw += lambda * r.mAngB;
}

// One projected Gauss–Seidel update of a row; returns the velocity
// correction it made (m/s).
double solveRow(Row& r, std::vector<BodyState>& s) noexcept {
  if (r.effMass == 0.0) return 0.0;
  const double delta = r.effMass * (r.target - rowVelocity(r, s));
  const double next = std::clamp(r.impulse + delta, r.lo, r.hi);
  const double applied = next - r.impulse;
  r.impulse = next;
  applyImpulse(r, s, applied);
  return std::abs(applied) / r.effMass;
}

void solvePushRow(Row& r, std::vector<BodyState>& s) noexcept {
  if (r.effMass == 0.0) return;
  const double delta = r.effMass * (r.pushTarget - rowPushVelocity(r, s));
  const double next = std::clamp(r.pushImpulse + delta, r.lo, r.hi);
  applyPush(r, s, next - r.pushImpulse);
  r.pushImpulse = next;
}

bool isUnit(const Vec3& v) noexcept { return v.allFinite() && std::abs(v.squaredNorm() - 1.0) < 1e-6; }

// Pose of a body index (kWorldBody: identity).
struct PoseRef {
  Vec3 x = Vec3::Zero();
  Quat q = Quat::Identity();
};
PoseRef poseOf(std::span<const SolverBody> bodies, int i) noexcept {
  if (i == kWorldBody) return {};
  return {bodies[static_cast<std::size_t>(i)].position, bodies[static_cast<std::size_t>(i)].orientation};
}

Status checkJointBodies(std::span<const SolverBody> bodies, int a, int b, const char* what) {
  const int n = static_cast<int>(bodies.size());
  for (int i : {a, b}) {
    if (i != kWorldBody && (i < 0 || i >= n))
      return fail(ErrorCode::InvalidArgument,
                  "body index " + std::to_string(i) + " is out of range [-1, " + std::to_string(n) + ")",
                  what, "pass an index into the body span or dm::kWorldBody");
  }
  if (a == b)
    return fail(ErrorCode::InvalidArgument, "both bodies are " + std::to_string(a), what,
                "a joint needs two different bodies (one may be dm::kWorldBody)");
  return ok();
}

Result<Vec3> unitAxis(const Vec3& axis, const char* what) {
  const double len = axis.norm();
  if (!std::isfinite(len) || len < 1e-12)
    return fail(ErrorCode::InvalidArgument, "axis is zero or not finite", what, "pass a nonzero direction");
  return Vec3(axis / len);
}

// Any unit vector perpendicular to unit `a`.
Vec3 perpendicular(const Vec3& a) noexcept {
  Vec3 t1, t2;
  tangentBasis(a, t1, t2);
  return t1;
}

}  // namespace

// ---------------------------------------------------------------- bodies ---

SolverBody SolverBody::dynamic(double mass, const Mat3& inertiaLocal, const Vec3& position,
                               const Quat& orientation) {
  SolverBody b;
  b.position = position;
  b.orientation = orientation.normalized();
  b.invMass = mass > 0.0 ? 1.0 / mass : 0.0;
  b.invInertiaLocal = mass > 0.0 ? Mat3(inertiaLocal.inverse()) : Mat3(Mat3::Zero());
  b.updateWorldInertia();
  return b;
}

SolverBody SolverBody::fixed(const Vec3& position, const Quat& orientation) {
  SolverBody b;
  b.position = position;
  b.orientation = orientation.normalized();
  return b;
}

void SolverBody::updateWorldInertia() noexcept {
  const Mat3 r = orientation.toRotationMatrix();
  invInertia = r * invInertiaLocal * r.transpose();
}

Mat3 boxInertia(double mass, const Vec3& h) noexcept {
  const Vec3 s = h.cwiseProduct(h);
  return (mass / 3.0) * Vec3(s.y() + s.z(), s.x() + s.z(), s.x() + s.y()).asDiagonal();
}

Mat3 sphereInertia(double mass, double radius) noexcept {
  return (0.4 * mass * radius * radius) * Mat3::Identity();
}

// ---------------------------------------------------------------- joints ---

Result<Joint> Joint::ball(std::span<const SolverBody> bodies, int a, int b, const Vec3& worldAnchor) {
  if (Status s = checkJointBodies(bodies, a, b, "Joint::ball"); !s) return std::move(s).error();
  const PoseRef pa = poseOf(bodies, a), pb = poseOf(bodies, b);
  Joint j;
  j.type = JointType::Ball;
  j.bodyA = a;
  j.bodyB = b;
  j.anchorA = pa.q.conjugate() * (worldAnchor - pa.x);
  j.anchorB = pb.q.conjugate() * (worldAnchor - pb.x);
  return j;
}

Result<Joint> Joint::hinge(std::span<const SolverBody> bodies, int a, int b, const Vec3& worldAnchor,
                           const Vec3& worldAxis) {
  auto j = ball(bodies, a, b, worldAnchor);
  if (!j) return std::move(j).error();
  auto axis = unitAxis(worldAxis, "Joint::hinge");
  if (!axis) return std::move(axis).error();
  const PoseRef pa = poseOf(bodies, a), pb = poseOf(bodies, b);
  const Vec3 ref = perpendicular(*axis);
  j->type = JointType::Hinge;
  j->axisA = pa.q.conjugate() * *axis;
  j->axisB = pb.q.conjugate() * *axis;
  j->referenceA = pa.q.conjugate() * ref;
  j->referenceB = pb.q.conjugate() * ref;
  return j;
}

Result<Joint> Joint::slider(std::span<const SolverBody> bodies, int a, int b, const Vec3& worldAnchor,
                            const Vec3& worldAxis) {
  auto j = ball(bodies, a, b, worldAnchor);
  if (!j) return std::move(j).error();
  auto axis = unitAxis(worldAxis, "Joint::slider");
  if (!axis) return std::move(axis).error();
  const PoseRef pa = poseOf(bodies, a), pb = poseOf(bodies, b);
  j->type = JointType::Slider;
  j->axisA = pa.q.conjugate() * *axis;
  j->axisB = pb.q.conjugate() * *axis;
  j->relativeRotation = (pa.q.conjugate() * pb.q).normalized();
  return j;
}

Result<Joint> Joint::fixed(std::span<const SolverBody> bodies, int a, int b, const Vec3& worldAnchor) {
  auto j = ball(bodies, a, b, worldAnchor);
  if (!j) return std::move(j).error();
  const PoseRef pa = poseOf(bodies, a), pb = poseOf(bodies, b);
  j->type = JointType::Fixed;
  j->relativeRotation = (pa.q.conjugate() * pb.q).normalized();
  return j;
}

// ---------------------------------------------------------------- solver ---

void ConstraintSolver::reserve(std::size_t bodies, std::size_t contacts, std::size_t joints) {
  state_.reserve(bodies + 1);
  contactRows_.reserve(3 * contacts);
  jointRows_.reserve(kMaxJointRows * joints);
}

Status ConstraintSolver::validate(std::span<const SolverBody> bodies,
                                  std::span<const ContactConstraint> contacts, std::span<const Joint> joints,
                                  double dt, const SolverOptions& o) const {
  const auto bad = [](std::string what, std::string where, std::string hint) {
    return fail(ErrorCode::InvalidArgument, std::move(what), std::move(where), std::move(hint));
  };
  if (!(std::isfinite(dt) && dt > 0.0))
    return bad("dt = " + std::to_string(dt) + " s", "ConstraintSolver::solve", "pass a finite step > 0");
  if (o.velocityIterations < 1 || o.positionIterations < 0)
    return bad("velocityIterations must be >= 1 and positionIterations >= 0", "SolverOptions",
               "use e.g. 10 and 4");
  if (!(o.baumgarte > 0.0 && o.baumgarte <= 1.0) || !(o.pushFactor > 0.0 && o.pushFactor <= 1.0))
    return bad("baumgarte and pushFactor must lie in (0, 1]", "SolverOptions", "use 0.2 and 0.8");
  if (!(o.warmStartFactor >= 0.0 && o.warmStartFactor <= 1.0) || !(o.slop >= 0.0) ||
      !(o.restitutionThreshold >= 0.0) || !(o.maxCorrectionVelocity > 0.0) || !(o.tolerance >= 0.0))
    return bad("warmStartFactor outside [0, 1] or a negative slop, threshold, tolerance or correction speed",
               "SolverOptions", "see the defaults in constraint_solver.hpp");
  const int n = static_cast<int>(bodies.size());
  const auto inRange = [n](int i) { return i == kWorldBody || (i >= 0 && i < n); };
  for (std::size_t i = 0; i < bodies.size(); ++i) {
    const SolverBody& b = bodies[i];
    if (!(b.invMass >= 0.0) || !std::isfinite(b.invMass) || !b.invInertia.allFinite() ||
        !b.linearVelocity.allFinite() || !b.angularVelocity.allFinite() || !b.position.allFinite())
      return bad("negative or non-finite mass, inertia, position or velocity",
                 "bodies[" + std::to_string(i) + "]",
                 "check the body state (a previous step may have blown up)");
  }
  for (std::size_t i = 0; i < contacts.size(); ++i) {
    const ContactConstraint& c = contacts[i];
    const auto where = [i] { return "contacts[" + std::to_string(i) + "]"; };
    if (!inRange(c.bodyA) || !inRange(c.bodyB))
      return bad("body index (" + std::to_string(c.bodyA) + ", " + std::to_string(c.bodyB) +
                     ") out of range [-1, " + std::to_string(n) + ")",
                 where(), "pass indices into the body span or dm::kWorldBody");
    if (!isUnit(c.point.normal) || !c.point.position.allFinite() || !std::isfinite(c.point.depth))
      return bad("normal not unit or position/depth not finite", where() + ".point",
                 "pass contacts as dm::collide() returns them");
    if (!(c.friction >= 0.0) || !(c.restitution >= 0.0 && c.restitution <= 1.0))
      return bad("friction < 0 or restitution outside [0, 1]", where(),
                 "use e.g. friction 0.5, restitution 0.2");
  }
  for (std::size_t i = 0; i < joints.size(); ++i) {
    const Joint& j = joints[i];
    const auto where = [i] { return "joints[" + std::to_string(i) + "]"; };
    if (!inRange(j.bodyA) || !inRange(j.bodyB) || j.bodyA == j.bodyB)
      return bad("body indices (" + std::to_string(j.bodyA) + ", " + std::to_string(j.bodyB) +
                     ") out of range [-1, " + std::to_string(n) + ") or equal",
                 where(), "build joints with dm::Joint::ball/hinge/slider/fixed");
    if (!isUnit(j.axisA) || !isUnit(j.axisB) || !j.anchorA.allFinite() || !j.anchorB.allFinite())
      return bad("axis not unit or anchor not finite", where(), "build joints with the Joint factories");
    if (j.limitEnabled && !(j.lower <= j.upper))
      return bad("limit lower > upper", where(), "swap the limits");
  }
  return ok();
}

void ConstraintSolver::buildJointRows(std::span<const SolverBody> bodies, Joint& joint, double dt,
                                      const SolverOptions& o) {
  const int n = static_cast<int>(bodies.size());
  const int ia = joint.bodyA == kWorldBody ? n : joint.bodyA;
  const int ib = joint.bodyB == kWorldBody ? n : joint.bodyB;
  const PoseRef pa = poseOf(bodies, joint.bodyA), pb = poseOf(bodies, joint.bodyB);
  const Vec3 rA = pa.q * joint.anchorA;
  const Vec3 rB = pb.q * joint.anchorB;
  const Vec3 d = (pb.x + rB) - (pa.x + rA);
  const double inv = 1.0 / dt;
  int slot = 0;

  // Equality row with position error C (J·v = 0 drives it; the correction
  // goes to the push pass or to a Baumgarte bias).
  const auto add = [&](const Vec3& linA, const Vec3& angA, const Vec3& linB, const Vec3& angB, double c,
                       bool inequality) {
    Row r;
    r.a = ia;
    r.b = ib;
    r.linA = linA;
    r.angA = angA;
    r.linB = linB;
    r.angB = angB;
    finishRow(r, state_);
    if (inequality) {
      // C ≥ 0 wanted: speculative when C > 0 (may approach by C this step).
      r.lo = 0.0;
      r.hi = kInf;
      if (c > 0.0) {
        r.target = -c * inv;
      } else {
        const double corr = std::min(-c * inv, o.maxCorrectionVelocity);
        r.target = o.splitImpulse ? 0.0 : o.baumgarte * corr;
        r.pushTarget = o.splitImpulse ? o.pushFactor * corr : 0.0;
      }
    } else {
      r.lo = -kInf;
      r.hi = kInf;
      const double corr = std::clamp(-c * inv, -o.maxCorrectionVelocity, o.maxCorrectionVelocity);
      r.target = o.splitImpulse ? 0.0 : o.baumgarte * corr;
      r.pushTarget = o.splitImpulse ? o.pushFactor * corr : 0.0;
    }
    r.out = &joint.impulses[static_cast<std::size_t>(slot++)];
    r.impulse = o.warmStart ? o.warmStartFactor * *r.out : 0.0;
    jointRows_.push_back(r);
  };
  const Vec3 zero = Vec3::Zero();
  const auto point = [&]() {
    for (int k = 0; k < 3; ++k) {
      const Vec3 e = Vec3::Unit(k);
      add(-e, -rA.cross(e), e, rB.cross(e), d[k], false);
    }
  };
  // Three angular rows locking q_B to q_A·relativeRotation.
  const auto lockRotation = [&]() {
    Quat dq = pb.q * (pa.q * joint.relativeRotation).conjugate();
    if (dq.w() < 0.0) dq.coeffs() = -dq.coeffs();
    const Vec3 err = 2.0 * dq.vec();
    for (int k = 0; k < 3; ++k) {
      const Vec3 e = Vec3::Unit(k);
      add(zero, -e, zero, e, err[k], false);
    }
  };
  // Linear row along u fixed in A: C = u·d.
  const auto slideRow = [&](const Vec3& u, double c, bool inequality) {
    add(-u, -(rA + d).cross(u), u, rB.cross(u), c, inequality);
  };

  switch (joint.type) {
    case JointType::Ball:
      point();
      break;
    case JointType::Hinge: {
      point();
      const Vec3 a1 = pa.q * joint.axisA;
      const Vec3 a2 = pb.q * joint.axisB;
      Vec3 b1, c1;
      tangentBasis(a1, b1, c1);
      const Vec3 err = a1.cross(a2);
      add(zero, -b1, zero, b1, b1.dot(err), false);
      add(zero, -c1, zero, c1, c1.dot(err), false);
      if (joint.limitEnabled) {
        const Vec3 refA = pa.q * joint.referenceA;
        const Vec3 refB = pb.q * joint.referenceB;
        const double angle = std::atan2(refA.cross(refB).dot(a1), refA.dot(refB));
        add(zero, -a1, zero, a1, angle - joint.lower, true);
        add(zero, a1, zero, -a1, joint.upper - angle, true);
      }
      break;
    }
    case JointType::Slider: {
      const Vec3 a1 = pa.q * joint.axisA;
      Vec3 b1, c1;
      tangentBasis(a1, b1, c1);
      slideRow(b1, b1.dot(d), false);
      slideRow(c1, c1.dot(d), false);
      lockRotation();
      if (joint.limitEnabled) {
        const double s = a1.dot(d);
        slideRow(a1, s - joint.lower, true);
        slideRow(-a1, joint.upper - s, true);
      }
      break;
    }
    case JointType::Fixed:
      point();
      lockRotation();
      break;
  }
}

Result<SolverStats> ConstraintSolver::solve(std::span<SolverBody> bodies,
                                            std::span<ContactConstraint> contacts, std::span<Joint> joints,
                                            double dt, const SolverOptions& o) {
  if (Status s = validate(bodies, contacts, joints, dt, o); !s) return std::move(s).error();
  const std::size_t n = bodies.size();
  const double inv = 1.0 / dt;

  // Copy velocities into the scratch; index n is the static world.
  state_.resize(n + 1);
  for (std::size_t i = 0; i < n; ++i) {
    const SolverBody& b = bodies[i];
    BodyState& s = state_[i];
    s.v = b.linearVelocity;
    s.w = b.angularVelocity;
    s.pv.setZero();
    s.pw.setZero();
    s.invMass = b.invMass;
    s.invInertia = b.invMass > 0.0 ? b.invInertia : Mat3(Mat3::Zero());
  }
  BodyState& world = state_[n];
  world.v.setZero();
  world.w.setZero();
  world.pv.setZero();
  world.pw.setZero();
  world.invMass = 0.0;
  world.invInertia.setZero();

  // Joint rows.
  jointRows_.clear();
  for (Joint& j : joints) buildJointRows(bodies, j, dt, o);

  // Contact rows: normal, tangent 1, tangent 2.
  contactRows_.resize(3 * contacts.size());
  const int world_index = static_cast<int>(n);
  for (std::size_t i = 0; i < contacts.size(); ++i) {
    ContactConstraint& c = contacts[i];
    const int ia = c.bodyA == kWorldBody ? world_index : c.bodyA;
    const int ib = c.bodyB == kWorldBody ? world_index : c.bodyB;
    const Vec3 xa = c.bodyA == kWorldBody ? Vec3::Zero() : bodies[static_cast<std::size_t>(ia)].position;
    const Vec3 xb = c.bodyB == kWorldBody ? Vec3::Zero() : bodies[static_cast<std::size_t>(ib)].position;
    const Vec3& nrm = c.point.normal;
    const Vec3 rA = c.point.position - xa;
    const Vec3 rB = c.point.position - xb;
    Vec3 t1, t2;
    tangentBasis(nrm, t1, t2);
    Row* rows = &contactRows_[3 * i];
    const Vec3* dirs[3] = {&nrm, &t1, &t2};
    for (int k = 0; k < 3; ++k) {
      Row& r = rows[k];
      const Vec3& u = *dirs[k];
      r.a = ia;
      r.b = ib;
      r.linA = -u;
      r.angA = -rA.cross(u);
      r.linB = u;
      r.angB = rB.cross(u);
      finishRow(r, state_);
      r.target = 0.0;
      r.pushTarget = 0.0;
      r.pushImpulse = 0.0;
      r.out = nullptr;
    }
    Row& rn = rows[0];
    rn.lo = 0.0;
    rn.hi = kInf;
    // Targets from the approach speed before any impulse of this step.
    const double vn = rowVelocity(rn, state_);
    if (c.point.depth < 0.0) {
      rn.target = c.point.depth * inv;  // speculative: may close the gap this step
    } else {
      if (vn < -o.restitutionThreshold) rn.target = -c.restitution * vn;
      const double corr = std::min(std::max(c.point.depth - o.slop, 0.0) * inv, o.maxCorrectionVelocity);
      if (o.splitImpulse)
        rn.pushTarget = o.pushFactor * corr;
      else
        rn.target = std::max(rn.target, o.baumgarte * corr);
    }
    const double scale = o.warmStart ? o.warmStartFactor : 0.0;
    rn.impulse = scale * std::max(c.normalImpulse, 0.0);
    rows[1].impulse = scale * c.frictionImpulse.dot(t1);
    rows[2].impulse = scale * c.frictionImpulse.dot(t2);
    // Friction bounds are set per sweep from the normal impulse.
    rows[1].lo = rows[2].lo = -kInf;
    rows[1].hi = rows[2].hi = kInf;
  }

  // Warm start.
  SolverStats stats;
  stats.rows = static_cast<int>(jointRows_.size() + contactRows_.size());
  if (o.warmStart) {
    for (const Row& r : jointRows_) applyImpulse(r, state_, r.impulse);
    for (const Row& r : contactRows_) applyImpulse(r, state_, r.impulse);
  }

  // Velocity sweeps.
  for (int it = 0; it < o.velocityIterations; ++it) {
    double change = 0.0;
    for (Row& r : jointRows_) change = std::max(change, solveRow(r, state_));
    for (std::size_t i = 0; i < contacts.size(); ++i) {
      Row* rows = &contactRows_[3 * i];
      Row& r1 = rows[1];
      Row& r2 = rows[2];
      // Friction: both tangent rows, then the accumulated tangential impulse
      // projected onto the Coulomb disk |λt| ≤ μ·λn.
      if (r1.effMass > 0.0 && r2.effMass > 0.0) {
        const double limit = contacts[i].friction * rows[0].impulse;
        double l1 = r1.impulse - r1.effMass * rowVelocity(r1, state_);
        double l2 = r2.impulse - r2.effMass * rowVelocity(r2, state_);
        const double len = std::hypot(l1, l2);
        if (len > limit) {
          const double f = len > 0.0 ? limit / len : 0.0;
          l1 *= f;
          l2 *= f;
        }
        const double d1 = l1 - r1.impulse, d2 = l2 - r2.impulse;
        r1.impulse = l1;
        r2.impulse = l2;
        applyImpulse(r1, state_, d1);
        applyImpulse(r2, state_, d2);
        change = std::max({change, std::abs(d1) / r1.effMass, std::abs(d2) / r2.effMass});
      }
      change = std::max(change, solveRow(rows[0], state_));
    }
    stats.iterations = it + 1;
    stats.residual = change;
    if (o.tolerance > 0.0 && change < o.tolerance) break;
  }

  // Split-impulse position sweeps on pseudo-velocities.
  if (o.splitImpulse) {
    for (int it = 0; it < o.positionIterations; ++it) {
      for (Row& r : jointRows_) solvePushRow(r, state_);
      for (std::size_t i = 0; i < contacts.size(); ++i) solvePushRow(contactRows_[3 * i], state_);
    }
  }

  // Write back.
  for (std::size_t i = 0; i < n; ++i) {
    SolverBody& b = bodies[i];
    if (b.invMass <= 0.0) continue;
    const BodyState& s = state_[i];
    b.linearVelocity = s.v;
    b.angularVelocity = s.w;
    b.pushVelocity = s.pv;
    b.turnVelocity = s.pw;
  }
  for (const Row& r : jointRows_) {
    *r.out = r.impulse;
    stats.maxImpulse = std::max(stats.maxImpulse, std::abs(r.impulse));
  }
  for (std::size_t i = 0; i < contacts.size(); ++i) {
    const Row* rows = &contactRows_[3 * i];
    ContactConstraint& c = contacts[i];
    c.normalImpulse = rows[0].impulse;
    c.frictionImpulse = rows[1].impulse * rows[1].linB + rows[2].impulse * rows[2].linB;
    stats.maxImpulse = std::max(stats.maxImpulse, c.normalImpulse);
  }
  return stats;
}

// ----------------------------------------------------------------- cache ---

namespace {

bool pairLess(int a0, int b0, int a1, int b1) noexcept { return a0 < a1 || (a0 == a1 && b0 < b1); }

}  // namespace

void ContactCache::reserve(std::size_t contacts) {
  entries_.reserve(contacts);
  used_.reserve(contacts);
}

void ContactCache::store(std::span<const ContactConstraint> contacts, std::span<const SolverBody> bodies) {
  entries_.clear();
  for (const ContactConstraint& c : contacts) {
    const PoseRef pa = poseOf(bodies, c.bodyA);
    Entry e;
    e.a = c.bodyA;
    e.b = c.bodyB;
    e.key = c.featureKey;
    e.localA = pa.q.conjugate() * (c.point.position - pa.x);
    e.normal = c.point.normal;
    e.normalImpulse = c.normalImpulse;
    e.frictionLocalA = pa.q.conjugate() * c.frictionImpulse;
    entries_.push_back(e);
  }
  std::sort(entries_.begin(), entries_.end(),
            [](const Entry& x, const Entry& y) { return pairLess(x.a, x.b, y.a, y.b); });
}

int ContactCache::warmStart(std::span<ContactConstraint> contacts, std::span<const SolverBody> bodies) {
  used_.assign(entries_.size(), 0);
  const int n = static_cast<int>(bodies.size());
  int matched = 0;
  for (ContactConstraint& c : contacts) {
    c.normalImpulse = 0.0;
    c.frictionImpulse.setZero();
    if ((c.bodyA != kWorldBody && (c.bodyA < 0 || c.bodyA >= n)) ||
        (c.bodyB != kWorldBody && (c.bodyB < 0 || c.bodyB >= n)))
      continue;  // solve() reports the bad index
    const auto first = std::lower_bound(
        entries_.begin(), entries_.end(), c,
        [](const Entry& e, const ContactConstraint& k) { return pairLess(e.a, e.b, k.bodyA, k.bodyB); });
    const PoseRef pa = poseOf(bodies, c.bodyA);
    const Vec3 localA = pa.q.conjugate() * (c.point.position - pa.x);
    std::ptrdiff_t best = -1;
    double bestDist = matchDistance * matchDistance;
    for (auto it = first; it != entries_.end() && it->a == c.bodyA && it->b == c.bodyB; ++it) {
      const std::ptrdiff_t k = it - entries_.begin();
      if (used_[static_cast<std::size_t>(k)]) continue;
      if (c.featureKey != 0) {
        if (it->key == c.featureKey) {
          best = k;
          break;
        }
        continue;
      }
      if (it->normal.dot(c.point.normal) < 0.7) continue;
      const double dist = (it->localA - localA).squaredNorm();
      if (dist <= bestDist) {
        bestDist = dist;
        best = k;
      }
    }
    if (best < 0) continue;
    const Entry& e = entries_[static_cast<std::size_t>(best)];
    used_[static_cast<std::size_t>(best)] = 1;
    c.normalImpulse = e.normalImpulse;
    c.frictionImpulse = pa.q * e.frictionLocalA;
    ++matched;
  }
  return matched;
}

// ------------------------------------------------------------ integration ---

void integrateVelocities(std::span<SolverBody> bodies, const Vec3& gravity, double dt) noexcept {
  for (SolverBody& b : bodies)
    if (b.invMass > 0.0) b.linearVelocity += gravity * dt;
}

void integratePositions(std::span<SolverBody> bodies, double dt) noexcept {
  for (SolverBody& b : bodies) {
    const Vec3 v = b.linearVelocity + b.pushVelocity;
    const Vec3 w = b.angularVelocity + b.turnVelocity;
    b.position += v * dt;
    // q̇ = ½·(0, ω)⊗q with ω in the world frame.
    const Quat spin(0.0, w.x(), w.y(), w.z());
    Quat dq = spin * b.orientation;
    b.orientation.coeffs() += (0.5 * dt) * dq.coeffs();
    b.orientation.normalize();
    if (b.invMass > 0.0) b.updateWorldInertia();
    b.pushVelocity.setZero();
    b.turnVelocity.setZero();
  }
}

}  // namespace dm
