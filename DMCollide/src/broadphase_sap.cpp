// Segmented sweep-and-prune: sorted lists in the columns of a coarse grid.
//
// One sorted list along one axis has the flaw the issue names: at fixed
// density the boxes whose projections overlap a box's grow like n^(2/3),
// so the swaps of an incremental sort (and the candidates of a sweep) grow
// like n^(5/3). Here the plane of the two other axes is cut into square
// columns of edge `cell_` (twice the median box extent there); a box enters
// every column its box touches, and each column keeps its own list sorted
// along the sweep axis. A column holds O(1) boxes per metre of the sweep
// axis at fixed density, so sorting and sweeping all of them is O(n + k).
//
// Data layout (slot = dense internal index; ids map to slots through
// `slotOf_`):
//  - per slot, one 64-byte `SlotData`: the box the user last gave and the
//    range of columns the slot currently has entries in (empty when it has
//    none, e.g. a parked slot with an unusable box or a wide one);
//  - per column, a vector of 64-byte entries {sweep-axis min and max, the
//    four bucket-axis bounds, slot, first column of the slot on each bucket
//    axis}, sorted by sweep-axis min.
//
// overlappingPairs():
//  1. every live slot recomputes its column range from its box; the columns
//     it newly touches get an entry appended (rare under coherent motion);
//  2. every column refreshes its entries from the slots' boxes, dropping the
//     entries of slots whose range no longer holds the column (left, parked,
//     removed — a reused slot is harmless: the entry then belongs to its new
//     box), re-sorts by insertion sort (nearly sorted: O(m + swaps)) and
//     sweeps: each entry against the following ones while their mins are
//     within its max. A pair that overlaps lies in every column both boxes
//     touch on the overlap; it is reported only in the column holding the
//     corner (max of the mins) of the overlap — with the column index a
//     monotone function of the coordinate that column is the pair of the
//     larger first columns, which the entries carry, so each pair comes out
//     once;
//  3. boxes spanning more than kMaxColumns columns are kept out of the
//     columns and tested against every live box (O(wide · n)).
// The sweep axis and the column edge are chosen at the first step and again
// when the number of boxes or their median size changes by 2× (the sweep
// axis: the one with the largest spread of box centres).
#include <dm/core/assert.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <unordered_map>

#include "broadphase_impl.hpp"

namespace dm::detail {

namespace {

// Column indices are clamped to ±kCellClamp (boxes out at ±1e308 land in
// the outermost columns; clamping keeps the index monotone).
constexpr double kCellClamp = 1 << 28;
// A box spanning more columns than this is tested against all boxes.
constexpr std::int64_t kMaxColumns = 64;

enum class SlotState : std::uint8_t { Free, Parked, Live };

struct SlotData {
  FlatBox box;
  // Columns [c1lo, c1hi] × [c2lo, c2hi] holding an entry of the slot; empty
  // (c1lo > c1hi) when none do.
  std::int32_t c1lo = 0, c1hi = -1, c2lo = 0, c2hi = -1;
  bool holds(std::int32_t c1, std::int32_t c2) const noexcept {
    return c1lo <= c1 && c1 <= c1hi && c2lo <= c2 && c2 <= c2hi;
  }
};
static_assert(sizeof(SlotData) == 64);

struct SweepEntry {
  double lo, hi;    // sweep axis
  double lo1, hi1;  // first bucket axis
  double lo2, hi2;  // second bucket axis
  std::uint32_t slot;
  std::int32_t c1, c2;  // the slot's first column on each bucket axis
};

struct Column {
  std::int32_t c1, c2;
  std::vector<SweepEntry> entries;
};

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
    std::uint32_t s;
    if (!free_.empty()) {
      s = free_.back();
      free_.pop_back();
    } else {
      s = static_cast<std::uint32_t>(state_.size());
      DM_DEMAND(s < kNoSlot, "sweep and prune: too many proxies");
      state_.push_back(SlotState::Free);
      idOf_.push_back(0);
      slots_.emplace_back();
    }
    slotOf_[id] = s;
    idOf_[s] = id;
    ++count_;
    setBox(s, box);
  }

  void update(ProxyId id, const Aabb& box) override {
    if (id >= slotOf_.size() || slotOf_[id] == kNoSlot) return;
    setBox(slotOf_[id], box);
  }

  void remove(ProxyId id) override {
    if (id >= slotOf_.size() || slotOf_[id] == kNoSlot) return;
    const std::uint32_t s = slotOf_[id];
    slotOf_[id] = kNoSlot;
    --count_;
    --(state_[s] == SlotState::Live ? live_ : parked_);
    // The slot's column entries go at the next step (its range is reset
    // then, or belongs to the box of whichever id reuses the slot).
    state_[s] = SlotState::Free;
    free_.push_back(s);
  }

  void clear() override { *this = SweepAndPruneBroadPhase(); }

  std::size_t size() const noexcept override { return count_; }

  void overlappingPairs(std::vector<ProxyPair>& out) override {
    keys_.clear();
    if (needsRebuild()) rebuild();
    enterColumns();
    for (Column& col : columns_) sweepColumn(col);
    pairsOfWide();
    fresh_ = false;
    emitSortedPairs(keys_, scratch_, out);
  }

  void query(const Aabb& box, std::vector<ProxyId>& out) const override {
    // O(n) scan of the slots' boxes.
    out.clear();
    const FlatBox q = toFlatBox(box);
    for (std::uint32_t s = 0; s < state_.size(); ++s)
      if (state_[s] == SlotState::Live && overlap(q, slots_[s].box)) out.push_back(idOf_[s]);
    std::sort(out.begin(), out.end());
  }

 private:
  void setBox(std::uint32_t s, const Aabb& box) {
    const bool usable = isUsableBox(box);
    if (state_[s] != SlotState::Free) --(state_[s] == SlotState::Live ? live_ : parked_);
    state_[s] = usable ? SlotState::Live : SlotState::Parked;
    ++(usable ? live_ : parked_);
    slots_[s].box = toFlatBox(box);
  }

  // Column of coordinate x on a bucket axis: floor(x / cell_), clamped;
  // monotone in x.
  std::int32_t columnOf(double x) const noexcept {
    const double v = std::clamp(x * inverseCell_, -kCellClamp, kCellClamp);
    const auto i = static_cast<std::int32_t>(v);
    return i - static_cast<std::int32_t>(static_cast<double>(i) > v);
  }

  double medianExtent(std::vector<double>& scratch) const {
    scratch.clear();
    for (std::uint32_t s = 0; s < state_.size(); ++s)
      if (state_[s] == SlotState::Live) {
        const FlatBox& b = slots_[s].box;
        scratch.push_back(0.5 * ((b.hi[axis1_] - b.lo[axis1_]) + (b.hi[axis2_] - b.lo[axis2_])));
      }
    if (scratch.empty()) return 0.0;
    auto mid = scratch.begin() + static_cast<std::ptrdiff_t>(scratch.size() / 2);
    std::nth_element(scratch.begin(), mid, scratch.end());
    return *mid;
  }

  bool needsRebuild() {
    if (builtFor_ == 0) return live_ > 0;
    if (live_ > 2 * builtFor_ || 2 * live_ < builtFor_) return true;
    // The median size, every 64 steps (O(n)).
    if (++sinceCheck_ < 64) return false;
    sinceCheck_ = 0;
    const double m = medianExtent(extents_);
    return m > 2 * builtExtent_ || 2 * m < builtExtent_;
  }

  // Chooses the sweep axis and the column edge, and empties the columns.
  void rebuild() {
    // Sweep along the axis of the widest spread (10th to 90th percentile)
    // of box centres.
    double spread[3] = {0, 0, 0};
    for (int k = 0; k < 3; ++k) {
      extents_.clear();
      for (std::uint32_t s = 0; s < state_.size(); ++s)
        if (state_[s] == SlotState::Live)
          extents_.push_back(0.5 * slots_[s].box.lo[k] + 0.5 * slots_[s].box.hi[k]);
      if (extents_.size() < 2) break;
      const auto at = [&](std::size_t q) {
        auto it = extents_.begin() + static_cast<std::ptrdiff_t>(q);
        std::nth_element(extents_.begin(), it, extents_.end());
        return *it;
      };
      const double lo = at(extents_.size() / 10), hi = at(extents_.size() - 1 - extents_.size() / 10);
      spread[k] = hi - lo;
    }
    axis0_ = int(std::max_element(spread, spread + 3) - spread);
    axis1_ = (axis0_ + 1) % 3, axis2_ = (axis0_ + 2) % 3;
    builtExtent_ = medianExtent(extents_);
    double cell = 2 * builtExtent_;
    if (!(cell > 0) || !std::isfinite(cell)) {
      // Points or flat boxes: about √n columns across the spread.
      cell = std::max(spread[axis1_], spread[axis2_]) / std::sqrt(double(live_));
      if (!(cell > 0) || !std::isfinite(cell)) cell = 1.0;
    }
    inverseCell_ = 1.0 / cell;
    if (!std::isfinite(inverseCell_)) inverseCell_ = 1.0;
    builtFor_ = live_;
    sinceCheck_ = 0;
    columns_.clear();
    columnOfCell_.clear();
    for (SlotData& d : slots_) d.c1lo = 0, d.c1hi = -1, d.c2lo = 0, d.c2hi = -1;
    fresh_ = true;
  }

  Column& column(std::int32_t c1, std::int32_t c2) {
    const std::uint64_t key = (std::uint64_t(std::uint32_t(c1)) << 32) | std::uint32_t(c2);
    const auto [it, added] = columnOfCell_.try_emplace(key, static_cast<std::uint32_t>(columns_.size()));
    if (added) columns_.push_back({c1, c2, {}});
    return columns_[it->second];
  }

  // Step 1: column ranges of the live slots, entries for newly touched
  // columns, and the list of wide slots.
  void enterColumns() {
    wide_.clear();
    for (std::uint32_t s = 0; s < state_.size(); ++s) {
      SlotData& d = slots_[s];
      if (state_[s] != SlotState::Live) {
        d.c1lo = 0, d.c1hi = -1, d.c2lo = 0, d.c2hi = -1;
        continue;
      }
      const std::int32_t a1 = columnOf(d.box.lo[axis1_]), b1 = columnOf(d.box.hi[axis1_]);
      const std::int32_t a2 = columnOf(d.box.lo[axis2_]), b2 = columnOf(d.box.hi[axis2_]);
      if ((std::int64_t(b1) - a1 + 1) * (std::int64_t(b2) - a2 + 1) > kMaxColumns) {
        wide_.push_back(s);
        d.c1lo = 0, d.c1hi = -1, d.c2lo = 0, d.c2hi = -1;
        continue;
      }
      if (a1 == d.c1lo && b1 == d.c1hi && a2 == d.c2lo && b2 == d.c2hi) continue;
      for (std::int32_t c1 = a1; c1 <= b1; ++c1)
        for (std::int32_t c2 = a2; c2 <= b2; ++c2)
          if (!d.holds(c1, c2)) column(c1, c2).entries.push_back({0, 0, 0, 0, 0, 0, s, a1, a2});
      d.c1lo = a1, d.c1hi = b1, d.c2lo = a2, d.c2hi = b2;
    }
  }

  // Step 2 for one column: refresh, drop, sort, sweep.
  void sweepColumn(Column& col) {
    std::vector<SweepEntry>& e = col.entries;
    std::size_t m = 0;
    for (std::size_t i = 0; i < e.size(); ++i) {
      const std::uint32_t s = e[i].slot;
      const SlotData& d = slots_[s];
      if (!d.holds(col.c1, col.c2)) continue;
      const FlatBox& b = d.box;
      e[m++] = {b.lo[axis0_], b.hi[axis0_], b.lo[axis1_], b.hi[axis1_], b.lo[axis2_], b.hi[axis2_], s,
                d.c1lo,       d.c2lo};
    }
    e.resize(m);
    if (fresh_) {
      std::sort(e.begin(), e.end(), [](const SweepEntry& a, const SweepEntry& b) { return a.lo < b.lo; });
    } else {
      for (std::size_t i = 1; i < m; ++i) {
        if (!(e[i].lo < e[i - 1].lo)) continue;
        const SweepEntry x = e[i];
        std::size_t j = i;
        do {
          e[j] = e[j - 1];
          --j;
        } while (j > 0 && x.lo < e[j - 1].lo);
        e[j] = x;
      }
    }
    for (std::size_t i = 0; i < m; ++i) {
      const SweepEntry& a = e[i];
      for (std::size_t j = i + 1; j < m && e[j].lo <= a.hi; ++j) {
        const SweepEntry& b = e[j];
        // Bitwise '&' on 0/1 integers: one branch for the six tests.
        const unsigned hit = unsigned{a.lo1 <= b.hi1} & unsigned{b.lo1 <= a.hi1} & unsigned{a.lo2 <= b.hi2} &
                             unsigned{b.lo2 <= a.hi2} & unsigned{std::max(a.c1, b.c1) == col.c1} &
                             unsigned{std::max(a.c2, b.c2) == col.c2};
        if (hit) keys_.push_back(pairKey(idOf_[a.slot], idOf_[b.slot]));
      }
    }
  }

  // Step 3: wide slots against every live slot (each wide pair once).
  void pairsOfWide() {
    for (const std::uint32_t w : wide_) {
      const FlatBox& bw = slots_[w].box;
      for (std::uint32_t s = 0; s < state_.size(); ++s) {
        if (state_[s] != SlotState::Live || s == w || !overlap(bw, slots_[s].box)) continue;
        // A live slot in no column is wide: that pair comes from the lower slot.
        const SlotData& d = slots_[s];
        if (d.c1lo > d.c1hi && s < w) continue;
        keys_.push_back(pairKey(idOf_[w], idOf_[s]));
      }
    }
  }

  std::vector<std::uint32_t> slotOf_;  // by id
  std::vector<ProxyId> idOf_;          // by slot
  std::vector<SlotState> state_;       // by slot
  std::vector<SlotData> slots_;        // by slot
  std::vector<std::uint32_t> free_, wide_;
  std::vector<Column> columns_;
  std::unordered_map<std::uint64_t, std::uint32_t> columnOfCell_;
  std::vector<double> extents_;
  std::vector<std::uint64_t> keys_, scratch_;
  int axis0_ = 0, axis1_ = 1, axis2_ = 2;
  double inverseCell_ = 1.0;
  double builtExtent_ = 0.0;
  std::size_t builtFor_ = 0;  // live boxes at the last rebuild; 0: never built
  int sinceCheck_ = 0;
  bool fresh_ = false;  // columns refilled since the last step: sort them from scratch
  std::size_t count_ = 0, live_ = 0, parked_ = 0;
};

}  // namespace

std::unique_ptr<BroadPhase> makeSweepAndPrune(const BroadPhaseOptions& /*options*/) {
  return std::make_unique<SweepAndPruneBroadPhase>();
}

}  // namespace dm::detail
