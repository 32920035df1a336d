// Suture threads: dm::CosseratRod (direct block-tridiagonal solve, see
// dm/physics/rod.hpp) against Bullet's rope (btSoftBodyHelpers::CreateRope,
// Gauss–Seidel link projection) on the same thread: 0.5 m of 3-0 nylon
// (0.3 mm across, 1140 kg/m³, E = 3 GPa), n = 50, 100, 200 segments, pinned
// at one end and released horizontal under gravity, h = 1 ms, 1000 steps:
//  * "swing": nothing else; it falls and swings down (one swing);
//  * "pull": a 1 N pull along it on its free end (a needle drawn through
//    tissue), taut from the start;
//  * with contacts (ours only, no like-for-like peer path yet): the swing
//    falls over a 5 mm tool shaft onto a table, two passes a step; the
//    deepest penetration of the run is printed.
//
// What is compared: the CPU time of a step, and how far each thread strays
// from its length: the largest strain of the run (length / rest length − 1).
// Hooke's value for the pull is F/(EA) = 0.47 %; a swing's tension is a few
// millinewtons (strain ~1e-5). Ours is an extensible Cosserat rod with
// bending and twist (one Newton pass a step, a 6×6 block per joint);
// Bullet's rope is point masses joined by links projected piterations times
// a step (kLST = 1, no bending, float). Columns: Bullet with piterations = 1
// (the same number of passes), and with the piterations that takes about our
// time per step (found from the measured cost of one more pass).
//
// Timing: thread CPU time, best of 5 rounds.
//
//   cmake -S . -B build-bench -G Ninja -DCMAKE_BUILD_TYPE=Release -DDM_BUILD_BENCH=ON
//   ninja -C build-bench physics_rod_bench && taskset -c 1 build-bench/Bench/physics_rod_bench
//
// Arguments (optional): segment counts, e.g. "200".
#include <dm/physics/rod.hpp>

#include <BulletSoftBody/btSoftBody.h>
#include <BulletSoftBody/btSoftBodyHelpers.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <vector>

#include "bench_bullet_soft.hpp"
#include "bench_cpu_clock.hpp"

namespace {

constexpr double kLength = 0.5, kStep = 1e-3;
constexpr int kSteps = 1000, kRounds = 5;

struct OursRun {
  dm::CosseratRod rod;
  double penetration = 0;  // deepest of the run, m
};

// With `contacts`, a tool shaft (a capsule of radius 5 mm across the swing,
// 5 cm below and 10 cm out from the pin) and a table 15 cm below the pin.
std::unique_ptr<OursRun> makeOurs(int n, double pull, bool contacts = false) {
  dm::RodOptions o;
  for (int i = 0; i <= n; ++i) o.nodes.push_back({kLength * i / n, 0, 0});
  o.iterations = contacts ? 2 : 1;  // contacts need two (rod.hpp, setObstacles)
  auto rod = dm::CosseratRod::create(o);
  dm::RodObstacle shaft, table;
  shaft.shape = dm::RodObstacle::Shape::Capsule;
  shaft.a = {0.1, -0.1, -0.05};
  shaft.b = {0.1, 0.1, -0.05};
  shaft.radius = 0.005;
  table.a = {0, 0, -0.15};
  if (!rod || !rod->pin(dm::RodEnd::Start, o.nodes.front()) ||
      !rod->setNodeForce(rod->nodeCount() - 1, {pull, 0, 0}) ||
      (contacts && !rod->setObstacles({shaft, table}))) {
    std::fprintf(stderr, "physics_rod_bench: could not build the rod\n");
    std::exit(1);
  }
  return std::make_unique<OursRun>(OursRun{std::move(rod).value()});
}

double strainOurs(const OursRun& r) { return r.rod.length() / r.rod.restLength() - 1; }

struct BulletRun {
  btSoftBodyWorldInfo info;
  std::unique_ptr<btSoftBody> body;
  double pull = 0;
};

std::unique_ptr<BulletRun> makeBullet(int n, int piterations, double nodeMass, double pull) {
  auto r = std::make_unique<BulletRun>();
  r->pull = pull;
  r->info.air_density = 0;
  r->info.water_density = 0;
  r->info.m_gravity.setValue(0, 0, btScalar(-9.81));
  r->info.m_sparsesdf.Initialize();
  // res + 2 nodes: n + 1 as ours; fixeds = 1 pins node 0.
  r->body.reset(btSoftBodyHelpers::CreateRope(r->info, btVector3(0, 0, 0), btVector3(btScalar(kLength), 0, 0),
                                              n - 1, 1));
  btSoftBody& sb = *r->body;
  for (int i = 1; i < sb.m_nodes.size(); ++i) sb.setMass(i, btScalar(nodeMass));
  sb.m_materials[0]->m_kLST = 1;
  dm::bench::usePositionSolverOnly(sb, piterations);
  return r;
}

void stepBullet(btSoftBody& sb, double pull) {
  if (pull != 0) sb.addForce(btVector3(btScalar(pull), 0, 0), sb.m_nodes.size() - 1);
  dm::bench::stepSoftBody(sb, kStep);
}

double strainBullet(const btSoftBody& sb) {
  double length = 0;
  for (int i = 1; i < sb.m_nodes.size(); ++i)
    length += double((sb.m_nodes[i].m_x - sb.m_nodes[i - 1].m_x).length());
  return length / kLength - 1;
}

struct Result {
  double secondsPerStep = 1e30;
  double maxStrain = 0;
};

// One timed round of kSteps steps (kept if it is the fastest so far), then,
// untimed, the largest strain of a run.
template <class Make, class Step, class Strain>
void timeRound(Result& result, Make make, Step step, Strain strain) {
  auto run = make();
  const std::int64_t t0 = dm::bench::threadCpuNs();
  for (int s = 0; s < kSteps; ++s) step(*run);
  const std::int64_t spent = dm::bench::threadCpuNs() - t0;
  result.secondsPerStep = std::min(result.secondsPerStep, 1e-9 * double(spent) / kSteps);
  if (result.maxStrain > 0) return;
  run = make();
  for (int s = 0; s < kSteps; ++s) {
    step(*run);
    result.maxStrain = std::max(result.maxStrain, strain(*run));
  }
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<int> sizes = {50, 100, 200};
  if (argc > 1) {
    sizes.clear();
    for (int i = 1; i < argc; ++i) {
      const int n = std::atoi(argv[i]);
      if (n < 2 || n > 20000) {
        std::fprintf(stderr, "usage: %s [segments ...]  (2 to 20000)\n", argv[0]);
        return 2;
      }
      sizes.push_back(n);
    }
  }
  std::printf("Suture thread 0.5 m (3-0 nylon), pinned, released horizontal, h = 1 ms, %d steps\n", kSteps);
  std::printf("us per step (thread CPU, best of %d); max strain of the run (pull: Hooke F/EA = %.2f %%)\n\n",
              kRounds, 100 / makeOurs(2, 0)->rod.axialStiffness());
  std::printf("%-6s %6s %9s %10s %12s %8s %12s %10s %10s %8s %12s\n", "case", "n", "ours us", "strain %",
              "Bullet(1) us", "ratio", "strain %", "Bullet pit", "Bullet us", "ratio", "strain %");
  for (const double pull : {0.0, 1.0})
    for (const int n : sizes) {
      const double nodeMass = makeOurs(n, 0)->rod.segmentMass(0);  // μ L / n per node
      auto oursStep = [](OursRun& r) { (void)r.rod.step(kStep); };
      auto bulletStep = [](BulletRun& r) { stepBullet(*r.body, r.pull); };
      auto bulletStrain = [](const BulletRun& r) { return strainBullet(*r.body); };
      Result ours, bullet1;
      for (int round = 0; round < kRounds; ++round) {
        timeRound(
            ours, [&] { return makeOurs(n, pull); }, oursStep, strainOurs);
        timeRound(
            bullet1, [&] { return makeBullet(n, 1, nodeMass, pull); }, bulletStep, bulletStrain);
      }
      // Bullet's passes in about our time per step: its first pass costs more
      // than the others (prediction, bounds), so the count comes from the
      // cost of one more pass, measured at a guess and refined.
      auto measure = [&](int passes) {
        Result r;
        for (int round = 0; round < kRounds; ++round)
          timeRound(
              r, [&] { return makeBullet(n, passes, nodeMass, pull); }, bulletStep, bulletStrain);
        return r;
      };
      int pit = std::max(2, int(std::lround(ours.secondsPerStep / bullet1.secondsPerStep)));
      Result bulletEq = measure(pit);
      for (int refine = 0; refine < 2; ++refine) {
        const double perPass = (bulletEq.secondsPerStep - bullet1.secondsPerStep) / (pit - 1);
        const int next =
            std::max(2, 1 + int(std::lround((ours.secondsPerStep - bullet1.secondsPerStep) / perPass)));
        if (next == pit) break;
        pit = next;
        bulletEq = measure(pit);
      }
      std::printf("%-6s %6d %9.1f %10.4f %12.1f %8.2f %12.4g %10d %10.1f %8.2f %12.4g\n",
                  pull > 0 ? "pull" : "swing", n, 1e6 * ours.secondsPerStep, 100 * ours.maxStrain,
                  1e6 * bullet1.secondsPerStep, ours.secondsPerStep / bullet1.secondsPerStep,
                  100 * bullet1.maxStrain, pit, 1e6 * bulletEq.secondsPerStep,
                  ours.secondsPerStep / bulletEq.secondsPerStep, 100 * bulletEq.maxStrain);
    }
  std::printf("\nratio = ours / Bullet (< 1: ours faster)\n");

  // Contacts: ours only. Bullet's rope meets rigid bodies only inside a
  // btSoftRigidDynamicsWorld (another stepping path, with its broad phase),
  // so there is no like-for-like peer row yet.
  std::printf(
      "\nwith contacts, ours only: swing down over a 5 mm tool shaft onto a table, two passes a step\n");
  std::printf("%6s %9s %10s %16s\n", "n", "ours us", "strain %", "penetration um");
  for (const int n : sizes) {
    auto step = [](OursRun& r) {
      auto report = r.rod.step(kStep);
      if (report) r.penetration = std::max(r.penetration, report->penetration);
    };
    Result ours;
    double penetration = 0;
    for (int round = 0; round < kRounds; ++round)
      timeRound(
          ours, [&] { return makeOurs(n, 0, true); }, step,
          [&](const OursRun& r) {
            penetration = std::max(penetration, r.penetration);
            return strainOurs(r);
          });
    std::printf("%6d %9.1f %10.4f %16.3f\n", n, 1e6 * ours.secondsPerStep, 100 * ours.maxStrain,
                1e6 * penetration);
  }
  return 0;
}
