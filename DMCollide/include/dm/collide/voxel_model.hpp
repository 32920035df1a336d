// dm/collide/voxel_model.hpp — a solid given on a voxel grid by occupancy
// and signed distance: the anatomy side of Voxmap–PointShell haptic
// rendering (bone and tissue segmented from CT/MRI), touched by a
// PointShell tool (dm/collide/point_shell.hpp), a sphere, a capsule or a point.
//
// Values live at voxel centres; the grid follows dm::Volume's conventions:
// nx×ny×nz centres, voxel (i, j, k) at indexToWorld()·(i, j, k), where
// "world" is the shape's local frame, metres. The signed distance is
// negative inside. Between centres it is interpolated trilinearly; outside
// the grid the value at the nearest grid point plus the distance to the grid
// is used, so queries are defined everywhere.
//
// Two storages behind one class:
//  * Dense: an occupancy bit and a float distance per voxel (4.125 bytes a voxel).
//  * Sparse: an OpenVDB FloatGrid narrow-band level set (toSparse()): only
//    voxels with |d| < bandWidth are stored; beyond the band the distance is
//    clamped to ±bandWidth (inside/outside by signed flood fill), so the
//    distance is exact only within the band and "at least bandWidth" beyond.
// Dense models from a mesh with a band (VoxelizeOptions::bandWidth) are
// clamped the same way. OpenVDB stays inside the library.
//
// Queries never allocate, lock or throw (haptic-loop safe).
//
// Collider table (pair_voxel.cpp): point shell – voxel model (Voxmap–
// PointShell: one contact per shell point with distance ≤ 0, depth −d,
// normal −∇d from the shell to the model, reduced to maxContacts; distance =
// the smallest point distance), point, segment, sphere and capsule – voxel
// model (deepest point of the core by a march plus golden-section search),
// box, cylinder, ellipsoid, convex hull and triangle – voxel model (their
// surface sampled adaptively at the voxel spacing, cells pruned by the
// field's Lipschitz bound; distance within one voxel of the true one), and
// the voxel-model raycaster. Meshes, planes and other voxel models have no
// collider: sample them into a PointShell. Distances farther than the band
// read as the band.
//
// @code
//   auto bone = dm::VoxelModel::fromOccupancy(ctVolume, 300.0);  // HU ≥ 300 is bone
//   if (!bone) return bone.error();
//   double d = (*bone)->distance(tipInVolumeFrame);               // m, < 0 inside
// @endcode
#pragma once

#include <dm/collide/point_shell.hpp>
#include <dm/collide/query.hpp>
#include <dm/collide/shapes.hpp>
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>
#include <dm/core/volume.hpp>
#include <dm/math/voxelize.hpp>

#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace dm {

/// How a VoxelModel stores its voxels.
enum class VoxelStorage : std::uint8_t {
  Dense,   ///< occupancy bits + float distance per voxel
  Sparse,  ///< OpenVDB FloatGrid narrow-band level set
};

/// Occupancy + signed distance on a voxel grid (see the file comment).
/// Immutable and shareable between objects.
class VoxelModel final : public Shape {
 public:
  ~VoxelModel() override;

  /// Dense model of the solid bounded by a closed mesh (m): dm::voxelizeMesh()
  /// with `options` (signedDistance is forced on; a bandWidth > 0 clamps the
  /// field to ±bandWidth). Fails like voxelizeMesh() (open mesh, bad voxel
  /// size, too large).
  /// @code
  ///   auto femur = dm::VoxelModel::fromMesh(femurMesh, {.voxelSize = 0.5e-3});
  ///   if (!femur) return femur.error();
  /// @endcode
  static Result<std::shared_ptr<const VoxelModel>> fromMesh(const Mesh& mesh, VoxelizeOptions options);

  /// Dense model of a segmentation: voxel v is inside when value ≥ `threshold`.
  /// The signed distance comes from an exact Euclidean distance transform
  /// (Felzenszwalb–Huttenlocher, separable, anisotropic spacing): outside,
  /// the distance to the nearest inside voxel centre minus half the smallest
  /// spacing; inside, minus (the distance to the nearest outside centre minus
  /// half the smallest spacing) — so the zero level runs midway between
  /// inside and outside centres. O(voxels), parallel; memory 12 bytes a
  /// voxel while building. Fails with InvalidArgument on an empty volume, a
  /// non-finite threshold or voxel value (named by index), and when no voxel
  /// or every voxel is inside (pad the volume).
  /// @code
  ///   auto skull = dm::VoxelModel::fromOccupancy(ct, 400.0);
  ///   if (!skull) return skull.error();
  /// @endcode
  static Result<std::shared_ptr<const VoxelModel>> fromOccupancy(const Volume& volume, double threshold);

  /// Dense model of a volume that already holds a signed distance (any voxel
  /// type, metres, negative inside; e.g. voxelizeMesh() output or a level set
  /// read with dm::readVdb()). The field should be a distance (neighbouring
  /// values differ by at most their spacing); its actual Lipschitz bound is
  /// measured and used for conservative culling, so a steeper field stays
  /// correct, only slower. Fails on an empty volume or a non-finite value.
  /// @code
  ///   auto liver = dm::VoxelModel::fromSdf(*sdfVolume);
  /// @endcode
  static Result<std::shared_ptr<const VoxelModel>> fromSdf(const Volume& sdf);

  /// Sparse copy of this model: an OpenVDB narrow-band level set keeping the
  /// voxels with |d| < bandWidth (m; the model's own band if smaller).
  /// Inside the band it samples exactly as the dense model. Fails with
  /// InvalidArgument when bandWidth is not finite or below the largest voxel
  /// spacing (the flood fill that signs the far field needs a closed band),
  /// and with Internal when OpenVDB throws. O(voxels).
  /// @code
  ///   auto sparse = dense->toSparse(3 * voxelSize);
  ///   if (!sparse) return sparse.error();
  /// @endcode
  Result<std::shared_ptr<const VoxelModel>> toSparse(double bandWidth) const;

  /// Dense copy (of a sparse model: distances clamped at its band). O(voxels).
  /// Fails with Internal when out of memory.
  Result<std::shared_ptr<const VoxelModel>> toDense() const;

  /// Dense or sparse (OpenVDB) storage.
  VoxelStorage storage() const noexcept { return storage_; }
  /// Grid size in voxels (each ≥ 1).
  const Vec3i& dims() const noexcept { return dims_; }
  /// Voxel index → local frame (m), and its inverse.
  const Affine3& indexToWorld() const noexcept { return indexToWorld_; }
  const Affine3& worldToIndex() const noexcept { return worldToIndex_; }
  /// Distance clamp, m: +∞ for an unclamped dense model.
  double bandWidth() const noexcept { return band_; }
  /// Bound on |∇distance| over all space (1 + √3·(measured slope)·conditioning),
  /// used to skip point-shell clusters; ≈ 2.73 for a true distance on an
  /// unsheared grid.
  double lipschitz() const noexcept { return lipschitz_; }

  /// Stored signed distance of voxel (i, j, k), m; +bandWidth (or +∞) outside the grid.
  double voxelDistance(int i, int j, int k) const noexcept;
  /// Stored occupancy of voxel (i, j, k); false outside the grid.
  bool voxelOccupied(int i, int j, int k) const noexcept;

  /// Signed distance at local point p (m, negative inside), trilinear. NaN for
  /// a non-finite p. O(1).
  double distance(const Vec3& p) const noexcept;
  /// Distance and its gradient (the derivative of the interpolant, unit-free;
  /// ≈ unit outward normal near the surface) at p. O(1).
  double distance(const Vec3& p, Vec3& gradient) const noexcept;
  /// Gradient of distance() at p.
  Vec3 gradient(const Vec3& p) const noexcept;
  /// Occupancy of the voxel whose centre is nearest to p (false outside the grid).
  bool occupied(const Vec3& p) const noexcept;

  /// First hit of a ray (local frame, unit direction) with the zero level:
  /// sphere tracing on distance() from the grid entry, then bisection on the
  /// first sign change (t to ~1e-6 voxel). A ray starting inside hits at t = 0
  /// with normal −direction (dm::RayHit convention). Normal: the normalised
  /// gradient. O(path length / voxel) worst case.
  std::optional<RayHit> raycast(const Ray& localRay) const noexcept;

  /// Memory held by the voxel storage, bytes (dense: arrays; sparse: the
  /// OpenVDB tree's memUsage()).
  std::size_t bytes() const noexcept;
  /// Number of occupied voxels.
  std::size_t occupiedCount() const noexcept { return occupiedCount_; }

  /// Bounds of the voxel boxes (centres' hull grown by half a voxel).
  Aabb localAabb() const noexcept override { return bounds_; }
  /// Occupied voxels × voxel volume, m³.
  double volume() const noexcept override;

 private:
  struct SparseGrid;  // OpenVDB grid; defined in voxel_model_vdb.cpp
  VoxelModel() noexcept;
  static Result<std::shared_ptr<VoxelModel>> denseFrom(const Vec3i& dims, const Affine3& indexToWorld,
                                                       std::vector<float> distances,
                                                       std::vector<std::uint64_t> occupancy, double band);
  static Result<std::shared_ptr<const VoxelModel>> sdfModel(const Volume& sdf, double band,
                                                            const std::string& where);
  void finish();
  void corners(int i, int j, int k, int di, int dj, int dk, float out[8]) const noexcept;
  float valueAt(int i, int j, int k) const noexcept;
  // Implemented in voxel_model_vdb.cpp.
  float sparseValue(int i, int j, int k) const noexcept;
  void sparseCorners(int i, int j, int k, int di, int dj, int dk, float out[8]) const noexcept;
  std::size_t sparseBytes() const noexcept;

  VoxelStorage storage_ = VoxelStorage::Dense;
  Vec3i dims_ = Vec3i::Ones();
  Affine3 indexToWorld_ = Affine3::Identity();
  Affine3 worldToIndex_ = Affine3::Identity();
  std::vector<float> distance_;           // dense: x fastest, as dm::Volume
  std::vector<std::uint64_t> occupancy_;  // dense: one bit per voxel
  std::shared_ptr<const SparseGrid> sparse_;
  double band_ = std::numeric_limits<double>::infinity();
  double lipschitz_ = 1.0;
  double minSpacing_ = 0.0;
  std::size_t occupiedCount_ = 0;
  Aabb bounds_;
};

/// Voxmap–PointShell penalty sum of a point shell pressed into a voxel
/// model, world frame: every shell point p with distance d < 0 adds
/// −d·n with n = −∇d (the direction the model must move to let go of the
/// point). `force` = Σ depth·n (m; times a stiffness, N/m, it is the force on
/// the model, its negative the force on the tool), `torque` = Σ (p − tool
/// origin) × (−depth·n) (m², the torque on the tool about its origin).
struct VoxmapPenalty {
  int count = 0;              ///< penetrating points
  double maxDepth = 0.0;      ///< m
  Vec3 force = Vec3::Zero();  ///< m (sum of depth × normal, normal from tool to model)
  Vec3 torque = Vec3::Zero();
};

/// Sums the penalty of `shell` at `poseShell` against `model` at `poseModel`
/// (see VoxmapPenalty). Skips hierarchy clusters that cannot touch. No
/// allocation; O(points near the surface + clusters visited).
/// @code
///   dm::VoxmapPenalty p = dm::voxmapPenalty(drill, poseDrill, skull, poseSkull);
///   deviceForce = -stiffness * p.force;  // on the tool
/// @endcode
VoxmapPenalty voxmapPenalty(const PointShell& shell, const Isometry3& poseShell, const VoxelModel& model,
                            const Isometry3& poseModel) noexcept;

}  // namespace dm
