// SceneRenderer: coverage and photometry against analytic values first
// (sphere discs, Lambert, inverse-square, spot cones, shadow projection,
// stereo disparity), then the queue (in-place updates, instancing, culling,
// LOD), textures, errors, and golden images.
#include <dm/math/primitives.hpp>
#include <dm/renderer/camera.hpp>
#include <dm/renderer/image_compare.hpp>
#include <dm/renderer/render_target.hpp>
#include <dm/renderer/scene_renderer.hpp>

#include <array>
#include <cmath>
#include <numbers>
#include <vector>

#include "render_fixture.hpp"

namespace {

using dm::test::kPi;

using dm::test::srgbToLinear;

// Linear value of channel c at pixel (x, y).
double linearAt(const dm::Image& img, int x, int y, int c = 0) {
  return srgbToLinear(img.at<std::uint8_t>(x, y, c));
}

// A w x h rectangle in the z = 0 plane facing +z; uv (0, 0) at the top-left corner.
dm::Mesh makeQuad(double w, double h) {
  dm::Mesh m;
  m.positions = {{-w / 2, h / 2, 0}, {w / 2, h / 2, 0}, {w / 2, -h / 2, 0}, {-w / 2, -h / 2, 0}};
  m.normals.assign(4, dm::Vec3::UnitZ());
  m.uvs = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
  m.triangles = {{0, 3, 2}, {0, 2, 1}};
  return m;
}

// A box with one set of vertices per face (flat shading).
dm::Mesh makeFlatBox(const dm::Vec3& half) {
  dm::Mesh m;
  for (int axis = 0; axis < 3; ++axis)
    for (int sign = -1; sign <= 1; sign += 2) {
      dm::Vec3 n = dm::Vec3::Zero();
      n[axis] = sign;
      const dm::Vec3 u = dm::Vec3::Unit((axis + 1) % 3) * sign, v = n.cross(u);
      const auto base = static_cast<std::uint32_t>(m.positions.size());
      const double su[4] = {-1, 1, 1, -1}, sv[4] = {-1, -1, 1, 1};
      for (int k = 0; k < 4; ++k) {
        const dm::Vec3 p = n + su[k] * u + sv[k] * v;
        m.positions.push_back(p.cwiseProduct(half));
        m.normals.push_back(n);
        m.uvs.emplace_back(float(su[k] * 0.5 + 0.5), float(0.5 - sv[k] * 0.5));
      }
      m.triangles.push_back({base, base + 1, base + 2});
      m.triangles.push_back({base, base + 2, base + 3});
    }
  return m;
}

dm::Affine3 at(const dm::Vec3& p) {
  dm::Affine3 t = dm::Affine3::Identity();
  t.translation() = p;
  return t;
}

struct Scene {
  dm::SceneRenderer renderer;
  dm::RenderTarget target;
};

Scene makeScene(int w, int h, int samples = 4, int shadowMapSize = 1024) {
  auto r = dm::SceneRenderer::create({.shadowMapSize = shadowMapSize});
  EXPECT_TRUE(r) << r.error();
  auto t = dm::RenderTarget::create({.width = w, .height = h, .samples = samples});
  EXPECT_TRUE(t) << t.error();
  return Scene{std::move(*r), std::move(*t)};
}

dm::Camera orthoFront(double height) {
  dm::Camera c = dm::Camera::lookAt({0, 0, 2}, {0, 0, 0});
  c.projection = dm::Camera::Projection::Orthographic;
  c.orthoHeight = height;
  return c;
}

// Centroid (x) of the pixels of a colour channel above half intensity within [x0, x1).
double centroidX(const dm::Image& img, int channel, int x0, int x1) {
  double sum = 0, n = 0;
  for (int y = 0; y < img.height(); ++y)
    for (int x = x0; x < x1; ++x) {
      const double v = linearAt(img, x, y, channel);
      sum += v * (x + 0.5);
      n += v;
    }
  return n > 0 ? sum / n : -1;
}

using dm::test::kDark;

}  // namespace

TEST(SceneRenderer, SphereCoverageMatchesTheAnalyticDiscInPerspective) {
  DM_REQUIRE_GL();
  Scene s = makeScene(256, 256);
  // Level 4: the inscribed polyhedron's silhouette is within 0.15 % of the sphere's area.
  auto ball = s.renderer.addMesh(dm::makeIcosphere(0.1, 4));
  ASSERT_TRUE(ball) << ball.error();
  auto white = s.renderer.addMaterial({.model = dm::ShadingModel::Unlit, .baseColor = dm::Vec4f(1, 1, 1, 1)});
  ASSERT_TRUE(white);
  const double d = 0.5, r = 0.1, fovY = 40;
  dm::Camera cam = dm::Camera::lookAt({0, 0, d}, {0, 0, 0});
  cam.fovYDeg = fovY;
  const dm::DrawItem item{.mesh = *ball, .material = *white};
  auto st = s.renderer.render(s.target, cam, {&item, 1}, {}, kDark);
  ASSERT_TRUE(st) << st.error();
  EXPECT_EQ(st->drawCalls, 1);
  auto img = s.target.readColor();
  ASSERT_TRUE(img);
  const double f = 128.0 / std::tan(fovY * kPi / 360.0);
  const double rPx = f * std::tan(std::asin(r / d));
  // Threshold 187 counts pixels at least half covered (a linear 0.5 reads 188).
  const double covered = double(dm::countCoveredPixels(*img, dm::Vec3f(0, 0, 0), 187));
  EXPECT_NEAR(covered / (kPi * rPx * rPx), 1.0, 0.01) << covered;
  EXPECT_NEAR(centroidX(*img, 0, 0, 256), 128.0, 0.25);
  EXPECT_EQ(glGetError(), GLenum(GL_NO_ERROR));
}

TEST(SceneRenderer, SphereCoverageMatchesTheAnalyticDiscInOrthographic) {
  DM_REQUIRE_GL();
  Scene s = makeScene(256, 256);
  auto ball = s.renderer.addMesh(dm::makeIcosphere(0.1, 4));
  auto white = s.renderer.addMaterial({.model = dm::ShadingModel::Unlit, .baseColor = dm::Vec4f(1, 1, 1, 1)});
  ASSERT_TRUE(ball && white);
  const dm::Camera cam = orthoFront(0.5);
  const dm::DrawItem item{.mesh = *ball, .material = *white};
  ASSERT_TRUE(s.renderer.render(s.target, cam, {&item, 1}, {}, kDark));
  auto img = s.target.readColor();
  ASSERT_TRUE(img);
  const double ppm = 256 / 0.5;
  const double covered = double(dm::countCoveredPixels(*img, dm::Vec3f(0, 0, 0), 187));
  EXPECT_NEAR(covered / (kPi * 0.1 * 0.1 * ppm * ppm), 1.0, 0.01) << covered;
}

TEST(SceneRenderer, LambertIntensityFollowsCosineOfIncidence) {
  DM_REQUIRE_GL();
  Scene s = makeScene(32, 32, 1);
  auto quad = s.renderer.addMesh(makeQuad(2, 2));
  auto mat = s.renderer.addMaterial({.model = dm::ShadingModel::BlinnPhong,
                                     .baseColor = dm::Vec4f(0.8f, 0.8f, 0.8f, 1),
                                     .specular = dm::Vec3f(0, 0, 0)});
  ASSERT_TRUE(quad && mat);
  const dm::DrawItem item{.mesh = *quad, .material = *mat};
  for (double deg : {0.0, 30.0, 60.0, 75.0}) {
    const double th = deg * kPi / 180;
    const dm::Light sun = dm::Light::directional({-std::sin(th), 0, -std::cos(th)});
    ASSERT_TRUE(s.renderer.render(s.target, orthoFront(1), {&item, 1}, {&sun, 1}, kDark));
    auto img = s.target.readColor();
    ASSERT_TRUE(img);
    const double expected = 0.8 * std::cos(th);
    EXPECT_NEAR(linearAt(*img, 16, 16) / expected, 1.0, 0.02) << deg << " degrees";
  }
}

TEST(SceneRenderer, PbrAtNormalIncidenceMatchesCookTorrance) {
  DM_REQUIRE_GL();
  Scene s = makeScene(32, 32, 1);
  auto quad = s.renderer.addMesh(makeQuad(2, 2));
  ASSERT_TRUE(quad);
  // Light, view and normal aligned: n.l = n.v = n.h = 1, so D = 1/(pi a^2)
  // (a = roughness^2), Smith G = 1, F = F0; radiance = E (kd base + pi F D / 4).
  struct Case {
    float metallic, roughness;
    double expected;
  } cases[] = {{0, 1, 0.96 * 0.5 + 0.04 / 4}, {0, 0.5f, 0.96 * 0.5 + 0.04 / (4 * 0.0625)}, {1, 1, 0.5 / 4}};
  const dm::Light sun = dm::Light::directional({0, 0, -1});
  for (const Case& c : cases) {
    auto mat = s.renderer.addMaterial({.model = dm::ShadingModel::Pbr,
                                       .baseColor = dm::Vec4f(0.5f, 0.5f, 0.5f, 1),
                                       .metallic = c.metallic,
                                       .roughness = c.roughness});
    ASSERT_TRUE(mat);
    const dm::DrawItem item{.mesh = *quad, .material = *mat};
    ASSERT_TRUE(s.renderer.render(s.target, orthoFront(0.01), {&item, 1}, {&sun, 1}, kDark));
    auto img = s.target.readColor();
    ASSERT_TRUE(img);
    EXPECT_NEAR(linearAt(*img, 16, 16) / c.expected, 1.0, 0.02) << c.metallic << ' ' << c.roughness;
  }
}

TEST(SceneRenderer, VertexColoursEmissiveAndWireframe) {
  DM_REQUIRE_GL();
  Scene s = makeScene(64, 64, 1);
  dm::Mesh quad = makeQuad(1, 1);
  quad.colors = {{1, 0, 0, 1}, {0, 1, 0, 1}, {0, 0, 1, 1}, {1, 1, 1, 1}};
  auto id = s.renderer.addMesh(quad);
  auto unlit = s.renderer.addMaterial({.model = dm::ShadingModel::Unlit, .baseColor = dm::Vec4f(1, 1, 1, 1)});
  auto glow = s.renderer.addMaterial({.baseColor = dm::Vec4f(0.5f, 0.5f, 0.5f, 1),
                                      .emissive = dm::Vec3f(0.25f, 0, 0),
                                      .useVertexColors = false});
  ASSERT_TRUE(id && unlit && glow);
  dm::DrawItem item{.mesh = *id, .material = *unlit};
  ASSERT_TRUE(s.renderer.render(s.target, orthoFront(1), {&item, 1}, {}, kDark));
  auto img = s.target.readColor();
  ASSERT_TRUE(img);
  // Corner pixels carry (nearly) the corner vertex colours: top-left red, top-right green.
  EXPECT_GT(linearAt(*img, 0, 0, 0), 0.9);
  EXPECT_LT(linearAt(*img, 0, 0, 1), 0.05);
  EXPECT_GT(linearAt(*img, 63, 0, 1), 0.9);
  EXPECT_GT(linearAt(*img, 63, 63, 2), 0.9);
  // No lights: ambient x base + emissive.
  item.material = *glow;
  const dm::RenderSettings ambient{.ambient = dm::Vec3f(0.2f, 0.2f, 0.2f)};
  ASSERT_TRUE(s.renderer.render(s.target, orthoFront(1), {&item, 1}, {}, ambient));
  img = s.target.readColor();
  ASSERT_TRUE(img);
  EXPECT_NEAR(linearAt(*img, 32, 32, 0), 0.1 + 0.25, 0.01);
  EXPECT_NEAR(linearAt(*img, 32, 32, 1), 0.1, 0.005);
  // Wireframe: only the 5 edges of the two triangles are drawn.
  item.material = *unlit;
  dm::RenderSettings wire = kDark;
  wire.wireframe = true;
  ASSERT_TRUE(s.renderer.render(s.target, orthoFront(2), {&item, 1}, {}, wire));
  img = s.target.readColor();
  ASSERT_TRUE(img);
  const std::size_t lines = dm::countCoveredPixels(*img, dm::Vec3f(0, 0, 0));
  EXPECT_GT(lines, 4u * 28u);
  EXPECT_LT(lines, 32u * 32u / 2);
}

// Blinn-Phong under a directional light 60° off the view axis, against
// ambient·c + emissive + I(c cos θ + s cos(θ/2)^shininess): once with the
// colour c as the material's (the renderer folds base × light on the CPU)
// and once as white × per-vertex colours c (multiplied per fragment).
TEST(SceneRenderer, BlinnPhongMatchesTheFormulaWithPlainAndVertexColours) {
  DM_REQUIRE_GL();
  Scene s = makeScene(64, 64, 1);
  const dm::Vec3f c(0.5f, 0.25f, 1.0f), spec(0.2f, 0.1f, 0.05f), emissive(0.02f, 0, 0);
  dm::Mesh quad = makeQuad(1, 1);
  auto plain = s.renderer.addMesh(quad);
  quad.colors.assign(4, dm::Vec4f(c.x(), c.y(), c.z(), 1));
  auto coloured = s.renderer.addMesh(quad);
  auto plainMat = s.renderer.addMaterial({.baseColor = dm::Vec4f(c.x(), c.y(), c.z(), 1),
                                          .specular = spec, .shininess = 8, .emissive = emissive});
  auto vertexMat = s.renderer.addMaterial(
      {.baseColor = dm::Vec4f(1, 1, 1, 1), .specular = spec, .shininess = 8, .emissive = emissive});
  ASSERT_TRUE(plain && coloured && plainMat && vertexMat);
  const double theta = 60 * kPi / 180, intensity = 0.6, ambient = 0.05;
  const dm::Light sun = dm::Light::directional({-std::sin(theta), 0, -std::cos(theta)}, float(intensity));
  const dm::RenderSettings settings{.background = dm::Vec4f(0, 0, 0, 1),
                                    .ambient = dm::Vec3f::Constant(float(ambient))};
  const dm::DrawItem items[2] = {{.mesh = *plain, .material = *plainMat},
                                 {.mesh = *coloured, .material = *vertexMat}};
  double got[2][3];
  for (int k = 0; k < 2; ++k) {
    ASSERT_TRUE(s.renderer.render(s.target, orthoFront(0.5), {&items[k], 1}, {&sun, 1}, settings));
    auto img = s.target.readColor();
    ASSERT_TRUE(img);
    for (int ch = 0; ch < 3; ++ch) got[k][ch] = linearAt(*img, 32, 32, ch);
  }
  const double specTerm = std::pow(std::cos(theta / 2), 8.0);
  for (int ch = 0; ch < 3; ++ch) {
    const double want = ambient * c[ch] + emissive[ch] + intensity * (c[ch] * std::cos(theta) + spec[ch] * specTerm);
    EXPECT_NEAR(got[0][ch], want, 0.01 * want + 0.002) << "plain, channel " << ch;
    EXPECT_NEAR(got[1][ch], want, 0.01 * want + 0.002) << "vertex colours, channel " << ch;
  }
}

TEST(SceneRenderer, PointLightFallsOffWithInverseSquare) {
  DM_REQUIRE_GL();
  Scene s = makeScene(32, 32, 1);
  auto quad = s.renderer.addMesh(makeQuad(2, 2));
  auto mat = s.renderer.addMaterial({.baseColor = dm::Vec4f(1, 1, 1, 1), .specular = dm::Vec3f(0, 0, 0)});
  ASSERT_TRUE(quad && mat);
  const dm::DrawItem item{.mesh = *quad, .material = *mat};
  double value[2];
  const double h[2] = {0.5, 1.0};
  for (int i = 0; i < 2; ++i) {
    const dm::Light lamp = dm::Light::point({0, 0, h[i]}, 0.2f, 100);
    ASSERT_TRUE(s.renderer.render(s.target, orthoFront(0.1), {&item, 1}, {&lamp, 1}, kDark));
    auto img = s.target.readColor();
    ASSERT_TRUE(img);
    value[i] = linearAt(*img, 16, 16);
    EXPECT_NEAR(value[i] / (0.2 / (h[i] * h[i])), 1.0, 0.03) << h[i];
  }
  EXPECT_NEAR(value[0] / value[1], 4.0, 0.08);
}

TEST(SceneRenderer, SpotLightConeEdgesLandAtTheExpectedRadius) {
  DM_REQUIRE_GL();
  Scene s = makeScene(256, 256, 1);
  auto quad = s.renderer.addMesh(makeQuad(2, 2));
  auto mat = s.renderer.addMaterial({.baseColor = dm::Vec4f(1, 1, 1, 1), .specular = dm::Vec3f(0, 0, 0)});
  ASSERT_TRUE(quad && mat);
  const dm::DrawItem item{.mesh = *quad, .material = *mat};
  const double h = 0.5, I = 0.2;
  const dm::Light spot = dm::Light::spot({0, 0, h}, {0, 0, -1}, 18, 22, float(I), 100);
  ASSERT_TRUE(s.renderer.render(s.target, orthoFront(1), {&item, 1}, {&spot, 1}, kDark));
  auto img = s.target.readColor();
  ASSERT_TRUE(img);
  const double ppm = 256;
  // Lit at 16° off axis: I cos³θ / h² (inverse square and incidence).
  for (int sign : {-1, 1}) {
    const double r16 = h * std::tan(16 * kPi / 180), r24 = h * std::tan(24 * kPi / 180);
    const int xIn = int(std::lround(128 + sign * r16 * ppm - 0.5));
    const int xOut = int(std::lround(128 + sign * r24 * ppm - 0.5));
    const double c16 = std::cos(16 * kPi / 180);
    EXPECT_NEAR(linearAt(*img, xIn, 128) / (I * c16 * c16 * c16 / (h * h)), 1.0, 0.04);
    EXPECT_LT(linearAt(*img, xOut, 128), 1e-3);
    EXPECT_LT(linearAt(*img, 128, int(std::lround(128 + sign * r24 * ppm - 0.5))), 1e-3);
  }
}

TEST(SceneRenderer, ShadowCentreLandsAtTheProjectedPixel) {
  DM_REQUIRE_GL();
  Scene s = makeScene(128, 128, 4, 1024);
  dm::Mesh ground = makeQuad(2, 2);
  ground.transform(dm::Affine3(dm::AngleAxis(-kPi / 2, dm::Vec3::UnitX())));  // now facing +y
  auto plane = s.renderer.addMesh(ground);
  auto ball = s.renderer.addMesh(dm::makeIcosphere(0.05, 3));
  auto mat = s.renderer.addMaterial({.baseColor = dm::Vec4f(1, 1, 1, 1), .specular = dm::Vec3f(0, 0, 0)});
  ASSERT_TRUE(plane && ball && mat);
  const dm::DrawItem items[] = {{.mesh = *plane, .material = *mat},
                                {.mesh = *ball, .material = *mat, .model = at({0, 0.3, 0})}};
  const dm::Vec3 dir = dm::Vec3(0.5, -1, 0).normalized();
  dm::Light sun = dm::Light::directional(dir, 0.8f);
  sun.castsShadow = true;
  dm::Camera cam = dm::Camera::lookAt({0, 2, 0}, {0, 0, 0}, {0, 0, -1});
  cam.projection = dm::Camera::Projection::Orthographic;
  cam.orthoHeight = 1;
  const dm::RenderSettings settings{.ambient = dm::Vec3f(0.1f, 0.1f, 0.1f)};
  auto st = s.renderer.render(s.target, cam, items, {&sun, 1}, settings);
  ASSERT_TRUE(st) << st.error();
  EXPECT_EQ(st->shadowMaps, 1);
  auto img = s.target.readColor();
  ASSERT_TRUE(img);
  const dm::Mat4f vp = cam.projectionMatrix(1) * cam.viewMatrix();
  auto valueAt = [&](const dm::Vec3& world) {
    dm::Vec3 px;
    EXPECT_TRUE(dm::projectToPixel(vp, world, 128, 128, px));
    return linearAt(*img, int(px.x()), int(px.y()));
  };
  // The ray through the sphere centre along the light meets y = 0 at x = 0.3 * 0.5.
  const double lit = 0.1 + 0.8 * (-dir.y());  // ambient + Lambert on the plane
  const double shadowed = 0.1;
  EXPECT_NEAR(valueAt({0.15, 0, 0}), shadowed, 0.02);
  EXPECT_NEAR(valueAt({0.15, 0, 0.03}), shadowed, 0.02);
  EXPECT_NEAR(valueAt({0.15, 0, 0.09}), lit, 0.03 * lit);
  EXPECT_NEAR(valueAt({0.15, 0, -0.09}), lit, 0.03 * lit);
  EXPECT_NEAR(valueAt({-0.3, 0, 0}), lit, 0.03 * lit);
  EXPECT_NEAR(valueAt({0.3, 0, 0}), lit, 0.03 * lit);
}

TEST(SceneRenderer, StereoDisparityIsZeroAtConvergenceAndAsPredictedNearer) {
  DM_REQUIRE_GL();
  Scene s = makeScene(256, 128);
  auto ball = s.renderer.addMesh(dm::makeIcosphere(1, 3));
  auto red = s.renderer.addMaterial({.model = dm::ShadingModel::Unlit, .baseColor = dm::Vec4f(1, 0, 0, 1)});
  auto green = s.renderer.addMaterial({.model = dm::ShadingModel::Unlit, .baseColor = dm::Vec4f(0, 1, 0, 1)});
  ASSERT_TRUE(ball && red && green);
  const double c = 0.5, zNear = 0.3, e = 0.03, fovY = 40;
  dm::Affine3 farT = at({0, 0.04, -c}), nearT = at({0, -0.02, -zNear});
  farT.linear() *= 0.012;
  nearT.linear() *= 0.008;
  const dm::DrawItem items[] = {{.mesh = *ball, .material = *red, .model = farT},
                                {.mesh = *ball, .material = *green, .model = nearT}};
  dm::Camera cam = dm::Camera::lookAt({0, 0, 0}, {0, 0, -1});
  cam.fovYDeg = fovY;
  auto st = s.renderer.renderStereo(s.target, cam, e, c, items, {}, kDark);
  ASSERT_TRUE(st) << st.error();
  EXPECT_EQ(st->instances, 4);
  auto img = s.target.readColor();
  ASSERT_TRUE(img);
  const double redL = centroidX(*img, 0, 0, 128), redR = centroidX(*img, 0, 128, 256) - 128;
  EXPECT_NEAR(redL - redR, 0.0, 0.2);
  EXPECT_NEAR(redL, 64.0, 0.3);
  const double f = 64 / std::tan(fovY * kPi / 360);
  const double predicted = f * e * (1 / zNear - 1 / c);  // crossed: left image further right
  const double greenL = centroidX(*img, 1, 0, 128), greenR = centroidX(*img, 1, 128, 256) - 128;
  EXPECT_GT(predicted, 5.0);
  EXPECT_NEAR(greenL - greenR, predicted, 0.3);
}

TEST(SceneRenderer, UpdateMeshInPlaceChangesCoverageWithoutReupload) {
  DM_REQUIRE_GL();
  Scene s = makeScene(128, 128);
  dm::Mesh quad = makeQuad(0.5, 0.5);
  quad.normals.clear();  // computed on upload; the caller's mesh stays as it is
  auto id = s.renderer.addMesh(quad);
  auto mat = s.renderer.addMaterial({.model = dm::ShadingModel::Unlit, .baseColor = dm::Vec4f(1, 1, 1, 1)});
  ASSERT_TRUE(id && mat);
  EXPECT_TRUE(quad.normals.empty());
  const dm::DrawItem item{.mesh = *id, .material = *mat};
  auto coverage = [&] {
    EXPECT_TRUE(s.renderer.render(s.target, orthoFront(1), {&item, 1}, {}, kDark));
    auto img = s.target.readColor();
    return img ? dm::countCoveredPixels(*img, dm::Vec3f(0, 0, 0), 187) : 0;
  };
  EXPECT_NEAR(double(coverage()), 64.0 * 64.0, 1);
  const auto before = *s.renderer.meshInfo(*id);
  EXPECT_EQ(before.uploads, 1);
  for (dm::Vec3& p : quad.positions) p *= 0.5;  // 0.25 m square: 32 x 32 px
  ASSERT_TRUE(s.renderer.updateMesh(*id, quad));
  EXPECT_NEAR(double(coverage()), 32.0 * 32.0, 1);
  const auto after = *s.renderer.meshInfo(*id);
  EXPECT_EQ(after.uploads, 1);
  EXPECT_EQ(after.inPlaceUpdates, 1);
  EXPECT_EQ(after.vertexBuffer, before.vertexBuffer);
  EXPECT_NEAR(after.bounds.max().x(), 0.125, 1e-12);
  quad.triangles.pop_back();  // topology change: half the square, re-uploaded
  ASSERT_TRUE(s.renderer.updateMesh(*id, quad));
  EXPECT_NEAR(double(coverage()), 32.0 * 32.0 / 2, 40);
  EXPECT_EQ(s.renderer.meshInfo(*id)->uploads, 2);
  EXPECT_EQ(s.renderer.meshInfo(*id)->triangleCount, 1u);
}

TEST(SceneRenderer, InstancesShareOneDrawCallAndMatchSeparateDraws) {
  DM_REQUIRE_GL();
  Scene s = makeScene(128, 128);
  auto box = s.renderer.addMesh(makeFlatBox({0.02, 0.02, 0.02}));
  ASSERT_TRUE(box);
  const dm::Material look{.baseColor = dm::Vec4f(0.2f, 0.6f, 0.9f, 1)};
  std::vector<dm::DrawItem> shared, separate;
  const auto one = s.renderer.addMaterial(look);
  ASSERT_TRUE(one);
  for (int i = 0; i < 100; ++i) {
    dm::Affine3 t = at({-0.45 + 0.1 * (i % 10), -0.45 + 0.1 * (i / 10), 0});
    t.rotate(dm::AngleAxis(0.1 * i, dm::Vec3(1, 1, 0).normalized()));
    shared.push_back({.mesh = *box, .material = *one, .model = t});
    auto own = s.renderer.addMaterial(look);  // same look, different material: no instancing
    ASSERT_TRUE(own);
    separate.push_back({.mesh = *box, .material = *own, .model = t});
  }
  const dm::Light sun = dm::Light::directional({-0.3, -0.5, -1});
  dm::Camera cam = dm::Camera::lookAt({0, 0, 2}, {0, 0, 0});
  cam.fovYDeg = 30;
  auto a = s.renderer.render(s.target, cam, shared, {&sun, 1});
  ASSERT_TRUE(a) << a.error();
  EXPECT_EQ(a->drawCalls, 1);
  EXPECT_EQ(a->instances, 100);
  EXPECT_EQ(a->triangles, 1200u);
  EXPECT_EQ(s.renderer.lastStats().drawCalls, 1);
  auto imgA = s.target.readColor();
  auto b = s.renderer.render(s.target, cam, separate, {&sun, 1});
  ASSERT_TRUE(b);
  EXPECT_EQ(b->drawCalls, 100);
  auto imgB = s.target.readColor();
  ASSERT_TRUE(imgA && imgB);
  auto diff = dm::compareImages(*imgA, *imgB, {.pixelThreshold = 0, .maxFraction = 0});
  ASSERT_TRUE(diff);
  EXPECT_TRUE(diff->passed) << diff->differing;
  EXPECT_GT(dm::countCoveredPixels(*imgA, dm::Vec3f(0, 0, 0)), 1000u);
}

TEST(SceneRenderer, ItemsOutsideTheFrustumAreCulledWithoutChangingThePicture) {
  DM_REQUIRE_GL();
  Scene s = makeScene(96, 96);
  auto ball = s.renderer.addMesh(dm::makeIcosphere(0.1, 2));
  auto mat = s.renderer.addMaterial({});
  ASSERT_TRUE(ball && mat);
  const dm::Light sun = dm::Light::directional({0, -1, -1});
  const dm::Camera cam = dm::Camera::lookAt({0, 0, 1}, {0, 0, 0});
  std::vector<dm::DrawItem> items = {{.mesh = *ball, .material = *mat}};
  auto alone = s.renderer.render(s.target, cam, items, {&sun, 1});
  ASSERT_TRUE(alone);
  EXPECT_EQ(alone->itemsCulled, 0);
  auto imgAlone = s.target.readColor();
  items.push_back({.mesh = *ball, .material = *mat, .model = at({0, 0, 2})});    // behind the eye
  items.push_back({.mesh = *ball, .material = *mat, .model = at({0, 0, 1.5})});  // behind the eye
  items.push_back({.mesh = *ball, .material = *mat, .model = at({3, 0, 0})});    // far right
  items.push_back({.mesh = *ball, .material = *mat, .model = at({0, 0, 0.3}), .visible = false});
  auto more = s.renderer.render(s.target, cam, items, {&sun, 1});
  ASSERT_TRUE(more);
  EXPECT_EQ(more->itemsCulled, 3);
  EXPECT_EQ(more->instances, 1);
  auto imgMore = s.target.readColor();
  ASSERT_TRUE(imgAlone && imgMore);
  auto diff = dm::compareImages(*imgMore, *imgAlone, {.pixelThreshold = 0, .maxFraction = 0});
  ASSERT_TRUE(diff);
  EXPECT_TRUE(diff->passed);
}

TEST(SceneRenderer, LodSwitchesWithProjectedSize) {
  DM_REQUIRE_GL();
  Scene s = makeScene(64, 64);
  auto fine = s.renderer.addMesh(dm::makeIcosphere(0.05, 3));    // 1280 triangles
  auto coarse = s.renderer.addMesh(dm::makeIcosphere(0.05, 1));  // 80
  auto mat = s.renderer.addMaterial({});
  ASSERT_TRUE(fine && coarse && mat);
  ASSERT_TRUE(s.renderer.setLods(*fine, {{*coarse, 0.1}}));
  dm::Camera cam = dm::Camera::lookAt({0, 0, 0}, {0, 0, -1});
  cam.fovYDeg = 40;
  // Projected diameter / height = r / (d tan(fov/2)): 0.1 at d = 1.37 m.
  for (const auto& [d, tris] :
       {std::pair{0.5, 1280u}, std::pair{1.3, 1280u}, std::pair{1.45, 80u}, std::pair{3.0, 80u}}) {
    const dm::DrawItem item{.mesh = *fine, .material = *mat, .model = at({0, 0, -d})};
    auto st = s.renderer.render(s.target, cam, {&item, 1}, {});
    ASSERT_TRUE(st);
    EXPECT_EQ(st->triangles, tris) << d;
    EXPECT_EQ(st->lodSwitches, tris == 80u ? 1 : 0);
  }
  EXPECT_FALSE(s.renderer.setLods(*fine, {{*coarse, 0}}));
  EXPECT_FALSE(s.renderer.setLods(*fine, {{*fine, 0.1}}));
}

TEST(SceneRenderer, CheckerTextureLandsOnTheExpectedPixelsAlsoFromAStridedView) {
  DM_REQUIRE_GL();
  Scene s = makeScene(128, 128, 1);
  auto quad = s.renderer.addMesh(makeQuad(1, 1));
  ASSERT_TRUE(quad);
  auto cell = [](int i, int j) { return (i + j) % 2 == 0; };
  auto fill = [&](dm::Image& img, int x0, int y0) {
    for (int y = 0; y < 64; ++y)
      for (int x = 0; x < 64; ++x) {
        const bool on = cell(x / 8, y / 8);
        img.at<std::uint8_t>(x0 + x, y0 + y, 0) = on ? 230 : 20;
        img.at<std::uint8_t>(x0 + x, y0 + y, 1) =
            std::uint8_t(40 + 20 * (y / 8));  // rows tell top from bottom
        img.at<std::uint8_t>(x0 + x, y0 + y, 2) = on ? 10 : 200;
      }
  };
  auto packed = dm::Image::create(64, 64, 3, dm::PixelType::U8);
  auto big = dm::Image::create(101, 90, 3, dm::PixelType::U8);
  ASSERT_TRUE(packed && big);
  fill(*packed, 0, 0);
  fill(*big, 13, 7);
  const dm::Image view = big->view(13, 7, 64, 64);
  ASSERT_FALSE(view.isContiguous());
  dm::Image results[2];
  for (int k = 0; k < 2; ++k) {
    auto tex = s.renderer.addTexture(k == 0 ? *packed : view, true);
    ASSERT_TRUE(tex) << tex.error();
    auto mat = s.renderer.addMaterial(
        {.model = dm::ShadingModel::Unlit, .baseColor = dm::Vec4f(1, 1, 1, 1), .colorTexture = *tex});
    ASSERT_TRUE(mat);
    const dm::DrawItem item{.mesh = *quad, .material = *mat};
    ASSERT_TRUE(s.renderer.render(s.target, orthoFront(1), {&item, 1}, {}, kDark));
    auto img = s.target.readColor();
    ASSERT_TRUE(img);
    // The 1 m quad fills the 1 m view: texel (u, v) at pixel (2u, 2v); cell centres 16 px apart.
    for (int j = 0; j < 8; ++j)
      for (int i = 0; i < 8; ++i) {
        const int px = 16 * i + 8, py = 16 * j + 8;
        EXPECT_NEAR(img->at<std::uint8_t>(px, py, 0), cell(i, j) ? 230 : 20, 1) << i << ',' << j;
        EXPECT_NEAR(img->at<std::uint8_t>(px, py, 1), 40 + 20 * j, 1) << i << ',' << j;
        EXPECT_NEAR(img->at<std::uint8_t>(px, py, 2), cell(i, j) ? 10 : 200, 1) << i << ',' << j;
      }
    results[k] = *img;
  }
  auto diff = dm::compareImages(results[0], results[1], {.pixelThreshold = 0, .maxFraction = 0});
  ASSERT_TRUE(diff);
  EXPECT_TRUE(diff->passed);
}

TEST(SceneRenderer, NormalMapTiltsTheShadingNormalAlongTheUvTangentFrame) {
  DM_REQUIRE_GL();
  Scene s = makeScene(32, 32, 1);
  auto quad = s.renderer.addMesh(makeQuad(1, 1));  // u along +x, v along -y (v = 0 at the top)
  ASSERT_TRUE(quad);
  const double alpha = 30 * kPi / 180;
  // Tangent-space normal tilted by alpha towards +u, then towards +v.
  const dm::Vec3 tilts[2] = {{std::sin(alpha), 0, std::cos(alpha)}, {0, std::sin(alpha), std::cos(alpha)}};
  // The world normals they should become: +u is +x, +v is -y.
  const dm::Vec3 world[2] = {{std::sin(alpha), 0, std::cos(alpha)}, {0, -std::sin(alpha), std::cos(alpha)}};
  for (int k = 0; k < 2; ++k) {
    auto map = dm::Image::create(4, 4, 3, dm::PixelType::U8);
    ASSERT_TRUE(map);
    for (int y = 0; y < 4; ++y)
      for (int x = 0; x < 4; ++x)
        for (int c = 0; c < 3; ++c)
          map->at<std::uint8_t>(x, y, c) = std::uint8_t(std::lround((tilts[k][c] * 0.5 + 0.5) * 255));
    auto tex = s.renderer.addTexture(*map, false);
    ASSERT_TRUE(tex);
    auto mat = s.renderer.addMaterial(
        {.baseColor = dm::Vec4f(0.8f, 0.8f, 0.8f, 1), .specular = dm::Vec3f(0, 0, 0), .normalTexture = *tex});
    ASSERT_TRUE(mat);
    const dm::DrawItem item{.mesh = *quad, .material = *mat};
    // Light along the tilted normal: full Lambert; along the mirrored tilt: cos(2 alpha).
    for (int mirror = 0; mirror < 2; ++mirror) {
      dm::Vec3 toLight = world[k];
      if (mirror == 1) toLight.head<2>() *= -1;
      const dm::Light sun = dm::Light::directional(-toLight);
      ASSERT_TRUE(s.renderer.render(s.target, orthoFront(1), {&item, 1}, {&sun, 1}, kDark));
      auto img = s.target.readColor();
      ASSERT_TRUE(img);
      const double expected = 0.8 * (mirror == 0 ? 1.0 : std::cos(2 * alpha));
      EXPECT_NEAR(linearAt(*img, 16, 16) / expected, 1.0, 0.03) << "tilt " << k << " mirror " << mirror;
    }
  }
}

TEST(SceneRenderer, GrayTextureIsReplicatedToRgb) {
  DM_REQUIRE_GL();
  Scene s = makeScene(16, 16, 1);
  auto gray = dm::Image::create(4, 4, 1, dm::PixelType::U8);
  ASSERT_TRUE(gray);
  for (int y = 0; y < 4; ++y)
    for (int x = 0; x < 4; ++x) gray->at<std::uint8_t>(x, y) = 150;
  auto tex = s.renderer.addTexture(*gray, true);
  auto quad = s.renderer.addMesh(makeQuad(1, 1));
  ASSERT_TRUE(tex && quad);
  auto mat = s.renderer.addMaterial(
      {.model = dm::ShadingModel::Unlit, .baseColor = dm::Vec4f(1, 1, 1, 1), .colorTexture = *tex});
  ASSERT_TRUE(mat);
  const dm::DrawItem item{.mesh = *quad, .material = *mat};
  ASSERT_TRUE(s.renderer.render(s.target, orthoFront(1), {&item, 1}, {}, kDark));
  auto img = s.target.readColor();
  ASSERT_TRUE(img);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(img->at<std::uint8_t>(8, 8, c), 150, 1);
}

TEST(SceneRenderer, BgrVideoTextureSamplesAsRgbAndUpdatesInPlaceOrOnResize) {
  DM_REQUIRE_GL();
  Scene s = makeScene(32, 32, 1);
  auto quad = s.renderer.addMesh(makeQuad(1, 1));
  ASSERT_TRUE(quad);
  // A frame as OpenCV delivers it: bytes B, G, R; the left half of each row differs from the right.
  auto frame = [](int w, int h, std::array<int, 3> leftRgb, std::array<int, 3> rightRgb) {
    auto img = dm::Image::create(w, h, 3, dm::PixelType::U8);
    EXPECT_TRUE(img);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        const auto& rgb = x < w / 2 ? leftRgb : rightRgb;
        for (int c = 0; c < 3; ++c) img->at<std::uint8_t>(x, y, c) = std::uint8_t(rgb[2 - c]);
      }
    return *img;
  };
  auto expectHalves = [&](std::array<int, 3> leftRgb, std::array<int, 3> rightRgb, const char* what) {
    auto img = s.target.readColor();
    ASSERT_TRUE(img);
    for (int c = 0; c < 3; ++c) {
      EXPECT_NEAR(img->at<std::uint8_t>(8, 16, c), leftRgb[c], 1) << what << " left, channel " << c;
      EXPECT_NEAR(img->at<std::uint8_t>(24, 16, c), rightRgb[c], 1) << what << " right, channel " << c;
    }
  };
  auto tex = s.renderer.addTexture(frame(16, 16, {230, 120, 10}, {30, 60, 200}), {.bgr = true, .mipmaps = false});
  ASSERT_TRUE(tex) << tex.error();
  auto mat = s.renderer.addMaterial(
      {.model = dm::ShadingModel::Unlit, .baseColor = dm::Vec4f(1, 1, 1, 1), .colorTexture = *tex});
  ASSERT_TRUE(mat);
  const dm::DrawItem item{.mesh = *quad, .material = *mat};
  ASSERT_TRUE(s.renderer.render(s.target, orthoFront(1), {&item, 1}, {}, kDark));
  expectHalves({230, 120, 10}, {30, 60, 200}, "first frame");

  // The next frame, same size: rewritten in place under the same id and material.
  ASSERT_TRUE(s.renderer.updateTexture(*tex, frame(16, 16, {90, 200, 140}, {250, 250, 0})));
  ASSERT_TRUE(s.renderer.render(s.target, orthoFront(1), {&item, 1}, {}, kDark));
  expectHalves({90, 200, 140}, {250, 250, 0}, "same-size update");

  // A resized stream (and a strided view of it): new storage, same id, order kept.
  auto wide = frame(40, 10, {0, 0, 255}, {255, 0, 0});
  ASSERT_TRUE(s.renderer.updateTexture(*tex, wide.view(0, 0, 40, 10)));
  ASSERT_TRUE(s.renderer.render(s.target, orthoFront(1), {&item, 1}, {}, kDark));
  expectHalves({0, 0, 255}, {255, 0, 0}, "resized update");

  // Bad frames fail with a message and leave the texture as it was.
  auto f32 = dm::Image::create(40, 10, 3, dm::PixelType::F32);
  ASSERT_TRUE(f32);
  auto bad = s.renderer.updateTexture(*tex, *f32);
  ASSERT_FALSE(bad);
  EXPECT_EQ(bad.error().code, dm::ErrorCode::Unsupported);
  EXPECT_EQ(s.renderer.updateTexture(*tex, dm::Image()).error().code, dm::ErrorCode::InvalidArgument);
  ASSERT_TRUE(s.renderer.render(s.target, orthoFront(1), {&item, 1}, {}, kDark));
  expectHalves({0, 0, 255}, {255, 0, 0}, "after refused updates");
  ASSERT_TRUE(s.renderer.removeTexture(*tex));
  EXPECT_EQ(s.renderer.updateTexture(*tex, wide).error().code, dm::ErrorCode::NotFound);
}

TEST(SceneRenderer, BadInputFailsWithAMessageAndDrawsNothing) {
  DM_REQUIRE_GL();
  Scene s = makeScene(16, 16, 1);
  auto ball = s.renderer.addMesh(dm::makeIcosphere(0.1, 1));
  auto mat = s.renderer.addMaterial({});
  ASSERT_TRUE(ball && mat);
  ASSERT_TRUE(s.renderer.removeMesh(*ball));
  EXPECT_EQ(s.renderer.removeMesh(*ball).error().code, dm::ErrorCode::NotFound);
  const dm::DrawItem item{.mesh = *ball, .material = *mat};
  auto stale = s.renderer.render(s.target, orthoFront(1), {&item, 1}, {});
  ASSERT_FALSE(stale);
  EXPECT_EQ(stale.error().where, "items[0].mesh");
  auto again = s.renderer.addMesh(dm::makeIcosphere(0.1, 1));  // reuses the slot, new generation
  ASSERT_TRUE(again);
  EXPECT_EQ(again->index, ball->index);
  EXPECT_FALSE(s.renderer.meshInfo(*ball));
  const std::vector<dm::Light> nine(9, dm::Light::directional({0, 0, -1}));
  EXPECT_FALSE(s.renderer.render(s.target, orthoFront(1), {}, nine));
  dm::Light badSpot = dm::Light::spot({0, 0, 1}, {0, 0, -1}, 30, 20);
  auto cone = s.renderer.render(s.target, orthoFront(1), {}, {&badSpot, 1});
  ASSERT_FALSE(cone);
  EXPECT_EQ(cone.error().where, "lights[0].outerConeDeg");
  dm::Mesh broken = dm::makeIcosphere(0.1, 0);
  broken.triangles[3][1] = 999;
  EXPECT_FALSE(s.renderer.addMesh(broken));
  EXPECT_FALSE(s.renderer.addMesh(dm::Mesh{}));
  auto f32 = dm::Image::create(4, 4, 1, dm::PixelType::F32);
  ASSERT_TRUE(f32);
  EXPECT_EQ(s.renderer.addTexture(*f32).error().code, dm::ErrorCode::Unsupported);
  EXPECT_FALSE(s.renderer.addMaterial({.roughness = 2}));
  EXPECT_FALSE(s.renderer.addMaterial({.colorTexture = dm::TextureId{5, 1}}));
  EXPECT_FALSE(dm::SceneRenderer::create({.shadowMapSize = 16}));
  EXPECT_EQ(glGetError(), GLenum(GL_NO_ERROR));
}

// ---- golden images (each paired with the analytic checks above) ----

namespace {

void expectGolden(const dm::Image& img, const char* name) {
  auto r = dm::checkGolden(img, dm::test::goldenDir() / name, dm::test::renderOutDir(),
                           {.pixelThreshold = 12, .maxFraction = 0.005});
  EXPECT_TRUE(r) << r.error();
}

struct ShowcaseScene {
  std::vector<dm::DrawItem> items;
  std::vector<dm::Light> lights;
};

// A lit box, sphere and torus on a ground plane.
ShowcaseScene makeShowcase(dm::SceneRenderer& r) {
  ShowcaseScene sc;
  dm::Mesh ground = makeQuad(1.2, 1.2);
  ground.transform(dm::Affine3(dm::AngleAxis(-kPi / 2, dm::Vec3::UnitX())));
  const auto groundMat =
      *r.addMaterial({.baseColor = dm::Vec4f(0.5f, 0.5f, 0.45f, 1), .specular = dm::Vec3f(0, 0, 0)});
  const auto red = *r.addMaterial({.baseColor = dm::Vec4f(0.7f, 0.1f, 0.08f, 1), .shininess = 64});
  const auto blue = *r.addMaterial({.baseColor = dm::Vec4f(0.1f, 0.25f, 0.7f, 1), .shininess = 16});
  const auto gold = *r.addMaterial({.baseColor = dm::Vec4f(0.8f, 0.6f, 0.1f, 1), .shininess = 128});
  dm::Affine3 torus = at({0.22, 0.06, 0.05});
  torus.rotate(dm::AngleAxis(-kPi / 2.5, dm::Vec3::UnitX()));
  dm::Affine3 box = at({-0.22, 0.08, 0});
  box.rotate(dm::AngleAxis(0.5, dm::Vec3::UnitY()));
  sc.items = {
      {.mesh = *r.addMesh(ground), .material = groundMat},
      {.mesh = *r.addMesh(makeFlatBox({0.08, 0.08, 0.08})), .material = red, .model = box},
      {.mesh = *r.addMesh(dm::makeIcosphere(0.09, 3)), .material = blue, .model = at({0, 0.09, -0.12})},
      {.mesh = *r.addMesh(dm::makeTorus(0.07, 0.025, 48, 16)), .material = gold, .model = torus}};
  dm::Light sun = dm::Light::directional({-0.6, -0.7, 0.45}, 0.9f);
  sun.castsShadow = true;
  sc.lights = {sun, dm::Light::point({0.3, 0.4, 0.4}, 0.15f, 3, dm::Vec3f(1, 0.9f, 0.8f))};
  return sc;
}

dm::Camera showcaseCamera() {
  dm::Camera cam = dm::Camera::lookAt({0.1, 0.45, 0.75}, {0, 0.05, 0});
  cam.fovYDeg = 40;
  return cam;
}

const dm::RenderSettings kShowcaseSettings{.background = dm::Vec4f(0.05f, 0.06f, 0.08f, 1),
                                           .ambient = dm::Vec3f(0.08f, 0.08f, 0.1f)};

}  // namespace

TEST(SceneRendererGolden, BlinnPhongBoxSphereTorus) {
  DM_REQUIRE_GL();
  Scene s = makeScene(192, 144);
  ShowcaseScene sc = makeShowcase(s.renderer);
  sc.lights[0].castsShadow = false;
  auto st = s.renderer.render(s.target, showcaseCamera(), sc.items, sc.lights, kShowcaseSettings);
  ASSERT_TRUE(st) << st.error();
  EXPECT_EQ(st->drawCalls, 4);
  auto img = s.target.readColor();
  ASSERT_TRUE(img);
  expectGolden(*img, "mesh_blinn_phong.png");
}

TEST(SceneRendererGolden, PbrSpheresVaryMetallicAndRoughness) {
  DM_REQUIRE_GL();
  Scene s = makeScene(250, 100);
  auto ball = s.renderer.addMesh(dm::makeIcosphere(0.045, 3));
  ASSERT_TRUE(ball);
  std::vector<dm::DrawItem> items;
  for (int row = 0; row < 2; ++row)
    for (int i = 0; i < 5; ++i) {
      auto m = s.renderer.addMaterial({.model = dm::ShadingModel::Pbr,
                                       .baseColor = dm::Vec4f(0.9f, 0.6f, 0.3f, 1),
                                       .metallic = float(row),
                                       .roughness = 0.1f + 0.2f * float(i)});
      ASSERT_TRUE(m);
      items.push_back({.mesh = *ball, .material = *m, .model = at({-0.2 + 0.1 * i, 0.05 - 0.1 * row, 0})});
    }
  const dm::Light lights[] = {dm::Light::directional({-0.5, -0.6, -1}, 2.5f),
                              dm::Light::point({0.5, 0.5, 0.5}, 0.5f, 5)};
  dm::Camera cam = dm::Camera::lookAt({0, 0, 1}, {0, 0, 0});
  cam.projection = dm::Camera::Projection::Orthographic;
  cam.orthoHeight = 0.21;
  auto st = s.renderer.render(
      s.target, cam, items, lights,
      {.background = dm::Vec4f(0.02f, 0.02f, 0.02f, 1), .ambient = dm::Vec3f(0.15f, 0.15f, 0.15f)});
  ASSERT_TRUE(st) << st.error();
  EXPECT_EQ(st->drawCalls, 10);
  auto img = s.target.readColor();
  ASSERT_TRUE(img);
  // The lower-left of each sphere faces away from both lights (ambient only):
  // a metal has no diffuse part, so the metallic row is darker there.
  dm::Vec3 px0, px1;
  const dm::Mat4f vp = cam.projectionMatrix(2.5) * cam.viewMatrix();
  const dm::Vec3 offset = 0.04 * dm::Vec3(-0.6, -0.6, 0.53).normalized();
  ASSERT_TRUE(dm::projectToPixel(vp, dm::Vec3(0.2, 0.05, 0) + offset, 250, 100, px0));
  ASSERT_TRUE(dm::projectToPixel(vp, dm::Vec3(0.2, -0.05, 0) + offset, 250, 100, px1));
  EXPECT_GT(linearAt(*img, int(px0.x()), int(px0.y())), linearAt(*img, int(px1.x()), int(px1.y())));
  expectGolden(*img, "mesh_pbr.png");
}

TEST(SceneRendererGolden, TexturedAndNormalMapped) {
  DM_REQUIRE_GL();
  Scene s = makeScene(160, 160);
  auto checker = dm::Image::create(64, 64, 4, dm::PixelType::U8);
  auto bumps = dm::Image::create(64, 64, 3, dm::PixelType::U8);
  ASSERT_TRUE(checker && bumps);
  for (int y = 0; y < 64; ++y)
    for (int x = 0; x < 64; ++x) {
      const bool on = ((x / 8) + (y / 8)) % 2 == 0;
      for (int c = 0; c < 3; ++c) checker->at<std::uint8_t>(x, y, c) = on ? 220 : std::uint8_t(40 + 60 * c);
      checker->at<std::uint8_t>(x, y, 3) = 255;
      // Ridges along x: the normal tilts in x with a sine of the column.
      const double nx = 0.6 * std::sin(2 * kPi * x / 16.0);
      const dm::Vec3 n = dm::Vec3(nx, 0, 1).normalized();
      for (int c = 0; c < 3; ++c)
        bumps->at<std::uint8_t>(x, y, c) = std::uint8_t(std::lround((n[c] * 0.5 + 0.5) * 255));
    }
  auto colorTex = s.renderer.addTexture(*checker, true);
  auto normalTex = s.renderer.addTexture(*bumps, false);
  ASSERT_TRUE(colorTex && normalTex);
  auto floorMat = s.renderer.addMaterial({.baseColor = dm::Vec4f(1, 1, 1, 1),
                                          .specular = dm::Vec3f(0.1f, 0.1f, 0.1f),
                                          .colorTexture = *colorTex});
  auto boxMat = s.renderer.addMaterial({.model = dm::ShadingModel::Pbr,
                                        .baseColor = dm::Vec4f(0.8f, 0.8f, 0.85f, 1),
                                        .roughness = 0.35f,
                                        .normalTexture = *normalTex});
  dm::Mesh floor = makeQuad(1, 1);
  for (auto& uv : floor.uvs) uv *= 4;  // repeat: the far part exercises the mipmaps
  floor.transform(dm::Affine3(dm::AngleAxis(-kPi / 2, dm::Vec3::UnitX())));
  auto floorId = s.renderer.addMesh(floor);
  auto boxId = s.renderer.addMesh(makeFlatBox({0.1, 0.1, 0.1}));
  ASSERT_TRUE(floorMat && boxMat && floorId && boxId);
  dm::Affine3 box = at({0, 0.1, 0});
  box.rotate(dm::AngleAxis(0.6, dm::Vec3::UnitY()));
  const dm::DrawItem items[] = {{.mesh = *floorId, .material = *floorMat},
                                {.mesh = *boxId, .material = *boxMat, .model = box}};
  const dm::Light lights[] = {dm::Light::directional({-0.3, -1, -0.6}, 1.8f)};
  dm::Camera cam = dm::Camera::lookAt({0.0, 0.35, 0.55}, {0, 0.05, 0});
  auto st = s.renderer.render(s.target, cam, items, lights, kShowcaseSettings);
  ASSERT_TRUE(st) << st.error();
  auto img = s.target.readColor();
  ASSERT_TRUE(img);
  expectGolden(*img, "mesh_textured.png");
}

TEST(SceneRendererGolden, DirectionalAndSpotShadows) {
  DM_REQUIRE_GL();
  Scene s = makeScene(192, 144);
  ShowcaseScene sc = makeShowcase(s.renderer);
  dm::Light spot =
      dm::Light::spot({-0.1, 0.6, 0.3}, {0.1, -1, -0.4}, 20, 28, 0.35f, 3, dm::Vec3f(0.6f, 0.8f, 1));
  spot.castsShadow = true;
  sc.lights[1] = spot;
  auto st = s.renderer.render(s.target, showcaseCamera(), sc.items, sc.lights, kShowcaseSettings);
  ASSERT_TRUE(st) << st.error();
  EXPECT_EQ(st->shadowMaps, 2);
  EXPECT_EQ(st->shadowDrawCalls, 2 * 4);
  auto img = s.target.readColor();
  ASSERT_TRUE(img);
  expectGolden(*img, "mesh_shadow.png");
}

TEST(SceneRendererGolden, StereoSideBySide) {
  DM_REQUIRE_GL();
  Scene s = makeScene(256, 112);
  ShowcaseScene sc = makeShowcase(s.renderer);
  auto st =
      s.renderer.renderStereo(s.target, showcaseCamera(), 0.06, 0.8, sc.items, sc.lights, kShowcaseSettings);
  ASSERT_TRUE(st) << st.error();
  EXPECT_EQ(st->drawCalls, 8);
  EXPECT_EQ(st->shadowMaps, 1);
  auto img = s.target.readColor();
  ASSERT_TRUE(img);
  expectGolden(*img, "mesh_stereo.png");
}
