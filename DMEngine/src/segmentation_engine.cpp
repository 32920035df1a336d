// segmentation_engine.cpp — a scene's haptic-guided segmentation
// (segmentation_engine.hpp).
#include "segmentation_engine.hpp"

#include <dm/core/config.hpp>
#include <dm/haptics/effects.hpp>
#include <dm/io/scene_file.hpp>
#include <dm/io/scene_resources.hpp>
#include <dm/io/volume_io.hpp>
#include <dm/vision/region_growing.hpp>
#include <dm/vision/segmentation.hpp>

#include <array>
#include <cmath>
#include <optional>

namespace dm {

namespace {

constexpr const char* kWhere = "engines/segmentation";
constexpr const char* kMaskFile = "segmentation.nii.gz";

Connectivity connectivityOf(int n) {
  return n == 26 ? Connectivity::TwentySix : n == 18 ? Connectivity::Eighteen : Connectivity::Six;
}

class SegmentationEngine final : public Engine, public SegmentationEngineHandle {
 public:
  SegmentationEngine(const SceneSegmentationEngine& desc, std::shared_ptr<const Volume> image,
                     HapticSegmentation segmentation, std::array<double, 2> window,
                     std::optional<RegionGrowResult> reference)
      : desc_(desc),
        image_(std::move(image)),
        seg_(std::move(segmentation)),
        window_(window),
        reference_(std::move(reference)) {}

  std::string_view name() const noexcept override { return "segmentation"; }

  // Paints at the tool's newest point. update() allocates (the growth's
  // queue): this is a normal thread, never the haptic one.
  bool tick(const TickInfo&) noexcept override {
    const Vec3 p = tool_ ? tool_() : Vec3::Constant(std::numeric_limits<double>::quiet_NaN());
    if (!p.allFinite()) return true;  // no sample yet
    try {
      auto u = seg_.update(p);
      if (!u) {
        error_ = u.error().within(kWhere);
        return false;
      }
    } catch (const std::exception& e) {
      error_ = fail(ErrorCode::Internal, e.what(), kWhere);
      return false;
    }
    ++updates_;
    edgeSum_ += seg_.edgeStrength().sampleWorld(p);
    radiusSum_ += seg_.adaptiveRadius(p);
    return true;
  }

  Error error() const override { return error_; }
  std::shared_ptr<Engine> engine() override { return self_.lock(); }

  std::unique_ptr<ForceEffect> guidance() override {
    if (!desc_.guidance) return nullptr;
    const HapticSegmentation* s = &seg_;
    return std::make_unique<ForceFieldEffect>([s](const Vec3& p) { return s->guidanceForce(p); },
                                              "segmentation");
  }

  void setTool(std::function<Vec3()> tool) override { tool_ = std::move(tool); }

  Status write(const std::filesystem::path& out, std::vector<std::string>& written) override {
    if (auto s = writeVolume(seg_.mask(), out / kMaskFile); !s) return s.error().within(kWhere);
    written.emplace_back(kMaskFile);
    return ok();
  }

  nlohmann::json summary() const override {
    const Volume& mask = seg_.mask();
    std::size_t painted = 0, inReference = 0, outside = 0;
    for (std::size_t n = 0; n < mask.voxelCount(); ++n) {
      if (mask.valueAt(n) == 0) continue;
      ++painted;
      outside += image_->valueAt(n) == 0;
      if (reference_) inReference += reference_->mask.valueAt(n) != 0;
    }
    const double n = static_cast<double>(updates_);
    nlohmann::json j = {{"updates", updates_},
                        {"window", {window_[0], window_[1]}},
                        {"painted_voxels", painted},
                        {"painted_ml", seg_.segmentedVolume() * 1e6},
                        {"outside_volume_voxels", outside},
                        {"mean_edge_strength", updates_ ? edgeSum_ / n : 0.0},
                        {"mean_radius_mm", updates_ ? 1e3 * radiusSum_ / n : 0.0},
                        {"guidance", desc_.guidance}};
    if (reference_) {
      j["reference_ml"] = reference_->stats.volumeMl;
      j["precision"] = painted ? static_cast<double>(inReference) / static_cast<double>(painted) : 0.0;
    }
    return j;
  }

  std::weak_ptr<SegmentationEngine> self_;

 private:
  SceneSegmentationEngine desc_;
  std::shared_ptr<const Volume> image_;
  HapticSegmentation seg_;
  std::array<double, 2> window_;
  std::optional<RegionGrowResult> reference_;
  std::function<Vec3()> tool_;
  std::size_t updates_ = 0;
  double edgeSum_ = 0.0, radiusSum_ = 0.0;
  Error error_;
};

}  // namespace

Result<std::shared_ptr<SegmentationEngineHandle>> makeSegmentationEngine(const SceneDesc& scene,
                                                                         const SceneResources& resources) {
  const SceneSegmentationEngine& g = *scene.engines.segmentation;
  auto image = resources.volume(g.volume);
  if (!image)
    return fail(ErrorCode::NotFound, "no volume \"" + g.volume + "\"", std::string(kWhere) + "/volume");
  const auto seed = nearestVoxel(*image, g.seed);
  if (!seed)
    return fail(ErrorCode::InvalidArgument, "the seed lies outside the volume \"" + g.volume + "\"",
                std::string(kWhere) + "/seed", "give a point (m, world) inside the image");
  std::array<double, 2> window{};
  if (g.window) {
    window = *g.window;
  } else {
    // The user's click: the seed's 5×5×5 neighbourhood.
    const NeighbourhoodStats w = neighbourhoodStats(*image, *seed);
    window = {w.mean - g.windowK * w.stddev, w.mean + g.windowK * w.stddev};
  }
  HapticSegmentationOptions so;
  so.edgeSigma = g.edgeSigma;
  so.rayCount = g.rays;
  so.minRadius = g.minRadius;
  so.maxRadius = g.maxRadius;
  so.edgeThreshold = g.edgeThreshold;
  so.gain = g.gain;
  so.maxForce = g.maxForce;
  so.grow = {.lower = window[0], .upper = window[1], .connectivity = connectivityOf(g.connectivity)};
  auto seg = HapticSegmentation::create(*image, so);
  if (!seg) return seg.error().within(kWhere);
  std::optional<RegionGrowResult> reference;
  if (g.referenceK) {
    auto r = growRegion(*image, std::array{*seed},
                        {.adaptive = true, .k = *g.referenceK, .connectivity = Connectivity::TwentySix});
    if (!r) return r.error().within(std::string(kWhere) + "/reference");
    reference = std::move(*r);
  }
  auto e = std::make_shared<SegmentationEngine>(g, std::move(image), std::move(*seg), window,
                                                std::move(reference));
  e->self_ = e;
  return std::shared_ptr<SegmentationEngineHandle>(e);
}

}  // namespace dm
