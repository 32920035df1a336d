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
using ContactRow = ConstraintSolver::ContactRow;
using Velocity = ConstraintSolver::Velocity;

// Effective mass and I⁻¹·J of a row whose Jacobian is set.
void finishRow(Row& r, const std::vector<double>& invMass, const std::vector<Mat3>& invInertia) noexcept {
  r.imA = invMass[static_cast<std::size_t>(r.a)];
  r.imB = invMass[static_cast<std::size_t>(r.b)];
  r.mAngA = invInertia[static_cast<std::size_t>(r.a)] * r.angA;
  r.mAngB = invInertia[static_cast<std::size_t>(r.b)] * r.angB;
  const double k =
      r.imA * r.linA.squaredNorm() + r.angA.dot(r.mAngA) + r.imB * r.linB.squaredNorm() + r.angB.dot(r.mAngB);
  r.effMass = k > 1e-300 ? 1.0 / k : 0.0;
}

double rowVelocity(const Row& r, const Velocity& A, const Velocity& B) noexcept {
  return r.linA.dot(A.v) + r.angA.dot(A.w) + r.linB.dot(B.v) + r.angB.dot(B.w);
}

void applyImpulse(const Row& r, Velocity& A, Velocity& B, double lambda) noexcept {
  A.v += (r.imA * lambda) * r.linA;
  A.w += lambda * r.mAngA;
  B.v += (r.imB * lambda) * r.linB;
  B.w += lambda * r.mAngB;
}

// One projected Gauss–Seidel update of a joint row on the velocities `vel`
// (or pseudo-velocities, with `target`/`impulse` the push ones); returns the
// impulse change.
double solveRow(const Row& r, std::vector<Velocity>& vel, double target, double& impulse) noexcept {
  if (r.effMass == 0.0) return 0.0;
  Velocity& A = vel[static_cast<std::size_t>(r.a)];
  Velocity& B = vel[static_cast<std::size_t>(r.b)];
  const double delta = r.effMass * (target - rowVelocity(r, A, B));
  const double next = std::clamp(impulse + delta, r.lo, r.hi);
  const double applied = next - impulse;
  impulse = next;
  applyImpulse(r, A, B, applied);
  return applied;
}

// Velocity of a contact row along direction k: u·(v_B − v_A) + angA·ω_A + angB·ω_B.
[[gnu::always_inline]] inline double contactVelocity(const ContactRow& c, int k, const Vec3& dv, const Velocity& A,
                              const Velocity& B) noexcept {
  return c.u[k].dot(dv) + c.angA[k].dot(A.w) + c.angB[k].dot(B.w);
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
  velocity_.reserve(bodies + 1);
  push_.reserve(bodies + 1);
  invMass_.reserve(bodies + 1);
  invInertia_.reserve(bodies + 1);
  contactRows_.reserve(contacts);
  manifolds_.reserve(contacts);
  scheduled_.reserve(contacts);
  schedule_.reserve(contacts);
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
    if (!inRange(c.bodyA) || !inRange(c.bodyB) || c.bodyA == c.bodyB)
      return bad("body index (" + std::to_string(c.bodyA) + ", " + std::to_string(c.bodyB) +
                     ") out of range [-1, " + std::to_string(n) + ") or equal",
                 where(), "pass two different indices into the body span or dm::kWorldBody");
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
    finishRow(r, invMass_, invInertia_);
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

void ConstraintSolver::buildContactRows(std::span<const SolverBody> bodies,
                                        std::span<const ContactConstraint> contacts, double dt,
                                        const SolverOptions& o) {
  const int worldIndex = static_cast<int>(bodies.size());
  const double inv = 1.0 / dt;
  const double scale = o.warmStart ? o.warmStartFactor : 0.0;
  contactRows_.resize(contacts.size());
  for (std::size_t i = 0; i < contacts.size(); ++i) {
    const ContactConstraint& c = contacts[i];
    ContactRow& r = contactRows_[i];
    r.a = c.bodyA == kWorldBody ? worldIndex : c.bodyA;
    r.b = c.bodyB == kWorldBody ? worldIndex : c.bodyB;
    const auto ia = static_cast<std::size_t>(r.a), ib = static_cast<std::size_t>(r.b);
    const Vec3 xa = c.bodyA == kWorldBody ? Vec3::Zero() : bodies[ia].position;
    const Vec3 xb = c.bodyB == kWorldBody ? Vec3::Zero() : bodies[ib].position;
    const Vec3 rA = c.point.position - xa;
    const Vec3 rB = c.point.position - xb;
    r.imA = invMass_[ia];
    r.imB = invMass_[ib];
    r.friction = c.friction;
    r.u[0] = c.point.normal;
    tangentBasis(r.u[0], r.u[1], r.u[2]);
    const Mat3& iA = invInertia_[ia];
    const Mat3& iB = invInertia_[ib];
    for (int k = 0; k < 3; ++k) {
      r.angA[k] = -rA.cross(r.u[k]);
      r.angB[k] = rB.cross(r.u[k]);
      r.mAngA[k] = iA * r.angA[k];
      r.mAngB[k] = iB * r.angB[k];
      const double m = r.imA * r.u[k].squaredNorm() + r.angA[k].dot(r.mAngA[k]) +
                       r.imB * r.u[k].squaredNorm() + r.angB[k].dot(r.mAngB[k]);
      r.effMass[k] = m > 1e-300 ? 1.0 / m : 0.0;
    }
    // Targets from the approach speed before any impulse of this step.
    const Velocity& A = velocity_[ia];
    const Velocity& B = velocity_[ib];
    const double vn = contactVelocity(r, 0, B.v - A.v, A, B);
    r.target = 0.0;
    r.pushTarget = 0.0;
    r.pushImpulse = 0.0;
    if (c.point.depth < 0.0) {
      r.target = c.point.depth * inv;  // speculative: may close the gap this step
    } else {
      if (vn < -o.restitutionThreshold) r.target = -c.restitution * vn;
      const double corr = std::min(std::max(c.point.depth - o.slop, 0.0) * inv, o.maxCorrectionVelocity);
      if (o.splitImpulse)
        r.pushTarget = o.pushFactor * corr;
      else
        r.target = std::max(r.target, o.baumgarte * corr);
    }
    r.impulse[0] = scale * std::max(c.normalImpulse, 0.0);
    r.impulse[1] = scale * c.frictionImpulse.dot(r.u[1]);
    r.impulse[2] = scale * c.frictionImpulse.dot(r.u[2]);
  }
}

// Groups the contact rows by body pair and pairs each manifold with the
// nearest later one (within a short window) that shares no dynamic body.
// Solving two independent manifolds interleaved gives exactly the result of
// solving one after the other, while the CPU overlaps their (long, serial)
// dependency chains; the sweep order becomes the schedule's order.
void ConstraintSolver::scheduleManifolds() {
  manifolds_.clear();
  const auto m = static_cast<std::uint32_t>(contactRows_.size());
  for (std::uint32_t i = 0; i < m;) {
    const int a = contactRows_[i].a, b = contactRows_[i].b;
    std::uint32_t j = i + 1;
    while (j < m && contactRows_[j].a == a && contactRows_[j].b == b) ++j;
    manifolds_.push_back({i, j});
    i = j;
  }
  const auto count = static_cast<std::uint32_t>(manifolds_.size());
  scheduled_.assign(count, 0);
  schedule_.clear();
  const auto dynamic = [this](int i) { return invMass_[static_cast<std::size_t>(i)] > 0.0 ||
                                              invInertia_[static_cast<std::size_t>(i)] != Mat3::Zero(); };
  const auto shares = [&](std::uint32_t x, std::uint32_t y) {
    const ContactRow& p = contactRows_[manifolds_[x].begin];
    const ContactRow& q = contactRows_[manifolds_[y].begin];
    for (const int u : {p.a, p.b})
      if (dynamic(u) && (u == q.a || u == q.b)) return true;
    return false;
  };
  constexpr std::uint32_t kWindow = 8;
  for (std::uint32_t x = 0; x < count; ++x) {
    if (scheduled_[x]) continue;
    scheduled_[x] = 1;
    std::uint32_t partner = kNoManifold;
    for (std::uint32_t y = x + 1; y < count && y <= x + kWindow; ++y) {
      if (scheduled_[y] || shares(x, y)) continue;
      partner = y;
      scheduled_[y] = 1;
      break;
    }
    schedule_.push_back({x, partner});
  }
}

namespace {

// One contact of a sweep: the friction pair (projected onto the Coulomb disk
// |λt| ≤ μ·λn), then the normal row, so that non-penetration is the last
// word. A and B are the manifold's body velocities (locals of the caller).
// y += s·x, spelled out: GCC otherwise calls Eigen's compound assignment
// out of line inside the (large) sweep loops.
[[gnu::always_inline]] inline void addScaled(Vec3& y, double s, const Vec3& x) noexcept {
  y.x() += s * x.x();
  y.y() += s * x.y();
  y.z() += s * x.z();
}

// Applies impulse magnitudes l[0..2] along the contact's directions (l = 0
// rows skipped by the caller's choice of `first`/`last`).
[[gnu::always_inline]] inline void applyContact(const ContactRow& r, Velocity& A, Velocity& B, int first, int last,
                                                const double* l) noexcept {
  for (int k = first; k <= last; ++k) {
    addScaled(A.v, -r.imA * l[k], r.u[k]);
    addScaled(A.w, l[k], r.mAngA[k]);
    addScaled(B.v, r.imB * l[k], r.u[k]);
    addScaled(B.w, l[k], r.mAngB[k]);
  }
}

template <bool kResidual>
[[gnu::always_inline]] inline void solveContact(ContactRow& r, Velocity& A, Velocity& B, double& change) noexcept {
  if (r.effMass[0] == 0.0) return;  // two non-dynamic bodies
  double l[3] = {0.0, 0.0, 0.0};
  if (r.effMass[1] > 0.0 && r.effMass[2] > 0.0) {
    const Vec3 dv = B.v - A.v;
    const double limit = r.friction * r.impulse[0];
    double l1 = r.impulse[1] - r.effMass[1] * contactVelocity(r, 1, dv, A, B);
    double l2 = r.impulse[2] - r.effMass[2] * contactVelocity(r, 2, dv, A, B);
    const double len2 = l1 * l1 + l2 * l2;
    if (len2 > limit * limit) {
      const double f = len2 > 0.0 ? limit / std::sqrt(len2) : 0.0;
      l1 *= f;
      l2 *= f;
    }
    l[1] = l1 - r.impulse[1];
    l[2] = l2 - r.impulse[2];
    r.impulse[1] = l1;
    r.impulse[2] = l2;
    applyContact(r, A, B, 1, 2, l);
    if constexpr (kResidual)
      change = std::max({change, std::abs(l[1]) / r.effMass[1], std::abs(l[2]) / r.effMass[2]});
  }
  const double vn = contactVelocity(r, 0, B.v - A.v, A, B);
  const double next = std::max(r.impulse[0] + r.effMass[0] * (r.target - vn), 0.0);
  l[0] = next - r.impulse[0];
  r.impulse[0] = next;
  applyContact(r, A, B, 0, 0, l);
  if constexpr (kResidual) change = std::max(change, std::abs(l[0]) / r.effMass[0]);
}

// The split-impulse update of a contact's normal row on pseudo-velocities.
[[gnu::always_inline]] inline void pushContact(ContactRow& r, Velocity& A, Velocity& B) noexcept {
  if (r.effMass[0] == 0.0) return;
  const double vn = contactVelocity(r, 0, B.v - A.v, A, B);
  const double next = std::max(r.pushImpulse + r.effMass[0] * (r.pushTarget - vn), 0.0);
  const double l[1] = {next - r.pushImpulse};
  r.pushImpulse = next;
  applyContact(r, A, B, 0, 0, l);
}

// One contact of a sweep; kMode 0: velocities, 1: velocities with the
// residual, 2: split-impulse pseudo-velocities.
template <int kMode>
[[gnu::always_inline]] inline void visitContact(ContactRow& r, Velocity& A, Velocity& B, double& change) noexcept {
  if constexpr (kMode == 2)
    pushContact(r, A, B);
  else
    solveContact<kMode == 1>(r, A, B, change);
}

// Runs visitContact over the scheduled manifolds with each manifold's body
// velocities in locals; paired manifolds advance contact by contact together.
// Returns the residual (kMode 1).
template <int kMode>
double forSchedule(const std::vector<std::array<std::uint32_t, 2>>& schedule,
                   const std::vector<ConstraintSolver::Manifold>& manifolds, std::vector<ContactRow>& rows,
                   std::vector<Velocity>& vel) noexcept {
  double change = 0.0;
  for (const auto& [x, y] : schedule) {
    const ConstraintSolver::Manifold& mx = manifolds[x];
    const ContactRow& hx = rows[mx.begin];
    Velocity& sax = vel[static_cast<std::size_t>(hx.a)];
    Velocity& sbx = vel[static_cast<std::size_t>(hx.b)];
    Velocity ax = sax, bx = sbx;
    if (y == ConstraintSolver::kNoManifold) {
      for (std::uint32_t k = mx.begin; k < mx.end; ++k) visitContact<kMode>(rows[k], ax, bx, change);
      sax = ax;
      sbx = bx;
      continue;
    }
    const ConstraintSolver::Manifold& my = manifolds[y];
    const ContactRow& hy = rows[my.begin];
    Velocity& say = vel[static_cast<std::size_t>(hy.a)];
    Velocity& sby = vel[static_cast<std::size_t>(hy.b)];
    Velocity ay = say, by = sby;
    const std::uint32_t nx = mx.end - mx.begin, ny = my.end - my.begin, common = std::min(nx, ny);
    for (std::uint32_t k = 0; k < common; ++k) {
      visitContact<kMode>(rows[mx.begin + k], ax, bx, change);
      visitContact<kMode>(rows[my.begin + k], ay, by, change);
    }
    for (std::uint32_t k = common; k < nx; ++k) visitContact<kMode>(rows[mx.begin + k], ax, bx, change);
    for (std::uint32_t k = common; k < ny; ++k) visitContact<kMode>(rows[my.begin + k], ay, by, change);
    // A body both manifolds name is non-dynamic: both copies are unchanged.
    sax = ax;
    sbx = bx;
    say = ay;
    sby = by;
  }
  return change;
}

}  // namespace

// One velocity sweep: joint rows, then the contacts in schedule order. With
// kResidual, returns the largest velocity correction |Δλ|/m_eff (else 0).
template <bool kResidual>
double ConstraintSolver::sweep() {
  double change = 0.0;
  for (Row& r : jointRows_) {
    const double applied = solveRow(r, velocity_, r.target, r.impulse);
    if constexpr (kResidual)
      if (r.effMass > 0.0) change = std::max(change, std::abs(applied) / r.effMass);
  }
  change = std::max(change, forSchedule<kResidual ? 1 : 0>(schedule_, manifolds_, contactRows_, velocity_));
  return change;
}

void ConstraintSolver::pushSweep() {
  for (Row& r : jointRows_) solveRow(r, push_, r.pushTarget, r.pushImpulse);
  forSchedule<2>(schedule_, manifolds_, contactRows_, push_);
}

Result<SolverStats> ConstraintSolver::solve(std::span<SolverBody> bodies,
                                            std::span<ContactConstraint> contacts, std::span<Joint> joints,
                                            double dt, const SolverOptions& o) {
  if (Status s = validate(bodies, contacts, joints, dt, o); !s) return std::move(s).error();
  const std::size_t n = bodies.size();

  // Copy velocities and mass properties into the scratch; index n is the
  // static world.
  velocity_.resize(n + 1);
  push_.resize(n + 1);
  invMass_.resize(n + 1);
  invInertia_.resize(n + 1);
  for (std::size_t i = 0; i < n; ++i) {
    const SolverBody& b = bodies[i];
    velocity_[i] = {b.linearVelocity, b.angularVelocity};
    push_[i] = {Vec3::Zero(), Vec3::Zero()};
    invMass_[i] = b.invMass;
    invInertia_[i] = b.invMass > 0.0 ? b.invInertia : Mat3(Mat3::Zero());
  }
  velocity_[n] = push_[n] = {Vec3::Zero(), Vec3::Zero()};
  invMass_[n] = 0.0;
  invInertia_[n].setZero();

  jointRows_.clear();
  for (Joint& j : joints) buildJointRows(bodies, j, dt, o);
  buildContactRows(bodies, contacts, dt, o);
  scheduleManifolds();

  // Warm start.
  SolverStats stats;
  stats.rows = static_cast<int>(jointRows_.size() + 3 * contactRows_.size());
  if (o.warmStart) {
    for (const Row& r : jointRows_)
      applyImpulse(r, velocity_[static_cast<std::size_t>(r.a)], velocity_[static_cast<std::size_t>(r.b)],
                   r.impulse);
    for (const ContactRow& r : contactRows_) {
      Velocity& A = velocity_[static_cast<std::size_t>(r.a)];
      Velocity& B = velocity_[static_cast<std::size_t>(r.b)];
      const Vec3 p = r.impulse[0] * r.u[0] + r.impulse[1] * r.u[1] + r.impulse[2] * r.u[2];
      A.v -= r.imA * p;
      A.w += r.impulse[0] * r.mAngA[0] + r.impulse[1] * r.mAngA[1] + r.impulse[2] * r.mAngA[2];
      B.v += r.imB * p;
      B.w += r.impulse[0] * r.mAngB[0] + r.impulse[1] * r.mAngB[1] + r.impulse[2] * r.mAngB[2];
    }
  }

  // Velocity sweeps; the residual is measured only where it is used (the
  // early exit, or the last sweep for the stats).
  for (int it = 0; it < o.velocityIterations; ++it) {
    const bool measure = o.tolerance > 0.0 || it + 1 == o.velocityIterations;
    const double change = measure ? sweep<true>() : sweep<false>();
    stats.iterations = it + 1;
    stats.residual = change;
    if (o.tolerance > 0.0 && change < o.tolerance) break;
  }

  // Split-impulse position sweeps on pseudo-velocities (contact normals and
  // joint rows).
  if (o.splitImpulse)
    for (int it = 0; it < o.positionIterations; ++it) pushSweep();

  // Write back.
  for (std::size_t i = 0; i < n; ++i) {
    SolverBody& b = bodies[i];
    if (b.invMass <= 0.0) continue;
    b.linearVelocity = velocity_[i].v;
    b.angularVelocity = velocity_[i].w;
    b.pushVelocity = push_[i].v;
    b.turnVelocity = push_[i].w;
  }
  for (const Row& r : jointRows_) {
    *r.out = r.impulse;
    stats.maxImpulse = std::max(stats.maxImpulse, std::abs(r.impulse));
  }
  for (std::size_t i = 0; i < contacts.size(); ++i) {
    const ContactRow& r = contactRows_[i];
    ContactConstraint& c = contacts[i];
    c.normalImpulse = r.impulse[0];
    c.frictionImpulse = r.impulse[1] * r.u[1] + r.impulse[2] * r.u[2];
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
  // A pair's contacts are consecutive: its rotations are made once.
  int lastA = 0, lastB = 0;
  PoseRef pa, pb;
  Mat3 toA, toB;  // world → body frames
  for (std::size_t i = 0; i < contacts.size(); ++i) {
    const ContactConstraint& c = contacts[i];
    if (i == 0 || c.bodyA != lastA || c.bodyB != lastB) {
      lastA = c.bodyA;
      lastB = c.bodyB;
      pa = poseOf(bodies, c.bodyA);
      pb = poseOf(bodies, c.bodyB);
      toA = pa.q.toRotationMatrix().transpose();
      toB = pb.q.toRotationMatrix().transpose();
    }
    Entry e;
    e.a = c.bodyA;
    e.b = c.bodyB;
    e.key = c.featureKey;
    e.localA = toA * (c.point.position - pa.x);
    e.localB = toB * (c.point.position - pb.x);
    e.normalLocalA = toA * c.point.normal;
    e.depth = c.point.depth;
    e.normal = c.point.normal;
    e.normalImpulse = c.normalImpulse;
    e.frictionLocalA = toA * c.frictionImpulse;
    entries_.push_back(e);
  }
  std::sort(entries_.begin(), entries_.end(),
            [](const Entry& x, const Entry& y) { return pairLess(x.a, x.b, y.a, y.b); });
}

int ContactCache::persist(int a, int b, std::span<const SolverBody> bodies, double margin, double mu, double e,
                          std::vector<ContactConstraint>& out) const {
  const auto first =
      std::lower_bound(entries_.begin(), entries_.end(), std::pair{a, b},
                       [](const Entry& x, const std::pair<int, int>& k) { return pairLess(x.a, x.b, k.first, k.second); });
  const PoseRef pa = poseOf(bodies, a), pb = poseOf(bodies, b);
  int added = 0;
  for (auto it = first; it != entries_.end() && it->a == a && it->b == b; ++it) {
    const Vec3 onA = pa.x + pa.q * it->localA;
    const Vec3 onB = pb.x + pb.q * it->localB;
    const Vec3 n = pa.q * it->normalLocalA;
    const Vec3 d = onB - onA;
    const double apart = d.dot(n);
    const double depth = std::min(it->depth - apart, 0.0);
    if (depth < -margin || (d - apart * n).squaredNorm() > margin * margin) continue;
    out.push_back(ContactConstraint::make(a, b, {0.5 * (onA + onB), n.normalized(), depth}, mu, e));
    ++added;
  }
  return added;
}

int ContactCache::warmStart(std::span<ContactConstraint> contacts, std::span<const SolverBody> bodies) {
  used_.assign(entries_.size(), 0);
  const int n = static_cast<int>(bodies.size());
  int matched = 0;
  // A pair's contacts are consecutive: search and rotation once per pair.
  bool haveRun = false;
  int lastA = 0, lastB = 0;
  std::vector<Entry>::const_iterator first = entries_.end();
  PoseRef pa;
  Mat3 fromA;  // A's frame → world
  for (ContactConstraint& c : contacts) {
    c.normalImpulse = 0.0;
    c.frictionImpulse.setZero();
    if ((c.bodyA != kWorldBody && (c.bodyA < 0 || c.bodyA >= n)) ||
        (c.bodyB != kWorldBody && (c.bodyB < 0 || c.bodyB >= n)))
      continue;  // solve() reports the bad index
    if (!haveRun || c.bodyA != lastA || c.bodyB != lastB) {
      haveRun = true;
      lastA = c.bodyA;
      lastB = c.bodyB;
      first = std::lower_bound(
          entries_.begin(), entries_.end(), c,
          [](const Entry& e, const ContactConstraint& k) { return pairLess(e.a, e.b, k.bodyA, k.bodyB); });
      pa = poseOf(bodies, c.bodyA);
      fromA = pa.q.toRotationMatrix();
    }
    if (first == entries_.end() || first->a != c.bodyA || first->b != c.bodyB) continue;  // a new pair
    const Vec3 localA = fromA.transpose() * (c.point.position - pa.x);
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
    c.frictionImpulse = fromA * e.frictionLocalA;
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
