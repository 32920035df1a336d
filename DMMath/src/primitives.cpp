// Analytic primitive meshes; see dm/math/primitives.hpp.
#include <dm/math/primitives.hpp>

#include <algorithm>
#include <cmath>
#include <map>
#include <numbers>
#include <utility>

namespace dm {

Mesh makeIcosphere(double radius, int levels) {
  const double t = (1.0 + std::sqrt(5.0)) / 2.0;
  Mesh m;
  m.name = "icosphere";
  m.positions = {{-1, t, 0},  {1, t, 0},  {-1, -t, 0}, {1, -t, 0}, {0, -1, t},  {0, 1, t},
                 {0, -1, -t}, {0, 1, -t}, {t, 0, -1},  {t, 0, 1},  {-t, 0, -1}, {-t, 0, 1}};
  m.triangles = {{0, 11, 5},  {0, 5, 1},  {0, 1, 7},  {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
                 {11, 10, 2}, {10, 7, 6}, {7, 1, 8},  {3, 9, 4},  {3, 4, 2},   {3, 2, 6}, {3, 6, 8},
                 {3, 8, 9},   {4, 9, 5},  {2, 4, 11}, {6, 2, 10}, {8, 6, 7},   {9, 8, 1}};
  levels = std::clamp(levels, 0, 8);
  for (int l = 0; l < levels; ++l) {
    std::map<std::pair<std::uint32_t, std::uint32_t>, std::uint32_t> mid;
    auto midpoint = [&](std::uint32_t a, std::uint32_t b) {
      const auto key = std::minmax(a, b);
      if (auto it = mid.find(key); it != mid.end()) return it->second;
      const auto id = static_cast<std::uint32_t>(m.positions.size());
      m.positions.push_back(0.5 * (m.positions[a] + m.positions[b]));
      mid.emplace(key, id);
      return id;
    };
    std::vector<Triangle> next;
    next.reserve(4 * m.triangles.size());
    for (const Triangle& tri : m.triangles) {
      const std::uint32_t ab = midpoint(tri[0], tri[1]), bc = midpoint(tri[1], tri[2]),
                          ca = midpoint(tri[2], tri[0]);
      next.push_back({tri[0], ab, ca});
      next.push_back({tri[1], bc, ab});
      next.push_back({tri[2], ca, bc});
      next.push_back({ab, bc, ca});
    }
    m.triangles = std::move(next);
  }
  for (Vec3& p : m.positions) p = radius * p.normalized();
  return m;
}

Mesh makeUvSphere(double radius, int rings, int segments) {
  rings = std::max(rings, 2);
  segments = std::max(segments, 3);
  Mesh m;
  m.name = "uv-sphere";
  m.positions.emplace_back(0, 0, radius);
  for (int i = 1; i < rings; ++i) {
    const double theta = std::numbers::pi * i / rings;
    for (int j = 0; j < segments; ++j) {
      const double phi = 2 * std::numbers::pi * j / segments;
      m.positions.emplace_back(radius * std::sin(theta) * std::cos(phi),
                               radius * std::sin(theta) * std::sin(phi), radius * std::cos(theta));
    }
  }
  m.positions.emplace_back(0, 0, -radius);
  const auto south = static_cast<std::uint32_t>(m.positions.size() - 1);
  auto ring = [&](int i, int j) {
    return static_cast<std::uint32_t>(1 + (i - 1) * segments + (j % segments));
  };
  for (int j = 0; j < segments; ++j) {
    m.triangles.push_back({0, ring(1, j), ring(1, j + 1)});
    m.triangles.push_back({south, ring(rings - 1, j + 1), ring(rings - 1, j)});
    for (int i = 1; i + 1 < rings; ++i) {
      m.triangles.push_back({ring(i, j), ring(i + 1, j), ring(i + 1, j + 1)});
      m.triangles.push_back({ring(i, j), ring(i + 1, j + 1), ring(i, j + 1)});
    }
  }
  return m;
}

Mesh makeTorus(double majorRadius, double minorRadius, int nu, int nv) {
  nu = std::max(nu, 3);
  nv = std::max(nv, 3);
  Mesh m;
  m.name = "torus";
  for (int i = 0; i < nu; ++i)
    for (int j = 0; j < nv; ++j) {
      const double u = 2 * std::numbers::pi * i / nu, v = 2 * std::numbers::pi * j / nv;
      const double rho = majorRadius + minorRadius * std::cos(v);
      m.positions.emplace_back(rho * std::cos(u), rho * std::sin(u), minorRadius * std::sin(v));
    }
  auto id = [&](int i, int j) { return static_cast<std::uint32_t>((i % nu) * nv + (j % nv)); };
  // dP/du x dP/dv points away from the tube's centre line, so
  // (i, j) -> (i+1, j) -> (i+1, j+1) is counter-clockwise from outside.
  for (int i = 0; i < nu; ++i)
    for (int j = 0; j < nv; ++j) {
      m.triangles.push_back({id(i, j), id(i + 1, j), id(i + 1, j + 1)});
      m.triangles.push_back({id(i, j), id(i + 1, j + 1), id(i, j + 1)});
    }
  return m;
}

Mesh makeBox(const Vec3& h) {
  Mesh m;
  m.name = "box";
  for (int i = 0; i < 8; ++i)
    m.positions.emplace_back(i & 1 ? h.x() : -h.x(), i & 2 ? h.y() : -h.y(), i & 4 ? h.z() : -h.z());
  m.triangles = {{0, 2, 1}, {1, 2, 3}, {4, 5, 6}, {5, 7, 6}, {0, 1, 4}, {1, 5, 4},
                 {2, 6, 3}, {3, 6, 7}, {0, 4, 2}, {2, 4, 6}, {1, 3, 5}, {3, 7, 5}};
  return m;
}

Mesh makeCylinder(double radius, double height, int segments) {
  segments = std::clamp(segments, 3, 65536);
  const auto n = static_cast<std::uint32_t>(segments);
  const double zt = 0.5 * height, zb = -0.5 * height;
  Mesh m;
  m.name = "cylinder";
  m.positions.reserve(4 * n + 2);
  m.normals.reserve(4 * n + 2);
  // Layout: [0] top centre, [1, n] top cap rim, [n+1] bottom centre,
  // [n+2, 2n+1] bottom cap rim, [2n+2, 3n+1] side bottom rim, [3n+2, 4n+1] side top rim.
  auto addRing = [&](double z, bool side, const Vec3& capNormal) {
    for (std::uint32_t j = 0; j < n; ++j) {
      const double phi = 2 * std::numbers::pi * j / n;
      const double c = std::cos(phi), s = std::sin(phi);
      m.positions.emplace_back(radius * c, radius * s, z);
      m.normals.push_back(side ? Vec3(c, s, 0) : capNormal);
    }
  };
  m.positions.emplace_back(0, 0, zt);
  m.normals.emplace_back(0, 0, 1);
  addRing(zt, false, Vec3::UnitZ());
  m.positions.emplace_back(0, 0, zb);
  m.normals.emplace_back(0, 0, -1);
  addRing(zb, false, -Vec3::UnitZ());
  addRing(zb, true, Vec3::Zero());
  addRing(zt, true, Vec3::Zero());
  const std::uint32_t topC = 0, topR = 1, botC = n + 1, botR = n + 2, sideB = 2 * n + 2, sideT = 3 * n + 2;
  m.triangles.reserve(4 * n);
  for (std::uint32_t j = 0; j < n; ++j) {
    const std::uint32_t k = (j + 1) % n;
    // φ increases counter-clockwise seen from +z: the top fan is CCW from
    // above, the bottom fan is reversed, and on the side (∂P/∂φ) × (∂P/∂z)
    // points outward.
    m.triangles.push_back({topC, topR + j, topR + k});
    m.triangles.push_back({botC, botR + k, botR + j});
    m.triangles.push_back({sideB + j, sideB + k, sideT + k});
    m.triangles.push_back({sideB + j, sideT + k, sideT + j});
  }
  return m;
}

Mesh makeCapsule(double radius, double height, int segments, int rings) {
  segments = std::clamp(segments, 3, 4096);
  rings = std::clamp(rings, 1, 2048);
  height = std::max(height, 0.0);
  const auto n = static_cast<std::uint32_t>(segments);
  const auto nr = static_cast<std::uint32_t>(rings);
  const bool shaft = height > 0;
  Mesh m;
  m.name = "capsule";
  // Every vertex is centre + radius · normal, with the centre the nearest
  // point of the axis segment, so positions and normals are exact.
  auto add = [&](const Vec3& centre, const Vec3& normal) {
    m.positions.push_back(centre + radius * normal);
    m.normals.push_back(normal);
  };
  auto addRing = [&](double theta, double zc) {
    for (std::uint32_t j = 0; j < n; ++j) {
      const double phi = 2 * std::numbers::pi * j / n;
      add(Vec3(0, 0, zc),
          Vec3(std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi), std::cos(theta)));
    }
  };
  const double zt = 0.5 * height, zb = -0.5 * height;
  // Rings from the north pole down: nr on the upper hemisphere (the last is
  // its equator), then the lower equator when there is a shaft, then the
  // remaining nr − 1 rings of the lower hemisphere.
  add(Vec3(0, 0, zt), Vec3::UnitZ());
  for (std::uint32_t i = 1; i <= nr; ++i) addRing(0.5 * std::numbers::pi * i / nr, zt);
  if (shaft) addRing(0.5 * std::numbers::pi, zb);
  for (std::uint32_t i = nr + 1; i < 2 * nr; ++i) addRing(0.5 * std::numbers::pi * i / nr, zb);
  add(Vec3(0, 0, zb), -Vec3::UnitZ());
  const std::uint32_t ringCount = shaft ? 2 * nr : 2 * nr - 1;
  const auto south = static_cast<std::uint32_t>(m.positions.size() - 1);
  auto ring = [&](std::uint32_t i, std::uint32_t j) { return 1 + i * n + (j % n); };
  m.triangles.reserve(2 * n * ringCount);
  for (std::uint32_t j = 0; j < n; ++j) {
    // Same winding as makeUvSphere: CCW from outside.
    m.triangles.push_back({0, ring(0, j), ring(0, j + 1)});
    m.triangles.push_back({south, ring(ringCount - 1, j + 1), ring(ringCount - 1, j)});
    for (std::uint32_t i = 0; i + 1 < ringCount; ++i) {
      m.triangles.push_back({ring(i, j), ring(i + 1, j), ring(i + 1, j + 1)});
      m.triangles.push_back({ring(i, j), ring(i + 1, j + 1), ring(i, j + 1)});
    }
  }
  return m;
}

Mesh makePlane(double halfX, double halfY, int divisions) {
  divisions = std::clamp(divisions, 1, 4096);
  const auto d = static_cast<std::uint32_t>(divisions);
  Mesh m;
  m.name = "plane";
  const std::size_t count = static_cast<std::size_t>(d + 1) * (d + 1);
  m.positions.reserve(count);
  m.uvs.reserve(count);
  // Row r runs along +x at y = halfY − 2·halfY·r/d: row 0 is the +y edge (v = 0).
  for (std::uint32_t r = 0; r <= d; ++r)
    for (std::uint32_t c = 0; c <= d; ++c) {
      const double u = static_cast<double>(c) / d, v = static_cast<double>(r) / d;
      m.positions.emplace_back(halfX * (2 * u - 1), halfY * (1 - 2 * v), 0.0);
      m.uvs.emplace_back(static_cast<float>(u), static_cast<float>(v));
    }
  m.normals.assign(count, Vec3::UnitZ());
  auto id = [&](std::uint32_t r, std::uint32_t c) { return r * (d + 1) + c; };
  m.triangles.reserve(2 * static_cast<std::size_t>(d) * d);
  for (std::uint32_t r = 0; r < d; ++r)
    for (std::uint32_t c = 0; c < d; ++c) {
      // Bottom-left, bottom-right, top-right (and top-left): CCW seen from +z.
      const std::uint32_t tl = id(r, c), tr = id(r, c + 1), bl = id(r + 1, c), br = id(r + 1, c + 1);
      m.triangles.push_back({bl, br, tr});
      m.triangles.push_back({bl, tr, tl});
    }
  return m;
}

}  // namespace dm
