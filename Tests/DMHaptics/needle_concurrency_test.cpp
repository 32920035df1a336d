// HapticNeedle with real threads (CI runs this under ThreadSanitizer): a
// haptic thread at about 1 kHz pushes the needle into FEM tissue while a
// physics thread steps it at 100 Hz. The exchange is two triple buffers:
// neither thread waits, nothing the haptic thread reads is rewritten under
// it, and the needle goes through the surface and on with the friction
// the physics computes.
#include <dm/haptics/needle.hpp>
#include <dm/physics/fem.hpp>
#include <dm/physics/needle.hpp>

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <thread>
#include <vector>

namespace dm {
namespace {

TEST(HapticNeedleConcurrency, HapticAndPhysicsThreadsExchangePosesAndModels) {
  auto mesh = tetMeshBox({6, 6, 4}, Vec3(0.03, 0.03, 0.02));
  ASSERT_TRUE(mesh.ok());
  auto body = FemBody::create(*mesh, {.youngsModulus = 3e4, .poissonRatio = 0.45, .density = 1000.0},
                              {.alpha = 30.0, .beta = 0.002});
  ASSERT_TRUE(body.ok());
  body->fixNodesWhere([](const Vec3& p) { return p.z() < 1e-9; });
  const std::vector<std::uint8_t> layerOf(mesh->tets.size(), 0);
  const NeedleLayer tissue{.punctureForce = 0.6, .cuttingForce = 0.2, .friction = 40.0};
  auto needle = NeedleInsertion::create(*body, layerOf, {&tissue, 1});
  ASSERT_TRUE(needle.ok());
  auto felt = HapticNeedle::create(*needle, {.maxForce = 5.0});
  ASSERT_TRUE(felt.ok());

  std::atomic<bool> done{false};
  std::atomic<int> physicsSteps{0};
  std::thread physics([&] {  // 100 Hz on an absolute schedule
    auto next = std::chrono::steady_clock::now();
    while (!done.load()) {
      if (!(*felt)->step(0.01).ok()) break;
      physicsSteps.fetch_add(1);
      next += std::chrono::milliseconds(10);
      std::this_thread::sleep_until(next);
    }
  });
  // The haptic thread (this one): 2 mm above the top to 12 mm into it, at
  // 10 µm a tick, then hold.
  Isometry3 device = Isometry3::Identity();
  HapticResponse out;
  double peak = 0.0;
  const auto start = std::chrono::steady_clock::now();
  for (int tick = 0;
       physicsSteps.load() < 200 && std::chrono::steady_clock::now() - start < std::chrono::seconds(60);
       ++tick) {
    const double depth = std::min(0.012, -0.002 + 1e-5 * tick);
    device.translation() = Vec3(0.0151, 0.0148, 0.02 - depth);
    out = (*felt)->tick({.dt = 1e-3, .devicePose = device});
    peak = std::max(peak, out.force.z());
    std::this_thread::sleep_for(std::chrono::microseconds(500));
  }
  done.store(true);
  physics.join();
  ASSERT_GE(physicsSteps.load(), 200);
  EXPECT_GT((*felt)->publishedModels(), 150u);
  ASSERT_TRUE(out.force.allFinite());
  // Through the surface (the peak was the threshold), then held by the
  // shaft's friction and no more than the peak.
  EXPECT_EQ(needle->punctureCount(), 1u);
  EXPECT_NEAR(peak, tissue.punctureForce, 0.1 * tissue.punctureForce);
  EXPECT_GT(needle->activeCouplingCount(), 2u);
  EXPECT_GT(out.force.z(), 0.0);
  EXPECT_LT(out.force.z(), tissue.cuttingForce + tissue.friction * 0.012 + 0.05);
}

}  // namespace
}  // namespace dm
