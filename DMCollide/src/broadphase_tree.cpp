// Dynamic AABB tree broad phase (after Box2D's b2DynamicTree and Bullet's
// btDbvt), in 3D.
//
// Data layout, hot and cold apart:
//  - `nodes_`: 32-byte nodes, two per cache line: the fat box as six floats
//    rounded outwards (it only has to contain the exact box), child1 and
//    child2; a leaf has child1 = −1 and its proxy id in child2. The tree
//    walks touch nothing else.
//  - `parent_` and `height_` (0 for a leaf, −1 while free) by node, used
//    when the tree changes; the free list is threaded through `parent_`.
//  - by proxy id: `real_`, the exact box (six doubles, what the reported
//    pairs are tested on), `fat_`, a copy of the leaf's fat box (so update()
//    reads only id-ordered memory), `leafOf_` (the leaf node, kAbsent, or
//    kParked for an id whose box is not finite and lives outside the tree)
//    and a `dirty_` flag. A leaf keeps its node while it moves (a rebuild,
//    below, renumbers every node).
//
// Fat boxes: a (re)inserted leaf stores its box enlarged on each side by
// options.fatMargin times its largest edge, and further, along each axis in
// the direction it last moved, by kPredict times that displacement (at most
// its largest edge; Box2D's aabbMultiplier is 4, 8 measured better in
// Bench/collide_broadphase_bench) — a box in steady motion stays inside its
// fat box about kPredict steps longer. A box that leaves its fat box is
// removed and inserted again. Insertion descends by the surface-area cost of
// Box2D (create a new parent here, or push the box down the cheaper child)
// and the path back to the root is re-balanced with AVL rotations, so the
// height stays O(log n) even for many identical boxes. Trees grown that
// way, one box at a time in no spatial order, are loose (a partner query
// visited ~250 nodes in the 100k-box bench, ~80 on a rebuilt tree), so once
// half as many leaves as there are proxies have been inserted since the last
// rebuild, overlappingPairs() rebuilds the tree top down (median split along
// the longest axis of the centres) and stores it depth first: O(n log n) per
// n/2 insertions, O(log n) amortized per insertion.
//
// Pairs, maintained incrementally: `pairs_`, the sorted list of the id pairs
// whose fat boxes overlap. Fat boxes change only when a leaf is (re)inserted
// or removed, which marks its id dirty. Each step drops every pair with a
// dirty member (a pass over flags, no boxes read), queries the tree once per
// dirty leaf for its current fat partners (a partner that is itself dirty
// and has the smaller id finds the pair instead; the queries run in Morton
// order of the boxes so that consecutive ones share cached upper nodes),
// radix-sorts those and merges them in; the reported pairs are those of the
// list whose exact boxes overlap, already in order. Cost per step:
// O(moved · log n + fat pairs); memory O(n + fat pairs).
#include <dm/core/assert.hpp>
#include <dm/math/float_bounds.hpp>

#include <algorithm>
#include <cfloat>
#include <cmath>

#include "broadphase_impl.hpp"

namespace dm::detail {

namespace {

constexpr std::int32_t kNull = -1;
constexpr std::int32_t kAbsent = -1;
constexpr std::int32_t kParked = -2;
/// Fat boxes reach this many last displacements ahead of a moving box.
constexpr double kPredict = 8.0;

/// A box as six floats; the tree's boxes.
struct FBox {
  float lo[3], hi[3];
};

inline FBox merged(const FBox& a, const FBox& b) noexcept {
  FBox r;
  for (int k = 0; k < 3; ++k) r.lo[k] = std::min(a.lo[k], b.lo[k]), r.hi[k] = std::max(a.hi[k], b.hi[k]);
  return r;
}

/// Half the surface area: the insertion cost measure.
inline double area(const FBox& b) noexcept {
  const double x = double(b.hi[0]) - b.lo[0], y = double(b.hi[1]) - b.lo[1], z = double(b.hi[2]) - b.lo[2];
  return x * y + y * z + z * x;
}

inline bool contains(const FBox& outer, const FlatBox& inner) noexcept {
  return outer.lo[0] <= inner.lo[0] && outer.lo[1] <= inner.lo[1] && outer.lo[2] <= inner.lo[2] &&
         inner.hi[0] <= outer.hi[0] && inner.hi[1] <= outer.hi[1] && inner.hi[2] <= outer.hi[2];
}

inline bool overlapF(const FBox& a, const FBox& b) noexcept {
  return a.lo[0] <= b.hi[0] && b.lo[0] <= a.hi[0] && a.lo[1] <= b.hi[1] && b.lo[1] <= a.hi[1] &&
         a.lo[2] <= b.hi[2] && b.lo[2] <= a.hi[2];
}

inline bool overlapFD(const FBox& a, const FlatBox& b) noexcept {
  return a.lo[0] <= b.hi[0] && b.lo[0] <= a.hi[0] && a.lo[1] <= b.hi[1] && b.lo[1] <= a.hi[1] &&
         a.lo[2] <= b.hi[2] && b.lo[2] <= a.hi[2];
}

/// The low 10 bits of v spread to every third bit (a Morton code axis).
inline std::uint64_t spreadBits(std::uint32_t v) noexcept {
  std::uint64_t x = v & 0x3ffu;
  x = (x | (x << 16)) & 0x30000ffull;
  x = (x | (x << 8)) & 0x300f00full;
  x = (x | (x << 4)) & 0x30c30c3ull;
  x = (x | (x << 2)) & 0x9249249ull;
  return x;
}

struct alignas(32) Node {
  FBox box;             // fat box of a leaf, union of the children otherwise
  std::int32_t child1;  // kNull for a leaf
  std::int32_t child2;  // a leaf's proxy id
  bool leaf() const noexcept { return child1 < 0; }
};
static_assert(sizeof(Node) == 32, "two nodes per cache line");

class DynamicAabbTreeBroadPhase final : public BroadPhase {
 public:
  explicit DynamicAabbTreeBroadPhase(const BroadPhaseOptions& options)
      : margin_(options.fatMargin > 0 && options.fatMargin < 1e6 ? options.fatMargin : 0.0) {}

  BroadPhaseKind kind() const noexcept override { return BroadPhaseKind::DynamicAabbTree; }

  void insert(ProxyId id, const Aabb& box) override {
    if (id < leafOf_.size() && leafOf_[id] != kAbsent) {
      DM_ASSERT(false, "broad phase: proxy id inserted twice");
      update(id, box);
      return;
    }
    if (id >= leafOf_.size()) {
      const std::size_t n = std::size_t(id) + 1;
      leafOf_.resize(n, kAbsent);
      real_.resize(n);
      fat_.resize(n);
      dirty_.resize(n, 0);
    }
    ++count_;
    const FlatBox b = toFlatBox(box);
    real_[id] = b;
    leafOf_[id] = isUsableBox(box) ? createLeaf(id, b) : kParked;
    markDirty(id);
  }

  void update(ProxyId id, const Aabb& box) override {
    if (id >= leafOf_.size() || leafOf_[id] == kAbsent) return;
    const std::int32_t leaf = leafOf_[id];
    const FlatBox b = toFlatBox(box);
    if (!isUsableBox(box)) {
      real_[id] = b;
      if (leaf != kParked) {
        removeLeaf(leaf);
        freeNode(leaf);
        leafOf_[id] = kParked;
        markDirty(id);
      }
      return;
    }
    if (leaf == kParked) {
      real_[id] = b;
      leafOf_[id] = createLeaf(id, b);
      markDirty(id);
      return;
    }
    const FlatBox old = real_[id];
    real_[id] = b;
    if (contains(fat_[id], b)) return;
    removeLeaf(leaf);
    setFat(leaf, id, b, &old);
    insertLeaf(leaf);
    markDirty(id);
  }

  void remove(ProxyId id) override {
    if (id >= leafOf_.size() || leafOf_[id] == kAbsent) return;
    const std::int32_t leaf = leafOf_[id];
    if (leaf != kParked) {
      removeLeaf(leaf);
      freeNode(leaf);
    }
    leafOf_[id] = kAbsent;
    markDirty(id);
    --count_;
  }

  void clear() override { *this = DynamicAabbTreeBroadPhase(BroadPhaseOptions{0.0, margin_}); }

  std::size_t size() const noexcept override { return count_; }

  void overlappingPairs(std::vector<ProxyPair>& out) override {
    if (insertions_ >= std::max<std::size_t>(64, count_ / 2)) rebuild();
    if (!moved_.empty()) {
      // Fat pairs of dirty ids are found again below (or are gone).
      kept_.clear();
      for (std::uint64_t key : pairs_)
        if (!dirty_[key >> 32] && !dirty_[key & 0xffffffffu]) kept_.push_back(key);
      // Query in Morton order of the fat boxes' centres: consecutive queries
      // then walk mostly the same upper nodes, which stay in cache.
      order_.clear();
      if (root_ != kNull) {
        const FBox& r = nodes_[root_].box;
        double lo[3], scale[3];
        for (int k = 0; k < 3; ++k) {
          lo[k] = r.lo[k];
          const double extent = double(r.hi[k]) - r.lo[k];
          scale[k] = extent > 0 && extent < INFINITY ? 1023.0 / extent : 0.0;
        }
        for (ProxyId id : moved_) {
          if (leafOf_[id] < 0) continue;
          const FBox& f = fat_[id];
          std::uint64_t code = 0;
          for (int k = 0; k < 3; ++k) {
            const double c = (0.5 * (double(f.lo[k]) + f.hi[k]) - lo[k]) * scale[k];
            code |= spreadBits(c >= 0 && c <= 1023.0 ? static_cast<std::uint32_t>(c) : 0u) << k;
          }
          order_.push_back((code << 32) | id);
        }
        sortPairKeys(order_, scratch_);
      }
      fresh_.clear();
      for (std::uint64_t key : order_) {
        const auto id = static_cast<ProxyId>(key & 0xffffffffu);
        findPartners(id, fat_[id]);
      }
      for (ProxyId id : moved_) dirty_[id] = 0;
      moved_.clear();
      sortPairKeys(fresh_, scratch_);
      pairs_.resize(kept_.size() + fresh_.size());
      std::merge(kept_.begin(), kept_.end(), fresh_.begin(), fresh_.end(), pairs_.begin());
    }
    // The pairs whose exact boxes overlap, in the list's (ascending) order.
    out.clear();
    for (std::uint64_t key : pairs_) {
      const auto a = static_cast<ProxyId>(key >> 32), b = static_cast<ProxyId>(key & 0xffffffffu);
      if (overlap(real_[a], real_[b])) out.push_back({a, b});
    }
  }

  void query(const Aabb& box, std::vector<ProxyId>& out) const override {
    out.clear();
    if (root_ == kNull) return;
    const FlatBox q = toFlatBox(box);
    std::vector<std::int32_t> stack = {root_};
    while (!stack.empty()) {
      const std::int32_t i = stack.back();
      stack.pop_back();
      const Node& n = nodes_[i];
      if (!overlapFD(n.box, q)) continue;
      if (n.leaf()) {
        const auto id = static_cast<ProxyId>(n.child2);
        if (overlap(real_[id], q)) out.push_back(id);
      } else {
        stack.push_back(n.child1);
        stack.push_back(n.child2);
      }
    }
    std::sort(out.begin(), out.end());
  }

 private:
  // Appends to fresh_ the keys of id's fat partners that id reports.
  void findPartners(ProxyId id, const FBox& fat) {
    stack_.clear();
    stack_.push_back(root_);
    while (!stack_.empty()) {
      const std::int32_t i = stack_.back();
      stack_.pop_back();
      const Node& n = nodes_[i];
      if (!overlapF(n.box, fat)) continue;
      if (!n.leaf()) {
        stack_.push_back(n.child1);
        stack_.push_back(n.child2);
        continue;
      }
      const auto other = static_cast<ProxyId>(n.child2);
      if (other != id && !(dirty_[other] && other < id)) fresh_.push_back(pairKey(id, other));
    }
  }

  // Rebuilds the tree top down from its leaves' fat boxes, splitting at the
  // median centre along the longest axis of the centres' bounds, and stores
  // it depth first (a subtree is one run of memory). O(n log n).
  void rebuild() {
    insertions_ = 0;
    items_.clear();
    for (ProxyId id = 0; id < leafOf_.size(); ++id) {
      if (leafOf_[id] < 0) continue;
      const FBox& f = fat_[id];
      Item it{{}, id};
      for (int k = 0; k < 3; ++k) {
        const double c = 0.5 * (double(f.lo[k]) + double(f.hi[k]));
        it.c[k] = c == c ? c : 0.0;  // −∞ + ∞ on a huge box: any order will do
      }
      items_.push_back(it);
    }
    const std::size_t n = items_.size();
    nodes_.assign(n == 0 ? 0 : 2 * n - 1, Node{});
    parent_.assign(nodes_.size(), kNull);
    height_.assign(nodes_.size(), 0);
    free_ = kNull;
    next_ = 0;
    root_ = n == 0 ? kNull : build(0, n, kNull);
  }

  std::int32_t build(std::size_t begin, std::size_t end, std::int32_t parent) {
    const auto index = static_cast<std::int32_t>(next_++);
    parent_[index] = parent;
    Node& node = nodes_[index];
    if (end - begin == 1) {
      const ProxyId id = items_[begin].id;
      node.box = fat_[id];
      node.child1 = kNull;
      node.child2 = static_cast<std::int32_t>(id);
      leafOf_[id] = index;
      return index;
    }
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (std::size_t i = begin; i < end; ++i)
      for (int k = 0; k < 3; ++k)
        lo[k] = std::min(lo[k], items_[i].c[k]), hi[k] = std::max(hi[k], items_[i].c[k]);
    int axis = 0;
    for (int k = 1; k < 3; ++k)
      if (hi[k] - lo[k] > hi[axis] - lo[axis]) axis = k;
    const std::size_t mid = begin + (end - begin) / 2;
    std::nth_element(items_.begin() + std::ptrdiff_t(begin), items_.begin() + std::ptrdiff_t(mid),
                     items_.begin() + std::ptrdiff_t(end),
                     [axis](const Item& a, const Item& b) { return a.c[axis] < b.c[axis]; });
    const std::int32_t c1 = build(begin, mid, index);
    const std::int32_t c2 = build(mid, end, index);
    Node& n = nodes_[index];
    n.child1 = c1;
    n.child2 = c2;
    n.box = merged(nodes_[c1].box, nodes_[c2].box);
    height_[index] = 1 + std::max(height_[c1], height_[c2]);
    return index;
  }

  // Stores the fat box of `b` in leaf and fat_[id]; `old` (the previous
  // exact box, or null) gives the displacement to predict along.
  void setFat(std::int32_t leaf, ProxyId id, const FlatBox& b, const FlatBox* old) {
    const double edge = std::max({b.hi[0] - b.lo[0], b.hi[1] - b.lo[1], b.hi[2] - b.lo[2]});
    double m = margin_ * edge;
    if (!(m >= 0)) m = 0;  // 0 · ∞ for an edge that overflows
    FBox f;
    for (int k = 0; k < 3; ++k) {
      double lo = b.lo[k] - m, hi = b.hi[k] + m;
      if (old && m > 0) {
        const double d = kPredict * 0.5 * ((b.lo[k] - old->lo[k]) + (b.hi[k] - old->hi[k]));
        if (d > 0) hi += std::min(d, edge);
        if (d < 0) lo += std::max(d, -edge);
      }
      f.lo[k] = floatDown(lo);
      f.hi[k] = floatUp(hi);
    }
    nodes_[leaf].box = f;
    fat_[id] = f;
  }

  std::int32_t allocNode() {
    if (free_ == kNull) {
      DM_DEMAND(nodes_.size() < 0x7fffffffu, "dynamic AABB tree: too many nodes");
      nodes_.push_back({});
      parent_.push_back(kNull);
      height_.push_back(-1);
      free_ = static_cast<std::int32_t>(nodes_.size() - 1);
    }
    const std::int32_t i = free_;
    free_ = parent_[i];
    parent_[i] = nodes_[i].child1 = nodes_[i].child2 = kNull;
    height_[i] = 0;
    return i;
  }

  void freeNode(std::int32_t i) {
    parent_[i] = free_;
    height_[i] = -1;
    free_ = i;
  }

  void markDirty(ProxyId id) {
    if (dirty_[id]) return;
    dirty_[id] = 1;
    moved_.push_back(id);
  }

  std::int32_t createLeaf(ProxyId id, const FlatBox& b) {
    const std::int32_t leaf = allocNode();
    nodes_[leaf].child2 = static_cast<std::int32_t>(id);
    setFat(leaf, id, b, nullptr);
    insertLeaf(leaf);
    return leaf;
  }

  void insertLeaf(std::int32_t leaf) {
    if (root_ == kNull) {
      root_ = leaf;
      parent_[leaf] = kNull;
      return;
    }
    ++insertions_;
    const FBox leafBox = nodes_[leaf].box;
    std::int32_t index = root_;
    while (!nodes_[index].leaf()) {
      const Node& n = nodes_[index];
      const double combinedArea = area(merged(n.box, leafBox));
      // Cost of a new parent of this node and the leaf, and the area every
      // ancestor below would gain if the leaf goes further down.
      const double cost = 2.0 * combinedArea;
      const double inheritance = 2.0 * (combinedArea - area(n.box));
      auto descendCost = [&](std::int32_t c) {
        const Node& cn = nodes_[c];
        const double grown = area(merged(leafBox, cn.box));
        return (cn.leaf() ? grown : grown - area(cn.box)) + inheritance;
      };
      const double cost1 = descendCost(n.child1), cost2 = descendCost(n.child2);
      if (cost < cost1 && cost < cost2) break;
      index = cost1 < cost2 ? n.child1 : n.child2;
    }
    const std::int32_t sibling = index;
    const std::int32_t oldParent = parent_[sibling];
    const std::int32_t newParent = allocNode();
    Node& p = nodes_[newParent];
    parent_[newParent] = oldParent;
    p.box = merged(leafBox, nodes_[sibling].box);
    height_[newParent] = height_[sibling] + 1;
    p.child1 = sibling;
    p.child2 = leaf;
    if (oldParent != kNull) {
      if (nodes_[oldParent].child1 == sibling) {
        nodes_[oldParent].child1 = newParent;
      } else {
        nodes_[oldParent].child2 = newParent;
      }
    } else {
      root_ = newParent;
    }
    parent_[sibling] = newParent;
    parent_[leaf] = newParent;
    refitUpwards(newParent);
  }

  void removeLeaf(std::int32_t leaf) {
    if (leaf == root_) {
      root_ = kNull;
      return;
    }
    const std::int32_t parent = parent_[leaf];
    const std::int32_t grandParent = parent_[parent];
    const std::int32_t sibling =
        nodes_[parent].child1 == leaf ? nodes_[parent].child2 : nodes_[parent].child1;
    freeNode(parent);
    if (grandParent == kNull) {
      root_ = sibling;
      parent_[sibling] = kNull;
      return;
    }
    if (nodes_[grandParent].child1 == parent) {
      nodes_[grandParent].child1 = sibling;
    } else {
      nodes_[grandParent].child2 = sibling;
    }
    parent_[sibling] = grandParent;
    refitUpwards(grandParent);
  }

  // Re-balances and refits every node from `index` to the root.
  void refitUpwards(std::int32_t index) {
    while (index != kNull) {
      index = balance(index);
      Node& n = nodes_[index];
      height_[index] = 1 + std::max(height_[n.child1], height_[n.child2]);
      n.box = merged(nodes_[n.child1].box, nodes_[n.child2].box);
      index = parent_[index];
    }
  }

  void replaceChild(std::int32_t parent, std::int32_t oldChild, std::int32_t newChild) {
    if (parent == kNull) {
      root_ = newChild;
    } else if (nodes_[parent].child1 == oldChild) {
      nodes_[parent].child1 = newChild;
    } else {
      nodes_[parent].child2 = newChild;
    }
  }

  // AVL rotation at `iA` when its children's heights differ by more than 1;
  // returns the node now at A's place.
  std::int32_t balance(std::int32_t iA) {
    if (height_[iA] < 2) return iA;
    const std::int32_t iB = nodes_[iA].child1, iC = nodes_[iA].child2;
    const std::int32_t diff = height_[iC] - height_[iB];
    if (diff > 1) return rotateUp(iA, iC, iB, true);
    if (diff < -1) return rotateUp(iA, iB, iC, false);
    return iA;
  }

  // Puts A's child `iU` (its second child when `second`, else its first) in
  // A's place: A becomes U's first child and keeps `iOther`; U keeps its
  // taller child and hands the shorter one to A. Returns iU.
  std::int32_t rotateUp(std::int32_t iA, std::int32_t iU, std::int32_t iOther, bool second) {
    Node& A = nodes_[iA];
    Node& U = nodes_[iU];
    const std::int32_t i1 = U.child1, i2 = U.child2;
    U.child1 = iA;
    parent_[iU] = parent_[iA];
    parent_[iA] = iU;
    replaceChild(parent_[iU], iA, iU);
    const bool keep1 = height_[i1] > height_[i2];
    const std::int32_t iUp = keep1 ? i1 : i2, iDown = keep1 ? i2 : i1;
    U.child2 = iUp;
    (second ? A.child2 : A.child1) = iDown;
    parent_[iDown] = iA;
    A.box = merged(nodes_[iOther].box, nodes_[iDown].box);
    U.box = merged(A.box, nodes_[iUp].box);
    height_[iA] = 1 + std::max(height_[iOther], height_[iDown]);
    height_[iU] = 1 + std::max(height_[iA], height_[iUp]);
    return iU;
  }

  double margin_;
  std::vector<Node> nodes_;
  std::vector<std::int32_t> parent_, height_;  // by node
  std::vector<std::int32_t> leafOf_;           // by id: leaf node, kAbsent or kParked
  std::vector<FlatBox> real_;                  // by id: exact box
  std::vector<FBox> fat_;                      // by id: the leaf's fat box
  std::vector<unsigned char> dirty_;           // by id: listed in moved_
  std::vector<ProxyId> moved_;                 // ids (re)inserted, parked or removed
  std::vector<std::int32_t> stack_;
  std::vector<std::uint64_t> pairs_;  // sorted id-pair keys whose fat boxes overlap
  std::vector<std::uint64_t> kept_, fresh_, order_, scratch_;
  struct Item {
    double c[3];  // fat box centre
    ProxyId id;
  };
  std::vector<Item> items_;     // rebuild() working memory
  std::size_t next_ = 0;        // rebuild(): next node
  std::size_t insertions_ = 0;  // leaves inserted since the last rebuild()
  std::int32_t root_ = kNull;
  std::int32_t free_ = kNull;
  std::size_t count_ = 0;
};

}  // namespace

std::unique_ptr<BroadPhase> makeDynamicAabbTree(const BroadPhaseOptions& options) {
  return std::make_unique<DynamicAabbTreeBroadPhase>(options);
}

}  // namespace dm::detail
