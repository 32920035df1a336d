// mc_tables.cpp — the marching cubes and marching tetrahedra case tables,
// generated at compile time.
//
// Marching cubes (Lorensen & Cline 1987) classifies the eight corners of a cell
// and looks up the triangles of the case. The transcribed 15-case table derives
// half of its cases by complementing the other half, and on a face whose
// inside corners are diagonal (an ambiguous face) a case and its complement
// then join different pairs of corners: neighbouring cells disagree and the
// surface gets cracks. Instead of transcribing a table, this file builds all
// 256 cases from one rule that only looks at the face itself, so two cells that
// share a face always cut it the same way:
//
//   On every face, walking round its corners counter-clockwise seen from
//   outside the cube, each edge where the walk enters the inside is joined to
//   the next edge where it leaves it. On an ambiguous face that keeps the two
//   inside corners apart (the inside is 6-connected, the outside 18-connected).
//
// The joined crossings form closed polygons on the cube's surface, each
// crossing on exactly one polygon. Each polygon is triangulated without
// diagonals inside a cube face (those would be shared with the neighbouring
// cell's triangulation and could put three or four triangles on one edge),
// choosing among the remaining triangulations the one whose worst triangle is
// best, judged at the edge midpoints.
// Going entry → exit along each face orients every polygon counter-clockwise
// seen from outside the isosurface (from the corners with value <= iso), the
// convention of dm::Mesh. Since each face segment is shared by exactly the two
// cells on that face and traversed in opposite directions by them, the surface
// is a closed, consistently oriented 2-manifold wherever it does not reach the
// grid border.
//
// Marching tetrahedra splits the cube into the six Kuhn tetrahedra around the
// diagonal 0–7 (corners 0, e_a, e_a + e_b, 7 for each permutation (a, b, c) of
// the axes). Their face diagonals run from the lower to the upper corner of
// every face in every cell, so tetrahedra of neighbouring cells share faces
// exactly and the piecewise-linear level set is unambiguous. Each tetrahedron
// gives one triangle (one or three corners inside) or a quad split into two
// (two inside); triangles are oriented so the inside corners lie behind them.
#include "mc_tables.hpp"

#include <cstdlib>

namespace dm::detail {
namespace {

// Calling this during constant evaluation makes the table initialisers fail
// to compile, so a broken rule is caught by the compiler, never at run time.
[[noreturn]] void tableGenerationFailed() { std::abort(); }
constexpr void require(bool condition) {
  if (!condition) tableGenerationFailed();
}

struct P3 {
  double x, y, z;
};
constexpr P3 operator-(P3 a, P3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
constexpr P3 cross(P3 a, P3 b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
constexpr double dot(P3 a, P3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }

constexpr P3 cornerPosition(int c) { return {double(c & 1), double((c >> 1) & 1), double((c >> 2) & 1)}; }

constexpr int lowerCorner(int e) { return kCellEdges[e].dx + 2 * kCellEdges[e].dy + 4 * kCellEdges[e].dz; }
constexpr int upperCorner(int e) {
  const auto& s = kKindStep[kCellEdges[e].kind];
  return lowerCorner(e) + s[0] + 2 * s[1] + 4 * s[2];
}
constexpr P3 edgeMidpoint(int e) {
  const P3 a = cornerPosition(lowerCorner(e)), b = cornerPosition(upperCorner(e));
  return {(a.x + b.x) / 2, (a.y + b.y) / 2, (a.z + b.z) / 2};
}

// The cell edge joining corners a and b (either order), among the first `count`.
constexpr int edgeBetween(int a, int b, int count) {
  for (int e = 0; e < count; ++e)
    if ((lowerCorner(e) == a && upperCorner(e) == b) || (lowerCorner(e) == b && upperCorner(e) == a))
      return e;
  tableGenerationFailed();
}

// Corners of each cube face, counter-clockwise seen from outside the cube.
constexpr int kFaces[6][4] = {{0, 4, 6, 2}, {1, 3, 7, 5}, {0, 1, 5, 4},
                              {2, 6, 7, 3}, {0, 2, 3, 1}, {4, 5, 7, 6}};

constexpr bool facesAreCounterClockwise() {
  for (const auto& f : kFaces) {
    P3 centre{0, 0, 0};
    for (int c : f) {
      const P3 p = cornerPosition(c);
      centre = {centre.x + p.x / 4, centre.y + p.y / 4, centre.z + p.z / 4};
    }
    const P3 outward = centre - P3{0.5, 0.5, 0.5};
    for (int p = 0; p < 4; ++p) {
      const P3 a = cornerPosition(f[p]), b = cornerPosition(f[(p + 1) & 3]),
               c = cornerPosition(f[(p + 2) & 3]);
      if (dot(cross(b - a, c - b), outward) <= 0) return false;
      if (dot(a - centre, outward) != 0) return false;  // on the face's plane
    }
  }
  return true;
}
static_assert(facesAreCounterClockwise());

// Scale-free shape quality: (area / sum of squared sides)², largest for an
// equilateral triangle, 0 for a degenerate one.
constexpr double triangleQuality(int ea, int eb, int ec) {
  const P3 a = edgeMidpoint(ea), b = edgeMidpoint(eb), c = edgeMidpoint(ec);
  const P3 n = cross(b - a, c - a);
  const double s = dot(b - a, b - a) + dot(c - b, c - b) + dot(a - c, a - c);
  return dot(n, n) / (s * s);
}

template <class Case, int kMax>
constexpr void addTriangle(Case& c, int e0, int e1, int e2) {
  require(c.count < kMax);
  c.edges[3 * c.count] = static_cast<std::uint8_t>(e0);
  c.edges[3 * c.count + 1] = static_cast<std::uint8_t>(e1);
  c.edges[3 * c.count + 2] = static_cast<std::uint8_t>(e2);
  ++c.count;
}

// Whether cube edges a and b lie on a common face of the cube.
constexpr bool shareFace(int a, int b) {
  for (const auto& f : kFaces) {
    int found = 0;
    for (int p = 0; p < 4; ++p) {
      const int e = edgeBetween(f[p], f[(p + 1) & 3], kMcEdgeCount);
      found += (e == a || e == b) ? 1 : 0;
    }
    if (found == 2) return true;
  }
  return false;
}

// Triangulates the polygon poly[0..k) (cell edges, in order) into table case c,
// keeping its orientation, with the best worst triangle among triangulations
// whose diagonals never join two edges of one cube face. Such a diagonal would
// lie in the face, which the neighbouring cell also triangulates: the same
// vertex pair could then carry more than two triangles. Every other diagonal
// belongs to this cell alone. Dynamic programming over sub-polygons, O(k³).
constexpr void triangulatePolygon(McCase& c, const int* poly, int k) {
  constexpr double kNone = -1;
  double best[kMcEdgeCount][kMcEdgeCount] = {};
  int split[kMcEdgeCount][kMcEdgeCount] = {};
  const auto chordAllowed = [&](int i, int j) {
    return j == i + 1 || (i == 0 && j == k - 1) || !shareFace(poly[i], poly[j]);
  };
  for (int i = 0; i + 1 < k; ++i) best[i][i + 1] = 1e300;  // a polygon side: nothing to triangulate
  for (int len = 2; len < k; ++len)
    for (int i = 0; i + len < k; ++i) {
      const int j = i + len;
      best[i][j] = kNone;
      if (!chordAllowed(i, j)) continue;
      for (int m = i + 1; m < j; ++m) {
        if (best[i][m] == kNone || best[m][j] == kNone) continue;
        double q = triangleQuality(poly[i], poly[m], poly[j]);
        q = best[i][m] < q ? best[i][m] : q;
        q = best[m][j] < q ? best[m][j] : q;
        if (q > best[i][j] * (1 + 1e-9)) {
          best[i][j] = q;
          split[i][j] = m;
        }
      }
    }
  require(best[0][k - 1] != kNone);
  // Emit the chosen triangles, sub-polygon by sub-polygon.
  int stack[2 * kMcEdgeCount][2] = {};
  int top = 0;
  stack[top][0] = 0;
  stack[top][1] = k - 1;
  ++top;
  while (top > 0) {
    --top;
    const int i = stack[top][0], j = stack[top][1];
    if (j - i < 2) continue;
    const int m = split[i][j];
    addTriangle<McCase, kMcMaxTriangles>(c, poly[i], poly[m], poly[j]);
    stack[top][0] = m;
    stack[top][1] = j;
    ++top;
    stack[top][0] = i;
    stack[top][1] = m;
    ++top;
  }
}

constexpr std::array<McCase, 256> buildMarchingCubes() {
  std::array<McCase, 256> table{};
  for (int cfg = 0; cfg < 256; ++cfg) {
    const auto in = [cfg](int c) { return ((cfg >> c) & 1) != 0; };
    int next[kMcEdgeCount];
    int predecessors[kMcEdgeCount] = {};
    for (int& n : next) n = -1;
    for (const auto& f : kFaces) {
      for (int p = 0; p < 4; ++p) {
        const int a = f[p], b = f[(p + 1) & 3];
        if (in(a) || !in(b)) continue;  // not an entry into the inside
        int m = (p + 1) & 3;
        while (!(in(f[m]) && !in(f[(m + 1) & 3]))) m = (m + 1) & 3;
        const int from = edgeBetween(a, b, kMcEdgeCount);
        const int to = edgeBetween(f[m], f[(m + 1) & 3], kMcEdgeCount);
        require(next[from] == -1);
        next[from] = to;
        ++predecessors[to];
      }
    }
    // Each crossed edge lies on exactly one polygon: one successor, one predecessor.
    for (int e = 0; e < kMcEdgeCount; ++e) {
      const bool crossed = in(lowerCorner(e)) != in(upperCorner(e));
      require(crossed ? (next[e] >= 0 && predecessors[e] == 1) : (next[e] == -1 && predecessors[e] == 0));
    }
    bool visited[kMcEdgeCount] = {};
    for (int start = 0; start < kMcEdgeCount; ++start) {
      if (next[start] < 0 || visited[start]) continue;
      int poly[kMcEdgeCount] = {};
      int k = 0;
      int e = start;
      for (; !visited[e]; e = next[e]) {
        visited[e] = true;
        poly[k++] = e;
      }
      require(e == start && k >= 3);
      triangulatePolygon(table[cfg], poly, k);
    }
  }
  return table;
}

// Appends triangle (e0, e1, e2), swapped if needed so that inside corner
// `inside` lies behind it (positive volume of the tetrahedron inside→triangle).
constexpr void addOrientedTet(MtCase& c, int e0, int e1, int e2, int inside) {
  const P3 r = cornerPosition(inside);
  const double det = dot(edgeMidpoint(e0) - r, cross(edgeMidpoint(e1) - r, edgeMidpoint(e2) - r));
  require(det != 0);
  if (det > 0)
    addTriangle<MtCase, kMtMaxTriangles>(c, e0, e1, e2);
  else
    addTriangle<MtCase, kMtMaxTriangles>(c, e0, e2, e1);
}

constexpr std::array<MtCase, 256> buildMarchingTets() {
  constexpr int kAxisOrder[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
  std::array<MtCase, 256> table{};
  for (int cfg = 0; cfg < 256; ++cfg) {
    const auto in = [cfg](int c) { return ((cfg >> c) & 1) != 0; };
    for (const auto& order : kAxisOrder) {
      const int tet[4] = {0, 1 << order[0], (1 << order[0]) | (1 << order[1]), 7};
      int inside[4] = {}, outside[4] = {};
      int ni = 0, no = 0;
      for (int c : tet) {
        if (in(c))
          inside[ni++] = c;
        else
          outside[no++] = c;
      }
      const auto edge = [](int a, int b) { return edgeBetween(a, b, kMtEdgeCount); };
      if (ni == 1 || ni == 3) {
        const int apex = ni == 1 ? inside[0] : outside[0];
        const int* others = ni == 1 ? outside : inside;
        addOrientedTet(table[cfg], edge(apex, others[0]), edge(apex, others[1]), edge(apex, others[2]),
                       inside[0]);
      } else if (ni == 2) {
        // Quad a-c, a-d, b-d, b-c (a cycle); split along the diagonal with the better worst triangle.
        const int q[4] = {edge(inside[0], outside[0]), edge(inside[0], outside[1]),
                          edge(inside[1], outside[1]), edge(inside[1], outside[0])};
        const auto worst = [&](int s) {
          const double q0 = triangleQuality(q[s], q[(s + 1) & 3], q[(s + 2) & 3]);
          const double q1 = triangleQuality(q[s], q[(s + 2) & 3], q[(s + 3) & 3]);
          return q0 < q1 ? q0 : q1;
        };
        const int s = worst(1) > worst(0) * (1 + 1e-9) ? 1 : 0;
        addOrientedTet(table[cfg], q[s], q[(s + 1) & 3], q[(s + 2) & 3], inside[0]);
        addOrientedTet(table[cfg], q[s], q[(s + 2) & 3], q[(s + 3) & 3], inside[0]);
      }
    }
  }
  return table;
}

constexpr std::array<McCase, 256> kMc = buildMarchingCubes();
constexpr std::array<MtCase, 256> kMt = buildMarchingTets();

// Spot checks against cases worked out by hand: nothing for an empty or full
// cube; one triangle cutting off a single corner (six for the tetrahedra, as
// corner 0 belongs to all of them); a quad when one face is inside; and for the
// bottom face inside, the tetrahedra {0,1,3,7}, {0,2,3,7} have three corners
// inside (1 triangle each), {0,1,5,7}, {0,2,6,7} two (a quad each) and
// {0,4,5,7}, {0,4,6,7} one (1 triangle each): 8 triangles.
constexpr bool knownCasesHold() {
  if (kMc[0].count != 0 || kMc[255].count != 0 || kMt[0].count != 0 || kMt[255].count != 0) return false;
  const auto& one = kMc[1];
  if (one.count != 1 || one.edges[0] + one.edges[1] + one.edges[2] != 0 + 4 + 8) return false;
  if (kMc[0x0F].count != 2 || kMc[0xF0].count != 2 || kMt[1].count != 6 || kMt[0x80].count != 6) return false;
  return kMt[0x0F].count == 8;
}
static_assert(knownCasesHold());

}  // namespace

const std::array<McCase, 256> kMarchingCubesCases = kMc;
const std::array<MtCase, 256> kMarchingTetsCases = kMt;

}  // namespace dm::detail
