// haptics_godobject_bench — tick time of dm::GodObjectRenderer against a
// proxy step built on FCL 0.7 distance queries, on the same meshes and the
// same scripted device path, in one process.
//
//   haptics_godobject_bench [ticks] [maxTriangles]
//
// Defaults: 20000 ticks per run, meshes of about 10k, 100k and 1M triangles
// (maxTriangles, default 1100000, skips the larger ones). Meshes: bumpy UV
// spheres (radius 5 cm, radial bumps of ±1 mm). The device path circles the
// sphere at 8 cm/s while its radius oscillates ±3 mm around 1 mm below the
// surface, so it presses, slides and lifts off (about 2/3 of the ticks in
// contact, up to 4 mm deep).
// Contenders, each timed per tick (wall clock, steady_clock) into a
// dm::LatencyHistogram:
//  - dm: GodObjectRenderer, point proxy (swept point + constraint planes);
//  - dm+: the same with force shading and friction (μs 0.3, μd 0.2);
//  - fcl: a "proxy via FCL distance" step: fcl::distance between a 1 µm
//    sphere at the device point and the mesh (BVHModel<OBBRSSd>, nearest
//    points); when the device point is behind the nearest triangle
//    (inside), the proxy is the nearest surface point, else the device
//    point; force = k·(proxy − device). It has no history, friction or
//    pop-through protection, so it does strictly less work per tick.
// Columns: p50, p99, p99.9 and max tick time (µs), ticks over the 1 ms
// haptic deadline, thread-CPU p99.9 (not counting preemption by other
// processes), and ratio = dm / fcl at p50 and p99.9 (below 1: dm faster).
// The last column compares the forces of dm (no shading) and fcl over the
// ticks where both are in contact (mean |ΔF| / mean |F|).
#include <dm/collide/bvh.hpp>
#include <dm/core/rt_loop.hpp>
#include <dm/haptics/god_object.hpp>
#include <dm/math/primitives.hpp>

#include <fcl/fcl.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <functional>
#include <memory>
#include <numbers>
#include <vector>

namespace {

using dm::Isometry3;
using dm::Vec3;

constexpr double kRadius = 0.05;       // m
constexpr double kStiffness = 1000.0;  // N/m
constexpr double kSkin = 1e-6;         // m

// UV sphere with about `triangles` triangles, vertices pushed radially by
// smooth bumps of ±1 mm.
dm::Mesh bumpySphere(std::size_t triangles) {
  // 2·segments·(rings − 1) triangles with segments = 2·(rings − 1).
  const int rings = 1 + static_cast<int>(std::lround(std::sqrt(double(triangles) / 4.0)));
  dm::Mesh m = dm::makeUvSphere(kRadius, rings, 2 * (rings - 1));
  for (Vec3& p : m.positions) {
    const Vec3 u = p.normalized();
    p = u * (kRadius + 0.001 * std::sin(9 * u.x()) * std::sin(7 * u.y() + 1) * std::cos(8 * u.z()));
  }
  return m;
}

// Scripted device point at tick i (1 kHz).
Vec3 devicePoint(int i) {
  const double t = i * 1e-3;
  const double a = 1.6 * t, b = 0.6 * std::sin(2 * std::numbers::pi * t / 7.0);
  const Vec3 u(std::cos(a) * std::cos(b), std::sin(a) * std::cos(b), std::sin(b));
  const double rho = kRadius - 0.001 + 0.003 * std::sin(2 * std::numbers::pi * t / 0.5);
  return rho * u;
}

double threadCpuNs() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return ts.tv_sec * 1e9 + ts.tv_nsec;
}

struct Row {
  dm::LatencyHistogram wall, cpu;
  int misses = 0;
  int contacts = 0;
};

// Runs `step` (returns the force) `ticks` times, timing each call.
void timeRun(int ticks, Row& row, std::vector<Vec3>& forces, const std::function<Vec3(int)>& step) {
  forces.assign(ticks, Vec3::Zero());
  for (int i = 0; i < ticks; ++i) {
    const double c0 = threadCpuNs();
    const auto t0 = std::chrono::steady_clock::now();
    const Vec3 f = step(i);
    const auto t1 = std::chrono::steady_clock::now();
    const double c1 = threadCpuNs();
    const auto ns = std::chrono::duration_cast<std::chrono::nanoseconds>(t1 - t0).count();
    row.wall.record(ns);
    row.cpu.record(static_cast<std::int64_t>(c1 - c0));
    row.misses += ns > 1'000'000;
    row.contacts += f.squaredNorm() > 0;
    forces[i] = f;
  }
}

void printRow(const char* name, std::size_t tris, const Row& r, const Row* peer, double forceDiff) {
  const dm::LatencyHistogram::Summary s = r.wall.summary(), c = r.cpu.summary();
  std::printf("%-4s %9zu %8.2f %8.2f %8.2f %9.1f %6d %8.2f %6d", name, tris, s.p50_us, s.p99_us, s.p999_us,
              s.max_us, r.misses, c.p999_us, r.contacts);
  if (peer) {
    const dm::LatencyHistogram::Summary p = peer->wall.summary();
    std::printf("  %6.2f  %6.2f", s.p50_us / p.p50_us, s.p999_us / p.p999_us);
  } else {
    std::printf("  %6s  %6s", "-", "-");
  }
  if (forceDiff >= 0) std::printf("  %6.2f %%", 100 * forceDiff);
  std::printf("\n");
}

}  // namespace

int main(int argc, char** argv) {
  const int ticks = argc > 1 ? std::max(100, std::atoi(argv[1])) : 20000;
  const std::size_t maxTris = argc > 2 ? std::strtoull(argv[2], nullptr, 10) : 1100000;
  std::printf("god-object tick time, %d ticks at 1 kHz along a press-slide-lift path on a bumpy sphere\n",
              ticks);
  std::printf("%-4s %9s %8s %8s %8s %9s %6s %8s %6s  %6s  %6s  %s\n", "", "tris", "p50_us", "p99_us",
              "p99.9_us", "max_us", ">1ms", "cpu99.9", "touch", "r_p50", "r_p999", "|dF|/|F| vs fcl");
  for (const std::size_t target : {10000u, 100000u, 1000000u}) {
    if (target > maxTris) continue;
    const dm::Mesh mesh = bumpySphere(target);
    auto built = dm::MeshBvh::build(mesh);
    if (!built) {
      std::fprintf(stderr, "%s\n", built.error().message().c_str());
      return 1;
    }
    const auto bvh = std::make_shared<const dm::MeshBvh>(std::move(*built));

    // FCL model and a tiny sphere at the device point.
    auto model = std::make_shared<fcl::BVHModel<fcl::OBBRSSd>>();
    {
      std::vector<fcl::Vector3d> v(mesh.positions.begin(), mesh.positions.end());
      std::vector<fcl::Triangle> t;
      t.reserve(mesh.triangles.size());
      for (const auto& tri : mesh.triangles) t.emplace_back(tri[0], tri[1], tri[2]);
      model->beginModel(static_cast<int>(t.size()), static_cast<int>(v.size()));
      model->addSubModel(v, t);
      model->endModel();
    }
    auto probe = std::make_shared<fcl::Sphered>(kSkin);
    fcl::CollisionObjectd meshObject(model, fcl::Transform3d::Identity());
    fcl::CollisionObjectd probeObject(probe, fcl::Transform3d::Identity());
    Vec3 fclProxy = devicePoint(0);
    const auto fclStep = [&](int i) -> Vec3 {
      const Vec3 hip = devicePoint(i);
      fcl::Transform3d tf = fcl::Transform3d::Identity();
      tf.translation() = hip;
      probeObject.setTransform(tf);
      probeObject.computeAABB();
      fcl::DistanceRequestd req(true);
      fcl::DistanceResultd res;
      fcl::distance(&meshObject, &probeObject, req, res);
      if (res.min_distance <= 0) return kStiffness * (fclProxy - hip);  // touching: keep the last proxy
      const int k = res.b1;
      const auto& tri = mesh.triangles[static_cast<std::size_t>(k)];
      const Vec3& a = mesh.positions[tri[0]];
      const Vec3 n = (mesh.positions[tri[1]] - a).cross(mesh.positions[tri[2]] - a).normalized();
      const Vec3 s = res.nearest_points[0];
      fclProxy = n.dot(hip - s) < 0 ? Vec3(s + kSkin * n) : hip;
      return kStiffness * (fclProxy - hip);
    };

    Row rows[3];
    std::vector<Vec3> forces[3];
    for (int variant = 0; variant < 2; ++variant) {
      const bool full = variant == 1;
      const dm::HapticMaterial mat{.stiffness = kStiffness,
                                   .damping = 0,
                                   .staticFriction = full ? 0.3 : 0.0,
                                   .dynamicFriction = full ? 0.2 : 0.0};
      auto r = dm::GodObjectRenderer::create({{.bvh = bvh, .pose = Isometry3::Identity(), .material = mat}},
                                             {.forceShading = full});
      if (!r) {
        std::fprintf(stderr, "%s\n", r.error().message().c_str());
        return 1;
      }
      dm::GodObjectRenderer& renderer = **r;
      Isometry3 pose = Isometry3::Identity();
      pose.translation() = devicePoint(0) * 1.2;
      renderer.reset(pose);
      timeRun(ticks, rows[variant], forces[variant], [&](int i) {
        pose.translation() = devicePoint(i);
        return renderer.tick({.timeNs = i * 1'000'000LL, .dt = 1e-3, .devicePose = pose}).force;
      });
    }
    timeRun(ticks, rows[2], forces[2], fclStep);

    double diff = 0, mag = 0;
    for (int i = 0; i < ticks; ++i) {
      if (forces[0][i].squaredNorm() > 0 && forces[2][i].squaredNorm() > 0) {
        diff += (forces[0][i] - forces[2][i]).norm();
        mag += forces[2][i].norm();
      }
    }
    printRow("dm", mesh.triangleCount(), rows[0], &rows[2], mag > 0 ? diff / mag : -1);
    printRow("dm+", mesh.triangleCount(), rows[1], &rows[2], -1);
    printRow("fcl", mesh.triangleCount(), rows[2], nullptr, -1);
  }
  return 0;
}
