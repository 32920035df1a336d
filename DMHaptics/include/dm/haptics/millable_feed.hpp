// dm/haptics/millable_feed.hpp — the drilled surface, from the haptic thread
// to a render thread, within one frame.
//
// The haptic thread edits a dm::MillableVolume (BurrRenderer) and may not
// allocate, lock or mesh; the render thread must not read a volume that
// another thread writes. MillableSurfaceFeed keeps a copy of the volume (the
// mirror) for the render side and sends it what changed: after each tick,
// publish() copies the voxels of every block the bone lists as changed into
// a lock-free queue (1 KiB a block) and clears the bone's change set; each
// frame, update() applies what arrived to the mirror, remeshes only the
// pieces that changed (MillableVolume::blockSurfaces) and hands back the
// whole surface. A block that finds the queue full waits in a fixed list
// and goes with a later publish(), with its voxels as they are then, so the
// mirror always catches up and never holds voxels older than what it shows.
//
// @code
//   auto feed = dm::MillableSurfaceFeed::create(burr->volume()).value();
//   // haptic thread, every tick:   burr->tick(in); feed->publish(burr->volume());
//   // render thread, every frame:  dm::Mesh s; if (feed->update(s).value_or(false))
//   view.updateObjectMesh("bone", s);
// @endcode
#pragma once

#include <dm/collide/millable_volume.hpp>
#include <dm/core/mesh.hpp>
#include <dm/core/result.hpp>
#include <dm/core/ring.hpp>

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

namespace dm {

/// Changed blocks of a millable volume, haptic thread → render thread (file
/// comment). One publisher thread and one updater thread.
class MillableSurfaceFeed {
 public:
  /// Blocks the queue holds between a publish() and an update().
  static constexpr std::size_t kQueueBlocks = 1024;

  /// A feed whose mirror is a copy of `bone` as it is now (before the
  /// haptic thread edits it). With `materialColors` (one per material of
  /// the bone) the surface's vertices are coloured by the material they
  /// show (MillableVolume::blockSurfaces). InvalidArgument when out of
  /// memory or for fewer colours than materials.
  static Result<std::unique_ptr<MillableSurfaceFeed>> create(const MillableVolume& bone,
                                                             std::vector<Vec4f> materialColors = {});

  /// Haptic thread, after a tick: queues the blocks `bone` changed (the
  /// volume create() copied) and clears its change set. Never allocates,
  /// locks or throws; what does not fit waits for the next call.
  void publish(MillableVolume& bone) noexcept;
  /// Blocks waiting for room in the queue (publisher thread).
  std::size_t waiting() const noexcept { return waiting_.size() - sent_; }

  /// Render thread: applies the queued blocks to the mirror and remeshes the
  /// changed pieces. On the first call, and whenever a piece changed, sets
  /// `surface` to the whole surface (every block's piece, in block order)
  /// and returns true; otherwise leaves it and returns false. Fails only
  /// when meshing fails (out of memory).
  Result<bool> update(Mesh& surface);
  /// The render side's copy (updater thread).
  const MillableVolume& mirror() const noexcept { return mirror_; }
  /// Blocks sent through the queue so far (any thread).
  std::uint64_t blocksSent() const noexcept { return blocksSent_.load(std::memory_order_relaxed); }

 private:
  struct Snapshot {
    std::uint32_t block = 0;
    std::array<std::uint16_t, MillableVolume::kBlockVoxels> voxels{};
  };
  explicit MillableSurfaceFeed(MillableVolume mirror);

  MillableVolume mirror_;                // updater thread
  std::vector<Mesh> pieces_;             // updater thread, one per block
  std::vector<Vec4f> colors_;            // per material, or empty
  bool first_ = true;                    // updater thread
  std::vector<std::uint32_t> waiting_;   // publisher: capacity = block count
  std::vector<std::uint8_t> isWaiting_;  // publisher
  std::size_t sent_ = 0;                 // publisher: waiting_[0, sent_) went out
  std::unique_ptr<SpscRing<Snapshot, kQueueBlocks>> queue_;
  std::atomic<std::uint64_t> blocksSent_{0};
};

}  // namespace dm
