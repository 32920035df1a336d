// Broad phases on N moving boxes at fixed density: each of our kinds against
// Bullet's btDbvtBroadphase and FCL's DynamicAABBTreeCollisionManager, in one
// process, on the identical box sequence.
//
// Scene: N boxes with edges uniform in [0.5, 1.5] m in a cube whose volume
// grows with N (0.25 boxes per m³, about two overlaps per box at any N),
// moving at constant random velocities (up to 0.05 m per step) and bouncing
// off the walls. Coordinates are rounded to multiples of 2⁻¹⁴ m so that they
// are exact in float (Bullet's btScalar) and in FCL's centre ± half-extent
// form: every contender sees exactly the same boxes. Per step each contender
// gets every box's new AABB and produces the overlapping pairs; the time of
// that (thread CPU time) is what is measured. The pair counts of all
// contenders are compared at every step.
//
//  - ours: update() for every box, then overlappingPairs() (sorted pairs);
//  - Bullet: setAabb() for every proxy, calculateOverlappingPairs(), then a
//    pass over the pair cache keeping the pairs whose exact AABBs overlap
//    (the cache holds pairs of fat boxes and removes stale ones lazily);
//  - FCL: setTranslation() + computeAABB() per object, update(), then
//    collide() with a callback that only counts (no narrow phase).
//
//   collide_broadphase_bench [steps=1000] [N list=1000,10000,100000] [only]
//   e.g. build-bp/Bench/collide_broadphase_bench 100 1000,10000
// `only` (for profiling) runs just the contenders whose names contain it
// (plus the peers, which the ratios need).
#include <dm/collide/broadphase.hpp>

#include <btBulletCollisionCommon.h>
#include <fcl/fcl.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <memory>
#include <random>
#include <string>
#include <vector>

namespace {

double cpuSeconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
}

double quantize(double x) { return std::round(x * 16384.0) / 16384.0; }

/// The moving boxes; step() advances them, identical for every contender
/// constructed with the same N and seed.
class Scene {
 public:
  explicit Scene(std::size_t n) : n_(n) {
    world_ = std::cbrt(double(n) / 0.25);
    std::mt19937_64 rng(42);
    std::uniform_real_distribution<double> edge(0.5, 1.5), unit(0.0, 1.0), dir(-1.0, 1.0);
    for (std::size_t i = 0; i < n; ++i) {
      Body b;
      for (int k = 0; k < 3; ++k) {
        b.half[k] = quantize(0.5 * edge(rng));
        b.centre[k] = quantize(b.half[k] + unit(rng) * (world_ - 2 * b.half[k]));
        b.vel[k] = quantize(0.05 / std::sqrt(3.0) * dir(rng));
      }
      bodies_.push_back(b);
    }
  }

  std::size_t size() const { return n_; }
  void step() {
    for (Body& b : bodies_)
      for (int k = 0; k < 3; ++k) {
        b.centre[k] += b.vel[k];
        if (b.centre[k] - b.half[k] < 0 || b.centre[k] + b.half[k] > world_) {
          b.vel[k] = -b.vel[k];
          b.centre[k] += 2 * b.vel[k];
        }
      }
  }
  dm::Aabb box(std::size_t i) const {
    const Body& b = bodies_[i];
    return dm::Aabb(dm::Vec3(b.centre[0] - b.half[0], b.centre[1] - b.half[1], b.centre[2] - b.half[2]),
                    dm::Vec3(b.centre[0] + b.half[0], b.centre[1] + b.half[1], b.centre[2] + b.half[2]));
  }
  const double* centre(std::size_t i) const { return bodies_[i].centre; }
  const double* half(std::size_t i) const { return bodies_[i].half; }

 private:
  struct Body {
    double centre[3], half[3], vel[3];
  };
  std::size_t n_;
  double world_;
  std::vector<Body> bodies_;
};

/// One contender: a name, the pair count per step and the time.
struct Run {
  std::string name;
  std::vector<std::size_t> counts;
  double seconds = 0;
  double msPerStep(int steps) const { return 1e3 * seconds / steps; }
};

Run runOurs(dm::BroadPhaseKind kind, std::size_t n, int steps) {
  Scene scene(n);
  Run r{std::string(dm::broadPhaseName(kind)), {}, 0};
  auto bp = dm::makeBroadPhase(kind);
  std::vector<dm::ProxyPair> pairs;
  for (std::size_t i = 0; i < n; ++i) bp->insert(dm::ProxyId(i), scene.box(i));
  bp->overlappingPairs(pairs);  // initial build, not timed
  for (int s = 0; s < steps; ++s) {
    scene.step();
    const double t0 = cpuSeconds();
    for (std::size_t i = 0; i < n; ++i) bp->update(dm::ProxyId(i), scene.box(i));
    bp->overlappingPairs(pairs);
    r.seconds += cpuSeconds() - t0;
    r.counts.push_back(pairs.size());
  }
  return r;
}

Run runBullet(std::size_t n, int steps) {
  Scene scene(n);
  Run r{"bullet btDbvtBroadphase", {}, 0};
  btDefaultCollisionConfiguration config;
  btCollisionDispatcher dispatcher(&config);
  btDbvtBroadphase bp;
  std::vector<btBroadphaseProxy*> proxies(n);
  auto toBt = [](const dm::Vec3& v) { return btVector3(btScalar(v.x()), btScalar(v.y()), btScalar(v.z())); };
  for (std::size_t i = 0; i < n; ++i) {
    const dm::Aabb b = scene.box(i);
    proxies[i] =
        bp.createProxy(toBt(b.min()), toBt(b.max()), BOX_SHAPE_PROXYTYPE, nullptr, 1, -1, &dispatcher);
  }
  bp.calculateOverlappingPairs(&dispatcher);
  for (int s = 0; s < steps; ++s) {
    scene.step();
    const double t0 = cpuSeconds();
    for (std::size_t i = 0; i < n; ++i) {
      const dm::Aabb b = scene.box(i);
      bp.setAabb(proxies[i], toBt(b.min()), toBt(b.max()), &dispatcher);
    }
    bp.calculateOverlappingPairs(&dispatcher);
    const btBroadphasePairArray& pairs = bp.getOverlappingPairCache()->getOverlappingPairArray();
    std::size_t count = 0;
    for (int p = 0; p < pairs.size(); ++p) {
      const btBroadphaseProxy* a = pairs[p].m_pProxy0;
      const btBroadphaseProxy* c = pairs[p].m_pProxy1;
      count += TestAabbAgainstAabb2(a->m_aabbMin, a->m_aabbMax, c->m_aabbMin, c->m_aabbMax) ? 1 : 0;
    }
    r.seconds += cpuSeconds() - t0;
    r.counts.push_back(count);
  }
  for (btBroadphaseProxy* p : proxies) bp.destroyProxy(p, &dispatcher);
  return r;
}

bool countPair(fcl::CollisionObjectd*, fcl::CollisionObjectd*, void* data) {
  ++*static_cast<std::size_t*>(data);
  return false;  // keep going; no narrow phase
}

Run runFcl(std::size_t n, int steps) {
  Scene scene(n);
  Run r{"fcl DynamicAABBTree", {}, 0};
  std::vector<std::unique_ptr<fcl::CollisionObjectd>> objects;
  fcl::DynamicAABBTreeCollisionManagerd manager;
  for (std::size_t i = 0; i < n; ++i) {
    const double* h = scene.half(i);
    auto geom = std::make_shared<fcl::Boxd>(2 * h[0], 2 * h[1], 2 * h[2]);
    objects.push_back(std::make_unique<fcl::CollisionObjectd>(geom));
    const double* c = scene.centre(i);
    objects.back()->setTranslation(fcl::Vector3d(c[0], c[1], c[2]));
    objects.back()->computeAABB();
    manager.registerObject(objects.back().get());
  }
  manager.setup();
  for (int s = 0; s < steps; ++s) {
    scene.step();
    const double t0 = cpuSeconds();
    for (std::size_t i = 0; i < n; ++i) {
      const double* c = scene.centre(i);
      objects[i]->setTranslation(fcl::Vector3d(c[0], c[1], c[2]));
      objects[i]->computeAABB();
    }
    manager.update();
    std::size_t count = 0;
    manager.collide(&count, countPair);
    r.seconds += cpuSeconds() - t0;
    r.counts.push_back(count);
  }
  return r;
}

std::vector<std::size_t> parseList(const char* s) {
  std::vector<std::size_t> out;
  std::string str(s);
  std::size_t pos = 0;
  while (pos < str.size()) {
    const std::size_t comma = str.find(',', pos);
    const std::string item = str.substr(pos, comma == std::string::npos ? std::string::npos : comma - pos);
    if (!item.empty()) out.push_back(std::strtoull(item.c_str(), nullptr, 10));
    if (comma == std::string::npos) break;
    pos = comma + 1;
  }
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  const int steps = argc > 1 ? std::max(1, std::atoi(argv[1])) : 1000;
  const std::vector<std::size_t> sizes =
      argc > 2 ? parseList(argv[2]) : std::vector<std::size_t>{1000, 10000, 100000};
  const dm::BroadPhaseKind ours[] = {dm::BroadPhaseKind::SweepAndPrune, dm::BroadPhaseKind::HashedGrid,
                                     dm::BroadPhaseKind::HierarchicalGrid,
                                     dm::BroadPhaseKind::DynamicAabbTree};
  const std::string only = argc > 3 ? argv[3] : "";
  bool allAgree = true;
  std::printf("broad phase: N moving boxes, %d steps, 0.25 boxes/m^3, edges 0.5-1.5 m, <=0.05 m/step\n",
              steps);
  for (std::size_t n : sizes) {
    std::vector<Run> runs;
    if (n <= 1000 && only.empty()) runs.push_back(runOurs(dm::BroadPhaseKind::BruteForce, n, steps));
    for (dm::BroadPhaseKind k : ours)
      if (std::string(dm::broadPhaseName(k)).find(only) != std::string::npos)
        runs.push_back(runOurs(k, n, steps));
    const std::size_t firstPeer = runs.size();
    runs.push_back(runBullet(n, steps));
    runs.push_back(runFcl(n, steps));
    for (const Run& r : runs)
      for (int s = 0; s < steps; ++s)
        if (r.counts[s] != runs[0].counts[s]) {
          std::printf("!!! MISMATCH N=%zu step %d: %s reports %zu pairs, %s reports %zu\n", n, s,
                      r.name.c_str(), r.counts[s], runs[0].name.c_str(), runs[0].counts[s]);
          allAgree = false;
          break;
        }
    double meanPairs = 0;
    for (std::size_t c : runs[0].counts) meanPairs += double(c);
    meanPairs /= steps;
    std::printf("\nN = %zu (%.0f pairs per step on average)\n", n, meanPairs);
    std::printf("  %-26s %12s %14s %14s\n", "contender", "ms/step", "ours/bullet", "ours/fcl");
    const Run& bullet = runs[firstPeer];
    const Run& fcl = runs[firstPeer + 1];
    for (std::size_t i = 0; i < runs.size(); ++i) {
      const Run& r = runs[i];
      if (i < firstPeer)
        std::printf("  %-26s %12.4f %14.3f %14.3f\n", r.name.c_str(), r.msPerStep(steps),
                    r.seconds / bullet.seconds, r.seconds / fcl.seconds);
      else
        std::printf("  %-26s %12.4f\n", r.name.c_str(), r.msPerStep(steps));
    }
    std::fflush(stdout);
  }
  std::printf("\n%s\n", allAgree ? "pair counts agree between all contenders at every step"
                                 : "!!! PAIR COUNTS DISAGREE (see above)");
  return allAgree ? 0 : 1;
}
