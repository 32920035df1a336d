// dm/haptics/god_object.hpp — the 3-DOF god-object (proxy) haptic renderer
// on triangle meshes (Zilles & Salisbury 1995; Ruspini, Kolarov & Khatib
// 1997), with static/dynamic friction and force shading.
//
// Each tick the proxy (IHIP) moves from where it was toward the device point
// (HIP) as far as the surfaces allow, so it never penetrates:
//  1. a swept point (or, for a ball tip of radius r > 0, a swept sphere) from
//     the proxy toward the goal against every object's MeshBvh
//     (dm::sweepPoint / dm::sweepSphere, dm/collide/toi.hpp);
//  2. the first surface hit becomes a constraint plane n·(p − q) ≥ r + skin;
//     the next goal is the point closest to the HIP on the free side of all
//     active planes (up to three), solved in closed form from the Lagrange
//     system (one plane: projection, two: projection on their line, three:
//     their vertex); planes whose multiplier turns negative are released;
//  3. repeat until the proxy stops moving (at most maxIterations sweeps).
// The proxy is never teleported, only swept from its last valid position,
// so thin objects (a one-triangle plate) cannot be popped through, and it
// keeps a skin (1 µm) off every surface so rounding cannot tunnel it.
//
// Force = k·(proxy − HIP) − b·v_device (in contact), with k, b from the
// material of the object whose constraint carries the most load.
// Friction (per material): the proxy sticks while the tangential part of the
// spring force ≤ μs·normal part; once sliding it follows only to the edge of
// the μd cone (tangential = μd·normal) until it can stick again.
// Force shading (Ruspini's two passes): a first pass finds the goal on the
// plane through the proxy with the normal interpolated from vertex normals;
// a second, constrained pass moves the proxy toward that goal, so the force
// direction turns smoothly over a tessellated curved surface.
// Moving objects (setObjectPose): a proxy in contact with the object is
// carried by its pose change; a free proxy is pushed by it (a sweep of the
// proxy relative to the object).
// Deforming objects (deformObject): the object's tree is swapped for one
// refitted to the deformed vertices (built off the haptic thread, e.g. by
// dm::HapticTissue from a FemBody); a proxy in contact is carried with the
// point it touches, a free proxy left inside a closed object is put back
// outside. contact() tells which triangle and point the proxy touches, so
// the force can be handed back to what deforms the surface.
//
// Real time: tick() and setObjectPose() never allocate, lock, log or throw;
// cost O(maxIterations · objects · log(triangles)).
//
// @code
//   auto r = dm::GodObjectRenderer::create({{.bvh = organBvh, .material = {.stiffness = 800}}}, {});
//   if (!r) { dm::log::warn("%s", r.error().message().c_str()); return; }
//   dm::HapticResponse out = (*r)->tick({.dt = 1e-3, .devicePose = pose});
// @endcode
#pragma once

#include <dm/collide/bvh.hpp>
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>
#include <dm/haptics/renderer.hpp>

#include <array>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>
#include <string_view>
#include <vector>

namespace dm {

/// One environment object of a GodObjectRenderer.
struct GodObjectObject {
  /// Triangle mesh tree in the object's local frame, m (non-null). Triangles
  /// are CCW from outside; open meshes (plates) are felt from both sides.
  std::shared_ptr<const MeshBvh> bvh;
  Isometry3 pose = Isometry3::Identity();  ///< local → world, finite, rigid
  HapticMaterial material;                 ///< validated by create()
  /// Optional unit vertex normals for force shading, local frame, one per
  /// mesh vertex (bvh->vertexCount()). Empty: the BVH's angle-weighted
  /// pseudonormals for closed meshes, no shading for open ones.
  std::vector<Vec3> vertexNormals;
};

/// Where the proxy touched in the last tick (the constraint that carries
/// the most load).
struct GodObjectContact {
  bool active = false;        ///< in contact
  std::uint32_t object = 0;   ///< object index
  std::uint32_t triangle = 0; ///< mesh triangle index of that object
  Vec3 point = Vec3::Zero();  ///< the proxy's projection on the contact plane, world, m
  Vec3 normal = Vec3::Zero(); ///< unit, from the surface toward the proxy, world
  /// The triangle's vertex indices (the mesh given to the object's tree)
  /// and the point's barycentric coordinates on them.
  std::array<std::uint32_t, 3> vertices{};
  Vec3 barycentric = Vec3::Zero();
};

/// Options of GodObjectRenderer::create().
struct GodObjectOptions {
  double proxyRadius = 0.0;   ///< m, ≥ 0: 0 = point proxy, > 0 = ball tip (swept sphere)
  double skin = 1e-6;         ///< m, > 0: gap kept between the proxy and every surface
  int maxIterations = 8;      ///< sweeps per pass, [1, 64]
  bool forceShading = false;  ///< two-pass shading with interpolated vertex normals
  /// N, > 0 (may be +inf): the force magnitude is clamped to it.
  double maxForce = std::numeric_limits<double>::infinity();
};

/// The god-object renderer; see the file comment. Not thread-safe: one
/// haptic thread calls tick() and setObjectPose().
class GodObjectRenderer final : public HapticRenderer {
 public:
  /// Builds the renderer over `objects` (at least one). Fails with
  /// InvalidArgument naming "objects[i]" and the field for a null BVH, a
  /// non-finite or non-rigid pose, a bad material (HapticMaterial::validate),
  /// vertex normals of the wrong count or not finite/non-zero, or an option
  /// out of range. Allocates O(total triangles) (a triangle-index map per
  /// object for shading). The proxy starts at the origin; call reset().
  /// @code
  ///   auto r = dm::GodObjectRenderer::create(std::move(objects), {.proxyRadius = 0.001});
  ///   if (r) (*r)->reset(devicePose);
  /// @endcode
  static Result<std::unique_ptr<GodObjectRenderer>> create(std::vector<GodObjectObject> objects,
                                                           const GodObjectOptions& options);

  /// "godobject".
  std::string_view name() const noexcept override { return "godobject"; }
  /// Puts the proxy at the device point and forgets contact and friction
  /// state. A device point inside a closed object (or closer to it than the
  /// tip radius) puts the proxy just outside the object's nearest surface
  /// point instead, so a simulation may start with the device pressed in.
  /// Open meshes have no inside: the proxy stays at the device point.
  void reset(const Isometry3& devicePose) noexcept override;
  /// One tick (see the file comment). A non-finite device pose or a
  /// non-finite or non-positive dt gives zero force and keeps the proxy; a
  /// non-finite velocity drops the damping term. Real-time safe, deterministic.
  HapticResponse tick(const HapticInput& input) noexcept override;
  /// Number of objects given to create().
  std::size_t objectCount() const noexcept override { return objects_.size(); }
  /// Moves object `index` from the next tick on (see the file comment).
  /// Out-of-range indices and non-finite or non-rigid poses are ignored.
  void setObjectPose(std::size_t index, const Isometry3& pose) noexcept override;

  /// Deforms object `index` now: `tree` is the object's
  /// tree refitted to its deformed vertices (MeshBvh::refit of a copy of the
  /// tree given to create(): same triangle and vertex counts, same leaf
  /// order). The renderer reads `tree` until the next deformObject() for
  /// the object or its own destruction; keep it alive and unchanged until
  /// then (dm::HapticTissue's triple buffer does), but the tree it replaces
  /// is not read again. Call it from the thread that ticks. A proxy in contact with
  /// the object moves with the point it touches (same barycentric
  /// coordinates on the same triangle, its offset turned with the
  /// triangle's normal); a free proxy the deformation left inside a closed
  /// object, or within the tip radius, is put just outside, as by reset().
  /// Returns false, changing nothing, for an index out of range, a null
  /// tree, other counts, or an object created with vertexNormals (they would
  /// not follow the deformation; shading then uses the refitted
  /// pseudonormals). Real-time safe: no allocation.
  bool deformObject(std::size_t index, const MeshBvh* tree) noexcept;
  /// The tree object `index` (< objectCount()) is rendered against now.
  const MeshBvh& objectTree(std::size_t index) const noexcept { return *objects_[index].tree; }
  /// Where the proxy touched in the last tick; inactive when free.
  const GodObjectContact& contact() const noexcept { return contact_; }

  /// Current proxy position (centre of the ball tip), world, m.
  const Vec3& proxy() const noexcept { return proxy_; }
  /// Current pose of object `index` (< objectCount()), local → world.
  const Isometry3& objectPose(std::size_t index) const noexcept { return objects_[index].pose; }

  /// A constraint plane n·p ≥ offset (world); public for the closed-form
  /// solver's tests, not part of the stable API.
  struct Plane {
    Vec3 normal = Vec3::UnitZ();  ///< unit, pointing to the free side
    double offset = 0.0;          ///< m
    std::uint32_t object = 0;     ///< object index
    std::uint32_t triangle = 0;   ///< mesh triangle index
    Vec3 point = Vec3::Zero();    ///< contact point on the surface, world
  };

  /// The point closest to `goal` with normal_i·p ≥ offset_i for every one of
  /// `count` (≤ 4) planes, by the closed-form Lagrange solution on each
  /// subset of at most three planes (the KKT point with all multipliers ≥ 0).
  /// On return `count` planes are the active ones (multiplier > 0), moved to
  /// the front with their multipliers in `lambda`. Returns false (and leaves
  /// the planes) when no subset is feasible (contradictory planes). O(1).
  static bool solveConstraints(const Vec3& goal, Plane* planes, int& count, double* lambda,
                               Vec3& out) noexcept;

 private:
  struct ObjectState {
    std::shared_ptr<const MeshBvh> bvh;  // the tree given to create() (owned)
    const MeshBvh* tree = nullptr;       // the geometry felt now: bvh or a deformed copy
    Isometry3 pose;
    Isometry3 pendingPose;
    bool posePending = false;
    HapticMaterial material;
    std::vector<Vec3> vertexNormals;    // local, unit; empty = bvh pseudonormals or none
    std::vector<std::uint32_t> leafOf;  // mesh triangle → leaf-order index
    bool shaded = false;
  };
  struct Sweep {
    bool hit = false;
    double t = 1.0;
    Plane plane;
  };

  GodObjectRenderer(std::vector<ObjectState> objects, const GodObjectOptions& options) noexcept;

  Sweep sweepAll(const Vec3& from, const Vec3& to) const noexcept;
  /// Moves `p` toward `to` until the first surface (stopping a skin before
  /// it); true with that surface's plane in `hit` when blocked.
  bool move(Vec3& p, const Vec3& to, Plane& hit) const noexcept;
  /// Constrained motion of the proxy from `start` toward `goal`; returns the
  /// end point and leaves the active planes in planes_/planeCount_.
  Vec3 constrainedMove(const Vec3& start, const Vec3& goal) noexcept;
  Vec3 shadedNormal(const Plane& plane) const noexcept;
  void applyPendingPoses() noexcept;
  /// A proxy inside a closed object, or closer than the tip radius, goes
  /// just outside its nearest surface point; true if it moved.
  bool pushOutOf(const ObjectState& o) noexcept;
  /// Barycentric coordinates, vertices, face normal and proxy offset of
  /// contact_ in its object's current tree (local frame).
  void recordContactGeometry() noexcept;

  std::vector<ObjectState> objects_;
  GodObjectOptions options_;
  Vec3 proxy_ = Vec3::Zero();
  bool inContact_ = false;
  bool sliding_ = false;
  std::uint32_t contactObject_ = 0;
  GodObjectContact contact_;
  Vec3 contactFaceNormal_ = Vec3::Zero();  // local, unnormalised, at the last tick
  Vec3 contactOffset_ = Vec3::Zero();      // proxy − contact point, local
  std::array<Plane, 4> planes_{};
  std::array<double, 4> lambda_{};
  int planeCount_ = 0;
};

}  // namespace dm
