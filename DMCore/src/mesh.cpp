#include <dm/core/mesh.hpp>

#include <algorithm>
#include <cmath>

namespace dm {

Aabb Mesh::bounds() const {
  Aabb box;
  for (const Vec3& p : positions) box.extend(p);
  return box;
}

Vec3 Mesh::faceNormal(std::size_t t) const {
  const Triangle& tri = triangles[t];
  const Vec3 n = (positions[tri[1]] - positions[tri[0]]).cross(positions[tri[2]] - positions[tri[0]]);
  const double len = n.norm();
  return len > 0 ? Vec3(n / len) : Vec3::Zero();
}

double Mesh::faceArea(std::size_t t) const {
  const Triangle& tri = triangles[t];
  return 0.5 * (positions[tri[1]] - positions[tri[0]]).cross(positions[tri[2]] - positions[tri[0]]).norm();
}

double Mesh::surfaceArea() const {
  double a = 0;
  for (std::size_t t = 0; t < triangles.size(); ++t) a += faceArea(t);
  return a;
}

void Mesh::computeNormals() {
  normals.assign(positions.size(), Vec3::Zero());
  for (std::size_t t = 0; t < triangles.size(); ++t) {
    const Triangle& tri = triangles[t];
    const Vec3 n = faceNormal(t);
    for (int c = 0; c < 3; ++c) {
      // Angle weighting (Thürmer & Wüthrich) makes the normal independent of
      // how the surface around a vertex is triangulated.
      const Vec3 e1 = positions[tri[(c + 1) % 3]] - positions[tri[c]];
      const Vec3 e2 = positions[tri[(c + 2) % 3]] - positions[tri[c]];
      const double denom = e1.norm() * e2.norm();
      if (denom <= 0) continue;
      const double angle = std::acos(std::clamp(e1.dot(e2) / denom, -1.0, 1.0));
      normals[tri[c]] += angle * n;
    }
  }
  for (Vec3& n : normals) {
    const double len = n.norm();
    n = len > 0 ? Vec3(n / len) : Vec3::Zero();
  }
}

Status Mesh::validate() const {
  const std::string where = name.empty() ? "mesh" : "mesh '" + name + "'";
  const std::size_t n = positions.size();
  auto sizeCheck = [&](std::size_t got, const char* attr) -> Status {
    if (got != 0 && got != n)
      return fail(ErrorCode::InvalidArgument,
                  std::string(attr) + " has " + std::to_string(got) + " entries for " + std::to_string(n) +
                      " vertices",
                  where, "give one per vertex or none");
    return ok();
  };
  if (auto s = sizeCheck(normals.size(), "normals"); !s) return s;
  if (auto s = sizeCheck(uvs.size(), "uvs"); !s) return s;
  if (auto s = sizeCheck(colors.size(), "colors"); !s) return s;
  for (std::size_t i = 0; i < n; ++i)
    if (!positions[i].allFinite())
      return fail(ErrorCode::InvalidArgument, "vertex " + std::to_string(i) + " has a NaN or Inf coordinate",
                  where, "fix or remove the vertex");
  for (std::size_t t = 0; t < triangles.size(); ++t)
    for (std::uint32_t v : triangles[t])
      if (v >= n)
        return fail(ErrorCode::InvalidArgument,
                    "triangle " + std::to_string(t) + " references vertex " + std::to_string(v) +
                        " but there are only " + std::to_string(n),
                    where);
  return ok();
}

void Mesh::transform(const Affine3& t) {
  for (Vec3& p : positions) p = t * p;
  // Normals transform with the inverse transpose of the linear part.
  const Mat3 nm = t.linear().inverse().transpose();
  for (Vec3& nrm : normals) {
    nrm = nm * nrm;
    const double len = nrm.norm();
    if (len > 0) nrm /= len;
  }
}

namespace {

// Appends one per-vertex attribute of `other` (see Mesh::append).
template <typename T>
void appendAttribute(std::vector<T>& into, std::size_t vertices, const std::vector<T>& from,
                     std::size_t fromVertices) {
  const bool have = vertices == 0 || into.size() == vertices;
  if (have && from.size() == fromVertices) {
    into.insert(into.end(), from.begin(), from.end());
  } else {
    into.clear();
  }
}

}  // namespace

void Mesh::append(const Mesh& other) {
  const std::size_t n = positions.size();
  const std::size_t m = other.positions.size();
  appendAttribute(normals, n, other.normals, m);
  appendAttribute(uvs, n, other.uvs, m);
  appendAttribute(colors, n, other.colors, m);
  positions.insert(positions.end(), other.positions.begin(), other.positions.end());
  const auto base = static_cast<std::uint32_t>(n);
  triangles.reserve(triangles.size() + other.triangles.size());
  for (const Triangle& t : other.triangles) triangles.push_back({t[0] + base, t[1] + base, t[2] + base});
}

}  // namespace dm
