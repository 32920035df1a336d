// dm/core/mesh.hpp — the shared triangle mesh of the data model.
//
// Loaded once into the resource manager and used by collision, physics and
// rendering through a handle. Positions are metres in the mesh's local frame
// (double); triangles index positions counter-clockwise seen from outside
// (normals point outward). Optional per-vertex attributes are either empty or
// have exactly one entry per position.
#pragma once

#include <dm/core/result.hpp>
#include <dm/core/types.hpp>

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace dm {

using Triangle = std::array<std::uint32_t, 3>;

struct Mesh {
  std::string name;
  std::vector<Vec3> positions;      ///< m, local frame
  std::vector<Vec3> normals;        ///< unit, per vertex; empty or positions.size()
  std::vector<Triangle> triangles;  ///< CCW from outside
  std::vector<Vec2f> uvs;           ///< texture coordinates; empty or positions.size()
  std::vector<Vec4f> colors;        ///< linear RGBA in [0, 1]; empty or positions.size()

  std::size_t vertexCount() const { return positions.size(); }
  std::size_t triangleCount() const { return triangles.size(); }
  bool empty() const { return triangles.empty(); }

  /// Axis-aligned bounds of the positions (empty box for an empty mesh). O(n).
  Aabb bounds() const;
  /// Unit normal of triangle t (zero vector for a degenerate triangle).
  Vec3 faceNormal(std::size_t t) const;
  /// Area of triangle t, m².
  double faceArea(std::size_t t) const;
  /// Sum of triangle areas, m².
  double surfaceArea() const;

  /// Recomputes `normals` as angle-weighted averages of face normals. O(n).
  void computeNormals();

  /// Checks the invariants: attribute sizes, indices in range, finite
  /// coordinates. Errors name the offending vertex or triangle index.
  Status validate() const;

  /// Applies `t` to positions and (rotation part) normals.
  void transform(const Affine3& t);

  /// Appends `other`'s vertices and triangles (its indices offset by this
  /// mesh's vertex count). A per-vertex attribute (normals, uvs, colors) is
  /// kept where both meshes carry it for every vertex (or this mesh has no
  /// vertices yet) and cleared otherwise, so the invariants hold. O(other).
  void append(const Mesh& other);
};

}  // namespace dm
