// BurrRenderer: a milling tool's god-object on a MillableVolume that removes
// bone by Archard's wear law (see dm/haptics/burr.hpp).
#include <dm/haptics/burr.hpp>
#include <dm/haptics/safety.hpp>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <string>

namespace dm {

namespace {

constexpr int kBurrMaxMoves = 64;            // proxy moves per tick (each ≤ step_)
constexpr int kBurrBisections = 6;           // touching point to step/64 (2 µm at 0.25 mm voxels)
constexpr double kBurrSameNormal = 0.99985;  // cos 1°
// Field queries per tick (a contact normal, over a larger ball, counts as
// two): the bound that keeps a tick's time fixed; a proxy that needs more
// goes on next tick.
constexpr int kBurrQueryBudget = 14;

}  // namespace

Status BurrOptions::validate(std::string_view where) const {
  const std::string at(where);
  if (auto s = tool.validate(at + "/tool"); !s) return s;
  auto check = [&](double v, const char* field, bool strict) -> Status {
    if (std::isfinite(v) && (strict ? v > 0.0 : v >= 0.0)) return ok();
    return fail(ErrorCode::InvalidArgument,
                formatString("%s must be finite and %s 0 (got %g)", field, strict ? ">" : "≥", v),
                at + "/" + field);
  };
  for (auto s :
       {check(stiffness, "stiffness", true), check(damping, "damping", false), check(rpm, "rpm", false),
        check(cuttingRadius, "cutting_radius", false), check(wearCoefficient, "wear_coefficient", false),
        check(walkCoefficient, "walk_coefficient", false),
        check(vibrationAmplitude, "vibration_amplitude", false), check(vibrationHz, "vibration_hz", false),
        check(maxForce, "max_force", true)})
    if (!s) return s;
  if (cuttingRadius == 0.0 && (tool.kind == MillingTool::Kind::Box || tool.kind == MillingTool::Kind::Voxels))
    return fail(ErrorCode::InvalidArgument, "a saw or voxel tool needs its cutting radius",
                at + "/cutting_radius",
                "give the distance of the cutting edges from the axis they turn or swing about, m");
  if (!std::isfinite(contactTolerance))
    return fail(ErrorCode::InvalidArgument, "contact_tolerance must be finite", at + "/contact_tolerance");
  if (!std::isfinite(normalMargin))
    return fail(ErrorCode::InvalidArgument, "normal_margin must be finite", at + "/normal_margin");
  if (auto s = check(warningDistance, "warning_distance", false); !s) return s;
  for (std::size_t k = 0; k < critical.size(); ++k)
    if (!critical[k])
      return fail(ErrorCode::InvalidArgument, "critical structure " + std::to_string(k) + " is null",
                  at + "/critical/" + std::to_string(k));
  return ok();
}

Result<std::unique_ptr<BurrRenderer>> BurrRenderer::create(std::shared_ptr<MillableVolume> bone,
                                                           BurrOptions options) {
  if (auto s = options.validate("burr"); !s) return s.error();
  if (!bone || bone->dims().prod() == 0)
    return fail(ErrorCode::InvalidArgument, "the burr needs a bone volume", "burr/volume");
  return std::unique_ptr<BurrRenderer>(new BurrRenderer(std::move(bone), std::move(options)));
}

BurrRenderer::BurrRenderer(std::shared_ptr<MillableVolume> bone, BurrOptions options) noexcept
    : bone_(std::move(bone)), options_(std::move(options)) {
  const double h = bone_->voxelSize();
  step_ = 0.5 * std::min(h, options_.tool.innerRadius());
  tolerance_ = options_.contactTolerance >= 0.0 ? options_.contactTolerance : 1e-3 * bone_->voxelVolume();
  margin_ = options_.normalMargin >= 0.0 ? options_.normalMargin : 2.0 * h;
  cuttingRadius_ = options_.cuttingRadius > 0.0 ? options_.cuttingRadius : options_.tool.radius;
  boundingRadius_ = options_.tool.boundingRadius();
  rpm_.store(options_.rpm, std::memory_order_relaxed);
}

void BurrRenderer::setRpm(double rpm) noexcept {
  if (std::isfinite(rpm) && rpm >= 0.0) rpm_.store(rpm, std::memory_order_relaxed);
}

void BurrRenderer::setObjectPose(std::size_t index, const Isometry3& pose) noexcept {
  if (index != 0 || !pose.matrix().allFinite()) return;
  bonePose_ = pose;
  boneInverse_ = pose.inverse();
}

Isometry3 BurrRenderer::toolPose(const Vec3& centre) const noexcept {
  Isometry3 pose = Isometry3::Identity();
  pose.linear() = rotation_;
  pose.translation() = centre;
  return pose;
}

double BurrRenderer::overlapAt(const Vec3& centre) noexcept {
  ++queries_;
  return bone_->overlap(options_.tool, toolPose(centre));
}

Vec3 BurrRenderer::normalAt(const Vec3& centre) noexcept {
  queries_ += 2;
  return bone_->contactNormal(options_.tool, toolPose(centre), margin_);
}

void BurrRenderer::reset(const Isometry3& devicePose) noexcept {
  last_ = {};
  normal_ = Vec3::Zero();
  const Isometry3 local = boneInverse_ * devicePose;
  if (!local.matrix().allFinite()) return;
  rotation_ = local.linear();
  proxy_ = local.translation();
  // A pose inside the bone: walk out along the contact normal.
  for (int i = 0; i < 4 * kBurrMaxMoves && overlapAt(proxy_) > tolerance_; ++i) {
    const Vec3 n = normalAt(proxy_);
    proxy_ += (n.squaredNorm() > 0.0 ? n : Vec3::UnitZ()) * step_;
  }
}

void BurrRenderer::moveProxy(const Vec3& target) noexcept {
  normal_ = Vec3::Zero();
  queries_ = 0;
  for (int move = 0; move < kBurrMaxMoves && queries_ < kBurrQueryBudget; ++move) {
    const bool sliding = normal_.squaredNorm() > 0.0;
    Vec3 d = target - proxy_;
    if (sliding && d.dot(normal_) < 0.0) d -= d.dot(normal_) * normal_;  // in the contact plane
    const double len = d.norm();
    if (len < 1e-9) return;
    const Vec3 step = d * std::min(1.0, step_ / len);
    const Vec3 q = proxy_ + step;
    if (overlapAt(q) <= tolerance_) {
      proxy_ = q;
      continue;
    }
    if (sliding && overlapAt(q + step_ * normal_) <= tolerance_) {
      // The surface curves or ripples under the plane: lift the step back
      // onto it along n, and take the normal there.
      double lo = 0.0, hi = step_;
      for (int b = 0; b < kBurrBisections && queries_ < kBurrQueryBudget; ++b) {
        const double mid = 0.5 * (lo + hi);
        (overlapAt(q + mid * normal_) <= tolerance_ ? hi : lo) = mid;
      }
      const Vec3 next = q + hi * normal_;
      const bool stuck = (next - proxy_).squaredNorm() < 1e-18;
      proxy_ = next;
      if (queries_ >= kBurrQueryBudget) return;
      if (const Vec3 n = normalAt(proxy_); n.squaredNorm() > 0.0) normal_ = n;
      if (stuck) return;
      continue;
    }
    // First touch, or a slide blocked by material the plane does not
    // describe (a wall ahead): stop at the last free point of the step and
    // take the normal there, which now sees that material too.
    double lo = 0.0, hi = 1.0;
    const double first = 1.0 / (1 << kBurrBisections);
    if (overlapAt(proxy_ + first * step) > tolerance_) hi = first;  // touching already: no way along the step
    while (hi - lo > first && queries_ < kBurrQueryBudget) {
      const double mid = 0.5 * (lo + hi);
      (overlapAt(proxy_ + mid * step) <= tolerance_ ? lo : hi) = mid;
    }
    proxy_ += lo * step;
    Vec3 n = normalAt(proxy_);
    if (n.squaredNorm() == 0.0) n = -step / step.norm();
    if (sliding && lo == 0.0 && n.dot(normal_) > kBurrSameNormal) return;  // a corner: no way on
    normal_ = n;
  }
}

HapticResponse BurrRenderer::tick(const HapticInput& input) noexcept {
  HapticResponse out;
  const Isometry3 local = boneInverse_ * input.devicePose;
  if (!local.matrix().allFinite()) {
    out.proxyPose = bonePose_ * toolPose(proxy_);
    return out;
  }
  rotation_ = local.linear();
  const Vec3 target = local.translation();
  moveProxy(target);

  last_ = {};
  const double dt = std::isfinite(input.dt) && input.dt > 0.0 ? input.dt : 0.0;
  const Vec3 spring = options_.stiffness * (proxy_ - target);
  Vec3 force = Vec3::Zero();
  if (normal_.squaredNorm() > 0.0) {
    // The frictionless proxy is held only by the bone, so the whole spring
    // is the contact force: its size is the normal force and its direction
    // the contact normal (in a cavity that hugs the tool, the material ahead
    // of the motion, not the net normal of the cavity).
    const Mat3& toLocal = boneInverse_.linear();
    const double fn = spring.norm();
    const Vec3 n = fn > 0.0 ? Vec3(spring / fn) : normal_;
    force = spring - options_.damping * (toLocal * input.linearVelocity);
    last_.contact = true;
    last_.normalForce = fn;
    last_.normal = bonePose_.linear() * n;
    const double rpm = rpm_.load(std::memory_order_relaxed);
    if (rpm > 0.0 && fn > 0.0) {
      const Vec3 axis = rotation_.col(2);
      const Vec3 across = axis.cross(n);
      if (const double s = across.norm(); s > 1e-6) force += options_.walkCoefficient * fn / s * across;
      const double t = static_cast<double>(input.timeNs) * 1e-9;
      force +=
          options_.vibrationAmplitude * fn * std::sin(2.0 * std::numbers::pi * options_.vibrationHz * t) * n;
      // Removal at the tool pressed toward the device by at most half a voxel.
      const double speed = rpm * (2.0 * std::numbers::pi / 60.0) * cuttingRadius_;
      Vec3 reach = target - proxy_;
      if (const double r = reach.norm(), cap = 0.5 * bone_->voxelSize(); r > cap) reach *= cap / r;
      last_.cut =
          bone_->mill(options_.tool, toolPose(proxy_ + reach), options_.wearCoefficient * fn * speed * dt);
    }
  } else {
    force = spring;  // the proxy lags only when the move budget ran out
  }
  // Critical structures and the skill metrics.
  if (!options_.critical.empty()) {
    double nearest = std::numeric_limits<double>::infinity();
    for (const auto& c : options_.critical) nearest = std::min(nearest, c->distance(proxy_));
    last_.criticalDistance = nearest - boundingRadius_;
    metrics_.closestApproach = std::min(metrics_.closestApproach, last_.criticalDistance);
    if (last_.criticalDistance < options_.warningDistance) metrics_.secondsWithinWarning += dt;
  }
  ++metrics_.ticks;
  metrics_.removed += last_.cut.removed;
  metrics_.removedForbidden += last_.cut.removedForbidden;
  out.force = bonePose_.linear() * force;
  Vec3 torque = Vec3::Zero();
  sanitizeWrench(out.force, torque, options_.maxForce, 0.0);
  out.contacts = last_.contact ? 1 : 0;
  out.penetration = last_.contact ? (proxy_ - target).norm() : 0.0;
  out.proxyPose = bonePose_ * toolPose(proxy_);
  return out;
}

}  // namespace dm
