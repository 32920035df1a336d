// dm/collide/shapes.hpp — collision shapes in their local frames.
//
// A shape is immutable geometry in its own frame (metres); an object in a
// world is a shape plus a pose (Isometry3, local → world), so one shape is
// shared by many objects through `ShapePtr`. Convex shapes expose a support
// mapping for GJK/EPA as a *core* plus a *margin*: a sphere is a point with
// a radius, a capsule a segment with a radius, everything else has margin 0.
// Distances are computed between cores and the radii subtracted afterwards,
// which keeps sphere and capsule queries exact to rounding and makes GJK
// converge in a few iterations on them.
//
// @code
//   auto ball = std::make_shared<dm::Sphere>(0.01);          // 1 cm radius
//   dm::Aabb box = ball->aabb(dm::Isometry3::Identity());
//   double v = ball->volume();                                // m³
// @endcode
#pragma once

#include <dm/core/mesh.hpp>
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>

#include <cstdint>
#include <memory>
#include <span>
#include <string_view>
#include <vector>

namespace dm {

class MeshBvh;  // dm/collide/bvh.hpp

/// Integer id of a shape kind. The built-in kinds are named; plugins obtain
/// further ids from registerShapeType(). Values are < kMaxShapeTypes.
enum class ShapeType : std::uint8_t {
  Point,
  Segment,
  Plane,
  TriangleShape,  ///< named after the class: dm::Triangle is dm::Mesh's index triple
  Sphere,
  Box,
  Capsule,
  Cylinder,
  Ellipsoid,
  ConvexHull,
  TriangleMesh,
  Compound,
  PointShell,  ///< surface points with normals (dm/collide/point_shell.hpp)
  SphereTree,  ///< hierarchy of spheres (dm/collide/sphere_tree.hpp)
  VoxelModel,  ///< occupancy + signed distance, dense or OpenVDB (dm/collide/voxel_model.hpp)
  FirstUser,  ///< first id handed out by registerShapeType()
};

/// Size of the shape-type id space (built-in plus user types); the collider
/// table is kMaxShapeTypes² entries.
inline constexpr int kMaxShapeTypes = 32;

/// Registers a user-defined shape kind by name and returns its id. Idempotent:
/// the same name gives the same id (so a plugin may be reloaded). Thread-safe.
/// Fails with InvalidArgument on an empty name or one of a built-in kind, and
/// with Busy when all kMaxShapeTypes ids are taken. O(number of types).
/// @code
///   auto id = dm::registerShapeType("voxel-model");
///   if (!id) return id.error();
///   // derive a shape class passing *id to Shape's constructor
/// @endcode
Result<ShapeType> registerShapeType(std::string_view name);

/// Name of a shape kind ("sphere", "box", ... or the registered name);
/// "unknown" for an id never handed out.
std::string_view shapeTypeName(ShapeType type) noexcept;

/// Sphere bounding a shape: centre (m, local frame) and radius (m).
struct BoundingSphere {
  Vec3 center = Vec3::Zero();
  double radius = 0.0;
};

/// Base of every shape: its kind, bounds and volume, all in the local frame.
class Shape {
 public:
  virtual ~Shape() = default;
  Shape(const Shape&) = delete;
  Shape& operator=(const Shape&) = delete;

  ShapeType type() const noexcept { return type_; }
  /// True for shapes derived from ConvexShape (GJK/EPA applies to them).
  bool isConvex() const noexcept { return convex_; }

  /// Axis-aligned bounds in the local frame (m). Plane: unbounded. O(1).
  virtual Aabb localAabb() const noexcept = 0;
  /// Axis-aligned bounds of the shape placed at `pose` (local → world), m.
  /// Tight for every convex built-in shape; for the others the local box
  /// rotated with the |R|·halfExtent formula. O(1) except hulls (O(√n)
  /// typical by hill-climbing) and compounds (O(children)).
  virtual Aabb aabb(const Isometry3& pose) const noexcept;
  /// Enclosed volume, m³ (0 for points, segments, triangles; +∞ for a plane;
  /// compound: sum of children, overlaps counted twice).
  virtual double volume() const noexcept = 0;
  /// A bounding sphere in the local frame (exact for sphere, box, capsule,
  /// cylinder, ellipsoid; the AABB's circumsphere otherwise).
  virtual BoundingSphere boundingSphere() const noexcept;

 protected:
  explicit Shape(ShapeType type, bool convex = false) noexcept : type_(type), convex_(convex) {}

 private:
  ShapeType type_;
  bool convex_;
};

/// Shared, immutable shape.
using ShapePtr = std::shared_ptr<const Shape>;

/// A bounded convex shape given by a support mapping of its core and a margin:
/// the shape is {core point + margin·u : |u| ≤ 1}. User shapes derive from it
/// with an id from registerShapeType() and get GJK/EPA queries for free.
class ConvexShape : public Shape {
 public:
  /// Point of the core farthest along `direction` (local frame, need not be
  /// unit, nonzero). `hint` is a per-query warm start (a vertex index for
  /// hulls, ignored otherwise): pass the same variable on consecutive calls.
  /// O(1) for primitives, O(√n) typical for hulls. Never allocates.
  virtual Vec3 supportCore(const Vec3& direction, std::uint32_t& hint) const noexcept = 0;
  /// A point of the core (local frame, m), as central as cheaply known: the
  /// start of MPR penetration queries. The default averages the six axis
  /// supports (a point of the core by convexity); shapes override it with
  /// their centre.
  virtual Vec3 interiorPoint() const noexcept;
  /// Radius added around the core, m (sphere and capsule radius; 0 otherwise).
  double margin() const noexcept { return margin_; }
  /// Support point of the full shape (core + margin) along `direction`.
  Vec3 support(const Vec3& direction) const noexcept;
  /// Tight world bounds from six support queries; overridden where a closed
  /// form exists.
  Aabb aabb(const Isometry3& pose) const noexcept override;

 protected:
  ConvexShape(ShapeType type, double margin) noexcept : Shape(type, true), margin_(margin) {}

 private:
  double margin_;
};

/// A single point at `position` (local frame, m).
class Point final : public ConvexShape {
 public:
  explicit Point(const Vec3& position = Vec3::Zero()) noexcept
      : ConvexShape(ShapeType::Point, 0.0), position_(position) {}
  const Vec3& position() const noexcept { return position_; }
  Vec3 supportCore(const Vec3&, std::uint32_t&) const noexcept override { return position_; }
  Vec3 interiorPoint() const noexcept override { return position_; }
  Aabb localAabb() const noexcept override { return Aabb(position_, position_); }
  double volume() const noexcept override { return 0.0; }

 private:
  Vec3 position_;
};

/// Segment [a, b] (m); also the core of a capsule.
class Segment final : public ConvexShape {
 public:
  Segment(const Vec3& a, const Vec3& b) noexcept : ConvexShape(ShapeType::Segment, 0.0), a_(a), b_(b) {}
  const Vec3& a() const noexcept { return a_; }
  const Vec3& b() const noexcept { return b_; }
  Vec3 supportCore(const Vec3& d, std::uint32_t&) const noexcept override {
    return d.dot(b_ - a_) > 0 ? b_ : a_;
  }
  Vec3 interiorPoint() const noexcept override { return 0.5 * (a_ + b_); }
  Aabb localAabb() const noexcept override;
  double volume() const noexcept override { return 0.0; }

 private:
  Vec3 a_, b_;
};

/// Half-space {x : normal·x ≤ offset} (local frame); `normal` is normalised
/// by the constructor (a zero normal becomes +z). Unbounded, not a ConvexShape.
class Plane final : public Shape {
 public:
  Plane(const Vec3& normal, double offset) noexcept;
  const Vec3& normal() const noexcept { return normal_; }
  double offset() const noexcept { return offset_; }
  Aabb localAabb() const noexcept override;
  Aabb aabb(const Isometry3& pose) const noexcept override;
  double volume() const noexcept override;

 private:
  Vec3 normal_;
  double offset_;
};

/// Triangle (a, b, c), counter-clockwise seen from the front (m). The class is
/// named TriangleShape because dm::Triangle is the index triple of dm::Mesh.
class TriangleShape final : public ConvexShape {
 public:
  TriangleShape(const Vec3& a, const Vec3& b, const Vec3& c) noexcept
      : ConvexShape(ShapeType::TriangleShape, 0.0), v_{a, b, c} {}
  const Vec3& vertex(int i) const noexcept { return v_[i]; }
  Vec3 supportCore(const Vec3& d, std::uint32_t&) const noexcept override;
  Vec3 interiorPoint() const noexcept override { return (v_[0] + v_[1] + v_[2]) / 3.0; }
  Aabb localAabb() const noexcept override;
  double volume() const noexcept override { return 0.0; }

 private:
  Vec3 v_[3];
};

/// Sphere of `radius` (m) centred at the origin: core point + margin.
class Sphere final : public ConvexShape {
 public:
  explicit Sphere(double radius) noexcept : ConvexShape(ShapeType::Sphere, radius) {}
  double radius() const noexcept { return margin(); }
  Vec3 supportCore(const Vec3&, std::uint32_t&) const noexcept override { return Vec3::Zero(); }
  Vec3 interiorPoint() const noexcept override { return Vec3::Zero(); }
  Aabb localAabb() const noexcept override;
  Aabb aabb(const Isometry3& pose) const noexcept override;
  double volume() const noexcept override;
  BoundingSphere boundingSphere() const noexcept override { return {Vec3::Zero(), radius()}; }
};

/// Box with `halfExtents` (m) along the local axes, centred at the origin.
class Box final : public ConvexShape {
 public:
  explicit Box(const Vec3& halfExtents) noexcept : ConvexShape(ShapeType::Box, 0.0), half_(halfExtents) {}
  const Vec3& halfExtents() const noexcept { return half_; }
  Vec3 supportCore(const Vec3& d, std::uint32_t&) const noexcept override;
  Vec3 interiorPoint() const noexcept override { return Vec3::Zero(); }
  Aabb localAabb() const noexcept override { return Aabb(-half_, half_); }
  Aabb aabb(const Isometry3& pose) const noexcept override;
  double volume() const noexcept override { return 8.0 * half_.prod(); }
  BoundingSphere boundingSphere() const noexcept override { return {Vec3::Zero(), half_.norm()}; }

 private:
  Vec3 half_;
};

/// Capsule along local z: segment from (0,0,−halfLength) to (0,0,+halfLength)
/// plus `radius` (m). Same axis convention as FCL (whose length = 2·halfLength).
class Capsule final : public ConvexShape {
 public:
  Capsule(double radius, double halfLength) noexcept
      : ConvexShape(ShapeType::Capsule, radius), h_(halfLength) {}
  double radius() const noexcept { return margin(); }
  double halfLength() const noexcept { return h_; }
  Vec3 supportCore(const Vec3& d, std::uint32_t&) const noexcept override {
    return {0, 0, d.z() >= 0 ? h_ : -h_};
  }
  Vec3 interiorPoint() const noexcept override { return Vec3::Zero(); }
  Aabb localAabb() const noexcept override;
  Aabb aabb(const Isometry3& pose) const noexcept override;
  double volume() const noexcept override;
  BoundingSphere boundingSphere() const noexcept override { return {Vec3::Zero(), h_ + radius()}; }

 private:
  double h_;
};

/// Solid cylinder along local z, |z| ≤ halfLength, x²+y² ≤ radius² (m).
class Cylinder final : public ConvexShape {
 public:
  Cylinder(double radius, double halfLength) noexcept
      : ConvexShape(ShapeType::Cylinder, 0.0), r_(radius), h_(halfLength) {}
  double radius() const noexcept { return r_; }
  double halfLength() const noexcept { return h_; }
  Vec3 supportCore(const Vec3& d, std::uint32_t&) const noexcept override;
  Vec3 interiorPoint() const noexcept override { return Vec3::Zero(); }
  Aabb localAabb() const noexcept override;
  Aabb aabb(const Isometry3& pose) const noexcept override;
  double volume() const noexcept override;
  BoundingSphere boundingSphere() const noexcept override;

 private:
  double r_, h_;
};

/// Solid ellipsoid x²/rx² + y²/ry² + z²/rz² ≤ 1 with semi-axes `radii` (m).
class Ellipsoid final : public ConvexShape {
 public:
  explicit Ellipsoid(const Vec3& radii) noexcept : ConvexShape(ShapeType::Ellipsoid, 0.0), radii_(radii) {}
  const Vec3& radii() const noexcept { return radii_; }
  Vec3 supportCore(const Vec3& d, std::uint32_t&) const noexcept override;
  Vec3 interiorPoint() const noexcept override { return Vec3::Zero(); }
  Aabb localAabb() const noexcept override { return Aabb(-radii_, radii_); }
  Aabb aabb(const Isometry3& pose) const noexcept override;
  double volume() const noexcept override;
  BoundingSphere boundingSphere() const noexcept override { return {Vec3::Zero(), radii_.maxCoeff()}; }

 private:
  Vec3 radii_;
};

/// Convex polytope: the hull of a point set (dm::convexHull), with vertex
/// adjacency so that supportCore() hill-climbs from the warm-start hint in
/// O(√n) typical time instead of scanning all n vertices.
class ConvexHull final : public ConvexShape {
 public:
  /// Hull of `points` (m). Fails like dm::convexHull (no points, NaN, fewer
  /// than 3 dimensions; the message says which). O(n log n).
  /// @code
  ///   auto hull = dm::ConvexHull::create(toolPoints);
  ///   if (!hull) return hull.error();
  ///   dm::ShapePtr shape = *hull;
  /// @endcode
  static Result<std::shared_ptr<const ConvexHull>> create(std::span<const Vec3> points);

  /// Hull vertices (m) and triangles (CCW from outside) as a closed mesh.
  const std::vector<Vec3>& vertices() const noexcept { return mesh_.positions; }
  const Mesh& mesh() const noexcept { return mesh_; }
  /// Neighbour vertices of vertex i along hull edges.
  std::span<const std::uint32_t> neighbors(std::uint32_t i) const noexcept {
    return {adjacency_.data() + adjacencyStart_[i], adjacency_.data() + adjacencyStart_[i + 1]};
  }
  Vec3 supportCore(const Vec3& d, std::uint32_t& hint) const noexcept override;
  /// The vertices as structure of arrays for vectorised scans: the x of
  /// vertices [0, p), then their y, then their z, where p is the vertex
  /// count rounded up to a multiple of 4 and the padding repeats vertex 0.
  std::span<const double> coordinates() const noexcept { return coordinates_; }
  /// The mean of the hull's vertices.
  Vec3 interiorPoint() const noexcept override { return centroid_; }
  Aabb localAabb() const noexcept override { return bounds_; }
  double volume() const noexcept override { return volume_; }
  BoundingSphere boundingSphere() const noexcept override { return sphere_; }

 private:
  ConvexHull() noexcept : ConvexShape(ShapeType::ConvexHull, 0.0) {}
  Mesh mesh_;
  std::vector<std::uint32_t> adjacencyStart_;  // size n + 1 (CSR)
  std::vector<std::uint32_t> adjacency_;
  // Extreme vertex along the centre direction of each cell of a cube map
  // (6 faces × 8 × 8 cells): a hill-climbing start a step or two from the
  // answer.
  static constexpr int kCubeGrid = 8;
  static int cubeCell(const Vec3& d) noexcept;
  std::vector<std::uint32_t> startVertex_;
  std::vector<double> coordinates_;  // see coordinates()
  Aabb bounds_;
  BoundingSphere sphere_;
  Vec3 centroid_ = Vec3::Zero();
  double volume_ = 0.0;
};

/// Triangle mesh (not convex) with its BVH, both shared. The BVH is built by
/// dm/collide/bvh.hpp; this shape only holds it for the mesh colliders.
class TriangleMesh final : public Shape {
 public:
  /// `mesh` must be non-null; `bvh` may be null until the mesh colliders need
  /// it. Bounds and volume (closed meshes; 0 if open) are computed here, O(n).
  TriangleMesh(std::shared_ptr<const Mesh> mesh, std::shared_ptr<const MeshBvh> bvh);
  /// The usual way to make one: builds the mesh's BVH (binned SAH, see
  /// bvh.hpp), O(n log n). Fails like MeshBvh::build() on an empty or NaN mesh.
  /// @code
  ///   auto skin = dm::TriangleMesh::create(std::make_shared<const dm::Mesh>(std::move(mesh)));
  ///   if (!skin) return skin.error();
  /// @endcode
  static Result<std::shared_ptr<const TriangleMesh>> create(std::shared_ptr<const Mesh> mesh);
  const std::shared_ptr<const Mesh>& mesh() const noexcept { return mesh_; }
  const std::shared_ptr<const MeshBvh>& bvh() const noexcept { return bvh_; }
  Aabb localAabb() const noexcept override { return bounds_; }
  double volume() const noexcept override { return volume_; }

 private:
  std::shared_ptr<const Mesh> mesh_;
  std::shared_ptr<const MeshBvh> bvh_;
  Aabb bounds_;
  double volume_ = 0.0;
};

/// One part of a Compound: a shape placed at `pose` in the compound's frame.
struct CompoundChild {
  ShapePtr shape;
  Isometry3 pose = Isometry3::Identity();
};

/// Rigid union of child shapes; queries dispatch over the children.
class Compound final : public Shape {
 public:
  /// Children must be non-null (null ones are dropped). O(children).
  explicit Compound(std::vector<CompoundChild> children);
  const std::vector<CompoundChild>& children() const noexcept { return children_; }
  Aabb localAabb() const noexcept override { return bounds_; }
  Aabb aabb(const Isometry3& pose) const noexcept override;
  double volume() const noexcept override;

 private:
  std::vector<CompoundChild> children_;
  Aabb bounds_;
};

/// World AABB of local box `local` placed at `pose` (|R|·half-extent rule,
/// tight for boxes). O(1).
Aabb transformAabb(const Aabb& local, const Isometry3& pose) noexcept;

}  // namespace dm
