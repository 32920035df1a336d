// dm/collide/sphere_tree.hpp — sphere trees over meshes and voxel models,
// stored (octree-based or k-means fitted) and implicit (derived from a voxel
// octree's level and index).
//
// A sphere tree approximates an object by spheres at every level of a
// hierarchy: level 0 is one sphere around everything, each deeper level a
// finer cover. Every level is a complete cover: every point of the surface
// (or, with `solid`, of the enclosed solid / the occupied voxels) lies in
// some sphere of every level, and each sphere covers at least the geometry
// its children cover. Build cost is O(P·L) for P covered points and L
// levels, plus O(iterations·P·L) for the fitted variant.
//
// Coverage is exact, not sampled: the mesh builders clip every triangle to
// the cells of a grid (Sutherland–Hodgman against the cell box) and a node's
// sphere is the minimal enclosing sphere (Welzl) of the clipped polygons'
// vertices of its cells, which contains their convex hull and so the surface
// inside the cells. With `solid`, the cell corners inside the closed mesh and
// the corners of cells entirely inside are added: the hull of those points
// and the clipped polygons contains solid ∩ cell (a polyhedron lies in the
// hull of its vertices). Voxel builders cover each occupied voxel's cube
// (index box [i−½, i+½]³ mapped by the volume's affine).
//
// As a collision Shape (type ShapeType::SphereTree, in the local frame) a
// sphere tree stands for the union of its deepest-level spheres; the
// colliders (sphere tree against sphere trees, any shape that has a sphere
// collider, planes) are exact for that union and so conservative for the
// source geometry: they report a hit whenever the source geometry would hit,
// and a distance that is a lower bound of the source's distance (by at most
// the largest leaf sphere's diameter). Each node has a second, "bound" radius
// about the same centre that encloses all leaf spheres below it; the queries
// prune with it.
//
// Tightness of a level = (sum of the volumes of its spheres) /
// (reference volume), where the reference is the enclosed volume of a closed
// mesh, the occupied voxel volume of a voxel model, and the root sphere's
// volume for an open mesh. Lower is tighter; a solid cover is ≥ 1; a surface
// cover of a closed mesh falls below 1 at deep levels (the spheres only
// wrap a shell around the surface).
//
// @code
//   dm::SphereTreeOptions opt;
//   opt.levels = 5;
//   auto tree = dm::buildSphereTreeFitted(dm::makeTorus(0.02, 0.005, 48, 16), opt);
//   for (const auto& s : (*tree)->levelStats()) std::printf("%d %zu %g\n", s.level, s.count, s.tightness);
// @endcode
#pragma once

#include <dm/collide/shapes.hpp>
#include <dm/core/mesh.hpp>
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>
#include <dm/core/volume.hpp>

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

namespace dm {

/// One node of a stored sphere tree (48 bytes). The nodes are stored
/// breadth-first: all level-0 nodes, then all level-1 nodes, ...; the
/// children of a node are contiguous, [firstChild, firstChild + childCount),
/// on the next level, and the children of consecutive nodes follow each
/// other. Leaves carry no reference to the triangles or voxels they cover
/// (the builders' pieces are cell fragments, not source primitives); the
/// builders store the surface of every node as a SurfacePatch beside the
/// nodes (SphereTree::patches()); the implicit tree's leaves are the voxels
/// themselves.
struct SphereTreeNode {
  Vec3 center = Vec3::Zero();  ///< m, local frame
  /// m: sphere about `center` covering the geometry of the node (what the
  /// tightness and the exported levels use).
  double radius = 0.0;
  /// m, ≥ radius: sphere about `center` enclosing the leaf spheres below the
  /// node as well (what the queries prune with). Equal to radius at leaves.
  double boundRadius = 0.0;
  std::uint32_t firstChild = 0;  ///< index into SphereTree::nodes() (unused at leaves)
  std::uint8_t childCount = 0;   ///< 0 (leaf) .. 8
  std::uint8_t level = 0;        ///< 0 = root
};

/// The surface inside one node of a sphere tree built from a mesh, or from a
/// voxel model (its isosurface at the threshold: the smooth surface the
/// voxels sample, not their staircase), as a small quadric patch in the
/// tree's local frame. With (u, v, w) the coordinates of
/// x − origin along (tangentU, tangentV, normal), the patch is the graph
///     w = h(u, v) = c₀ + c₁u + c₂v + ½(c₃u² + 2c₄uv + c₅v²),  |(u, v)| ≤ halfWidth,
/// least-squares fitted to the node's surface points (the triangles clipped to its cells; a node under two
/// triangles across: the mesh vertices near it with normals within 30°, the smooth shape, not one facet),
/// then raised by the largest residual of its own points, so none lies above it: outward (+normal) it is
/// conservative, and it lies within `deviation` of every surface point. On a
/// smooth surface it is exact to second order (a sphere, cylinder or torus
/// patch is a quadric graph up to O(halfWidth³·κ²)); where the node holds an
/// edge, a corner or both sides of a thin wall, `coherence` or `deviation`
/// says so. Such a node whose surface is two or three flat faces meeting
/// at a crease (a box's edge or corner, a groove, a cylinder's rim) also
/// holds them as a `Crease`: the planes of its facets grouped by normal,
/// and whether the solid there is their half-spaces' intersection (an edge
/// or corner that sticks out) or their union (a groove, an inner corner).
/// Its signed distance (creaseQuery) is then exact for the faces' planes: a
/// point beside a convex edge is nearest the edge, not either face. Any
/// other node falls back to its sphere.
struct SurfacePatch {
  Vec3 origin = Vec3::Zero();  ///< m: area centroid of the node's surface
  Vec3 normal = Vec3::Zero();  ///< unit outward (area-weighted mean normal); zero: the node holds no surface
  Vec3 tangentU = Vec3::Zero();   ///< unit, ⟂ normal
  Vec3 tangentV = Vec3::Zero();   ///< normal × tangentU
  std::array<double, 6> coeff{};  ///< c₀ (m), c₁, c₂ (1), c₃, c₄, c₅ (1/m) of h(u, v)
  double halfWidth = 0.0;         ///< m: largest |(u, v)| of the node's surface points
  double deviation = 0.0;         ///< m: largest distance (along normal) of a surface point below the patch
  double coherence = 0.0;  ///< |Σ area·n| / Σ area ∈ [0, 1]: 1 flat, ≈ 0 both sides of a thin wall

  /// The node's surface as 2 or 3 planes meeting at a crease (see above).
  struct Crease {
    std::uint8_t planes = 0;         ///< 0 (none), 2 (an edge) or 3 (a corner)
    bool convex = false;             ///< solid = ∩ of the planes' inner half-spaces; else their ∪
    std::array<Vec3, 3> normal{};    ///< unit, outward
    std::array<double, 3> offset{};  ///< m: plane i = {x : normal[i]·x = offset[i]}
    double deviation = 0.0;          ///< m: largest distance of a facet's point from its group's plane
    double reach = 0.0;              ///< m: largest distance of the node's surface points from origin
  };
  Crease crease;

  /// True when the node holds surface (normal is a unit vector).
  bool valid() const noexcept { return normal.squaredNorm() > 0.5; }
  /// True when the node holds a crease (crease.planes ≥ 2).
  bool hasCrease() const noexcept { return crease.planes >= 2; }
  /// w = h(u, v), m.
  double height(double u, double v) const noexcept;
  /// Where a point x (local frame) is relative to the patch.
  struct Query {
    double distance = 0.0;  ///< m, first order: (w − h) / |∇(w − h)|; > 0 outside (exact for a plane)
    Vec3 normal = Vec3::Zero();  ///< unit outward normal of the patch at (u, v)
    double lateral = 0.0;        ///< m: |(u, v)|, to compare with halfWidth
  };
  Query query(const Vec3& x) const noexcept;
  /// Where x is relative to the crease's planes (hasCrease()): the exact
  /// signed distance to the solid they bound (convex: the nearest point of
  /// the intersection of half-spaces, on a face, the edge or the corner;
  /// concave: the nearest plane outside, the nearest point of the free
  /// wedge inside), the outward normal there (from the nearest point to x),
  /// and `lateral` = |nearest point − origin|. O(1).
  Query creaseQuery(const Vec3& x) const noexcept;
  /// The point of the patch (|(u, v)| ≤ halfWidth) farthest along the unit
  /// direction d (local frame): the quadric's stationary point where it is a
  /// maximum inside the disc, else the best of the centre and the rim point
  /// the objective's gradient points to. O(1).
  Vec3 support(const Vec3& d) const noexcept;
};

/// How a stored tree was built.
enum class SphereTreeMethod : std::uint8_t {
  Octree,  ///< a node = an octree cell of the source's bounds (fixed grid)
  Fitted,  ///< a node = a k-means cluster of the parent's pieces (tighter)
  Given,   ///< made by SphereTree::fromNodes()
};

/// "octree", "fitted" or "given".
const char* toString(SphereTreeMethod method) noexcept;

/// Options of the sphere tree builders.
struct SphereTreeOptions {
  /// Levels including the root, 1..10; leaves are at level `levels − 1`.
  int levels = 4;
  /// Cover the solid (closed meshes: the enclosed volume; voxel models: all
  /// occupied voxels) instead of the surface (voxel models: the occupied
  /// voxels with an unoccupied 6-neighbour).
  bool solid = false;
  /// Voxel models: a voxel is occupied where its value > threshold.
  double threshold = 0.0;
  /// Fitted trees: Lloyd iterations of the k-means split of each node.
  int fittedIterations = 6;
  /// Upper bound on the covered pieces (clipped triangle pieces, cells,
  /// voxel rows) and nodes; the builders fail with InvalidArgument beyond it
  /// instead of allocating without bound.
  std::size_t maxPieces = std::size_t{1} << 23;
};

/// Statistics of one level of a sphere tree.
struct SphereTreeLevelStats {
  int level = 0;
  std::size_t count = 0;    ///< spheres on the level
  double tightness = 0.0;   ///< Σ sphere volumes / reference volume (see the file comment)
  double maxRadius = 0.0;   ///< m
  double meanRadius = 0.0;  ///< m
};

/// Common base of the stored and the implicit sphere tree: a hierarchy of
/// spheres addressed by opaque node ids, which is what the colliders
/// traverse. Both have ShapeType::SphereTree.
class SphereHierarchy : public Shape {
 public:
  /// Opaque node address (stored tree: index; implicit tree: level and cell).
  using NodeId = std::uint64_t;

  /// Number of levels (root = level 0). All leaves are on the deepest level.
  virtual int levelCount() const noexcept = 0;
  /// The root node.
  virtual NodeId root() const noexcept = 0;
  /// Writes the children of `node` to `out` and returns their count (0 at
  /// leaves, ≤ 8). O(1) stored, O(8) implicit. No allocation.
  virtual int children(NodeId node, NodeId out[8]) const noexcept = 0;
  /// Covering sphere of `node`, local frame (m).
  virtual BoundingSphere sphere(NodeId node) const noexcept = 0;
  /// Sphere about sphere(node).center enclosing every leaf sphere below.
  virtual BoundingSphere bound(NodeId node) const noexcept = 0;
  /// Per level: count, tightness, radii. O(nodes) stored, O(levels) implicit.
  virtual std::vector<SphereTreeLevelStats> levelStats() const = 0;
  /// m³: the tightness reference (see the file comment).
  virtual double referenceVolume() const noexcept = 0;

  /// Volume of the object the tree was built from (the reference volume).
  double volume() const noexcept override { return referenceVolume(); }

 protected:
  SphereHierarchy() noexcept : Shape(ShapeType::SphereTree) {}
};

/// A stored sphere tree: a flat breadth-first node array (see
/// SphereTreeNode). Immutable and shareable.
class SphereTree final : public SphereHierarchy {
 public:
  /// A tree from nodes in the layout of SphereTreeNode (breadth-first,
  /// children contiguous on the next level, all leaves on the deepest
  /// level); boundRadius is recomputed. `referenceVolume` (m³, > 0) is the
  /// tightness reference. Fails with InvalidArgument naming the first bad
  /// node (index, field) on an empty array, a bad child range, a level that
  /// does not increase by one, a leaf above the deepest level, or a
  /// non-finite or negative centre or radius. O(n).
  /// @code
  ///   std::vector<dm::SphereTreeNode> nodes(1);
  ///   nodes[0].radius = 0.01;
  ///   auto tree = dm::SphereTree::fromNodes(std::move(nodes), 4.19e-6);
  /// @endcode
  static Result<std::shared_ptr<const SphereTree>> fromNodes(
      std::vector<SphereTreeNode> nodes, double referenceVolume,
      SphereTreeMethod method = SphereTreeMethod::Given);
  /// The same, with one SurfacePatch per node (empty: none). Also fails
  /// naming the first bad patch on a size that is not the node count, a
  /// non-finite field, a normal or tangent that is not unit (or zero, for a
  /// node without surface), a negative halfWidth or deviation, or a
  /// coherence outside [0, 1].
  static Result<std::shared_ptr<const SphereTree>> fromNodes(
      std::vector<SphereTreeNode> nodes, std::vector<SurfacePatch> patches, double referenceVolume,
      SphereTreeMethod method = SphereTreeMethod::Given);

  const std::vector<SphereTreeNode>& nodes() const noexcept { return nodes_; }
  /// One surface patch per node for trees built from meshes and voxel
  /// models (node i's patch is patches()[i]; nodes without surface, e.g.
  /// inside a solid tree, have an invalid one); empty for trees given without.
  std::span<const SurfacePatch> patches() const noexcept { return patches_; }
  /// The nodes of level `l` (contiguous in nodes()); empty for a bad level.
  std::span<const SphereTreeNode> level(int l) const noexcept;
  SphereTreeMethod method() const noexcept { return method_; }

  int levelCount() const noexcept override { return static_cast<int>(levelStart_.size()) - 1; }
  NodeId root() const noexcept override { return 0; }
  int children(NodeId node, NodeId out[8]) const noexcept override;
  BoundingSphere sphere(NodeId node) const noexcept override;
  BoundingSphere bound(NodeId node) const noexcept override;
  std::vector<SphereTreeLevelStats> levelStats() const override;
  double referenceVolume() const noexcept override { return referenceVolume_; }

  /// Bounds of the leaf spheres (m, local frame).
  Aabb localAabb() const noexcept override { return bounds_; }
  /// The root's bound sphere.
  BoundingSphere boundingSphere() const noexcept override { return bound(0); }

 private:
  SphereTree() noexcept = default;
  std::vector<SphereTreeNode> nodes_;
  std::vector<SurfacePatch> patches_;      // empty or one per node
  std::vector<std::uint32_t> levelStart_;  // size levels + 1
  SphereTreeMethod method_ = SphereTreeMethod::Given;
  double referenceVolume_ = 0.0;
  Aabb bounds_;
};

/// Octree sphere tree of a mesh: level l has the non-empty cells of a
/// 2^l × 2^l × 2^l subdivision of the mesh's bounding box, each with the
/// minimal sphere of the surface (with options.solid and a closed mesh: the
/// solid) inside the cell, and the SurfacePatch of the surface in it. Fails with InvalidArgument on an
/// invalid or empty mesh, levels outside 1..10, `solid` with an open mesh (the message says so), or more than
/// options.maxPieces pieces.
/// @code
///   auto tree = dm::buildSphereTreeOctree(dm::makeIcosphere(0.01, 3), {});
///   if (!tree) return tree.error();
/// @endcode
Result<std::shared_ptr<const SphereTree>> buildSphereTreeOctree(const Mesh& mesh,
                                                                const SphereTreeOptions& options = {});

/// Fitted sphere tree of a mesh: the surface (or solid) is cut into pieces
/// on a grid 4× finer than the octree's leaves; each node's pieces are split
/// by k-means on the piece centroids into k ≤ 8 clusters (seeded with both an
/// octant split of the node's box and farthest-point seeds; the partition
/// with the least Σ radius³ kept), and each cluster gets the minimal sphere
/// of its pieces. The k of the nodes of a level are shares of the octree
/// tree's count on the next level, proportional to the nodes' pieces, so
/// both trees have about the same number of spheres per level.
/// Fails like buildSphereTreeOctree().
/// @code
///   auto tree = dm::buildSphereTreeFitted(torusMesh, {.levels = 5});
/// @endcode
Result<std::shared_ptr<const SphereTree>> buildSphereTreeFitted(const Mesh& mesh,
                                                                const SphereTreeOptions& options = {});

/// Octree sphere tree of a voxel model (occupied: value > options.threshold):
/// cells of the occupied voxels' index bounding box, each voxel assigned by
/// its centre, spheres covering the voxels' cubes in world coordinates (m,
/// through volume.indexToWorld()). A node's SurfacePatch is fitted to the
/// isosurface at the threshold (dm::extractIsosurface, closed at the grid's
/// border) clipped to the node's cells: where the values vary smoothly (a
/// CT's, a distance field's) it follows the sampled surface to second order
/// instead of the voxels' staircase. Fails with InvalidArgument on an empty
/// volume, no occupied voxel, levels outside 1..10 or too many pieces, and
/// like extractIsosurface.
/// @code
///   auto tree = dm::buildSphereTreeOctree(labels, {.levels = 4, .solid = true, .threshold = 0.5});
/// @endcode
Result<std::shared_ptr<const SphereTree>> buildSphereTreeOctree(const Volume& volume,
                                                                const SphereTreeOptions& options = {});

/// Fitted sphere tree of a voxel model; see the mesh overload and the
/// octree voxel overload. Fails like the latter.
/// @code
///   auto tree = dm::buildSphereTreeFitted(labels, {.levels = 4, .solid = true});
/// @endcode
Result<std::shared_ptr<const SphereTree>> buildSphereTreeFitted(const Volume& volume,
                                                                const SphereTreeOptions& options = {});

/// The implicit sphere tree of a voxel octree: the occupancy (value >
/// threshold) in the octree of the cube of 2^D voxels per axis that holds
/// the grid (D = ⌈log2 of the largest dimension⌉), one occupancy bit per cell
/// and level (a cell is occupied when any voxel below it is; only the cells
/// that overlap the grid are stored, about 8/7 bit per voxel), and no stored
/// spheres: the sphere of cell (l, i, j, k) is computed from its level and
/// index (cellSphere()). Level D's cells are the voxels. Child spheres lie
/// inside their parent's, and the shape is the union of the occupied voxels'
/// spheres.
class ImplicitSphereTree final : public SphereHierarchy {
 public:
  /// Largest D accepted (1024 voxels per axis).
  static constexpr int kMaxDepth = 10;

  /// The octree of `volume`'s occupancy. Fails with InvalidArgument on an
  /// empty volume, no occupied voxel or a largest dimension above 2^kMaxDepth.
  /// O(voxels).
  /// @code
  ///   auto tree = dm::ImplicitSphereTree::create(labels, 0.5);
  ///   if (!tree) return tree.error();
  /// @endcode
  static Result<std::shared_ptr<const ImplicitSphereTree>> create(const Volume& volume,
                                                                  double threshold = 0.0);

  /// D: the padded grid has 2^D cells per axis; levelCount() = D + 1.
  int depth() const noexcept { return depth_; }
  /// True when cell (level, i, j, k) contains an occupied voxel (false
  /// outside the padded grid). O(1).
  bool occupied(int level, int i, int j, int k) const noexcept {
    if (level < 0 || level > depth_) return false;
    const Vec3i& n = levelDims_[static_cast<std::size_t>(level)];
    if (i < 0 || j < 0 || k < 0 || i >= n.x() || j >= n.y() || k >= n.z()) return false;
    const std::size_t b = bitIndex(level, i, j, k);
    return (bits_[static_cast<std::size_t>(level)][b / 64] >> (b % 64)) & 1u;
  }
  /// The occupied children of cell (level, i, j, k): bit dx + 2·dy + 4·dz
  /// is set when cell (2i + dx, 2j + dy, 2k + dz) of level + 1 is occupied;
  /// 0 at the leaf level and outside the grid. O(1), one call where eight
  /// occupied() would do (the simultaneous descents' inner loop).
  [[gnu::always_inline]] std::uint8_t childMask(int level, int i, int j, int k) const noexcept {
    if (level < 0 || level >= depth_) return 0;
    const auto l = static_cast<std::size_t>(level + 1);
    const Vec3i& n = levelDims_[l];
    const int ci = 2 * i, cj = 2 * j, ck = 2 * k;
    if (ci < 0 || cj < 0 || ck < 0 || ci >= n.x() || cj >= n.y() || ck >= n.z()) return 0;
    const std::uint64_t* bits = bits_[l].data();
    const auto bit = [bits](std::size_t x) { return static_cast<unsigned>((bits[x >> 6] >> (x & 63)) & 1u); };
    const std::size_t b = bitIndex(level + 1, ci, cj, ck);
    const std::size_t sy = static_cast<std::size_t>(n.x());
    const std::size_t sz = sy * static_cast<std::size_t>(n.y());
    const bool x1 = ci + 1 < n.x(), y1 = cj + 1 < n.y(), z1 = ck + 1 < n.z();
    unsigned m = bit(b);
    if (x1) m |= bit(b + 1) << 1;
    if (y1) m |= bit(b + sy) << 2 | (x1 ? bit(b + sy + 1) << 3 : 0u);
    if (z1) {
      m |= bit(b + sz) << 4 | (x1 ? bit(b + sz + 1) << 5 : 0u);
      if (y1) m |= bit(b + sz + sy) << 6 | (x1 ? bit(b + sz + sy + 1) << 7 : 0u);
    }
    return static_cast<std::uint8_t>(m);
  }
  /// Sphere of cell (level, i, j, k): the cell spans voxel indices
  /// [i·s − ½, (i+1)·s − ½] (s = 2^(D − level), likewise j, k); centre = the
  /// affine image of the box centre, radius = half the longest of the four
  /// world diagonals of the cell = s/2 · max|A·(±1, ±1, 1)|. O(1).
  BoundingSphere cellSphere(int level, int i, int j, int k) const noexcept;

  int levelCount() const noexcept override { return depth_ + 1; }
  NodeId root() const noexcept override { return 0; }
  int children(NodeId node, NodeId out[8]) const noexcept override;
  BoundingSphere sphere(NodeId node) const noexcept override;
  /// Children's spheres lie inside their parent's: bound = sphere.
  BoundingSphere bound(NodeId node) const noexcept override { return sphere(node); }
  std::vector<SphereTreeLevelStats> levelStats() const override;
  double referenceVolume() const noexcept override { return referenceVolume_; }
  Aabb localAabb() const noexcept override { return bounds_; }
  BoundingSphere boundingSphere() const noexcept override { return sphere(root()); }

  /// Packs/unpacks a node id (level in the top 6 bits, then k, j, i, 18 bits each).
  /// Inline, like occupied(): the simultaneous descents call them per cell pair.
  static NodeId nodeId(int level, int i, int j, int k) noexcept {
    return static_cast<NodeId>(level) << (3 * kMortonBits) |
           (static_cast<NodeId>(k) & kCoordMask) << (2 * kMortonBits) |
           (static_cast<NodeId>(j) & kCoordMask) << kMortonBits | (static_cast<NodeId>(i) & kCoordMask);
  }
  static void unpack(NodeId id, int& level, int& i, int& j, int& k) noexcept {
    level = static_cast<int>(id >> (3 * kMortonBits));
    k = static_cast<int>((id >> (2 * kMortonBits)) & kCoordMask);
    j = static_cast<int>((id >> kMortonBits) & kCoordMask);
    i = static_cast<int>(id & kCoordMask);
  }

 private:
  ImplicitSphereTree() noexcept = default;
  int depth_ = 0;
  Affine3 indexToWorld_ = Affine3::Identity();
  double halfDiagonal_ = 0.0;  // max |A·(±1,±1,1)| / 2, per voxel
  static constexpr int kMortonBits = 18;
  static constexpr std::uint64_t kCoordMask = (std::uint64_t{1} << kMortonBits) - 1;
  std::size_t bitIndex(int level, int i, int j, int k) const noexcept {
    const Vec3i& n = levelDims_[static_cast<std::size_t>(level)];
    return static_cast<std::size_t>(i) +
           static_cast<std::size_t>(n.x()) *
               (static_cast<std::size_t>(j) + static_cast<std::size_t>(n.y()) * static_cast<std::size_t>(k));
  }
  std::vector<Vec3i> levelDims_;                  // per level: ⌈dims / 2^(D−l)⌉ cells
  std::vector<std::vector<std::uint64_t>> bits_;  // per level, one bit per cell, x fastest
  std::vector<std::size_t> occupiedCount_;        // per level
  double referenceVolume_ = 0.0;
  Aabb bounds_;
};

}  // namespace dm
