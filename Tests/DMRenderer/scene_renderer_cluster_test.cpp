// Cluster culling through a DMCollide tree (SceneRenderer::setMeshTree):
// zoomed in on a 160k-triangle sphere, the renderer submits a small share of
// the triangles and the image equals drawing it whole; seen entirely, it
// draws everything; after an in-place deformation that brings other
// triangles into view, the recomputed cluster boxes still draw them; a tree
// of other triangles is refused.
#include <dm/collide/bvh.hpp>
#include <dm/math/primitives.hpp>
#include <dm/renderer/camera.hpp>
#include <dm/renderer/image_compare.hpp>
#include <dm/renderer/render_target.hpp>
#include <dm/renderer/scene_renderer.hpp>

#include <cstdio>

#include "render_fixture.hpp"

namespace {

struct Pair {
  dm::SceneRenderer renderer;
  dm::RenderTarget target;
  dm::MeshId whole, clustered;
  dm::MaterialId material;
};

Pair makePair(const dm::Mesh& mesh) {
  auto r = dm::SceneRenderer::create();
  auto t = dm::RenderTarget::create({.width = 160, .height = 120, .samples = 1});
  EXPECT_TRUE(r && t);
  Pair p{std::move(*r), std::move(*t), {}, {}, {}};
  auto a = p.renderer.addMesh(mesh);
  auto b = p.renderer.addMesh(mesh);
  auto m = p.renderer.addMaterial({.baseColor = dm::Vec4f(0.7f, 0.5f, 0.4f, 1)});
  EXPECT_TRUE(a && b && m);
  p.whole = *a, p.clustered = *b, p.material = *m;
  auto tree = dm::MeshBvh::build(mesh);
  EXPECT_TRUE(tree);
  EXPECT_TRUE(p.renderer.setMeshTree(p.clustered, *tree, 1024));
  return p;
}

// Renders `mesh` alone; returns the image and the stats.
std::pair<dm::Image, dm::RenderStats> draw(Pair& p, dm::MeshId mesh, const dm::Camera& cam) {
  const dm::Light sun = dm::Light::directional({-0.3, -0.5, -1});
  const dm::DrawItem item{.mesh = mesh, .material = p.material};
  auto st = p.renderer.render(p.target, cam, {&item, 1}, {&sun, 1});
  EXPECT_TRUE(st) << st.error();
  auto img = p.target.readColor();
  EXPECT_TRUE(img);
  return {std::move(*img), *st};
}

void expectSameImage(const dm::Image& a, const dm::Image& b) {
  auto diff = dm::compareImages(a, b, {.pixelThreshold = 1, .maxFraction = 0});
  ASSERT_TRUE(diff);
  EXPECT_TRUE(diff->passed) << diff->differing << " pixels differ, max " << diff->maxDifference;
}

TEST(SceneRendererClusters, ZoomedInDrawsAFractionAndTheSameImage) {
  DM_REQUIRE_GL();
  const dm::Mesh sphere = dm::makeUvSphere(1.0, 200, 400);  // 160k triangles
  Pair p = makePair(sphere);
  auto info = p.renderer.meshInfo(p.clustered);
  ASSERT_TRUE(info);
  EXPECT_GE(info->clusters, sphere.triangles.size() / 1024);
  dm::Camera close = dm::Camera::lookAt({0, 0, 1.25}, {0, 0, 0});
  close.fovYDeg = 30;
  close.farPlane = 0.6;  // an endoscope's working range: the far side of the sphere is not in view
  const auto [imgWhole, stWhole] = draw(p, p.whole, close);
  const auto [imgCulled, stCulled] = draw(p, p.clustered, close);
  std::printf("zoomed in: %zu of %zu triangles drawn, %d clusters culled\n", stCulled.triangles,
              stWhole.triangles, stCulled.clustersCulled);
  EXPECT_EQ(stWhole.triangles, sphere.triangles.size());
  EXPECT_LT(stCulled.triangles * 5, stWhole.triangles);
  EXPECT_GT(stCulled.clustersCulled, 0);
  expectSameImage(imgCulled, imgWhole);

  const dm::Camera far = dm::Camera::lookAt({0, 0, 4}, {0, 0, 0});
  const auto [imgAllWhole, stAllWhole] = draw(p, p.whole, far);
  const auto [imgAll, stAll] = draw(p, p.clustered, far);
  EXPECT_EQ(stAll.triangles, sphere.triangles.size());
  EXPECT_EQ(stAll.clustersCulled, 0);
  expectSameImage(imgAll, imgAllWhole);
}

TEST(SceneRendererClusters, InPlaceDeformationKeepsTheClustersRight) {
  DM_REQUIRE_GL();
  dm::Mesh sphere = dm::makeUvSphere(1.0, 100, 200);
  Pair p = makePair(sphere);
  dm::Camera close = dm::Camera::lookAt({0, 0, 1.25}, {0, 0, 0});
  close.fovYDeg = 30;
  close.farPlane = 0.6;
  // Turn the sphere half a turn about y in place: the triangles in view were
  // behind it, so stale cluster boxes would cull them.
  for (dm::Vec3& v : sphere.positions) v = dm::Vec3(-v.x(), v.y(), -v.z());
  sphere.normals.clear();
  ASSERT_TRUE(p.renderer.updateMesh(p.whole, sphere));
  ASSERT_TRUE(p.renderer.updateMesh(p.clustered, sphere));
  auto info = p.renderer.meshInfo(p.clustered);
  ASSERT_TRUE(info);
  EXPECT_EQ(info->inPlaceUpdates, 1);
  EXPECT_GT(info->clusters, 0u);
  const auto [imgWhole, stWhole] = draw(p, p.whole, close);
  const auto [imgCulled, stCulled] = draw(p, p.clustered, close);
  EXPECT_LT(stCulled.triangles * 4, stWhole.triangles);
  expectSameImage(imgCulled, imgWhole);
}

TEST(SceneRendererClusters, TreeOfOtherTrianglesIsRefused) {
  DM_REQUIRE_GL();
  auto r = dm::SceneRenderer::create();
  ASSERT_TRUE(r);
  auto mesh = r->addMesh(dm::makeIcosphere(0.5, 2));
  ASSERT_TRUE(mesh);
  auto other = dm::MeshBvh::build(dm::makeIcosphere(0.5, 3));
  auto sameCountOtherOrder = dm::makeIcosphere(0.5, 2);
  std::swap(sameCountOtherOrder.triangles[0], sameCountOtherOrder.triangles[1]);
  auto shuffled = dm::MeshBvh::build(sameCountOtherOrder);
  ASSERT_TRUE(other && shuffled);
  auto st = r->setMeshTree(*mesh, *other);
  ASSERT_FALSE(st);
  EXPECT_NE(st.error().message().find("triangles"), std::string::npos) << st.error().message();
  EXPECT_FALSE(r->setMeshTree(*mesh, *shuffled));
  auto own = dm::MeshBvh::build(dm::makeIcosphere(0.5, 2));
  ASSERT_TRUE(own);
  EXPECT_FALSE(r->setMeshTree(*mesh, *own, 0));
  EXPECT_TRUE(r->setMeshTree(*mesh, *own, 64));
}

}  // namespace
