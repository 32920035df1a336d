// HapticLoop with real threads (CI runs this under ThreadSanitizer): the
// loop on its real-time thread at 1 kHz, a physics thread publishing object
// poses through the HapticLocalModel at its own rate, the device servo on
// its own thread, and a consumer reading latest() and stats(). Every pose
// set the renderer receives must be whole (never torn between two
// publishes) and never older than the previous one.
#include <dm/haptics/haptic_loop.hpp>
#include <dm/io/drivers.hpp>

#include <gtest/gtest.h>

#include <array>
#include <atomic>
#include <chrono>
#include <thread>

namespace dm {
namespace {

// Three objects; physics publishes version v as translations (v, v, v) for
// every object. The renderer (loop thread only) checks each tick that all
// three carry the same version and that versions never go backwards.
class VersionCheckingRenderer final : public HapticRenderer {
 public:
  std::string_view name() const noexcept override { return "versions"; }
  void reset(const Isometry3&) noexcept override {}
  HapticResponse tick(const HapticInput& in) noexcept override {
    ++ticks;
    const double v = x[0];
    if (x[1] != v || x[2] != v) ++torn;
    if (v < lastVersion) ++backwards;
    lastVersion = v;
    HapticResponse r;
    r.force = -10.0 * in.devicePose.translation();  // a soft spring to the origin
    return r;
  }
  std::size_t objectCount() const noexcept override { return 3; }
  void setObjectPose(std::size_t index, const Isometry3& pose) noexcept override {
    if (index < 3) x[index] = pose.translation().x();
    if (index == 2) ++sets;
  }

  std::array<double, 3> x{0, 0, 0};
  double lastVersion = 0.0;
  std::uint64_t ticks = 0, torn = 0, backwards = 0, sets = 0;
};

TEST(HapticLoopConcurrency, PhysicsServoAndConsumerThreadsAroundTheRealTimeLoop) {
  FactoryRegistry registry;
  PluginLinker linker(registry);
  ASSERT_TRUE(registerBuiltinDrivers(linker).ok());
  auto dev = HapticDevice::open(registry, "sim-haptic", {{"path", "circle"}, {"radius", "0.02"}});
  ASSERT_TRUE(dev.ok()) << dev.error().message();
  HapticDevice& device = **dev;

  VersionCheckingRenderer renderer;
  HapticLocalModel model(3);
  EffectStack effects(1);
  ASSERT_TRUE(effects.add(std::make_unique<ViscosityEffect>(1.0)).ok());
  HapticLoopConfig cfg;
  cfg.servoInLoop = false;  // the device's own servo thread below
  cfg.passivity.enabled = true;
  auto loop =
      HapticLoop::create({.device = device, .renderer = renderer, .model = &model, .effects = &effects}, cfg);
  ASSERT_TRUE(loop.ok()) << loop.error().message();

  RealClock clock;
  std::atomic<bool> done{false};
  std::thread servo([&] {
    while (!done.load(std::memory_order_relaxed)) {
      device.servo(clock.now());
      std::this_thread::sleep_for(std::chrono::microseconds(500));
    }
  });
  std::thread physics([&] {
    std::array<Isometry3, 3> poses;
    for (int v = 1; !done.load(std::memory_order_relaxed); ++v) {
      for (auto& p : poses) p = Isometry3(Eigen::Translation3d(v, v, v));
      model.publish(poses, clock.now());
      std::this_thread::sleep_for(std::chrono::milliseconds(3));
    }
  });
  // The loop renders from the device's first state on (the ticks before it
  // are fault ticks without a renderer tick): start it once the servo
  // thread has produced one, so that every loop tick is a renderer tick.
  const auto stateBy = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  while (!device.hasState() && std::chrono::steady_clock::now() < stateBy)
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  ASSERT_TRUE(device.hasState()) << "the servo thread produced no state in 5 s";
  ASSERT_TRUE((*loop)->start().ok());
  double maxGain = 0.0;
  std::uint64_t consumerReads = 0;
  const auto until = std::chrono::steady_clock::now() + std::chrono::milliseconds(300);
  while (std::chrono::steady_clock::now() < until) {
    const HapticLoopSample& s = (*loop)->latest();
    maxGain = std::max(maxGain, s.gain);
    EXPECT_TRUE(s.deviceForce.allFinite());
    const HapticLoopStats st = (*loop)->stats();
    EXPECT_LE(st.faultTicks, st.loop.ticks + 1);
    ++consumerReads;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  (*loop)->stop();
  done = true;
  servo.join();
  physics.join();

  const HapticLoopStats st = (*loop)->stats();
  EXPECT_GT(st.loop.ticks, 10u);
  EXPECT_EQ(renderer.ticks, st.loop.ticks);
  EXPECT_EQ(renderer.torn, 0u);
  EXPECT_EQ(renderer.backwards, 0u);
  EXPECT_GT(renderer.sets, 0u);
  EXPECT_EQ(renderer.sets, model.appliedCount());
  EXPECT_LE(model.appliedCount(), model.publishedCount());
  EXPECT_GT(device.counters().servoSteps, 0u);
  EXPECT_GT(consumerReads, 0u);
  EXPECT_LE(maxGain, 1.0);
}

}  // namespace
}  // namespace dm
