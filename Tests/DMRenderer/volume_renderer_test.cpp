// VolumeRenderer: placement through anisotropic rotated affines (MIP disc
// area, blob position), empty-space skipping, depth interplay with opaque
// geometry, transparent transfer functions, slice views against the voxel
// values, isosurface depth, voxel cubes, errors, and Colin27 goldens.
#include <dm/core/filesystem.hpp>
#include <dm/io/volume_io.hpp>
#include <dm/math/isosurface.hpp>
#include <dm/renderer/image_compare.hpp>
#include <dm/renderer/render_target.hpp>
#include <dm/renderer/scene_renderer.hpp>
#include <dm/renderer/shader.hpp>
#include <dm/renderer/volume_renderer.hpp>

#include <cmath>
#include <cstdio>
#include <memory>
#include <numbers>

#include "render_fixture.hpp"

namespace {

using dm::Vec3;

// sRGB encoding of a linear value (0..255, unrounded) and its inverse.
double srgb8Unrounded(double linear) { return dm::test::srgbEncode255(linear); }
double linear(int encoded) { return dm::test::srgbToLinear(encoded); }

dm::VolumeRenderer& renderer() {
  static std::unique_ptr<dm::VolumeRenderer> r;
  if (!r) {
    auto made = dm::VolumeRenderer::create();
    DM_DEMAND(made.ok(), "VolumeRenderer::create failed");
    r = std::make_unique<dm::VolumeRenderer>(std::move(*made));
  }
  return *r;
}

// Anisotropic spacing (m), rotated about a skew axis, translated.
dm::Affine3 skewAffine(const Vec3& spacing, const Vec3& translation) {
  dm::Affine3 a = dm::Affine3::Identity();
  a.linear() = dm::AngleAxis(0.5, Vec3(1, 2, 3).normalized()).toRotationMatrix() * spacing.asDiagonal();
  a.translation() = translation;
  return a;
}

// A sphere of radius r (m) around `centre`, values 1 inside and 0 outside
// with a linear ramp two voxels wide, so the 0.5 level set of its trilinear
// interpolation is the sphere itself (a hard 0/1 edge would put the level
// set up to half a voxel off).
// `ramp` (m) overrides the ramp width.
dm::Volume sphereVolume(const dm::Vec3i& dims, const dm::Affine3& affine, const Vec3& centre, double r,
                        double ramp = 0) {
  auto v = dm::Volume::create(dims, dm::VoxelType::F32, affine);
  DM_DEMAND(v.ok(), "volume");
  const double h = ramp > 0 ? ramp : 2 * v->spacing().maxCoeff();
  for (int k = 0; k < dims.z(); ++k)
    for (int j = 0; j < dims.y(); ++j)
      for (int i = 0; i < dims.x(); ++i) {
        const double d = (affine * Vec3(i, j, k) - centre).norm();
        v->setValue(i, j, k, std::clamp(0.5 - (d - r) / h, 0.0, 1.0));
      }
  return std::move(*v);
}

dm::Vec3 volumeCentre(const dm::Volume& v) {
  return v.indexToWorld() * ((v.dims().cast<double>() - Vec3(1, 1, 1)) / 2);
}

dm::Camera orthoCamera(const Vec3& target, const Vec3& fromDir, double height) {
  dm::Camera cam = dm::Camera::lookAt(target + fromDir.normalized() * 0.5, target, Vec3(0, 0, 1));
  cam.projection = dm::Camera::Projection::Orthographic;
  cam.orthoHeight = height;
  cam.nearPlane = 0.05;
  cam.farPlane = 2;
  return cam;
}

std::size_t countAtLeast(const dm::Image& img, int channel, int threshold) {
  std::size_t n = 0;
  for (int y = 0; y < img.height(); ++y)
    for (int x = 0; x < img.width(); ++x)
      if (img.at<std::uint8_t>(x, y, channel) >= threshold) ++n;
  return n;
}

// Colin27 (ch2.nii.gz), loaded once for the golden tests.
const dm::Volume* colin() {
  static std::unique_ptr<dm::Volume> v;
  static bool tried = false;
  if (!tried) {
    tried = true;
    auto path = dm::FileSystem::global().resolve("mricron:ch2.nii.gz");
    if (!path) return nullptr;
    auto vol = dm::readVolume(*path);
    if (vol) v = std::make_unique<dm::Volume>(std::move(*vol));
  }
  return v.get();
}

// Draws an NDC rectangle [x0, x1] x [-1, 1] at NDC depth `ndcZ`, writing depth.
void drawOpaqueQuad(float x0, float x1, float ndcZ, const dm::Vec4f& color) {
  ASSERT_TRUE(dm::test::drawNdcRect(x0, -1, x1, 1, ndcZ, color));
}

struct SphereScene {
  dm::Volume volume;
  Vec3 centre;
  double radius = 0.015;
};

SphereScene skewSphere(double ramp = 0) {
  const dm::Affine3 a = skewAffine(Vec3(1.0e-3, 1.25e-3, 1.6e-3), Vec3(0.01, -0.02, 0.03));
  const dm::Vec3i dims(48, 40, 32);
  auto probe = dm::Volume::create(dims, dm::VoxelType::U8, a);
  const Vec3 c = volumeCentre(*probe);
  return {sphereVolume(dims, a, c, 0.015, ramp), c, 0.015};
}

}  // namespace

TEST(VolumeRenderer, MipOfSphereCoversPiRSquaredThroughSkewAnisotropicAffine) {
  DM_REQUIRE_GL();
  const SphereScene s = skewSphere();
  auto id = renderer().addVolume(s.volume);
  ASSERT_TRUE(id) << id.error();
  auto rt = dm::RenderTarget::create({.width = 128, .height = 128, .samples = 1});
  ASSERT_TRUE(rt);
  const double height = 0.06;
  for (const Vec3& dir : {Vec3(0.3, 0.2, 0.5), Vec3(-1, 0.1, 0.05)}) {
    rt->clear(dm::Vec4f(0, 0, 0, 1));
    const dm::Camera cam = orthoCamera(s.centre, dir, height);
    auto r = renderer().render(*rt, cam, *id,
                               {.mode = dm::VolumeRenderMode::Mip, .windowLow = 0, .windowHigh = 1});
    ASSERT_TRUE(r) << r.error();
    auto img = rt->readColor();
    ASSERT_TRUE(img);
    // MIP value >= 0.5 exactly inside the sphere's silhouette disc.
    const double pxPerM = 128 / height;
    const double expected = std::numbers::pi * std::pow(s.radius * pxPerM, 2);
    const auto covered =
        static_cast<double>(countAtLeast(*img, 0, static_cast<int>(std::ceil(srgb8Unrounded(0.5)))));
    EXPECT_NEAR(covered, expected, 0.02 * expected) << "view from " << dir.transpose();
  }
  EXPECT_TRUE(renderer().removeVolume(*id));
}

TEST(VolumeRenderer, BlobAppearsWhereProjectToPixelPutsIt) {
  DM_REQUIRE_GL();
  const dm::Affine3 a = skewAffine(Vec3(0.8e-3, 1.1e-3, 1.4e-3), Vec3(-0.03, 0.05, 0.02));
  const dm::Vec3i dims(40, 36, 30);
  auto vol = dm::Volume::create(dims, dm::VoxelType::U16, a);
  ASSERT_TRUE(vol);
  const Vec3 blob = a * Vec3(27.3, 10.6, 19.2);  // off-centre, between voxel centres
  const double sigma = 1.2e-3;
  for (int k = 0; k < dims.z(); ++k)
    for (int j = 0; j < dims.y(); ++j)
      for (int i = 0; i < dims.x(); ++i)
        vol->setValue(i, j, k,
                      60000 * std::exp(-(a * Vec3(i, j, k) - blob).squaredNorm() / (2 * sigma * sigma)));
  auto id = renderer().addVolume(*vol);
  ASSERT_TRUE(id) << id.error();
  auto rt = dm::RenderTarget::create({.width = 128, .height = 96, .samples = 1});
  ASSERT_TRUE(rt);
  dm::Camera cam = dm::Camera::lookAt(volumeCentre(*vol) + Vec3(0.08, -0.12, 0.1), volumeCentre(*vol));
  cam.fovYDeg = 35;
  rt->clear(dm::Vec4f(0, 0, 0, 1));
  ASSERT_TRUE(renderer().render(*rt, cam, *id, {.mode = dm::VolumeRenderMode::Mip, .stepVoxels = 0.25}));
  auto img = rt->readColor();
  ASSERT_TRUE(img);
  // Intensity-weighted centroid of the bright pixels.
  double sx = 0, sy = 0, sw = 0;
  for (int y = 0; y < img->height(); ++y)
    for (int x = 0; x < img->width(); ++x) {
      const double w = img->at<std::uint8_t>(x, y, 0);
      if (w < 100) continue;
      sx += w * (x + 0.5);
      sy += w * (y + 0.5);
      sw += w;
    }
  ASSERT_GT(sw, 0);
  Vec3 px;
  ASSERT_TRUE(dm::projectToPixel(cam.projectionMatrix(128.0 / 96.0) * cam.viewMatrix(), blob, 128, 96, px));
  EXPECT_NEAR(sx / sw, px.x(), 1.0);
  EXPECT_NEAR(sy / sw, px.y(), 1.0);
  EXPECT_TRUE(renderer().removeVolume(*id));
}

TEST(VolumeRenderer, EmptySpaceSkippingKeepsTheImageAndSkipsSamples) {
  DM_REQUIRE_GL();
  const SphereScene s = skewSphere();
  auto id = renderer().addVolume(s.volume);
  ASSERT_TRUE(id);
  auto tf = dm::TransferFunction::create(
      {{0, {0, 0, 0, 0}}, {0.4, {0, 0, 0, 0}}, {0.6, {0.9, 0.6, 0.3, 0.2}}, {1, {1, 0.9, 0.8, 0.4}}});
  ASSERT_TRUE(tf);
  ASSERT_TRUE(renderer().setTransferFunction(*id, *tf));
  auto info = renderer().info(*id);
  ASSERT_TRUE(info);
  const auto cells = static_cast<std::size_t>(info->cellGrid.prod());
  EXPECT_GT(info->activeCells, 0u);
  EXPECT_LT(info->activeCells, cells);
  auto rt = dm::RenderTarget::create({.width = 96, .height = 96, .samples = 1});
  ASSERT_TRUE(rt);
  const dm::Camera cam = orthoCamera(s.centre, Vec3(0.2, -0.4, 0.3), 0.07);
  dm::Image images[2];
  dm::VolumeRenderStats stats[2];
  for (int skip = 0; skip < 2; ++skip) {
    rt->clear(dm::Vec4f(0.1f, 0.1f, 0.2f, 1));
    ASSERT_TRUE(renderer().render(*rt, cam, *id, {.emptySpaceSkipping = skip == 1, .collectStats = true}));
    auto img = rt->readColor();
    ASSERT_TRUE(img);
    images[skip] = std::move(*img);
    stats[skip] = renderer().lastStats();
  }
  auto diff = dm::compareImages(images[1], images[0], {.pixelThreshold = 1, .maxFraction = 0});
  ASSERT_TRUE(diff) << diff.error();
  EXPECT_TRUE(diff->passed) << diff->differing << " pixels differ, max " << diff->maxDifference;
  EXPECT_GT(countCoveredPixels(images[0], dm::Vec3f(89, 89, 124), 8), 500u);
  EXPECT_EQ(stats[0].skippedSamples, 0u);
  EXPECT_GT(stats[1].skippedSamples, 0u);
  EXPECT_EQ(stats[0].rays, stats[1].rays);
  EXPECT_LT(stats[1].samples, stats[0].samples * 3 / 4);
  // Every lattice position up to a ray's termination is either sampled or
  // skipped, and both runs terminate at the same sample.
  EXPECT_EQ(stats[1].samples + stats[1].skippedSamples, stats[0].samples);
  EXPECT_TRUE(renderer().removeVolume(*id));
}

TEST(VolumeRenderer, OpaqueGeometryInFrontHidesItsHalfOfTheVolume) {
  DM_REQUIRE_GL();
  const SphereScene s = skewSphere();
  auto id = renderer().addVolume(s.volume);
  ASSERT_TRUE(id);
  auto rt = dm::RenderTarget::create({.width = 96, .height = 96, .samples = 4});
  ASSERT_TRUE(rt);
  const dm::Camera cam = orthoCamera(s.centre, Vec3(0.1, 1, 0.2), 0.06);
  const dm::Mat4f vp = cam.projectionMatrix(1.0) * cam.viewMatrix();
  // A quad over the left half, 5 mm in front of the sphere's nearest point.
  Vec3 front;
  ASSERT_TRUE(dm::projectToPixel(vp, s.centre - cam.forward() * (s.radius + 0.005), 96, 96, front));
  rt->bind();
  rt->clear(dm::Vec4f(0, 0, 0, 1));
  drawOpaqueQuad(-1.f, 0.f, static_cast<float>(2 * front.z() - 1), dm::Vec4f(0, 1, 0, 1));
  ASSERT_TRUE(renderer().render(*rt, cam, *id, {.mode = dm::VolumeRenderMode::Iso, .isoValue = 0.5}));
  auto img = rt->readColor();
  ASSERT_TRUE(img);
  std::size_t leftNotGreen = 0, rightLit = 0;
  for (int y = 0; y < 96; ++y)
    for (int x = 0; x < 96; ++x) {
      const bool green = img->at<std::uint8_t>(x, y, 1) == 255 && img->at<std::uint8_t>(x, y, 0) == 0;
      if (x < 48 && !green) ++leftNotGreen;
      if (x >= 48 && img->at<std::uint8_t>(x, y, 0) > 30) ++rightLit;
    }
  EXPECT_EQ(leftNotGreen, 0u);
  const double halfDisc = std::numbers::pi * std::pow(s.radius * 96 / 0.06, 2) / 2;
  EXPECT_NEAR(static_cast<double>(rightLit), halfDisc, 0.05 * halfDisc);

  // A quad behind the sphere does not hide it; the isosurface writes its
  // own depth at the sphere's front point.
  rt->clear(dm::Vec4f(0, 0, 0, 1));
  Vec3 back;
  ASSERT_TRUE(dm::projectToPixel(vp, s.centre + cam.forward() * (s.radius + 0.005), 96, 96, back));
  rt->bind();
  drawOpaqueQuad(-1.f, 1.f, static_cast<float>(2 * back.z() - 1), dm::Vec4f(0, 1, 0, 1));
  ASSERT_TRUE(renderer().render(*rt, cam, *id, {.mode = dm::VolumeRenderMode::Iso, .isoValue = 0.5}));
  auto depth = rt->readDepth();
  ASSERT_TRUE(depth);
  Vec3 nearest;
  ASSERT_TRUE(dm::projectToPixel(vp, s.centre - cam.forward() * s.radius, 96, 96, nearest));
  const double voxelDepth =
      1.6e-3 / (cam.farPlane - cam.nearPlane);  // window depth of 1.6 mm (ortho: linear)
  EXPECT_NEAR(depth->at<float>(48, 48), nearest.z(), voxelDepth);
  EXPECT_NEAR(depth->at<float>(2, 2), back.z(), 1e-6);
  EXPECT_TRUE(renderer().removeVolume(*id));
}

TEST(VolumeRenderer, FullyTransparentTransferFunctionLeavesTheBackground) {
  DM_REQUIRE_GL();
  const SphereScene s = skewSphere();
  auto id = renderer().addVolume(s.volume);
  ASSERT_TRUE(id);
  auto clear = dm::TransferFunction::create({{0, {1, 1, 1, 0}}, {1, {1, 0, 0, 0}}});
  ASSERT_TRUE(clear);
  ASSERT_TRUE(renderer().setTransferFunction(*id, *clear));
  EXPECT_EQ(renderer().info(*id)->activeCells, 0u);
  auto rt = dm::RenderTarget::create({.width = 64, .height = 64, .samples = 1});
  ASSERT_TRUE(rt);
  rt->clear(dm::Vec4f(0.2f, 0.3f, 0.4f, 1));
  auto before = rt->readColor();
  ASSERT_TRUE(before);
  for (bool skip : {false, true})
    ASSERT_TRUE(renderer().render(*rt, orthoCamera(s.centre, Vec3(1, 1, 1), 0.06), *id,
                                  {.emptySpaceSkipping = skip, .shading = true}));
  auto after = rt->readColor();
  ASSERT_TRUE(after);
  auto diff = dm::compareImages(*after, *before, {.pixelThreshold = 0, .maxFraction = 0});
  ASSERT_TRUE(diff);
  EXPECT_TRUE(diff->passed) << diff->differing << " pixels changed";
  auto depth = rt->readDepth();
  ASSERT_TRUE(depth);
  EXPECT_EQ(depth->at<float>(32, 32), 1.0f);
  EXPECT_TRUE(renderer().removeVolume(*id));
}

TEST(VolumeRenderer, SliceViewsShowTheVoxelValuesWithTheVolumesAspect) {
  DM_REQUIRE_GL();
  // A linear ramp v = 2i + 3j + 5k is reproduced exactly by trilinear
  // interpolation, so every pixel's value is known from its world point.
  const dm::Vec3i dims(20, 12, 16);
  dm::Affine3 a = dm::Affine3::Identity();
  a.linear() = Vec3(-1.5e-3, 2.0e-3, 1.0e-3).asDiagonal();  // mirrored x, anisotropic
  a.translation() = Vec3(0.02, -0.01, 0.005);
  auto vol = dm::Volume::create(dims, dm::VoxelType::U8, a);
  ASSERT_TRUE(vol);
  for (int k = 0; k < dims.z(); ++k)
    for (int j = 0; j < dims.y(); ++j)
      for (int i = 0; i < dims.x(); ++i) vol->setValue(i, j, k, 2 * i + 3 * j + 5 * k);
  auto id = renderer().addVolume(*vol);
  ASSERT_TRUE(id);
  const double vmax = 2 * 19 + 3 * 11 + 5 * 15;
  auto rt = dm::RenderTarget::create({.width = 210, .height = 80, .samples = 1});
  ASSERT_TRUE(rt);
  rt->clear(dm::Vec4f(0, 0, 1, 1));
  const Vec3 at = a * Vec3(7.2, 5.5, 9.7);
  const dm::SliceAxis axes[3] = {dm::SliceAxis::Axial, dm::SliceAxis::Coronal, dm::SliceAxis::Sagittal};
  const dm::VolumeRenderSettings settings{.windowLow = 0, .windowHigh = vmax};
  for (int v = 0; v < 3; ++v)
    ASSERT_TRUE(renderer().renderSliceView(*rt, {70 * v, 0, 70, 80}, *id, axes[v], at, settings));
  auto img = rt->readColor();
  ASSERT_TRUE(img);
  const dm::Affine3 toIndex = a.inverse();
  // World extent of the box per axis (voxel edges), m.
  const Vec3 extent = (a.linear() * dims.cast<double>()).cwiseAbs();
  const int upAxis[3] = {1, 2, 2}, rightAxis[3] = {0, 0, 1};
  for (int v = 0; v < 3; ++v) {
    auto cam = renderer().sliceViewCamera(*id, axes[v], at, 70.0 / 80.0);
    ASSERT_TRUE(cam);
    const dm::Mat4f inv =
        (cam->projectionMatrix(70.0 / 80.0) * cam->viewMatrix()).cast<double>().inverse().cast<float>();
    int checked = 0, worst = 0;
    int minX = 1000, maxX = -1, minY = 1000, maxY = -1;
    for (int y = 0; y < 80; ++y)
      for (int x = 0; x < 70; ++x) {
        const bool covered =
            img->at<std::uint8_t>(70 * v + x, y, 2) != 255 || img->at<std::uint8_t>(70 * v + x, y, 0) == 255;
        if (covered) {
          minX = std::min(minX, x), maxX = std::max(maxX, x), minY = std::min(minY, y),
          maxY = std::max(maxY, y);
        }
        const Eigen::Vector4f ndc((x + 0.5f) / 70 * 2 - 1, 1 - (y + 0.5f) / 80 * 2, 0, 1);
        const Eigen::Vector4f w = inv * ndc;
        Vec3 world = (w.head<3>() / w.w()).cast<double>();
        const int normal = v == 0 ? 2 : v == 1 ? 1 : 0;
        world[normal] = at[normal];
        const Vec3 ijk = toIndex * world;
        if ((ijk.array() < 0.2).any() || (ijk.array() > dims.cast<double>().array() - 1.2).any()) continue;
        const double value = 2 * ijk.x() + 3 * ijk.y() + 5 * ijk.z();
        const int got = img->at<std::uint8_t>(70 * v + x, y, 0);
        worst = std::max(worst, static_cast<int>(std::abs(got - srgb8Unrounded(value / vmax))));
        ++checked;
      }
    EXPECT_GT(checked, 300) << "view " << v;
    EXPECT_LE(worst, 2) << "view " << v;
    // Same metres per pixel on both image axes: the covered rectangle has
    // the box's world aspect.
    const double wPx = maxX - minX + 1, hPx = maxY - minY + 1;
    const double scale = std::min(70 / extent[rightAxis[v]], 80 / extent[upAxis[v]]);
    EXPECT_NEAR(wPx, extent[rightAxis[v]] * scale, 1.5) << "view " << v;
    EXPECT_NEAR(hPx, extent[upAxis[v]] * scale, 1.5) << "view " << v;
  }
  // Radiological axial view: patient right (+x, i decreasing here) on the
  // image left, so values grow to the right; anterior (+y) up.
  const int row = 40, col = 35;
  EXPECT_GT(img->at<std::uint8_t>(col + 8, row, 0), img->at<std::uint8_t>(col - 8, row, 0));
  EXPECT_GT(img->at<std::uint8_t>(col, row - 8, 0), img->at<std::uint8_t>(col, row + 8, 0));
  EXPECT_TRUE(renderer().removeVolume(*id));
}

TEST(VolumeRenderer, SlicePlaneIn3DShowsTheValueWhereEachRayMeetsThePlane) {
  DM_REQUIRE_GL();
  // Linear ramp (exact under trilinear filtering) in a skew volume; a
  // coronal plane seen obliquely by a perspective camera.
  const dm::Affine3 a = skewAffine(Vec3(1.0e-3, 1.5e-3, 1.2e-3), Vec3(0.01, 0.0, -0.02));
  const dm::Vec3i dims(24, 20, 18);
  auto vol = dm::Volume::create(dims, dm::VoxelType::F32, a);
  ASSERT_TRUE(vol);
  for (int k = 0; k < dims.z(); ++k)
    for (int j = 0; j < dims.y(); ++j)
      for (int i = 0; i < dims.x(); ++i) vol->setValue(i, j, k, 1.5 * i + 2 * j + 2.5 * k);
  auto id = renderer().addVolume(*vol);
  ASSERT_TRUE(id);
  const double vmax = 1.5 * 23 + 2 * 19 + 2.5 * 17;
  const Vec3 c = volumeCentre(*vol);
  dm::Camera cam = dm::Camera::lookAt(c + Vec3(0.03, 0.06, 0.025), c, Vec3(0, 0, 1));
  cam.fovYDeg = 40;
  auto rt = dm::RenderTarget::create({.width = 96, .height = 80, .samples = 1});
  ASSERT_TRUE(rt);
  rt->clear(dm::Vec4f(0, 0, 1, 1));
  ASSERT_TRUE(renderer().render(*rt, cam, *id,
                                {.mode = dm::VolumeRenderMode::Slice,
                                 .windowLow = 0,
                                 .windowHigh = vmax,
                                 .sliceAxis = dm::SliceAxis::Coronal,
                                 .slicePosition = c}));
  auto img = rt->readColor();
  ASSERT_TRUE(img);
  const dm::Mat4f inv =
      (cam.projectionMatrix(96.0 / 80.0) * cam.viewMatrix()).cast<double>().inverse().cast<float>();
  const dm::Affine3 toIndex = a.inverse();
  int inside = 0, outside = 0, worst = 0;
  for (int y = 0; y < 80; y += 2)
    for (int x = 0; x < 96; x += 2) {
      const float nx = (x + 0.5f) / 96 * 2 - 1, ny = 1 - (y + 0.5f) / 80 * 2;
      const Eigen::Vector4f n = inv * Eigen::Vector4f(nx, ny, -1, 1), f = inv * Eigen::Vector4f(nx, ny, 1, 1);
      const Vec3 p0 = (n.head<3>() / n.w()).cast<double>(), p1 = (f.head<3>() / f.w()).cast<double>();
      const double t = (c.y() - p0.y()) / (p1.y() - p0.y());
      const Vec3 ijk = toIndex * (p0 + t * (p1 - p0));
      const bool background = img->at<std::uint8_t>(x, y, 2) == 255 && img->at<std::uint8_t>(x, y, 0) == 0;
      if ((ijk.array() < -0.7).any() || (ijk.array() > dims.cast<double>().array() - 0.3).any()) {
        outside += background ? 0 : 1;  // clearly outside the box: untouched
        continue;
      }
      if ((ijk.array() < 0.3).any() || (ijk.array() > dims.cast<double>().array() - 1.3).any()) continue;
      const double v = 1.5 * ijk.x() + 2 * ijk.y() + 2.5 * ijk.z();
      worst = std::max(worst,
                       static_cast<int>(std::abs(img->at<std::uint8_t>(x, y, 0) - srgb8Unrounded(v / vmax))));
      ++inside;
    }
  EXPECT_GT(inside, 200);
  EXPECT_EQ(outside, 0);
  EXPECT_LE(worst, 2);
  EXPECT_TRUE(renderer().removeVolume(*id));
}

TEST(VolumeRenderer, IsoShadingFollowsLambertOnASphere) {
  DM_REQUIRE_GL();
  // A wide ramp (8 mm) keeps the field smooth around the surface, so the
  // central-difference gradient is radial up to interpolation error.
  const SphereScene s = skewSphere(8e-3);
  auto id = renderer().addVolume(s.volume);
  ASSERT_TRUE(id);
  auto rt = dm::RenderTarget::create({.width = 96, .height = 96, .samples = 1});
  ASSERT_TRUE(rt);
  const double height = 0.06, pxPerM = 96 / height;
  const dm::Camera cam = orthoCamera(s.centre, Vec3(0.4, -0.3, 0.6), height);
  // Diffuse only, white: a pixel at distance rho from the disc centre sees
  // the normal at angle asin(rho / r) from the view direction.
  const dm::VolumeRenderSettings headlight{.mode = dm::VolumeRenderMode::Iso,
                                           .ambient = 0,
                                           .diffuse = 1,
                                           .specular = 0,
                                           .isoValue = 0.5,
                                           .isoColor = Vec3(1, 1, 1)};
  rt->clear(dm::Vec4f(0, 0, 0, 1));
  ASSERT_TRUE(renderer().render(*rt, cam, *id, headlight));
  auto img = rt->readColor();
  ASSERT_TRUE(img);
  int checked = 0;
  double worst = 0;
  for (int y = 0; y < 96; y += 3)
    for (int x = 0; x < 96; x += 3) {
      const double rho = std::hypot(x + 0.5 - 48, y + 0.5 - 48) / pxPerM / s.radius;
      if (rho > 0.8) continue;  // the silhouette's slope magnifies sub-voxel offsets
      worst = std::max(worst, std::abs(linear(img->at<std::uint8_t>(x, y, 0)) - std::sqrt(1 - rho * rho)));
      ++checked;
    }
  EXPECT_GT(checked, 100);
  EXPECT_LT(worst, 0.04);
  // A light from the camera's right: the left half of the disc faces away
  // and stays black (no ambient), the right rim is lit.
  dm::VolumeRenderSettings side = headlight;
  side.lightDirection = cam.right();
  rt->clear(dm::Vec4f(0, 0, 0, 1));
  ASSERT_TRUE(renderer().render(*rt, cam, *id, side));
  auto lit = rt->readColor();
  ASSERT_TRUE(lit);
  const int r = static_cast<int>(s.radius * pxPerM);
  EXPECT_LE(lit->at<std::uint8_t>(48 - r / 2, 48, 0), 2);
  EXPECT_GT(linear(lit->at<std::uint8_t>(48 + r * 3 / 4, 48, 0)), 0.6);
  EXPECT_TRUE(renderer().removeVolume(*id));
}

TEST(VolumeRenderer, IsoSurfaceLinesUpWithTheMarchingCubesMesh) {
  DM_REQUIRE_GL();
  // The ray-cast isosurface and the marching-cubes mesh of the same skew,
  // anisotropic volume must project to the same pixels and depths.
  const SphereScene s = skewSphere();
  const dm::Volume& vol = s.volume;
  auto id = renderer().addVolume(vol);
  ASSERT_TRUE(id);
  auto mesh = dm::extractIsosurface(vol, {.iso = 0.5, .computeNormals = false, .threads = 1});
  ASSERT_TRUE(mesh) << mesh.error();
  auto rt = dm::RenderTarget::create({.width = 128, .height = 128, .samples = 1});
  ASSERT_TRUE(rt);
  dm::Camera cam = dm::Camera::lookAt(s.centre + Vec3(0.05, 0.07, 0.04), s.centre + Vec3(0.004, 0, -0.003));
  cam.fovYDeg = 40;
  rt->clear(dm::Vec4f(0, 0, 0, 1));
  ASSERT_TRUE(renderer().render(*rt, cam, *id, {.mode = dm::VolumeRenderMode::Iso, .isoValue = 0.5}));
  auto img = rt->readColor();
  auto depth = rt->readDepth();
  ASSERT_TRUE(img && depth);
  const dm::Mat4f vp = cam.projectionMatrix(1.0) * cam.viewMatrix();
  double x0 = 1e9, x1 = -1e9, y0 = 1e9, y1 = -1e9;
  for (const Vec3& p : mesh->positions) {
    Vec3 px;
    ASSERT_TRUE(dm::projectToPixel(vp, p, 128, 128, px));
    x0 = std::min(x0, px.x()), x1 = std::max(x1, px.x()), y0 = std::min(y0, px.y()),
    y1 = std::max(y1, px.y());
  }
  int cx0 = 1000, cx1 = -1, cy0 = 1000, cy1 = -1;
  for (int y = 0; y < 128; ++y)
    for (int x = 0; x < 128; ++x)
      if (img->at<std::uint8_t>(x, y, 0) > 0) {
        cx0 = std::min(cx0, x), cx1 = std::max(cx1, x), cy0 = std::min(cy0, y), cy1 = std::max(cy1, y);
      }
  // Covered pixel centres lie inside the mesh's projected extent, within a pixel.
  EXPECT_NEAR(cx0 + 0.5, x0, 1.0);
  EXPECT_NEAR(cx1 + 0.5, x1, 1.0);
  EXPECT_NEAR(cy0 + 0.5, y0, 1.0);
  EXPECT_NEAR(cy1 + 0.5, y1, 1.0);
  // The depth written at the projection of the mesh point nearest the
  // camera is that point's depth.
  Vec3 nearest = mesh->positions.front();
  for (const Vec3& p : mesh->positions)
    if ((p - cam.position).norm() < (nearest - cam.position).norm()) nearest = p;
  Vec3 px;
  ASSERT_TRUE(dm::projectToPixel(vp, nearest, 128, 128, px));
  const float written = depth->at<float>(static_cast<int>(px.x()), static_cast<int>(px.y()));
  Vec3 behind;
  ASSERT_TRUE(dm::projectToPixel(vp, nearest + cam.forward() * 0.5e-3, 128, 128, behind));
  EXPECT_NEAR(written, px.z(), behind.z() - px.z());  // within half a millimetre
  EXPECT_TRUE(renderer().removeVolume(*id));
}

TEST(VolumeRenderer, VoxelCubesDrawEveryVoxelAboveTheThreshold) {
  DM_REQUIRE_GL();
  const SphereScene s = skewSphere();
  auto id = renderer().addVolume(s.volume);
  ASSERT_TRUE(id);
  std::uint64_t expected = 0;
  for (std::size_t i = 0; i < s.volume.voxelCount(); ++i) expected += s.volume.valueAt(i) >= 0.5 ? 1 : 0;
  auto rt = dm::RenderTarget::create({.width = 96, .height = 96, .samples = 1});
  ASSERT_TRUE(rt);
  rt->clear(dm::Vec4f(0, 0, 0, 1));
  const dm::Camera cam = orthoCamera(s.centre, Vec3(0.3, 0.2, 0.5), 0.06);
  ASSERT_TRUE(
      renderer().render(*rt, cam, *id, {.mode = dm::VolumeRenderMode::Voxels, .voxelThreshold = 0.5}));
  EXPECT_EQ(renderer().lastStats().voxelsDrawn, expected);
  auto img = rt->readColor();
  ASSERT_TRUE(img);
  // The cubes' silhouette is the sphere's disc up to a voxel of stair steps.
  const double disc = std::numbers::pi * std::pow(s.radius * 96 / 0.06, 2);
  EXPECT_NEAR(static_cast<double>(dm::countCoveredPixels(*img, dm::Vec3f(0, 0, 0), 4)), disc, 0.1 * disc);
  EXPECT_TRUE(renderer().removeVolume(*id));
}

TEST(VolumeRenderer, RefusesBadInputNamingIt) {
  DM_REQUIRE_GL();
  const int max3d = dm::test::renderContext()->info().max3dTextureSize;
  auto tooLong = dm::Volume::create({max3d + 1, 1, 2}, dm::VoxelType::U8);
  ASSERT_TRUE(tooLong);
  auto refused = renderer().addVolume(*tooLong);
  ASSERT_FALSE(refused);
  EXPECT_NE(refused.error().what.find("dims[0]"), std::string::npos) << refused.error();
  EXPECT_NE(refused.error().what.find("GL_MAX_3D_TEXTURE_SIZE"), std::string::npos);

  auto small = dm::Volume::create({4, 4, 4}, dm::VoxelType::F64);
  ASSERT_TRUE(small);
  auto id = renderer().addVolume(*small);
  ASSERT_TRUE(id) << id.error();
  auto rt = dm::RenderTarget::create({.width = 8, .height = 8, .samples = 1});
  ASSERT_TRUE(rt);
  const dm::Camera cam = dm::Camera::lookAt(Vec3(0, 0, 1), Vec3(0, 0, 0));
  auto badStep = renderer().render(*rt, cam, *id, {.stepVoxels = 0});
  ASSERT_FALSE(badStep);
  EXPECT_EQ(badStep.error().where, "VolumeRenderSettings::stepVoxels");
  auto badViewport = renderer().render(*rt, cam, *id, {.viewport = {4, 4, 8, 8}});
  ASSERT_FALSE(badViewport);
  EXPECT_NE(badViewport.error().what.find("outside the 8x8 target"), std::string::npos);
  ASSERT_TRUE(renderer().removeVolume(*id));
  auto stale = renderer().render(*rt, cam, *id, {});
  ASSERT_FALSE(stale);
  EXPECT_EQ(stale.error().code, dm::ErrorCode::NotFound);
  EXPECT_FALSE(renderer().setTransferFunction(*id, *dm::TransferFunction::greyRamp(0, 1)));
  // A reused slot gets a new generation.
  auto again = renderer().addVolume(*small);
  ASSERT_TRUE(again);
  EXPECT_EQ(again->index, id->index);
  EXPECT_NE(again->generation, id->generation);
  EXPECT_TRUE(renderer().removeVolume(*again));
}

// ---- Colin27 goldens, each paired with reference-independent checks --------

class VolumeColin : public ::testing::Test {
 protected:
  void SetUp() override {
    DM_REQUIRE_GL();
    vol_ = colin();
    ASSERT_NE(vol_, nullptr) << "mricron:ch2.nii.gz (apt install mricron-data)";
    auto id = renderer().addVolume(*vol_);
    ASSERT_TRUE(id) << id.error();
    id_ = *id;
  }
  void TearDown() override {
    if (id_.generation != 0) {
      EXPECT_TRUE(renderer().removeVolume(id_));
    }
  }
  const dm::Volume* vol_ = nullptr;
  dm::VolumeId id_;
};

TEST_F(VolumeColin, CompositeSkinGolden) {
  auto skin = dm::TransferFunction::mriSkin(0, 255);
  ASSERT_TRUE(skin);
  ASSERT_TRUE(renderer().setTransferFunction(id_, *skin));
  auto rt = dm::RenderTarget::create({.width = 160, .height = 160, .samples = 1});
  ASSERT_TRUE(rt);
  rt->clear(dm::Vec4f(0, 0, 0, 1));
  const Vec3 c = vol_->worldBounds().center();
  dm::Camera cam = dm::Camera::lookAt(c + Vec3(0.25, 0.35, 0.12), c, Vec3(0, 0, 1));
  cam.fovYDeg = 40;
  ASSERT_TRUE(renderer().render(*rt, cam, id_, {.stepVoxels = 1.0}));
  auto img = rt->readColor();
  ASSERT_TRUE(img);
  // The head is opaque skin: its silhouette covers a good part of the image
  // and everything lies inside the projected volume box.
  const dm::Mat4f vp = cam.projectionMatrix(1.0) * cam.viewMatrix();
  double x0 = 1e9, x1 = -1e9, y0 = 1e9, y1 = -1e9;
  const dm::Aabb b = vol_->worldBounds();
  for (int k = 0; k < 8; ++k) {
    Vec3 p;
    ASSERT_TRUE(dm::projectToPixel(vp, b.corner(static_cast<dm::Aabb::CornerType>(k)), 160, 160, p));
    x0 = std::min(x0, p.x()), x1 = std::max(x1, p.x()), y0 = std::min(y0, p.y()), y1 = std::max(y1, p.y());
  }
  std::size_t covered = 0, outside = 0;
  for (int y = 0; y < 160; ++y)
    for (int x = 0; x < 160; ++x) {
      if (img->at<std::uint8_t>(x, y, 0) < 20) continue;
      ++covered;
      if (x + 0.5 < x0 - 1 || x + 0.5 > x1 + 1 || y + 0.5 < y0 - 1 || y + 0.5 > y1 + 1) ++outside;
    }
  EXPECT_EQ(outside, 0u);
  EXPECT_GT(covered, 160u * 160u / 5);
  auto r = dm::checkGolden(*img, dm::test::goldenDir() / "volume_ch2_composite.png", dm::test::renderOutDir(),
                           {.pixelThreshold = 12, .maxFraction = 0.005});
  EXPECT_TRUE(r) << r.error();
}

TEST_F(VolumeColin, MipGolden) {
  auto rt = dm::RenderTarget::create({.width = 160, .height = 192, .samples = 1});
  ASSERT_TRUE(rt);
  rt->clear(dm::Vec4f(0, 0, 0, 1));
  const Vec3 c = vol_->worldBounds().center();
  // Seen from the front (anterior, +y), orthographic.
  dm::Camera cam = dm::Camera::lookAt(c + Vec3(0, 0.5, 0), c, Vec3(0, 0, 1));
  cam.projection = dm::Camera::Projection::Orthographic;
  cam.orthoHeight = 0.24;
  ASSERT_TRUE(renderer().render(*rt, cam, id_, {.mode = dm::VolumeRenderMode::Mip, .stepVoxels = 1.0}));
  auto img = rt->readColor();
  ASSERT_TRUE(img);
  // Reference-independent: along the central column every pixel is the
  // maximum of the voxels on its ray; check the brightest pixel against the
  // volume's maximum and an empty corner against the background.
  int brightest = 0;
  for (int y = 0; y < 192; ++y)
    for (int x = 0; x < 160; ++x) brightest = std::max<int>(brightest, img->at<std::uint8_t>(x, y, 0));
  const auto [lo, hi] = vol_->range();
  EXPECT_GE(brightest, static_cast<int>(srgb8Unrounded(0.9)));
  EXPECT_EQ(img->at<std::uint8_t>(1, 1, 0), 0);
  EXPECT_EQ(lo, 0.0);
  EXPECT_GT(hi, 200.0);
  auto r = dm::checkGolden(*img, dm::test::goldenDir() / "volume_ch2_mip.png", dm::test::renderOutDir(),
                           {.pixelThreshold = 12, .maxFraction = 0.005});
  EXPECT_TRUE(r) << r.error();
}

TEST_F(VolumeColin, SlicesGolden) {
  auto rt = dm::RenderTarget::create({.width = 240, .height = 96, .samples = 1});
  ASSERT_TRUE(rt);
  rt->clear(dm::Vec4f(0, 0, 0, 1));
  const Vec3 at = vol_->indexToWorld() * Vec3(90, 108, 80);
  const dm::SliceAxis axes[3] = {dm::SliceAxis::Axial, dm::SliceAxis::Coronal, dm::SliceAxis::Sagittal};
  for (int v = 0; v < 3; ++v)
    ASSERT_TRUE(renderer().renderSliceView(*rt, {80 * v, 0, 80, 96}, id_, axes[v], at));
  auto img = rt->readColor();
  ASSERT_TRUE(img);
  // Reference-independent: pixel centres show the trilinear voxel value at
  // their world point on the plane (window = the volume's range).
  const auto [lo, hi] = vol_->range();
  for (int v = 0; v < 3; ++v) {
    auto cam = renderer().sliceViewCamera(id_, axes[v], at, 80.0 / 96.0);
    ASSERT_TRUE(cam);
    const dm::Mat4f inv =
        (cam->projectionMatrix(80.0 / 96.0) * cam->viewMatrix()).cast<double>().inverse().cast<float>();
    int checked = 0, bad = 0;
    for (int y = 4; y < 96; y += 7)
      for (int x = 3; x < 80; x += 5) {
        const Eigen::Vector4f w =
            inv * Eigen::Vector4f((x + 0.5f) / 80 * 2 - 1, 1 - (y + 0.5f) / 96 * 2, 0, 1);
        Vec3 world = (w.head<3>() / w.w()).cast<double>();
        const int normal = v == 0 ? 2 : v == 1 ? 1 : 0;
        world[normal] = at[normal];
        const Vec3 ijk = vol_->worldToIndex() * world;
        if ((ijk.array() < 0).any() || (ijk.array() > vol_->dims().cast<double>().array() - 1).any())
          continue;
        const double expected = (vol_->sampleWorld(world) - lo) / (hi - lo);
        // Compared in linear units: texture filtering runs at 8-bit weight
        // precision on llvmpipe, which the sRGB curve magnifies in the dark.
        if (std::abs(linear(img->at<std::uint8_t>(80 * v + x, y, 0)) - expected) > 0.015) ++bad;
        ++checked;
      }
    EXPECT_GT(checked, 80) << "view " << v;
    EXPECT_LE(bad, checked / 50) << "view " << v;
  }
  auto r = dm::checkGolden(*img, dm::test::goldenDir() / "volume_ch2_slices.png", dm::test::renderOutDir(),
                           {.pixelThreshold = 12, .maxFraction = 0.005});
  EXPECT_TRUE(r) << r.error();
}

// The skin as marching-cubes mesh (SceneRenderer) and as the volume's own
// first hit of the same iso value (VolumeRenderer) under one camera: their
// silhouettes agree to well under a pixel along the outline (measured: 19
// pixels disagree along an outline of 331). The golden shows
// the mesh on the left half and the volume on the right.
TEST_F(VolumeColin, MeshOverVolumeAlignmentGolden) {
  constexpr int kSize = 160;
  constexpr double kIso = 40;
  auto mesh = dm::extractIsosurface(*vol_, {.iso = kIso, .closeBorders = true});
  ASSERT_TRUE(mesh) << mesh.error();
  const Vec3 c = vol_->worldBounds().center();
  dm::Camera cam = dm::Camera::lookAt(c + Vec3(0.3, 0.3, 0.1), c, Vec3(0, 0, 1));
  cam.fovYDeg = 40;
  cam.nearPlane = 0.1;
  cam.farPlane = 1.0;

  auto volumeRt = dm::RenderTarget::create({.width = kSize, .height = kSize, .samples = 1});
  ASSERT_TRUE(volumeRt);
  volumeRt->clear(dm::Vec4f(0, 0, 0, 1));
  ASSERT_TRUE(renderer().render(*volumeRt, cam, id_,
                                {.mode = dm::VolumeRenderMode::Iso,
                                 .stepVoxels = 0.25,
                                 .isoValue = kIso,
                                 .isoColor = Vec3(0.35, 0.55, 0.9)}));
  auto volumeImg = volumeRt->readColor();
  ASSERT_TRUE(volumeImg);

  auto scene = dm::SceneRenderer::create();
  ASSERT_TRUE(scene) << scene.error();
  auto meshId = scene->addMesh(*mesh);
  ASSERT_TRUE(meshId) << meshId.error();
  auto mat = scene->addMaterial({.baseColor = dm::Vec4f(0.9f, 0.55f, 0.35f, 1)});
  ASSERT_TRUE(mat);
  const dm::DrawItem item{.mesh = *meshId, .material = *mat};
  const dm::Light light =
      dm::Light::directional(cam.forward() + Vec3(0, 0, -0.3), 1.0f);  // a headlight from above
  auto meshRt = dm::RenderTarget::create({.width = kSize, .height = kSize, .samples = 1});
  ASSERT_TRUE(meshRt);
  ASSERT_TRUE(scene->render(*meshRt, cam, {&item, 1}, {&light, 1}, {.background = dm::Vec4f(0, 0, 0, 1)}));
  auto meshImg = meshRt->readColor();
  ASSERT_TRUE(meshImg);

  // Silhouettes: covered pixels of each, their disagreement against the
  // outline length (pixels with an uncovered 4-neighbour).
  auto covered = [](const dm::Image& img, int x, int y) {
    return img.at<std::uint8_t>(x, y, 0) > 8 || img.at<std::uint8_t>(x, y, 1) > 8 ||
           img.at<std::uint8_t>(x, y, 2) > 8;
  };
  std::size_t area = 0, outline = 0, disagree = 0;
  for (int y = 1; y + 1 < kSize; ++y)
    for (int x = 1; x + 1 < kSize; ++x) {
      const bool m = covered(*meshImg, x, y), v = covered(*volumeImg, x, y);
      area += m;
      disagree += m != v;
      if (m && (!covered(*meshImg, x - 1, y) || !covered(*meshImg, x + 1, y) ||
                !covered(*meshImg, x, y - 1) || !covered(*meshImg, x, y + 1)))
        ++outline;
    }
  ASSERT_GT(area, std::size_t(kSize * kSize / 8));
  // A one-pixel shift of either would disagree along about half the outline.
  EXPECT_LT(double(disagree), 0.25 * double(outline)) << disagree << " pixels disagree along " << outline;
  std::printf("silhouettes: %zu pixels disagree along an outline of %zu\n", disagree, outline);

  dm::Image composed = meshImg->clone();
  for (int y = 0; y < kSize; ++y)
    for (int x = kSize / 2; x < kSize; ++x)
      for (int ch = 0; ch < 4; ++ch)
        composed.at<std::uint8_t>(x, y, ch) = volumeImg->at<std::uint8_t>(x, y, ch);
  auto r = dm::checkGolden(composed, dm::test::goldenDir() / "volume_ch2_mesh_alignment.png",
                           dm::test::renderOutDir(), {.pixelThreshold = 12, .maxFraction = 0.005});
  EXPECT_TRUE(r) << r.error();
}
