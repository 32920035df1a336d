// Sequential-impulse contact and joint solver; see constraint_solver.hpp for
// the algorithm, conventions and references.
#include <dm/physics/constraint_solver.hpp>

#include <dm/core/host_cpu.hpp>

// No a * b + c fused into an FMA anywhere in this file, so the sweeps'
// versions for wider vector units (see pickSweep) give the bits of
// the baseline SSE2 one on every x86-64.
#if defined(__clang__)
#pragma clang fp contract(off)
#elif defined(__GNUC__)
#pragma GCC optimize("fp-contract=off")
#endif

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <string>
#include <tuple>

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
using Velocity = ConstraintSolver::Velocity;
using WideRow = ConstraintSolver::WideRow;

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
  manifolds_.reserve(contacts);
  scheduled_.reserve(contacts);
  groups_.reserve(contacts);
  wideRows_.reserve(contacts);
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

// Groups the contacts by body pair (consecutive contacts of one pair form a
// manifold) and gathers each manifold with up to kLanes − 1 later ones (the
// first free ones within a short window) that share no dynamic body with it
// or each other. Solving independent manifolds side by side gives exactly
// the result of solving them one after the other, while SIMD lanes do their
// arithmetic at once and the CPU overlaps their (long, serial) dependency
// chains; the sweep order becomes the groups' order, which keeps the input's
// bottom-up order up to the window (8 manifolds: a 20-row pyramid at
// 1/60 s drifts half as far as with 16, at the same speed).
void ConstraintSolver::scheduleManifolds(std::span<const ContactConstraint> contacts) {
  const int world = static_cast<int>(velocity_.size()) - 1;
  const auto index = [world](int i) { return i == kWorldBody ? world : i; };
  manifolds_.clear();
  const auto m = static_cast<std::uint32_t>(contacts.size());
  for (std::uint32_t i = 0; i < m;) {
    const int a = contacts[i].bodyA, b = contacts[i].bodyB;
    std::uint32_t j = i + 1;
    while (j < m && contacts[j].bodyA == a && contacts[j].bodyB == b) ++j;
    manifolds_.push_back({i, j});
    i = j;
  }
  const auto count = static_cast<std::uint32_t>(manifolds_.size());
  scheduled_.assign(count, 0);
  groups_.clear();
  const auto dynamic = [this](int i) { return invMass_[static_cast<std::size_t>(i)] > 0.0 ||
                                              invInertia_[static_cast<std::size_t>(i)] != Mat3::Zero(); };
  const auto shares = [&](std::uint32_t x, std::uint32_t y) {
    const ContactConstraint& p = contacts[manifolds_[x].begin];
    const ContactConstraint& q = contacts[manifolds_[y].begin];
    const int qa = index(q.bodyA), qb = index(q.bodyB);
    for (const int u : {index(p.bodyA), index(p.bodyB)})
      if (dynamic(u) && (u == qa || u == qb)) return true;
    return false;
  };
  constexpr std::uint32_t kWindow = 8;
  std::uint32_t rows = 0;
  for (std::uint32_t x = 0; x < count; ++x) {
    if (scheduled_[x]) continue;
    scheduled_[x] = 1;
    Group g;
    int lanes = 1;
    g.manifold[0] = x;
    for (std::uint32_t y = x + 1; y < count && y <= x + kWindow && lanes < kLanes; ++y) {
      if (scheduled_[y]) continue;
      bool free = true;
      for (int l = 0; l < lanes && free; ++l) free = !shares(g.manifold[l], y);
      if (!free) continue;
      g.manifold[lanes++] = y;
      scheduled_[y] = 1;
    }
    std::uint32_t most = 0;
    for (int l = 0; l < kLanes; ++l) {
      if (l >= lanes) {
        g.manifold[l] = kNoManifold;
        g.a[l] = g.b[l] = world;
        continue;
      }
      const Manifold& mf = manifolds_[g.manifold[l]];
      g.a[l] = index(contacts[mf.begin].bodyA);
      g.b[l] = index(contacts[mf.begin].bodyB);
      most = std::max(most, mf.end - mf.begin);
    }
    g.rowBegin = rows;
    g.rowEnd = rows += most;
    groups_.push_back(g);
  }
}


namespace {

// kLanes doubles as one value Lanes<R>, held in registers of type R: with
// GCC/Clang vector extensions two SSE2 registers (R = Pair, every x86-64
// has them) or one AVX register (R = Quad, in the sweeps compiled for AVX,
// chosen at run time); a plain array of doubles elsewhere (or with
// DM_SOLVER_PLAIN_LANES defined). Lane by lane the arithmetic is the scalar
// one, IEEE operation for operation (no FMA, see the top of the file), so
// every representation gives the same bits.
#if defined(__GNUC__) && !defined(DM_SOLVER_PLAIN_LANES)
#define DM_SOLVER_VECTOR_LANES 1
using Pair = double __attribute__((vector_size(16)));
using Quad = double __attribute__((vector_size(32)));
using Narrow = Pair;
#else
using Narrow = double;
#endif
static_assert(ConstraintSolver::kLanes == 4, "Lanes holds four doubles");

template <class R>
struct Lanes {
  static constexpr int kWidth = sizeof(R) / sizeof(double);  // doubles per register
  static constexpr int kCount = 4 / kWidth;                  // registers
  R h[kCount];
};
template <class R>
struct LaneMask {
  using M = decltype(R{} > R{});  // all-ones/zero integer lanes, or bool
  M h[Lanes<R>::kCount];
};

// Element-wise over the registers (a loop the compiler unrolls; no lambda,
// which would pass AVX registers through memory outside the AVX code).
#define DM_LANEWISE(Type, expr)                    \
  Type out;                                        \
  _Pragma("GCC unroll 4") for (int i = 0; i < Lanes<R>::kCount; ++i) out.h[i] = (expr); \
  return out

// Four doubles as Lanes, and lane l of Lanes (built and read lane by lane,
// not through memory: a vector load of four scalar stores stalls).
template <class R>
[[gnu::always_inline]] inline Lanes<R> make(double x0, double x1, double x2, double x3) noexcept {
  if constexpr (Lanes<R>::kCount == 1)
    return {{R{x0, x1, x2, x3}}};
  else if constexpr (Lanes<R>::kCount == 2)
    return {{R{x0, x1}, R{x2, x3}}};
  else
    return {{x0, x1, x2, x3}};
}
template <class R>
[[gnu::always_inline]] inline double lane(const Lanes<R>& x, int l) noexcept {
  if constexpr (Lanes<R>::kWidth == 1)
    return x.h[l];
  else
    return x.h[l / Lanes<R>::kWidth][l % Lanes<R>::kWidth];
}

// WideRow's lanes are 32-byte aligned (so the 256-bit loads are not split).
// Not for clang: clang 14's UBSan alignment check crashes the compiler on
// this builtin with a template-dependent alignment (the ASan+UBSan tree).
#if defined(__GNUC__) && !defined(__clang__)
#define DM_ALIGNED(p, n) __builtin_assume_aligned(p, n)
#else
#define DM_ALIGNED(p, n) (p)
#endif
template <class R>
[[gnu::always_inline]] inline Lanes<R> load(const double (&p)[4]) noexcept {
  Lanes<R> r;
  std::memcpy(&r, DM_ALIGNED(p, sizeof(R)), sizeof r);
  return r;
}
template <class R>
[[gnu::always_inline]] inline void store(double (&p)[4], const Lanes<R>& v) noexcept {
  std::memcpy(DM_ALIGNED(p, sizeof(R)), &v, sizeof v);
}
#undef DM_ALIGNED
template <class R>
[[gnu::always_inline]] inline Lanes<R> splat(double x) noexcept {
  return make<R>(x, x, x, x);
}
#define DM_BINARY(op)                                                                                 \
  template <class R>                                                                                  \
  [[gnu::always_inline]] inline Lanes<R> operator op(const Lanes<R>& a, const Lanes<R>& b) noexcept { \
    DM_LANEWISE(Lanes<R>, a.h[i] op b.h[i]);                                                          \
  }
DM_BINARY(+)
DM_BINARY(-)
DM_BINARY(*)
DM_BINARY(/)
#undef DM_BINARY
template <class R>
[[gnu::always_inline]] inline Lanes<R> operator-(const Lanes<R>& a) noexcept {
  DM_LANEWISE(Lanes<R>, -a.h[i]);
}
template <class R>
[[gnu::always_inline]] inline LaneMask<R> greater(const Lanes<R>& a, const Lanes<R>& b) noexcept {
  DM_LANEWISE(LaneMask<R>, a.h[i] > b.h[i]);
}
template <class R>
[[gnu::always_inline]] inline LaneMask<R> operator&(const LaneMask<R>& a, const LaneMask<R>& b) noexcept {
  DM_LANEWISE(LaneMask<R>, a.h[i] & b.h[i]);
}
// m ? a : b per lane.
template <class R>
[[gnu::always_inline]] inline Lanes<R> select(const LaneMask<R>& m, const Lanes<R>& a, const Lanes<R>& b) noexcept {
  DM_LANEWISE(Lanes<R>, m.h[i] ? a.h[i] : b.h[i]);
}
#undef DM_LANEWISE
template <class R>
[[gnu::always_inline]] inline bool any(const LaneMask<R>& m) noexcept {
  bool out = false;
  for (int i = 0; i < Lanes<R>::kCount; ++i) {
    if constexpr (Lanes<R>::kWidth == 1) {
      out = out || m.h[i];
    } else {
      for (int k = 0; k < Lanes<R>::kWidth; ++k) out = out || m.h[i][k] != 0;
    }
  }
  return out;
}
#if defined(DM_SOLVER_VECTOR_LANES) && defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__)
// Quad lanes (only in the AVX2 and AVX-512 versions, which are flattened:
// these are inlined there): one sign-mask instruction instead of extracting
// and or-ing four lanes; one vector square root (IEEE, so the same bits as
// four std::sqrt) instead of four calls.
[[gnu::target("avx2")]] inline bool any(const LaneMask<Quad>& m) noexcept {
  return __builtin_ia32_movmskpd256(reinterpret_cast<Quad>(m.h[0])) != 0;
}
[[gnu::target("avx2")]] inline Lanes<Quad> sqrt(const Lanes<Quad>& a) noexcept {
  return {{__builtin_ia32_sqrtpd256(a.h[0])}};
}
#endif
// std::max(a, b) per lane (a when b is not larger, as std::max).
template <class R>
[[gnu::always_inline]] inline Lanes<R> max(const Lanes<R>& a, const Lanes<R>& b) noexcept {
  return select(greater(b, a), b, a);
}
template <class R>
[[gnu::always_inline]] inline Lanes<R> abs(const Lanes<R>& a) noexcept {
  return select(greater(splat<R>(0.0), a), splat<R>(0.0) - a, a);
}
template <class R>
[[gnu::always_inline]] inline Lanes<R> sqrt(const Lanes<R>& a) noexcept {
  return make<R>(std::sqrt(lane(a, 0)), std::sqrt(lane(a, 1)), std::sqrt(lane(a, 2)), std::sqrt(lane(a, 3)));
}

// The two bodies' velocities (or pseudo-velocities) of each lane.
template <class R>
struct LaneVelocity {
  Lanes<R> v[3], w[3];
};

template <class R>
[[gnu::always_inline]] inline void gather(const std::vector<Velocity>& vel, const int (&index)[4],
                                          LaneVelocity<R>& out) noexcept {
  const Velocity& s0 = vel[static_cast<std::size_t>(index[0])];
  const Velocity& s1 = vel[static_cast<std::size_t>(index[1])];
  const Velocity& s2 = vel[static_cast<std::size_t>(index[2])];
  const Velocity& s3 = vel[static_cast<std::size_t>(index[3])];
  for (int c = 0; c < 3; ++c) {
    out.v[c] = make<R>(s0.v[c], s1.v[c], s2.v[c], s3.v[c]);
    out.w[c] = make<R>(s0.w[c], s1.w[c], s2.w[c], s3.w[c]);
  }
}

template <class R>
[[gnu::always_inline]] inline void scatter(const LaneVelocity<R>& in, const int (&index)[4],
                                           std::vector<Velocity>& vel) noexcept {
  // A body two lanes name is non-dynamic: every lane holds it unchanged.
  for (int l = 0; l < 4; ++l) {
    Velocity& s = vel[static_cast<std::size_t>(index[l])];
    for (int c = 0; c < 3; ++c) {
      s.v[c] = lane(in.v[c], l);
      s.w[c] = lane(in.w[c], l);
    }
  }
}

// u·(v_B − v_A) + angA·ω_A + angB·ω_B along direction k, lane by lane.
template <class R>
[[gnu::always_inline]] inline Lanes<R> wideVelocity(const WideRow& r, int k, const Lanes<R> (&dv)[3],
                                                    const LaneVelocity<R>& A, const LaneVelocity<R>& B) noexcept {
  const auto dot = [](const double (&x)[3][4], const Lanes<R> (&y)[3]) {
    return (load<R>(x[0]) * y[0] + load<R>(x[1]) * y[1]) + load<R>(x[2]) * y[2];
  };
  return (dot(r.u[k], dv) + dot(r.angA[k], A.w)) + dot(r.angB[k], B.w);
}

// Applies impulse changes l along direction k of every lane.
template <class R>
[[gnu::always_inline]] inline void wideApply(const WideRow& r, int k, const Lanes<R>& l, const Lanes<R>& sA,
                                             const Lanes<R>& sB, LaneVelocity<R>& A, LaneVelocity<R>& B) noexcept {
  for (int c = 0; c < 3; ++c) {
    A.v[c] = A.v[c] + sA * load<R>(r.u[k][c]);
    A.w[c] = A.w[c] + l * load<R>(r.mAngA[k][c]);
    B.v[c] = B.v[c] + sB * load<R>(r.u[k][c]);
    B.w[c] = B.w[c] + l * load<R>(r.mAngB[k][c]);
  }
}

// One contact of every lane of a WideRow: the friction pair (projected onto
// the Coulomb disk |λt| ≤ μ·λn), then the normal row, so that
// non-penetration is the last word. Lanes without friction (a zero tangent
// effective mass) and empty lanes (all zero) keep their impulses. With
// kResidual, `change` takes the largest |Δλ|/m_eff per lane (0/0 of an empty
// lane is NaN, which max() passes over).
template <class R, bool kResidual>
[[gnu::always_inline]] inline void wideContact(WideRow& r, LaneVelocity<R>& A, LaneVelocity<R>& B,
                                               Lanes<R>& change) noexcept {
  const Lanes<R> zero = splat<R>(0.0);
  const Lanes<R> imA = load<R>(r.imA), imB = load<R>(r.imB), negImA = zero - imA;
  const Lanes<R> e1 = load<R>(r.effMass[1]), e2 = load<R>(r.effMass[2]);
  const LaneMask<R> rubs = greater(e1, zero) & greater(e2, zero);
  Lanes<R> dv[3];
  for (int c = 0; c < 3; ++c) dv[c] = B.v[c] - A.v[c];
  const Lanes<R> i0 = load<R>(r.impulse[0]), i1 = load<R>(r.impulse[1]), i2 = load<R>(r.impulse[2]);
  const Lanes<R> limit = load<R>(r.friction) * i0;
  Lanes<R> l1 = i1 - e1 * wideVelocity(r, 1, dv, A, B);
  Lanes<R> l2 = i2 - e2 * wideVelocity(r, 2, dv, A, B);
  const Lanes<R> len2 = l1 * l1 + l2 * l2;
  const LaneMask<R> slides = greater(len2, limit * limit);
  if (any(slides)) {
    const Lanes<R> f = select(greater(len2, zero), limit / sqrt(len2), zero);
    l1 = select(slides, l1 * f, l1);
    l2 = select(slides, l2 * f, l2);
  }
  const Lanes<R> d1 = select(rubs, l1 - i1, zero), d2 = select(rubs, l2 - i2, zero);
  store(r.impulse[1], select(rubs, l1, i1));
  store(r.impulse[2], select(rubs, l2, i2));
  // Tangent 1 then tangent 2 (as the scalar solver).
  for (int c = 0; c < 3; ++c) {
    A.v[c] = A.v[c] + (negImA * d1) * load<R>(r.u[1][c]);
    A.v[c] = A.v[c] + (negImA * d2) * load<R>(r.u[2][c]);
    A.w[c] = A.w[c] + d1 * load<R>(r.mAngA[1][c]);
    A.w[c] = A.w[c] + d2 * load<R>(r.mAngA[2][c]);
    B.v[c] = B.v[c] + (imB * d1) * load<R>(r.u[1][c]);
    B.v[c] = B.v[c] + (imB * d2) * load<R>(r.u[2][c]);
    B.w[c] = B.w[c] + d1 * load<R>(r.mAngB[1][c]);
    B.w[c] = B.w[c] + d2 * load<R>(r.mAngB[2][c]);
  }
  if constexpr (kResidual) change = max(max(change, abs(d1) / e1), abs(d2) / e2);
  for (int c = 0; c < 3; ++c) dv[c] = B.v[c] - A.v[c];
  const Lanes<R> e0 = load<R>(r.effMass[0]);
  const Lanes<R> vn = wideVelocity(r, 0, dv, A, B);
  const Lanes<R> next = max(i0 + e0 * (load<R>(r.target) - vn), zero);
  const Lanes<R> d0 = next - i0;
  store(r.impulse[0], next);
  wideApply(r, 0, d0, negImA * d0, imB * d0, A, B);
  if constexpr (kResidual) change = max(change, abs(d0) / e0);
}

// The split-impulse update of the normal rows of a WideRow on
// pseudo-velocities.
template <class R>
[[gnu::always_inline]] inline void widePush(WideRow& r, LaneVelocity<R>& A, LaneVelocity<R>& B) noexcept {
  const Lanes<R> zero = splat<R>(0.0);
  Lanes<R> dv[3];
  for (int c = 0; c < 3; ++c) dv[c] = B.v[c] - A.v[c];
  const Lanes<R> i0 = load<R>(r.pushImpulse);
  const Lanes<R> vn = wideVelocity(r, 0, dv, A, B);
  const Lanes<R> next = max(i0 + load<R>(r.effMass[0]) * (load<R>(r.pushTarget) - vn), zero);
  const Lanes<R> d0 = next - i0;
  store(r.pushImpulse, next);
  wideApply(r, 0, d0, (zero - load<R>(r.imA)) * d0, load<R>(r.imB) * d0, A, B);
}

// One sweep over the groups; kMode 0: velocities, 1: velocities with the
// residual (returned), 2: split-impulse pseudo-velocities.
template <class R, int kMode>
[[gnu::always_inline]] inline double sweepGroups(const std::vector<ConstraintSolver::Group>& groups,
                                                 std::vector<WideRow>& rows, std::vector<Velocity>& vel) noexcept {
  Lanes<R> change = splat<R>(0.0);
  for (const ConstraintSolver::Group& g : groups) {
    LaneVelocity<R> A, B;
    gather(vel, g.a, A);
    gather(vel, g.b, B);
    for (std::uint32_t k = g.rowBegin; k < g.rowEnd; ++k) {
      if constexpr (kMode == 2)
        widePush(rows[k], A, B);
      else
        wideContact<R, kMode == 1>(rows[k], A, B, change);
    }
    scatter(A, g.a, vel);
    scatter(B, g.b, vel);
  }
  alignas(32) double out[4];
  store(out, change);
  return std::max({out[0], out[1], out[2], out[3]});
}

// Applies the contacts' incoming impulses (warm start), group by group.
template <class R>
[[gnu::always_inline]] inline void warmStartGroups(const std::vector<ConstraintSolver::Group>& groups,
                                                   const std::vector<WideRow>& rows,
                                                   std::vector<Velocity>& vel) noexcept {
  for (const ConstraintSolver::Group& g : groups) {
    LaneVelocity<R> A, B;
    gather(vel, g.a, A);
    gather(vel, g.b, B);
    for (std::uint32_t k = g.rowBegin; k < g.rowEnd; ++k) {
      const WideRow& r = rows[k];
      const Lanes<R> negImA = splat<R>(0.0) - load<R>(r.imA), imB = load<R>(r.imB);
      for (int d = 0; d < 3; ++d) {
        const Lanes<R> l = load<R>(r.impulse[d]);
        wideApply(r, d, l, negImA * l, imB * l, A, B);
      }
    }
    scatter(A, g.a, vel);
    scatter(B, g.b, vel);
  }
}

// buildContactRows' inputs and output.
struct RowBuild {
  std::span<const SolverBody> bodies;
  std::span<const ContactConstraint> contacts;
  double dt;
  const SolverOptions& o;
  const std::vector<ConstraintSolver::Group>& groups;
  const std::vector<ConstraintSolver::Manifold>& manifolds;
  const std::vector<double>& invMass;
  const std::vector<Mat3>& invInertia;
  const std::vector<Velocity>& velocity;
  std::vector<WideRow>& rows;
};

template <class R, class F>
[[gnu::always_inline]] inline Lanes<R> lanesOf(F f) noexcept {
  return make<R>(f(0), f(1), f(2), f(3));
}
template <class R>
[[gnu::always_inline]] inline void cross(const Lanes<R> (&a)[3], const Lanes<R> (&b)[3], Lanes<R> (&out)[3]) noexcept {
  out[0] = a[1] * b[2] - a[2] * b[1];
  out[1] = a[2] * b[0] - a[0] * b[2];
  out[2] = a[0] * b[1] - a[1] * b[0];
}
template <class R>
[[gnu::always_inline]] inline Lanes<R> dot(const Lanes<R> (&a)[3], const Lanes<R> (&b)[3]) noexcept {
  return (a[0] * b[0] + a[1] * b[1]) + a[2] * b[2];
}
// Eigen's Mat3 · Vec3, sum for sum: rows 0 and 1 as one SSE2 packet
// ((m0·v0 + m1·v1) + m2·v2), row 2 reduced m0·v0 + (m1·v1 + m2·v2).
template <class R>
[[gnu::always_inline]] inline void times(const Lanes<R> (&m)[3][3], const Lanes<R> (&v)[3],
                                         Lanes<R> (&out)[3]) noexcept {
  for (int r = 0; r < 2; ++r) out[r] = (m[r][0] * v[0] + m[r][1] * v[1]) + m[r][2] * v[2];
  out[2] = m[2][0] * v[0] + (m[2][1] * v[1] + m[2][2] * v[2]);
}
// x in the active lanes, 0 elsewhere.
template <class R>
[[gnu::always_inline]] inline void put(double (&out)[4], const LaneMask<R>& active, const Lanes<R>& x) noexcept {
  store(out, select(active, x, splat<R>(0.0)));
}

template <class R>
[[gnu::always_inline]] inline void buildRowsAs(const RowBuild& in) noexcept {
  using L = Lanes<R>;
  const SolverOptions& o = in.o;
  const double inv = 1.0 / in.dt;
  const double scale = o.warmStart ? o.warmStartFactor : 0.0;
  const std::size_t world = in.velocity.size() - 1;
  const L zero = splat<R>(0.0);
  ContactConstraint empty;  // an empty lane's stand-in (any finite contact; the lane is zeroed)
  empty.point.normal = Vec3::UnitZ();
  for (const ConstraintSolver::Group& g : in.groups) {
    // The lanes' bodies: inverse masses and inertias, origins, velocities.
    std::size_t ia[4], ib[4];
    std::uint32_t first[4], size[4];
    for (int l = 0; l < 4; ++l) {
      const std::uint32_t x = g.manifold[l];
      const bool none = x == ConstraintSolver::kNoManifold;
      first[l] = none ? 0 : in.manifolds[x].begin;
      size[l] = none ? 0 : in.manifolds[x].end - in.manifolds[x].begin;
      ia[l] = static_cast<std::size_t>(g.a[l]);
      ib[l] = static_cast<std::size_t>(g.b[l]);
    }
    const L mA = lanesOf<R>([&](int l) { return in.invMass[ia[l]]; });
    const L mB = lanesOf<R>([&](int l) { return in.invMass[ib[l]]; });
    L IA[3][3], IB[3][3], XA[3], XB[3], VA[3], WA[3], VB[3], WB[3];
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) {
        IA[r][c] = lanesOf<R>([&](int l) { return in.invInertia[ia[l]](r, c); });
        IB[r][c] = lanesOf<R>([&](int l) { return in.invInertia[ib[l]](r, c); });
      }
      XA[r] = lanesOf<R>([&](int l) { return ia[l] == world ? 0.0 : in.bodies[ia[l]].position[r]; });
      XB[r] = lanesOf<R>([&](int l) { return ib[l] == world ? 0.0 : in.bodies[ib[l]].position[r]; });
      VA[r] = lanesOf<R>([&](int l) { return in.velocity[ia[l]].v[r]; });
      WA[r] = lanesOf<R>([&](int l) { return in.velocity[ia[l]].w[r]; });
      VB[r] = lanesOf<R>([&](int l) { return in.velocity[ib[l]].v[r]; });
      WB[r] = lanesOf<R>([&](int l) { return in.velocity[ib[l]].w[r]; });
    }
    for (std::uint32_t k = 0; k < g.rowEnd - g.rowBegin; ++k) {
      // Contact k of each lane, with its tangent basis.
      const ContactConstraint* c[4];
      Vec3 t[4][2];
      for (int l = 0; l < 4; ++l) {
        c[l] = k < size[l] ? &in.contacts[first[l] + k] : &empty;
        tangentBasis(c[l]->point.normal, t[l][0], t[l][1]);
      }
      const LaneMask<R> active = greater(lanesOf<R>([&](int l) { return k < size[l] ? 1.0 : 0.0; }), zero);
      WideRow& w = in.rows[g.rowBegin + k];
      L P[3], rA[3], rB[3], U[3][3], F[3];
      for (int r = 0; r < 3; ++r) {
        P[r] = lanesOf<R>([&](int l) { return c[l]->point.position[r]; });
        U[0][r] = lanesOf<R>([&](int l) { return c[l]->point.normal[r]; });
        U[1][r] = lanesOf<R>([&](int l) { return t[l][0][r]; });
        U[2][r] = lanesOf<R>([&](int l) { return t[l][1][r]; });
        F[r] = lanesOf<R>([&](int l) { return c[l]->frictionImpulse[r]; });
        rA[r] = P[r] - XA[r];
        rB[r] = P[r] - XB[r];
      }
      L angA0[3], angB0[3];
      for (int d = 0; d < 3; ++d) {
        L angA[3], angB[3], mAngA[3], mAngB[3];
        cross(rA, U[d], angA);
        for (L& x : angA) x = -x;  // −rA × u
        cross(rB, U[d], angB);
        times(IA, angA, mAngA);
        times(IB, angB, mAngB);
        const L sq = dot(U[d], U[d]);
        const L m = ((mA * sq + dot(angA, mAngA)) + mB * sq) + dot(angB, mAngB);
        put(w.effMass[d], active, select(greater(m, splat<R>(1e-300)), splat<R>(1.0) / m, zero));
        for (int e = 0; e < 3; ++e) {
          put(w.u[d][e], active, U[d][e]);
          put(w.angA[d][e], active, angA[e]);
          put(w.angB[d][e], active, angB[e]);
          put(w.mAngA[d][e], active, mAngA[e]);
          put(w.mAngB[d][e], active, mAngB[e]);
        }
        if (d == 0)
          for (int e = 0; e < 3; ++e) {
            angA0[e] = angA[e];
            angB0[e] = angB[e];
          }
      }
      put(w.imA, active, mA);
      put(w.imB, active, mB);
      put(w.friction, active, lanesOf<R>([&](int l) { return c[l]->friction; }));
      // Targets from the approach speed before any impulse of this step.
      L dv[3];
      for (int e = 0; e < 3; ++e) dv[e] = VB[e] - VA[e];
      const L vn = (dot(U[0], dv) + dot(angA0, WA)) + dot(angB0, WB);
      const L depth = lanesOf<R>([&](int l) { return c[l]->point.depth; });
      const L restitution = lanesOf<R>([&](int l) { return c[l]->restitution; });
      L target = select(greater(splat<R>(-o.restitutionThreshold), vn), -restitution * vn, zero);
      const L over = max(depth - splat<R>(o.slop), zero) * splat<R>(inv);
      const L cap = splat<R>(o.maxCorrectionVelocity);
      const L corr = select(greater(over, cap), cap, over);  // std::min(over, cap)
      L pushTarget = zero;
      if (o.splitImpulse)
        pushTarget = splat<R>(o.pushFactor) * corr;
      else
        target = max(target, splat<R>(o.baumgarte) * corr);
      const LaneMask<R> speculative = greater(zero, depth);  // may close the gap this step
      put(w.target, active, select(speculative, depth * splat<R>(inv), target));
      put(w.pushTarget, active, select(speculative, zero, pushTarget));
      store(w.pushImpulse, zero);
      const L sc = splat<R>(scale);
      put(w.impulse[0], active, sc * max(lanesOf<R>([&](int l) { return c[l]->normalImpulse; }), zero));
      put(w.impulse[1], active, sc * dot(F, U[1]));
      put(w.impulse[2], active, sc * dot(F, U[2]));
    }
  }
}

// The sweeps: kMode 0, 1, 2 of sweepGroups and 3: warmStartGroups (returns 0).
using SweepFn = double (*)(const std::vector<ConstraintSolver::Group>&, std::vector<WideRow>&,
                           std::vector<Velocity>&) noexcept;
template <class R, int kMode>
[[gnu::always_inline]] inline double sweepAs(const std::vector<ConstraintSolver::Group>& groups,
                                             std::vector<WideRow>& rows, std::vector<Velocity>& vel) noexcept {
  if constexpr (kMode == 3) {
    warmStartGroups<R>(groups, rows, vel);
    return 0.0;
  } else {
    return sweepGroups<R, kMode>(groups, rows, vel);
  }
}

void buildRowsNarrow(const RowBuild& in) noexcept { buildRowsAs<Narrow>(in); }

template <int kMode>
double sweepNarrow(const std::vector<ConstraintSolver::Group>& groups, std::vector<WideRow>& rows,
                   std::vector<Velocity>& vel) noexcept {
  return sweepAs<Narrow, kMode>(groups, rows, vel);
}

// Also compiled for AVX2, where the CPU (and the OS) has it, which the build
// does not assume: the four lanes in one 256-bit register instead of two
// 128-bit ones, half the instructions (AVX2, not AVX: the lane masks are
// 256-bit integer operations); and for x86-64-v4 (AVX-512 VL), where 32
// registers hold the lanes without spilling. GCC only (function targets
// with vector types); chosen once at load time by dm::simdLevel() (the
// CPU's widest, capped by DM_SIMD; not an ifunc: ThreadSanitizer builds
// crash in an ifunc resolver, which runs before the TSan runtime is up).
#if defined(DM_SOLVER_VECTOR_LANES) && defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__)
#define DM_SOLVER_AVX 1
template <int kMode>
[[gnu::target("avx2"), gnu::noinline, gnu::flatten]] double sweepAvx(const std::vector<ConstraintSolver::Group>& groups,
                                                      std::vector<WideRow>& rows,
                                                      std::vector<Velocity>& vel) noexcept {
  return sweepAs<Quad, kMode>(groups, rows, vel);
}
[[gnu::target("avx2"), gnu::noinline]] void buildRowsAvx(const RowBuild& in) noexcept { buildRowsAs<Quad>(in); }
[[gnu::target("arch=x86-64-v4"), gnu::noinline]] void buildRowsAvx512(const RowBuild& in) noexcept {
  buildRowsAs<Quad>(in);
}
template <int kMode>
[[gnu::target("arch=x86-64-v4"), gnu::noinline, gnu::flatten]] double sweepAvx512(
    const std::vector<ConstraintSolver::Group>& groups, std::vector<WideRow>& rows,
    std::vector<Velocity>& vel) noexcept {
  return sweepAs<Quad, kMode>(groups, rows, vel);
}
#endif

template <int kMode>
SweepFn pickSweep() noexcept {
#if defined(DM_SOLVER_AVX)
  if (simdLevel() == SimdLevel::Avx512) return &sweepAvx512<kMode>;
  if (simdLevel() == SimdLevel::Avx2) return &sweepAvx<kMode>;
#endif
  return &sweepNarrow<kMode>;
}

using BuildFn = void (*)(const RowBuild&) noexcept;
BuildFn pickBuild() noexcept {
#if defined(DM_SOLVER_AVX)
  if (simdLevel() == SimdLevel::Avx512) return &buildRowsAvx512;
  if (simdLevel() == SimdLevel::Avx2) return &buildRowsAvx;
#endif
  return &buildRowsNarrow;
}

const BuildFn gBuildRows = pickBuild();
const SweepFn gSweepVelocities = pickSweep<0>();
const SweepFn gSweepResidual = pickSweep<1>();
const SweepFn gSweepPush = pickSweep<2>();
const SweepFn gWarmStart = pickSweep<3>();

}  // namespace

// The three rows of every contact, four lanes at a time: row k of a group
// holds contact k of each lane's manifold (an empty lane, or a manifold with
// fewer contacts: all zero). Lane by lane the arithmetic is that of the
// scalar derivation in Eigen, sum for sum, so the rows are the same bits in
// every lane representation.
void ConstraintSolver::buildContactRows(std::span<const SolverBody> bodies,
                                        std::span<const ContactConstraint> contacts, double dt,
                                        const SolverOptions& o) {
  wideRows_.resize(groups_.empty() ? 0 : groups_.back().rowEnd);
  gBuildRows({bodies, contacts, dt, o, groups_, manifolds_, invMass_, invInertia_, velocity_, wideRows_});
}

// One velocity sweep: joint rows, then the contacts group by group. With
// kResidual, returns the largest velocity correction |Δλ|/m_eff (else 0).
template <bool kResidual>
double ConstraintSolver::sweep() {
  double change = 0.0;
  for (Row& r : jointRows_) {
    const double applied = solveRow(r, velocity_, r.target, r.impulse);
    if constexpr (kResidual)
      if (r.effMass > 0.0) change = std::max(change, std::abs(applied) / r.effMass);
  }
  change = std::max(change, kResidual ? gSweepResidual(groups_, wideRows_, velocity_)
                                      : gSweepVelocities(groups_, wideRows_, velocity_));
  return change;
}

void ConstraintSolver::pushSweep() {
  for (Row& r : jointRows_) solveRow(r, push_, r.pushTarget, r.pushImpulse);
  gSweepPush(groups_, wideRows_, push_);
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
  scheduleManifolds(contacts);
  buildContactRows(bodies, contacts, dt, o);

  // Warm start.
  SolverStats stats;
  stats.rows = static_cast<int>(jointRows_.size() + 3 * contacts.size());
  if (o.warmStart) {
    for (const Row& r : jointRows_)
      applyImpulse(r, velocity_[static_cast<std::size_t>(r.a)], velocity_[static_cast<std::size_t>(r.b)],
                   r.impulse);
    gWarmStart(groups_, wideRows_, velocity_);
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
  for (const Group& g : groups_)
    for (int l = 0; l < kLanes; ++l) {
      const std::uint32_t x = g.manifold[l];
      if (x == kNoManifold) continue;
      for (std::uint32_t i = manifolds_[x].begin; i < manifolds_[x].end; ++i) {
        const WideRow& w = wideRows_[g.rowBegin + (i - manifolds_[x].begin)];
        ContactConstraint& c = contacts[i];
        c.normalImpulse = w.impulse[0][l];
        for (int e = 0; e < 3; ++e) c.frictionImpulse[e] = w.impulse[1][l] * w.u[1][e][l] + w.impulse[2][l] * w.u[2][e][l];
        stats.maxImpulse = std::max(stats.maxImpulse, c.normalImpulse);
      }
    }
  return stats;
}

// ----------------------------------------------------------------- cache ---

namespace {

bool pairLess(int a0, int b0, int a1, int b1) noexcept { return a0 < a1 || (a0 == a1 && b0 < b1); }

}  // namespace

void ContactCache::reserve(std::size_t contacts) {
  entries_.reserve(contacts);
  runs_.reserve(contacts);
  used_.reserve(contacts);
}

void ContactCache::store(std::span<const ContactConstraint> contacts, std::span<const SolverBody> bodies) {
  entries_.clear();
  runs_.clear();
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
      runs_.push_back({c.bodyA, c.bodyB, static_cast<std::uint32_t>(i), static_cast<std::uint32_t>(i)});
    }
    ++runs_.back().end;
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
  // The entries stay in input order; the runs (far fewer) are sorted by
  // pair, a pair's in input order, and index them (sorted only when out of
  // order: the check is linear).
  const auto runLess = [](const Run& x, const Run& y) {
    return pairLess(x.a, x.b, y.a, y.b) || (x.a == y.a && x.b == y.b && x.begin < y.begin);
  };
  if (!std::is_sorted(runs_.begin(), runs_.end(), runLess)) std::sort(runs_.begin(), runs_.end(), runLess);
}

std::pair<const ContactCache::Run*, const ContactCache::Run*> ContactCache::runsOf(int a, int b,
                                                                                 const Run* hint) const noexcept {
  const Run *begin = runs_.data(), *end = runs_.data() + runs_.size();
  const Run* first = nullptr;
  // Where the contacts come pair by pair in the runs' order, the pair's runs
  // start right at the hint (the end of the last pair's): no search.
  if (hint && hint >= begin && hint < end && hint->a == a && hint->b == b &&
      (hint == begin || pairLess(hint[-1].a, hint[-1].b, a, b)))
    first = hint;
  else
    first = std::lower_bound(begin, end, std::pair{a, b}, [](const Run& x, const std::pair<int, int>& k) {
      return pairLess(x.a, x.b, k.first, k.second);
    });
  const Run* last = first;
  while (last != runs_.data() + runs_.size() && last->a == a && last->b == b) ++last;
  return {first, last};
}

int ContactCache::persist(int a, int b, std::span<const SolverBody> bodies, double margin, double mu, double e,
                          std::vector<ContactConstraint>& out) const {
  const auto [first, last] = runsOf(a, b);
  const PoseRef pa = poseOf(bodies, a), pb = poseOf(bodies, b);
  int added = 0;
  for (const Run* r = first; r != last; ++r) {
    for (auto it = entries_.begin() + r->begin; it != entries_.begin() + r->end; ++it) {
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
  const Run *first = nullptr, *last = nullptr;
  PoseRef pa;
  Mat3 fromA = Mat3::Identity();  // A's frame → world (set with the first run)
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
      std::tie(first, last) = runsOf(c.bodyA, c.bodyB, last);
      pa = poseOf(bodies, c.bodyA);
      fromA = pa.q.toRotationMatrix();
    }
    if (first == last) continue;  // a new pair
    const Vec3 localA = fromA.transpose() * (c.point.position - pa.x);
    std::ptrdiff_t best = -1;
    double bestDist = matchDistance * matchDistance;
    bool keyed = false;  // found by feature key: the first match wins
    for (const Run* r = first; r != last && !keyed; ++r) {
      for (std::uint32_t k = r->begin; k < r->end; ++k) {
        const Entry& it = entries_[k];
        if (used_[k]) continue;
        if (c.featureKey != 0) {
          if (it.key == c.featureKey) {
            best = k;
            keyed = true;
            break;
          }
          continue;
        }
        if (it.normal.dot(c.point.normal) < 0.7) continue;
        const double dist = (it.localA - localA).squaredNorm();
        if (dist <= bestDist) {
          bestDist = dist;
          best = k;
        }
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

#undef DM_SOLVER_AVX
#undef DM_SOLVER_VECTOR_LANES
