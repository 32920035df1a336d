// Cosserat rods: building, the end attachments and the direct XPBD step.
// See dm/physics/rod.hpp for the model and the solver.
#include <dm/collide/triangle.hpp>
#include <dm/math/geometry.hpp>
#include <dm/physics/rod.hpp>

#include <Eigen/Cholesky>
#include <Eigen/LU>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <string>
#include <utility>

namespace dm {

namespace {
namespace rodimpl {

Error invalidRod(std::string what, std::string where, std::string hint = {}) {
  return fail(ErrorCode::InvalidArgument, std::move(what), std::move(where), std::move(hint));
}

Status positiveField(double value, const char* field, const char* unit) {
  if (std::isfinite(value) && value > 0) return ok();
  return invalidRod(formatString("%s is %g %s", field, value, unit), formatString("RodOptions.%s", field),
                    formatString("give a finite %s > 0 %s", field, unit));
}

Mat3 cross(const Vec3& r) {
  Mat3 m;
  m << 0, -r.z(), r.y(), r.z(), 0, -r.x(), -r.y(), r.x(), 0;
  return m;
}

// Rotates body z to the world: the tangent of a segment of orientation q.
Vec3 axisOf(const Quat& q) {  // the third column of q's rotation matrix
  const double x = q.x(), y = q.y(), z = q.z(), w = q.w();
  return Vec3(2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y));
}

// exp(dθ) ⊗ q: q turned by |dθ| about dθ in the world frame (exactly, so
// that a step's corrections and logRotation() agree at any angle).
void rotate(Quat& q, const Vec3& dtheta) {
  const double angle = dtheta.norm();
  if (angle < 1e-9) {  // first order: cos ≈ 1, sin(a/2)/a ≈ ½
    const Quat dq(1, 0.5 * dtheta.x(), 0.5 * dtheta.y(), 0.5 * dtheta.z());
    q = (dq * q).normalized();
    return;
  }
  const double s = std::sin(0.5 * angle) / angle;
  const Quat dq(std::cos(0.5 * angle), s * dtheta.x(), s * dtheta.y(), s * dtheta.z());
  q = (dq * q).normalized();
}

// The rotation vector of q (the shorter way round): the inverse of rotate().
Vec3 logRotation(Quat q) {
  if (q.w() < 0) q.coeffs() = -q.coeffs();
  const double s = q.vec().norm();
  if (s < 1e-12) return 2 * q.vec();
  return (2 * std::atan2(s, q.w()) / s) * q.vec();
}

// The positive semidefinite part of −sym([a]×[b]×) = (a·b) I − ½(a bᵀ + b aᵀ),
// in closed form. With k = |a||b| and c = â·b̂ its eigenvalues are ½k(c − 1)
// along â + b̂, ½k(1 + c) along â − b̂ and k c along â × b̂; the kept part is
// ½k(1 + c)(I − e eᵀ) − ½k/(1 + c) v vᵀ for c > 0 (e = (â + b̂)/|â + b̂|,
// v = â × b̂; k (I − b̂ b̂ᵀ) when a ∥ b, a string in tension) and
// ½k(1 + c) d dᵀ for c ≤ 0 (d = (â − b̂)/|â − b̂|).
Mat3 stiffeningPart(const Vec3& a, const Vec3& b) {
  const double na = a.norm(), nb = b.norm();
  if (na * nb <= 0) return Mat3::Zero();
  const Vec3 ua = a / na, ub = b / nb;
  const double k = na * nb, c = ua.dot(ub);
  if (c > 0) {
    const Vec3 e = (ua + ub) / std::sqrt(2 * (1 + c));
    const Vec3 v = ua.cross(ub);
    return 0.5 * k * (1 + c) * (Mat3::Identity() - e * e.transpose()) -
           (0.5 * k / (1 + c)) * (v * v.transpose());
  }
  const Vec3 d = (ua - ub) / std::sqrt(2 * (1 - c));
  return 0.5 * k * (1 + c) * (d * d.transpose());
}

// One constraint's Jacobian block for one segment, J = [[A, X], [0, Y]] in
// 3×3 blocks (A: position rows by position, ±I or with rows off; X, Y: by
// rotation; rotation rows never depend on position), times that segment's
// W = diag(w I, P): J W = [[w A, X P], [0, Y P]]. addTimesTransposeOf forms
// J W Kᵀ for another block K of the same segment from 3×3 products, about
// half the work of the 6×6 ones.
struct WeightedJacobian {
  Mat3 wa, xp, yp;
  const Mat6& j;
  WeightedJacobian(const Mat6& jacobian, double w, const Mat3& p)
      : wa(w * jacobian.topLeftCorner<3, 3>()),
        xp(jacobian.topRightCorner<3, 3>() * p),
        yp(jacobian.bottomRightCorner<3, 3>() * p),
        j(jacobian) {}
  void addTimesTransposeOf(const WeightedJacobian& k, Mat6& out) const {
    const Mat3 kaT = k.j.topLeftCorner<3, 3>().transpose(), kxT = k.j.topRightCorner<3, 3>().transpose(),
               kyT = k.j.bottomRightCorner<3, 3>().transpose();
    out.topLeftCorner<3, 3>() += wa * kaT + xp * kxT;
    out.topRightCorner<3, 3>() += xp * kyT;
    out.bottomLeftCorner<3, 3>() += yp * kxT;
    out.bottomRightCorner<3, 3>() += yp * kyT;
  }
};

// The smallest rotation taking unit vector a to unit vector b (half a turn
// about an axis normal to a when they are opposite).
Quat minimalRotation(const Vec3& a, const Vec3& b) {
  const double c = a.dot(b);
  if (c < -1 + 1e-12) {
    const Vec3 axis = a.unitOrthogonal();
    return Quat(0, axis.x(), axis.y(), axis.z());
  }
  const Vec3 s = a.cross(b);
  return Quat(1 + c, s.x(), s.y(), s.z()).normalized();
}

constexpr std::uint8_t kAllRows = 0x3F;
constexpr std::uint8_t kPositionRows = 0x07;

}  // namespace rodimpl
}  // namespace

const char* toString(RodAttachment attachment) noexcept {
  switch (attachment) {
    case RodAttachment::Free:
      return "free";
    case RodAttachment::Pinned:
      return "pinned";
    case RodAttachment::Clamped:
      return "clamped";
  }
  return "?";
}

Result<CosseratRod> CosseratRod::create(const RodOptions& o) {
  using namespace rodimpl;
  if (o.nodes.size() < 2)
    return invalidRod(formatString("%zu nodes", o.nodes.size()), "RodOptions.nodes",
                      "give the centreline as at least two points (one segment)");
  if (o.nodes.size() - 1 > kMaxSegments)
    return invalidRod(formatString("%zu segments, more than %zu", o.nodes.size() - 1, kMaxSegments),
                      "RodOptions.nodes", "use fewer, longer segments");
  for (std::size_t k = 0; k < o.nodes.size(); ++k) {
    if (!o.nodes[k].allFinite())
      return invalidRod("the point is not finite", formatString("RodOptions.nodes[%zu]", k));
    if (k > 0 && (o.nodes[k] - o.nodes[k - 1]).norm() < 1e-9)
      return invalidRod(formatString("it is %g m from node %zu", (o.nodes[k] - o.nodes[k - 1]).norm(), k - 1),
                        formatString("RodOptions.nodes[%zu]", k),
                        "consecutive nodes must be at least 1e-9 m apart");
  }
  if (Status s = positiveField(o.radius, "radius", "m"); !s) return std::move(s).error();
  if (Status s = positiveField(o.density, "density", "kg/m^3"); !s) return std::move(s).error();
  if (Status s = positiveField(o.youngModulus, "youngModulus", "Pa"); !s) return std::move(s).error();
  if (Status s = positiveField(o.shearModulus, "shearModulus", "Pa"); !s) return std::move(s).error();
  if (o.rest != RodRestShape::Straight && o.rest != RodRestShape::Initial)
    return invalidRod(formatString("unknown rest shape %d", int(o.rest)), "RodOptions.rest");

  CosseratRod rod;
  if (Status s = rod.setGravity(o.gravity); !s) return std::move(s).error().within("RodOptions");
  if (Status s = rod.setDamping(o.damping); !s) return std::move(s).error().within("RodOptions");
  if (Status s = rod.setIterations(o.iterations); !s) return std::move(s).error().within("RodOptions");

  const std::size_t n = o.nodes.size() - 1;
  const double r = o.radius;
  const double area = std::numbers::pi * r * r;
  const double areaMoment = std::numbers::pi * r * r * r * r / 4;  // I, per bending axis
  rod.axialK_ = o.youngModulus * area;
  rod.bendK_ = o.youngModulus * areaMoment;
  rod.twistK_ = o.shearModulus * 2 * areaMoment;  // J = 2 I for a circle

  rod.p_.resize(n);
  rod.q_.resize(n);
  rod.len_.resize(n);
  rod.mass_.resize(n);
  rod.inertiaPerp_.resize(n);
  rod.inertiaAxial_.resize(n);
  Vec3 previousTangent = Vec3::UnitZ();
  Quat frame = Quat::Identity();
  for (std::size_t i = 0; i < n; ++i) {
    const Vec3 d = o.nodes[i + 1] - o.nodes[i];
    const double l = d.norm();
    const Vec3 t = d / l;
    // Parallel transport: the minimal rotation from the previous tangent, so
    // an initially curved rod starts without twist.
    frame = (minimalRotation(previousTangent, t) * frame).normalized();
    previousTangent = t;
    rod.p_[i] = 0.5 * (o.nodes[i] + o.nodes[i + 1]);
    rod.q_[i] = frame;
    rod.len_[i] = l;
    rod.mass_[i] = o.density * area * l;
    rod.inertiaPerp_[i] = rod.mass_[i] * (3 * r * r + l * l) / 12;  // solid cylinder
    rod.inertiaAxial_[i] = rod.mass_[i] * r * r / 2;
    rod.restLength_ += l;
  }
  rod.v_.assign(n, Vec3::Zero());
  rod.w_.assign(n, Vec3::Zero());
  rod.pPrev_ = rod.pStart_ = rod.p_;
  rod.qPrev_ = rod.qStart_ = rod.q_;
  rod.wg_.assign(n, Vec6::Zero());
  rod.kick_.assign(n, Vec6::Zero());
  rod.invInertia_.assign(n, Mat3::Identity());
  rod.force_.assign(n, Vec3::Zero());
  rod.torque_.assign(n, Vec3::Zero());
  rod.nodeForce_.assign(n + 1, Vec3::Zero());
  rod.kinematic_.assign(n, 0);
  rod.contactImpulse_.assign(n, Vec6::Zero());
  rod.radius_ = r;
  rod.graspCenter_.assign(n, Vec3::Zero());
  rod.graspFrame_.assign(n, Quat::Identity());

  const std::size_t m = n + 1;
  rod.restRel_.assign(m, Quat::Identity());
  rod.compliance_.assign(m, Vec6::Zero());
  rod.rows_.assign(m, 0);
  // Each constraint holds the rod's elasticity over the length it stands for:
  // half of each segment it joins, so an attachment holds its end node
  // through the end segment's outer half and the lengths add up to the rod's.
  for (std::size_t c = 0; c <= n; ++c) {
    const double lc = 0.5 * ((c > 0 ? rod.len_[c - 1] : 0.0) + (c < n ? rod.len_[c] : 0.0));
    Vec6 alpha;
    alpha << lc / rod.axialK_, lc / rod.axialK_, lc / rod.axialK_, lc / rod.bendK_, lc / rod.bendK_,
        lc / rod.twistK_;
    rod.compliance_[c] = alpha;
    if (c == 0 || c == n) continue;  // the ends start free
    rod.rows_[c] = kAllRows;
    if (o.rest == RodRestShape::Initial)
      rod.restRel_[c] = (rod.q_[c - 1].conjugate() * rod.q_[c]).conjugate();
  }
  rod.lambda_.assign(m, Vec6::Zero());
  rod.rhs_.assign(m, Vec6::Zero());
  rod.dlambda_.assign(m, Vec6::Zero());
  rod.jl_.assign(m, Mat6::Zero());
  rod.jr_.assign(m, Mat6::Zero());
  rod.diag_.assign(m, Mat6::Identity());
  rod.off_.assign(m, Mat6::Zero());
  rod.elim_.assign(m, Mat6::Zero());
  return rod;
}

Vec3 CosseratRod::node(std::size_t k) const {
  const std::size_t n = segmentCount();
  auto startOf = [&](std::size_t i) -> Vec3 { return p_[i] - 0.5 * len_[i] * rodimpl::axisOf(q_[i]); };
  auto endOf = [&](std::size_t i) -> Vec3 { return p_[i] + 0.5 * len_[i] * rodimpl::axisOf(q_[i]); };
  // An attached end node is where it is held: the end segment's outer half
  // stretches towards it (its compliance is the attachment's).
  if (k == 0) return ends_[0].kind == RodAttachment::Free ? startOf(0) : ends_[0].point;
  if (k >= n) return ends_[1].kind == RodAttachment::Free ? endOf(n - 1) : ends_[1].point;
  return 0.5 * (endOf(k - 1) + startOf(k));
}

double CosseratRod::length() const {
  double total = 0;
  Vec3 previous = node(0);
  for (std::size_t k = 1; k < nodeCount(); ++k) {
    const Vec3 x = node(k);
    total += (x - previous).norm();
    previous = x;
  }
  return total;
}

Vec3 CosseratRod::linearMomentum() const {
  Vec3 sum = Vec3::Zero();
  for (std::size_t i = 0; i < segmentCount(); ++i) sum += mass_[i] * v_[i];
  return sum;
}

Status CosseratRod::pin(RodEnd end, const Vec3& point) {
  if (!point.allFinite()) return rodimpl::invalidRod("the point is not finite", "CosseratRod::pin: point");
  End& e = ends_[endIndex(end)];
  const std::size_t c = end == RodEnd::Start ? 0 : segmentCount();
  if (e.kind != RodAttachment::Pinned) lambda_[c].setZero();  // no warm start from another kind
  e.kind = RodAttachment::Pinned;
  e.point = point;
  rows_[c] = rodimpl::kPositionRows;
  return ok();
}

Status CosseratRod::clamp(RodEnd end, const Vec3& point, const Quat& frame) {
  if (!point.allFinite()) return rodimpl::invalidRod("the point is not finite", "CosseratRod::clamp: point");
  if (!frame.coeffs().allFinite() || frame.norm() < 1e-6)
    return rodimpl::invalidRod("the frame is not a rotation", "CosseratRod::clamp: frame",
                               "give a finite, non-zero quaternion");
  End& e = ends_[endIndex(end)];
  const std::size_t c = end == RodEnd::Start ? 0 : segmentCount();
  if (e.kind != RodAttachment::Clamped) lambda_[c].setZero();
  e.kind = RodAttachment::Clamped;
  e.point = point;
  e.frame = frame.normalized();
  rows_[c] = rodimpl::kAllRows;
  return ok();
}

void CosseratRod::release(RodEnd end) noexcept {
  const std::size_t i = endIndex(end);
  ends_[i].kind = RodAttachment::Free;
  const std::size_t c = end == RodEnd::Start ? 0 : segmentCount();
  rows_[c] = 0;
  lambda_[c].setZero();
  reaction_[i] = RodWrench{};
}

RodWrench CosseratRod::reaction(RodEnd end) const noexcept { return reaction_[endIndex(end)]; }

Status CosseratRod::grasp(std::size_t segment, const Vec3& center, const Quat& orientation) {
  if (segment >= segmentCount())
    return rodimpl::invalidRod(formatString("segment %zu of %zu", segment, segmentCount()),
                               "CosseratRod::grasp: segment");
  if (!center.allFinite())
    return rodimpl::invalidRod("the centre is not finite", "CosseratRod::grasp: center");
  if (!orientation.coeffs().allFinite() || orientation.norm() < 1e-6)
    return rodimpl::invalidRod("the orientation is not a rotation", "CosseratRod::grasp: orientation",
                               "give a finite, non-zero quaternion");
  kinematic_[segment] = 1;
  graspCenter_[segment] = center;
  graspFrame_[segment] = orientation.normalized();
  return ok();
}

void CosseratRod::releaseGrasp(std::size_t segment) noexcept {
  if (segment < kinematic_.size()) kinematic_[segment] = 0;
}

RodWrench CosseratRod::graspLoad(std::size_t segment) const noexcept {
  if (!grasped(segment) || lastH_ <= 0) return {};
  const Vec6 load =
      (jr_[segment].transpose() * lambda_[segment] + jl_[segment + 1].transpose() * lambda_[segment + 1]) /
      (lastH_ * lastH_);
  return {load.head<3>(), load.tail<3>()};
}

Status CosseratRod::setObstacles(const std::vector<RodObstacle>& obstacles) {
  using ObstacleShape = RodObstacle::Shape;
  // Checked in place and copied only once valid, so that moving the same
  // number of obstacles each step allocates nothing (the messages are built
  // on the error path alone).
  for (std::size_t k = 0; k < obstacles.size(); ++k) {
    const RodObstacle& o = obstacles[k];
    auto where = [k](const char* field) {
      return formatString("CosseratRod::setObstacles: obstacles[%zu]%s", k, field);
    };
    if (o.shape != ObstacleShape::Plane && o.shape != ObstacleShape::Sphere &&
        o.shape != ObstacleShape::Capsule)
      return rodimpl::invalidRod(formatString("unknown shape %d", int(o.shape)), where(".shape"));
    if (!o.a.allFinite() || !o.b.allFinite() || !o.normal.allFinite() || !std::isfinite(o.radius))
      return rodimpl::invalidRod("a field is not finite", where(""));
    if (o.shape == ObstacleShape::Plane) {
      if (o.normal.norm() < 1e-12) return rodimpl::invalidRod("the normal is zero", where(".normal"));
      if (o.radius != 0) return rodimpl::invalidRod("a plane has no radius", where(".radius"), "leave it 0");
      if (!o.b.isZero(0)) return rodimpl::invalidRod("a plane has one point", where(".b"), "leave it zero");
    } else {
      if (!(o.radius > 0))
        return rodimpl::invalidRod(formatString("radius is %g m", o.radius), where(".radius"),
                                   "give a radius > 0 m");
      if (o.shape == ObstacleShape::Sphere && !o.b.isZero(0))
        return rodimpl::invalidRod("a sphere has one point", where(".b"), "leave it zero");
      if (o.normal != Vec3::UnitZ())
        return rodimpl::invalidRod("only a plane has a normal", where(".normal"), "leave it at its default");
    }
  }
  if (obstacles.size() != obstacles_.size()) {  // a new set: no warm start
    contactLambda_.assign(nodeCount() * obstacles.size(), 0.0);
    for (Vec6& c : contactImpulse_) c.setZero();
  }
  obstacles_ = obstacles;  // same size: copied into the existing storage
  for (RodObstacle& o : obstacles_)
    if (o.shape == ObstacleShape::Plane) o.normal.normalize();
  return ok();
}

Vec3 CosseratRod::contactForce() const noexcept {
  if (lastH_ <= 0) return Vec3::Zero();
  Vec3 sum = Vec3::Zero();
  for (const Vec6& c : contactImpulse_) sum += c.head<3>();
  return sum / (lastH_ * lastH_);
}

// Gap between the rod's surface at node k (a sphere of the rod's radius on
// the node, as node() places it) and the obstacle's (negative: overlap), and
// the contact normal out of the obstacle.
double CosseratRod::contactGap(std::size_t k, const RodObstacle& o, Vec3& normal) const {
  const Vec3 x = node(k);
  Vec3 onObstacle = o.a;
  switch (o.shape) {
    case RodObstacle::Shape::Plane:
      normal = o.normal;
      return o.normal.dot(x - o.a) - radius_;
    case RodObstacle::Shape::Sphere:
      break;
    case RodObstacle::Shape::Capsule:
      onObstacle = closestPointOnSegment(x, o.a, o.b);
      break;
  }
  const Vec3 d = x - onObstacle;
  const double distance = d.norm();
  // On the obstacle's centre or axis (not reached by a rod that was outside):
  // push out across the rod.
  normal = distance > 1e-15 ? Vec3(d / distance)
                            : rodimpl::axisOf(q_[std::min(k, segmentCount() - 1)]).unitOrthogonal();
  return distance - radius_ - o.radius;
}

// The segments a contact at `node` acts on, their share of it and the arm
// of their joint point there: a node where two segments meet is the
// midpoint of their joint points, so its contact acts on both (half the
// Jacobian each) and does not pull the joint apart; an end node is one
// segment's end. None for an attached end or a grasped segment.
int CosseratRod::nodeSegments(std::size_t node, std::size_t* seg, double* share, Vec3* arm) const {
  const std::size_t n = segmentCount();
  if ((node == 0 && ends_[0].kind != RodAttachment::Free) ||
      (node == n && ends_[1].kind != RodAttachment::Free))
    return 0;  // an attached end node stays where it is held
  int count = 0;
  const bool inner = node > 0 && node < n;
  if (node > 0 && !kinematic_[node - 1]) {
    seg[count] = node - 1;
    share[count] = inner ? 0.5 : 1.0;
    arm[count++] = 0.5 * len_[node - 1] * rodimpl::axisOf(q_[node - 1]);
  }
  if (node < n && !kinematic_[node]) {
    seg[count] = node;
    share[count] = inner ? 0.5 : 1.0;
    arm[count++] = -0.5 * len_[node] * rodimpl::axisOf(q_[node]);
  }
  return count;  // 0: held by the jaws
}

// One Gauss–Seidel sweep of the unilateral contacts (zero compliance, the
// accumulated λ kept ≥ 0). The sweep moves the segments at a node without
// turning them: turning a light segment by its end's push zig-zags its
// neighbours' joints, and a 3-0 suture falling on a 5 mm tool shaft at
// 1 m/s then diverged within a few steps with one pass a step. The
// contacts' full Jacobian (with the torque) still enters the residual
// (refreshContactImpulses), so a settled rod is in exact equilibrium; only
// the path to it changes.
void CosseratRod::projectContacts() {
  const std::size_t k = obstacles_.size();
  if (k == 0) return;
  for (std::size_t node = 0; node <= segmentCount(); ++node) {
    std::size_t seg[2];
    double share[2];
    Vec3 arm[2];
    const int count = nodeSegments(node, seg, share, arm);
    if (count == 0) continue;
    for (std::size_t o = 0; o < k; ++o) {
      double& lambda = contactLambda_[node * k + o];
      Vec3 normal;
      const double gap = contactGap(node, obstacles_[o], normal);
      if (gap >= 0 && lambda == 0) continue;
      double w = 0;
      for (int a = 0; a < count; ++a) w += share[a] * share[a] / mass_[seg[a]];
      const double next = std::max(lambda - gap / w, 0.0);
      const double d = next - lambda;
      if (d == 0) continue;
      lambda = next;
      for (int a = 0; a < count; ++a) p_[seg[a]] += (share[a] * d / mass_[seg[a]]) * normal;
    }
  }
  refreshContactImpulses();
}

// Σ J_cᵀ λ_c per segment from the contacts' λ and their normals and arms
// where the rod is now. Rebuilt, not accumulated: an impulse kept from
// where a node touched before would point along the old normal, and as the
// thread slid over a bar those stale directions acted as friction (a
// frictionless bar held 3 % more tension on one side than on the other, and
// a suture dropped on a table chattered at 0.01–0.07 m/s with one or two
// passes a step).
void CosseratRod::refreshContactImpulses() {
  for (Vec6& c : contactImpulse_) c.setZero();
  const std::size_t k = obstacles_.size();
  for (std::size_t node = 0; k > 0 && node <= segmentCount(); ++node) {
    std::size_t seg[2];
    double share[2];
    Vec3 arm[2];
    const int count = nodeSegments(node, seg, share, arm);
    for (std::size_t o = 0; count > 0 && o < k; ++o) {
      const double lambda = contactLambda_[node * k + o];
      if (lambda == 0) continue;
      Vec3 normal;
      (void)contactGap(node, obstacles_[o], normal);
      for (int a = 0; a < count; ++a) {
        contactImpulse_[seg[a]].head<3>() += share[a] * lambda * normal;
        contactImpulse_[seg[a]].tail<3>() += share[a] * lambda * arm[a].cross(normal);
      }
    }
  }
}

Status CosseratRod::setNodeForce(std::size_t k, const Vec3& force) {
  if (k >= nodeCount())
    return rodimpl::invalidRod(formatString("node %zu of %zu", k, nodeCount()),
                               "CosseratRod::setNodeForce: k");
  if (!force.allFinite())
    return rodimpl::invalidRod("the force is not finite", "CosseratRod::setNodeForce: force");
  nodeForce_[k] = force;
  return ok();
}

Status CosseratRod::setVelocity(const Vec3& velocity, const Vec3& angularVelocity) {
  if (!velocity.allFinite() || !angularVelocity.allFinite())
    return rodimpl::invalidRod("the velocity is not finite", "CosseratRod::setVelocity");
  // A rigid motion: each segment moves with the velocity of its centre
  // about the rod's centre of mass.
  Vec3 com = Vec3::Zero();
  double total = 0;
  for (std::size_t i = 0; i < segmentCount(); ++i) com += mass_[i] * p_[i], total += mass_[i];
  com /= total;
  for (std::size_t i = 0; i < segmentCount(); ++i) {
    v_[i] = velocity + angularVelocity.cross(p_[i] - com);
    w_[i] = angularVelocity;
  }
  return ok();
}

Status CosseratRod::setGravity(const Vec3& gravity) {
  if (!gravity.allFinite()) return rodimpl::invalidRod("gravity is not finite", "gravity");
  gravity_ = gravity;
  return ok();
}

Status CosseratRod::setDamping(double rate) {
  if (!std::isfinite(rate) || rate < 0)
    return rodimpl::invalidRod(formatString("damping is %g 1/s", rate), "damping", "give a finite rate >= 0");
  damping_ = rate;
  return ok();
}

Status CosseratRod::setIterations(int iterations) {
  if (iterations < 1 || iterations > 100)
    return rodimpl::invalidRod(formatString("iterations is %d", iterations), "iterations", "give 1 ... 100");
  iterations_ = iterations;
  return ok();
}

// ---------------------------------------------------------------------------
// The step

// Evaluates every constraint at the current state: the right-hand side
// −C − α̃λ into rhs_, the Jacobians into jl_ and jr_, α̃ (or 1 for a row that
// is off) on the diagonal blocks.
void CosseratRod::evaluate(double h) {
  using namespace rodimpl;
  const std::size_t n = segmentCount();
  const double invH2 = 1.0 / (h * h);
  for (std::size_t c = 0; c <= n; ++c) {
    const std::uint8_t rows = rows_[c];
    Mat6& jl = jl_[c];
    Mat6& jr = jr_[c];
    jl.setZero();
    jr.setZero();
    if (rows == 0) {
      rhs_[c].setZero();
      diag_[c].setIdentity();
      continue;
    }
    const bool hasLeft = c > 0, hasRight = c < n;
    Vec3 xl, xr, rl = Vec3::Zero(), rr = Vec3::Zero();
    Quat ql, qr;
    if (hasLeft) {
      ql = q_[c - 1];
      rl = 0.5 * len_[c - 1] * axisOf(ql);
      xl = p_[c - 1] + rl;
    } else {
      ql = ends_[0].frame;
      xl = ends_[0].point;
    }
    if (hasRight) {
      qr = q_[c];
      rr = -0.5 * len_[c] * axisOf(qr);
      xr = p_[c] + rr;
    } else {
      qr = ends_[1].frame;
      xr = ends_[1].point;
    }
    Vec6 C;
    C.head<3>() = xl - xr;
    Quat err = restRel_[c] * ql.conjugate() * qr;
    if (err.w() < 0) err.coeffs() = -err.coeffs();
    C.tail<3>() = 2 * err.vec();
    // dC_r / dθ_right = (w I − [v]×) (R_l R_rest)ᵀ, and minus that for the left.
    const Mat3 g = (err.w() * Mat3::Identity() - cross(err.vec())) *
                   (ql * restRel_[c].conjugate()).toRotationMatrix().transpose();
    if (hasLeft) {
      jl.topLeftCorner<3, 3>().setIdentity();
      jl.topRightCorner<3, 3>() = -cross(rl);
      jl.bottomRightCorner<3, 3>() = -g;
    }
    if (hasRight) {
      jr.topLeftCorner<3, 3>() = -Mat3::Identity();
      jr.topRightCorner<3, 3>() = cross(rr);
      jr.bottomRightCorner<3, 3>() = g;
    }
    for (int row = 0; row < 6; ++row)
      if (!(rows & (1u << row))) {
        jl.row(row).setZero();
        jr.row(row).setZero();
        C[row] = 0;
      }
    const Vec6 alphaTilde = compliance_[c] * invH2;
    rhs_[c] = -C - alphaTilde.cwiseProduct(lambda_[c]);
    diag_[c] = alphaTilde.asDiagonal();
    for (int row = 0; row < 6; ++row)
      if (!(rows & (1u << row))) diag_[c](row, row) = 1, rhs_[c][row] = 0;
  }
}

// Adds J W Jᵀ to the blocks evaluate() started, and the primal residual to
// the right-hand side. XPBD as published assumes M (x − x̃) = Jᵀλ holds after
// every pass, which is true only while J does not change; here the residual
// g = M (x − x̃) − Jᵀλ is kept (the full Newton step of Macklin et al.'s
// eq. 8 with the geometric stiffness left out), so that the passes converge
// to the backward-Euler step itself and a settled rod has no bias from the
// Jacobian's change over the step: (J W Jᵀ + α̃) Δλ = −C − α̃λ + J W g and
// Δx = W (Jᵀ Δλ − g). From x̃ with λ = 0 the first pass would be XPBD's;
// step() starts closer (see there).
void CosseratRod::assemble() {
  using namespace rodimpl;
  const std::size_t n = segmentCount();
  // Segment i is the right side of constraint i and the left side of
  // constraint i+1, so it adds to diag_[i], diag_[i+1] and off_[i].
  for (std::size_t i = 0; i < n; ++i) {
    if (kinematic_[i]) {  // held by the jaws: W = 0, nothing to correct
      invInertia_[i].setZero();
      wg_[i].setZero();
      off_[i].setZero();
      continue;
    }
    const double invMass = 1.0 / mass_[i];
    const Vec3 z = axisOf(q_[i]);
    const Mat3 inertia =
        inertiaPerp_[i] * Mat3::Identity() + (inertiaAxial_[i] - inertiaPerp_[i]) * z * z.transpose();
    // Geometric stiffness of the joint forces on the segment's rotation: the
    // force λ_p at arm r turns with the segment, d(r × λ)/dθ = [λ]×[r]× (and
    // minus that on the right side). Under tension it is a large restoring
    // stiffness (T·l against the inertia m l²/12 of a short, light segment)
    // that Newton's step must see, or the passes overshoot and diverge (a
    // 1 N pull on a 3-0 suture did, with 1 cm segments at 1 kHz). Only its
    // stiffening part is kept, so the block stays positive definite (Tournier
    // et al. 2015, "Stable constrained dynamics").
    // Both joints' forces act at ±l/2 along the axis, so the two terms add
    // to [Λ]×[r]× with Λ their sum and r this segment's end.
    const Mat3 invInertia =
        (inertia + stiffeningPart(lambda_[i].head<3>() + lambda_[i + 1].head<3>(), 0.5 * len_[i] * z))
            .inverse();
    invInertia_[i] = invInertia;
    const Vec6 jtl =
        jr_[i].transpose() * lambda_[i] + jl_[i + 1].transpose() * lambda_[i + 1] + contactImpulse_[i];
    Vec6& u = wg_[i];  // W g, with W = K⁻¹ for the rotation
    u.head<3>() = (p_[i] - pStart_[i]) - kick_[i].head<3>() - invMass * jtl.head<3>();
    u.tail<3>() = invInertia * (inertia * logRotation(q_[i] * qStart_[i].conjugate()) - kick_[i].tail<3>() -
                                jtl.tail<3>());
    rhs_[i] += jr_[i] * u;
    rhs_[i + 1] += jl_[i + 1] * u;
    // Constraint i has this segment on its right, constraint i+1 on its left.
    const WeightedJacobian right(jr_[i], invMass, invInertia), left(jl_[i + 1], invMass, invInertia);
    right.addTimesTransposeOf(right, diag_[i]);
    left.addTimesTransposeOf(left, diag_[i + 1]);
    off_[i].setZero();
    right.addTimesTransposeOf(left, off_[i]);
  }
}

// Block Cholesky elimination of the block-tridiagonal system (Eigen's LLT
// per block: hand-written 6×6 loops measured 25 % slower), in place:
// dlambda_ receives the solution of (J W Jᵀ + α̃) Δλ = rhs_.
void CosseratRod::solveSystem() {
  using namespace rodimpl;
  const std::size_t n = segmentCount();
  Mat6 factor = diag_[0];
  for (std::size_t c = 0; c <= n; ++c) {
    Vec6 y = rhs_[c];
    if (c > 0) {
      factor.noalias() = diag_[c] - off_[c - 1].transpose() * elim_[c - 1];
      y.noalias() -= off_[c - 1].transpose() * dlambda_[c - 1];
    }
    const Eigen::LLT<Mat6> llt(factor);
    if (llt.info() != Eigen::Success) {
      for (std::size_t k = 0; k <= n; ++k) dlambda_[k].setZero();
      return;
    }
    dlambda_[c] = llt.solve(y);
    if (c < n) {
      // S⁻¹ B by row operations on a row-major copy (six columns at once):
      // LLT::solve with a matrix takes Eigen's blocked general path, a sixth
      // of the whole step at this size (perf).
      const Mat6& l = llt.matrixLLT();
      Eigen::Matrix<double, 6, 6, Eigen::RowMajor> x = off_[c];
      for (int i = 0; i < 6; ++i) {  // L Y = B
        for (int k = 0; k < i; ++k) x.row(i) -= l(i, k) * x.row(k);
        x.row(i) /= l(i, i);
      }
      for (int i = 5; i >= 0; --i) {  // Lᵀ X = Y
        for (int k = i + 1; k < 6; ++k) x.row(i) -= l(k, i) * x.row(k);
        x.row(i) /= l(i, i);
      }
      elim_[c] = x;
    }
  }
  for (std::size_t c = n; c-- > 0;) dlambda_[c].noalias() -= elim_[c] * dlambda_[c + 1];
}

// Δx = W (Jᵀ Δλ − g) on every segment; λ += Δλ.
void CosseratRod::applyCorrection() {
  const std::size_t n = segmentCount();
  for (std::size_t i = 0; i < n; ++i) {
    if (kinematic_[i]) continue;
    const Vec6 impulse = jr_[i].transpose() * dlambda_[i] + jl_[i + 1].transpose() * dlambda_[i + 1];
    p_[i] += impulse.head<3>() / mass_[i] - wg_[i].head<3>();
    rodimpl::rotate(q_[i], invInertia_[i] * impulse.tail<3>() - wg_[i].tail<3>());
  }
  for (std::size_t c = 0; c <= n; ++c) lambda_[c] += dlambda_[c];
}

Result<RodStepReport> CosseratRod::step(double h) {
  if (!std::isfinite(h) || h <= 0 || h > 1)
    return rodimpl::invalidRod(formatString("h is %g s", h), "CosseratRod::step: h", "give 0 < h <= 1 s");
  const std::size_t n = segmentCount();

  // Applied loads: node forces act at the segment ends they sit on.
  for (std::size_t i = 0; i < n; ++i) force_[i].setZero(), torque_[i].setZero();
  for (std::size_t k = 0; k <= n; ++k) {
    const Vec3& f = nodeForce_[k];
    if (f.isZero(0)) continue;
    const std::size_t i = k < n ? k : n - 1;
    const Vec3 arm = (k < n ? -0.5 : 0.5) * len_[i] * rodimpl::axisOf(q_[i]);
    force_[i] += f;
    torque_[i] += arm.cross(f);
  }
  // The backward-Euler target is x̃ = x + h v + h² W f_ext; the applied
  // loads enter through the kick h² W f_ext (kept as a vector, so a light
  // segment's large predicted turn cannot wrap round). The passes start from
  // x + h v with the last step's λ rescaled to this h: a settled or slowly
  // moving rod satisfies that start already, and one pass a step tracks it.
  // (The gyroscopic torque is left out: the segments are slender.)
  const double rescale = lastH_ > 0 ? (h * h) / (lastH_ * lastH_) : 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    pPrev_[i] = p_[i];
    qPrev_[i] = q_[i];
    kick_[i].head<3>() = (h * h) * (gravity_ + force_[i] / mass_[i]);
    kick_[i].tail<3>() = (h * h) * torque_[i];
    if (kinematic_[i]) {  // the jaws put it where they are
      kick_[i].setZero();
      p_[i] = graspCenter_[i];
      q_[i] = graspFrame_[i];
    } else {
      p_[i] += h * v_[i];
      rodimpl::rotate(q_[i], h * w_[i]);
    }
    pStart_[i] = p_[i];
    qStart_[i] = q_[i];
  }
  for (std::size_t c = 0; c <= n; ++c) lambda_[c] *= rescale;
  for (double& l : contactLambda_) l *= rescale;
  lastH_ = h;
  // Contacts first, so that the first pass starts outside the obstacles
  // (with the last step's W; it then sweeps them after every pass). The
  // sweep ends by rebuilding the contacts' impulses for the first pass.
  projectContacts();
  for (int it = 0; it < iterations_; ++it) {
    evaluate(h);
    assemble();
    solveSystem();
    applyCorrection();
    projectContacts();
  }
  // Residuals and reactions at the final state.
  evaluate(h);
  RodStepReport report;
  for (std::size_t c = 0; c <= n; ++c) {
    report.positionResidual = std::max(report.positionResidual, rhs_[c].head<3>().cwiseAbs().maxCoeff());
    report.rotationResidual = std::max(report.rotationResidual, rhs_[c].tail<3>().cwiseAbs().maxCoeff());
  }
  for (std::size_t node = 0; node <= n; ++node)
    for (const RodObstacle& o : obstacles_) {
      Vec3 normal;
      report.penetration = std::max(report.penetration, -contactGap(node, o, normal));
    }
  const double invH2 = 1.0 / (h * h);
  const Mat6* rodSide[2] = {&jr_[0], &jl_[n]};  // the rod is right of c = 0 and left of c = n
  const std::size_t endConstraint[2] = {0, n};
  for (int e = 0; e < 2; ++e) {
    const Vec6& lambda = lambda_[endConstraint[e]];
    const Mat6& j = *rodSide[e];
    reaction_[e].force = invH2 * (j.leftCols<3>().transpose() * lambda);
    reaction_[e].torque = invH2 * (j.bottomRightCorner<3, 3>().transpose() * lambda.tail<3>());
  }
  // Velocities from the positions, then the medium's damping.
  const double keep = std::exp(-damping_ * h);
  for (std::size_t i = 0; i < n; ++i) {
    v_[i] = keep * (p_[i] - pPrev_[i]) / h;
    w_[i] = keep * rodimpl::logRotation(q_[i] * qPrev_[i].conjugate()) / h;
  }
  return report;
}

}  // namespace dm
