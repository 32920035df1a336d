// Cloth-like sheets: dm::MassSpringBody against Bullet's btSoftBody on the
// same n × n sheets (n = 64, 128, 256), 1 m × 1 m, pinned at the two corners
// of one edge, under gravity, with the same links (structural grid
// neighbours, both diagonals of every cell, nodes two apart), the same node
// masses, gravity and time step. Prints nanoseconds per node-step and the
// ratio ours / Bullet (below 1: we are faster).
//
// What is matched. Bullet's sheet comes from btSoftBodyHelpers::CreatePatch
// (structural links, same node order, corners pinned with mass 0); the shear
// and bend links are appended with appendLink so that both sides have exactly
// the same link list. Bullet is stepped directly (predictMotion,
// solveConstraints, integrateMotion — what btSoftRigidDynamicsWorld does per
// soft body, minus broadphase and rigid contacts, of which there are none),
// with viterations = diterations = 0 and piterations position-solver sweeps
// over the links. The models differ: Bullet projects links as position
// constraints (stiffness kLST in [0, 1], float precision) where we integrate
// viscoelastic forces in double precision (the implicit step keeps its
// element blocks in single precision and sums in double), so the comparison
// is cost per node-step at equal work, not equal physics. Equal work: our
// symplectic step (one force evaluation) against piterations = 1; our
// implicit step (one Newton step, CG with block-Jacobi; each CG iteration is
// one sweep over the links) against piterations = our mean CG iteration
// count.
//
// Timing: single-threaded rows use the thread's CPU time (robust on a shared
// machine), best of 5 rounds, the contenders taking turns round by round;
// the "ours par." column is wall time with dm::parallelFor on every hardware
// thread (in the implicit step only the element loop and the final update
// run in parallel: its assembly and CG sweeps scatter and stay serial).
//
//   cmake -S . -B build-phm-bench -G Ninja -DCMAKE_BUILD_TYPE=Release -DDM_BUILD_BENCH=ON
//   ninja -C build-phm-bench physics_cloth_bench && build-phm-bench/Bench/physics_cloth_bench
//
// Arguments (optional): "--implicit" runs only the h = 1/60 s table; sheet
// sizes (e.g. "64 128") replace the default 64 128 256.
#include <dm/physics/mass_spring.hpp>

#include <BulletSoftBody/btSoftBody.h>
#include <BulletSoftBody/btSoftBodyHelpers.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <functional>
#include <initializer_list>
#include <memory>
#include <string>
#include <vector>

#include "bench_bullet_soft.hpp"

namespace {

double cpuSeconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
}

double wallSeconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

// One timed contender: `reset` makes a fresh simulation, `step` advances it
// one step; `best` receives the seconds per step of its fastest round.
struct Contender {
  std::function<void()> reset, step;
  bool wall = false;  // wall-clock time (parallel runs) instead of thread CPU time
  double best = 1e30;
};

// Best of `rounds` rounds of `steps` steps for each contender, the
// contenders taking turns round by round: on a shared host whose speed
// drifts, every contender sees the same spells of fast and slow rounds, so
// the ratios do not depend on which ran in a fast spell.
void timeInterleaved(int steps, int rounds, std::initializer_list<Contender*> contenders) {
  for (int round = 0; round < rounds; ++round)
    for (Contender* c : contenders) {
      c->reset();
      const double t0 = c->wall ? wallSeconds() : cpuSeconds();
      for (int s = 0; s < steps; ++s) c->step();
      c->best = std::min(c->best, ((c->wall ? wallSeconds() : cpuSeconds()) - t0) / steps);
    }
}
constexpr int kRounds = 5;

struct Params {
  int n = 64;
  double h = 1e-3;                                // s
  double nodeMass = 0;                            // kg
  double kStructural = 0, kShear = 0, kBend = 0;  // N/m
  double damping = 0;                             // N·s/m, every layer
};

// Explicitly stable parameters at h: ω_max·h ≈ 0.5 for the stiffest node
// (ω_max² ≈ 2 Σ k / m over its 12 elements).
Params paramsFor(int n, double h) {
  Params p;
  p.n = n;
  p.h = h;
  p.nodeMass = 0.1 / double(n * n);
  p.kStructural = 0.02 * p.nodeMass / (h * h);
  p.kShear = 0.5 * p.kStructural;
  p.kBend = 0.1 * p.kStructural;
  p.damping = 0.1 * p.kStructural * h;
  return p;
}

dm::MassSpringBody makeOurs(const Params& p, bool parallel) {
  auto sheet = dm::MassSpringBody::makeSheet(
      {.nx = p.n,
       .ny = p.n,
       .width = 1.0,
       .height = 1.0,
       .mass = p.nodeMass * p.n * p.n,
       .structural = {true, p.kStructural, p.damping, dm::SpringModel::KelvinVoigt},
       .shear = {true, p.kShear, p.damping, dm::SpringModel::KelvinVoigt},
       .bend = {true, p.kBend, p.damping, dm::SpringModel::KelvinVoigt}});
  if (!sheet) {
    std::fprintf(stderr, "%s\n", sheet.error().message().c_str());
    std::exit(1);
  }
  sheet->setPinned(0, true);
  sheet->setPinned(std::size_t(p.n - 1), true);
  sheet->setGravity({0, 0, -9.81});
  sheet->setSolverOptions(
      {.cgTolerance = 1e-4, .cgMaxIterations = 200, .parallel = parallel, .parallelMinParticles = 0});
  return std::move(sheet).value();
}

struct BulletSheet {
  btSoftBodyWorldInfo info;
  std::unique_ptr<btSoftBody> body;
};

std::unique_ptr<BulletSheet> makeBullet(const Params& p, int piterations) {
  auto s = std::make_unique<BulletSheet>();
  s->info.air_density = 0;
  s->info.water_density = 0;
  s->info.m_gravity.setValue(0, 0, btScalar(-9.81));
  s->info.m_sparsesdf.Initialize();
  const int n = p.n;
  // fixeds 1 + 2: corners (0, 0) and (n−1, 0), i.e. nodes 0 and n−1 as ours.
  s->body.reset(btSoftBodyHelpers::CreatePatch(s->info, btVector3(0, 0, 0), btVector3(1, 0, 0),
                                               btVector3(0, 1, 0), btVector3(1, 1, 0), n, n, 1 + 2, false));
  btSoftBody& sb = *s->body;
  btSoftBody::Material* shear = sb.appendMaterial();
  btSoftBody::Material* bend = sb.appendMaterial();
  shear->m_kLST = btScalar(p.kShear / p.kStructural);
  bend->m_kLST = btScalar(p.kBend / p.kStructural);
  const auto id = [n](int a, int b) { return a + n * b; };
  for (int b = 0; b < n; ++b)
    for (int a = 0; a < n; ++a) {
      if (a + 1 < n && b + 1 < n) {
        sb.appendLink(id(a, b), id(a + 1, b + 1), shear);
        sb.appendLink(id(a + 1, b), id(a, b + 1), shear);
      }
      if (a + 2 < n) sb.appendLink(id(a, b), id(a + 2, b), bend);
      if (b + 2 < n) sb.appendLink(id(a, b), id(a, b + 2), bend);
    }
  for (int i = 0; i < sb.m_nodes.size(); ++i)
    sb.setMass(i, (i == 0 || i == n - 1) ? btScalar(0) : btScalar(p.nodeMass));
  dm::bench::usePositionSolverOnly(sb, piterations);
  return s;
}

void stepBullet(btSoftBody& sb, double h) { dm::bench::stepSoftBody(sb, h); }

double lowestOurs(const dm::MassSpringBody& b) {
  double z = 0;
  for (std::size_t i = 0; i < b.particleCount(); ++i) z = std::min(z, b.position(i).z());
  return z;
}

double lowestBullet(const btSoftBody& sb) {
  double z = 0;
  for (int i = 0; i < sb.m_nodes.size(); ++i) z = std::min(z, double(sb.m_nodes[i].m_x.z()));
  return z;
}

// About 0.05 s of our explicit stepping per round.
int stepsFor(int n) { return std::max(10, int(1e6 / (double(n) * n))); }

}  // namespace

int main(int argc, char** argv) {
  bool implicitOnly = false;
  std::vector<int> sizes;
  for (int a = 1; a < argc; ++a) {
    if (std::string(argv[a]) == "--implicit")
      implicitOnly = true;
    else if (const int n = std::atoi(argv[a]); n >= 4 && n <= 2048)
      sizes.push_back(n);
    else {
      std::fprintf(stderr, "usage: %s [--implicit] [n ...]  (n: sheet size, 4 to 2048)\n", argv[0]);
      return 2;
    }
  }
  if (sizes.empty()) sizes = {64, 128, 256};
  std::printf(
      "Mass-spring sheets, structural + shear (both diagonals) + bend (2 apart), 2 corners pinned.\n");
  std::printf("ns per node-step; ratio = ours / Bullet (< 1: ours faster).\n\n");

  // Table 1: explicit, h = 1 ms (parameters explicitly stable).
  if (!implicitOnly) {
    std::printf("h = 1 ms: ours symplectic Euler (1 force evaluation) vs btSoftBody piterations = 1\n");
    std::printf("%6s %8s %12s %12s %12s %8s %14s %14s\n", "n", "links", "ours", "ours par.", "Bullet",
                "ratio", "sag ours [m]", "sag Bullet [m]");
  }
  for (int n : sizes) {
    if (implicitOnly) break;
    const Params p = paramsFor(n, 1e-3);
    const int steps = stepsFor(n);
    const double nodes = double(n) * n;
    dm::MassSpringBody ours = makeOurs(p, false), par = makeOurs(p, true);
    std::unique_ptr<BulletSheet> bullet;
    Contender cOurs{[&] { ours = makeOurs(p, false); }, [&] { (void)ours.stepSymplectic(p.h); }};
    Contender cPar{[&] { par = makeOurs(p, true); }, [&] { (void)par.stepSymplectic(p.h); }, true};
    Contender cBullet{[&] { bullet = makeBullet(p, 1); }, [&] { stepBullet(*bullet->body, p.h); }};
    timeInterleaved(steps, kRounds, {&cOurs, &cPar, &cBullet});
    const double tOurs = cOurs.best, tPar = cPar.best, tBullet = cBullet.best;
    const double sagOurs = lowestOurs(ours);
    std::printf("%6d %8zu %12.2f %12.2f %12.2f %8.3f %14.4f %14.4f\n", n, ours.elementCount(),
                1e9 * tOurs / nodes, 1e9 * tPar / nodes, 1e9 * tBullet / nodes, tOurs / tBullet, sagOurs,
                lowestBullet(*bullet->body));
    if (bullet->body->m_links.size() != int(ours.elementCount()))
      std::printf("  (link count differs: Bullet %d)\n", bullet->body->m_links.size());
    std::fflush(stdout);
  }

  // Table 2: implicit at a frame-rate step where the explicit path is unstable.
  const double hFrame = 1.0 / 60;
  std::printf("%sh = 1/60 s (same springs, h*omega_max ~ 8): ours backward Euler + CG (tol 1e-4)\n",
              implicitOnly ? "" : "\n");
  std::printf("vs btSoftBody with piterations = our mean CG iterations, and = 1\n");
  std::printf("%6s %8s %12s %12s %8s %12s %8s %12s\n", "n", "CG it.", "ours", "ours par.", "Bullet", "ratio",
              "Bt it=1", "ratio");
  for (int n : sizes) {
    Params p = paramsFor(n, 1e-3);
    p.h = hFrame;
    const int steps = std::max(3, stepsFor(n) / 20);
    const double nodes = double(n) * n;
    // Our mean CG iteration count (for Bullet's piterations) from an untimed
    // run of the same steps; the timed runs repeat it exactly.
    dm::MassSpringBody ours = makeOurs(p, false);
    long iterations = 0, calls = 0;
    for (int s = 0; s < steps; ++s)
      if (auto r = ours.stepImplicit(p.h)) iterations += r->cgIterations, ++calls;
    const int meanIt = std::max(1, int(std::lround(double(iterations) / double(std::max(1L, calls)))));
    dm::MassSpringBody par = makeOurs(p, true);
    std::unique_ptr<BulletSheet> bullet, bullet1;
    Contender cOurs{[&] { ours = makeOurs(p, false); }, [&] { (void)ours.stepImplicit(p.h); }};
    Contender cPar{[&] { par = makeOurs(p, true); }, [&] { (void)par.stepImplicit(p.h); }, true};
    Contender cBullet{[&] { bullet = makeBullet(p, meanIt); }, [&] { stepBullet(*bullet->body, p.h); }};
    Contender cBullet1{[&] { bullet1 = makeBullet(p, 1); }, [&] { stepBullet(*bullet1->body, p.h); }};
    timeInterleaved(steps, kRounds, {&cOurs, &cPar, &cBullet, &cBullet1});
    const double tOurs = cOurs.best, tPar = cPar.best, tBullet = cBullet.best, tBullet1 = cBullet1.best;
    std::printf("%6d %8d %12.2f %12.2f %8.2f %12.3f %8.2f %12.3f\n", n, meanIt, 1e9 * tOurs / nodes,
                1e9 * tPar / nodes, 1e9 * tBullet / nodes, tOurs / tBullet, 1e9 * tBullet1 / nodes,
                tOurs / tBullet1);
    std::fflush(stdout);
  }
  return 0;
}
