// HapticDevice: the driver vtable behind a safety layer (clamp, NaN guard,
// deadline fade, loss and reconnection), see dm/io/haptic_device.hpp.
#include <dm/io/haptic_device.hpp>

#include <algorithm>
#include <cmath>
#include <cstring>

namespace dm {

namespace {

std::string fixedString(const char* s, std::size_t capacity) { return std::string(s, strnlen(s, capacity)); }

bool finite3(const double* v) noexcept {
  return std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]);
}

}  // namespace

std::string_view deviceEventName(DeviceEventType type) noexcept {
  switch (type) {
    case DeviceEventType::Lost:
      return "lost";
    case DeviceEventType::Reconnected:
      return "reconnected";
    case DeviceEventType::DeadlineMissed:
      return "deadline-missed";
    case DeviceEventType::DeadlineRecovered:
      return "deadline-recovered";
    case DeviceEventType::NonFiniteCommand:
      return "non-finite-command";
  }
  return "unknown";
}

bool clampVectorNorm(Vec3& v, double limit) noexcept {
  if (!v.allFinite()) {
    v.setZero();
    return true;
  }
  const double n = v.norm();
  if (n <= limit) return false;
  v *= limit / n;  // n > limit ≥ 0, so n > 0
  return true;
}

Result<std::unique_ptr<HapticDevice>> HapticDevice::open(const FactoryRegistry& registry,
                                                         std::string_view driver, const DeviceParams& params,
                                                         const HapticSafety& safety) {
  auto factory = registry.find(DM_HAPTIC_DEVICE_KIND, driver, DM_HAPTIC_DEVICE_KIND_ABI_VERSION);
  if (!factory) return std::move(factory).error();
  const auto* vt = factory->as<DmHapticDeviceVTable>();
  const std::string where = "haptic device '" + std::string(driver) + "' (" + factory->provider + ")";
  if (!vt || !vt->open || !vt->close || !vt->get_info || !vt->read_state || !vt->write_output)
    return fail(ErrorCode::Device, "driver vtable has a null function", where,
                "the driver must set open, close, get_info, read_state and write_output");
  if (!(safety.deadlineSeconds >= 0.0) || !(safety.fadeSeconds >= 0.0) || !(safety.forceLimit >= 0.0) ||
      !(safety.torqueLimit >= 0.0) || !(safety.reconnectIntervalSeconds >= 0.0))
    return fail(ErrorCode::InvalidArgument, "negative or NaN safety setting", where,
                "deadline, fade, limits and reconnect interval are ≥ 0");

  std::vector<DmDeviceParam> cParams;
  cParams.reserve(params.size());
  for (const auto& [k, v] : params) cParams.push_back({k.c_str(), v.c_str()});
  char error[512] = {0};
  DmDevice* dev = vt->open(cParams.data(), cParams.size(), error, sizeof error);
  if (!dev)
    return fail(ErrorCode::InvalidArgument, error[0] ? fixedString(error, sizeof error) : "open failed",
                where, "fix the device parameters in the scene");

  std::unique_ptr<HapticDevice> d(new HapticDevice());
  d->vt_ = vt;
  d->device_ = dev;
  d->keepAlive_ = factory->keepAlive;
  d->safety_ = safety;
  DmHapticInfo ci{};
  if (vt->get_info(dev, &ci) != DM_DEVICE_OK)
    return fail(ErrorCode::Device, "get_info failed", where, "check the device connection");
  HapticInfo& info = d->info_;
  info.driver = fixedString(ci.identity.driver, sizeof ci.identity.driver);
  info.vendor = fixedString(ci.identity.vendor, sizeof ci.identity.vendor);
  info.model = fixedString(ci.identity.model, sizeof ci.identity.model);
  info.serial = fixedString(ci.identity.serial, sizeof ci.identity.serial);
  info.capabilities = ci.capabilities;
  info.buttonCount = std::min<std::uint32_t>(ci.button_count, 32);
  info.workspace = Aabb(Vec3(ci.workspace_min[0], ci.workspace_min[1], ci.workspace_min[2]),
                        Vec3(ci.workspace_max[0], ci.workspace_max[1], ci.workspace_max[2]));
  info.maxForce = ci.max_force;
  info.maxTorque = ci.max_torque;
  info.maxStiffness = ci.max_stiffness;
  info.maxDamping = ci.max_damping;
  info.servoRateHz = ci.servo_rate_hz;
  if (!(info.maxForce > 0.0) || !std::isfinite(info.maxForce) || !(info.maxTorque >= 0.0) ||
      !std::isfinite(info.maxTorque) || !(info.servoRateHz > 0.0) || !std::isfinite(info.servoRateHz) ||
      !finite3(ci.workspace_min) || !finite3(ci.workspace_max))
    return fail(ErrorCode::Device,
                "driver reports nonsensical limits (max force, torque, servo rate or workspace)", where,
                "a driver must report a positive finite max force and servo rate");
  d->forceLimit_ = safety.forceLimit > 0.0 ? std::min(safety.forceLimit, info.maxForce) : info.maxForce;
  d->torqueLimit_ = safety.torqueLimit > 0.0 ? std::min(safety.torqueLimit, info.maxTorque) : info.maxTorque;
  if (!(info.capabilities & DM_HAPTIC_CAP_TORQUE)) d->torqueLimit_ = 0.0;
  return d;
}

HapticDevice::~HapticDevice() {
  if (vt_ && device_) {
    if (connected()) {
      const double zero[3] = {0, 0, 0};
      vt_->write_output(device_, lastServoNs_, zero, zero);  // leave no force behind
    }
    vt_->close(device_);
  }
}

void HapticDevice::command(const Vec3& force, const Vec3& torque, std::int64_t nowNs) noexcept {
  Command& c = commands_.writeBuffer();
  if (force.allFinite() && torque.allFinite()) {
    c.force = force;
    c.torque = torque;
  } else {
    c.force.setZero();
    c.torque.setZero();
    nonFinite_.fetch_add(1, std::memory_order_relaxed);
  }
  c.timeNs = nowNs;
  c.valid = true;
  commands_.publish();
}

void HapticDevice::pushEvent(DeviceEventType type, std::int64_t nowNs) noexcept {
  (void)events_.tryPush(DeviceEvent{type, nowNs});  // a full ring drops the event; counters still count
}

void HapticDevice::markLost(std::int64_t nowNs) noexcept {
  if (!connected_.load(std::memory_order_relaxed)) return;
  connected_.store(false, std::memory_order_release);
  output_ = HapticOutput{};
  lostSinceNs_ = nowNs;
  lastReconnectTryNs_ = nowNs;
  losses_.fetch_add(1, std::memory_order_relaxed);
  pushEvent(DeviceEventType::Lost, nowNs);
}

DeviceStatus HapticDevice::servo(std::int64_t nowNs) noexcept {
  lastServoNs_ = nowNs;
  servoSteps_.fetch_add(1, std::memory_order_relaxed);
  const std::uint64_t nf = nonFinite_.load(std::memory_order_relaxed);
  if (nf != nonFiniteSeen_) {
    nonFiniteSeen_ = nf;
    pushEvent(DeviceEventType::NonFiniteCommand, nowNs);
  }

  if (!connected_.load(std::memory_order_relaxed)) {
    const auto interval = static_cast<std::int64_t>(safety_.reconnectIntervalSeconds * 1e9);
    if (!vt_->reconnect || nowNs - lastReconnectTryNs_ < interval) return DeviceStatus::Lost;
    lastReconnectTryNs_ = nowNs;
    if (vt_->reconnect(device_, nowNs) != DM_DEVICE_OK) return DeviceStatus::Lost;
    connected_.store(true, std::memory_order_release);
    resumedAtNs_ = nowNs;
    reconnects_.fetch_add(1, std::memory_order_relaxed);
    pushEvent(DeviceEventType::Reconnected, nowNs);
  }

  DmHapticState s{};
  const int rs = vt_->read_state(device_, nowNs, &s);
  if (rs == DM_DEVICE_ERROR_LOST) {
    markLost(nowNs);
    return DeviceStatus::Lost;
  }
  bool ioError = rs != DM_DEVICE_OK;
  if (!ioError && finite3(s.position) && finite3(s.linear_velocity) && finite3(s.angular_velocity) &&
      std::isfinite(s.orientation[0]) && std::isfinite(s.orientation[1]) && std::isfinite(s.orientation[2]) &&
      std::isfinite(s.orientation[3])) {
    HapticState& st = states_.writeBuffer();
    st.timeNs = s.time_ns;
    st.position = Vec3(s.position[0], s.position[1], s.position[2]);
    st.orientation = Quat(s.orientation[0], s.orientation[1], s.orientation[2], s.orientation[3]);
    if (st.orientation.norm() > 0.0) st.orientation.normalize();
    st.linearVelocity = Vec3(s.linear_velocity[0], s.linear_velocity[1], s.linear_velocity[2]);
    st.angularVelocity = Vec3(s.angular_velocity[0], s.angular_velocity[1], s.angular_velocity[2]);
    st.buttons = s.buttons;
    states_.publish();
    hasState_.store(true, std::memory_order_release);
  } else {
    ioError = true;  // a sample with NaN is dropped like a failed read
  }

  // The safe output for now.
  const Command& c = commands_.read();
  HapticOutput out;
  if (c.valid && c.timeNs >= resumedAtNs_) {
    out.force = c.force;
    out.torque = c.torque;
    const double age = 1e-9 * static_cast<double>(nowNs - c.timeNs);
    double gain = 1.0;
    if (age > safety_.deadlineSeconds) {
      gain = safety_.fadeSeconds > 0.0 ? 1.0 - (age - safety_.deadlineSeconds) / safety_.fadeSeconds : 0.0;
      gain = std::clamp(gain, 0.0, 1.0);
      if (!fading_) {
        fading_ = true;
        deadlineMisses_.fetch_add(1, std::memory_order_relaxed);
        pushEvent(DeviceEventType::DeadlineMissed, nowNs);
      }
    } else if (fading_) {
      fading_ = false;
      pushEvent(DeviceEventType::DeadlineRecovered, nowNs);
    }
    out.force *= gain;
    out.torque *= gain;
    bool clamped = clampVectorNorm(out.force, forceLimit_);
    clamped = clampVectorNorm(out.torque, torqueLimit_) || clamped;
    if (clamped) clamped_.fetch_add(1, std::memory_order_relaxed);
  }
  output_ = out;
  const int ws = vt_->write_output(device_, nowNs, out.force.data(), out.torque.data());
  if (ws == DM_DEVICE_ERROR_LOST) {
    markLost(nowNs);
    return DeviceStatus::Lost;
  }
  if (ws != DM_DEVICE_OK) ioError = true;
  if (ioError) {
    ioErrors_.fetch_add(1, std::memory_order_relaxed);
    return DeviceStatus::IoError;
  }
  return DeviceStatus::Ok;
}

HapticCounters HapticDevice::counters() const noexcept {
  HapticCounters c;
  c.servoSteps = servoSteps_.load(std::memory_order_relaxed);
  c.clamped = clamped_.load(std::memory_order_relaxed);
  c.nonFinite = nonFinite_.load(std::memory_order_relaxed);
  c.deadlineMisses = deadlineMisses_.load(std::memory_order_relaxed);
  c.losses = losses_.load(std::memory_order_relaxed);
  c.reconnects = reconnects_.load(std::memory_order_relaxed);
  c.ioErrors = ioErrors_.load(std::memory_order_relaxed);
  return c;
}

}  // namespace dm
