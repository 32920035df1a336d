// dm/physics/sph_boundary.hpp — boundary particles for dm::SphFluid on a
// triangle mesh's surface: a static wall or organ (addBoundaryParticles) or
// a rigid body's surface in its own frame (addRigidBoundary).
//
// sampleBoundary() lays every triangle's lattice of n = ⌈longest edge /
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
// along its edge's or vertex's normal, to the inset of every face there. The mesh's triangles must face
// outwards (counter-clockwise seen from outside) for the inset to go in.
//
// Deterministic: the samples come in triangle order. Cost O(samples) with a
// hash of cells half a spacing wide.
//
// @code
//   auto ball = dm::sampleBoundary(dm::makeIcosphere(0.02, 3), d, d / 3);
//   auto body = fluid.addRigidBoundary(*ball, pose);
// @endcode
#pragma once

#include <dm/core/mesh.hpp>
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>

#include <cstddef>
#include <vector>

namespace dm {

/// At most this many samples (a 1 m² surface at 0.5 mm spacing is 4 M).
inline constexpr std::size_t kMaxBoundarySamples = 20'000'000;

/// See the file comment. Fails (InvalidArgument) on a spacing that is not
/// positive and finite, an inset that is negative, not finite or a spacing
/// or more, an empty mesh, a non-finite vertex or an index out of range, and
/// when the surface would need more than kMaxBoundarySamples samples
/// (naming the count).
Result<std::vector<Vec3>> sampleBoundary(const Mesh& mesh, double spacing, double inset);

}  // namespace dm
