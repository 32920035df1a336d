// The haptic loop and the local model; see dm/haptics/haptic_loop.hpp.
#include <dm/haptics/haptic_loop.hpp>

#include <algorithm>
#include <cmath>
#include <string>

namespace dm {

// ---------------------------------------------------------------- local model

HapticLocalModel::HapticLocalModel(std::size_t capacity)
    : capacity_(capacity), buffer_(Snapshot{std::vector<Isometry3>(capacity, Isometry3::Identity()), 0, 0}) {}

std::size_t HapticLocalModel::publish(std::span<const Isometry3> poses, std::int64_t timeNs) noexcept {
  Snapshot& s = buffer_.writeBuffer();
  const std::size_t n = std::min(poses.size(), capacity_);
  // The vector was sized at construction: copying into it never allocates.
  std::copy_n(poses.begin(), n, s.poses.begin());
  s.count = n;
  s.timeNs = timeNs;
  buffer_.publish();
  published_.fetch_add(1, std::memory_order_relaxed);
  return n;
}

std::size_t HapticLocalModel::apply(HapticRenderer& renderer) noexcept {
  if (!buffer_.update()) return 0;
  const Snapshot& s = buffer_.readBuffer();
  const std::size_t n = std::min(s.count, renderer.objectCount());
  for (std::size_t i = 0; i < n; ++i) renderer.setObjectPose(i, s.poses[i]);
  appliedTimeNs_ = s.timeNs;
  applied_.fetch_add(1, std::memory_order_relaxed);
  return n;
}

// ---------------------------------------------------------------- haptic loop

namespace {
Error invalid(const char* field, const std::string& what, const char* hint) {
  return fail(ErrorCode::InvalidArgument, what, std::string("HapticLoopConfig.") + field, hint);
}

double limitOf(double requested, double device) noexcept {
  // A device limit of 0 (e.g. the torque of a 3-DOF device) means none rendered.
  return requested > 0.0 ? std::min(requested, std::max(0.0, device)) : std::max(0.0, device);
}
}  // namespace

Result<std::unique_ptr<HapticLoop>> HapticLoop::create(const Parts& parts, const HapticLoopConfig& config) {
  if (auto s = RealTimeLoop::validate(config.loop); !s) return s.error();
  if (!std::isfinite(config.workspaceScale) || !(config.workspaceScale > 0.0)) {
    return invalid("workspaceScale", "workspaceScale is " + std::to_string(config.workspaceScale),
                   "use a positive finite scale (world metres per device metre)");
  }
  if (!std::isfinite(config.forceScale) || !(config.forceScale > 0.0)) {
    return invalid("forceScale", "forceScale is " + std::to_string(config.forceScale),
                   "use a positive finite scale (device newtons per world newton)");
  }
  if (!std::isfinite(config.fadeSeconds) || !(config.fadeSeconds >= 0.0)) {
    return invalid("fadeSeconds", "fadeSeconds is " + std::to_string(config.fadeSeconds), "use a time ≥ 0 s");
  }
  if (!(config.forceLimit >= 0.0) || !(config.torqueLimit >= 0.0)) {
    return invalid("forceLimit", "force or torque limit is negative or NaN",
                   "use 0 (device limit) or a positive value");
  }
  const Mat3 r = config.deviceToWorld.linear();
  if (!config.deviceToWorld.matrix().allFinite() || !(r.transpose() * r).isApprox(Mat3::Identity(), 1e-9) ||
      !(r.determinant() > 0.0)) {
    return invalid("deviceToWorld", "deviceToWorld is not a finite rigid transform",
                   "use a rotation (orthonormal, det +1) and a translation; put scaling in workspaceScale");
  }
  if (!(config.passivity.threshold >= 0.0) || !(config.passivity.maxDamping >= 0.0) ||
      !(config.passivity.maxAngularDamping >= 0.0)) {
    return invalid("passivity", "passivity threshold or damping cap is negative or NaN", "use values ≥ 0");
  }
  return std::unique_ptr<HapticLoop>(new HapticLoop(parts, config));
}

HapticLoop::HapticLoop(const Parts& parts, const HapticLoopConfig& config)
    : device_(parts.device),
      renderer_(parts.renderer),
      model_(parts.model),
      effects_(parts.effects),
      config_(config),
      limits_(limitsFor(parts.device.info(), config.loop.rate_hz)),
      passivity_(config.passivity),
      rotation_(config.deviceToWorld.linear()),
      fade_(config.fadeSeconds),
      rt_(config.loop, [this](const TickInfo& info) { tick(info); }) {
  forceLimit_ = limitOf(config.forceLimit, limits_.maxForce);
  torqueLimit_ = limitOf(config.torqueLimit, limits_.maxTorque);
  if (std::isinf(passivity_.maxDamping) && limits_.maxDamping > 0.0)
    passivity_.maxDamping = limits_.maxDamping;
}

HapticLoop::~HapticLoop() { rt_.stop(); }

Status HapticLoop::start() {
  if (rt_.running()) return rt_.start();  // Busy, from the loop itself
  // The thread is not running: its state may be reset from here.
  needReset_ = true;
  havePrevious_ = false;
  fade_.reset();
  pc_.reset();
  workOnUser_.store(0.0, std::memory_order_relaxed);
  return rt_.start();
}

void HapticLoop::stop() { rt_.stop(); }

bool HapticLoop::running() const noexcept { return rt_.running(); }

Status HapticLoop::runLockstep(VirtualClock& clock, std::uint64_t n) { return rt_.runLockstep(clock, n); }

void HapticLoop::tick(const TickInfo& info) noexcept {
  const std::int64_t realStart = realClock_.now();
  const std::int64_t now = info.start_ns;
  const double dt = info.dt();

  bool lost = false;
  if (config_.servoInLoop) lost = device_.servo(now) == DeviceStatus::Lost;
  lost = lost || !device_.connected();

  bool poseUpdate = false;
  if (model_ != nullptr) {
    const std::uint64_t before = model_->appliedCount();
    model_->apply(renderer_);
    poseUpdate = model_->appliedCount() != before;
  }

  // Device frame → world.
  const HapticState& st = device_.state();
  Isometry3 devicePose = Isometry3::Identity();
  devicePose.translate(st.position);
  devicePose.rotate(st.orientation);
  const double s = config_.workspaceScale;
  HapticInput in;
  in.timeNs = now;
  in.dt = dt;
  in.devicePose.linear() = rotation_ * st.orientation.toRotationMatrix();
  in.devicePose.translation() = config_.deviceToWorld * (s * st.position);
  in.linearVelocity = s * (rotation_ * st.linearVelocity);
  in.angularVelocity = rotation_ * st.angularVelocity;

  // A device that never reported a state has no pose: the tool waits (no
  // output; the renderer is neither reset nor ticked, or a god-object's
  // proxy would start at a pose nobody holds and stay on its side of a wall).
  const bool posed = device_.hasState();
  HapticResponse resp;
  if (posed) {
    if (needReset_) {
      renderer_.reset(in.devicePose);
      needReset_ = false;
    }
    resp = renderer_.tick(in);
    if (effects_ != nullptr) effects_->apply(in, resp);
  }

  // World → device frame.
  Vec3 force = config_.forceScale * (rotation_.transpose() * resp.force);
  Vec3 torque = rotation_.transpose() * resp.torque;
  const bool finite = force.allFinite() && torque.allFinite();
  if (!finite) {
    force.setZero();
    torque.setZero();
  }

  // Passivity observer: the previous command acted over the displacement
  // measured since (zero-order hold), then the controller for this one.
  if (havePrevious_) {
    pc_.observe(prevForce_, prevTorque_, devicePose.translation() - prevDevicePose_.translation(),
                rotationDelta(prevDevicePose_, devicePose));
  }
  const bool pcActive =
      finite && pc_.control(force, torque, st.linearVelocity, st.angularVelocity, dt, passivity_);
  sanitizeWrench(force, torque, forceLimit_, torqueLimit_);

  const std::int64_t elapsed = realClock_.now() - realStart + (info.start_ns - info.scheduled_ns);
  const bool overrun = info.skipped > 0 || elapsed > info.period_ns;
  const bool fault = !finite || (overrun && config_.overrunFades) || lost || !posed;
  if (lost) fade_.cut();
  fade_.apply(force, torque, finite, fault, dt);
  device_.command(force, torque, now);

  prevForce_ = force;
  prevTorque_ = torque;
  prevDevicePose_ = devicePose;
  havePrevious_ = true;

  if (overrun) overruns_.fetch_add(1, std::memory_order_relaxed);
  if (!finite) nonFinite_.fetch_add(1, std::memory_order_relaxed);
  if (lost) lostTicks_.fetch_add(1, std::memory_order_relaxed);
  if (fault) faultTicks_.fetch_add(1, std::memory_order_relaxed);
  if (poseUpdate) poseUpdates_.fetch_add(1, std::memory_order_relaxed);
  if (pcActive) passivityTicks_.fetch_add(1, std::memory_order_relaxed);
  workOnUser_.store(pc_.workOnUser(), std::memory_order_relaxed);

  HapticLoopSample& out = last_;
  out.tick = info.index;
  out.timeNs = now;
  out.input = in;
  out.response = resp;
  out.deviceForce = force;
  out.deviceTorque = torque;
  out.gain = fade_.gain();
  out.fault = fault;
  out.passivityActive = pcActive;
  out.workOnUser = pc_.workOnUser();
  samples_.writeBuffer() = out;
  samples_.publish();

  compute_.record(realClock_.now() - realStart);
}

HapticLoopStats HapticLoop::stats() const noexcept {
  HapticLoopStats s;
  s.loop = rt_.stats();
  s.compute = compute_.summary();
  s.overruns = overruns_.load(std::memory_order_relaxed);
  s.nonFinite = nonFinite_.load(std::memory_order_relaxed);
  s.lostTicks = lostTicks_.load(std::memory_order_relaxed);
  s.faultTicks = faultTicks_.load(std::memory_order_relaxed);
  s.poseUpdates = poseUpdates_.load(std::memory_order_relaxed);
  s.passivityTicks = passivityTicks_.load(std::memory_order_relaxed);
  s.workOnUser = workOnUser_.load(std::memory_order_relaxed);
  return s;
}

}  // namespace dm
