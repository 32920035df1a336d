// Primitive meshes against their analytic volume, area and topology.
#include <dm/math/mass_properties.hpp>
#include <dm/math/mesh_topology.hpp>
#include <dm/math/primitives.hpp>

#include <gtest/gtest.h>

#include <numbers>

namespace dm {
namespace {

void expectClosedOriented(const Mesh& m, int genus) {
  const MeshTopology t = analyzeTopology(m);
  EXPECT_TRUE(t.isClosed) << m.name;
  EXPECT_TRUE(t.isManifold) << m.name;
  EXPECT_TRUE(t.isOrientedConsistently) << m.name;
  ASSERT_TRUE(t.genus.has_value()) << m.name;
  EXPECT_EQ(*t.genus, genus) << m.name;
}

TEST(Primitives, BoxIsExact) {
  const Mesh box = makeBox(Vec3(0.1, 0.2, 0.3));
  expectClosedOriented(box, 0);
  auto mp = computeMassProperties(box);
  ASSERT_TRUE(mp) << mp.error();
  EXPECT_NEAR(mp->volume, 0.2 * 0.4 * 0.6, 1e-15);
  EXPECT_NEAR(box.surfaceArea(), 2 * (0.2 * 0.4 + 0.4 * 0.6 + 0.2 * 0.6), 1e-15);
  EXPECT_LT(mp->centroid.norm(), 1e-15);
}

TEST(Primitives, SpheresConvergeToTheBall) {
  const double r = 0.05, ball = 4.0 / 3.0 * std::numbers::pi * r * r * r;
  const Mesh ico = makeIcosphere(r, 4);
  EXPECT_EQ(ico.triangleCount(), 20u * 256u);
  expectClosedOriented(ico, 0);
  for (const Vec3& p : ico.positions) ASSERT_NEAR(p.norm(), r, 1e-15);
  auto v = computeMassProperties(ico);
  ASSERT_TRUE(v);
  EXPECT_LT(v->volume, ball);  // inscribed
  EXPECT_NEAR(v->volume, ball, 0.005 * ball);

  const Mesh uv = makeUvSphere(r, 32, 64);
  EXPECT_EQ(uv.triangleCount(), 2u * 64u * 31u);
  expectClosedOriented(uv, 0);
  auto w = computeMassProperties(uv);
  ASSERT_TRUE(w);
  EXPECT_LT(w->volume, ball);
  EXPECT_NEAR(w->volume, ball, 0.01 * ball);
}

TEST(Primitives, TorusHasGenusOneAndPappusVolume) {
  const double R = 0.3, r = 0.1;
  const Mesh t = makeTorus(R, r, 128, 64);
  EXPECT_EQ(t.triangleCount(), 2u * 128u * 64u);
  expectClosedOriented(t, 1);
  auto mp = computeMassProperties(t);
  ASSERT_TRUE(mp);
  const double pappus = 2 * std::numbers::pi * std::numbers::pi * R * r * r;
  EXPECT_NEAR(mp->volume, pappus, 0.01 * pappus);
  EXPECT_LT(mp->centroid.norm(), 1e-12);
}

}  // namespace
}  // namespace dm
