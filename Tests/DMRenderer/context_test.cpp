// Headless context, render targets, read-back and shader errors.
#include <dm/renderer/context.hpp>
#include <dm/renderer/image_compare.hpp>
#include <dm/renderer/render_target.hpp>
#include <dm/renderer/shader.hpp>

#include <cmath>

#include "render_fixture.hpp"

namespace {

// sRGB encoding of a linear value, rounded to the stored byte.
int srgb8(double linear) { return static_cast<int>(std::lround(dm::test::srgbEncode255(linear))); }

using dm::test::kFlatFs;
using dm::test::kFlatVs;

}  // namespace

TEST(GlContext, Gives45CoreHeadless) {
  DM_REQUIRE_GL();
  const dm::ContextInfo& info = dm::test::renderContext()->info();
  EXPECT_NE(info.platform, dm::EglPlatform::Auto);
  EXPECT_NE(info.glVersion.find("4."), std::string::npos) << info.glVersion;
  EXPECT_FALSE(info.glRenderer.empty());
  EXPECT_GE(info.maxTextureSize, 4096);
  EXPECT_GE(info.max3dTextureSize, 256);
  EXPECT_TRUE(dm::test::renderContext()->isCurrent());
}

TEST(GlContext, PlatformNamesRoundTripAndBadOnesAreRefused) {
  for (auto p : {dm::EglPlatform::Auto, dm::EglPlatform::Device, dm::EglPlatform::Surfaceless})
    EXPECT_EQ(*dm::parseEglPlatform(dm::toString(p)), p);
  auto bad = dm::parseEglPlatform("wayland");
  ASSERT_FALSE(bad);
  EXPECT_EQ(bad.error().where, "DM_EGL_PLATFORM");
  EXPECT_NE(bad.error().hint.find("surfaceless"), std::string::npos);
}

TEST(GlContext, EveryListedDeviceIsNumberedInOrder) {
  const auto devices = dm::listEglDevices();
  for (std::size_t i = 0; i < devices.size(); ++i) EXPECT_EQ(devices[i].index, static_cast<int>(i));
}

TEST(GlContext, SecondContextCoexistsAndFirstStaysUsable) {
  DM_REQUIRE_GL();
  {
    auto second = dm::GlContext::create(
        {.platform = dm::test::renderContext()->info().platform, .ignoreEnvironment = true});
    ASSERT_TRUE(second) << second.error();
    EXPECT_TRUE((*second)->isCurrent());
    EXPECT_FALSE(dm::test::renderContext()->isCurrent());
  }
  // Destroying the second must not terminate the display the first uses.
  ASSERT_TRUE(dm::test::renderContext()->makeCurrent());
  auto rt = dm::RenderTarget::create({.width = 8, .height = 8, .samples = 1});
  ASSERT_TRUE(rt) << rt.error();
  rt->clear(dm::Vec4f(1, 0, 0, 1));
  auto img = rt->readColor();
  ASSERT_TRUE(img);
  EXPECT_EQ(img->at<std::uint8_t>(3, 3, 0), 255);
}

// The EGL device platform end to end on whichever device is enumerated
// (Mesa's software device on CI machines, a GPU where there is one): a
// context on it draws, and asking for a device that is not there names the
// index and the count.
TEST(GlContext, DevicePlatformDrawsOnAnEnumeratedDevice) {
  DM_REQUIRE_GL();
  const auto devices = dm::listEglDevices();
  if (devices.empty()) GTEST_SKIP() << "no EGL device is enumerated here";
  {
    auto ctx = dm::GlContext::create({.platform = dm::EglPlatform::Device, .deviceIndex = 0, .ignoreEnvironment = true});
    ASSERT_TRUE(ctx) << ctx.error();
    EXPECT_EQ((*ctx)->info().platform, dm::EglPlatform::Device);
    EXPECT_EQ((*ctx)->info().deviceIndex, 0);
    EXPECT_NE((*ctx)->info().glVersion.find("4."), std::string::npos) << (*ctx)->info().glVersion;
    auto rt = dm::RenderTarget::create({.width = 16, .height = 16, .samples = 1});
    ASSERT_TRUE(rt) << rt.error();
    rt->bind();
    rt->clear(dm::Vec4f(0, 0, 1, 1));
    ASSERT_TRUE(dm::test::drawNdcRect(-1, -1, 0, 1, 0, dm::Vec4f(1, 0, 0, 1)));  // the left half red
    auto img = rt->readColor();
    ASSERT_TRUE(img);
    EXPECT_EQ(img->at<std::uint8_t>(4, 8, 0), 255);
    EXPECT_EQ(img->at<std::uint8_t>(4, 8, 2), 0);
    EXPECT_EQ(img->at<std::uint8_t>(12, 8, 0), 0);
    EXPECT_EQ(img->at<std::uint8_t>(12, 8, 2), 255);
  }
  auto missing = dm::GlContext::create({.platform = dm::EglPlatform::Device,
                                        .deviceIndex = int(devices.size()) + 3,
                                        .ignoreEnvironment = true});
  ASSERT_FALSE(missing);
  EXPECT_NE(missing.error().message().find("index " + std::to_string(devices.size() + 3) + " requested"),
            std::string::npos)
      << missing.error().message();
  ASSERT_TRUE(dm::test::renderContext()->makeCurrent());
}

TEST(RenderTarget, ClearReadsBackSrgbEncoded) {
  DM_REQUIRE_GL();
  auto rt = dm::RenderTarget::create({.width = 32, .height = 16, .samples = 4});
  ASSERT_TRUE(rt) << rt.error();
  rt->bind();
  rt->clear(dm::Vec4f(0.5f, 0.25f, 0.0f, 1.0f));
  auto img = rt->readColor();
  ASSERT_TRUE(img) << img.error();
  ASSERT_EQ(img->width(), 32);
  ASSERT_EQ(img->height(), 16);
  ASSERT_EQ(img->channels(), 4);
  EXPECT_NEAR(img->at<std::uint8_t>(5, 7, 0), srgb8(0.5), 1);
  EXPECT_NEAR(img->at<std::uint8_t>(5, 7, 1), srgb8(0.25), 1);
  EXPECT_EQ(img->at<std::uint8_t>(5, 7, 2), 0);
  EXPECT_EQ(img->at<std::uint8_t>(5, 7, 3), 255);
}

TEST(RenderTarget, RowsComeBackTopToBottomAndViewportsAddressFromTheTop) {
  DM_REQUIRE_GL();
  auto rt = dm::RenderTarget::create({.width = 40, .height = 20, .samples = 1, .srgb = false});
  ASSERT_TRUE(rt);
  rt->clear(dm::Vec4f(0, 0, 0, 1));
  // A full-viewport quad drawn into the top-left 10x5 viewport only.
  rt->bindViewport(0, 0, 10, 5);
  ASSERT_TRUE(dm::test::drawNdcRect(-1, -1, 1, 1, 0.0f, dm::Vec4f(0, 1, 0, 1)));
  auto img = rt->readColor();
  ASSERT_TRUE(img);
  EXPECT_EQ(dm::countCoveredPixels(*img, dm::Vec3f(0, 0, 0)), 50u);
  EXPECT_EQ(img->at<std::uint8_t>(0, 0, 1), 255);
  EXPECT_EQ(img->at<std::uint8_t>(9, 4, 1), 255);
  EXPECT_EQ(img->at<std::uint8_t>(10, 4, 1), 0);
  EXPECT_EQ(img->at<std::uint8_t>(0, 5, 1), 0);
  auto depth = rt->readDepth();
  ASSERT_TRUE(depth);
  // NDC z = 0 maps to window depth 0.5; cleared pixels stay at 1.
  EXPECT_FLOAT_EQ(depth->at<float>(2, 2), 0.5f);
  EXPECT_FLOAT_EQ(depth->at<float>(30, 15), 1.0f);
}

TEST(RenderTarget, RefusesBadSizes) {
  DM_REQUIRE_GL();
  auto zero = dm::RenderTarget::create({.width = 0, .height = 10});
  ASSERT_FALSE(zero);
  EXPECT_NE(zero.error().what.find("0x10"), std::string::npos);
  auto huge = dm::RenderTarget::create({.width = 1 << 20, .height = 4});
  EXPECT_FALSE(huge);
  EXPECT_FALSE(dm::RenderTarget::create({.width = 4, .height = 4, .samples = 0}));
}

TEST(AsyncReadback, MatchesSynchronousReadAndRefusesWhenFull) {
  DM_REQUIRE_GL();
  auto rt = dm::RenderTarget::create({.width = 64, .height = 48, .samples = 4});
  ASSERT_TRUE(rt);
  auto ring = dm::AsyncReadback::create(64, 48, 2);
  ASSERT_TRUE(ring) << ring.error();
  rt->clear(dm::Vec4f(0.2f, 0.4f, 0.6f, 1));
  ASSERT_TRUE(ring->request(*rt));
  rt->clear(dm::Vec4f(1, 1, 0, 1));
  ASSERT_TRUE(ring->request(*rt));
  auto full = ring->request(*rt);
  ASSERT_FALSE(full);
  EXPECT_EQ(full.error().code, dm::ErrorCode::Busy);
  auto first = ring->wait();
  ASSERT_TRUE(first) << first.error();
  EXPECT_NEAR(first->at<std::uint8_t>(10, 10, 2), srgb8(0.6), 1);
  auto second = ring->wait();
  ASSERT_TRUE(second);
  auto sync = rt->readColor();
  ASSERT_TRUE(sync);
  auto diff = dm::compareImages(*second, *sync, {.pixelThreshold = 0, .maxFraction = 0});
  ASSERT_TRUE(diff) << diff.error();
  EXPECT_TRUE(diff->passed);
  EXPECT_EQ(ring->pending(), 0);
  EXPECT_EQ(ring->wait().error().code, dm::ErrorCode::NotFound);
  auto polled = ring->poll();
  ASSERT_TRUE(polled);
  EXPECT_FALSE(polled->has_value());
  auto small = dm::RenderTarget::create({.width = 8, .height = 8, .samples = 1});
  EXPECT_FALSE(ring->request(*small));
}

TEST(ShaderProgram, CompileErrorNamesProgramStageAndLine) {
  DM_REQUIRE_GL();
  const char* badFs = "out vec4 o;\nvoid main() {\n  o = vec4(undefined_name, 1.0);\n}\n";
  auto prog = dm::ShaderProgram::create(
      "broken", {{dm::ShaderStage::Vertex, kFlatVs}, {dm::ShaderStage::Fragment, badFs}});
  ASSERT_FALSE(prog);
  EXPECT_EQ(prog.error().code, dm::ErrorCode::Parse);
  EXPECT_EQ(prog.error().where, "shader broken, fragment stage");
  EXPECT_NE(prog.error().what.find("undefined_name"), std::string::npos) << prog.error().what;
  EXPECT_NE(prog.error().hint.find("line 3"), std::string::npos) << prog.error().hint;
}

TEST(ShaderProgram, LinkErrorNamesProgram) {
  DM_REQUIRE_GL();
  const char* fsNeedsInput = "in vec3 v_missing;\nout vec4 o;\nvoid main() { o = vec4(v_missing, 1.0); }\n";
  auto prog = dm::ShaderProgram::create(
      "mismatch", {{dm::ShaderStage::Vertex, kFlatVs}, {dm::ShaderStage::Fragment, fsNeedsInput}});
  ASSERT_FALSE(prog);
  EXPECT_EQ(prog.error().where, "shader mismatch");
}

TEST(ShaderProgram, DefinesSelectVariants) {
  DM_REQUIRE_GL();
  const char* fs = "out vec4 o;\nvoid main() { o = vec4(VALUE, 0.0, 0.0, 1.0); }\n";
  auto prog = dm::ShaderProgram::create(
      "variant", {{dm::ShaderStage::Vertex, kFlatVs}, {dm::ShaderStage::Fragment, fs}}, {{"VALUE", "0.25"}});
  ASSERT_TRUE(prog) << prog.error();
  EXPECT_GE(prog->location("u_depth"), 0);
  EXPECT_EQ(prog->location("u_not_there"), -1);
}
