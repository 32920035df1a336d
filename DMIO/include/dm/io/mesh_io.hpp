// dm/io/mesh_io.hpp — triangle meshes from and to files (patient and tool
// models).
//
// Import goes through Assimp, so every format Assimp 5 reads works: OBJ, STL
// (ASCII and binary), PLY, OFF, glTF 2 (.gltf/.glb), Collada, FBX, 3DS, ...
// (supportedMeshExtensions() lists them). The scene graph is flattened:
// every node's transform is applied to the positions and normals of the
// meshes it references (a mirroring transform also flips the winding so
// triangles stay counter-clockwise from outside), points and lines are
// dropped, polygons are triangulated. The result is then
//  * scaled to metres: MeshImportOptions::unit names the file's length unit
//    (the file's own unit metadata, e.g. Collada <unit>, is applied by Assimp
//    first) and `scale` multiplies on top;
//  * welded (by position, exactly or within `weldTolerance`), which removes
//    the duplicated corners of faceted formats such as STL; triangles that
//    collapse to an edge or a point are dropped;
//  * given normals: a file normal is kept when it is finite and non-zero and
//    welding did not merge vertices with different file normals (per-face
//    normals of STL, hard edges of OBJ); every other vertex gets the
//    angle-weighted normal of Mesh::computeNormals() (or, with
//    computeNormals off, the mesh gets no normals at all);
//  * checked: finite coordinates, indices in range, at least one triangle.
//    Non-manifold edges (more than two triangles) and inconsistently oriented
//    neighbours are accepted but reported with dm::log::warn.
// Texture coordinates (first set) and vertex colours (first set) are kept
// when present; parts without them get (0, 0) and opaque white.
//
// With the default isolation, bad input never crashes, hangs or throws the
// caller: every failure is a dm::Error naming the file (or the
// "<memory>.hint" source of parseMesh) and, where it applies, the mesh and
// vertex. Inputs over `maxFileBytes` (all files an import opens, together:
// .mtl, .bin, ...) or producing more than `maxTriangles` triangles are
// refused. Assimp 5.2 loops forever, crashes or corrupts memory on some
// malformed files, so by default it runs in a helper process with a deadline
// (MeshImportOptions::isolation, timeoutSeconds). Inputs known to make it
// loop are refused before it sees them: OFF and PLY headers promising more
// elements than the file holds, PLY headers without an "end_header" line,
// Collada index lists with letters. Declared sizes are held to the budget
// from the header, before any mesh memory is allocated: a PLY or OFF header
// declaring more faces than `maxTriangles`, or more vertices than three per
// allowed triangle (at most 2^32 - 1), and a binary STL declaring more
// triangles, fail with Unsupported naming the figure and the limit.
//
// Export (writeMesh) uses the SDK's own writers: STL (binary or ASCII), PLY
// (binary little-endian or ASCII; positions as double) and OBJ (text), each
// with normals when the mesh has them, written atomically.
//
// @code
//   dm::MeshImportOptions opt; opt.unit = "mm";
//   auto tool = dm::readMesh("scalpel.stl", opt);
//   if (!tool) { std::cerr << tool.error() << '\n'; return 1; }
//   auto s = dm::writeMesh(*tool, "scalpel_m.ply");
// @endcode
#pragma once

#include <dm/core/mesh.hpp>
#include <dm/core/result.hpp>
#include <dm/io/isolation.hpp>

#include <cstddef>
#include <filesystem>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace dm {

/// Options for readMesh(), readMeshes() and parseMesh().
struct MeshImportOptions {
  /// Length unit of the file's coordinates: "m", "cm", "mm", "um", "inch"
  /// (or "in"), "ft". Positions are converted to metres.
  std::string unit = "m";
  /// Extra factor applied after the unit conversion (must be finite and > 0).
  double scale = 1.0;
  /// readMesh(): merge every part of the scene into one mesh. When false,
  /// readMesh() fails on a file with more than one part (use readMeshes()).
  bool mergeMeshes = true;
  /// Merge vertices at the same position (see weldTolerance).
  bool weld = true;
  /// Weld distance in metres (after scaling); 0 merges only identical
  /// positions. Welding within a tolerance is greedy in vertex order.
  double weldTolerance = 0.0;
  /// Compute normals for vertices without a usable file normal; when false
  /// such meshes get no normals.
  bool computeNormals = true;
  /// Largest number of triangles accepted (over all parts and instances);
  /// also the budget a PLY, OFF or binary STL header's declared counts are
  /// held to before the import (faces; vertices: three per triangle).
  std::size_t maxTriangles = 50'000'000;
  /// Largest number of bytes read, over every file the import opens.
  std::size_t maxFileBytes = std::size_t{2} << 30;
  /// Where Assimp runs (dm/io/isolation.hpp): by default in the dm-isolate
  /// helper program, so that a file which makes it crash or loop (Assimp 5
  /// does both on some malformed files) fails with an Error instead of
  /// taking the caller down, whatever threads the caller runs. Costs a
  /// process start and a copy of the mesh through a pipe
  /// (docs/performance.md); Isolation::InProcess only for trusted files.
  /// The helper may allocate about 1 KiB per allowed triangle plus 64× the
  /// file size and 512 MiB; a file that makes Assimp ask for more fails
  /// with Unsupported.
  Isolation isolation = Isolation::Helper;
  /// Wall-clock limit for Assimp in the helper or child, seconds (0: none).
  /// Not with Isolation::InProcess.
  double timeoutSeconds = 120.0;
};

/// Options for writeMesh() and encodeMesh().
struct MeshExportOptions {
  /// Binary STL / binary little-endian PLY when true, ASCII when false.
  /// OBJ is always text.
  bool binary = true;
};

/// Metres per `unit` ("m", "cm", "mm", "um", "inch"/"in", "ft"; case-
/// sensitive). Fails with InvalidArgument listing the accepted names.
Result<double> metresPerUnit(std::string_view unit);

/// The extensions Assimp reads, as "*.3ds;*.obj;..." (lower case).
std::string supportedMeshExtensions();

/// True if the extension of `file` (case-insensitive) is one Assimp reads.
bool canReadMesh(const std::filesystem::path& file);

/// Reads `file` into one mesh named after the file's stem (see the header
/// comment for what is done to it). Fails, naming the file, when it is
/// missing, unreadable, too large, malformed, has no triangles, a non-finite
/// vertex (named by its mesh and index), too many triangles, or — with
/// mergeMeshes off — more than one part; when isolated, also when Assimp
/// crashes (Parse) or runs past timeoutSeconds (Timeout). O(triangles · log).
/// @code
///   auto m = dm::readMesh("liver.obj");
///   if (!m) { std::cerr << m.error() << '\n'; return 1; }
///   double area = m->surfaceArea();  // m²
/// @endcode
Result<Mesh> readMesh(const std::filesystem::path& file, const MeshImportOptions& options = {});

/// Reads `file` into one mesh per (node, mesh) pair of the scene, each with
/// its node transform applied, named after the node ("node" or, when a node
/// holds several meshes, "node/mesh"; the mesh name, then "part<i>", when the
/// node has no name). Each part is welded on its own; parts without
/// triangles (or whose triangles all collapse when welded) are left out.
/// `mergeMeshes` is ignored. Fails like readMesh().
/// @code
///   auto parts = dm::readMeshes("instruments.glb");
///   if (!parts) { std::cerr << parts.error() << '\n'; return 1; }
///   for (const dm::Mesh& p : *parts) std::cout << p.name << '\n';
/// @endcode
Result<std::vector<Mesh>> readMeshes(const std::filesystem::path& file,
                                     const MeshImportOptions& options = {});

/// Parses a mesh file held in memory; `formatHint` is its extension without
/// the dot ("stl", "obj", "glb", ...). Files it refers to (.mtl, .bin,
/// textures) are never opened: formats that need them fail cleanly. The
/// result is named after the hint; errors name "<memory>.hint". Otherwise
/// like readMesh(). Used for data from archives, the network and fuzzing.
/// @code
///   auto m = dm::parseMesh(bytes, "stl");
///   if (!m) { std::cerr << m.error() << '\n'; return 1; }
/// @endcode
Result<Mesh> parseMesh(std::span<const std::byte> bytes, std::string_view formatHint,
                       const MeshImportOptions& options = {});

/// Encodes `mesh` in the format named by `extension` ("stl", "ply", "obj" or
/// with a dot; case-insensitive). STL stores float32 positions and face
/// normals; PLY stores double positions and, when present, float normals,
/// texture coordinates (s, t) and float RGBA colours; OBJ stores positions,
/// normals and texture coordinates with shortest round-trip decimals and
/// colours as the common "v x y z r g b" extension (alpha is dropped).
/// Fails on an unknown extension, an invalid mesh (Mesh::validate), a mesh
/// without triangles, or more elements than the format can count. O(n).
Result<std::vector<std::byte>> encodeMesh(const Mesh& mesh, std::string_view extension,
                                          const MeshExportOptions& options = {});

/// Writes `mesh` to `file`, choosing the format by its extension (.stl,
/// .ply, .obj; see encodeMesh()), atomically (a reader never sees a partial
/// file). Fails like encodeMesh() or when the file cannot be written; errors
/// name the file.
/// @code
///   if (auto s = dm::writeMesh(mesh, "out.stl", {.binary = false}); !s)
///     std::cerr << s.error() << '\n';
/// @endcode
Status writeMesh(const Mesh& mesh, const std::filesystem::path& file, const MeshExportOptions& options = {});

}  // namespace dm
