// Incremental sweep-and-prune on three axes with temporal coherence.
//
// Data layout (slot = dense internal index; ids map to slots through
// `slotOf_`, so a removed id can be re-inserted before the next step):
//  - per axis k, `axis_[k]`: the sorted endpoint array, 16-byte entries
//    {value, slot << 1 | isMax}, ordered by (value, isMax) so that a min sorts
//    before a max of equal value — touching boxes overlap;
//  - per slot: the target box the user last gave (per axis k, `target_[k]`
//    holds min and max of slot s at 2s and 2s + 1, so an endpoint's tag is
//    its index there) and the box the endpoint arrays currently encode
//    ("committed", `cur_`, one 48-byte struct per slot);
//  - the current pair set, a PairKeySet of slot-pair keys: memory O(n + k).
//
// update() only writes the target (O(1)). overlappingPairs() processes the
// axes one at a time: it copies the targets of axis k into the endpoints,
// re-sorts that array by insertion sort (nearly sorted after coherent
// motion: O(n + swaps)), then commits axis k. Elements only move left, so a
// box's min stays left of its max and each swap of a min of A with a max of
// B flips exactly the axis-k overlap of {A, B}: a min passing a max left
// starts it (the pair is added if the committed boxes overlap on the other
// two axes), a max passing a min left ends it (the pair is removed if it
// overlapped on the other two). Invariant between steps: the pair set is
// exactly the set of committed boxes that overlap on all three axes.
//
// New boxes are appended at the end of each array (committed as empty) and
// sorted in like moved ones. Removed slots are purged in one O(n + k) pass
// at the next step. When many boxes arrive at once or the insertion sort
// exceeds a swap budget (teleports of many boxes), the step falls back to a
// full rebuild: std::sort of the three arrays and the pairs from a hashed grid.
#include <dm/core/assert.hpp>

#include <algorithm>
#include <array>
#include <limits>

#include "broadphase_impl.hpp"

namespace dm::detail {

namespace {

constexpr std::uint32_t kNoSlot = ~std::uint32_t(0);
constexpr double kInf = std::numeric_limits<double>::infinity();

/// The committed box of a slot, 48 contiguous bytes: the other-axis tests of a
/// swap read two of these.
using SlotBox = FlatBox;

struct Endpoint {
  double value;
  std::uint32_t tag;  // slot << 1 | isMax
};

inline bool endpointLess(const Endpoint& a, const Endpoint& b) noexcept {
  // Bitwise, not short-circuit: no branch to mispredict in the sort loops.
  return (a.value < b.value) | ((a.value == b.value) & ((a.tag & 1u) < (b.tag & 1u)));
}

enum class SlotState : std::uint8_t { Free, Parked, Pending, Live, Dead };

class SweepAndPruneBroadPhase final : public BroadPhase {
 public:
  BroadPhaseKind kind() const noexcept override { return BroadPhaseKind::SweepAndPrune; }

  void insert(ProxyId id, const Aabb& box) override {
    if (id < slotOf_.size() && slotOf_[id] != kNoSlot) {
      DM_ASSERT(false, "broad phase: proxy id inserted twice");
      update(id, box);
      return;
    }
    if (id >= slotOf_.size()) slotOf_.resize(std::size_t(id) + 1, kNoSlot);
    const std::uint32_t s = allocSlot(id);
    slotOf_[id] = s;
    ++count_;
    setTarget(s, box);
    if (isUsableBox(box)) {
      state_[s] = SlotState::Pending;
      pending_.push_back(s);
    }
  }

  void update(ProxyId id, const Aabb& box) override {
    if (id >= slotOf_.size() || slotOf_[id] == kNoSlot) return;
    const std::uint32_t s = slotOf_[id];
    const bool usable = isUsableBox(box);
    switch (state_[s]) {
      case SlotState::Live:
        if (usable) {
          setTarget(s, box);
        } else {
          // Leave the arrays: the slot dies, the id continues in a parked slot.
          killLiveSlot(s);
          const std::uint32_t p = allocSlot(id);
          slotOf_[id] = p;
          setTarget(p, box);
        }
        break;
      case SlotState::Pending:
        setTarget(s, box);
        if (!usable) state_[s] = SlotState::Parked;
        break;
      case SlotState::Parked:
        setTarget(s, box);
        if (usable) {
          state_[s] = SlotState::Pending;
          pending_.push_back(s);
        }
        break;
      default:
        break;
    }
  }

  void remove(ProxyId id) override {
    if (id >= slotOf_.size() || slotOf_[id] == kNoSlot) return;
    const std::uint32_t s = slotOf_[id];
    slotOf_[id] = kNoSlot;
    --count_;
    if (state_[s] == SlotState::Live) {
      killLiveSlot(s);
    } else {
      // Not in the arrays and in no pair: reusable at once (a stale entry in
      // pending_ is skipped because activation checks the state).
      state_[s] = SlotState::Free;
      free_.push_back(s);
    }
  }

  void clear() override { *this = SweepAndPruneBroadPhase(); }

  std::size_t size() const noexcept override { return count_; }

  void overlappingPairs(std::vector<ProxyPair>& out) override {
    if (!dead_.empty()) purgeDead();
    std::size_t added = 0;
    for (std::uint32_t s : pending_) {
      if (state_[s] != SlotState::Pending) continue;
      state_[s] = SlotState::Live;
      for (int k = 0; k < 3; ++k) {
        // Appended after everything, and new boxes are appended one after
        // the other: until axis k is sorted the box overlaps no box on it,
        // which the empty interval [+inf, -inf] encodes.
        cur_[s].lo[k] = kInf;
        cur_[s].hi[k] = -kInf;
        axis_[k].push_back({target_[k][2 * s], s << 1});
        axis_[k].push_back({target_[k][2 * s + 1], (s << 1) | 1u});
      }
      ++added;
    }
    pending_.clear();
    const std::size_t live = axis_[0].size() / 2;
    const bool bulk = added > 32 && 8 * added > live;
    if (bulk || !sortIncremental()) rebuild();

    keys_.clear();
    pairs_.forEach(
        [&](std::uint64_t k) { keys_.push_back(pairKey(idOf_[k >> 32], idOf_[k & 0xffffffffu])); });
    emitSortedPairs(keys_, scratch_, out);
  }

  void query(const Aabb& box, std::vector<ProxyId>& out) const override {
    // O(n) scan of the targets: the endpoint arrays may lag behind update().
    out.clear();
    const Vec3 lo = box.min(), hi = box.max();
    for (std::uint32_t s = 0; s < state_.size(); ++s) {
      if (state_[s] != SlotState::Live && state_[s] != SlotState::Pending) continue;
      if (lo.x() <= target_[0][2 * s + 1] && target_[0][2 * s] <= hi.x() && lo.y() <= target_[1][2 * s + 1] &&
          target_[1][2 * s] <= hi.y() && lo.z() <= target_[2][2 * s + 1] && target_[2][2 * s] <= hi.z())
        out.push_back(idOf_[s]);
    }
    std::sort(out.begin(), out.end());
  }

 private:
  std::uint32_t allocSlot(ProxyId id) {
    std::uint32_t s;
    if (!free_.empty()) {
      s = free_.back();
      free_.pop_back();
    } else {
      s = static_cast<std::uint32_t>(state_.size());
      DM_DEMAND(s < (kNoSlot >> 1), "sweep and prune: too many proxies");
      state_.push_back(SlotState::Free);
      idOf_.push_back(0);
      cur_.push_back({{kInf, kInf, kInf}, {-kInf, -kInf, -kInf}});
      for (int k = 0; k < 3; ++k) {
        target_[k].push_back(kInf), target_[k].push_back(kInf);
      }
    }
    state_[s] = SlotState::Parked;
    idOf_[s] = id;
    return s;
  }

  void setTarget(std::uint32_t s, const Aabb& box) {
    for (int k = 0; k < 3; ++k) target_[k][2 * s] = box.min()[k], target_[k][2 * s + 1] = box.max()[k];
  }

  void killLiveSlot(std::uint32_t s) {
    state_[s] = SlotState::Dead;
    dead_.push_back(s);
  }

  // Drops the endpoints and pairs of dead slots and frees them: O(n + k).
  void purgeDead() {
    pairs_.eraseIf([&](std::uint64_t k) {
      return state_[k >> 32] == SlotState::Dead || state_[k & 0xffffffffu] == SlotState::Dead;
    });
    for (auto& a : axis_)
      a.erase(std::remove_if(a.begin(), a.end(),
                             [&](const Endpoint& e) { return state_[e.tag >> 1] == SlotState::Dead; }),
              a.end());
    for (std::uint32_t s : dead_) {
      state_[s] = SlotState::Free;
      free_.push_back(s);
    }
    dead_.clear();
  }

  bool overlapOnAxis(int j, std::uint32_t a, std::uint32_t b) const noexcept {
    return (cur_[a].lo[j] <= cur_[b].hi[j]) & (cur_[b].lo[j] <= cur_[a].hi[j]);
  }

  void commitAxis(int k) {
    const double* t = target_[k].data();
    for (std::size_t s = 0; s < cur_.size(); ++s) cur_[s].lo[k] = t[2 * s], cur_[s].hi[k] = t[2 * s + 1];
  }

  // Insertion sort of the three axes with pair updates at each crossing.
  // False if the swap budget ran out (the caller rebuilds from scratch).
  bool sortIncremental() {
    const std::size_t m = axis_[0].size();
    // About what a rebuild costs, counted in swaps.
    std::size_t budget = 1024 + 32 * m;
    for (int k = 0; k < 3; ++k) {
      const int j1 = (k + 1) % 3, j2 = (k + 2) % 3;
      std::vector<Endpoint>& a = axis_[k];
      const double* t = target_[k].data();
      for (Endpoint& e : a) e.value = t[e.tag];
      for (std::size_t i = 1; i < m; ++i) {
        const Endpoint x = a[i];
        if (!endpointLess(x, a[i - 1])) continue;
        const std::uint32_t sx = x.tag >> 1;
        const bool xMax = x.tag & 1u;
        std::size_t j = i;
        do {
          const Endpoint y = a[j - 1];
          if (xMax != bool(y.tag & 1u)) {
            const std::uint32_t sy = y.tag >> 1;
            if (overlapOnAxis(j1, sx, sy) && overlapOnAxis(j2, sx, sy)) {
              const std::uint64_t key = pairKey(sx, sy);
              if (xMax) {
                pairs_.erase(key);  // x's max passed y's min: axis k separates
              } else {
                pairs_.insert(key);  // x's min passed y's max: axis k overlaps
              }
            }
          }
          a[j] = y;
          --j;
        } while (j > 0 && endpointLess(x, a[j - 1]));
        a[j] = x;
        const std::size_t swaps = i - j;
        if (swaps > budget) return false;
        budget -= swaps;
      }
      commitAxis(k);
    }
    return true;
  }

  // Full re-sort of the three arrays and a fresh pair set, found by the
  // hashed grid on the committed boxes (slots as ids): O(n log n + k), where
  // a sort-and-sweep on one axis would cost the pairs overlapping in x,
  // O(n^(5/3)) at fixed density.
  void rebuild() {
    for (int k = 0; k < 3; ++k) {
      std::vector<Endpoint>& a = axis_[k];
      for (Endpoint& e : a) e.value = target_[k][e.tag];
      std::sort(a.begin(), a.end(), endpointLess);
      commitAxis(k);
    }
    pairs_.clear();
    auto grid = makeHashedGrid({});
    for (const Endpoint& e : axis_[0]) {
      if (e.tag & 1u) continue;
      const std::uint32_t s = e.tag >> 1;
      grid->insert(s, Aabb(Vec3(cur_[s].lo[0], cur_[s].lo[1], cur_[s].lo[2]),
                           Vec3(cur_[s].hi[0], cur_[s].hi[1], cur_[s].hi[2])));
    }
    grid->overlappingPairs(gridPairs_);
    for (const ProxyPair& p : gridPairs_) pairs_.insert(pairKey(p.a, p.b));
  }

  std::vector<std::uint32_t> slotOf_;          // by id
  std::vector<ProxyId> idOf_;                  // by slot
  std::vector<SlotState> state_;               // by slot
  std::array<std::vector<double>, 3> target_;  // per axis: min, max by slot
  std::vector<SlotBox> cur_;                   // committed, by slot
  std::array<std::vector<Endpoint>, 3> axis_;
  std::vector<std::uint32_t> free_, pending_, dead_;
  std::vector<ProxyPair> gridPairs_;
  PairKeySet pairs_;
  std::vector<std::uint64_t> keys_, scratch_;
  std::size_t count_ = 0;
};

}  // namespace

std::unique_ptr<BroadPhase> makeSweepAndPrune(const BroadPhaseOptions& /*options*/) {
  return std::make_unique<SweepAndPruneBroadPhase>();
}

}  // namespace dm::detail
