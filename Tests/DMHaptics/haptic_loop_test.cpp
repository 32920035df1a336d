// HapticLoop in lockstep on a real dm::HapticDevice (the built-in
// "sim-haptic" driver): the device → world → device frame mapping against
// the transform formulas, allocation-free ticks, the local model (a 10 Hz
// physics publisher never slows the haptic ticks), the loop-side fade on
// renderer NaN, overruns and device loss, a renderer that waits for the
// device's first pose, the passivity observer against the
// zero-order-hold work sum, the passivity controller on a sampled wall, and
// configuration errors.
#include <dm/haptics/haptic_loop.hpp>
#include <dm/io/drivers.hpp>

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <limits>
#include <numbers>
#include <thread>
#include <vector>

#include "../common/alloc_counter.hpp"

namespace dm {
namespace {

constexpr std::int64_t kMs = 1'000'000;

struct Builtin {
  FactoryRegistry registry;
  PluginLinker linker{registry};
  Builtin() { EXPECT_TRUE(registerBuiltinDrivers(linker).ok()); }
};

std::unique_ptr<HapticDevice> openSim(const Builtin& b, const DeviceParams& params) {
  auto d = HapticDevice::open(b.registry, "sim-haptic", params);
  EXPECT_TRUE(d.ok()) << (d.ok() ? "" : d.error().message());
  return d.ok() ? std::move(*d) : nullptr;
}

// A test renderer: either a constant world force, or a spring of stiffness
// k pulling the device point to the position of object 0, or a penalty
// wall z < wallZ (normal +z); it can be told to return NaN or to stall.
class ProbeRenderer final : public HapticRenderer {
 public:
  enum class Mode { Constant, Spring, Wall };
  Mode mode = Mode::Constant;
  Vec3 constant = Vec3::Zero();
  double k = 0.0;
  double wallZ = 0.0;
  bool returnNan = false;
  std::chrono::microseconds stall{0};

  std::string_view name() const noexcept override { return "probe"; }
  void reset(const Isometry3& pose) noexcept override {
    resetPose = pose;
    ++resets;
  }
  HapticResponse tick(const HapticInput& in) noexcept override {
    ++ticks;
    last = in;
    if (stall.count() > 0) std::this_thread::sleep_for(stall);
    HapticResponse r;
    const Vec3 p = in.devicePose.translation();
    switch (mode) {
      case Mode::Constant:
        r.force = constant;
        break;
      case Mode::Spring:
        r.force = k * (anchor.translation() - p);
        break;
      case Mode::Wall:
        if (p.z() < wallZ) r.force = Vec3(0, 0, k * (wallZ - p.z()));
        break;
    }
    if (returnNan) r.force.x() = std::numeric_limits<double>::quiet_NaN();
    return r;
  }
  std::size_t objectCount() const noexcept override { return 1; }
  void setObjectPose(std::size_t index, const Isometry3& pose) noexcept override {
    if (index == 0) {
      anchor = pose;
      ++poseSets;
    }
  }

  Isometry3 anchor = Isometry3::Identity();
  Isometry3 resetPose = Isometry3::Identity();
  HapticInput last;
  std::uint64_t ticks = 0, resets = 0, poseSets = 0;
};

TEST(HapticLoop, MapsDeviceFrameToWorldAndForceBack) {
  Builtin b;
  auto dev =
      openSim(b, {{"path", "line"}, {"from", "0.01,0.02,0.03"}, {"to", "0.05,0.02,0.03"}, {"period", "1"}});
  ASSERT_TRUE(dev);
  ProbeRenderer r;
  r.constant = Vec3(1, 0, 0);
  HapticLoopConfig cfg;
  cfg.deviceToWorld = Eigen::Translation3d(1, 0, 0) * Eigen::AngleAxisd(std::numbers::pi / 2, Vec3::UnitZ());
  cfg.workspaceScale = 2.0;
  cfg.forceScale = 0.5;
  cfg.overrunFades = false;  // exact values whatever the machine load
  auto loop = HapticLoop::create({.device = *dev, .renderer = r}, cfg);
  ASSERT_TRUE(loop.ok()) << loop.error().message();
  VirtualClock clock;
  ASSERT_TRUE((*loop)->runLockstep(clock, 100).ok());

  const HapticState& st = dev->state();  // the sample the last tick used (servo ran in the tick)
  const Mat3 rz = Eigen::AngleAxisd(std::numbers::pi / 2, Vec3::UnitZ()).toRotationMatrix();
  const Vec3 expectedP = Vec3(1, 0, 0) + rz * (2.0 * st.position);
  EXPECT_NEAR((r.last.devicePose.translation() - expectedP).norm(), 0.0, 1e-12);
  EXPECT_NEAR((r.last.linearVelocity - 2.0 * rz * st.linearVelocity).norm(), 0.0, 1e-12);
  EXPECT_GT(st.linearVelocity.norm(), 0.01);  // the line moves, so the velocity check means something
  EXPECT_NEAR((r.last.devicePose.linear() - rz * st.orientation.toRotationMatrix()).norm(), 0.0, 1e-12);
  EXPECT_EQ(r.last.timeNs, 99 * kMs);
  EXPECT_DOUBLE_EQ(r.last.dt, 1e-3);
  EXPECT_EQ(r.resets, 1u);

  // World +x is device −y under a +90° turn about z; forceScale halves it.
  const HapticLoopSample& s = (*loop)->latest();
  EXPECT_NEAR((s.deviceForce - Vec3(0, -0.5, 0)).norm(), 0.0, 1e-12);
  EXPECT_EQ(s.tick, 99u);
  ASSERT_TRUE((*loop)->stepOnce(clock).ok());  // its servo sends the previous command
  EXPECT_NEAR((dev->lastOutput().force - Vec3(0, -0.5, 0)).norm(), 0.0, 1e-12);
}

TEST(HapticLoop, TicksNeverAllocate) {
  Builtin b;
  auto dev = openSim(b, {{"path", "circle"}, {"radius", "0.02"}});
  ASSERT_TRUE(dev);
  ProbeRenderer r;
  r.mode = ProbeRenderer::Mode::Spring;
  r.k = 100.0;
  HapticLocalModel model(1);
  EffectStack effects(3);
  ASSERT_TRUE(effects.add(std::make_unique<ViscosityEffect>(2.0)).ok());
  ASSERT_TRUE(effects.add(std::make_unique<VibrationEffect>(0.2, 100.0, Vec3::UnitZ())).ok());
  ASSERT_TRUE(effects.add(std::make_unique<VirtualFixture>(SafeSphere{Vec3::Zero(), 0.01}, 200.0, 1.0)).ok());
  HapticLoopConfig cfg;
  cfg.passivity.enabled = true;
  auto loop = HapticLoop::create({.device = *dev, .renderer = r, .model = &model, .effects = &effects}, cfg);
  ASSERT_TRUE(loop.ok());
  VirtualClock clock;
  ASSERT_TRUE((*loop)->runLockstep(clock, 10).ok());  // warm-up

  const std::vector<Isometry3> poses(1, Isometry3(Eigen::Translation3d(0.01, 0, 0)));
  const auto before = test::countedAllocations();
  test::tCountAllocations = true;
  for (int chunk = 0; chunk < 10; ++chunk) {
    model.publish(poses, clock.now());
    const Status s = (*loop)->runLockstep(clock, 100);
    if (!s) break;
  }
  const HapticLoopStats st = (*loop)->stats();
  test::tCountAllocations = false;
  EXPECT_EQ(test::countedAllocations(), before);
  EXPECT_EQ(st.loop.ticks, 1010u);
  EXPECT_EQ(st.poseUpdates, 10u);
  EXPECT_EQ(st.compute.count, 1010u);
  EXPECT_GT(st.compute.max_us, 0.0);
  EXPECT_EQ(r.poseSets, 10u);
}

TEST(HapticLocalModel, AppliesOnlyTheNewestSetOnce) {
  HapticLocalModel model(2);
  ProbeRenderer r;                // one object
  EXPECT_EQ(model.apply(r), 0u);  // nothing published yet
  EXPECT_EQ(model.appliedTimeNs(), -1);
  for (int v = 1; v <= 3; ++v) {
    const std::vector<Isometry3> poses(3, Isometry3(Eigen::Translation3d(v, 0, 0)));
    EXPECT_EQ(model.publish(poses, 100 * v), 2u);  // capacity 2: the third pose is dropped
  }
  EXPECT_EQ(model.apply(r), 1u);  // the renderer has one object
  EXPECT_EQ(r.anchor.translation().x(), 3.0);
  EXPECT_EQ(model.appliedTimeNs(), 300);
  EXPECT_EQ(model.apply(r), 0u);
  EXPECT_EQ(r.poseSets, 1u);
  EXPECT_EQ(model.publishedCount(), 3u);
  EXPECT_EQ(model.appliedCount(), 1u);
}

TEST(HapticLoop, SlowPhysicsNeverDropsHapticTicks) {
  Builtin b;
  auto dev = openSim(b, {{"path", "point"}});
  ASSERT_TRUE(dev);
  ProbeRenderer r;
  r.mode = ProbeRenderer::Mode::Spring;
  r.k = 50.0;
  HapticLocalModel model(1);
  auto loop = HapticLoop::create({.device = *dev, .renderer = r, .model = &model});
  ASSERT_TRUE(loop.ok());

  // Physics at 10 Hz: object 0 steps 1 mm along x per physics step.
  std::atomic<bool> done{false};
  std::thread physics([&] {
    for (int step = 1; !done.load(); ++step) {
      const Isometry3 pose(Eigen::Translation3d(1e-3 * step, 0, 0));
      model.publish(std::span<const Isometry3>(&pose, 1), step);
      for (int i = 0; i < 10 && !done.load(); ++i) std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
  });
  VirtualClock clock;
  std::uint64_t requested = 0;
  double lastX = 0.0;
  bool monotone = true;
  // Haptic ticks run in lockstep as fast as they can, whatever physics does.
  for (int chunk = 0; chunk < 60 && model.appliedCount() < 3; ++chunk) {
    ASSERT_TRUE((*loop)->runLockstep(clock, 200).ok());
    requested += 200;
    monotone = monotone && r.anchor.translation().x() >= lastX;
    lastX = r.anchor.translation().x();
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  done = true;
  physics.join();
  const HapticLoopStats st = (*loop)->stats();
  EXPECT_EQ(st.loop.ticks, requested);
  EXPECT_EQ(r.ticks, requested);
  EXPECT_EQ(st.loop.deadline_misses, 0u);  // lockstep: virtual time, never late
  EXPECT_GE(model.appliedCount(), 3u);
  EXPECT_LE(model.appliedCount(), model.publishedCount());
  EXPECT_EQ(r.poseSets, st.poseUpdates);
  EXPECT_GE(requested, 20 * model.appliedCount());  // many haptic ticks per physics step
  EXPECT_TRUE(monotone);
  EXPECT_NEAR(r.anchor.translation().x(), 1e-3 * static_cast<double>(model.appliedTimeNs()), 1e-12);
}

TEST(HapticLoop, RendererNanFadesTheLastForceOutAndRecovers) {
  Builtin b;
  auto dev = openSim(b, {{"path", "point"}});
  ASSERT_TRUE(dev);
  ProbeRenderer r;
  r.constant = Vec3(0, 0, 2.0);
  HapticLoopConfig cfg;
  cfg.fadeSeconds = 0.005;   // 5 ticks at 1 kHz
  cfg.overrunFades = false;  // only the NaN fades here, whatever the machine load
  auto loop = HapticLoop::create({.device = *dev, .renderer = r}, cfg);
  ASSERT_TRUE(loop.ok());
  VirtualClock clock;
  ASSERT_TRUE((*loop)->runLockstep(clock, 20).ok());
  EXPECT_NEAR((*loop)->latest().deviceForce.z(), 2.0, 1e-12);

  r.returnNan = true;
  for (int k = 1; k <= 7; ++k) {
    ASSERT_TRUE((*loop)->stepOnce(clock).ok());
    const HapticLoopSample& s = (*loop)->latest();
    const double g = std::max(0.0, 1.0 - 0.2 * k);
    EXPECT_TRUE(s.fault);
    EXPECT_NEAR(s.gain, g, 1e-12) << k;
    EXPECT_NEAR((s.deviceForce - Vec3(0, 0, 2.0 * g)).norm(), 0.0, 1e-12) << k;  // held, faded, finite
  }
  r.returnNan = false;
  for (int k = 1; k <= 6; ++k) {
    ASSERT_TRUE((*loop)->stepOnce(clock).ok());
    EXPECT_NEAR((*loop)->latest().gain, std::min(1.0, 0.2 * k), 1e-12) << k;  // ramps back, no step
  }
  const HapticLoopStats st = (*loop)->stats();
  EXPECT_EQ(st.nonFinite, 7u);
  EXPECT_GE(st.faultTicks, 7u);
  EXPECT_EQ(dev->counters().nonFinite, 0u);  // the device never saw a NaN
}

TEST(HapticLoop, OverrunningTicksFadeTheOutput) {
  Builtin b;
  auto dev = openSim(b, {{"path", "point"}});
  ASSERT_TRUE(dev);
  ProbeRenderer r;
  r.constant = Vec3(1.0, 0, 0);
  HapticLoopConfig cfg;
  cfg.fadeSeconds = 0.004;
  auto loop = HapticLoop::create({.device = *dev, .renderer = r}, cfg);
  ASSERT_TRUE(loop.ok());
  VirtualClock clock;
  ASSERT_TRUE((*loop)->runLockstep(clock, 5).ok());
  const std::uint64_t overrunsBefore = (*loop)->stats().overruns;

  r.stall = std::chrono::microseconds(2500);  // 2.5 periods of real time per tick
  for (int k = 1; k <= 5; ++k) {
    ASSERT_TRUE((*loop)->stepOnce(clock).ok());
    const HapticLoopSample& s = (*loop)->latest();
    EXPECT_TRUE(s.fault);
    EXPECT_LE(s.gain, std::max(0.0, 1.0 - 0.25 * k) + 1e-12) << k;  // 1 ms of a 4 ms fade per tick
  }
  EXPECT_EQ((*loop)->latest().gain, 0.0);
  EXPECT_EQ((*loop)->latest().deviceForce.norm(), 0.0);
  EXPECT_GE((*loop)->stats().overruns - overrunsBefore, 5u);

  r.stall = std::chrono::microseconds(0);
  const std::uint64_t overrunsStalled = (*loop)->stats().overruns;
  ASSERT_TRUE((*loop)->runLockstep(clock, 200).ok());
  if ((*loop)->stats().overruns == overrunsStalled) {  // no preemption by a loaded machine meanwhile
    EXPECT_EQ((*loop)->latest().gain, 1.0);
    EXPECT_NEAR((*loop)->latest().deviceForce.x(), 1.0, 1e-12);
  }
  EXPECT_GT((*loop)->latest().gain, 0.0);

  // With overrunFades off the same stalls are counted but the output stays.
  cfg.overrunFades = false;
  auto counting = HapticLoop::create({.device = *dev, .renderer = r}, cfg);
  ASSERT_TRUE(counting.ok());
  r.stall = std::chrono::microseconds(2500);
  ASSERT_TRUE((*counting)->runLockstep(clock, 3).ok());
  EXPECT_EQ((*counting)->stats().overruns, 3u);
  EXPECT_EQ((*counting)->latest().gain, 1.0);
  EXPECT_FALSE((*counting)->latest().fault);
}

TEST(HapticLoop, DeviceLossCutsAndReconnectionRampsUp) {
  Builtin b;
  auto dev = openSim(b, {{"path", "point"}, {"drop_at", "0.05"}, {"reconnect_at", "0.1"}});
  ASSERT_TRUE(dev);
  ProbeRenderer r;
  r.constant = Vec3(0, 1.0, 0);
  HapticLoopConfig cfg;
  cfg.fadeSeconds = 0.01;
  cfg.overrunFades = false;
  auto loop = HapticLoop::create({.device = *dev, .renderer = r}, cfg);
  ASSERT_TRUE(loop.ok());
  VirtualClock clock;
  ASSERT_TRUE((*loop)->runLockstep(clock, 60).ok());  // lost at 50 ms
  EXPECT_FALSE(dev->connected());
  EXPECT_EQ((*loop)->latest().gain, 0.0);
  EXPECT_EQ((*loop)->latest().deviceForce.norm(), 0.0);
  EXPECT_EQ(dev->lastOutput().force.norm(), 0.0);

  // Reconnection is retried every 100 ms from the loss: back at 150 ms.
  bool sawRamp = false;
  for (int k = 0; k < 200; ++k) {
    ASSERT_TRUE((*loop)->stepOnce(clock).ok());
    const double g = (*loop)->latest().gain;
    if (g > 0.0 && g < 1.0) sawRamp = true;
  }
  EXPECT_TRUE(dev->connected());
  EXPECT_TRUE(sawRamp);  // no force step after reconnection
  EXPECT_EQ((*loop)->latest().gain, 1.0);
  EXPECT_NEAR(dev->lastOutput().force.y(), 1.0, 1e-12);
  EXPECT_GT((*loop)->stats().lostTicks, 0u);
}

TEST(HapticLoop, TheRendererWaitsForTheDevicesFirstPose) {
  // A device that is lost from its first servo (a remote one whose first
  // state is still on the way) has no pose: a renderer reset at the
  // default pose would start a god-object's proxy at the device origin.
  Builtin b;
  auto dev = openSim(
      b, {{"path", "point"}, {"center", "0.01,0.02,0.03"}, {"drop_at", "0"}, {"reconnect_at", "0.05"}});
  ASSERT_TRUE(dev);
  ProbeRenderer r;
  r.constant = Vec3(0, 1.0, 0);
  HapticLoopConfig cfg;
  cfg.overrunFades = false;
  auto loop = HapticLoop::create({.device = *dev, .renderer = r}, cfg);
  ASSERT_TRUE(loop.ok());
  VirtualClock clock;
  ASSERT_TRUE((*loop)->runLockstep(clock, 60).ok());
  EXPECT_FALSE(dev->hasState());
  EXPECT_EQ(r.ticks, 0u);
  EXPECT_EQ(r.resets, 0u);
  EXPECT_TRUE((*loop)->latest().fault);
  EXPECT_EQ((*loop)->latest().deviceForce.norm(), 0.0);
  EXPECT_EQ((*loop)->stats().faultTicks, 60u);
  // Reconnected at 100 ms (retried every 100 ms from the loss): the first
  // tick with a state resets the renderer where the device is.
  ASSERT_TRUE((*loop)->runLockstep(clock, 100).ok());
  EXPECT_TRUE(dev->hasState());
  EXPECT_EQ(r.resets, 1u);
  EXPECT_GT(r.ticks, 0u);
  EXPECT_NEAR((r.resetPose.translation() - Vec3(0.01, 0.02, 0.03)).norm(), 0.0, 1e-12);
}

TEST(HapticLoop, ObserverSumsTheZeroOrderHoldWork) {
  Builtin b;
  auto dev = openSim(b, {{"path", "circle"}, {"radius", "0.03"}, {"period", "0.5"}});
  ASSERT_TRUE(dev);
  ProbeRenderer r;
  r.mode = ProbeRenderer::Mode::Spring;
  r.k = 150.0;
  r.anchor = Isometry3(Eigen::Translation3d(0.01, 0, 0));
  HapticLoopConfig cfg;
  cfg.deviceToWorld = Eigen::AngleAxisd(0.3, Vec3::UnitX()) * Isometry3::Identity();
  auto loop = HapticLoop::create({.device = *dev, .renderer = r}, cfg);
  ASSERT_TRUE(loop.ok());
  VirtualClock clock;
  double expected = 0.0;
  Vec3 prevF = Vec3::Zero(), prevX = Vec3::Zero();
  for (int k = 0; k < 600; ++k) {
    ASSERT_TRUE((*loop)->stepOnce(clock).ok());
    const Vec3 x = dev->state().position;
    if (k > 0) expected += prevF.dot(x - prevX);
    prevF = (*loop)->latest().deviceForce;
    prevX = x;
  }
  EXPECT_NEAR((*loop)->stats().workOnUser, expected, 1e-12);
  EXPECT_NE(expected, 0.0);
}

TEST(HapticLoop, PassivityControllerStopsASampledWallFromGeneratingEnergy) {
  // The device sweeps 4 cm in and out of a wall at z = 0 rendered at only
  // 100 Hz: the zero-order hold makes the wall active (energy out > in).
  auto run = [](bool controlled) {
    Builtin b;
    auto dev = openSim(b, {{"path", "line"}, {"from", "0,0,0.02"}, {"to", "0,0,-0.02"}, {"period", "1"}});
    EXPECT_TRUE(dev);
    ProbeRenderer r;
    r.mode = ProbeRenderer::Mode::Wall;
    r.k = 300.0;  // ≤ 6 N at 2 cm: below the 8 N force limit
    HapticLoopConfig cfg;
    cfg.loop.rate_hz = 100.0;
    cfg.passivity.enabled = controlled;
    cfg.overrunFades = false;
    auto loop = HapticLoop::create({.device = *dev, .renderer = r}, cfg);
    EXPECT_TRUE(loop.ok());
    VirtualClock clock;
    EXPECT_TRUE((*loop)->runLockstep(clock, 101).ok());  // one full sweep, back at the top
    return (*loop)->stats();
  };
  const HapticLoopStats free = run(false);
  const HapticLoopStats pc = run(true);
  // The zero-order-hold leak K·N·Δx²: N = 25 ticks of Δx = 0.8 mm to the bottom.
  EXPECT_NEAR(free.workOnUser, 300.0 * 25 * 0.0008 * 0.0008, 1e-9);
  EXPECT_EQ(free.passivityTicks, 0u);
  EXPECT_GT(pc.passivityTicks, 0u);
  EXPECT_LE(pc.workOnUser, 1e-9);
}

TEST(HapticLoop, LimitsAndConfigurationErrors) {
  Builtin b;
  auto dev = openSim(b, {{"path", "point"}});
  ASSERT_TRUE(dev);
  ProbeRenderer r;
  HapticLoopConfig cfg;
  cfg.loop.rate_hz = 500.0;
  auto loop = HapticLoop::create({.device = *dev, .renderer = r}, cfg);
  ASSERT_TRUE(loop.ok());
  // sim-haptic: 2000 N/m at its 1 kHz servo rate → 1000 N/m at 500 Hz.
  EXPECT_DOUBLE_EQ((*loop)->limits().maxStiffness, 1000.0);
  EXPECT_EQ((*loop)->periodNs(), 2 * kMs);

  struct Case {
    HapticLoopConfig cfg;
    const char* field;
  };
  std::vector<Case> cases(5);
  cases[0].cfg.workspaceScale = 0.0;
  cases[0].field = "workspaceScale";
  cases[1].cfg.forceScale = std::numeric_limits<double>::quiet_NaN();
  cases[1].field = "forceScale";
  cases[2].cfg.fadeSeconds = -1.0;
  cases[2].field = "fadeSeconds";
  cases[3].cfg.deviceToWorld.linear() = 2.0 * Mat3::Identity();
  cases[3].field = "deviceToWorld";
  cases[4].cfg.loop.rate_hz = 0.0;
  cases[4].field = "rate_hz";
  for (const Case& c : cases) {
    auto bad = HapticLoop::create({.device = *dev, .renderer = r}, c.cfg);
    ASSERT_FALSE(bad.ok()) << c.field;
    EXPECT_EQ(bad.error().code, ErrorCode::InvalidArgument);
    EXPECT_NE(bad.error().message().find(c.field), std::string::npos) << bad.error().message();
  }
}

TEST(HapticLoop, RunsOnItsRealTimeThread) {
  Builtin b;
  auto dev = openSim(b, {{"path", "circle"}});
  ASSERT_TRUE(dev);
  ProbeRenderer r;
  r.constant = Vec3(0.5, 0, 0);
  auto loop = HapticLoop::create({.device = *dev, .renderer = r});
  ASSERT_TRUE(loop.ok());
  ASSERT_TRUE((*loop)->start().ok());
  EXPECT_FALSE((*loop)->start().ok());  // Busy
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  (*loop)->stop();
  EXPECT_FALSE((*loop)->running());
  const HapticLoopStats st = (*loop)->stats();
  EXPECT_GT(st.loop.ticks, 0u);
  EXPECT_EQ(st.compute.count, st.loop.ticks);
  EXPECT_EQ(r.resets, 1u);
  EXPECT_EQ(r.ticks, st.loop.ticks);
}

}  // namespace
}  // namespace dm
