// Tests of dm/collide/broadphase.hpp: every accelerated broad phase must
// report exactly the pair set and query results of brute force (all
// n(n−1)/2 box tests, the definition of the answer) on random moving scenes
// with inserts, removes, teleports and non-finite boxes, on many co-located
// identical boxes, on touching boxes and on the empty broad phase.
#include <dm/collide/broadphase.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <memory>
#include <random>
#include <string>
#include <vector>

namespace {

using dm::Aabb;
using dm::BroadPhase;
using dm::BroadPhaseKind;
using dm::BroadPhaseOptions;
using dm::ProxyId;
using dm::ProxyPair;
using dm::Vec3;

constexpr BroadPhaseKind kAccelerated[] = {BroadPhaseKind::SweepAndPrune, BroadPhaseKind::HashedGrid,
                                           BroadPhaseKind::HierarchicalGrid, BroadPhaseKind::DynamicAabbTree};

/// Each accelerated kind with default options plus option variants that
/// reach other code paths (tiny cells: boxes spanning many cells; huge
/// cells: everything in one cell; no fat margin).
struct Variant {
  BroadPhaseKind kind;
  BroadPhaseOptions options;
  std::string label;
};

std::vector<Variant> variants() {
  std::vector<Variant> v;
  for (BroadPhaseKind k : kAccelerated) v.push_back({k, {}, std::string(dm::broadPhaseName(k))});
  v.push_back({BroadPhaseKind::HashedGrid, {0.02, 0.1}, "hashed-grid cell 0.02"});
  v.push_back({BroadPhaseKind::HashedGrid, {50.0, 0.1}, "hashed-grid cell 50"});
  v.push_back({BroadPhaseKind::HierarchicalGrid, {0.01, 0.1}, "hierarchical-grid cell 0.01"});
  v.push_back({BroadPhaseKind::DynamicAabbTree, {0.0, 0.0}, "dynamic-aabb-tree margin 0"});
  v.push_back({BroadPhaseKind::DynamicAabbTree, {0.0, 2.0}, "dynamic-aabb-tree margin 2"});
  return v;
}

Aabb box(double x0, double y0, double z0, double x1, double y1, double z1) {
  return Aabb(Vec3(x0, y0, z0), Vec3(x1, y1, z1));
}

/// Positions and sizes on a 1/64 grid so that exactly touching faces occur.
double snap(double x) { return std::round(x * 64.0) / 64.0; }

Aabb randomBox(std::mt19937_64& rng, double world) {
  std::uniform_real_distribution<double> u(0.0, world);
  std::uniform_real_distribution<double> logSize(std::log(0.05), std::log(2.0));
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  Vec3 lo(snap(u(rng)), snap(u(rng)), snap(u(rng)));
  Vec3 size;
  for (int k = 0; k < 3; ++k) size[k] = snap(std::exp(logSize(rng)));
  if (unit(rng) < 0.02) size *= 4.0;  // a few large boxes
  return Aabb(lo, lo + size);
}

/// Runs the same operations on brute force and on `v`, comparing the pair
/// sets and some queries after each step.
class Lockstep {
 public:
  explicit Lockstep(const Variant& v)
      : ref_(dm::makeBroadPhase(BroadPhaseKind::BruteForce)), bp_(dm::makeBroadPhase(v.kind, v.options)) {}

  void insert(ProxyId id, const Aabb& b) { ref_->insert(id, b), bp_->insert(id, b); }
  void update(ProxyId id, const Aabb& b) { ref_->update(id, b), bp_->update(id, b); }
  void remove(ProxyId id) { ref_->remove(id), bp_->remove(id); }
  void clear() { ref_->clear(), bp_->clear(); }

  /// Compares pairs and the queries of `probes`; returns the pair count.
  std::size_t check(const std::vector<Aabb>& probes, const std::string& where) {
    ref_->overlappingPairs(refPairs_);
    bp_->overlappingPairs(pairs_);
    EXPECT_EQ(bp_->size(), ref_->size()) << where;
    EXPECT_EQ(pairs_.size(), refPairs_.size()) << where;
    EXPECT_TRUE(pairs_ == refPairs_) << where << ": first difference at " << firstDifference();
    for (const Aabb& q : probes) {
      ref_->query(q, refIds_);
      bp_->query(q, ids_);
      EXPECT_TRUE(ids_ == refIds_) << where << ": query differs (" << ids_.size() << " vs " << refIds_.size()
                                   << ")";
    }
    return refPairs_.size();
  }

  BroadPhase& bp() { return *bp_; }

 private:
  std::string firstDifference() const {
    for (std::size_t i = 0; i < std::max(pairs_.size(), refPairs_.size()); ++i) {
      if (i >= pairs_.size() || i >= refPairs_.size() || !(pairs_[i] == refPairs_[i])) {
        auto str = [](const std::vector<ProxyPair>& p, std::size_t j) {
          return j < p.size() ? "(" + std::to_string(p[j].a) + "," + std::to_string(p[j].b) + ")"
                              : std::string("end");
        };
        return "index " + std::to_string(i) + ": got " + str(pairs_, i) + ", want " + str(refPairs_, i);
      }
    }
    return "none";
  }

  std::unique_ptr<BroadPhase> ref_, bp_;
  std::vector<ProxyPair> pairs_, refPairs_;
  std::vector<ProxyId> ids_, refIds_;
};

TEST(BroadPhase, RandomMovingScenesMatchBruteForce) {
  for (const Variant& v : variants()) {
    SCOPED_TRACE(v.label);
    std::mt19937_64 rng(1234);
    const double world = 6.0;
    Lockstep ls(v);
    std::vector<Aabb> boxes;
    std::vector<char> live;
    for (ProxyId id = 0; id < 300; ++id) {
      boxes.push_back(randomBox(rng, world));
      live.push_back(1);
      ls.insert(id, boxes.back());
    }
    std::uniform_real_distribution<double> jitter(-0.12, 0.12);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    std::uniform_int_distribution<ProxyId> pick(0, 299);
    std::size_t totalPairs = 0;
    for (int step = 0; step < 50; ++step) {
      const std::string where = v.label + ", step " + std::to_string(step);
      for (ProxyId id = 0; id < boxes.size(); ++id) {
        if (!live[id]) continue;
        if (step == 30) {
          boxes[id] = randomBox(rng, world);  // everything teleports at once
        } else if (unit(rng) < 0.01) {
          boxes[id] = randomBox(rng, world);  // a few teleports
        } else if (unit(rng) < 0.8) {
          const Vec3 d(snap(jitter(rng)), snap(jitter(rng)), snap(jitter(rng)));
          boxes[id] = Aabb(boxes[id].min() + d, boxes[id].max() + d);
        }
        ls.update(id, boxes[id]);
      }
      // Removes and (re-)inserts mid-run, some of the same id in one step.
      for (int r = 0; r < 6; ++r) {
        const ProxyId id = pick(rng);
        if (live[id]) {
          ls.remove(id);
          live[id] = 0;
        } else {
          boxes[id] = randomBox(rng, world);
          ls.insert(id, boxes[id]);
          live[id] = 1;
        }
      }
      if (step % 7 == 3) {  // remove and re-insert in the same step
        const ProxyId id = pick(rng);
        if (live[id]) {
          ls.remove(id);
          boxes[id] = randomBox(rng, world);
          ls.insert(id, boxes[id]);
        }
      }
      if (step % 10 == 5) {  // a burst of new, sparse ids
        for (ProxyId id = 1000 + ProxyId(step); id < 1000 + ProxyId(step) + 40; id += 2)
          ls.insert(id, randomBox(rng, world));
      }
      if (step % 10 == 6) {
        for (ProxyId id = 1000 + ProxyId(step) - 1; id < 1000 + ProxyId(step) + 39; id += 2) ls.remove(id);
      }
      std::vector<Aabb> probes = {randomBox(rng, world), randomBox(rng, world),
                                  box(-1, -1, -1, world + 3, world + 3, world + 3)};
      totalPairs += ls.check(probes, where);
      if (::testing::Test::HasFailure()) return;
    }
    EXPECT_GT(totalPairs, 50u * 100u);  // the scene is not trivially sparse
  }
}

TEST(BroadPhase, CoLocatedIdenticalBoxes) {
  for (const Variant& v : variants()) {
    SCOPED_TRACE(v.label);
    Lockstep ls(v);
    const Aabb b = box(1, 1, 1, 2, 2, 2);
    for (ProxyId id = 0; id < 200; ++id) ls.insert(id, b);
    EXPECT_EQ(ls.check({b, box(2, 2, 2, 3, 3, 3), box(2.5, 0, 0, 3, 1, 1)}, "co-located"), 200u * 199u / 2u);
    // Move all together, then slide one away, then collapse to a point.
    for (ProxyId id = 0; id < 200; ++id) ls.update(id, box(5, 5, 5, 6, 6, 6));
    EXPECT_EQ(ls.check({}, "moved together"), 200u * 199u / 2u);
    ls.update(7, box(6, 5, 5, 7, 6, 6));  // touches the others
    EXPECT_EQ(ls.check({}, "one touching"), 200u * 199u / 2u);
    ls.update(7, box(6.5, 5, 5, 7, 6, 6));
    EXPECT_EQ(ls.check({}, "one apart"), 199u * 198u / 2u);
    for (ProxyId id = 0; id < 200; ++id) ls.update(id, box(3, 3, 3, 3, 3, 3));
    EXPECT_EQ(ls.check({box(3, 3, 3, 3, 3, 3)}, "points"), 200u * 199u / 2u);
  }
}

TEST(BroadPhase, TouchingBoxesOverlap) {
  for (const Variant& v : variants()) {
    SCOPED_TRACE(v.label);
    Lockstep ls(v);
    ls.insert(0, box(0, 0, 0, 1, 1, 1));
    ls.insert(1, box(1, 0, 0, 2, 1, 1));        // face
    ls.insert(2, box(1, 1, 0, 2, 2, 1));        // edge with 0
    ls.insert(3, box(1, 1, 1, 2, 2, 2));        // corner with 0
    ls.insert(4, box(-1, 0, 0, -1e-12, 1, 1));  // a hair apart from 0
    ls.insert(5, box(0, -2, 0, 1, -1e-9, 1));   // a hair apart from 0
    ls.check({box(1, 1, 1, 1, 1, 1)}, "touching");
    std::vector<ProxyPair> pairs;
    ls.bp().overlappingPairs(pairs);
    const std::vector<ProxyPair> want = {{0, 1}, {0, 2}, {0, 3}, {1, 2}, {1, 3}, {2, 3}};
    EXPECT_EQ(pairs, want);
  }
}

TEST(BroadPhase, EmptyAndUnknownIds) {
  for (const Variant& v : variants()) {
    SCOPED_TRACE(v.label);
    auto bp = dm::makeBroadPhase(v.kind, v.options);
    EXPECT_EQ(bp->kind(), v.kind);
    std::vector<ProxyPair> pairs = {{1, 2}};
    std::vector<ProxyId> ids = {3};
    bp->overlappingPairs(pairs);
    bp->query(box(-1e9, -1e9, -1e9, 1e9, 1e9, 1e9), ids);
    EXPECT_TRUE(pairs.empty());
    EXPECT_TRUE(ids.empty());
    EXPECT_EQ(bp->size(), 0u);
    bp->remove(5);  // unknown: ignored
    bp->update(6, box(0, 0, 0, 1, 1, 1));
    EXPECT_EQ(bp->size(), 0u);
    bp->insert(2, box(0, 0, 0, 1, 1, 1));
    bp->insert(9, box(0.5, 0.5, 0.5, 1, 1, 1));
    bp->remove(5);
    bp->remove(100000);
    EXPECT_EQ(bp->size(), 2u);
    bp->overlappingPairs(pairs);
    EXPECT_EQ(pairs, (std::vector<ProxyPair>{{2, 9}}));
    bp->remove(2);
    bp->remove(2);
    EXPECT_EQ(bp->size(), 1u);
    bp->overlappingPairs(pairs);
    EXPECT_TRUE(pairs.empty());
    bp->clear();
    EXPECT_EQ(bp->size(), 0u);
    bp->query(box(-1, -1, -1, 2, 2, 2), ids);
    EXPECT_TRUE(ids.empty());
    bp->insert(9, box(0, 0, 0, 1, 1, 1));
    bp->insert(2, box(1, 1, 1, 2, 2, 2));
    bp->overlappingPairs(pairs);
    EXPECT_EQ(pairs, (std::vector<ProxyPair>{{2, 9}}));
  }
}

TEST(BroadPhase, NonFiniteBoxOverlapsNothing) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  for (const Variant& v : variants()) {
    SCOPED_TRACE(v.label);
    Lockstep ls(v);
    ls.insert(0, box(0, 0, 0, 1, 1, 1));
    ls.insert(1, box(nan, 0, 0, 1, 1, 1));
    ls.insert(2, box(0.5, 0.5, 0.5, 2, 2, 2));
    ls.insert(3, box(0, 0, 0, 1, 1, nan));
    EXPECT_EQ(ls.check({box(0, 0, 0, 1, 1, 1), box(nan, nan, nan, nan, nan, nan)}, "nan inserted"), 1u);
    ls.update(1, box(0.25, 0.25, 0.25, 0.75, 0.75, 0.75));
    EXPECT_EQ(ls.check({box(0, 0, 0, 1, 1, 1)}, "nan repaired"), 3u);
    ls.update(0, box(nan, nan, nan, nan, nan, nan));
    EXPECT_EQ(ls.check({box(0, 0, 0, 1, 1, 1)}, "nan again"), 1u);
    ls.update(0, box(0, 0, 0, 1, 1, 1));
    ls.remove(3);
    EXPECT_EQ(ls.check({}, "all finite"), 3u);
    // An infinite box is not usable either; brute force agrees because
    // inf − inf comparisons still order, so only check it overlaps nothing
    // in the accelerated broad phase.
    ls.bp().update(2, box(-inf, 0, 0, inf, 1, 1));
    std::vector<ProxyPair> pairs;
    ls.bp().overlappingPairs(pairs);
    EXPECT_EQ(pairs, (std::vector<ProxyPair>{{0, 1}}));
  }
}

TEST(BroadPhase, HugeAndFlatBoxesMatchBruteForce) {
  // Edges that overflow to infinity, flat boxes and points among normal ones.
  for (const Variant& v : variants()) {
    SCOPED_TRACE(v.label);
    Lockstep ls(v);
    ls.insert(0, box(-1e308, -1e308, -1e308, 1e308, 1e308, 1e308));
    ls.insert(1, box(0, 0, 0, 1, 1, 1));
    ls.insert(2, box(0.5, 0.5, 0.5, 0.5, 0.5, 0.5));
    ls.insert(3, box(-5, -5, 1, 5, 5, 1));
    ls.insert(4, box(1e300, 1e300, 1e300, 1e301, 1e301, 1e301));
    ls.insert(5, box(3, 3, 3, 4, 4, 4));
    EXPECT_EQ(ls.check({box(0, 0, 0, 0, 0, 0), box(2, 2, 2, 1e302, 1e302, 1e302)}, "huge"), 5u + 2u);
    ls.update(0, box(-1, -1, -1, 0, 0, 0));
    EXPECT_EQ(ls.check({}, "huge shrunk"), 3u);
  }
}

TEST(BroadPhase, SteadyMotionReversalsAndLargeMovesMatchBruteForce) {
  // The tree stretches fat boxes along the last displacement: boxes in steady
  // motion that then reverse, stop, jump far or crowd into one spot must still
  // report exactly brute force's pairs.
  for (const Variant& v : variants()) {
    SCOPED_TRACE(v.label);
    std::mt19937_64 rng(7);
    std::uniform_real_distribution<double> dir(-0.05, 0.05);
    Lockstep ls(v);
    std::vector<Aabb> boxes;
    std::vector<Vec3> vel;
    for (ProxyId id = 0; id < 200; ++id) {
      boxes.push_back(randomBox(rng, 5.0));
      vel.push_back(Vec3(snap(dir(rng)), snap(dir(rng)), snap(dir(rng))));
      ls.insert(id, boxes.back());
    }
    for (int step = 0; step < 60; ++step) {
      for (ProxyId id = 0; id < boxes.size(); ++id) {
        if (step == 20) vel[id] = -vel[id];                      // everything reverses
        if (step == 35 && id % 2 == 0) vel[id] = Vec3(0, 0, 0);  // half stop
        Vec3 d = vel[id];
        if (step == 45 && id % 5 == 0) d = Vec3(snap(40 * dir(rng)), 0, snap(-40 * dir(rng)));  // jumps
        if (step == 50 && id % 3 == 0) d = Vec3(2.5, 2.5, 2.5) - boxes[id].min();  // crowd at one corner
        boxes[id] = Aabb(boxes[id].min() + d, boxes[id].max() + d);
        ls.update(id, boxes[id]);
      }
      ls.check({randomBox(rng, 5.0), box(2.5, 2.5, 2.5, 2.5, 2.5, 2.5)},
               v.label + ", step " + std::to_string(step));
      if (::testing::Test::HasFailure()) return;
    }
  }
}

TEST(BroadPhase, HugeBoxesAmongManyMatchBruteForce) {
  // Enough boxes that the tree rebuilds itself, with boxes whose centres
  // overflow (−1e308…1e308) or lie far out among them.
  for (const Variant& v : variants()) {
    SCOPED_TRACE(v.label);
    std::mt19937_64 rng(5);
    Lockstep ls(v);
    ls.insert(0, box(-1e308, -1e308, -1e308, 1e308, 1e308, 1e308));
    ls.insert(1, box(1e300, 1e300, 1e300, 1e301, 1e301, 1e301));
    ls.insert(2, box(-1e308, 0, 0, 1e308, 1, 1));
    for (ProxyId id = 3; id < 400; ++id) ls.insert(id, randomBox(rng, 10.0));
    ls.check({box(0, 0, 0, 1, 1, 1), box(2e300, 2e300, 2e300, 3e300, 3e300, 3e300)}, "huge among many");
    for (ProxyId id = 3; id < 400; id += 2) ls.update(id, randomBox(rng, 10.0));
    ls.update(1, box(0, 0, 0, 1e301, 1e301, 1e301));
    ls.check({box(0, 0, 0, 1, 1, 1)}, "huge among many, moved");
  }
}

TEST(BroadPhase, BulkInsertAndRemoveMatchBruteForce) {
  for (const Variant& v : variants()) {
    SCOPED_TRACE(v.label);
    std::mt19937_64 rng(99);
    Lockstep ls(v);
    for (ProxyId id = 0; id < 1000; ++id) ls.insert(id, randomBox(rng, 22.0));
    ls.check({randomBox(rng, 22.0)}, "bulk insert");
    for (ProxyId id = 0; id < 1000; id += 3) ls.remove(id);
    ls.check({randomBox(rng, 22.0)}, "bulk remove");
    for (ProxyId id = 0; id < 1000; id += 3) ls.insert(id, randomBox(rng, 22.0));
    ls.check({randomBox(rng, 22.0)}, "re-insert");
  }
}

// Sweep-and-prune keeps one sorted list per column of a coarse grid (edge:
// twice the median box size, re-chosen when the count or the median size
// changes by 2x) and reports a pair only in the column holding the corner of
// its overlap. Boxes crossing column edges every step, spanning several
// columns or more than the column limit (plates), arriving and leaving in
// numbers that re-choose the grid, growing threefold, vanishing and
// returning, and slots reused within a step must still give brute force's
// pairs.
TEST(BroadPhase, SweepAndPruneColumnsMatchBruteForce) {
  const Variant v{BroadPhaseKind::SweepAndPrune, {}, "sweep-and-prune"};
  std::mt19937_64 rng(77);
  std::uniform_real_distribution<double> u(0.0, 12.0), dir(-0.4, 0.4);
  Lockstep ls(v);
  std::vector<Aabb> boxes(700);
  std::vector<Vec3> vel(700);
  std::vector<char> live(700, 0);
  auto place = [&](ProxyId id, const Vec3& lo, const Vec3& size) {
    boxes[id] = Aabb(lo, lo + size);
    vel[id] = Vec3(snap(dir(rng)), snap(dir(rng)), snap(dir(rng)));
    if (live[id]) {
      ls.update(id, boxes[id]);
    } else {
      ls.insert(id, boxes[id]);
      live[id] = 1;
    }
  };
  auto randomLo = [&] { return Vec3(snap(u(rng)), snap(u(rng)), snap(u(rng))); };
  for (ProxyId id = 0; id < 150; ++id) place(id, randomLo(), Vec3(1, 1, 1));
  place(150, Vec3(-74, 5, -74), Vec3(160, 0.125, 160));  // plates: more columns than the limit
  place(151, Vec3(5, -74, -74), Vec3(0.125, 160, 160));
  place(152, Vec3(-74, -74, 5), Vec3(160, 160, 0.125));
  place(153, Vec3(0, 6, 6), Vec3(12, 0.25, 0.25));  // rods: a few columns, or a long list entry
  place(154, Vec3(6, 0, 6), Vec3(0.25, 12, 0.25));
  place(155, Vec3(6, 6, 0), Vec3(0.25, 0.25, 12));
  std::size_t total = 0;
  for (int step = 0; step < 110; ++step) {
    const std::string where = "step " + std::to_string(step);
    for (ProxyId id = 0; id < boxes.size(); ++id) {
      if (!live[id]) continue;
      Vec3 d = vel[id];
      for (int k = 0; k < 3; ++k)
        if ((boxes[id].min()[k] + d[k] < -2 && d[k] < 0) || (boxes[id].max()[k] + d[k] > 14 && d[k] > 0))
          vel[id][k] = -vel[id][k], d[k] = 0;
      boxes[id] = Aabb(boxes[id].min() + d, boxes[id].max() + d);
      ls.update(id, boxes[id]);
    }
    if (step == 10)  // three times as many boxes: the grid is re-chosen
      for (ProxyId id = 200; id < 500; ++id) place(id, randomLo(), Vec3(0.5, 1.5, 1));
    if (step == 20)  // and back
      for (ProxyId id = 200; id < 480; ++id) ls.remove(id), live[id] = 0;
    if (step == 30)  // every box three times the size: re-chosen at the next size check
      for (ProxyId id = 0; id < boxes.size(); ++id)
        if (live[id] && id < 150) place(id, boxes[id].min(), 3 * (boxes[id].max() - boxes[id].min()));
    if (step % 5 == 2) {  // a slot freed and taken by another id in the same step
      const ProxyId gone = ProxyId(step % 150), fresh = ProxyId(500 + step);
      ls.remove(gone), live[gone] = 0;
      place(fresh, randomLo(), Vec3(2, 0.5, 1));
      place(gone, randomLo(), Vec3(1, 1, 1));
    }
    if (step == 15) ls.update(5, box(std::nan(""), 0, 0, 1, 1, 1));  // parked, out of its columns
    if (step == 17) ls.update(5, boxes[5]);
    total += ls.check({box(5, 5, 5, 6, 6, 6)}, where);
    if (::testing::Test::HasFailure()) return;
  }
  EXPECT_GT(total, 110u * 150u);
  // Points only: no size to take a column edge from.
  Lockstep points(v);
  for (ProxyId id = 0; id < 300; ++id) {
    const Vec3 p(double(id % 4), double(id % 3), double(id % 5));  // 60 spots
    points.insert(id, Aabb(p, p));
  }
  EXPECT_GT(points.check({box(1, 1, 1, 2, 2, 2)}, "points"), 300u);
}

TEST(BroadPhase, NamesRoundTrip) {
  for (BroadPhaseKind k :
       {BroadPhaseKind::BruteForce, BroadPhaseKind::SweepAndPrune, BroadPhaseKind::HashedGrid,
        BroadPhaseKind::HierarchicalGrid, BroadPhaseKind::DynamicAabbTree}) {
    const auto parsed = dm::parseBroadPhaseKind(dm::broadPhaseName(k));
    ASSERT_TRUE(parsed.ok()) << dm::broadPhaseName(k);
    EXPECT_EQ(*parsed, k);
    EXPECT_EQ(dm::makeBroadPhase(k)->kind(), k);
  }
  const auto bad = dm::parseBroadPhaseKind("octree");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().message().find("sweep-and-prune"), std::string::npos) << bad.error().message();
}

}  // namespace
