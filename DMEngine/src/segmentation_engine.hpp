// segmentation_engine.hpp (private) — the segmentation engine of a scene run
// (docs/scene-format.md, "Segmentation"): DMVision's haptic-guided
// segmentation (dm::HapticSegmentation) of a volume resource, painted at the
// haptic tool's point `rate_hz` times a second on the engine's own (normal)
// thread, and its guidance force — away from edges, into homogeneous
// tissue — an effect in the haptic loop. The guidance reads only what was
// fixed when the segmentation was built (the edge map, the rays), so the
// haptic thread evaluates it while this engine paints; the tool's point
// comes from the loop's lock-free newest sample. After the run the mask is
// written as segmentation.nii.gz and the summary says what was painted (and,
// with a reference, its precision against an adaptive region grown from the
// seed over the whole volume). Compiled only when DMVision exists.
#pragma once

#include <dm/core/result.hpp>
#include <dm/core/types.hpp>
#include <dm/engine/engine.hpp>

#include <nlohmann/json.hpp>

#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace dm {

class ForceEffect;
struct SceneResources;
struct SceneDesc;

class SegmentationEngineHandle {
 public:
  virtual ~SegmentationEngineHandle() = default;
  virtual std::shared_ptr<Engine> engine() = 0;
  /// The guidance force as an effect for the haptic loop, or null with
  /// "guidance": false. Once, before the run.
  virtual std::unique_ptr<ForceEffect> guidance() = 0;
  /// Where the tool is (world, m), read by each tick on the engine's
  /// thread; before the run.
  virtual void setTool(std::function<Vec3()> tool) = 0;
  /// Control thread, after the run: the mask as `out`/segmentation.nii.gz
  /// (its name added to `written`).
  virtual Status write(const std::filesystem::path& out, std::vector<std::string>& written) = 0;
  /// Control thread, after the run: updates, the window, what was painted,
  /// voxels painted outside the image (value 0), along the tool's path the
  /// mean edge strength and adaptive radius, and the reference's figures.
  virtual nlohmann::json summary() const = 0;
};

/// Builds the segmentation of the scene's engines/segmentation: its volume
/// resource, the window (given, or from the seed's 5×5×5 neighbourhood), the
/// edge map, and the reference region when asked; fails naming the engine's
/// JSON path (a seed outside the volume, an empty window) before anything runs.
Result<std::shared_ptr<SegmentationEngineHandle>> makeSegmentationEngine(const SceneDesc& scene,
                                                                         const SceneResources& resources);

}  // namespace dm
