// Declared-size budgets of mesh import (issue 37): a PLY, OFF or binary STL
// header whose element counts exceed MeshImportOptions::maxTriangles (faces)
// or three vertices per allowed triangle is refused before Assimp sees the
// file, with the figure and the limit in the message; a header promising
// more than the file holds is refused the same way. The model is a regular
// icosahedron (edge 2: area 20·√3, volume (5/12)(3+√5)·8), curved enough
// that a wrong face count or a dropped face shows in its area.
#include <dm/io/mesh_io.hpp>

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "../common/temp_dir.hpp"
#include "file_test_support.hpp"

namespace {

namespace fs = std::filesystem;
using dm::test::TempDir;
using dm::test::writeText;

using dm::test::mentions;

struct Icosahedron {
  std::vector<std::array<double, 3>> v;
  std::vector<std::array<int, 3>> f;  ///< outward, counter-clockwise
};

// The 12 corners (0, ±1, ±φ) and their cyclic permutations; the faces are
// the triples at mutual distance 2, turned to face outward.
Icosahedron icosahedron() {
  const double p = (1 + std::sqrt(5.0)) / 2;
  Icosahedron ico;
  for (double a : {-1.0, 1.0})
    for (double b : {-p, p}) {
      ico.v.push_back({0, a, b});
      ico.v.push_back({a, b, 0});
      ico.v.push_back({b, 0, a});
    }
  auto d2 = [&](int i, int j) {
    double s = 0;
    for (int c = 0; c < 3; ++c) s += (ico.v[i][c] - ico.v[j][c]) * (ico.v[i][c] - ico.v[j][c]);
    return s;
  };
  for (int i = 0; i < 12; ++i)
    for (int j = i + 1; j < 12; ++j)
      for (int k = j + 1; k < 12; ++k) {
        if (std::abs(d2(i, j) - 4) > 1e-9 || std::abs(d2(j, k) - 4) > 1e-9 || std::abs(d2(i, k) - 4) > 1e-9)
          continue;
        std::array<double, 3> e1{}, e2{}, c{};
        for (int a = 0; a < 3; ++a) {
          e1[a] = ico.v[j][a] - ico.v[i][a];
          e2[a] = ico.v[k][a] - ico.v[i][a];
          c[a] = ico.v[i][a] + ico.v[j][a] + ico.v[k][a];
        }
        const double n0 = e1[1] * e2[2] - e1[2] * e2[1], n1 = e1[2] * e2[0] - e1[0] * e2[2],
                     n2 = e1[0] * e2[1] - e1[1] * e2[0];
        const bool outward = n0 * c[0] + n1 * c[1] + n2 * c[2] > 0;
        ico.f.push_back(outward ? std::array<int, 3>{i, j, k} : std::array<int, 3>{i, k, j});
      }
  return ico;
}

const double kArea = 20 * std::sqrt(3.0);

template <class T>
void put(std::string& s, T value) {
  char b[sizeof(T)];
  std::memcpy(b, &value, sizeof(T));
  s.append(b, sizeof(T));
}

std::string binaryStl(const Icosahedron& ico, std::uint32_t declared) {
  std::string s(80, ' ');
  put<std::uint32_t>(s, declared);
  for (const auto& t : ico.f) {
    for (int c = 0; c < 3; ++c) put<float>(s, 0.0f);
    for (int corner : t)
      for (int c = 0; c < 3; ++c) put<float>(s, static_cast<float>(ico.v[corner][c]));
    put<std::uint16_t>(s, 0);
  }
  return s;
}

std::string binaryPly(const Icosahedron& ico) {
  std::string s = "ply\nformat binary_little_endian 1.0\ncomment icosahedron, edge 2\nelement vertex " +
                  std::to_string(ico.v.size()) +
                  "\nproperty float x\nproperty float y\nproperty float z\nelement face " +
                  std::to_string(ico.f.size()) + "\nproperty list uchar int vertex_indices\nend_header\n";
  for (const auto& p : ico.v)
    for (double x : p) put<float>(s, static_cast<float>(x));
  for (const auto& t : ico.f) {
    put<std::uint8_t>(s, 3);
    for (int i : t) put<std::int32_t>(s, i);
  }
  return s;
}

std::string off(const Icosahedron& ico) {
  std::string s = "OFF\n" + std::to_string(ico.v.size()) + " " + std::to_string(ico.f.size()) + " 30\n";
  for (const auto& p : ico.v)
    s += std::to_string(p[0]) + " " + std::to_string(p[1]) + " " + std::to_string(p[2]) + "\n";
  for (const auto& t : ico.f)
    s += "3 " + std::to_string(t[0]) + " " + std::to_string(t[1]) + " " + std::to_string(t[2]) + "\n";
  return s;
}

dm::MeshImportOptions budget(std::size_t maxTriangles) {
  dm::MeshImportOptions o;
  o.maxTriangles = maxTriangles;
  return o;
}

TEST(MeshBudget, TheIcosahedronHasTwentyOutwardFaces) {
  const Icosahedron ico = icosahedron();
  ASSERT_EQ(ico.v.size(), 12u);
  ASSERT_EQ(ico.f.size(), 20u);
}

// Each format: over the budget by one face it is refused naming both
// figures; at the budget it reads, and the surface is the icosahedron's.
TEST(MeshBudget, HeadersOverTheTriangleBudgetAreRefusedWithFigureAndLimit) {
  TempDir dir("mesh_budget");
  const Icosahedron ico = icosahedron();
  writeText(dir / "ico.stl", binaryStl(ico, 20));
  writeText(dir / "ico.ply", binaryPly(ico));
  writeText(dir / "ico.off", off(ico));
  const std::pair<const char*, const char*> formats[] = {
      {"ico.stl", "binary STL header declares 20 triangles, more than the budget of 19"},
      {"ico.ply", "PLY header declares 20 faces, more than the budget of 19"},
      {"ico.off", "OFF header declares 20 faces, more than the budget of 19"}};
  for (const auto& [name, message] : formats) {
    SCOPED_TRACE(name);
    auto refused = dm::readMesh(dir / name, budget(19));
    ASSERT_FALSE(refused);
    EXPECT_EQ(refused.error().code, dm::ErrorCode::Unsupported);
    EXPECT_TRUE(mentions(refused.error(), message)) << refused.error();
    EXPECT_TRUE(mentions(refused.error(), "maxTriangles")) << refused.error();
    EXPECT_TRUE(mentions(refused.error(), (dir / name).string())) << refused.error();

    auto read = dm::readMesh(dir / name, budget(20));
    ASSERT_TRUE(read) << read.error();
    EXPECT_EQ(read->triangles.size(), 20u);
    EXPECT_EQ(read->positions.size(), 12u);                 // welded
    EXPECT_NEAR(read->surfaceArea(), kArea, 1e-5 * kArea);  // float coordinates
  }
}

// Vertices: three per allowed triangle. Ten vertices and one face are over
// a budget of 3 triangles (9 vertices) by their vertices alone.
TEST(MeshBudget, VertexCountsOverThreePerAllowedTriangleAreRefused) {
  const std::string ply =
      "ply\nformat ascii 1.0\nelement vertex 10\nproperty float x\nproperty float y\nproperty float z\n"
      "element face 1\nproperty list uchar int vertex_indices\nend_header\n" +
      std::string("0 0 0\n1 0 0\n0 1 0\n0 0 1\n1 1 0\n1 0 1\n0 1 1\n1 1 1\n2 0 0\n0 2 0\n3 0 1 2\n");
  auto refused =
      dm::parseMesh({reinterpret_cast<const std::byte*>(ply.data()), ply.size()}, "ply", budget(3));
  ASSERT_FALSE(refused);
  EXPECT_TRUE(mentions(refused.error(), "PLY header declares 10 vertices, more than the budget of 9"))
      << refused.error();
  // Four allowed triangles allow 12 vertices: the one triangle reads.
  auto read = dm::parseMesh({reinterpret_cast<const std::byte*>(ply.data()), ply.size()}, "ply", budget(4));
  ASSERT_TRUE(read) << read.error();
  EXPECT_EQ(read->triangles.size(), 1u);
  EXPECT_NEAR(read->surfaceArea(), 0.5, 1e-12);
}

// The defaults (50 million triangles): a PLY header asking for three
// billion vertices, the case that made Assimp in its helper allocate up to
// the helper's memory budget (tens of GiB) before failing, is refused from
// its header at once.
TEST(MeshBudget, BillionsOfDeclaredVerticesAreRefusedFromTheHeaderAlone) {
  TempDir dir("mesh_budget_huge");
  writeText(dir / "huge.ply",
            "ply\nformat ascii 1.0\nelement vertex 3000000000\nproperty float x\nproperty float y\n"
            "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n");
  auto refused = dm::readMesh(dir / "huge.ply");
  ASSERT_FALSE(refused);
  EXPECT_EQ(refused.error().code, dm::ErrorCode::Unsupported);
  EXPECT_TRUE(mentions(refused.error(), "declares 3000000000 vertices, more than the budget of 150000000"))
      << refused.error();

  // A binary STL declaring 2^31 triangles whose size fits the count would
  // be 100 GiB; one whose size does not fit is not binary STL to Assimp
  // either and fails as such. With a size to match (sparse), the header is
  // refused without reading the triangles.
  const fs::path sparse = dir / "huge.stl";
  {
    std::string head(80, ' ');
    put<std::uint32_t>(head, 60'000'000);
    writeText(sparse, head);
    fs::resize_file(sparse, 84 + std::uint64_t{50} * 60'000'000);
  }
  dm::MeshImportOptions roomy;
  roomy.maxFileBytes = std::size_t{4} << 30;
  auto stl = dm::readMesh(sparse, roomy);
  ASSERT_FALSE(stl);
  EXPECT_TRUE(mentions(stl.error(),
                       "binary STL header declares 60000000 triangles, more than the budget of 50000000"))
      << stl.error();
}

// Within the budget but more than the bytes after the header can hold.
TEST(MeshBudget, PlyCountsTheFileCannotHoldAreRefusedNamingBoth) {
  const Icosahedron ico = icosahedron();
  std::string ply = binaryPly(ico);
  const std::string declared = "element face 20\n";
  ply.replace(ply.find(declared), declared.size(), "element face 2000\n");
  auto refused = dm::parseMesh({reinterpret_cast<const std::byte*>(ply.data()), ply.size()}, "ply");
  ASSERT_FALSE(refused);
  EXPECT_EQ(refused.error().code, dm::ErrorCode::Parse);
  // 12 vertices of 12 bytes and 2000 faces of at least one count byte.
  EXPECT_TRUE(
      mentions(refused.error(), "12 'vertex', 2000 'face' elements, at least 2144 bytes, but only 404 bytes"))
      << refused.error();
}

}  // namespace
