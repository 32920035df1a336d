// Dynamic AABB tree broad phase (after Box2D's b2DynamicTree and Bullet's
// btDbvt), in 3D with doubles.
//
// Data layout: one array of 128-byte, cache-line aligned nodes {fat box,
// exact box of a leaf (six doubles each), parent or next-free, child1,
// child2 (−1 for a leaf), height (0 for a leaf), proxy id, moved flag} with
// a free list threaded through `parent`; `leafOf_` maps a proxy id to its
// leaf node (or kParked for an id whose box is not finite, which lives
// outside the tree). A leaf keeps its node while it moves.
//
// Leaves store "fat" boxes, enlarged on each side by options.fatMargin times
// the box's largest edge, so a box that moves a little stays inside its fat
// box and needs no tree change; one that leaves it is removed and inserted
// again. Insertion descends by the surface-area cost of Box2D (create a new
// parent here, or push the box down the cheaper child) and the path back to
// the root is re-balanced with AVL rotations, so the height stays O(log n)
// even for many identical boxes.
//
// Pairs (as in Box2D): a persistent hash set of the leaf-node pairs whose
// fat boxes overlap. Fat boxes change only when a leaf is (re)inserted, so only
// those leaves ("moved", listed once each) query the tree for new partners;
// every step one pass over the set drops the pairs whose fat boxes parted or
// whose proxies left, and reports those whose exact boxes overlap. Cost per
// step: O(moved · log n + fat pairs); memory O(n + fat pairs).
#include <dm/core/assert.hpp>

#include <algorithm>

#include "broadphase_impl.hpp"

namespace dm::detail {

namespace {

constexpr std::int32_t kNull = -1;
constexpr std::int32_t kAbsent = -1;
constexpr std::int32_t kParked = -2;

using Box = FlatBox;

inline Box merged(const Box& a, const Box& b) noexcept {
  Box r;
  for (int k = 0; k < 3; ++k) r.lo[k] = std::min(a.lo[k], b.lo[k]), r.hi[k] = std::max(a.hi[k], b.hi[k]);
  return r;
}

/// Half the surface area: the insertion cost measure.
inline double area(const Box& b) noexcept {
  const double x = b.hi[0] - b.lo[0], y = b.hi[1] - b.lo[1], z = b.hi[2] - b.lo[2];
  return x * y + y * z + z * x;
}

inline bool contains(const Box& outer, const Box& inner) noexcept {
  return outer.lo[0] <= inner.lo[0] && outer.lo[1] <= inner.lo[1] && outer.lo[2] <= inner.lo[2] &&
         inner.hi[0] <= outer.hi[0] && inner.hi[1] <= outer.hi[1] && inner.hi[2] <= outer.hi[2];
}

struct alignas(64) Node {
  Box box;              // fat box of a leaf, union of the children otherwise
  Box real;             // leaf: the exact box
  std::int32_t parent;  // next free node while on the free list
  std::int32_t child1;  // kNull for a leaf
  std::int32_t child2;
  std::int32_t height;  // 0 for a leaf, −1 while free
  ProxyId id;
  std::uint32_t moved;  // leaf: (re)inserted since the last overlappingPairs()
};

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
    if (id >= leafOf_.size()) leafOf_.resize(std::size_t(id) + 1, kAbsent);
    ++count_;
    leafOf_[id] = isUsableBox(box) ? createLeaf(id, toFlatBox(box)) : kParked;
  }

  void update(ProxyId id, const Aabb& box) override {
    if (id >= leafOf_.size() || leafOf_[id] == kAbsent) return;
    const std::int32_t leaf = leafOf_[id];
    if (!isUsableBox(box)) {
      if (leaf != kParked) {
        removeLeaf(leaf);
        freeNode(leaf);
        leafOf_[id] = kParked;
      }
      return;
    }
    const Box b = toFlatBox(box);
    if (leaf == kParked) {
      leafOf_[id] = createLeaf(id, b);
      return;
    }
    nodes_[leaf].real = b;
    if (contains(nodes_[leaf].box, b)) return;
    removeLeaf(leaf);
    nodes_[leaf].box = fatten(b);
    insertLeaf(leaf);
    markMoved(leaf);
  }

  void remove(ProxyId id) override {
    if (id >= leafOf_.size() || leafOf_[id] == kAbsent) return;
    const std::int32_t leaf = leafOf_[id];
    if (leaf != kParked) {
      removeLeaf(leaf);
      freeNode(leaf);
    }
    leafOf_[id] = kAbsent;
    --count_;
  }

  void clear() override {
    nodes_.clear();
    leafOf_.clear();
    root_ = kNull;
    free_ = kNull;
    count_ = 0;
    fatPairs_.clear();
    moved_.clear();
  }

  std::size_t size() const noexcept override { return count_; }

  void overlappingPairs(std::vector<ProxyPair>& out) override {
    // New pairs of fat boxes: only a (re)inserted leaf can start one.
    for (ProxyId id : moved_) {
      const std::int32_t leaf = leafOf_[id];
      if (leaf < 0 || !nodes_[leaf].moved) continue;
      nodes_[leaf].moved = 0;
      const Box fat = nodes_[leaf].box;
      stack_.clear();
      stack_.push_back(root_);
      while (!stack_.empty()) {
        const std::int32_t i = stack_.back();
        stack_.pop_back();
        const Node& n = nodes_[i];
        if (!overlap(n.box, fat)) continue;
        if (n.height > 0) {
          stack_.push_back(n.child1);
          stack_.push_back(n.child2);
        } else if (i != leaf) {
          fatPairs_.insert(pairKey(static_cast<std::uint32_t>(leaf), static_cast<std::uint32_t>(i)));
        }
      }
    }
    moved_.clear();
    // Drop pairs whose fat boxes parted (or whose proxies left the tree);
    // report the remaining pairs whose exact boxes overlap. eraseIf may
    // visit a key twice, hence the unique() after sorting.
    keys_.clear();
    fatPairs_.eraseIf([&](std::uint64_t key) {
      // A freed node has height −1 and a reused one is a leaf whose pairs
      // are as valid as any: only "both leaves with overlapping fat boxes"
      // keeps a pair.
      const Node& a = nodes_[key >> 32];
      const Node& b = nodes_[key & 0xffffffffu];
      if (a.height != 0 || b.height != 0 || !overlap(a.box, b.box)) return true;
      if (overlap(a.real, b.real)) keys_.push_back(pairKey(a.id, b.id));
      return false;
    });
    emitSortedPairs(keys_, scratch_, out);
    out.erase(std::unique(out.begin(), out.end()), out.end());
  }

  void query(const Aabb& box, std::vector<ProxyId>& out) const override {
    out.clear();
    if (root_ == kNull) return;
    const Box q = toFlatBox(box);
    std::vector<std::int32_t> stack = {root_};
    while (!stack.empty()) {
      const std::int32_t i = stack.back();
      stack.pop_back();
      const Node& n = nodes_[i];
      if (!overlap(n.box, q)) continue;
      if (n.height == 0) {
        if (overlap(n.real, q)) out.push_back(n.id);
      } else {
        stack.push_back(n.child1);
        stack.push_back(n.child2);
      }
    }
    std::sort(out.begin(), out.end());
  }

 private:
  Box fatten(const Box& b) const noexcept {
    const double m = margin_ * std::max({b.hi[0] - b.lo[0], b.hi[1] - b.lo[1], b.hi[2] - b.lo[2]});
    if (!(m >= 0)) return b;  // 0 · ∞ for an edge that overflows
    Box f = b;
    for (int k = 0; k < 3; ++k) f.lo[k] -= m, f.hi[k] += m;
    return f;
  }

  std::int32_t allocNode() {
    if (free_ == kNull) {
      DM_DEMAND(nodes_.size() < 0x7fffffffu, "dynamic AABB tree: too many nodes");
      nodes_.push_back({});
      nodes_.back().parent = kNull;
      free_ = static_cast<std::int32_t>(nodes_.size() - 1);
    }
    const std::int32_t i = free_;
    free_ = nodes_[i].parent;
    nodes_[i].parent = nodes_[i].child1 = nodes_[i].child2 = kNull;
    nodes_[i].height = 0;
    nodes_[i].moved = 0;
    return i;
  }

  void freeNode(std::int32_t i) {
    nodes_[i].parent = free_;
    nodes_[i].height = -1;
    free_ = i;
  }

  void markMoved(std::int32_t leaf) {
    if (nodes_[leaf].moved) return;
    nodes_[leaf].moved = 1;
    moved_.push_back(nodes_[leaf].id);
  }

  std::int32_t createLeaf(ProxyId id, const Box& b) {
    const std::int32_t leaf = allocNode();
    nodes_[leaf].id = id;
    nodes_[leaf].box = fatten(b);
    nodes_[leaf].real = b;
    insertLeaf(leaf);
    markMoved(leaf);
    return leaf;
  }

  void insertLeaf(std::int32_t leaf) {
    if (root_ == kNull) {
      root_ = leaf;
      nodes_[leaf].parent = kNull;
      return;
    }
    const Box leafBox = nodes_[leaf].box;
    std::int32_t index = root_;
    while (nodes_[index].height > 0) {
      const Node& n = nodes_[index];
      const double combinedArea = area(merged(n.box, leafBox));
      // Cost of a new parent of this node and the leaf, and the area every
      // ancestor below would gain if the leaf goes further down.
      const double cost = 2.0 * combinedArea;
      const double inheritance = 2.0 * (combinedArea - area(n.box));
      auto descendCost = [&](std::int32_t c) {
        const Node& cn = nodes_[c];
        const double grown = area(merged(leafBox, cn.box));
        return (cn.height == 0 ? grown : grown - area(cn.box)) + inheritance;
      };
      const double cost1 = descendCost(n.child1), cost2 = descendCost(n.child2);
      if (cost < cost1 && cost < cost2) break;
      index = cost1 < cost2 ? n.child1 : n.child2;
    }
    const std::int32_t sibling = index;
    const std::int32_t oldParent = nodes_[sibling].parent;
    const std::int32_t newParent = allocNode();
    Node& p = nodes_[newParent];
    p.parent = oldParent;
    p.box = merged(leafBox, nodes_[sibling].box);
    p.height = nodes_[sibling].height + 1;
    p.child1 = sibling;
    p.child2 = leaf;
    p.id = 0;
    if (oldParent != kNull) {
      if (nodes_[oldParent].child1 == sibling) {
        nodes_[oldParent].child1 = newParent;
      } else {
        nodes_[oldParent].child2 = newParent;
      }
    } else {
      root_ = newParent;
    }
    nodes_[sibling].parent = newParent;
    nodes_[leaf].parent = newParent;
    refitUpwards(newParent);
  }

  void removeLeaf(std::int32_t leaf) {
    if (leaf == root_) {
      root_ = kNull;
      return;
    }
    const std::int32_t parent = nodes_[leaf].parent;
    const std::int32_t grandParent = nodes_[parent].parent;
    const std::int32_t sibling =
        nodes_[parent].child1 == leaf ? nodes_[parent].child2 : nodes_[parent].child1;
    freeNode(parent);
    if (grandParent == kNull) {
      root_ = sibling;
      nodes_[sibling].parent = kNull;
      return;
    }
    if (nodes_[grandParent].child1 == parent) {
      nodes_[grandParent].child1 = sibling;
    } else {
      nodes_[grandParent].child2 = sibling;
    }
    nodes_[sibling].parent = grandParent;
    refitUpwards(grandParent);
  }

  // Re-balances and refits every node from `index` to the root.
  void refitUpwards(std::int32_t index) {
    while (index != kNull) {
      index = balance(index);
      Node& n = nodes_[index];
      n.height = 1 + std::max(nodes_[n.child1].height, nodes_[n.child2].height);
      n.box = merged(nodes_[n.child1].box, nodes_[n.child2].box);
      index = n.parent;
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
    Node& A = nodes_[iA];
    if (A.height < 2) return iA;
    const std::int32_t iB = A.child1, iC = A.child2;
    Node& B = nodes_[iB];
    Node& C = nodes_[iC];
    const std::int32_t diff = C.height - B.height;
    if (diff > 1) {  // rotate C up
      const std::int32_t iF = C.child1, iG = C.child2;
      Node& F = nodes_[iF];
      Node& G = nodes_[iG];
      C.child1 = iA;
      C.parent = A.parent;
      A.parent = iC;
      replaceChild(C.parent, iA, iC);
      if (F.height > G.height) {
        C.child2 = iF;
        A.child2 = iG;
        G.parent = iA;
        A.box = merged(B.box, G.box);
        C.box = merged(A.box, F.box);
        A.height = 1 + std::max(B.height, G.height);
        C.height = 1 + std::max(A.height, F.height);
      } else {
        C.child2 = iG;
        A.child2 = iF;
        F.parent = iA;
        A.box = merged(B.box, F.box);
        C.box = merged(A.box, G.box);
        A.height = 1 + std::max(B.height, F.height);
        C.height = 1 + std::max(A.height, G.height);
      }
      return iC;
    }
    if (diff < -1) {  // rotate B up
      const std::int32_t iD = B.child1, iE = B.child2;
      Node& D = nodes_[iD];
      Node& E = nodes_[iE];
      B.child1 = iA;
      B.parent = A.parent;
      A.parent = iB;
      replaceChild(B.parent, iA, iB);
      if (D.height > E.height) {
        B.child2 = iD;
        A.child1 = iE;
        E.parent = iA;
        A.box = merged(C.box, E.box);
        B.box = merged(A.box, D.box);
        A.height = 1 + std::max(C.height, E.height);
        B.height = 1 + std::max(A.height, D.height);
      } else {
        B.child2 = iE;
        A.child1 = iD;
        D.parent = iA;
        A.box = merged(C.box, D.box);
        B.box = merged(A.box, E.box);
        A.height = 1 + std::max(C.height, D.height);
        B.height = 1 + std::max(A.height, E.height);
      }
      return iB;
    }
    return iA;
  }

  double margin_;
  std::vector<Node> nodes_;
  std::vector<std::int32_t> leafOf_;  // by id: leaf node, kAbsent or kParked
  std::vector<std::int32_t> stack_;
  std::vector<ProxyId> moved_;  // ids whose leaf was (re)inserted
  PairKeySet fatPairs_;         // leaf node pairs whose fat boxes overlap
  std::vector<std::uint64_t> keys_, scratch_;
  std::int32_t root_ = kNull;
  std::int32_t free_ = kNull;
  std::size_t count_ = 0;
};

}  // namespace

std::unique_ptr<BroadPhase> makeDynamicAabbTree(const BroadPhaseOptions& options) {
  return std::make_unique<DynamicAabbTreeBroadPhase>(options);
}

}  // namespace dm::detail
