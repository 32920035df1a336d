// dm/collide/toi.hpp — time of impact of moving shapes within one step:
// conservative advancement on the distance query (convex pairs and meshes),
// the bisection resolver on the boolean query (every supported pair), and
// swept point / swept sphere casts against triangle meshes for a haptic
// god-object proxy.
//
// Motion model: over a step t ∈ [0, 1] a shape's frame moves from
// Motion::start to Motion::end with its origin on a straight line at constant
// speed and its rotation turning at constant angular velocity about a fixed
// world axis (the shortest-path slerp of the two orientations, about the
// frame origin). A point at distance ≤ r from the frame origin therefore moves
// at most |Δx| + θ·r during the step (θ ∈ [0, π] the rotation angle), which
// is the bound conservative advancement uses.
//
// All inputs and results are in the world frame, metres; t is the fraction
// of the step.
//
// @code
//   dm::Motion tool{toolPosePrev, toolPoseNow}, organ = dm::Motion::stationary(organPose);
//   dm::ToiResult r = dm::conservativeAdvancement(toolShape, tool, organShape, organ);
//   if (r.hit) toolPose = tool.at(r.t);   // stop the tool at first contact
// @endcode
#pragma once

#include <dm/collide/bvh.hpp>
#include <dm/collide/mesh_query.hpp>
#include <dm/collide/query.hpp>
#include <dm/collide/shapes.hpp>
#include <dm/core/types.hpp>

#include <cstdint>

namespace dm {

/// Rigid motion of a shape's frame over one step (see the file comment):
/// translation interpolated linearly, rotation by slerp at constant angular
/// velocity about a fixed world axis, both about the frame origin.
struct Motion {
  Isometry3 start = Isometry3::Identity();  ///< pose at t = 0 (local → world)
  Isometry3 end = Isometry3::Identity();    ///< pose at t = 1

  /// A shape that does not move during the step.
  static Motion stationary(const Isometry3& pose) noexcept { return {pose, pose}; }

  /// Pose at t (t in [0, 1]; other values extrapolate). at(0) == start and
  /// at(1) == end up to rounding. O(1), no allocation.
  Isometry3 at(double t) const noexcept;
  /// Displacement of the frame origin over the step, m.
  Vec3 displacement() const noexcept { return end.translation() - start.translation(); }
  /// Rotation vector of the step (world frame): unit axis × angle, angle in
  /// [0, π] rad; the angular velocity in rad per step.
  Vec3 rotationVector() const noexcept;
  /// Upper bound of the distance any point within `radius` (m) of the frame
  /// origin travels during the step: |Δx| + θ·radius, m. A non-rotating
  /// motion gives |Δx| for any radius (also +∞).
  double maxPointDisplacement(double radius) const noexcept;
};

/// What a time-of-impact query found.
enum class ToiStatus : std::uint8_t {
  Hit,            ///< first contact at t within the step
  NoHit,          ///< the shapes stay apart over the whole step
  Overlapping,    ///< already in contact at t = 0
  MaxIterations,  ///< gave up; t is the last time known to be free (a safe lower bound)
  Unsupported,    ///< no distance (CA) or boolean (bisection) collider for the pair
};

/// Result of conservativeAdvancement() and bisectImpact(), world frame.
struct ToiResult {
  ToiStatus status = ToiStatus::NoHit;
  /// True for Hit and Overlapping.
  bool hit = false;
  /// Time of impact in [0, 1]: CA gives the last advancement (distance <
  /// tolerance there, never later than the true first contact); bisection the
  /// first overlapping time it found (within `tolerance` after the true one).
  /// 1 for NoHit.
  double t = 1.0;
  Vec3 point = Vec3::Zero();    ///< contact point at t, m (midway between the closest points)
  Vec3 normal = Vec3::UnitZ();  ///< unit contact normal at t, from A to B
  /// Signed distance at t, m (CA: in [0, tolerance) on Hit; bisection: minus
  /// the contact depth; negative on Overlapping).
  double distance = 0.0;
  int iterations = 0;  ///< distance (CA) or boolean (bisection) queries made
};

/// Options of conservativeAdvancement().
struct ToiOptions {
  double tolerance = 1e-6;  ///< m: contact when the distance drops below it (> 0)
  int maxIterations = 200;  ///< distance queries before giving up with MaxIterations
};

/// Time of first contact of two moving shapes by conservative advancement
/// (Mirtich 1996; Zhang et al. 2006): query the distance d at t, advance t by
/// d / μ where μ bounds how fast the distance can shrink, until d < tolerance
/// (Hit) or t passes 1 (NoHit). Never overshoots the true contact time.
/// Bounds, with rA, rB the radius of a sphere about each frame origin that
/// contains the shape (Shape::boundingSphere()) and ωA, ωB the rotation
/// vectors:
///  * convex pairs (ConvexShape or Plane on both sides): the separating
///    plane of the closest points is valid over the interval, so
///    μ = max(0, n·(ΔxA − ΔxB)) + |n × ωA|·rA + |n × ωB|·rB along the unit
///    normal n (A → B) — tight for translations;
///  * any other pair (triangle meshes, compounds): μ = |ΔxA − ΔxB| + |ωA|·rA
///    + |ωB|·rB, the largest relative speed of any two points.
/// Distances come from dm::distance() (the collider table), so every pair
/// with a distance collider works: convex pairs, mesh–mesh, mesh–sphere,
/// mesh–capsule, compounds of those; others report Unsupported, as do a
/// rotating unbounded shape (plane) and a NaN distance (non-finite poses). Costs `iterations`
/// distance queries; no allocation except what dm::collide() needs for the
/// normal when the shapes already overlap at t = 0.
/// @code
///   dm::ToiResult r = dm::conservativeAdvancement(ball, dm::Motion{p0, p1}, floor,
///                                                 dm::Motion::stationary(floorPose));
///   if (r.status == dm::ToiStatus::Hit) ballPose = dm::Motion{p0, p1}.at(r.t);
/// @endcode
ToiResult conservativeAdvancement(const Shape& a, const Motion& motionA, const Shape& b,
                                  const Motion& motionB, const ToiOptions& options = {},
                                  PairCache* cache = nullptr);

/// Options of bisectImpact().
struct BisectOptions {
  /// Uniform samples of the step after t = 0 (≥ 1): the boolean query runs at
  /// t = 1/samples, 2/samples, ... 1 until the first overlap.
  int samples = 8;
  double tolerance = 1e-6;  ///< final bracket width in t (fraction of the step, > 0)
  int maxIterations = 64;   ///< bisection halvings at most (after the sampling)
};

/// Time of first contact of two moving shapes with only the boolean query
/// (dm::intersect), so it works for every pair the collider table supports,
/// user shapes included: sample the step at options.samples uniform times,
/// take the first overlapping sample, bisect between it and the sample before
/// it down to options.tolerance, and report the contact (dm::collide(), the
/// deepest contact) at the overlapping end of the bracket. It can miss a
/// contact that begins and ends between two samples (a thin wall crossed
/// fast, a grazing touch): use more samples, or conservative advancement
/// where a distance exists. Cost: ≤ samples + 1 + log2(1 / (samples ·
/// tolerance)) boolean queries and one contact query.
/// @code
///   dm::ToiResult r = dm::bisectImpact(drill, drillMotion, bone, dm::Motion::stationary(bonePose));
///   if (r.hit) stopAt(drillMotion.at(r.t), r.point, r.normal);
/// @endcode
ToiResult bisectImpact(const Shape& a, const Motion& motionA, const Shape& b, const Motion& motionB,
                       const BisectOptions& options = {});

/// Options of sweepPoint() and sweepSphere().
struct SweepOptions {
  /// Ignore triangles whose front face (CCW) the motion does not approach
  /// (direction · face normal ≥ 0), e.g. to leave a closed mesh from inside.
  bool cullBackFaces = false;
  /// m (≥ 0), sweepSphere() only: a triangle counts only if the sphere would
  /// go deeper than `skin` into it during the step, so a sphere sliding on a
  /// face, or grazing an edge, at exactly its radius (up to rounding) is not
  /// stopped; and a sphere already in contact is stopped only if it moves
  /// deeper (it can slide along or leave the surface).
  double skin = 1e-9;
};

/// What a sweep found.
enum class SweepStatus : std::uint8_t {
  NoHit,             ///< free over the whole motion
  Hit,               ///< first contact at t (t = 0: touching at the start and moving deeper)
  StartPenetrating,  ///< t = 0: the sphere starts more than `skin` deep in a triangle and moves deeper
};

/// First contact of a sweep, world frame.
struct SweepHit {
  SweepStatus status = SweepStatus::NoHit;
  double t = 1.0;             ///< fraction of the motion from `from` to `to`, [0, 1]
  Vec3 point = Vec3::Zero();  ///< contact point on the mesh, m
  /// Unit normal: sweepPoint() the triangle's outward (CCW) face normal;
  /// sweepSphere() from the contact point to the sphere centre at t (for a
  /// face contact, the face normal on the sphere's side).
  Vec3 normal = Vec3::UnitZ();
  std::uint32_t triangle = kNoTriangle;  ///< mesh triangle index
  bool hit() const noexcept { return status != SweepStatus::NoHit; }
};

/// First hit of the point moving on the segment from → to (world, m) with the
/// mesh (MeshBvh at `pose`): a segment cast through the BVH with the
/// watertight dm::rayTriangle (both faces unless culled; a point starting on
/// a triangle hits at t = 0). A zero or non-finite motion gives NoHit.
/// O(log n) typical, no allocation, no exceptions.
/// @code
///   dm::SweepHit h = dm::sweepPoint(*organ.bvh(), organPose, tipPrev, tipNow);
///   if (h.hit()) tipNow = h.point;
/// @endcode
SweepHit sweepPoint(const MeshBvh& bvh, const Isometry3& pose, const Vec3& from, const Vec3& to,
                    const SweepOptions& options = {}) noexcept;
/// sweepPoint() on a TriangleMesh shape (NoHit when it has no BVH).
SweepHit sweepPoint(const TriangleMesh& mesh, const Isometry3& pose, const Vec3& from, const Vec3& to,
                    const SweepOptions& options = {}) noexcept;

/// First contact of a sphere of `radius` (m, > 0; 0 gives sweepPoint())
/// whose centre moves on the segment from → to (world, m) with the mesh:
/// BVH traversal with the node boxes inflated by the radius, and per
/// triangle the exact earliest contact of the face interior (plane offset by
/// the radius), the three edges (segment against an infinite cylinder, a
/// quadratic) and the three corners (segment against a sphere); the minimum
/// over triangles. Starting contacts follow SweepOptions::skin: t = 0 with
/// Hit (touching) or StartPenetrating (deeper than skin), normal pointing
/// out of the deepest triangle. O(log n) typical; no allocation, no
/// exceptions: fit for a 1 kHz god-object proxy.
/// @code
///   dm::SweepHit h = dm::sweepSphere(*organ.bvh(), organPose, 0.002, proxy, device);
///   proxy = h.hit() ? Vec3(proxy + h.t * (device - proxy)) : device;   // then slide on h.normal
/// @endcode
SweepHit sweepSphere(const MeshBvh& bvh, const Isometry3& pose, double radius, const Vec3& from,
                     const Vec3& to, const SweepOptions& options = {}) noexcept;
/// sweepSphere() on a TriangleMesh shape (NoHit when it has no BVH).
SweepHit sweepSphere(const TriangleMesh& mesh, const Isometry3& pose, double radius, const Vec3& from,
                     const Vec3& to, const SweepOptions& options = {}) noexcept;

}  // namespace dm
