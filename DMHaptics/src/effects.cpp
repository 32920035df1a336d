// Force effects and the effect stack; see dm/haptics/effects.hpp.
#include <dm/collide/mesh_query.hpp>
#include <dm/core/clock.hpp>
#include <dm/haptics/effects.hpp>
#include <dm/math/geometry.hpp>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <string>

namespace dm {

namespace {
double nonNegative(double x) noexcept { return x >= 0.0 && std::isfinite(x) ? x : 0.0; }
}  // namespace

ViscosityEffect::ViscosityEffect(double damping, std::optional<Aabb> region) noexcept
    : damping_(nonNegative(damping)), region_(region) {}

void ViscosityEffect::apply(const HapticInput& input, HapticResponse& out) const noexcept {
  if (region_ && !region_->contains(input.devicePose.translation())) return;
  out.force -= damping_ * input.linearVelocity;
}

SnapToSurfaceEffect::SnapToSurfaceEffect(ClosestPointFn closest, double stiffness, double captureDistance)
    : closest_(std::move(closest)),
      stiffness_(nonNegative(stiffness)),
      capture_(nonNegative(captureDistance)) {}

SnapToSurfaceEffect::SnapToSurfaceEffect(const MeshBvh& bvh, const Isometry3& pose, double stiffness,
                                         double captureDistance)
    : bvh_(&bvh), pose_(pose), stiffness_(nonNegative(stiffness)), capture_(nonNegative(captureDistance)) {}

double SnapToSurfaceEffect::magnitudeAt(double r) const noexcept {
  if (!(r >= 0.0) || !(r < capture_)) return 0.0;
  return stiffness_ * std::min(r, capture_ - r);
}

void SnapToSurfaceEffect::apply(const HapticInput& input, HapticResponse& out) const noexcept {
  const Vec3 p = input.devicePose.translation();
  Vec3 q;
  if (bvh_ != nullptr) {
    const MeshPointQuery mq = closestPointOnMesh(*bvh_, pose_, p, capture_);
    if (!std::isfinite(mq.distance)) return;
    q = mq.point;
  } else if (!closest_ || !closest_(p, q)) {
    return;
  }
  const Vec3 d = q - p;
  const double r = d.norm();
  if (!(r > 0.0) || !std::isfinite(r)) return;
  out.force += magnitudeAt(r) / r * d;
}

VibrationEffect::VibrationEffect(double amplitude, double frequencyHz, const Vec3& axis,
                                 double phase) noexcept
    : amplitude_(std::isfinite(amplitude) ? amplitude : 0.0),
      omega_(std::isfinite(frequencyHz) ? 2.0 * std::numbers::pi * frequencyHz : 0.0),
      phase_(std::isfinite(phase) ? phase : 0.0),
      axis_(axis.allFinite() && axis.norm() > 0.0 ? Vec3(axis.normalized()) : Vec3::Zero()) {}

ForceFieldEffect::ForceFieldEffect(ForceFieldFn field, std::string name)
    : field_(std::move(field)), name_(std::move(name)) {}

void ForceFieldEffect::apply(const HapticInput& input, HapticResponse& out) const noexcept {
  if (!field_) return;
  const Vec3 f = field_(input.devicePose.translation());
  if (f.allFinite()) out.force += f;
}

void VibrationEffect::apply(const HapticInput& input, HapticResponse& out) const noexcept {
  const double t = nanosToSeconds(input.timeNs);
  out.force += amplitude_ * std::sin(omega_ * t + phase_) * axis_;
}

Vec3 closestPointInRegion(const SafeRegion& region, const Vec3& p, bool* inside) noexcept {
  Vec3 q = p;
  bool in = true;
  if (const auto* s = std::get_if<SafeSphere>(&region)) {
    const Vec3 d = p - s->center;
    const double r = d.norm();
    if (r > s->radius) {
      in = false;
      q = s->center + (r > 0.0 ? Vec3(d * (s->radius / r)) : Vec3::Zero());
    }
  } else if (const auto* b = std::get_if<SafeBox>(&region)) {
    const Vec3 local = b->pose.inverse() * p;
    const Vec3 clamped = local.cwiseMax(-b->halfExtents).cwiseMin(b->halfExtents);
    in = clamped == local;
    q = in ? p : Vec3(b->pose * clamped);
  } else if (const auto* c = std::get_if<SafeCorridor>(&region)) {
    const Vec3 axisPoint = closestPointOnSegment(p, c->a, c->b);
    const Vec3 d = p - axisPoint;
    const double r = d.norm();
    if (r > c->radius) {
      in = false;
      q = axisPoint + d * (c->radius / r);
    }
  }
  if (inside != nullptr) *inside = in;
  return q;
}

VirtualFixture::VirtualFixture(const SafeRegion& region, double stiffness, double damping) noexcept
    : region_(region), stiffness_(nonNegative(stiffness)), damping_(nonNegative(damping)) {}

void VirtualFixture::apply(const HapticInput& input, HapticResponse& out) const noexcept {
  const Vec3 p = input.devicePose.translation();
  bool inside = true;
  const Vec3 q = closestPointInRegion(region_, p, &inside);
  if (inside) return;
  const Vec3 e = p - q;
  const double d = e.norm();
  if (!(d > 0.0) || !std::isfinite(d)) return;
  const Vec3 n = e / d;
  const double push = stiffness_ * d + damping_ * input.linearVelocity.dot(n);
  if (push > 0.0) out.force -= push * n;
}

EffectStack::EffectStack(std::size_t capacity) : capacity_(capacity) { effects_.reserve(capacity); }

Result<ForceEffect*> EffectStack::add(std::unique_ptr<ForceEffect> effect) {
  if (!effect) {
    return fail(ErrorCode::InvalidArgument, "effect is null", "EffectStack::add",
                "pass a constructed effect");
  }
  if (effects_.size() >= capacity_) {
    return fail(ErrorCode::Busy, "effect stack is full (" + std::to_string(capacity_) + " effects)",
                "EffectStack::add", "construct the EffectStack with a larger capacity");
  }
  ForceEffect* raw = effect.get();
  effects_.push_back(std::move(effect));
  return raw;
}

bool EffectStack::remove(const ForceEffect* effect) noexcept {
  const auto it = std::find_if(effects_.begin(), effects_.end(),
                               [effect](const std::unique_ptr<ForceEffect>& e) { return e.get() == effect; });
  if (it == effects_.end()) return false;
  effects_.erase(it);
  return true;
}

void EffectStack::clear() noexcept { effects_.clear(); }

void EffectStack::apply(const HapticInput& input, HapticResponse& out) const noexcept {
  for (const auto& e : effects_) e->apply(input, out);
}

}  // namespace dm
