// vision_volume_bench — 3-D processing of dm::Volume on the Colin27 MRI
// (mricron-data): region growing of the white matter of ch2bet (voxels/s),
// Gaussian smoothing of ch2 against a naive single-threaded separable triple
// loop (the peer; the ratio is printed and the outputs compared), 3-D Canny,
// connected components, ball morphology, and the haptic segmentation's
// real-time guidance force (µs per call). Plain program, no assertions.
//
//   vision_volume_bench [repetitions]
#include <dm/core/filesystem.hpp>
#include <dm/core/units.hpp>
#include <dm/io/volume_io.hpp>
#include <dm/vision/region_growing.hpp>
#include <dm/vision/segmentation.hpp>
#include <dm/vision/volume_filters.hpp>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <vector>

namespace {

using Clock = std::chrono::steady_clock;

template <class F>
double bestSeconds(int reps, F&& fn) {
  double best = 1e300;
  for (int r = 0; r < reps; ++r) {
    const auto t0 = Clock::now();
    fn();
    best = std::min(best, std::chrono::duration<double>(Clock::now() - t0).count());
  }
  return best;
}

// The peer: the textbook separable Gaussian, one thread, clamp-to-edge
// borders, the same truncation (3 sigma) and normalisation as ours.
std::vector<float> naiveGaussian(const dm::Volume& v, double sigma) {
  const dm::Vec3i d = v.dims();
  const dm::Vec3 sp = v.spacing();
  std::vector<float> a(v.voxelCount()), b(v.voxelCount());
  for (std::size_t n = 0; n < a.size(); ++n) a[n] = static_cast<float>(v.valueAt(n));
  for (int axis = 0; axis < 3; ++axis) {
    const double s = sigma / sp[axis];
    const int r = static_cast<int>(std::ceil(3.0 * s));
    std::vector<double> w(static_cast<std::size_t>(r) + 1);
    double sum = 0;
    for (int t = 0; t <= r; ++t) {
      w[static_cast<std::size_t>(t)] = std::exp(-0.5 * t * t / (s * s));
      sum += t ? 2 * w[static_cast<std::size_t>(t)] : w[0];
    }
    for (double& x : w) x /= sum;
    for (int k = 0; k < d.z(); ++k)
      for (int j = 0; j < d.y(); ++j)
        for (int i = 0; i < d.x(); ++i) {
          double acc = 0;
          for (int t = -r; t <= r; ++t) {
            int p[3] = {i, j, k};
            p[axis] = std::clamp(p[axis] + t, 0, d[axis] - 1);
            acc += w[static_cast<std::size_t>(std::abs(t))] * a[v.linearIndex(p[0], p[1], p[2])];
          }
          b[v.linearIndex(i, j, k)] = static_cast<float>(acc);
        }
    std::swap(a, b);
  }
  return a;
}

// Best thread CPU time of fn() over `reps` runs: for the single-threaded
// real-time queries, so a loaded machine does not inflate them.
template <class F>
double bestThreadCpuSeconds(int reps, F&& fn) {
  auto now = [] {
    timespec ts{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
  };
  double best = 1e300;
  for (int r = 0; r < reps; ++r) {
    const double t0 = now();
    fn();
    best = std::min(best, now() - t0);
  }
  return best;
}

}  // namespace

int main(int argc, char** argv) {
  const int reps = argc > 1 ? std::max(1, std::atoi(argv[1])) : 3;
  auto headPath = dm::FileSystem::global().resolve("mricron:ch2.nii.gz");
  auto brainPath = dm::FileSystem::global().resolve("mricron:ch2bet.nii.gz");
  if (!headPath || !brainPath) {
    std::fprintf(stderr, "needs mricron-data (apt install mricron-data)\n");
    return 1;
  }
  auto head = dm::readVolume(*headPath);
  auto brain = dm::readVolume(*brainPath);
  if (!head || !brain) {
    std::fprintf(stderr, "cannot read the Colin27 volumes\n");
    return 1;
  }
  std::printf("ch2: %dx%dx%d voxels (%zu), best of %d\n", head->dims().x(), head->dims().y(),
              head->dims().z(), head->voxelCount(), reps);

  // Region growing: white matter of ch2bet from a seed in the right corona radiata.
  const auto seed = dm::nearestVoxel(*brain, dm::Vec3(26, -12, 30) * dm::units::mm);
  if (!seed) return 1;
  dm::RegionGrowResult wm;
  const double tGrow = bestSeconds(reps, [&] {
    wm = std::move(dm::growRegion(*brain, std::array{*seed},
                                  {.lower = 100, .upper = 255, .connectivity = dm::Connectivity::TwentySix})
                       .value());
  });
  std::printf("region growing (26-conn, interval)  %8.1f ms  %zu voxels  %.1f mL  %.1f Mvoxel/s\n",
              tGrow * 1e3, wm.stats.voxelCount, wm.stats.volumeMl, wm.stats.voxelCount / tGrow * 1e-6);
  const double tGrowGrad = bestSeconds(reps, [&] {
    wm = std::move(dm::growRegion(*brain, std::array{*seed},
                                  {.lower = 100,
                                   .upper = 255,
                                   .maxGradient = 40.0 / dm::units::mm,
                                   .connectivity = dm::Connectivity::TwentySix})
                       .value());
  });
  std::printf("region growing (+ gradient bound)   %8.1f ms  %zu voxels  %.1f Mvoxel/s\n", tGrowGrad * 1e3,
              wm.stats.voxelCount, wm.stats.voxelCount / tGrowGrad * 1e-6);

  // Gaussian smoothing, sigma 2 mm, against the naive separable loop.
  const double sigma = 2.0 * dm::units::mm;
  dm::Volume smooth;
  const double tOurs =
      bestSeconds(reps, [&] { smooth = std::move(dm::gaussianSmooth(*head, sigma).value()); });
  std::vector<float> ref;
  const double tNaive = bestSeconds(1, [&] { ref = naiveGaussian(*head, sigma); });
  double maxDiff = 0;
  for (std::size_t n = 0; n < ref.size(); ++n)
    maxDiff = std::max(maxDiff, std::abs(smooth.valueAt(n) - ref[n]));
  std::printf(
      "gaussian sigma 2 mm: ours %8.1f ms, naive 1-thread %8.1f ms, ratio naive/ours %.2f, max |diff| %.2g\n",
      tOurs * 1e3, tNaive * 1e3, tNaive / tOurs, maxDiff);

  dm::EdgeMap edges;
  const double tEdges =
      bestSeconds(reps, [&] { edges = std::move(dm::detectEdges(*head, {.sigma = 1e-3}).value()); });
  std::printf("3-D Canny (sigma 1 mm)              %8.1f ms\n", tEdges * 1e3);
  const dm::Volume mask = dm::threshold(*brain, 1.0).value();
  std::size_t comps = 0;
  const double tCc = bestSeconds(reps, [&] { comps = dm::labelComponents(mask).value().count(); });
  std::printf("connected components (26-conn)      %8.1f ms  %zu components\n", tCc * 1e3, comps);
  const double tErode = bestSeconds(reps, [&] { (void)dm::erode(mask, 5).value(); });
  std::printf("erode, ball radius 5 voxels         %8.1f ms\n", tErode * 1e3);

  // Haptic segmentation on ch2bet: guidance force per haptic tick.
  auto seg = dm::HapticSegmentation::create(*brain, {.grow = {.lower = 100, .upper = 255}});
  if (!seg) return 1;
  const dm::Vec3 probe = brain->indexToWorld() * seed->cast<double>();
  const int calls = 2000;
  dm::Vec3 sink = dm::Vec3::Zero();
  const double tForce = bestThreadCpuSeconds(reps, [&] {
    for (int c = 0; c < calls; ++c) sink += seg->guidanceForce(probe + dm::Vec3(1e-5 * (c % 7), 0, 0));
  });
  const double tUpdate = bestSeconds(reps, [&] {
    seg->clear();
    (void)seg->update(probe).value();
  });
  std::printf("haptic guidanceForce (64 rays)      %8.1f us/call (thread CPU time) (|F| %.3g N)\n",
              tForce / calls * 1e6, sink.norm() / calls);
  std::printf("haptic update (rays + growth)       %8.2f ms  radius %.1f mm\n", tUpdate * 1e3,
              seg->adaptiveRadius(probe) * 1e3);
  return 0;
}
