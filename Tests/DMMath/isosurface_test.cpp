#include <dm/math/isosurface.hpp>
#include <dm/math/mesh_topology.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <map>
#include <numbers>
#include <random>
#include <string>
#include <utility>
#include <vector>

namespace {

using dm::IsoMethod;
using dm::Vec3;

constexpr IsoMethod kMethods[] = {IsoMethod::MarchingCubes, IsoMethod::MarchingTetrahedra};
const char* name(IsoMethod m) { return m == IsoMethod::MarchingCubes ? "MC" : "MT"; }

/// A volume whose voxel (i, j, k) holds f(indexToWorld · (i, j, k)).
dm::Volume sampled(const dm::Vec3i& dims, dm::VoxelType type, const dm::Affine3& a,
                   const std::function<double(const Vec3&)>& f) {
  auto v = dm::Volume::create(dims, type, a);
  EXPECT_TRUE(v);
  for (int k = 0; k < dims.z(); ++k)
    for (int j = 0; j < dims.y(); ++j)
      for (int i = 0; i < dims.x(); ++i) v->setValue(i, j, k, f(a * Vec3(i, j, k)));
  return std::move(*v);
}

/// Axis-aligned grid of spacing h covering [lo, hi] (metres).
dm::Affine3 gridAffine(const Vec3& lo, double h) {
  dm::Affine3 a = dm::Affine3::Identity();
  a.linear() = h * dm::Mat3::Identity();
  a.translation() = lo;
  return a;
}

dm::Vec3i gridDims(const Vec3& lo, const Vec3& hi, double h) {
  const Vec3 n = ((hi - lo) / h).array().ceil() + 1;
  return {static_cast<int>(n.x()), static_cast<int>(n.y()), static_cast<int>(n.z())};
}

dm::Mesh extract(const dm::Volume& v, double iso, IsoMethod m, bool closeBorders = false, int threads = 0) {
  auto r =
      dm::extractIsosurface(v, {.iso = iso, .method = m, .closeBorders = closeBorders, .threads = threads});
  EXPECT_TRUE(r) << (r ? "" : r.error().message());
  if (!r) return {};
  EXPECT_TRUE(r->validate());
  return std::move(*r);
}

/// A closed, consistently oriented 2-manifold with the given Euler
/// characteristic and number of pieces, enclosing a positive volume.
void expectClosedSurface(const dm::Mesh& m, long long euler, std::size_t components,
                         const std::string& what) {
  const dm::MeshTopology t = dm::analyzeTopology(m);
  EXPECT_TRUE(t.isClosed) << what << ": " << t.boundaryEdges << " boundary edges";
  EXPECT_TRUE(t.isManifold) << what << ": " << t.nonManifoldEdges << " non-manifold edges, "
                            << t.nonManifoldVertices << " non-manifold vertices";
  EXPECT_TRUE(t.isOrientedConsistently) << what << ": " << t.misorientedEdges << " misoriented edges";
  EXPECT_EQ(t.unreferencedVertices, 0u) << what;
  EXPECT_EQ(t.eulerCharacteristic, euler) << what;
  EXPECT_EQ(t.components, components) << what;
  ASSERT_TRUE(t.volume) << what;
  EXPECT_GT(*t.volume, 0) << what << ": triangles face inward";
}

// ---------------------------------------------------------------------------
// Sphere: f = R − |x − c| (positive inside), exact in double voxels.

struct SphereCase {
  double R = 0.04;
  Vec3 c{0.0513, 0.0497, 0.0502};  // off the grid's symmetry planes
  double f(const Vec3& x) const { return R - (x - c).norm(); }
};

TEST(Isosurface, SphereIsClosedOrientedAndConvergesToTheTrueSurface) {
  const SphereCase s;
  const double ball = 4.0 / 3.0 * std::numbers::pi * s.R * s.R * s.R;
  for (IsoMethod m : kMethods) {
    double previousError = 1;
    for (int level = 0; level < 3; ++level) {
      const double h = s.R / (4 << level);
      const Vec3 lo = s.c.array() - 1.3 * s.R, hi = s.c.array() + 1.3 * s.R;
      const dm::Volume v = sampled(gridDims(lo, hi, h), dm::VoxelType::F64, gridAffine(lo, h),
                                   [&](const Vec3& x) { return s.f(x); });
      const dm::Mesh mesh = extract(v, 0.0, m);
      const std::string what = std::string(name(m)) + " h=R/" + std::to_string(4 << level);
      expectClosedSurface(mesh, 2, 1, what);

      // Vertices are roots of the linear interpolant of a concave f along an
      // edge of length L: f >= 0 there, and f <= L²·max|f''|/8 with
      // |f''| <= 1/(R − L) on the edge (the distance to c is >= R − L) —
      // except that a root within L/65536 of a voxel is held L/65536 from it
      // (so no two vertices share a position), which changes f (|∇f| = 1)
      // by at most L/65536. (A root exactly on a voxel would go L/256 in; no
      // node of this grid lies on the sphere.)
      const double L = m == IsoMethod::MarchingCubes ? h : std::sqrt(3.0) * h;
      const double margin = L / 65536;
      const double bound = L * L / (8 * (s.R - L));
      double worst = 0;
      for (const Vec3& p : mesh.positions) {
        EXPECT_GE(s.f(p), -margin - 1e-15) << what;
        worst = std::max(worst, s.f(p));
      }
      EXPECT_LE(worst, bound + margin) << what;

      // The inscribed polyhedron's volume error shrinks like h².
      const auto t = dm::analyzeTopology(mesh);
      const double error = (ball - *t.volume) / ball;
      EXPECT_GT(error, 0) << what << ": vertices inside a convex ball enclose less";
      EXPECT_LT(error, 0.05) << what;
      if (level > 0) {
        EXPECT_LT(error, previousError / 3) << what << ": not converging at second order";
      }
      previousError = error;
      ASSERT_TRUE(t.centroid);
      EXPECT_LT((*t.centroid - s.c).norm(), 0.01 * h) << what;

      // Gradient normals against the analytic outward normal.
      ASSERT_EQ(mesh.normals.size(), mesh.positions.size());
      double worstDot = 1;
      for (std::size_t i = 0; i < mesh.positions.size(); ++i)
        worstDot = std::min(worstDot, mesh.normals[i].dot((mesh.positions[i] - s.c).normalized()));
      EXPECT_GT(worstDot, 0.99) << what;
    }
  }
}

TEST(Isosurface, SingleInsideVoxelGivesTheExactCellStar) {
  // One voxel at 1 in zeros, iso 0.5: every vertex is at the middle of an edge
  // from that voxel. MC cuts off one corner in each of its 8 cells: an
  // octahedron of volume 4/3·(h/2)³. MT cuts off the voxel's corner in each of
  // the 24 Kuhn tetrahedra around it (6 in the two cells where it is corner 0
  // or 7, 2 in the other six), each 1/8 of a tetrahedron of volume h³/6.
  const double h = 0.002;
  auto v = dm::Volume::create({5, 5, 5}, dm::VoxelType::F32, gridAffine(Vec3(0.1, -0.2, 0.3), h));
  ASSERT_TRUE(v);
  v->setValue(2, 2, 2, 1.0);
  for (IsoMethod m : kMethods) {
    const dm::Mesh mesh = extract(*v, 0.5, m);
    const auto t = dm::analyzeTopology(mesh);
    const bool mc = m == IsoMethod::MarchingCubes;
    EXPECT_EQ(mesh.triangleCount(), mc ? 8u : 24u) << name(m);
    EXPECT_EQ(mesh.vertexCount(), mc ? 6u : 14u) << name(m);  // MT adds 8 diagonals through the voxel
    expectClosedSurface(mesh, 2, 1, name(m));
    ASSERT_TRUE(t.volume);
    const double expected = mc ? 4.0 / 3.0 * std::pow(h / 2, 3) : 24 * (h * h * h / 6) / 8;
    EXPECT_NEAR(*t.volume, expected, 1e-12 * expected) << name(m);
    ASSERT_TRUE(t.centroid);
    EXPECT_LT((*t.centroid - (Vec3(0.1, -0.2, 0.3) + Vec3::Constant(2 * h))).norm(), 1e-12) << name(m);
  }
}

TEST(Isosurface, InsideIsStrictlyAboveIso) {
  auto v = dm::Volume::create({3, 3, 3}, dm::VoxelType::U8);
  ASSERT_TRUE(v);
  v->setValue(1, 1, 1, 5);
  for (IsoMethod m : kMethods) {
    EXPECT_TRUE(extract(*v, 5.0, m).empty()) << name(m) << ": a voxel equal to iso is outside";
    EXPECT_FALSE(extract(*v, 4.999, m).empty()) << name(m);
    EXPECT_FALSE(extract(*v, 4.0, m).empty()) << name(m);
    EXPECT_TRUE(extract(*v, 300.0, m).empty()) << name(m) << ": iso above the type's range";
    // Below the type's range everything is inside and the grid has no surface
    // until the borders are closed.
    EXPECT_TRUE(extract(*v, -1e9, m).empty()) << name(m);
    expectClosedSurface(extract(*v, -1e9, m, true), 2, 1, name(m));
  }
}

TEST(Isosurface, TorusHasEulerCharacteristicZero) {
  const double Rt = 0.03, r = 0.012, h = r / 4;
  const auto f = [&](const Vec3& x) { return r - std::hypot(std::hypot(x.x(), x.y()) - Rt, x.z()); };
  const Vec3 hi(Rt + r + 2 * h, Rt + r + 2 * h, r + 2 * h);
  const dm::Volume v = sampled(gridDims(-hi, hi, h), dm::VoxelType::F64, gridAffine(-hi, h), f);
  for (IsoMethod m : kMethods) {
    const dm::Mesh mesh = extract(v, 0.0, m);
    expectClosedSurface(mesh, 0, 1, name(m));
    const auto t = dm::analyzeTopology(mesh);
    ASSERT_TRUE(t.genus);
    EXPECT_EQ(*t.genus, 1);
    const double exact = 2 * std::numbers::pi * std::numbers::pi * Rt * r * r;
    EXPECT_NEAR(*t.volume, exact, 0.03 * exact) << name(m);
  }
}

TEST(Isosurface, TwoSpheresAreTwoComponents) {
  const Vec3 a(0.02, 0.025, 0.025), b(0.055, 0.025, 0.025);
  const auto f = [&](const Vec3& x) { return std::max(0.012 - (x - a).norm(), 0.015 - (x - b).norm()); };
  const dm::Volume v = sampled({39, 26, 26}, dm::VoxelType::F32, gridAffine(Vec3::Zero(), 0.002), f);
  for (IsoMethod m : kMethods) {
    const dm::Mesh mesh = extract(v, 0.0, m);
    expectClosedSurface(mesh, 4, 2, name(m));
    const auto t = dm::analyzeTopology(mesh);
    const double exact = 4.0 / 3.0 * std::numbers::pi * (std::pow(0.012, 3) + std::pow(0.015, 3));
    EXPECT_NEAR(*t.volume, exact, 0.03 * exact) << name(m);
  }
}

// ---------------------------------------------------------------------------
// Watertightness where every cell is ambiguous-prone: random noise.

/// Undirected edges used by exactly one triangle.
std::vector<std::pair<std::uint32_t, std::uint32_t>> boundaryEdges(const dm::Mesh& m) {
  std::map<std::pair<std::uint32_t, std::uint32_t>, int> count;
  for (const auto& t : m.triangles)
    for (int c = 0; c < 3; ++c) {
      const std::uint32_t a = t[static_cast<std::size_t>(c)], b = t[static_cast<std::size_t>((c + 1) % 3)];
      ++count[{std::min(a, b), std::max(a, b)}];
    }
  std::vector<std::pair<std::uint32_t, std::uint32_t>> out;
  for (const auto& [e, n] : count)
    if (n == 1) out.push_back(e);
  return out;
}

TEST(Isosurface, RandomNoiseIsManifoldAndOpenOnlyAtTheBorder) {
  const dm::Vec3i dims(17, 19, 23);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  auto v = dm::Volume::create(dims, dm::VoxelType::F64);  // identity affine: positions are indices
  ASSERT_TRUE(v);
  for (std::size_t n = 0; n < v->voxelCount(); ++n) v->setValueAt(n, u(rng));
  for (IsoMethod m : kMethods) {
    const dm::Mesh open = extract(*v, 0.5, m);
    const auto t = dm::analyzeTopology(open);
    EXPECT_GT(open.triangleCount(), 5000u);
    EXPECT_EQ(t.nonManifoldEdges, 0u) << name(m);
    EXPECT_EQ(t.nonManifoldVertices, 0u) << name(m);
    EXPECT_TRUE(t.isOrientedConsistently) << name(m);
    EXPECT_GT(t.boundaryEdges, 0u) << name(m);
    // Every boundary edge runs along one of the six border planes.
    for (const auto& [a, b] : boundaryEdges(open)) {
      const Vec3 &p = open.positions[a], &q = open.positions[b];
      bool onBorder = false;
      for (int ax = 0; ax < 3; ++ax) {
        const double far = dims[ax] - 1;
        onBorder = onBorder || (p[ax] == 0 && q[ax] == 0) || (p[ax] == far && q[ax] == far);
      }
      EXPECT_TRUE(onBorder) << name(m) << ": boundary edge inside the grid from " << p.transpose() << " to "
                            << q.transpose();
    }

    const dm::Mesh closed = extract(*v, 0.5, m, true);
    const auto tc = dm::analyzeTopology(closed);
    EXPECT_TRUE(tc.isClosed) << name(m) << ": " << tc.boundaryEdges << " boundary edges";
    EXPECT_TRUE(tc.isManifold) << name(m);
    EXPECT_TRUE(tc.isOrientedConsistently) << name(m);
    ASSERT_TRUE(tc.volume);
    // About half the voxels are inside; the surface encloses about half the box.
    const double box = (dims.x() - 1) * (dims.y() - 1) * (dims.z() - 1);
    EXPECT_GT(*tc.volume, 0.3 * box) << name(m);
    EXPECT_LT(*tc.volume, 0.7 * box) << name(m);
  }
}

/// Twice the smallest triangle area of `m` (m²).
double smallestDoubleArea(const dm::Mesh& m) {
  double a = std::numeric_limits<double>::infinity();
  for (const auto& t : m.triangles) {
    const Vec3& p = m.positions[t[0]];
    a = std::min(a, (m.positions[t[1]] - p).cross(m.positions[t[2]] - p).norm());
  }
  return a;
}

/// `m` as an STL file holds it: three corners per triangle, no indices.
dm::Mesh triangleSoup(const dm::Mesh& m) {
  dm::Mesh soup;
  for (const auto& t : m.triangles) {
    const auto base = static_cast<std::uint32_t>(soup.positions.size());
    for (int c = 0; c < 3; ++c) soup.positions.push_back(m.positions[t[static_cast<std::size_t>(c)]]);
    soup.triangles.push_back({base, base + 1, base + 2});
  }
  return soup;
}

TEST(Isosurface, IntegerDataAtIntegerIsoIsWatertightByPosition) {
  // Property test: integer voxels, many of them equal to an integer iso (what
  // people type for uint8 MRI). Every vertex must have a position of its own
  // and every triangle a positive area, so that rebuilding the connectivity
  // from positions alone (an STL file read back) gives the same closed,
  // manifold, consistently oriented surface.
  std::mt19937 rng(11);
  int cases = 0;
  for (int trial = 0; trial < 24; ++trial) {
    const int hi = 1 + trial % 4;  // values 0..hi
    std::uniform_int_distribution<int> u(0, hi);
    std::uniform_int_distribution<int> size(3, 13);
    auto v = dm::Volume::create({size(rng), size(rng), size(rng)}, dm::VoxelType::U8);
    ASSERT_TRUE(v);
    for (std::size_t n = 0; n < v->voxelCount(); ++n) v->setValueAt(n, u(rng));
    for (int iso = 0; iso < hi; ++iso)
      for (IsoMethod m : kMethods) {
        const std::string what =
            std::string(name(m)) + " trial " + std::to_string(trial) + " iso " + std::to_string(iso);
        const dm::Mesh mesh = extract(*v, iso, m, true);
        if (mesh.empty()) continue;
        ++cases;
        const auto t = dm::analyzeTopology(mesh);
        EXPECT_TRUE(t.isClosed && t.isManifold && t.isOrientedConsistently)
            << what << ": " << t.boundaryEdges << " boundary, " << t.nonManifoldEdges
            << " non-manifold edges, " << t.nonManifoldVertices << " non-manifold vertices, "
            << t.misorientedEdges << " misoriented";
        EXPECT_EQ(t.degenerateTriangles, 0u) << what;
        EXPECT_GT(smallestDoubleArea(mesh), 0.0) << what << ": a zero-area triangle";

        dm::Mesh welded = triangleSoup(mesh);
        auto w = dm::weldVertices(welded, 0.0);
        ASSERT_TRUE(w) << what;
        EXPECT_EQ(welded.positions.size(), mesh.positions.size()) << what << ": vertices share a position";
        EXPECT_EQ(w->trianglesRemoved, 0u) << what;
        const auto tw = dm::analyzeTopology(welded);
        EXPECT_TRUE(tw.isClosed && tw.isManifold && tw.isOrientedConsistently)
            << what << " rebuilt from positions: " << tw.nonManifoldEdges << " non-manifold edges, "
            << tw.nonManifoldVertices << " non-manifold vertices, " << tw.misorientedEdges << " misoriented";
        EXPECT_EQ(tw.eulerCharacteristic, t.eulerCharacteristic) << what;
      }
  }
  EXPECT_GT(cases, 60);
}

TEST(Isosurface, VerticesKeepOffTheVoxelsByTheEdgeMargin) {
  // Two voxels, 40 (outside at iso 40) and 41: the crossing is on the outside
  // voxel itself; the vertex is placed 1/256 of the edge into it (from either
  // end). A root merely close to a voxel stays where it is down to 1/65536 of
  // the edge, and is held there below that. Elsewhere the linear
  // interpolation is exact.
  auto v = dm::Volume::create({2, 1, 1}, dm::VoxelType::F32);
  ASSERT_TRUE(v);
  const auto vertexX = [&](double a, double b, double iso) {
    v->setValue(0, 0, 0, a);
    v->setValue(1, 0, 0, b);
    const dm::Mesh mesh = extract(*v, iso, IsoMethod::MarchingCubes, true);
    double x = -1;
    for (const Vec3& p : mesh.positions)
      if (p.y() == 0 && p.z() == 0 && p.x() > 0 && p.x() < 1) x = p.x();  // the one on the real edge
    return x;
  };
  EXPECT_DOUBLE_EQ(vertexX(40, 41, 40), 1.0 / 256.0);
  EXPECT_DOUBLE_EQ(vertexX(41, 40, 40), 1.0 - 1.0 / 256.0);
  EXPECT_DOUBLE_EQ(vertexX(0, 100, 99.9), 0.999);
  EXPECT_DOUBLE_EQ(vertexX(0, 100, 25), 0.25);
  EXPECT_DOUBLE_EQ(vertexX(0, 100, 0.2), 0.002);
  EXPECT_DOUBLE_EQ(vertexX(0, 1, 1e-7), 1.0 / 65536.0);
  EXPECT_DOUBLE_EQ(vertexX(1, 0, 1e-7), 1.0 - 1.0 / 65536.0);
}

TEST(Isosurface, EveryPairOfNeighbouringCellCasesIsWatertight) {
  // All 2^12 inside/outside patterns of two cells sharing a face, along each
  // axis: every pair of cube cases meets on every face orientation. With the
  // borders closed the surface must be a closed oriented manifold (some
  // patterns have a tunnel, so pieces need not be spheres).
  for (int axis = 0; axis < 3; ++axis) {
    dm::Vec3i dims(2, 2, 2);
    dims[axis] = 3;
    auto v = dm::Volume::create(dims, dm::VoxelType::U8);
    ASSERT_TRUE(v);
    for (IsoMethod m : kMethods) {
      int failures = 0;
      for (int pattern = 1; pattern < 4096 && failures < 5; ++pattern) {
        for (std::size_t n = 0; n < 12; ++n) v->setValueAt(n, (pattern >> n) & 1);
        const auto r =
            dm::extractIsosurface(*v, {.iso = 0.5, .method = m, .closeBorders = true, .threads = 1});
        ASSERT_TRUE(r);
        const auto t = dm::analyzeTopology(*r);
        // A closed orientable surface has χ = 2·(components − genus).
        const long long chi = t.eulerCharacteristic;
        const bool good = t.isClosed && t.isManifold && t.isOrientedConsistently && t.volume &&
                          *t.volume > 0 && chi % 2 == 0 && chi <= 2 * static_cast<long long>(t.components);
        if (!good) ++failures;
        EXPECT_TRUE(good) << name(m) << " axis " << axis << " pattern " << pattern << ": boundary "
                          << t.boundaryEdges << ", non-manifold " << t.nonManifoldEdges << "/"
                          << t.nonManifoldVertices << ", misoriented " << t.misorientedEdges << ", χ "
                          << t.eulerCharacteristic << ", components " << t.components;
      }
    }
  }
}

// ---------------------------------------------------------------------------
// Placement in the world.

TEST(Isosurface, MirroredAffineKeepsTrianglesCounterClockwiseFromOutside) {
  const SphereCase s;
  const double h = s.R / 6;
  dm::Affine3 a = gridAffine(s.c + Vec3(1.3 * s.R, -1.3 * s.R, -1.3 * s.R), h);
  a.linear()(0, 0) = -h;  // i runs toward −x: a left-handed index frame
  ASSERT_LT(a.linear().determinant(), 0);
  const dm::Volume v = sampled({17, 17, 17}, dm::VoxelType::F64, a, [&](const Vec3& x) { return s.f(x); });
  for (IsoMethod m : kMethods) {
    const dm::Mesh mesh = extract(v, 0.0, m);
    expectClosedSurface(mesh, 2, 1, name(m));
    // Face normals (from the winding) and vertex normals both point away from c.
    for (std::size_t t = 0; t < mesh.triangleCount(); ++t) {
      const auto& tri = mesh.triangles[t];
      const Vec3 centre = (mesh.positions[tri[0]] + mesh.positions[tri[1]] + mesh.positions[tri[2]]) / 3;
      EXPECT_GT(mesh.faceNormal(t).dot(centre - s.c), 0) << name(m) << " triangle " << t;
    }
    for (std::size_t i = 0; i < mesh.vertexCount(); ++i)
      EXPECT_GT(mesh.normals[i].dot((mesh.positions[i] - s.c).normalized()), 0.98) << name(m);
  }
}

TEST(Isosurface, ObliqueAffinePlacesTheSurfaceInTheWorld) {
  // Anisotropic, sheared, rotated, translated voxel grid sampling a world sphere.
  const SphereCase s;
  dm::Mat3 shear = dm::Mat3::Identity();
  shear(0, 1) = 0.3;
  shear(1, 2) = -0.2;
  const dm::Mat3 linear = dm::AngleAxis(0.6, Vec3(1, -2, 0.5).normalized()).toRotationMatrix() * shear *
                          Vec3(0.004, 0.005, 0.0035).asDiagonal();
  dm::Affine3 a = dm::Affine3::Identity();
  a.linear() = linear;
  const dm::Vec3i dims(40, 40, 40);
  a.translation() = s.c - linear * Vec3(19.5, 19.5, 19.5);  // grid centred on the sphere
  const dm::Volume v = sampled(dims, dm::VoxelType::F64, a, [&](const Vec3& x) { return s.f(x); });
  for (IsoMethod m : kMethods) {
    const dm::Mesh mesh = extract(v, 0.0, m);
    expectClosedSurface(mesh, 2, 1, name(m));
    double L = 0;  // longest world edge the method cuts
    for (const auto& step : {Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(0, 0, 1), Vec3(1, 1, 0), Vec3(1, 0, 1),
                             Vec3(0, 1, 1), Vec3(1, 1, 1)}) {
      if (m == IsoMethod::MarchingCubes && step.sum() > 1) continue;
      L = std::max(L, (linear * step).norm());
    }
    for (const Vec3& p : mesh.positions) {  // as in the axis-aligned case, with the floor L/65536
      EXPECT_GE(s.f(p), -L / 65536 - 1e-15) << name(m);
      EXPECT_LE(s.f(p), L * L / (8 * (s.R - L)) + L / 65536) << name(m);
    }
    const auto t = dm::analyzeTopology(mesh);
    ASSERT_TRUE(t.centroid);
    EXPECT_LT((*t.centroid - s.c).norm(), 0.01 * L) << name(m);
    const double ball = 4.0 / 3.0 * std::numbers::pi * std::pow(s.R, 3);
    EXPECT_NEAR(*t.volume, ball, 0.03 * ball) << name(m);
    for (std::size_t i = 0; i < mesh.vertexCount(); ++i)
      EXPECT_GT(mesh.normals[i].dot((mesh.positions[i] - s.c).normalized()), 0.99) << name(m);
  }
}

TEST(Isosurface, BorderIsOpenUnlessClosed) {
  // A sphere cut by the grid's x = 0 plane.
  const double R = 0.02, h = 0.002;
  const Vec3 c(0.005, 0.025, 0.025);
  const dm::Volume v = sampled({26, 26, 26}, dm::VoxelType::F32, gridAffine(Vec3::Zero(), h),
                               [&](const Vec3& x) { return R - (x - c).norm(); });
  for (IsoMethod m : kMethods) {
    const auto open = dm::analyzeTopology(extract(v, 0.0, m));
    EXPECT_FALSE(open.isClosed) << name(m);
    EXPECT_GT(open.boundaryEdges, 0u) << name(m);
    EXPECT_TRUE(open.isManifold) << name(m);
    EXPECT_FALSE(open.volume) << name(m);

    const dm::Mesh closed = extract(v, 0.0, m, true);
    expectClosedSurface(closed, 2, 1, name(m));
    // The cap is half a voxel outside the grid, facing −x.
    std::size_t capVertices = 0;
    for (std::size_t i = 0; i < closed.vertexCount(); ++i) {
      EXPECT_GE(closed.positions[i].x(), -0.5 * h - 1e-15) << name(m);
      if (closed.positions[i].x() == -0.5 * h) {
        ++capVertices;
        EXPECT_NEAR(closed.normals[i].x(), -1.0, 1e-12) << name(m);
      }
    }
    EXPECT_GT(capVertices, 20u) << name(m);
  }
}

// ---------------------------------------------------------------------------
// Voxel types, threads, errors.

TEST(Isosurface, EveryVoxelTypeGivesTheSameClosedSurface) {
  // The sphere's f (m) scaled and offset into each type's range; the rounding
  // to integers moves the surface by at most 1 / scale.
  struct Encoding {
    dm::VoxelType type;
    double offset, scale;
  };
  const Encoding encodings[] = {{dm::VoxelType::U8, 100, 1e3},   {dm::VoxelType::I8, 0, 1e3},
                                {dm::VoxelType::U16, 1000, 1e4}, {dm::VoxelType::I16, 0, 1e4},
                                {dm::VoxelType::U32, 1e5, 1e6},  {dm::VoxelType::I32, -1e5, 1e6},
                                {dm::VoxelType::F32, 0, 1},      {dm::VoxelType::F64, 0, 1}};
  const SphereCase s;
  const double h = s.R / 6;
  const Vec3 lo = s.c.array() - 1.3 * s.R;
  const auto dims = gridDims(lo, s.c.array() + 1.3 * s.R, h);
  for (const Encoding& e : encodings) {
    const dm::Volume v =
        sampled(dims, e.type, gridAffine(lo, h), [&](const Vec3& x) { return e.offset + e.scale * s.f(x); });
    const bool integer = e.type != dm::VoxelType::F32 && e.type != dm::VoxelType::F64;
    const double iso = e.offset + (integer ? 0.5 : 0.0);
    for (IsoMethod m : kMethods) {
      const std::string what = std::string(dm::toString(e.type)) + " " + name(m);
      const dm::Mesh mesh = extract(v, iso, m);
      expectClosedSurface(mesh, 2, 1, what);
      for (const Vec3& p : mesh.positions) EXPECT_LT(std::abs(s.f(p)), 0.5 * h) << what;
    }
  }
}

TEST(Isosurface, OutputDoesNotDependOnThreadCount) {
  // A noisy blob big enough to be split into several slabs.
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-0.3, 0.3);
  auto v = dm::Volume::create({41, 45, 50}, dm::VoxelType::F32, gridAffine(Vec3(0.01, 0.02, 0.03), 0.001));
  ASSERT_TRUE(v);
  for (int k = 0; k < 50; ++k)
    for (int j = 0; j < 45; ++j)
      for (int i = 0; i < 41; ++i)
        v->setValue(i, j, k, 18.0 - Vec3(i - 20, j - 22, k - 25).norm() + 3 * u(rng));
  for (IsoMethod m : kMethods)
    for (bool close : {false, true}) {
      const dm::Mesh one = extract(*v, 0.0, m, close, 1);
      ASSERT_GT(one.triangleCount(), 10000u);
      for (int threads : {2, 3, 8}) {
        const dm::Mesh many = extract(*v, 0.0, m, close, threads);
        EXPECT_TRUE(many.positions == one.positions) << name(m) << " threads " << threads;
        EXPECT_TRUE(many.normals == one.normals) << name(m) << " threads " << threads;
        EXPECT_TRUE(many.triangles == one.triangles) << name(m) << " threads " << threads;
      }
    }
}

TEST(Isosurface, RejectsBadInputWithAMessage) {
  const dm::Volume empty;
  auto r = dm::extractIsosurface(empty, {});
  ASSERT_FALSE(r);
  EXPECT_EQ(r.error().code, dm::ErrorCode::InvalidArgument);
  EXPECT_NE(r.error().what.find("empty"), std::string::npos);

  auto v = dm::Volume::create({8, 8, 8}, dm::VoxelType::F32);
  ASSERT_TRUE(v);
  v->setValue(3, 4, 4, 1.0);
  v->setValue(4, 4, 4, 1.0);
  r = dm::extractIsosurface(*v, {.iso = std::nan("")});
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().what.find("iso"), std::string::npos);
  EXPECT_FALSE(dm::extractIsosurface(*v, {.iso = INFINITY}));
  EXPECT_FALSE(dm::extractIsosurface(*v, {.iso = 0.5, .threads = -1}));

  // The cap is exclusive of the count itself.
  auto full = dm::extractIsosurface(*v, {.iso = 0.5});
  ASSERT_TRUE(full);
  const std::size_t n = full->triangleCount();
  ASSERT_GT(n, 0u);
  r = dm::extractIsosurface(*v, {.iso = 0.5, .maxTriangles = n - 1});
  ASSERT_FALSE(r);
  EXPECT_EQ(r.error().code, dm::ErrorCode::Unsupported);
  EXPECT_NE(r.error().what.find("maxTriangles"), std::string::npos);
  EXPECT_TRUE(dm::extractIsosurface(*v, {.iso = 0.5, .maxTriangles = n}));
}

TEST(Isosurface, FlatAndDegenerateVolumes) {
  // A single slice has no cells: empty unless the borders are closed.
  auto v = dm::Volume::create({6, 5, 1}, dm::VoxelType::F32);
  ASSERT_TRUE(v);
  v->setValue(2, 2, 0, 1.0);
  v->setValue(3, 2, 0, 1.0);
  for (IsoMethod m : kMethods) {
    EXPECT_TRUE(extract(*v, 0.5, m).empty()) << name(m);
    expectClosedSurface(extract(*v, 0.5, m, true), 2, 1, name(m));
  }
  // NaN voxels count as outside and never produce NaN positions or normals.
  auto w = dm::Volume::create({5, 5, 5}, dm::VoxelType::F32);
  ASSERT_TRUE(w);
  w->setValue(2, 2, 2, 1.0);
  w->setValue(1, 2, 2, std::nan(""));
  for (IsoMethod m : kMethods) {
    const dm::Mesh mesh = extract(*w, 0.5, m);  // extract() checks validate(): finite
    expectClosedSurface(mesh, 2, 1, name(m));
    for (const Vec3& n : mesh.normals) EXPECT_NEAR(n.norm(), 1.0, 1e-12) << name(m);
  }
}

}  // namespace
