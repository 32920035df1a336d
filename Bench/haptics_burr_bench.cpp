// haptics_burr_bench — drilling voxel bone at the haptic rate: the tick of
// dm::BurrRenderer on a dense 512³ MillableVolume with removal included, the
// carving of a burr's sphere against OpenVDB's CSG difference, and the visual
// update of the touched blocks against OpenVDB's volumeToMesh of the same
// region.
//
//   haptics_burr_bench [ticks] [n] [tick]
//
// Defaults: 5000 ticks, n = 512 voxels a side at 0.25 mm (a 128 mm cube);
// a third argument "tick" runs the tick row alone (for profiles).
// Bone: a skull-like spherical shell (outer radius 55 mm, inner 48 mm) from
// its analytic signed distance, partial-volume occupancy (fromSdf). Burr: a
// 1.5 mm sphere at 80,000 rpm, 800 N/m, Archard k = 0.1, hardness 0.5 GPa.
// The device circles 3 mm about the top of the skull at 0.5 Hz while it goes
// down 4 mm over the run, 1 mm ahead of the cut, so the burr drills and
// slides the whole time.
// Rows (wall clock per call after 200 warm-up ticks; thread CPU beside it):
//  - tick dense: BurrRenderer::tick() — god-object moves, contact normal,
//    removal (MillableVolume::mill) and change-set bookkeeping;
//  - carve dm / carve openvdb: removing the whole burr sphere at the proxy
//    poses of the tick row (dm: mill() with unbounded work, which takes all
//    the tool overlaps; openvdb: tools::createLevelSetSphere at the pose and
//    tools::csgDifference from a narrow-band (3 voxels) FloatGrid of the
//    same bone), a pose every 10 ticks;
//  - surface dm / surface openvdb: one render frame's visual update every 33
//    ticks of carving (dm: blockSurfaces() of the changed 8³ blocks; openvdb:
//    tools::clip of its grid to those blocks' box, then tools::volumeToMesh).
// Columns: mean, p50, p99, p99.9 and max (µs), thread-CPU mean and p99.9
// (µs: without the time other processes took the core); for the
// peer rows the ratio dm / openvdb of the wall means (below 1: dm faster).
// Goals (issue 31): tick p99.9 ≤ 250 µs; visual update ≤ 33 ms; dm ≤ 0.5×
// OpenVDB.
#include <dm/core/rt_loop.hpp>
#include <dm/core/volume.hpp>
#include <dm/haptics/burr.hpp>

#include <openvdb/openvdb.h>
#include <openvdb/tools/Clip.h>
#include <openvdb/tools/Composite.h>
#include <openvdb/tools/LevelSetSphere.h>
#include <openvdb/tools/SignedFloodFill.h>
#include <openvdb/tools/VolumeToMesh.h>

#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <memory>
#include <numbers>
#include <string_view>
#include <vector>

#include "bench_latency.hpp"

namespace {

using dm::Isometry3;
using dm::Vec3;

constexpr double kVoxel = 0.25e-3;
constexpr double kOuter = 55e-3, kInner = 48e-3, kBurr = 1.5e-3;

double skull(const Vec3& p) { return std::max(p.norm() - kOuter, kInner - p.norm()); }

Vec3 device(int i, int ticks) {
  const double t = i * 1e-3, a = 2 * std::numbers::pi * 0.5 * t;
  const double depth = 1e-3 + 4e-3 * i / ticks;
  return Vec3(3e-3 * std::cos(a), 3e-3 * std::sin(a), kOuter + kBurr - depth);
}

using dm::bench::timeCall;
using Row = dm::bench::LatencyRow;
void printRow(const char* name, const Row& r, double ratio) { dm::bench::printLatencyRow(name, r, ratio); }

openvdb::FloatGrid::Ptr vdbSkull(int n, const dm::Affine3& a) {
  auto grid = openvdb::FloatGrid::create(static_cast<float>(3 * kVoxel));
  openvdb::Mat4d m = openvdb::Mat4d::identity();
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) m(c, r) = a.linear()(r, c);
    m(3, r) = a.translation()[r];
  }
  grid->setTransform(openvdb::math::Transform::createLinearTransform(m));
  grid->setGridClass(openvdb::GRID_LEVEL_SET);
  auto acc = grid->getAccessor();
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        const double d = skull(a * Vec3(i, j, k));
        if (std::abs(d) < 3 * kVoxel) acc.setValue(openvdb::Coord(i, j, k), static_cast<float>(d));
      }
  openvdb::tools::signedFloodFill(grid->tree());
  return grid;
}

}  // namespace

int main(int argc, char** argv) {
  const int ticks = argc > 1 ? std::atoi(argv[1]) : 5000;
  const int n = argc > 2 ? std::atoi(argv[2]) : 512;
  if (ticks < 400 || n < 64) {
    std::fprintf(stderr, "usage: haptics_burr_bench [ticks >= 400] [n >= 64]\n");
    return 2;
  }
  dm::Affine3 a = dm::Affine3::Identity();
  a.linear() = dm::Mat3::Identity() * kVoxel;
  a.translation() = Vec3(-0.5 * (n - 1) * kVoxel, -0.5 * (n - 1) * kVoxel, kOuter + 5e-3 - (n - 1) * kVoxel);
  auto build = [&]() {
    auto sdf = dm::Volume::create(dm::Vec3i(n, n, n), dm::VoxelType::F32, a, std::size_t{1} << 33);
    if (!sdf) {
      std::fprintf(stderr, "%s\n", sdf.error().message().c_str());
      std::exit(1);
    }
    float* v = sdf->data<float>();
    for (int k = 0; k < n; ++k)
      for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) *v++ = static_cast<float>(skull(a * Vec3(i, j, k)));
    auto bone = dm::MillableVolume::fromSdf(*sdf);
    if (!bone) {
      std::fprintf(stderr, "%s\n", bone.error().message().c_str());
      std::exit(1);
    }
    return std::make_shared<dm::MillableVolume>(std::move(*bone));
  };

  std::printf("haptics_burr_bench: %d ticks, %d^3 voxels of %.2f mm (%.0f MB dense), burr %.1f mm\n", ticks,
              n, kVoxel * 1e3, n * double(n) * n * 3 / 1e6, kBurr * 1e3);
  std::printf("%-16s %7s %10s %10s %10s %10s %10s %10s %10s  %8s\n", "", "calls", "mean_us", "p50_us",
              "p99_us", "p999_us", "max_us", "cpu_mean", "cpu_p999", "dm/vdb");

  // Tick row.
  std::vector<Isometry3> proxies;
  {
    auto bone = build();
    auto burr = dm::BurrRenderer::create(bone, {.tool = dm::MillingTool::sphere(kBurr), .stiffness = 800.0});
    if (!burr) return 1;
    (*burr)->reset(dm::Isometry3(Eigen::Translation3d(device(0, ticks) + Vec3(0, 0, 3e-3))));
    Row row;
    int contacts = 0;
    for (int i = 0; i < ticks; ++i) {
      Isometry3 pose = Isometry3::Identity();
      pose.translation() = device(i, ticks);
      dm::HapticResponse out;
      auto call = [&] { out = (*burr)->tick({.timeNs = i * 1000000LL, .dt = 1e-3, .devicePose = pose}); };
      if (i < 200) {
        call();
      } else {
        timeCall(row, call);
      }
      contacts += out.contacts;
      if (i % 10 == 0) proxies.push_back(out.proxyPose);
      bone->clearChanges();
    }
    printRow("tick dense", row, -1);
    {
      Row q;
      const Isometry3 at = proxies.back();
      for (int i = 0; i < 2000; ++i)
        timeCall(q, [&] { (void)bone->overlap(dm::MillingTool::sphere(kBurr), at); });
      printRow("overlap query", q, -1);
      Row nrm;
      for (int i = 0; i < 2000; ++i)
        timeCall(nrm, [&] { (void)bone->contactNormal(dm::MillingTool::sphere(kBurr), at, 2 * kVoxel); });
      printRow("normal query", nrm, -1);
    }
    std::printf("  removed %.2f mm^3, in contact %.0f %% of ticks\n", bone->removedVolume(0) * 1e9,
                100.0 * contacts / ticks);
  }

  if (argc > 3 && std::string_view(argv[3]) == "tick") return 0;
  // Carve and surface rows: dm and OpenVDB on the same poses.
  openvdb::initialize();
  auto bone = build();
  openvdb::FloatGrid::Ptr grid = vdbSkull(n, a);
  const dm::MillingTool sphere = dm::MillingTool::sphere(kBurr);
  Row carveDm, carveVdb, surfDm, surfVdb;
  std::size_t triangles = 0, vdbPolygons = 0;
  for (std::size_t p = 0; p < proxies.size(); ++p) {
    const Isometry3& pose = proxies[p];
    timeCall(carveDm, [&] { bone->mill(sphere, pose, 1e30); });
    timeCall(carveVdb, [&] {
      const Vec3 c = pose.translation();
      auto ball = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
          static_cast<float>(kBurr), openvdb::Vec3f(float(c.x()), float(c.y()), float(c.z())),
          static_cast<float>(kVoxel), 3.0f);
      openvdb::tools::csgDifference(*grid, *ball);
    });
    if ((p + 1) % 3 != 0 || bone->changedBlocks().empty()) continue;  // 3 poses = 30 ticks ≈ a frame at 33 Hz
    const auto blocks = bone->changedBlocks();
    dm::Vec3i lo = dm::Vec3i::Constant(1 << 30), hi = dm::Vec3i::Constant(-1);
    for (std::uint32_t b : blocks) {
      const dm::Vec3i bd = bone->blockDims();
      const dm::Vec3i bi(int(b % bd.x()), int((b / bd.x()) % bd.y()), int(b / (bd.x() * bd.y())));
      lo = lo.cwiseMin(bi * 8);
      hi = hi.cwiseMax(bi * 8 + dm::Vec3i::Constant(8));
    }
    timeCall(surfDm, [&] {
      auto pieces = bone->blockSurfaces(blocks);
      if (pieces)
        for (const auto& m : *pieces) triangles += m.triangles.size();
    });
    timeCall(surfVdb, [&] {
      const Vec3 wlo = a * lo.cast<double>(), whi = a * hi.cast<double>();
      const openvdb::BBoxd box(openvdb::Vec3d(wlo.x(), wlo.y(), wlo.z()),
                               openvdb::Vec3d(whi.x(), whi.y(), whi.z()));
      auto clipped = openvdb::tools::clip(*grid, box);
      std::vector<openvdb::Vec3s> points;
      std::vector<openvdb::Vec3I> tris;
      std::vector<openvdb::Vec4I> quads;
      openvdb::tools::volumeToMesh(*clipped, points, tris, quads, 0.0);
      vdbPolygons += tris.size() + 2 * quads.size();
    });
    bone->clearChanges();
  }
  const double carveRatio = carveDm.wall.summary().mean_us / carveVdb.wall.summary().mean_us;
  const double surfRatio = surfDm.wall.summary().mean_us / surfVdb.wall.summary().mean_us;
  printRow("carve dm", carveDm, carveRatio);
  printRow("carve openvdb", carveVdb, -1);
  printRow("surface dm", surfDm, surfRatio);
  printRow("surface openvdb", surfVdb, -1);
  std::printf("  surface triangles: dm %zu, openvdb %zu (quads as two)\n", triangles, vdbPolygons);
  return 0;
}
