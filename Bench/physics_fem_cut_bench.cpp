// Cutting FEM tissue: the cost of one cut update — the topology
// (dm::TetCutter::cut: crossings, splitting, regrouping the nodes) and the
// solver (dm::FemBody::applyCut: masses, block pattern, colouring) — as a
// function of the elements it splits, next to rebuilding the body from
// scratch (FemBody::create on TetCutter::mesh() plus copying the state),
// which is what a simulator without incremental updates does on each cut.
// Also the implicit step before and after the cut (colours added by the
// updates cost parallel phases).
//
// Scene: the 5 cm tissue cube of physics_fem_bench (E = 10 kPa, ν = 0.45,
// clamped at its bottom, h = 10 ms) at ~10k and ~50k tetrahedra; a blade
// cutting 2 cm deep, drawn across the top along a line oblique to the grid
// from outside to outside in steps of 0.5, 2 and 8 mm along x (one update
// per step, the body stepping between them). Times are thread CPU time on one thread (the
// body's loops run serially: `parallel = false`), mean per update.
//
//   cmake -S . -B build-rel -G Ninja -DCMAKE_BUILD_TYPE=Release -DDM_BUILD_BENCH=ON
//   ninja -C build-rel physics_fem_cut_bench && build-rel/Bench/physics_fem_cut_bench
#include <dm/physics/fem.hpp>
#include <dm/physics/tet_cut.hpp>

#include <cstdio>
#include <ctime>
#include <vector>

namespace {

constexpr double kSize = 0.05, kH = 0.01;

double cpuSeconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
}

const dm::FemMaterial kMaterial{.youngsModulus = 1e4, .poissonRatio = 0.45, .density = 1000};
const dm::FemDamping kDamping{.alpha = 1.0, .beta = 0.01};
const dm::FemSolverOptions kOptions{.tolerance = 1e-4, .maxIterations = 200, .parallel = false};

struct Row {
  int updates = 0;
  double splitPerUpdate = 0, cutMs = 0, applyMs = 0, rebuildMs = 0, stepBeforeMs = 0, stepAfterMs = 0;
  std::size_t colourBefore = 0, colourAfter = 0;
  bool ok = true;
};

Row run(const dm::Vec3i& cells, double stepLength) {
  Row row;
  auto mesh = dm::tetMeshBox(cells, dm::Vec3::Constant(kSize));
  auto body = dm::FemBody::create(*mesh, kMaterial, kDamping, kOptions);
  auto cutter = dm::TetCutter::create(*mesh);
  if (!mesh || !body || !cutter) return {.ok = false};
  body->fixNodesWhere([](const dm::Vec3& p) { return p.z() < 1e-12; });
  body->setGravity({0, 0, -9.81});
  for (int i = 0; i < 3; ++i) row.ok = row.ok && body->step(kH).ok();
  double t0 = cpuSeconds();
  for (int i = 0; i < 5; ++i) row.ok = row.ok && body->step(kH).ok();
  row.stepBeforeMs = (cpuSeconds() - t0) / 5 * 1e3;
  row.colourBefore = body->colourCount();
  // The blade: a vertical edge from 5 mm over the top to 2 cm under it,
  // drawn along the line y = 1.01 cm + 0.6 x (across the grid, not along
  // its planes).
  const double zTop = kSize + 0.005, zLow = kSize - 0.0199;
  auto y = [](double x) { return 0.0101 + 0.6 * x; };
  std::size_t split = 0;
  for (double x = -0.002; x < kSize + 0.002; x += stepLength) {
    const double x1 = x + stepLength;
    const auto sweep = dm::bladeSweep(dm::Vec3(x, y(x), zLow), dm::Vec3(x, y(x), zTop),
                                      dm::Vec3(x1, y(x1), zLow), dm::Vec3(x1, y(x1), zTop));
    t0 = cpuSeconds();
    auto up = cutter->cut(sweep, body->positions());
    const double t1 = cpuSeconds();
    row.ok = row.ok && up.ok();
    if (!up) break;
    if (!up->changedElements.empty()) row.ok = row.ok && body->applyCut(*cutter, *up).ok();
    const double t2 = cpuSeconds();
    // Rebuilding instead: the body from the cut mesh, its state copied.
    auto rebuilt = dm::FemBody::create(cutter->mesh(), kMaterial, kDamping, kOptions);
    if (rebuilt) {
      for (std::size_t i = 0; i < body->nodeCount(); ++i)
        if (body->isFixed(i)) rebuilt->setFixed(i, true);
      rebuilt->setPositions(body->positions());
      rebuilt->setVelocities(body->velocities());
    }
    const double t3 = cpuSeconds();
    row.ok = row.ok && rebuilt.ok();
    row.cutMs += (t1 - t0) * 1e3, row.applyMs += (t2 - t1) * 1e3, row.rebuildMs += (t3 - t2) * 1e3;
    split += up->tetsSplit;
    ++row.updates;
    row.ok = row.ok && body->step(kH).ok();
  }
  row.splitPerUpdate = double(split) / row.updates;
  row.cutMs /= row.updates, row.applyMs /= row.updates, row.rebuildMs /= row.updates;
  t0 = cpuSeconds();
  for (int i = 0; i < 5; ++i) row.ok = row.ok && body->step(kH).ok();
  row.stepAfterMs = (cpuSeconds() - t0) / 5 * 1e3;
  row.colourAfter = body->colourCount();
  return row;
}

}  // namespace

int main() {
  std::printf(
      "Cut update (TetCutter::cut + FemBody::applyCut) vs rebuilding the body, one thread, ms per "
      "update\n\n");
  std::printf(
      "| tets | blade step | updates | split per update | cut | applyCut | cut + apply | rebuild | rebuild / "
      "(cut + apply) | step before → after | colours before → after |\n");
  std::printf("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|---|\n");
  struct Case {
    dm::Vec3i cells;
    const char* name;
  };
  for (const Case& c : {Case{{12, 12, 12}, "10,368"}, Case{{20, 20, 21}, "50,400"}})
    for (const double step : {0.0005, 0.002, 0.008}) {
      const Row r = run(c.cells, step);
      if (!r.ok) {
        std::printf("| %s | %.1f mm | failed |\n", c.name, step * 1e3);
        continue;
      }
      const double ours = r.cutMs + r.applyMs;
      std::printf(
          "| %s | %.1f mm | %d | %.1f | %.3f | %.3f | %.3f | %.2f | %.1f | %.2f → %.2f ms | %zu → %zu |\n",
          c.name, step * 1e3, r.updates, r.splitPerUpdate, r.cutMs, r.applyMs, ours, r.rebuildMs,
          r.rebuildMs / ours, r.stepBeforeMs, r.stepAfterMs, r.colourBefore, r.colourAfter);
    }
  return 0;
}
