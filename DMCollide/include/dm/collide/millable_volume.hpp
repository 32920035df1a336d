// dm/collide/millable_volume.hpp — bone that a burr or a saw removes: a
// dense voxel grid of fractional occupancy (partial volume) and material
// labels, edited in place by a milling tool and publishing what changed.
//
// Model. Voxel v holds o_v ∈ [0, 1], the fraction of its cell filled with
// material (16 bits), and a material index (8 bits) into a table of
// MillingMaterial (hardness, forbidden). The surface is the 0.5 level of o.
// A MillingTool (sphere, flat-ended cylinder, box — a saw blade — or any
// VoxelModel) covers the fraction K_v = clamp(1/2 − s(x_v)/h, 0, 1) of voxel v,
// s the tool's signed distance at the voxel centre, h the smallest spacing
// (partial volume of a plane through the cell, exact for axis-aligned faces).
// The material a voxel keeps outside the tool is at most 1 − K_v, so
//  * the tool overlaps the material by r_v = max(0, o_v + K_v − 1) of each
//    cell (overlap(): the contact test of the burr's god-object), and
//  * milling lowers o_v toward 1 − K_v, never below: a tool that dwells
//    leaves its own shape with the 0.5 level on its surface (sub-voxel, not
//    stepped), and a tool at a pose it has milled overlaps nothing.
// Removal follows Archard's wear law, V = k·F·s/H (wear volume from normal
// force, sliding distance and hardness): mill() takes the wear work
// W = k·F·s (J) of one tick, shares F over the cells in reach in proportion
// to their overlap r_v, and removes ΔV_v = W·(r_v / Σr)/H_v from each, capped
// at r_v. Removal is therefore monotone in force, speed and 1/hardness, and
// removed volume is accounted per material.
//
// Change sets. Voxels are grouped in 8³ blocks; every block mill() touches is
// listed once in changedBlocks() until clearChanges(), so the collision
// model, the renderer and the recorder apply only what changed (see the
// architecture's "Surgical interactions change the patient"). The grid is
// the collision model itself: there is nothing else to update.
//
// Threads. Queries (overlap, contactNormal) and mill() never allocate,
// lock or throw (haptic-loop safe). The volume is not synchronised: one
// thread edits it; others read changed blocks between ticks (lockstep) or
// through a copy the editing thread publishes.
//
// @code
//   auto bone = dm::MillableVolume::fromIntensity(ct, 300.0, 1200.0);  // HU: partial volume
//   if (!bone) return bone.error();
//   auto burr = dm::MillingTool::sphere(2e-3);
//   double touching = bone->overlap(burr, pose);                       // m³
//   dm::MillResult cut = bone->mill(burr, pose, 1e-3);                 // J of wear work
// @endcode
#pragma once

#include <dm/collide/voxel_model.hpp>
#include <dm/core/mesh.hpp>
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>
#include <dm/core/volume.hpp>

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace dm {

/// The cutting part of a tool, in the tool's frame (origin at its centre;
/// a cylinder's axis and a box's thin side along local z by convention).
struct MillingTool {
  enum class Kind : std::uint8_t { Sphere, Cylinder, Box, Voxels };
  Kind kind = Kind::Sphere;
  double radius = 2e-3;                     ///< m: sphere, cylinder
  double halfLength = 0.0;                  ///< m: cylinder, along local z (flat ends)
  Vec3 halfExtents = Vec3::Zero();          ///< m: box
  std::shared_ptr<const VoxelModel> shape;  ///< Voxels: the tool's signed distance, tool frame

  static MillingTool sphere(double radius) { return {.kind = Kind::Sphere, .radius = radius}; }
  static MillingTool cylinder(double radius, double halfLength) {
    return {.kind = Kind::Cylinder, .radius = radius, .halfLength = halfLength};
  }
  static MillingTool box(const Vec3& halfExtents) { return {.kind = Kind::Box, .halfExtents = halfExtents}; }
  static MillingTool voxels(std::shared_ptr<const VoxelModel> model) {
    return {.kind = Kind::Voxels, .shape = std::move(model)};
  }

  /// Signed distance (m, negative inside) at tool-frame point p and its
  /// gradient (unit outward direction where defined). O(1).
  double distance(const Vec3& p, Vec3& gradient) const noexcept;
  /// Radius of a ball about the origin that holds the tool, m.
  double boundingRadius() const noexcept;
  /// Half extents of a box about the origin, along the tool's axes, that
  /// holds the tool, m (tighter than the ball for long tools).
  Vec3 boundingHalfExtents() const noexcept;
  /// Radius of the largest ball about the origin inside the tool, m
  /// (sphere, cylinder, box; a voxel tool: −distance at the origin).
  double innerRadius() const noexcept;
  /// Ok, or InvalidArgument naming the field of `where` that is not finite
  /// or not positive, or a Voxels tool without a shape.
  Status validate(std::string_view where) const;
};

/// One material of a millable volume.
struct MillingMaterial {
  std::string name = "bone";
  double hardness = 0.5e9;  ///< Pa (> 0): Archard hardness; cortical bone ≈ 0.3–0.7 GPa
  bool forbidden = false;   ///< a critical structure (nerve, vessel, dura): removal is counted as a violation
};

/// What one mill() call removed.
struct MillResult {
  double removed = 0.0;           ///< m³
  double removedForbidden = 0.0;  ///< m³ of it in forbidden materials
  int voxels = 0;                 ///< voxels whose occupancy went down
};

/// One connected piece of bone (MillableVolume::fragments()).
struct BoneFragment {
  std::size_t cells = 0;         ///< voxels at least half full
  double volume = 0.0;           ///< m³: Σ occupancy × cell volume over them
  Vec3 centroid = Vec3::Zero();  ///< m, the volume's frame
  /// m⁵: the second moment about the centroid, Σ o·V·(|r|²I − r rᵀ) plus each
  /// cell's own (a cube's h²/6 per unit volume); times a density it is the
  /// inertia tensor (kg·m²).
  Mat3 inertia = Mat3::Zero();
  Vec3i lo = Vec3i::Zero(), hi = Vec3i::Zero();  ///< index bounds of its cells, inclusive
};

/// The pieces of a millable volume: labels (U32, this grid's affine; 0 = no
/// bone, k + 1 = fragments[k]) and the fragments, largest volume first.
struct FragmentMap {
  Volume labels;
  std::vector<BoneFragment> fragments;
};

/// Fractional-occupancy voxel bone edited by milling tools (file comment).
class MillableVolume {
 public:
  static constexpr int kBlock = 8;  ///< block edge, voxels
  static constexpr std::uint16_t kFull = 65535;
  /// The cells a tool can cover (internal to the queries).
  struct Box {
    int i0, i1, j0, j1, k0, k1;  ///< inclusive index ranges
    double reach;                ///< m: radius about the tool's origin that holds every cell it can cover
    Vec3 slab;                   ///< m: half extents along the tool's axes that hold every such cell
    bool slabs;                  ///< clip to `slab` too (not for a sphere: its ball is exact)
  };

  /// Occupancy from a signed distance volume (m, negative inside):
  /// o = clamp(1/2 − d/h), h the smallest spacing. One material.
  /// InvalidArgument for an empty volume, a non-finite value (named by
  /// index) or a material that fails MillableVolume::setMaterials' checks.
  static Result<MillableVolume> fromSdf(const Volume& sdf, MillingMaterial material = {});
  /// Occupancy from intensity by CT's partial-volume law: o = clamp((I − empty)
  /// / (full − empty)) (e.g. soft tissue and cortical bone in HU). One
  /// material. InvalidArgument when empty ≥ full, either is not finite, or
  /// a voxel is not finite.
  static Result<MillableVolume> fromIntensity(const Volume& volume, double empty, double full,
                                              MillingMaterial material = {});

  /// Sets the material table (≤ 256 entries, hardness finite > 0, names
  /// unique and non-empty) and, with `labels` (same dims as this volume,
  /// integer values < materials.size()), every voxel's material; without
  /// labels every voxel takes material 0. Counters of removed volume reset.
  /// InvalidArgument naming the entry or the voxel index.
  Status setMaterials(std::vector<MillingMaterial> materials, const Volume* labels = nullptr);

  const Vec3i& dims() const noexcept { return dims_; }
  const Affine3& indexToWorld() const noexcept { return indexToWorld_; }
  const Affine3& worldToIndex() const noexcept { return worldToIndex_; }
  /// Smallest spacing h, m (the tool kernel's ramp width).
  double voxelSize() const noexcept { return h_; }
  /// Volume of one cell, m³.
  double voxelVolume() const noexcept { return cellVolume_; }
  const std::vector<MillingMaterial>& materials() const noexcept { return materials_; }

  /// Occupancy of voxel (i, j, k) in [0, 1]; 0 outside the grid.
  double occupancy(int i, int j, int k) const noexcept;
  /// Material index of voxel (i, j, k); 0 outside the grid.
  int material(int i, int j, int k) const noexcept;
  /// Σ o·cell volume, m³. O(voxels).
  double materialVolume() const noexcept;
  /// Volume removed so far from material `m` (0 for an unknown index), m³.
  double removedVolume(std::size_t m) const noexcept;

  /// Material overlapped by `tool` at `pose` (tool frame → this volume's
  /// frame): Σ max(0, o_v + K_v − 1)·cell volume, m³ (file comment).
  /// O(cells in the tool's bounding box). Real-time safe.
  double overlap(const MillingTool& tool, const Isometry3& pose) const noexcept;
  /// Direction to move `tool` out of the material near it: −Σ w_v ∇s(x_v),
  /// normalised, over the material within `margin` (m, ≥ 0) of the tool,
  /// w_v = o_v·clamp(1/2 − (s − margin)/h). For a sphere this is the
  /// direction from the centroid of that material to the centre (Agus et al.
  /// 2002). Zero when no material is within reach. Real-time safe.
  Vec3 contactNormal(const MillingTool& tool, const Isometry3& pose, double margin) const noexcept;
  /// Removes wear work `work` (J = Archard k·F·s, ≥ 0) from the cells the
  /// tool overlaps (file comment) and records their blocks as changed.
  /// Non-finite or non-positive work removes nothing. Real-time safe.
  MillResult mill(const MillingTool& tool, const Isometry3& pose, double work) noexcept;

  /// Blocks whose surface piece (blockSurfaces) changed since
  /// clearChanges(), each once, in the order first changed: the blocks of
  /// the changed voxels, and the block below on an axis where a changed voxel
  /// lies on its block's low face (that piece closes its seam with it).
  /// Block b holds voxels [bx·8, bx·8 + 8) × ... with b = bx + nbx·(by + nby·bz).
  std::span<const std::uint32_t> changedBlocks() const noexcept { return {changed_.data(), changedCount_}; }
  void clearChanges() noexcept;
  /// Blocks per axis.
  const Vec3i& blockDims() const noexcept { return blockDims_; }

  /// Voxels of a block (8³), as readBlock() and writeBlock() copy them.
  static constexpr std::size_t kBlockVoxels = std::size_t{kBlock} * kBlock * kBlock;
  /// Copies block b's occupancy (raw, kFull = 1; x fastest; cells beyond
  /// the grid read 0) into `out`: what changed, for a copy of this volume on
  /// another thread. False for an unknown block. Real-time safe.
  bool readBlock(std::uint32_t b, std::span<std::uint16_t, kBlockVoxels> out) const noexcept;
  /// Sets block b's occupancy from `in` (as readBlock() gives it; cells
  /// beyond the grid are skipped) and lists the changed blocks as mill()
  /// does, so a copy kept on a render thread knows which pieces to remesh.
  /// Removed volume is not counted (it is the original's). False for an
  /// unknown block.
  bool writeBlock(std::uint32_t b, std::span<const std::uint16_t, kBlockVoxels> in) noexcept;

  /// The bone's connected pieces after sawing: voxels at least half full,
  /// joined across faces (6-connected; pieces that touch only along an edge
  /// or at a corner are apart, as the 0.5 surface separates them), each with
  /// its mass properties. O(voxels), 4 bytes a voxel for the labels; not for
  /// the haptic thread. Fails with InvalidArgument when out of memory.
  Result<FragmentMap> fragments() const;
  /// Occupancy (F32, values in [0, 1]) of fragments[k] alone, cropped to its
  /// cells with one empty layer around: ImplicitSphereTree::create(v, 0.5)
  /// and BonePlacementRenderer take it as the moving fragment. InvalidArgument
  /// for k out of range or a map of another volume.
  Result<Volume> fragmentOccupancy(const FragmentMap& map, std::size_t k) const;
  /// 1 where a voxel of a forbidden material is at least half full, else 0
  /// (U8, this grid's affine): the critical structures as they stand, for
  /// VoxelModel::fromOccupancy(mask, 0.5) → BurrOptions::critical.
  Result<Volume> forbiddenMask() const;
  /// The occupancy as a float volume (values in [0, 1], this grid's affine),
  /// for isosurfaces at 0.5 and ray casting.
  Result<Volume> occupancyVolume() const;
  /// Surface (0.5 level, outward normals) of the voxels of blocks `blocks`
  /// grown by one voxel each way, each block meshed on its own so a renderer
  /// replaces just those pieces: pieces[i] is the mesh of blocks[i].
  /// With `materialColors` (one per material), each vertex is coloured by
  /// the material of the fullest voxel of its cell, so what the tool
  /// exposed (dentin under enamel, a nerve) shows. InvalidArgument for an
  /// unknown block index or fewer colours than materials.
  Result<std::vector<Mesh>> blockSurfaces(std::span<const std::uint32_t> blocks,
                                          std::span<const Vec4f> materialColors = {}) const;

 private:
  MillableVolume() = default;
  static Result<MillableVolume> fromFraction(const Volume& v, const char* what,
                                             double (*fraction)(double value, double a, double b), double a,
                                             double b, MillingMaterial material);
  Box toolBox(const MillingTool& tool, const Isometry3& pose, double grow) const noexcept;
  std::size_t index(int i, int j, int k) const noexcept {
    return static_cast<std::size_t>(i) +
           static_cast<std::size_t>(dims_.x()) *
               (static_cast<std::size_t>(j) +
                static_cast<std::size_t>(dims_.y()) * static_cast<std::size_t>(k));
  }
  void markChanged(int i, int j, int k) noexcept;
  void colorByMaterial(Mesh& mesh, std::span<const Vec4f> materialColors) const;
  /// Block b's first voxel and its extent clipped to the grid; false for an unknown block.
  bool blockRange(std::uint32_t b, Vec3i& lo, Vec3i& n) const noexcept;

  Vec3i dims_ = Vec3i::Zero();
  Affine3 indexToWorld_ = Affine3::Identity();
  Affine3 worldToIndex_ = Affine3::Identity();
  double h_ = 0.0;
  double cellVolume_ = 0.0;
  std::vector<std::uint16_t> occupancy_;  // x fastest, as dm::Volume
  std::vector<std::uint8_t> material_;
  std::vector<MillingMaterial> materials_;
  std::vector<double> hardness_;  // per material, Pa
  std::vector<double> removed_;   // per material, m³
  Vec3i blockDims_ = Vec3i::Zero();
  std::vector<std::uint8_t> blockChanged_;
  std::vector<std::uint32_t> changed_;  // capacity = block count, so it never grows
  std::size_t changedCount_ = 0;
};

}  // namespace dm
