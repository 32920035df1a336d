// tool_impulse.cpp — running impulse totals from the haptic thread to the
// physics thread (dm/haptics/tool_impulse.hpp).
#include <dm/haptics/tool_impulse.hpp>

#include <algorithm>
#include <cmath>

namespace dm {

ToolImpulseChannel::ToolImpulseChannel(std::size_t objects)
    : running_(objects), totals_(std::vector<ToolImpulse>(objects)), seen_(objects) {}

void ToolImpulseChannel::add(std::size_t object, const Vec3& force, const Vec3& point, double dt) noexcept {
  if (object >= running_.size() || !(dt > 0.0) || !std::isfinite(dt) || !force.allFinite() ||
      !point.allFinite())
    return;
  ToolImpulse& r = running_[object];
  r.linear += force * dt;
  r.angular += point.cross(force) * dt;
}

void ToolImpulseChannel::addWrench(std::size_t object, const Vec3& force, const Vec3& torque,
                                   double dt) noexcept {
  if (object >= running_.size() || !(dt > 0.0) || !std::isfinite(dt) || !force.allFinite() ||
      !torque.allFinite())
    return;
  ToolImpulse& r = running_[object];
  r.linear += force * dt;
  r.angular += torque * dt;
}

void ToolImpulseChannel::publish() noexcept {
  // Every buffer was sized by the constructor: this copy never allocates.
  std::copy(running_.begin(), running_.end(), totals_.writeBuffer().begin());
  totals_.publish();
}

bool ToolImpulseChannel::take(std::span<ToolImpulse> out) noexcept {
  const std::size_t n = std::min(out.size(), seen_.size());
  if (!totals_.update()) {
    std::fill_n(out.begin(), n, ToolImpulse{});
    return false;
  }
  const std::vector<ToolImpulse>& t = totals_.readBuffer();
  for (std::size_t i = 0; i < n; ++i) {
    out[i].linear = t[i].linear - seen_[i].linear;
    out[i].angular = t[i].angular - seen_[i].angular;
  }
  std::copy(t.begin(), t.end(), seen_.begin());
  return true;
}

ToolImpulse ToolImpulseChannel::taken(std::size_t object) const noexcept {
  return object < seen_.size() ? seen_[object] : ToolImpulse{};
}

}  // namespace dm
