// dm/physics/sph_boundary.hpp — boundary particles for dm::SphFluid on a
// triangle mesh's surface: a static wall or organ (addBoundaryParticles), a
// rigid body's surface in its own frame (addRigidBoundary) or a deforming
// tissue's surface that carries its samples along (addSurfaceBoundary).
//
// The sampling lays every triangle's lattice of n = ⌈longest edge /
// spacing⌉ steps per edge on it (so no two neighbouring samples of a
// triangle are more than a spacing apart), keeps a sample only when no kept
// one lies within half a spacing (edges and corners shared by triangles come
// once), and moves each `inset` along its triangle's inward normal.
//
// The inset that puts the fluid's edge on the mesh — so that a body
// displaces its own volume — is a third of a spacing, measured: fluid
// particles under pressure settle into the hollows between boundary
// particles, so the fluid's edge (half a spacing outside its outer
// particles' centres) lies about d/3 outside the boundary particles, not
// the d/2 of the lattice at rest. With d/3 a sphere of 3 spacings' radius
// held under water feels 0.94-0.99 of ρ0 g V (by how its icosphere is
// sampled), a cube of 6 spacings 0.99, and floating spheres take
// Archimedes' drafts (Tests/DMPhysics/sph_rigid_test.cpp); with d/2 the
// sphere felt 8-17 % less. A sample on an edge or vertex of the mesh moves
// along its edge's or vertex's normal, to the inset of every face there.
// The mesh's triangles must face outwards (counter-clockwise seen from
// outside) for the inset to go in.
//
// A BoundarySurface keeps each sample as its triangle, its barycentric
// coordinates and the feature it lies on (the face, an edge, a vertex), so
// it can place them again on the same mesh deformed (the normals from the
// deformed triangles), give them the vertices' velocities interpolated, and
// spread forces on the samples back onto the vertices (the transpose of
// the interpolation, so the total force and its moment about any point are
// kept for samples on the triangles). sampleBoundary() is create + place on
// the mesh as given.
//
// Deterministic: the samples come in triangle order. Cost O(samples) with a
// hash of cells half a spacing wide to create; place() O(triangles +
// samples), allocation-free.
//
// @code
//   auto ball = dm::sampleBoundary(dm::makeIcosphere(0.02, 3), d, d / 3);
//   auto body = fluid.addRigidBoundary(*ball, pose);
//   auto skin = dm::BoundarySurface::create(tissueSurface, d, d / 3);
//   auto id = fluid.addSurfaceBoundary(std::move(*skin), tissueSurface.positions);
// @endcode
#pragma once

#include <dm/core/mesh.hpp>
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

namespace dm {

/// At most this many samples (a 1 m² surface at 0.5 mm spacing is 4 M).
inline constexpr std::size_t kMaxBoundarySamples = 20'000'000;

/// Samples of a mesh's surface that follow the mesh as it deforms. See the
/// file comment.
class BoundarySurface {
 public:
  /// Fails (InvalidArgument) on a spacing that is not positive and finite,
  /// an inset that is negative, not finite or a spacing or more, an empty
  /// mesh, a non-finite vertex or an index out of range, and when the
  /// surface would need more than kMaxBoundarySamples samples (naming the
  /// count).
  static Result<BoundarySurface> create(const Mesh& mesh, double spacing, double inset);

  std::size_t size() const noexcept { return samples_.size(); }
  std::size_t vertexCount() const noexcept { return vertexNormal_.size(); }
  std::size_t triangleCount() const noexcept { return triangles_.size(); }
  double inset() const noexcept { return inset_; }

  /// The samples for the mesh's vertices at `vertices` (vertexCount() of
  /// them) into `out` (size() of them); the inset along the deformed
  /// normals. A triangle collapsed to a line or a point leaves its samples
  /// on it, without inset. Allocation-free.
  void place(std::span<const Vec3> vertices, std::span<Vec3> out);
  /// The vertices' velocities interpolated at the samples.
  void interpolate(std::span<const Vec3> vertexValues, std::span<Vec3> out) const;
  /// Adds each sample's vector to its triangle's vertices by its
  /// barycentric weights (the transpose of interpolate()).
  void spread(std::span<const Vec3> sampleValues, std::span<Vec3> vertexValues) const;

 private:
  enum class Feature : std::uint8_t { Face, Vertex0, Vertex1, Vertex2, Edge01, Edge12, Edge20 };
  struct Sample {
    std::uint32_t triangle;
    Feature feature;
    double s, t;  // p = a + s (b − a) + t (c − a)
  };
  BoundarySurface() = default;

  std::vector<Triangle> triangles_;
  std::vector<std::array<std::uint32_t, 3>> edges_;  // per triangle: its edges (01, 12, 20)
  std::vector<Sample> samples_;
  double inset_ = 0.0;
  // Scratch of place(): per triangle, vertex, edge.
  std::vector<Vec3> faceNormal_, vertexNormal_, edgeNormal_;
};

/// The samples of BoundarySurface::create(mesh, spacing, inset) placed on
/// the mesh as it is.
Result<std::vector<Vec3>> sampleBoundary(const Mesh& mesh, double spacing, double inset);

}  // namespace dm
