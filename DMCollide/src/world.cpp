// The collision world: object storage with generational ids, pair records
// merged from the broad phase each step, the filtered (parallel) narrow
// phase and deterministic event dispatch; see dm/collide/world.hpp.
#include <dm/collide/world.hpp>
#include <dm/core/assert.hpp>
#include <dm/core/tasks.hpp>

#include <algorithm>
#include <chrono>
#include <string>
#include <utility>

namespace dm {

namespace {

// Where an object's box lives.
enum BoxClass : std::uint8_t {
  kInBroadPhase,  // finite, non-empty: a broad-phase proxy
  kUnbounded,     // an infinite coordinate (planes): tested against every box by the world
  kInvalid,       // NaN or empty: overlaps nothing
  kNowhere,       // not placed yet, or removed
};

BoxClass classify(const Aabb& box) noexcept {
  if (box.min().hasNaN() || box.max().hasNaN()) return kInvalid;
  if ((box.min().array() > box.max().array()).any()) return kInvalid;
  if (!box.min().allFinite() || !box.max().allFinite()) return kUnbounded;
  return kInBroadPhase;
}

std::string describe(ObjectId id) {
  return "object " + std::to_string(id.index) + " (generation " + std::to_string(id.generation) + ")";
}

double secondsSince(std::chrono::steady_clock::time_point t0) noexcept {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

/// Marks the world as inside a callback for the guard's lifetime (restored
/// on exit, exceptions included).
class CollisionWorld::DispatchGuard {
 public:
  explicit DispatchGuard(CollisionWorld& world) noexcept : world_(world) { world_.dispatching_ = true; }
  ~DispatchGuard() { world_.dispatching_ = false; }
  DispatchGuard(const DispatchGuard&) = delete;
  DispatchGuard& operator=(const DispatchGuard&) = delete;

 private:
  CollisionWorld& world_;
};

CollisionWorld::CollisionWorld(const WorldOptions& options)
    : options_(options), broadPhase_(makeBroadPhase(options.broadPhase, options.broadPhaseOptions)) {}

CollisionWorld::~CollisionWorld() = default;
CollisionWorld::CollisionWorld(CollisionWorld&&) noexcept = default;
CollisionWorld& CollisionWorld::operator=(CollisionWorld&&) noexcept = default;

// ------------------------------------------------------------------ objects

const CollisionWorld::Object* CollisionWorld::find(ObjectId id) const noexcept {
  if (id.index >= objects_.size()) return nullptr;
  const Object& o = objects_[id.index];
  return o.shape && o.generation == id.generation ? &o : nullptr;
}

CollisionWorld::Object* CollisionWorld::find(ObjectId id) noexcept {
  return const_cast<Object*>(std::as_const(*this).find(id));
}

bool CollisionWorld::contains(ObjectId id) const noexcept { return find(id) != nullptr; }

const ShapePtr& CollisionWorld::shape(ObjectId id) const noexcept {
  static const ShapePtr kNull;
  const Object* o = find(id);
  return o ? o->shape : kNull;
}

const Isometry3& CollisionWorld::pose(ObjectId id) const noexcept {
  static const Isometry3 kIdentity = Isometry3::Identity();
  const Object* o = find(id);
  return o ? o->pose : kIdentity;
}

const Aabb& CollisionWorld::aabb(ObjectId id) const noexcept {
  static const Aabb kEmpty;
  const Object* o = find(id);
  return o ? o->box : kEmpty;
}

std::uint64_t CollisionWorld::tags(ObjectId id) const noexcept {
  const Object* o = find(id);
  return o ? o->tags : 0;
}

void* CollisionWorld::user(ObjectId id) const noexcept {
  const Object* o = find(id);
  return o ? o->user : nullptr;
}

ObjectId CollisionWorld::idAt(std::uint32_t i) const noexcept {
  if (i >= objects_.size() || !objects_[i].shape) return {};
  return {i, objects_[i].generation};
}

void CollisionWorld::placeBox(std::uint32_t i, bool fresh) {
  Object& o = objects_[i];
  const auto before = fresh ? kNowhere : static_cast<BoxClass>(o.boxClass);
  o.box = o.shape->aabb(o.pose);
  const BoxClass after = classify(o.box);
  if (before == kInBroadPhase && after == kInBroadPhase) {
    broadPhase_->update(i, o.box);
  } else {
    if (before == kInBroadPhase) broadPhase_->remove(i);
    if (before == kUnbounded && after != kUnbounded)
      unbounded_.erase(std::lower_bound(unbounded_.begin(), unbounded_.end(), i));
    if (after == kInBroadPhase) broadPhase_->insert(i, o.box);
    if (after == kUnbounded && before != kUnbounded)
      unbounded_.insert(std::lower_bound(unbounded_.begin(), unbounded_.end(), i), i);
  }
  o.boxClass = after;
}

Result<ObjectId> CollisionWorld::add(ShapePtr shape, const Isometry3& pose, const ObjectDesc& desc) {
  if (!shape)
    return fail(ErrorCode::InvalidArgument, "shape is null", "CollisionWorld::add",
                "pass a shape made with std::make_shared<dm::Sphere>(...) or a create() function");
  if (!pose.matrix().allFinite())
    return fail(ErrorCode::InvalidArgument, "pose has a non-finite entry", "CollisionWorld::add",
                "check the pose source for NaN or infinite values");
  if (dispatching_)
    return fail(ErrorCode::Busy, "add() called from a pair callback", "CollisionWorld::add",
                "collect the objects in the callback and add them after step() returns");
  std::uint32_t i = 0;
  if (!free_.empty()) {
    i = free_.back();
    free_.pop_back();
  } else {
    if (objects_.size() >= ObjectId::kInvalidIndex)
      return fail(ErrorCode::Busy, "the world holds 2^32 - 1 objects", "CollisionWorld::add",
                  "remove objects first");
    i = static_cast<std::uint32_t>(objects_.size());
    objects_.emplace_back();
  }
  Object& o = objects_[i];
  o.shape = std::move(shape);
  o.pose = pose;
  o.tags = desc.tags;
  o.user = desc.user;
  placeBox(i, true);
  ++live_;
  return ObjectId{i, o.generation};
}

Status CollisionWorld::remove(ObjectId id) {
  Object* o = find(id);
  if (!o)
    return fail(ErrorCode::NotFound, describe(id) + " is not in the world", "CollisionWorld::remove",
                "the object was removed before or never added; check contains()");
  if (dispatching_)
    return fail(ErrorCode::Busy, "remove() called from a pair callback", "CollisionWorld::remove",
                "collect the ids in the callback and remove them after step() returns");
  const std::uint32_t i = id.index;
  goodbyes_.clear();
  for (const PairRecord& r : pairs_)
    if (r.touching && (r.key.a == i || r.key.b == i)) goodbyes_.push_back({r.key, r.a, r.b});
  removedGoodbyes_ += goodbyes_.size();
  if (!goodbyes_.empty() && !callbacks_.empty()) {
    DispatchGuard guard(*this);
    for (const PendingEvent& e : goodbyes_) dispatch(PairEventKind::Goodbye, e.a, e.b, {});
  }
  goodbyes_.clear();
  removedPairs_ += std::erase_if(pairs_, [i](const PairRecord& r) { return r.key.a == i || r.key.b == i; });

  o = &objects_[i];  // callbacks may have moved nothing, but re-read after them anyway
  if (o->boxClass == kInBroadPhase) broadPhase_->remove(i);
  if (o->boxClass == kUnbounded) unbounded_.erase(std::lower_bound(unbounded_.begin(), unbounded_.end(), i));
  o->boxClass = kNowhere;
  o->shape.reset();
  o->user = nullptr;
  o->tags = 0;
  ++o->generation;
  free_.push_back(i);
  --live_;
  return ok();
}

Status CollisionWorld::setPose(ObjectId id, const Isometry3& pose) {
  Object* o = find(id);
  if (!o)
    return fail(ErrorCode::NotFound, describe(id) + " is not in the world", "CollisionWorld::setPose",
                "the object was removed; check contains()");
  if (!pose.matrix().allFinite())
    return fail(ErrorCode::InvalidArgument, "pose has a non-finite entry", "CollisionWorld::setPose",
                "check the pose source for NaN or infinite values");
  o->pose = pose;
  placeBox(id.index, false);
  return ok();
}

Status CollisionWorld::setShape(ObjectId id, ShapePtr shape) {
  Object* o = find(id);
  if (!o)
    return fail(ErrorCode::NotFound, describe(id) + " is not in the world", "CollisionWorld::setShape",
                "the object was removed; check contains()");
  if (!shape)
    return fail(ErrorCode::InvalidArgument, "shape is null", "CollisionWorld::setShape",
                "pass a shape made with std::make_shared or a create() function");
  if (dispatching_)
    return fail(ErrorCode::Busy, "setShape() called from a pair callback", "CollisionWorld::setShape",
                "change the shape after step() returns");
  o->shape = std::move(shape);
  for (PairRecord& r : pairs_)
    if (r.key.a == id.index || r.key.b == id.index) r.cache = PairCache{};
  placeBox(id.index, false);
  return ok();
}

Status CollisionWorld::setTags(ObjectId id, std::uint64_t tags) {
  Object* o = find(id);
  if (!o)
    return fail(ErrorCode::NotFound, describe(id) + " is not in the world", "CollisionWorld::setTags",
                "the object was removed; check contains()");
  o->tags = tags;
  return ok();
}

Status CollisionWorld::setUser(ObjectId id, void* user) {
  Object* o = find(id);
  if (!o)
    return fail(ErrorCode::NotFound, describe(id) + " is not in the world", "CollisionWorld::setUser",
                "the object was removed; check contains()");
  o->user = user;
  return ok();
}

// ---------------------------------------------------- broad phase, options

void CollisionWorld::setBroadPhase(BroadPhaseKind kind, const BroadPhaseOptions& options) {
  DM_DEMAND(!dispatching_, "CollisionWorld::setBroadPhase called from a pair callback");
  const Status s = setBroadPhase(makeBroadPhase(kind, options));
  DM_DEMAND(s.ok(), "makeBroadPhase returned null");
  options_.broadPhase = kind;
  options_.broadPhaseOptions = options;
}

Status CollisionWorld::setBroadPhase(std::unique_ptr<BroadPhase> broadPhase) {
  if (!broadPhase)
    return fail(ErrorCode::InvalidArgument, "broad phase is null", "CollisionWorld::setBroadPhase",
                "pass an object made with dm::makeBroadPhase() or a BroadPhase subclass");
  if (dispatching_)
    return fail(ErrorCode::Busy, "setBroadPhase() called from a pair callback",
                "CollisionWorld::setBroadPhase", "swap the broad phase after step() returns");
  broadPhase->clear();
  for (std::uint32_t i = 0; i < objects_.size(); ++i)
    if (objects_[i].shape && objects_[i].boxClass == kInBroadPhase) broadPhase->insert(i, objects_[i].box);
  broadPhase_ = std::move(broadPhase);
  options_.broadPhase = broadPhase_->kind();
  return ok();
}

BroadPhaseKind CollisionWorld::broadPhaseKind() const noexcept { return broadPhase_->kind(); }

void CollisionWorld::setOptions(const WorldOptions& options) {
  DM_DEMAND(!dispatching_, "CollisionWorld::setOptions called from a pair callback");
  options_ = options;
  setBroadPhase(options.broadPhase, options.broadPhaseOptions);
}

void CollisionWorld::setPairFilter(PairFilter filter) {
  DM_DEMAND(!dispatching_, "CollisionWorld::setPairFilter called from a pair callback");
  pairFilter_ = std::move(filter);
}

// ---------------------------------------------------------------- filters

bool CollisionWorld::accepts(const ObjectFilter& f, ObjectId id) const {
  const Object* o = find(id);
  if (!o || !f.types.contains(o->shape->type())) return false;
  if ((o->tags & f.tagsAll) != f.tagsAll) return false;
  if (f.tagsAny != 0 && (o->tags & f.tagsAny) == 0) return false;
  if ((o->tags & f.tagsNone) != 0) return false;
  return !f.predicate || f.predicate(*this, id);
}

bool CollisionWorld::accepts(const PairFilter& f, ObjectId a, ObjectId b, bool* swapped) const {
  bool swap = false;
  bool pass = false;
  switch (f.mode) {
    case PairFilter::Mode::Both:
      pass = accepts(f.first, a) && accepts(f.first, b);
      break;
    case PairFilter::Mode::Either:
      pass = accepts(f.first, a) || accepts(f.first, b);
      break;
    case PairFilter::Mode::Between:
      if (accepts(f.first, a) && accepts(f.second, b)) {
        pass = true;
      } else if (accepts(f.first, b) && accepts(f.second, a)) {
        pass = true;
        swap = true;
      }
      break;
  }
  if (pass && f.predicate) pass = swap ? f.predicate(*this, b, a) : f.predicate(*this, a, b);
  if (swapped) *swapped = swap;
  return pass;
}

// -------------------------------------------------------------- callbacks

CallbackId CollisionWorld::addCallback(PairEventKind kind, PairFilter filter, PairCallback fn) {
  DM_DEMAND(!dispatching_, "CollisionWorld::addCallback called from a pair callback");
  const CallbackId id = nextCallback_++;
  callbacks_.push_back({id, kind, std::move(filter), std::move(fn)});
  return id;
}

bool CollisionWorld::removeCallback(CallbackId id) {
  DM_DEMAND(!dispatching_, "CollisionWorld::removeCallback called from a pair callback");
  return std::erase_if(callbacks_, [id](const CallbackEntry& c) { return c.id == id; }) > 0;
}

void CollisionWorld::dispatch(PairEventKind kind, ObjectId a, ObjectId b,
                              std::span<const ContactPoint> contacts) {
  for (const CallbackEntry& cb : callbacks_) {
    if (cb.kind != kind || !cb.fn) continue;
    bool swapped = false;
    if (!accepts(cb.filter, a, b, &swapped)) continue;
    PairEvent event{kind, swapped ? b : a, swapped ? a : b, contacts};
    if (swapped && !contacts.empty()) {
      // Normals point from the event's a to its b.
      flipped_.assign(contacts.begin(), contacts.end());
      for (ContactPoint& c : flipped_) c.normal = -c.normal;
      event.contacts = flipped_;
    }
    cb.fn(event);
  }
}

// ------------------------------------------------------------------- step

void CollisionWorld::collectPairs() {
  broadPhase_->overlappingPairs(candidates_);
  DM_ASSERT(std::is_sorted(candidates_.begin(), candidates_.end()), "broad phase pairs must be sorted");
  if (!unbounded_.empty()) {
    const auto n = static_cast<std::uint32_t>(objects_.size());
    for (const std::uint32_t u : unbounded_) {
      const Aabb& box = objects_[u].box;
      for (std::uint32_t j = 0; j < n; ++j) {
        const Object& o = objects_[j];
        if (j == u || !o.shape || o.boxClass == kInvalid) continue;
        if (o.boxClass == kUnbounded && j < u) continue;  // listed when u was j
        if (boxesOverlap(box, o.box)) candidates_.push_back({std::min(u, j), std::max(u, j)});
      }
    }
    std::sort(candidates_.begin(), candidates_.end());
  }
  candidates_.erase(std::unique(candidates_.begin(), candidates_.end()), candidates_.end());
}

void CollisionWorld::mergePairs() {
  // Both lists are sorted: one pass keeps the records whose boxes still
  // overlap, ends the others and begins records (fresh caches) for new pairs.
  next_.clear();
  std::size_t i = 0;
  std::size_t j = 0;
  while (i < pairs_.size() || j < candidates_.size()) {
    if (j == candidates_.size() || (i < pairs_.size() && pairs_[i].key < candidates_[j])) {
      const PairRecord& r = pairs_[i++];
      if (r.touching) goodbyes_.push_back({r.key, r.a, r.b});
      ++stats_.pairsDestroyed;
    } else if (i == pairs_.size() || candidates_[j] < pairs_[i].key) {
      const ProxyPair k = candidates_[j++];
      PairRecord r;
      r.key = k;
      r.a = {k.a, objects_[k.a].generation};
      r.b = {k.b, objects_[k.b].generation};
      r.created = step_;
      next_.push_back(r);
      ++stats_.pairsCreated;
    } else {
      next_.push_back(pairs_[i++]);
      ++j;
    }
  }
  pairs_.swap(next_);
}

void CollisionWorld::selectWork() {
  work_.clear();
  bool contactCallbacks = false;
  for (const CallbackEntry& cb : callbacks_) contactCallbacks |= cb.kind == PairEventKind::Contact;
  const ColliderTable& table = ColliderTable::global();
  for (std::uint32_t k = 0; k < pairs_.size(); ++k) {
    PairRecord& r = pairs_[k];
    r.hit = false;
    r.wantContacts = false;
    if (!accepts(pairFilter_, r.a, r.b)) {
      ++stats_.filteredOut;
      continue;
    }
    bool swapped = false;
    if (!table.find(*objects_[r.key.a].shape, *objects_[r.key.b].shape, swapped)) {
      ++stats_.unsupported;
      continue;
    }
    r.wantContacts = options_.contactsForAllPairs;
    if (!r.wantContacts && contactCallbacks)
      for (const CallbackEntry& cb : callbacks_)
        if (cb.kind == PairEventKind::Contact && accepts(cb.filter, r.a, r.b)) {
          r.wantContacts = true;
          break;
        }
    work_.push_back(k);
  }
}

void CollisionWorld::runNarrowPhase() {
  if (results_.size() < work_.size()) results_.resize(work_.size());
  CollisionRequest request = options_.contactRequest;
  request.maxContacts = std::max(request.maxContacts, 1);
  // Each work item touches only its own pair record and result slot; shapes
  // and poses are read-only here.
  auto body = [&](std::size_t begin, std::size_t end) {
    for (std::size_t w = begin; w < end; ++w) {
      PairRecord& r = pairs_[work_[w]];
      const Object& a = objects_[r.key.a];
      const Object& b = objects_[r.key.b];
      CollisionResult& res = results_[w];
      res.clear();
      r.hit = intersect(*a.shape, a.pose, *b.shape, b.pose, &r.cache);
      if (r.hit && r.wantContacts) collide(*a.shape, a.pose, *b.shape, b.pose, request, res, &r.cache);
    }
  };
  stats_.parallel = options_.parallel && work_.size() >= std::max<std::size_t>(options_.parallelMinPairs, 2);
  if (stats_.parallel)
    parallelFor(0, work_.size(), std::max<std::size_t>(options_.parallelGrain, 1), body);
  else
    body(0, work_.size());
}

void CollisionWorld::gatherResults() {
  touching_.clear();
  contacts_.clear();
  std::size_t w = 0;
  for (std::uint32_t k = 0; k < pairs_.size(); ++k) {
    PairRecord& r = pairs_[k];
    bool now = false;
    const CollisionResult* res = nullptr;
    if (w < work_.size() && work_[w] == k) {
      now = r.hit;
      res = &results_[w++];
    }
    if (now && !r.touching) hellos_.push_back({r.key, r.a, r.b});
    if (!now && r.touching) goodbyes_.push_back({r.key, r.a, r.b});
    r.touching = now;
    if (!now) continue;
    TouchingPair t{r.a, r.b, static_cast<std::uint32_t>(contacts_.size()), 0};
    if (r.wantContacts) {
      ++stats_.contactQueries;
      contacts_.insert(contacts_.end(), res->contacts.begin(), res->contacts.end());
      t.contactCount = static_cast<std::uint32_t>(res->contacts.size());
    }
    touching_.push_back(t);
  }
  // Goodbyes come from two sorted passes (ended records, separated pairs).
  std::sort(goodbyes_.begin(), goodbyes_.end());
}

void CollisionWorld::dispatchStep() {
  if (callbacks_.empty()) return;
  bool has[4] = {false, false, false, false};
  for (const CallbackEntry& cb : callbacks_) has[static_cast<int>(cb.kind)] = true;
  DispatchGuard guard(*this);
  if (has[static_cast<int>(PairEventKind::Goodbye)])
    for (const PendingEvent& e : goodbyes_) dispatch(PairEventKind::Goodbye, e.a, e.b, {});
  if (has[static_cast<int>(PairEventKind::Hello)])
    for (const PendingEvent& e : hellos_) dispatch(PairEventKind::Hello, e.a, e.b, {});
  if (has[static_cast<int>(PairEventKind::Touching)])
    for (const TouchingPair& t : touching_) dispatch(PairEventKind::Touching, t.a, t.b, {});
  if (has[static_cast<int>(PairEventKind::Contact)])
    for (const TouchingPair& t : touching_)
      dispatch(PairEventKind::Contact, t.a, t.b,
               std::span<const ContactPoint>(contacts_.data() + t.firstContact, t.contactCount));
}

void CollisionWorld::step() {
  DM_DEMAND(!dispatching_, "CollisionWorld::step called from a pair callback");
  using Clock = std::chrono::steady_clock;
  const auto t0 = Clock::now();
  ++step_;
  stats_ = WorldStats{};
  stats_.step = step_;
  stats_.objects = live_;
  stats_.goodbyes = removedGoodbyes_;
  stats_.pairsDestroyed = removedPairs_;
  removedGoodbyes_ = 0;
  removedPairs_ = 0;
  goodbyes_.clear();
  hellos_.clear();

  collectPairs();
  mergePairs();
  selectWork();
  stats_.broadPhasePairs = pairs_.size();
  stats_.narrowPhaseTests = work_.size();
  const auto t1 = Clock::now();
  stats_.broadPhaseSeconds = std::chrono::duration<double>(t1 - t0).count();

  runNarrowPhase();
  const auto t2 = Clock::now();
  stats_.narrowPhaseSeconds = std::chrono::duration<double>(t2 - t1).count();

  gatherResults();
  stats_.touchingPairs = touching_.size();
  stats_.contacts = contacts_.size();
  stats_.hellos = hellos_.size();
  stats_.goodbyes += goodbyes_.size();
  dispatchStep();
  stats_.dispatchSeconds = secondsSince(t2);
  stats_.totalSeconds = secondsSince(t0);
}

std::optional<PairInfo> CollisionWorld::pair(ObjectId a, ObjectId b) const {
  if (!contains(a) || !contains(b) || a.index == b.index) return std::nullopt;
  if (b.index < a.index) std::swap(a, b);
  const ProxyPair key{a.index, b.index};
  const auto it = std::lower_bound(pairs_.begin(), pairs_.end(), key,
                                   [](const PairRecord& r, const ProxyPair& k) { return r.key < k; });
  if (it == pairs_.end() || it->key != key || it->a != a || it->b != b) return std::nullopt;
  return PairInfo{it->a, it->b, it->created, it->touching, it->cache};
}

}  // namespace dm
