// dm/haptics/bone_placement.hpp — impulse-based 6-DOF haptic rendering for
// placing one voxelized bone fragment against another (fracture reduction,
// graft fitting): both fragments are ImplicitSphereTrees
// (dm/collide/sphere_tree.hpp) of voxel occupancies; the moving fragment is
// a dynamic rigid body held by a virtual coupling to the device pose.
//
// Collision. The two implicit trees are descended simultaneously (the
// moving tree mapped into the fixed tree's frame by the relative pose, each
// level's cell spheres an affine function of the cell index set up once a
// tick): a pair of cells is kept while their spheres overlap by more than
// 0.9·slop (below: only leaf pairs that deep act, and a leaf lies within
// R − r of its ancestor's centre, so shallower cell pairs hold none); only
// occupied cells are visited (ImplicitSphereTree::occupied); the node with
// the larger sphere is split first, and when it is more than 4× larger than
// the other it skips a level (its 64 grandchildren are tested at once); the
// last two levels are tested leaf block against leaf block. The stack is
// fixed-size. Leaf (voxel) spheres overlapping by more than 0.9·slop give
// contact pairs with normal n = (c_moving − c_fixed)/|…| (world, pointing
// toward the moving fragment) and depth r1 + r2 − |c_moving − c_fixed|; the
// deepest `maxContacts` are kept.
//
// Response, per tick of dt (Guendelman et al. 2003, Mirtich 1996 style):
//   1. the coupling (linear k_c, b_c on the centre of mass's offset from the
//      device's image of it; angular k_r, b_r on the rotation vector
//      log(R_device·R_fragmentᵀ)) is integrated into the velocities,
//      linearly implicitly, so stiff couplings stay stable;
//   2. contacts are found at the current pose, and `iterations`
//      Gauss–Seidel passes of normal impulses (restitution 0, accumulated
//      impulses clamped ≥ 0) remove the approaching normal velocity
//      n·(v + ω×r) < 0 of every kept pair (all deeper than 0.9·slop:
//      shallower ones are the resting overlap of touching voxels); pairs
//      deeper than the slop are also pushed out by split impulses (Catto):
//      a second Gauss–Seidel solve for a pseudo-velocity with target speed
//      β·(depth − slop)/dt, used for this tick's pose update only;
//   3. the pose is integrated (position by v·dt, orientation by the
//      exponential of ω·dt). No gravity, no friction, no gyroscopic term.
// The force and torque on the user's hand are minus the coupling force and
// torque on the fragment after the step, NaN-guarded and clamped to
// maxForce / maxTorque (dm::sanitizeWrench). At rest they equal
// −k_c·(device − fragment offset) and −k_r·(rotation offset).
//
// Frames: the moving fragment's local frame is its occupancy volume's world
// frame (the frame of its tree); its pose maps it to the scene; the device
// pose drives that pose (at rest with no contact, fragment pose = device
// pose). The fixed fragment is placed by `fixedPose`. SI units.
//
// Leaf spheres of face-adjacent voxels already overlap (r1 + r2 − h > 0 for
// voxel spacing h): that overlap is the default slop, so voxel faces that
// touch are in resting contact, and pairs overlapping less (diagonal
// neighbours, a gap between the faces) do not resist and are not contacts.
// The union of leaf
// spheres is bumpy with period h, so a fragment sliding on a face feels
// (and rests on) bumps: frictionless, but the normal tilts by up to ~40°.
// Impulses are only as good as the kept pairs: keep maxContacts above the
// pairs of the contact area, or equally deep pairs left out leave
// directions unconstrained and the fragment can sink between spheres.
//
// Real time: tick() and setObjectPose() never allocate, lock or throw;
// create() sizes the traversal stack and the contact buffer.
//
// @code
//   auto r = dm::BonePlacementRenderer::create(fixedTree, dm::Isometry3::Identity(), movingTree,
//   movingLabels, {}); if (!r) return r.error(); dm::HapticResponse out = (*r)->tick({.dt = 1e-3, .devicePose
//   = pose});
// @endcode
#pragma once

#include <dm/collide/sphere_tree.hpp>
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>
#include <dm/core/volume.hpp>
#include <dm/haptics/renderer.hpp>

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string_view>
#include <vector>

namespace dm {

/// Options of a BonePlacementRenderer (SI units). Defaults suit fragments of
/// a few centimetres at 1 kHz.
struct BonePlacementOptions {
  double couplingStiffness = 300.0;       ///< k_c, N/m, > 0
  double couplingDamping = 2.0;           ///< b_c, N·s/m, ≥ 0 (on device − fragment velocity)
  double couplingAngularStiffness = 0.3;  ///< k_r, N·m/rad, > 0
  double couplingAngularDamping = 1e-3;   ///< b_r, N·m·s/rad, ≥ 0
  /// kg, ≥ 0: fragment mass; 0 = occupied voxels × voxel volume × density.
  /// A given mass scales the voxel inertia to it.
  double mass = 0.0;
  double density = 1900.0;  ///< kg/m³, > 0 (cortical bone ≈ 1900)
  double threshold = 0.0;   ///< occupancy: voxel value > threshold (must match the moving tree's)
  /// Deepest contact pairs kept per tick, 1..4096. Keep it above the pairs
  /// of the expected contact area (about 4 per voxel of contact face): a
  /// truncated set of equally deep pairs leaves directions unconstrained.
  int maxContacts = 1024;
  int iterations = 8;  ///< Gauss–Seidel passes over the contacts, 1..100
  /// Levels above the voxels whose cells are the contact elements, 0..4:
  /// 0 the voxels; 1 cells of 2³ voxels (occupied when any voxel is), a
  /// quarter of the pairs and a coarser, up to a cell fuller surface; the
  /// mass properties stay the voxels'. For fragments too fine for the
  /// haptic rate (docs/performance.md, "Bone placement").
  int contactLevel = 0;
  /// m: overlap of leaf spheres treated as touching: pairs deeper than
  /// 0.9·slop stop approach, the depth beyond it is pushed out; negative =
  /// the resting overlap of face-adjacent voxels (of face-adjacent contact
  /// cells with contactLevel > 0; see the file comment).
  double slop = -1.0;
  double baumgarte = 0.2;            ///< β in [0, 1]: fraction of depth − slop removed per tick
  double maxForce = 20.0;            ///< N, > 0 (∞ allowed): clamp of the force to the user
  double maxTorque = 1.0;            ///< N·m, > 0 (∞ allowed): clamp of the torque to the user
  std::size_t stackCapacity = 4096;  ///< traversal stack entries, 64..1<<20
};

/// Mass properties of a voxel occupancy: each occupied voxel a uniform
/// parallelepiped (its index cube mapped by the volume's affine).
struct VoxelMassProperties {
  double mass = 0.0;                 ///< kg
  Vec3 centerOfMass = Vec3::Zero();  ///< m, volume's world frame
  Mat3 inertia = Mat3::Zero();       ///< kg·m² about the centre of mass, volume's world frame
  std::size_t voxels = 0;            ///< occupied voxels
};

/// Mass properties of the voxels of `volume` with value > threshold at
/// `density` (kg/m³): centres from indexToWorld(), each voxel's own inertia
/// m·(tr C·I − C), C = A·Aᵀ/12 (A = the affine's linear part) added to the
/// parallel-axis sum. Fails with InvalidArgument on an empty volume, no
/// occupied voxel, or a density that is not finite and > 0. O(voxels).
/// @code
///   auto mp = dm::voxelMassProperties(labels, 0.5, 1900.0);
///   if (mp) std::printf("%g kg\n", mp->mass);
/// @endcode
Result<VoxelMassProperties> voxelMassProperties(const Volume& volume, double threshold, double density);

/// Reference points of a fragment (its volume's world frame): the centres
/// of its occupied voxels (value > threshold) that lie furthest along −x,
/// +x, −y, +y, −z, +z, then the one nearest the occupied voxels' centroid —
/// seven points that pin down its pose, for
/// BonePlacementRenderer::alignmentError. Empty without occupied voxels.
/// O(voxels).
/// @code
///   auto points = dm::boneReferencePoints(fragment, 0.5);
///   double e = renderer->alignmentError(points, dm::Isometry3::Identity());
/// @endcode
std::vector<Vec3> boneReferencePoints(const Volume& volume, double threshold);

/// RMS distance (m) between `points` (a fragment's frame) placed by `pose`
/// and by `target`; 0 for no points. O(points).
double boneAlignmentError(std::span<const Vec3> points, const Isometry3& pose,
                          const Isometry3& target) noexcept;

/// One contact pair of the last tick, world frame.
struct BoneContact {
  Vec3 point = Vec3::Zero();    ///< m, midway in the overlap of the two leaf spheres
  Vec3 normal = Vec3::UnitZ();  ///< unit, from the fixed sphere's centre toward the moving one's
  double depth = 0.0;           ///< m, r1 + r2 − centre distance (> 0)
  double impulse = 0.0;         ///< N·s, accumulated normal impulse (≥ 0)
  double correction = 0.0;      ///< N·s, accumulated split impulse of the position correction (≥ 0)
                                ///< N·s, accumulated normal impulse (≥ 0)
};

/// Impulse-based bone fragment placement renderer (see the file comment).
class BonePlacementRenderer final : public HapticRenderer {
 public:
  /// Builds the renderer with the moving fragment at rest at the identity
  /// pose (call reset() with the device pose first). `movingOccupancy` is
  /// the volume the moving tree was built from (mass properties). Fails with
  /// InvalidArgument naming the field: null `fixed` / `moving`,
  /// `fixedPose` not finite or not rigid, an occupancy without occupied
  /// voxel, or an option out of its range (BonePlacementOptions). O(voxels).
  /// @code
  ///   auto r = dm::BonePlacementRenderer::create(fixedTree, pose, movingTree, movingLabels, {.threshold =
  ///   0.5}); if (!r) return r.error();
  /// @endcode
  static Result<std::unique_ptr<BonePlacementRenderer>> create(
      std::shared_ptr<const ImplicitSphereTree> fixed, const Isometry3& fixedPose,
      std::shared_ptr<const ImplicitSphereTree> moving, const Volume& movingOccupancy,
      const BonePlacementOptions& options);

  /// "boneplacement".
  std::string_view name() const noexcept override { return "boneplacement"; }
  /// Fragment at `devicePose`, at rest. A non-finite pose is ignored.
  void reset(const Isometry3& devicePose) noexcept override;
  /// One tick (file comment). The coupling dampers act on
  /// input.linearVelocity / angularVelocity − the fragment's. A non-finite
  /// input or dt ≤ 0 answers zero force and keeps the state. proxyPose =
  /// fragment pose; contacts = kept pairs; penetration = device–fragment
  /// distance while in contact. O(visited cell pairs + contacts·iterations).
  HapticResponse tick(const HapticInput& input) noexcept override;
  /// 1 (the fixed fragment).
  std::size_t objectCount() const noexcept override { return 1; }
  /// Moves the fixed fragment (index 0) from the next tick on; other indices
  /// and non-rigid poses are ignored.
  void setObjectPose(std::size_t index, const Isometry3& pose) noexcept override;

  /// RMS distance (m) between `referencePointsInMovingFrame` (fragment
  /// frame) placed at the current fragment pose and at `targetPose`; 0 for
  /// no points. O(points).
  /// @code
  ///   double e = r->alignmentError(landmarks, referencePose);
  /// @endcode
  double alignmentError(std::span<const Vec3> referencePointsInMovingFrame,
                        const Isometry3& targetPose) const noexcept;

  /// Moving fragment pose (its frame → world).
  Isometry3 fragmentPose() const noexcept;
  /// Centre-of-mass velocity (m/s) and angular velocity (rad/s), world.
  const Vec3& fragmentVelocity() const noexcept { return velocity_; }
  const Vec3& fragmentAngularVelocity() const noexcept { return angularVelocity_; }
  /// Mass properties in use (inertia about the centre of mass, fragment frame).
  const VoxelMassProperties& massProperties() const noexcept { return massProps_; }
  /// Contact pairs found by the last tick: leaf pairs overlapping by more
  /// than 0.9·slop(), the ones that act (deepest first is not guaranteed).
  std::span<const BoneContact> contacts() const noexcept { return {contacts_.data(), contactCount_}; }
  /// Largest depth of the last tick's pairs (m), 0 without one.
  double maxContactDepth() const noexcept { return maxDepth_; }
  /// Pairs dropped since create() because the traversal stack was full.
  std::uint64_t stackOverflows() const noexcept { return stackOverflows_; }
  /// Slop in use (m).
  double slop() const noexcept { return slop_; }
  const BonePlacementOptions& options() const noexcept { return options_; }

 private:
  struct Pair {
    ImplicitSphereTree::NodeId fixedNode;
    ImplicitSphereTree::NodeId movingNode;
  };
  BonePlacementRenderer() = default;
  void findContacts() noexcept;
  void offerContact(const Vec3& cFixed, double rFixed, const Vec3& cMoving, double rMoving) noexcept;
  void solveContacts(double dt, Vec3& pseudoVelocity, Vec3& pseudoAngular) noexcept;

  std::shared_ptr<const ImplicitSphereTree> fixed_;
  std::shared_ptr<const ImplicitSphereTree> moving_;
  Isometry3 fixedPose_ = Isometry3::Identity();
  BonePlacementOptions options_;
  VoxelMassProperties massProps_;
  Mat3 inertiaBodyInverse_ = Mat3::Identity();
  double slop_ = 0.0;
  int contactDepthF_ = 0;  // the trees' contact levels: depth − contactLevel (≥ 0)
  int contactDepthM_ = 0;
  // State: centre of mass (world), orientation, velocities (world).
  Vec3 position_ = Vec3::Zero();
  Quat orientation_ = Quat::Identity();
  Vec3 velocity_ = Vec3::Zero();
  Vec3 angularVelocity_ = Vec3::Zero();
  // Per-tick buffers sized by create().
  std::vector<Pair> stack_;
  std::vector<BoneContact> contacts_;
  struct SolverRow {  // per contact, fixed for a tick's solve
    Vec3 r;           // lever arm from the centre of mass, world
    Vec3 angular;     // I⁻¹ (r × n)
    double effMass;   // 1 / (1/m + (r × n)·I⁻¹(r × n))
  };
  std::vector<SolverRow> rows_;  // sized with contacts_
  std::vector<std::uint32_t> active_;  // a solve pass's pairs, sized with contacts_
  std::size_t contactCount_ = 0;
  double maxDepth_ = 0.0;
  std::uint64_t stackOverflows_ = 0;
  Isometry3 movingToFixed_ = Isometry3::Identity();  // scratch of findContacts()
};

}  // namespace dm
