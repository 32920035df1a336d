// dm/collide/point_shell.hpp — a shape given by points on its surface with
// outward normals: the tool side of Voxmap–PointShell haptic rendering
// (McNeely, Puterbaugh, Troy 1999). Each point stands for a patch of about
// spacing² of surface; pressed into a VoxelModel (dm/collide/voxel_model.hpp)
// every point below the anatomy's surface yields a penalty contact.
//
// The points (local frame, m) are kept in the leaf order of a bounding-sphere
// hierarchy (binary, median split on the longest axis, ≤ kLeafSize points per
// leaf), so that queries skip whole clusters that are far from the other
// shape. originalIndex() maps back to the input order.
//
// @code
//   auto shell = dm::PointShell::fromMesh(dm::makeIcosphere(0.005, 3), {.spacing = 0.5e-3});
//   if (!shell) return shell.error();
//   for (const dm::Vec3& p : (*shell)->points()) draw(p);
// @endcode
#pragma once

#include <dm/collide/shapes.hpp>
#include <dm/core/mesh.hpp>
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

namespace dm {

/// One node of a PointShell's bounding-sphere hierarchy. Internal node:
/// count == 0, children are nodes `first` and `first + 1`. Leaf: the points
/// [first, first + count) of points().
struct PointShellNode {
  Vec3 center = Vec3::Zero();  ///< sphere centre, local frame, m
  double radius = 0.0;         ///< m; every point of the subtree lies within it
  std::uint32_t first = 0;     ///< left child (internal) or first point (leaf)
  std::uint32_t count = 0;     ///< 0 for an internal node, else number of points

  bool isLeaf() const noexcept { return count != 0; }
};

/// Options of PointShell::fromMesh().
struct PointShellOptions {
  double spacing = 0.0;                ///< m, > 0: target distance between neighbouring points
  std::uint64_t seed = 1;              ///< random seed (the result is deterministic for a seed)
  std::size_t maxPoints = 10'000'000;  ///< largest point count accepted (checked before sampling)
};

/// Surface points with unit outward normals (see the file comment).
class PointShell final : public Shape {
 public:
  /// Most points in one leaf of the hierarchy.
  static constexpr std::uint32_t kLeafSize = 16;
  /// Depth bound of the hierarchy (median splits: ⌈log2 n⌉ + 1 ≤ 34 for
  /// n < 2^32); traversal stacks are sized from it.
  static constexpr int kMaxDepth = 40;

  /// Shell from explicit points and normals (local frame, m; the normals are
  /// normalised here, any length > 0). O(n log n). Fails with InvalidArgument
  /// when there are no points, the two sizes differ, or a point or normal is
  /// not finite or a normal is zero; the message names the index.
  /// @code
  ///   auto shell = dm::PointShell::create(points, normals);
  ///   if (!shell) return shell.error();
  ///   dm::ShapePtr tool = *shell;
  /// @endcode
  static Result<std::shared_ptr<const PointShell>> create(std::span<const Vec3> points,
                                                          std::span<const Vec3> normals);

  /// Samples the surface of `mesh` (m, CCW from outside) with points about
  /// `options.spacing` apart: round(area / spacing²) points, each carrying
  /// the unit normal of its triangle. Candidates are drawn area-weighted
  /// (5 per final point), then thinned to the final count by weighted sample
  /// elimination (Yuksel 2015), which leaves a Poisson-disk-like even
  /// spread. Degenerate triangles get no points. O(n log n) in the number of
  /// candidates. Fails with InvalidArgument on an invalid mesh
  /// (Mesh::validate()), one without area, spacing ≤ 0 or not finite, or
  /// more than options.maxPoints points.
  /// @code
  ///   auto shell = dm::PointShell::fromMesh(drillBit, {.spacing = 0.3e-3});
  ///   if (!shell) return shell.error();
  /// @endcode
  static Result<std::shared_ptr<const PointShell>> fromMesh(const Mesh& mesh,
                                                            const PointShellOptions& options);

  /// Number of points.
  std::size_t size() const noexcept { return points_.size(); }
  /// Points (local frame, m) in hierarchy leaf order.
  std::span<const Vec3> points() const noexcept { return points_; }
  /// Unit outward normals, same order as points().
  std::span<const Vec3> normals() const noexcept { return normals_; }
  /// Input index of point k (create(): index into `points`; fromMesh(): the
  /// index of the triangle the point lies on).
  std::uint32_t originalIndex(std::size_t k) const noexcept { return original_[k]; }
  /// Hierarchy nodes; nodes()[0] is the root.
  std::span<const PointShellNode> nodes() const noexcept { return nodes_; }
  /// Surface area one point stands for, m² (fromMesh: area / size; create:
  /// 0, unknown).
  double areaPerPoint() const noexcept { return areaPerPoint_; }

  Aabb localAabb() const noexcept override { return bounds_; }
  /// 0: a point shell is a surface sample, it encloses no volume by itself.
  double volume() const noexcept override { return 0.0; }
  BoundingSphere boundingSphere() const noexcept override { return {nodes_[0].center, nodes_[0].radius}; }

 private:
  PointShell() noexcept : Shape(ShapeType::PointShell) {}
  void buildHierarchy();

  std::vector<Vec3> points_;
  std::vector<Vec3> normals_;
  std::vector<std::uint32_t> original_;
  std::vector<PointShellNode> nodes_;
  Aabb bounds_;
  double areaPerPoint_ = 0.0;
};

}  // namespace dm
