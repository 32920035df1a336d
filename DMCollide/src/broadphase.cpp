// Broad-phase names, the factory, and the brute-force reference every other
// broad phase is tested against.
#include <dm/collide/broadphase.hpp>
#include <dm/core/assert.hpp>

#include <algorithm>
#include <array>
#include <string>

namespace dm {

namespace {

constexpr std::array<std::string_view, 5> kNames = {"brute-force", "sweep-and-prune", "hashed-grid",
                                                    "hierarchical-grid", "dynamic-aabb-tree"};

/// All n(n−1)/2 box tests each step. Boxes live in a dense array indexed by
/// id (ids are the world's dense object indices), with a liveness flag.
class BruteForceBroadPhase final : public BroadPhase {
 public:
  BroadPhaseKind kind() const noexcept override { return BroadPhaseKind::BruteForce; }

  void insert(ProxyId id, const Aabb& box) override {
    if (id >= boxes_.size()) {
      boxes_.resize(id + 1);
      live_.resize(id + 1, 0);
    }
    DM_ASSERT(!live_[id], "broad phase: proxy id inserted twice");
    count_ += live_[id] ? 0 : 1;
    live_[id] = 1;
    boxes_[id] = box;
  }
  void update(ProxyId id, const Aabb& box) override {
    if (id < boxes_.size() && live_[id]) boxes_[id] = box;
  }
  void remove(ProxyId id) override {
    if (id < boxes_.size() && live_[id]) {
      live_[id] = 0;
      --count_;
    }
  }
  void clear() override {
    boxes_.clear();
    live_.clear();
    count_ = 0;
  }
  std::size_t size() const noexcept override { return count_; }

  void overlappingPairs(std::vector<ProxyPair>& out) override {
    out.clear();
    const auto n = static_cast<ProxyId>(boxes_.size());
    for (ProxyId i = 0; i < n; ++i) {
      if (!live_[i]) continue;
      for (ProxyId j = i + 1; j < n; ++j)
        if (live_[j] && boxesOverlap(boxes_[i], boxes_[j])) out.push_back({i, j});
    }
  }
  void query(const Aabb& box, std::vector<ProxyId>& out) const override {
    out.clear();
    for (ProxyId i = 0; i < static_cast<ProxyId>(boxes_.size()); ++i)
      if (live_[i] && boxesOverlap(boxes_[i], box)) out.push_back(i);
  }

 private:
  std::vector<Aabb> boxes_;
  std::vector<unsigned char> live_;
  std::size_t count_ = 0;
};

}  // namespace

std::string_view broadPhaseName(BroadPhaseKind kind) noexcept {
  const auto i = static_cast<std::size_t>(kind);
  return i < kNames.size() ? kNames[i] : std::string_view("unknown");
}

Result<BroadPhaseKind> parseBroadPhaseKind(std::string_view name) {
  for (std::size_t i = 0; i < kNames.size(); ++i)
    if (kNames[i] == name) return static_cast<BroadPhaseKind>(i);
  std::string list;
  for (std::string_view n : kNames) list += (list.empty() ? "" : ", ") + std::string(n);
  return fail(ErrorCode::InvalidArgument, "unknown broad phase '" + std::string(name) + "'", "broad phase",
              "use one of: " + list);
}

std::unique_ptr<BroadPhase> makeBroadPhase(BroadPhaseKind kind, const BroadPhaseOptions& options) {
  (void)options;
  switch (kind) {
    case BroadPhaseKind::BruteForce:
    default:
      return std::make_unique<BruteForceBroadPhase>();
  }
}

}  // namespace dm
