// haptics_vps_bench — tick time of dm::VpsRenderer (Voxmap–PointShell with
// virtual coupling) for point shells of about 380, 10k and 100k points
// against a dense and an OpenVDB sparse voxel model, and the raw per-point
// field sampling it rests on.
//
//   haptics_vps_bench [ticks] [maxPoints]
//
// Defaults: 3000 ticks per run (300 for the 100k shell), every shell size
// (maxPoints, default 200000, skips larger ones).
// Scene: a skull-like thick spherical shell (outer radius 40 mm, inner
// 34 mm) from its analytic signed distance sampled at 0.5 mm (170³ voxels;
// sparse: OpenVDB narrow band of 3 voxels). Tool: a spherical burr of radius
// 4 mm sampled by PointShell::fromMesh at the spacing that gives the point
// count. The device circles 2 mm around the top of the skull at 1 Hz while
// its depth oscillates 1 to 2 mm below the surface, so the burr stays in
// contact and slides (about a fifth of its points touch or brake).
// Rows, each timed per call (wall clock, steady_clock) into a
// dm::LatencyHistogram after 200 warm-up ticks:
//  - tick dense / tick sparse: VpsRenderer::tick() (hierarchy culling,
//    sampling, the 6×6 implicit step);
//  - raw dm sparse: VoxelModel::distance(p, gradient) on every shell point at
//    the tool pose of each tick (no culling), the sampling cost alone;
//  - raw openvdb (built with -DDM_VPS_BENCH_OPENVDB and linked with
//    OpenVDB): the same points through openvdb::tools::GridSampler<FloatGrid,
//    BoxSampler>::wsSample on a FloatGrid holding the same band values, one
//    sampler (and its accessor) reused across the points — value only, no
//    gradient, so it does less work than the dm row.
// Columns: wall-clock mean, p50, p99 and max (µs); thread-CPU mean and p99
// (µs; not counting preemption by other processes on a shared machine);
// points per µs (shell points / CPU mean); mean touching points; and for the
// raw rows the ratio dm / openvdb of the CPU means (below 1: dm faster).
// Goal: a 10k-point tick ≤ 500 µs.
#include <dm/core/rt_loop.hpp>
#include <dm/core/volume.hpp>
#include <dm/haptics/vps.hpp>
#include <dm/math/primitives.hpp>

#ifdef DM_VPS_BENCH_OPENVDB
#include <openvdb/openvdb.h>
#include <openvdb/tools/Interpolation.h>
#include <openvdb/tools/SignedFloodFill.h>
#endif

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <functional>
#include <memory>
#include <numbers>
#include <vector>

#include "bench_cpu_clock.hpp"

namespace {

using dm::Isometry3;
using dm::Vec3;

constexpr double kOuter = 0.040, kInner = 0.034, kVoxel = 0.5e-3, kBurr = 0.004;

double skullSdf(const Vec3& p) {
  const double r = p.norm();
  return std::max(r - kOuter, kInner - r);
}

std::shared_ptr<const dm::VoxelModel> skullModel() {
  const double lo = -kOuter - 2e-3;
  const int n = static_cast<int>(std::ceil(2 * -lo / kVoxel)) + 1;
  dm::Affine3 a = dm::Affine3::Identity();
  a.linear() = kVoxel * dm::Mat3::Identity();
  a.translation() = Vec3::Constant(lo);
  auto v = dm::Volume::create(dm::Vec3i::Constant(n), dm::VoxelType::F32, a);
  if (!v) return nullptr;
  float* d = v->data<float>();
  for (int k = 0, idx = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i, ++idx)
        d[idx] = static_cast<float>(skullSdf(Vec3(lo, lo, lo) + kVoxel * Vec3(i, j, k)));
  auto m = dm::VoxelModel::fromSdf(*v);
  if (!m) {
    std::fprintf(stderr, "%s\n", m.error().message().c_str());
    return nullptr;
  }
  return *m;
}

// Device pose at tick i (1 kHz): circling the top of the skull, pressing in.
Isometry3 devicePose(int i) {
  const double t = i * 1e-3;
  const double a = 2 * std::numbers::pi * t;
  const double depth = 1.5e-3 + 0.5e-3 * std::sin(2 * std::numbers::pi * 0.7 * t);
  Isometry3 p = Isometry3::Identity();
  p.translation() = Vec3(2e-3 * std::cos(a), 2e-3 * std::sin(a), kOuter + kBurr - depth);
  return p;
}

using dm::bench::threadCpuNs;

struct Row {
  dm::LatencyHistogram wall, cpu;
  double contacts = 0;
};

void timeCalls(int count, Row& row, const std::function<int(int)>& call) {
  for (int i = 0; i < count; ++i) {
    const std::int64_t c0 = threadCpuNs();
    const auto t0 = std::chrono::steady_clock::now();
    const int c = call(i);
    const auto t1 = std::chrono::steady_clock::now();
    const std::int64_t c1 = threadCpuNs();
    row.wall.record(std::chrono::duration_cast<std::chrono::nanoseconds>(t1 - t0).count());
    row.cpu.record(c1 - c0);
    row.contacts += c;
  }
  row.contacts /= count;
}

void printRow(const char* name, std::size_t points, const Row& r, double ratio) {
  const dm::LatencyHistogram::Summary s = r.wall.summary(), c = r.cpu.summary();
  std::printf("%-16s %8zu %9.2f %9.2f %9.2f %9.2f %9.2f %9.2f %9.1f %8.0f", name, points, s.mean_us, s.p50_us,
              s.p99_us, s.max_us, c.mean_us, c.p99_us, points / c.mean_us, r.contacts);
  if (ratio > 0)
    std::printf("  %6.2f\n", ratio);
  else
    std::printf("  %6s\n", "-");
}

#ifdef DM_VPS_BENCH_OPENVDB
// FloatGrid with the sparse model's band values and transform.
openvdb::FloatGrid::Ptr vdbCopy(const dm::VoxelModel& m) {
  openvdb::initialize();
  auto grid = openvdb::FloatGrid::create(static_cast<float>(m.bandWidth()));
  openvdb::Mat4d mat = openvdb::Mat4d::identity();
  const Eigen::Matrix4d e = m.indexToWorld().matrix();
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) mat(r, c) = e(c, r);
  grid->setTransform(openvdb::math::Transform::createLinearTransform(mat));
  grid->setGridClass(openvdb::GRID_LEVEL_SET);
  auto acc = grid->getAccessor();
  for (int k = 0; k < m.dims().z(); ++k)
    for (int j = 0; j < m.dims().y(); ++j)
      for (int i = 0; i < m.dims().x(); ++i) {
        const double d = m.voxelDistance(i, j, k);
        if (std::abs(d) < m.bandWidth()) acc.setValue(openvdb::Coord(i, j, k), static_cast<float>(d));
      }
  openvdb::tools::signedFloodFill(grid->tree());
  grid->tree().prune();
  return grid;
}
#endif

}  // namespace

int main(int argc, char** argv) {
  const int ticks = argc > 1 ? std::max(100, std::atoi(argv[1])) : 3000;
  const std::size_t maxPoints = argc > 2 ? std::strtoull(argv[2], nullptr, 10) : 200000;
  const auto dense = skullModel();
  if (!dense) return 1;
  auto sparse = dense->toSparse(3 * kVoxel);
  if (!sparse) {
    std::fprintf(stderr, "%s\n", sparse.error().message().c_str());
    return 1;
  }
  std::printf(
      "VPS tick, skull shell %d^3 voxels of %.2f mm (dense %.1f MB, sparse %.1f MB), burr r = %.0f mm\n",
      dense->dims().x(), kVoxel * 1e3, dense->bytes() / 1e6, (*sparse)->bytes() / 1e6, kBurr * 1e3);
#ifdef DM_VPS_BENCH_OPENVDB
  const openvdb::FloatGrid::Ptr vdb = vdbCopy(**sparse);
#else
  std::printf("(raw openvdb row off: build with -DDM_VPS_BENCH_OPENVDB and link OpenVDB)\n");
#endif
  std::printf("%-16s %8s %9s %9s %9s %9s %9s %9s %9s %8s  %6s\n", "", "points", "mean_us", "p50_us", "p99_us",
              "max_us", "cpu_mean", "cpu_p99", "pts/us", "touch", "dm/vdb");
  const double area = 4 * std::numbers::pi * kBurr * kBurr;
  for (const std::size_t target : {380u, 10000u, 100000u}) {
    if (target > maxPoints) continue;
    auto shell = dm::PointShell::fromMesh(dm::makeIcosphere(kBurr, 6),
                                          {.spacing = std::sqrt(area / static_cast<double>(target))});
    if (!shell) {
      std::fprintf(stderr, "%s\n", shell.error().message().c_str());
      return 1;
    }
    const std::size_t n = (*shell)->size();
    const int runTicks = n > 50000 ? std::max(100, ticks / 10) : ticks;
    std::vector<Isometry3> toolPoses(static_cast<std::size_t>(runTicks));
    for (const auto& [name, model] : {std::pair{"tick dense", dense}, std::pair{"tick sparse", *sparse}}) {
      auto vps = dm::VpsRenderer::create(*shell, {{model, Isometry3::Identity(), {.stiffness = 2000.0}}}, {});
      if (!vps) {
        std::fprintf(stderr, "%s\n", vps.error().message().c_str());
        return 1;
      }
      (*vps)->reset(devicePose(0));
      for (int i = 0; i < 200; ++i) (*vps)->tick({.dt = 1e-3, .devicePose = devicePose(i)});
      Row row;
      timeCalls(runTicks, row, [&](int i) {
        const dm::HapticResponse out = (*vps)->tick({.dt = 1e-3, .devicePose = devicePose(200 + i)});
        toolPoses[static_cast<std::size_t>(i)] = out.proxyPose;
        return out.contacts;
      });
      printRow(name, n, row, -1);
    }
    // Raw sampling of every point at the tool poses of the sparse run.
    const auto points = (*shell)->points();
    double sink = 0;
    Row raw;
    timeCalls(runTicks, raw, [&](int i) {
      const Isometry3& pose = toolPoses[static_cast<std::size_t>(i)];
      int touching = 0;
      for (const Vec3& p : points) {
        Vec3 g;
        const double d = (*sparse)->distance(pose * p, g);
        sink += d + g.x();
        touching += d <= 0;
      }
      return touching;
    });
#ifdef DM_VPS_BENCH_OPENVDB
    Row peer;
    timeCalls(runTicks, peer, [&](int i) {
      const Isometry3& pose = toolPoses[static_cast<std::size_t>(i)];
      openvdb::tools::GridSampler<openvdb::FloatGrid, openvdb::tools::BoxSampler> sampler(*vdb);
      int touching = 0;
      for (const Vec3& p : points) {
        const Vec3 w = pose * p;
        const double d = sampler.wsSample(openvdb::Vec3d(w.x(), w.y(), w.z()));
        sink += d;
        touching += d <= 0;
      }
      return touching;
    });
    printRow("raw dm sparse", n, raw, raw.cpu.mean() / peer.cpu.mean());
    printRow("raw openvdb", n, peer, -1);
#else
    printRow("raw dm sparse", n, raw, -1);
#endif
    if (sink == 12345.678) std::printf(" ");  // keeps the sampling loops alive
  }
  return 0;
}
