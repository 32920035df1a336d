// dm/collide/gjk.hpp — GJK distance and EPA penetration between convex shapes.
//
// GJK (Gilbert, Johnson & Keerthi 1988, with van den Bergen's termination
// tests) finds the closest points of the two shapes' *cores* (ConvexShape::
// supportCore); the margins (sphere/capsule radii) are subtracted afterwards,
// so sphere and capsule pairs are exact to rounding. The simplex sub-step is
// the exact Voronoi-region closest point (dm::closestPointOnTriangle and the
// tetrahedron's outside faces), which stays robust on degenerate simplices.
// When the cores overlap, EPA (expanding polytope with a horizon) gives the
// penetration depth, normal and deepest points; its polytope keeps face
// adjacency, so an expansion removes only the faces that see the new point.
// MPR (GjkOptions::method) is the cheaper alternative for penetration: an
// upper bound of the depth found along a portal between the shapes'
// interior points and the origin.
// Booleans of shapes without margin (and the overlap test before EPA) use a
// cheaper GJK that tracks only a search direction (Muratori's simplex
// update) and answers only with a certificate — a separating direction or
// a tetrahedron around the origin — falling back to the exact GJK when
// rounding leaves it unsure. For booleans its simplex starts with a point
// inside A − B (the shapes' interiorPoint()s), so that three support pairs
// prove a typical overlap. Everything works on the stack: no allocation,
// no locks, no exceptions, bounded iterations.
//
// @code
//   dm::GjkCache cache;                       // keep one per pair between steps
//   dm::GjkResult r = dm::gjkDistance(a, poseA, b, poseB, &cache);
//   if (r.distance < 0) applyContact(r.normal, -r.distance);
// @endcode
#pragma once

#include <dm/collide/shapes.hpp>
#include <dm/core/types.hpp>

#include <cstdint>

namespace dm {

/// Per-pair warm start, owned by the caller (e.g. the world's pair record).
/// Zero-initialised is a valid cold start.
struct GjkCache {
  /// Last separating direction (world frame, closest point of A − B; need not
  /// be unit). Zero: start from the centre offset.
  Vec3 direction = Vec3::Zero();
  std::uint32_t hintA = 0;  ///< support warm start of shape A (hull vertex index)
  std::uint32_t hintB = 0;  ///< support warm start of shape B
  int iterations = 0;       ///< GJK iterations of the last query (diagnostic)
};

/// Outcome of gjkDistance(), world frame.
struct GjkResult {
  /// Signed distance of the full shapes (m): > 0 separated, < 0 penetrating
  /// by −distance (EPA depth, or margin overlap of separated cores).
  double distance = 0.0;
  Vec3 pointA = Vec3::Zero();  ///< closest (or deepest) point on A, m
  Vec3 pointB = Vec3::Zero();  ///< closest (or deepest) point on B, m
  /// Unit normal from A to B: B moves along it to separate (or is found along
  /// it). Translating B by −distance·normal (if < 0) makes the shapes touch.
  Vec3 normal = Vec3::UnitX();
  /// False when EPA could not build a volume (flat shapes, e.g. two coplanar
  /// triangles): depth is then the margin sum and the normal a best guess.
  bool exact = true;
};

/// How gjkDistance() measures the penetration of overlapping cores.
enum class PenetrationMethod {
  /// Expanding polytope: the minimum translation distance, to epaTolerance.
  Epa,
  /// Minkowski portal refinement (Snethen, Game Programming Gems 7, 2008 —
  /// libccd's and Bullet's MPR): depth along the portal found from the
  /// shapes' interior points towards the origin. An upper bound of the
  /// minimum depth (equal for spheres and for shallow face contacts, larger
  /// for deep or skewed overlaps), usually a few times cheaper than EPA.
  /// Falls back to EPA when the Minkowski difference is flat.
  Mpr,
};

/// Tolerances and bounds of gjkDistance()/gjkIntersect().
struct GjkOptions {
  /// Stop when the distance bound gap is below relativeTolerance · distance².
  double relativeTolerance = 1e-12;
  /// EPA stops when the support along the nearest face's normal is within
  /// epaTolerance · (polytope size) of the face: the depth error bound.
  /// Polytope pairs terminate exactly well before it.
  double epaTolerance = 1e-9;
  int maxIterations = 128;     ///< GJK iterations
  int maxEpaIterations = 128;  ///< EPA expansions (each adds one vertex)
  bool penetration = true;     ///< measure the depth on overlap (else distance = 0 there)
  PenetrationMethod method = PenetrationMethod::Epa;
  /// MPR stops when a new support gains less than mprTolerance · (size of
  /// the shapes) over the portal (libccd's mpr_tolerance, made relative).
  double mprTolerance = 1e-6;
  int maxMprIterations = 128;  ///< MPR portal discoveries and refinements
};

/// True if the shapes overlap or touch (distance ≤ 0 within rounding).
/// Early-outs on the first separating direction; with a warm cache a
/// separated, slowly moving pair usually costs one support pair. O(k·support).
/// @code
///   dm::GjkCache c;
///   bool hit = dm::gjkIntersect(box, poseA, hull, poseB, &c);
/// @endcode
bool gjkIntersect(const ConvexShape& a, const Isometry3& poseA, const ConvexShape& b, const Isometry3& poseB,
                  GjkCache* cache = nullptr, const GjkOptions& options = {}) noexcept;

/// Signed distance, closest/deepest points and normal between two convex
/// shapes (world frame, m). Never fails: degenerate input gives a finite best
/// estimate with `exact = false`. EPA keeps its polytope (≤ 128 vertices,
/// 256 faces) on the stack: about 30 KB.
/// @code
///   dm::GjkResult r = dm::gjkDistance(capsule, poseA, sphere, poseB);
///   double gap = r.distance;   // m
/// @endcode
GjkResult gjkDistance(const ConvexShape& a, const Isometry3& poseA, const ConvexShape& b,
                      const Isometry3& poseB, GjkCache* cache = nullptr,
                      const GjkOptions& options = {}) noexcept;

}  // namespace dm
