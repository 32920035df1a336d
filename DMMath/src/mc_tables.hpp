// mc_tables.hpp — private case tables of marching cubes and marching tetrahedra.
//
// Cell corner c of a grid cell (i, j, k) is the node (i + dx, j + dy, k + dz)
// with c = dx + 2·dy + 4·dz, so a cube case is the byte whose bit c is set when
// corner c is inside (value > iso). Cell edges are identified by the lattice
// edge they lie on: a kind (the direction, axis or diagonal) and the offset
// (dx, dy, dz) of its lower node from the cell's node (i, j, k). Edges 0..11 are
// the cube edges used by marching cubes; marching tetrahedra adds the six face
// diagonals and the body diagonal of the Kuhn (Freudenthal) split into six
// tetrahedra sharing the diagonal 0–7, which is the same in every cell and
// therefore matches across faces.
//
// The tables are generated at compile time in mc_tables.cpp (their own
// translation unit, so edits to the extraction algorithm do not rebuild them);
// see there for the rules that make the surfaces closed.
#pragma once

#include <array>
#include <cstdint>

namespace dm::detail {

/// Direction of a lattice edge. The first three lie in a node slice (k fixed),
/// the last four join slice k to slice k + 1.
enum EdgeKind : std::uint8_t { kEdgeX, kEdgeY, kEdgeXY, kEdgeZ, kEdgeXZ, kEdgeYZ, kEdgeXYZ, kEdgeKinds };

/// Number of kinds that lie in one node slice.
inline constexpr int kSliceKinds = 3;

/// Node step (dx, dy, dz) of each edge kind.
inline constexpr std::array<std::array<std::uint8_t, 3>, kEdgeKinds> kKindStep = {
    {{1, 0, 0}, {0, 1, 0}, {1, 1, 0}, {0, 0, 1}, {1, 0, 1}, {0, 1, 1}, {1, 1, 1}}};

/// One edge of a cell: its kind and the offset of its lower node in the cell.
struct CellEdge {
  std::uint8_t kind;
  std::uint8_t dx, dy, dz;
};

/// The 19 cell edges: 0..3 along x (offset dy + 2dz), 4..7 along y (dx + 2dz),
/// 8..11 along z (dx + 2dy), 12..13 xy-diagonals (dz), 14..15 xz-diagonals (dy),
/// 16..17 yz-diagonals (dx), 18 the body diagonal.
inline constexpr std::array<CellEdge, 19> kCellEdges = {{{kEdgeX, 0, 0, 0},
                                                         {kEdgeX, 0, 1, 0},
                                                         {kEdgeX, 0, 0, 1},
                                                         {kEdgeX, 0, 1, 1},
                                                         {kEdgeY, 0, 0, 0},
                                                         {kEdgeY, 1, 0, 0},
                                                         {kEdgeY, 0, 0, 1},
                                                         {kEdgeY, 1, 0, 1},
                                                         {kEdgeZ, 0, 0, 0},
                                                         {kEdgeZ, 1, 0, 0},
                                                         {kEdgeZ, 0, 1, 0},
                                                         {kEdgeZ, 1, 1, 0},
                                                         {kEdgeXY, 0, 0, 0},
                                                         {kEdgeXY, 0, 0, 1},
                                                         {kEdgeXZ, 0, 0, 0},
                                                         {kEdgeXZ, 0, 1, 0},
                                                         {kEdgeYZ, 0, 0, 0},
                                                         {kEdgeYZ, 1, 0, 0},
                                                         {kEdgeXYZ, 0, 0, 0}}};

inline constexpr int kMcEdgeCount = 12;
inline constexpr int kMtEdgeCount = 19;
/// Most triangles one cube case produces.
inline constexpr int kMcMaxTriangles = 5;
inline constexpr int kMtMaxTriangles = 12;

/// Triangles of one case: `count` triangles, edges[3t .. 3t+2] are the cell
/// edges carrying the vertices of triangle t, counter-clockwise seen from
/// outside (the side of the corners with value <= iso) in index space.
struct McCase {
  std::uint8_t count;
  std::array<std::uint8_t, 3 * kMcMaxTriangles> edges;
};
struct MtCase {
  std::uint8_t count;
  std::array<std::uint8_t, 3 * kMtMaxTriangles> edges;
};

/// Marching cubes, indexed by cube case.
extern const std::array<McCase, 256> kMarchingCubesCases;
/// Marching tetrahedra (six Kuhn tetrahedra per cube), indexed by cube case.
extern const std::array<MtCase, 256> kMarchingTetsCases;

}  // namespace dm::detail
