// dm/math/mesh_filters.hpp — clean-up filters for meshes from segmentation,
// scanning or isosurfacing, run by the scene loader before a mesh is used.
//
// keepLargestComponent() drops the floating specks and islands that a
// threshold or marching cubes leaves next to the organ of interest;
// smoothMesh() removes staircase and scanner noise with Taubin's λ|μ filter,
// which, unlike plain Laplacian smoothing, hardly shrinks the shape.
//
// @code
//   auto iso = dm::extractIsosurface(ct, {.iso = 150});
//   dm::Mesh liver = dm::keepLargestComponent(*iso);
//   if (auto s = dm::smoothMesh(liver, 20); !s) return s.error();
// @endcode
#pragma once

#include <dm/core/mesh.hpp>
#include <dm/core/result.hpp>

#include <cstddef>
#include <limits>

namespace dm {

/// The connected piece of `mesh` with the most triangles, where two triangles
/// are connected when they share a vertex index (so weld a triangle soup
/// first, see weldVertices()). Ties go to the piece whose first triangle comes
/// first. Triangles keep their relative order; vertices no kept triangle uses
/// are dropped and the rest keep their relative order, indices remapped.
/// Normals, uvs and colours are carried along when they have one entry per
/// position (an attribute of any other size is dropped). Triangles with an
/// out-of-range index belong to no piece and are dropped. An empty mesh gives
/// an empty mesh. If `removedComponents` is given it receives the number of
/// pieces dropped (pieces − 1, or 0). O(V + F) time and memory (flood fill
/// over a vertex → triangle table).
/// @code
///   std::size_t specks = 0;
///   dm::Mesh organ = dm::keepLargestComponent(segmented, &specks);
///   dm::log::info("dropped %zu islands", specks);
/// @endcode
Mesh keepLargestComponent(const Mesh& mesh, std::size_t* removedComponents = nullptr);

/// Options of smoothMesh().
struct SmoothOptions {
  int iterations = 10;  ///< λ|μ pairs, 0..1000; 5 to 50 is typical
  double lambda = 0.5;  ///< shrinking step, finite and > 0
  double mu = -0.53;    ///< inflating step, finite and < −λ
  /// Largest distance (m) a vertex may end up from where it started: each
  /// iteration ends by pulling any vertex further away back onto the sphere
  /// of this radius around its start. Since the vertices of an isosurface lie
  /// on it, this bounds the smoothed surface's vertices' distance to the
  /// original surface (half a voxel keeps the anatomy and removes the
  /// staircase of a 1 mm scan). Infinity: unbounded; otherwise finite, > 0.
  double maxDisplacement = std::numeric_limits<double>::infinity();
};

/// Taubin λ|μ smoothing (Taubin, "A signal processing approach to fair
/// surface design", SIGGRAPH 1995): each of `iterations` runs one shrinking
/// step p ← p + λ·L(p) and one inflating step p ← p + μ·L(p), where L(p) is
/// the mean of the vertex's one-ring neighbours (the vertices it shares a
/// triangle edge with, uniform "umbrella" weights) minus p, then applies
/// `maxDisplacement`. Vertices on a
/// boundary edge (one triangle) or a non-manifold edge (more than two), and
/// vertices no triangle uses, stay exactly where they are; degenerate
/// triangles (a repeated index) are ignored. Normals are recomputed
/// afterwards (Mesh::computeNormals()), also for 0 iterations; triangles,
/// uvs and colours are untouched. λ = 0.5, μ = −0.53 (pass-band
/// k = 1/λ + 1/μ ≈ 0.11) removes high-frequency noise while keeping the volume
/// nearly constant. O(iterations·(V + F)) time; memory: the one-ring table
/// and three position buffers, allocated once.
/// Fails with InvalidArgument (mesh unchanged) when iterations is outside
/// [0, 1000], λ is not a finite value > 0, μ is not finite or μ ≥ −λ,
/// maxDisplacement is not > 0 (NaN included), or the mesh is invalid
/// (Mesh::validate()).
/// @code
///   dm::Mesh skin = loadScan("face.stl");
///   if (auto s = dm::smoothMesh(skin, {.iterations = 10, .maxDisplacement = 0.5e-3}); !s) return s.error();
///   renderer.addMesh(skin);  // normals already recomputed
/// @endcode
Status smoothMesh(Mesh& mesh, const SmoothOptions& options);

/// smoothMesh() with `iterations`, λ and μ, unbounded displacement.
Status smoothMesh(Mesh& mesh, int iterations, double lambda = 0.5, double mu = -0.53);

}  // namespace dm
