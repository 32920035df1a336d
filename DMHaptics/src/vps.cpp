// Voxmap–PointShell renderer with virtual coupling; see dm/haptics/vps.hpp
// for the force model, the stiffness rule and the integrator.
#include <dm/haptics/vps.hpp>

#include <Eigen/Cholesky>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>
#include <utility>

#include "option_rules.hpp"

namespace dm {

namespace {

bool finiteScalar(double v) noexcept { return std::isfinite(v); }

// Rotation vector (axis · angle, |angle| ≤ π) of a unit quaternion.
Vec3 rotationVector(Quat q) noexcept {
  if (q.w() < 0) q.coeffs() = -q.coeffs();
  const double s = q.vec().norm();
  if (s < 1e-12) return 2.0 * q.vec();
  return (2.0 * std::atan2(s, q.w()) / s) * q.vec();
}

// Unit quaternion of a rotation vector.
Quat quatFromRotationVector(const Vec3& phi) noexcept {
  const double angle = phi.norm();
  if (angle < 1e-12) return Quat(1.0, 0.5 * phi.x(), 0.5 * phi.y(), 0.5 * phi.z()).normalized();
  return Quat(AngleAxis(angle, phi / angle));
}

Status validateOptions(const VpsOptions& o) {
  using haptics_detail::OptionRule;
  constexpr const char* kOwner = "dm::VpsRenderer::create";
  const auto coupling = haptics_detail::couplingRules(o.couplingStiffness, o.couplingDamping,
                                                      o.couplingAngularStiffness, o.couplingAngularDamping);
  const OptionRule checks[] = {
      {"mass", o.mass, finiteScalar(o.mass) && o.mass > 0, "finite and > 0 kg"},
      {"referenceContacts", o.referenceContacts,
       finiteScalar(o.referenceContacts) && o.referenceContacts >= 1, "finite and >= 1"},
      {"maxPointDepth", o.maxPointDepth, finiteScalar(o.maxPointDepth) && o.maxPointDepth > 0,
       "finite and > 0 m"},
      {"brakeDistance", o.brakeDistance, finiteScalar(o.brakeDistance) && o.brakeDistance >= 0,
       "finite and >= 0 m"},
      {"brakeDamping", o.brakeDamping, finiteScalar(o.brakeDamping) && o.brakeDamping >= 0,
       "finite and >= 0 N*s/m"},
      {"maxForce", o.maxForce, !std::isnan(o.maxForce) && o.maxForce > 0, "> 0 N (infinity allowed)"},
      {"maxTorque", o.maxTorque, !std::isnan(o.maxTorque) && o.maxTorque > 0, "> 0 N*m (infinity allowed)"},
      {"substeps", static_cast<double>(o.substeps), o.substeps >= 1 && o.substeps <= 64, "between 1 and 64"},
  };
  if (auto s = haptics_detail::checkOptionRules(coupling, kOwner, "VpsOptions"); !s) return s;
  if (auto s = haptics_detail::checkOptionRules(checks, kOwner, "VpsOptions"); !s) return s;
  if (!o.inertia.isZero(0.0)) {
    const std::string where = "dm::VpsRenderer::create: options.inertia";
    if (!o.inertia.allFinite())
      return fail(ErrorCode::InvalidArgument, "inertia has a non-finite entry", where,
                  "pass a finite symmetric positive definite matrix (kg*m^2) or all zeros");
    if ((o.inertia - o.inertia.transpose()).norm() > 1e-9 * o.inertia.norm())
      return fail(ErrorCode::InvalidArgument, "inertia is not symmetric", where,
                  "pass a symmetric positive definite matrix (kg*m^2) or all zeros");
    Eigen::LLT<Mat3> llt(o.inertia);
    if (llt.info() != Eigen::Success || !(o.inertia.diagonal().minCoeff() > 0))
      return fail(ErrorCode::InvalidArgument, "inertia is not positive definite", where,
                  "pass a symmetric positive definite matrix (kg*m^2) or all zeros to derive it");
  }
  return ok();
}

// Solid box of the shell's local bounds with mass m, about the shell origin.
Mat3 boxInertia(const Aabb& box, double m) {
  const Vec3 e = box.sizes();
  const Vec3 c = box.center();
  // A floor keeps a flat or needle-like shell's inertia invertible.
  const double floor = 1e-4 * m * e.squaredNorm();
  Mat3 inertia = Mat3::Zero();
  inertia(0, 0) = std::max(m / 12.0 * (e.y() * e.y() + e.z() * e.z()), floor);
  inertia(1, 1) = std::max(m / 12.0 * (e.x() * e.x() + e.z() * e.z()), floor);
  inertia(2, 2) = std::max(m / 12.0 * (e.x() * e.x() + e.y() * e.y()), floor);
  inertia += m * (c.squaredNorm() * Mat3::Identity() - c * c.transpose());
  if (!(inertia.diagonal().minCoeff() > 0)) inertia = Mat3::Identity() * std::max(floor, 1e-12);
  return inertia;
}

// Adds J Jᵀ to the lower triangle of `m` (21 entries).
void addOuterLower(Mat6& m, const Vec6& j) noexcept {
  for (int c = 0; c < 6; ++c)
    for (int r = c; r < 6; ++r) m(r, c) += j[r] * j[c];
}

Mat6 symmetricFromLower(const Mat6& lower) noexcept {
  Mat6 m = lower;
  for (int c = 0; c < 6; ++c)
    for (int r = c + 1; r < 6; ++r) m(c, r) = m(r, c);
  return m;
}

Vec3 clampNorm(const Vec3& v, double maxNorm) noexcept {
  const double n = v.norm();
  return n > maxNorm ? Vec3(v * (maxNorm / n)) : v;
}

}  // namespace

// What one sample of the shell against all objects yields, world frame:
// the penalty wrench on the tool (about its origin), its stiffness matrix
// −∂wrench/∂(translation, rotation vector) and the contact + braking
// damping matrix on the tool's (velocity, angular velocity).
struct VpsRenderer::ContactSample {
  Vec6 wrench = Vec6::Zero();
  Vec6* perObject = nullptr;  // each object's share of `wrench` (objects_.size() entries)
  Mat6 stiffness = Mat6::Zero();
  Mat6 damping = Mat6::Zero();
  int contacts = 0;
};

Result<std::unique_ptr<VpsRenderer>> VpsRenderer::create(std::shared_ptr<const PointShell> tool,
                                                         std::vector<VpsObject> objects,
                                                         const VpsOptions& options) {
  const std::string where = "dm::VpsRenderer::create";
  if (!tool)
    return fail(ErrorCode::InvalidArgument, "tool point shell is null", where + ": tool",
                "build one with dm::PointShell::fromMesh or dm::PointShell::create");
  if (Status s = validateOptions(options); !s) return s.error();
  std::unique_ptr<VpsRenderer> r(new VpsRenderer());
  r->objects_.reserve(objects.size());
  for (std::size_t i = 0; i < objects.size(); ++i) {
    VpsObject& o = objects[i];
    const std::string at = where + ": objects[" + std::to_string(i) + "]";
    if (!o.model)
      return fail(ErrorCode::InvalidArgument, "voxel model is null", at + ".model",
                  "build one with dm::VoxelModel::fromMesh / fromSdf / fromOccupancy");
    if (!isRigidPose(o.pose))
      return fail(ErrorCode::InvalidArgument, "pose is not finite or not a rigid transform", at + ".pose",
                  "pass a rotation (orthonormal, det +1) and a finite translation");
    if (Status s = o.material.validate(at + ".material"); !s) return s.error();
    r->objects_.push_back({std::move(o.model), o.pose, o.pose.inverse(Eigen::Isometry), o.material,
                           Vec3::Zero(), Vec3::Zero()});
  }
  r->objectWrench_.assign(r->objects_.size(), Vec6::Zero());
  r->tool_ = std::move(tool);
  r->options_ = options;
  r->mass_ = options.mass;
  r->inertiaBody_ =
      options.inertia.isZero(0.0) ? boxInertia(r->tool_->localAabb(), options.mass) : options.inertia;
  r->reset(Isometry3::Identity());
  return r;
}

void VpsRenderer::reset(const Isometry3& devicePose) noexcept {
  if (!devicePose.matrix().allFinite()) return;
  position_ = devicePose.translation();
  orientation_ = Quat(devicePose.linear()).normalized();
  velocity_.setZero();
  angularVelocity_.setZero();
  lastDevice_ = devicePose;
  contactForce_.setZero();
  contactTorque_.setZero();
  for (Object& o : objects_) o.force = o.torque = Vec3::Zero();
}

void VpsRenderer::setObjectPose(std::size_t index, const Isometry3& pose) noexcept {
  if (index >= objects_.size() || !isRigidPose(pose)) return;
  objects_[index].pose = pose;
  objects_[index].inverse = pose.inverse(Eigen::Isometry);
}

Isometry3 VpsRenderer::toolPose() const noexcept {
  Isometry3 p = Isometry3::Identity();
  p.linear() = orientation_.toRotationMatrix();
  p.translation() = position_;
  return p;
}

double VpsRenderer::toolKineticEnergy() const noexcept {
  const Mat3 r = orientation_.toRotationMatrix();
  const Vec3 wBody = r.transpose() * angularVelocity_;
  return 0.5 * mass_ * velocity_.squaredNorm() + 0.5 * wBody.dot(inertiaBody_ * wBody);
}

void VpsRenderer::sampleContacts(ContactSample& out) const noexcept {
  const PointShell& shell = *tool_;
  const auto nodes = shell.nodes();
  const auto points = shell.points();
  const auto normals = shell.normals();
  const Isometry3 tool = toolPose();
  const Mat3 rTool = tool.linear();
  const bool wantBrake = options_.brakeDistance > 0 && options_.brakeDamping > 0;
  const double cutoff = wantBrake ? options_.brakeDistance : 0.0;
  const double maxDepth = options_.maxPointDepth;
  const double nRef = options_.referenceContacts;
  for (std::size_t k = 0; k < objects_.size(); ++k) {
    const Object& obj = objects_[k];
    const VoxelModel& model = *obj.model;
    const Isometry3 toModel = obj.inverse * tool;
    const Mat3 rObj = obj.pose.linear();
    const double lipschitz = model.lipschitz();
    const bool wantDamping = obj.material.damping > 0;
    Vec6 wrench = Vec6::Zero();
    Mat6 stiffness = Mat6::Zero(), damping = Mat6::Zero(), brake = Mat6::Zero();
    int inContact = 0, braking = 0;
    std::uint32_t stack[2 * PointShell::kMaxDepth + 2];
    int top = 0;
    stack[top++] = 0;
    while (top > 0) {
      const PointShellNode& node = nodes[stack[--top]];
      // Lipschitz culling: no point of the cluster can be within `cutoff`.
      if (!(model.distance(toModel * node.center) - lipschitz * node.radius <= cutoff)) continue;
      if (!node.isLeaf()) {
        stack[top++] = node.first + 1;
        stack[top++] = node.first;
        continue;
      }
      for (std::uint32_t i = node.first; i < node.first + node.count; ++i) {
        Vec3 g;
        const double d = model.distance(toModel * points[i], g);
        const bool touching = d <= 0;
        if (!touching && !(d < cutoff)) continue;  // also skips NaN
        const double gn = g.norm();
        const Vec3 n = gn > 1e-12 && std::isfinite(gn) ? Vec3(rObj * (g / gn)) : Vec3(-(rTool * normals[i]));
        const Vec3 r = rTool * points[i];
        Vec6 j;
        j << n, r.cross(n);
        const bool approaching = n.dot(velocity_ + angularVelocity_.cross(r)) < 0;
        if (touching) {
          ++inContact;
          const double depth = std::min(-d, maxDepth);
          wrench += depth * j;
          // A clamped point's force no longer changes with the pose.
          if (-d < maxDepth) addOuterLower(stiffness, j);
          if (wantDamping && approaching) addOuterLower(damping, j);
        } else if (approaching) {
          ++braking;
          addOuterLower(brake, j);
        }
      }
    }
    if (inContact > 0) {
      const double scale = 1.0 / std::max(static_cast<double>(inContact), nRef);
      out.wrench += obj.material.stiffness * scale * wrench;
      if (out.perObject != nullptr) out.perObject[k] = obj.material.stiffness * scale * wrench;
      out.stiffness += obj.material.stiffness * scale * symmetricFromLower(stiffness);
      if (wantDamping) out.damping += obj.material.damping * scale * symmetricFromLower(damping);
      out.contacts += inContact;
    }
    if (braking > 0)
      out.damping +=
          options_.brakeDamping / std::max(static_cast<double>(braking), nRef) * symmetricFromLower(brake);
  }
}

void VpsRenderer::integrate(const ContactSample& contact, const Isometry3& device0, const Isometry3& device1,
                            const Vec3& deviceVelocity, const Vec3& deviceAngularVelocity,
                            double dt) noexcept {
  const int steps = options_.substeps;
  const double h = dt / steps;
  const double kc = options_.couplingStiffness, bc = options_.couplingDamping;
  const double kr = options_.couplingAngularStiffness, br = options_.couplingAngularDamping;
  const Vec3 sampledPosition = position_;
  const Quat sampledOrientation = orientation_;
  const Quat q0 = Quat(device0.linear()).normalized();
  const Quat q1 = Quat(device1.linear()).normalized();

  // Constant parts of the step matrix: coupling spring and damper + contact.
  Mat6 stiffness = contact.stiffness;
  Mat6 damping = contact.damping;
  for (int a = 0; a < 3; ++a) {
    stiffness(a, a) += kc;
    stiffness(a + 3, a + 3) += kr;
    damping(a, a) += bc;
    damping(a + 3, a + 3) += br;
  }
  for (int s = 1; s <= steps; ++s) {
    const double alpha = static_cast<double>(s) / steps;
    const Vec3 xd = (1.0 - alpha) * device0.translation() + alpha * device1.translation();
    const Quat qd = q0.slerp(alpha, q1);
    const Mat3 rot = orientation_.toRotationMatrix();
    const Mat3 inertia = rot * inertiaBody_ * rot.transpose();

    // Explicit parts of the forces at the start of the step: coupling spring
    // and the device-velocity side of its damper, the contact wrench
    // linearised about the sampled pose, and the gyroscopic term.
    Vec6 force;
    force.head<3>() = kc * (xd - position_) + bc * deviceVelocity;
    force.tail<3>() = kr * rotationVector(qd * orientation_.conjugate()) + br * deviceAngularVelocity -
                      angularVelocity_.cross(inertia * angularVelocity_);
    Vec6 moved;
    moved << position_ - sampledPosition, rotationVector(orientation_ * sampledOrientation.conjugate());
    force += contact.wrench - contact.stiffness * moved;

    // Linearly implicit Euler: (M + hD + h²K) u⁺ = M u + h f.
    Mat6 mass = Mat6::Zero();
    mass.topLeftCorner<3, 3>() = mass_ * Mat3::Identity();
    mass.bottomRightCorner<3, 3>() = inertia;
    Vec6 u;
    u << velocity_, angularVelocity_;
    const Mat6 a = mass + h * damping + (h * h) * stiffness;
    const Vec6 next = a.ldlt().solve(mass * u + h * force);
    velocity_ = next.head<3>();
    angularVelocity_ = next.tail<3>();
    position_ += h * velocity_;
    orientation_ = (quatFromRotationVector(h * angularVelocity_) * orientation_).normalized();
  }
}

HapticResponse VpsRenderer::tick(const HapticInput& input) noexcept {
  HapticResponse out;
  out.proxyPose = toolPose();
  const bool finiteInput = std::isfinite(input.dt) && input.dt > 0 && input.devicePose.matrix().allFinite() &&
                           input.linearVelocity.allFinite() && input.angularVelocity.allFinite();
  if (!finiteInput) return out;

  const Vec3 keptPosition = position_, keptVelocity = velocity_, keptAngularVelocity = angularVelocity_;
  const Quat keptOrientation = orientation_;

  ContactSample contact;
  std::fill(objectWrench_.begin(), objectWrench_.end(), Vec6::Zero());
  contact.perObject = objectWrench_.data();
  const Vec3 sampledPosition = position_;
  sampleContacts(contact);
  integrate(contact, lastDevice_, input.devicePose, input.linearVelocity, input.angularVelocity, input.dt);

  // Coupling force and torque on the tool at the end of the tick; the user
  // feels their reaction.
  const Vec3 xd = input.devicePose.translation();
  const Quat qd = Quat(input.devicePose.linear()).normalized();
  const Vec3 couplingForce = options_.couplingStiffness * (xd - position_) +
                             options_.couplingDamping * (input.linearVelocity - velocity_);
  const Vec3 couplingTorque =
      options_.couplingAngularStiffness * rotationVector(qd * orientation_.conjugate()) +
      options_.couplingAngularDamping * (input.angularVelocity - angularVelocity_);
  if (!position_.allFinite() || !orientation_.coeffs().allFinite() || !velocity_.allFinite() ||
      !angularVelocity_.allFinite() || !couplingForce.allFinite() || !couplingTorque.allFinite()) {
    position_ = keptPosition, velocity_ = keptVelocity, angularVelocity_ = keptAngularVelocity;
    orientation_ = keptOrientation;
    return out;
  }
  lastDevice_ = input.devicePose;
  contactForce_ = contact.wrench.head<3>();
  contactTorque_ = contact.wrench.tail<3>();
  // Newton's third law, object by object: what pushes the tool pushes the
  // object back; the torque moves from the tool's origin to the world's.
  for (std::size_t k = 0; k < objects_.size(); ++k) {
    const Vec3 f = objectWrench_[k].head<3>();
    objects_[k].force = -f;
    objects_[k].torque = -(objectWrench_[k].tail<3>() + sampledPosition.cross(f));
  }

  out.force = clampNorm(-couplingForce, options_.maxForce);
  out.torque = clampNorm(-couplingTorque, options_.maxTorque);
  out.proxyPose = toolPose();
  out.contacts = contact.contacts;
  out.penetration = contact.contacts > 0 ? (xd - position_).norm() : 0.0;
  return out;
}

}  // namespace dm
