// SceneRenderer height textures (parallax occlusion mapping), against
// geometry: a flat quad with colour stripes and a stepped relief seen at 45°
// from either side by an orthographic camera. A texture edge lying in the
// pit must appear shifted towards the viewer by depth x tan(view angle) and
// one on the plateau must not move; a flat relief at the surface (all ones)
// must render the same image as no height texture; heightScale is validated.
#include <dm/io/image_io.hpp>
#include <dm/renderer/camera.hpp>
#include <dm/renderer/image_compare.hpp>
#include <dm/renderer/render_target.hpp>
#include <dm/renderer/scene_renderer.hpp>

#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <limits>
#include <numbers>
#include <string>
#include <vector>

#include "render_fixture.hpp"

namespace {

using dm::test::kPi;
constexpr int kSize = 256;          // target pixels per side
constexpr double kOrtho = 1.0;      // orthographic view height, m: 256 px per m
constexpr double kTheta = kPi / 4;  // view angle from the quad's normal
constexpr double kDepth = 0.1;      // heightScale, m
constexpr double kStepU = 0.375;    // the relief: plateau (height 1) for u < kStepU, pit (height 0) beyond
constexpr int kTex = 64;            // texture texels per side
// Edge positions, pixels. llvmpipe lands within 0.01 px of the analytic
// columns (the refinement is exact on a flat pit); the slack is for GPUs'
// coarser filtering weights. The shift measured is 18 px.
constexpr double kTolerancePx = 0.5;

struct HeightScene {
  dm::SceneRenderer renderer;
  dm::RenderTarget target;
};

HeightScene makeScene() {
  auto r = dm::SceneRenderer::create();
  EXPECT_TRUE(r) << r.error();
  auto t = dm::RenderTarget::create({.width = kSize, .height = kSize, .samples = 1});
  EXPECT_TRUE(t) << t.error();
  return HeightScene{std::move(*r), std::move(*t)};
}

// A 1 m square in z = 0 facing +z; u along +x, v along -y, uv (0, 0) at the top-left corner.
dm::Mesh makeQuad() {
  dm::Mesh m;
  m.positions = {{-0.5, 0.5, 0}, {0.5, 0.5, 0}, {0.5, -0.5, 0}, {-0.5, -0.5, 0}};
  m.normals.assign(4, dm::Vec3::UnitZ());
  m.uvs = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
  m.triangles = {{0, 3, 2}, {0, 2, 1}};
  return m;
}

// A kTex x kTex U8 image whose texels depend on one texture coordinate t in
// [0, 1) (texel centre): u when !alongV, v when alongV.
dm::Image makeImage(int channels, bool alongV, const std::function<std::array<int, 3>(double)>& texel) {
  auto img = dm::Image::create(kTex, kTex, channels, dm::PixelType::U8);
  EXPECT_TRUE(img);
  for (int y = 0; y < kTex; ++y)
    for (int x = 0; x < kTex; ++x) {
      const double t = ((alongV ? y : x) + 0.5) / kTex;
      const auto rgb = texel(t);
      for (int c = 0; c < channels; ++c) img->at<std::uint8_t>(x, y, c) = std::uint8_t(rgb[std::size_t(c)]);
    }
  return *img;
}

// Colour: red for t in [0, 0.25) and [0.5, 0.75), blue elsewhere (edges at 0, 0.25, 0.5, 0.75).
dm::Image stripes(bool alongV) {
  return makeImage(3, alongV, [](double t) {
    return int(std::floor(t * 4)) % 2 == 0 ? std::array<int, 3>{230, 20, 20}
                                           : std::array<int, 3>{20, 20, 230};
  });
}

dm::Image heightMap(bool alongV, const std::function<double(double)>& h) {
  return makeImage(1, alongV, [&](double t) {
    const int v = int(std::lround(h(t) * 255));
    return std::array<int, 3>{v, v, v};
  });
}

// Orthographic camera 2 m away at kTheta from the normal, on the +x side
// (side = +1) or the -x side (side = -1). Its right vector is +x either way,
// so world x maps to pixel column kSize / 2 + x cos(kTheta) * kSize / kOrtho.
dm::Camera obliqueCamera(int side) {
  dm::Camera c = dm::Camera::lookAt({2 * side * std::sin(kTheta), 0, 2 * std::cos(kTheta)}, {0, 0, 0});
  c.projection = dm::Camera::Projection::Orthographic;
  c.orthoHeight = kOrtho;
  return c;
}

double columnOfU(double u) { return kSize / 2.0 + (u - 0.5) * std::cos(kTheta) * kSize / kOrtho; }

// Columns (sub-pixel) along the middle row where the linear red-minus-blue
// difference changes sign, between the columns of u = u0 and u = u1.
std::vector<double> redBlueEdges(const dm::Image& img, double u0, double u1) {
  std::vector<double> edges;
  const int y = kSize / 2;
  auto diff = [&](int x) {
    return dm::test::srgbToLinear(img.at<std::uint8_t>(x, y, 0)) -
           dm::test::srgbToLinear(img.at<std::uint8_t>(x, y, 2));
  };
  const int x0 = int(std::ceil(columnOfU(u0))), x1 = int(std::floor(columnOfU(u1)));
  for (int x = x0; x < x1; ++x) {
    const double a = diff(x), b = diff(x + 1);
    if ((a > 0) != (b > 0)) edges.push_back(x + 0.5 + a / (a - b));  // pixel centres at x + 0.5
  }
  return edges;
}

std::string formatColumn(double x) { return " " + std::to_string(x); }

void saveForInspection(const dm::Image& img, const std::string& name) {
  std::filesystem::create_directories(dm::test::renderOutDir());
  const auto path = dm::test::renderOutDir() / (name + ".png");
  if (dm::writePng(img, path)) std::fprintf(stderr, "wrote %s\n", path.string().c_str());
}

using dm::test::kDark;

// A lit material whose rendered colour keeps the texture's red/blue order:
// light straight onto the quad, no specular (Blinn–Phong), rough dielectric (PBR).
dm::Material material(dm::ShadingModel model) {
  dm::Material m;
  m.model = model;
  m.baseColor = dm::Vec4f(1, 1, 1, 1);
  m.specular = dm::Vec3f(0, 0, 0);
  m.roughness = 1;
  return m;
}

const char* modelName(dm::ShadingModel m) {
  return m == dm::ShadingModel::Unlit ? "unlit" : m == dm::ShadingModel::BlinnPhong ? "blinn-phong" : "pbr";
}

}  // namespace

TEST(SceneRendererHeight, PitShiftsTextureEdgesTowardTheViewerByDepthTimesTanTheta) {
  DM_REQUIRE_GL();
  HeightScene s = makeScene();
  auto quad = s.renderer.addMesh(makeQuad());
  ASSERT_TRUE(quad) << quad.error();
  const dm::Light sun = dm::Light::directional({0, 0, -1});
  const double shift = kDepth * std::tan(kTheta);  // along the surface, m (= u: the quad is 1 m per uv unit)
  // The window of u searched for edges: clear of the quad's border, where
  // repeat-wrapped texels and the relief's wrap-around make other edges.
  const double window[2] = {0.2, 0.88};
  for (const bool alongV : {false, true}) {
    // alongV: the textures vary with v and the quad turns 90° about z, so v
    // runs along +x and the picture is the same; this checks the v direction.
    dm::Affine3 model = dm::Affine3::Identity();
    if (alongV) model.linear() = dm::AngleAxis(kPi / 2, dm::Vec3::UnitZ()).toRotationMatrix();
    auto color = s.renderer.addTexture(stripes(alongV), {.srgb = true, .mipmaps = false});
    auto step = s.renderer.addTexture(heightMap(alongV, [](double t) { return t < kStepU ? 1.0 : 0.0; }),
                                      {.srgb = false, .mipmaps = false});
    auto zeros = s.renderer.addTexture(heightMap(alongV, [](double) { return 0.0; }),
                                       {.srgb = false, .mipmaps = false});
    ASSERT_TRUE(color && step && zeros);
    for (const auto shading :
         {dm::ShadingModel::Unlit, dm::ShadingModel::BlinnPhong, dm::ShadingModel::Pbr}) {
      // (height texture, scale, does u lie in the pit)
      struct Case {
        const char* name;
        dm::TextureId height;
        double scale;
        bool (*pit)(double);
      };
      const Case cases[] = {
          {"none", {}, 0, [](double) { return false; }},
          {"step at scale 0", *step, 0, [](double) { return false; }},
          {"step", *step, kDepth, [](double u) { return u > kStepU; }},
          {"all zeros", *zeros, kDepth, [](double) { return true; }},
      };
      for (const Case& c : cases) {
        dm::Material m = material(shading);
        m.colorTexture = *color;
        m.heightTexture = c.height;
        m.heightScale = float(c.scale);
        auto mat = s.renderer.addMaterial(m);
        ASSERT_TRUE(mat) << mat.error();
        const dm::DrawItem item{.mesh = *quad, .material = *mat, .model = model};
        for (const int side : {+1, -1}) {
          ASSERT_TRUE(s.renderer.render(s.target, obliqueCamera(side), {&item, 1}, {&sun, 1}, kDark));
          auto img = s.target.readColor();
          ASSERT_TRUE(img);
          // Where each colour edge e should be seen: a point of the pit at
          // depth d shows the texture d tan(theta) away from the viewer, so
          // the edge appears at e + side * shift. None of these edges lies
          // behind the step's wall (kStepU + shift < 0.5 + shift and
          // 0.5 - shift > kStepU).
          std::vector<double> expected;
          for (const double e : {-0.25, 0.0, 0.25, 0.5, 0.75, 1.0, 1.25}) {
            const double seen = e + (c.pit(e) && c.scale > 0 ? side * shift : 0.0);
            if (seen > window[0] && seen < window[1]) expected.push_back(columnOfU(seen));
          }
          const std::vector<double> edges = redBlueEdges(*img, window[0], window[1]);
          const std::string what = std::string(modelName(shading)) + ", " + c.name + ", viewed from " +
                                   (side > 0 ? "+x" : "-x") + (alongV ? ", along v" : ", along u");
          auto list = [](const std::vector<double>& v) {
            std::string out;
            for (const double x : v) out += formatColumn(x);
            return out;
          };
          ASSERT_EQ(edges.size(), expected.size())
              << what << ": edges at columns" << list(edges) << ", expected" << list(expected);
          bool good = true;
          for (std::size_t k = 0; k < edges.size(); ++k) {
            EXPECT_NEAR(edges[k], expected[k], kTolerancePx) << what << ", edge " << k;
            good = good && std::abs(edges[k] - expected[k]) <= kTolerancePx;
          }
          if (!good) saveForInspection(*img, "height_edges");
        }
      }
    }
  }
  EXPECT_EQ(glGetError(), GLenum(GL_NO_ERROR));
}

TEST(SceneRendererHeight, ReliefAtTheSurfaceRendersLikeNoHeightTexture) {
  DM_REQUIRE_GL();
  HeightScene s = makeScene();
  auto quad = s.renderer.addMesh(makeQuad());
  ASSERT_TRUE(quad) << quad.error();
  auto color = s.renderer.addTexture(stripes(false));  // sRGB, mipmapped: the default path
  // A normal map that varies with u (tilt towards +u, then -u) so that a uv
  // shift of the normal lookup would show in the lighting too.
  auto normal = s.renderer.addTexture(
      makeImage(3, false,
                [](double t) {
                  const int x = t < 0.5 ? 200 : 55;
                  const int z =
                      int(std::lround((std::sqrt(1 - std::pow(x / 127.5 - 1, 2)) * 0.5 + 0.5) * 255));
                  return std::array<int, 3>{x, 128, z};
                }),
      false);
  auto ones = s.renderer.addTexture(heightMap(false, [](double) { return 1.0; }), false);
  ASSERT_TRUE(color && normal && ones);
  const dm::Light light = dm::Light::directional({-1, 0.3, -1});
  for (const auto shading : {dm::ShadingModel::Unlit, dm::ShadingModel::BlinnPhong, dm::ShadingModel::Pbr}) {
    dm::Image images[2];
    for (int k = 0; k < 2; ++k) {
      dm::Material m = material(shading);
      m.colorTexture = *color;
      m.normalTexture = *normal;
      if (k == 1) {
        m.heightTexture = *ones;
        m.heightScale = float(kDepth);
      }
      auto mat = s.renderer.addMaterial(m);
      ASSERT_TRUE(mat) << mat.error();
      const dm::DrawItem item{.mesh = *quad, .material = *mat};
      ASSERT_TRUE(s.renderer.render(s.target, obliqueCamera(+1), {&item, 1}, {&light, 1}, kDark));
      auto img = s.target.readColor();
      ASSERT_TRUE(img);
      images[k] = *img;
    }
    // The quad covers a good part of the image, so an equal image is not an empty one.
    EXPECT_GT(dm::countCoveredPixels(images[0], dm::Vec3f(0, 0, 0)), std::size_t(kSize * kSize / 3));
    auto diff = dm::compareImages(images[1], images[0]);
    ASSERT_TRUE(diff) << diff.error();
    EXPECT_TRUE(diff->passed) << modelName(shading) << ": " << diff->differing << " pixels differ, max "
                              << diff->maxDifference;
    if (!diff->passed) saveForInspection(diff->diff, std::string("height_ones_diff_") + modelName(shading));
  }
}

TEST(SceneRendererHeight, HeightScaleIsValidated) {
  DM_REQUIRE_GL();
  HeightScene s = makeScene();
  for (const float bad :
       {-0.001f, std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity()}) {
    auto mat = s.renderer.addMaterial({.heightScale = bad});
    ASSERT_FALSE(mat) << bad;
    EXPECT_EQ(mat.error().code, dm::ErrorCode::InvalidArgument);
    EXPECT_EQ(mat.error().where, "material.heightScale");
    EXPECT_NE(mat.error().message().find("heightScale"), std::string::npos) << mat.error().message();
  }
  auto good = s.renderer.addMaterial({.heightScale = 0.002f});
  ASSERT_TRUE(good) << good.error();
  EXPECT_FALSE(s.renderer.setMaterial(*good, {.heightScale = -1}));
  // A stale height texture is refused like a stale colour or normal texture.
  EXPECT_FALSE(s.renderer.addMaterial({.heightTexture = dm::TextureId{7, 1}, .heightScale = 0.01f}));
}
