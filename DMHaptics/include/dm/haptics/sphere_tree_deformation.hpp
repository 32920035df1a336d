// dm/haptics/sphere_tree_deformation.hpp — a soft object for the sphere-tree
// 6-DOF renderer: a spring network on one level of its sphere tree (the
// skeleton), stepped at the haptic rate (Wang et al., "Six-degree-of-freedom
// haptic simulation of organ deformation in dental operations", ICRA 2012:
// a dental mirror pushing a tongue aside).
//
// Model. The nodes of level `skeletonLevel` of the rest tree are mass points
// (the object's mass shared by sphere volume) with displacements d_i from
// their rest centres. Each is tied to its rest position by
// `anchorStiffness`, to every skeleton node whose rest sphere touches its
// own (|c_i − c_j| ≤ 1.05 (r_i + r_j)) by `linkStiffness`, and damped by
// `damping` against the rest frame; nodes whose rest centre lies in
// `fixedRegion` do not move (the tongue's root). Small displacements, so the
// network is linear:
//     m_i d̈_i = f_i − k_a d_i − Σ_j k_l (d_i − d_j) − c ḋ_i,
// integrated by implicit Euler in fixed steps of `timeStep` (unconditionally
// stable; the system matrix M + h C + h² K is inverted once at create()).
// Static answer: K d = f, the springs in series and parallel.
//
// Every node of the tree (all levels) follows the skeleton by linear moving
// least squares over its kWeights nearest skeleton nodes (an affine
// displacement field is reproduced exactly, value and slope): its sphere
// and SurfacePatch move by the interpolated displacement (displacement()),
// and a node's bound grows by how far the leaves below it can have moved
// relative to it (bound(): Σ|w| times the largest |d_j − its displacement|
// over the skeleton nodes those leaves are weighted on), so the deformed
// tree stays a valid hierarchy. Bounds are
// evaluated when asked for and kept until the next step: a tick costs the
// nodes the collision visits, not the whole tree. A node's patch follows
// the interpolant to first order: it is carried by the local affine map
// x ↦ origin + u + F (x − origin), F the deformation gradient
// (deformationGradient()), so its normals turn with a dent (they would be
// off by about |∇u| otherwise). Mesh vertices follow the same weights
// (bind() / deform(): the graphics follow the deformed tree).
//
// Contact forces come from the renderer (addForce on an environment node,
// object local frame; the node's weights share it over the skeleton) and
// act in the next step(): one haptic tick of lag, as in the paper.
//
// Real time: addForce(), step(), reset() and the accessors never allocate,
// lock or throw (create() and bind() allocate). One thread (the haptic
// thread) steps it; deform() may run on another only while step() does not.
//
// @code
//   auto tongue = dm::buildSphereTreeFitted(tongueMesh, {.levels = 5});
//   auto soft = dm::SphereTreeDeformation::create(*tongue, {.skeletonLevel = 2,
//                                                  .fixedRegion = dm::Aabb(rootLo, rootHi)});
//   auto r = dm::SphereTree6DofRenderer::create(mirror, {{.tree = *tongue, .deformation = *soft}});
// @endcode
#pragma once

#include <dm/collide/sphere_tree.hpp>
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>

#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <vector>

namespace dm {

/// Options of SphereTreeDeformation; see the file comment.
struct SphereTreeDeformationOptions {
  /// Level of the tree whose nodes are the mass points, 0..levels−1, at
  /// most kMaxSkeletonNodes nodes (level 2 or 3 of a fitted tree).
  int skeletonLevel = 2;
  /// kg, > 0: the object's mass, shared by the skeleton nodes by sphere volume.
  double mass = 0.05;
  /// N/m, ≥ 0: each skeleton node to its rest position. With no fixed node,
  /// > 0 (else the object floats away).
  double anchorStiffness = 100.0;
  /// N/m, ≥ 0: between touching skeleton nodes.
  double linkStiffness = 300.0;
  /// N·s/m, ≥ 0: each skeleton node against the rest frame.
  double damping = 1.0;
  /// s, > 0: the integrator's fixed step; step(dt) takes as many as dt holds.
  double timeStep = 1e-3;
  /// Object local frame: skeleton nodes whose rest centre lies in it stay put.
  std::optional<Aabb> fixedRegion;
};

/// A spring–sphere-tree soft object; see the file comment.
class SphereTreeDeformation {
 public:
  /// Most skeleton nodes (the dense system inverse is n² doubles).
  static constexpr int kMaxSkeletonNodes = 512;
  /// Skeleton nodes a point is interpolated over (its nearest).
  static constexpr std::size_t kWeights = 8;
  /// Most fixed steps one step() takes (a longer dt drops the rest: the
  /// object lags rather than stalling the haptic thread).
  static constexpr int kMaxSubsteps = 16;

  /// Fails with InvalidArgument naming the field ("options.skeletonLevel",
  /// "options.mass", ...) on a null tree, a level out of range or with more
  /// than kMaxSkeletonNodes nodes, a non-finite or out-of-range value, no
  /// anchor and no fixed node, or every skeleton node fixed. O(n³ + nodes).
  static Result<std::shared_ptr<SphereTreeDeformation>> create(
      std::shared_ptr<const SphereTree> rest, const SphereTreeDeformationOptions& options = {});
  ~SphereTreeDeformation();
  SphereTreeDeformation(const SphereTreeDeformation&) = delete;
  SphereTreeDeformation& operator=(const SphereTreeDeformation&) = delete;

  /// Adds `force` (N, object local frame) on tree node `node` (any level)
  /// for the next step(). Out-of-range nodes and non-finite forces are ignored.
  void addForce(std::uint32_t node, const Vec3& force) noexcept;
  /// Advances by dt (s; non-finite or ≤ 0: nothing) under the forces added
  /// since the last step (then cleared), in fixed steps of timeStep.
  /// Returns how far any node moved (m), a bound for the renderer's margin.
  /// O(kMaxSubsteps · n²).
  double step(double dt) noexcept;
  /// Back to rest, at rest; forces cleared.
  void reset() noexcept;

  /// The rest tree.
  const SphereTree& rest() const noexcept;
  /// The deformed node `node`'s bound (object local frame): the rest
  /// centre displaced, the rest bound radius grown (a leaf's: its radius).
  /// Kept until the next step() (not thread-safe: the stepping thread
  /// only). Out of range: a zero sphere. O(skeleton nodes below it), once a step.
  BoundingSphere bound(std::uint32_t node) const noexcept;
  /// m, object local frame: node `node`'s displacement, which also moves its
  /// SurfacePatch (zero out of range). O(1).
  Vec3 displacement(std::uint32_t node) const noexcept;
  /// The deformation gradient F = I + ∂u/∂x of the interpolant at
  /// node `node`'s rest centre (identity out of range): its patch deforms
  /// by x ↦ origin + u + F (x − origin), so its normals turn by F⁻ᵀ. O(1).
  Mat3 deformationGradient(std::uint32_t node) const noexcept;
  /// The skeleton: its node indices in the tree, and which are fixed.
  std::span<const std::uint32_t> skeleton() const noexcept;
  bool fixed(std::size_t skeletonIndex) const noexcept;
  /// N, object local frame: the force the springs exert on the object's
  /// fixed region and anchors together (the reaction to what pushes it;
  /// equal and opposite to the applied force at rest).
  Vec3 supportForce() const noexcept;

  /// Per-point skeleton weights for deform(): the graphics' binding.
  struct Binding {
    std::vector<std::array<std::uint32_t, kWeights>> index;  // skeleton indices
    std::vector<std::array<double, kWeights>> weight;        // sum 1 (some may be negative)
  };
  /// Binds points (object local frame, at rest) to the skeleton by the
  /// nodes' interpolation weights. O(points · skeleton).
  Binding bind(std::span<const Vec3> restPoints) const;
  /// out[i] = restPoints[i] + the bound displacement. Sizes must match the
  /// binding (else false, out untouched). No allocation.
  bool deform(const Binding& binding, std::span<const Vec3> restPoints, std::span<Vec3> out) const noexcept;

 private:
  struct State;  // sphere_tree_deformation.cpp
  explicit SphereTreeDeformation(std::unique_ptr<State> s) noexcept;
  std::unique_ptr<State> s_;
};

}  // namespace dm
