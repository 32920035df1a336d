// Hashed uniform grid and hierarchical grid broad phases (one class, two
// modes), rebuilt from the boxes at every overlappingPairs(): O(n + k).
//
// Data layout:
//  - the proxies live in dense arrays (swap-remove): `boxes_` (six doubles
//    each), `ids_`, `usable_`; `slotOf_` maps an id to its dense index;
//  - each step every box emits one 16-byte entry {cell key, dense index} per
//    grid cell it covers, at its level. A cell key packs the level (6 bits)
//    and the three cell coordinates (19 bits each, clamped, so far-away
//    cells merge instead of overflowing); the entries are counting-sorted by
//    a hash of the key into power-of-two buckets (`bucketStart_`), so one
//    bucket holds every entry of a cell (plus, rarely, entries of other
//    cells with the same hash, told apart by the key).
//
// A pair of overlapping boxes on the same level is reported only from the
// cell that contains the max-of-mins corner of their intersection: the
// corner lies in both boxes, so both have an entry there, and in no other
// common cell — no duplicate pairs and no n² memory.
//
// Hashed grid: one level, cell edge from the options or twice the mean box
// edge. A box covering more than kMaxCells cells goes to an "oversize" list
// tested against every box instead.
//
// Hierarchical grid: level l has cell edge c0·2^l; a box lives on the finest
// level whose cell is at least its largest edge, so it covers at most 2×2×2
// cells there and the cell is less than twice its edge. (The expected box
// tests per box grow like (c + e)⁶ / c³ for cell c and edge e, least at
// c = e: a cell of 2–4 edges costs about three times as much.) Pairs on one
// level are found as above; a box finds partners on each coarser occupied
// level by looking up the (at most 8) cells it covers there and applying the
// same corner rule with that level's cells, so each cross-level pair is
// found once, from its finer member.
#include <dm/core/assert.hpp>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>

#include "broadphase_impl.hpp"

namespace dm::detail {

namespace {

constexpr int kCoordBits = 19;
constexpr double kCoordHalf = double(1 << (kCoordBits - 1));
constexpr int kMaxLevels = 64;
constexpr std::size_t kMaxCells = 512;  // per box on the hashed grid

struct CellEntry {
  std::uint64_t key;
  std::uint32_t index;
};

/// Cell coordinate of x on a level with inverse cell edge `inv`, shifted to
/// [0, 2^19). Monotone in x, so a point inside a box has its cell inside the
/// box's cell range.
inline std::uint64_t cellCoord(double x, double inv) noexcept {
  const double v = std::clamp(x * inv, -kCoordHalf, kCoordHalf - 1.0);
  // floor(v) without a libm call (not inlined without SSE4.1): truncate,
  // then step down where truncation went up. Exact: |v| < 2^18.
  const auto t = static_cast<std::int64_t>(v);
  const std::int64_t f = t - static_cast<std::int64_t>(static_cast<double>(t) > v);
  return static_cast<std::uint64_t>(f + std::int64_t(kCoordHalf));
}

/// overlap() with no branches: in the cell loops the outcome is a coin toss
/// to the predictor.
inline bool overlapNoBranch(const FlatBox& a, const FlatBox& b) noexcept {
  return (a.lo[0] <= b.hi[0]) & (b.lo[0] <= a.hi[0]) & (a.lo[1] <= b.hi[1]) & (b.lo[1] <= a.hi[1]) &
         (a.lo[2] <= b.hi[2]) & (b.lo[2] <= a.hi[2]);
}

inline std::uint64_t cellKey(int level, std::uint64_t x, std::uint64_t y, std::uint64_t z) noexcept {
  return (std::uint64_t(level) << (3 * kCoordBits)) | (x << (2 * kCoordBits)) | (y << kCoordBits) | z;
}

inline int keyLevel(std::uint64_t key) noexcept { return static_cast<int>(key >> (3 * kCoordBits)); }

class GridBroadPhase final : public BroadPhase {
 public:
  GridBroadPhase(bool hierarchical, const BroadPhaseOptions& options)
      : hierarchical_(hierarchical), fixedCell_(options.cellSize > 0 ? options.cellSize : 0.0) {}

  BroadPhaseKind kind() const noexcept override {
    return hierarchical_ ? BroadPhaseKind::HierarchicalGrid : BroadPhaseKind::HashedGrid;
  }

  void insert(ProxyId id, const Aabb& box) override {
    if (id < slotOf_.size() && slotOf_[id] != kNoSlot) {
      DM_ASSERT(false, "broad phase: proxy id inserted twice");
      update(id, box);
      return;
    }
    if (id >= slotOf_.size()) slotOf_.resize(std::size_t(id) + 1, kNoSlot);
    slotOf_[id] = static_cast<std::uint32_t>(ids_.size());
    ids_.push_back(id);
    boxes_.push_back({});
    usable_.push_back(0);
    set(slotOf_[id], box);
  }

  void update(ProxyId id, const Aabb& box) override {
    if (id < slotOf_.size() && slotOf_[id] != kNoSlot) set(slotOf_[id], box);
  }

  void remove(ProxyId id) override {
    if (id >= slotOf_.size() || slotOf_[id] == kNoSlot) return;
    const std::uint32_t i = slotOf_[id];
    const std::uint32_t last = static_cast<std::uint32_t>(ids_.size() - 1);
    if (i != last) {
      ids_[i] = ids_[last];
      boxes_[i] = boxes_[last];
      usable_[i] = usable_[last];
      slotOf_[ids_[i]] = i;
    }
    ids_.pop_back();
    boxes_.pop_back();
    usable_.pop_back();
    slotOf_[id] = kNoSlot;
  }

  void clear() override { *this = GridBroadPhase(hierarchical_, BroadPhaseOptions{fixedCell_, 0.1}); }

  std::size_t size() const noexcept override { return ids_.size(); }

  void overlappingPairs(std::vector<ProxyPair>& out) override {
    keys_.clear();
    chooseCellSize();
    buildEntries();
    pairsWithinCells();
    if (hierarchical_) pairsAcrossLevels();
    pairsOfOversize();
    emitSortedPairs(keys_, scratch_, out);
  }

  void query(const Aabb& box, std::vector<ProxyId>& out) const override {
    // O(n) scan: the cell table is rebuilt per step and may lag update().
    out.clear();
    const FlatBox q = toFlatBox(box);
    for (std::size_t i = 0; i < ids_.size(); ++i)
      if (usable_[i] && overlap(boxes_[i], q)) out.push_back(ids_[i]);
    std::sort(out.begin(), out.end());
  }

 private:
  void set(std::uint32_t i, const Aabb& box) {
    boxes_[i] = toFlatBox(box);
    usable_[i] = isUsableBox(box) ? 1 : 0;
  }

  static double largestEdge(const FlatBox& b) noexcept {
    return std::max({b.hi[0] - b.lo[0], b.hi[1] - b.lo[1], b.hi[2] - b.lo[2]});
  }

  // Hashed: cell = 2 × mean largest edge. Hierarchical: finest cell = √2 ×
  // the mean largest edge halved until it is at most the smallest largest
  // edge, but at most 8 levels below the mean. Either
  // is kept until the wanted value drifts by more than a factor 2, so the
  // cells stay put while the boxes merely move.
  void chooseCellSize() {
    if (fixedCell_ > 0) {
      cell_ = fixedCell_;
    } else {
      double sum = 0, smallest = INFINITY;
      std::size_t n = 0;
      FlatBox bounds{{INFINITY, INFINITY, INFINITY}, {-INFINITY, -INFINITY, -INFINITY}};
      for (std::size_t i = 0; i < ids_.size(); ++i) {
        if (!usable_[i]) continue;
        const double e = largestEdge(boxes_[i]);
        sum += e;
        if (e > 0) smallest = std::min(smallest, e);
        for (int k = 0; k < 3; ++k)
          bounds.lo[k] = std::min(bounds.lo[k], boxes_[i].lo[k]),
          bounds.hi[k] = std::max(bounds.hi[k], boxes_[i].hi[k]);
        ++n;
      }
      if (n == 0) return;
      const double mean = sum / double(n);
      double want = 2.0 * mean;
      if (hierarchical_) {
        // Level l holds edges in (c0·2^(l−1), c0·2^l]: put the mean in the
        // middle of one (at c0·2^l / √2, in log scale) so that a population
        // of similar boxes shares a level instead of straddling two.
        const double finest = std::max(smallest, mean / 256.0);
        want = mean * std::sqrt(2.0);
        while (want > finest && std::isfinite(want)) want *= 0.5;
      }
      if (!(want > 0) || !std::isfinite(want)) {
        // All boxes are points: spread them over about n cells.
        want = largestEdge(bounds) / std::cbrt(double(n));
        if (!(want > 0) || !std::isfinite(want)) want = 1.0;
      }
      if (!(cell_ > 0) || want > 2.0 * cell_ || want < 0.5 * cell_) cell_ = want;
    }
    for (int l = 0; l < kMaxLevels; ++l) inv_[l] = std::ldexp(1.0 / cell_, -l);
  }

  int levelOf(const FlatBox& b) const noexcept {
    if (!hierarchical_) return 0;
    const double r = largestEdge(b) * inv_[0];
    if (!(r > 1.0)) return 0;
    if (!(r < 0x1p62)) return kMaxLevels - 1;  // also an infinite edge
    // ceil(log2 r), exactly, from the bits: r = 1.f · 2^e, so e when the
    // fraction f is zero, else e + 1.
    const auto bits = std::bit_cast<std::uint64_t>(r);
    const int e = static_cast<int>((bits >> 52) & 0x7ff) - 1023;
    const bool fraction = (bits & ((std::uint64_t(1) << 52) - 1)) != 0;
    return std::clamp(fraction ? e + 1 : e, 0, kMaxLevels - 1);
  }

  void buildEntries() {
    entries_.clear();
    oversize_.clear();
    boxLevel_.assign(ids_.size(), 0);
    levelsUsed_ = 0;
    for (std::uint32_t i = 0; i < ids_.size(); ++i) {
      if (!usable_[i]) continue;
      const FlatBox& b = boxes_[i];
      const int l = levelOf(b);
      const double inv = inv_[l];
      const std::uint64_t x0 = cellCoord(b.lo[0], inv), x1 = cellCoord(b.hi[0], inv);
      const std::uint64_t y0 = cellCoord(b.lo[1], inv), y1 = cellCoord(b.hi[1], inv);
      const std::uint64_t z0 = cellCoord(b.lo[2], inv), z1 = cellCoord(b.hi[2], inv);
      if ((x1 - x0 + 1) * (y1 - y0 + 1) * (z1 - z0 + 1) > kMaxCells) {
        oversize_.push_back(i);
        boxLevel_[i] = -1;
        continue;
      }
      boxLevel_[i] = static_cast<std::int8_t>(l);
      levelsUsed_ |= std::uint64_t(1) << l;
      for (std::uint64_t x = x0; x <= x1; ++x)
        for (std::uint64_t y = y0; y <= y1; ++y)
          for (std::uint64_t z = z0; z <= z1; ++z) entries_.push_back({cellKey(l, x, y, z), i});
    }
    // Counting sort by bucket.
    const std::size_t buckets = std::bit_ceil(std::max<std::size_t>(16, entries_.size()));
    shift_ = 64u - static_cast<unsigned>(std::countr_zero(buckets));
    bucketStart_.assign(buckets + 1, 0);
    for (const CellEntry& e : entries_) ++bucketStart_[bucketOf(e.key) + 1];
    for (std::size_t b = 0; b < buckets; ++b) bucketStart_[b + 1] += bucketStart_[b];
    sorted_.resize(entries_.size());
    cursor_.assign(bucketStart_.begin(), bucketStart_.end() - 1);
    for (const CellEntry& e : entries_) sorted_[cursor_[bucketOf(e.key)]++] = e;
  }

  std::size_t bucketOf(std::uint64_t key) const noexcept {
    return static_cast<std::size_t>((key * 0x9E3779B97F4A7C15ull) >> shift_);
  }

  // Key of the cell at `level` holding the max-of-mins corner of a ∩ b.
  std::uint64_t cornerKey(int level, const FlatBox& a, const FlatBox& b) const noexcept {
    const double inv = inv_[level];
    return cellKey(level, cellCoord(std::max(a.lo[0], b.lo[0]), inv),
                   cellCoord(std::max(a.lo[1], b.lo[1]), inv), cellCoord(std::max(a.lo[2], b.lo[2]), inv));
  }

  void emit(std::uint32_t i, std::uint32_t j) { keys_.push_back(pairKey(ids_[i], ids_[j])); }

  void pairsWithinCells() {
    const std::size_t buckets = bucketStart_.size() - 1;
    for (std::size_t bk = 0; bk < buckets; ++bk) {
      const std::uint32_t begin = bucketStart_[bk], end = bucketStart_[bk + 1];
      for (std::uint32_t p = begin; p + 1 < end; ++p) {
        const CellEntry ep = sorted_[p];
        const FlatBox& a = boxes_[ep.index];
        for (std::uint32_t q = p + 1; q < end; ++q) {
          const CellEntry eq = sorted_[q];
          if (eq.key != ep.key) continue;
          const FlatBox& b = boxes_[eq.index];
          if (overlapNoBranch(a, b) && cornerKey(keyLevel(ep.key), a, b) == ep.key) emit(ep.index, eq.index);
        }
      }
    }
  }

  void pairsAcrossLevels() {
    for (std::uint32_t i = 0; i < ids_.size(); ++i) {
      if (!usable_[i] || boxLevel_[i] < 0) continue;
      const FlatBox& a = boxes_[i];
      const int la = boxLevel_[i];
      if (la + 1 >= kMaxLevels) continue;  // the top level has no coarser one
      for (std::uint64_t coarser = levelsUsed_ >> (la + 1); coarser;) {
        const int l = la + 1 + std::countr_zero(coarser);
        coarser &= coarser - 1;
        const double inv = inv_[l];
        const std::uint64_t x0 = cellCoord(a.lo[0], inv), x1 = cellCoord(a.hi[0], inv);
        const std::uint64_t y0 = cellCoord(a.lo[1], inv), y1 = cellCoord(a.hi[1], inv);
        const std::uint64_t z0 = cellCoord(a.lo[2], inv), z1 = cellCoord(a.hi[2], inv);
        for (std::uint64_t x = x0; x <= x1; ++x)
          for (std::uint64_t y = y0; y <= y1; ++y)
            for (std::uint64_t z = z0; z <= z1; ++z) {
              const std::uint64_t key = cellKey(l, x, y, z);
              const std::size_t bk = bucketOf(key);
              for (std::uint32_t q = bucketStart_[bk]; q < bucketStart_[bk + 1]; ++q) {
                if (sorted_[q].key != key) continue;
                const FlatBox& b = boxes_[sorted_[q].index];
                if (overlapNoBranch(a, b) && cornerKey(l, a, b) == key) emit(i, sorted_[q].index);
              }
            }
      }
    }
  }

  void pairsOfOversize() {
    for (std::size_t p = 0; p < oversize_.size(); ++p) {
      const std::uint32_t i = oversize_[p];
      const FlatBox& a = boxes_[i];
      for (std::uint32_t j = 0; j < ids_.size(); ++j)
        if (usable_[j] && boxLevel_[j] >= 0 && overlap(a, boxes_[j])) emit(i, j);
      for (std::size_t q = p + 1; q < oversize_.size(); ++q)
        if (overlap(a, boxes_[oversize_[q]])) emit(i, oversize_[q]);
    }
  }

  bool hierarchical_;
  double fixedCell_;
  double cell_ = 0.0;
  std::array<double, kMaxLevels> inv_{};
  std::vector<std::uint32_t> slotOf_;  // by id
  std::vector<ProxyId> ids_;           // dense
  std::vector<FlatBox> boxes_;         // dense
  std::vector<unsigned char> usable_;  // dense
  std::vector<std::int8_t> boxLevel_;  // dense; −1 = oversize
  std::vector<CellEntry> entries_, sorted_;
  std::vector<std::uint32_t> bucketStart_, cursor_, oversize_;
  std::vector<std::uint64_t> keys_, scratch_;
  std::uint64_t levelsUsed_ = 0;
  unsigned shift_ = 60;
};

}  // namespace

std::unique_ptr<BroadPhase> makeHashedGrid(const BroadPhaseOptions& options) {
  return std::make_unique<GridBroadPhase>(false, options);
}

std::unique_ptr<BroadPhase> makeHierarchicalGrid(const BroadPhaseOptions& options) {
  return std::make_unique<GridBroadPhase>(true, options);
}

}  // namespace dm::detail
