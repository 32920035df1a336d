// Screen-space fluid rendering against geometry and optics: each sphere's
// depth is the analytic ray–sphere hit, a slab of particles is as thick as
// the slab and transmits exp(−σ t) (Beer–Lambert), smoothing turns the
// spheres' bumps into a flat face, a ball of fluid lit from the camera
// shades as n·l of a sphere, meshes in front hide the fluid, the surface's
// depth is written; then a golden image of blood pooled on a floor.
#include <dm/math/primitives.hpp>
#include <dm/renderer/camera.hpp>
#include <dm/renderer/fluid_renderer.hpp>
#include <dm/renderer/image_compare.hpp>
#include <dm/renderer/render_target.hpp>
#include <dm/renderer/scene_renderer.hpp>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "render_fixture.hpp"

namespace fluid_render_test {

using dm::test::srgbToLinear;

// Points of a cubic lattice of spacing d filling [lo, hi] (cell centres).
std::vector<dm::Vec3> lattice(const dm::Vec3& lo, const dm::Vec3& hi, double d) {
  std::vector<dm::Vec3> out;
  const dm::Vec3 n = ((hi - lo) / d).array().round();
  for (int i = 0; i < int(n.x()); ++i)
    for (int j = 0; j < int(n.y()); ++j)
      for (int k = 0; k < int(n.z()); ++k) out.push_back(lo + d * dm::Vec3(i + 0.5, j + 0.5, k + 0.5));
  return out;
}

// Looking down −z at the origin from z = 0.5 m; orthographic, `height` m high.
dm::Camera orthoDown(double height) {
  dm::Camera c = dm::Camera::lookAt({0, 0, 0.5}, {0, 0, 0});
  c.projection = dm::Camera::Projection::Orthographic;
  c.orthoHeight = height;
  return c;
}

struct Rig {
  dm::FluidRenderer fluid;
  dm::RenderTarget target;
};

Rig makeRig(int w, int h, int samples = 1) {
  auto f = dm::FluidRenderer::create();
  EXPECT_TRUE(f) << f.error();
  auto t = dm::RenderTarget::create({.width = w, .height = h, .samples = samples});
  EXPECT_TRUE(t) << t.error();
  return Rig{std::move(*f), std::move(*t)};
}

// No lights, no ambient, no reflection: what is drawn is only the scene
// behind, attenuated.
dm::FluidLook pureAbsorber(const dm::Vec3f& sigma) {
  dm::FluidLook look;
  look.absorption = sigma;
  look.fresnelF0 = 0;
  look.specular = 0;
  return look;
}

const dm::Vec3f kNoAmbient = dm::Vec3f::Zero();

// A 4 × 4 × 1 cm slab of particles 2 mm apart (its front face at z = 0),
// drawn 3/4 of a spacing wide so the lattice's straight gaps are closed.
// Each particle is moved by up to half a pixel (0.125 mm at the slab tests'
// 0.25 mm pixels) across the view, as a fluid's particles lie at any place
// relative to the pixels: a lattice aligned with the pixels would sample
// every sphere's chord at the same offsets, a bias of a few per cent of
// the thickness that no real fluid shows.
constexpr double kSpacing = 2e-3, kSlabDepth = 1e-2, kSlabPixel = 0.25e-3;
constexpr int kSlabPixels = 240;  // 6 cm
std::vector<dm::Vec3> slab() {
  std::vector<dm::Vec3> p = lattice({-0.02, -0.02, -kSlabDepth}, {0.02, 0.02, 0}, kSpacing);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> jitter(-kSlabPixel / 2, kSlabPixel / 2);
  for (dm::Vec3& q : p) {
    q.x() += jitter(rng);
    q.y() += jitter(rng);
  }
  return p;
}

TEST(FluidRenderer, EachSphereIsDrawnAtItsAnalyticRayHit) {
  DM_REQUIRE_GL();
  Rig rig = makeRig(96, 96);
  dm::Camera cam = dm::Camera::lookAt({0.03, 0.02, 0.2}, {0, 0, 0});
  cam.fovYDeg = 20;
  const std::vector<dm::Vec3> p = {{0, 0, 0}, {0.012, -0.004, -0.01}};  // the second partly behind the first
  const double r = 0.008;
  rig.target.clear();
  dm::FluidLook look;
  look.smoothingIterations = 0;
  ASSERT_TRUE(rig.fluid.render(rig.target, cam, p, r, look, {}, kNoAmbient));
  auto raw = rig.fluid.readRawDepth();
  ASSERT_TRUE(raw) << raw.error();
  // The reference: every pixel centre's ray against both spheres, in double.
  const dm::Mat4f viewProj = cam.projectionMatrix(1.0) * cam.viewMatrix();
  const Eigen::Matrix4d inv = viewProj.cast<double>().inverse();
  const dm::Vec3 eye = cam.position, fwd = cam.forward();
  int hits = 0, compared = 0, edge = 0;
  double worst = 0;
  for (int y = 0; y < 96; ++y)
    for (int x = 0; x < 96; ++x) {
      const Eigen::Vector4d ndc((x + 0.5) / 48.0 - 1, 1 - (y + 0.5) / 48.0, 1, 1);
      Eigen::Vector4d far = inv * ndc;
      const dm::Vec3 dir = (far.head<3>() / far.w() - eye).normalized();
      double best = 0, margin = 1;
      for (const dm::Vec3& c : p) {
        const dm::Vec3 oc = c - eye;
        const double b = oc.dot(dir), h = r * r - (oc.squaredNorm() - b * b);
        margin = std::min(margin, std::abs(h) / (r * r));
        if (h <= 0) continue;
        const double t = b - std::sqrt(h), depth = t * dir.dot(fwd);
        if (best == 0 || depth < best) best = depth;
      }
      const double got = raw->at<float>(x, y);
      if (margin < 0.05) {  // within a few per cent of a silhouette: either answer
        ++edge;
        continue;
      }
      ++compared;
      if (best > 0) ++hits;
      EXPECT_EQ(got > 0, best > 0) << x << "," << y;
      if (best > 0 && got > 0) worst = std::max(worst, std::abs(got - best));
    }
  EXPECT_GT(hits, 500);  // two discs of about 11 px radius (8 mm at 0.2 m, 0.73 mm a pixel), overlapping
  EXPECT_LT(edge, compared / 10);
  EXPECT_LT(worst, 2e-5) << "eye depth against the analytic hit, m";
}

TEST(FluidRenderer, ASlabIsAsThickAsItIsDeepAndTransmitsByBeerLambert) {
  DM_REQUIRE_GL();
  Rig rig = makeRig(kSlabPixels, kSlabPixels);
  const std::vector<dm::Vec3> p = slab();
  const dm::Vec3f sigma(50, 100, 200);  // 1/m: the 1 cm slab transmits e^-0.5, e^-1, e^-2
  dm::FluidLook look = pureAbsorber(sigma);
  look.particleVolume = float(kSpacing * kSpacing * kSpacing);
  rig.target.clear(dm::Vec4f(1, 1, 1, 1));
  auto st = rig.fluid.render(rig.target, orthoDown(0.06), p, 0.75 * kSpacing, look, {}, kNoAmbient);
  ASSERT_TRUE(st) << st.error();
  EXPECT_EQ(st->particles, int(p.size()));
  auto thick = rig.fluid.readThickness();
  auto color = rig.target.readColor();
  ASSERT_TRUE(thick && color);
  // The central 2 × 2 cm: ten lattice periods each way.
  double sum = 0, sumSq = 0, worst = 0;
  int n = 0;
  for (int y = 80; y < 160; ++y)
    for (int x = 80; x < 160; ++x) {
      const double t = thick->at<float>(x, y);
      sum += t;
      sumSq += t * t;
      ++n;
      for (int c = 0; c < 3; ++c) {
        const double expected = std::exp(-double(sigma[c]) * t);
        worst = std::max(
            worst, std::abs(srgbToLinear(color->at<std::uint8_t>(x, y, c)) - expected) / (0.004 + expected));
      }
    }
  const double mean = sum / n, sd = std::sqrt(std::max(0.0, sumSq / n - mean * mean));
  EXPECT_NEAR(mean, kSlabDepth, 0.02 * kSlabDepth) << "mean thickness, m";
  EXPECT_LT(sd, 0.1 * mean) << "the thickness blur evens the lattice's pattern";
  EXPECT_LT(worst, 0.03) << "relative departure from exp(-sigma t), per pixel and channel";
  // Outside the slab nothing is drawn: the white background stays.
  EXPECT_EQ(color->at<std::uint8_t>(5, 5, 1), 255);
}

// Angle (degrees) of the normal of the orthographic depth image `z` (m, 0 =
// none) at (x, y) from the view axis, by central differences; −1 where a
// neighbour has no fluid.
double tiltDeg(const dm::Image& z, int x, int y, double pixel) {
  const float l = z.at<float>(x - 1, y), r = z.at<float>(x + 1, y);
  const float u = z.at<float>(x, y - 1), d = z.at<float>(x, y + 1);
  if (l <= 0 || r <= 0 || u <= 0 || d <= 0) return -1;
  const dm::Vec3 n(-(r - l) / (2 * pixel), (d - u) / (2 * pixel), 1);
  return std::acos(1 / n.norm()) * 180 / dm::test::kPi;
}

TEST(FluidRenderer, SmoothingTurnsTheSpheresIntoOneFlatFace) {
  DM_REQUIRE_GL();
  Rig rig = makeRig(kSlabPixels, kSlabPixels);
  dm::FluidLook look;
  look.particleVolume = float(kSpacing * kSpacing * kSpacing);
  rig.target.clear();
  ASSERT_TRUE(rig.fluid.render(rig.target, orthoDown(0.06), slab(), 0.75 * kSpacing, look, {}, kNoAmbient));
  auto raw = rig.fluid.readRawDepth();
  auto smooth = rig.fluid.readSmoothedDepth();
  ASSERT_TRUE(raw && smooth);
  int rawSteep = 0, smoothSteep = 0, n = 0;
  double depthSum = 0;
  for (int y = 80; y < 160; ++y)
    for (int x = 80; x < 160; ++x) {
      const double a = tiltDeg(*raw, x, y, kSlabPixel), b = tiltDeg(*smooth, x, y, kSlabPixel);
      ASSERT_GE(a, 0);
      ASSERT_GE(b, 0);
      rawSteep += a > 20;
      smoothSteep += b > 10;
      depthSum += smooth->at<float>(x, y);
      ++n;
    }
  EXPECT_GT(rawSteep, n / 3) << "the spheres' bumps, unsmoothed";
  EXPECT_LT(smoothSteep, n / 50) << "after 3 bilateral passes the face is within 10 deg of flat";
  // The face lies between the front spheres' tops (0.5 m − z_top) and their
  // centres: the filter averages tops and the dips between them.
  const double top = 0.5 - (-kSpacing / 2 + 0.75 * kSpacing), centre = 0.5 + kSpacing / 2;
  EXPECT_GT(depthSum / n, top);
  EXPECT_LT(depthSum / n, centre);
}

TEST(FluidRenderer, ABallOfFluidLitFromTheCameraShadesAsASphere) {
  DM_REQUIRE_GL();
  Rig rig = makeRig(128, 128);
  // A 2.5 cm ball of particles 2 mm apart, opaque (its body colour white).
  // Shells d apart, each with points about d apart (a Fibonacci sphere), as
  // a droplet's particles settle in layers under its surface; a cubic
  // lattice would instead show the terraces of its layers.
  std::vector<dm::Vec3> p;
  const double R = 0.025, golden = dm::test::kPi * (3 - std::sqrt(5.0));
  for (double shell = R - kSpacing / 2; shell > 0; shell -= kSpacing) {
    const int count = std::max(1, int(std::round(4 * dm::test::kPi * shell * shell / (kSpacing * kSpacing))));
    for (int i = 0; i < count; ++i) {
      const double z = 1 - (i + 0.5) * 2 / count, ring = std::sqrt(1 - z * z), phi = golden * i;
      p.push_back(shell * dm::Vec3(ring * std::cos(phi), ring * std::sin(phi), z));
    }
  }
  dm::FluidLook look;
  look.color = dm::Vec3f(1, 1, 1);
  look.absorption = dm::Vec3f(1e5f, 1e5f, 1e5f);
  look.fresnelF0 = 0;
  look.specular = 0;
  look.particleVolume = float(kSpacing * kSpacing * kSpacing);
  const dm::Light light = dm::Light::directional({0, 0, -1}, 1);
  rig.target.clear();
  ASSERT_TRUE(
      rig.fluid.render(rig.target, orthoDown(0.064), p, 0.75 * kSpacing, look, {&light, 1}, kNoAmbient));
  auto color = rig.target.readColor();
  ASSERT_TRUE(color);
  // The drawn surface is the ball's outer skin: its outer shell plus the
  // drawing radius, R' ≈ R − d/2 + 3d/4. Shaded n·l = sqrt(1 − ρ²/R'²).
  const double outer = R - kSpacing / 2 + 0.75 * kSpacing, pixel = 0.064 / 128;
  double errSum = 0;
  int n = 0, bad = 0;
  for (int y = 0; y < 128; ++y)
    for (int x = 0; x < 128; ++x) {
      const double px = (x + 0.5 - 64) * pixel, py = (64 - y - 0.5) * pixel, rho = std::hypot(px, py);
      if (rho > 0.8 * outer) continue;
      const double expected = std::sqrt(1 - rho * rho / (outer * outer));
      const double err = std::abs(srgbToLinear(color->at<std::uint8_t>(x, y, 0)) - expected);
      errSum += err;
      bad += err > 0.1;
      ++n;
    }
  EXPECT_LT(errSum / n, 0.03) << "mean |shade − n·l| inside 0.8 R";
  EXPECT_LT(bad, n / 50);
}

TEST(FluidRenderer, AMeshInFrontHidesTheFluidAndTheSurfaceDepthIsWritten) {
  DM_REQUIRE_GL();
  Rig rig = makeRig(kSlabPixels, kSlabPixels);
  dm::FluidLook look;
  look.particleVolume = float(kSpacing * kSpacing * kSpacing);
  const dm::Camera cam = orthoDown(0.06);
  rig.target.clear();
  rig.target.bind();
  // The left half covered by a green plane at z = +1 cm (in front of the
  // slab's face at 0): NDC depth of eye distance 0.49 m, near 0.01, far 100.
  const double ndcZ = (2 * 0.49 - (100 + 0.01)) / (100 - 0.01);
  ASSERT_TRUE(dm::test::drawNdcRect(-1, -1, 0, 1, float(ndcZ), dm::Vec4f(0, 1, 0, 1)));
  ASSERT_TRUE(rig.fluid.render(rig.target, cam, slab(), 0.75 * kSpacing, look, {}, kNoAmbient));
  auto raw = rig.fluid.readRawDepth();
  auto color = rig.target.readColor();
  auto depth = rig.target.readDepth();
  ASSERT_TRUE(raw && color && depth);
  for (int y = 60; y < 180; y += 13) {
    EXPECT_EQ(raw->at<float>(90, y), 0.0f) << "hidden by the plane";
    EXPECT_EQ(color->at<std::uint8_t>(90, y, 1), 255);
    EXPECT_GT(raw->at<float>(150, y), 0.0f);
    EXPECT_LT(color->at<std::uint8_t>(150, y, 1), 60) << "blood, not the background";
    // The written window depth is the face's: eye depth 0.5 m less at most a
    // radius, so between those of 0.49 and 0.502 m.
    const double wz = depth->at<float>(150, y), eyeDepth = ((wz * 2 - 1) * (100 - 0.01) + (100 + 0.01)) / 2;
    EXPECT_GT(eyeDepth, 0.49);
    EXPECT_LT(eyeDepth, 0.502);
  }
}

TEST(FluidRenderer, RefusesLooksItCannotDraw) {
  DM_REQUIRE_GL();
  Rig rig = makeRig(32, 32);
  const std::vector<dm::Vec3> p = {{0, 0, 0}};
  const dm::Camera cam = orthoDown(0.1);
  auto refused = [&](const dm::FluidLook& look, double r, const char* needle) {
    auto st = rig.fluid.render(rig.target, cam, p, r, look, {}, kNoAmbient);
    ASSERT_FALSE(st) << needle;
    EXPECT_NE(st.error().message().find(needle), std::string::npos) << st.error();
  };
  dm::FluidLook look;
  refused(look, 0, "radius");
  refused(look, std::nan(""), "radius");
  look.absorption.x() = -1;
  refused(look, 0.01, "absorption");
  look = {};
  look.fresnelF0 = 1.5f;
  refused(look, 0.01, "fresnelF0");
  look = {};
  look.smoothingIterations = 17;
  refused(look, 0.01, "smoothingIterations");
  look = {};
  look.smoothingRadius = 0;
  refused(look, 0.01, "smoothingRadius");
  look = {};
  look.particleVolume = -1;
  refused(look, 0.01, "particleVolume");
  const std::vector<dm::Light> nine(9, dm::Light::directional({0, 0, -1}));
  EXPECT_FALSE(rig.fluid.render(rig.target, cam, p, 0.01, dm::FluidLook{}, nine, kNoAmbient));
  EXPECT_FALSE(rig.fluid.render(rig.target, cam, p, 0.01, dm::FluidLook{}, {}, kNoAmbient, {0, 0, 64, 64}));
  // Nothing to draw is not an error, and draws nothing.
  rig.target.clear(dm::Vec4f(0, 0, 1, 1));
  ASSERT_TRUE(rig.fluid.render(rig.target, cam, {}, 0.01, dm::FluidLook{}, {}, kNoAmbient));
  auto color = rig.target.readColor();
  ASSERT_TRUE(color);
  EXPECT_EQ(color->at<std::uint8_t>(16, 16, 2), 255);
  EXPECT_EQ(glGetError(), GLenum(GL_NO_ERROR));
}

TEST(FluidRenderer, FromTransmittanceGivesTheLayerItsColour) {
  const dm::FluidLook look = dm::FluidLook::fromTransmittance({0.5f, 0.02f, 1.0f}, 1e-3f);
  EXPECT_NEAR(std::exp(-look.absorption.x() * 1e-3), 0.5, 1e-5);
  EXPECT_NEAR(std::exp(-look.absorption.y() * 1e-3), 0.02, 1e-5);
  EXPECT_EQ(look.absorption.z(), 0.0f);
  EXPECT_EQ(look.color, dm::Vec3f(0.5f, 0.02f, 1.0f));
}

// Blood pooled on a grey floor under a lamp, a drop falling into it, seen at
// an angle; paired with the analytic checks above.
TEST(FluidRendererGolden, BloodPoolOnAFloor) {
  DM_REQUIRE_GL();
  auto meshes = dm::SceneRenderer::create();
  ASSERT_TRUE(meshes) << meshes.error();
  Rig rig = makeRig(320, 240, 4);
  dm::Mesh floor = dm::makeBox(dm::Vec3(0.06, 0.06, 0.002));
  const auto floorMesh = meshes->addMesh(floor);
  const auto grey = meshes->addMaterial({.baseColor = dm::Vec4f(0.6f, 0.6f, 0.55f, 1), .shininess = 16});
  ASSERT_TRUE(floorMesh && grey);
  dm::DrawItem item{.mesh = *floorMesh, .material = *grey};
  item.model.translation() = dm::Vec3(0, 0, -0.002);
  const std::vector<dm::Light> lights = {dm::Light::directional({-0.3, -0.4, -0.85}, 0.9f),
                                         dm::Light::point({0.03, 0.02, 0.08}, 0.01f, 1)};
  const dm::RenderSettings settings{.background = dm::Vec4f(0.05f, 0.06f, 0.08f, 1),
                                    .ambient = dm::Vec3f(0.1f, 0.1f, 0.1f)};
  dm::Camera cam = dm::Camera::lookAt({0.0, -0.09, 0.07}, {0, 0, 0}, {0, 0, 1});
  cam.fovYDeg = 45;
  ASSERT_TRUE(meshes->render(rig.target, cam, {&item, 1}, lights, settings));
  // A pool 3 mm deep over a 5 cm disc and a 4 mm drop falling into it,
  // particles about 1.5 mm apart (each moved by up to a fifth of that, as a
  // fluid's are).
  std::vector<dm::Vec3> p;
  const double d = 1.5e-3;
  const dm::Vec3 drop(0.004, 0.002, 0.012);
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> jitter(-0.2 * d, 0.2 * d);
  for (const dm::Vec3& q : lattice({-0.03, -0.03, 0}, {0.03, 0.03, 0.018}, d)) {
    const bool pool = std::hypot(q.x() + 0.005, q.y()) < 0.025 && q.z() < 0.003;
    if (pool || (q - drop).norm() < 0.004) p.push_back(q + dm::Vec3(jitter(rng), jitter(rng), jitter(rng)));
  }
  // Blood: 1 mm transmits half the red and 2 % of the rest; a deep layer
  // shows a dark red.
  dm::FluidLook look = dm::FluidLook::fromTransmittance({0.5f, 0.02f, 0.02f}, 1e-3f);
  look.color = dm::Vec3f(0.12f, 0.005f, 0.005f);
  look.particleVolume = float(d * d * d);
  ASSERT_TRUE(rig.fluid.render(rig.target, cam, p, 0.75 * d, look, lights, settings.ambient));
  auto img = rig.target.readColor();
  ASSERT_TRUE(img);
  auto r = dm::checkGolden(*img, dm::test::goldenDir() / "fluid_blood_pool.png", dm::test::renderOutDir(),
                           {.pixelThreshold = 12, .maxFraction = 0.005});
  EXPECT_TRUE(r) << r.error();
}

}  // namespace fluid_render_test
