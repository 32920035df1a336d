// dm/haptics/haptic_loop.hpp — the haptic loop: ties a HapticRenderer to a
// dm::HapticDevice on DMCore's real-time loop (dm::RealTimeLoop, 1 kHz by
// default), and the local model through which physics moves the renderer's
// environment objects at its own, slower rate.
//
// One tick (HapticLoop):
//   1. device.servo(now) when config.servoInLoop (else the device's own
//      servo thread runs it), then device.state();
//   2. the newest object poses from the HapticLocalModel, if physics
//      published any since the last tick, go to renderer.setObjectPose();
//   3. device frame → world: p_w = deviceToWorld · (s·p_d), R_w = R·R_d,
//      v_w = s·R·v_d, ω_w = R·ω_d (s = workspaceScale, R = deviceToWorld's
//      rotation);
//   4. renderer.tick(), then the EffectStack adds its forces; until the
//      device reported its first state (HapticDevice::hasState) it has no
//      pose: the renderer is neither reset nor ticked, the output is zero
//      and the tick counts as a fault;
//   5. world → device frame: F_d = forceScale·Rᵀ·F_w, τ_d = Rᵀ·τ_w
//      (forceScale = workspaceScale preserves power, so a passive scene stays
//      passive at the hand; 1 renders forces unscaled);
//   6. safety, in the device frame where the limits live: NaN/Inf → fault;
//      the passivity observer adds the work the previous command did over
//      the measured displacement and, if enabled, the passivity controller
//      adds damping; force / torque clamped (dm::clampVectorNorm); the
//      OutputFade ramps the output down while the tick is faulty (renderer
//      NaN, overrun: compute time plus wake-up lateness over one period) and
//      cuts it while the device is lost, ramping back up after;
//   7. device.command(F_d, τ_d, now). HapticDevice itself fades stale
//      commands and zeroes a lost device's output: the loop does not repeat it.
// The loop's own compute time per tick goes into a LatencyHistogram (real
// clock, also in lockstep); wake-up latency and deadline misses are the
// RealTimeLoop's.
//
// Threads: tick() never allocates, locks, logs or throws. The loop is the
// HapticDevice's state() consumer while it runs; other threads read
// latest() (one consumer thread) and stats() (any thread).
//
// @code
//   dm::HapticLoop::Parts parts{.device = *device, .renderer = renderer, .model = &model, .effects =
//   &effects}; auto loop = dm::HapticLoop::create(parts, {.loop = {.rate_hz = 1000, .name = "haptics"}}); if
//   (!loop) return loop.error();
//   (*loop)->start();  ...  (*loop)->stop();            // or (*loop)->runLockstep(clock, 1000)
// @endcode
#pragma once

#include <dm/core/clock.hpp>
#include <dm/core/result.hpp>
#include <dm/core/rt_loop.hpp>
#include <dm/core/triple_buffer.hpp>
#include <dm/core/types.hpp>
#include <dm/haptics/effects.hpp>
#include <dm/haptics/renderer.hpp>
#include <dm/haptics/safety.hpp>
#include <dm/io/haptic_device.hpp>

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

namespace dm {

/// Latest environment object poses, from the physics thread to the haptic
/// thread through a dm::TripleBuffer: physics publishes at its own rate and
/// the haptic loop applies the newest complete set at the start of a tick,
/// never waiting, so a slow physics step never slows the haptic rate.
/// Capacity (number of objects) fixed at construction; not copyable or movable.
/// @code
///   dm::HapticLocalModel model(scene.objectCount());
///   model.publish(poses, clock.now());   // physics thread, e.g. 100 Hz
///   model.apply(renderer);               // haptic thread (HapticLoop does it)
/// @endcode
class HapticLocalModel {
 public:
  /// Room for `capacity` object poses (allocated now).
  explicit HapticLocalModel(std::size_t capacity);
  HapticLocalModel(const HapticLocalModel&) = delete;
  HapticLocalModel& operator=(const HapticLocalModel&) = delete;

  std::size_t capacity() const noexcept { return capacity_; }

  /// Physics thread (one writer): publishes poses[i] (object i, its frame →
  /// world) for i < min(poses.size(), capacity()) as taken at `timeNs`.
  /// Returns how many it copied. Never blocks or allocates. O(n).
  std::size_t publish(std::span<const Isometry3> poses, std::int64_t timeNs) noexcept;

  /// Haptic thread (one reader): if a set arrived since the last call, calls
  /// renderer.setObjectPose(i, pose) for i < min(count, renderer.objectCount())
  /// and returns how many; else 0. Never blocks or allocates. O(n).
  std::size_t apply(HapticRenderer& renderer) noexcept;

  /// Haptic thread: publish time (ns) of the set applied last; -1 before the first.
  std::int64_t appliedTimeNs() const noexcept { return appliedTimeNs_; }
  /// Any thread: sets published / sets applied so far.
  std::uint64_t publishedCount() const noexcept { return published_.load(std::memory_order_relaxed); }
  std::uint64_t appliedCount() const noexcept { return applied_.load(std::memory_order_relaxed); }

 private:
  struct Snapshot {
    std::vector<Isometry3> poses;
    std::size_t count = 0;
    std::int64_t timeNs = 0;
  };
  std::size_t capacity_;
  TripleBuffer<Snapshot> buffer_;
  std::int64_t appliedTimeNs_ = -1;
  std::atomic<std::uint64_t> published_{0}, applied_{0};
};

/// Configuration of a HapticLoop.
struct HapticLoopConfig {
  /// Rate (1 kHz default; may be higher), priority, CPU pinning, name.
  RealTimeLoopConfig loop{.rate_hz = 1000.0, .name = "dm-haptics"};
  /// Device frame → world (rigid). Together with workspaceScale: see the file comment.
  Isometry3 deviceToWorld = Isometry3::Identity();
  double workspaceScale = 1.0;  ///< world metres per device metre, > 0
  double forceScale = 1.0;      ///< device force per world force, > 0
  /// true: the loop calls device.servo(now) at the start of each tick;
  /// false: the application runs servo() on the device's own thread.
  bool servoInLoop = true;
  double fadeSeconds = 0.005;  ///< s, ≥ 0: loop-side fade (OutputFade)
  /// true: an overrun (compute time + wake-up lateness > period) fades the
  /// output. false: overruns are only counted — for headless lockstep runs
  /// whose output must not depend on how loaded the machine is.
  bool overrunFades = true;
  double forceLimit = 0.0;   ///< N; > 0: min(this, device max force), else the device's
  double torqueLimit = 0.0;  ///< N·m; > 0: min(this, device max torque), else the device's
                             ///< (a device with max torque 0 gets no torque)
  /// Passivity controller (device frame). Off by default: the observer
  /// always runs. An infinite maxDamping is replaced by the device's.
  PassivityConfig passivity{.enabled = false};
};

/// What one tick did, published for a consumer (graphics, logging, tests).
struct HapticLoopSample {
  std::uint64_t tick = 0;            ///< tick index
  std::int64_t timeNs = 0;           ///< tick time (loop clock)
  HapticInput input;                 ///< what the renderer got (world)
  HapticResponse response;           ///< renderer + effects, world, before safety
  Vec3 deviceForce = Vec3::Zero();   ///< N, commanded, device frame
  Vec3 deviceTorque = Vec3::Zero();  ///< N·m, commanded, device frame
  double gain = 1.0;                 ///< OutputFade gain
  bool fault = false;                ///< renderer NaN, overrun, device lost or without a state yet
  bool passivityActive = false;      ///< the passivity controller added damping
  double workOnUser = 0.0;           ///< J, observer total (device frame)
};

/// Counters of a HapticLoop (monotone) and its timing.
struct HapticLoopStats {
  RealTimeLoopStats loop;             ///< ticks, deadline misses, wake-up latency (us)
  LatencyHistogram::Summary compute;  ///< tick compute time, real clock, us
  std::uint64_t overruns = 0;         ///< ticks whose lateness + compute exceeded the period
  std::uint64_t nonFinite = 0;        ///< ticks with NaN/Inf from the renderer or effects
  std::uint64_t lostTicks = 0;        ///< ticks with the device lost
  std::uint64_t faultTicks = 0;       ///< ticks with any fault
  std::uint64_t poseUpdates = 0;      ///< local-model sets applied
  std::uint64_t passivityTicks = 0;   ///< ticks where the controller added damping
  double workOnUser = 0.0;            ///< J, passivity observer total
};

/// The haptic loop; see the file comment. Not copyable or movable (its
/// RealTimeLoop calls back into it); owned through unique_ptr.
class HapticLoop {
 public:
  /// What the loop drives; every referenced object must outlive the loop.
  struct Parts {
    HapticDevice& device;
    HapticRenderer& renderer;
    HapticLocalModel* model = nullptr;  ///< optional
    EffectStack* effects = nullptr;     ///< optional; not modified while running
  };

  /// Checks `config` (RealTimeLoop::validate, scales > 0 and finite,
  /// fadeSeconds ≥ 0, a finite rigid deviceToWorld, limits ≥ 0) and builds
  /// the loop; starts nothing. InvalidArgument naming the field otherwise.
  static Result<std::unique_ptr<HapticLoop>> create(const Parts& parts, const HapticLoopConfig& config = {});
  ~HapticLoop();
  HapticLoop(const HapticLoop&) = delete;
  HapticLoop& operator=(const HapticLoop&) = delete;

  /// Starts the real-time thread; the first tick with a device state resets
  /// the renderer at the device pose; the fade and the passivity observer start afresh (the
  /// counters keep counting). Fails like RealTimeLoop::start().
  Status start();
  /// Stops and joins the thread. Idempotent.
  void stop();
  bool running() const noexcept;

  /// Lockstep: `n` ticks on the calling thread, advancing `clock` by one
  /// period each (RealTimeLoop::runLockstep). The first tick with a device
  /// state resets the renderer at the device pose.
  /// @code
  ///   dm::VirtualClock clock;
  ///   if (auto s = loop->runLockstep(clock, 1000); !s) return s;  // one second at 1 kHz
  /// @endcode
  Status runLockstep(VirtualClock& clock, std::uint64_t n);
  Status stepOnce(VirtualClock& clock) { return runLockstep(clock, 1); }

  /// One tick driven by an outside scheduler (e.g. an engine of a
  /// dm::MasterEngine ticking at this loop's rate), exactly what the loop's
  /// own thread runs each period; `info` carries the tick's time and period.
  /// Never while start()ed. Real-time safe.
  /// @code
  ///   auto haptics = dm::makeFunctionEngine("haptics", [&](const dm::TickInfo& t) { loop->tick(t); return
  ///   true; });
  /// @endcode
  void tick(const TickInfo& info) noexcept;
  /// The sample of the tick that just ran, for the thread that runs the
  /// ticks (other threads use latest()).
  const HapticLoopSample& lastSample() const noexcept { return last_; }
  /// Counters and timing; any thread, allocation-free.
  HapticLoopStats stats() const noexcept;
  /// Compute-time histogram (ns, real clock).
  const LatencyHistogram& computeHistogram() const noexcept { return compute_; }
  /// The newest tick's sample (one consumer thread).
  const HapticLoopSample& latest() noexcept { return samples_.read(); }
  /// The device's limits at this loop's rate (dm::limitsFor): clamp scene
  /// materials with clampMaterial(m, loop.limits()).
  const HapticLimits& limits() const noexcept { return limits_; }
  const HapticLoopConfig& config() const noexcept { return config_; }
  /// Loop period in ns.
  std::int64_t periodNs() const noexcept { return rt_.periodNs(); }

 private:
  HapticLoop(const Parts& parts, const HapticLoopConfig& config);

  HapticDevice& device_;
  HapticRenderer& renderer_;
  HapticLocalModel* model_;
  EffectStack* effects_;
  HapticLoopConfig config_;
  HapticLimits limits_;
  PassivityConfig passivity_;
  double forceLimit_ = 0.0, torqueLimit_ = 0.0;
  Mat3 rotation_ = Mat3::Identity();  // deviceToWorld's rotation

  // loop-thread state
  RealClock realClock_;
  OutputFade fade_;
  PassivityController pc_;
  bool needReset_ = true;
  bool havePrevious_ = false;
  Isometry3 prevDevicePose_ = Isometry3::Identity();
  Vec3 prevForce_ = Vec3::Zero(), prevTorque_ = Vec3::Zero();

  LatencyHistogram compute_;
  HapticLoopSample last_;  // the tick that just ran (loop thread)
  TripleBuffer<HapticLoopSample> samples_;
  std::atomic<std::uint64_t> overruns_{0}, nonFinite_{0}, lostTicks_{0}, faultTicks_{0}, poseUpdates_{0},
      passivityTicks_{0};
  std::atomic<double> workOnUser_{0.0};
  RealTimeLoop rt_;  // last: destroyed (and stopped) first
};

}  // namespace dm
