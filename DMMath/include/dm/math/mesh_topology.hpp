// dm/math/mesh_topology.hpp — combinatorial analysis and repair of triangle meshes.
//
// analyzeTopology() answers "is this mesh a closed, consistently oriented
// 2-manifold, how many pieces, what genus, what volume" — the questions to ask
// of a mesh before using it for collision, physics or mass properties (and
// what `dmtool info` prints). weldVertices() merges coincident vertices of a
// triangle soup (e.g. from STL) so that those questions have an answer.
#pragma once

#include <dm/core/mesh.hpp>
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>

#include <cstddef>
#include <optional>

namespace dm {

/// What analyzeTopology() found. Counts refer to undirected edges {a, b}.
struct MeshTopology {
  std::size_t vertices = 0;              ///< positions referenced by at least one triangle
  std::size_t unreferencedVertices = 0;  ///< positions no triangle uses
  std::size_t edges = 0;                 ///< distinct undirected edges of non-degenerate triangles
  std::size_t triangles = 0;             ///< all triangles
  std::size_t degenerateTriangles = 0;   ///< triangles repeating an index (ignored by the rest)
  std::size_t boundaryEdges = 0;         ///< edges with exactly one triangle
  std::size_t nonManifoldEdges = 0;      ///< edges with more than two triangles
  /// Vertices whose triangles do not form one fan (connected through shared
  /// edges), e.g. two cones touching at their tips.
  std::size_t nonManifoldVertices = 0;
  /// Edges with two triangles that traverse them in the same direction (one
  /// of the two is flipped), plus edges with more than two triangles.
  std::size_t misorientedEdges = 0;
  std::size_t components = 0;  ///< connected pieces (triangles joined by shared vertices)
  /// V − E + F over referenced vertices, edges and non-degenerate triangles.
  /// 2 per sphere-like closed piece, 0 for a torus, 2 − 2g for genus g.
  long long eulerCharacteristic = 0;

  bool isClosed = false;                ///< at least one triangle and no boundary edges
  bool isManifold = false;              ///< no non-manifold edges or vertices
  bool isOrientedConsistently = false;  ///< every edge with two triangles is used once in each direction
  /// Total genus Σ gᵢ = components − χ/2, set for closed, oriented manifolds.
  std::optional<long long> genus;
  /// Signed enclosed volume (m³, divergence theorem; positive when triangles
  /// are counter-clockwise from outside), set for closed, oriented manifolds.
  std::optional<double> volume;
  /// Centroid of the enclosed solid (m), set when `volume` is set and nonzero.
  std::optional<Vec3> centroid;
  double surfaceArea = 0;  ///< m²
};

/// Analyses the connectivity of `mesh`. Indices must be in range (see
/// Mesh::validate()); out-of-range triangles are counted as degenerate.
/// O(V + F) time and memory (edges are grouped per lower vertex).
/// @code
///   dm::MeshTopology t = dm::analyzeTopology(mesh);
///   if (!t.isClosed || !t.isManifold) dm::log::warn("mesh is not watertight");
///   if (t.volume) mass = density * *t.volume;
/// @endcode
MeshTopology analyzeTopology(const Mesh& mesh);

/// What weldVertices() changed.
struct WeldReport {
  std::size_t verticesRemoved = 0;   ///< positions merged into an earlier one
  std::size_t trianglesRemoved = 0;  ///< triangles that collapsed (two corners merged)
};

/// Merges vertices closer than or equal to `tolerance` (m): going through the
/// vertices in order, each one maps to the first earlier kept vertex within
/// `tolerance`, else it is kept (greedy, so the result is deterministic but
/// not a transitive closure). Kept vertices keep their position, uv and colour;
/// normals of merged vertices are averaged and renormalised. Triangles are
/// reindexed and those that collapse are removed; kept vertices stay in their
/// original order. tolerance 0 merges exact duplicates only.
/// Spatial hash with cells of size `tolerance`: O(V + F) expected.
/// Fails with InvalidArgument on a negative or non-finite tolerance, a
/// non-finite position or an out-of-range index (the mesh is left unchanged).
/// @code
///   auto r = dm::weldVertices(stlSoup, 1e-9);
///   if (!r) return r.error();
///   dm::log::info("merged %zu vertices", r->verticesRemoved);
/// @endcode
Result<WeldReport> weldVertices(Mesh& mesh, double tolerance);

/// The generalized winding number of `mesh` at p: the sum of its triangles'
/// solid angles over 4π (Jacobson et al. 2013). 1 inside and 0 outside a
/// closed mesh whose triangles face outwards (−1 inside one facing in),
/// fractional where holes let the outside in; > 0.5 is the robust inside
/// test. O(triangles); indices must be in range (Mesh::validate()).
double windingNumber(const Mesh& mesh, const Vec3& p);

}  // namespace dm
