// dm/math/mass_properties.hpp — volume, centre of mass and inertia of closed triangle meshes.
//
// The solid enclosed by a closed, outward-oriented triangle mesh of uniform
// density is integrated exactly with the divergence theorem (Eberly,
// "Polyhedral Mass Properties (Revisited)", 2002, a reformulation of Mirtich
// 1996): each triangle contributes closed-form surface integrals of the
// monomials 1, x, y, z, x², y², z², xy, yz, zx. Coordinates are taken
// relative to the centre of the mesh's bounding box, so a small mesh far from
// the origin loses no precision to cancellation.
#pragma once

#include <dm/core/mesh.hpp>
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>

namespace dm {

/// Rigid-body properties of the solid bounded by a closed mesh, uniform density.
struct MassProperties {
  double volume = 0;             ///< m³, > 0
  double mass = 0;               ///< kg, density · volume
  Vec3 centroid = Vec3::Zero();  ///< m, centre of mass in the mesh's frame
  /// kg·m², symmetric inertia tensor about `centroid`, axes of the mesh's frame
  /// (diagonal = moments ∫ρ(y²+z²)dV..., off-diagonal = products −∫ρxy dV...).
  Mat3 inertia = Mat3::Zero();
  /// kg·m², eigenvalues of `inertia`, ascending.
  Vec3 principalMoments = Vec3::Zero();
  /// Columns: unit principal axes in the mesh's frame, matching
  /// `principalMoments`; a rotation (det +1), so inertia = R·diag(moments)·Rᵀ.
  /// Axes of repeated moments (a sphere, a cube) are any orthonormal basis of
  /// their eigenspace.
  Mat3 principalAxes = Mat3::Identity();
};

/// Mass properties of the solid enclosed by `mesh` with uniform `density`
/// (kg/m³). The mesh must be closed (every edge shared by one triangle in each
/// direction) with triangles counter-clockwise seen from outside; several
/// closed pieces add up, and an inward-facing piece inside an outward one
/// makes a cavity. Triangles that repeat a vertex index are ignored.
/// O(F log F) time (the closedness check sorts the edges), O(F) memory.
/// Fails with InvalidArgument on an empty or invalid mesh (Mesh::validate()),
/// a non-positive or non-finite density, an open or inconsistently oriented
/// mesh (the message names an offending edge), and a signed volume that is
/// negative (inside-out mesh) or zero (flat mesh).
/// @code
///   auto mp = dm::computeMassProperties(scalpelMesh, 7900.0);  // steel
///   if (!mp) return mp.error();
///   body.setMass(mp->mass, mp->inertia, mp->centroid);
/// @endcode
Result<MassProperties> computeMassProperties(const Mesh& mesh, double density = 1.0);

/// Inertia tensor (kg·m²) of the same body about `point` (m, mesh frame),
/// axes of the mesh's frame, by the parallel axis theorem:
/// I_p = I_c + m (|d|² E − d dᵀ) with d = point − centroid.
Mat3 inertiaAboutPoint(const MassProperties& properties, const Vec3& point);

}  // namespace dm
