// Tests for dm/io/mesh_io.hpp: meshes with known geometry written by the
// test (cube: area 6, volume 1, corner normals along the diagonals), scenes
// with node transforms worked out by hand, round trips through our writers,
// bad inputs, and a walk over every model of the assimp-testmodels package.
#include <dm/core/log.hpp>
#include <dm/io/mesh_io.hpp>

#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "../common/temp_dir.hpp"
#include "file_test_support.hpp"

namespace {

namespace fs = std::filesystem;

const fs::path kModels = "/usr/share/assimp/models";

#define DM_REQUIRE_TESTMODELS()                                                      \
  do {                                                                               \
    if (!fs::is_directory(kModels))                                                  \
      FAIL() << "the Debian package assimp-testmodels is not installed (" << kModels \
             << " is missing); install it with: apt-get install assimp-testmodels";  \
  } while (0)

using dm::test::TempDir;
using dm::test::writeText;

std::vector<std::byte> bytesOf(const std::string& s) {
  std::vector<std::byte> b(s.size());
  std::memcpy(b.data(), s.data(), s.size());
  return b;
}

// The unit cube [0,1]^3: corners and six quads, counter-clockwise seen from
// outside (OBJ numbering from 1).
const double kCubeCorners[8][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0},
                                   {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};
const int kCubeQuads[6][4] = {{1, 4, 3, 2}, {5, 6, 7, 8}, {1, 2, 6, 5},
                              {3, 4, 8, 7}, {1, 5, 8, 4}, {2, 3, 7, 6}};

std::string cubeObj() {
  std::string s = "# unit cube\n";
  for (const auto& c : kCubeCorners)
    s += "v " + std::to_string(c[0]) + " " + std::to_string(c[1]) + " " + std::to_string(c[2]) + "\n";
  for (const auto& q : kCubeQuads)
    s += "f " + std::to_string(q[0]) + " " + std::to_string(q[1]) + " " + std::to_string(q[2]) + " " +
         std::to_string(q[3]) + "\n";
  return s;
}

// The cube's 12 triangles as corner positions; `corner(t, c)` may perturb or
// replace the text of a coordinate triple.
using CornerText = std::string (*)(int triangle, int corner, const double* p);

std::string defaultCorner(int, int, const double* p) {
  char buf[128];
  std::snprintf(buf, sizeof buf, "%.17g %.17g %.17g", p[0], p[1], p[2]);
  return buf;
}

std::string cubeStlAscii(CornerText corner = defaultCorner) {
  std::string s = "solid cube\n";
  int t = 0;
  for (const auto& q : kCubeQuads) {
    const int tris[2][3] = {{q[0], q[1], q[2]}, {q[0], q[2], q[3]}};
    for (const auto& tri : tris) {
      const dm::Vec3 p0(kCubeCorners[tri[0] - 1]), p1(kCubeCorners[tri[1] - 1]), p2(kCubeCorners[tri[2] - 1]);
      const dm::Vec3 n = (p1 - p0).cross(p2 - p0).normalized();
      s += "facet normal " + defaultCorner(0, 0, n.data()) + "\n outer loop\n";
      for (int c = 0; c < 3; ++c) s += "  vertex " + corner(t, c, kCubeCorners[tri[c] - 1]) + "\n";
      s += " endloop\nendfacet\n";
      ++t;
    }
  }
  return s + "endsolid cube\n";
}

double signedVolume(const dm::Mesh& m) {
  double v = 0;
  for (const dm::Triangle& t : m.triangles)
    v += m.positions[t[0]].dot(m.positions[t[1]].cross(m.positions[t[2]])) / 6.0;
  return v;
}

void expectUnitCube(const dm::Mesh& m, double size = 1.0) {
  EXPECT_EQ(m.vertexCount(), 8u);
  EXPECT_EQ(m.triangleCount(), 12u);
  EXPECT_NEAR(m.surfaceArea(), 6 * size * size, 1e-12 * size * size);
  EXPECT_NEAR(signedVolume(m), size * size * size, 1e-12 * size * size * size);  // outward orientation
  const dm::Aabb box = m.bounds();
  EXPECT_TRUE(box.min().isApprox(dm::Vec3::Zero(), 0.0) || box.min().norm() < 1e-15 * size) << box.min();
  EXPECT_NEAR((box.max() - dm::Vec3::Constant(size)).norm(), 0.0, 1e-15 * size) << box.max();
  ASSERT_EQ(m.normals.size(), 8u);
  // Every corner touches three faces with 90° each: the angle-weighted normal
  // is the diagonal away from the centre.
  for (std::size_t i = 0; i < 8; ++i) {
    const dm::Vec3 expected = (m.positions[i] - dm::Vec3::Constant(size / 2)).normalized();
    EXPECT_NEAR((m.normals[i] - expected).norm(), 0.0, 1e-12) << "vertex " << i;
  }
}

using dm::test::mentions;

// ---------------------------------------------------------------------------

TEST(MeshIo, UnitCubeObjHasExactAreaVolumeBoundsAndNormals) {
  TempDir dir("cube_obj");
  writeText(dir / "cube.obj", cubeObj());
  auto m = dm::readMesh(dir / "cube.obj");
  ASSERT_TRUE(m) << m.error();
  EXPECT_EQ(m->name, "cube");
  expectUnitCube(*m);
  EXPECT_TRUE(m->uvs.empty());
  EXPECT_TRUE(m->colors.empty());
}

TEST(MeshIo, StlCornersAreWeldedAndFacetNormalsReplaced) {
  TempDir dir("cube_stl");
  writeText(dir / "cube.stl", cubeStlAscii());
  auto m = dm::readMesh(dir / "cube.stl");
  ASSERT_TRUE(m) << m.error();
  expectUnitCube(*m);  // 36 corners → 8 vertices; facet normals disagree → computed

  dm::MeshImportOptions noWeld;
  noWeld.weld = false;
  auto raw = dm::readMesh(dir / "cube.stl", noWeld);
  ASSERT_TRUE(raw) << raw.error();
  EXPECT_EQ(raw->triangleCount(), 12u);
  // Assimp joins identical (position, facet normal) pairs: three per corner.
  EXPECT_EQ(raw->vertexCount(), 24u);
  EXPECT_NEAR(raw->surfaceArea(), 6.0, 1e-12);
  EXPECT_NEAR(signedVolume(*raw), 1.0, 1e-12);

  dm::MeshImportOptions noNormals;
  noNormals.computeNormals = false;
  auto bare = dm::readMesh(dir / "cube.stl", noNormals);
  ASSERT_TRUE(bare) << bare.error();
  EXPECT_TRUE(bare->normals.empty());  // the facet normals do not describe welded vertices
}

TEST(MeshIo, UnitAndScaleConvertToMetres) {
  TempDir dir("units");
  writeText(dir / "cube.obj", cubeObj());
  dm::MeshImportOptions mm;
  mm.unit = "mm";
  auto a = dm::readMesh(dir / "cube.obj", mm);
  ASSERT_TRUE(a) << a.error();
  expectUnitCube(*a, 1e-3);

  dm::MeshImportOptions cm2;
  cm2.unit = "cm";
  cm2.scale = 2.0;
  auto b = dm::readMesh(dir / "cube.obj", cm2);
  ASSERT_TRUE(b) << b.error();
  expectUnitCube(*b, 0.02);

  dm::MeshImportOptions inch;
  inch.unit = "inch";
  auto c = dm::readMesh(dir / "cube.obj", inch);
  ASSERT_TRUE(c) << c.error();
  EXPECT_NEAR(c->bounds().max().x(), 0.0254, 1e-15);

  dm::MeshImportOptions bad;
  bad.unit = "furlong";
  auto d = dm::readMesh(dir / "cube.obj", bad);
  ASSERT_FALSE(d);
  EXPECT_EQ(d.error().code, dm::ErrorCode::InvalidArgument);
  EXPECT_TRUE(mentions(d.error(), "furlong")) << d.error();
  EXPECT_TRUE(mentions(d.error(), (dir / "cube.obj").string())) << d.error();

  dm::MeshImportOptions zero;
  zero.scale = 0;
  EXPECT_FALSE(dm::readMesh(dir / "cube.obj", zero));
  dm::MeshImportOptions negTol;
  negTol.weldTolerance = -1;
  EXPECT_FALSE(dm::readMesh(dir / "cube.obj", negTol));

  auto u = dm::metresPerUnit("ft");
  ASSERT_TRUE(u);
  EXPECT_DOUBLE_EQ(*u, 0.3048);
}

TEST(MeshIo, ToleranceWeldMergesNearbyCorners) {
  // Every corner occurrence is displaced by up to 20 µm (far above float
  // resolution at 1 m), so only a tolerance weld restores 8 vertices.
  TempDir dir("jitter");
  writeText(dir / "jitter.stl", cubeStlAscii([](int t, int c, const double* p) {
              const double d = 2e-5 * std::sin(1.0 + 3.0 * t + 7.0 * c);
              char buf[128];
              std::snprintf(buf, sizeof buf, "%.17g %.17g %.17g", p[0] + d, p[1] - d, p[2] + 0.5 * d);
              return std::string(buf);
            }));
  auto exact = dm::readMesh(dir / "jitter.stl");
  ASSERT_TRUE(exact) << exact.error();
  EXPECT_GT(exact->vertexCount(), 8u);

  dm::MeshImportOptions tol;
  tol.weldTolerance = 1e-4;
  auto welded = dm::readMesh(dir / "jitter.stl", tol);
  ASSERT_TRUE(welded) << welded.error();
  EXPECT_EQ(welded->vertexCount(), 8u);
  EXPECT_EQ(welded->triangleCount(), 12u);
  EXPECT_NEAR(welded->surfaceArea(), 6.0, 1e-3);
  EXPECT_NEAR(signedVolume(*welded), 1.0, 1e-3);

  // A tolerance larger than the cube collapses everything.
  tol.weldTolerance = 5.0;
  auto collapsed = dm::readMesh(dir / "jitter.stl", tol);
  ASSERT_FALSE(collapsed);
  EXPECT_TRUE(mentions(collapsed.error(), "degenerate")) << collapsed.error();
}

TEST(MeshIo, FileNormalsAreKept) {
  // Normals that are not the geometric ones must survive a PLY round trip.
  TempDir dir("normals");
  writeText(dir / "cube.obj", cubeObj());
  auto m = dm::readMesh(dir / "cube.obj");
  ASSERT_TRUE(m) << m.error();
  const dm::Vec3 tilted = dm::Vec3(1, 2, 3).normalized();
  for (auto& n : m->normals) n = tilted;
  ASSERT_TRUE(dm::writeMesh(*m, dir / "tilted.ply"));
  auto back = dm::readMesh(dir / "tilted.ply");
  ASSERT_TRUE(back) << back.error();
  ASSERT_EQ(back->normals.size(), 8u);
  for (const auto& n : back->normals) EXPECT_NEAR((n - tilted).norm(), 0.0, 1e-6);
}

TEST(MeshIo, AttributesSurviveOurWriters) {
  TempDir dir("attributes");
  writeText(dir / "cube.obj", cubeObj());
  auto m = dm::readMesh(dir / "cube.obj");
  ASSERT_TRUE(m) << m.error();
  m->uvs.resize(8);
  m->colors.resize(8);
  for (std::size_t i = 0; i < 8; ++i) {
    m->uvs[i] = dm::Vec2f(0.125f * static_cast<float>(i), 1.0f - 0.125f * static_cast<float>(i));
    m->colors[i] = dm::Vec4f(0.25f, 0.5f, static_cast<float>(i) / 8.0f, 1.0f);
  }
  for (const char* name : {"a.ply", "b.ply", "c.obj"}) {
    const bool binary = std::string(name) != "b.ply";
    ASSERT_TRUE(dm::writeMesh(*m, dir / name, {.binary = binary})) << name;
    auto back = dm::readMesh(dir / name);
    ASSERT_TRUE(back) << name << ": " << back.error();
    ASSERT_EQ(back->vertexCount(), 8u) << name;
    ASSERT_EQ(back->uvs.size(), 8u) << name;
    ASSERT_EQ(back->colors.size(), 8u) << name;
    for (std::size_t i = 0; i < 8; ++i) {
      // Match by position: the reader may order vertices differently.
      std::size_t j = 0;
      while (j < 8 && (m->positions[j] - back->positions[i]).norm() > 1e-9) ++j;
      ASSERT_LT(j, 8u) << name;
      EXPECT_NEAR((back->uvs[i] - m->uvs[j]).norm(), 0.0f, 1e-6f) << name << " vertex " << i;
      EXPECT_NEAR((back->colors[i].head<3>() - m->colors[j].head<3>()).norm(), 0.0f, 1e-6f) << name;
    }
  }
}

TEST(MeshIo, WritersAreExact) {
  // ASCII numbers are shortest round-trip decimals, binary PLY stores doubles.
  dm::Mesh m;
  m.name = "exact";
  m.positions = {{0.1, 1.0 / 3.0, -2.718281828459045}, {1e-300, 12345.678901234567, 0.2}, {0.3, 0.7, 1e10}};
  m.triangles = {{0, 1, 2}};
  auto objText = dm::encodeMesh(m, "obj");
  ASSERT_TRUE(objText) << objText.error();
  std::string text(reinterpret_cast<const char*>(objText->data()), objText->size());
  std::istringstream lines(text);
  std::string line;
  std::size_t v = 0;
  while (std::getline(lines, line)) {
    if (line.rfind("v ", 0) != 0) continue;
    double x, y, z;
    ASSERT_EQ(std::sscanf(line.c_str(), "v %lf %lf %lf", &x, &y, &z), 3) << line;
    ASSERT_LT(v, 3u);
    EXPECT_EQ(x, m.positions[v].x());
    EXPECT_EQ(y, m.positions[v].y());
    EXPECT_EQ(z, m.positions[v].z());
    ++v;
  }
  EXPECT_EQ(v, 3u);
  EXPECT_NE(text.find("f 1 2 3"), std::string::npos);

  auto ply = dm::encodeMesh(m, ".PLY", {.binary = true});
  ASSERT_TRUE(ply) << ply.error();
  const std::string marker = "end_header\n";
  std::string all(reinterpret_cast<const char*>(ply->data()), ply->size());
  const std::size_t body = all.find(marker);
  ASSERT_NE(body, std::string::npos);
  ASSERT_EQ(all.size(), body + marker.size() + 3 * 24 + 13);  // 3 vertices of 3 doubles, one face
  for (std::size_t i = 0; i < 3; ++i)
    for (int k = 0; k < 3; ++k) {
      double d;
      std::memcpy(&d, all.data() + body + marker.size() + 24 * i + 8 * static_cast<std::size_t>(k), 8);
      EXPECT_EQ(d, m.positions[i][k]);
    }

  auto stl = dm::encodeMesh(m, "stl", {.binary = true});
  ASSERT_TRUE(stl);
  EXPECT_EQ(stl->size(), 84u + 50u);  // header, count, one facet
  EXPECT_NE(std::memcmp(stl->data(), "solid", 5), 0);
}

TEST(MeshIo, WusonStlAndPlyAgree) {
  DM_REQUIRE_TESTMODELS();
  auto stl = dm::readMesh(kModels / "STL/Wuson.stl");
  auto ply = dm::readMesh(kModels / "PLY/Wuson.ply");
  ASSERT_TRUE(stl) << stl.error();
  ASSERT_TRUE(ply) << ply.error();
  EXPECT_EQ(stl->vertexCount(), ply->vertexCount());
  EXPECT_EQ(stl->triangleCount(), ply->triangleCount());
  const dm::Aabb a = stl->bounds(), b = ply->bounds();
  const double extent = a.diagonal().norm();
  EXPECT_GT(extent, 0);
  EXPECT_LT((a.min() - b.min()).norm(), 1e-6 * extent)
      << a.min().transpose() << " vs " << b.min().transpose();
  EXPECT_LT((a.max() - b.max()).norm(), 1e-6 * extent)
      << a.max().transpose() << " vs " << b.max().transpose();
  EXPECT_NEAR(stl->surfaceArea(), ply->surfaceArea(), 1e-6 * stl->surfaceArea());

  // The same holds for the ASCII and binary STL spiders.
  auto sa = dm::readMesh(kModels / "STL/Spider_ascii.stl");
  auto sb = dm::readMesh(kModels / "STL/Spider_binary.stl");
  ASSERT_TRUE(sa) << sa.error();
  ASSERT_TRUE(sb) << sb.error();
  EXPECT_EQ(sa->vertexCount(), sb->vertexCount());
  EXPECT_EQ(sa->triangleCount(), sb->triangleCount());
}

TEST(MeshIo, RoundTripThroughEveryWriter) {
  DM_REQUIRE_TESTMODELS();
  auto src = dm::readMesh(kModels / "STL/sphereWithHole.stl");
  ASSERT_TRUE(src) << src.error();
  TempDir dir("roundtrip");
  const double extent = src->bounds().diagonal().norm();
  struct Case {
    const char* file;
    bool binary;
  };
  for (const Case c : {Case{"b.stl", true}, Case{"a.stl", false}, Case{"b.ply", true}, Case{"a.ply", false},
                       Case{"t.obj", false}}) {
    SCOPED_TRACE(c.file);
    ASSERT_TRUE(dm::writeMesh(*src, dir / c.file, {.binary = c.binary}));
    auto back = dm::readMesh(dir / c.file);
    ASSERT_TRUE(back) << back.error();
    ASSERT_EQ(back->triangleCount(), src->triangleCount());
    EXPECT_EQ(back->vertexCount(), src->vertexCount());
    // Triangle by triangle, corner by corner (float32 precision for STL and
    // for Assimp, which reads every format into floats).
    double worst = 0;
    for (std::size_t t = 0; t < src->triangleCount(); ++t)
      for (int k = 0; k < 3; ++k)
        worst = std::max(worst, (back->positions[back->triangles[t][static_cast<std::size_t>(k)]] -
                                 src->positions[src->triangles[t][static_cast<std::size_t>(k)]])
                                    .norm());
    EXPECT_LT(worst, 1e-6 * extent);
    EXPECT_LT((back->bounds().min() - src->bounds().min()).norm(), 1e-6 * extent);
    EXPECT_LT((back->bounds().max() - src->bounds().max()).norm(), 1e-6 * extent);
    EXPECT_NEAR(back->surfaceArea(), src->surfaceArea(), 1e-5 * src->surfaceArea());
  }
}

// Collada scene: one triangle (0,0,0) (1,0,0) (0,1,0) instanced by
//  A: translate (10,0,0) · rotate 90° about z   → (10,0,0) (10,1,0) (9,0,0)
//  B: mirror x, translate (0,5,0)               → (0,5,0) (-1,5,0) (0,6,0), winding flipped
//  C, child of B: translate (0,0,2)             → (0,5,2) (-1,5,2) (0,6,2)
// All three face +z once orientation is restored.
std::string sceneDae(const char* meter = "1") {
  return std::string(R"(<?xml version="1.0" encoding="utf-8"?>
<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
  <asset><unit name="u" meter=")") +
         meter + R"("/><up_axis>Y_UP</up_axis></asset>
  <library_geometries>
    <geometry id="tri" name="tri">
      <mesh>
        <source id="tri-pos">
          <float_array id="tri-pos-array" count="9">0 0 0 1 0 0 0 1 0</float_array>
          <technique_common>
            <accessor source="#tri-pos-array" count="3" stride="3">
              <param name="X" type="float"/><param name="Y" type="float"/><param name="Z" type="float"/>
            </accessor>
          </technique_common>
        </source>
        <vertices id="tri-vtx"><input semantic="POSITION" source="#tri-pos"/></vertices>
        <triangles count="1"><input semantic="VERTEX" source="#tri-vtx" offset="0"/><p>0 1 2</p></triangles>
      </mesh>
    </geometry>
  </library_geometries>
  <library_visual_scenes>
    <visual_scene id="Scene" name="Scene">
      <node id="A" name="A">
        <translate>10 0 0</translate><rotate>0 0 1 90</rotate>
        <instance_geometry url="#tri"/>
      </node>
      <node id="B" name="B">
        <matrix>-1 0 0 0  0 1 0 5  0 0 1 0  0 0 0 1</matrix>
        <instance_geometry url="#tri"/>
        <node id="C" name="C">
          <translate>0 0 2</translate>
          <instance_geometry url="#tri"/>
        </node>
      </node>
    </visual_scene>
  </library_visual_scenes>
  <scene><instance_visual_scene url="#Scene"/></scene>
</COLLADA>
)";
}

void expectTriangle(const dm::Mesh& m, std::size_t t, const std::vector<dm::Vec3>& corners) {
  // The same corners in the same cyclic order (a rotation is allowed).
  std::vector<dm::Vec3> got;
  for (std::uint32_t v : m.triangles[t]) got.push_back(m.positions[v]);
  bool match = false;
  for (int r = 0; r < 3 && !match; ++r) {
    bool all = true;
    for (int k = 0; k < 3; ++k)
      all = all &&
            (got[static_cast<std::size_t>((k + r) % 3)] - corners[static_cast<std::size_t>(k)]).norm() < 1e-5;
    match = all;
  }
  EXPECT_TRUE(match) << "triangle " << t << ": " << got[0].transpose() << " | " << got[1].transpose() << " | "
                     << got[2].transpose();
  EXPECT_NEAR((m.faceNormal(t) - dm::Vec3::UnitZ()).norm(), 0.0, 1e-6) << "triangle " << t;
}

TEST(MeshIo, NodeTransformsAreAppliedPerPartAndMerged) {
  TempDir dir("nodes");
  writeText(dir / "scene.dae", sceneDae());
  const std::vector<dm::Vec3> a{{10, 0, 0}, {10, 1, 0}, {9, 0, 0}};
  const std::vector<dm::Vec3> b{{0, 5, 0}, {0, 6, 0}, {-1, 5, 0}};
  const std::vector<dm::Vec3> c{{0, 5, 2}, {0, 6, 2}, {-1, 5, 2}};

  auto parts = dm::readMeshes(dir / "scene.dae");
  ASSERT_TRUE(parts) << parts.error();
  ASSERT_EQ(parts->size(), 3u);
  EXPECT_EQ((*parts)[0].name, "A");
  EXPECT_EQ((*parts)[1].name, "B");
  EXPECT_EQ((*parts)[2].name, "C");
  for (const auto& p : *parts) {
    ASSERT_EQ(p.triangleCount(), 1u) << p.name;
    ASSERT_EQ(p.normals.size(), 3u) << p.name;
    for (const auto& n : p.normals) EXPECT_NEAR((n - dm::Vec3::UnitZ()).norm(), 0.0, 1e-6) << p.name;
  }
  expectTriangle((*parts)[0], 0, a);
  expectTriangle((*parts)[1], 0, b);
  expectTriangle((*parts)[2], 0, c);

  auto merged = dm::readMesh(dir / "scene.dae");
  ASSERT_TRUE(merged) << merged.error();
  EXPECT_EQ(merged->name, "scene");
  ASSERT_EQ(merged->triangleCount(), 3u);
  EXPECT_EQ(merged->vertexCount(), 9u);
  expectTriangle(*merged, 0, a);
  expectTriangle(*merged, 1, b);
  expectTriangle(*merged, 2, c);
  EXPECT_LT((merged->bounds().min() - dm::Vec3(-1, 0, 0)).norm(), 1e-6);
  EXPECT_LT((merged->bounds().max() - dm::Vec3(10, 6, 2)).norm(), 1e-6);

  dm::MeshImportOptions single;
  single.mergeMeshes = false;
  auto refused = dm::readMesh(dir / "scene.dae", single);
  ASSERT_FALSE(refused);
  EXPECT_TRUE(mentions(refused.error(), "3 parts")) << refused.error();
  EXPECT_TRUE(mentions(refused.error(), "readMeshes")) << refused.error();
}

TEST(MeshIo, ColladaUnitIsHonouredBeforeOurs) {
  // <unit meter="0.01">: the file is in centimetres; Assimp applies it.
  TempDir dir("dae_unit");
  writeText(dir / "cm.dae", sceneDae("0.01"));
  auto m = dm::readMesh(dir / "cm.dae");
  ASSERT_TRUE(m) << m.error();
  EXPECT_LT((m->bounds().max() - dm::Vec3(0.10, 0.06, 0.02)).norm(), 1e-7) << m->bounds().max().transpose();
}

const std::string kPlyHeader =
    "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
    "element face 1\nproperty list uchar int vertex_indices\n";

TEST(MeshIo, BadFilesFailWithTheFileName) {
  TempDir dir("bad");
  std::mt19937 rng(7);
  std::string garbage(3000, '\0');
  for (char& ch : garbage) ch = static_cast<char>(rng() & 0xFF);

  struct Case {
    const char* file;
    std::string content;
    const char* expect;  ///< text the message must contain besides the file name
  };
  const std::vector<Case> cases = {
      {"empty.stl", "", "empty"},
      {"empty.obj", "", "empty"},
      {"garbage.stl", garbage, ""},
      {"garbage.ply", garbage, ""},
      {"garbage.glb", garbage, ""},
      {"points.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\np 1\np 2\np 3\n", "no triangles"},
      {"lines.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nl 1 2\nl 2 3\n", "no triangles"},
      {"points.ply",
       "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
       "end_header\n0 0 0\n1 0 0\n0 1 0\n",
       "no triangles"},
      {"nan.stl", cubeStlAscii([](int t, int c, const double* p) {
         return t == 4 && c == 1 ? std::string("nan 0 0") : defaultCorner(t, c, p);
       }),
       "vertex 13"},  // corner 1 of triangle 4: vertex 4·3 + 1
      {"nan.obj", "v 0 0 0\nv 1 0 0\nv 0 1 nan\nf 1 2 3\n", "vertex 2"},
      {"inf.obj", "v 0 0 0\nv 1 0 0\nv 0 1 inf\nf 1 2 3\n", "non-finite"},
      {"index.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n", ""},
      {"header.off", "OFF\n35353523535358 6 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", "OFF header"},
      // Headers Assimp 5.2 would loop on forever: refused before it sees them.
      {"glued.ply", kPlyHeader + "end_header0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", "end_header"},
      {"noend.ply", kPlyHeader + "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", "no 'end_header'"},
      {"letter.dae",
       [] {
         std::string d = sceneDae();
         d.replace(d.find("<p>0 1 2</p>"), 12, "<p>0 1 x 2</p>");
         return d;
       }(),
       "character 'x'"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.file);
    const fs::path p = dir / c.file;
    writeText(p, c.content);
    auto m = dm::readMesh(p);
    ASSERT_FALSE(m) << "loaded " << m->triangleCount() << " triangles";
    EXPECT_TRUE(mentions(m.error(), p.string())) << m.error();
    EXPECT_TRUE(mentions(m.error(), c.expect)) << m.error();
    auto parts = dm::readMeshes(p);
    EXPECT_FALSE(parts);
  }

  auto missing = dm::readMesh(dir / "missing.stl");
  ASSERT_FALSE(missing);
  EXPECT_EQ(missing.error().code, dm::ErrorCode::NotFound);
  EXPECT_TRUE(mentions(missing.error(), (dir / "missing.stl").string()));
  auto directory = dm::readMesh(dir.path());
  ASSERT_FALSE(directory);
  EXPECT_TRUE(mentions(directory.error(), dir.path().string()));
}

TEST(MeshIo, SizeAndTriangleLimitsAreEnforced) {
  TempDir dir("limits");
  writeText(dir / "cube.obj", cubeObj());
  dm::MeshImportOptions small;
  small.maxFileBytes = 50;
  auto a = dm::readMesh(dir / "cube.obj", small);
  ASSERT_FALSE(a);
  EXPECT_TRUE(mentions(a.error(), "maxFileBytes")) << a.error();
  EXPECT_TRUE(mentions(a.error(), (dir / "cube.obj").string())) << a.error();

  dm::MeshImportOptions few;
  few.maxTriangles = 11;
  auto b = dm::readMesh(dir / "cube.obj", few);
  ASSERT_FALSE(b);
  EXPECT_TRUE(mentions(b.error(), "more than 11 triangles")) << b.error();
  few.maxTriangles = 12;
  EXPECT_TRUE(dm::readMesh(dir / "cube.obj", few));

  // Files a scene refers to (here a glTF buffer) count against the same budget.
  const std::string gltf =
      R"({"asset":{"version":"2.0"},"scene":0,"scenes":[{"nodes":[0]}],"nodes":[{"mesh":0}],
    "meshes":[{"primitives":[{"attributes":{"POSITION":0},"mode":4}]}],
    "buffers":[{"uri":"tri.bin","byteLength":4036}],"bufferViews":[{"buffer":0,"byteOffset":0,"byteLength":36}],
    "accessors":[{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}]})";
  writeText(dir / "tri.gltf", gltf);
  std::string bin(4036, '\0');
  const float corners[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
  std::memcpy(bin.data(), corners, sizeof corners);
  writeText(dir / "tri.bin", bin);
  dm::MeshImportOptions budget;
  budget.maxFileBytes = gltf.size() + 1000;
  auto c = dm::readMesh(dir / "tri.gltf", budget);
  ASSERT_FALSE(c);
  EXPECT_TRUE(mentions(c.error(), "maxFileBytes")) << c.error();
  EXPECT_TRUE(mentions(c.error(), (dir / "tri.gltf").string())) << c.error();
  budget.maxFileBytes = gltf.size() + bin.size();
  auto d = dm::readMesh(dir / "tri.gltf", budget);
  ASSERT_TRUE(d) << d.error();
  EXPECT_EQ(d->triangleCount(), 1u);
  EXPECT_NEAR(d->surfaceArea(), 0.5, 1e-7);
}

TEST(MeshIo, NonManifoldInputLoadsWithAWarning) {
  TempDir dir("nonmanifold");
  // Three triangles on the edge 1-2 (a "book" with three pages).
  writeText(dir / "book.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 -1 0\nv 0 0 1\nf 1 2 3\nf 2 1 4\nf 1 2 5\n");
  std::mutex mu;
  std::vector<std::string> warnings;
  dm::log::setSink([&](dm::log::Level level, std::string_view msg) {
    std::lock_guard lock(mu);
    if (level == dm::log::Level::Warn) warnings.emplace_back(msg);
  });
  auto m = dm::readMesh(dir / "book.obj");
  dm::log::flush();
  dm::log::setSink({});
  ASSERT_TRUE(m) << m.error();
  EXPECT_EQ(m->triangleCount(), 3u);
  EXPECT_EQ(m->vertexCount(), 5u);
  bool found = false;
  for (const auto& w : warnings)
    found = found ||
            (w.find("1 non-manifold edges") != std::string::npos && w.find("book.obj") != std::string::npos);
  EXPECT_TRUE(found) << warnings.size() << " warnings";
}

TEST(MeshIo, ParseMeshFromMemory) {
  const auto obj = bytesOf(cubeObj());
  auto m = dm::parseMesh(obj, "obj");
  ASSERT_TRUE(m) << m.error();
  expectUnitCube(*m);
  auto dotted = dm::parseMesh(obj, ".OBJ");
  ASSERT_TRUE(dotted) << dotted.error();

  const auto stl = bytesOf(cubeStlAscii());
  auto s = dm::parseMesh(stl, "stl");
  ASSERT_TRUE(s) << s.error();
  expectUnitCube(*s);

  auto badHint = dm::parseMesh(obj, "o/bj");
  ASSERT_FALSE(badHint);
  EXPECT_EQ(badHint.error().code, dm::ErrorCode::InvalidArgument);

  auto empty = dm::parseMesh({}, "stl");
  ASSERT_FALSE(empty);
  EXPECT_TRUE(mentions(empty.error(), "<memory>.stl")) << empty.error();

  // A glTF whose buffer is an external file: never opened from memory.
  const std::string gltf =
      R"({"asset":{"version":"2.0"},"scene":0,"scenes":[{"nodes":[0]}],"nodes":[{"mesh":0}],
    "meshes":[{"primitives":[{"attributes":{"POSITION":0}}]}],
    "buffers":[{"uri":"/etc/hostname","byteLength":36}],"bufferViews":[{"buffer":0,"byteLength":36}],
    "accessors":[{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}]})";
  auto g = dm::parseMesh(bytesOf(gltf), "gltf");
  ASSERT_FALSE(g);
  EXPECT_TRUE(mentions(g.error(), "<memory>.gltf")) << g.error();
}

TEST(MeshIo, ExportRejectsWhatCannotBeWritten) {
  TempDir dir("export");
  writeText(dir / "cube.obj", cubeObj());
  auto m = dm::readMesh(dir / "cube.obj");
  ASSERT_TRUE(m) << m.error();

  auto unknown = dm::writeMesh(*m, dir / "cube.xyz");
  ASSERT_FALSE(unknown);
  EXPECT_EQ(unknown.error().code, dm::ErrorCode::Unsupported);
  EXPECT_TRUE(mentions(unknown.error(), (dir / "cube.xyz").string()));

  dm::Mesh nan = *m;
  nan.positions[3].y() = std::nan("");
  auto n = dm::writeMesh(nan, dir / "nan.stl");
  ASSERT_FALSE(n);
  EXPECT_TRUE(mentions(n.error(), "vertex 3")) << n.error();
  EXPECT_TRUE(mentions(n.error(), (dir / "nan.stl").string())) << n.error();
  EXPECT_FALSE(fs::exists(dir / "nan.stl"));

  dm::Mesh empty;
  EXPECT_FALSE(dm::writeMesh(empty, dir / "empty.ply"));

  auto noDir = dm::writeMesh(*m, dir / "no/such/dir/cube.stl");
  ASSERT_FALSE(noDir);
  EXPECT_TRUE(mentions(noDir.error(), "cube.stl")) << noDir.error();
}

// The helper program (the default), a forked child and the caller itself
// import the same meshes, from a file and from memory, and report the same
// errors.
TEST(MeshIo, IsolatedAndInProcessImportsAgree) {
  TempDir dir("isolate");
  writeText(dir / "scene.dae", sceneDae());
  writeText(dir / "nan.obj", "v 0 0 0\nv 1 0 0\nv 0 1 nan\nf 1 2 3\n");
  dm::MeshImportOptions inProcess;
  inProcess.isolation = dm::Isolation::InProcess;
  auto b = dm::readMeshes(dir / "scene.dae", inProcess);
  ASSERT_TRUE(b) << b.error();
  const std::string dae = sceneDae();
  const std::span<const std::byte> daeBytes(reinterpret_cast<const std::byte*>(dae.data()), dae.size());
  dm::MeshImportOptions mergedInProcess = inProcess;
  auto fromMemoryInProcess = dm::parseMesh(daeBytes, "dae", mergedInProcess);
  ASSERT_TRUE(fromMemoryInProcess) << fromMemoryInProcess.error();
  auto d = dm::readMesh(dir / "nan.obj", inProcess);
  ASSERT_FALSE(d);
  for (const dm::Isolation isolation : {dm::Isolation::Helper, dm::Isolation::Fork}) {
    SCOPED_TRACE(dm::toString(isolation));
    dm::MeshImportOptions isolated;
    isolated.isolation = isolation;
    auto a = dm::readMeshes(dir / "scene.dae", isolated);
    ASSERT_TRUE(a) << a.error();
    ASSERT_EQ(a->size(), b->size());
    for (std::size_t i = 0; i < a->size(); ++i) {
      EXPECT_EQ((*a)[i].name, (*b)[i].name);
      EXPECT_EQ((*a)[i].positions, (*b)[i].positions);
      EXPECT_EQ((*a)[i].normals, (*b)[i].normals);
      EXPECT_EQ((*a)[i].triangles, (*b)[i].triangles);
    }
    auto fromMemory = dm::parseMesh(daeBytes, "dae", isolated);
    ASSERT_TRUE(fromMemory) << fromMemory.error();
    EXPECT_EQ(fromMemory->positions, fromMemoryInProcess->positions);
    EXPECT_EQ(fromMemory->triangles, fromMemoryInProcess->triangles);
    // Errors found in the other process come back intact.
    auto c = dm::readMesh(dir / "nan.obj", isolated);
    ASSERT_FALSE(c);
    EXPECT_EQ(c.error().message(), d.error().message());
  }
}

TEST(MeshIo, IsolatedImportIsCutOffAtTheDeadline) {
  DM_REQUIRE_TESTMODELS();
  // This model takes Assimp over a second (subdivision surfaces); 20 ms is
  // far too short, so the child is killed and the deadline reported.
  const fs::path slowModel = kModels / "AC/sample_subdiv.ac";
  dm::MeshImportOptions hurry;
  hurry.timeoutSeconds = 0.02;
  auto m = dm::readMesh(slowModel, hurry);
  ASSERT_FALSE(m);
  EXPECT_EQ(m.error().code, dm::ErrorCode::Timeout) << m.error();
  EXPECT_TRUE(mentions(m.error(), slowModel.string())) << m.error();
  EXPECT_TRUE(mentions(m.error(), "0.02 s")) << m.error();
  // Without the deadline the same file loads.
  auto full = dm::readMesh(slowModel);
  ASSERT_TRUE(full) << full.error();
  EXPECT_GT(full->triangleCount(), 0u);

  dm::MeshImportOptions bad;
  bad.timeoutSeconds = -1;
  EXPECT_FALSE(dm::readMesh(slowModel, bad));
}

TEST(MeshIo, AnAssimpCrashIsContained) {
  // Found by Tests/fuzz/mesh_fuzz.cpp: Assimp 5.2.5's OFF reader dereferences
  // a wild pointer on these 82 bytes (a plain Importer::ReadFile segfaults).
  // Isolated, the import fails with an error and this process carries on.
  const std::string off =
      "OFF\n3 4\n0.1 0.2 0.3\n0.2 0.3  0.3 0.4\n0.3 0.4 0.5\n0\n20.4 40.4\n0.3 0.4 0.5\n0\n20.4 4\n";
  TempDir dir("crash");
  writeText(dir / "crash.off", off);
  auto m = dm::readMesh(dir / "crash.off");
  ASSERT_FALSE(m);
  EXPECT_TRUE(mentions(m.error(), (dir / "crash.off").string())) << m.error();
  EXPECT_TRUE(mentions(m.error(), "Assimp crashed")) << m.error();
  auto p = dm::parseMesh(bytesOf(off), "off");
  ASSERT_FALSE(p);
  EXPECT_TRUE(mentions(p.error(), "<memory>.off")) << p.error();
  EXPECT_TRUE(mentions(p.error(), "Assimp crashed")) << p.error();
}

TEST(MeshIo, SupportedExtensionsComeFromAssimp) {
  const std::string list = dm::supportedMeshExtensions();
  for (const char* e : {"*.stl", "*.obj", "*.ply", "*.off", "*.gltf", "*.glb", "*.dae"})
    EXPECT_NE(list.find(e), std::string::npos) << e << " in " << list;
  EXPECT_TRUE(dm::canReadMesh("a/b/Model.STL"));
  EXPECT_TRUE(dm::canReadMesh("x.glb"));
  EXPECT_FALSE(dm::canReadMesh("notes.txt"));
  EXPECT_FALSE(dm::canReadMesh("noextension"));
}

// ---------------------------------------------------------------------------
// Acceptance: every model of assimp-testmodels either loads with sane numbers
// or fails with a message naming the file; none crashes or hangs.

TEST(MeshIoWalk, EveryAssimpTestModelLoadsOrFailsCleanly) {
  DM_REQUIRE_TESTMODELS();
  const char* slowEnv = std::getenv("DM_SLOW_TESTS");
  const bool slow = slowEnv != nullptr && std::string(slowEnv) == "1";
  constexpr std::uintmax_t kSkipAbove = 5u << 20;  // bytes, unless DM_SLOW_TESTS=1

  std::vector<fs::path> files;
  for (const auto& e :
       fs::recursive_directory_iterator(kModels, fs::directory_options::skip_permission_denied))
    if (e.is_regular_file() && dm::canReadMesh(e.path())) files.push_back(e.path());
  std::sort(files.begin(), files.end());
  ASSERT_GT(files.size(), 100u) << "assimp-testmodels looks incomplete under " << kModels;

  // Warnings about non-manifold test models are expected; keep the output short.
  const dm::log::Level oldLevel = dm::log::level();
  dm::log::setLevel(dm::log::Level::Error);
  std::size_t tried = 0, loaded = 0, failed = 0, skipped = 0, triangles = 0;
  double slowest = 0;
  fs::path slowestFile;
  const auto t0 = std::chrono::steady_clock::now();
  for (const fs::path& f : files) {
    std::error_code ec;
    if (!slow && fs::file_size(f, ec) > kSkipAbove) {
      ++skipped;
      continue;
    }
    ++tried;
    const auto t1 = std::chrono::steady_clock::now();
    auto m = dm::readMesh(f);
    const double dt = std::chrono::duration<double>(std::chrono::steady_clock::now() - t1).count();
    if (dt > slowest) {
      slowest = dt;
      slowestFile = f;
    }
    if (!m) {
      ++failed;
      EXPECT_TRUE(mentions(m.error(), f.string())) << m.error();
      EXPECT_FALSE(m.error().what.empty()) << f;
      continue;
    }
    ++loaded;
    triangles += m->triangleCount();
    EXPECT_GT(m->triangleCount(), 0u) << f;
    EXPECT_TRUE(m->validate()) << f;
    EXPECT_TRUE(m->bounds().min().allFinite() && m->bounds().max().allFinite()) << f;
    EXPECT_TRUE(std::isfinite(m->surfaceArea())) << f;
    EXPECT_TRUE(m->normals.empty() || m->normals.size() == m->vertexCount()) << f;
    for (const dm::Vec3& n : m->normals)
      if (!(std::abs(n.norm() - 1.0) < 1e-6 || n.isZero())) {
        ADD_FAILURE() << f << ": normal of length " << n.norm();
        break;
      }
  }
  dm::log::setLevel(oldLevel);
  const double total = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf(
      "[ walk     ] %zu model files: %zu tried, %zu loaded (%zu triangles), %zu failed cleanly, %zu skipped "
      "(over %ju bytes; DM_SLOW_TESTS=1 walks them), %.1f s, slowest %.2f s (%s)\n",
      files.size(), tried, loaded, triangles, failed, skipped, static_cast<std::uintmax_t>(kSkipAbove), total,
      slowest, slowestFile.string().c_str());
  EXPECT_EQ(tried + skipped, files.size());
  EXPECT_GT(loaded, tried / 2);  // most test models are good
}

}  // namespace

#undef DM_REQUIRE_TESTMODELS
