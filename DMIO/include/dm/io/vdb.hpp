// dm/io/vdb.hpp — sparse volumes to and from OpenVDB (.vdb) files.
//
// OpenVDB (Museth 2013) stores sparse grids: only voxels that differ from a
// background value (fog volumes) or lie in a narrow band around a surface
// (level sets) are stored. readVdb() densifies one scalar grid into a
// dm::Volume; writeVdb() writes a dm::Volume back sparsely, as a fog volume
// or as a narrow-band level set (e.g. the output of dm::voxelizeMesh with
// signedDistance). OpenVDB stays behind this header (it is linked privately
// into DM::IO); its exceptions become dm::Error values naming the file and
// the grid.
//
// Conventions: OpenVDB voxel (i, j, k) is sampled at index-space point
// (i, j, k), like dm::Volume, and OpenVDB world units are taken as metres.
// The grid's linear transform (scale, rotation, translation, general affine)
// becomes the volume's indexToWorld(); frustum and other non-linear maps are
// rejected.
//
// @code
//   auto sdf = dm::voxelizeMesh(tool, {.voxelSize = 5e-4, .signedDistance = true});
//   if (auto s = dm::writeVdb(*sdf, "tool.vdb", {.gridName = "surface", .levelSet = true}); !s) return s;
//   auto back = dm::readVdb("tool.vdb", {.gridName = "surface"});
// @endcode
#pragma once

#include <dm/core/result.hpp>
#include <dm/core/volume.hpp>
#include <dm/io/isolation.hpp>

#include <cstddef>
#include <filesystem>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace dm {

/// Options of readVdb() / parseVdb().
struct VdbReadOptions {
  /// Grid to read; empty: the first float, double, int32, int64 or bool grid.
  std::string gridName;
  /// Largest dense voxel payload accepted, in bytes: the box the grid's
  /// metadata declares is checked before its tree is read, the dense box
  /// before the volume is allocated.
  std::size_t maxBytes = Volume::kDefaultMaxBytes;
  /// Where OpenVDB parses (dm/io/isolation.hpp): by default in the
  /// dm-isolate helper program with a memory budget of about
  /// 2·maxBytes + 16·file size + 1 GiB and a deadline, so a crafted file that
  /// makes OpenVDB allocate or loop becomes an Error. Isolation::InProcess
  /// for trusted files (no process start, no copy of the volume).
  Isolation isolation = Isolation::Helper;
  double timeoutSeconds = 60.0;  ///< isolated parsing only; 0: no deadline
};

/// Options of writeVdb().
struct VdbWriteOptions {
  std::string gridName = "density";  ///< name of the grid in the file
  /// Write a narrow-band level set (grid class GRID_LEVEL_SET) of a signed
  /// distance volume in metres, negative inside: background = halfWidthVoxels
  /// · voxelSize (the largest spacing), voxels with |d| >= background are
  /// dropped and the inactive inside is -background (signed flood fill).
  bool levelSet = false;
  double halfWidthVoxels = 3.0;  ///< level set only; > 0
  /// Fog volumes: voxels within tolerance of the background 0 are inactive
  /// (not stored). 0 stores every nonzero voxel.
  double tolerance = 0.0;
};

/// Reads one scalar grid of a .vdb file as a dense volume covering the
/// grid's active voxel bounding box, united with the dense box that
/// writeVdb() records in the grid metadata ("dm_dense_min"/"dm_dense_max"),
/// so a written volume reads back with its own dims and affine. Voxels
/// outside the active set take the tree's inactive value (background, or
/// -background inside a level set). Float, int32 and bool grids give an F32
/// volume, double and int64 grids an F64 one. indexToWorld() is the grid's
/// linear transform composed with the box's offset, in metres.
/// The file is read into memory (at most 2·maxBytes + 1 MiB) and parsed by
/// OpenVDB from there with short reads failing at once; the sparse tree is
/// loaded, then the dense size is checked against options.maxBytes before
/// allocating it. O(file + dense voxels) time.
/// Fails, naming the file and the grid, with NotFound (missing file, or no
/// grid of that name: the hint lists the grids), Parse (not a VDB file,
/// truncated or corrupt: whatever OpenVDB throws), Version (a file version
/// OpenVDB 10 cannot read), Unsupported (non-scalar grid, non-linear
/// transform, empty grid, out of memory) or InvalidArgument (dense box over
/// maxBytes).
/// Hostile files: OpenVDB allocates what length fields inside the file ask
/// for, which the default isolation (VdbReadOptions::isolation) contains.
/// @code
///   auto v = dm::readVdb("bunny.vdb");
///   if (!v) { std::cerr << v.error() << '\n'; return 1; }
///   float d = v->data<float>()[0];
/// @endcode
Result<Volume> readVdb(const std::filesystem::path& file, const VdbReadOptions& options = {});

/// readVdb() from the bytes of a .vdb file in memory; `sourceName` names
/// it in errors. Checks the stream header (magic 0x56444220, file version
/// 213..224, header size) before handing the bytes to OpenVDB, refuses a
/// grid whose metadata declares a box over maxBytes before any tree is
/// read, and makes every short read fail at once. OpenVDB 10 allocates strings and
/// compressed blocks at the lengths stored in the file before reading them
/// (e.g. openvdb::readString, up to 4 GiB from a 4-byte field), so with
/// isolation (the default) the parse runs in another process with a memory
/// budget and deadline (Tests/fuzz/vdb_fuzz.cpp exercises this path).
/// @code
///   auto bytes = dm::readFile("grid.vdb");
///   auto v = dm::parseVdb(*bytes, "grid.vdb");
/// @endcode
Result<Volume> parseVdb(std::span<const std::byte> bytes, std::string_view sourceName,
                        const VdbReadOptions& options = {});

/// Writes `volume` as one grid of a new .vdb file, atomically (temporary
/// file in the same directory, then rename). F64 volumes become a double
/// grid, every other type a float grid. The transform is the volume's
/// indexToWorld() (any invertible affine). Only voxels that differ from the
/// background (see VdbWriteOptions) are active, so the file is sparse; the
/// dense index box is recorded in the grid metadata for readVdb().
/// O(voxels). Fails, naming the file and grid, on an empty volume, a level
/// set of a non-F32/F64 volume, bad options, or an I/O error.
/// @code
///   if (auto s = dm::writeVdb(fog, "smoke.vdb"); !s) std::cerr << s.error() << '\n';
/// @endcode
Status writeVdb(const Volume& volume, const std::filesystem::path& file, const VdbWriteOptions& options = {});

/// The grids of a .vdb file, one string each: "name (type, class, N active
/// voxels)", e.g. "surface (float, level set, 120345 active voxels)". Loads
/// the whole file (like readVdb()). Fails like readVdb() on an unreadable file.
/// @code
///   for (const auto& g : dm::listVdbGrids("scene.vdb").value()) std::puts(g.c_str());
/// @endcode
Result<std::vector<std::string>> listVdbGrids(const std::filesystem::path& file);

}  // namespace dm
