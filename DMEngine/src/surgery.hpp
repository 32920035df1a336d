// surgery.hpp (private) — what a scene's surgical keys become in a run: the
// millable bone with its critical structures, the burr renderer over it, the
// feed that carries the drilled surface to the render engine, and the burr's
// part of summary.json.
#pragma once

#include <dm/core/result.hpp>
#include <dm/haptics/burr.hpp>
#include <dm/haptics/millable_feed.hpp>

#include <nlohmann/json.hpp>

#include <memory>
#include <string>

namespace dm {

struct SceneDesc;
struct SceneResources;

/// The burr renderer of a scene whose haptics engine has "renderer": "burr".
struct SceneBurrBuild {
  std::unique_ptr<BurrRenderer> renderer;
  std::unique_ptr<MillableSurfaceFeed> feed;  ///< for the render engine
  std::string object;                         ///< the milled object's name
  double initialVolume = 0.0;                 ///< m³ of material before milling
};

/// Voxelizes the milled object's mesh (its scale baked in) at its
/// "voxel_size" into a MillableVolume in the object's frame; every critical
/// and inclusion object's mesh, placed in that frame, becomes a material
/// where it lies inside the grid (forbidden for critical ones; the
/// occupancy there is the union of bone and part; a later part wins where
/// two overlap), and the critical ones together the signed distance the burr
/// measures its approach against. The feed colours the drawn surface by
/// material (each part's scene colour relative to the bone's). Stiffness and
/// damping come from the bone's haptic material; the tool and cutting model
/// from the "burr" block.
Result<SceneBurrBuild> buildSceneBurr(const SceneDesc& scene, const SceneResources& resources);

/// summary.json's "burr": removed volume per material, removed forbidden
/// volume, closest approach to a critical structure and the time within the
/// warning distance, the material's initial and remaining volume, and the
/// blocks sent to the render engine. Control thread, after the run.
nlohmann::json burrSummary(const BurrRenderer& burr, const MillableSurfaceFeed* feed, double initialVolume);

}  // namespace dm
