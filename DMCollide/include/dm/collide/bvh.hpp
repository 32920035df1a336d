// dm/collide/bvh.hpp — axis-aligned bounding volume hierarchy over the
// triangles of a dm::Mesh, for mesh queries (mesh_query.hpp): boolean,
// contacts, distance, closest point, raycast.
//
// The tree is read-only after build() except for refit() (deformation with
// unchanged connectivity). It is shared between objects (shape + pose), so a
// TriangleMesh shape holds a std::shared_ptr<const MeshBvh>.
//
// Memory layout (what traversal touches):
//  * nodes: one flat array of 32-byte BvhNode. nodes[0] is the root,
//    nodes[1] is unused padding, and the two children of an internal node
//    are adjacent at (first, first + 1) with `first` even, so the array
//    being 64-byte aligned, both children boxes of a node share one 64-byte
//    cache line and are tested together. A child always has a larger index
//    than its parent (reverse index order is bottom-up: refit uses it).
//  * boxes are float, rounded outward from the double triangle bounds, so
//    they always contain the exact triangles (exactness of results comes from
//    the double triangle tests in the leaves).
//  * obbs: a parallel array (one BvhObb per node, same index) of oriented
//    boxes in double, axes from the covariance of the node's corners, for
//    distance bounds: a surface patch is thin along its normal, so these
//    are far tighter than the axis-aligned boxes on curved or tilted parts.
//    Distance traversals use them; overlap traversals use the float boxes.
//  * leaves hold 1..maxLeafSize triangles contiguous in leaf order; the
//    triangles' three corners (double, metres) are copied in leaf order
//    (corners(k)), so a leaf's geometry is one contiguous run of memory.
//    originalTriangle(k) maps back to the mesh's triangle index.
//
// Build: binned SAH (surface-area heuristic) on the centroids, over all three
// axes in one pass per node (float boxes, SSE2 lanes; a node of fewer than
// `bins` triangles gets one bin per triangle, and the children's bounds come
// from the bins), with subtrees of large nodes built in parallel on oneTBB. Time
// O(n log n) for n triangles (each of the O(log n) levels bins and partitions
// O(n) centroids), memory O(n). Depth is capped (object-median splits below
// depth 64), so the fixed traversal stacks of mesh_query.hpp cannot overflow.
//
// @code
//   dm::Result<dm::MeshBvh> bvh = dm::MeshBvh::build(mesh);
//   if (!bvh) { dm::log::warn("%s", bvh.error().message().c_str()); return; }
//   auto shared = std::make_shared<const dm::MeshBvh>(std::move(*bvh));
// @endcode
#pragma once

#include <dm/core/mesh.hpp>
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

namespace dm {

/// One node of a MeshBvh (32 bytes). Internal node: count == 0 and the
/// children are nodes `first` and `first + 1`. Leaf: count in
/// [1, maxLeafSize] triangles, leaf-order indices [first, first + count).
struct BvhNode {
  float lo[3];          ///< box minimum, m, rounded down from the exact bounds
  std::uint32_t first;  ///< left child (internal) or first triangle (leaf)
  float hi[3];          ///< box maximum, m, rounded up
  std::uint32_t count;  ///< 0 for an internal node, else number of triangles

  bool isLeaf() const noexcept { return count != 0; }
};
static_assert(sizeof(BvhNode) == 32, "BvhNode must stay 32 bytes (two per cache line)");

/// Oriented bounding box of a node (double, m, the mesh's frame): the set
/// center + Σ s_i·axes.col(i) with |s_i| ≤ half[i]. Axes are orthonormal;
/// the box contains every corner of the node's triangles (rounded outward).
struct BvhObb {
  Mat3 axes;    ///< columns: unit axes
  Vec3 center;  ///< m
  Vec3 half;    ///< half extents along the axes, m
};

/// Options of MeshBvh::build().
struct BvhBuildOptions {
  int bins = 16;                         ///< SAH bins per axis, clamped to [4, 64]
  int maxLeafSize = 4;                   ///< most triangles per leaf, clamped to [1, 8]
  std::size_t parallelThreshold = 4096;  ///< subtrees with more triangles build as parallel tasks
};

/// Bounding volume hierarchy over a triangle mesh (see the file comment for
/// the memory layout). Copyable and movable; immutable except refit().
class MeshBvh {
 public:
  /// Hard bound on tree depth (root = depth 0); traversal stacks are sized from it.
  static constexpr int kMaxDepth = 100;

  /// Builds the tree over `mesh.triangles` (positions in metres, any local
  /// frame). O(n log n), allocates O(n). Fails (InvalidArgument) on a mesh
  /// without triangles, with an index out of range or a non-finite
  /// coordinate, or with more than 2^30 triangles; the message names the
  /// offending triangle or vertex. Degenerate triangles are kept.
  /// @code
  ///   auto bvh = dm::MeshBvh::build(mesh, {.bins = 32});
  ///   if (bvh) std::printf("%zu nodes\n", bvh->nodes().size());
  /// @endcode
  static Result<MeshBvh> build(const Mesh& mesh, const BvhBuildOptions& options = {});

  /// Updates corners, boxes (bottom-up) and, for closed meshes, the
  /// pseudonormals after the vertices moved; connectivity is unchanged.
  /// `positions` has one entry per vertex of the mesh given to build()
  /// (metres, same frame). O(n log n) (each node's oriented box is refitted
  /// to its triangles along the build's axes), no allocation. Fails (InvalidArgument, tree
  /// unchanged) on a size mismatch or a non-finite position. The tree is not
  /// rebuilt, so large deformations make queries slower, never wrong.
  /// @code
  ///   mesh.positions[7].z() += 0.001;
  ///   if (auto s = bvh.refit(mesh.positions); !s) dm::log::warn("%s", s.error().message().c_str());
  /// @endcode
  Status refit(std::span<const Vec3> positions);

  /// All nodes; nodes()[0] is the root, nodes()[1] padding (see file comment).
  std::span<const BvhNode> nodes() const noexcept { return {nodeData(), nodeCount_}; }
  /// Node i (i < nodes().size()).
  const BvhNode& node(std::uint32_t i) const noexcept { return nodeData()[i]; }
  /// Oriented box of node i (i < nodes().size(); entry 1 is padding). Kept
  /// by refit() with the build's axes and updated extents.
  const BvhObb& obb(std::uint32_t i) const noexcept { return obbs_[i]; }

  std::size_t triangleCount() const noexcept { return tris_.size(); }
  std::size_t vertexCount() const noexcept { return vertexCount_; }
  /// Depth of the deepest leaf (root alone: 0), <= kMaxDepth.
  int depth() const noexcept { return depth_; }
  /// Exact bounds of all triangles (double), m.
  const Aabb& bounds() const noexcept { return bounds_; }

  /// The three corners of leaf-order triangle k (pointer to 3 consecutive Vec3), m.
  const Vec3* corners(std::uint32_t k) const noexcept { return &corners_[3 * std::size_t(k)]; }
  /// Mesh triangle index of leaf-order triangle k.
  std::uint32_t originalTriangle(std::uint32_t k) const noexcept { return order_[k]; }
  /// Vertex indices of leaf-order triangle k.
  const Triangle& triangleIndices(std::uint32_t k) const noexcept { return tris_[k]; }

  /// True when the mesh is a closed, consistently oriented 2-manifold
  /// without degenerate triangles: then the pseudonormals below exist and
  /// point-mesh distances are signed (negative inside).
  bool isClosed() const noexcept { return closed_; }
  /// Unit face normal of leaf-order triangle k (right-handed corner order;
  /// zero for a degenerate triangle). Every mesh, kept by refit().
  const Vec3& faceNormal(std::uint32_t k) const noexcept { return faceNormals_[k]; }
  /// Edge pseudonormal (normalised sum of the two adjacent face normals) of
  /// edge e of leaf-order triangle k; e = 0: corners 0–1, 1: 1–2, 2: 2–0
  /// (closed meshes only).
  const Vec3& edgeNormal(std::uint32_t k, int e) const noexcept {
    return edgeNormals_[3 * std::size_t(k) + e];
  }
  /// Angle-weighted vertex pseudonormal of mesh vertex v (closed meshes only).
  const Vec3& vertexNormal(std::uint32_t v) const noexcept { return vertexNormals_[v]; }

 private:
  friend struct BvhBuilder;
  struct alignas(64) NodeBlock {
    BvhNode pair[2];
  };
  static_assert(sizeof(NodeBlock) == 2 * sizeof(BvhNode));
  // Storage in 64-byte blocks, viewed as BvhNode[2 * blocks].
  std::vector<NodeBlock> blocks_;
  std::size_t nodeCount_ = 0;
  const BvhNode* nodeData() const noexcept { return blocks_.empty() ? nullptr : blocks_.front().pair; }
  BvhNode* nodeData() noexcept { return blocks_.empty() ? nullptr : blocks_.front().pair; }

  std::vector<BvhObb> obbs_;             // per node, parallel to the node array
  std::vector<std::uint32_t> nodeSpan_;  // per node: first leaf-order triangle and end (2 per node)
  std::vector<Vec3> corners_;            // 3 per triangle, leaf order
  std::vector<Triangle> tris_;           // vertex indices, leaf order
  std::vector<std::uint32_t> order_;     // leaf order -> mesh triangle
  std::vector<Vec3> faceNormals_;        // per triangle, leaf order
  std::vector<Vec3> edgeNormals_;        // closed meshes: 3 per triangle, leaf order
  std::vector<Vec3> vertexNormals_;      // closed meshes: per vertex
  std::vector<std::uint32_t>
      neighbours_;  // closed meshes: 3 per triangle (leaf order of the triangle across edge e)
  Aabb bounds_;
  std::size_t vertexCount_ = 0;
  int depth_ = 0;
  bool closed_ = false;

  void computeFaceNormals() noexcept;
  void computeNormals() noexcept;
  void computeBoxes() noexcept;
  void computeObbExtents() noexcept;
  void computeObbs();
};

}  // namespace dm
