// HapticTissue with real threads (CI runs this under ThreadSanitizer): a
// haptic thread ticks the god-object on FEM tissue (TissueGodObject) while a
// physics thread steps the body and publishes its surfaces. The exchange is
// two triple buffers: no tree the renderer reads is rewritten under it, and
// the pressed tissue settles to the same force as in lockstep.
#include <dm/haptics/tissue.hpp>
#include <dm/physics/fem.hpp>

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <thread>

namespace dm {
namespace {

TEST(HapticTissueConcurrency, HapticAndPhysicsThreadsExchangeSurfacesAndGrips) {
  auto mesh = tetMeshBox({6, 6, 3}, Vec3(0.03, 0.03, 0.015), Vec3(-0.015, -0.015, 0.0));
  ASSERT_TRUE(mesh.ok());
  auto body = FemBody::create(*mesh, {.youngsModulus = 2e4, .poissonRatio = 0.45, .density = 1000},
                              {.alpha = 5.0, .beta = 0.02});
  ASSERT_TRUE(body.ok());
  body->fixNodesWhere([](const Vec3& p) { return p.z() < 1e-9; });
  auto tissue = HapticTissue::create(*body, {.stiffness = 800.0, .tipRadius = 1e-6});
  ASSERT_TRUE(tissue.ok());
  auto god = GodObjectRenderer::create({{.bvh = (*tissue)->restTree(), .material = {.stiffness = 800.0}}}, {});
  ASSERT_TRUE(god.ok());
  const TissueBinding binding{tissue->get(), 0};
  TissueGodObject felt(**god, {&binding, 1});

  Isometry3 device = Isometry3::Identity();
  device.translation() = Vec3(0.0011, 0.0007, 0.02);
  felt.reset(device);
  std::atomic<bool> done{false};
  std::atomic<int> physicsSteps{0};
  std::thread physics([&] {  // 100 Hz on an absolute schedule
    auto next = std::chrono::steady_clock::now();
    while (!done.load()) {
      if (!(*tissue)->step(0.01).ok()) break;
      physicsSteps.fetch_add(1);
      next += std::chrono::milliseconds(10);
      std::this_thread::sleep_until(next);
    }
  });
  // The haptic thread (this one): press 2 mm below the top, about 1 kHz.
  HapticResponse out;
  const auto start = std::chrono::steady_clock::now();
  int tick = 0;
  while (physicsSteps.load() < 150 && std::chrono::steady_clock::now() - start < std::chrono::seconds(60)) {
    const double s = std::min(1.0, tick / 300.0);
    device.translation().z() = 0.02 - s * 0.007;  // to 2 mm below the top (z = 0.015)
    out = felt.tick({.timeNs = 0, .dt = 1e-3, .devicePose = device});
    ++tick;
    std::this_thread::sleep_for(std::chrono::microseconds(500));
  }
  done.store(true);
  physics.join();
  ASSERT_GE(physicsSteps.load(), 150);
  EXPECT_GT((*tissue)->publishedSurfaces(), 100u);
  EXPECT_GT((*tissue)->grippedSteps(), 50u);
  ASSERT_TRUE(out.force.allFinite());
  EXPECT_GT(out.contacts, 0);
  // The tissue gave way: far less than the 1.6 N of a rigid surface, and the
  // hand and the tissue pull on each other with opposite forces.
  EXPECT_GT(out.force.z(), 0.05);
  EXPECT_LT(out.force.z(), 1.2);
  EXPECT_LT(((*tissue)->toolForce() + out.force).norm(), 0.1 * out.force.norm());
}

}  // namespace
}  // namespace dm
