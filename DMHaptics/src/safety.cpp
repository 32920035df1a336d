// Passivity bound, material limits, wrench sanitiser, output fade and the
// passivity observer / controller; see dm/haptics/safety.hpp.
#include <dm/core/clock.hpp>
#include <dm/haptics/safety.hpp>

#include <algorithm>
#include <cmath>

namespace dm {

double passiveStiffnessBound(double deviceDamping, double virtualDamping, double rateHz) noexcept {
  if (!std::isfinite(deviceDamping) || !std::isfinite(virtualDamping) || !std::isfinite(rateHz) ||
      !(rateHz > 0.0)) {
    return 0.0;
  }
  // b > K·T/2 + |B|  ⇔  K < 2·(b − |B|)/T.
  const double margin = deviceDamping - std::abs(virtualDamping);
  return margin > 0.0 ? 2.0 * margin * rateHz : 0.0;
}

HapticLimits limitsFor(const HapticInfo& info, double loopRateHz) noexcept {
  HapticLimits l;
  l.maxDamping = std::isfinite(info.maxDamping) ? std::max(0.0, info.maxDamping) : 0.0;
  l.maxForce = std::isfinite(info.maxForce) ? std::max(0.0, info.maxForce) : 0.0;
  l.maxTorque = std::isfinite(info.maxTorque) ? std::max(0.0, info.maxTorque) : 0.0;
  const bool servoOk = std::isfinite(info.servoRateHz) && info.servoRateHz > 0.0;
  if (!servoOk || !std::isfinite(loopRateHz) || !(loopRateHz > 0.0) || !std::isfinite(info.maxStiffness) ||
      !(info.maxStiffness > 0.0)) {
    l.rateHz = servoOk && std::isfinite(loopRateHz) && loopRateHz > 0.0
                   ? std::min(loopRateHz, info.servoRateHz)
                   : 0.0;
    return l;
  }
  l.rateHz = std::min(loopRateHz, info.servoRateHz);
  l.deviceDamping = info.maxStiffness / (2.0 * info.servoRateHz);
  l.maxStiffness = passiveStiffnessBound(l.deviceDamping, 0.0, l.rateHz);
  return l;
}

HapticMaterial clampMaterial(HapticMaterial m, const HapticLimits& limits) noexcept {
  const double kMax = std::max(0.0, limits.maxStiffness);
  const double bMax = std::max(0.0, limits.maxDamping);
  if (!(m.stiffness > 0.0)) m.stiffness = std::min(1.0, kMax);  // NaN or ≤ 0
  m.stiffness = std::min(m.stiffness, kMax);
  if (!(m.damping >= 0.0)) m.damping = 0.0;
  m.damping = std::min(m.damping, bMax);
  if (!(m.staticFriction >= 0.0) || !std::isfinite(m.staticFriction)) m.staticFriction = 0.0;
  if (!(m.dynamicFriction >= 0.0) || !std::isfinite(m.dynamicFriction)) m.dynamicFriction = 0.0;
  m.dynamicFriction = std::min(m.dynamicFriction, m.staticFriction);
  return m;
}

bool sanitizeWrench(Vec3& force, Vec3& torque, double forceLimit, double torqueLimit) noexcept {
  const bool badF = !force.allFinite();
  const bool badT = !torque.allFinite();
  if (badF) force.setZero();
  if (badT) torque.setZero();
  clampVectorNorm(force, std::max(0.0, forceLimit));
  clampVectorNorm(torque, std::max(0.0, torqueLimit));
  return badF || badT;
}

OutputFade::OutputFade(double fadeSeconds) noexcept
    : fadeSeconds_(fadeSeconds >= 0.0 && std::isfinite(fadeSeconds) ? fadeSeconds : 0.0) {}

void OutputFade::reset() noexcept {
  gain_ = 1.0;
  heldForce_.setZero();
  heldTorque_.setZero();
}

void OutputFade::cut() noexcept { gain_ = 0.0; }

void OutputFade::apply(Vec3& force, Vec3& torque, bool finite, bool fault, double dt) noexcept {
  if (finite) {
    heldForce_ = force;
    heldTorque_ = torque;
  } else {
    force = heldForce_;
    torque = heldTorque_;
  }
  const double step = fadeSeconds_ > 0.0 ? std::max(0.0, dt) / fadeSeconds_ : 1.0;
  gain_ = std::clamp(fault ? gain_ - step : gain_ + step, 0.0, 1.0);
  force *= gain_;
  torque *= gain_;
}

void PassivityController::reset() noexcept {
  linearWork_ = angularWork_ = 0.0;
  lastAlpha_ = lastBeta_ = 0.0;
}

void PassivityController::observe(const Vec3& force, const Vec3& torque, const Vec3& dx,
                                  const Vec3& dtheta) noexcept {
  const double wl = force.dot(dx);
  const double wa = torque.dot(dtheta);
  if (std::isfinite(wl)) linearWork_ += wl;
  if (std::isfinite(wa)) angularWork_ += wa;
}

namespace {
// Damping coefficient that brings the predicted work of one port back to
// the threshold (Hannaford & Ryu's α = −E_obs / (ΔT·v²)), capped.
double portDamping(double work, const Vec3& effort, const Vec3& flow, double dt, double threshold,
                   double cap) noexcept {
  const double v2 = flow.squaredNorm();
  if (!(v2 > 0.0) || !(dt > 0.0)) return 0.0;
  const double predicted = work + effort.dot(flow) * dt;
  if (!(predicted > threshold)) return 0.0;
  const double alpha = (predicted - threshold) / (v2 * dt);
  return std::isfinite(alpha) ? std::min(alpha, cap) : cap;
}
}  // namespace

bool PassivityController::control(Vec3& force, Vec3& torque, const Vec3& v, const Vec3& w, double dt,
                                  const PassivityConfig& cfg) noexcept {
  lastAlpha_ = lastBeta_ = 0.0;
  if (!cfg.enabled || !v.allFinite() || !w.allFinite()) return false;
  const double threshold = std::max(0.0, cfg.threshold);
  lastAlpha_ = portDamping(linearWork_, force, v, dt, threshold, std::max(0.0, cfg.maxDamping));
  lastBeta_ = portDamping(angularWork_, torque, w, dt, threshold, std::max(0.0, cfg.maxAngularDamping));
  if (std::isfinite(lastAlpha_)) force -= lastAlpha_ * v;
  if (std::isfinite(lastBeta_)) torque -= lastBeta_ * w;
  return lastAlpha_ > 0.0 || lastBeta_ > 0.0;
}

Vec3 rotationDelta(const Isometry3& from, const Isometry3& to) noexcept {
  const Eigen::AngleAxisd aa(Mat3(to.linear() * from.linear().transpose()));
  return aa.angle() * aa.axis();
}

namespace {
constexpr double kNoLimit = std::numeric_limits<double>::infinity();

double replay(HapticRenderer& renderer, std::span<const Isometry3> path, double dt,
              const PassivityConfig* pc) noexcept {
  if (path.size() < 2 || !(dt > 0.0) || !std::isfinite(dt)) return 0.0;
  renderer.reset(path[0]);
  PassivityController ctl;
  const std::int64_t dtNs = secondsToNanos(dt);
  for (std::size_t k = 0; k + 1 < path.size(); ++k) {
    HapticInput in;
    in.timeNs = static_cast<std::int64_t>(k) * dtNs;
    in.dt = dt;
    in.devicePose = path[k];
    if (k > 0) {
      in.linearVelocity = (path[k].translation() - path[k - 1].translation()) / dt;
      in.angularVelocity = rotationDelta(path[k - 1], path[k]) / dt;
    }
    const HapticResponse r = renderer.tick(in);
    Vec3 f = r.force, t = r.torque;
    sanitizeWrench(f, t, kNoLimit, kNoLimit);
    if (pc != nullptr) ctl.control(f, t, in.linearVelocity, in.angularVelocity, dt, *pc);
    ctl.observe(f, t, path[k + 1].translation() - path[k].translation(), rotationDelta(path[k], path[k + 1]));
  }
  return ctl.workOnUser();
}
}  // namespace

double pathWork(HapticRenderer& renderer, std::span<const Isometry3> path, double dt) noexcept {
  return replay(renderer, path, dt, nullptr);
}

double pathWork(HapticRenderer& renderer, std::span<const Isometry3> path, double dt,
                const PassivityConfig& pc) noexcept {
  return replay(renderer, path, dt, &pc);
}

}  // namespace dm
