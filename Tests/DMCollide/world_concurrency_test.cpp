// Concurrency tests of dm/collide/world.hpp (run under ThreadSanitizer in
// CI): the parallel narrow phase gives exactly the serial run's pairs,
// contacts and events, step after step, and worlds sharing shapes step
// concurrently on different threads.
//
// Under ThreadSanitizer the narrow phase stays on the calling thread: the
// system oneTBB is not instrumented, so TSan cannot see its task
// synchronisation and reports races inside oneTBB's own templates
// (blocked_range, start_for) for any parallel loop. The serial-vs-parallel
// equality is checked by the plain run of this binary; the TSan run checks
// the worlds on separate std::threads, whose synchronisation it sees.
#include <dm/collide/shapes.hpp>
#include <dm/collide/world.hpp>

#include <gtest/gtest.h>

#include <memory>
#include <random>
#include <thread>
#include <tuple>
#include <utility>
#include <vector>

namespace {

#if defined(__SANITIZE_THREAD__)
constexpr bool kThreadSanitizer = true;
#elif defined(__has_feature)
#if __has_feature(thread_sanitizer)
constexpr bool kThreadSanitizer = true;
#else
constexpr bool kThreadSanitizer = false;
#endif
#else
constexpr bool kThreadSanitizer = false;
#endif

using dm::CollisionWorld;
using dm::Isometry3;
using dm::ObjectId;
using dm::PairEvent;
using dm::PairEventKind;
using dm::Vec3;

/// Everything a step hands out, for comparing two runs.
struct Trace {
  std::vector<std::pair<ObjectId, ObjectId>> touching;
  std::vector<dm::ContactPoint> contacts;
  std::vector<std::tuple<PairEventKind, ObjectId, ObjectId, std::size_t>> events;  // kind, a, b, contacts
};

bool sameContacts(const std::vector<dm::ContactPoint>& x, const std::vector<dm::ContactPoint>& y) {
  if (x.size() != y.size()) return false;
  for (std::size_t i = 0; i < x.size(); ++i)
    if (x[i].position != y[i].position || x[i].normal != y[i].normal || x[i].depth != y[i].depth)
      return false;
  return true;
}

/// A world of `n` mixed shapes (shared `shapes`) in a 0.6 m cube whose
/// objects drift by a seeded walk; `trace` collects every step's output.
class Rig {
 public:
  Rig(const std::vector<dm::ShapePtr>& shapes, bool parallel, std::uint64_t seed)
      : world_({.broadPhase = dm::BroadPhaseKind::DynamicAabbTree,
                .parallel = parallel,
                .parallelMinPairs = 1,
                .parallelGrain = 4,
                .contactsForAllPairs = true}),
        rng_(seed) {
    std::uniform_real_distribution<double> u(0.0, 0.6);
    for (const dm::ShapePtr& s : shapes) {
      Isometry3 p = Isometry3::Identity();
      p.linear() = Eigen::AngleAxisd(u(rng_) * 10, Vec3(u(rng_), u(rng_), 1).normalized()).toRotationMatrix();
      p.translation() = Vec3(u(rng_), u(rng_), u(rng_));
      poses_.push_back(p);
      ids_.push_back(*world_.add(s, p, {.tags = ids_.size() % 2 ? 1u : 2u}));
    }
    for (PairEventKind k : {PairEventKind::Hello, PairEventKind::Goodbye, PairEventKind::Contact})
      world_.addCallback(
          k, dm::PairFilter::between(dm::ObjectFilter::withTags(1), {}), [this](const PairEvent& e) {
            trace_.events.emplace_back(e.kind, e.a, e.b, e.contacts.size());
            trace_.contacts.insert(trace_.contacts.end(), e.contacts.begin(), e.contacts.end());
          });
  }

  /// Moves every object by the walk and steps; returns the step's trace.
  Trace step(bool move) {
    trace_ = {};
    if (move) {
      std::uniform_real_distribution<double> d(-0.01, 0.01);
      for (std::size_t i = 0; i < ids_.size(); ++i) {
        poses_[i].translation() += Vec3(d(rng_), d(rng_), d(rng_));
        EXPECT_TRUE(world_.setPose(ids_[i], poses_[i]).ok());
      }
    }
    world_.step();
    for (const dm::TouchingPair& t : world_.touchingPairs()) trace_.touching.emplace_back(t.a, t.b);
    trace_.contacts.insert(trace_.contacts.end(), world_.contacts().begin(), world_.contacts().end());
    return trace_;
  }

  const CollisionWorld& world() const { return world_; }

 private:
  CollisionWorld world_;
  std::mt19937_64 rng_;
  std::vector<Isometry3> poses_;
  std::vector<ObjectId> ids_;
  Trace trace_;
};

std::vector<dm::ShapePtr> mixedShapes(std::size_t n) {
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> size(0.01, 0.05);
  std::vector<dm::ShapePtr> shapes;
  for (std::size_t i = 0; i < n; ++i) {
    if (i % 4 == 0) shapes.push_back(std::make_shared<dm::Sphere>(size(rng)));
    if (i % 4 == 1) shapes.push_back(std::make_shared<dm::Box>(Vec3(size(rng), size(rng), size(rng))));
    if (i % 4 == 2) shapes.push_back(std::make_shared<dm::Capsule>(size(rng), size(rng)));
    if (i % 4 == 3) shapes.push_back(std::make_shared<dm::Cylinder>(size(rng), size(rng)));  // GJK pairs
  }
  return shapes;
}

void expectSame(const Trace& parallel, const Trace& serial, int step) {
  EXPECT_EQ(parallel.touching, serial.touching) << "step " << step;
  EXPECT_EQ(parallel.events, serial.events) << "step " << step;
  EXPECT_TRUE(sameContacts(parallel.contacts, serial.contacts)) << "step " << step;
}

TEST(CollisionWorldConcurrency, ParallelNarrowPhaseEqualsSerial) {
  if (kThreadSanitizer) GTEST_SKIP() << "oneTBB is not instrumented here (see the file comment)";
  const auto shapes = mixedShapes(400);
  Rig parallel(shapes, true, 5), serial(shapes, false, 5);
  std::size_t touching = 0;
  for (int s = 0; s < 12; ++s) {
    const Trace p = parallel.step(true), q = serial.step(true);
    expectSame(p, q, s);
    touching += q.touching.size();
    EXPECT_TRUE(parallel.world().stats().parallel || parallel.world().stats().narrowPhaseTests < 2);
    EXPECT_FALSE(serial.world().stats().parallel);
  }
  EXPECT_GT(touching, 12u * 20u) << "the scene must have contacts to compare";
  // Standing still: repeated steps give the same answer, and no events.
  const Trace first = parallel.step(false);
  for (int s = 0; s < 3; ++s) {
    const Trace again = parallel.step(false);
    EXPECT_EQ(again.touching, first.touching);
    EXPECT_EQ(parallel.world().stats().hellos + parallel.world().stats().goodbyes, 0u);
  }
}

TEST(CollisionWorldConcurrency, WorldsSharingShapesStepOnSeparateThreads) {
  const auto shapes = mixedShapes(240);
  Rig a(shapes, !kThreadSanitizer, 8), b(shapes, !kThreadSanitizer, 9);
  Rig a2(shapes, false, 8), b2(shapes, false, 9);
  std::vector<Trace> ta, tb;
  std::thread ra([&] {
    for (int s = 0; s < 6; ++s) ta.push_back(a.step(true));
  });
  std::thread rb([&] {
    for (int s = 0; s < 6; ++s) tb.push_back(b.step(true));
  });
  ra.join();
  rb.join();
  for (int s = 0; s < 6; ++s) {
    expectSame(ta[s], a2.step(true), s);
    expectSame(tb[s], b2.step(true), s);
  }
}

}  // namespace
