// dm/haptics/sphere_tree_6dof.hpp — 6-DOF constraint-based haptic rendering
// with sphere trees (Wang, Zhang, Wang, Zhao et al., "Six-degree-of-freedom
// haptic rendering using configuration-based optimization", IEEE ToH 2013;
// "Haptic rendering for dental training system").
//
// The tool and the environment objects are sphere trees. The tool is
// represented by the spheres of one chosen level of its tree (3, 4, 5, ...:
// the accuracy/speed trade-off), the environment by its leaf spheres.
//
// Spheres alone stand off a curved surface by up to a sphere's radius and
// give normals between sphere centres, tens of degrees off the surface's. So
// where a tree built from a mesh stores a SurfacePatch (a quadric fitted to
// the node's surface, dm/collide/sphere_tree.hpp) that fits within
// `surfaceTolerance`, the node collides through its patch instead: a tool
// patch by its support point (the point of the patch farthest towards the
// environment), an environment leaf by the patch's surface and normal at
// the tool point. Candidate pairs are still found with the spheres (which
// contain the patches); a tool point only counts against an environment
// patch that it lies over, and at most a quarter of the patch's width below
// it. An environment leaf at an edge, a corner, a groove or a thin wall
// whose surface is two or three flat faces collides through its crease
// (the faces' planes, SurfacePatch::Crease): its normal is the direction
// from the crease's nearest point to the tool patch's centre of curvature
// (beside an edge, not either face's normal), and a crease takes a tool
// point before any face patch it also lies over (a face's patch reaches
// past a convex edge). Other nodes, and trees without patches, collide
// through their spheres as in the published method. Each
// tick the graphic tool's configuration q_g (position and orientation, the
// orientation as a rotation increment about the previous graphic pose) is
// the minimiser of
//     ½ (q_g − q_h)ᵀ M (q_g − q_h),  M = diag(m, m, m, I, I, I),
// under the linearised non-penetration constraints of the candidate sphere
// pairs (tool sphere i, environment leaf j, normal n from j to i, lever r
// from the tool origin to i's centre, signed gap d):
//     n·(Δx + Δθ × r) ≥ −d
// (for a patch: n its normal at the tool point, r the lever to that point).
// Candidates are the pairs within a margin of the previous graphic pose:
// the step the tool may take this tick (how far the handle moved since the
// last tick, as translation + rotation × tool reach, plus how far the
// objects moved, plus `marginEpsilon` to catch up with a handle that drew
// ahead, at most `maxStep`) plus `marginEpsilon`. The motion is clamped to
// the step (and, when more than maxConstraints pairs are near, to the gap
// of the nearest dropped pair), so no contact can be missed, and a
// swept-sphere test of every candidate along the straight motion moves the
// tool back to the time of impact so it never passes through thin objects.
// The QP is solved by projected Gauss–Seidel on its dual, re-linearised a
// few times per tick. Force and torque on the user: a 6×6 diagonal spring
// K (q_g − q_h) between the graphic tool and the handle (no virtual
// coupling dynamics; K comes from the options, not from the materials'
// stiffness). The rendering is frictionless: the materials' friction
// coefficients are validated but not rendered; their damping acts on the
// device velocity while the tool touches the object.
//
// Patient changes. The force on each object is the user's force shared over
// the touching constraints by their multipliers (Newton's third law). A soft
// object (SphereTreeObject::deformation, dm/haptics/sphere_tree_deformation.hpp)
// takes its share on the nodes touched and is stepped at the start of the
// next tick; its deformed tree is what collides, and how far it moved
// widens the margin like an object's motion. A bonded piece
// (releaseForce) comes off in the tick its force exceeds the bond: from
// the next tick on it does not collide, and the tool, no longer held,
// follows the handle — the sudden drop of the feedback force the seed
// reports for calculus removal.
//
// Real time: tick() and setObjectPose() never allocate, lock or throw; all
// buffers are sized by create() from options.maxConstraints.
//
// @code
//   auto tool = dm::buildSphereTreeFitted(dm::makeIcosphere(0.003, 3), {.levels = 5});
//   auto r = dm::SphereTree6DofRenderer::create(*tool, {{.tree = toothTree}}, {.toolLevel = 4});
//   dm::HapticResponse out = (*r)->tick({.dt = 1e-3, .devicePose = handlePose});
// @endcode
#pragma once

#include <dm/collide/sphere_tree.hpp>
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>
#include <dm/haptics/renderer.hpp>
#include <dm/haptics/sphere_tree_deformation.hpp>

#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

namespace dm {

/// One environment object of the sphere-tree renderer.
struct SphereTreeObject {
  /// Stored or implicit (voxel) sphere tree, object local frame (m). Its
  /// leaf spheres are the object's surface. Required.
  std::shared_ptr<const SphereHierarchy> tree;
  Isometry3 pose = Isometry3::Identity();  ///< local → world
  HapticMaterial material;                 ///< damping is rendered; friction is not (see the file comment)
  std::string name;                        ///< for messages; may be empty
  /// A soft object: the spring–sphere-tree model built on `tree` (which
  /// must then be that stored tree). The renderer steps it at the start of
  /// every tick and feeds it the contact forces; null = rigid.
  std::shared_ptr<SphereTreeDeformation> deformation;
  /// N, > 0: a bonded piece (calculus on a tooth) comes off when the tool
  /// pushes it harder than this, and collides no more (objectReleased());
  /// infinity = never.
  double releaseForce = std::numeric_limits<double>::infinity();
};

/// Options of SphereTree6DofRenderer.
struct SphereTree6DofOptions {
  /// Level of the tool tree whose spheres collide (0 = root); the tool tree
  /// must have more than `toolLevel` levels. Deeper = more accurate, slower.
  int toolLevel = 4;
  /// kg, > 0: translational weight m of M.
  double mass = 0.1;
  /// kg·m², ≥ 0: rotational weight I of M (isotropic); 0 = m·(2/5)·R² with R
  /// the tool root sphere's radius (a solid ball's inertia).
  double inertia = 0.0;
  /// N/m per world axis, each > 0: the linear part of K.
  Vec3 linearStiffness = Vec3::Constant(1000.0);
  /// N·m/rad per world axis, each ≥ 0: the angular part of K; all three 0 =
  /// linearStiffness · I / m (K ∝ M: the torque is then r × F of the contacts).
  Vec3 angularStiffness = Vec3::Zero();
  /// Most constraints per tick, 1..65536; beyond it the deepest (smallest
  /// gap) candidate pairs are kept and the tool moves at most the smallest
  /// dropped gap in that tick (so it cannot hit a dropped pair). Sizes the
  /// preallocated buffers.
  int maxConstraints = 256;
  /// Projected Gauss–Seidel sweeps per linearisation, 1..10000.
  int solverIterations = 60;
  /// Linearisations (QP solves) per tick, 1..16.
  int linearizations = 3;
  /// m, ≥ 0: how much farther than the handle moved the tool may move in a
  /// tick (catch-up speed = marginEpsilon / dt), the extra margin of the
  /// candidate pairs, and the gap below which a pair counts as touching.
  double marginEpsilon = 1e-4;
  /// m, > 0: the farthest any tool sphere moves in one tick (the tool's
  /// speed limit; a handle farther away is followed over several ticks).
  double maxStep = 0.02;
  /// ≥ 0, a share of a node's sphere radius: a tool node (on toolLevel) or
  /// an environment leaf whose SurfacePatch lies within this share of its
  /// radius of the node's surface (and whose normals agree within about
  /// 25°) collides through the patch, exactly to second order on smooth
  /// surfaces; an environment leaf at an edge, corner, groove or thin wall
  /// whose crease planes lie within it of its facets, through the crease;
  /// other nodes and trees without patches (given and implicit trees)
  /// collide through their spheres. 0 = spheres only (the published method).
  double surfaceTolerance = 0.1;
};

/// The 6-DOF constraint-based sphere-tree haptic renderer; see the file
/// comment. name() is "spheretree". Not thread-safe: one haptic thread
/// calls tick() and setObjectPose().
class SphereTree6DofRenderer final : public HapticRenderer {
 public:
  /// Builds the renderer for `tool` (a stored sphere tree, tool local frame,
  /// the handle pose is its frame) and `objects`. Fails with
  /// InvalidArgument naming the field ("objects[2].tree", "objects[0]
  /// (gum).material/damping", "options.toolLevel", ...) on a null tree, a
  /// non-finite pose, an invalid material, a tool tree with toolLevel or
  /// fewer levels, or an option out of its range. No objects is allowed (free space). O(tool nodes +
  /// objects).
  /// @code
  ///   auto r = dm::SphereTree6DofRenderer::create(*tool, {{.tree = plate}}, {});
  ///   if (!r) return r.error();
  /// @endcode
  static Result<std::unique_ptr<SphereTree6DofRenderer>> create(std::shared_ptr<const SphereTree> tool,
                                                                std::vector<SphereTreeObject> objects,
                                                                const SphereTree6DofOptions& options = {});

  ~SphereTree6DofRenderer() override;

  std::string_view name() const noexcept override { return "spheretree"; }
  /// Puts the graphic tool at `devicePose` and clears the history; a tool
  /// placed inside an object is pushed out over the next ticks.
  void reset(const Isometry3& devicePose) noexcept override;
  /// One haptic tick: candidate pairs, QP solves, swept-sphere check, force.
  /// A non-finite input or dt ≤ 0 returns zero force and keeps the state.
  /// O(pairs visited + solverIterations · linearizations · constraints); no
  /// allocation.
  HapticResponse tick(const HapticInput& input) noexcept override;
  std::size_t objectCount() const noexcept override;
  void setObjectPose(std::size_t index, const Isometry3& pose) noexcept override;

  /// Current graphic tool pose (world).
  Isometry3 graphicPose() const noexcept;
  /// Level of the tool tree used, and its sphere count.
  int toolLevel() const noexcept;
  std::size_t toolSphereCount() const noexcept;
  /// m: the largest tool sphere radius on the used level, and the largest
  /// environment leaf radius: the approximation error of the contact
  /// surfaces is below 2·(sum of both).
  double toolSphereMaxRadius() const noexcept;
  double environmentLeafMaxRadius() const noexcept;
  /// Candidate pairs of the last tick (before truncation to maxConstraints).
  std::size_t lastCandidateCount() const noexcept;
  /// N, world: the force the tool put on object `index` in the last tick
  /// (the user's force K (q_h − q_g) shared over the touching constraints
  /// by their multipliers; zero out of range or out of contact).
  Vec3 objectForce(std::size_t index) const noexcept;
  /// N·m, world: the moment of objectForce(index) about the world origin,
  /// each row's share acting at its tool point (a sphere's surface point
  /// toward the object, or a patch's support point) at the final pose. What
  /// a physics engine applies to a body the tool pushes
  /// (dm::ToolImpulseChannel::addWrench).
  Vec3 objectTorque(std::size_t index) const noexcept;
  /// Whether object `index` came off (its releaseForce was exceeded).
  bool objectReleased(std::size_t index) const noexcept;

 private:
  struct State;  // sphere_tree_6dof.cpp
  explicit SphereTree6DofRenderer(std::unique_ptr<State> state) noexcept;
  std::unique_ptr<State> s_;
};

}  // namespace dm
