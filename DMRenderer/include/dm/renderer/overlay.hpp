// dm/renderer/overlay.hpp — the 2-D overlay drawn over a rendered frame:
// HUD text, filled and outlined rectangles, lines and polylines, sprites
// (images), and small line plots such as the last seconds of a force trace.
//
// Coordinates are pixels of the render target, origin top-left, y down; a
// pixel (i, j) covers [i, i+1) x [j, j+1), so a rectangle on whole pixels
// covers exactly width x height pixels. Colours are LINEAR RGBA with straight
// (not premultiplied) alpha; drawing blends over whatever the target holds
// (src-alpha / one-minus-src-alpha, in linear space on sRGB targets), with
// no depth test and no depth writes.
//
// Text is rasterised with FreeType from a real font file (by default
// Debian's fonts-dejavu-core: DejaVuSansMono.ttf, else DejaVuSans.ttf) into
// one glyph atlas: printable ASCII plus ° ± µ ² ³ × · μ Δ (other code points
// show as '?'), baked at whole pixel sizes on first use, laid out without
// kerning, glyphs snapped to whole pixels so they map 1:1 onto the target.
//
// A frame is begin(target), any number of drawing calls, end(): the calls
// only append to one vertex array; end() uploads it into one buffer and
// issues one draw call per run of consecutive sprites sharing a texture (one
// call in all when there are no sprites). After a warm-up frame, frames of
// the same size do not allocate (the arrays keep their capacity), as long
// as no new text size or texture is introduced. Every call needs the
// GlContext the overlay was created with current on the calling thread.
//
// @code
//   auto overlay = dm::Overlay::create();                  // DejaVu font
//   overlay->begin(target); overlay->text(8, 8, "|F| = 1.2 N", 14, dm::Vec4f(1, 1, 1, 1));
//   if (auto s = overlay->end(); !s) dm::log::warn("%s", s.error().message().c_str());
// @endcode
#pragma once

#include <dm/core/image.hpp>
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <span>
#include <string_view>

namespace dm {

class RenderTarget;

/// Where a DejaVu font lives on Debian/Ubuntu (package fonts-dejavu-core).
inline constexpr const char* kDejaVuSansMonoPath = "/usr/share/fonts/truetype/dejavu/DejaVuSansMono.ttf";
inline constexpr const char* kDejaVuSansPath = "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf";

/// How to create an Overlay.
struct OverlayOptions {
  /// Font file (TrueType/OpenType). Empty: kDejaVuSansMonoPath, else
  /// kDejaVuSansPath. A path given here is used as is (no fallback).
  std::filesystem::path fontPath;
  int bakeSize = 14;          ///< pixel size baked at create(); others are baked on first use
  int atlasSize = 512;        ///< initial atlas width and height in texels (64..4096); it grows in height
  int maxAtlasHeight = 4096;  ///< texels; once full, new text sizes use the nearest baked size, scaled
};

/// A rectangle in pixels (origin top-left, y down).
struct OverlayRect {
  float x = 0, y = 0;
  float width = 0, height = 0;
};

/// Which point of the text box `Overlay::text` places at (x, y).
enum class TextAnchor : std::uint8_t {
  TopLeft,
  Top,
  TopRight,
  Left,
  Center,
  Right,
  BottomLeft,
  Bottom,
  BottomRight,
  BaselineLeft,  ///< the first line's baseline at y, the pen start at x
};

/// Size of a laid-out text in pixels. The text box is `width` x `height`;
/// its top is `ascent` above the first baseline. The ink box is where glyph
/// coverage lands, relative to the box's top-left (left/top inclusive,
/// right/bottom exclusive; all zero for text without ink, e.g. spaces).
struct TextMetrics {
  float width = 0;   ///< advance width of the widest line
  float height = 0;  ///< (lines - 1) * lineHeight + ascent + descent
  int ascent = 0;    ///< pixels from the box top to the first baseline
  int descent = 0;   ///< pixels below the last baseline
  int lineHeight = 0;
  int lines = 0;  ///< '\n' separates lines
  int inkLeft = 0, inkTop = 0, inkRight = 0, inkBottom = 0;
};

/// A texture the overlay can draw as a sprite: a generational handle of the
/// overlay's own (SceneRenderer textures are dm::TextureId).
struct SpriteId {
  std::uint32_t index = 0;
  std::uint32_t generation = 0;  ///< 0 = invalid
  bool valid() const { return generation != 0; }
};

/// How an image becomes a sprite texture.
struct TextureOptions {
  bool srgb = true;     ///< pixels are sRGB-encoded (photos, PNGs); false: linear data
  bool linear = false;  ///< bilinear sampling when scaled; default nearest (pixel-exact 1:1)
};

/// One line of a plot: `values` are evenly spaced in x over the plot's
/// width (first at the left edge, last at the right); non-finite values
/// break the line.
struct OverlaySeries {
  std::span<const float> values;
  Vec4f color = Vec4f(1, 1, 1, 1);
  float width = 1.5f;  ///< line width, pixels
};

/// Appearance and axes of a plot.
struct PlotOptions {
  bool autoRange = true;     ///< y range from the data, widened to whole grid steps
  float yMin = 0, yMax = 1;  ///< used when !autoRange (values outside are clamped to the frame)
  float xMin = 0, xMax = 1;  ///< x-axis label values of the first and last sample (e.g. -2 s .. 0 s)
  bool axes = true;          ///< left and bottom axis lines
  bool grid = true;          ///< gridlines at the tick values
  bool labels = true;        ///< tick labels (printf %g) left of and below the data area
  std::string_view title;    ///< centred above the data area; empty: none
  std::string_view yLabel;   ///< top left above the y axis (e.g. "|F| N"); empty: none
  std::string_view xLabel;   ///< centred below the x tick labels; empty: none
  float textSize = 11;       ///< pixels
  Vec4f background = Vec4f(0, 0, 0, 0.5f);
  Vec4f axisColor = Vec4f(0.8f, 0.8f, 0.8f, 1);
  Vec4f gridColor = Vec4f(0.5f, 0.5f, 0.5f, 0.35f);
  Vec4f textColor = Vec4f(0.9f, 0.9f, 0.9f, 1);
};

/// Where a plot put its data and the y range it used: sample i of n lies
/// at x = area.x + area.width * i / (n - 1), value v at
/// y = area.y + area.height * (yMax - v) / (yMax - yMin).
struct PlotLayout {
  OverlayRect area;  ///< the data area inside the frame, pixels
  float yMin = 0, yMax = 1;
  float yStep = 0;  ///< grid step in y
};

/// What the last end() drew.
struct OverlayStats {
  int drawCalls = 0;
  std::size_t vertices = 0;  ///< 6 per quad or line segment
  int bakedSizes = 0;        ///< text sizes in the atlas
  int atlasWidth = 0, atlasHeight = 0;
};

/// The 2-D overlay renderer. Move-only; destroy it with its context current.
class Overlay {
 public:
  /// Opens the font, bakes `options.bakeSize`, compiles the shader. Fails
  /// with NotFound naming the font path and the package fonts-dejavu-core
  /// when the font is missing, Parse when FreeType cannot read it, or
  /// InvalidArgument when no GL context is current.
  static Result<Overlay> create(const OverlayOptions& options = {});

  Overlay();
  Overlay(Overlay&&) noexcept;
  Overlay& operator=(Overlay&&) noexcept;
  Overlay(const Overlay&) = delete;
  Overlay& operator=(const Overlay&) = delete;
  ~Overlay();

  /// The font file in use.
  const std::filesystem::path& fontPath() const;

  /// Starts a frame drawn over `target` (which must outlive end()).
  void begin(const RenderTarget& target);
  /// Uploads the frame's vertices and draws them into the target given to
  /// begin(). Leaves blending and depth/cull/scissor state as it found
  /// them. Fails when called without begin() or on a GL error.
  Status end();
  /// Draw calls and vertices of the last end(), atlas size.
  const OverlayStats& stats() const;

  /// Text box size and ink box of UTF-8 `text` at `sizePx` (rounded to whole
  /// pixels, 4..256), exactly as text() lays it out. O(length); bakes the
  /// size on first use.
  TextMetrics measureText(std::string_view text, float sizePx);
  /// Draws UTF-8 `text` (lines separated by '\n') at `sizePx` with the
  /// `anchor` point of its box at (x, y), the box snapped to whole pixels.
  void text(float x, float y, std::string_view text, float sizePx, const Vec4f& color,
            TextAnchor anchor = TextAnchor::TopLeft);

  /// Fills `r` with `color`.
  void fillRect(const OverlayRect& r, const Vec4f& color);
  /// Outlines `r` with a border `width` pixels wide drawn inside `r`.
  void strokeRect(const OverlayRect& r, const Vec4f& color, float width = 1);
  /// A straight line from a to b, `width` pixels wide, with butt ends
  /// (covers length x width pixels).
  void line(const Vec2f& a, const Vec2f& b, const Vec4f& color, float width = 1);
  /// Connected line through `points` (mitred joins, limited to 4x the half
  /// width); non-finite points break it. O(points), no allocation.
  void polyline(std::span<const Vec2f> points, const Vec4f& color, float width = 1);

  /// Uploads `image` (U8, 1 to 4 channels: gray, gray+alpha, RGB, RGBA) once
  /// as a sprite texture. Fails on other pixel types or sizes beyond
  /// GL_MAX_TEXTURE_SIZE.
  Result<SpriteId> createTexture(const Image& image, const TextureOptions& options = {});
  /// Replaces the pixels of a texture made by createTexture (same or other size).
  Status updateTexture(SpriteId id, const Image& image);
  /// A handle to a GL texture owned elsewhere whose row 0 is the bottom, as
  /// in RenderTarget::colorTexture() (picture-in-picture; resolve() a
  /// multisampled target first). The overlay never deletes it.
  SpriteId wrapTexture(std::uint32_t glTexture);
  /// Frees the texture (GL objects of wrapped ones stay); the handle becomes invalid.
  void destroyTexture(SpriteId id);
  /// Draws the texture stretched over `dst`, multiplied by `tint`. Invalid
  /// handles draw nothing.
  void sprite(SpriteId id, const OverlayRect& dst, const Vec4f& tint = Vec4f(1, 1, 1, 1));

  /// A line plot of `series` inside `frame` (background, grid, axes, tick
  /// labels, title), each series one polyline. Returns where the data went.
  /// O(total samples); no allocation after warm-up.
  PlotLayout plot(const OverlayRect& frame, std::span<const OverlaySeries> series,
                  const PlotOptions& options = {});

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace dm
