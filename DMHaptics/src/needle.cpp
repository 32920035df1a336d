// The needle felt at 1 kHz: device pose to the physics, the frozen coupling
// to the haptic thread; see dm/haptics/needle.hpp.
#include <dm/haptics/needle.hpp>
#include <dm/haptics/safety.hpp>

#include <algorithm>
#include <cmath>
#include <string>

namespace dm {

Result<std::unique_ptr<HapticNeedle>> HapticNeedle::create(NeedleInsertion& needle,
                                                           const HapticNeedleOptions& options) {
  constexpr const char* where = "HapticNeedle::create";
  const auto bad = [&](const char* field, std::string what, const char* hint) {
    return fail(ErrorCode::InvalidArgument, std::move(what), std::string(where) + ": options." + field, hint);
  };
  if (!options.tip.allFinite())
    return bad("tip", "the tip is not finite", "give the tip in the device frame, m");
  const double norm = options.axis.norm();
  if (!(norm > 1e-12) || !std::isfinite(norm))
    return bad("axis", "the axis is zero or not finite", "give the shaft's direction, handle to tip");
  const Vec3 axis = options.axis / norm;
  const Vec3 across = options.normal - options.normal.dot(axis) * axis;
  if (!options.normal.allFinite() || !(across.norm() > 1e-6 * std::max(1.0, options.normal.norm())))
    return bad("normal", "the normal is parallel to the axis or not finite",
               "give the direction toward the needle's centre of curvature, across the axis");
  if (!isRigidPose(options.tissuePose))
    return bad("tissuePose", "the tissue pose is not a finite rigid transform",
               "give a rotation and a translation");
  if (!(options.maxForce > 0.0) || !std::isfinite(options.maxForce))
    return bad("maxForce", formatString("maxForce is %g N", options.maxForce),
               "give the device's force limit, > 0");
  if (!(options.maxTorque >= 0.0))
    return bad("maxTorque", formatString("maxTorque is %g N·m", options.maxTorque),
               "give the device's torque limit, >= 0 (0 for a 3-DOF device)");
  HapticNeedleOptions o = options;
  o.axis = axis;
  o.normal = across.normalized();
  return std::unique_ptr<HapticNeedle>(new HapticNeedle(needle, o));
}

HapticNeedle::HapticNeedle(NeedleInsertion& needle, const HapticNeedleOptions& options)
    : needle_(&needle), options_(options) {
  mount_.linear().col(0) = options.normal;
  mount_.linear().col(1) = options.axis.cross(options.normal);
  mount_.linear().col(2) = options.axis;
  mount_.translation() = options.tip;
  toTissue_ = options.tissuePose.inverse(Eigen::Isometry);
  needle.localModel(models_.writeBuffer());
  models_.publish();
  working_.assign(models_.read());
}

void HapticNeedle::reset(const Isometry3& /*devicePose*/) noexcept {
  models_.update();
  working_.assign(models_.readBuffer());
}

void HapticNeedle::setObjectPose(std::size_t index, const Isometry3& pose) noexcept {
  if (index == 0 && isRigidPose(pose)) {
    options_.tissuePose = pose;
    toTissue_ = pose.inverse(Eigen::Isometry);
  }
}

HapticResponse HapticNeedle::tick(const HapticInput& input) noexcept {
  if (models_.update()) working_.assign(models_.readBuffer());
  HapticResponse out;
  out.proxyPose = input.devicePose;  // the needle is rigid in the hand: drawn where the device is
  const Isometry3& device = input.devicePose;
  const Isometry3 needle = toTissue_ * device * mount_;
  if (!isRigidPose(needle)) {
    out.force.setZero(), out.torque.setZero();
    return out;
  }
  poses_.write(Pose{.valid = true, .needle = needle});
  const Wrench w = working_.evaluate(needle);
  const Vec3 tipWorld = device * options_.tip;
  const Mat3& R = options_.tissuePose.linear();
  out.force = R * w.force;
  out.torque = R * w.torque + (tipWorld - device.translation()).cross(out.force);
  sanitizeWrench(out.force, out.torque, options_.maxForce, options_.maxTorque);
  out.contacts = int(working_.pointCount) + (working_.state == NeedleTip::Pressing ? 1 : 0);
  out.penetration = working_.state == NeedleTip::Pressing
                        ? (needle.translation() - working_.membrane).dot(needle.linear().col(2))
                        : 0.0;
  if (!(out.penetration > 0.0)) out.penetration = 0.0;
  return out;
}

Result<FemStepReport> HapticNeedle::step(double h) {
  poses_.update();
  const Pose& pose = poses_.readBuffer();
  auto report = pose.valid ? needle_->step(pose.needle, h) : needle_->body().step(h);
  if (!report) return std::move(report).error().within("HapticNeedle::step");
  needle_->localModel(models_.writeBuffer());
  models_.publish();
  published_.fetch_add(1, std::memory_order_relaxed);
  return report;
}

}  // namespace dm
