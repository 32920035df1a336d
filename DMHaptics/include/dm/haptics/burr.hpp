// dm/haptics/burr.hpp — drilling, burring and sawing voxel bone at the
// haptic rate: a god-object of the tool's shape on a MillableVolume
// (dm/collide/millable_volume.hpp) that removes bone where it presses.
//
// Each tick, in the bone's frame:
//  1. Contact (god-object, Zilles & Salisbury 1995, with the tool's volume
//     for the surface). The proxy — the tool's centre, its orientation the
//     device's — moves toward the device in steps of at most half the
//     smaller of a voxel and the tool's inner radius, so it cannot pass a
//     one-voxel plate. Where a step would overlap material (overlap() above
//     `contactTolerance`) it stops at the touching point (bisection), takes
//     the contact normal n (contactNormal() over the material within
//     `normalMargin` of the tool: the direction from the centroid of the
//     nearby material, Agus et al. 2002) and slides in the plane of n,
//     lifted back onto the surface along n after each step.
//  2. Force on the hand: the proxy–device spring k·(proxy − device) and
//     damping −b·v while in contact; its component along n is the normal
//     force F_n. The spinning burr adds its walk, μ_w·F_n along ω̂ × n (the
//     material's resistance to the cutting edges' surface velocity, ω̂ the
//     shaft axis, the tool's local +z, right-handed), and its vibration,
//     a·F_n·sin(2π·f·t) along n. The sum is NaN-guarded and clamped to
//     maxForce. The spring is the passive part; keep k within the device's
//     passivity bound (dm/haptics/safety.hpp) — a removal only lets the
//     proxy follow the device, which takes energy out of the spring.
//  3. Removal (Archard's wear law, Agus et al. 2002 / Arbabtafti et al. 2008
//     in spirit): wear work W = k_w·F_n·v·dt with v = rpm·2π/60·cuttingRadius
//     the cutting edges' speed; MillableVolume::mill() removes it at the tool
//     advanced from the proxy toward the device by at most half a voxel (the
//     material the pressed tool reaches), shared over the overlapped cells by
//     their overlap and each cell's hardness. Next tick the proxy follows into
//     the cut. Removal is monotone in force, speed and 1/hardness; nothing is
//     removed where the tool never was; the cavity of a tool that dwelt is the
//     tool's swept volume with the surface at sub-voxel precision.
//
// Lockstep runs are reproducible bit for bit (no randomness; the vibration's
// phase is the input's time). tick() never allocates, locks, logs or throws;
// setRpm() may be called from any thread. The volume is edited in place: read
// its changed blocks between ticks (lockstep) or from the haptic thread.
//
// @code
//   auto bone = std::make_shared<dm::MillableVolume>(std::move(*dm::MillableVolume::fromIntensity(ct, 300,
//   1200))); auto burr = dm::BurrRenderer::create(bone, {.tool = dm::MillingTool::sphere(2e-3), .stiffness =
//   800}); if (!burr) return burr.error();
//   (*burr)->reset(devicePose);
//   dm::HapticResponse r = (*burr)->tick({.timeNs = t, .dt = 1e-3, .devicePose = pose});
// @endcode
#pragma once

#include <dm/collide/millable_volume.hpp>
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>
#include <dm/haptics/renderer.hpp>

#include <atomic>
#include <cstdint>
#include <limits>
#include <memory>
#include <string_view>
#include <vector>

namespace dm {

/// Settings of a BurrRenderer (see the file comment for the model).
struct BurrOptions {
  MillingTool tool = MillingTool::sphere(2e-3);  ///< the cutting part, tool frame (shaft along local z)
  double stiffness = 1000.0;                     ///< N/m, proxy–device spring (> 0)
  double damping = 0.0;                          ///< N·s/m, on the device velocity in contact (≥ 0)
  double rpm = 80000.0;                          ///< burr speed at start (≥ 0; setRpm() changes it)
  /// m: radius of the cutting edges' circle; 0 takes the sphere's or
  /// cylinder's radius; box (saw) and voxel tools must give it (a saw: the
  /// blade's distance from its pivot, with rpm its oscillation).
  double cuttingRadius = 0.0;
  double wearCoefficient = 0.1;      ///< Archard k_w (≥ 0): abrasive burrs on bone ≈ 0.05–0.2
  double walkCoefficient = 0.3;      ///< tangential / normal force of the spinning tool (≥ 0)
  double vibrationAmplitude = 0.05;  ///< vibration force / normal force (≥ 0)
  double vibrationHz = 160.0;        ///< felt vibration frequency (≥ 0, below half the loop rate)
  double maxForce = 10.0;            ///< N, clamp on the force sent (> 0)
  /// m³ of overlap that counts as touching; < 0: a thousandth of a voxel.
  double contactTolerance = -1.0;
  /// m, how far beyond the tool material shapes the contact normal; < 0: two voxels.
  double normalMargin = -1.0;
  /// Critical structures (nerve, vessel, dura), each a signed distance in
  /// the bone volume's frame, e.g. VoxelModel::fromOccupancy of
  /// MillableVolume::forbiddenMask() or one per structure; empty: none.
  /// Each tick measures the tool's distance to the nearest
  /// (BurrTickInfo::criticalDistance). Null entries are an error.
  std::vector<std::shared_ptr<const VoxelModel>> critical;
  double warningDistance = 1e-3;  ///< m (≥ 0): closer than this counts as time within the margin

  /// Ok, or InvalidArgument naming the field of `where`.
  Status validate(std::string_view where) const;
};

/// What the last tick did to the bone.
struct BurrTickInfo {
  bool contact = false;
  double normalForce = 0.0;    ///< N, F_n
  Vec3 normal = Vec3::Zero();  ///< contact normal, world
  MillResult cut;              ///< what this tick removed
  /// m: the tool's distance to the nearest critical structure (its centre's
  /// distance minus the tool's bounding radius: exact for a sphere, a lower
  /// bound otherwise; negative: inside one); +∞ without critical structures.
  double criticalDistance = std::numeric_limits<double>::infinity();
};

/// Skill metrics since the renderer was built or resetMetrics() (issue 31's
/// critical structures).
struct BurrMetrics {
  std::int64_t ticks = 0;
  double closestApproach = std::numeric_limits<double>::infinity();  ///< m, smallest criticalDistance
  double secondsWithinWarning = 0.0;  ///< s with criticalDistance < warningDistance
  double removed = 0.0;               ///< m³
  double removedForbidden = 0.0;      ///< m³ of it in forbidden materials
};

/// Bone drilling and burring as a haptic renderer (file comment).
class BurrRenderer final : public HapticRenderer {
 public:
  /// Fails with InvalidArgument for invalid options (named as "burr/<field>")
  /// or a null or empty volume.
  static Result<std::unique_ptr<BurrRenderer>> create(std::shared_ptr<MillableVolume> bone,
                                                      BurrOptions options);

  std::string_view name() const noexcept override { return "burr"; }
  void reset(const Isometry3& devicePose) noexcept override;
  HapticResponse tick(const HapticInput& input) noexcept override;
  std::size_t objectCount() const noexcept override { return 1; }
  /// Moves the bone (its volume frame → world).
  void setObjectPose(std::size_t index, const Isometry3& pose) noexcept override;

  /// Burr speed, revolutions per minute (≥ 0; 0 stops removal, walk and
  /// vibration; non-finite or negative is ignored). Any thread.
  void setRpm(double rpm) noexcept;
  double rpm() const noexcept { return rpm_.load(std::memory_order_relaxed); }
  const BurrTickInfo& lastTick() const noexcept { return last_; }
  const BurrMetrics& metrics() const noexcept { return metrics_; }
  void resetMetrics() noexcept { metrics_ = {}; }
  const MillableVolume& volume() const noexcept { return *bone_; }
  MillableVolume& volume() noexcept { return *bone_; }
  const BurrOptions& options() const noexcept { return options_; }

 private:
  BurrRenderer(std::shared_ptr<MillableVolume> bone, BurrOptions options) noexcept;
  Isometry3 toolPose(const Vec3& centre) const noexcept;
  double overlapAt(const Vec3& centre) noexcept;
  Vec3 normalAt(const Vec3& centre) noexcept;
  void moveProxy(const Vec3& target) noexcept;

  std::shared_ptr<MillableVolume> bone_;
  BurrOptions options_;
  std::atomic<double> rpm_{0.0};
  Isometry3 bonePose_ = Isometry3::Identity();
  Isometry3 boneInverse_ = Isometry3::Identity();
  Mat3 rotation_ = Mat3::Identity();  // tool orientation, bone frame
  Vec3 proxy_ = Vec3::Zero();         // tool centre, bone frame
  Vec3 normal_ = Vec3::Zero();        // contact plane of this tick, bone frame (zero: none)
  int queries_ = 0;                   // field queries this tick
  double step_ = 0.0, tolerance_ = 0.0, margin_ = 0.0, cuttingRadius_ = 0.0, boundingRadius_ = 0.0;
  BurrTickInfo last_;
  BurrMetrics metrics_;
};

}  // namespace dm
