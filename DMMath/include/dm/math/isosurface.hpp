// dm/math/isosurface.hpp — triangle meshes of an isosurface of a dm::Volume.
//
// Conventions:
//  - A voxel is *inside* when its value is > iso (strictly), so for a CT the
//    skin at iso −300 HU encloses the voxels denser than −300, and for a signed
//    distance field that is positive inside the surface is its zero set.
//  - Triangles are counter-clockwise seen from outside and vertex normals point
//    outward, i.e. toward decreasing values (n = −∇f / |∇f|), in world space,
//    whatever the handedness of the volume's affine (a mirrored affine flips
//    the winding so it stays counter-clockwise in the world).
//  - Positions are world coordinates in metres: the volume's index-to-world
//    affine applied to the interpolated point on the grid edge.
//  - Each crossed grid edge gives exactly one vertex, shared by all the cells
//    around it, strictly inside the edge (see extractIsosurface), so there
//    are no duplicate vertices, by index or by position, and no zero-area
//    triangles. Where the isosurface is
//    closed inside the grid the mesh is a closed, consistently oriented
//    2-manifold (ambiguous faces are resolved the same way from both cells;
//    see DMMath/src/mc_tables.cpp). Where the inside reaches the grid border
//    the mesh is open along it, unless `closeBorders` is set.
//  - The output is bit-for-bit the same for any thread count.
#pragma once

#include <dm/core/mesh.hpp>
#include <dm/core/result.hpp>
#include <dm/core/volume.hpp>

#include <cstddef>
#include <cstdint>
#include <functional>

namespace dm {

/// Which cell triangulation to use.
enum class IsoMethod : std::uint8_t {
  MarchingCubes,       ///< one case table per cube (up to 5 triangles per cell)
  MarchingTetrahedra,  ///< six tetrahedra per cube; unambiguous, about 2–3× more triangles
};

/// Options of extractIsosurface().
struct IsosurfaceOptions {
  double iso = 0.0;                             ///< threshold in voxel value units; inside is value > iso
  IsoMethod method = IsoMethod::MarchingCubes;  ///< cell triangulation
  bool computeNormals = true;                   ///< fill Mesh::normals from the volume gradient
  /// Treat everything outside the grid as outside (a virtual layer of voxels
  /// below iso), so the surface closes half a voxel beyond the border with flat
  /// caps whose normals point out of the grid.
  bool closeBorders = false;
  int threads = 0;               ///< worker threads; 0 = std::thread::hardware_concurrency()
  std::size_t maxTriangles = 0;  ///< fail when the output would exceed this; 0 = no cap
  /// Called with the fraction done in [0, 1], nondecreasing, from the calling
  /// thread only, at most about 100 times; may be empty. Must not throw.
  std::function<void(double)> progress;
};

/// Extracts the isosurface `options.iso` of `volume` as a triangle mesh (world
/// coordinates in metres, see the conventions above).
///
/// Vertices lie on grid edges at the linear interpolation of the two voxel
/// values; normals (if requested) are the central-difference gradient at both
/// end voxels (one-sided at the border), interpolated the same way, mapped to
/// the world by the inverse transpose of the affine and negated. Where the
/// gradient vanishes or is not finite the normal falls back to the edge
/// direction from the inside voxel to the outside one. Voxel values that are
/// NaN count as outside. A voxel exactly at iso is outside, and the vertices
/// of the edges from it to inside voxels (whose linear root is the voxel
/// itself) go 1/256 of their edge into it; every other vertex stays at least
/// 1/65536 of its edge off both ends. So no two vertices share a position and
/// no triangle has zero area, even where voxels equal iso (integer data at an
/// integer iso): the mesh stays a manifold when something merges vertices by
/// position (an STL file, a mesh tool), and the surface moves by at most
/// 1/256 of a voxel, only around voxels at iso.
///
/// Runs on `options.threads` threads over z-slabs: O(voxels) to classify, then
/// O(active cells + triangles). Memory: one bit per voxel plus a few index
/// slices per thread, plus the output. An iso outside the value range gives
/// an empty mesh.
///
/// Fails with InvalidArgument on an empty volume, a non-finite iso or a
/// negative thread count, and with Unsupported when the output would have more
/// than `options.maxTriangles` triangles (when set) or more than 2³² − 1
/// vertices, or when memory runs out.
/// @code
///   auto skin = dm::extractIsosurface(head, {.iso = 40, .closeBorders = true});
///   if (!skin) return skin.error();
///   resources.add("skin", std::move(*skin));
/// @endcode
Result<Mesh> extractIsosurface(const Volume& volume, const IsosurfaceOptions& options = {});

}  // namespace dm
