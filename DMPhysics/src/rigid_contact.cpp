// The contact pipeline of PhysicsWorld::step (see rigid_contact.hpp): broad
// phase on the state's AABBs, DMCollide narrow phase, continuous collision,
// ConstraintSolver with a ContactCache, position update of the constrained
// bodies.
#include <dm/collide/broadphase.hpp>
#include <dm/collide/toi.hpp>
#include <dm/math/float_bounds.hpp>
#include <dm/physics/rigid_contact.hpp>
#include <dm/physics/world.hpp>

#include <algorithm>
#include <bit>
#include <cmath>
#include <functional>
#include <limits>
#include <span>
#include <string>

#if defined(__SSE2__)
#include <immintrin.h>
#endif

namespace dm {

namespace {

Isometry3 posed(const Vec3& x, const Quat& q, const Isometry3& offset) {
  Isometry3 pose = Isometry3::Identity();
  pose.linear() = q.toRotationMatrix();
  pose.translation() = x;
  // Most shapes sit at the body's origin: skip the 4 × 4 product then.
  if (offset.translation().isZero(0.0) && offset.linear() == Mat3::Identity()) return pose;
  return pose * offset;
}

bool unbounded(const Aabb& box) noexcept { return !(box.min().allFinite() && box.max().allFinite()); }

// Insertion sort of v[begin, end) by `less`, for input in nearly the order
// wanted (last step's): about linear time. Gives up after `budget` element
// moves and returns false (the range is then partly sorted; sort it another
// way).
template <class T, class Less>
bool insertionSort(std::vector<T>& v, std::size_t begin, std::size_t end, Less less, std::size_t budget) {
  std::size_t moves = 0;
  for (std::size_t k = begin + 1; k < end && moves <= budget; ++k) {
    const T x = v[k];
    std::size_t j = k;
    for (; j > begin && less(x, v[j - 1]) && moves <= budget; --j, ++moves) v[j] = v[j - 1];
    v[j] = x;
  }
  return moves <= budget;
}

// RigidContactState::colliderKind, set once per step in beginContacts: the
// broad and narrow phases ask it for every body and pair.
constexpr std::uint8_t kNoCollider = 0, kBounded = 1, kUnbounded = 2;

// Half the thinnest extent of a shape, m: a body moving less than this per
// step cannot pass through anything its own thickness would hit.
double thickness(const Shape& shape) noexcept {
  switch (shape.type()) {
    case ShapeType::Sphere:
      return static_cast<const Sphere&>(shape).radius();
    case ShapeType::Capsule:
      return static_cast<const Capsule&>(shape).radius();
    case ShapeType::Box:
      return static_cast<const Box&>(shape).halfExtents().minCoeff();
    default: {
      const Aabb box = shape.localAabb();
      return unbounded(box) ? 0.0 : 0.5 * box.sizes().minCoeff();
    }
  }
}

}  // namespace

bool PhysicsWorld::collider(std::uint32_t i) const noexcept {
  return bodies_[i].shape != nullptr && materials_[i].collides;
}

bool PhysicsWorld::jointed(std::uint32_t a, std::uint32_t b) const noexcept {
  const std::uint64_t key = (std::uint64_t{std::min(a, b)} << 32) | std::max(a, b);
  return std::binary_search(jointedPairs_.begin(), jointedPairs_.end(), key);
}

bool PhysicsWorld::contactsActive() const noexcept {
  if (!joints_.empty()) return true;
  if (!contactSettings_.enabled) return false;
  std::size_t colliders = 0;
  bool dynamic = false;
  for (std::uint32_t i = 0; i < bodies_.size(); ++i) {
    if (!collider(i)) continue;
    ++colliders;
    dynamic = dynamic || model_[i].inverseMass > 0.0;
  }
  return dynamic && colliders >= 2;
}

void PhysicsWorld::reserveContacts(WorldState& state) const {
  RigidContactState& c = state.contact_;
  const std::size_t n = bodies_.size();
  c.bodies.resize(n);
  c.shapePoses.assign(n, Isometry3::Identity());
  c.colliderKind.assign(n, kNoCollider);
  for (std::size_t i = 0; i < n; ++i) {
    SolverBody& b = c.bodies[i];
    b.position = state.s_.position[i];
    b.orientation = state.s_.orientation[i];
    b.invMass = model_[i].inverseMass;
    b.invInertiaLocal = model_[i].inverseInertia;
    b.updateWorldInertia();
  }
  c.joints = joints_;
  c.constrained.assign(n, 0);
  c.asleep.assign(n, 0);
  c.sleepBlocked.assign(n, 0);
  c.stillTime.assign(n, 0.0);
  c.islandTime.assign(n, 0.0);
  c.island.resize(n);
  for (std::uint32_t i = 0; i < n; ++i) c.island[i] = i;
  c.sleeping = 0;
  std::size_t colliders = 0, planes = 0;
  for (std::uint32_t i = 0; i < n; ++i) {
    if (!collider(i)) continue;
    ++colliders;
    if (unbounded(state.bounds_[i])) ++planes;
  }
  const std::size_t pairs =
      contactSettings_.pairCapacity > 0 ? contactSettings_.pairCapacity : 4 * colliders + colliders * planes;
  const auto perPair = static_cast<std::size_t>(std::max(contactSettings_.maxContactsPerPair, 1));
  const std::size_t contacts = pairs * perPair + colliders;
  c.order.reserve(colliders);
  c.sweep.reserve(colliders);
  c.pairs.reserve(pairs);
  c.zOrder.reserve(colliders);
  c.zRank.assign(n, 0);
  c.buckets.reserve(colliders + 1);
  c.bucketed.reserve(pairs);
  c.sweepLo.reserve(colliders + 4);
  c.sweepFilter.reserve(4 * (colliders + 4));
  c.contacts.reserve(contacts);
  c.narrow.contacts.reserve(std::max<std::size_t>(16, 2 * perPair));
  c.solver.reserve(n, contacts, joints_.size());
  c.cache.reserve(contacts);
}

void PhysicsWorld::broadPhase(WorldState& state) const {
  RigidContactState& c = state.contact_;
  const std::vector<Aabb>& box = state.bounds_;
  const std::vector<std::uint8_t>& kind = c.colliderKind;
  const auto eligible = [this](std::uint32_t a, std::uint32_t b) {
    return (model_[a].inverseMass > 0.0 || model_[b].inverseMass > 0.0) && !jointed(a, b);
  };
  const auto push = [&c](std::uint32_t a, std::uint32_t b) {
    c.pairs.push_back({std::min(a, b), std::max(a, b)});
  };
  c.sweep.clear();
  c.pairs.clear();
  const auto n = static_cast<std::uint32_t>(bodies_.size());
  const auto packed = [&box](std::uint32_t i) {
    return RigidContactState::SweepBox{{box[i].min().x(), box[i].min().y(), box[i].min().z()},
                                       {box[i].max().x(), box[i].max().y(), box[i].max().z()},
                                       i};
  };
  // Sort-and-sweep on x over the packed boxes; ties broken by index, so the
  // sorted order is unique (reproducible whatever the sort). The boxes come
  // in last step's sorted order (c.order), which bodies change little from
  // step to step: an insertion sort finishes in about linear time, and falls
  // back to std::sort when it has to move too much. Boxes within the contact
  // margin pair up too (persistent and speculative contacts).
  using SweepBox = RigidContactState::SweepBox;
  const auto before = [](const SweepBox& p, const SweepBox& q) {
    return p.lo[0] < q.lo[0] || (p.lo[0] == q.lo[0] && p.id < q.id);
  };
  std::size_t bounded = 0;
  for (std::uint32_t i = 0; i < n; ++i) bounded += kind[i] == kBounded;
  bool sorted = false;
  if (c.order.size() == bounded && bounded > 0) {
    bool same = true;  // the same colliders as last step (materials may change)
    for (const std::uint32_t i : c.order) {
      same = same && i < n && kind[i] == kBounded;
      if (same) c.sweep.push_back(packed(i));
    }
    sorted = same && insertionSort(c.sweep, 0, bounded, before, 8 * bounded);
  }
  if (!sorted) {
    c.sweep.clear();
    for (std::uint32_t i = 0; i < n; ++i)
      if (kind[i] == kBounded) c.sweep.push_back(packed(i));
    std::sort(c.sweep.begin(), c.sweep.end(), before);
  }
  c.order.clear();
  const double margin = contactSettings_.contactMargin;
  const std::size_t m = c.sweep.size();
  // Most boxes within reach along x are far away along y or z (a column of
  // a stack, a layer of falling bodies): four candidates at a time, the
  // exact x bound and a float pretest of y and z give a mask of those that
  // may overlap, and only these take the exact double test below. The same
  // pairs as one exact test per candidate, in the same order.
  constexpr std::size_t kPad = 4;  // a block may start at m
  const std::size_t stride = m + kPad;
  c.sweepLo.resize(stride);
  c.sweepFilter.resize(4 * stride);
  double* const lo0 = c.sweepLo.data();
  float* const loY = c.sweepFilter.data();
  float* const loZ = loY + stride;
  float* const hiY = loZ + stride;
  float* const hiZ = hiY + stride;
  for (std::size_t k = 0; k < stride; ++k) {
    if (k < m) {
      const SweepBox& p = c.sweep[k];
      lo0[k] = p.lo[0];
      loY[k] = floatDown(p.lo[1]);
      loZ[k] = floatDown(p.lo[2]);
      hiY[k] = floatUp(p.hi[1] + margin);
      hiZ[k] = floatUp(p.hi[2] + margin);
    } else {
      lo0[k] = std::numeric_limits<double>::infinity();
      loY[k] = loZ[k] = hiY[k] = hiZ[k] = 0.0f;
    }
  }
  for (std::size_t k = 0; k < m; ++k) {
    const SweepBox& p = c.sweep[k];
    c.order.push_back(p.id);
    const double end = p.hi[0] + margin;
    for (std::size_t l = k + 1;; l += 4) {
      // Bit j: box l + j may pair with p. The boxes are sorted by min x, so
      // the x bits are a prefix; a block whose last one fails is the last.
      unsigned inX = 0, mask = 0;
#if defined(__SSE2__)
      const __m128d e = _mm_set1_pd(end);
      inX = static_cast<unsigned>(_mm_movemask_pd(_mm_cmple_pd(_mm_loadu_pd(lo0 + l), e))) |
            static_cast<unsigned>(_mm_movemask_pd(_mm_cmple_pd(_mm_loadu_pd(lo0 + l + 2), e))) << 2;
      const __m128 near = _mm_and_ps(
          _mm_and_ps(_mm_cmple_ps(_mm_loadu_ps(loY + l), _mm_set1_ps(hiY[k])),
                     _mm_cmple_ps(_mm_loadu_ps(loZ + l), _mm_set1_ps(hiZ[k]))),
          _mm_and_ps(_mm_cmpge_ps(_mm_loadu_ps(hiY + l), _mm_set1_ps(loY[k])),
                     _mm_cmpge_ps(_mm_loadu_ps(hiZ + l), _mm_set1_ps(loZ[k]))));
      mask = inX & static_cast<unsigned>(_mm_movemask_ps(near));
#else
      for (unsigned j = 0; j < 4; ++j) {
        const std::size_t q = l + j;
        inX |= unsigned{lo0[q] <= end} << j;
        mask |= unsigned{lo0[q] <= end && loY[q] <= hiY[k] && loZ[q] <= hiZ[k] && hiY[q] >= loY[k] &&
                         hiZ[q] >= loZ[k]}
                << j;
      }
#endif
      for (; mask != 0; mask &= mask - 1) {
        const SweepBox& q = c.sweep[l + static_cast<std::size_t>(std::countr_zero(mask))];
        if (q.lo[1] <= p.hi[1] + margin && p.lo[1] <= q.hi[1] + margin && q.lo[2] <= p.hi[2] + margin &&
            p.lo[2] <= q.hi[2] + margin && p.lo[0] <= q.hi[0] + margin && eligible(p.id, q.id))
          push(p.id, q.id);
      }
      if (inX != 0xF) break;
    }
  }
  // Unbounded shapes (planes) against every bounded collider, in index
  // order: a plane's pairs are then already in the order sorted below.
  for (std::uint32_t u = 0; u < n; ++u) {
    if (kind[u] != kUnbounded) continue;
    for (std::uint32_t b = 0; b < n; ++b)
      if (kind[b] == kBounded && eligible(u, b)) push(u, b);
  }
  sortBottomUp(state);
}

void PhysicsWorld::sortBottomUp(WorldState& state) const {
  // Bottom-up (ground contacts first): sequential impulses then carry the
  // support up a stack within one sweep, which tall stacks need at large dt.
  // The order: by the pair's lower box bottom z, then by the pair (a, b).
  // Sorting the colliders by (z, index) instead — an insertion sort from
  // last step's order, about linear — gives each pair its lower body, whose
  // bottom is the pair's z: a counting sort by that body's place then lists
  // the pairs by z, and only pairs of bodies with equal z (one body's few
  // pairs, mostly) still need ordering among themselves.
  RigidContactState& c = state.contact_;
  const std::vector<Aabb>& box = state.bounds_;
  const auto n = static_cast<std::uint32_t>(bodies_.size());
  const auto z = [&box](std::uint32_t i) { return box[i].min().z(); };
  const auto lower = [&z](std::uint32_t i, std::uint32_t j) {
    return z(i) < z(j) || (z(i) == z(j) && i < j);
  };
  std::size_t colliders = 0;
  const std::vector<std::uint8_t>& kind = c.colliderKind;
  for (std::uint32_t i = 0; i < n; ++i) colliders += kind[i] != kNoCollider;
  bool sorted = false;
  if (c.zOrder.size() == colliders && colliders > 0) {
    // The same colliders as last step (a permutation of them, all still
    // colliders, as many): insertion sort, with a budget of moves.
    bool same = true;
    for (const std::uint32_t i : c.zOrder) same = same && i < n && kind[i] != kNoCollider;
    sorted = same && insertionSort(c.zOrder, 0, colliders, lower, 8 * colliders);
  }
  if (!sorted) {
    c.zOrder.clear();
    for (std::uint32_t i = 0; i < n; ++i)
      if (kind[i] != kNoCollider) c.zOrder.push_back(i);
    std::sort(c.zOrder.begin(), c.zOrder.end(), lower);
  }
  for (std::uint32_t r = 0; r < colliders; ++r) c.zRank[c.zOrder[r]] = r;
  // Counting sort of the pairs by the place of their lower body (stable).
  c.buckets.assign(colliders + 1, 0);
  const auto place = [&c](const ProxyPair& p) { return std::min(c.zRank[p.a], c.zRank[p.b]); };
  for (const ProxyPair& p : c.pairs) ++c.buckets[place(p) + 1];
  for (std::size_t r = 0; r < colliders; ++r) c.buckets[r + 1] += c.buckets[r];
  c.bucketed.resize(c.pairs.size());
  for (const ProxyPair& p : c.pairs) c.bucketed[c.buckets[place(p)]++] = p;
  // buckets[r] is now where place r's pairs end. Within a run of places of
  // equal z, order the pairs by (a, b): insertion sort (the sweep and the
  // plane loop list them nearly so), std::sort if that moves too much.
  std::size_t begin = 0;
  for (std::size_t r = 0; r < colliders;) {
    std::size_t last = r;
    while (last + 1 < colliders && z(c.zOrder[last + 1]) == z(c.zOrder[r])) ++last;
    const std::size_t end = c.buckets[last];
    if (!insertionSort(c.bucketed, begin, end, std::less<ProxyPair>{}, 8 * (end - begin)))
      std::sort(c.bucketed.begin() + static_cast<std::ptrdiff_t>(begin),
                c.bucketed.begin() + static_cast<std::ptrdiff_t>(end));
    begin = end;
    r = last + 1;
  }
  std::copy(c.bucketed.begin(), c.bucketed.end(), c.pairs.begin());
}

void PhysicsWorld::narrowPhase(WorldState& state) const {
  RigidContactState& c = state.contact_;
  const auto awake = [this, &c](std::uint32_t i) { return model_[i].inverseMass > 0.0 && !c.asleep[i]; };
  if (c.sleeping > 0) {
    // An awake dynamic body colliding with a sleeper, or within the contact
    // margin of it, wakes the sleeper's island before any contact is made,
    // so the island takes part in full.
    const CollisionRequest test{.contacts = false, .maxContacts = 1};
    for (const ProxyPair& pair : c.pairs) {
      const std::uint32_t a = pair.a, b = pair.b;
      if (c.asleep[a] == c.asleep[b]) continue;
      const std::uint32_t sleeper = c.asleep[a] ? a : b, other = c.asleep[a] ? b : a;
      if (!awake(other) || !c.asleep[sleeper]) continue;  // static bodies wake nothing
      // Colliding, or close enough for speculative contacts (step 2).
      const Isometry3& pa = c.shapePoses[a];
      const Isometry3& pb = c.shapePoses[b];
      collide(*bodies_[a].shape, pa, *bodies_[b].shape, pb, test, c.narrow);
      bool near = c.narrow.colliding;
      if (!near && contactSettings_.contactMargin > 0.0) {
        const DistanceResult d = distance(*bodies_[a].shape, pa, *bodies_[b].shape, pb);
        near = d.supported && d.distance < contactSettings_.contactMargin;
      }
      if (near) wakeIsland(state, sleeper);
    }
  }
  const CollisionRequest request{.contacts = true,
                                 .maxContacts = std::max(contactSettings_.maxContactsPerPair, 1)};
  const double margin = contactSettings_.contactMargin;
  for (const ProxyPair& pair : c.pairs) {
    const std::uint32_t a = pair.a, b = pair.b;
    if (c.sleeping > 0 && !awake(a) && !awake(b)) continue;  // sleepers among themselves or on the ground
    const BodyDesc& da = bodies_[a];
    const BodyDesc& db = bodies_[b];
    const double mu = std::sqrt(materials_[a].friction * materials_[b].friction);
    const double e = std::max(materials_[a].restitution, materials_[b].restitution);
    const Aabb& boxA = state.bounds_[a];
    const Aabb& boxB = state.bounds_[b];
    bool colliding = false;
    double gapBound = 0.0;  // a lower bound on the shapes' distance, m (0: unknown)
    const bool planar = c.colliderKind[a] == kUnbounded || c.colliderKind[b] == kUnbounded;
    if (planar || boxesOverlap(boxA, boxB)) {
      collide(*da.shape, c.shapePoses[a], *db.shape, c.shapePoses[b], request, c.narrow);
      colliding = c.narrow.colliding;
      gapBound = c.narrow.separation;
    }
    if (!colliding) {
      if (!(margin > 0.0)) continue;
      // Apart now: last step's contacts, if still close, as speculative ones.
      int kept = c.cache.size() > 0
                     ? c.cache.persist(static_cast<int>(a), static_cast<int>(b), c.bodies, margin, mu, e, c.contacts)
                     : 0;
      // No history (say, a scene built touching): the manifold the pair
      // would have if B were moved onto A, moved back, as speculative
      // contacts. Only between two bounded shapes: a plane pair (the broad
      // phase pairs a plane with every collider) needs no distance query;
      // nor does a pair the collision test already found farther apart than
      // twice the margin (the query's answer would be compared with the
      // margin only; GJK's error is orders of magnitude below it).
      if (kept == 0 && !planar && !(gapBound >= 2.0 * margin)) {
        const Isometry3& pa = c.shapePoses[a];
        const Isometry3& pb = c.shapePoses[b];
        const DistanceResult d = distance(*da.shape, pa, *db.shape, pb);
        Vec3 n = d.pointB - d.pointA;
        const double len = n.norm();
        if (len > 1e-9 * margin) {
          n /= len;
        } else {
          // Touching to rounding: the closest points give no direction; take
          // the axis along which the boxes are farthest apart.
          const Vec3 apart = (boxB.min() - boxA.max()).cwiseMax(boxA.min() - boxB.max());
          Eigen::Index k = 0;
          apart.maxCoeff(&k);
          n = Vec3::Unit(k) * (boxB.center()[k] >= boxA.center()[k] ? 1.0 : -1.0);
        }
        if (d.supported && d.distance >= 0.0 && d.distance < margin) {
          const double shift = d.distance + std::min(1e-6, 0.01 * margin);
          Isometry3 moved = pb;
          moved.translation() -= shift * n;
          collide(*da.shape, pa, *db.shape, moved, request, c.narrow);
          if (c.narrow.colliding) {
            for (const ContactPoint& q : c.narrow.contacts) {
              const ContactPoint p{q.position + 0.5 * shift * n, q.normal,
                                   std::min(q.depth - shift * n.dot(q.normal), 0.0)};
              c.contacts.push_back(
                  ContactConstraint::make(static_cast<int>(a), static_cast<int>(b), p, mu, e));
            }
            kept = static_cast<int>(c.narrow.contacts.size());
          }
        }
      }
      if (kept > 0) c.constrained[a] = c.constrained[b] = 1;
      continue;
    }
    for (const ContactPoint& p : c.narrow.contacts)
      c.contacts.push_back(ContactConstraint::make(static_cast<int>(a), static_cast<int>(b), p, mu, e));
    c.constrained[a] = c.constrained[b] = 1;
  }
  c.stats.pairs = c.pairs.size();
}

void PhysicsWorld::continuousCollision(WorldState& state) const {
  RigidContactState& c = state.contact_;
  const WorldSnapshot& s = state.s_;
  const auto n = static_cast<std::uint32_t>(bodies_.size());
  const auto touching = [&c](std::uint32_t a, std::uint32_t b) {
    for (const ContactConstraint& k : c.contacts)
      if ((k.bodyA == static_cast<int>(a) && k.bodyB == static_cast<int>(b)) ||
          (k.bodyA == static_cast<int>(b) && k.bodyB == static_cast<int>(a)))
        return true;
    return false;
  };
  for (std::uint32_t i = 0; i < n; ++i) {
    if (!collider(i) || !materials_[i].ccd || !(model_[i].inverseMass > 0.0)) continue;
    const BodyDesc& di = bodies_[i];
    const Shape& shape = *di.shape;
    const Motion motion{c.shapePoses[i], posed(s.position[i], s.orientation[i], di.shapeOffset)};
    const double thick = thickness(shape);
    const double travel = motion.maxPointDisplacement(shape.boundingSphere().radius);
    if (!(travel > 0.5 * thick)) continue;  // cannot skip over anything in one step
    Aabb swept = state.bounds_[i];
    swept.extend(shape.aabb(motion.end));
    ToiResult best;
    std::uint32_t hit = i;
    for (std::uint32_t j = 0; j < n; ++j) {
      if (j == i || !collider(j) || jointed(i, j) || !boxesOverlap(state.bounds_[j], swept)) continue;
      if (touching(i, j)) continue;  // the narrow phase already has this pair
      const BodyDesc& dj = bodies_[j];
      const Motion other = Motion::stationary(c.shapePoses[j]);
      ToiResult r = conservativeAdvancement(shape, motion, *dj.shape, other,
                                            {.tolerance = contactSettings_.ccdTolerance});
      if (r.status == ToiStatus::Unsupported) {
        const double samples = thick > 0.0 ? std::ceil(travel / thick) : 8.0;
        r = bisectImpact(shape, motion, *dj.shape, other,
                         {.samples = static_cast<int>(std::clamp(samples, 8.0, 256.0))});
      }
      if (r.status == ToiStatus::Hit && r.t < best.t) {
        best = r;
        hit = j;
      }
    }
    if (hit == i) continue;
    // Back to the time of impact; the solver takes the contact from there.
    const Isometry3 pose = motion.at(best.t) * di.shapeOffset.inverse();
    c.bodies[i].position = pose.translation();
    c.bodies[i].orientation = Quat(pose.rotation()).normalized();
    c.shapePoses[i] = posed(c.bodies[i].position, c.bodies[i].orientation, di.shapeOffset);
    const ContactPoint p{best.point, best.normal, std::max(0.0, -best.distance)};
    c.contacts.push_back(
        ContactConstraint::make(static_cast<int>(i), static_cast<int>(hit), p,
                                std::sqrt(materials_[i].friction * materials_[hit].friction),
                                std::max(materials_[i].restitution, materials_[hit].restitution)));
    c.constrained[i] = c.constrained[hit] = 1;
    ++c.stats.ccdHits;
  }
}

void PhysicsWorld::beginContacts(WorldState& state) const {
  RigidContactState& c = state.contact_;
  if (c.sleeping > 0 && !(contactSettings_.sleep && contactSettings_.enabled)) wakeAll(state);
  c.stats = ContactStats{};
  c.contacts.clear();
  for (std::size_t i = 0; i < bodies_.size(); ++i) {
    c.bodies[i].position = state.s_.position[i];
    c.bodies[i].orientation = state.s_.orientation[i];
    c.constrained[i] = 0;
  }
  if (!contactSettings_.enabled) return;
  // Each collider's kind and shape pose once: a body takes part in many
  // pairs of the broad and narrow phases and CCD. CCD keeps the pose current
  // when it moves a body back.
  for (std::uint32_t i = 0; i < bodies_.size(); ++i) {
    c.colliderKind[i] = !collider(i) ? kNoCollider : unbounded(state.bounds_[i]) ? kUnbounded : kBounded;
    if (c.colliderKind[i] != kNoCollider)
      c.shapePoses[i] = posed(c.bodies[i].position, c.bodies[i].orientation, bodies_[i].shapeOffset);
  }
  broadPhase(state);
  narrowPhase(state);
}

Status PhysicsWorld::finishContacts(WorldState& state, double dt) const {
  RigidContactState& c = state.contact_;
  WorldSnapshot& s = state.s_;
  const std::size_t n = bodies_.size();
  for (std::size_t i = 0; i < n; ++i) {
    c.bodies[i].linearVelocity = s.linearVelocity[i];
    c.bodies[i].angularVelocity = s.angularVelocity[i];
  }
  if (contactSettings_.enabled) continuousCollision(state);
  for (const Joint& j : c.joints) {
    if (j.bodyA != kWorldBody) c.constrained[static_cast<std::size_t>(j.bodyA)] = 1;
    if (j.bodyB != kWorldBody) c.constrained[static_cast<std::size_t>(j.bodyB)] = 1;
  }
  if (c.contacts.empty() && c.joints.empty()) {
    c.cache.clear();
    if (contactSettings_.sleep) updateSleep(state, dt);
    return ok();
  }
  for (std::size_t i = 0; i < n; ++i)
    if (c.constrained[i] && model_[i].inverseMass > 0.0) c.bodies[i].updateWorldInertia();
  c.stats.warmStarted = static_cast<std::size_t>(c.cache.warmStart(c.contacts, c.bodies));
  auto solved = c.solver.solve(c.bodies, c.contacts, c.joints, dt, contactSettings_.solver);
  if (!solved)
    return fail(ErrorCode::Unsupported, "the contact solver rejected the step: " + solved.error().message(),
                "PhysicsWorld::step at t = " + std::to_string(s.time) + " s",
                "reduce dt or check the bodies' states; restore a snapshot to continue");
  c.stats.solver = *solved;
  c.stats.contacts = c.contacts.size();
  c.cache.store(c.contacts, c.bodies);
  for (std::size_t i = 0; i < n; ++i) {
    if (!c.constrained[i] || !(model_[i].inverseMass > 0.0)) continue;
    SolverBody& b = c.bodies[i];
    integratePositions(std::span<SolverBody>(&b, 1), dt);
    s.position[i] = b.position;
    s.orientation[i] = b.orientation;
    s.linearVelocity[i] = b.linearVelocity;
    if (model_[i].kind == BodyKind::Rigid) s.angularVelocity[i] = b.angularVelocity;
  }
  if (contactSettings_.sleep) updateSleep(state, dt);
  return ok();
}

// ---------------------------------------------------------------------------
// Sleeping

void PhysicsWorld::wakeIsland(WorldState& state, std::uint32_t body) const noexcept {
  RigidContactState& c = state.contact_;
  if (body >= c.asleep.size() || !c.asleep[body]) return;
  const std::uint32_t id = c.island[body];
  for (std::size_t j = 0; j < c.asleep.size(); ++j) {
    if (!c.asleep[j] || c.island[j] != id) continue;
    c.asleep[j] = 0;
    c.stillTime[j] = 0.0;
    --c.sleeping;
  }
  c.stats.sleeping = c.sleeping;
}

void PhysicsWorld::wakeAll(WorldState& state) const noexcept {
  RigidContactState& c = state.contact_;
  std::fill(c.asleep.begin(), c.asleep.end(), std::uint8_t{0});
  std::fill(c.stillTime.begin(), c.stillTime.end(), 0.0);
  c.sleeping = 0;
  c.stats.sleeping = 0;
}

void PhysicsWorld::holdSleepers(WorldState& state) const noexcept {
  // The integrators advanced every body; sleepers go back to where they lie.
  RigidContactState& c = state.contact_;
  WorldSnapshot& s = state.s_;
  for (std::size_t i = 0; i < c.asleep.size(); ++i) {
    if (!c.asleep[i]) continue;
    s.position[i] = c.bodies[i].position;
    s.orientation[i] = c.bodies[i].orientation;
    s.linearVelocity[i].setZero();
    s.angularVelocity[i].setZero();
  }
}

void PhysicsWorld::updateSleep(WorldState& state, double dt) const noexcept {
  RigidContactState& c = state.contact_;
  WorldSnapshot& s = state.s_;
  const auto n = static_cast<std::uint32_t>(bodies_.size());
  // A contact that reached a sleeper anyway (a CCD hit) wakes its island.
  for (const ContactConstraint& k : c.contacts)
    for (const int side : {k.bodyA, k.bodyB})
      if (side != kWorldBody) wakeIsland(state, static_cast<std::uint32_t>(side));
  const auto awake = [this, &c](std::uint32_t i) { return model_[i].inverseMass > 0.0 && !c.asleep[i]; };

  // Bodies something outside the contacts acts on stay awake.
  std::fill(c.sleepBlocked.begin(), c.sleepBlocked.end(), std::uint8_t{!forces_.user.empty()});
  const auto block = [&c](BodyId id) {
    if (id.valid() && id.index < c.sleepBlocked.size()) c.sleepBlocked[id.index] = 1;
  };
  for (const ExternalForce& f : forces_.forces) block(f.body);
  for (const ExternalTorque& t : forces_.torques) block(t.body);
  for (const Spring& sp : forces_.springs) {
    block(sp.a);
    block(sp.b);
  }
  for (const NewtonianGravity& g : forces_.newtonian) {
    if (g.bodies.empty()) std::fill(c.sleepBlocked.begin(), c.sleepBlocked.end(), std::uint8_t{1});
    for (const BodyId id : g.bodies) block(id);
  }
  for (const Impulse& imp : impulses_)
    if (imp.time >= s.time) block(imp.body);
  for (const Joint& j : c.joints)
    for (const int side : {j.bodyA, j.bodyB})
      if (side != kWorldBody) c.sleepBlocked[static_cast<std::size_t>(side)] = 1;

  // Stillness, then islands by union–find over the contacts and joints
  // between awake dynamic bodies (the smaller index is the root, so the
  // result does not depend on the order of the unions).
  const double lin2 = contactSettings_.sleepLinearVelocity * contactSettings_.sleepLinearVelocity;
  const double ang2 = contactSettings_.sleepAngularVelocity * contactSettings_.sleepAngularVelocity;
  for (std::uint32_t i = 0; i < n; ++i) {
    if (!awake(i)) continue;
    c.island[i] = i;
    const bool still = !c.sleepBlocked[i] && c.constrained[i] && s.linearVelocity[i].squaredNorm() <= lin2 &&
                       s.angularVelocity[i].squaredNorm() <= ang2;
    c.stillTime[i] = still ? c.stillTime[i] + dt : 0.0;
  }
  const auto find = [&c](std::uint32_t i) {
    while (c.island[i] != i) {
      c.island[i] = c.island[c.island[i]];
      i = c.island[i];
    }
    return i;
  };
  const auto unite = [&](int a, int b) {
    if (a == kWorldBody || b == kWorldBody) return;
    const auto ua = static_cast<std::uint32_t>(a), ub = static_cast<std::uint32_t>(b);
    if (!awake(ua) || !awake(ub)) return;
    const std::uint32_t ra = find(ua), rb = find(ub);
    if (ra < rb)
      c.island[rb] = ra;
    else if (rb < ra)
      c.island[ra] = rb;
  };
  for (const ContactConstraint& k : c.contacts) unite(k.bodyA, k.bodyB);
  for (const Joint& j : c.joints) unite(j.bodyA, j.bodyB);
  for (std::uint32_t i = 0; i < n; ++i)
    if (awake(i)) c.islandTime[i] = std::numeric_limits<double>::infinity();
  for (std::uint32_t i = 0; i < n; ++i) {
    if (!awake(i)) continue;
    const std::uint32_t r = find(i);
    c.islandTime[r] = std::min(c.islandTime[r], c.stillTime[i]);
  }
  for (std::uint32_t i = 0; i < n; ++i) {
    if (!awake(i)) continue;
    const std::uint32_t r = find(i);
    if (!(c.islandTime[r] >= contactSettings_.timeToSleep)) continue;
    c.island[i] = r;  // the island's id: its smallest body index
    c.asleep[i] = 1;
    ++c.sleeping;
    s.linearVelocity[i].setZero();
    s.angularVelocity[i].setZero();
  }
  c.stats.sleeping = c.sleeping;
}

}  // namespace dm
