// dm/math/simplify.hpp — quadric-error mesh simplification and discrete levels of detail.
//
// simplifyMesh() reduces a triangle mesh by greedy edge collapses ordered by
// the quadric error metric of Garland & Heckbert ("Surface Simplification
// Using Quadric Error Metrics", SIGGRAPH 1997): every vertex carries the sum
// of the area-weighted squared-distance quadrics of its original faces, an
// edge (u, v) collapses to the point minimising Q_u + Q_v (the 3x3 system,
// else the best point of the edge), cheapest first from a priority queue with
// lazy deletion. Collapses that would break the surface are refused: the link
// condition (Dey et al. 1999) keeps a manifold a manifold of the same genus,
// no face may flip or become a sliver, and boundary edges keep their shape
// (penalty planes through them; a boundary vertex never leaves the boundary).
// With a finite SimplifyOptions::maxError every collapse is also checked
// against the original surface in both directions: points of the original
// (vertices, edge midpoints, centroids and three inner points per face)
// against the new faces around the vertex they merged into, and a grid of
// points about maxError apart on each new face against the original (through
// a BVH). The result is within maxError at all those points; between them the
// true distance can exceed it by a fraction of an original edge length.
//
// buildLods() chains simplifications into discrete levels of detail and
// hausdorffDistance() measures how far two meshes are apart.
//
// @code
//   dm::SimplifyReport rep;
//   auto lod = dm::simplifyMesh(mesh, {.targetRatio = 0.1, .maxError = 0.5e-3}, &rep);
//   if (lod) dm::log::info("%zu -> %zu triangles, %g m", rep.trianglesBefore, rep.trianglesAfter,
//   rep.maxDistance);
// @endcode
#pragma once

#include <dm/core/mesh.hpp>
#include <dm/core/result.hpp>

#include <cstddef>
#include <functional>
#include <limits>
#include <span>
#include <vector>

namespace dm {

/// What simplifyMesh() aims for and what it must keep.
struct SimplifyOptions {
  double targetRatio = 0.5;         ///< fraction of triangles to keep, (0, 1]
  std::size_t targetTriangles = 0;  ///< if > 0, overrides targetRatio
  /// m: never move the surface further than this from the original (stop
  /// early instead). Infinity disables the check (and its cost).
  double maxError = std::numeric_limits<double>::infinity();
  /// Boundary edges keep their shape: penalty planes perpendicular to the
  /// boundary faces, boundary vertices move only along the boundary, and
  /// vertices of non-manifold edges never move.
  bool preserveBoundary = true;
  /// Reject collapses that create non-manifold edges, flip a face normal, or
  /// change the genus of a closed mesh (link condition), and slivers.
  bool preserveTopology = true;
  /// Called with the fraction done in [0, 1], from the calling thread, at
  /// most ~100 times; may be empty.
  std::function<void(double)> progress;
};

/// What simplifyMesh() did.
struct SimplifyReport {
  std::size_t trianglesBefore = 0, trianglesAfter = 0;
  /// m: measured symmetric Hausdorff distance between result and input
  /// (hausdorffDistance with vertices, edge midpoints and centroids).
  double maxDistance = 0.0;
};

/// Simplifies `mesh` to about options.targetTriangles (else targetRatio ·
/// triangleCount()) triangles; fewer collapses happen when the topology,
/// boundary or maxError checks refuse the rest. Degenerate input triangles
/// are dropped. The result has no unused vertices, recomputed normals, and
/// the uvs and colours of the surviving vertices. The report (optional)
/// costs one hausdorffDistance() of the two meshes.
/// O(F log F) time, O(F) memory (about 0.2–0.3 M input triangles/s on one
/// core); a finite maxError adds work proportional to the original points per
/// remaining vertex and the new faces' sample grids (about 10x slower).
/// Fails with InvalidArgument on an empty or invalid mesh (Mesh::validate():
/// NaN coordinates, indices out of range), a ratio outside (0, 1] or NaN, or
/// a negative or NaN maxError.
/// @code
///   auto out = dm::simplifyMesh(mesh, {.targetRatio = 0.25});
///   if (!out) return out.error();
///   dm::writeMesh(*out, "organ_lod1.ply");
/// @endcode
Result<Mesh> simplifyMesh(const Mesh& mesh, const SimplifyOptions& options, SimplifyReport* report = nullptr);

/// One level of detail.
struct MeshLod {
  Mesh mesh;
  double ratio = 1.0;        ///< triangles of this level / triangles of the input
  double maxDistance = 0.0;  ///< m: measured Hausdorff distance to the input mesh (LOD 0: 0)
};

/// LOD 0 is the input; each level simplifies the previous one to ratios[i]
/// of the input's triangles (ratios strictly decreasing in (0, 1]); the
/// maxError of `base` applies to each step. Each level's maxDistance is
/// measured against the input (not the previous level).
/// Fails like simplifyMesh, and on ratios that are not strictly decreasing.
/// @code
///   const double ratios[] = {0.5, 0.2, 0.05};
///   auto lods = dm::buildLods(skin, ratios);
///   for (const auto& l : *lods) dm::log::info("%zu tris, %g m", l.mesh.triangleCount(), l.maxDistance);
/// @endcode
Result<std::vector<MeshLod>> buildLods(const Mesh& mesh, std::span<const double> ratios,
                                       const SimplifyOptions& base = {});

/// Symmetric Hausdorff distance between two triangle meshes (m), sampled:
/// vertices, edge midpoints and face centroids (plus `samplesPerTriangle`
/// deterministic pseudo-random barycentric samples) of each mesh against the
/// exact closest point on the other, through a bounding-volume hierarchy.
/// A lower bound of the true distance that converges with the sampling.
/// Triangles with out-of-range indices are ignored; infinity when exactly
/// one mesh has no triangles, 0 when both have none.
/// O((Fa + Fb) · samples · log F) time, parallel over triangles.
/// @code
///   double d = dm::hausdorffDistance(original, simplified);
///   EXPECT_LT(d, 1e-3);
/// @endcode
double hausdorffDistance(const Mesh& a, const Mesh& b, int samplesPerTriangle = 4);

}  // namespace dm
