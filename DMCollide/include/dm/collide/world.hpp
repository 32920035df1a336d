// dm/collide/world.hpp — the collision world: objects, a swappable broad
// phase, filtered narrow phase in parallel, and pair events.
//
// An object is a shared shape placed at a pose, with a 64-bit tag mask and
// an optional user pointer. step() runs the pipeline
//
//   broad phase (box pairs) → pair records (one PairCache each) →
//   world pair filter → narrow phase in parallel (dm::intersect, and
//   dm::collide where contacts are wanted) → events on the calling thread
//
// and leaves the touching pairs, their contacts and statistics for callers
// who poll. A *pair record* lives exactly as long as the two objects' boxes
// overlap: it is created when the broad phase first reports the pair and
// destroyed when the boxes separate (or an object is removed). It holds the
// pair's PairCache, so GJK warm starts carry from step to step.
//
// Events, each delivered to the callbacks whose PairFilter accepts the pair:
//  - Hello:    the narrow phase says "touching" and did not at the previous step;
//  - Goodbye:  a touching pair stops touching, its boxes separate, the world
//              filter starts rejecting it, or remove() deletes one object
//              (then delivered from inside remove(), while the object still
//              exists);
//  - Touching: every touching pair, every step;
//  - Contact:  every touching pair, every step, with its contacts from
//              dm::collide (WorldOptions::contactRequest).
// Within a step the kinds come in that order (goodbyes first), pairs in
// ascending (index a, index b) order, and for one pair the callbacks in
// registration order — the same order whatever the thread count.
//
// Filters (object filters by shape type, tag bits and predicate, combined
// into pair filters) run on the calling thread: the world pair filter before
// the narrow phase (rejected pairs are never tested), callback filters at
// dispatch. Shape pairs without a collider are skipped and counted in
// WorldStats::unsupported. Planes (unbounded boxes) stay out of the broad
// phase and are paired with every object whose box reaches them.
//
// Ids are generational: a removed object's index is reused by a later add()
// with a higher generation, so a stale ObjectId never names the new object.
//
// Swapping the broad phase (setBroadPhase) re-inserts every box; pair records
// and their touching state are kept, so a swap produces no events.
//
// Not real-time code: add/remove and the first steps allocate, callbacks are
// std::function. A steady state (same objects, same pairs) reuses every
// buffer and allocates nothing. One thread uses a world at a time; only the
// narrow phase inside step() runs on worker threads.
//
// @code
//   dm::CollisionWorld world;
//   auto tool = *world.add(std::make_shared<dm::Sphere>(0.005), toolPose, {.tags = kTool});
//   auto organ = *world.add(liverShape, liverPose, {.tags = kTissue});
//   world.addCallback(dm::PairEventKind::Contact,
//                     dm::PairFilter::between(dm::ObjectFilter::withTags(kTool),
//                     dm::ObjectFilter::withTags(kTissue)),
//                     [](const dm::PairEvent& e) { applyForce(e.a, e.contacts); });
//   world.step();
// @endcode
#pragma once

#include <dm/collide/broadphase.hpp>
#include <dm/collide/query.hpp>
#include <dm/collide/shapes.hpp>
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>

#include <compare>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <initializer_list>
#include <memory>
#include <optional>
#include <span>
#include <vector>

namespace dm {

/// Generational handle of an object in a CollisionWorld. `index` is dense
/// (also the broad-phase proxy id) and reused after remove(); `generation`
/// counts the reuses of that index, so a stale id compares unequal to the
/// new object's id and every accessor treats it as absent.
struct ObjectId {
  static constexpr std::uint32_t kInvalidIndex = 0xffffffffu;
  std::uint32_t index = kInvalidIndex;
  std::uint32_t generation = 0;
  /// False for a default-constructed id (it never names an object).
  bool valid() const noexcept { return index != kInvalidIndex; }
  friend bool operator==(const ObjectId&, const ObjectId&) = default;
  friend auto operator<=>(const ObjectId&, const ObjectId&) = default;
};

/// Per-object data besides shape and pose.
struct ObjectDesc {
  /// Tag bits for filters (an application's categories: tool, tissue, ...).
  std::uint64_t tags = 0;
  /// Opaque pointer for the application; the world never dereferences it.
  void* user = nullptr;
};

/// A set of shape types (one bit per ShapeType id, user types included).
class ShapeTypeSet {
 public:
  static_assert(kMaxShapeTypes <= 32, "ShapeTypeSet holds 32 shape types");
  /// The empty set.
  constexpr ShapeTypeSet() noexcept = default;
  /// Every shape type.
  static constexpr ShapeTypeSet all() noexcept { return ShapeTypeSet(0xffffffffu); }
  /// Exactly the listed types, e.g. `ShapeTypeSet::of({ShapeType::Sphere, ShapeType::Capsule})`.
  static constexpr ShapeTypeSet of(std::initializer_list<ShapeType> types) noexcept {
    ShapeTypeSet s;
    for (ShapeType t : types) s.add(t);
    return s;
  }
  /// Adds `t`; returns *this.
  constexpr ShapeTypeSet& add(ShapeType t) noexcept {
    bits_ |= 1u << static_cast<unsigned>(t);
    return *this;
  }
  /// True if `t` is in the set.
  constexpr bool contains(ShapeType t) const noexcept { return (bits_ >> static_cast<unsigned>(t)) & 1u; }
  /// The bits, bit i = ShapeType id i.
  constexpr std::uint32_t bits() const noexcept { return bits_; }

 private:
  constexpr explicit ShapeTypeSet(std::uint32_t bits) noexcept : bits_(bits) {}
  std::uint32_t bits_ = 0;
};

class CollisionWorld;

/// Which objects pass: all criteria must hold. The default passes every
/// object. Tag tests on the object's tags t: (t & tagsAll) == tagsAll,
/// tagsAny == 0 or (t & tagsAny) != 0, (t & tagsNone) == 0.
struct ObjectFilter {
  ShapeTypeSet types = ShapeTypeSet::all();  ///< shape type must be in this set
  std::uint64_t tagsAll = 0;                 ///< every one of these bits set
  std::uint64_t tagsAny = 0;                 ///< at least one of these bits set (0: no requirement)
  std::uint64_t tagsNone = 0;                ///< none of these bits set
  /// Optional user test, called last, on the thread calling step()/remove().
  std::function<bool(const CollisionWorld& world, ObjectId id)> predicate;

  /// Objects of the given shape types.
  static ObjectFilter ofTypes(ShapeTypeSet types) {
    ObjectFilter f;
    f.types = types;
    return f;
  }
  /// Objects with at least one of the bits of `anyTags`.
  static ObjectFilter withTags(std::uint64_t anyTags) {
    ObjectFilter f;
    f.tagsAny = anyTags;
    return f;
  }
  /// Objects for which `fn(world, id)` is true.
  static ObjectFilter where(std::function<bool(const CollisionWorld&, ObjectId)> fn) {
    ObjectFilter f;
    f.predicate = std::move(fn);
    return f;
  }
};

/// Which pairs pass, from object filters and an optional pair predicate.
/// The default passes every pair.
struct PairFilter {
  enum class Mode : std::uint8_t {
    Both,     ///< both objects pass `first`
    Either,   ///< at least one object passes `first`
    Between,  ///< one object passes `first` and the other `second`; events name it first
  };
  Mode mode = Mode::Both;  ///< how the object filters combine
  ObjectFilter first;      ///< the object filter (Both, Either) or the first side (Between)
  ObjectFilter second;     ///< the second side; used by Mode::Between only
  /// Optional test of the (oriented) pair, called after the object filters.
  std::function<bool(const CollisionWorld& world, ObjectId a, ObjectId b)> predicate;

  /// Pairs whose two objects pass `f`.
  static PairFilter both(ObjectFilter f) {
    PairFilter p;
    p.first = std::move(f);
    return p;
  }
  /// Pairs with at least one object passing `f`.
  static PairFilter either(ObjectFilter f) {
    PairFilter p;
    p.mode = Mode::Either;
    p.first = std::move(f);
    return p;
  }
  /// Pairs of one object passing `a` and one passing `b` (e.g. tool–tissue);
  /// events report the object passing `a` as PairEvent::a.
  static PairFilter between(ObjectFilter a, ObjectFilter b) {
    PairFilter p;
    p.mode = Mode::Between;
    p.first = std::move(a);
    p.second = std::move(b);
    return p;
  }
  /// Pairs for which `fn(world, a, b)` is true.
  static PairFilter where(std::function<bool(const CollisionWorld&, ObjectId, ObjectId)> fn) {
    PairFilter p;
    p.predicate = std::move(fn);
    return p;
  }
};

/// What happened to a pair (see the file comment).
enum class PairEventKind : std::uint8_t { Hello, Goodbye, Touching, Contact };

/// One event as a callback sees it. Objects are in ascending index order,
/// except for Mode::Between filters, which put the object passing `first`
/// in `a`. Contact normals point from a to b (flipped for a swapped pair).
struct PairEvent {
  PairEventKind kind = PairEventKind::Touching;  ///< what happened
  ObjectId a;                                    ///< first object (see above for the order)
  ObjectId b;                                    ///< second object
  /// Contact events only: the pair's contacts (world frame, m); may be empty
  /// for shapes that only graze. Valid during the call only.
  std::span<const ContactPoint> contacts;
};

/// A callback; runs on the thread calling step() (or remove() for its
/// goodbyes). It may read the world and call setPose/setTags/setUser, but
/// not add/remove objects, step, or change callbacks or options.
using PairCallback = std::function<void(const PairEvent& event)>;

/// Handle of a registered callback.
using CallbackId = std::uint32_t;

/// A pair found touching by the last step(), for callers who poll.
struct TouchingPair {
  ObjectId a;  ///< lower index
  ObjectId b;  ///< higher index
  /// Range of this pair's contacts in CollisionWorld::contacts() (normals a → b);
  /// empty unless contacts were computed for the pair.
  std::uint32_t firstContact = 0;
  std::uint32_t contactCount = 0;
};

/// Counts and times of the last step(). Removal counts (goodbyes,
/// pairsDestroyed) include the remove() calls since the previous step.
struct WorldStats {
  std::uint64_t step = 0;            ///< number of the step (first step() is 1)
  std::size_t objects = 0;           ///< live objects
  std::size_t broadPhasePairs = 0;   ///< box-overlapping pairs = live pair records
  std::size_t filteredOut = 0;       ///< pairs the world pair filter rejected
  std::size_t unsupported = 0;       ///< pairs with no collider in the ColliderTable (never touching)
  std::size_t narrowPhaseTests = 0;  ///< pairs handed to the narrow phase
  std::size_t contactQueries = 0;    ///< of those, pairs that also ran dm::collide
  std::size_t touchingPairs = 0;     ///< pairs touching after the step
  std::size_t contacts = 0;          ///< contacts computed
  std::size_t hellos = 0;            ///< Hello events (pairs starting to touch)
  std::size_t goodbyes = 0;          ///< Goodbye events
  std::size_t pairsCreated = 0;      ///< pair records (PairCache lifetimes) begun
  std::size_t pairsDestroyed = 0;    ///< pair records ended
  bool parallel = false;             ///< the narrow phase ran on worker threads
  double broadPhaseSeconds = 0.0;    ///< broad phase and pair bookkeeping
  double narrowPhaseSeconds = 0.0;   ///< narrow phase
  double dispatchSeconds = 0.0;      ///< gathering results and running callbacks
  double totalSeconds = 0.0;         ///< whole step()
};

/// What the world keeps about one box-overlapping pair.
struct PairInfo {
  ObjectId a;                       ///< lower index
  ObjectId b;                       ///< higher index
  std::uint64_t createdAtStep = 0;  ///< step() during which the record (and its cache) was created
  bool touching = false;            ///< narrow-phase result of the last step
  PairCache cache;                  ///< copy of the pair's narrow-phase cache
};

/// Configuration of a world.
struct WorldOptions {
  BroadPhaseKind broadPhase = BroadPhaseKind::DynamicAabbTree;  ///< broad phase made at construction
  BroadPhaseOptions broadPhaseOptions;                          ///< its tuning knobs
  /// Run the narrow phase with dm::parallelFor when at least
  /// `parallelMinPairs` pairs are tested; false: always on the calling thread
  /// (results are identical either way).
  bool parallel = true;
  std::size_t parallelMinPairs = 64;  ///< fewer tested pairs than this run on the calling thread
  std::size_t parallelGrain = 8;      ///< pairs per parallel chunk (0 taken as 1)
  /// Compute contacts for every touching pair (for polling through
  /// contacts()); false: only for pairs some Contact callback accepts.
  bool contactsForAllPairs = false;
  /// Request passed to dm::collide (maxContacts < 1 is taken as 1).
  CollisionRequest contactRequest;
};

/// Objects, broad phase, pair records, callbacks and the last step's
/// results. Movable, not copyable.
class CollisionWorld {
 public:
  /// An empty world with `options`' broad phase.
  /// @code
  ///   dm::CollisionWorld world({.broadPhase = dm::BroadPhaseKind::SweepAndPrune});
  /// @endcode
  explicit CollisionWorld(const WorldOptions& options = {});
  ~CollisionWorld();
  /// Moves objects, pairs and callbacks; the moved-from world may only be
  /// destroyed or assigned to.
  CollisionWorld(CollisionWorld&&) noexcept;
  /// As the move constructor.
  CollisionWorld& operator=(CollisionWorld&&) noexcept;
  CollisionWorld(const CollisionWorld&) = delete;
  CollisionWorld& operator=(const CollisionWorld&) = delete;

  // ---------------------------------------------------------------- objects

  /// Adds `shape` at `pose` (local → world). Reuses the most recently freed
  /// index (generation + 1) or appends one. Fails with InvalidArgument for a
  /// null shape or a non-finite pose, Busy from inside a callback. O(1)
  /// amortised plus the broad-phase insert. Planes (unbounded boxes) are kept
  /// out of the broad phase and paired with every object whose box reaches
  /// them, O(objects) per plane per step.
  /// @code
  ///   auto id = world.add(std::make_shared<dm::Box>(dm::Vec3(0.1, 0.1, 0.1)), pose, {.tags = 2});
  ///   if (!id) return id.error();
  /// @endcode
  Result<ObjectId> add(ShapePtr shape, const Isometry3& pose, const ObjectDesc& desc = {});
  /// Removes an object; its touching pairs get Goodbye events right away (the
  /// object is still readable in those callbacks). Fails with NotFound for a
  /// stale id, Busy from inside a callback. O(pair records).
  Status remove(ObjectId id);
  /// Moves an object (box updated in the broad phase now; pairs at the next
  /// step()). Fails with NotFound for a stale id, InvalidArgument for a
  /// non-finite pose.
  Status setPose(ObjectId id, const Isometry3& pose);
  /// Replaces an object's shape; the caches of its pairs are reset (hints
  /// into the old shape are meaningless), touching states kept. Fails like
  /// add() and with NotFound for a stale id.
  Status setShape(ObjectId id, ShapePtr shape);
  /// Replaces an object's tag bits. Fails with NotFound for a stale id.
  Status setTags(ObjectId id, std::uint64_t tags);
  /// Replaces an object's user pointer. Fails with NotFound for a stale id.
  Status setUser(ObjectId id, void* user);

  /// True if `id` names a live object (index in range, generation current).
  bool contains(ObjectId id) const noexcept;
  /// The object's shape; null for a stale id.
  const ShapePtr& shape(ObjectId id) const noexcept;
  /// The object's pose; identity for a stale id.
  const Isometry3& pose(ObjectId id) const noexcept;
  /// The object's world box (Shape::aabb at its pose); empty for a stale id.
  const Aabb& aabb(ObjectId id) const noexcept;
  /// The object's tag bits; 0 for a stale id.
  std::uint64_t tags(ObjectId id) const noexcept;
  /// The object's user pointer; null for a stale id.
  void* user(ObjectId id) const noexcept;
  /// Number of live objects.
  std::size_t size() const noexcept { return live_; }
  /// One past the highest index in use; iterate `idAt(i)` for i below it.
  std::uint32_t indexBound() const noexcept { return static_cast<std::uint32_t>(objects_.size()); }
  /// The live object at index `i`, or an invalid id when `i` is free.
  ObjectId idAt(std::uint32_t i) const noexcept;

  // ------------------------------------------------- broad phase, options

  /// Replaces the broad phase, re-inserting every box, O(n) inserts. Pair
  /// records, caches and touching states are kept: no events result.
  /// @code
  ///   world.setBroadPhase(dm::BroadPhaseKind::HashedGrid, {.cellSize = 0.02});
  /// @endcode
  void setBroadPhase(BroadPhaseKind kind, const BroadPhaseOptions& options = {});
  /// Installs a broad phase made elsewhere (a user implementation of the
  /// BroadPhase interface): it is cleared, then filled as above. Fails with
  /// InvalidArgument for null, Busy from inside a callback.
  Status setBroadPhase(std::unique_ptr<BroadPhase> broadPhase);
  /// The kind of the broad phase in use (as its kind() reports).
  BroadPhaseKind broadPhaseKind() const noexcept;
  /// Replaces the options; the broad phase is rebuilt as by setBroadPhase()
  /// (O(n), no events).
  void setOptions(const WorldOptions& options);
  /// The options in effect.
  const WorldOptions& options() const noexcept { return options_; }

  /// Sets the world pair filter: rejected pairs are never tested (and stop
  /// touching, with a Goodbye, if they were). Default: every pair.
  void setPairFilter(PairFilter filter);
  /// The world pair filter in effect.
  const PairFilter& pairFilter() const noexcept { return pairFilter_; }

  // ------------------------------------------------------------ callbacks

  /// Registers `fn` for events of `kind` on pairs `filter` accepts; returns
  /// its handle. Contact callbacks make the world compute contacts for the
  /// pairs they accept.
  /// @code
  ///   world.addCallback(dm::PairEventKind::Hello, {}, [](const dm::PairEvent& e) { beep(e.a, e.b); });
  /// @endcode
  CallbackId addCallback(PairEventKind kind, PairFilter filter, PairCallback fn);
  /// Unregisters a callback; false for an unknown handle.
  bool removeCallback(CallbackId id);

  // ----------------------------------------------------------------- step

  /// Runs broad phase, filters, narrow phase and callbacks for the current
  /// poses (see the file comment). O(broad phase + pairs × narrow phase).
  /// Must not be called from a callback. An exception thrown by a callback
  /// leaves step() with the world consistent (the step's state is committed
  /// before any callback runs) and skips the step's remaining callbacks.
  /// @code
  ///   world.setPose(tool, devicePose);
  ///   world.step();
  ///   for (const dm::TouchingPair& p : world.touchingPairs()) mark(p.a, p.b);
  /// @endcode
  void step();

  /// Pairs touching after the last step, ascending by (a.index, b.index).
  /// Ids may have been removed since (check contains()).
  std::span<const TouchingPair> touchingPairs() const noexcept { return touching_; }
  /// Contacts of the last step, indexed by TouchingPair::firstContact.
  std::span<const ContactPoint> contacts() const noexcept { return contacts_; }
  /// Statistics of the last step.
  const WorldStats& stats() const noexcept { return stats_; }
  /// Number of step() calls so far.
  std::uint64_t stepCount() const noexcept { return step_; }
  /// The pair record of two objects (either order), or nullopt when their
  /// boxes did not overlap at the last step. O(log pairs).
  std::optional<PairInfo> pair(ObjectId a, ObjectId b) const;

  /// True if the object passes `filter` (false for a stale id).
  bool accepts(const ObjectFilter& filter, ObjectId id) const;
  /// True if the pair passes `filter`; `swapped` (optional) is set when a
  /// Mode::Between filter matched `b` as first. False for stale ids.
  bool accepts(const PairFilter& filter, ObjectId a, ObjectId b, bool* swapped = nullptr) const;

 private:
  struct Object {
    ShapePtr shape;  // null while the index is free
    Isometry3 pose = Isometry3::Identity();
    Aabb box;
    std::uint64_t tags = 0;
    void* user = nullptr;
    std::uint32_t generation = 0;
    std::uint8_t boxClass = 0;  // BoxClass in world.cpp: in the broad phase, unbounded, or NaN
  };
  struct PairRecord {
    ProxyPair key;  // object indices, a < b
    ObjectId a, b;
    PairCache cache;
    std::uint64_t created = 0;
    bool touching = false;      // after the last step
    bool wantContacts = false;  // this step
    bool hit = false;           // narrow-phase answer of this step (written by one worker)
  };
  struct PendingEvent {
    ProxyPair key;
    ObjectId a, b;
    friend bool operator<(const PendingEvent& l, const PendingEvent& r) noexcept { return l.key < r.key; }
  };
  struct CallbackEntry {
    CallbackId id = 0;
    PairEventKind kind = PairEventKind::Touching;
    PairFilter filter;
    PairCallback fn;
  };
  class DispatchGuard;

  const Object* find(ObjectId id) const noexcept;
  Object* find(ObjectId id) noexcept;
  void placeBox(std::uint32_t index, bool inserted);
  void collectPairs();
  void mergePairs();
  void selectWork();
  void runNarrowPhase();
  void gatherResults();
  void dispatch(PairEventKind kind, ObjectId a, ObjectId b, std::span<const ContactPoint> contacts);
  void dispatchStep();

  WorldOptions options_;
  PairFilter pairFilter_;
  std::unique_ptr<BroadPhase> broadPhase_;
  std::vector<Object> objects_;
  std::vector<std::uint32_t> free_;       // freed indices, reused last-in first-out
  std::vector<std::uint32_t> unbounded_;  // indices with infinite boxes, ascending
  std::size_t live_ = 0;
  std::vector<CallbackEntry> callbacks_;
  CallbackId nextCallback_ = 1;
  bool dispatching_ = false;
  std::uint64_t step_ = 0;

  // Per-step buffers, reused so that a steady state does not allocate.
  std::vector<ProxyPair> candidates_;
  std::vector<PairRecord> pairs_;  // ascending by key
  std::vector<PairRecord> next_;
  std::vector<std::uint32_t> work_;       // indices into pairs_ to test, ascending
  std::vector<CollisionResult> results_;  // one slot per work item (never shrunk)
  std::vector<PendingEvent> goodbyes_;
  std::vector<PendingEvent> hellos_;
  std::vector<TouchingPair> touching_;
  std::vector<ContactPoint> contacts_;
  std::vector<ContactPoint> flipped_;  // contacts of a pair handed over swapped
  std::size_t removedGoodbyes_ = 0;    // since the last step, for the stats
  std::size_t removedPairs_ = 0;
  WorldStats stats_;
};

}  // namespace dm
