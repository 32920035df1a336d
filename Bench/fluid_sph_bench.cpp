// fluid_sph_bench — the particle fluid (dm::SphFluid, DFSPH) and its
// neighbour search (dm::NeighborGrid) against nanoflann's k-d tree.
//
//   fluid_sph_bench [steps [particles ...]]
//
// With particle counts, only the step rows for those counts (a quicker
// measure of one size while tuning).
//
// Neighbour rows: a settled-looking fluid block (a lattice of spacing d with
// a ±0.2 d jitter, seed 1) of 10k, 50k and 200k particles; all pairs within
// 2d listed — ours: NeighborGrid::build (cell binning, the lists) on the
// oneTBB threads (2 on the 2-core machine); nanoflann (Debian
// libnanoflann-dev 1.4): KDTreeSingleIndexAdaptor built, then radiusSearch
// for every point, one thread (it has no parallel radius search) and on 2
// threads (the points split between two std::threads querying the one
// tree). Column: ms per full search (best of 5), ratio ours / nanoflann
// (below 1: ours is faster); the pair counts must agree.
// Step rows: a dam break — a block of water (d = 5 mm) released in the
// corner of a box twice its width, water's viscosity — of 10k, 50k and 200k
// particles, `steps` steps (default 20) of 2 ms after 10 to let it start,
// with 1 and 2 threads: steps per second,
// sub-steps and pressure iterations per step. Goal (issue 34): 50k
// particles at 30 steps/s or more on the 2-core machine.
#include <dm/collide/neighbor_grid.hpp>
#include <dm/core/tasks.hpp>
#include <dm/physics/sph_fluid.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <nanoflann.hpp>
#include <random>
#include <thread>
#include <vector>

namespace {

using dm::Vec3;
using Clock = std::chrono::steady_clock;

double msSince(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

struct Cloud {
  const std::vector<Vec3>* points;
  std::size_t kdtree_get_point_count() const { return points->size(); }
  double kdtree_get_pt(std::size_t i, std::size_t dim) const { return (*points)[i][int(dim)]; }
  template <class Box>
  bool kdtree_get_bbox(Box&) const {
    return false;
  }
};
using Tree = nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<double, Cloud>, Cloud, 3>;

std::vector<Vec3> jitteredBlock(std::size_t n, double d) {
  const int side = int(std::ceil(std::cbrt(double(n))));
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> j(-0.2 * d, 0.2 * d);
  std::vector<Vec3> p;
  for (int z = 0; z < side && p.size() < n; ++z)
    for (int y = 0; y < side && p.size() < n; ++y)
      for (int x = 0; x < side && p.size() < n; ++x)
        p.emplace_back(x * d + j(rng), y * d + j(rng), z * d + j(rng));
  return p;
}

// All pairs within r by nanoflann, on `threads` threads; returns the pair count.
std::size_t nanoflannPairs(const std::vector<Vec3>& p, double r, int threads) {
  Cloud cloud{&p};
  Tree tree(3, cloud, nanoflann::KDTreeSingleIndexAdaptorParams(10));
  tree.buildIndex();
  std::vector<std::size_t> counts(std::size_t(threads), 0);
  auto work = [&](int t) {
    std::vector<std::pair<unsigned int, double>> matches;
    nanoflann::SearchParams params;
    params.sorted = false;
    for (std::size_t i = std::size_t(t); i < p.size(); i += std::size_t(threads)) {
      const double q[3] = {p[i].x(), p[i].y(), p[i].z()};
      counts[std::size_t(t)] += tree.radiusSearch(q, r * r, matches, params) - 1;  // less itself
    }
  };
  std::vector<std::thread> pool;
  for (int t = 1; t < threads; ++t) pool.emplace_back(work, t);
  work(0);
  for (auto& t : pool) t.join();
  std::size_t total = 0;
  for (std::size_t c : counts) total += c;
  return total;
}

void neighbourRows() {
  std::printf("%-28s %10s %12s %14s %12s %10s\n", "neighbour search (r = 2d)", "particles", "ours ms",
              "nanoflann ms", "(2 threads)", "ratio");
  for (std::size_t n : {10000u, 50000u, 200000u}) {
    const double d = 0.005;
    const std::vector<Vec3> p = jitteredBlock(n, d);
    dm::NeighborGrid grid;
    double ours = 1e300, peer1 = 1e300, peer2 = 1e300;
    std::size_t oursPairs = 0, peerPairs = 0;
    for (int k = 0; k < 5; ++k) {
      auto t0 = Clock::now();
      grid.build(p, 2 * d);
      ours = std::min(ours, msSince(t0));
      oursPairs = grid.pairCount();
      t0 = Clock::now();
      peerPairs = nanoflannPairs(p, 2 * d, 1);
      peer1 = std::min(peer1, msSince(t0));
      t0 = Clock::now();
      (void)nanoflannPairs(p, 2 * d, 2);
      peer2 = std::min(peer2, msSince(t0));
    }
    if (oursPairs != peerPairs) {
      std::printf("pair counts differ: %zu against %zu\n", oursPairs, peerPairs);
      std::exit(1);
    }
    std::printf("%-28s %10zu %12.2f %14.2f %12.2f %10.2f\n", "all pairs, lists", n, ours, peer1, peer2,
                ours / std::min(peer1, peer2));
  }
}

void stepRows(int steps, const std::vector<std::size_t>& targets) {
  std::printf("\n%-28s %10s %8s %12s %10s %12s\n", "DFSPH dam break, 2 ms steps", "particles", "threads",
              "steps/s", "sub-steps", "iterations");
  for (std::size_t target : targets) {
    for (int threads : {1, 2}) {
      const double d = 0.005;
      auto made = dm::SphFluid::create({.particleSpacing = d, .viscosity = 1e-6});
      if (!made) std::exit(1);
      dm::SphFluid fluid = *made;
      // A block of w × w × 2w in the corner of a 2w × w × 2w box.
      const double w = std::cbrt(double(target) / 2.0) * d;
      fluid.addBoxBoundary({0, 0, 0}, {2 * w, w, 2 * w});
      fluid.addBlock({0, 0, 0}, {w, w, 2 * w});
      // One thread: a TaskPool of one. Two: this thread in the default
      // arena with oneTBB's one worker on a 2-core machine (a pool's task
      // would run on that worker alone while this thread waits outside).
      dm::TaskPool pool({.max_concurrency = 1});
      auto run = [&](int count) {
        auto advance = [&] {
          for (int k = 0; k < count; ++k)
            if (!fluid.step(0.002)) std::exit(1);
        };
        if (threads == 1)
          pool.submit(advance).get();
        else
          advance();
      };
      run(10);
      double subSteps = 0, iterations = 0;
      const auto t0 = Clock::now();
      for (int k = 0; k < steps; ++k) {
        run(1);
        subSteps += fluid.lastStep().subSteps;
        iterations += fluid.lastStep().densityIterations + fluid.lastStep().divergenceIterations;
      }
      const double secs = msSince(t0) / 1e3;
      std::printf("%-28s %10zu %8d %12.1f %10.1f %12.1f\n", "step", fluid.size(), threads, steps / secs,
                  subSteps / steps, iterations / steps);
    }
  }
}

}  // namespace

int main(int argc, char** argv) {
  const int steps = argc > 1 ? std::max(1, std::atoi(argv[1])) : 20;
  std::vector<std::size_t> targets;
  for (int a = 2; a < argc; ++a) {
    const long n = std::atol(argv[a]);
    if (n < 100) {
      std::fprintf(stderr, "fluid_sph_bench: particle count '%s' is not a number of 100 or more\n", argv[a]);
      return 2;
    }
    targets.push_back(std::size_t(n));
  }
  if (targets.empty()) {
    neighbourRows();
    targets = {10000, 50000, 200000};
  }
  stepRows(steps, targets);
  return 0;
}
