// Private to DMIO: the checks a mesh input gets before Assimp sees it
// (mesh_io.cpp runs them in the caller's process, ahead of the helper).
// Two kinds:
//  * inputs known to make Assimp 5.2 loop or allocate without end: OFF and
//    PLY headers promising more elements than the file holds, PLY headers
//    without an "end_header" line, Collada index lists with letters;
//  * declared sizes over the import's budget: the element counts of a PLY
//    or OFF header and the triangle count of a binary STL are refused when
//    they exceed MeshImportOptions::maxTriangles (faces; vertices: three per
//    allowed triangle, at most 2^32 - 1), with the figure and the limit in
//    the message, before any mesh memory is allocated.
// Each runs on the first kMeshHeadBytes of the input (Collada: the whole
// text) and reads nothing past it.
#pragma once

#include <dm/core/result.hpp>

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

namespace dm::detail {

/// How much of a mesh input the header checks see.
inline constexpr std::size_t kMeshHeadBytes = 64 * 1024;

/// The start of a mesh input and what is known about it.
struct MeshHead {
  std::string_view head;        ///< its first kMeshHeadBytes (or all of it)
  std::uint64_t fileBytes = 0;  ///< its whole size
  std::string extension;        ///< lower case, no dot ("ply", "stl", ...); may be empty
};

/// The most vertices a header may declare when `maxTriangles` triangles are
/// allowed: three per triangle, at most 2^32 - 1 (the index type).
std::uint64_t vertexBudget(std::size_t maxTriangles);

/// OFF, PLY and binary STL header checks (see the file comment). Parse for a
/// header that promises more than the file can hold or that makes Assimp
/// loop; Unsupported for declared counts over the budget.
Status checkMeshHead(const MeshHead& in, std::size_t maxTriangles, const std::string& where);

/// True for a file Assimp will read as Collada (by extension or content).
bool looksLikeCollada(std::string_view head, bool daeExtension);

/// Refuses a Collada <p> index list that holds anything but integers and
/// blanks (Assimp 5.2 loops on it).
Status checkColladaIndexLists(std::string_view xml, const std::string& where);

}  // namespace dm::detail
