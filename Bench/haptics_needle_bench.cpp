// haptics_needle_bench — a needle in 5,400 tetrahedra of FEM tissue felt at
// 1 kHz: the tick of dm::HapticNeedle (its local model of the coupling,
// evaluated at the device's pose) while a physics thread steps the needle
// and the tissue at 100 Hz, against the coupled step itself run in the tick
// (what the haptic loop would pay without the local model).
//
//   haptics_needle_bench [ticks]
//
// Defaults: 5000 ticks. Tissue: a 50 × 50 × 45 mm block of 5 mm cells (10 ×
// 10 × 9 cells, 5,400 tetrahedra), E = 30 kPa, ν = 0.45, base fixed; one
// layer: puncture 1 N, cutting 0.3 N, friction 40 N/m, coupling points every
// 0.5 mm. The device goes in at 10 mm/s from 2 mm above the top, with a
// 0.5 mm sideways wobble at 2 Hz, to 35 mm, then back out.
// Rows (wall clock per call; thread CPU beside it):
//  - tick: HapticNeedle::tick() on a real-time 1 kHz schedule, the physics
//    thread (HapticNeedle::step(0.01) every 10 ms) beside it;
//  - step: the physics thread's steps (NeedleInsertion::step with the FEM
//    step), for scale;
//  - coupled step: NeedleInsertion::step(1 ms) on a second block at every
//    tick's pose, the same path (the peer: no local model).
// Columns: mean, p50, p99, p99.9 and max (µs), thread-CPU mean and p99.9
// (µs); ratio: the tick's mean over the coupled step's (below 1: the local
// model is cheaper). Goal (issue 33): tick p99.9 ≤ 150 µs with 5k tetrahedra.
// Run it with two cores (`taskset -c 0,1`) so the physics thread has its
// own.
#include <dm/haptics/needle.hpp>
#include <dm/physics/fem.hpp>
#include <dm/physics/needle.hpp>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <numbers>
#include <thread>
#include <vector>

#include "bench_latency.hpp"

namespace {

using dm::Isometry3;
using dm::Vec3;

struct Tissue {
  dm::FemBody body;
  std::vector<std::uint8_t> layerOf;
};

Tissue block() {
  auto mesh = dm::tetMeshBox({10, 10, 9}, Vec3(0.05, 0.05, 0.045));
  auto body = dm::FemBody::create(*mesh, {.youngsModulus = 3e4, .poissonRatio = 0.45, .density = 1000.0},
                                  {.alpha = 30.0, .beta = 0.002});
  if (!mesh || !body) std::abort();
  body->fixNodesWhere([](const Vec3& p) { return p.z() < 1e-9; });
  return {std::move(*body), std::vector<std::uint8_t>(mesh->tets.size(), 0)};
}

// The needle's tip at tick i (10 mm/s in to 35 mm, then out), pointing down.
Vec3 tipAt(int i, int ticks) {
  const double t = i * 1e-3, half = ticks * 0.5e-3;
  const double depth = -0.002 + 0.01 * (t < half ? t : 2 * half - t);
  const double wobble = 5e-4 * std::sin(2 * std::numbers::pi * 2.0 * t);
  return Vec3(0.0251 + wobble, 0.0247, 0.045 - std::min(depth, 0.035));
}

const dm::NeedleLayer kLayer{.punctureForce = 1.0, .cuttingForce = 0.3, .friction = 40.0};
const dm::NeedleOptions kOptions{.couplingSpacing = 5e-4};

}  // namespace

int main(int argc, char** argv) {
  const int ticks = argc > 1 ? std::max(1000, std::atoi(argv[1])) : 5000;
  Tissue felt = block();
  auto needle = dm::NeedleInsertion::create(felt.body, felt.layerOf, {&kLayer, 1}, kOptions);
  if (!needle) return 1;
  auto haptic = dm::HapticNeedle::create(*needle, {});
  if (!haptic) return 1;

  dm::bench::LatencyRow tick, step;
  std::atomic<bool> done{false};
  std::thread physics([&] {
    auto next = std::chrono::steady_clock::now();
    while (!done.load()) {
      bool ok = true;
      dm::bench::timeCall(step, [&] { ok = (*haptic)->step(0.01).ok(); });
      if (!ok) std::abort();
      next += std::chrono::milliseconds(10);
      std::this_thread::sleep_until(next);
    }
  });
  std::size_t maxPoints = 0;
  double maxForce = 0.0;
  auto next = std::chrono::steady_clock::now();
  for (int i = 0; i < ticks; ++i) {
    Isometry3 pose = Isometry3::Identity();
    pose.translation() = tipAt(i, ticks);
    dm::HapticResponse out;
    dm::bench::timeCall(tick, [&] { out = (*haptic)->tick({.dt = 1e-3, .devicePose = pose}); });
    maxPoints = std::max(maxPoints, std::size_t(out.contacts));
    maxForce = std::max(maxForce, out.force.norm());
    next += std::chrono::microseconds(1000);
    std::this_thread::sleep_until(next);
  }
  done.store(true);
  physics.join();

  // The peer: the coupled step at every tick's pose, on its own block.
  Tissue direct = block();
  auto coupled = dm::NeedleInsertion::create(direct.body, direct.layerOf, {&kLayer, 1}, kOptions);
  if (!coupled) return 1;
  dm::bench::LatencyRow full;
  const int fullTicks = std::min(ticks, 2000);
  for (int i = 0; i < fullTicks; ++i) {
    const Vec3 tip = tipAt(i * ticks / fullTicks, ticks);
    bool ok = true;
    dm::bench::timeCall(full,
                        [&] { ok = coupled->step(tip, Vec3(0, 0, -1), 1e-3 * ticks / fullTicks).ok(); });
    if (!ok) return 1;
  }

  std::printf(
      "haptics_needle_bench: %d ticks, %zu tetrahedra, up to %zu coupling points, peak force %.2f N, "
      "%llu models published, punctures %zu\n",
      ticks, felt.body.tetCount(), maxPoints, maxForce,
      static_cast<unsigned long long>((*haptic)->publishedModels()), needle->punctureCount());
  std::printf("%-16s %7s %10s %10s %10s %10s %10s %10s %10s  %8s\n", "row", "count", "mean_us", "p50_us",
              "p99_us", "p999_us", "max_us", "cpu_mean", "cpu_p999", "ratio");
  const double ratio = tick.wall.summary().mean_us / full.wall.summary().mean_us;
  dm::bench::printLatencyRow("tick", tick, ratio);
  dm::bench::printLatencyRow("step (100 Hz)", step, -1);
  dm::bench::printLatencyRow("coupled step", full, -1);
  return 0;
}
