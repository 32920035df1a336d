// Tests of dm/collide/world.hpp: pair events against analytic sphere
// schedules, filters against the filter definitions enumerated by hand,
// contacts against the closed-form sphere–sphere contact, broad-phase swaps,
// id reuse, pair-record (PairCache) lifetime, and a random moving scene
// against an O(n²) loop of dm::intersect for every broad phase.
#include <dm/collide/broadphase.hpp>
#include <dm/collide/query.hpp>
#include <dm/collide/shapes.hpp>
#include <dm/collide/world.hpp>

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <memory>
#include <numbers>
#include <random>
#include <set>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include "collide_test_support.hpp"

namespace {

using dm::BroadPhaseKind;
using dm::CollisionWorld;
using dm::Isometry3;
using dm::ObjectFilter;
using dm::ObjectId;
using dm::PairEvent;
using dm::PairEventKind;
using dm::PairFilter;
using dm::ShapeType;
using dm::Vec3;

constexpr std::array<BroadPhaseKind, 5> kKinds = {
    BroadPhaseKind::BruteForce, BroadPhaseKind::SweepAndPrune, BroadPhaseKind::HashedGrid,
    BroadPhaseKind::HierarchicalGrid, BroadPhaseKind::DynamicAabbTree};

using dm::test::at;

Isometry3 randomWorldPose(std::mt19937_64& rng, double extent) {
  std::normal_distribution<double> g(0.0, 1.0);
  std::uniform_real_distribution<double> u(0.0, extent);
  Isometry3 p = Isometry3::Identity();
  p.linear() = dm::Quat(Eigen::Vector4d(g(rng), g(rng), g(rng), g(rng)).normalized()).toRotationMatrix();
  p.translation() = Vec3(u(rng), u(rng), u(rng));
  return p;
}

/// (kind, a, b, step) of one event, with ids as the callback saw them.
struct Logged {
  PairEventKind kind;
  ObjectId a, b;
  std::uint64_t step;
  friend bool operator==(const Logged&, const Logged&) = default;
};

/// Records every event of the given kinds for every pair.
void logAll(CollisionWorld& world, std::vector<Logged>& log, std::initializer_list<PairEventKind> kinds) {
  for (PairEventKind k : kinds)
    world.addCallback(k, {}, [&log, &world](const PairEvent& e) {
      log.push_back({e.kind, e.a, e.b, world.stepCount()});
    });
}

std::string kindName(BroadPhaseKind k) { return std::string(dm::broadPhaseName(k)); }

// ------------------------------------------------------------------ events

TEST(CollisionWorld, HelloAtFirstOverlapGoodbyeAtSeparation) {
  // Unit spheres; B approaches A along the xy diagonal and leaves again.
  // Spheres touch iff d ≤ 2; their boxes overlap iff d/√2 ≤ 2.
  auto ball = std::make_shared<dm::Sphere>(1.0);
  auto distanceAt = [](int s) { return s <= 12 ? 3.5 - 0.2 * s : 1.1 + 0.2 * (s - 12); };
  for (BroadPhaseKind kind : kKinds) {
    SCOPED_TRACE(kindName(kind));
    CollisionWorld world({.broadPhase = kind});
    const ObjectId a = *world.add(ball, at(0, 0, 0));
    const ObjectId b = *world.add(ball, at(10, 10, 0));
    std::vector<Logged> log;
    logAll(world, log, {PairEventKind::Hello, PairEventKind::Goodbye, PairEventKind::Touching});
    std::uint64_t created = 0;
    for (int s = 1; s <= 24; ++s) {
      const double d = distanceAt(s);
      ASSERT_TRUE(world.setPose(b, at(d / std::sqrt(2.0), d / std::sqrt(2.0), 0)).ok());
      log.clear();
      world.step();
      const bool touching = d <= 2.0, wasTouching = s > 1 && distanceAt(s - 1) <= 2.0;
      const bool boxes = d / std::sqrt(2.0) <= 2.0,
                 hadBoxes = s > 1 && distanceAt(s - 1) / std::sqrt(2.0) <= 2.0;
      std::vector<Logged> expected;
      if (!touching && wasTouching) expected.push_back({PairEventKind::Goodbye, a, b, world.stepCount()});
      if (touching && !wasTouching) expected.push_back({PairEventKind::Hello, a, b, world.stepCount()});
      if (touching) expected.push_back({PairEventKind::Touching, a, b, world.stepCount()});
      EXPECT_EQ(log, expected) << "step " << s << " d = " << d;
      EXPECT_EQ(world.touchingPairs().size(), touching ? 1u : 0u);
      EXPECT_EQ(world.stats().pairsCreated, boxes && !hadBoxes ? 1u : 0u) << "step " << s;
      EXPECT_EQ(world.stats().pairsDestroyed, !boxes && hadBoxes ? 1u : 0u) << "step " << s;
      const auto info = world.pair(b, a);
      ASSERT_EQ(info.has_value(), boxes) << "step " << s;
      if (!boxes) continue;
      if (!hadBoxes) created = world.stepCount();
      EXPECT_EQ(info->createdAtStep, created) << "the pair record lives while the boxes overlap";
      EXPECT_EQ(info->touching, touching);
      EXPECT_EQ(info->a, a);
    }
    EXPECT_EQ(created, 4u);  // d = 2.7 is the first distance below 2√2
  }
}

TEST(CollisionWorld, GoodbyeOnRemoveAndReusedIdsGetNoStaleEvents) {
  auto ball = std::make_shared<dm::Sphere>(0.5);
  for (BroadPhaseKind kind : kKinds) {
    SCOPED_TRACE(kindName(kind));
    CollisionWorld world({.broadPhase = kind});
    const ObjectId a = *world.add(ball, at(0, 0, 0));
    const ObjectId b = *world.add(ball, at(0.8, 0, 0));
    const ObjectId far = *world.add(ball, at(5, 0, 0));
    std::vector<Logged> log;
    bool removedStillReadable = false;
    world.addCallback(PairEventKind::Goodbye, {}, [&](const PairEvent& e) {
      removedStillReadable = world.contains(e.b) && world.shape(e.b) != nullptr;
    });
    logAll(world, log, {PairEventKind::Hello, PairEventKind::Goodbye});
    world.step();
    ASSERT_EQ(log, (std::vector<Logged>{{PairEventKind::Hello, a, b, 1}}));

    // remove() says goodbye at once, while the object still exists.
    log.clear();
    ASSERT_TRUE(world.remove(b).ok());
    EXPECT_EQ(log, (std::vector<Logged>{{PairEventKind::Goodbye, a, b, 1}}));
    EXPECT_TRUE(removedStillReadable);
    EXPECT_FALSE(world.contains(b));
    EXPECT_EQ(world.shape(b), nullptr);
    EXPECT_EQ(world.remove(b).error().code, dm::ErrorCode::NotFound);
    EXPECT_EQ(world.setPose(b, at(0, 0, 0)).error().code, dm::ErrorCode::NotFound);
    EXPECT_EQ(world.size(), 2u);

    // The freed index comes back with a new generation, at the same place:
    // the new object says hello; nothing about the old one leaks through.
    log.clear();
    const ObjectId c = *world.add(ball, at(0.8, 0, 0));
    EXPECT_EQ(c.index, b.index);
    EXPECT_NE(c.generation, b.generation);
    EXPECT_FALSE(world.contains(b));
    EXPECT_EQ(world.idAt(c.index), c);
    world.step();
    EXPECT_EQ(log, (std::vector<Logged>{{PairEventKind::Hello, a, c, 2}}));
    EXPECT_EQ(world.stats().goodbyes, 1u) << "the removal's goodbye is counted in the next step's stats";
    EXPECT_EQ(world.pair(a, c)->createdAtStep, 2u) << "a reused index starts a fresh pair record";
    EXPECT_FALSE(world.pair(a, b).has_value());

    // Removing an object whose box overlaps but which does not touch: no
    // event; its replacement far away: no event either.
    ASSERT_TRUE(world.setPose(far, at(0.0, 0.95, 0.95)).ok());  // boxes overlap a, spheres do not
    world.step();
    log.clear();
    ASSERT_TRUE(world.remove(far).ok());
    const ObjectId d = *world.add(ball, at(40, 0, 0));
    EXPECT_EQ(d.index, far.index);
    world.step();
    world.step();
    EXPECT_TRUE(log.empty());
    EXPECT_EQ(world.touchingPairs().size(), 1u);
  }
}

TEST(CollisionWorld, BadInputFailsWithMessages) {
  CollisionWorld world;
  auto none = world.add(nullptr, at(0, 0, 0));
  ASSERT_FALSE(none.ok());
  EXPECT_EQ(none.error().code, dm::ErrorCode::InvalidArgument);
  Isometry3 nan = at(0, 0, 0);
  nan.translation().x() = std::nan("");
  auto bad = world.add(std::make_shared<dm::Sphere>(1.0), nan);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().message().find("non-finite"), std::string::npos);
  EXPECT_EQ(world.size(), 0u);
  const ObjectId a = *world.add(std::make_shared<dm::Sphere>(1.0), at(0, 0, 0));
  const ObjectId b = *world.add(std::make_shared<dm::Sphere>(1.0), at(1, 0, 0));
  EXPECT_FALSE(world.setPose(a, nan).ok());
  EXPECT_FALSE(world.setShape(a, nullptr).ok());
  EXPECT_EQ(world.setBroadPhase(std::unique_ptr<dm::BroadPhase>()).error().code,
            dm::ErrorCode::InvalidArgument);
  dm::Status inside = dm::ok();
  world.addCallback(PairEventKind::Hello, {}, [&](const PairEvent&) {
    inside = world.remove(b);
    if (inside.ok()) return;
    auto added = world.add(std::make_shared<dm::Sphere>(1.0), at(0, 0, 0));
    if (added.ok()) inside = dm::ok();
  });
  world.step();
  ASSERT_FALSE(inside.ok());
  EXPECT_EQ(inside.error().code, dm::ErrorCode::Busy);
  EXPECT_TRUE(world.contains(b));
  EXPECT_EQ(world.size(), 2u);
}

// ----------------------------------------------------------------- filters

constexpr std::uint64_t kTool = 1, kTissue = 2, kBone = 4;

TEST(CollisionWorld, FiltersSelectExactlyTheExpectedPairs) {
  // Six mutually touching objects near the origin; every filter's pair set
  // is enumerated from the filter's definition.
  struct Spec {
    dm::ShapePtr shape;
    std::uint64_t tags;
  };
  int marker = 0;
  const std::vector<Spec> specs = {
      {std::make_shared<dm::Sphere>(0.3), kTool},
      {std::make_shared<dm::Sphere>(0.25), kTool},
      {std::make_shared<dm::Box>(Vec3(0.3, 0.2, 0.25)), kTissue},
      {std::make_shared<dm::Box>(Vec3(0.2, 0.3, 0.2)), kTissue},
      {std::make_shared<dm::Capsule>(0.2, 0.3), kBone},
      {std::make_shared<dm::Capsule>(0.15, 0.2), kTissue | kBone},
  };
  CollisionWorld world;
  std::vector<ObjectId> ids;
  for (std::size_t i = 0; i < specs.size(); ++i)
    ids.push_back(*world.add(specs[i].shape, at(0.05 * i, -0.03 * i, 0.02 * i),
                             {.tags = specs[i].tags, .user = i == 3 ? &marker : nullptr}));

  using Pair = std::pair<std::size_t, std::size_t>;  // spec indices, oriented as the event
  auto spec = [&](ObjectId id) {
    for (std::size_t i = 0; i < ids.size(); ++i)
      if (ids[i] == id) return i;
    ADD_FAILURE() << "unknown id";
    return std::size_t(0);
  };
  std::vector<std::set<Pair>> seen(6);
  std::vector<std::set<Pair>> contactsSeen(1);
  auto record = [&](int slot) {
    return [&, slot](const PairEvent& e) { seen[slot].insert({spec(e.a), spec(e.b)}); };
  };
  world.addCallback(PairEventKind::Touching,
                    PairFilter::between(ObjectFilter::withTags(kTool), ObjectFilter::withTags(kTissue)),
                    record(0));
  world.addCallback(
      PairEventKind::Touching,
      PairFilter::both(ObjectFilter::ofTypes(dm::ShapeTypeSet::of({ShapeType::Sphere, ShapeType::Capsule}))),
      record(1));
  world.addCallback(PairEventKind::Touching,
                    PairFilter::either(ObjectFilter::where(
                        [&](const CollisionWorld& w, ObjectId id) { return w.user(id) == &marker; })),
                    record(2));
  world.addCallback(PairEventKind::Touching,
                    PairFilter::where([&](const CollisionWorld&, ObjectId a, ObjectId b) {
                      return spec(a) + spec(b) == 5;
                    }),
                    record(3));
  ObjectFilter noBone;
  noBone.tagsNone = kBone;
  world.addCallback(PairEventKind::Touching, PairFilter::both(noBone), record(4));
  ObjectFilter tissueBone;
  tissueBone.tagsAll = kTissue | kBone;
  world.addCallback(PairEventKind::Hello, PairFilter::either(tissueBone), record(5));
  world.addCallback(PairEventKind::Contact,
                    PairFilter::between(ObjectFilter::withTags(kTissue), ObjectFilter::withTags(kTool)),
                    [&](const PairEvent& e) {
                      EXPECT_FALSE(e.contacts.empty());
                      contactsSeen[0].insert({spec(e.a), spec(e.b)});
                    });
  world.step();

  // Every pair touches (the test's premise), checked with dm::intersect.
  std::set<Pair> all;
  for (std::size_t i = 0; i < specs.size(); ++i)
    for (std::size_t j = i + 1; j < specs.size(); ++j) {
      ASSERT_TRUE(dm::intersect(*specs[i].shape, world.pose(ids[i]), *specs[j].shape, world.pose(ids[j])));
      all.insert({i, j});
    }
  ASSERT_EQ(world.stats().touchingPairs, all.size());

  auto expect = [&](auto&& keep, bool orientToolFirst = false, std::uint64_t firstTag = kTool) {
    std::set<Pair> out;
    for (auto [i, j] : all) {
      if (!keep(i, j)) continue;
      if (orientToolFirst && !(specs[i].tags & firstTag)) std::swap(i, j);
      out.insert({i, j});
    }
    return out;
  };
  auto has = [&](std::size_t i, std::uint64_t t) { return (specs[i].tags & t) != 0; };
  auto type = [&](std::size_t i) { return specs[i].shape->type(); };
  auto sphereOrCapsule = [&](std::size_t i) {
    return type(i) == ShapeType::Sphere || type(i) == ShapeType::Capsule;
  };
  EXPECT_EQ(seen[0], expect(
                         [&](auto i, auto j) {
                           return (has(i, kTool) && has(j, kTissue)) || (has(j, kTool) && has(i, kTissue));
                         },
                         true));
  EXPECT_EQ(seen[0].size(), 6u);
  EXPECT_EQ(seen[1], expect([&](auto i, auto j) { return sphereOrCapsule(i) && sphereOrCapsule(j); }));
  EXPECT_EQ(seen[2], expect([&](auto i, auto j) { return i == 3 || j == 3; }));
  EXPECT_EQ(seen[3], expect([&](auto i, auto j) { return i + j == 5; }));
  EXPECT_EQ(seen[4], expect([&](auto i, auto j) { return !has(i, kBone) && !has(j, kBone); }));
  EXPECT_EQ(seen[5], expect([&](auto i, auto j) { return i == 5 || j == 5; }));
  EXPECT_EQ(
      contactsSeen[0],
      expect([&](auto i,
                 auto j) { return (has(i, kTool) && has(j, kTissue)) || (has(j, kTool) && has(i, kTissue)); },
             true, kTissue));
  EXPECT_EQ(world.stats().contactQueries, 6u) << "contacts only for the pairs a contact callback wants";

  // A world filter keeps rejected pairs out of the narrow phase entirely,
  // and pairs that were touching say goodbye.
  std::set<Pair> goodbyes;
  world.addCallback(PairEventKind::Goodbye, {}, [&](const PairEvent& e) {
    goodbyes.insert({spec(e.a), spec(e.b)});
  });
  world.setPairFilter(PairFilter::both(noBone));
  for (auto& s : seen) s.clear();
  world.step();
  const std::set<Pair> kept = expect([&](auto i, auto j) { return !has(i, kBone) && !has(j, kBone); });
  EXPECT_EQ(world.stats().narrowPhaseTests, kept.size());
  EXPECT_EQ(world.stats().filteredOut, all.size() - kept.size());
  EXPECT_EQ(world.stats().broadPhasePairs, all.size());
  EXPECT_EQ(world.stats().touchingPairs, kept.size());
  EXPECT_EQ(seen[4], kept);
  EXPECT_EQ(goodbyes, expect([&](auto i, auto j) { return has(i, kBone) || has(j, kBone); }));

  // Tags change at run time.
  ASSERT_TRUE(world.setTags(ids[4], kTool).ok());
  for (auto& s : seen) s.clear();
  world.step();
  EXPECT_EQ(world.stats().filteredOut, all.size() - kept.size() - 4);
  EXPECT_TRUE(seen[0].contains({4, 2}));
}

// ---------------------------------------------------------------- contacts

TEST(CollisionWorld, ContactsMatchAnalyticSphereSphere) {
  const double ra = 0.5, rb = 0.3;
  const Vec3 ca(0.1, -0.2, 0.3), cb = ca + Vec3(0.4, 0.3, -0.2);
  CollisionWorld world({.contactsForAllPairs = true});
  const ObjectId a =
      *world.add(std::make_shared<dm::Sphere>(ra), at(ca.x(), ca.y(), ca.z()), {.tags = kTissue});
  const ObjectId b =
      *world.add(std::make_shared<dm::Sphere>(rb), at(cb.x(), cb.y(), cb.z()), {.tags = kTool});
  std::vector<PairEvent> got;
  std::vector<dm::ContactPoint> gotContacts;
  world.addCallback(PairEventKind::Contact,
                    PairFilter::between(ObjectFilter::withTags(kTool), ObjectFilter::withTags(kTissue)),
                    [&](const PairEvent& e) {
                      got.push_back(e);
                      gotContacts.assign(e.contacts.begin(), e.contacts.end());
                    });
  world.step();

  const double d = (cb - ca).norm();
  const Vec3 n = (cb - ca) / d;
  const double depth = ra + rb - d;
  const Vec3 mid = 0.5 * ((ca + ra * n) + (cb - rb * n));
  // Polled: a → b.
  ASSERT_EQ(world.touchingPairs().size(), 1u);
  ASSERT_EQ(world.touchingPairs()[0].contactCount, 1u);
  const dm::ContactPoint& c = world.contacts()[world.touchingPairs()[0].firstContact];
  EXPECT_NEAR(c.depth, depth, 1e-12);
  EXPECT_NEAR((c.normal - n).norm(), 0.0, 1e-12);
  EXPECT_NEAR((c.position - mid).norm(), 0.0, 1e-12);
  // Callback with the tool first: b → a, normal flipped.
  ASSERT_EQ(got.size(), 1u);
  EXPECT_EQ(got[0].a, b);
  EXPECT_EQ(got[0].b, a);
  ASSERT_EQ(gotContacts.size(), 1u);
  EXPECT_NEAR(gotContacts[0].depth, depth, 1e-12);
  EXPECT_NEAR((gotContacts[0].normal + n).norm(), 0.0, 1e-12);
  EXPECT_NEAR((gotContacts[0].position - mid).norm(), 0.0, 1e-12);

  // Without contact callbacks or contactsForAllPairs, only the boolean answer.
  world.setOptions({});
  got.clear();
  world.step();
  EXPECT_EQ(world.touchingPairs()[0].contactCount, 1u) << "the contact callback still wants this pair";
  CollisionWorld plain;
  (void)*plain.add(std::make_shared<dm::Sphere>(ra), at(ca.x(), ca.y(), ca.z()));
  (void)*plain.add(std::make_shared<dm::Sphere>(rb), at(cb.x(), cb.y(), cb.z()));
  plain.step();
  ASSERT_EQ(plain.touchingPairs().size(), 1u);
  EXPECT_EQ(plain.touchingPairs()[0].contactCount, 0u);
  EXPECT_EQ(plain.stats().contactQueries, 0u);
}

TEST(CollisionWorld, PlanesAreTestedAgainstEveryObject) {
  // Floor z ≤ 0 (an unbounded box) and spheres at several heights: touching
  // iff z − r ≤ 0.
  for (BroadPhaseKind kind : kKinds) {
    SCOPED_TRACE(kindName(kind));
    CollisionWorld world({.broadPhase = kind});
    const ObjectId floor = *world.add(std::make_shared<dm::Plane>(Vec3::UnitZ(), 0.0), Isometry3::Identity());
    const ObjectId wall = *world.add(std::make_shared<dm::Plane>(Vec3(1, 1, 0), 0.0), at(2, 0, 0));
    auto ball = std::make_shared<dm::Sphere>(0.1);
    std::vector<ObjectId> balls;
    const std::vector<double> heights = {-0.5, 0.05, 0.099, 0.101, 0.5, 3.0};
    for (std::size_t i = 0; i < heights.size(); ++i)
      balls.push_back(*world.add(ball, at(10.0 * i, 0.3 * i, heights[i])));
    world.step();
    std::set<std::pair<ObjectId, ObjectId>> got, want;
    for (const auto& t : world.touchingPairs()) got.insert({t.a, t.b});
    for (std::size_t i = 0; i < balls.size(); ++i) {
      if (heights[i] - 0.1 <= 0) want.insert({floor, balls[i]});
      if (dm::intersect(*world.shape(wall), world.pose(wall), *ball, world.pose(balls[i])))
        want.insert({wall, balls[i]});
    }
    if (dm::intersect(*world.shape(floor), world.pose(floor), *world.shape(wall), world.pose(wall)))
      want.insert({floor, wall});  // only if a plane–plane collider exists
    EXPECT_EQ(got, want);
    EXPECT_TRUE(want.contains({wall, balls[0]}));
    // Two planes' boxes always overlap; without a plane–plane collider the
    // pair is skipped and counted.
    const bool planePair = dm::ColliderTable::global().check(*world.shape(floor), *world.shape(wall)).ok();
    EXPECT_EQ(world.stats().unsupported, planePair ? 0u : 1u);
  }
}

// ------------------------------------------------- pair records and caches

/// A user shape whose collider counts its calls in the pair cache, to see
/// the PairCache of a pair live exactly as long as the pair's boxes overlap.
class CountingBall final : public dm::ConvexShape {
 public:
  CountingBall(ShapeType type, double r) : dm::ConvexShape(type, r) {}
  Vec3 supportCore(const Vec3&, std::uint32_t&) const noexcept override { return Vec3::Zero(); }
  dm::Aabb localAabb() const noexcept override {
    return dm::Aabb(Vec3::Constant(-margin()), Vec3::Constant(margin()));
  }
  double volume() const noexcept override { return 4.0 / 3.0 * std::numbers::pi * std::pow(margin(), 3); }
};

bool countingIntersect(const dm::Shape& a, const Isometry3& pa, const dm::Shape& b, const Isometry3& pb,
                       dm::PairCache* cache) {
  if (cache) ++cache->gjk.hintA;
  const double r =
      static_cast<const CountingBall&>(a).margin() + static_cast<const CountingBall&>(b).margin();
  return (pa.translation() - pb.translation()).norm() <= r;
}

TEST(CollisionWorld, PairCacheLivesWhileBoxesOverlap) {
  auto type = dm::registerShapeType("collision-world-test-counting-ball");
  ASSERT_TRUE(type.ok());
  dm::Collider collider;
  collider.intersect = &countingIntersect;
  collider.contacts = [](const dm::Shape&, const Isometry3&, const dm::Shape&, const Isometry3&,
                         const dm::CollisionRequest&, dm::CollisionResult&, dm::PairCache*) {};
  collider.distance = [](const dm::Shape&, const Isometry3&, const dm::Shape&, const Isometry3&,
                         dm::PairCache*) { return dm::DistanceResult{}; };
  ASSERT_TRUE(dm::ColliderTable::global().registerCollider(*type, *type, collider).ok());
  auto ball = std::make_shared<CountingBall>(*type, 1.0);
  for (BroadPhaseKind kind : kKinds) {
    SCOPED_TRACE(kindName(kind));
    CollisionWorld world({.broadPhase = kind});
    const ObjectId a = *world.add(ball, at(0, 0, 0));
    const ObjectId b = *world.add(ball, at(1.5, 0, 0));
    for (int s = 1; s <= 5; ++s) {
      world.step();
      ASSERT_TRUE(world.pair(a, b));
      EXPECT_EQ(world.pair(a, b)->cache.gjk.hintA, static_cast<std::uint32_t>(s)) << "one cache, kept";
    }
    // Boxes apart for one step: the record and its cache end.
    ASSERT_TRUE(world.setPose(b, at(2.5, 0, 0)).ok());
    world.step();
    EXPECT_FALSE(world.pair(a, b));
    EXPECT_EQ(world.stats().pairsDestroyed, 1u);
    ASSERT_TRUE(world.setPose(b, at(1.5, 0, 0)).ok());
    world.step();
    EXPECT_EQ(world.pair(a, b)->cache.gjk.hintA, 1u) << "a fresh cache";
    EXPECT_EQ(world.pair(a, b)->createdAtStep, 7u);
    // A filtered-out pair keeps its record (boxes still overlap) but is not tested.
    world.setPairFilter(PairFilter::where([](const CollisionWorld&, ObjectId, ObjectId) { return false; }));
    world.step();
    EXPECT_EQ(world.pair(a, b)->cache.gjk.hintA, 1u);
    EXPECT_EQ(world.stats().narrowPhaseTests, 0u);
    world.setPairFilter({});
    world.step();
    EXPECT_EQ(world.pair(a, b)->cache.gjk.hintA, 2u);
    // A new shape resets the cache without ending the record.
    ASSERT_TRUE(world.setShape(b, std::make_shared<CountingBall>(*type, 1.0)).ok());
    world.step();
    EXPECT_EQ(world.pair(a, b)->cache.gjk.hintA, 1u);
    EXPECT_EQ(world.pair(a, b)->createdAtStep, 7u);
  }
}

// ------------------------------------------- random scenes vs brute force

struct Scene {
  std::vector<dm::ShapePtr> shapes;
  std::vector<Isometry3> poses;
  std::vector<Vec3> velocity;
};

/// ~300 spheres, boxes and capsules in a 1 m cube (a few exactly
/// co-located), each moving at its own constant velocity.
Scene randomScene(std::uint64_t seed, std::size_t n) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> size(0.01, 0.06), v(-0.02, 0.02);
  Scene s;
  for (std::size_t i = 0; i < n; ++i) {
    switch (i % 3) {
      case 0:
        s.shapes.push_back(std::make_shared<dm::Sphere>(size(rng)));
        break;
      case 1:
        s.shapes.push_back(std::make_shared<dm::Box>(Vec3(size(rng), size(rng), size(rng))));
        break;
      default:
        s.shapes.push_back(std::make_shared<dm::Capsule>(size(rng), size(rng)));
        break;
    }
    s.poses.push_back(i < 12 && i % 2 == 0 ? at(0.5, 0.5, 0.5) : randomWorldPose(rng, 1.0));
    s.velocity.push_back(i < 12 ? Vec3::Zero() : Vec3(v(rng), v(rng), v(rng)));
  }
  return s;
}

std::set<std::pair<std::uint32_t, std::uint32_t>> bruteForceTouching(const Scene& s) {
  std::set<std::pair<std::uint32_t, std::uint32_t>> out;
  for (std::uint32_t i = 0; i < s.shapes.size(); ++i)
    for (std::uint32_t j = i + 1; j < s.shapes.size(); ++j)
      if (dm::intersect(*s.shapes[i], s.poses[i], *s.shapes[j], s.poses[j])) out.insert({i, j});
  return out;
}

std::set<std::pair<std::uint32_t, std::uint32_t>> touchingIndices(const CollisionWorld& w) {
  std::set<std::pair<std::uint32_t, std::uint32_t>> out;
  for (const auto& t : w.touchingPairs()) out.insert({t.a.index, t.b.index});
  return out;
}

TEST(CollisionWorld, RandomSceneMatchesBruteForceForEveryBroadPhase) {
  Scene scene = randomScene(7, 300);
  std::vector<std::unique_ptr<CollisionWorld>> worlds;
  for (BroadPhaseKind kind : kKinds) {
    worlds.push_back(std::make_unique<CollisionWorld>(dm::WorldOptions{.broadPhase = kind}));
    for (std::size_t i = 0; i < scene.shapes.size(); ++i)
      ASSERT_TRUE(worlds.back()->add(scene.shapes[i], scene.poses[i]).ok());
  }
  std::size_t touchingTotal = 0;
  for (int step = 0; step < 30; ++step) {
    for (std::size_t i = 0; i < scene.poses.size(); ++i) {
      scene.poses[i].translation() += scene.velocity[i];
      for (auto& w : worlds)
        ASSERT_TRUE(w->setPose(ObjectId{static_cast<std::uint32_t>(i), 0}, scene.poses[i]).ok());
    }
    const auto want = bruteForceTouching(scene);
    touchingTotal += want.size();
    for (std::size_t k = 0; k < worlds.size(); ++k) {
      worlds[k]->step();
      EXPECT_EQ(touchingIndices(*worlds[k]), want) << kindName(kKinds[k]) << " step " << step;
      EXPECT_EQ(worlds[k]->stats().touchingPairs, want.size());
    }
  }
  EXPECT_GT(touchingTotal, 30u * 15u) << "the scene must have contacts to compare";
}

TEST(CollisionWorld, BroadPhaseSwapMidRunGivesNoSpuriousEvents) {
  Scene scene = randomScene(11, 150);
  CollisionWorld reference({.broadPhase = BroadPhaseKind::BruteForce});
  CollisionWorld swapped({.broadPhase = BroadPhaseKind::DynamicAabbTree});
  std::vector<Logged> refLog, swapLog;
  for (CollisionWorld* w : {&reference, &swapped})
    for (std::size_t i = 0; i < scene.shapes.size(); ++i)
      ASSERT_TRUE(w->add(scene.shapes[i], scene.poses[i]).ok());
  logAll(reference, refLog, {PairEventKind::Hello, PairEventKind::Goodbye});
  logAll(swapped, swapLog, {PairEventKind::Hello, PairEventKind::Goodbye});
  std::size_t events = 0;
  for (int step = 0; step < 25; ++step) {
    if (step % 3 == 2) {
      const BroadPhaseKind next = kKinds[(step / 3) % kKinds.size()];
      if (step % 2)
        swapped.setBroadPhase(next, {.cellSize = step % 4 == 1 ? 0.0 : 0.15});
      else
        ASSERT_TRUE(swapped.setBroadPhase(dm::makeBroadPhase(next)).ok());  // a broad phase made elsewhere
      EXPECT_TRUE(swapLog.empty()) << "a swap alone says nothing";
    }
    for (std::size_t i = 0; i < scene.poses.size(); ++i) {
      scene.poses[i].translation() += 2.0 * scene.velocity[i];
      const ObjectId id{static_cast<std::uint32_t>(i), 0};
      ASSERT_TRUE(reference.setPose(id, scene.poses[i]).ok());
      ASSERT_TRUE(swapped.setPose(id, scene.poses[i]).ok());
    }
    reference.step();
    swapped.step();
    EXPECT_EQ(swapLog, refLog) << "step " << step;
    EXPECT_EQ(touchingIndices(swapped), touchingIndices(reference));
    EXPECT_EQ(swapped.stats().pairsCreated, reference.stats().pairsCreated);
    EXPECT_EQ(swapped.stats().pairsDestroyed, reference.stats().pairsDestroyed);
    events += refLog.size();
    refLog.clear();
    swapLog.clear();
  }
  EXPECT_GT(events, 10u) << "the scene must produce events to compare";
}

}  // namespace
