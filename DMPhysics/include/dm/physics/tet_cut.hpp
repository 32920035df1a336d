// dm/physics/tet_cut.hpp — continuous cutting of a tetrahedral mesh by a
// blade's swept surface: the virtual node algorithm.
//
// What it is for: a scalpel, scissors or a hook separating FEM tissue as
// the tool moves. Each tick the blade's cutting edge sweeps a surface (the
// quad between its last and its current pose); TetCutter records where that
// surface crosses the mesh's edges and, once a tetrahedron's crossed edges
// separate its corners, splits it.
//
// Method (Molino, Bao & Fedkiw 2004, "A virtual node algorithm for changing
// mesh topology during simulation", SIGGRAPH): chosen over splitting
// elements along the cut because the simulation mesh keeps its original
// element shapes, so cutting never makes sliver or inverted elements.
//  * Crossings: an edge is crossed once, where the swept surface first meets
//    it (in the current, deformed configuration: linear elements map that
//    point to one material point), kept `snap` of the edge's length from
//    either end.
//  * Separation: a tetrahedron's corners fall into components joined by its
//    uncrossed edges. One component: the element is whole (a crossing there
//    is a crack that has not gone through it yet). k ≥ 2 components: the
//    element becomes k copies, one per component, each with that
//    component's corners as its real nodes and duplicates (virtual nodes) of
//    the other corners, all at the original rest shape.
//  * Material: each copy holds the part of the element on its side of the
//    cut. The element is subdivided into 24 small tetrahedra (corner, edge
//    point, face point, cell point), each owned by its corner's component;
//    edge points are the crossings, face and cell points the mean of the
//    crossings on that face or in that cell. For a planar cut this region is
//    exactly the element's part on each side of the plane (the interface
//    lies in the plane); in general it is a piecewise-planar surface through
//    the crossings. A copy's volume fraction scales its mass and stiffness;
//    the fractions of an element's copies add up to one.
//  * Nodes: copies of face-neighbouring elements share the nodes of their
//    common face when they share a real node on it (so material that is
//    still joined across the face stays joined); a corner slot that joins
//    no real node is a virtual node, appended after the original nodes at
//    its original's rest position. At a crack front the copies of the last
//    separated elements meet a whole element, which glues their virtual
//    nodes back to the originals: a partial cut opens only where the blade
//    has gone through.
//  * Incremental: crossings only accumulate, so components only split. An
//    update revisits the elements whose edges were crossed and regroups the
//    nodes of separated elements only (O(cut area), not O(mesh)); element
//    indices are stable (a split element keeps its index for its first copy,
//    further copies are appended), node indices are stable, and every new
//    node names the node whose state it starts from.
//  * Surface: the boundary of the cut mesh, as vertices embedded in the
//    elements (up to four nodes and weights) so it follows the deformation:
//    the original boundary faces (split at crossings) and, inside separated
//    elements, the cut faces between copies — two sheets that open as the
//    pieces move apart. Closed wherever the blade did not exit.
//
// Tearing uses the same machinery: tear() crosses an element's edges by a
// plane (through the crossings it has, so a crack keeps its plane), and
// tensileTears() picks the elements whose principal stress reaches the
// material's strength.
//
// Units: SI (m). Deterministic: the same mesh and the same calls give the
// same elements, nodes and surface bit for bit (lockstep replays).
//
// @code
//   auto mesh = dm::tetMeshBox({8, 8, 4}, dm::Vec3(0.04, 0.04, 0.02));
//   auto cutter = dm::TetCutter::create(*mesh);
//   std::vector<dm::Vec3> x = cutter->restPositions();
//   auto sweep = dm::bladeSweep(tipBefore, heelBefore, tipNow, heelNow);
//   auto up = cutter->cut(sweep, x);  // up->newNodes: append their sources' states
//   // cutter->elements(): copies with nodes and volume fractions
// @endcode
#pragma once

#include <dm/core/mesh.hpp>
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>
#include <dm/physics/fem.hpp>

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

namespace dm {

/// A triangle of a cutting surface, body frame (m).
using CutTriangle = std::array<Vec3, 3>;

/// The surface a straight cutting edge sweeps moving from (a0, b0) to
/// (a1, b1): two triangles of the quad a0 b0 b1 a1. Degenerate (zero-area)
/// triangles cut nothing.
std::array<CutTriangle, 2> bladeSweep(const Vec3& a0, const Vec3& b0, const Vec3& a1, const Vec3& b1);

/// Options of TetCutter.
struct TetCutOptions {
  /// A crossing is kept at least this fraction of its edge's length from
  /// either end, in (0, 0.25]: a cut through or next to a node moves that
  /// far so no copy holds a vanishing part of its element (a planar cut's
  /// smallest copy holds ≥ snap³ of its element's volume).
  double snap = 0.02;
};

/// An element of the cut mesh: a copy of one original tetrahedron.
struct CutElement {
  Tet nodes{};               ///< node indices (originals or virtual), the original's corner order
  std::uint32_t source = 0;  ///< the original tetrahedron
  double fraction = 1.0;     ///< its material's share of the original's volume, (0, 1]
};

/// A node that a cut update appended or regrouped: its state (position,
/// velocity) starts as `source`'s state before the update.
struct CutNodeChange {
  std::uint32_t node = 0;
  std::uint32_t source = 0;
};

/// What one TetCutter::cut() changed.
struct CutUpdate {
  std::size_t edgesCrossed = 0;  ///< edges crossed for the first time
  std::size_t tetsSplit = 0;     ///< original tetrahedra split (or split further)
  /// Elements whose nodes or fraction changed, appended ones included,
  /// ascending.
  std::vector<std::uint32_t> changedElements;
  /// Nodes appended (indices ≥ the node count before), ascending; earlier
  /// nodes keep their indices and meaning.
  std::vector<CutNodeChange> newNodes;
};

/// A tear through one element (TetCutter::tear): a plane normal to
/// `normal` (body frame).
struct TearSplit {
  std::uint32_t element = 0;
  Vec3 normal = Vec3::UnitX();
};

/// A vertex of the cut surface: Σ weights[i]·x[nodes[i]] (unused entries
/// weigh 0), so it follows the nodes.
struct CutSurfaceVertex {
  std::array<std::uint32_t, 4> nodes{};
  std::array<double, 4> weights{};
};

/// The cut surface: triangles counter-clockwise seen from outside the
/// material, indexing `vertices`.
struct CutSurface {
  std::vector<CutSurfaceVertex> vertices;
  std::vector<Triangle> triangles;
  /// Positions of the vertices for node positions x (one per node).
  void evaluate(std::span<const Vec3> x, std::vector<Vec3>& out) const;
};

/// The tears of a body whose material fails in tension: elements not yet
/// split whose largest principal stress (FemBody::elementStress) is at
/// least `strength` (Pa), each torn across that stress's direction. Where
/// any of them touches a crack (TetCutter::touchesCrack) only those grow
/// it; otherwise only the most stressed one starts a crack (ties: the lowest
/// element), so a uniform field opens one crack, not one per element. The
/// body must be in step with the cutter (FemBody::applyCut). O(T).
/// @code
///   auto tears = dm::tensileTears(body, cutter, 5e4);
///   if (!tears.empty())
///     if (auto up = cutter.tear(tears, body.positions())) body.applyCut(cutter, *up);
/// @endcode
std::vector<TearSplit> tensileTears(const FemBody& body, const TetCutter& cutter, double strength);

/// Cuts a tetrahedral mesh by swept surfaces; see the file comment.
/// Not thread-safe.
class TetCutter {
 public:
  /// Fails (InvalidArgument) on an invalid mesh (TetMesh::validate()), a
  /// mesh with hanging nodes (a hierarchical grid: cut a conforming mesh),
  /// or snap outside (0, 0.25]. O(T log T).
  static Result<TetCutter> create(const TetMesh& mesh, const TetCutOptions& options = {});

  /// Crosses the edges that `surface` meets at the current node positions
  /// `x` (one per node: nodeCount()) and splits the elements it separates.
  /// Fails (InvalidArgument, nothing changed) on a size mismatch or a
  /// non-finite position or triangle. O(E) per triangle for the crossing
  /// search plus O(separated elements) for the regrouping.
  Result<CutUpdate> cut(std::span<const CutTriangle> surface, std::span<const Vec3> x);

  /// Tears elements (material failure, not a blade): each split's plane,
  /// normal to its `normal`, through the mean of the crossings its element
  /// already has (so a crack grows in the plane it started in) or else
  /// through the element's centroid at positions x, crosses the element's
  /// uncrossed edges it meets; the elements that separates split as in
  /// cut(). Fails (InvalidArgument, nothing changed) like cut(), and on an
  /// element out of range or a normal that is zero or not finite.
  Result<CutUpdate> tear(std::span<const TearSplit> splits, std::span<const Vec3> x);
  /// Whether element e's original tetrahedron has a crossed edge: a cut or
  /// a crack reaches it.
  bool touchesCrack(std::size_t e) const;
  /// Whether element e's original tetrahedron is split.
  bool isSplit(std::size_t e) const { return labelCount_[elements_[e].source] > 1; }

  std::size_t nodeCount() const noexcept { return origin_.size(); }
  std::size_t originalNodeCount() const noexcept { return x0_.size(); }
  std::size_t originalTetCount() const noexcept { return tets_.size(); }
  /// The original node each node copies (itself for an original).
  std::span<const std::uint32_t> nodeOrigin() const noexcept { return origin_; }
  /// Rest positions of all nodes (a virtual node at its original's).
  std::vector<Vec3> restPositions() const;
  /// The elements: original tetrahedron t's first copy is element t.
  const std::vector<CutElement>& elements() const noexcept { return elements_; }
  /// Original tetrahedra split into two or more copies.
  std::size_t splitTetCount() const noexcept { return split_.size(); }
  std::size_t crossedEdgeCount() const noexcept { return crossedCount_; }
  std::size_t edgeCount() const noexcept { return edgeNodes_.size(); }
  /// Rest volume of element e's material, m³ (fraction × original volume).
  double elementVolume(std::size_t e) const;
  /// Connected pieces (elements joined through shared nodes): each element's
  /// piece index (0 … pieces−1, numbered by lowest element) into `pieceOf`;
  /// returns the piece count. O(T).
  std::size_t pieces(std::vector<std::uint32_t>& pieceOf) const;
  /// The cut mesh: rest positions of all nodes, the elements' nodes and
  /// their fractions (TetMesh::fractions), as FemBody::create() takes it.
  TetMesh mesh() const;
  /// The surface of the cut mesh (see the file comment). O(surface log surface).
  CutSurface surface() const;

 private:
  TetCutter() = default;
  // Corner components of original tetrahedron t from its uncrossed edges:
  // label per corner (0 … k−1, by first corner) and k.
  int labelCorners(std::size_t t, std::array<std::uint8_t, 4>& label) const;
  // Weights over t's corners of its subdivision points: the crossing on
  // each crossed edge (the midpoint otherwise), the mean of a face's
  // crossings where it has two or more (its centroid otherwise), the mean of
  // the cell's crossings (its centroid if none). A face's point depends on
  // the face alone, so both its tetrahedra agree.
  struct Subdivision {
    std::array<std::array<double, 4>, 6> edge{};
    std::array<std::array<double, 4>, 4> face{};  // the face opposite each corner
    std::array<double, 4> cell{};
    std::array<bool, 6> crossed{};
  };
  Subdivision subdivision(std::size_t t) const;
  // Volume fraction of each component of t.
  void componentFractions(std::size_t t, const std::array<std::uint8_t, 4>& label, int k,
                          std::array<double, 4>& fraction) const;
  // Checks positions for cut() and tear().
  Status checkPositions(std::span<const Vec3> x, const char* where) const;
  // Crosses edge e at fraction s from its lower node (snapped) and marks its
  // tetrahedra dirty.
  void cross(std::size_t e, double s, std::vector<std::uint32_t>& dirty, CutUpdate& update);
  // Splits the dirty tetrahedra that their crossings separate, regroups
  // the nodes, and finishes the update.
  void splitDirty(std::vector<std::uint32_t>& dirty, CutUpdate& update);
  // Regroups the nodes of every split element's copies (the virtual node
  // rule), keeping node indices where it can.
  void regroupNodes(CutUpdate& update);

  TetCutOptions options_;
  std::vector<Vec3> x0_;                                 // original rest nodes
  std::vector<Tet> tets_;                                // original tetrahedra
  std::vector<double> volume_;                           // original volumes
  std::vector<std::array<std::uint32_t, 6>> tetEdge_;    // global edge of each local edge
  std::vector<std::array<std::uint32_t, 4>> tetFace_;    // global face opposite each corner
  std::vector<std::array<std::uint32_t, 2>> edgeNodes_;  // (lower, higher) original node
  std::vector<std::uint32_t> edgeTetStart_, edgeTets_;   // edge → tetrahedra (CSR)
  std::vector<std::array<std::uint32_t, 2>> faceTets_;   // one or two tetrahedra (kNone)
  std::vector<double> crossing_;                         // per edge: from the lower node, or < 0
  std::size_t crossedCount_ = 0;
  std::vector<std::array<std::uint8_t, 4>> label_;    // per original tet
  std::vector<std::uint8_t> labelCount_;              // per original tet
  std::vector<std::array<std::uint32_t, 4>> copyOf_;  // per original tet: element of each label
  std::vector<std::uint32_t> split_;                  // original tets with ≥ 2 copies, ascending
  std::vector<CutElement> elements_;
  std::vector<std::uint32_t> origin_;  // per node
};

}  // namespace dm
