#include <dm/core/mesh.hpp>

#include <gtest/gtest.h>

#include <cmath>

namespace {

// Unit cube [0,1]^3 with outward CCW triangles.
dm::Mesh cube() {
  dm::Mesh m;
  m.name = "cube";
  for (int i = 0; i < 8; ++i) m.positions.emplace_back(i & 1, (i >> 1) & 1, (i >> 2) & 1);
  m.triangles = {{0, 2, 1}, {1, 2, 3}, {4, 5, 6}, {5, 7, 6}, {0, 1, 4}, {1, 5, 4},
                 {2, 6, 3}, {3, 6, 7}, {0, 4, 2}, {2, 4, 6}, {1, 3, 5}, {3, 7, 5}};
  return m;
}

TEST(Mesh, BoundsAreaAndOutwardFaceNormals) {
  dm::Mesh m = cube();
  ASSERT_TRUE(m.validate());
  EXPECT_TRUE(m.bounds().min().isApprox(dm::Vec3(0, 0, 0)));
  EXPECT_TRUE(m.bounds().max().isApprox(dm::Vec3(1, 1, 1)));
  EXPECT_NEAR(m.surfaceArea(), 6.0, 1e-12);
  const dm::Vec3 centre(0.5, 0.5, 0.5);
  for (std::size_t t = 0; t < m.triangleCount(); ++t) {
    const dm::Vec3 c =
        (m.positions[m.triangles[t][0]] + m.positions[m.triangles[t][1]] + m.positions[m.triangles[t][2]]) /
        3;
    EXPECT_GT(m.faceNormal(t).dot(c - centre), 0) << "triangle " << t << " faces inward";
  }
}

TEST(Mesh, AngleWeightedVertexNormalsOfCubeCornersAreDiagonal) {
  dm::Mesh m = cube();
  m.computeNormals();
  for (std::size_t v = 0; v < m.vertexCount(); ++v) {
    const dm::Vec3 expected = (m.positions[v] - dm::Vec3(0.5, 0.5, 0.5)).normalized();
    EXPECT_LT((m.normals[v] - expected).norm(), 1e-12) << "vertex " << v;
  }
}

TEST(Mesh, ValidateNamesTheProblem) {
  dm::Mesh m = cube();
  m.triangles.push_back({0, 1, 99});
  auto s = m.validate();
  ASSERT_FALSE(s);
  EXPECT_NE(s.error().what.find("triangle 12 references vertex 99"), std::string::npos) << s.error();
  m = cube();
  m.positions[3].y() = std::nan("");
  s = m.validate();
  ASSERT_FALSE(s);
  EXPECT_NE(s.error().what.find("vertex 3"), std::string::npos);
  m = cube();
  m.normals.resize(2);
  EXPECT_FALSE(m.validate());
}

TEST(Mesh, TransformScalesAndRotatesNormals) {
  dm::Mesh m = cube();
  m.computeNormals();
  dm::Affine3 t = dm::Affine3::Identity();
  t.linear() = dm::AngleAxis(M_PI / 2, dm::Vec3::UnitZ()).toRotationMatrix() * 2.0;
  t.translation() = dm::Vec3(1, 2, 3);
  m.transform(t);
  EXPECT_NEAR(m.surfaceArea(), 24.0, 1e-12);
  dm::Mesh ref = m;
  ref.computeNormals();
  for (std::size_t v = 0; v < m.vertexCount(); ++v) EXPECT_LT((m.normals[v] - ref.normals[v]).norm(), 1e-12);
}

TEST(Mesh, AppendedMeshesKeepTheirTrianglesAndSharedAttributes) {
  // A cube and a moved, scaled cube with normals: the union has both areas,
  // every triangle of the second keeps its own face normal (its indices
  // point at its own vertices), and normals stay per vertex.
  dm::Mesh a = cube();
  a.computeNormals();
  dm::Mesh b = cube();
  dm::Affine3 t = dm::Affine3::Identity();
  t.linear() = dm::AngleAxis(0.3, dm::Vec3(1, 2, 3).normalized()).toRotationMatrix() * 0.5;
  t.translation() = dm::Vec3(3, 0, 0);
  b.transform(t);
  b.computeNormals();
  dm::Mesh u;
  u.append(a);
  u.append(b);
  ASSERT_TRUE(u.validate());
  EXPECT_EQ(u.vertexCount(), 16u);
  EXPECT_NEAR(u.surfaceArea(), 6.0 + 1.5, 1e-12);
  for (std::size_t k = 0; k < b.triangleCount(); ++k)
    EXPECT_LT((u.faceNormal(12 + k) - b.faceNormal(k)).norm(), 1e-12) << "triangle " << k;
  ASSERT_EQ(u.normals.size(), 16u);
  EXPECT_EQ(u.normals[9], b.normals[1]);
  // A mesh without normals or with colours the first lacks: the attribute
  // that is not everyone's is dropped, never left short of the positions.
  dm::Mesh c = cube();
  c.colors.assign(8, dm::Vec4f(1, 0, 0, 1));
  u.append(c);
  ASSERT_TRUE(u.validate());
  EXPECT_TRUE(u.normals.empty());
  EXPECT_TRUE(u.colors.empty());
  EXPECT_EQ(u.triangles.back()[0], 16u + 3u);  // cube's last triangle starts at its vertex 3
}

}  // namespace
