// Tests of dm/collide/bvh.hpp: build failures, tree invariants (every
// triangle in exactly one leaf, child boxes inside parents, leaf boxes
// containing their triangles) and refit against a rebuilt tree.
#include <dm/collide/bvh.hpp>
#include <dm/collide/mesh_query.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <vector>

namespace {

using dm::Vec3;

dm::Mesh randomSoup(std::size_t n, std::uint64_t seed, double spread = 1.0, double size = 0.05) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1, 1);
  dm::Mesh m;
  for (std::size_t t = 0; t < n; ++t) {
    const Vec3 c = spread * Vec3(u(rng), u(rng), u(rng));
    const auto base = static_cast<std::uint32_t>(m.positions.size());
    for (int k = 0; k < 3; ++k) m.positions.push_back(c + size * Vec3(u(rng), u(rng), u(rng)));
    m.triangles.push_back({base, base + 1, base + 2});
  }
  return m;
}

/// A wavy open sheet z = 0.1 sin(3x) cos(2y) over [-1, 1]², n × n quads.
dm::Mesh sheet(int n) {
  dm::Mesh m;
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) {
      const double x = -1 + 2.0 * i / n, y = -1 + 2.0 * j / n;
      m.positions.emplace_back(x, y, 0.1 * std::sin(3 * x) * std::cos(2 * y));
    }
  auto id = [n](int i, int j) { return static_cast<std::uint32_t>(j * (n + 1) + i); };
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      m.triangles.push_back({id(i, j), id(i + 1, j), id(i + 1, j + 1)});
      m.triangles.push_back({id(i, j), id(i + 1, j + 1), id(i, j + 1)});
    }
  return m;
}

bool boxContains(const dm::BvhNode& n, const Vec3& p) {
  for (int a = 0; a < 3; ++a)
    if (!(double(n.lo[a]) <= p[a] && p[a] <= double(n.hi[a]))) return false;
  return true;
}

void checkInvariants(const dm::MeshBvh& bvh, const dm::Mesh& mesh) {
  const auto nodes = bvh.nodes();
  ASSERT_GE(nodes.size(), 1u);
  std::vector<int> seen(mesh.triangleCount(), 0);
  std::vector<int> reached(nodes.size(), 0);
  reached[0] = 1;
  for (std::uint32_t i = 0; i < nodes.size(); ++i) {
    if (i == 1) continue;  // padding
    const dm::BvhNode& n = nodes[i];
    ASSERT_EQ(reached[i], 1) << "node " << i << " reached " << reached[i] << " times";
    for (int a = 0; a < 3; ++a) ASSERT_LE(n.lo[a], n.hi[a]);
    if (n.isLeaf()) {
      ASSERT_LE(n.count, 4u);
      ASSERT_LE(n.first + n.count, bvh.triangleCount());
      for (std::uint32_t k = n.first; k < n.first + n.count; ++k) {
        ++seen[bvh.originalTriangle(k)];
        const dm::Triangle& tri = mesh.triangles[bvh.originalTriangle(k)];
        EXPECT_EQ(bvh.triangleIndices(k), tri);
        for (int c = 0; c < 3; ++c) {
          EXPECT_EQ(bvh.corners(k)[c], mesh.positions[tri[c]]);
          EXPECT_TRUE(boxContains(n, bvh.corners(k)[c])) << "leaf " << i;
        }
      }
    } else {
      ASSERT_EQ(n.first % 2, 0u) << "children pairs start at even slots";
      ASSERT_GT(n.first, i);
      ASSERT_LT(n.first + 1, nodes.size());
      for (std::uint32_t c = n.first; c < n.first + 2; ++c) {
        ++reached[c];
        for (int a = 0; a < 3; ++a) {
          EXPECT_LE(n.lo[a], nodes[c].lo[a]);
          EXPECT_GE(n.hi[a], nodes[c].hi[a]);
        }
      }
    }
  }
  for (std::size_t t = 0; t < seen.size(); ++t) ASSERT_EQ(seen[t], 1) << "triangle " << t;
  // Oriented boxes: orthonormal axes, and every corner of the subtree's
  // triangles inside (the distance traversal prunes by them).
  for (std::uint32_t i = 0; i < nodes.size(); ++i) {
    if (i == 1) continue;
    const dm::BvhObb& o = bvh.obb(i);
    ASSERT_TRUE((o.axes.transpose() * o.axes).isIdentity(1e-12)) << "node " << i;
    std::vector<std::uint32_t> pending{i};
    while (!pending.empty()) {
      const dm::BvhNode& n = nodes[pending.back()];
      pending.pop_back();
      if (!n.isLeaf()) {
        pending.push_back(n.first);
        pending.push_back(n.first + 1);
        continue;
      }
      for (std::uint32_t k = n.first; k < n.first + n.count; ++k)
        for (int c = 0; c < 3; ++c) {
          const Vec3 q = o.axes.transpose() * (bvh.corners(k)[c] - o.center);
          ASSERT_TRUE((q.cwiseAbs().array() <= o.half.array()).all())
              << "node " << i << " triangle " << k << " outside by " << (q.cwiseAbs() - o.half).maxCoeff();
        }
    }
  }
  EXPECT_LE(bvh.depth(), dm::MeshBvh::kMaxDepth);
  EXPECT_TRUE(bvh.bounds().contains(mesh.bounds()));
}

TEST(MeshBvh, RejectsBadMeshes) {
  dm::Mesh empty;
  auto e = dm::MeshBvh::build(empty);
  ASSERT_FALSE(e);
  EXPECT_NE(e.error().what.find("no triangles"), std::string::npos);

  dm::Mesh nan = sheet(2);
  nan.positions[3].y() = std::numeric_limits<double>::quiet_NaN();
  auto n = dm::MeshBvh::build(nan);
  ASSERT_FALSE(n);
  EXPECT_NE(n.error().what.find("position 3"), std::string::npos);

  dm::Mesh bad = sheet(2);
  bad.triangles[5][1] = 999;
  auto b = dm::MeshBvh::build(bad);
  ASSERT_FALSE(b);
  EXPECT_NE(b.error().what.find("triangle 5"), std::string::npos);
}

TEST(MeshBvh, InvariantsOnSoupsSheetsAndDegenerateInput) {
  for (std::size_t n : {1u, 2u, 5u, 17u, 1000u, 20000u}) {
    const dm::Mesh m = randomSoup(n, n);
    auto bvh = dm::MeshBvh::build(m);
    ASSERT_TRUE(bvh) << bvh.error().message();
    checkInvariants(*bvh, m);
    EXPECT_FALSE(bvh->isClosed());
  }
  const dm::Mesh s = sheet(40);
  auto bs = dm::MeshBvh::build(s, {.bins = 32, .maxLeafSize = 2});
  ASSERT_TRUE(bs);
  checkInvariants(*bs, s);
  // All triangles identical: no SAH split exists, the median split must still terminate.
  dm::Mesh same = randomSoup(1, 1);
  for (int i = 0; i < 999; ++i) same.triangles.push_back(same.triangles[0]);
  auto bsame = dm::MeshBvh::build(same);
  ASSERT_TRUE(bsame);
  checkInvariants(*bsame, same);
  EXPECT_LE(bsame->depth(), 12);
  // Huge and tiny coordinates.
  dm::Mesh scaled = randomSoup(500, 3, 1e6, 1e3);
  auto bhuge = dm::MeshBvh::build(scaled);
  ASSERT_TRUE(bhuge);
  checkInvariants(*bhuge, scaled);
  for (auto& p : scaled.positions) p *= 1e-12;
  auto btiny = dm::MeshBvh::build(scaled);
  ASSERT_TRUE(btiny);
  checkInvariants(*btiny, scaled);
}

TEST(MeshBvh, ClosedMeshGetsPseudonormals) {
  // Octahedron, counter-clockwise from outside.
  dm::Mesh o;
  o.positions = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
  o.triangles = {{0, 2, 4}, {2, 1, 4}, {1, 3, 4}, {3, 0, 4}, {2, 0, 5}, {1, 2, 5}, {3, 1, 5}, {0, 3, 5}};
  auto bvh = dm::MeshBvh::build(o);
  ASSERT_TRUE(bvh);
  ASSERT_TRUE(bvh->isClosed());
  // By symmetry the vertex pseudonormal of vertex 4 is +z, edge 0–2 bisects two faces.
  EXPECT_NEAR((bvh->vertexNormal(4) - Vec3(0, 0, 1)).norm(), 0, 1e-15);
  for (std::uint32_t k = 0; k < 8; ++k) {
    const Vec3* c = bvh->corners(k);
    const Vec3 centroid = (c[0] + c[1] + c[2]) / 3;
    EXPECT_NEAR((bvh->faceNormal(k) - centroid.normalized()).norm(), 0, 1e-15);
    for (int e = 0; e < 3; ++e) {
      const Vec3 mid = 0.5 * (c[e] + c[(e + 1) % 3]);
      EXPECT_NEAR((bvh->edgeNormal(k, e) - mid.normalized()).norm(), 0, 1e-15);
    }
  }
}

TEST(MeshBvh, RefitEqualsRebuild) {
  dm::Mesh a = sheet(30);
  dm::Mesh b = randomSoup(800, 21, 0.8, 0.08);
  auto ba = dm::MeshBvh::build(a);
  auto bb = dm::MeshBvh::build(b);
  ASSERT_TRUE(ba && bb);
  // Deform both (large motions: the refitted tree is worse, never wrong).
  std::mt19937_64 rng(4);
  std::uniform_real_distribution<double> u(-1, 1);
  for (auto& p : a.positions)
    p += Vec3(0.2 * std::sin(5 * p.y()), 0.1 * p.x() * p.x(), 0.3 * std::cos(4 * p.x()));
  for (auto& p : b.positions) p = 1.3 * p + 0.02 * Vec3(u(rng), u(rng), u(rng));
  ASSERT_TRUE(ba->refit(a.positions));
  ASSERT_TRUE(bb->refit(b.positions));
  checkInvariants(*ba, a);
  checkInvariants(*bb, b);
  auto ra = dm::MeshBvh::build(a);
  auto rb = dm::MeshBvh::build(b);
  ASSERT_TRUE(ra && rb);
  for (int i = 0; i < 60; ++i) {
    const dm::Isometry3 pa = dm::Isometry3(dm::Quat::UnitRandom());
    dm::Isometry3 pb = dm::Isometry3(dm::Quat::UnitRandom());
    pb.translation() = 0.8 * Vec3(u(rng), u(rng), u(rng));
    EXPECT_EQ(dm::meshMeshIntersect(*ba, pa, *bb, pb), dm::meshMeshIntersect(*ra, pa, *rb, pb));
    EXPECT_EQ(dm::meshMeshDistance(*ba, pa, *bb, pb).distance,
              dm::meshMeshDistance(*ra, pa, *rb, pb).distance);
    const Vec3 q(u(rng), u(rng), u(rng));
    EXPECT_EQ(dm::closestPointOnMesh(*ba, pa, q).distance, dm::closestPointOnMesh(*ra, pa, q).distance);
  }
  // Wrong size or NaN: refused, tree unchanged.
  const auto before = ba->nodes()[0];
  EXPECT_FALSE(ba->refit(std::span<const Vec3>(a.positions).first(3)));
  std::vector<Vec3> bad = a.positions;
  bad[7].x() = std::numeric_limits<double>::infinity();
  EXPECT_FALSE(ba->refit(bad));
  EXPECT_EQ(ba->nodes()[0].lo[0], before.lo[0]);
  EXPECT_EQ(ba->nodes()[0].hi[2], before.hi[2]);
}

}  // namespace
