// dm/math/voxelize.hpp — closed triangle meshes to occupancy and signed
// distance volumes.
//
// voxelizeMesh() samples the solid bounded by a closed mesh at the centres of
// an axis-aligned grid: either as a U8 occupancy volume (1 inside, 0 outside)
// or as an F32 signed distance field in metres (negative inside) — the input
// of voxel collision, of volumetric tool/organ models and, written with
// dm::writeVdb(levelSet = true), of OpenVDB level sets.
//
// Inside/outside is exact: every x-column of voxel centres is intersected
// with the mesh in fixed-point coordinates with exact integer predicates and
// a symbolic perturbation, so rays through vertices and edges count once. The
// signed winding number decides (nonzero = inside) for consistently oriented
// meshes, so nested shells make cavities and overlapping pieces a union; the
// crossing parity decides for closed meshes with inconsistent orientation.
// Distances are exact point-to-triangle distances (dm::closestPointOnTriangle).
#pragma once

#include <dm/core/mesh.hpp>
#include <dm/core/result.hpp>
#include <dm/core/volume.hpp>

#include <cstddef>
#include <functional>

namespace dm {

/// Options of voxelizeMesh().
struct VoxelizeOptions {
  double voxelSize = 0.0;       ///< m, > 0 (isotropic)
  int paddingVoxels = 2;        ///< empty voxels added around the mesh bounds on each side
  bool signedDistance = false;  ///< false: U8 occupancy (1 inside, 0 outside); true: F32 signed distance in
                                ///< metres, negative inside
  double bandWidth = 0.0;       ///< m; SDF only: exact distance within this band of the surface, clamped to
                                ///< ±bandWidth beyond (0: exact everywhere)
  std::size_t maxBytes = Volume::kDefaultMaxBytes;  ///< largest output voxel payload accepted
  std::function<void(double)> progress;  ///< called with a fraction in [0,1] from the calling thread, at most
                                         ///< ~100 times; may be empty
};

/// Voxelizes a closed triangle mesh (metres) into a Volume whose voxel
/// centres lie on the world lattice of spacing h = voxelSize (centre (i, j, k)
/// at origin + h·(i, j, k), the origin a multiple of h), axis-aligned,
/// covering the mesh bounds plus `paddingVoxels` on each side;
/// indexToWorld() places it.
///
/// Occupancy: a voxel is 1 when its centre is inside the solid (see the
/// header comment), 0 otherwise; centres exactly on the surface may go
/// either way. Signed distance: the Euclidean distance from the centre to the
/// nearest triangle, negative inside. With bandWidth > 0 it is exact wherever
/// |d| <= bandWidth and ±bandWidth beyond. With bandWidth = 0 it is exact
/// within 1.5 h of the surface and propagated beyond by a closest-triangle
/// transform (passes along ±x, ±y, ±z that re-evaluate the exact distance to
/// the neighbours' closest triangles, then a local descent to nearer
/// triangles around the closest one's vertices): the value is always the
/// exact distance to some triangle, so never below the true distance, and
/// equals it except near medial regions where the nearest triangle changes
/// within a voxel. Measured against brute force (Tests/DMMath/voxelize_test):
/// exact (< 1e-6 m) for boxes and convex polyhedra; for a torus at h = 3 mm,
/// 0.35 % of the voxels off, by at most 0.026 h. Use a band when exactness
/// matters and the far field does not.
///
/// Cost: O(F·r + voxels) for the sign, where r is the number of voxel columns
/// a triangle covers; for an SDF with a band, one BVH nearest-triangle query
/// of radius bandWidth per voxel (O(F log F) to build); for an exact-
/// everywhere SDF, O(F·27) seed distances and O(voxels) for the passes.
/// Parallel over z-slabs (dm::parallelFor).
/// Memory: the output plus, for an SDF with bandWidth = 0, 4 bytes per voxel,
/// and with a band, a BVH of about 40 bytes per triangle.
///
/// Fails with InvalidArgument on an empty mesh, an invalid one (NaN
/// coordinates, indices out of range: Mesh::validate()), voxelSize <= 0 or not
/// finite, a negative padding or bandWidth, an output of more than `maxBytes`
/// (checked before allocating), and, always for occupancy and for the sign of
/// an SDF, a mesh that is not closed (the message counts the boundary and
/// non-manifold edges; dm::weldVertices() fixes triangle soups).
/// @code
///   auto sdf = dm::voxelizeMesh(scalpel, {.voxelSize = 0.5e-3, .signedDistance = true});
///   if (!sdf) return sdf.error();
///   double d = sdf->sampleWorld(tipPosition);  // m, < 0 inside
/// @endcode
Result<Volume> voxelizeMesh(const Mesh& mesh, const VoxelizeOptions& options);

}  // namespace dm
