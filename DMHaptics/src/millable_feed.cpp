// millable_feed.cpp — changed blocks of a millable volume through a
// lock-free queue, and the render side's incremental surface.
#include <dm/haptics/millable_feed.hpp>

#include <algorithm>
#include <new>

namespace dm {

MillableSurfaceFeed::MillableSurfaceFeed(MillableVolume mirror) : mirror_(std::move(mirror)) {}

Result<std::unique_ptr<MillableSurfaceFeed>> MillableSurfaceFeed::create(const MillableVolume& bone,
                                                                         std::vector<Vec4f> materialColors) {
  if (!materialColors.empty() && materialColors.size() < bone.materials().size())
    return fail(ErrorCode::InvalidArgument,
                formatString("%zu colours for %zu materials", materialColors.size(), bone.materials().size()),
                "MillableSurfaceFeed", "give one colour per material, or none");
  try {
    std::unique_ptr<MillableSurfaceFeed> feed(new MillableSurfaceFeed(bone));
    feed->mirror_.clearChanges();
    feed->colors_ = std::move(materialColors);
    const auto blocks = static_cast<std::size_t>(bone.blockDims().prod());
    feed->pieces_.resize(blocks);
    feed->waiting_.reserve(blocks);
    feed->isWaiting_.assign(blocks, 0);
    feed->queue_ = std::make_unique<SpscRing<Snapshot, kQueueBlocks>>();
    return feed;
  } catch (const std::bad_alloc&) {
    return fail(ErrorCode::InvalidArgument, "out of memory copying the millable volume",
                "MillableSurfaceFeed", "use a smaller or coarser volume");
  }
}

void MillableSurfaceFeed::publish(MillableVolume& bone) noexcept {
  for (std::uint32_t b : bone.changedBlocks()) {
    if (b >= isWaiting_.size() || isWaiting_[b]) continue;
    isWaiting_[b] = 1;
    waiting_.push_back(b);  // within the reserved block count: each block waits once
  }
  bone.clearChanges();
  Snapshot s;
  while (sent_ < waiting_.size()) {
    s.block = waiting_[sent_];
    bone.readBlock(s.block, s.voxels);
    if (!queue_->tryPush(s)) break;
    isWaiting_[s.block] = 0;
    ++sent_;
    blocksSent_.fetch_add(1, std::memory_order_relaxed);
  }
  if (sent_ == waiting_.size()) {
    waiting_.clear();
    sent_ = 0;
  } else if (sent_ > 0) {
    waiting_.erase(waiting_.begin(), waiting_.begin() + static_cast<std::ptrdiff_t>(sent_));
    sent_ = 0;
  }
}

Result<bool> MillableSurfaceFeed::update(Mesh& surface) {
  Snapshot s;
  while (queue_->tryPop(s)) mirror_.writeBlock(s.block, s.voxels);
  std::vector<std::uint32_t> remesh;
  if (first_) {
    remesh.resize(pieces_.size());
    for (std::size_t b = 0; b < remesh.size(); ++b) remesh[b] = static_cast<std::uint32_t>(b);
  } else {
    remesh.assign(mirror_.changedBlocks().begin(), mirror_.changedBlocks().end());
  }
  mirror_.clearChanges();
  if (remesh.empty()) return false;
  auto fresh = mirror_.blockSurfaces(remesh, colors_);
  if (!fresh) return fresh.error();
  for (std::size_t n = 0; n < remesh.size(); ++n) pieces_[remesh[n]] = std::move((*fresh)[n]);
  first_ = false;

  std::size_t vertices = 0, triangles = 0;
  for (const Mesh& p : pieces_) {
    vertices += p.positions.size();
    triangles += p.triangles.size();
  }
  surface = Mesh();
  surface.positions.reserve(vertices);
  surface.normals.reserve(vertices);
  surface.triangles.reserve(triangles);
  if (!colors_.empty()) surface.colors.reserve(vertices);
  for (const Mesh& p : pieces_) surface.append(p);
  if (surface.normals.size() != surface.positions.size()) surface.computeNormals();
  return true;
}

}  // namespace dm
