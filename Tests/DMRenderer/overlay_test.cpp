// The 2-D overlay: text measured against its rendered ink and DejaVu's
// published metrics, exact rectangle and line coverage, linear-space
// blending, plot geometry against the sine it plots, 1:1 sprites, batching,
// allocation-free steady frames, the missing-font error and the HUD golden.
#include <dm/renderer/image_compare.hpp>
#include <dm/renderer/overlay.hpp>
#include <dm/renderer/render_target.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <fstream>
#include <numbers>
#include <vector>

#include "../common/alloc_counter.hpp"
#include "render_fixture.hpp"

namespace {

using dm::test::srgbToLinear;

struct Box {
  int left = 0, top = 0, right = 0, bottom = 0;  // right/bottom exclusive
  bool empty() const { return right <= left; }
};

// Bounding box of pixels whose colour differs from black (ink over a black clear).
Box inkBox(const dm::Image& img, int threshold = 0) {
  Box b{img.width(), img.height(), -1, -1};
  for (int y = 0; y < img.height(); ++y)
    for (int x = 0; x < img.width(); ++x)
      for (int c = 0; c < 3; ++c)
        if (img.at<std::uint8_t>(x, y, c) > threshold) {
          b.left = std::min(b.left, x);
          b.top = std::min(b.top, y);
          b.right = std::max(b.right, x + 1);
          b.bottom = std::max(b.bottom, y + 1);
        }
  if (b.right < 0) return {};
  return b;
}

struct Frame {
  dm::RenderTarget target;
  dm::Overlay overlay;
};

// A single-sample sRGB target cleared to `clear` and a fresh overlay.
Frame makeFrame(int w, int h, const dm::Vec4f& clear = dm::Vec4f(0, 0, 0, 1), int samples = 1) {
  auto rt = dm::RenderTarget::create({.width = w, .height = h, .samples = samples});
  EXPECT_TRUE(rt) << rt.error();
  auto ov = dm::Overlay::create();
  EXPECT_TRUE(ov) << ov.error();
  Frame f{std::move(*rt), std::move(*ov)};
  f.target.clear(clear);
  return f;
}

dm::Image read(const dm::RenderTarget& rt) {
  auto img = rt.readColor();
  EXPECT_TRUE(img) << img.error();
  return std::move(*img);
}

const dm::Vec4f kWhite(1, 1, 1, 1);

}  // namespace

TEST(Overlay, MissingFontIsAClearErrorNamingPathAndPackage) {
  DM_REQUIRE_GL();
  auto missing = dm::Overlay::create({.fontPath = "/nonexistent/fonts/NoSuchFont.ttf"});
  ASSERT_FALSE(missing);
  EXPECT_EQ(missing.error().code, dm::ErrorCode::NotFound);
  EXPECT_NE(missing.error().message().find("/nonexistent/fonts/NoSuchFont.ttf"), std::string::npos);
  EXPECT_NE(missing.error().hint.find("fonts-dejavu-core"), std::string::npos);

  const auto junk = dm::test::renderOutDir() / "overlay_not_a_font.ttf";
  std::filesystem::create_directories(junk.parent_path());
  std::ofstream(junk) << "this is not a TrueType font";
  auto bad = dm::Overlay::create({.fontPath = junk});
  ASSERT_FALSE(bad);
  EXPECT_EQ(bad.error().code, dm::ErrorCode::Parse);
  EXPECT_EQ(bad.error().where, junk.string());

  EXPECT_FALSE(dm::Overlay::create({.bakeSize = 0}));
}

TEST(Overlay, DefaultFontIsDejaVuSansMono) {
  DM_REQUIRE_GL();
  auto ov = dm::Overlay::create();
  ASSERT_TRUE(ov) << ov.error();
  EXPECT_EQ(ov->fontPath(), std::filesystem::path(dm::kDejaVuSansMonoPath));
  auto sans = dm::Overlay::create({.fontPath = dm::kDejaVuSansPath});
  ASSERT_TRUE(sans) << sans.error();
}

TEST(Overlay, MeasureTextFollowsDejaVuMetrics) {
  DM_REQUIRE_GL();
  auto ov = dm::Overlay::create();
  ASSERT_TRUE(ov) << ov.error();
  // DejaVu Sans Mono: advance 1233/2048 em, cap height 1493/2048 em. Hinting
  // rounds each advance to a whole pixel, so allow half a pixel per glyph.
  for (float px : {12.0f, 20.0f, 31.0f}) {
    const dm::TextMetrics ten = ov->measureText("MMMMMMMMMM", px);
    EXPECT_NEAR(ten.width, 10 * px * 1233.0 / 2048.0, 5.0) << px;
    // Monospaced: the advance width of n glyphs is n times one glyph's.
    EXPECT_FLOAT_EQ(ten.width, 10 * ov->measureText("i", px).width) << px;
    const dm::TextMetrics h = ov->measureText("H", px);
    EXPECT_NEAR(h.inkBottom - h.inkTop, px * 1493.0 / 2048.0, 1.01) << px;
    EXPECT_EQ(h.inkBottom, h.ascent) << "H sits on the baseline";
    const dm::TextMetrics two = ov->measureText("H\nH", px);
    EXPECT_EQ(two.lines, 2);
    EXPECT_FLOAT_EQ(two.height, two.lineHeight + two.ascent + two.descent);
  }
  // Non-ASCII symbols are real glyphs, not the '?' fallback.
  const dm::TextMetrics deg = ov->measureText("\xC2\xB0", 20);  // °
  const dm::TextMetrics q = ov->measureText("?", 20);
  EXPECT_LT(deg.inkBottom - deg.inkTop, q.inkBottom - q.inkTop);
  EXPECT_EQ(ov->measureText("\xE2\x82\xAC", 20).inkBottom, q.inkBottom) << "unknown code points show as '?'";
}

TEST(Overlay, FullAtlasFallsBackToTheNearestBakedSizeScaled) {
  DM_REQUIRE_GL();
  auto ov = dm::Overlay::create({.bakeSize = 8, .atlasSize = 128, .maxAtlasHeight = 128});
  ASSERT_TRUE(ov) << ov.error();
  // 64 px glyphs cannot fit a 128x128 atlas: the 8 px glyphs are drawn 8x larger.
  const dm::TextMetrics big = ov->measureText("MMMMMMMMMM", 64);
  EXPECT_FLOAT_EQ(big.width, 8 * ov->measureText("MMMMMMMMMM", 8).width);
  EXPECT_NEAR(big.width, 10 * 64 * 1233.0 / 2048.0, 0.1 * big.width);
  auto rt = dm::RenderTarget::create({.width = 480, .height = 100, .samples = 1});
  ASSERT_TRUE(rt);
  rt->clear(dm::Vec4f(0, 0, 0, 1));
  ov->begin(*rt);
  ov->text(10, 10, "MMMMMMMMMM", 64, kWhite);
  ASSERT_TRUE(ov->end());
  EXPECT_EQ(ov->stats().bakedSizes, 1);
  const Box ink = inkBox(read(*rt));
  EXPECT_NEAR(ink.right - ink.left, big.inkRight - big.inkLeft, 2);
  EXPECT_NEAR(ink.bottom - ink.top, big.inkBottom - big.inkTop, 2);
}

TEST(Overlay, RenderedTextInkMatchesMeasureText) {
  DM_REQUIRE_GL();
  Frame f = makeFrame(200, 60);
  const char* text =
      "Hg 37.5\xC2\xB0"
      "C \xC2\xB1\xC2\xB5m";  // "Hg 37.5°C ±µm"
  const dm::TextMetrics m = f.overlay.measureText(text, 20);
  struct Placement {
    dm::TextAnchor anchor;
    float x, y, fraction;  // fraction of the box left of / above the anchor point
  };
  for (const Placement& p :
       {Placement{dm::TextAnchor::TopLeft, 20, 5, 0.0f}, Placement{dm::TextAnchor::Center, 100, 30, 0.5f},
        Placement{dm::TextAnchor::BottomRight, 180, 55, 1.0f}}) {
    f.target.clear(dm::Vec4f(0, 0, 0, 1));
    f.overlay.begin(f.target);
    f.overlay.text(p.x, p.y, text, 20, kWhite, p.anchor);
    ASSERT_TRUE(f.overlay.end());
    const Box ink = inkBox(read(f.target));
    ASSERT_FALSE(ink.empty());
    const int boxLeft = static_cast<int>(std::round(p.x - p.fraction * m.width));
    const int boxTop = static_cast<int>(std::round(p.y - p.fraction * m.height));
    EXPECT_NEAR(ink.left, boxLeft + m.inkLeft, 1);
    EXPECT_NEAR(ink.right, boxLeft + m.inkRight, 1);
    EXPECT_NEAR(ink.top, boxTop + m.inkTop, 1);
    EXPECT_NEAR(ink.bottom, boxTop + m.inkBottom, 1);
    // The ink lies inside the text box, give or take the glyphs' side bearings.
    EXPECT_NEAR(ink.right - ink.left, m.width, 3);
  }
  EXPECT_EQ(f.overlay.stats().drawCalls, 1);
}

TEST(Overlay, FilledRectCoversExactlyItsPixels) {
  DM_REQUIRE_GL();
  Frame f = makeFrame(64, 48);
  f.overlay.begin(f.target);
  f.overlay.fillRect({10, 7, 23, 13}, dm::Vec4f(1, 0, 0, 1));
  ASSERT_TRUE(f.overlay.end());
  dm::Image img = read(f.target);
  EXPECT_EQ(dm::countCoveredPixels(img, dm::Vec3f(0, 0, 0)), 23u * 13u);
  EXPECT_EQ(img.at<std::uint8_t>(10, 7, 0), 255);
  EXPECT_EQ(img.at<std::uint8_t>(32, 19, 0), 255);
  EXPECT_EQ(img.at<std::uint8_t>(9, 7, 0), 0);
  EXPECT_EQ(img.at<std::uint8_t>(10, 6, 0), 0);
  EXPECT_EQ(img.at<std::uint8_t>(33, 19, 0), 0);
  EXPECT_EQ(img.at<std::uint8_t>(32, 20, 0), 0);
  EXPECT_EQ(f.overlay.stats().vertices, 6u);

  f.target.clear(dm::Vec4f(0, 0, 0, 1));
  f.overlay.begin(f.target);
  f.overlay.strokeRect({4, 5, 30, 20}, dm::Vec4f(0, 1, 0, 1), 3);
  ASSERT_TRUE(f.overlay.end());
  img = read(f.target);
  EXPECT_EQ(dm::countCoveredPixels(img, dm::Vec3f(0, 0, 0)), 30u * 20u - 24u * 14u);
  EXPECT_EQ(img.at<std::uint8_t>(4 + 15, 5 + 10, 1), 0) << "the inside stays clear";
}

TEST(Overlay, LineCoverageIsLengthTimesWidth) {
  DM_REQUIRE_GL();
  Frame f = makeFrame(160, 160);
  f.overlay.begin(f.target);
  f.overlay.line({10, 20}, {110, 20}, kWhite, 4);
  ASSERT_TRUE(f.overlay.end());
  EXPECT_EQ(dm::countCoveredPixels(read(f.target), dm::Vec3f(0, 0, 0)), 400u);

  f.target.clear(dm::Vec4f(0, 0, 0, 1));
  f.overlay.begin(f.target);
  // Not at 45 degrees: there pixel centres sample the edges in lockstep, a bias of up to a pixel per row.
  f.overlay.line({20, 20}, {120, 83}, kWhite, 3);
  ASSERT_TRUE(f.overlay.end());
  const double diagonal = std::sqrt(100.0 * 100.0 + 63.0 * 63.0) * 3;
  EXPECT_NEAR(static_cast<double>(dm::countCoveredPixels(read(f.target), dm::Vec3f(0, 0, 0))), diagonal,
              0.03 * diagonal);

  // A mitred polyline covers its centre-line length times its width.
  const std::array<dm::Vec2f, 4> pts = {dm::Vec2f(20, 30), dm::Vec2f(120, 30), dm::Vec2f(120, 130),
                                        dm::Vec2f(40, 70)};
  const double length = 100 + 100 + std::sqrt(80.0 * 80.0 + 60.0 * 60.0);
  f.target.clear(dm::Vec4f(0, 0, 0, 1));
  f.overlay.begin(f.target);
  f.overlay.polyline(pts, kWhite, 5);
  ASSERT_TRUE(f.overlay.end());
  EXPECT_NEAR(static_cast<double>(dm::countCoveredPixels(read(f.target), dm::Vec3f(0, 0, 0))), length * 5,
              0.03 * length * 5);
}

TEST(Overlay, HalfAlphaBlendsLinearlyOverTheBackground) {
  DM_REQUIRE_GL();
  const dm::Vec4f bg(0.2f, 0.4f, 0.8f, 1), fg(1.0f, 0.1f, 0.0f, 0.5f);
  Frame f = makeFrame(32, 32, bg);
  f.overlay.begin(f.target);
  f.overlay.fillRect({0, 0, 16, 32}, fg);
  ASSERT_TRUE(f.overlay.end());
  const dm::Image img = read(f.target);
  for (int c = 0; c < 3; ++c) {
    const double expected = 0.5 * fg[c] + 0.5 * bg[c];
    EXPECT_NEAR(srgbToLinear(img.at<std::uint8_t>(8, 16, c)), expected, 0.008) << "channel " << c;
    EXPECT_NEAR(srgbToLinear(img.at<std::uint8_t>(24, 16, c)), bg[c], 0.008) << "channel " << c;
  }
}

TEST(Overlay, PlotPutsASineWhereTheMathSays) {
  DM_REQUIRE_GL();
  Frame f = makeFrame(240, 140);
  std::vector<float> sine(361);
  for (std::size_t i = 0; i < sine.size(); ++i)
    sine[i] = static_cast<float>(std::sin(2 * std::numbers::pi * static_cast<double>(i) / 360.0));
  const dm::OverlaySeries series[] = {{sine, dm::Vec4f(0, 1, 0, 1), 1.5f}};
  for (bool autoRange : {true, false}) {
    f.target.clear(dm::Vec4f(0, 0, 0, 1));
    f.overlay.begin(f.target);
    const dm::PlotLayout L = f.overlay.plot({0, 0, 240, 140}, series,
                                            {.autoRange = autoRange, .yMin = -2, .yMax = 2, .title = "sine"});
    ASSERT_TRUE(f.overlay.end());
    EXPECT_EQ(f.overlay.stats().drawCalls, 1);
    const float lo = autoRange ? -1.0f : -2.0f, hi = -lo;
    EXPECT_FLOAT_EQ(L.yMin, lo);
    EXPECT_FLOAT_EQ(L.yMax, hi);
    ASSERT_GT(L.area.width, 150);
    ASSERT_GT(L.area.height, 80);
    const dm::Image img = read(f.target);
    const auto green = [&](int x, int y) {
      return img.at<std::uint8_t>(x, y, 1) > 200 && img.at<std::uint8_t>(x, y, 0) < 90 &&
             img.at<std::uint8_t>(x, y, 2) < 90;
    };
    // Column by column, the line's pixels centre on the sine's value there.
    int topRow = img.height(), checked = 0;
    double topColumnSum = 0;
    int topColumnCount = 0;
    for (int x = static_cast<int>(L.area.x) + 2; x < static_cast<int>(L.area.x + L.area.width) - 2; ++x) {
      double sum = 0;
      int n = 0;
      for (int y = 0; y < img.height(); ++y)
        if (green(x, y)) {
          sum += y;
          ++n;
          if (y < topRow) {
            topRow = y;
            topColumnSum = 0;
            topColumnCount = 0;
          }
          if (y == topRow) {
            topColumnSum += x;
            ++topColumnCount;
          }
        }
      ASSERT_GT(n, 0) << "column " << x;
      const double t = (x + 0.5 - L.area.x) / L.area.width;
      const double slope = std::abs(2 * std::numbers::pi * std::cos(2 * std::numbers::pi * t)) / (hi - lo) *
                           L.area.height / L.area.width;
      if (slope > 1.5) continue;  // steep: a column holds a long vertical run
      const double expectedY =
          L.area.y + L.area.height * (hi - std::sin(2 * std::numbers::pi * t)) / (hi - lo);
      EXPECT_NEAR(sum / n + 0.5, expectedY, 1.5) << "column " << x;
      ++checked;
    }
    EXPECT_GT(checked, 80);
    // The maximum: a quarter of the way across, at the top of the range.
    EXPECT_NEAR(topColumnSum / topColumnCount + 0.5, L.area.x + 0.25 * L.area.width, 3.0);
    EXPECT_NEAR(topRow + 0.75, L.area.y + L.area.height * (hi - 1) / (hi - lo), 1.0);
  }
}

TEST(Overlay, SpriteShowsImagePixelsOneToOne) {
  DM_REQUIRE_GL();
  Frame f = makeFrame(64, 40);
  auto rgba = dm::Image::create(5, 4, 4, dm::PixelType::U8);
  auto rgb = dm::Image::create(3, 2, 3, dm::PixelType::U8);
  auto gray = dm::Image::create(2, 2, 1, dm::PixelType::U8);
  ASSERT_TRUE(rgba && rgb && gray);
  for (int y = 0; y < 4; ++y)
    for (int x = 0; x < 5; ++x) {
      rgba->at<std::uint8_t>(x, y, 0) = static_cast<std::uint8_t>(20 + 50 * x);
      rgba->at<std::uint8_t>(x, y, 1) = static_cast<std::uint8_t>(30 + 60 * y);
      rgba->at<std::uint8_t>(x, y, 2) = static_cast<std::uint8_t>(250 - 13 * (x + y));
      rgba->at<std::uint8_t>(x, y, 3) = 255;
    }
  for (int y = 0; y < 2; ++y)
    for (int x = 0; x < 3; ++x)
      for (int c = 0; c < 3; ++c)
        rgb->at<std::uint8_t>(x, y, c) = static_cast<std::uint8_t>(40 * (x + 1) + 70 * c + y);
  gray->at<std::uint8_t>(0, 0) = 10;
  gray->at<std::uint8_t>(1, 0) = 100;
  gray->at<std::uint8_t>(0, 1) = 180;
  gray->at<std::uint8_t>(1, 1) = 250;
  auto t1 = f.overlay.createTexture(*rgba);
  auto t2 = f.overlay.createTexture(*rgb);
  auto t3 = f.overlay.createTexture(*gray);
  ASSERT_TRUE(t1 && t2 && t3);
  f.overlay.begin(f.target);
  f.overlay.fillRect({0, 0, 2, 2}, kWhite);
  f.overlay.sprite(*t1, {13, 9, 5, 4});
  f.overlay.sprite(*t1, {30, 9, 10, 8});  // 2x, nearest
  f.overlay.sprite(*t2, {50, 30, 3, 2});
  f.overlay.sprite(*t3, {2, 30, 2, 2});
  ASSERT_TRUE(f.overlay.end());
  EXPECT_EQ(f.overlay.stats().drawCalls, 3) << "one draw call per sprite texture run";
  const dm::Image img = read(f.target);
  for (int y = 0; y < 4; ++y)
    for (int x = 0; x < 5; ++x)
      for (int c = 0; c < 3; ++c) {
        EXPECT_NEAR(img.at<std::uint8_t>(13 + x, 9 + y, c), rgba->at<std::uint8_t>(x, y, c), 1);
        for (int sy = 0; sy < 2; ++sy)
          for (int sx = 0; sx < 2; ++sx)
            EXPECT_NEAR(img.at<std::uint8_t>(30 + 2 * x + sx, 9 + 2 * y + sy, c),
                        rgba->at<std::uint8_t>(x, y, c), 1);
      }
  for (int y = 0; y < 2; ++y)
    for (int x = 0; x < 3; ++x)
      for (int c = 0; c < 3; ++c)
        EXPECT_NEAR(img.at<std::uint8_t>(50 + x, 30 + y, c), rgb->at<std::uint8_t>(x, y, c), 1);
  for (int y = 0; y < 2; ++y)
    for (int x = 0; x < 2; ++x)
      EXPECT_NEAR(img.at<std::uint8_t>(2 + x, 30 + y, 1), gray->at<std::uint8_t>(x, y), 1);
  // Exactly the requested rectangles were touched.
  EXPECT_EQ(dm::countCoveredPixels(img, dm::Vec3f(0, 0, 0), 0), 4u + 20u + 80u + 6u + 4u);

  // A destroyed texture's handle draws nothing; a stale handle is not reused.
  f.overlay.destroyTexture(*t2);
  auto t4 = f.overlay.createTexture(*rgb);
  ASSERT_TRUE(t4);
  EXPECT_FALSE(f.overlay.updateTexture(*t2, *rgb));
  EXPECT_TRUE(f.overlay.updateTexture(*t4, *rgba));
  auto f32 = dm::Image::create(2, 2, 1, dm::PixelType::F32);
  EXPECT_FALSE(f.overlay.createTexture(*f32));
}

TEST(Overlay, WrappedRenderTargetTextureKeepsItsTopUp) {
  DM_REQUIRE_GL();
  Frame f = makeFrame(32, 32);
  auto inner = dm::RenderTarget::create({.width = 8, .height = 8, .samples = 1});
  ASSERT_TRUE(inner);
  inner->clear(dm::Vec4f(0, 0, 1, 1));
  f.overlay.begin(*inner);
  f.overlay.fillRect({0, 0, 8, 3}, dm::Vec4f(1, 0, 0, 1));  // the top three rows red
  ASSERT_TRUE(f.overlay.end());
  const dm::SpriteId pip = f.overlay.wrapTexture(inner->colorTexture());
  ASSERT_TRUE(pip.valid());
  f.overlay.begin(f.target);
  f.overlay.sprite(pip, {10, 12, 8, 8});
  ASSERT_TRUE(f.overlay.end());
  const dm::Image img = read(f.target);
  EXPECT_EQ(img.at<std::uint8_t>(13, 12, 0), 255);
  EXPECT_EQ(img.at<std::uint8_t>(13, 14, 0), 255);
  EXPECT_EQ(img.at<std::uint8_t>(13, 15, 0), 0);
  EXPECT_EQ(img.at<std::uint8_t>(13, 15, 2), 255);
  EXPECT_EQ(img.at<std::uint8_t>(17, 19, 2), 255);
  EXPECT_EQ(dm::countCoveredPixels(img, dm::Vec3f(0, 0, 0)), 64u);
  f.overlay.destroyTexture(pip);
  EXPECT_NE(inner->colorTexture(), 0u);
}

TEST(Overlay, SteadyFramesDoNotAllocate) {
  DM_REQUIRE_GL();
  Frame f = makeFrame(256, 160);
  std::vector<float> force(2000);
  for (std::size_t i = 0; i < force.size(); ++i)
    force[i] = 2.0f + std::sin(0.01f * static_cast<float>(i)) + 0.1f * std::sin(0.7f * static_cast<float>(i));
  auto img = dm::Image::create(8, 8, 4, dm::PixelType::U8);
  ASSERT_TRUE(img);
  auto tex = f.overlay.createTexture(*img);
  ASSERT_TRUE(tex);
  const dm::OverlaySeries series[] = {{force, dm::Vec4f(1, 0.8f, 0.2f, 1), 1.5f}};
  std::uint64_t allocations = 0;
  for (int frame = 0; frame < 4; ++frame) {
    if (frame == 3) dm::test::tCountAllocations = true;
    const auto before = dm::test::countedAllocations();
    f.overlay.begin(f.target);
    f.overlay.text(4, 4,
                   "|F| = 2.31 N  \xC2\xB1"
                   "0.05",
                   14, kWhite);
    f.overlay.plot({4, 24, 248, 132}, series,
                   {.xMin = -2, .xMax = 0, .title = "|F| last 2 s", .yLabel = "N"});
    f.overlay.sprite(*tex, {230, 4, 8, 8});
    const bool ended = static_cast<bool>(f.overlay.end());
    allocations = dm::test::countedAllocations() - before;
    dm::test::tCountAllocations = false;
    ASSERT_TRUE(ended);
  }
  EXPECT_EQ(allocations, 0u);
  EXPECT_EQ(f.overlay.stats().drawCalls, 1);
  EXPECT_GE(f.overlay.stats().vertices, 6u * 1999u);
}

TEST(Overlay, EndWithoutBeginFails) {
  DM_REQUIRE_GL();
  auto ov = dm::Overlay::create();
  ASSERT_TRUE(ov) << ov.error();
  auto s = ov->end();
  ASSERT_FALSE(s);
  EXPECT_EQ(s.error().code, dm::ErrorCode::InvalidArgument);
}

TEST(Overlay, HudGolden) {
  DM_REQUIRE_GL();
  Frame f = makeFrame(256, 160, dm::Vec4f(0.02f, 0.03f, 0.05f, 1));
  std::vector<float> force(2000);
  for (std::size_t i = 0; i < force.size(); ++i) {
    const float t = static_cast<float>(i) / 1000.0f;
    force[i] = 1.5f + std::sin(3.0f * t) * std::exp(-0.5f * t) + 0.15f * std::sin(40.0f * t);
  }
  std::vector<float> limit(2, 2.5f);
  auto img = dm::Image::create(32, 32, 4, dm::PixelType::U8);
  ASSERT_TRUE(img);
  for (int y = 0; y < 32; ++y)
    for (int x = 0; x < 32; ++x) {
      const bool cross = std::abs(x - y) < 2 || std::abs(x + y - 31) < 2;
      img->at<std::uint8_t>(x, y, 0) = cross ? 255 : static_cast<std::uint8_t>(8 * x);
      img->at<std::uint8_t>(x, y, 1) = cross ? 255 : static_cast<std::uint8_t>(8 * y);
      img->at<std::uint8_t>(x, y, 2) = cross ? 255 : 128;
      img->at<std::uint8_t>(x, y, 3) = 255;
    }
  auto tex = f.overlay.createTexture(*img);
  ASSERT_TRUE(tex);
  const dm::OverlaySeries series[] = {{force, dm::Vec4f(1, 0.7f, 0.1f, 1), 1.5f},
                                   {limit, dm::Vec4f(1, 0.1f, 0.1f, 0.8f), 1.0f}};
  f.overlay.begin(f.target);
  f.overlay.fillRect({4, 4, 176, 44}, dm::Vec4f(0, 0, 0, 0.5f));
  f.overlay.text(8, 6, "DMPlatform HUD", 14, kWhite);
  f.overlay.text(8, 24,
                 "T 37.0\xC2\xB0"
                 "C  \xC2\xB1"
                 "0.2  5 \xC2\xB5m",
                 12, dm::Vec4f(0.6f, 1, 0.6f, 1));
  f.overlay.sprite(*tex, {216, 8, 32, 32});
  f.overlay.strokeRect({215, 7, 34, 34}, kWhite, 1);
  f.overlay.plot({4, 56, 248, 100}, series, {.xMin = -2, .xMax = 0, .title = "|F| (N)", .xLabel = "t (s)"});
  ASSERT_TRUE(f.overlay.end());
  EXPECT_EQ(f.overlay.stats().drawCalls, 1) << "everything in one batch with one sprite texture";
  const dm::Image out = read(f.target);
  // Reference-independent: the sprite's centre pixel is its image's, the text is white.
  EXPECT_NEAR(out.at<std::uint8_t>(216 + 16, 8 + 16, 0), 255, 1);
  EXPECT_NEAR(out.at<std::uint8_t>(216 + 4, 8 + 24, 1), img->at<std::uint8_t>(4, 24, 1), 1);
  auto s = dm::checkGolden(out, dm::test::goldenDir() / "overlay_hud.png", dm::test::renderOutDir(),
                           {.pixelThreshold = 12, .maxFraction = 0.005});
  EXPECT_TRUE(s) << s.error();
}
